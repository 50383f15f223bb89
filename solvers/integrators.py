"""The time integrators of the implicit solvers, as incremental potentials (docs/design.md, "Time integration").

Both integrators of `scenarios.model.INTEGRATORS` minimise the same potential over the end-of-step positions x,

    E(x) = 1/(2 h_eff^2) |x - x_tilde|_M^2 + U(x) + h_eff sum Phi(v(x)),    v(x) = (x - x_bar) / h_eff,

U the elastic, gravity and contact energies, Phi the dissipation potentials (friction, contact damping), and
x_tilde = x_bar + h_eff v_bar; the end-of-step velocity is v(x^{n+1}). They differ in x_bar, v_bar and the effective
step h_eff:

- backward Euler: x_bar = x^n, v_bar = v^n, h_eff = h (first order);
- BDF2 at a constant step h: x_bar = 4/3 x^n - 1/3 x^{n-1}, v_bar = 4/3 v^n - 1/3 v^{n-1}, h_eff = 2/3 h (second
  order). It needs the state one step h before the step's start (`State.previous`); without one at that distance (the
  first step, or the first step after a change of step size) the step is backward Euler. So a step that
  `solvers.simulate.advance` retries as two half steps after a full one restarts BDF2: the first half step is
  backward Euler, the second is BDF2 at h/2 on the first, and the next full step is backward Euler again (a half
  step that follows a half step keeps BDF2: its history is one half step back).

The formulas hold for any coordinates: vertex positions (the full-space solver) or latent coordinates (the reduced
solver, whose decoding is linear).
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from scenarios.model import INTEGRATORS
from solvers.model import State

#: h_eff / h of BDF2.
BDF2_BETA = 2.0 / 3.0

#: Relative tolerance on the previous state's distance in time for it to count as one step back (the times are sums
#: of steps: they agree to round-off, while a change of step size is a factor of 2 at least).
_SAME_STEP = 1e-6


@dataclass(frozen=True)
class Lagged:
    """One step's integrator constants in coordinates y (positions (n, 3) [m] or latent (r,)): y_bar, the velocity
    v_bar (shape of y, per second) and the effective step h_eff [s]."""

    y_bar: np.ndarray
    v_bar: np.ndarray
    h_eff: float

    @property
    def y_tilde(self) -> np.ndarray:
        """The inertial target y_bar + h_eff v_bar."""
        return self.y_bar + self.h_eff * self.v_bar

    def velocity(self, y: np.ndarray) -> np.ndarray:
        """The velocity (y - y_bar) / h_eff of end-of-step coordinates y."""
        return (y - self.y_bar) / self.h_eff


def previous_step(state: State, dt: float) -> State | None:
    """`state.previous` if it lies one step dt [s] before `state` (BDF2 can use it), else None."""
    prev = state.previous
    if prev is None or abs((state.t - prev.t) - dt) > _SAME_STEP * dt:
        return None
    return prev


def lagged(integrator: str, y: np.ndarray, v: np.ndarray, y_prev: np.ndarray | None, v_prev: np.ndarray | None,
           dt: float) -> Lagged:
    """The step's constants of `integrator` from the start-of-step coordinates y and velocity v, and the same one step
    dt [s] before (None: none, the step is then backward Euler)."""
    if integrator not in INTEGRATORS:
        raise ValueError(f"time.integrator = {integrator!r}: expected one of {list(INTEGRATORS)}")
    if integrator == "bdf2" and y_prev is not None and v_prev is not None:
        return Lagged((4.0 * y - y_prev) / 3.0, (4.0 * v - v_prev) / 3.0, BDF2_BETA * dt)
    return Lagged(y, v, dt)

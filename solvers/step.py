"""One step's incremental potential as a `solvers.newton_method.NewtonProblem`, shared by the implicit solvers: a backend
gives the energy, the Newton direction, the step norm and the contact points of its unknowns, and `StepProblem`
caps every step by the one feasible-step rule of the physics terms (`solvers.physics.terms.max_feasible_step`:
the barrier law keeps every contact point above the plane; without a capping term a step is never capped), and
where a step evaluates what the contact terms lag (`ContactLag`, the scene's `contact.lag`) with the one loop of
lagged solves both solvers run (`solve_lagged`)."""

from __future__ import annotations

from abc import ABC, abstractmethod
from collections.abc import Sequence
from dataclasses import dataclass
from typing import Protocol

import numpy as np

from frictionbench.scenarios.spec import CONTACT_LAGS
from frictionbench.solvers.model import Model
from frictionbench.solvers.newton_method import Direction, NewtonResult
from frictionbench.solvers.physics.contact import damped_points, signed_distance
from frictionbench.solvers.physics.terms import Term, lagged_at_start, max_feasible_step, step_capping


class StepProblem(ABC):
    """A step of `model`'s potential with `terms` over a backend's unknowns y (vertex positions (n, 3) [m] or
    latent coordinates (r,))."""

    def __init__(self, model: Model, terms: Sequence[Term]) -> None:
        self.model = model
        self.capping = step_capping(terms)

    @abstractmethod
    def energy(self, y: np.ndarray) -> float:
        """E(y) [J]."""

    @abstractmethod
    def direction(self, y: np.ndarray) -> Direction:
        """The Newton direction at y (from the PSD-projected Hessian)."""

    def chord_direction(self, y: np.ndarray) -> Direction | None:
        """The chord direction at y (the last direction's factorisation reused; `solvers.newton_method.minimise`), None
        where the backend keeps none (the default)."""
        return None

    @abstractmethod
    def step_norm(self, dy: np.ndarray) -> float:
        """The size of a step dy in velocity units [m/s]."""

    @abstractmethod
    def contact_points(self, y: np.ndarray, dy: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """The contact points' positions at y and their displacement along dy, (p, 3) each [m]."""

    def max_step(self, y: np.ndarray, dy: np.ndarray) -> float:
        """Largest alpha <= 1 that every capping term allows (1 where none caps a step)."""
        if not self.capping:
            return 1.0
        return max_feasible_step(self.capping, self.model, *self.contact_points(y, dy))


# ----- where a step evaluates what contact lags --------------------------------------------------------------------
#: Most solves of a `fixed-point` step (the first, converged, solve included; a later one a re-lag and its Newton
#: iterations); a step that reaches the cap closes with a converged solve at its last lag and counts it in the
#: step's `lag_unconverged` counter. The truth ladders of quick-damped take 3-10 a step on average (experiments/figures.md,
#: "The truth step").
LAG_MAX_SOLVES = 24
#: A `fixed-point` step's solves up to this one take one Newton iteration after their re-lag, later ones run to
#: convergence: one iteration a re-lag is a Picard iteration with an inexact inner solve, which converges where the
#: lag contracts faster than Newton does (most steps), but not always through a stick/slip switch, where converged
#: solves do (measured on a skidding block: one step ran to a cap of 40 one-iteration re-lags).
LAG_ONE_ITERATION_SOLVES = 12


@dataclass(frozen=True)
class ContactLag:
    """Where a step evaluates what the contact terms lag (`Term.begin_step`: friction's normal pressure; the
    contact-damping gate, the points below the plane), the scene's `contact.lag`:

    - `start` (the paper's, and the default): at the start of the step, x^n and v^n. The lag is then O(h) off the
      step's end, so contact and friction are first order under any integrator;
    - `corrected`: two solves: solve with the lag at the start, re-lag at that solution's end state and solve
      once more from it, to convergence (a predictor-corrector, as Heun's method corrects Euler's). Where the
      step resolves contact the lag is then O(h^2) off the step's end: second order at two solves, where the fixed
      point takes 2-5; in an impact or a stick/slip switch inside a step one correction is not the fixed point
      (measured: experiments/figures.md). The second solve is skipped where the re-lag is bitwise the same (free flight);
    - `fixed-point`: lagged iterations (IPC's) to the step's own end state: solve with the lag at the start, then
      re-lag at the current iterate's end state and take one Newton iteration from it, until re-lagging no longer
      moves the solution (the first Newton step after a re-lag is below tolerance, or the lagged quantities come
      out bitwise the same, as in free flight). The normal pressure is then the step's own end state's, as an
      implicit integrator takes it (the tolerance test is the one a converged solve per re-lag would end on: the
      end point solves its own lag's step). The damping gate is the points below the plane at the start or at any
      of the step's lags so far: monotone within a step, so that the iteration cannot cycle between a point damped
      and not (a gate taken at the end alone, or at the start or the end, flips a point that the damping itself
      lifts back above the plane: measured, a 2-cycle that held 3-27 points and every step of a contact phase at
      the cap).

    (A third rule, the lag at the history's linear extrapolation to the step's end, was measured and dropped: it
    extrapolates the contact's unresolved ringing and diverged on a sliding block at dt 0.01-0.0025,
    experiments/figures.md.)
    """

    mode: str = "start"

    def __post_init__(self) -> None:
        if self.mode not in CONTACT_LAGS:
            raise ValueError(f"contact.lag = {self.mode!r}: expected one of {list(CONTACT_LAGS)}")

    @property
    def max_solves(self) -> int:
        """The most solves a step runs under this rule: 1 (`start`), 2 (`corrected`), LAG_MAX_SOLVES (`fixed-point`)."""
        return {"start": 1, "corrected": 2}.get(self.mode, LAG_MAX_SOLVES)

    def relag_iterations(self, solve: int) -> int | None:
        """Newton iterations of the step's solve number `solve` (2 the first after a re-lag): one for the first
        `fixed-point` ones (the re-lag folded into Newton's loop, up to LAG_ONE_ITERATION_SOLVES), None (to
        convergence) for later ones and for `corrected`."""
        return 1 if self.mode == "fixed-point" and solve <= LAG_ONE_ITERATION_SOLVES else None


class LaggedStep(Protocol):
    """What `solve_lagged` needs of a backend's step: set the step's lagged quantities from lag coordinates and
    velocities (returning them: the normal pressure and the damping gate at the contact points, to compare; the
    gate is the points below the plane at the start or at any of the step's lags so far), run Newton from y0
    (None: the backend's own initial guess) for at most max_iter iterations (None: the backend's limit), and the
    velocity of end-of-step coordinates."""

    def relag(self, y_lag: np.ndarray, v_lag: np.ndarray) -> tuple[np.ndarray, ...]: ...

    def newton(self, y0: np.ndarray | None, max_iter: int | None = None) -> NewtonResult: ...

    def velocity(self, y: np.ndarray) -> np.ndarray: ...


def gate_positions(model: Model, x: np.ndarray, x_start: np.ndarray) -> np.ndarray:
    """Per contact point whichever of its earlier gate position x_start (the step's start, or the lowest of its lags
    so far) and its lagged position x (p, 3) [m] lies lower, (p, 3) [m] (x itself for the start lag, `x is x_start`,
    or without a plane): what the terms take as x_lag, whose signed distance is negative exactly at the
    contact-damping gate."""
    if x is x_start or model.plane_normal is None:
        return x
    lower = signed_distance(x_start, model.plane_normal, model.plane_offset) < signed_distance(
        x, model.plane_normal, model.plane_offset)
    return np.where(lower[:, None], x_start, x)


def lagged_contact(terms: Sequence[Term], model: Model, x: np.ndarray, v: np.ndarray, x_start: np.ndarray
                   ) -> tuple[np.ndarray | None, np.ndarray, np.ndarray]:
    """(fn, gate, x_gate) of a step lagged at contact points x (p, 3) [m] moving at v (p, 3) [m/s], from the earlier
    gate positions x_start (p, 3) [m] (the start's, x itself for the start lag; a re-lag's: the previous lag's
    x_gate): the normal pressure (p,) [Pa] at (x, v) (`lagged_at_start`; None without a term that lags it), the
    contact-damping gate (p,) bool, the points below the plane at x_start or at x (`ContactLag`; all False without a
    plane), and the gate positions (`gate_positions`)."""
    fn = lagged_at_start(terms, model, x, v)
    x_gate = gate_positions(model, x, x_start)
    if model.plane_normal is None:
        return fn, np.zeros(x.shape[0], bool), x_gate
    return fn, damped_points(x_gate, model.plane_normal, model.plane_offset), x_gate


def solve_lagged(step: LaggedStep, lag: ContactLag, y: np.ndarray, v: np.ndarray
                 ) -> tuple[NewtonResult, dict[str, int]]:
    """One step's Newton solve(s) under `lag` (`ContactLag`) from the start coordinates y and velocities v.
    Returns the last solve's result with the iterations, halvings, linear iterations and stalls of every solve
    summed, and the counters `lag_solves` (solves run: a `corrected` or `fixed-point` step; a fixed point's re-lag
    and its Newton iteration count as one) and `lag_unconverged` (a `fixed-point` step: 1 where it stopped at
    LAG_MAX_SOLVES)."""
    key = step.relag(y, v)
    res = step.newton(None)
    if lag.max_solves == 1:
        return res, {}
    solves, unconverged = 1, 1
    while solves < lag.max_solves:
        new_key = step.relag(res.y, step.velocity(res.y))
        if all(_same(a, b) for a, b in zip(key, new_key)):
            unconverged = 0
            break
        key = new_key
        again = step.newton(res.y, lag.relag_iterations(solves + 1))
        res = res.then(again)
        solves += 1
        if again.iters == 1 and again.converged:
            unconverged = 0
            break
    if solves > 1 and lag.relag_iterations(solves) == 1 and not res.converged:
        # the fixed point stopped after a re-lag's one iteration (the cap, or a re-lag that changed nothing): that
        # lag's solve, to convergence
        res = res.then(step.newton(res.y))
    return res, {"lag_solves": solves} | ({"lag_unconverged": unconverged} if lag.mode == "fixed-point" else {})


def _same(a: np.ndarray | None, b: np.ndarray | None) -> bool:
    """Bitwise equality of two lagged arrays (None: none lagged)."""
    return (a is None and b is None) or (a is not None and b is not None and np.array_equal(a, b))

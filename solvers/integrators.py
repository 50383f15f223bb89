"""The time integrators of the implicit solvers, as incremental potentials (docs/physics.md, "Time integration").

An integrator is an object: an `Integrator` subclass with its `name` (what a scenario's `time.integrator` says), its
formal `order`, the `history` it needs (how many states before the step's start) and its `coefficients` for a step
of size h after one of size h_prev, registered by name in `INTEGRATORS` (`register`). Every integrator minimises the
same potential over the end-of-step positions x,

    E(x) = 1/(2 h_eff^2) |x - x_tilde|_M^2 + U(x) + h_eff sum Phi(v(x)),    v(x) = (x - x_bar) / h_eff,

U the elastic, gravity and contact energies, Phi the dissipation potentials (friction, contact damping), and
x_tilde = x_bar + h_eff v_bar; the end-of-step velocity is v(x^{n+1}). They differ in x_bar, v_bar and the effective
step h_eff (`Coefficients`):

- backward Euler: x_bar = x^n, v_bar = v^n, h_eff = h (first order);
- BDF2 after a step h_prev, with w = h / h_prev: x_bar = ((1 + w)^2 x^n - w^2 x^{n-1}) / (1 + 2w), v_bar the same of
  v, h_eff = (1 + w) / (1 + 2w) h (second order for bounded w). At a constant step (w = 1): 4/3 x^n - 1/3 x^{n-1},
  h_eff = 2/3 h. Without a previous state (the first step) the step is backward Euler.

The formulas hold for any coordinates: vertex positions (the full-space solver) or latent coordinates (the reduced
solver, whose decoding is linear). A solver asks its model's integrator for the history it uses
(`Integrator.previous`, from `State.previous`) and for the step's constants (`Integrator.lagged`).

Which previous state a step uses is the integrator's `restart_on_step_change`: True (what every run does) uses the
previous state only where it lies one step h back, so a step that `solvers.simulate.advance` retries as two half
steps after a full one restarts BDF2: the first half step is backward Euler, the second is BDF2 at h/2 on the first,
and the next full step is backward Euler again (a half step that follows a half step keeps BDF2: its history is one
half step back). False uses the previous state at any distance, with the variable-step coefficients: what an
adaptive step size needs (`solvers.simulate`, a scenario with `time.tol`).

Each integrator also estimates the local error of a step it took (`Integrator.local_error`, Milne's device): the
difference between the implicit step's end positions and an explicit predictor through the same history, scaled by
the two formulas' error constants at the step ratio w (docs/physics.md, "Adaptive steps"):

- one-step formula (backward Euler, and BDF2's first step): predictor y^n + h v^n; the error constants of h^2 y^(2)
  are +1/2 (implicit) and -1/2 (predictor), so the estimate is (y^{n+1} - predictor) / 2, of order p = 1;
- BDF2: predictor the quadratic through y^{n-1} and y^n with slope v^n at t^n; the error constants of h^3 y^(3) are
  (1 + w)^2 / (6w (1 + 2w)) (implicit) and -(1 + w) / (6w) (predictor), so the estimate is
  (1 + w) / (2 + 3w) (y^{n+1} - predictor) (2/5 at w = 1), of order p = 2.

The registry lives here, with the classes. The scenario loader, in the bottom layer that may not import solvers
(pyproject.toml's layer contracts), validates `time.integrator` against the built-in names it declares
(`scenarios.spec.BUILTIN_INTEGRATORS`, which a test holds equal to this module's classes) and those an extension's
`register` hands down to it (`scenarios.spec.register_integrator_name`).
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import TYPE_CHECKING, ClassVar

import numpy as np

from frictionbench.scenarios.spec import register_integrator_name

if TYPE_CHECKING:  # a Model (solvers.model) holds its integrator from this module
    from frictionbench.solvers.model import State

#: Relative tolerance on two step sizes for them to count as equal (the times are sums of steps: a step recomputed
#: from them agrees to round-off, while a change of step size is a factor of 2 at least).
_SAME_STEP = 1e-6


def same_step(h: float, h_prev: float) -> bool:
    """Whether steps h and h_prev [s] are one size up to the round-off of times summed from steps."""
    return abs(h_prev - h) <= _SAME_STEP * h


def step_ratio(h: float, h_prev: float) -> float:
    """w = h / h_prev [-], exactly 1 where the two steps are one size (`same_step`)."""
    return 1.0 if same_step(h, h_prev) else h / h_prev


@dataclass(frozen=True)
class Coefficients:
    """One step's integrator coefficients in coordinates y: y_bar = (current y^n + previous y^{n-1}) / denominator
    (the same of the velocities for v_bar) and h_eff = beta h [s]. previous = 0: a one-step formula, which needs no
    y^{n-1} and has current = denominator = 1 (y_bar = y^n, v_bar = v^n)."""

    current: float
    previous: float
    denominator: float
    beta: float


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


#: Backward Euler's coefficients, also every multistep integrator's first step: y_bar = y^n, h_eff = h.
ONE_STEP = Coefficients(1.0, 0.0, 1.0, 1.0)


@dataclass(frozen=True)
class LocalError:
    """A step's estimated local error: `error` (shape of y, in y's units) and the `order` p of the formula the step
    used (its local error is O(h^(p+1)): a step-size controller's exponent is 1 / (p + 1))."""

    error: np.ndarray
    order: int


def one_step_error(y_new: np.ndarray, y: np.ndarray, v: np.ndarray, h: float) -> LocalError:
    """The local error of a one-step (backward-Euler) step of h [s] from (y, v) to y_new: (y_new - y - h v) / 2
    (the implicit formula's error +h^2 y^(2) / 2 against the explicit Taylor predictor's -h^2 y^(2) / 2), order 1."""
    return LocalError(0.5 * (y_new - y - h * v), 1)


@dataclass(frozen=True)
class Integrator:
    """A time integrator (module docstring): `name` (a scenario's `time.integrator`), formal `order` of accuracy,
    `history` (how many states before the step's start it uses) and, per instance, whether a change of step size
    restarts it (`restart_on_step_change`)."""

    name: ClassVar[str]
    order: ClassVar[int]
    history: ClassVar[int]

    restart_on_step_change: bool = True

    def coefficients(self, h: float, h_prev: float | None) -> Coefficients:
        """The coefficients of a step of h [s] after a step of h_prev [s] (None: no previous state); this default
        is the one-step formula (y_bar = y^n, h_eff = h) of an integrator without history."""
        return ONE_STEP

    def previous(self, state: State, h: float) -> State | None:
        """The state before `state` that a step of h [s] from it uses (`state.previous`), or None: none kept, none
        needed (no history), or (with `restart_on_step_change`) not one step h back."""
        prev = state.previous
        if self.history == 0 or prev is None:
            return None
        if self.restart_on_step_change and not same_step(h, state.t - prev.t):
            return None
        return prev

    def lagged(self, y: np.ndarray, v: np.ndarray, h: float,
               previous: tuple[np.ndarray, np.ndarray, float] | None = None) -> Lagged:
        """The step's constants from the start-of-step coordinates y and velocity v, a step of h [s], and
        `previous` = (y, v, step [s] that led to the start) of the state before (None: none)."""
        c = self.coefficients(h, None if previous is None else previous[2])
        if c.previous == 0.0:
            return Lagged(y, v, c.beta * h)
        y_prev, v_prev, _ = previous
        return Lagged((c.current * y + c.previous * y_prev) / c.denominator,
                      (c.current * v + c.previous * v_prev) / c.denominator, c.beta * h)

    def local_error(self, y_new: np.ndarray, y: np.ndarray, v: np.ndarray, h: float,
                    previous: tuple[np.ndarray, np.ndarray, float] | None = None) -> LocalError:
        """The estimated local error of the step of h [s] from (y, v) that ended at y_new, with `previous` as
        `lagged` takes it (the history the step used); this default is the one-step formula's (`one_step_error`)."""
        return one_step_error(y_new, y, v, h)


#: The integrators by name (`register`).
INTEGRATORS: dict[str, type[Integrator]] = {}


def register(cls: type[Integrator]) -> type[Integrator]:
    """Class decorator: make `cls` the integrator of its `name` (here and for the scenario loader)."""
    INTEGRATORS[cls.name] = cls
    register_integrator_name(cls.name)
    return cls


def get_integrator(name: str, variable_step: bool = False) -> Integrator:
    """The integrator a scenario's `time.integrator = name` asks for: restarting on a change of step size, or with
    `variable_step` (an adaptive run's) keeping its history with the variable-step coefficients; a ValueError naming
    the field and the known names for any other."""
    if name not in INTEGRATORS:
        raise ValueError(f"time.integrator = {name!r}: expected one of {list(INTEGRATORS)}")
    return INTEGRATORS[name](restart_on_step_change=not variable_step)


@register
class BackwardEuler(Integrator):
    """Backward (implicit) Euler: first order, no history (the one-step coefficients), the paper's integrator."""

    name = "backward-euler"
    order = 1
    history = 0


@register
class BDF2(Integrator):
    """The second-order backward differentiation formula in its variable-step form, started by backward Euler."""

    name = "bdf2"
    order = 2
    history = 1

    def coefficients(self, h: float, h_prev: float | None) -> Coefficients:
        """With w = h / h_prev: ((1 + w)^2, -w^2) / (1 + 2w) and beta = (1 + w) / (1 + 2w); w is exactly 1 where
        the two steps are one size (`same_step`), so a constant step computes (4 y^n - y^{n-1}) / 3 and 2/3 h.
        Backward Euler without a previous step."""
        if h_prev is None:
            return ONE_STEP
        w = step_ratio(h, h_prev)
        return Coefficients((1.0 + w) ** 2, -(w * w), 1.0 + 2.0 * w, (1.0 + w) / (1.0 + 2.0 * w))

    def local_error(self, y_new: np.ndarray, y: np.ndarray, v: np.ndarray, h: float,
                    previous: tuple[np.ndarray, np.ndarray, float] | None = None) -> LocalError:
        """Milne's estimate (module docstring) with w = h / h_prev (`step_ratio`): the predictor
        y^n + h v^n + (h / h_prev)^2 (y^{n-1} - y^n + h_prev v^n), the quadratic through y^{n-1} and y^n with slope
        v^n at t^n, and the estimate (1 + w) / (2 + 3w) (y_new - predictor), order 2. Without `previous` the step
        was backward Euler: its estimate (`one_step_error`)."""
        if previous is None:
            return one_step_error(y_new, y, v, h)
        y_prev, _, h_prev = previous
        w = step_ratio(h, h_prev)
        predictor = y + h * v + (w * w) * (y_prev - y + (h / w) * v)
        return LocalError((1.0 + w) / (2.0 + 3.0 * w) * (y_new - predictor), 2)

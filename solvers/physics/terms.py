"""Physics terms of the incremental potential as objects: one `Term` per effect, each in its own module of
solvers/physics (inertia and gravity in inertia.py, elasticity in material.py, Kelvin-Voigt material damping in
viscosity.py, penalty contact, barrier contact and contact damping in contact.py, friction in friction.py).

A term holds its pure numpy reference (energy [J], gradient (n, 3) [N], PSD-projected Hessian (3n, 3n) [N/m] over
the vertex positions x (n, 3) [m]) and declares what it needs from a step through two hooks, both on the contact
points: `begin_step` fixes what the term lags from the start of the step (friction: the normal pressure), and
`max_step` caps a Newton step (the barrier law: no point may cross the plane; `max_feasible_step` is the one rule
both solvers apply).

The physics knows no backend: a term declares its kind, and each backend derives its evaluation from that
declaration alone (`solvers.full.terms.launcher`, `solvers.reduced.terms.body_evaluation` and `point_launch`), with
no table of term classes to edit. The kinds:
- `VertexTerm`: sum_i m_i (|x_i - y_i|^2 / (2 tau^2) - a . x_i), declared by its target y (`target`), tau^2
  (`tau2`) and a (`acceleration`): inertia, gravity. Both backends evaluate it in closed form.
- `DensityTerm`: sum_e V_e psi(F_e) over the tets, declared with the names of its warp kernels (`TetKernels`):
  elasticity, viscosity. Without kernels it runs from its numpy reference.
- `PointTerm`: a law per contact point, pure maths at any sample points (`at_points`), optionally with the name of
  its warp kernel (`kernel`, its scalar arguments `kernel_parameters`): contact, damping, friction.
- any other `BodyTerm`: its numpy reference alone (exact in both backends, but a full-mesh evaluation per call).
A kernel is named, not imported (solvers/physics sits below the kernels, pyproject.toml): a bare name is one of
the backend's kernel module (`solvers.kernels`; a cubature kernel, `solvers.reduced.kernels`), "module:name" any
other, e.g. the term's own module. A backend passes a kernel its arguments by their names: its own arrays and step
constants (x, x_hat, tets, vol, h, mode, ...) and the term's `kernel_parameters`.
`applies(model)` says whether a scene has a term; a solver takes `terms_of(model)` and loops over them. A term is
a class registered here by `@register` in a module of solvers/physics (every module of the package is imported;
`_MODULES` gives the summation order of the built-in ones).
"""

from __future__ import annotations

import importlib
import pkgutil
from abc import ABC, abstractmethod
from collections.abc import Sequence
from dataclasses import dataclass
from typing import ClassVar

import numpy as np
import scipy.sparse as sp

from frictionbench.solvers.model import Model


#: Energy [J], gradient and Hessian of a term (None where not asked for).
Evaluation = tuple[float, np.ndarray | None, np.ndarray | None]

#: The modules that define terms, in the order their terms are summed.
_MODULES = tuple(f"{__package__}.{name}" for name in ("inertia", "material", "viscosity", "contact", "friction"))
_TERMS: list["Term"] = []


@dataclass(frozen=True)
class StepData:
    """One step's constants (`solvers.integrators`): the inertial target x_hat = x_tilde = x_bar + h_eff v_bar (n, 3)
    [m], the start-of-step positions x_lag = x^n (n, 3) [m], the time step h [s], the lagged normal pressure fn (p,)
    [Pa] at the model's contact points (None without friction), `inertia` (False: static equilibrium, no inertial
    term), and the integrator's x_bar (n, 3) [m] and effective step h_eff [s]: the inertial term is
    1/(2 h_eff^2) |x - x_hat|_M^2 and every dissipative term uses the velocity v(x) = (x - x_bar) / h_eff. Backward
    Euler (the defaults, None): x_bar = x_lag, h_eff = h."""

    x_hat: np.ndarray
    x_lag: np.ndarray
    h: float
    fn: np.ndarray | None = None
    inertia: bool = True
    x_bar: np.ndarray | None = None
    h_eff: float | None = None

    def __post_init__(self) -> None:
        if self.x_bar is None:
            object.__setattr__(self, "x_bar", self.x_lag)
        if self.h_eff is None:
            object.__setattr__(self, "h_eff", self.h)


class Term(ABC):
    """One term of the incremental potential; see the module docstring."""

    name: ClassVar[str] = ""

    @abstractmethod
    def applies(self, model: Model) -> bool:
        """Whether `model`'s scene contains this term."""

    @abstractmethod
    def energy(self, model: Model, step: StepData, x: np.ndarray) -> float:
        """The term's energy at x [J] (numpy reference)."""

    @abstractmethod
    def gradient(self, model: Model, step: StepData, x: np.ndarray) -> np.ndarray:
        """Its gradient (n, 3) [N] (numpy reference)."""

    @abstractmethod
    def hessian(self, model: Model, step: StepData, x: np.ndarray) -> sp.csr_matrix:
        """Its PSD-projected Hessian (3n, 3n) [N/m] (numpy reference)."""

    def begin_step(self, model: Model, x: np.ndarray, v: np.ndarray) -> np.ndarray | None:
        """What the term lags from the start of a step, given the contact points' positions x (p, 3) [m] and
        velocities v (p, 3) [m/s] there: friction's normal pressure (p,) [Pa] (`StepData.fn`); None (the default):
        nothing."""
        return None

    def max_step(self, model: Model, x: np.ndarray, dx: np.ndarray) -> float:
        """The largest alpha <= 1 for which the contact points x + alpha dx (p, 3) [m] stay admissible; 1 (the
        default): the term does not cap a step."""
        return 1.0

    def lag_reach(self, model: Model) -> float:
        """The signed distance to the plane [m] from which on what the term lags is zero at a contact point whose
        positions at the start of the step and where the step lags contact both lie at least that far: its
        `begin_step` value and, for a point term, its `lagged_support`. -inf, it lags nothing (the default for a
        term that overrides neither); +inf (the default for any other), at any distance. It lets a backend compute
        the lag at the points below it alone (`solvers.reduced.solver`)."""
        lags = type(self).begin_step is not Term.begin_step or (
            isinstance(self, PointTerm) and type(self).lagged_support is not PointTerm.lagged_support)
        return np.inf if lags else -np.inf


class BodyTerm(Term):
    """A term over the whole body (inertia, gravity, elasticity, viscosity): a `VertexTerm`, a `DensityTerm`, or
    else evaluated by every backend from its numpy reference."""


class VertexTerm(BodyTerm):
    """sum_i m_i (|x_i - y_i|^2 / (2 tau^2) - a . x_i) [J] over the vertices with lumped masses m_i [kg]: a spring
    of the mass to the step's positions y (`target`) and a uniform acceleration a (3,) [m/s^2]. Inertia:
    y = x_hat, tau = h_eff; gravity: tau^2 = inf (no spring), a = g."""

    #: y: which of the step's positions (`StepData`): "x_hat", "x_lag" or "x_bar".
    target: ClassVar[str] = "x_hat"

    @abstractmethod
    def tau2(self, model: Model, h: float, inertia: bool) -> float:
        """tau^2 [s^2] at the effective step h [s] (inertia False: static equilibrium); inf: no spring."""

    def acceleration(self, model: Model) -> np.ndarray:
        """a (3,) [m/s^2]; zero by default."""
        return np.zeros(3)


@dataclass(frozen=True)
class TetKernels:
    """The names of a `DensityTerm`'s warp kernels (module docstring: a bare name in `solvers.kernels`, else
    "module:name"), one thread per tet: `energy` adds sum_e V_e psi_e into `energy`, `gradient` the forces into
    `grad`, `hessian` adds into the 16 blocks (3x3) of tet e from `blocks[16 e]` (zeroed before), or assigns them
    (`hessian_assigns`).
    `at_bar` (None: none), a kernel (x, tets, Dm_inv, OUT) run once a step at x = x_bar that writes a per-tet 3x3
    array passed to the other kernels under OUT's name (viscosity: the Green strain E_bar). `cubature` (None: none;
    a bare name in `solvers.reduced.kernels`), the reduced backend's kernel at the cubature tets' deformation
    gradients F (and F_bar, those at x_bar, if it takes them), with a packed output row per tet [psi, vec P,
    L (`rows` x 9)], L^T L the density's projected Hessian in F (`solvers.reduced.kernels.evaluate`)."""

    energy: str
    gradient: str
    hessian: str
    at_bar: str | None = None
    cubature: str | None = None
    rows: int = 9
    #: The Hessian kernel assigns every block of its tets (rather than adding into them): the blocks need no zeroing
    #: before it (viscosity's; elasticity's adds its modes one by one).
    hessian_assigns: bool = False


class DensityTerm(BodyTerm):
    """sum_e V_e psi(F_e) [J], an energy density per tet of its deformation gradient F_e (and of the step's, as
    viscosity's rate: `TetKernels.at_bar`), evaluated by the kernels it names (`kernels`; None: its numpy
    reference)."""

    kernels: ClassVar[TetKernels | None] = None
    #: A rate term: absent in static equilibrium (`StepData.inertia` False), as viscosity.
    rate: ClassVar[bool] = False

    def kernel_parameters(self, model: Model, h: float) -> dict[str, float]:
        """The kernels' scalar arguments by name at the effective step h [s] (each kernel takes those it names)."""
        return {}


class PointTerm(Term):
    """A term per contact point (contact, damping, friction): evaluated at any sample points, by `at_points` or by
    the warp kernel it names (`kernel`, module docstring; None: none). Such a kernel runs one thread per point p of
    `points` (its vertex i = points[p]) and adds, by `mode` (0: energy; 1: gradient and Hessian; 2: all three),
    into `energy`, `grad[i]` and the diagonal block `values[diag[i]]`; it may take the vertex arrays x, x_lag,
    x_bar, the per-point area and lagged pressure fn, the plane's `normal`, the effective step h, and the term's
    `kernel_parameters`."""

    kernel: ClassVar[str | None] = None

    def kernel_parameters(self, model: Model) -> dict[str, float]:
        """The kernel's scalar arguments by name, constant over a run."""
        return {}

    @abstractmethod
    def at_points(self, model: Model, x: np.ndarray, x_lag: np.ndarray, x_bar: np.ndarray, area: np.ndarray,
                  fn: np.ndarray | None, h: float, order: int) -> Evaluation:
        """Energy [J], gradient (p, 3) [N] (order >= 1) and Hessian blocks (p, 3, 3) [N/m] (order 2) at points x
        (p, 3) [m] with start-of-step positions x_lag and the integrator's x_bar (p, 3) [m] (velocity
        (x - x_bar) / h), area weights area (p,) [m^2], lagged pressure fn (p,), h the effective step h_eff [s]."""

    def reach(self, model: Model) -> float:
        """The signed distance to the plane [m] below which the term can be nonzero at a point through the point's
        own position: -inf, never; +inf (the default), at any distance. With `lagged_support` it bounds the term's
        support, which lets a backend evaluate it at the candidate points alone (`solvers.reduced.solver`)."""
        return np.inf

    def lagged_support(self, model: Model, x_lag: np.ndarray, fn: np.ndarray | None) -> np.ndarray | None:
        """The points (p,) bool at which the term can be nonzero whatever their position, from what the step
        lags: the start-of-step (damping-gate) positions x_lag (p, 3) [m] and the normal pressure fn (p,) [Pa];
        None (the default): none. At a point neither below `reach` nor in this set, the term's energy, gradient
        and Hessian are exactly zero."""
        return None

    def _at(self, model: Model, step: StepData, x: np.ndarray, order: int) -> Evaluation:
        p = model.points
        return self.at_points(model, x[p], step.x_lag[p], step.x_bar[p], model.area, step.fn, step.h_eff, order)

    def energy(self, model: Model, step: StepData, x: np.ndarray) -> float:
        return self._at(model, step, x, 0)[0]

    def gradient(self, model: Model, step: StepData, x: np.ndarray) -> np.ndarray:
        return scatter_points(model, self._at(model, step, x, 1)[1])

    def hessian(self, model: Model, step: StepData, x: np.ndarray) -> sp.csr_matrix:
        return point_blocks(model, self._at(model, step, x, 2)[2])


def register(term_class: type[Term]) -> type[Term]:
    """Register a term (class decorator)."""
    _TERMS.append(term_class())
    return term_class


def all_terms() -> list[Term]:
    """Every registered term, in summation order: by module in the order of `_MODULES` (terms of the package's
    other modules, and of modules outside it, last), then in registration order within a module."""
    for info in pkgutil.iter_modules(importlib.import_module(__package__).__path__):
        importlib.import_module(f"{__package__}.{info.name}")
    rank = {m: k for k, m in enumerate(_MODULES)}
    return sorted(_TERMS, key=lambda t: rank.get(type(t).__module__, len(_MODULES)))


def terms_of(model: Model) -> list[Term]:
    """The terms `model`'s scene contains, in summation order."""
    return [t for t in all_terms() if t.applies(model)]


def lagged_at_start(terms: Sequence[Term], model: Model, x: np.ndarray, v: np.ndarray) -> np.ndarray | None:
    """The step's lagged normal pressure (p,) [Pa] (`StepData.fn`) from the terms' `begin_step` at the contact
    points' start-of-step positions x and velocities v (p, 3); None where no term lags it."""
    fn = None
    for term in terms:
        lag = term.begin_step(model, x, v)
        if lag is not None:
            fn = lag
    return fn


def step_capping(terms: Sequence[Term]) -> list[Term]:
    """The terms that cap a Newton step (those that override `Term.max_step`)."""
    return [t for t in terms if type(t).max_step is not Term.max_step]


def max_feasible_step(terms: Sequence[Term], model: Model, x: np.ndarray, dx: np.ndarray) -> float:
    """The one feasible-step rule of every solver: the largest alpha <= 1 that every term allows for the contact
    points x + alpha dx (p, 3) [m] (`Term.max_step`)."""
    alpha = 1.0
    for term in terms:
        alpha = min(alpha, term.max_step(model, x, dx))
    return alpha


# ----- helpers of the numpy references ---------------------------------------------------------------------------
def scatter_points(model: Model, values: np.ndarray) -> np.ndarray:
    """Per-contact-point vectors (p, 3) added onto the vertices, (n, 3)."""
    out = np.zeros((model.n, 3))
    np.add.at(out, model.points, values)
    return out


def element_blocks(model: Model, blocks: np.ndarray) -> sp.csr_matrix:
    """Per-tet Hessians (m, 12, 12), vertex-major (3 a + alpha over the tet's vertices a), summed into a (3n, 3n)
    matrix."""
    idx = (3 * model.tets[:, :, None] + np.arange(3)).reshape(-1, 12)
    rows = np.repeat(idx, 12, axis=1).ravel()
    cols = np.tile(idx, (1, 12)).ravel()
    return sp.csr_matrix((blocks.ravel(), (rows, cols)), shape=(3 * model.n, 3 * model.n))


def point_blocks(model: Model, blocks: np.ndarray) -> sp.csr_matrix:
    """Per-contact-point 3x3 blocks (p, 3, 3) on the diagonal of a (3n, 3n) matrix."""
    idx = 3 * model.points[:, None] + np.arange(3)
    rows = np.repeat(idx, 3, axis=1).ravel()
    cols = np.tile(idx, (1, 3)).ravel()
    return sp.csr_matrix((blocks.ravel(), (rows, cols)), shape=(3 * model.n, 3 * model.n))


def reference_energy(model: Model, step: StepData, x: np.ndarray) -> float:
    """E(x) [J]: the sum of the model's terms' numpy references."""
    return sum(t.energy(model, step, x) for t in terms_of(model))


def reference_gradient(model: Model, step: StepData, x: np.ndarray) -> np.ndarray:
    """dE/dx (n, 3) [N] from the numpy references."""
    return sum(t.gradient(model, step, x) for t in terms_of(model))


def reference_hessian(model: Model, step: StepData, x: np.ndarray) -> sp.csr_matrix:
    """The PSD-projected Hessian (3n, 3n) [N/m] from the numpy references."""
    return sum(t.hessian(model, step, x) for t in terms_of(model))

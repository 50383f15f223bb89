"""Physics terms of the incremental potential as objects: one `Term` per effect, each in its own module of
solvers/physics (inertia and gravity in inertia.py, elasticity in material.py, Kelvin-Voigt material damping in
viscosity.py, penalty contact, barrier contact and contact damping in contact.py, friction in friction.py).

A term holds its pure numpy reference (energy [J], gradient (n, 3) [N], PSD-projected Hessian (3n, 3n) [N/m] over
the vertex positions x (n, 3) [m]) and declares what it needs from a step through two hooks, both on the contact
points: `begin_step` fixes what the term lags from the start of the step (friction: the normal pressure), and
`max_step` caps a Newton step (the barrier law: no point may cross the plane; `max_feasible_step` is the one rule
both solvers apply). A `PointTerm` (contact, damping, friction) is pure maths at any sample points (`at_points`).
The physics knows no backend: each backend implements the evaluation of the terms in its own package, in a table
keyed by the term's class (`solvers.full.terms` with the warp kernels, `solvers.reduced.terms` with the reduced
evaluations of the body terms, its default the term's numpy reference; the reduced solver sums the point terms'
`at_points` itself).
`applies(model)` says whether a scene has a term; a solver takes `terms_of(model)` and loops over them. A term is
a class registered here by `@register` in a module of solvers/physics (every module of the package is imported;
`_MODULES` gives the summation order of the built-in ones).
"""

from __future__ import annotations

import importlib
import pkgutil
from abc import ABC, abstractmethod
from collections.abc import Callable, Sequence
from dataclasses import dataclass, field
from typing import ClassVar, Generic, TypeVar

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
    """A term over the whole body (inertia, gravity, elasticity, viscosity): each backend evaluates it by its own
    table (`solvers.full.terms`, `solvers.reduced.terms`: there by default from its numpy
    reference)."""


class PointTerm(Term):
    """A term per contact point (contact, damping, friction): evaluated at any sample points."""

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


#: A backend's evaluation class of a term (the values of a `TermTable`).
Impl = TypeVar("Impl")


@dataclass
class TermTable(Generic[Impl]):
    """A backend's evaluation class for each term class (`classes`), registered by `@table.register(TermClass)`;
    `what` names it in errors (e.g. "full-space launcher"); `default`: the class of the terms without one (None:
    such terms are refused)."""

    what: str
    classes: dict[type[Term], type[Impl]] = field(default_factory=dict)
    default: type[Impl] | None = None

    def register(self, *term_classes: type[Term]) -> Callable[[type[Impl]], type[Impl]]:
        """Register an evaluation class for `term_classes` (class decorator)."""
        def add(evaluation: type[Impl]) -> type[Impl]:
            for term_class in term_classes:
                self.classes[term_class] = evaluation
            return evaluation
        return add

    def build(self, backend: object, terms: Sequence[Term]) -> list[Impl]:
        """An evaluation `cls(backend, term)` of each of `terms`, in their order (`default` for the terms without a
        class of their own); ValueError naming the terms without one where there is no default."""
        missing = [t.name for t in terms if type(t) not in self.classes and self.default is None]
        if missing:
            raise ValueError(f"terms {missing} have no {self.what}")
        return [self.classes.get(type(t), self.default)(backend, t) for t in terms]


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

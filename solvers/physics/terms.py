"""Physics terms of the incremental potential as objects: one `Term` per effect, each in its own module of
solvers/physics (inertia and gravity in inertia.py, elasticity in material.py, Kelvin-Voigt material damping in
viscosity.py, penalty contact, barrier contact and contact damping in contact.py, friction in friction.py).

A term holds its pure numpy reference (energy [J], gradient (n, 3) [N], PSD-projected Hessian (3n, 3n) [N/m] over
the vertex positions x (n, 3) [m]) and its evaluation for each backend: `launch` adds it with the full-space warp
kernels into a `solvers.full.solver.FullSpaceSolver`'s buffers; for the reduced solver
(`solvers.licrom.reduced.ReducedSolver`), a body term gives its energy, gradient and Hessian in the latent
coordinates (`reduced`) and its gradient at the projected-gradient scheme's sample vertices (`sample_gradient`),
while a `PointTerm` (contact, damping, friction) is evaluated at contact sample points (`at_points`), which the
reduced solver sums and projects once. `applies(model)` says whether a scene has it; a solver takes
`terms_of(model)` and loops over them. Adding a term is one module that registers its class here
(`register`) and is listed in `_MODULES`, plus its tests.
"""

from __future__ import annotations

import importlib
from abc import ABC, abstractmethod
from dataclasses import dataclass
from typing import TYPE_CHECKING, ClassVar

import numpy as np
import scipy.sparse as sp

if TYPE_CHECKING:
    import warp as wp

    from solvers.full.solver import FullSpaceSolver
    from solvers.licrom.reduced import ReducedSolver, ReducedStep
    from solvers.model import Model


#: Energy [J], gradient and Hessian of a term (None where not asked for).
Evaluation = tuple[float, np.ndarray | None, np.ndarray | None]

#: The modules that define terms, in the order their terms are summed.
_MODULES = ("solvers.physics.inertia", "solvers.physics.material", "solvers.physics.viscosity",
            "solvers.physics.contact", "solvers.physics.friction")
_TERMS: list["Term"] = []


@dataclass(frozen=True)
class StepData:
    """One step's constants (`solvers.integrators`): the inertial target x_hat = x_tilde = x_bar + h_eff v_bar (n, 3)
    [m], the start-of-step positions x_prev = x^n (n, 3) [m], the time step h [s], the lagged normal pressure fn (p,)
    [Pa] at the model's contact points (None without friction), `inertia` (False: static equilibrium, no inertial
    term), and the integrator's x_bar (n, 3) [m] and effective step h_eff [s]: the inertial term is
    1/(2 h_eff^2) |x - x_hat|_M^2 and every dissipative term uses the velocity v(x) = (x - x_bar) / h_eff. Backward
    Euler (the defaults, None): x_bar = x_prev, h_eff = h."""

    x_hat: np.ndarray
    x_prev: np.ndarray
    h: float
    fn: np.ndarray | None = None
    inertia: bool = True
    x_bar: np.ndarray | None = None
    h_eff: float | None = None

    def __post_init__(self) -> None:
        if self.x_bar is None:
            object.__setattr__(self, "x_bar", self.x_prev)
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

    @abstractmethod
    def launch(self, solver: FullSpaceSolver, x: wp.array, h: float, mode: int, inertia: bool) -> None:
        """Add the term at x with the full-space kernels: mode 0 its energy into solver.energy_buf, mode 1 its
        gradient into solver.grad and Hessian blocks into solver.values. h is the step's effective step h_eff [s]
        (the solver's arrays x_hat, x_prev and x_bar hold the step's other constants)."""


class BodyTerm(Term):
    """A term over the whole body (inertia, gravity, elasticity): its reduced evaluations."""

    @abstractmethod
    def reduced(self, rs: ReducedSolver, q: np.ndarray, st: ReducedStep, order: int) -> Evaluation:
        """Energy [J], gradient (r,) [N] (order >= 1) and Hessian (r, r) [N/m] (order 2, None where it is zero)
        at latent coordinates q (r,), with the reduced step's constants st."""

    @abstractmethod
    def sample_gradient(self, rs: ReducedSolver, q: np.ndarray, st: ReducedStep, u: np.ndarray,
                        u_hat: np.ndarray) -> np.ndarray:
        """The full-space gradient (k, 3) [N] at the projected-gradient scheme's sample vertices, whose
        displacements are u and u_hat (k, 3) [m] at q and q_hat."""


class PointTerm(Term):
    """A term per contact point (contact, damping, friction): evaluated at any sample points."""

    @abstractmethod
    def at_points(self, model: Model, x: np.ndarray, x_prev: np.ndarray, x_bar: np.ndarray, area: np.ndarray,
                  fn: np.ndarray | None, h: float, order: int) -> Evaluation:
        """Energy [J], gradient (p, 3) [N] (order >= 1) and Hessian blocks (p, 3, 3) [N/m] (order 2) at points x
        (p, 3) [m] with start-of-step positions x_prev and the integrator's x_bar (p, 3) [m] (velocity
        (x - x_bar) / h), area weights area (p,) [m^2], lagged pressure fn (p,), h the effective step h_eff [s]."""

    def _at(self, model: Model, step: StepData, x: np.ndarray, order: int) -> Evaluation:
        p = model.points
        return self.at_points(model, x[p], step.x_prev[p], step.x_bar[p], model.area, step.fn, step.h_eff, order)

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
    """Every registered term, in summation order: by module in the order of `_MODULES` (terms of other modules
    last), then in registration order within a module."""
    for module in _MODULES:
        importlib.import_module(module)
    rank = {m: k for k, m in enumerate(_MODULES)}
    return sorted(_TERMS, key=lambda t: rank.get(type(t).__module__, len(_MODULES)))


def terms_of(model: Model) -> list[Term]:
    """The terms `model`'s scene contains, in summation order."""
    return [t for t in all_terms() if t.applies(model)]


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

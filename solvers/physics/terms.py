"""Physics terms of the incremental potential as objects: one `Term` per effect, each in its own module of
solvers/physics (inertia and gravity in inertia.py, elasticity in material.py, penalty contact, barrier contact and
contact damping in contact.py, friction in friction.py).

A term holds its pure numpy reference (energy [J], gradient (n, 3) [N], PSD-projected Hessian (3n, 3n) [N/m] over
the vertex positions x (n, 3) [m]) and its evaluation for each backend: `launch` adds it with the full-space warp
kernels into a `solvers.full.solver.FullSpaceSolver`'s buffers. `applies(model)` says whether a scene has it; a
solver takes `terms_of(model)` and loops over them. Adding a term is one module that registers its class here
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
    from solvers.model import Model

#: The modules that define terms, in the order their terms are summed.
_MODULES = ("solvers.physics.inertia", "solvers.physics.material", "solvers.physics.contact",
            "solvers.physics.friction")
_TERMS: list["Term"] = []


@dataclass(frozen=True)
class StepData:
    """One step's constants: x_hat = x^n + h v^n (n, 3) [m], x_prev = x^n (n, 3) [m], the time step h [s], the
    lagged normal pressure fn (p,) [Pa] at the model's contact points (None without friction), and `inertia`
    (False: static equilibrium, no inertial term)."""

    x_hat: np.ndarray
    x_prev: np.ndarray
    h: float
    fn: np.ndarray | None = None
    inertia: bool = True


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
        gradient into solver.grad and Hessian blocks into solver.values."""


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

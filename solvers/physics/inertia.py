"""Inertia and gravity: lumped mass, the inertial term of the incremental potential (backward Euler's, or BDF2's with
its target x_tilde and effective step h_eff, `solvers.integrators`) and the potential of uniform gravity, with their
`Term` objects."""

from __future__ import annotations

import numpy as np
import scipy.sparse as sp

from frictionbench.solvers.model import Model
from frictionbench.solvers.physics.terms import StepData, VertexTerm, register


def lumped_mass(vol: np.ndarray, tets: np.ndarray, n_vertices: int, density: float) -> np.ndarray:
    """Vertex masses (n,) [kg]: each tet gives rho V_e / 4 to each of its 4 vertices."""
    m = np.zeros(n_vertices)
    np.add.at(m, tets, np.repeat((density * vol / 4.0)[:, None], 4, axis=1))
    return m


def inertia_energy(x: np.ndarray, x_hat: np.ndarray, mass: np.ndarray, h: float) -> float:
    """1/(2 h^2) |x - x_hat|_M^2 [J] with x_hat = x^n + h v^n, positions (n, 3), mass (n,)."""
    d = x - x_hat
    return float(0.5 / h**2 * np.einsum("i,ij,ij->", mass, d, d))


def inertia_gradient(x: np.ndarray, x_hat: np.ndarray, mass: np.ndarray, h: float) -> np.ndarray:
    """M (x - x_hat) / h^2, (n, 3) [N]."""
    return mass[:, None] * (x - x_hat) / h**2


def gravity_energy(x: np.ndarray, mass: np.ndarray, gravity: np.ndarray) -> float:
    """Potential of a uniform field: -sum_i m_i g . x_i [J]; gravity (3,) [m/s^2]."""
    return float(-mass @ (x @ gravity))


def gravity_gradient(mass: np.ndarray, gravity: np.ndarray) -> np.ndarray:
    """-m_i g (n, 3) [N], constant."""
    return -mass[:, None] * gravity[None, :]


@register
class Inertia(VertexTerm):
    """1/(2 h_eff^2) |x - x_hat|_M^2 (absent in static equilibrium, StepData.inertia = False)."""

    name = "inertia"
    target = "x_hat"

    def tau2(self, model: Model, h: float, inertia: bool) -> float:
        """h_eff^2; inf (no term) in static equilibrium."""
        return h**2 if inertia else np.inf

    def applies(self, model: Model) -> bool:
        return model.has("inertia")

    def energy(self, model: Model, step: StepData, x: np.ndarray) -> float:
        return inertia_energy(x, step.x_hat, model.mass, step.h_eff) if step.inertia else 0.0

    def gradient(self, model: Model, step: StepData, x: np.ndarray) -> np.ndarray:
        return inertia_gradient(x, step.x_hat, model.mass, step.h_eff) if step.inertia else np.zeros_like(x)

    def hessian(self, model: Model, step: StepData, x: np.ndarray) -> sp.csr_matrix:
        return sp.diags(np.repeat(model.mass, 3) / step.h_eff**2 * step.inertia).tocsr()




@register
class Gravity(VertexTerm):
    """-sum_i m_i g . x_i, a uniform field."""

    name = "gravity"

    def tau2(self, model: Model, h: float, inertia: bool) -> float:
        """No spring: inf."""
        return np.inf

    def acceleration(self, model: Model) -> np.ndarray:
        """g."""
        return model.gravity

    def applies(self, model: Model) -> bool:
        return model.has("gravity")

    def energy(self, model: Model, step: StepData, x: np.ndarray) -> float:
        return gravity_energy(x, model.mass, model.gravity)

    def gradient(self, model: Model, step: StepData, x: np.ndarray) -> np.ndarray:
        return gravity_gradient(model.mass, model.gravity)

    def hessian(self, model: Model, step: StepData, x: np.ndarray) -> sp.csr_matrix:
        return sp.csr_matrix((3 * model.n, 3 * model.n))



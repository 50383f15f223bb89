"""Inertia and gravity: lumped mass, the inertial term of the incremental potential (backward Euler's, or BDF2's with
its target x_tilde and effective step h_eff, `solvers.integrators`) and the potential of uniform gravity, with their
`Term` objects."""

from __future__ import annotations

from typing import TYPE_CHECKING

import numpy as np
import scipy.sparse as sp

from solvers.physics.terms import BodyTerm, Evaluation, StepData, register

if TYPE_CHECKING:
    import warp as wp

    from solvers.full.solver import FullSpaceSolver
    from solvers.licrom.reduced import ReducedSolver, ReducedStep
    from solvers.model import Model


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
class Inertia(BodyTerm):
    """1/(2 h_eff^2) |x - x_hat|_M^2 (absent in static equilibrium, StepData.inertia = False)."""

    name = "inertia"

    def applies(self, model: Model) -> bool:
        return model.has("inertia")

    def energy(self, model: Model, step: StepData, x: np.ndarray) -> float:
        return inertia_energy(x, step.x_hat, model.mass, step.h_eff) if step.inertia else 0.0

    def gradient(self, model: Model, step: StepData, x: np.ndarray) -> np.ndarray:
        return inertia_gradient(x, step.x_hat, model.mass, step.h_eff) if step.inertia else np.zeros_like(x)

    def hessian(self, model: Model, step: StepData, x: np.ndarray) -> sp.csr_matrix:
        return sp.diags(np.repeat(model.mass, 3) / step.h_eff**2 * step.inertia).tocsr()

    def launch(self, solver: FullSpaceSolver, x: wp.array, h: float, mode: int, inertia: bool) -> None:
        import warp as wp

        from solvers.full import kernels as K

        wp.launch(K.inertia_gravity_kernel, solver.model.n, device=solver.device, inputs=[
            x, solver.x_hat, solver.mass, 1.0 / h**2 if inertia else 0.0, wp.vec3d(0.0, 0.0, 0.0), solver.diag,
            solver.grad, solver.values, solver.energy_buf, mode])

    def reduced(self, rs: ReducedSolver, q: np.ndarray, st: ReducedStep, order: int) -> Evaluation:
        """1/(2 h_eff^2) (q - q_hat)^T M_r (q - q_hat), M_r = W^T M W."""
        M_r, d, h = rs.reduced.M_r, q - st.q_hat, st.h_eff
        E = 0.5 / h**2 * float(d @ M_r @ d)
        return E, (M_r @ d / h**2 if order >= 1 else None), (M_r / h**2 if order == 2 else None)

    def sample_gradient(self, rs: ReducedSolver, q: np.ndarray, st: ReducedStep, u: np.ndarray,
                        u_hat: np.ndarray) -> np.ndarray:
        """w_i (u_i - u_hat_i) / h_eff^2 with the sample vertices' cubature masses w_i."""
        return rs.samples.weight[:, None] * ((u - u_hat) / st.h_eff**2)


@register
class Gravity(BodyTerm):
    """-sum_i m_i g . x_i, a uniform field."""

    name = "gravity"

    def applies(self, model: Model) -> bool:
        return model.has("gravity")

    def energy(self, model: Model, step: StepData, x: np.ndarray) -> float:
        return gravity_energy(x, model.mass, model.gravity)

    def gradient(self, model: Model, step: StepData, x: np.ndarray) -> np.ndarray:
        return gravity_gradient(model.mass, model.gravity)

    def hessian(self, model: Model, step: StepData, x: np.ndarray) -> sp.csr_matrix:
        return sp.csr_matrix((3 * model.n, 3 * model.n))

    def launch(self, solver: FullSpaceSolver, x: wp.array, h: float, mode: int, inertia: bool) -> None:
        import warp as wp

        from solvers.full import kernels as K

        wp.launch(K.inertia_gravity_kernel, solver.model.n, device=solver.device, inputs=[
            x, solver.x_hat, solver.mass, 0.0, solver.gravity, solver.diag, solver.grad, solver.values,
            solver.energy_buf, mode])

    def reduced(self, rs: ReducedSolver, q: np.ndarray, st: ReducedStep, order: int) -> Evaluation:
        """-g_r . q with the reduced weight g_r = sum_i m_i W_i^T g."""
        g_r = rs.reduced.gravity_q
        return -float(g_r @ q), (-g_r if order >= 1 else None), None

    def sample_gradient(self, rs: ReducedSolver, q: np.ndarray, st: ReducedStep, u: np.ndarray,
                        u_hat: np.ndarray) -> np.ndarray:
        """-w_i g with the sample vertices' cubature masses w_i."""
        return rs.samples.weight[:, None] * -rs.model.gravity

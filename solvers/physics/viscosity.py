"""Kelvin-Voigt material damping as a dissipative potential on the Green strain rate (docs/physics.md, "Material
damping").

With the Green strain E(F) = (F^T F - I) / 2 and its rate E_dot = (E(x) - E(x_bar)) / h_eff over the step
(`StepData.x_bar`, `h_eff`: backward Euler x^n and h), the dissipation potential eta |E_dot|_F^2 per volume gives
D(x) = h_eff sum_e V_e eta |E_dot_e|^2 = sum_e V_e eta / h_eff |E(F_e) - E(F_bar_e)|_F^2 [J], whose gradient is
the viscous second Piola-Kirchhoff stress S = 2 eta E_dot pulled back, P = F S. A rigid motion leaves E unchanged,
so translation and rotation are not damped.

Per element, with A = E(F) - E(F_bar) and c = eta / h_eff: density c |A|^2, stress P = 2 c F A, and density
Hessian 2 c (J^T J + I (x) A) (row-major vec, J = dE/dF). The Gauss-Newton part 2 c J^T J is PSD; the rest
2 c I (x) A has A's eigenvalues, and is projected by clamping them at 0 (I (x) A_+), so the Hessian is exact
wherever A is positive semi-definite (the element stretches against the start of the step).

`viscosity_for_damping_ratio` resolves a scenario's `material.damping_ratio` zeta_1 of the first non-rigid mode:
eta = 2 zeta_1 omega_1 / (phi_1^T D_1 phi_1) with (omega_1, phi_1) the first non-rigid generalised eigenpair of
the elastic Hessian K and the lumped mass M at rest (phi_1 mass-normalised) and D_1 the viscous Hessian at rest per
unit eta and unit h_eff (the damping matrix per unit viscosity: C = eta D_1).
"""

from __future__ import annotations

import numpy as np
import scipy.sparse as sp
import scipy.sparse.linalg as spla

from frictionbench.solvers.model import Model
from frictionbench.solvers.physics.material import (deformation_gradient, nodal_forces, project_psd, pulled_back,
                                                    rest_stiffness)
from frictionbench.solvers.physics.terms import DensityTerm, StepData, TetKernels, element_blocks, register

#: Eigenvalues within this relative distance of omega_1^2 belong to the first mode's eigenspace (a symmetric mesh
#: has degenerate modes); a rigid mode's eigenvalue is below this fraction of omega_1^2.
_DEGENERATE, _RIGID = 1e-6, 1e-6


def green_strain(F: np.ndarray) -> np.ndarray:
    """E = (F^T F - I) / 2, shape (..., 3, 3)."""
    return 0.5 * (np.swapaxes(F, -1, -2) @ F - np.eye(3))


def viscous_density(F: np.ndarray, F_bar: np.ndarray, c: float) -> np.ndarray:
    """c |E(F) - E(F_bar)|_F^2 [J/m^3], shape (...); c = eta / h_eff [Pa]."""
    A = green_strain(F) - green_strain(F_bar)
    return c * np.einsum("...ij,...ij->...", A, A)


def viscous_stress(F: np.ndarray, F_bar: np.ndarray, c: float) -> np.ndarray:
    """Its derivative in F, P = 2 c F (E(F) - E(F_bar)) [Pa], shape (..., 3, 3)."""
    return 2.0 * c * F @ (green_strain(F) - green_strain(F_bar))


def viscous_dpdf(F: np.ndarray, F_bar: np.ndarray, c: float, project: bool = True) -> np.ndarray:
    """Density Hessian (..., 9, 9) [Pa] (row-major vec): 2 c (J^T J + I (x) A), A = E(F) - E(F_bar), J = dvec E /
    dvec F; with `project`, A's eigenvalues clamped at 0 (PSD; exact where A is PSD)."""
    eye = np.eye(3)
    # dE[j, l] / dF[i, k] = (F[i, j] delta_lk + delta_jk F[i, l]) / 2
    J = 0.5 * (np.einsum("...ij,lk->...jlik", F, eye) + np.einsum("jk,...il->...jlik", eye, F))
    J = J.reshape(F.shape[:-2] + (9, 9))
    A = green_strain(F) - green_strain(F_bar)
    if project:
        A = project_psd(A)
    IA = np.einsum("ik,...jl->...ijkl", eye, A).reshape(F.shape[:-2] + (9, 9))
    return 2.0 * c * (np.swapaxes(J, -1, -2) @ J + IA)


def viscous_energy(x: np.ndarray, x_bar: np.ndarray, tets: np.ndarray, Dm_inv: np.ndarray, vol: np.ndarray,
                   c: float) -> float:
    """D(x) = sum_e V_e c |E(F_e) - E(F_bar_e)|^2 [J] for positions x, x_bar (n, 3) [m], c = eta / h_eff [Pa]."""
    F, F_bar = deformation_gradient(x, tets, Dm_inv), deformation_gradient(x_bar, tets, Dm_inv)
    return float(vol @ viscous_density(F, F_bar, c))


def viscous_gradient(x: np.ndarray, x_bar: np.ndarray, tets: np.ndarray, Dm_inv: np.ndarray, vol: np.ndarray,
                     c: float) -> np.ndarray:
    """dD/dx (n, 3) [N]."""
    F, F_bar = deformation_gradient(x, tets, Dm_inv), deformation_gradient(x_bar, tets, Dm_inv)
    return nodal_forces(viscous_stress(F, F_bar, c), tets, Dm_inv, vol, x.shape[0])


def viscous_element_hessians(x: np.ndarray, x_bar: np.ndarray, tets: np.ndarray, Dm_inv: np.ndarray,
                             vol: np.ndarray, c: float, project: bool = True) -> np.ndarray:
    """Per-element Hessians (m, 12, 12) [N/m], vertex-major; Gauss-Newton plus the projected rest if `project`,
    else exact."""
    F, F_bar = deformation_gradient(x, tets, Dm_inv), deformation_gradient(x_bar, tets, Dm_inv)
    return pulled_back(viscous_dpdf(F, F_bar, c, project), Dm_inv, vol)


def first_mode(model: Model) -> tuple[float, np.ndarray]:
    """The first non-rigid vibration mode of the free body at rest: omega_1 [rad/s] and the mass-normalised
    eigenvectors phi (3n, k) of its eigenspace (k > 1 where the mesh's symmetry makes the mode degenerate), from
    K phi = omega^2 M phi (K the elastic Hessian at rest, M the lumped mass) by shift-invert Lanczos about a
    negative shift, skipping the six rigid modes. Raises ValueError if the body does not have exactly six."""
    K = rest_stiffness(model).tocsc()
    M = sp.diags(np.repeat(model.mass, 3)).tocsc()
    scale = model.mu_snh / (model.density * model.L**2)  # [1/s^2], the order of omega_1^2
    k = min(9, 3 * model.n - 1)
    v0 = np.random.default_rng(0).standard_normal(3 * model.n)  # deterministic start: a reproducible basis
    w, phi = spla.eigsh(K, k=k, M=M, sigma=-1e-2 * scale, which="LM", v0=v0)
    order = np.argsort(w)
    w, phi = w[order], phi[:, order]
    if not (np.all(np.abs(w[:6]) < _RIGID * w[6]) and w[6] > 0.0):
        raise ValueError(f"the body on this mesh does not have exactly six rigid modes (smallest eigenvalues of "
                         f"K phi = omega^2 M phi: {w[:7].tolist()} 1/s^2)")
    cluster = np.flatnonzero(np.abs(w - w[6]) <= _DEGENERATE * w[6])
    return float(np.sqrt(w[6])), phi[:, cluster]


def rest_dissipation(model: Model, phi: np.ndarray) -> np.ndarray:
    """phi^T D_1 phi (k,) [kg/s per Pa s] for displacement fields phi (3n, k), with D_1 the viscous Hessian at
    rest per unit eta and unit h_eff (the damping matrix per unit viscosity, C = eta D_1). At rest F = F_bar = I,
    so only the Gauss-Newton part is left and dE = sym(dF): phi^T D_1 phi = sum_e 2 V_e |sym(dF_e(phi))|_F^2."""
    out = np.empty(phi.shape[1])
    for k in range(phi.shape[1]):
        dF = deformation_gradient(phi[:, k].reshape(-1, 3), model.tets, model.Dm_inv)
        sym = 0.5 * (dF + np.swapaxes(dF, 1, 2))
        out[k] = 2.0 * float(model.vol @ np.einsum("eij,eij->e", sym, sym))
    return out


def viscosity_for_damping_ratio(model: Model, zeta: float) -> float:
    """The viscosity eta [Pa s] that gives the first non-rigid mode the damping ratio zeta [-]:
    eta = 2 zeta omega_1 / (phi_1^T D_1 phi_1); for a degenerate mode, phi_1^T D_1 phi_1 is the mean over an
    M-orthonormal basis of its eigenspace (the trace there over its dimension), which does not depend on the
    basis."""
    omega, phi = first_mode(model)
    return 2.0 * zeta * omega / float(rest_dissipation(model, phi).mean())


@register
class Viscosity(DensityTerm):
    """sum_e V_e eta / h_eff |E(F_e) - E(F_bar_e)|^2 (Kelvin-Voigt); absent in static equilibrium (no rates)."""

    name = "viscosity"
    kernels = TetKernels("viscous_energy_kernel", "viscous_gradient_kernel", "viscous_hessian_kernel",
                         at_bar="green_strain_kernel", cubature="viscous_kernel", rows=15,
                         hessian_assigns=True)
    rate = True

    def kernel_parameters(self, model: Model, h: float) -> dict[str, float]:
        """eta / h_eff [Pa]."""
        return {"eta_over_h": model.viscosity / h}

    def applies(self, model: Model) -> bool:
        return model.has("viscosity")

    def energy(self, model: Model, step: StepData, x: np.ndarray) -> float:
        if not step.inertia:
            return 0.0
        return viscous_energy(x, step.x_bar, model.tets, model.Dm_inv, model.vol, model.viscosity / step.h_eff)

    def gradient(self, model: Model, step: StepData, x: np.ndarray) -> np.ndarray:
        if not step.inertia:
            return np.zeros_like(x)
        return viscous_gradient(x, step.x_bar, model.tets, model.Dm_inv, model.vol, model.viscosity / step.h_eff)

    def hessian(self, model: Model, step: StepData, x: np.ndarray) -> sp.csr_matrix:
        if not step.inertia:
            return sp.csr_matrix((3 * model.n, 3 * model.n))
        return element_blocks(model, viscous_element_hessians(x, step.x_bar, model.tets, model.Dm_inv, model.vol,
                                                              model.viscosity / step.h_eff))

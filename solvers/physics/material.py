"""Stable Neo-Hookean elasticity (Smith, de Goes, Kim 2018) as pure numpy functions.

Psi(F) = mu/2 (I_C - 3) + lam/2 (J - alpha)^2 - mu/2 log(I_C + 1),  alpha = 1 + 3 mu / (4 lam),
with I_C = |F|_F^2, J = det F and (mu, lam) re-parametrised from the Lame parameters so that small strains
match linear elasticity: mu = 4/3 mu_L, lam = lambda_L + 5/6 mu_L. Batched over leading axes: F has shape
(..., 3, 3). Vectorised 3x3 quantities use row-major `vec(F)[3 i + j] = F[i, j]`. `Elasticity` is the term
sum_e V_e Psi(F_e) of the incremental potential.
"""

from __future__ import annotations

import numpy as np
import scipy.sparse as sp

from frictionbench.solvers.model import Model
from frictionbench.solvers.physics.terms import DensityTerm, StepData, TetKernels, element_blocks, register


def lame_parameters(youngs_modulus: float, poisson_ratio: float) -> tuple[float, float]:
    """Lame parameters (mu_L, lambda_L) [Pa] of a linear isotropic material with E [Pa] and nu [-]."""
    E, nu = youngs_modulus, poisson_ratio
    return E / (2.0 * (1.0 + nu)), E * nu / ((1.0 + nu) * (1.0 - 2.0 * nu))


def snh_parameters(youngs_modulus: float, poisson_ratio: float) -> tuple[float, float]:
    """Stable Neo-Hookean (mu, lam) [Pa]: mu = 4/3 mu_L, lam = lambda_L + 5/6 mu_L."""
    mu_l, lam_l = lame_parameters(youngs_modulus, poisson_ratio)
    return 4.0 / 3.0 * mu_l, lam_l + 5.0 / 6.0 * mu_l


def cofactor(F: np.ndarray) -> np.ndarray:
    """dJ/dF = cof(F) (..., 3, 3): columns f1 x f2, f2 x f0, f0 x f1 of F's columns f0, f1, f2."""
    f0, f1, f2 = F[..., :, 0], F[..., :, 1], F[..., :, 2]
    return np.stack([np.cross(f1, f2), np.cross(f2, f0), np.cross(f0, f1)], axis=-1)


def snh_energy_density(F: np.ndarray, mu: float, lam: float) -> np.ndarray:
    """Energy density Psi(F) [J/m^3], shape (...)."""
    alpha = 1.0 + 0.75 * mu / lam
    ic = np.einsum("...ij,...ij->...", F, F)
    J = np.linalg.det(F)
    return 0.5 * mu * (ic - 3.0) + 0.5 * lam * (J - alpha) ** 2 - 0.5 * mu * np.log1p(ic)


def snh_pk1(F: np.ndarray, mu: float, lam: float) -> np.ndarray:
    """First Piola-Kirchhoff stress P = dPsi/dF [Pa], shape (..., 3, 3)."""
    alpha = 1.0 + 0.75 * mu / lam
    ic = np.einsum("...ij,...ij->...", F, F)[..., None, None]
    J = np.linalg.det(F)[..., None, None]
    return mu * (1.0 - 1.0 / (ic + 1.0)) * F + lam * (J - alpha) * cofactor(F)


def _cross_matrix(a: np.ndarray) -> np.ndarray:
    """Skew matrix [a]_x with [a]_x b = a x b, shape (..., 3, 3)."""
    z = np.zeros(a.shape[:-1])
    return np.stack(
        [np.stack([z, -a[..., 2], a[..., 1]], -1),
         np.stack([a[..., 2], z, -a[..., 0]], -1),
         np.stack([-a[..., 1], a[..., 0], z], -1)], -2)


def snh_dpdf(F: np.ndarray, mu: float, lam: float) -> np.ndarray:
    """Exact Hessian d2Psi/dF2 (..., 9, 9) in row-major vec ordering (may be indefinite)."""
    alpha = 1.0 + 0.75 * mu / lam
    lead = F.shape[:-2]
    f = F.reshape(lead + (9,))
    ic = np.einsum("...i,...i->...", f, f)[..., None, None]
    J = np.linalg.det(F)[..., None, None]
    g = cofactor(F).reshape(lead + (9,))
    # d2J/dF2: d cof(F)[i, c] / dF[k, l]; with columns f_c of F, cof[:, 0] = f1 x f2 etc.
    cols = [F[..., :, c] for c in range(3)]
    H3 = np.zeros(lead + (3, 3, 3, 3))  # [i, c, k, l] = d cof[i, c] / d F[k, l]
    for c in range(3):
        a, b = (c + 1) % 3, (c + 2) % 3
        # cof[:, c] = f_a x f_b: derivative wrt f_a is -[f_b]_x, wrt f_b is [f_a]_x.
        H3[..., :, c, :, a] = -_cross_matrix(cols[b])
        H3[..., :, c, :, b] = _cross_matrix(cols[a])
    H3 = H3.reshape(lead + (9, 9))
    eye = np.broadcast_to(np.eye(9), lead + (9, 9))
    return (mu * (1.0 - 1.0 / (ic + 1.0)) * eye
            + 2.0 * mu / (ic + 1.0) ** 2 * np.einsum("...i,...j->...ij", f, f)
            + lam * np.einsum("...i,...j->...ij", g, g)
            + lam * (J - alpha) * H3)


def project_psd(H: np.ndarray, floor: float = 0.0) -> np.ndarray:
    """Symmetric matrices (..., k, k) with eigenvalues clamped below at `floor` (numpy reference)."""
    w, Q = np.linalg.eigh(0.5 * (H + np.swapaxes(H, -1, -2)))
    return np.einsum("...ik,...k,...jk->...ij", Q, np.maximum(w, floor), Q)


def shape_matrices(X: np.ndarray, tets: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Rest shape data: Dm^-1 (m, 3, 3) and rest volumes V_e = det(Dm)/6 (m,) [m^3] of tets (m, 4)."""
    Dm = np.stack([X[tets[:, k]] - X[tets[:, 0]] for k in (1, 2, 3)], axis=-1)
    return np.linalg.inv(Dm), np.linalg.det(Dm) / 6.0


def deformation_gradient(x: np.ndarray, tets: np.ndarray, Dm_inv: np.ndarray) -> np.ndarray:
    """F = Ds Dm^-1 (m, 3, 3) for positions x (n, 3)."""
    Ds = np.stack([x[tets[:, k]] - x[tets[:, 0]] for k in (1, 2, 3)], axis=-1)
    return Ds @ Dm_inv


def shape_gradients(Dm_inv: np.ndarray) -> np.ndarray:
    """g (m, 4, 3): dF/dx_a = e_alpha g_a^T, i.e. F = sum_a x_a g_a^T; rows 1..3 of g are rows of Dm^-1."""
    g123 = Dm_inv  # row k-1 of Dm^-1 belongs to vertex k
    return np.concatenate([-g123.sum(axis=1, keepdims=True), g123], axis=1)


def elastic_energy(x: np.ndarray, tets: np.ndarray, Dm_inv: np.ndarray, vol: np.ndarray,
                   mu: float, lam: float) -> float:
    """Total elastic energy sum_e V_e Psi(F_e) [J]."""
    return float(vol @ snh_energy_density(deformation_gradient(x, tets, Dm_inv), mu, lam))


def elastic_gradient(x: np.ndarray, tets: np.ndarray, Dm_inv: np.ndarray, vol: np.ndarray,
                     mu: float, lam: float) -> np.ndarray:
    """Gradient of the elastic energy with respect to positions, (n, 3) [N]."""
    return nodal_forces(snh_pk1(deformation_gradient(x, tets, Dm_inv), mu, lam), tets, Dm_inv, vol, x.shape[0])


def nodal_forces(P: np.ndarray, tets: np.ndarray, Dm_inv: np.ndarray, vol: np.ndarray, n: int) -> np.ndarray:
    """The gradient (n, 3) [N] of energies V_e psi(F_e) whose stresses dpsi/dF are P (m, 3, 3) [Pa]: V_e P_e g_a
    summed on each tet's vertices."""
    fe = vol[:, None, None] * np.einsum("eij,eaj->eai", P, shape_gradients(Dm_inv))  # (m, 4, 3)
    out = np.zeros((n, 3))
    np.add.at(out, tets, fe)
    return out


def element_hessians(x: np.ndarray, tets: np.ndarray, Dm_inv: np.ndarray, vol: np.ndarray,
                     mu: float, lam: float, project: bool = True) -> np.ndarray:
    """Per-element Hessians (m, 12, 12), vertex-major (3 a + alpha), projected to PSD if `project`."""
    H9 = snh_dpdf(deformation_gradient(x, tets, Dm_inv), mu, lam)
    if project:
        H9 = project_psd(H9)
    return pulled_back(H9, Dm_inv, vol)


def rest_stiffness(model: Model) -> sp.csr_matrix:
    """The elastic Hessian K (3n, 3n) [N/m] of the body at rest (F = I), unprojected (PSD there: its null space
    the six rigid motions)."""
    return element_blocks(model, element_hessians(model.X, model.tets, model.Dm_inv, model.vol, model.mu_snh,
                                                  model.lam_snh, project=False))


def pulled_back(H9: np.ndarray, Dm_inv: np.ndarray, vol: np.ndarray) -> np.ndarray:
    """Per-element Hessians (m, 12, 12) over the tets' vertex positions (vertex-major, 3 a + alpha) of energies
    V_e psi(F_e) whose density Hessians in F are H9 (m, 9, 9) (row-major vec): V_e B_e^T H9_e B_e."""
    g = shape_gradients(Dm_inv)  # (m, 4, 3)
    # d vec(F)[3 i + j] / d x[a, alpha] = delta_{i alpha} g[a, j]
    B = np.einsum("il,eaj->eijal", np.eye(3), g).reshape(-1, 9, 12)
    return vol[:, None, None] * (np.swapaxes(B, 1, 2) @ H9 @ B)


@register
class Elasticity(DensityTerm):
    """sum_e V_e Psi(F_e), stable Neo-Hookean; the Hessian projected per element."""

    name = "elasticity"
    kernels = TetKernels("elastic_energy_kernel", "elastic_gradient_kernel", "elastic_hessian_kernel",
                         cubature="snh_kernel")

    def kernel_parameters(self, model: Model, h: float) -> dict[str, float]:
        """The SNH parameters mu, lam [Pa] and the rest offset alpha = 1 + 3 mu / (4 lam) [-]."""
        return {"mu": model.mu_snh, "lam": model.lam_snh, "alpha": 1.0 + 0.75 * model.mu_snh / model.lam_snh}

    def applies(self, model: Model) -> bool:
        return model.has("elasticity")

    def energy(self, model: Model, step: StepData, x: np.ndarray) -> float:
        return elastic_energy(x, model.tets, model.Dm_inv, model.vol, model.mu_snh, model.lam_snh)

    def gradient(self, model: Model, step: StepData, x: np.ndarray) -> np.ndarray:
        return elastic_gradient(x, model.tets, model.Dm_inv, model.vol, model.mu_snh, model.lam_snh)

    def hessian(self, model: Model, step: StepData, x: np.ndarray) -> sp.csr_matrix:
        return element_blocks(model, element_hessians(x, model.tets, model.Dm_inv, model.vol, model.mu_snh,
                                                      model.lam_snh))



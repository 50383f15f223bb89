"""A training-free subspace: the body's linear vibration modes and their modal derivatives, beside the affine fields
(`modal`, a `ReducedPlugin`).

Linear modes: the k lowest non-rigid solutions of K phi = omega^2 M phi at rest (K the unprojected elastic Hessian
`rest_stiffness`, M the lumped mass; shift-and-invert Lanczos). Modal derivatives (Barbic and James 2005, "Real-time
subspace integration for St. Venant-Kirchhoff deformable models"): the second-order terms of the displacement
along two modes, K Psi_ij = -(dK/dq_j) phi_i, where dK/dq_j is the derivative of the elastic Hessian along phi_j
(here by central differences of the element Hessians); symmetric in i, j, since both are third derivatives of the
elastic energy. They add what a mode's large deflection does to the others, which the linear modes alone miss.
The derivatives of the first `derivative_modes` modes, each scaled by omega_1^2 / (omega_i omega_j) (the weight of
their amplitudes under a common load), are reduced by their mass-weighted principal components to `derivatives`
columns. The basis is the 12 affine fields, then the modes' and the derivatives' parts beyond them, mass-orthonormal.

Everything is computed on the run's own mesh from its rest shape and material, so the family needs no training data
and no transfer to another mesh of the shape.
"""

from __future__ import annotations

import time

import numpy as np
import scipy.sparse as sp
import scipy.sparse.linalg as spla

from frictionbench.solvers.model import Model
from frictionbench.solvers.physics.material import element_hessians, rest_stiffness
from frictionbench.solvers.physics.terms import element_blocks
from frictionbench.solvers.reduced.bases import affine_basis, mass_orthonormalise
from frictionbench.solvers.reduced.plugin import COMMON_PARAMETERS, FRAME_PARAMETERS, ReducedPlugin

#: Central-difference step of the Hessian's derivative along a mode, as a fraction of L (the mode scaled so that its
#: largest vertex displacement is this): the difference's truncation error is O(step^2) of a quadratic variation.
DERIVATIVE_STEP = 1e-4
#: The rigid motions' eigenvalues lie below this fraction of the largest of the k + 6 computed (round-off of zero).
RIGID_TOL = 1e-8


def vibration_modes(model: Model, k: int) -> tuple[np.ndarray, np.ndarray]:
    """The k lowest elastic modes of the body at rest: phi (n, 3, k), mass-normalised (phi^T M phi = I), and their
    omega^2 (k,) [rad^2/s^2], ascending; the six rigid motions excluded. ValueError for k outside [1, 3n - 6]."""
    n = model.n
    if not 1 <= k <= 3 * n - 6:
        raise ValueError(f"modes = {k}: the mesh of {n} vertices has 1 to {3 * n - 6} elastic modes")
    K = rest_stiffness(model).tocsc()
    M = sp.diags(np.repeat(model.mass, 3)).tocsc()
    # shift below zero so that K - sigma M is positive definite; the scale is a bar's first mode, E / (rho L^2)
    mat = model.scenario.material
    sigma = -1e-2 * mat.youngs_modulus / (mat.density * model.L**2)
    v0 = np.random.default_rng(0).standard_normal(3 * n)
    w, V = spla.eigsh(K, k=min(k + 6, 3 * n - 1), M=M, sigma=sigma, which="LM", v0=v0)
    order = np.argsort(w)
    w, V = w[order], V[:, order]
    elastic = w > RIGID_TOL * abs(w).max()
    if int((~elastic).sum()) != 6:
        raise RuntimeError(f"{int((~elastic).sum())} rigid modes found at rest, expected 6 (a free body)")
    w, V = w[elastic][:k], V[:, elastic][:, :k]
    V /= np.sqrt(np.einsum("ik,i,ik->k", V, np.repeat(model.mass, 3), V))
    return V.reshape(n, 3, k), w


def hessian_derivative(model: Model, direction: np.ndarray) -> sp.csr_matrix:
    """dK/ds (3n, 3n) [N/m per unit s] of the unprojected elastic Hessian at X + s direction, at s = 0
    (direction (n, 3) [m per unit s]), by central differences of step DERIVATIVE_STEP L in the largest vertex
    displacement."""
    h = DERIVATIVE_STEP * model.L / float(np.abs(direction).max())
    args = (model.tets, model.Dm_inv, model.vol, model.mu_snh, model.lam_snh)
    plus = element_hessians(model.X + h * direction, *args, project=False)
    minus = element_hessians(model.X - h * direction, *args, project=False)
    return element_blocks(model, (plus - minus) / (2.0 * h))


def modal_derivatives(model: Model, phi: np.ndarray) -> np.ndarray:
    """Psi (n, 3, k, k): the modal derivatives of the modes phi (n, 3, k), K Psi_ij = -(dK/dq_j) phi_i, solved in the
    complement of the rigid motions (K is singular on them): each mass-orthogonal to them."""
    n, _, k = phi.shape
    K = rest_stiffness(model).tocsc()
    Rf = _rigid_motions(model).reshape(-1, 6)
    # K + (M R)(M R)^T is definite; for a right-hand side orthogonal to the rigid motions R (K's null space, so its
    # range's complement) its solution u has R^T M u = 0 and K u = rhs
    MR = np.repeat(model.mass, 3)[:, None] * Rf
    solve = spla.factorized((K + sp.csr_matrix(MR @ MR.T)).tocsc())
    Phi = phi.reshape(-1, k)
    out = np.zeros((3 * n, k, k))
    for j in range(k):
        rhs = -(hessian_derivative(model, phi[:, :, j]) @ Phi)  # (3n, k): column i is -(dK/dq_j) phi_i
        rhs -= Rf @ (Rf.T @ rhs)  # round-off's rigid part (Rf is Euclidean-orthonormal)
        for i in range(k):
            out[:, i, j] = solve(rhs[:, i])
    return out.reshape(n, 3, k, k)


def _rigid_motions(model: Model) -> np.ndarray:
    """The six rigid motions of the rest shape (n, 3, 6), Euclidean-orthonormal over the 3n coordinates."""
    Xc = model.X - model.X.mean(axis=0)
    cols = [np.tile(np.eye(3)[a], (model.n, 1)) for a in range(3)] + [np.cross(np.eye(3)[a], Xc) for a in range(3)]
    Q, _ = np.linalg.qr(np.stack(cols, axis=2).reshape(-1, 6))
    return Q.reshape(model.n, 3, 6)


def modal_basis(model: Model, modes: int, derivatives: int, derivative_modes: int) -> tuple[np.ndarray, dict]:
    """W (n, 3, 12 + modes + derivatives), mass-orthonormal: the affine fields, then the linear modes' and the
    (scaled, principal) modal derivatives' parts beyond them (module doc); and its stats (the modes' frequencies
    [rad/s], the time to compute it [s])."""
    t0 = time.perf_counter()
    phi, w2 = vibration_modes(model, modes)
    cols = [phi]
    if derivatives:
        m = min(derivative_modes, modes)
        if not 1 <= derivatives <= m * (m + 1) // 2:
            raise ValueError(f"derivatives = {derivatives}: {m} modes have 1 to {m * (m + 1) // 2} modal derivatives")
        psi = modal_derivatives(model, phi[:, :, :m])
        iu = np.triu_indices(m)
        scale = w2[0] / np.sqrt(w2[iu[0]] * w2[iu[1]])
        D = psi[:, :, iu[0], iu[1]] * scale  # (n, 3, m (m + 1) / 2)
        s = np.sqrt(np.repeat(model.mass, 3))[:, None]
        U, _, _ = np.linalg.svd(s * D.reshape(-1, D.shape[2]), full_matrices=False)
        cols.append((U[:, :derivatives] / s).reshape(model.n, 3, derivatives))
    A = mass_orthonormalise(affine_basis(model.X), model.mass)
    Af = A.reshape(-1, 12)
    rest = np.concatenate(cols, axis=2).reshape(-1, modes + derivatives)
    m3 = np.repeat(model.mass, 3)
    rest = rest - Af @ (Af.T @ (m3[:, None] * rest))  # beyond the affine fields
    W = mass_orthonormalise(np.concatenate([A, rest.reshape(model.n, 3, -1)], axis=2), model.mass)
    return W, {"modal_s": time.perf_counter() - t0, "omega_first": float(np.sqrt(w2[0])),
               "omega_last": float(np.sqrt(w2[-1]))}


class Modal(ReducedPlugin):
    """The training-free subspace of the body's own mechanics (module doc): `modes` linear vibration modes and
    `derivatives` principal modal derivatives of the first `derivative_modes` of them, beside the 12 affine fields
    (r = 12 + modes + derivatives), computed on the run's mesh at setup (untimed, reported as `modal_s`)."""

    name = "modal"
    parameters = COMMON_PARAMETERS | {"modes": 12, "derivatives": 12, "derivative_modes": 6}

    def basis_of(self, model: Model) -> tuple[np.ndarray, dict | None, dict]:
        """The modal basis of this mesh, no stored cubature (an optimised one falls back to uniform), its stats."""
        p = self.params
        W, info = modal_basis(model, int(p["modes"]), int(p["derivatives"]), int(p["derivative_modes"]))
        return W, None, info


class ModalFrame(Modal):
    """The modal subspace stepped in the body's frame (`solvers.reduced.frame.FrameSolver`): the modes and their
    derivatives, computed at rest, turned with the body, as modal warping does for each element."""

    name = "modal-frame"
    basis_frame = "body"
    parameters = Modal.parameters | FRAME_PARAMETERS

"""Linear-subspace baselines for the reduced solver: bases W (n, 3, r) with u(X_i) = W[i] q (docs/solvers.md).

- `affine_fields` / `affine_basis`: the 12 exact affine fields (every rigid motion and every homogeneous strain),
  mesh-free; `affine_fields` is also the affine part of LiCROM's neural field (torch);
- `pod_basis`: proper orthogonal decomposition of training displacements, computed on the training mesh;
- `interpolate_basis`: a basis of one mesh carried to another mesh of the same shape (piecewise linear on the
  first mesh's tets, `barycentric_weights`);
- `full_basis`: the complete per-vertex basis (the reduced solver then equals the full-space one);
- `project`: the coordinates of displacements in a basis (mass-weighted least squares);
- `body_rotation`, `body_frame_displacements`, `rotated_basis`: the body's frame (`solvers.reduced.frame`).
"""

from __future__ import annotations

from typing import TypeVar

import numpy as np
from scipy.spatial import cKDTree

ArrayT = TypeVar("ArrayT")  # a numpy array or a torch tensor


def standardised_positions(X: np.ndarray) -> np.ndarray:
    """Xhat = (X - mean) / std per axis, (n, 3) dimensionless (axes with zero spread are only centred)."""
    std = X.std(axis=0)
    return (X - X.mean(axis=0)) / np.where(std > 0.0, std, 1.0)


#: Number of affine fields: 3 translations and 9 linear maps.
N_AFFINE = 12


def affine_fields(Xhat: ArrayT) -> ArrayT:
    """The 12 affine fields A (n, 3, 12) at standardised positions Xhat (n, 3), a numpy array or a torch tensor
    (the result is of the same kind and dtype; differentiable in torch).

    Column 4 c + k is e_c phi_k(Xhat), phi = [1, Xhat_x, Xhat_y, Xhat_z], so A q is the displacement (L - I) X + b
    of any affine map X -> L X + b (every rigid motion included), with q in metres.
    """
    n = Xhat.shape[0]
    A = Xhat.new_zeros((n, 3, N_AFFINE)) if hasattr(Xhat, "new_zeros") else np.zeros((n, 3, N_AFFINE), Xhat.dtype)
    for c in range(3):
        A[:, c, 4 * c] = 1.0
        A[:, c, 4 * c + 1:4 * c + 4] = Xhat
    return A


def affine_basis(X: np.ndarray) -> np.ndarray:
    """The 12 affine displacement fields at rest positions X (n, 3): W (n, 3, 12) [m per unit q], the
    `affine_fields` of the standardised positions (`standardised_positions`)."""
    return affine_fields(standardised_positions(np.asarray(X, dtype=np.float64)))


def project(W: np.ndarray, u: np.ndarray, mass: np.ndarray | None = None) -> np.ndarray:
    """Least-squares coordinates of displacements in the basis W (n, 3, r): q = argmin sum_i m_i |W_i q - u_i|^2.

    u: one field (n, 3) [m] -> q (r,), or frames (F, n, 3) -> q (F, r), each frame fitted on its own.
    mass: (n,) non-negative weights [kg] (default: uniform, the Euclidean fit). Rank-deficient W gives the
    minimum-norm q.
    """
    W = np.asarray(W, dtype=np.float64)
    u = np.asarray(u, dtype=np.float64)
    if W.ndim != 3 or W.shape[1] != 3 or u.shape[-2:] != W.shape[:2] or u.ndim not in (2, 3):
        raise ValueError(f"W {W.shape} and u {u.shape}: expected (n, 3, r) and (n, 3) or (F, n, 3)")
    A, B = W.reshape(-1, W.shape[2]), u.reshape(-1, 3 * W.shape[0]).T  # (3n, r), (3n, F)
    if mass is not None:
        root = np.sqrt(np.repeat(np.asarray(mass, dtype=np.float64), 3))
        A, B = A * root[:, None], B * root[:, None]
    q = np.linalg.lstsq(A, B, rcond=None)[0].T  # (F, r)
    return q[0] if u.ndim == 2 else q


def smooth_basis(X: np.ndarray, r: int, scale: float, seed: int = 0) -> np.ndarray:
    """The 12 affine fields and r - 12 random smooth fields (quadratic, cubic and trigonometric in the standardised
    rest positions, `seed` fixing their mix) scaled by `scale` [m], (n, 3, r): a basis with no training behind it,
    for checks of the reduced machinery (the device check, the tests)."""
    rng = np.random.default_rng(seed)
    x, y, z = standardised_positions(X).T
    feats = np.stack([x * x, y * y, z * z, x * y, y * z, x * z, x * y * z, np.sin(2 * x), np.cos(2 * y)], axis=1)
    extra = np.einsum("nf,fak->nak", feats, rng.standard_normal((feats.shape[1], 3, r - 12)))
    return scale * np.concatenate([affine_basis(X), extra], axis=2)


def full_basis(n: int) -> np.ndarray:
    """The complete per-vertex basis W (n, 3, 3n): W[i, a, 3 i + a] = 1, so q is the flattened displacement."""
    return np.eye(3 * n).reshape(n, 3, 3 * n)


def mass_orthonormalise(W: np.ndarray, mass: np.ndarray) -> np.ndarray:
    """Columns of W (n, 3, r) made orthonormal in the lumped-mass inner product (W^T M W = I), same span."""
    s = np.sqrt(mass)[:, None, None]
    Q, _ = np.linalg.qr((s * W).reshape(-1, W.shape[2]))
    return Q.reshape(W.shape) / s


def pod_basis(trajectories_u: np.ndarray, r: int, mass: np.ndarray, affine_X: np.ndarray | None = None
              ) -> np.ndarray:
    """Proper orthogonal decomposition of training displacements: W (n, 3, r), mass-orthonormal (W^T M W = I).

    trajectories_u: (F, n, 3) displacements u = x - X [m] of all training frames stacked (no mean is removed:
    q = 0 is the rest state); mass: (n,) lumped masses [kg]. The modes are the leading left singular vectors of
    M^(1/2) U (U = the frames as columns), i.e. the best rank-r fit of the frames in the mass norm.

    Affine part: by default NOT included -- plain POD, the classic mesh-bound baseline, which needs many modes
    for large rotations. With the rest positions `affine_X` (n, 3), columns 0..11 span the 12 affine fields
    exactly (`affine_basis`) and columns 12..r-1 are the POD modes of what the frames have beyond their
    mass-orthogonal projection onto the affine fields (requires r >= 12).
    """
    if affine_X is None:
        return _pod_modes(trajectories_u, r, mass)
    if r < 12:
        raise ValueError(f"r = {r}: an affine-plus-POD basis needs r >= 12")
    A = mass_orthonormalise(affine_basis(affine_X), mass)
    if r == 12:
        return A
    U = trajectories_u.reshape(trajectories_u.shape[0], -1)  # (F, 3n)
    Af = A.reshape(-1, 12)
    residual = U - (U * np.repeat(mass, 3)) @ Af @ Af.T
    modes = _pod_modes(residual.reshape(trajectories_u.shape), r - 12, mass)
    return mass_orthonormalise(np.concatenate([A, modes], axis=2), mass)


def _pod_modes(trajectories_u: np.ndarray, r: int, mass: np.ndarray) -> np.ndarray:
    """Leading r mass-orthonormal POD modes (n, 3, r) of frames (F, n, 3)."""
    F, n, _ = trajectories_u.shape
    if not 1 <= r <= min(F, 3 * n):
        raise ValueError(f"r = {r}: POD of {F} frames of {n} vertices gives at most {min(F, 3 * n)} modes")
    s = np.sqrt(np.repeat(mass, 3))
    Phi, _, _ = np.linalg.svd(s[:, None] * trajectories_u.reshape(F, -1).T, full_matrices=False)
    return (Phi[:, :r] / s[:, None]).reshape(n, 3, r)


def barycentric_weights(X_src: np.ndarray, tets: np.ndarray, points: np.ndarray, candidates: int = 16
                        ) -> tuple[np.ndarray, np.ndarray]:
    """For each point (p, 3) [m], the source tet (p,) of the mesh (X_src (n, 3) [m], tets (m, 4)) holding it (or
    the best of its `candidates` nearest tets by centroid) and its barycentric weights (p, 4), clamped to be
    non-negative and renormalised: a point outside the mesh takes the closest point of that tet."""
    centroids = X_src[tets].mean(axis=1)
    k = min(candidates, len(tets))
    _, near = cKDTree(centroids).query(points, k=k)
    near = near.reshape(len(points), k)
    T = X_src[tets[near]]  # (p, k, 4, 3)
    D = np.stack([T[:, :, j] - T[:, :, 0] for j in (1, 2, 3)], axis=-1)  # (p, k, 3, 3)
    lam123 = np.linalg.solve(D, (points[:, None, :] - T[:, :, 0])[..., None])[..., 0]
    lam = np.concatenate([1.0 - lam123.sum(-1, keepdims=True), lam123], axis=-1)  # (p, k, 4)
    outside = np.maximum(-lam, 0.0).sum(-1)  # 0 inside the tet
    best = outside.argmin(axis=1)
    rows = np.arange(len(points))
    w = np.maximum(lam[rows, best], 0.0)
    return near[rows, best], w / w.sum(axis=1, keepdims=True)


#: The farthest a vertex of the target mesh may lie outside the source mesh when a basis is carried across, as a
#: fraction of the source mesh's bounding-box diagonal: two discretisations of one curved boundary differ by a
#: fraction of an edge; farther out the target is another shape.
OUTSIDE_TOLERANCE = 0.02


def interpolate_basis(W: np.ndarray, X_src: np.ndarray, tets: np.ndarray, X_dst: np.ndarray) -> np.ndarray:
    """A basis W (n, 3, r) of the mesh (X_src (n, 3) [m], tets (m, 4)), piecewise linear on its rest tets,
    evaluated at the rest vertices X_dst (p, 3) [m] of another mesh of the same shape: (p, 3, r). A vertex outside
    the source mesh takes the value at the closest point of its nearest tet; one farther out than
    OUTSIDE_TOLERANCE of the source's bounding-box diagonal is an error naming it (another shape)."""
    tet, w = barycentric_weights(X_src, tets, X_dst)
    idx = tets[tet]  # (p, 4)
    gap = np.linalg.norm(np.einsum("pk,pkd->pd", w, X_src[idx]) - X_dst, axis=1)
    size = float(np.linalg.norm(X_src.max(axis=0) - X_src.min(axis=0)))
    far = int(np.argmax(gap))
    if gap[far] > OUTSIDE_TOLERANCE * size:
        raise ValueError(f"vertex {far} of the target mesh (at {X_dst[far].round(4).tolist()} m) lies {gap[far]:.3g} m "
                         f"outside the source mesh ({gap[far] / size:.1%} of its size, more than "
                         f"{OUTSIDE_TOLERANCE:.0%}): not a mesh of the same shape")
    return np.einsum("pk,pkdr->pdr", w, W[idx])


# ----- the body's frame (`solvers.reduced.frame`) ---------------------------------------------------------------
def body_rotation(X: np.ndarray, x: np.ndarray, mass: np.ndarray) -> np.ndarray:
    """The body's rotation R (3, 3) (or (F, 3, 3) for frames x (F, n, 3)): the rotation part of the polar decomposition
    of A = sum_i m_i (x_i - c)(X_i - C)^T with c, C the mass centres of x and X (n, 3) [m]; the rotation that
    best maps the rest shape's offsets onto the current ones in the mass norm (shape matching)."""
    x = np.asarray(x, dtype=np.float64)
    w = mass / mass.sum()
    Xc = X - w @ X
    xc = x - np.einsum("n,...na->...a", w, x)[..., None, :]
    A = np.einsum("n,...na,nb->...ab", w, xc, Xc)
    return _rotation_of(A)


def _rotation_of(A: np.ndarray) -> np.ndarray:
    """The proper rotations R (..., 3, 3) of the polar decompositions A = R S of matrices A (..., 3, 3); where A
    reflects (an inverted fit), the reflection moved onto its smallest stretch."""
    U, _, Vt = np.linalg.svd(A)
    U[..., :, 2] *= np.where(np.linalg.det(U @ Vt) < 0.0, -1.0, 1.0)[..., None]
    return U @ Vt


def rotation_angle(R1: np.ndarray, R2: np.ndarray) -> float:
    """The angle [rad] of the rotation R1^T R2 between two rotations (3, 3), from |R1 - R2|_F = 2 sqrt(2) sin(angle / 2)
    (accurate for small angles too, where the trace's arccos loses half the digits)."""
    return float(2.0 * np.arcsin(min(1.0, np.linalg.norm(R1 - R2) / (2.0 * np.sqrt(2.0)))))


def body_frame_displacements(X: np.ndarray, x: np.ndarray, mass: np.ndarray) -> np.ndarray:
    """Displacements in the body's frame (F, n, 3) [m] of frames x (F, n, 3): R_f^T (x_f - c_f) + C - X, each frame
    turned back by its rotation R_f (`body_rotation`) and moved back onto the rest mass centre C."""
    x = np.asarray(x, dtype=np.float64)
    w = mass / mass.sum()
    R = body_rotation(X, x, mass)
    c = np.einsum("n,fna->fa", w, x)
    return np.einsum("fba,fnb->fna", R, x - c[:, None, :]) + (w @ X) - X


def rotated_basis(W: np.ndarray, R: np.ndarray) -> np.ndarray:
    """W(R) (n, 3, r): the first 12 columns of W (the affine fields' span) as they are, the others turned by R."""
    out = W.copy()
    out[:, :, N_AFFINE:] = np.einsum("ab,nbk->nak", R, W[:, :, N_AFFINE:])
    return out

"""Taichi kernels of the reduced solver (float64): Stable Neo-Hookean at the cubature tets.

The reduced solver's hot path is the per-cubature-tet evaluation of the energy density Psi(F), the first
Piola-Kirchhoff stress P(F) and the PSD-projected Hessian (dP/dF)_+ at deformation gradients F (c, 3, 3). One
kernel does all three into one packed output array (its width selects how much), so that a call is one launch;
the linear reductions with the constant jacobians B_c = dvec(F_c)/dq are dense matrix products left to BLAS
(solvers/licrom/reduced.py). Each output mirrors the numpy reference in solvers/physics/material.py (row-major
vec: vec(F)[3 i + j] = F[i, j]) and is tested against it. Measured on this project's 2-core CPU machine: a
launch costs ~0.1-0.2 ms, the Hessian ~3-4 us per tet (about half of it taichi's float64 3x3 SVD).

Taichi is initialised once per process (`init_taichi`), in float64, with its offline kernel cache under
solvers.warp_runtime.cache_root()/taichi so that the compile cost (seconds) is paid once per machine.
"""

import numpy as np
import taichi as ti

from frictionbench.solvers.warp_runtime import cache_root

ENERGY, STRESS, HESSIAN = 0, 1, 2
"""Evaluation modes: Psi only; Psi and P; Psi, P and (dP/dF)_+."""
_WIDTH = {ENERGY: 1, STRESS: 10, HESSIAN: 91}
"""Columns of the kernel's packed output row per tet: [Psi, vec P (9), vec (dP/dF)_+ (81)]."""

_initialised_device: str | None = None


def init_taichi(device: str = "cpu") -> None:
    """Initialise taichi once per process on `device` (`cpu` or `cuda`), float64, offline cache on.

    Raises RuntimeError if taichi was already initialised here for another device (a second ti.init would
    invalidate what the first one compiled).
    """
    global _initialised_device
    if device not in ("cpu", "cuda"):
        raise ValueError(f"device = {device!r}: expected 'cpu' or 'cuda'")
    if _initialised_device is not None:
        if _initialised_device != device:
            raise RuntimeError(f"taichi already runs on {_initialised_device!r} in this process; "
                               f"cannot switch to {device!r}")
        return
    ti.init(arch=ti.cuda if device == "cuda" else ti.cpu, default_fp=ti.f64, offline_cache=True,
            offline_cache_file_path=str(cache_root() / "taichi"), log_level=ti.WARN)
    _initialised_device = device


@ti.func
def _jacobi_eigen(A: ti.template()):
    """Eigen-decomposition of a symmetric 3x3 matrix by cyclic Jacobi rotations (exact Givens rotations,
    robust for repeated eigenvalues). Returns (eigenvalues (3,), eigenvectors as columns (3, 3))."""
    D = A
    Q = ti.Matrix.identity(ti.f64, 3)
    for _sweep in range(10):
        off = D[0, 1] * D[0, 1] + D[0, 2] * D[0, 2] + D[1, 2] * D[1, 2]
        if off <= 1e-32 * (D[0, 0] * D[0, 0] + D[1, 1] * D[1, 1] + D[2, 2] * D[2, 2]) + 1e-300:
            break
        for pair in range(3):
            p = 0 if pair < 2 else 1
            r = 1 if pair == 0 else 2
            if ti.abs(D[p, r]) > 1e-300:
                theta = (D[r, r] - D[p, p]) / (2.0 * D[p, r])
                t = 1.0 / (ti.abs(theta) + ti.sqrt(theta * theta + 1.0))
                if theta < 0.0:
                    t = -t
                c = 1.0 / ti.sqrt(t * t + 1.0)
                s = t * c
                R = ti.Matrix.identity(ti.f64, 3)
                R[p, p] = c
                R[r, r] = c
                R[p, r] = s
                R[r, p] = -s
                D = R.transpose() @ D @ R
                Q = Q @ R
    return ti.Vector([D[0, 0], D[1, 1], D[2, 2]]), Q


@ti.func
def _add_mode(out: ti.template(), e: ti.i32, Q: ti.template(), lam_v: ti.f64):
    """out[e, 10:91] += lam_v vec(Q) vec(Q)^T (lower triangle only) for an eigen-matrix Q (3x3, unit Frobenius
    norm) of dP/dF, if lam_v > 0."""
    if lam_v > 0.0:
        v = ti.Vector([Q[0, 0], Q[0, 1], Q[0, 2], Q[1, 0], Q[1, 1], Q[1, 2], Q[2, 0], Q[2, 1], Q[2, 2]])
        for a in range(9):
            for b in range(a + 1):
                out[e, 10 + 9 * a + b] += lam_v * v[a] * v[b]


@ti.kernel
def snh_kernel(F: ti.types.ndarray(dtype=ti.f64, ndim=2), mu: ti.f64, lam: ti.f64,
               out: ti.types.ndarray(dtype=ti.f64, ndim=2)):
    """Per tet e with F[e] = vec(F_e) (row-major, 9): out[e, 0] = Psi; if out has >= 10 columns, out[e, 1:10] =
    vec P; if it has 91, out[e, 10:91] = vec (dP/dF)_+ (9x9, row-major).

    dP/dF = a I + b f f^T + d g g^T + c d2J/dF2 with a = mu (1 - 1/(I_C+1)), b = 2 mu/(I_C+1)^2, c = lam (J -
    alpha), d = lam, f = vec F, g = vec cof F. In the rotation-variant SVD F = U diag(s) V^T (det U = det V = 1)
    its eigen-matrices are, per index pair (i, j) with k the third, a twist U (e_i e_j^T - e_j e_i^T) V^T / sqrt 2
    with eigenvalue a + c s_k, a flip with + and eigenvalue a - c s_k, and three scaling modes U diag(w) V^T with
    w the eigenvectors of A_ij = a delta_ij + b s_i s_j + d g_i g_j + c s_k [i != j], g = (s1 s2, s0 s2, s0 s1).
    Negative eigenvalues are dropped (PSD projection).
    """
    alpha = 1.0 + 0.75 * mu / lam
    width = out.shape[1]
    for e in range(F.shape[0]):
        Fm = ti.Matrix.zero(ti.f64, 3, 3)
        for i, j in ti.static(ti.ndrange(3, 3)):
            Fm[i, j] = F[e, 3 * i + j]
        ic = Fm.norm_sqr()
        J = Fm.determinant()
        out[e, 0] = 0.5 * mu * (ic - 3.0) + 0.5 * lam * (J - alpha) ** 2 - 0.5 * mu * ti.log(1.0 + ic)
        ca = mu * (1.0 - 1.0 / (ic + 1.0))
        cc = lam * (J - alpha)
        if width >= 10:
            f0 = ti.Vector([Fm[0, 0], Fm[1, 0], Fm[2, 0]])
            f1 = ti.Vector([Fm[0, 1], Fm[1, 1], Fm[2, 1]])
            f2 = ti.Vector([Fm[0, 2], Fm[1, 2], Fm[2, 2]])
            cof = ti.Matrix.cols([f1.cross(f2), f2.cross(f0), f0.cross(f1)])
            Pm = ca * Fm + cc * cof
            for i, j in ti.static(ti.ndrange(3, 3)):
                out[e, 1 + 3 * i + j] = Pm[i, j]
        if width >= 91:
            U, S, V = ti.svd(Fm, ti.f64)
            flip = ti.Matrix([[1.0, 0.0, 0.0], [0.0, 1.0, 0.0], [0.0, 0.0, -1.0]])
            if U.determinant() < 0.0:
                U = U @ flip
                S = S @ flip
            if V.determinant() < 0.0:
                V = V @ flip
                S = S @ flip
            s = ti.Vector([S[0, 0], S[1, 1], S[2, 2]])
            cb = 2.0 * mu / ((ic + 1.0) * (ic + 1.0))
            g = ti.Vector([s[1] * s[2], s[0] * s[2], s[0] * s[1]])
            A = ti.Matrix.zero(ti.f64, 3, 3)
            for i, j in ti.static(ti.ndrange(3, 3)):
                A[i, j] = cb * s[i] * s[j] + lam * g[i] * g[j]
                if ti.static(i == j):
                    A[i, j] += ca
                else:
                    A[i, j] += cc * s[3 - i - j]
            ls, Qs = _jacobi_eigen(A)
            for k in range(81):
                out[e, 10 + k] = 0.0
            Vt = V.transpose()
            for m in range(9):
                # modes 0-2: scaling (column m of Qs); 3-5: twist and 6-8: flip about axis k = m % 3
                k = m % 3
                i, j = (k + 1) % 3, (k + 2) % 3
                D = ti.Matrix.zero(ti.f64, 3, 3)
                lam_v = 0.0
                if m < 3:
                    for d in ti.static(range(3)):
                        D[d, d] = Qs[d, m]
                    lam_v = ls[m]
                else:
                    D[i, j] = 0.7071067811865476
                    D[j, i] = -0.7071067811865476
                    lam_v = ca + cc * s[k]
                    if m >= 6:
                        D[j, i] = 0.7071067811865476
                        lam_v = ca - cc * s[k]
                _add_mode(out, e, U @ D @ Vt, lam_v)
            for a in range(9):
                for b in range(a):
                    out[e, 10 + 9 * b + a] = out[e, 10 + 9 * a + b]


def snh_evaluate(F: np.ndarray, mu: float, lam: float, mode: int = HESSIAN
                 ) -> tuple[np.ndarray, np.ndarray | None, np.ndarray | None]:
    """Psi (c,) [J/m^3], P (c, 3, 3) [Pa] (mode >= STRESS, else None) and (dP/dF)_+ (c, 9, 9) [Pa]
    (mode == HESSIAN, else None) at F (c, 3, 3). Requires `init_taichi` first. One kernel launch."""
    c = F.shape[0]
    out = np.empty((c, _WIDTH[mode]))
    snh_kernel(np.ascontiguousarray(F, dtype=np.float64).reshape(c, 9), float(mu), float(lam), out)
    P = out[:, 1:10].reshape(c, 3, 3) if mode >= STRESS else None
    H = out[:, 10:].reshape(c, 9, 9) if mode == HESSIAN else None
    return out[:, 0], P, H

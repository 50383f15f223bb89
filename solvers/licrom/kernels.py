"""Warp kernel of the reduced solver (float64, CPU and CUDA): Stable Neo-Hookean at the cubature tets.

The reduced solver's hot path is the per-cubature-tet evaluation of the energy density Psi(F), the first
Piola-Kirchhoff stress P(F) and the PSD-projected Hessian (dP/dF)_+ at deformation gradients F (c, 3, 3). One
kernel does all three into one packed output array (its width selects how much), so that a call is one launch;
the linear reductions with the constant jacobians B_c = dvec(F_c)/dq are dense matrix products left to BLAS
(solvers/licrom/reduced.py). The kernel shares the SNH functions of the full-space solver (solvers/kernels.py:
the energy density, the cofactor and the analytic eigensystem of dP/dF), and each output mirrors the numpy
reference in solvers/physics/material.py (row-major vec: vec(F)[3 i + j] = F[i, j]) and is tested against it.
Measured on this project's 2-core CPU machine at 60 tets: ~15 us a call for the energy or the stress (mostly the
launch), ~150 us with the Hessian (~2.3 us a tet).
"""

from __future__ import annotations

import numpy as np
import warp as wp

from frictionbench.solvers.kernels import cofactor, snh_eigensystem, snh_mode, snh_psi
from frictionbench.solvers.warp_runtime import RecordedLaunch, init_warp

f64 = wp.float64

ENERGY, STRESS, HESSIAN = 0, 1, 2
"""Evaluation modes: Psi only; Psi and P; Psi, P and (dP/dF)_+."""
_WIDTH = {ENERGY: 1, STRESS: 10, HESSIAN: 91}
"""Columns of the kernel's packed output row per tet: [Psi, vec P (9), vec (dP/dF)_+ (81)]."""
DEVICES = ("cpu", "cuda")
vec9d = wp.types.vector(length=9, dtype=f64)
mat99d = wp.types.matrix(shape=(9, 9), dtype=f64)


@wp.kernel
def snh_kernel(F: wp.array(dtype=wp.mat33d), mu: f64, lam: f64, out: wp.array2d(dtype=f64)):
    """Per tet e: out[e, 0] = Psi(F[e]); if out has >= 10 columns, out[e, 1:10] = vec P; if it has 91,
    out[e, 10:91] = vec (dP/dF)_+ (9x9, row-major): the modes of `snh_eigensystem` with a positive eigenvalue."""
    e = wp.tid()
    Fm = F[e]
    alpha = f64(1.0) + f64(0.75) * mu / lam
    out[e, 0] = snh_psi(Fm, mu, lam, alpha)
    width = out.shape[1]
    if width >= 10:
        ic = wp.ddot(Fm, Fm)
        P = mu * (f64(1.0) - f64(1.0) / (ic + f64(1.0))) * Fm + lam * (wp.determinant(Fm) - alpha) * cofactor(Fm)
        for i in range(3):
            for j in range(3):
                out[e, 1 + 3 * i + j] = P[i, j]
    if width >= 91:
        U, s, V, Qs, ls, ca, cc = snh_eigensystem(Fm, mu, lam, alpha)
        H = mat99d()
        for m in range(9):
            Q, lam_v = snh_mode(U, s, V, Qs, ls, ca, cc, m)
            if lam_v > f64(0.0):
                v = vec9d(Q[0, 0], Q[0, 1], Q[0, 2], Q[1, 0], Q[1, 1], Q[1, 2], Q[2, 0], Q[2, 1], Q[2, 2])
                H += lam_v * wp.outer(v, v)
        for a in range(9):
            for b in range(9):
                out[e, 10 + 9 * a + b] = H[a, b]


def check_device(device: str) -> None:
    """Raise ValueError naming `device` unless the kernel can run there (DEVICES)."""
    if device not in DEVICES:
        raise ValueError(f"device = {device!r}: expected one of {DEVICES}")


_buffers: dict[tuple[int, int, str], tuple[RecordedLaunch, wp.array, wp.array, np.ndarray, np.ndarray]] = {}
"""(tets, width, device) -> the kernel's launch (`RecordedLaunch`), its input and output arrays, allocated once and
reused by every call, and on the CPU their numpy views (on CUDA, None)."""


def snh_evaluate(F: np.ndarray, mu: float, lam: float, mode: int = HESSIAN, device: str = "cpu"
                 ) -> tuple[np.ndarray, np.ndarray | None, np.ndarray | None]:
    """Psi (c,) [J/m^3], P (c, 3, 3) [Pa] (mode >= STRESS, else None) and (dP/dF)_+ (c, 9, 9) [Pa]
    (mode == HESSIAN, else None) at F (c, 3, 3), on `device` ("cpu" or "cuda"). One kernel launch; the results
    are new arrays."""
    check_device(device)
    init_warp()
    c = F.shape[0]
    key = (c, _WIDTH[mode], device)
    if key not in _buffers:
        F_wp, out_wp = wp.empty(c, dtype=wp.mat33d, device=device), wp.empty(key[:2], dtype=f64, device=device)
        views = (F_wp.numpy(), out_wp.numpy()) if device == "cpu" else (None, None)
        _buffers[key] = (RecordedLaunch(snh_kernel, c, [F_wp, 1.0, 1.0, out_wp], device), F_wp, out_wp) + views
    launch, F_wp, out_wp, F_view, out_view = _buffers[key]
    if F_view is None:
        F_wp.assign(np.ascontiguousarray(F, dtype=np.float64))
    else:
        F_view[...] = F
    launch.set(1, float(mu))
    launch.set(2, float(lam))
    launch.launch(c)
    out = out_wp.numpy().copy() if out_view is None else out_view.copy()
    P = out[:, 1:10].reshape(c, 3, 3) if mode >= STRESS else None
    H = out[:, 10:].reshape(c, 9, 9) if mode == HESSIAN else None
    return out[:, 0], P, H

"""Warp kernel of the reduced solver (float64, CPU and CUDA): Stable Neo-Hookean at the cubature tets.

The reduced solver's hot path is the per-cubature-tet evaluation of the energy density Psi(F), the first
Piola-Kirchhoff stress P(F) and the PSD-projected Hessian (dP/dF)_+ at deformation gradients F (c, 3, 3). One
kernel does all three into one packed output array (its width selects how much), so that a call is one launch;
the linear reductions with the constant jacobians B_c = dvec(F_c)/dq are dense matrix products left to BLAS
(solvers/licrom/reduced.py). The Hessian leaves the kernel as a factor, (dP/dF)_+ = L^T L with L (9, 9) the modes
of positive weight as rows (sqrt(l_m) vec(Q_m)): writing the modes costs the kernel less than summing their outer
products, and the reduction then needs one product (L_c B_c) per tet and one symmetric product (G^T G) instead of
two general ones. The kernel shares the SNH functions of the full-space solver (solvers/kernels.py: the energy
density, the cofactor and the analytic eigensystem of dP/dF), and each output mirrors the numpy reference in
solvers/physics/material.py (row-major vec: vec(F)[3 i + j] = F[i, j]) and is tested against it. Measured on this
project's 2-core CPU machine at 60 tets: ~15 us a call for the energy or the stress (mostly the launch), ~100-150 us
with the Hessian factor (~1.5-2.3 us a tet, the machine's speed varying from day to day).
"""

from __future__ import annotations

import numpy as np
import warp as wp

from frictionbench.solvers.kernels import cofactor, snh_eigensystem, snh_mode, snh_psi
from frictionbench.solvers.warp_runtime import RecordedLaunch, init_warp

f64 = wp.float64

ENERGY, STRESS, HESSIAN = 0, 1, 2
"""Evaluation modes: Psi only; Psi and P; Psi, P and the factor L of (dP/dF)_+ = L^T L."""
_WIDTH = {ENERGY: 1, STRESS: 10, HESSIAN: 91}
"""Columns of the kernel's packed output row per tet: [Psi, vec P (9), L (81, row-major)]."""
DEVICES = ("cpu", "cuda")


@wp.kernel
def snh_kernel(F: wp.array(dtype=wp.mat33d), mu: f64, lam: f64, out: wp.array2d(dtype=f64)):
    """Per tet e: out[e, 0] = Psi(F[e]); if out has >= 10 columns, out[e, 1:10] = vec P; if it has 91,
    out[e, 10:91] = L (9x9, row-major) with (dP/dF)_+ = L^T L: row m is sqrt(l_m) vec(Q_m) for the modes (Q_m, l_m)
    of `snh_eigensystem` with a positive weight l_m, zero for the others."""
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
        for m in range(9):
            Q, lam_v = snh_mode(U, s, V, Qs, ls, ca, cc, m)
            w = f64(0.0)
            if lam_v > f64(0.0):
                w = wp.sqrt(lam_v)
            for i in range(3):
                for j in range(3):
                    out[e, 10 + 9 * m + 3 * i + j] = w * Q[i, j]


def check_device(device: str) -> None:
    """Raise ValueError naming `device` unless the kernel can run there (DEVICES)."""
    if device not in DEVICES:
        raise ValueError(f"device = {device!r}: expected one of {DEVICES}")


_buffers: dict[tuple[int, int, str], tuple[RecordedLaunch, wp.array, wp.array, np.ndarray, np.ndarray]] = {}
"""(tets, width, device) -> the kernel's launch (`RecordedLaunch`), its input and output arrays, allocated once and
reused by every call, and on the CPU their numpy views (on CUDA, None)."""


def snh_evaluate(F: np.ndarray, mu: float, lam: float, mode: int = HESSIAN, device: str = "cpu"
                 ) -> tuple[np.ndarray, np.ndarray | None, np.ndarray | None]:
    """Psi (c,) [J/m^3], P (c, 3, 3) [Pa] (mode >= STRESS, else None) and the factor L (c, 9, 9) [sqrt(Pa)] of
    (dP/dF)_+ = L_c^T L_c (row-major vec; mode == HESSIAN, else None) at F (c, 3, 3), on `device` ("cpu" or
    "cuda"). One kernel launch; the results are new arrays."""
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
    L = out[:, 10:].reshape(c, 9, 9) if mode == HESSIAN else None
    return out[:, 0], P, L

"""Warp kernel of the reduced solver (float64, CPU and CUDA): Stable Neo-Hookean at the cubature tets.

The reduced solver's hot path is the per-cubature-tet evaluation of the energy density Psi(F), the first
Piola-Kirchhoff stress P(F) and the PSD-projected Hessian (dP/dF)_+ at deformation gradients F (c, 3, 3). One
kernel does all three into one packed output array (its width selects how much), so that a call is one launch;
the linear reductions with the constant jacobians B_c = dvec(F_c)/dq are dense matrix products left to BLAS
(solvers/reduced/solver.py). The Hessian leaves the kernel as a factor, (dP/dF)_+ = L^T L with L (9, 9) the modes
of positive weight as rows (sqrt(l_m) vec(Q_m)): writing the modes costs the kernel less than summing their outer
products, and the reduction then needs one product (L_c B_c) per tet and one symmetric product (G^T G) instead of
two general ones. The kernel shares the SNH functions of the full-space solver (solvers/kernels.py: the energy
density, the cofactor and the analytic eigensystem of dP/dF), and each output mirrors the numpy reference in
solvers/physics/material.py (row-major vec: vec(F)[3 i + j] = F[i, j]) and is tested against it. Measured on this
project's 2-core CPU machine at 60 tets: ~15 us a call for the energy or the stress (mostly the launch), ~100-150 us
with the Hessian factor (~1.5-2.3 us a tet, the machine's speed varying from day to day).

The Kelvin-Voigt damping's density, stress and projected density Hessian (solvers/physics/viscosity.py) come from a
second kernel of the same shape (`viscous_evaluate`), its Hessian also as a factor (15 rows: the six distinct rows
of the Green strain's jacobian, and the nine modes of I (x) A_+). A `DensityTerm` names its kernel of this shape
(`TetKernels.cubature`), which `evaluate` launches with its arguments by name.
"""

from __future__ import annotations

from collections.abc import Mapping

import numpy as np
import warp as wp

from frictionbench.solvers.kernels import cofactor, green_strain, snh_eigensystem, snh_mode, snh_psi, sym_eig3
from frictionbench.solvers.warp_runtime import RecordedLaunch, init_warp, kernel_inputs

f64 = wp.float64

ENERGY, STRESS, HESSIAN = 0, 1, 2
"""Evaluation modes: Psi only; Psi and P; Psi, P and the factor L of (dP/dF)_+ = L^T L."""
VISCOUS_ROWS = 15
"""Rows of the viscous kernel's Hessian factor: 6 of the strain jacobian, 9 of I (x) A_+ (`TetKernels.rows`)."""
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


@wp.kernel
def viscous_kernel(F: wp.array(dtype=wp.mat33d), F_bar: wp.array(dtype=wp.mat33d), eta_over_h: f64,
                   out: wp.array2d(dtype=f64)):
    """Kelvin-Voigt per tet e, with A = E(F) - E(F_bar) and c = eta_over_h = eta / h_eff [Pa]: out[e, 0] = c |A|_F^2; if out has
    >= 10 columns, out[e, 1:10] = vec P, P = 2 c F A; if it has more (145), out[e, 10:145] = L (15x9, row-major) with
    L^T L = 2 c (J^T J + I (x) A_+) (`solvers.physics.viscosity.viscous_dpdf`, projected): rows 0-5 sqrt(2 c) times
    the rows of J = dvec E / dvec F for E's entries (0,0), (1,1), (2,2), (0,1), (0,2), (1,2) (the off-diagonal ones
    times sqrt 2: their twins (l, j) are the same row), rows 6 + 3 m + i sqrt(2 c max(lambda_m, 0)) (e_i (x) q_m)
    for A's eigenpairs (lambda_m, q_m)."""
    e = wp.tid()
    c = eta_over_h
    Fm = F[e]
    A = green_strain(Fm) - green_strain(F_bar[e])
    out[e, 0] = c * wp.ddot(A, A)
    width = out.shape[1]
    if width >= 10:
        P = f64(2.0) * c * Fm * A
        for i in range(3):
            for j in range(3):
                out[e, 1 + 3 * i + j] = P[i, j]
    if width > 10:
        s2c = wp.sqrt(f64(2.0) * c)
        for p in range(6):
            j = p
            l = p
            w = s2c
            if p >= 3:
                j = (p - 3) // 2  # p = 3, 4, 5: (0, 1), (0, 2), (1, 2)
                l = p - 2 - (p - 3) // 2
                w = s2c * wp.sqrt(f64(2.0))
            for i in range(3):
                for k in range(3):
                    v = f64(0.0)
                    if k == l:
                        v += f64(0.5) * Fm[i, j]
                    if k == j:
                        v += f64(0.5) * Fm[i, l]
                    out[e, 10 + 9 * p + 3 * i + k] = w * v
        Q, lam = sym_eig3(A)
        for m in range(3):
            w = wp.sqrt(f64(2.0) * c * wp.max(lam[m], f64(0.0)))
            for i0 in range(3):
                for i in range(3):
                    for j in range(3):
                        v = f64(0.0)
                        if i == i0:
                            v = w * Q[j, m]
                        out[e, 10 + 9 * (6 + 3 * m + i0) + 3 * i + j] = v


def check_device(device: str) -> None:
    """Raise ValueError naming `device` unless the kernel can run there (DEVICES)."""
    if device not in DEVICES:
        raise ValueError(f"device = {device!r}: expected one of {DEVICES}")


_buffers: dict[tuple[str, int, int, str], tuple] = {}
"""(kernel, tets, width, device) -> its launch (`RecordedLaunch`), its input arrays by name and output array,
allocated once and reused by every call, and on the CPU their numpy views by name (on CUDA, None)."""


def width(mode: int, rows: int) -> int:
    """Columns of a cubature kernel's packed output row per tet in `mode`: [density] (ENERGY), [density, vec P]
    (STRESS), [density, vec P, L (rows x 9, row-major)] (HESSIAN)."""
    return (1, 10, 10 + 9 * rows)[mode]


def evaluate(kernel: wp.Kernel, inputs: Mapping[str, np.ndarray], scalars: Mapping[str, float], mode: int,
             rows: int, device: str) -> tuple[np.ndarray, np.ndarray | None, np.ndarray | None]:
    """One launch of a cubature kernel (a `solvers.physics.terms.TetKernels.cubature`: one thread per tet, its
    packed output row in `out`) with its arguments by name: the (c, 3, 3) arrays of `inputs` (F, and F_bar where it
    takes it), the scalars it takes of `scalars` and an output of `width(mode, rows)` columns. Returns its first
    column (c,), vec P (c, 3, 3) from STRESS on and the Hessian factor (c, rows, 9) in HESSIAN (else None); new
    arrays."""
    check_device(device)
    init_warp()
    c = next(iter(inputs.values())).shape[0]
    cols = width(mode, rows)
    key = (kernel.key, c, cols, device)
    if key not in _buffers:
        arrays = {name: wp.empty(c, dtype=wp.mat33d, device=device) for name in inputs}
        out_wp = wp.empty((c, cols), dtype=f64, device=device)
        views = {name: a.numpy() for name, a in [*arrays.items(), ("out", out_wp)]} if device == "cpu" else None
        launch = RecordedLaunch(kernel, c, kernel_inputs(kernel, {**scalars, **arrays, "out": out_wp}, kernel.key),
                                device)
        _buffers[key] = launch, arrays, out_wp, views
    launch, arrays, out_wp, views = _buffers[key]
    for name, a in inputs.items():
        if views is None:
            arrays[name].assign(np.ascontiguousarray(a, dtype=np.float64))
        else:
            views[name][...] = a
    for index, label in enumerate(launch.labels):
        if label in scalars:
            launch.set(index, float(scalars[label]))
    launch.launch(c)
    out = out_wp.numpy().copy() if views is None else views["out"].copy()
    P = out[:, 1:10].reshape(c, 3, 3) if cols >= 10 else None
    L = out[:, 10:].reshape(c, rows, 9) if cols > 10 else None
    return out[:, 0], P, L


def snh_evaluate(F: np.ndarray, mu: float, lam: float, mode: int = HESSIAN, device: str = "cpu"
                 ) -> tuple[np.ndarray, np.ndarray | None, np.ndarray | None]:
    """Psi (c,) [J/m^3], P (c, 3, 3) [Pa] (mode >= STRESS, else None) and the factor L (c, 9, 9) [sqrt(Pa)] of
    (dP/dF)_+ = L_c^T L_c (row-major vec; mode == HESSIAN, else None) at F (c, 3, 3), on `device` ("cpu" or
    "cuda"). One kernel launch; the results are new arrays."""
    return evaluate(snh_kernel, {"F": F}, {"mu": mu, "lam": lam}, mode, 9, device)


def viscous_evaluate(F: np.ndarray, F_bar: np.ndarray, c: float, mode: int = HESSIAN, device: str = "cpu"
                     ) -> tuple[np.ndarray, np.ndarray | None, np.ndarray | None]:
    """Kelvin-Voigt at F against F_bar (c, 3, 3) with c = eta / h_eff [Pa]: the density (c,) [J/m^3], P (c, 3, 3)
    [Pa] (mode >= STRESS, else None) and the factor L (c, 15, 9) [sqrt(Pa)] of the projected density Hessian
    2 c (J^T J + I (x) A_+) = L_c^T L_c (mode == HESSIAN, else None); `viscous_kernel`. One launch; new arrays."""
    return evaluate(viscous_kernel, {"F": F, "F_bar": F_bar}, {"eta_over_h": c}, mode, VISCOUS_ROWS, device)

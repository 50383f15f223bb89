"""The kernels' 3x3 linear algebra (`solvers.kernels.sym_eig3`, `svd3_rotations`) against numpy's LAPACK on
generic, near-rest, degenerate, inverted, flat, rank-one and zero matrices: backward stable, orthonormal factors,
the singular values' order and the inversion's sign."""

from __future__ import annotations

import numpy as np
import pytest
import warp as wp

from frictionbench.solvers.kernels import svd3_rotations, sym_eig3
from frictionbench.solvers.warp_runtime import init_warp

init_warp()

TOL = 1e-13  # relative to the matrix's largest entry: a few ulps of the sums of three products


@wp.kernel
def _svd(F: wp.array(dtype=wp.mat33d), U: wp.array(dtype=wp.mat33d), s: wp.array(dtype=wp.vec3d),
         V: wp.array(dtype=wp.mat33d)):
    e = wp.tid()
    u, sv, v = svd3_rotations(F[e])
    U[e] = u
    s[e] = sv
    V[e] = v


@wp.kernel
def _eig(A: wp.array(dtype=wp.mat33d), Q: wp.array(dtype=wp.mat33d), lam: wp.array(dtype=wp.vec3d)):
    e = wp.tid()
    q, lv = sym_eig3(A[e])
    Q[e] = q
    lam[e] = lv


def _rotations(rng: np.random.Generator, n: int) -> np.ndarray:
    q, _ = np.linalg.qr(rng.standard_normal((n, 3, 3)))
    return q * np.sign(np.linalg.det(q))[:, None, None]


def _cases() -> dict[str, np.ndarray]:
    rng, n = np.random.default_rng(11), 64

    def with_singular_values(s: list[float]) -> np.ndarray:
        return _rotations(rng, n) @ np.diag(s) @ _rotations(rng, n).transpose(0, 2, 1)

    return {"generic": rng.standard_normal((n, 3, 3)),
            "near rest, rotated": _rotations(rng, n) @ (np.eye(3) + 1e-3 * rng.standard_normal((n, 3, 3))),
            "a rotation": _rotations(rng, n),
            "two equal": with_singular_values([1.3, 1.3, 0.6]),
            "inverted": with_singular_values([1.1, 0.8, -0.3]),
            "flat": with_singular_values([1.0, 0.4, 1e-10]),
            "rank one": with_singular_values([2.0, 0.0, 0.0]),
            "zero": np.zeros((n, 3, 3))}


def _run(kernel: wp.Kernel, A: np.ndarray, outputs: list) -> list[np.ndarray]:
    arrays = [wp.zeros(A.shape[0], dtype=t, device="cpu") for t in outputs]
    wp.launch(kernel, A.shape[0], inputs=[wp.array(A, dtype=wp.mat33d, device="cpu")], outputs=arrays, device="cpu")
    return [a.numpy() for a in arrays]


def _orthonormal(Q: np.ndarray) -> float:
    return float(np.abs(Q.transpose(0, 2, 1) @ Q - np.eye(3)).max())


@pytest.mark.parametrize("name", list(_cases()))
def test_the_rotation_variant_svd_is_backward_stable_with_rotations_and_the_inversion_in_the_last_value(
        name: str) -> None:
    F = _cases()[name]
    scale = max(float(np.abs(F).max()), 1.0)
    U, s, V = _run(_svd, F, [wp.mat33d, wp.vec3d, wp.mat33d])
    assert np.abs(U @ (s[:, :, None] * V.transpose(0, 2, 1)) - F).max() <= TOL * scale
    assert _orthonormal(U) <= TOL and _orthonormal(V) <= TOL
    assert np.allclose(np.linalg.det(U), 1.0, atol=TOL) and np.allclose(np.linalg.det(V), 1.0, atol=TOL)
    assert np.abs(np.abs(s) - np.linalg.svd(F, compute_uv=False)).max() <= TOL * scale
    assert (s[:, 0] >= s[:, 1] - TOL * scale).all() and (s[:, 1] >= np.abs(s[:, 2]) - TOL * scale).all()
    det = np.linalg.det(F)
    clear = np.abs(det) > 1e-8 * scale**3
    assert (np.sign(s[clear, 2]) == np.sign(det[clear])).all()


@pytest.mark.parametrize("name", list(_cases()))
def test_the_symmetric_eigendecomposition_is_backward_stable_and_orthonormal(name: str) -> None:
    F = _cases()[name]
    A = F + F.transpose(0, 2, 1)
    scale = max(float(np.abs(A).max()), 1.0)
    Q, lam = _run(_eig, A, [wp.mat33d, wp.vec3d])
    assert np.abs(Q @ (lam[:, :, None] * Q.transpose(0, 2, 1)) - A).max() <= TOL * scale
    assert _orthonormal(Q) <= TOL
    assert np.abs(np.sort(lam, axis=1) - np.linalg.eigvalsh(A)).max() <= TOL * scale

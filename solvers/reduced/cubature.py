"""Cubature of the reduced elastic energy: which tets are evaluated online, and with which weights.

The reduced elastic energy sum_e V_e Psi(F_e(q)) over all m tets is approximated by sum_c w_c V_c Psi(F_c(q))
over a few cubature tets c (docs/solvers.md, "Cubature"). A cubature is a pair `(ids, weights)`: tet indices (c,) into
`model.tets` and dimensionless weights (c,) multiplying V_c Psi(F_c); every tet with weight 1 is exact.

- `all_tets`: every tet, weight 1 (exact; the reference for the other two).
- `uniform_cubature`: uniformly random tets with one common weight preserving the total volume (the LiCROM code).
- `optimized_cubature`: An, Kim & James 2008 -- greedy selection on training forces with non-negative least
  squares weights. Measured (block and cheese coarse, a 20-column smooth basis: affine + random quadratic
  fields, 40 random training states with principal stretches mostly within 10-15% of 1): 20 / 30 / 50 optimised
  tets fit the training forces to a relative error of 3% / 1.5% / 0.5-0.8%; uniform cubature of the same sizes
  stays at 20-40% (tests/test_reduced.py checks this, also on held-out states).
"""

from __future__ import annotations

import numpy as np
from scipy.optimize import nnls
from tqdm import tqdm

from frictionbench.solvers.model import Model
from frictionbench.solvers.physics.material import deformation_gradient, shape_gradients, snh_pk1

Cubature = tuple[np.ndarray, np.ndarray]
"""(tet ids (c,) int64, weights (c,) float64)."""


def deformation_jacobians(model: Model, W: np.ndarray, ids: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Constant parts of F_c(q) = F_c(0) + dF_c/dq q for the tets `ids` (c,) and the basis W (n, 3, r).

    Returns F0 (c, 3, 3), the deformation gradient of the rest mesh (the identity up to round-off), and
    B (c, 9, r) with B[c, 3 i + j, k] = d F_c[i, j] / d q_k = sum_a W[tet_a, i, k] g_a[j] [1/m per unit q]
    (F = sum_a x_a g_a^T, g_a the shape gradients).
    """
    tets, Dm_inv = model.tets[ids], model.Dm_inv[ids]
    F0 = deformation_gradient(model.X, tets, Dm_inv)
    B = np.einsum("caik,caj->cijk", W[tets], shape_gradients(Dm_inv))
    return F0, np.ascontiguousarray(B.reshape(len(ids), 9, W.shape[2]))


def all_tets(model: Model) -> Cubature:
    """Every tet with weight 1: the exact elastic energy."""
    m = model.tets.shape[0]
    return np.arange(m, dtype=np.int64), np.ones(m)


def uniform_cubature(model: Model, count: int, seed: int = 0) -> Cubature:
    """`count` distinct tets drawn uniformly at random, all with the weight (total volume) / (their volume), so
    that sum_c w_c V_c equals the mesh volume."""
    m = model.tets.shape[0]
    if not 1 <= count <= m:
        raise ValueError(f"cubature count {count} outside [1, {m}] (the mesh has {m} tets)")
    ids = np.sort(np.random.default_rng(seed).choice(m, size=count, replace=False)).astype(np.int64)
    return ids, np.full(count, model.vol.sum() / model.vol[ids].sum())


def tet_force_columns(model: Model, W: np.ndarray, training_q: np.ndarray, ids: np.ndarray) -> np.ndarray:
    """Each tet's contribution to the reduced elastic forces at the training states, (S r, c) [N per unit q].

    Column c stacks V_c B_c^T vec P(F_c(q_s)) over the samples s = 0..S-1 of training_q (S, r); the reduced
    elastic force of a cubature (ids, w) at all samples is columns @ w. Memory: S r c floats.
    """
    F0, B = deformation_jacobians(model, W, ids)
    S, r = training_q.shape
    F = F0[:, None] + (B @ training_q.T).transpose(0, 2, 1).reshape(len(ids), S, 3, 3)
    P = snh_pk1(F, model.mu_snh, model.lam_snh).reshape(len(ids), S, 9)
    cols = model.vol[ids][:, None, None] * np.matmul(P, B)  # (c, S, r)
    return cols.reshape(len(ids), S * r).T


def _normalised_targets(columns: np.ndarray, S: int) -> tuple[np.ndarray, np.ndarray]:
    """Rows scaled so that every training sample's exact force has unit norm (An et al.: each pose counts
    equally); samples with zero force (the rest state) are dropped. Returns (columns, targets)."""
    b = columns.sum(axis=1).reshape(S, -1)
    norms = np.linalg.norm(b, axis=1)
    keep = norms > 1e-12 * max(norms.max(), 1e-300)
    scale = np.repeat(np.where(keep, 1.0 / np.where(keep, norms, 1.0), 0.0), b.shape[1])
    rows = np.repeat(keep, b.shape[1])
    return columns[rows] * scale[rows, None], (b.ravel() * scale)[rows]


def cubature_force_error(model: Model, W: np.ndarray, training_q: np.ndarray, cubature: Cubature) -> float:
    """Relative error of the cubature's reduced elastic forces on the training states: |A w - b| / |b| with
    every sample's exact force b_s (all tets, weight 1) normalised to unit norm."""
    ids, w = cubature
    cols = tet_force_columns(model, W, training_q, np.arange(model.tets.shape[0]))
    A, b = _normalised_targets(cols, training_q.shape[0])
    return float(np.linalg.norm(A[:, ids] @ w - b) / np.linalg.norm(b))


def optimized_cubature(model: Model, W: np.ndarray, training_q: np.ndarray, count: int, seed: int = 0,
                       candidates: int | None = None, rel_tol: float = 1e-6, progress: bool = False) -> Cubature:
    """Greedy cubature of An, Kim & James (2008) on the training states training_q (S, r).

    Targets: the exact reduced elastic forces W^T f_el(q_s) of every sample (each normalised to unit norm);
    each tet's contribution is one column (`tet_force_columns`). Each round adds the tet whose column is best
    aligned with the current residual (among `candidates` random unselected tets, all if None), then refits
    all weights by non-negative least squares (scipy.optimize.nnls). Stops after `count` rounds or when the
    relative residual is below rel_tol. Tets left with weight 0 are dropped, so fewer than `count` may
    come back. Cost: S r m floats of memory, `count` NNLS solves of size (S r, <= count) (minutes at r = 84 and
    210 tets on the coarse cheese); `progress`: a bar over the rounds.
    """
    m = model.tets.shape[0]
    if not 1 <= count <= m:
        raise ValueError(f"cubature count {count} outside [1, {m}] (the mesh has {m} tets)")
    rng = np.random.default_rng(seed)
    A, b = _normalised_targets(tet_force_columns(model, W, training_q, np.arange(m)), training_q.shape[0])
    col_norm = np.maximum(np.linalg.norm(A, axis=0), 1e-300)
    selected: list[int] = []
    w = np.zeros(0)
    residual = b.copy()
    b_norm = np.linalg.norm(b)
    for _ in tqdm(range(count), desc=f"cubature r={W.shape[2]}", unit="tet", disable=not progress, leave=False):
        free = np.setdiff1d(np.arange(m), selected)
        if candidates is not None and candidates < free.size:
            free = rng.choice(free, size=candidates, replace=False)
        selected.append(int(free[np.argmax(A[:, free].T @ residual / col_norm[free])]))
        w, _ = nnls(A[:, selected], b)
        residual = b - A[:, selected] @ w
        if np.linalg.norm(residual) <= rel_tol * b_norm:
            break
    ids, w = np.asarray(selected, dtype=np.int64), np.asarray(w)
    order = np.argsort(ids)
    keep = w[order] > 0.0
    return ids[order][keep], w[order][keep]

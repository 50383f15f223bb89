"""Carry a trajectory from one mesh to another mesh of the same shape (for error metrics across resolutions).

The displacement field of the source trajectory is piecewise linear on its rest tets; it is evaluated at the
target mesh's rest vertices by barycentric interpolation in the source tet that contains each vertex. Target
vertices outside the source mesh (the two discretisations of a curved boundary differ slightly) take the
barycentric extrapolation of the nearest candidate tet, clamped to its face: the closest point of the source body.
"""

from __future__ import annotations

import numpy as np
from scipy.spatial import cKDTree

from frictionbench.solvers.trajectory import Trajectory


def barycentric_weights(X_src: np.ndarray, tets: np.ndarray, points: np.ndarray, candidates: int = 16
                        ) -> tuple[np.ndarray, np.ndarray]:
    """For each point (p, 3), the source tet (p,) holding it (or the best of its `candidates` nearest tets by
    centroid) and its barycentric weights (p, 4), clamped to be non-negative and renormalised."""
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


def transfer_to_mesh(traj: Trajectory, target: Trajectory) -> Trajectory:
    """`traj` re-expressed on `target`'s mesh: x = X_target + interpolated displacement, same frames."""
    tet, w = barycentric_weights(traj.X, traj.tets, target.X)
    idx = traj.tets[tet]  # (p, 4)
    u = traj.x - traj.X[None]
    x = target.X[None] + np.einsum("pk,fpkd->fpd", w, u[:, idx])
    v = None if traj.v is None else np.einsum("pk,fpkd->fpd", w, traj.v[:, idx])
    return Trajectory(t=traj.t, x=x, X=target.X, tets=target.tets, surface=target.surface, v=v,
                      meta=dict(traj.meta, transferred_from=f"{len(traj.X)} vertices"))

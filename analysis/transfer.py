"""Carry a trajectory from one mesh to another mesh of the same shape (for error metrics across resolutions).

The displacement field of the source trajectory is piecewise linear on its rest tets; it is evaluated at the
target mesh's rest vertices by barycentric interpolation in the source tet that contains each vertex. Target
vertices outside the source mesh (the two discretisations of a curved boundary differ slightly) take the
barycentric extrapolation of the nearest candidate tet, clamped to its face: the closest point of the source body.
"""

from __future__ import annotations

import numpy as np

from frictionbench.solvers.reduced.bases import barycentric_weights
from frictionbench.solvers.trajectory import Trajectory


def transfer_to_mesh(traj: Trajectory, target: Trajectory) -> Trajectory:
    """`traj` re-expressed on `target`'s mesh: x = X_target + interpolated displacement, same frames."""
    tet, w = barycentric_weights(traj.X, traj.tets, target.X)
    idx = traj.tets[tet]  # (p, 4)
    u = traj.x - traj.X[None]
    x = target.X[None] + np.einsum("pk,fpkd->fpd", w, u[:, idx])
    v = None if traj.v is None else np.einsum("pk,fpkd->fpd", w, traj.v[:, idx])
    return Trajectory(t=traj.t, x=x, X=target.X, tets=target.tets, surface=target.surface, v=v,
                      meta=dict(traj.meta, transferred_from=f"{len(traj.X)} vertices"))

"""Trajectories as ParaView data: one VTU file per frame plus a PVD collection that lists them with their times."""

from __future__ import annotations

import os
from pathlib import Path
from xml.sax.saxutils import quoteattr

import meshio
import numpy as np

from frictionbench.analysis.metrics import vertex_velocities
from frictionbench.scenarios.atomic import write_text_atomic
from frictionbench.solvers.trajectory import Trajectory


def export_vtu_series(traj: Trajectory, out_dir: str | os.PathLike, name: str = "frame") -> Path:
    """Write `{name}_{k:05d}.vtu` for every frame k and `{name}.pvd` into out_dir; returns the PVD path.

    Each VTU holds the deformed mesh (points x_k [m], tetra cells) with point data `displacement` x_k - X [m]
    and `velocity` [m/s] (stored velocities, else finite differences of the frames). The PVD is written last,
    atomically, so an existing PVD never lists a frame file that is not complete.
    """
    out = Path(out_dir)
    out.mkdir(parents=True, exist_ok=True)
    velocity = vertex_velocities(traj)
    cells = [("tetra", np.asarray(traj.tets, dtype=np.int64))]
    entries = []
    for k in range(traj.n_frames):
        file = f"{name}_{k:05d}.vtu"
        meshio.Mesh(points=traj.x[k], cells=cells,
                    point_data={"displacement": traj.x[k] - traj.X, "velocity": velocity[k]}).write(out / file)
        entries.append(f'    <DataSet timestep="{float(traj.t[k])!r}" group="" part="0" file={quoteattr(file)}/>')
    xml = "\n".join(['<?xml version="1.0"?>',
                     '<VTKFile type="Collection" version="0.1" byte_order="LittleEndian">',
                     "  <Collection>", *entries, "  </Collection>", "</VTKFile>", ""])
    return write_text_atomic(out / f"{name}.pvd", xml)


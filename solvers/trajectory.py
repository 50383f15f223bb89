"""Trajectories: what every solver produces and every metric reads.

Stored as one `.npz` per run, written atomically (a temporary file renamed into place), so a run that dies
never leaves a half-written trajectory behind, and uncompressed: zlib shrinks float64 frames by 2-12% (measured on
this project's stores: a reduced run's 6.4 MB to 6.3, a full-space ladder level's 12.8 MB to 11.3) at ~45 ms of CPU
a MB, which the matrix's client would spend beside workers whose steps are being timed (a reduced run's steps take
about as long as compressing its frames).
"""

from __future__ import annotations

import json
import os
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np

from frictionbench.scenarios.atomic import atomic_open


@dataclass
class Trajectory:
    """Stored frames of one simulation.

    t: (F,) frame times [s].
    x: (F, n, 3) vertex positions [m].
    X: (n, 3) rest positions [m].
    tets: (m, 4) vertex indices of the tetrahedra.
    surface: (k, 3) boundary triangles (outward orientation).
    v: (F, n, 3) vertex velocities [m/s], optional.
    q: (F, r) latent coordinates of a reduced solver, optional.
    basis: (n, 3, r) that solver's subspace (x = X + basis q) [m per unit q], optional.
    meta: JSON-serialisable provenance (scenario name, solver, parameters, seeds).
    """

    t: np.ndarray
    x: np.ndarray
    X: np.ndarray
    tets: np.ndarray
    surface: np.ndarray
    v: np.ndarray | None = None
    q: np.ndarray | None = None
    basis: np.ndarray | None = None
    meta: dict = field(default_factory=dict)

    @property
    def n_frames(self) -> int:
        """Number of stored frames F."""
        return int(self.t.shape[0])

    def until(self, t_end: float) -> Trajectory:
        """The frames at times t <= t_end [s] (the same arrays sliced, not copied)."""
        n = int(np.searchsorted(self.t, t_end, side="right"))
        return Trajectory(t=self.t[:n], x=self.x[:n], X=self.X, tets=self.tets, surface=self.surface,
                          v=None if self.v is None else self.v[:n], q=None if self.q is None else self.q[:n],
                          basis=self.basis, meta=self.meta)

    def save(self, path: str | os.PathLike) -> Path:
        """Write to `path` (.npz, uncompressed; see the module docstring) atomically; returns the path."""
        arrays = {"t": self.t, "x": self.x, "X": self.X, "tets": self.tets, "surface": self.surface}
        if self.v is not None:
            arrays["v"] = self.v
        if self.q is not None:
            arrays["q"] = self.q
        if self.basis is not None:
            arrays["basis"] = self.basis
        arrays["meta"] = np.array(json.dumps(self.meta, sort_keys=True, default=str))
        with atomic_open(path, "wb") as f:
            np.savez(f, **arrays)
        return Path(path)

    @classmethod
    def load(cls, path: str | os.PathLike) -> "Trajectory":
        """Read a trajectory written by `save`."""
        with np.load(path, allow_pickle=False) as z:
            meta = json.loads(str(z["meta"])) if "meta" in z else {}
            return cls(
                t=z["t"], x=z["x"], X=z["X"], tets=z["tets"], surface=z["surface"],
                v=z["v"] if "v" in z else None, q=z["q"] if "q" in z else None,
                basis=z["basis"] if "basis" in z else None, meta=meta,
            )


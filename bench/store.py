"""The results store: one folder per (scenario, solver, settings) run, keyed by a hash, written atomically.

A run folder holds `trajectory.npz` (with a reduced run's basis) and `stats.json`; it counts as done only once
`stats.json` exists (written last), so an interrupted run is simply redone and a rerun recomputes only what is
missing. Only the client writes the store: workers return what they computed (`bench.payload`).
"""

from __future__ import annotations

import hashlib
import json
from functools import lru_cache
from pathlib import Path

from frictionbench.scenarios.atomic import write_json_atomic
from frictionbench.scenarios.load import scenario_to_dict
from frictionbench.scenarios.model import MeshSpec, Scenario
from frictionbench.solvers.trajectory import Trajectory


@lru_cache(maxsize=64)
def mesh_identity(spec: MeshSpec) -> str:
    """What a mesh spec resolves to: a digest of the actual vertices and tets (TetWild does not give the same mesh
    twice, so a recipe does not identify a mesh), or the file path (whose contents the scenario hash covers)."""
    if spec.path:
        return spec.path
    from frictionbench.scenarios.meshes import load_mesh

    return load_mesh(spec).digest()


def run_key(scenario: Scenario, solver: str, params: dict, mesh: MeshSpec | None = None) -> str:
    """Stable key `<solver>-<sha256[:16]>` of what is simulated and how (not of its name); `mesh` overrides the
    scenario's mesh (remeshing)."""
    blob = json.dumps({"scenario": scenario_to_dict(scenario) | {"name": "", "description": "", "tags": []},
                       "mesh": mesh_identity(mesh or scenario.mesh), "mesh_spec": (mesh or scenario.mesh).key,
                       "solver": solver, "params": params}, sort_keys=True, default=str)
    return f"{solver}-{hashlib.sha256(blob.encode()).hexdigest()[:16]}"


class RunStore:
    """Run folders under `root`: `root/<key>/{trajectory.npz, stats.json}`."""

    def __init__(self, root: str | Path) -> None:
        self.root = Path(root)

    def folder(self, key: str) -> Path:
        """The folder of run `key`."""
        return self.root / key

    def done(self, key: str) -> bool:
        """Whether run `key` finished (its stats were written, after its trajectory)."""
        return (self.folder(key) / "stats.json").is_file()

    def save(self, key: str, traj: Trajectory | None, stats: dict) -> Path:
        """Store a run: trajectory first, stats last (the completion marker); each file is written atomically."""
        folder = self.folder(key)
        if traj is not None:
            traj.save(folder / "trajectory.npz")
        write_json_atomic(folder / "stats.json", stats)
        return folder

    def stats(self, key: str) -> dict:
        """The stored stats of run `key` (without loading its trajectory)."""
        return json.loads((self.folder(key) / "stats.json").read_text())

    def load(self, key: str) -> tuple[Trajectory | None, dict]:
        """The stored trajectory (None for a failed run) and stats of run `key`."""
        path = self.folder(key) / "trajectory.npz"
        return (Trajectory.load(path) if path.is_file() else None), self.stats(key)


def load_run_info(out: str | Path) -> dict:
    """The run.json of a results folder (suite, device, variants, ...; written by `bench.runner.run_suite`)."""
    return json.loads((Path(out) / "run.json").read_text())

"""The results store: one folder per (scenario, solver, settings) run, keyed by a hash, written atomically; and the
truth store, the truth ladders' runs kept across results folders.

A run folder holds `trajectory.npz` (with a reduced run's basis) and `stats.json`; it counts as done only once
`stats.json` exists (written last), so an interrupted run is simply redone and a rerun recomputes only what is
missing. Only the client writes the stores: workers return what they computed (`bench.payload`).
"""

from __future__ import annotations

import hashlib
import json
import os
import shutil
import tempfile
from functools import lru_cache
from pathlib import Path

from frictionbench.scenarios.atomic import atomic_open, write_json_atomic
from frictionbench.scenarios.load import scenario_to_dict
from frictionbench.scenarios.spec import MeshSpec, Scenario
from frictionbench.solvers.trajectory import Trajectory
from frictionbench.solvers.version import PHYSICS_VERSION

#: The truth store's folder when none is given: $FRICTIONBENCH_TRUTH_STORE, else `cache_root()/truths`.
TRUTH_STORE_ENV = "FRICTIONBENCH_TRUTH_STORE"


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


class TruthStore:
    """The truth ladders' runs kept for every results folder of this machine: `root/v<PHYSICS_VERSION>-<device>/<key>/`
    with a run folder's files (`RunStore`), keyed by the run's store key (scenario with its step and frames,
    integrator, contact lag, solver, parameters, mesh: `run_key`), the physics version that computed it and the
    device it ran on. A results folder's ladder looks a run up here before computing it and copies it in
    (`fetch`, its stats with `from_truth_store` and its own `timed_in` and timings), and gives this store each run
    it computes (`put`). A run enters whole or not at all (assembled in a temporary folder, then renamed), so
    concurrent writers are safe: the first one's copy stays. `version` (default PHYSICS_VERSION) is for tests; clearing
    the store is deleting `root`."""

    def __init__(self, root: str | Path, device: str, version: int | None = None) -> None:
        self.root = Path(root)
        self.version = PHYSICS_VERSION if version is None else version
        self.shelf = self.root / f"v{self.version}-{device}"

    def folder(self, key: str) -> Path:
        """The folder of run `key`."""
        return self.shelf / key

    def done(self, key: str) -> bool:
        """Whether run `key` is here."""
        return (self.folder(key) / "stats.json").is_file()

    def fetch(self, key: str, into: RunStore) -> bool:
        """Copy run `key` into the results store `into` (trajectory first, stats last, each atomically; the stats
        gain `from_truth_store`: true); False when it is not here."""
        if not self.done(key):
            return False
        source = self.folder(key)
        if (source / "trajectory.npz").is_file():
            _copy_atomic(source / "trajectory.npz", into.folder(key) / "trajectory.npz")
        stats = json.loads((source / "stats.json").read_text())
        write_json_atomic(into.folder(key) / "stats.json", stats | {"from_truth_store": True})
        return True

    def put(self, key: str, source: RunStore) -> bool:
        """Keep run `key` of the results store `source` here, unless it is here already, failed, or was computed by
        another physics version than this store's (its stats' `physics_version`, which runs from before the truth
        store do not record); returns whether it was added."""
        stats = source.stats(key)
        if self.done(key) or stats.get("failed") or stats.get("physics_version") != self.version:
            return False
        self.shelf.mkdir(parents=True, exist_ok=True)
        tmp = Path(tempfile.mkdtemp(dir=self.shelf, prefix=f".{key}.", suffix=".tmp"))
        try:
            if (source.folder(key) / "trajectory.npz").is_file():
                shutil.copyfile(source.folder(key) / "trajectory.npz", tmp / "trajectory.npz")
            write_json_atomic(tmp / "stats.json", {k: v for k, v in stats.items() if k != "from_truth_store"})
            os.chmod(tmp, 0o755)
            os.rename(tmp, self.folder(key))
        except OSError:  # another writer's copy arrived first (a folder is renamed only onto a missing one)
            if self.done(key):
                return False
            raise
        finally:
            shutil.rmtree(tmp, ignore_errors=True)
        return True


def truth_store_root(path: str | Path | None = None) -> Path:
    """The truth store's folder: `path` where given, else $FRICTIONBENCH_TRUTH_STORE, else `cache_root()/truths`
    (`solvers.warp_runtime.cache_root`: $FRICTIONBENCH_CACHE, else ~/.cache/frictionbench)."""
    if path is not None:
        return Path(path)
    if os.environ.get(TRUTH_STORE_ENV):
        return Path(os.environ[TRUTH_STORE_ENV])
    from frictionbench.solvers.warp_runtime import cache_root  # here: warp is imported only where it is needed

    return cache_root() / "truths"


def _copy_atomic(source: Path, target: Path) -> None:
    """Copy the file `source` onto `target` atomically (`scenarios.atomic.atomic_open`)."""
    with source.open("rb") as f, atomic_open(target, "wb") as out:
        shutil.copyfileobj(f, out)


def load_run_info(out: str | Path) -> dict:
    """The run.json of a results folder (suite, device, variants, ...; written by `bench.runner.run_suite`)."""
    return json.loads((Path(out) / "run.json").read_text())

"""The matrix on a real Dask cluster whose workers share no filesystem with the client.

Marked `cluster`: each test starts a `dask scheduler` and `dask worker` processes; every worker runs in its own
mount namespace (`unshare --mount`) with a private tmpfs over the client's temporary folder (which holds the
client's output folder) and another over the client's cache, so it can neither read nor write what the client
sees; the tests check that isolation before relying on it. Needs root (CI and the development machines run as
root) and about 2 minutes on 2 cores.
"""

from __future__ import annotations

import json
import os
import signal
import subprocess
import sys
import threading
import time
from collections.abc import Callable, Iterator
from pathlib import Path

import numpy as np
import pandas as pd
import pytest

from frictionbench.bench.runner import Task, Variant, run_suite, run_tasks
from frictionbench.bench.store import RunStore
from frictionbench.bench.matrix import variant_set
from frictionbench.scenarios.suites import load_suite
from frictionbench.solvers.trajectory import Trajectory
from frictionbench.solvers.warp_runtime import cache_root

from scenes import block_drop, mu_axis, suite_tables, write_toml

pytestmark = pytest.mark.cluster

REPO = Path(__file__).resolve().parents[1]
# the worker's commands: hide the client's folders behind private tmpfs mounts, keep a copy of the compiled
# kernels (software, not results), then start the worker with its own cache and temporary folder
WORKER_SHELL = """set -e
mount -t tmpfs tmpfs "$HIDE"
mkdir -p "$PRIV/cache" "$PRIV/tmp"
if [ -d "$CLIENT_CACHE/warp" ]; then cp -a "$CLIENT_CACHE/warp" "$PRIV/cache/"; fi
if [ -d "$CLIENT_CACHE" ]; then mount -t tmpfs tmpfs "$CLIENT_CACHE"; fi
exec "$PYTHON" -m distributed.cli.dask_worker "$ADDRESS" --nthreads 1 --no-nanny --name "$NAME" \\
  --local-directory "$PRIV/tmp" --no-dashboard
"""


def _hidden_root(tmp_path: Path) -> Path:
    """What a worker's private tmpfs covers: all of /tmp when the code and the interpreter live elsewhere, else
    the test's own temporary folder (which holds the client's output)."""
    tmp = Path("/tmp").resolve()
    inside = [p for p in (REPO, Path(sys.prefix).resolve(), Path(sys.base_prefix).resolve()) if p.is_relative_to(tmp)]
    return tmp if tmp_path.resolve().is_relative_to(tmp) and not inside else tmp_path.resolve()


class Cluster:
    """A scheduler and isolated workers, as subprocesses (see the module docstring)."""

    def __init__(self, tmp_path: Path) -> None:
        self.tmp_path = tmp_path
        self.workers: dict[str, subprocess.Popen] = {}
        scheduler_file = tmp_path / "scheduler.json"
        self.scheduler = subprocess.Popen(
            [sys.executable, "-m", "distributed.cli.dask_scheduler", "--host", "127.0.0.1", "--port", "0",
             "--no-dashboard", "--scheduler-file", str(scheduler_file)],
            stdout=subprocess.DEVNULL, stderr=subprocess.DEVNULL, start_new_session=True)
        deadline = time.time() + 60
        while not scheduler_file.is_file() and time.time() < deadline:
            time.sleep(0.1)
        self.address = json.loads(scheduler_file.read_text())["address"]

    def start_workers(self, n: int) -> None:
        """Start `n` isolated workers and wait until they joined."""
        from dask.distributed import Client

        hide = _hidden_root(self.tmp_path)
        for i in range(n):
            name = f"w{i}"
            env = os.environ | {"HIDE": str(hide), "PRIV": str(hide / f"worker-{name}"),
                                "CLIENT_CACHE": str(cache_root().resolve()), "PYTHON": sys.executable,
                                "ADDRESS": self.address, "NAME": name,
                                "FRICTIONBENCH_CACHE": str(hide / f"worker-{name}" / "cache"),
                                "TMPDIR": str(hide / f"worker-{name}" / "tmp"),
                                "PYTHONPATH": os.pathsep.join(filter(None, [str(REPO), os.environ.get("PYTHONPATH")]))}
            self.workers[name] = subprocess.Popen(
                ["unshare", "--mount", "--propagation", "private", "sh", "-c", WORKER_SHELL], env=env,
                stdout=subprocess.DEVNULL, stderr=subprocess.DEVNULL, start_new_session=True)
        with Client(self.address, timeout=60) as client:
            client.wait_for_workers(n, timeout=180)

    def kill(self, name: str) -> None:
        """SIGKILL a worker (its whole process group)."""
        os.killpg(self.workers[name].pid, signal.SIGKILL)
        self.workers[name].wait()

    def close(self) -> None:
        """Stop every process this cluster started."""
        for proc in [*self.workers.values(), self.scheduler]:
            if proc.poll() is None:
                os.killpg(proc.pid, signal.SIGKILL)
                proc.wait()


@pytest.fixture
def cluster(tmp_path: Path, monkeypatch: pytest.MonkeyPatch) -> Iterator[Callable[[int], Cluster]]:
    """start(n) -> a cluster of n isolated workers, which `--executor dask` runs use (FRICTIONBENCH_DASK_SCHEDULER)."""
    started: list[Cluster] = []

    def start(n: int) -> Cluster:
        c = Cluster(tmp_path)
        started.append(c)
        c.start_workers(n)
        monkeypatch.setenv("FRICTIONBENCH_DASK_SCHEDULER", c.address)
        return c

    yield start
    for c in started:
        c.close()


def assert_isolated(address: str, client_folder: Path) -> None:
    """The workers see none of `client_folder` (an existing, non-empty folder of the client's), and what they write
    at its path does not reach the client."""
    from dask.distributed import Client

    mine = set(os.listdir(client_folder))
    assert mine
    probe = client_folder / "written-by-a-worker"
    with Client(address) as client:
        seen = client.run(lambda path: os.listdir(path) if os.path.isdir(path) else [], str(client_folder))
        client.run(os.makedirs, str(probe))
    assert len(seen) >= 2 and all(not mine & set(listing) for listing in seen.values()), seen  # its own files only
    assert not probe.exists()


def _trajectory_arrays(traj: Trajectory) -> dict[str, np.ndarray]:
    return {k: getattr(traj, k) for k in ("t", "x", "X", "tets", "surface", "v", "q", "basis") if getattr(traj, k) is not None}


#: Columns that differ between two runs of the same computation: timings, and when the results were written
NOT_REPEATABLE = {"setup_s", "warmup_s", "train_s", "step_ms_median", "step_ms_p95", "speedup", "timestamp_utc",
                  "wall_s_per_sim_s", "speedup_equal_accuracy"}


def test_isolated_workers_reproduce_a_process_pool_run(tmp_path, cluster):
    """The quick-undamped suite's references (one training member, the held-out one) and two reduced variants (a LiCROM
    checkpoint and a POD basis, both trained on the client and carried to the workers): the client's store gets
    every run, identical to a process-pool run's (trajectories, bases, metrics). The full-space runs are bitwise
    equal (MKL's reproducible mode, `solvers.linalg`); a reduced run's dense products (torch evaluating the neural
    field's basis, BLAS) may round differently in a worker whose thread pools Dask's nanny started single-threaded
    than in one limited at run time, so its basis and states are compared to round-off (1e-12 of their size)."""
    variants = [Variant("licrom", variant_set("licrom")[0].params | {"epochs": 2}, label="r20"), Variant("pod", {"r": 8}, label="r8")]
    only = "quick-undamped/p[14]_mu0.[13]"  # p1_mu0.1 (train) and p4_mu0.3 (test)
    # without the truth ladder: its runs are full-space runs like the references, through the same tasks
    local = pd.read_csv(run_suite("quick-undamped", tmp_path / "process", variants, jobs=2, executor="process",
                                  report=False, only=only, with_truth=False))
    c = cluster(2)  # after the local run: the workers start with a copy of its compiled kernels
    assert_isolated(c.address, tmp_path)
    remote = pd.read_csv(run_suite("quick-undamped", tmp_path / "dask", variants, jobs=2, executor="dask", report=False,
                                   only=only, with_truth=False))
    assert len(remote) == len(local) == 2 * 3 and (remote["status"] == "ok").all()
    local, remote = (df.set_index(["scenario", "variant"]).sort_index() for df in (local, remote))
    assert list(remote.index) == list(local.index)
    stores = {"process": RunStore(tmp_path / "process" / "runs"), "dask": RunStore(tmp_path / "dask" / "runs")}
    for index in local.index:
        (a, a_stats), (b, b_stats) = (stores[s].load(df.loc[index, "run"]) for s, df in
                                      (("process", local), ("dask", remote)))
        arrays_a, arrays_b = _trajectory_arrays(a), _trajectory_arrays(b)
        assert arrays_a.keys() == arrays_b.keys()
        for k in arrays_a:
            if index[1] == "reference" or k not in ("x", "v", "q", "basis"):
                assert np.array_equal(arrays_a[k], arrays_b[k]), (index, k)
            else:
                scale = np.abs(arrays_a[k]).max() + 1.0
                assert np.abs(arrays_a[k] - arrays_b[k]).max() <= 1e-12 * scale, (index, k)
        assert (a.basis is None) == (b.basis is None) == (index[1] == "reference"), index
    assert remote["proj_rmse_rel"].notna().sum() == 4  # the reduced rows' projection error, from the stored bases
    compared = [c for c in local.columns if c not in NOT_REPEATABLE | {"run"}]  # a model's key has its path
    pd.testing.assert_frame_equal(remote[compared], local[compared])


KILL_SUITE = suite_tables("kill", block_drop(duration=6.0), mu_axis(0.1, 0.2, 0.3, 0.4),
                          description="four block drops of a few seconds each")


def test_a_worker_killed_mid_task_costs_only_that_task(tmp_path, cluster):
    """SIGKILL one of two workers while it computes a run: the matrix completes on the other, every task is
    computed to completion once, and a rerun computes nothing."""
    from dask.distributed import Client

    suite_file = write_toml(tmp_path / "kill.toml", KILL_SUITE)
    tasks = [Task(m.scenario, "full", {}) for m in load_suite(str(suite_file)).scenarios]
    store = RunStore(tmp_path / "out" / "runs")
    c = cluster(2)
    assert_isolated(c.address, tmp_path)
    monitor = Client(c.address)
    monitor.get_task_stream()  # starts the scheduler's record of finished tasks
    killed: dict = {}

    def kill_w0_mid_task() -> None:
        deadline = time.time() + 300
        while time.time() < deadline:
            info = monitor.scheduler_info()["workers"]
            w0 = next((addr for addr, w in info.items() if w["name"] == "w0"), None)
            busy = monitor.processing().get(w0) if w0 else None
            if busy:
                time.sleep(0.5)  # well inside its run (600 steps, a few seconds each)
                if monitor.processing().get(w0) == busy:
                    killed["keys"] = busy
                    c.kill("w0")
                    return
            time.sleep(0.05)

    killer = threading.Thread(target=kill_w0_mid_task)
    killer.start()
    try:
        computed = run_tasks(tasks, store, "cpu", jobs=2, executor="dask", desc="kill")
    finally:
        killer.join()
    finished = [t for t in monitor.get_task_stream() if t["key"].startswith("execute")
                and t.get("status", "OK").upper() == "OK"]
    monitor.close()
    assert killed and c.workers["w0"].poll() is not None
    assert computed == len(tasks) == 4 and all(store.done(t.key) for t in tasks)
    assert sorted(t["key"] for t in finished) == sorted({t["key"] for t in finished})  # none twice
    # the lost one rerun: by Dask under its key, or, where the scheduler cancels it instead ("lost dependencies",
    # seen in full test runs), submitted again by run_tasks under a new one; either way four finish, none twice
    assert len(finished) == 4
    marks = {t.key: (store.folder(t.key) / "stats.json").stat().st_mtime_ns for t in tasks}
    assert run_tasks(tasks, store, "cpu", jobs=2, executor="dask", desc="rerun") == 0
    assert marks == {t.key: (store.folder(t.key) / "stats.json").stat().st_mtime_ns for t in tasks}

"""The truth store (`bench.store.TruthStore`): a truth ladder's runs kept across results folders, keyed by the
run's store key, the physics version and the device, reused instead of recomputed, written whole or not at all."""

from __future__ import annotations

import json
import threading
from pathlib import Path

import pandas as pd
import pytest

from frictionbench.bench import store as store_module
from frictionbench.bench.cli import main
from frictionbench.bench.runner import run_suite
from frictionbench.bench.store import RunStore, TruthStore, truth_store_root
from frictionbench.solvers.trajectory import Trajectory
from frictionbench.solvers.version import PHYSICS_VERSION

from scenes import block_drop, mu_axis, suite_tables, write_toml

SUITE = suite_tables("kept", block_drop(clearance=0.005, duration=0.04), mu_axis(0.3),
                     description="one short block drop", truth={"tol": 1e-6, "depth": 2, "integrator": "bdf2"})


@pytest.fixture
def suite_file(tmp_path: Path) -> Path:
    return write_toml(tmp_path / "kept.toml", SUITE)


def _ladder_runs(out: Path) -> pd.DataFrame:
    rows = pd.read_csv(out / "results.csv")
    return rows[rows["ladder"] == "bdf2"].sort_values("ladder_level")


def _file_bytes(store: RunStore, key: str) -> bytes:
    return (store.folder(key) / "trajectory.npz").read_bytes()


def test_a_second_results_folder_takes_its_truth_from_the_store(tmp_path: Path, suite_file: Path,
                                                                private_truth_store: Path):
    """The first run computes its ladder and keeps every level in the truth store (under the physics version and
    the device); a run into another folder copies them in (same trajectory bytes, same stats and timings with
    `from_truth_store`) instead of recomputing, and its rows are the same."""
    first = run_suite(str(suite_file), tmp_path / "a", variants=[], report=False)
    ladder = _ladder_runs(tmp_path / "a")
    assert len(ladder) == 3
    truths = TruthStore(private_truth_store, "cpu")
    assert truths.shelf == private_truth_store / f"v{PHYSICS_VERSION}-cpu"
    assert all(truths.done(k) for k in ladder["run"])
    a, b = RunStore(tmp_path / "a" / "runs"), RunStore(tmp_path / "b" / "runs")
    assert not any(a.stats(k).get("from_truth_store") for k in ladder["run"])
    second = run_suite(str(suite_file), tmp_path / "b", variants=[], report=False)
    for key in ladder["run"]:  # the same bytes, and the same timings: not a recomputed run
        assert _file_bytes(a, key) == _file_bytes(b, key)
        assert b.stats(key) == a.stats(key) | {"from_truth_store": True}
    rows = [pd.read_csv(csv).set_index("run") for csv in (first, second)]
    truth = [c for c in rows[0].columns if c.startswith("truth_")] + ["err_truth"]
    pd.testing.assert_frame_equal(rows[1][truth], rows[0][truth])
    pd.testing.assert_series_equal(rows[1].loc[ladder["run"], "wall_s_per_sim_s"],
                                   rows[0].loc[ladder["run"], "wall_s_per_sim_s"])
    assert json.loads((tmp_path / "b" / "run.json").read_text())["truth_store"] == str(truths.shelf)


def test_another_physics_version_or_device_reuses_nothing(tmp_path: Path, suite_file: Path,
                                                          private_truth_store: Path, monkeypatch):
    """A client of another physics version finds nothing and recomputes; its workers (spawned: this code's
    version) stamp their runs with theirs, which its store does not keep."""
    run_suite(str(suite_file), tmp_path / "a", variants=[], report=False)
    keys = list(_ladder_runs(tmp_path / "a")["run"])
    assert not any(TruthStore(private_truth_store, "cuda").done(k) for k in keys)
    monkeypatch.setattr(store_module, "PHYSICS_VERSION", PHYSICS_VERSION + 1)
    run_suite(str(suite_file), tmp_path / "b", variants=[], report=False)
    b = RunStore(tmp_path / "b" / "runs")
    assert not any(b.stats(k).get("from_truth_store") for k in keys)  # recomputed
    assert all(b.stats(k)["physics_version"] == PHYSICS_VERSION for k in keys)
    assert not any(TruthStore(private_truth_store, "cpu").shelf.parent.glob(f"v{PHYSICS_VERSION + 1}-cpu/*"))


def _one_run(tmp_path: Path, name: str, stats: dict, block) -> tuple[RunStore, str]:
    import numpy as np

    store = RunStore(tmp_path / name)
    traj = Trajectory(t=np.array([0.0]), x=block.X[None], X=block.X, tets=block.tets, surface=block.surface)
    store.save("full-0123456789abcdef", traj, stats)
    return store, "full-0123456789abcdef"


def test_only_good_runs_of_this_physics_version_are_kept(tmp_path: Path, block):
    truths = TruthStore(tmp_path / "truths", "cpu")
    for name, stats in (("failed", {"failed": True, "physics_version": PHYSICS_VERSION}),
                        ("old", {"failed": False}), ("other", {"failed": False, "physics_version": -1})):
        source, key = _one_run(tmp_path, name, stats, block)
        assert not truths.put(key, source) and not truths.done(key)
    source, key = _one_run(tmp_path, "good", {"failed": False, "physics_version": PHYSICS_VERSION,
                                              "from_truth_store": True}, block)
    assert truths.put(key, source) and truths.done(key)
    assert json.loads((truths.folder(key) / "stats.json").read_text()) == {"failed": False,
                                                                           "physics_version": PHYSICS_VERSION}
    assert not truths.put(key, source)  # already there: kept as it was


def test_concurrent_writers_leave_one_whole_copy(tmp_path: Path, block):
    """Eight threads keep the same run at once: exactly one adds it, the folder is whole, no temporary is left;
    a fetched copy loads (without pickle) and equals the source."""
    truths = TruthStore(tmp_path / "truths", "cpu")
    sources = [_one_run(tmp_path, f"s{i}", {"failed": False, "physics_version": PHYSICS_VERSION}, block)
               for i in range(8)]
    added: list[bool] = []
    barrier = threading.Barrier(len(sources))

    def put(source: RunStore, key: str) -> None:
        barrier.wait()
        added.append(truths.put(key, source))

    threads = [threading.Thread(target=put, args=s) for s in sources]
    for t in threads:
        t.start()
    for t in threads:
        t.join()
    key = sources[0][1]
    assert sorted(added) == [False] * 7 + [True]
    assert sorted(p.name for p in truths.shelf.iterdir()) == [key]
    assert sorted(p.name for p in truths.folder(key).iterdir()) == ["stats.json", "trajectory.npz"]
    into = RunStore(tmp_path / "into")
    assert truths.fetch(key, into) and not truths.fetch("full-ffffffffffffffff", into)
    traj, stats = into.load(key)
    assert (traj.x == block.X[None]).all() and stats["from_truth_store"] is True


def test_the_truth_store_flags(tmp_path: Path, suite_file: Path, private_truth_store: Path, capsys):
    """--truth-store DIR keeps the ladder there; --no-truth-store reads and writes none; both at once are refused;
    without either, $FRICTIONBENCH_TRUTH_STORE (here the test's own) is the default."""
    assert truth_store_root() == private_truth_store and truth_store_root(tmp_path / "x") == tmp_path / "x"
    mine = tmp_path / "mine"
    assert main(["run", "--suite", str(suite_file), "--solvers", "full", "--out", str(tmp_path / "a"),
                 "--no-report", "--truth-store", str(mine)]) == 0
    keys = list(_ladder_runs(tmp_path / "a")["run"])
    assert all(TruthStore(mine, "cpu").done(k) for k in keys) and not any(private_truth_store.iterdir())
    assert main(["run", "--suite", str(suite_file), "--solvers", "full", "--out", str(tmp_path / "b"),
                 "--no-report", "--no-truth-store"]) == 0
    assert json.loads((tmp_path / "b" / "run.json").read_text())["truth_store"] is None
    assert not any(private_truth_store.iterdir())
    b = RunStore(tmp_path / "b" / "runs")
    assert not any(b.stats(k).get("from_truth_store") for k in keys)
    with pytest.raises(SystemExit) as stop:
        main(["run", "--suite", str(suite_file), "--out", str(tmp_path / "c"), "--truth-store", str(mine),
              "--no-truth-store"])
    assert stop.value.code == 2 and "not allowed with" in capsys.readouterr().err

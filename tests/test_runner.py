"""The matrix runner: results and report, resume after an interruption, gates, and a real Dask cluster."""

from __future__ import annotations

import os
import shutil
from pathlib import Path

import pandas as pd
import pytest

from frictionbench.bench.cli import main, resolve_jobs
from frictionbench.bench.executors import usable_cores
from frictionbench.bench.runner import Task, run_suite, run_tasks
from frictionbench.bench.store import RunStore, load_run_info
from frictionbench.scenarios.errors import ScenarioError
from frictionbench.scenarios.load import scenario_from_dict
from frictionbench.scenarios.suites import load_suite

from scenes import EXPERIMENTS, block_drop, mu_axis, suite_tables, write_toml

SUITE = suite_tables("tiny", block_drop(), mu_axis(0.2, 0.6), description="two short block drops",
                     split={"test": [{"mu": "mu0.6"}]})


@pytest.fixture
def suite_file(tmp_path: Path) -> Path:
    return write_toml(tmp_path / "tiny.toml", SUITE)


def test_run_writes_results_and_resumes_only_what_is_missing(tmp_path, suite_file):
    out = tmp_path / "out"
    csv = run_suite(str(suite_file), out, variants=[], jobs=1)
    results = pd.read_csv(csv)
    assert len(results) == 2 and set(results["variant"]) == {"reference"}
    assert results["finite"].all() and (results["pos_rmse_rel"] == 0).all()
    assert (out / "report.html").is_file()
    runs = sorted((out / "runs").iterdir())
    assert len(runs) == 2
    # simulate an interruption: the second run lost its completion marker (its trajectory may be half-written)
    (runs[1] / "stats.json").unlink()
    (runs[1] / "trajectory.npz").write_bytes(b"truncated")
    before = (runs[0] / "stats.json").stat().st_mtime_ns
    run_suite(str(suite_file), out, variants=[], jobs=1)
    assert (runs[0] / "stats.json").stat().st_mtime_ns == before  # not recomputed
    assert (runs[1] / "stats.json").is_file()  # recomputed
    assert len(pd.read_csv(out / "results.csv")) == 2


def test_gate_exits_non_zero_when_violated(tmp_path, suite_file):
    out = tmp_path / "out"
    run_suite(str(suite_file), out, variants=[], jobs=1, report=False)
    good = tmp_path / "good.toml"
    good.write_text('[[gate]]\nsuite = "tiny"\nvariant = "full/reference"\nmetric = "finite"\nequals = true\n')
    bad = tmp_path / "bad.toml"
    bad.write_text('[[gate]]\nsuite = "tiny"\nvariant = "full/reference"\n'
                   'metric = "step_ms_median"\nmax = 0.0\n')
    assert main(["gate", str(out), "--gates", str(good)]) == 0
    assert main(["gate", str(out), "--gates", str(bad)]) == 1


def test_dask_executor_runs_the_same_tasks(tmp_path, suite_file):
    suite = load_suite(str(suite_file))
    tasks = [Task(m.scenario, "full", {}) for m in suite.scenarios]
    store = RunStore(tmp_path / "runs")
    run_tasks(tasks, store, "cpu", jobs=2, executor="dask", desc="dask")
    assert all(store.done(t.key) for t in tasks)
    traj, stats = store.load(tasks[0].key)
    assert traj.n_frames == 6 and not stats["failed"]


def test_reduced_variants_give_rows_with_speedup_and_remeshing(tmp_path, suite_file):
    from frictionbench.bench.runner import Variant

    variants = [Variant("affine", {}, label="affine12"), Variant("affine", {}, label="affine12-remesh", remesh="alt"),
                Variant("pod", {"r": 4}, label="r4")]
    doubled = [*variants, Variant("affine", {}, label="affine12")]  # a variant given twice runs, and has rows, once
    results = pd.read_csv(run_suite(str(suite_file), tmp_path / "out", variants=doubled, jobs=1, report=False))
    assert len(results) == 2 * 4
    affine = results[results["variant"] == "affine12"]
    assert (affine["speedup"] > 0).all() and affine["pos_rmse_rel"].notna().all()
    assert (affine["proj_rmse_rel"] <= affine["pos_rmse_rel"] + 1e-12).all()  # projection bounds the error
    remeshed = results[results["variant"] == "affine12-remesh"]
    assert (remeshed["mesh"] == "block/coarse_alt").all() and (remeshed["remesh"] == "alt").all()
    assert remeshed["pos_rmse_rel"].notna().all()  # compared with the full run on the other mesh
    pod = results[results["variant"] == "r4"]
    assert pod["pos_rmse_rel"].notna().all() and (pod["status"] == "ok").all()
    assert (pod["train_mesh"] == "block/coarse").all()


def test_two_different_runs_under_one_name_are_refused_before_any_run(tmp_path, suite_file):
    from frictionbench.bench.runner import Variant

    clash = [Variant("pod", {"r": 4}, label="r4"), Variant("pod", {"r": 6}, label="r4")]
    with pytest.raises(ValueError, match="pod variant 'r4' differs"):
        run_suite(str(suite_file), tmp_path / "out", variants=clash, jobs=1, report=False)
    assert not (tmp_path / "out" / "runs").exists() or not any((tmp_path / "out" / "runs").iterdir())


def test_remesh_ratio_divides_by_the_same_model_on_the_same_scenario_on_its_training_mesh():
    from frictionbench.analysis.derived import with_remesh_ratio

    def row(scenario, variant, err, remesh="", model=None, status="ok"):
        return {"scenario": scenario, "solver": "licrom", "variant": variant, "model": model or variant,
                "remesh": remesh, "train_mesh": "cheese/medium", "status": status, "pos_rmse_rel": err}

    rows = with_remesh_ratio([row("a", "m", 0.02), row("b", "m", 0.04), row("a", "m-re", 0.03, "alt", "m"),
                              row("b", "m-re", 0.02, "alt", "m"), row("c", "m", None, status="failed"),
                              row("c", "m-re", 0.01, "alt", "m")])
    ratios = {(r["scenario"], r["variant"]): r.get("remesh_ratio") for r in rows}
    assert ratios[("a", "m-re")] == pytest.approx(1.5) and ratios[("b", "m-re")] == pytest.approx(0.5)
    assert ratios[("c", "m-re")] is None  # its training-mesh run failed: no ratio, and the gate fails
    assert ratios[("a", "m")] is None  # rows on the training mesh carry none


def test_ref_dt_change_is_the_finest_full_space_run_on_the_reference_mesh():
    from frictionbench.analysis.derived import with_ref_dt_change

    def row(scenario, variant, dt, err, solver="full", remesh="", status="ok"):
        return {"scenario": scenario, "solver": solver, "variant": variant, "dt": dt, "pos_rmse_rel": err,
                "remesh": remesh, "status": status}

    rows = with_ref_dt_change([
        row("a", "reference", 0.01, 0.0), row("a", "dt-half", 0.005, 0.2), row("a", "dt-quarter", 0.0025, 0.3),
        row("a", "dt2x", 0.02, 0.4), row("a", "barrier", 0.01, 0.1), row("a", "other-mesh", 0.005, 0.01, remesh="alt"),
        row("a", "r20", 0.005, 0.05, solver="licrom"),
        row("b", "reference", 0.01, 0.0), row("b", "dt-half", 0.005, None, status="failed"), row("b", "r20", 0.01, 0.1),
        row("c", "reference", 0.01, 0.0)])
    change = {(r["scenario"], r["variant"]): r.get("ref_dt_change") for r in rows}
    assert {v for (s, _), v in change.items() if s == "a"} == {0.3}  # every row of a, from its finest dt
    assert all(v is None for (s, _), v in change.items() if s != "a")  # failed or absent: none


def test_full_sweeps_larger_dt_and_other_mesh_are_compared_with_the_reference(tmp_path, suite_file):
    from frictionbench.bench.runner import Variant

    variants = [Variant("full", {}, label="dt2x", dt_scale=2.0), Variant("full", {}, label="dt-half", dt_scale=0.5),
                Variant("full", {}, label="other-mesh", remesh="alt", transfer=True)]
    results = pd.read_csv(run_suite(str(suite_file), tmp_path / "out", variants=variants, jobs=1, report=False))
    dt2 = results[results["variant"] == "dt2x"]
    assert (dt2["dt"] == 0.02).all() and (dt2["frames_compared"] == 3).all()  # t = 0, 0.02, 0.04
    assert (dt2["pos_rmse_rel"] > 0).all() and (dt2["pos_rmse_rel"] < 0.05).all()
    half = results[results["variant"] == "dt-half"].set_index("scenario")
    assert (half["dt"] == 0.005).all() and (half["frames_compared"] == 6).all()  # the reference's frames
    assert (half["pos_rmse_rel"] > 0).all() and (half["pos_rmse_rel"] < 0.05).all()
    for scenario, rows in results.groupby("scenario"):
        assert (rows["ref_dt_change"] == half.loc[scenario, "pos_rmse_rel"]).all()
    other = results[results["variant"] == "other-mesh"]
    assert (other["mesh"] == "block/coarse_alt").all()
    assert (other["pos_rmse_rel"] > 0).all() and (other["pos_rmse_rel"] < 0.02).all()


def test_transfer_reproduces_a_linear_field_exactly(block):
    import numpy as np

    from frictionbench.analysis.transfer import transfer_to_mesh
    from frictionbench.scenarios.meshes import load_mesh
    from frictionbench.scenarios.spec import MeshSpec
    from frictionbench.solvers.trajectory import Trajectory

    other = load_mesh(MeshSpec("block", "coarse_alt"))
    A = np.array([[0.1, 0.02, 0.0], [0.0, -0.05, 0.03], [0.01, 0.0, 0.2]])
    src = Trajectory(t=np.array([0.0]), x=(block.X + block.X @ A.T + 0.3)[None], X=block.X, tets=block.tets,
                     surface=block.surface)
    dst = Trajectory(t=np.array([0.0]), x=other.X[None], X=other.X, tets=other.tets, surface=other.surface)
    moved = transfer_to_mesh(src, dst)
    assert np.allclose(moved.x[0], other.X + other.X @ A.T + 0.3, atol=1e-12)


def test_killed_run_resumes_without_recomputing(tmp_path, suite_file):
    """SIGKILL a real `frictionbench run` once its first run is stored; the rerun keeps that one as it was."""
    import signal
    import subprocess
    import sys
    import time

    out = tmp_path / "out"
    cmd = [sys.executable, "-m", "frictionbench.bench.cli", "run", "--suite", str(suite_file), "--solvers", "full",
           "--out", str(out)]
    proc = subprocess.Popen(cmd, stdout=subprocess.DEVNULL, stderr=subprocess.DEVNULL, start_new_session=True)
    deadline = time.time() + 300
    while not list((out / "runs").glob("*/stats.json")) and time.time() < deadline:
        time.sleep(0.05)
    os.killpg(proc.pid, signal.SIGKILL)
    proc.wait()
    finished = {p: p.stat().st_mtime_ns for p in (out / "runs").glob("*/stats.json")}
    assert 1 <= len(finished) and not (out / "results.csv").exists()
    assert subprocess.run(cmd, capture_output=True).returncode == 0
    assert all(p.stat().st_mtime_ns == t for p, t in finished.items())  # nothing finished was recomputed
    assert len(list((out / "runs").glob("*/stats.json"))) == 2 and len(pd.read_csv(out / "results.csv")) == 2


def test_sigterm_stops_the_workers_with_the_run(tmp_path):
    """A run stopped with SIGTERM exits at once and takes its pool workers with it (a worker left behind would
    compute its long run to the end), and nothing half-done is stored."""
    import signal
    import subprocess
    import sys
    import time

    import psutil

    suite = write_toml(tmp_path / "long.toml", SUITE | {"base": block_drop(duration=60.0)})  # minutes per run
    out = tmp_path / "out"
    cmd = [sys.executable, "-m", "frictionbench.bench.cli", "run", "--suite", str(suite), "--solvers", "full",
           "--jobs", "2",
           "--out", str(out)]
    proc = subprocess.Popen(cmd, stdout=subprocess.DEVNULL, stderr=subprocess.DEVNULL, start_new_session=True)
    try:
        parent, deadline = psutil.Process(proc.pid), time.time() + 120
        workers: list = []
        while len(workers) < 2 and time.time() < deadline:  # the pool's workers (the resource tracker besides)
            workers = [c for c in parent.children() if "spawn_main" in " ".join(c.cmdline())]
            time.sleep(0.2)
        assert len(workers) == 2
        time.sleep(3.0)  # the workers are inside their runs
        proc.send_signal(signal.SIGTERM)
        assert proc.wait(timeout=30) == 128 + signal.SIGTERM
        gone, alive = psutil.wait_procs(workers, timeout=10)
        assert not alive, alive
    finally:
        if proc.poll() is None:
            os.killpg(proc.pid, signal.SIGKILL)
    assert not list((out / "runs").glob("*/stats.json"))  # nothing half-done was stored


LAWS_SUITE = SUITE | {"suite": {"name": "laws", "description": "two short block drops"}, "extra": [
    {"labels": {"case": "touching"},
     "overrides": {"initial.clearance": 0.0, "plane.friction": 0.4, "tags": ["resting"]}}]}


def test_barrier_variant_compares_the_laws_and_a_stability_matrix_judges_every_case(tmp_path):
    suite = write_toml(tmp_path / "laws.toml", LAWS_SUITE)
    gates = tmp_path / "gates.toml"
    gates.write_text("""
[[gate]]
suite = "laws"
variant = "full/barrier"
metric = "max_penetration_rel"
max = 0.0

[[gate]]
suite = "laws"
variant = "full/reference"
tag = "resting"
metric = "energy_ratio_max"
max = 1.01
""")
    out = tmp_path / "out"
    assert main(["run", "--suite", str(suite), "--solvers", "barrier", "--out", str(out), "--no-report"]) == 0
    rows = pd.read_csv(out / "results.csv")
    barrier = rows[rows["variant"] == "barrier"].set_index("scenario")
    assert (rows[rows["variant"] == "reference"]["law"] == "penalty").all()
    assert set(barrier.loc[["laws/mu0.2", "laws/mu0.6"], "status"]) == {"ok"}
    assert (barrier.loc[["laws/mu0.2", "laws/mu0.6"], "max_penetration_rel"] == 0.0).all()
    assert (barrier.loc[["laws/mu0.2", "laws/mu0.6"], "law"] == "barrier").all()
    # the barrier law cannot start in contact: a failed row that says why, not a crash of the matrix
    touching = barrier.loc["laws/touching"]
    assert touching["status"] == "failed" and "not applicable" in touching["failure"]
    assert "initial.clearance" in touching["failure"]
    for column in ("not_converged", "line_search_stalls", "step_retries", "volume_ratio_final", "tags",
                   "linear_solver", "mkl_version"):
        assert column in rows
    assert rows.loc[rows["variant"] == "reference", "linear_solver"].isin(["pardiso", "superlu"]).all()
    from frictionbench.bench.gates import check, load_gates
    from frictionbench.bench.reporting import build_report

    verdicts = check(rows, load_gates(gates), "laws")
    tagged = [v for v in verdicts if v.gate.endswith("[resting]")]
    assert [v.scenario for v in tagged] == ["laws/touching"]
    assert sum(not v.passed for v in verdicts) == 1  # the barrier row that could not run
    page = build_report(out, gates_file=gates).read_text(encoding="utf-8")
    assert 'class="stability-matrix"' in page and '<td class="text">cases</td>' in page
    assert "fail: max_penetration_rel" in page
    assert "Contact laws side by side" in page


def test_only_runs_the_matching_members(tmp_path, suite_file):
    out = tmp_path / "out"
    assert main(["run", "--suite", str(suite_file), "--solvers", "full", "--only", "tiny/*0.2", "--out", str(out),
                 "--no-report"]) == 0
    assert set(pd.read_csv(out / "results.csv")["scenario"]) == {"tiny/mu0.2"}
    assert main(["run", "--suite", str(suite_file), "--solvers", "full", "--only", "nothing*", "--out", str(out),
                 "--no-report"]) == 2


def test_resolution_runs_every_member_on_its_shapes_other_catalogue_mesh(tmp_path, suite_file):
    """`--resolution coarse_alt`: the same members on the shape's other mesh, recorded in run.json; a resolution
    the catalogue does not have for a member's shape is refused before any run, naming the option."""
    out = tmp_path / "out"
    assert main(["run", "--suite", str(suite_file), "--solvers", "full", "--only", "tiny/*0.2", "--resolution",
                 "coarse_alt", "--out", str(out), "--no-report", "--no-truth"]) == 0
    results = pd.read_csv(out / "results.csv")
    assert set(results["scenario"]) == {"tiny/mu0.2"} and set(results["mesh"]) == {"block/coarse_alt"}
    assert load_run_info(out)["resolution"] == "coarse_alt"
    suite = load_suite(suite_file)
    assert suite.at_resolution(None) is suite
    assert {m.scenario.mesh.key for m in suite.at_resolution("medium").scenarios} == {"block/medium"}
    with pytest.raises(ScenarioError, match="--resolution.*'huge'.*no such catalogue resolution"):
        suite.at_resolution("huge")
    assert main(["run", "--suite", str(suite_file), "--solvers", "full", "--resolution", "huge", "--out",
                 str(tmp_path / "bad"), "--no-report", "--no-truth"]) == 2
    assert not (tmp_path / "bad" / "runs").exists() or not any((tmp_path / "bad" / "runs").iterdir())


@pytest.mark.parametrize("suite", ["quick", "quick-undamped", "paper", "paper-damped", "hard"])
def test_every_gate_names_a_variant_of_its_suites_default_matrix(suite):
    """A gate on a label no default run produces would only ever fail as 'matched no row' after a long run. A list
    of labels matches a row of any of them: at least one is in the default matrix, and every one is a label of some
    variant set or experiment file (an on-demand run is judged too)."""
    from frictionbench.bench.cli import parse_variants
    from frictionbench.bench.gates import load_gates
    from frictionbench.bench.matrix import set_names

    labels = {"full/reference"} | {f"{v.solver}/{v.label or v.solver}" for v in parse_variants(None, suite=suite)}
    every = parse_variants(",".join(set_names()), matrices=[str(p) for p in EXPERIMENTS.glob("*.toml")])
    known = labels | {f"{v.solver}/{v.label or v.solver}" for v in every}
    for gate in load_gates():
        if gate["suite"] == suite and gate["variant"] != "*":
            named = gate["variant"] if isinstance(gate["variant"], list) else [gate["variant"]]
            assert set(named) & labels and set(named) <= known, (gate, sorted(labels))


def test_a_task_the_executor_cancels_is_submitted_again(tmp_path: Path, monkeypatch) -> None:
    """A future the executor cancels (Dask's scheduler may, when the worker that held the task died) gives no result:
    run_tasks submits the task again, up to MAX_ATTEMPTS times in all, and then raises."""
    from concurrent.futures import CancelledError, Future

    from frictionbench.bench import runner

    class Cancelling:
        """An executor that cancels the first `cancel` submissions and runs the others inline."""

        slots = 1

        def __init__(self, cancel: int) -> None:
            self.cancel, self.submitted = cancel, 0

        def share(self, obj):
            return obj

        def submit(self, fn, *args):
            self.submitted += 1
            f = Future()
            if self.submitted <= self.cancel:
                f.cancel()
            else:
                f.set_result(fn(*args))
            return f

        @staticmethod
        def as_completed(futures):
            return list(futures)

        def __enter__(self):
            return self

        def __exit__(self, *exc):
            return None

    sc = scenario_from_dict(block_drop(duration=0.02) | {"name": "cancelled"})
    task = runner.Task(sc, "full", {})
    for cancel, ok in ((runner.MAX_ATTEMPTS - 1, True), (runner.MAX_ATTEMPTS, False)):
        executor = Cancelling(cancel)
        monkeypatch.setattr(runner, "make_executor", lambda *a, executor=executor: executor)
        store = runner.RunStore(tmp_path / f"runs{cancel}")
        if ok:
            assert runner.run_tasks([task], store, "cpu", 1, "process", "t") == 1 and store.done(task.key)
        else:
            with pytest.raises(CancelledError):
                runner.run_tasks([task], store, "cpu", 1, "process", "t")
            assert not store.done(task.key)
        assert executor.submitted == min(cancel + 1, runner.MAX_ATTEMPTS)


def test_jobs_default_to_the_usable_cores_on_the_cpu_and_to_one_on_cuda():
    assert resolve_jobs(None, "cpu") == usable_cores() >= 1
    assert resolve_jobs(None, "cuda") == 1
    assert resolve_jobs(3, "cuda") == resolve_jobs(3, "cpu") == 3


@pytest.mark.parametrize("jobs", ["0", "-2", "two"])
def test_a_bad_jobs_count_is_refused_naming_the_flag_and_value(tmp_path, capsys, jobs):
    with pytest.raises(SystemExit) as stop:
        main(["run", "--suite", "quick", "--out", str(tmp_path / "o"), "--jobs", jobs])
    assert stop.value.code == 2 and f"--jobs = '{jobs}'" in capsys.readouterr().err
    assert not (tmp_path / "o").exists()


def test_follow_up_tasks_run_as_soon_as_their_task_is_stored_and_again_on_resume(tmp_path: Path) -> None:
    """run_tasks(then=...): a task's follow-ups (a ladder's next level) are submitted when its result is stored,
    with no barrier between 'levels'; on a rerun the stored tasks are followed without running them."""
    from frictionbench.bench import runner

    def task(i: int) -> runner.Task:
        return runner.Task(scenario_from_dict(block_drop(duration=0.01 * (i + 1)) | {"name": f"chain{i}"}), "full", {})

    chain = [task(i) for i in range(3)]  # chain[i] -> chain[i + 1]
    followed: list[int] = []

    def then(t: runner.Task) -> list[runner.Task]:
        i = next(i for i, c in enumerate(chain) if c.key == t.key)
        followed.append(i)
        return [chain[i + 1]] if i + 1 < len(chain) else []

    store = RunStore(tmp_path / "runs")
    assert runner.run_tasks(chain[:1], store, "cpu", 2, "process", "t", then=then) == 3
    assert followed == [0, 1, 2] and all(store.done(t.key) for t in chain)
    followed.clear()
    shutil.rmtree(store.folder(chain[2].key))  # a run lost from the store: the rerun follows to it and computes it
    assert runner.run_tasks(chain[:1], store, "cpu", 2, "process", "t", then=then) == 1
    assert followed == [0, 1, 2] and store.done(chain[2].key)

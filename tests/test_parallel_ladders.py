"""A truth ladder's levels run ahead of its climb where a slot would stay idle (`run_tasks(ahead=...)`,
`run_ladders`): the ladders are those of the climb level by level, a run asked for never waits behind one run ahead,
no level beyond the depth runs, and a rerun recomputes nothing.

Most tests replace the solver by a made-up one (`made_up_solver`: a drift whose ladder differences halve per level)
and the executor by a clock (`SimulatedPool`: a level-k run takes 2^k units), so that which runs are in flight at
once, and what a ladder records, follow from the scheduling alone; one test runs the real solver in a process pool
and on a local Dask cluster."""

from __future__ import annotations

import math
from concurrent.futures import Future
from pathlib import Path

import numpy as np
import pytest

from frictionbench.analysis.metrics import error_over_time, pos_rmse_rel
from frictionbench.analysis.truth import ladder_continues
from frictionbench.bench import runner
from frictionbench.bench.payload import RunResult
from frictionbench.bench.runner import Ladder, Task, levels_ahead, run_ladders
from frictionbench.bench.store import RunStore
from frictionbench.scenarios.meshes import load_mesh
from frictionbench.scenarios.suites import Suite, suite_from_dict
from frictionbench.solvers.trajectory import Trajectory

from scenes import block_drop, mu_axis, suite_tables

#: The scenes' step [s] (level k of a ladder steps by BASE_DT / 2^k)
BASE_DT = 0.01


def level_of(task: Task) -> int:
    """The ladder level of a task, from its step."""
    return round(math.log2(BASE_DT / task.scenario.time.dt))


def made_up_solver(failing: dict[str, int] | None = None):
    """An `execute` stand-in: every vertex drifts from rest by mu (dt / BASE_DT) t along x [m] (mu the plane's
    friction, dt the run's step, t the frame time [s]), so that level k differs from level k - 1 by
    d_k = mu 2^-k rms(t) / L (0.041 mu 2^(1 - k) for these 0.04 s drops of the block); a member named in
    `failing` fails from that level on."""
    failing = failing or {}

    def execute(task: Task, mesh, artefacts, device, threads=1, solvers=None) -> RunResult:
        sc = task.scenario
        if level_of(task) >= failing.get(sc.name, math.inf):
            return RunResult(None, {"failed": True, "failure": "made up", "solver": task.solver})
        t = np.arange(sc.time.n_steps // sc.time.frame_every + 1) * sc.time.dt * sc.time.frame_every
        x = mesh.X[None] + (sc.plane.friction * sc.time.dt / BASE_DT * t)[:, None, None] * np.array([1.0, 0.0, 0.0])
        return RunResult(Trajectory(t=t, x=x, X=mesh.X, tets=mesh.tets, surface=mesh.surface),
                         {"failed": False, "solver": task.solver})

    return execute


class SimulatedPool:
    """An executor on a simulated clock: a run of level k of member m takes `cost[m]` x 2^k units (1 x 2^k by
    default); `as_completed` gives the run in flight that ends first (computed then, inline) and moves the clock to
    its end. `log` records ("submit" | "done", key, level, member, time) in order; `abandoned` the keys given up."""

    def __init__(self, jobs: int, cost: dict[str, float] | None = None) -> None:
        self.jobs, self.slots, self.cost, self.now = jobs, jobs, cost or {}, 0.0
        self.flight: dict[Future, tuple[float, Task, tuple]] = {}
        self.log: list[tuple[str, str, int, str, float]] = []
        self.abandoned: list[str] = []

    def share(self, obj):
        return obj

    def submit(self, fn, *args) -> Future:
        task = args[0]
        assert len(self.flight) < self.jobs, "more runs in flight than jobs"
        f = Future()
        self.flight[f] = (self.now + self.cost.get(task.scenario.name, 1.0) * 2 ** level_of(task), task,
                          (fn, *args))
        self.log.append(("submit", task.key, level_of(task), task.scenario.name, self.now))
        return f

    def as_completed(self, futures):
        f = min(futures, key=lambda f: self.flight[f][0])
        self.now, task, (fn, *args) = self.flight.pop(f)
        f.set_result(fn(*args))
        self.log.append(("done", task.key, level_of(task), task.scenario.name, self.now))
        return iter([f])

    def abandon(self, futures) -> None:
        self.abandoned = [self.flight[f][1].key for f in futures]

    def __enter__(self):
        return self

    def __exit__(self, *exc):
        return None

    def submitted(self) -> list[tuple[str, int]]:
        """(member, level) of every submission, in order."""
        return [(member, k) for event, _, k, member, _ in self.log if event == "submit"]


def suite(*mus: float, tol: float, depth: int, ladders: tuple[str, ...] = ()) -> Suite:
    """Block drops of 0.04 s at each friction coefficient in `mus`, with a backward-Euler ladder of `tol`, `depth`
    (and the frontier `ladders`)."""
    return suite_from_dict(suite_tables("par", block_drop(dt=BASE_DT, duration=0.04), mu_axis(*mus),
                                        truth={"tol": tol, "depth": depth, "integrator": "backward-euler",
                                               "ladders": list(ladders)}))


def climbed(s: Suite, failing: dict[str, int] | None = None) -> dict[str, dict[str, tuple]]:
    """Each member's ladders as the climb level by level makes them, computed here without the runner's
    scheduling: scenario -> integrator -> (level keys, differences, failed, frame differences)."""
    execute, spec = made_up_solver(failing), s.truth
    out: dict[str, dict[str, tuple]] = {}
    for m in s.scenarios:
        mesh = load_mesh(m.scenario.mesh)
        by = out.setdefault(m.scenario.name, {})
        for integrator in (spec.integrator, *spec.ladders):
            ladder = Ladder(m, integrator, spec=spec)
            keys, diffs, frames, previous, failed = [], [], None, None, False
            for k in range(spec.depth + 1 if integrator == spec.integrator else len(by[spec.integrator][0])):
                result = execute(ladder.task(k), mesh, (), "cpu")
                if result.trajectory is None:
                    failed = True
                    break
                keys.append(ladder.task(k).key)
                if previous is not None:
                    diffs.append(pos_rmse_rel(previous, result.trajectory))
                    frames = error_over_time(previous, result.trajectory)
                previous = result.trajectory
                if integrator == spec.integrator and not ladder_continues(diffs, spec.tol, spec.depth):
                    break
            by[integrator] = (keys, diffs, failed, frames)
    return out


def recorded(ladders: dict[str, dict[str, Ladder]]) -> dict[str, dict[str, tuple]]:
    """The same fields of the runner's ladders."""
    return {name: {i: ([t.key for t in lad.tasks], lad.differences, lad.failed, lad.frame_differences)
                   for i, lad in by.items()} for name, by in ladders.items()}


def assert_same_ladders(got: dict, want: dict) -> None:
    assert got.keys() == want.keys()
    for name in want:
        assert list(got[name]) == list(want[name]), name
        for integrator, (keys, diffs, failed, frames) in want[name].items():
            g_keys, g_diffs, g_failed, g_frames = got[name][integrator]
            assert (g_keys, g_diffs, g_failed) == (keys, diffs, failed), (name, integrator)
            assert (g_frames is None) == (frames is None)
            if frames is not None:
                assert all(np.array_equal(a, b) for a, b in zip(g_frames, frames))


def run(s: Suite, store: RunStore, jobs: int, monkeypatch, failing=None, cost=None) -> tuple[dict, SimulatedPool]:
    """`run_ladders` on the made-up solver and a simulated pool of `jobs`: (its ladders, the pool)."""
    pool = SimulatedPool(jobs, cost)
    monkeypatch.setattr(runner, "execute", made_up_solver(failing))
    monkeypatch.setattr(runner, "make_executor", lambda kind, jobs: pool)
    return run_ladders(s, s.truth, store, "cpu", jobs, "process"), pool


def test_the_made_up_ladders_stop_where_meant():
    """The made-up differences halve per level (so the ladders below stop where their tol puts them)."""
    want = climbed(suite(0.2, 0.4, tol=0.003, depth=4))
    d = want["par/mu0.2"]["backward-euler"][1]
    assert len(d) >= 2 and all(b == pytest.approx(a / 2) for a, b in zip(d, d[1:]))
    assert want["par/mu0.4"]["backward-euler"][1][0] == pytest.approx(2 * d[0])


@pytest.mark.parametrize("jobs", [1, 2, 3, 8])
@pytest.mark.parametrize("failing", [None, {"par/mu1.0": 2}])
def test_the_ladders_are_those_of_the_climb_level_by_level(tmp_path: Path, monkeypatch, jobs, failing):
    """Members that certify at different levels, one that runs out of depth and (parametrised) one whose level 2
    fails, with a frontier ladder: the same levels, differences, failures and frame differences at any number of
    jobs as the climb level by level; with one job nothing runs ahead."""
    s = suite(0.05, 0.1, 0.2, 1.0, tol=0.003, depth=3, ladders=("bdf2",))
    want = climbed(s, failing)
    levels = {name: (len(by["backward-euler"][0]), by["backward-euler"][2]) for name, by in want.items()}
    assert levels == {"par/mu0.05": (2, False), "par/mu0.1": (3, False), "par/mu0.2": (4, False),
                      "par/mu1.0": (2, True) if failing else (4, False)}
    ladders, pool = run(s, RunStore(tmp_path / "runs"), jobs, monkeypatch, failing)
    assert_same_ladders(recorded(ladders), want)
    asked = {k for by in want.values() for keys, *_ in by.values() for k in keys}
    if jobs == 1:
        failed_levels = len(failing or {})
        assert len(pool.submitted()) == len(asked) + failed_levels and not pool.abandoned


def test_with_two_jobs_one_members_next_level_runs_beside_its_first(tmp_path: Path, monkeypatch):
    """One member, every level needed: its levels 0 and 1 start together, each later level as soon as a slot
    frees, and the ladder ends sooner than the climb level by level (the sum of its levels' costs)."""
    s = suite(2.0, tol=1e-6, depth=3)
    assert len(climbed(s)["par/mu2.0"]["backward-euler"][0]) == 4  # every level needed
    ladders, pool = run(s, RunStore(tmp_path / "runs"), 2, monkeypatch)
    assert pool.log[:2] == [("submit", ladders["par/mu2.0"]["backward-euler"].tasks[k].key, k, "par/mu2.0", 0.0)
                            for k in (0, 1)]
    assert pool.submitted() == [("par/mu2.0", k) for k in range(4)] and not pool.abandoned
    assert pool.now < sum(2 ** k for k in range(4))


def test_runs_ahead_stay_within_the_depth_and_never_keep_a_run_asked_for_waiting(tmp_path: Path, monkeypatch):
    """Four members at different costs on two and three jobs: no level beyond the depth is submitted; a run ahead
    is submitted only while no run asked for waits (a level is asked for once the level below is done and asked
    for: its ask follows max(ask, end) of the level below); a run ahead still in flight when the ladders end is
    abandoned, and its ladder does not record it."""
    s = suite(0.05, 0.1, 0.2, 1.0, tol=0.003, depth=3)
    want = climbed(s)
    ran_ahead = {}
    for jobs in (2, 3):
        ladders, pool = run(s, RunStore(tmp_path / f"runs{jobs}"), jobs, monkeypatch,
                            cost={"par/mu0.05": 1.0, "par/mu0.1": 1.7, "par/mu0.2": 0.6, "par/mu1.0": 2.3})
        assert_same_ladders(recorded(ladders), want)
        assert max(k for _, k in pool.submitted()) <= s.truth.depth
        seq = {(event, key): i for i, (event, key, *_) in enumerate(pool.log)}
        asked_at: dict[str, int] = {}  # key of a ladder level -> index in the log of the event that asked for it
        for by in want.values():
            keys = by["backward-euler"][0]
            asked_at[keys[0]] = -1  # asked for at the start
            for below, key in zip(keys, keys[1:]):
                asked_at[key] = max(asked_at[below], seq[("done", below)])
        ahead = [i for i, (event, key, *_) in enumerate(pool.log) if event == "submit"
                 and (key not in asked_at or asked_at[key] > i)]
        ran_ahead[jobs] = len(ahead)
        for i in ahead:
            waiting = [key for key, a in asked_at.items() if a < i < seq[("submit", key)]]
            assert not waiting, (jobs, pool.log[i], waiting)
        recorded_keys = {t.key for by in ladders.values() for lad in by.values() for t in lad.tasks}
        assert not set(pool.abandoned) & recorded_keys
    assert ran_ahead[3] > 0  # with two jobs the required runs keep both slots busy here


def test_a_level_run_ahead_of_a_ladder_that_stopped_below_it_is_stored_not_recorded(tmp_path: Path, monkeypatch):
    """A cheap member that certifies at level 1 while an expensive one climbs: its level 2, run ahead, finishes
    and is kept in the store (a valid run) but not in its ladder; a rerun submits nothing and gives the same
    ladders."""
    s = suite(0.05, 2.0, tol=0.004, depth=3)  # mu0.05 certifies at level 1, mu2.0 runs out of depth
    want = climbed(s)
    assert len(want["par/mu0.05"]["backward-euler"][0]) == 2 and len(want["par/mu2.0"]["backward-euler"][0]) == 4
    store = RunStore(tmp_path / "runs")
    ladders, pool = run(s, store, 5, monkeypatch, cost={"par/mu0.05": 1.0, "par/mu2.0": 10.0})
    assert_same_ladders(recorded(ladders), want)
    level2 = Ladder(s.scenarios[0], "backward-euler", spec=s.truth).task(2)
    assert ("done", level2.key) in {(e, k) for e, k, *_ in pool.log} and store.done(level2.key)
    assert level2.key not in {t.key for t in ladders["par/mu0.05"]["backward-euler"].tasks}
    again, pool = run(s, store, 5, monkeypatch)
    assert pool.log == []
    assert_same_ladders(recorded(again), want)


def test_levels_ahead_are_nearest_first_then_in_member_order():
    a, b = object(), object()
    assert levels_ahead([(a, 0), (b, 2)], depth=3) == [(a, 1), (b, 3), (a, 2), (a, 3)]
    assert levels_ahead([(a, 3)], depth=3) == []


@pytest.mark.parametrize("executor", ["process", "dask"])
def test_real_runs_ahead_give_the_ladder_of_one_job_and_stop_with_it(tmp_path: Path, executor: str):
    """The real solver, two jobs in a process pool and on a local Dask cluster: a ladder that certifies at its first
    halving (tol 0.5) while its level 2 runs ahead (started when level 0 ends, twice level 1's steps) records the
    same runs and differences as with one job, and its ladder stops at level 1 (whether a level run ahead
    finished before the stop depends on the machine's load: such a run is stored, valid, and not in the ladder)."""
    s = suite(0.3, tol=0.5, depth=3)
    one = run_ladders(s, s.truth, RunStore(tmp_path / "one"), "cpu", 1, "process")
    store = RunStore(tmp_path / "two")
    two = run_ladders(s, s.truth, store, "cpu", 2, executor)
    assert_same_ladders(recorded(two), recorded(one))
    assert len(two["par/mu0.3"]["backward-euler"].tasks) == 2

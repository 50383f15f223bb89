"""The matrix runner: every scenario of a suite with the full-space reference and every solver variant.

Phases: (1) full-space references of every member (also the training data), (2) reduced models trained per mesh
shape on the suite's training split (cached; on the training members' references), (3) with a truth, each member's
truth ladder, the runs of (5) filling the slots its last levels leave idle, (4) the models of the variants whose
`training` is "truth", on the training members' truths, (5) every variant on every member (and on the other mesh
of the shape, for remeshing), (6) metrics against the references, the rows built by
`analysis.rows.collect_rows` -> results.csv and report.html. Each run is a folder of the `RunStore` keyed by a
hash of its scenario and settings: an interrupted run resumes with what is missing.
Runs execute through a pluggable executor (`executors.make_executor`: a local process pool or a Dask cluster):
a task carries what its worker needs and returns what it produced (`bench.payload`); only the client writes here.
"""

from __future__ import annotations

import os
import sys
import threading
import time
from collections import deque
from collections.abc import Callable, Mapping, Sequence
from concurrent.futures import CancelledError
from dataclasses import dataclass, field, replace
from functools import cached_property
from datetime import UTC, datetime
from pathlib import Path

import numpy as np
from tqdm import tqdm

from frictionbench.analysis.metrics import error_over_time, pos_rmse_rel
from frictionbench.analysis.records import RunRecord
from frictionbench.analysis.rows import collect_rows, ladder_label
from frictionbench.analysis.table import write_results_csv
from frictionbench.analysis.truth import ladder_continues
from frictionbench.bench.executors import make_executor, usable_cores
from frictionbench.bench.payload import Artefact, RunResult, artefact_folders, localised
from frictionbench.bench.store import RunStore, TruthStore, run_key, truth_store_root
from frictionbench.bench.training import (NO_MODEL, Unprepared, family_scenarios, prepare_variants, shape_of,
                                          training_kind)
from frictionbench.scenarios.atomic import write_json_atomic
from frictionbench.scenarios.meshes import TetMesh, load_mesh
from frictionbench.scenarios.spec import MeshSpec, Scenario
from frictionbench.scenarios.suites import TOLERANCE_FACTOR, SuiteMember, TruthSpec, load_suite
from frictionbench.solvers.registry import entries, register_entries, unavailable
from frictionbench.solvers.trajectory import Trajectory
from frictionbench.solvers.version import PHYSICS_VERSION

#: The solver whose runs are the references of the matrix (every other run is compared with its run of the same
#: scenario); its default parameters are the reference's.
REFERENCE = "full"


@dataclass(frozen=True)
class Variant:
    """One solver configuration of the matrix: solver name, parameters, label, and an optional other mesh
    resolution of the same shape (remeshing; compared with the full-space run on that mesh, or, with `transfer`,
    carried onto the reference mesh and compared with the reference itself: accuracy across resolutions).
    `model` names the trained model a variant shares with another (a remeshed variant with its training-mesh
    variant, a level of a step ladder with its base; default: the label); `remesh_of` the variant on the training
    mesh a remeshed one is compared with (`remesh_ratio`; default: its model); `overrides` and `dt_scale` change the
    scenario (e.g. a larger time step), `frame_scale` multiplies its frame_every (a finer step storing its frames at
    the scene's frame times). `tags` are columns its rows carry as they are, which place them and change no run: a
    point of an accuracy-for-time curve (`bench.matrix.step_ladder`) has `curve`, `curve_level` and `curve_twin`
    (`analysis.curves`). `training` names what a trained model learns from (`bench.training.training_kind`): the
    training members' references at the scene's step (default), their truths (the finest runs of their truth
    ladders), or "family:N", N scenes per shape drawn across their family and run at the scene's step
    (`bench.training.family_scenarios`); the training runs are part of the model's cache key, so no two share a
    model."""

    solver: str
    params: dict = field(default_factory=dict)
    label: str = ""
    remesh: str | None = None
    model: str = ""
    remesh_of: str = ""
    overrides: dict = field(default_factory=dict)
    dt_scale: float = 1.0
    transfer: bool = False
    frame_scale: int = 1
    tags: dict = field(default_factory=dict)
    training: str = "reference"

    def __post_init__(self) -> None:
        try:
            training_kind(self.training)
        except ValueError as err:
            raise ValueError(f"variant {self.label or self.solver!r}: {err}") from None

    def scenario(self, sc: Scenario) -> Scenario:
        """The member's scenario with this variant's `overrides` (dotted fields, e.g. {"contact.stiffness": 1e6}),
        its time step times `dt_scale` and its frame_every times `frame_scale`, validated by the scenario loader."""
        if not self.overrides and self.dt_scale == 1.0 and self.frame_scale == 1:
            return sc
        from frictionbench.scenarios.load import scenario_from_dict, scenario_to_dict

        d = scenario_to_dict(sc)
        d["time"]["dt"] = sc.time.dt * self.dt_scale
        if self.frame_scale != 1:
            d["time"]["frame_every"] = sc.time.frame_every * self.frame_scale
        for dotted, value in self.overrides.items():
            *path, last = dotted.split(".")
            table = d
            for part in path:
                table = table[part]
            table[last] = value
        return scenario_from_dict(d, source=f"variant {self.label or self.solver}")


@dataclass(frozen=True)
class Task:
    """One simulation: scenario, solver, parameters, mesh (None: the scenario's own)."""

    scenario: Scenario
    solver: str
    params: dict
    mesh: MeshSpec | None = None

    @cached_property
    def key(self) -> str:
        """Store key of this run (computed once: it hashes the scenario and the mesh)."""
        return run_key(self.scenario, self.solver, self.params, self.mesh)


def execute(task: Task, mesh: TetMesh, artefacts: tuple[Artefact, ...], device: str, threads: int = 1,
            solvers: dict[str, str] | None = None) -> RunResult:
    """Run one task on a worker, which may share no filesystem with the client: `mesh` is the task's mesh (the
    arrays, not a path) and `artefacts` the folders its file parameters name (written once into the worker's
    cache); returns the trajectory (with a reduced run's basis) and stats for the client to store. A failed run is
    a result with its reason, never an exception. Its BLAS, OpenMP and torch thread pools are limited to `threads`
    so that parallel workers do not oversubscribe the cores; the parent's registered `solvers`
    (`solvers.registry.entries`) are registered here too."""
    from threadpoolctl import threadpool_limits

    from frictionbench.solvers.run import run_scenario
    from frictionbench.solvers.warp_runtime import cache_root

    # a worker's bars are disabled: a thread lock, not tqdm's inter-process one, whose semaphore a worker stopped
    # mid-run (a run ahead abandoned, `run_tasks`) would leave for the resource tracker to warn about
    tqdm.set_lock(threading.RLock())
    register_entries(solvers or {})
    traj = None
    try:
        params = localised(task.params, artefacts, cache_root() / "artefacts")
        with threadpool_limits(threads):
            traj, stats = run_scenario(task.scenario, task.solver, device, params, task.mesh, tet_mesh=mesh)
    except Exception as err:  # a failed run is a row with its reason, never a crash of the matrix
        traj, stats = None, {"failed": True, "failure": f"{type(err).__name__}: {err}", "solver": task.solver}
    stats["params"] = task.params  # the record names the client's artefacts, not the worker's copies
    stats["physics_version"] = PHYSICS_VERSION  # what computed it (`bench.store.TruthStore` keeps only its own)
    if traj is not None:
        traj.meta["params"] = task.params
    stats["scenario"] = task.scenario.name
    return RunResult(traj, stats)


#: This process's session (its start in UTC and its process id): every run it computes is stored with it as
#: `timed_in`, so that a row can say whether its cost and its ladder's were timed in one session
#: (`analysis.truth.with_frontier`, `timed_beside_ladder`); a resumed store keeps each run's own session.
SESSION = f"{datetime.now(UTC):%Y-%m-%dT%H:%M:%SZ}-{os.getpid()}"

#: Most submissions of one task whose future the executor cancels (`run_tasks`).
MAX_ATTEMPTS = 3


def run_tasks(tasks: Sequence[Task], store: RunStore, device: str, jobs: int, executor: str,
              desc: str, then: Callable[[Task], Sequence[Task]] | None = None,
              ahead: Callable[[], Sequence[Task]] | None = None, truths: TruthStore | None = None,
              later: Sequence[Task] = ()) -> int:
    """Execute the tasks not yet done, `jobs` at a time, with a progress bar; returns how many were computed.

    The client keeps at most `jobs` tasks in flight (the executor's `slots`: more on a Dask cluster of more workers)
    and chooses each one it submits: first the tasks asked for
    (`tasks`, then what `then` returns), in the order asked; where none waits and a slot would stay idle, the first
    task of `ahead()` (where given: tasks worth starting before anything asks for them, a ladder's next levels, most
    wanted first) not yet stored, asked for, in flight or tried; where none of those is left either, the next of
    `later` (tasks of a later phase that need nothing of this one, e.g. the variants' runs beside the ladders' last
    levels: each submitted only to a slot that would stay idle while a task asked for runs, stored like `ahead`'s,
    and, unlike them, finished before the call returns). A task run ahead is stored like any (a valid run);
    asked for later, it is followed at once (or once it finishes); one still in flight when nothing asked for is
    left is abandoned (the executor stops it). Each distinct mesh and artefact is shared with the workers once; the
    client stores each result as it arrives, so an interruption costs only the tasks in flight (a Dask task whose
    worker dies is rerun on another; one the executor cancels instead, as Dask's scheduler does when the worker held
    the only copy of a shared mesh ("lost dependencies"), is submitted again with its mesh and artefacts shared
    afresh, up to MAX_ATTEMPTS times in all). `then(task)`, where given, is called on the client once a task asked
    for is stored (or found stored) and returns the tasks that follow from it (a ladder's next level): no worker
    waits for a slower member's run. `truths`, where given, is looked up before a task asked for is computed (a run
    found there is copied into `store`, `TruthStore.fetch`) and is given each run computed here or found stored
    (`TruthStore.put`). A task asked for that gives no result (not a failed run, which is a result) is raised once
    every other one is stored. The progress bar counts the tasks asked for; its note, those running ahead.
    """
    asked: set[str] = set()
    waiting: deque[Task] = deque()
    flying: set[str] = set()  # keys in flight
    tried: set[str] = set()  # keys submitted ahead of being asked for
    ahead_done: set[str] = set()  # keys computed ahead and not asked for yet
    total = done = 0  # the tasks asked for that were not stored when asked (or were run ahead), and those done

    def stored(t: Task) -> bool:
        """Whether t is in the store (copied there from the truth store if it is only there)."""
        if store.done(t.key):
            if truths is not None:
                truths.put(t.key, store)
            return True
        return truths is not None and truths.fetch(t.key, store)

    def ask(new: Sequence[Task]) -> None:
        """Ask for the tasks of `new` not asked for yet: the stored ones are followed through `then` at once, the
        others wait for a slot (or for their run ahead to finish)."""
        nonlocal total, done
        queue = deque(new)
        while queue:
            t = queue.popleft()
            if t.key in asked:
                continue
            asked.add(t.key)
            if t.key in flying:
                total += 1
            elif stored(t):
                if t.key in ahead_done:
                    ahead_done.discard(t.key)
                    total, done = total + 1, done + 1
                if then is not None:
                    queue.extend(then(t))
            else:
                waiting.append(t)
                total += 1

    ask(tasks)
    if not waiting:
        return 0
    threads = max(1, usable_cores() // jobs)
    computed = 0
    with make_executor(executor, jobs) as ex, tqdm(total=total, desc=desc, unit="run") as bar:
        shared: dict = {}
        pending: dict = {}
        spare = deque(later)
        later_keys = {t.key for t in later}
        attempts: dict[str, int] = {}
        lost = []

        def submit(t: Task, fresh: bool = False) -> None:
            """Submit t with its mesh and artefacts shared once (`fresh`: shared again, the earlier copies lost)."""
            needs = [t.mesh or t.scenario.mesh, *artefact_folders(t.params)]
            for need in needs:
                if fresh or need not in shared:
                    shared[need] = ex.share(load_mesh(need) if isinstance(need, MeshSpec) else Artefact.of(need))
            f = ex.submit(execute, t, shared[needs[0]], tuple(shared[n] for n in needs[1:]), device, threads,
                          entries())
            pending[f] = t
            flying.add(t.key)
            attempts[t.key] = attempts.get(t.key, 0) + 1

        def next_ahead() -> Task | None:
            """The first task of `ahead()` worth a slot: not stored, asked for, in flight or tried."""
            for t in ahead() if ahead is not None else ():
                if (t.key not in asked and t.key not in flying and t.key not in tried and not store.done(t.key)
                        and not (truths is not None and truths.done(t.key))):
                    return t
            return None

        def next_later() -> Task | None:
            """The first task of `later` not yet stored, asked for, in flight or tried."""
            while spare:
                t = spare.popleft()
                if t.key not in asked and t.key not in flying and t.key not in tried and not store.done(t.key):
                    return t
            return None

        def fill() -> None:
            """Submit tasks while a slot is free (the waiting ones first, then ones ahead, then later ones); bring
            the bar up to date."""
            while len(pending) < ex.slots:
                if waiting:
                    submit(waiting.popleft())
                elif asked & flying and (t := next_ahead() or next_later()) is not None:
                    tried.add(t.key)
                    submit(t)
                else:
                    break
            bar.total = total
            if tried:
                bar.set_postfix_str(f"{len(flying - asked)} ahead", refresh=False)
            bar.update(done - bar.n)

        fill()
        while waiting or asked & flying or flying & later_keys:  # a later task in flight is finished, not dropped
            f = next(iter(ex.as_completed(pending)))
            t = pending.pop(f)
            flying.discard(t.key)
            try:
                result = f.result()
            except CancelledError as err:
                if attempts[t.key] < MAX_ATTEMPTS:
                    submit(t, fresh=True)
                    continue
                if t.key in asked:
                    lost.append(err)
            except Exception as err:  # no result at all (e.g. every worker that tried it died): the others are
                if t.key in asked:    # still stored, and the rerun computes only this one
                    lost.append(err)
            else:
                store.save(t.key, result.trajectory, result.stats | {"timed_in": SESSION})
                if truths is not None and t.key not in later_keys:
                    truths.put(t.key, store)
                computed += 1
                if t.key not in asked:
                    ahead_done.add(t.key)
                elif then is not None:
                    ask(then(t))
            if t.key in asked:
                done += 1
            fill()
        if pending:  # runs ahead of a ladder that stopped below them: not wanted
            bar.set_postfix_str(f"{len(pending)} ahead given up")
            ex.abandon(list(pending))
    if lost:
        raise lost[0]
    return computed


def mesh_variant(member: SuiteMember, resolution: str) -> MeshSpec:
    """The scenario's mesh at another resolution of the same catalogue shape; `alt` names the independently
    generated mesh beside the scenario's own resolution (coarse -> coarse_alt)."""
    spec = member.scenario.mesh
    res = f"{spec.resolution}_alt" if resolution == "alt" else resolution
    return MeshSpec(name=spec.name, resolution=res, scale=spec.scale)


def run_suite(suite_name: str, out: str | Path, variants: Sequence[Variant], device: str = "cpu", jobs: int = 1,
              executor: str = "process", report: bool = True, only: str | None = None,
              resolution: str | None = None, allow_large: bool = False, reference: str = REFERENCE,
              with_truth: bool = True, truth_overrides: dict | None = None, truth_store: str | Path | None = None,
              use_truth_store: bool = True) -> Path:
    """Run the matrix of `suite_name` with `variants` into `out` (only the members matching the shell pattern
    `only`, if given; every member on its shape's mesh at `resolution`, if given, `Suite.at_resolution`), every run
    compared with the `reference` solver's; returns the results.csv path. Every run is checked by the resource guard
    first (`guard_resources`; `allow_large` or the suite's own `allow_large` lifts its bounds). With `with_truth`,
    the suite's `[truth]` (changed by `truth_overrides`: tol, depth, integrator,
    named `--truth-*` in errors; a suite without one gets the defaults when overrides are given) builds a ground
    truth per member (`run_ladders`) and every row gets err_truth and the frontier's columns; with
    `use_truth_store`, its runs are kept in and taken from the truth store at `truth_store` (default
    `bench.store.truth_store_root`), shared by every results folder of the machine. A variant whose solver
    is unavailable here is skipped (`available_variants`): a note on stderr and `skipped` in run.json say why, and
    results.csv has no row for it."""
    out = Path(out)
    store = RunStore(out / "runs")
    suite = load_suite(suite_name).only(only).at_resolution(resolution)
    variants, skipped = available_variants(distinct_variants(variants))
    spec = truth_config(suite, with_truth, truth_overrides)
    guard_resources(suite, variants, allow_large=allow_large or suite.allow_large, truth=spec)
    t0 = time.perf_counter()
    refs = {m.scenario.name: Task(m.scenario, reference, {}) for m in suite.scenarios}
    remesh_refs = [Task(m.scenario, reference, {}, mesh_variant(m, v.remesh))
                   for m in suite.scenarios for v in variants if v.remesh and not v.transfer]
    run_tasks(list(refs.values()) + remesh_refs, store, device, jobs, executor, "references")
    family = family_tasks(suite, variants, reference)
    run_tasks([t for by in family.values() for tasks in by.values() for t in tasks], store, device, jobs, executor,
              "family training runs")
    truths = TruthStore(truth_store_root(truth_store), device) if spec and use_truth_store else None
    # the variants that need no truth are prepared (trained) first, so that their runs fill the slots the ladders'
    # last levels leave idle; those trained on truths, after the ladders
    early = [v for v in variants if v.training != "truth"]
    resolved = prepare_variants(suite, early, store, refs, out / "models", device, family=family)
    ladders = (run_ladders(suite, spec, store, device, jobs, executor, reference, truths,
                           later=variant_tasks(suite, resolved, early)) if spec else {})
    late = [v for v in variants if v.training == "truth"]
    resolved = list(resolved) + list(prepare_variants(suite, late, store, refs, out / "models", device, ladders))
    run_tasks(variant_tasks(suite, resolved, variants), store, device, jobs, executor, "solver variants")
    rows = collect_rows(suite, refs, run_records(suite, refs, resolved, variants), store, ladders, spec)
    csv = write_results_csv(rows, out / "results.csv")
    write_json_atomic(out / "run.json", {"suite": suite_name, "device": device, "jobs": jobs, "executor": executor,
                                         "variants": [v.__dict__ for v in variants], "only": only,
                                         "resolution": resolution, "reference": reference,
                                         "truth": spec.__dict__ if spec else None,
                                         "truth_store": str(truths.shelf) if truths else None,
                                         "skipped": skipped, "wall_s": time.perf_counter() - t0})
    if report:
        from frictionbench.bench.reporting import build_report  # here, not above: the worker processes need no plotting

        build_report(out)
    return csv


def family_tasks(suite, variants: Sequence[Variant], reference: str) -> dict[str, dict[str, list[Task]]]:
    """The full-space runs of the training families the variants ask for (`training = "family:N"`), by training and
    mesh shape (`bench.training.family_scenarios`)."""
    wanted = sorted({v.training for v in variants if training_kind(v.training)[0] == "family"})
    return {w: {shape: [Task(sc, reference, {}) for sc in scenes]
                for shape, scenes in family_scenarios(suite, training_kind(w)[1]).items()} for w in wanted}


def distinct_variants(variants: Sequence[Variant]) -> list[Variant]:
    """The variants with each run once, in their order: a variant of the same solver and name as an earlier one (a
    row's identity) and the same run (`_as_run`) is kept once, as whichever of the two places it on a curve has it
    (sets that share a variant, e.g. `pod-fast` and `pod-cubature-size`; its `tags`). Raises ValueError, naming the variant, for
    two different runs of one solver under one name: their rows could not be told apart."""
    kept: dict[tuple[str, str], Variant] = {}
    for v in variants:
        key = v.solver, v.label or v.solver
        same = kept.setdefault(key, v)
        if _as_run(same) != _as_run(v):
            raise ValueError(f"its {v.solver} variant {key[1]!r} differs from another of that name")
        if v.tags.get("curve") and not same.tags.get("curve"):
            kept[key] = v
    return list(kept.values())


def _as_run(variant: Variant) -> Variant:
    """The variant without what only places its rows (its `tags`) and with its trained model named as the rows name
    it (`model`, else its name): two variants equal here run the same run."""
    return replace(variant, tags={}, model=variant.model or variant.label or variant.solver)


def available_variants(variants: Sequence[Variant]) -> tuple[list[Variant], list[dict]]:
    """(the variants whose solver is available here, the others as {solver, variant, reason}), each skipped one
    noted on stderr with the reason (`solvers.registry.unavailable`: a package it requires is missing, or its module
    does not import)."""
    reasons = {name: unavailable(name) for name in dict.fromkeys(v.solver for v in variants)}
    skipped = [{"solver": v.solver, "variant": v.label or v.solver, "reason": reasons[v.solver]}
               for v in variants if reasons[v.solver] is not None]
    for s in skipped:
        print(f"note: skipping variant {s['variant']!r}: solver {s['solver']!r} is unavailable: {s['reason']}",
              file=sys.stderr)
    return [v for v in variants if reasons[v.solver] is None], skipped


def truth_config(suite, with_truth: bool = True, overrides: dict | None = None) -> TruthSpec | None:
    """The truth a run builds: None without `with_truth`; else the suite's `[truth]` changed by `overrides`
    (tol, depth, integrator; errors name `--truth-<key>`), the defaults where the suite has none and overrides
    are given, None where it has none and none are given. The ladder's integrator must be one the scenarios
    accept (checked on the first member, before any work)."""
    overrides = {k: v for k, v in (overrides or {}).items() if v is not None}
    if not with_truth or (suite.truth is None and not overrides):
        return None
    spec = (suite.truth or TruthSpec()).with_(**overrides, where="--truth", sep="-") if overrides else suite.truth
    for integrator in (spec.integrator, *spec.ladders):
        ladder_variant(suite.scenarios[0].scenario, integrator, spec.depth, tol=spec.level_tol(spec.depth),
                       lag=spec.contact_lag).scenario(suite.scenarios[0].scenario)
    return spec


def guard_resources(suite, variants: Sequence[Variant], allow_large: bool = False,
                    truth: TruthSpec | None = None) -> None:
    """Refuse the whole matrix before any work when one of its runs (a reference, a remeshed reference, a variant
    with its own time step, the deepest run a truth ladder may need) exceeds the bounds of
    `scenarios.resources.check_resources`."""
    from frictionbench.scenarios.errors import ScenarioError
    from frictionbench.scenarios.resources import check_runs

    runs = []
    for m in suite.scenarios:
        runs.append((m.scenario, m.scenario.mesh))
        if truth is not None:
            runs.append((ladder_variant(m.scenario, truth.integrator, truth.depth, tol=truth.level_tol(truth.depth),
                                        lag=truth.contact_lag).scenario(m.scenario), m.scenario.mesh))
        for v in variants:
            try:
                sc = v.scenario(m.scenario)
            except ScenarioError:  # not applicable: a failed row, never run
                continue
            runs.append((sc, mesh_variant(m, v.remesh) if v.remesh else sc.mesh))
    check_runs(runs, allow_large=allow_large)


def ladder_variant(sc: Scenario, integrator: str, k: int, solver: str = REFERENCE, tol: float | None = None,
                   lag: str = "start") -> Variant:
    """Level k of a truth ladder: the full-space solver at dt / 2^k with `integrator`, a frame every
    frame_every x 2^k steps (the frames of every level fall on the same times); with `tol` (a tolerance ladder's
    level, `TruthSpec.level_tol`) the solver with adaptive steps at time.tol = tol instead, dt and frames the
    scenario's; `lag` other than `start` sets the runs' contact.lag (`TruthSpec.contact_lag`)."""
    overrides: dict = {}
    if integrator != sc.time.integrator:
        overrides["time.integrator"] = integrator
    if tol is not None:
        overrides["time.tol"] = tol
    if lag != "start":
        overrides["contact.lag"] = lag
    return Variant(solver, {}, label=ladder_label(integrator, k, "step" if tol is None else "tolerance"),
                   overrides=overrides, dt_scale=0.5 ** k if tol is None else 1.0,
                   frame_scale=2 ** k if tol is None else 1)


@dataclass
class Ladder:
    """The runs of one member's ladder with one integrator, level by level: their tasks, the differences
    d_k = pos_rmse_rel(x_{k-1}, x_k) [fraction of L] between successive levels, and whether a run failed (which
    ends it: the truth is then the last good level). `spec` is the suite's truth: a tolerance ladder's levels are
    adaptive runs at its `TruthSpec.level_tol`."""

    member: SuiteMember
    integrator: str
    solver: str = REFERENCE
    spec: TruthSpec = field(default_factory=TruthSpec)
    tasks: list[Task] = field(default_factory=list)
    differences: list[float] = field(default_factory=list)
    failed: bool = False
    #: (t (F,) [s], per-frame difference (F,) [fraction of L]) of the last two levels
    frame_differences: tuple[np.ndarray, np.ndarray] | None = None

    def task(self, k: int) -> Task:
        """The task of level k."""
        sc = self.member.scenario
        return Task(ladder_variant(sc, self.integrator, k, self.solver, self.spec.level_tol(k),
                                   self.spec.contact_lag).scenario(sc),
                    self.solver, self.spec.solver_params)

    def add(self, task: Task, store: RunStore, previous: Trajectory | None) -> Trajectory | None:
        """Record the finished run of the next level; returns its trajectory (None if it failed)."""
        traj, stats = store.load(task.key)
        if traj is None or stats.get("failed"):
            self.failed = True
            return None
        self.tasks.append(task)
        if previous is not None:
            self.differences.append(pos_rmse_rel(previous, traj))
            self.frame_differences = error_over_time(previous, traj)
        return traj

    @property
    def good_levels(self) -> int:
        """How many levels ran without failing."""
        return len(self.tasks)


def run_ladders(suite, spec: TruthSpec, store: RunStore, device: str, jobs: int, executor: str,
                reference: str = REFERENCE, truths: TruthStore | None = None, later: Sequence[Task] = ()
                ) -> dict[str, dict[str, Ladder]]:
    """Every member's truth ladder (`spec.integrator`) climbed level by level until `ladder_continues` says stop,
    each member on its own (its next level is asked for as soon as its last one is stored); then, for that member,
    the ladders of `spec.ladders` to the same level as its truth. A slot that would stay idle runs a climbing
    ladder's next levels ahead (`levels_ahead`; never beyond `spec.depth`, never before a run asked for): a level
    is added to its ladder only once the climb below it asks for it, so the ladders are those of the climb level by
    level, and a level run ahead of a ladder that stopped below it is only stored. Every run is an ordinary run of
    the store (cached, resumable), and of `truths` where given (`run_tasks`); a slot that would stay idle even so
    runs a task of `later` (`run_tasks`: the variants' runs that need no truth, beside the last levels of the
    slowest ladders). Returns scenario -> integrator -> Ladder (the truth's integrator first)."""
    ladders = {m.scenario.name: {spec.integrator: Ladder(m, spec.integrator, reference, spec)}
               for m in suite.scenarios}
    climbing: dict[str, tuple[Ladder, int]] = {}  # task key -> (truth ladder, level) of the level asked for
    last: dict[int, Trajectory | None] = {}
    others: list[tuple[Ladder, Task]] = []
    tasks: dict[tuple[int, int], Task] = {}

    def level(ladder: Ladder, k: int) -> Task:
        """The task of level k of a truth ladder (built once)."""
        return tasks.setdefault((id(ladder), k), ladder.task(k))

    def climb(ladder: Ladder, k: int) -> Task:
        task = level(ladder, k)
        climbing[task.key] = (ladder, k)
        return task

    def then(task: Task) -> list[Task]:
        """The next level of the truth ladder `task` belongs to; or, once that ladder stops, its member's frontier
        ladders to the same level."""
        if task.key not in climbing:  # a frontier ladder's run: recorded below, in level order
            return []
        ladder, k = climbing.pop(task.key)
        last[id(ladder)] = ladder.add(task, store, last.get(id(ladder)))
        if not ladder.failed and ladder_continues(ladder.differences, spec.tol, spec.depth):
            return [climb(ladder, k + 1)]
        last.pop(id(ladder), None)
        by = ladders[ladder.member.scenario.name]
        new = []
        for integrator in spec.ladders:
            by[integrator] = Ladder(ladder.member, integrator, reference, spec)
            new += [(by[integrator], by[integrator].task(j)) for j in range(ladder.good_levels)]
        others.extend(new)
        return [t for _, t in new]

    def ahead() -> list[Task]:
        """The levels above each climbing ladder's, nearest first (`levels_ahead`)."""
        return [level(ladder, j) for ladder, j in levels_ahead(list(climbing.values()), spec.depth)]

    kind = "dt / 2^level" if spec.start_tol is None else f"tol {spec.start_tol:g} / {TOLERANCE_FACTOR:g}^level"
    run_tasks([climb(by[spec.integrator], 0) for by in ladders.values()], store, device, jobs, executor,
              f"truth ladders ({kind})", then=then, ahead=ahead, truths=truths, later=later)
    previous: dict[int, Trajectory | None] = {}
    for ladder, task in others:
        if not ladder.failed:
            previous[id(ladder)] = ladder.add(task, store, previous.get(id(ladder)))
    return ladders


def levels_ahead(climbing: Sequence[tuple[Ladder, int]], depth: int) -> list[tuple[Ladder, int]]:
    """(ladder, level) of the levels a run may start ahead of its climb, most wanted first: for each (ladder,
    level asked for) of `climbing`, the levels above it up to `depth`, nearest first, and among equally near ones in
    the order of `climbing`. The nearest is the one most likely needed and the cheapest (each level costs about
    twice the one below it), and a run ahead holds no slot a climb needs: a level that ends frees its slot and asks
    for at most one run (the next level, often in flight already), so only a truth ladder's end, asking for its
    frontier ladders' levels at once, may wait for a run ahead to end."""
    return [(ladder, k + gap) for gap in range(1, depth + 1) for ladder, k in climbing if k + gap <= depth]


def variant_tasks(suite, resolved, variants: Sequence[Variant]) -> list[Task]:
    """The runs of `variants` on every member of `suite`, member by member (`member_variants` on the prepared
    `resolved` pairs; a variant with no model for a member's shape, or not applicable to it, has none)."""
    tasks = []
    for m in suite.scenarios:
        for v, params in member_variants(resolved, variants, m):
            if not isinstance(params, str) and isinstance(task := variant_task(v, m, params), Task):
                tasks.append(task)
    return tasks


def variant_task(v: Variant, member: SuiteMember, params: dict) -> Task | str:
    """The task of a variant on a member, or the reason it has none (its overrides make an invalid scenario,
    e.g. the barrier law on a body that starts touching the plane)."""
    from frictionbench.scenarios.errors import ScenarioError

    try:
        sc = v.scenario(member.scenario)
    except ScenarioError as err:
        return f"not applicable: {err}"
    return Task(sc, v.solver, params, mesh_variant(member, v.remesh) if v.remesh else None)


def member_variants(resolved, variants: Sequence[Variant], member: SuiteMember) -> list[tuple[Variant, dict | str]]:
    """The (variant, params) that apply to one member: a per-shape entry only to members of that shape; in place
    of params the reason (a failed row) when a variant has none for the member's shape: its `Unprepared` reason
    there (`bench.training.prepare_variants`), else NO_MODEL."""
    shape = shape_of(member)
    out: list[tuple[Variant, dict | str]] = []
    for v in variants:
        entries = [p for w, p in resolved if w is v]
        match = [p for p in entries if isinstance(p, dict) and p.get("shape", shape) == shape]
        why = [p.reason for p in entries if isinstance(p, Unprepared) and p.shape == shape]
        out.append((v, match[0] if match else why[0] if why else NO_MODEL))
    return out


def run_records(suite, refs: Mapping[str, Task], resolved, variants: Sequence[Variant]) -> list[RunRecord]:
    """Every variant's run on every member of `suite`, resolved for row building (`analysis.records.RunRecord`),
    member by member in the variants' order: its run (`variant_task`) or why it has none (`member_variants`, on the
    prepared `resolved` pairs), the full-space run it is compared with (the member's reference `refs[name]`, or with
    another mesh and no `transfer`, the reference solver's run on that mesh), and its rows' descriptive cells."""
    records = []
    for m in suite.scenarios:
        sc, ref = m.scenario, refs[m.scenario.name]
        for v, params in member_variants(resolved, variants, m):
            ident = {"member": sc.name, "solver": v.solver, "variant": v.label or v.solver, "tags": dict(v.tags)}
            task = params if isinstance(params, str) else variant_task(v, m, params)
            if isinstance(task, str):
                records.append(RunRecord(**ident, failure=task))
                continue
            label, mesh = ident["variant"], task.mesh
            compare = ref.key if mesh is None or v.transfer else Task(sc, ref.solver, {}, mesh).key
            columns = {"remesh": v.remesh or "", "r": params.get("r"), "mesh": (mesh or sc.mesh).key,
                       "model": v.model or label, "remesh_of": (v.remesh_of or v.model or label) if v.remesh else "",
                       "train_mesh": sc.mesh.key if "shape" in params else "",
                       "train_data": v.training if "shape" in params else ""}
            records.append(RunRecord(**ident, key=task.key, scenario=task.scenario, compare_key=compare,
                                     transfer=mesh is not None and v.transfer,
                                     other_mesh=mesh is not None and not v.transfer, columns=columns))
    return records

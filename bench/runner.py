"""The matrix runner: every scenario of a suite with the full-space reference and every solver variant.

Phases: (1) full-space references of every member (also the training data), (2) reduced models trained per mesh
shape on the suite's training split (cached), (3) every variant on every member (and on the other mesh of the
shape, for remeshing), (4) metrics against the references -> results.csv and report.html. Each run is a folder of
the `RunStore` keyed by a hash of its scenario and settings: an interrupted run resumes with what is missing.
Runs execute through a pluggable executor (`executors.make_executor`: a local process pool or a Dask cluster):
a task carries what its worker needs and returns what it produced (`bench.payload`); only the client writes here.
"""

from __future__ import annotations

import os
import time
from collections.abc import Sequence
from dataclasses import dataclass, field, replace
from pathlib import Path

from tqdm import tqdm

from analysis.derived import with_remesh_ratio
from analysis.metrics import compare
from analysis.table import write_results_csv
from analysis.transfer import transfer_to_mesh
from bench.executors import make_executor
from bench.payload import Artefact, RunResult, artefact_folders, localised
from bench.store import RunStore, run_key
from scenarios.atomic import write_json_atomic
from scenarios.meshes import TetMesh, load_mesh
from scenarios.model import MeshSpec, Scenario
from scenarios.suites import SuiteMember, load_suite
from solvers.registry import entries, register_entries

#: The solver whose runs are the references of the matrix (every other run is compared with its run of the same
#: scenario); its default parameters are the reference's.
REFERENCE = "full"


@dataclass(frozen=True)
class Variant:
    """One solver configuration of the matrix: solver name, parameters, label, and an optional other mesh
    resolution of the same shape (remeshing; compared with the full-space run on that mesh, or, with `transfer`,
    carried onto the reference mesh and compared with the reference itself: accuracy across resolutions).
    `model` names the trained model a remeshed variant shares with its training-mesh variant (default: the
    label); `overrides` and `dt_scale` change the scenario (e.g. a larger time step)."""

    solver: str
    params: dict = field(default_factory=dict)
    label: str = ""
    remesh: str | None = None
    model: str = ""
    overrides: dict = field(default_factory=dict)
    dt_scale: float = 1.0
    transfer: bool = False

    def scenario(self, sc: Scenario) -> Scenario:
        """The member's scenario with this variant's `overrides` (dotted fields, e.g. {"contact.stiffness": 1e6})
        and its time step times `dt_scale`, validated by the scenario loader."""
        if not self.overrides and self.dt_scale == 1.0:
            return sc
        from scenarios.load import scenario_from_dict, scenario_to_dict

        d = scenario_to_dict(sc)
        d["time"]["dt"] = sc.time.dt * self.dt_scale
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

    @property
    def key(self) -> str:
        """Store key of this run."""
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

    from solvers.run import run_scenario
    from solvers.warp_runtime import cache_root

    register_entries(solvers or {})
    traj = None
    try:
        params = localised(task.params, artefacts, cache_root() / "artefacts")
        with threadpool_limits(threads):
            traj, stats = run_scenario(task.scenario, task.solver, device, params, task.mesh, tet_mesh=mesh)
    except Exception as err:  # a failed run is a row with its reason, never a crash of the matrix
        traj, stats = None, {"failed": True, "failure": f"{type(err).__name__}: {err}", "solver": task.solver}
    stats["params"] = task.params  # the record names the client's artefacts, not the worker's copies
    if traj is not None:
        traj.meta["params"] = task.params
    stats["scenario"] = task.scenario.name
    return RunResult(traj, stats)


def run_tasks(tasks: Sequence[Task], store: RunStore, device: str, jobs: int, executor: str,
              desc: str) -> int:
    """Execute the tasks not yet done, `jobs` at a time, with a progress bar; returns how many were computed.

    Each distinct mesh and artefact is shared with the workers once; the client stores each result as it
    arrives, so an interruption costs only the tasks in flight (a Dask task whose worker dies is rerun on another).
    A task that gives no result (not a failed run, which is a result) is raised once every other one is stored.
    """
    todo = [t for t in {t.key: t for t in tasks}.values() if not store.done(t.key)]
    if not todo:
        return 0
    threads = max(1, (os.cpu_count() or 1) // jobs)
    with make_executor(executor, jobs) as ex:
        meshes: dict = {}
        artefacts: dict = {}
        futures = {}
        for t in todo:
            spec = t.mesh or t.scenario.mesh
            if spec not in meshes:
                meshes[spec] = ex.share(load_mesh(spec))
            for folder in artefact_folders(t.params):
                if folder not in artefacts:
                    artefacts[folder] = ex.share(Artefact.of(folder))
            carried = tuple(artefacts[folder] for folder in artefact_folders(t.params))
            futures[ex.submit(execute, t, meshes[spec], carried, device, threads, entries())] = t
        lost = []
        for f in tqdm(ex.as_completed(futures), total=len(futures), desc=desc, unit="run"):
            try:
                result = f.result()
            except Exception as err:  # no result at all (e.g. every worker that tried it died): the others are
                lost.append(err)      # still stored, and the rerun computes only this one
                continue
            store.save(futures[f].key, result.trajectory, result.stats)
    if lost:
        raise lost[0]
    return len(todo)


def mesh_variant(member: SuiteMember, resolution: str) -> MeshSpec:
    """The scenario's mesh at another resolution of the same catalogue shape; `alt` names the independently
    generated mesh beside the scenario's own resolution (coarse -> coarse_alt)."""
    spec = member.scenario.mesh
    res = f"{spec.resolution}_alt" if resolution == "alt" else resolution
    return MeshSpec(name=spec.name, resolution=res, scale=spec.scale)


def run_suite(suite_name: str, out: str | Path, variants: Sequence[Variant], device: str = "cpu", jobs: int = 1,
              executor: str = "process", report: bool = True, only: str | None = None,
              allow_large: bool = False, reference: str = REFERENCE) -> Path:
    """Run the matrix of `suite_name` with `variants` into `out` (only the members matching the shell pattern
    `only`, if given), every run compared with the `reference` solver's; returns the results.csv path. Every run
    is checked by the resource guard first (`guard_resources`; `allow_large` or the suite's own `allow_large` lifts
    its bounds)."""
    from bench.training import prepare_variants

    out = Path(out)
    store = RunStore(out / "runs")
    suite = load_suite(suite_name).only(only)
    guard_resources(suite, variants, allow_large=allow_large or suite.allow_large)
    t0 = time.perf_counter()
    refs = {m.scenario.name: Task(m.scenario, reference, {}) for m in suite.scenarios}
    remesh_refs = [Task(m.scenario, reference, {}, mesh_variant(m, v.remesh))
                   for m in suite.scenarios for v in variants if v.remesh and not v.transfer]
    run_tasks(list(refs.values()) + remesh_refs, store, device, jobs, executor, "references")
    resolved = prepare_variants(suite, variants, store, refs, out / "models", device)
    tasks = []
    for m in suite.scenarios:
        for v, params in member_variants(resolved, variants, m):
            if params is None:
                continue
            task = variant_task(v, m, params)
            if isinstance(task, Task):
                tasks.append(task)
    run_tasks(tasks, store, device, jobs, executor, "solver variants")
    rows = collect_rows(suite, refs, resolved, variants, store)
    csv = write_results_csv(rows, out / "results.csv")
    write_json_atomic(out / "run.json", {"suite": suite_name, "device": device, "jobs": jobs, "executor": executor,
                                         "variants": [v.__dict__ for v in variants], "only": only,
                                         "reference": reference, "wall_s": time.perf_counter() - t0})
    if report:
        from bench.reporting import build_report  # here, not above: the worker processes need no plotting

        build_report(out)
    return csv


def guard_resources(suite, variants: Sequence[Variant], allow_large: bool = False) -> None:
    """Refuse the whole matrix before any work when one of its runs (a reference, a remeshed reference, a variant
    with its own time step) exceeds the bounds of `scenarios.resources.check_resources`."""
    from scenarios.errors import ScenarioError
    from scenarios.resources import check_runs

    runs = []
    for m in suite.scenarios:
        runs.append((m.scenario, m.scenario.mesh))
        for v in variants:
            try:
                sc = v.scenario(m.scenario)
            except ScenarioError:  # not applicable: a failed row, never run
                continue
            runs.append((sc, mesh_variant(m, v.remesh) if v.remesh else sc.mesh))
    check_runs(runs, allow_large=allow_large)


def variant_task(v: Variant, member: SuiteMember, params: dict) -> Task | str:
    """The task of a variant on a member, or the reason it has none (its overrides make an invalid scenario,
    e.g. the barrier law on a body that starts touching the plane)."""
    from scenarios.errors import ScenarioError

    try:
        sc = v.scenario(member.scenario)
    except ScenarioError as err:
        return f"not applicable: {err}"
    return Task(sc, v.solver, params, mesh_variant(member, v.remesh) if v.remesh else None)


def member_variants(resolved, variants: Sequence[Variant], member: SuiteMember) -> list[tuple[Variant, dict | None]]:
    """The (variant, params) that apply to one member: a per-shape entry only to members of that shape; None
    (a failed row) when a variant has no entry for the member's shape."""
    shape = member.scenario.mesh.name or member.scenario.mesh.key
    out = []
    for v in variants:
        entries = [p for w, p in resolved if w is v]
        match = [p for p in entries if p is not None and p.get("shape", shape) == shape]
        out.append((v, match[0] if match else None))
    return out


def collect_rows(suite, refs: dict[str, Task], resolved, variants: Sequence[Variant], store: RunStore) -> list[dict]:
    """One results row per (member, variant) plus one per reference: identity, metrics, timings."""
    rows = []
    for m in tqdm(suite.scenarios, desc="metrics", unit="scenario"):
        sc = m.scenario
        ref_task = refs[sc.name]
        ref, ref_stats = store.load(ref_task.key)
        base = {"suite": suite.name, "scenario": sc.name, "split": m.split, "mesh": sc.mesh.key,
                "mu": sc.plane.friction if sc.plane else None, "law": sc.contact.law, "tags": " ".join(sc.tags)}
        rows.append(base | {"solver": ref_task.solver, "variant": "reference", "run": ref_task.key, "dt": sc.time.dt}
                    | _timing(ref_stats, ref_stats) | _metrics(ref, ref, sc, ref_stats))
        for v, params in member_variants(resolved, variants, m):
            label = v.label or v.solver
            if params is None:
                rows.append(base | {"solver": v.solver, "variant": label, "status": "failed",
                                    "failure": "no reduced model for this mesh shape"})
                continue
            task = variant_task(v, m, params)
            if not isinstance(task, Task):
                rows.append(base | {"solver": v.solver, "variant": label, "status": "failed", "failure": task})
                continue
            mesh = task.mesh
            traj, stats = store.load(task.key)
            # metrics against the full-space run on the same mesh (the other mesh's own reference when remeshed),
            # or against the reference itself after carrying the trajectory onto its mesh (`transfer`)
            if mesh is None or v.transfer:
                v_ref, v_ref_stats = ref, ref_stats
                if mesh is not None and traj is not None:
                    traj = transfer_to_mesh(traj, ref)
            else:
                v_ref, v_ref_stats = store.load(Task(sc, ref_task.solver, {}, mesh).key)
            row = base | {"solver": v.solver, "variant": label, "run": task.key, "remesh": v.remesh or "",
                          "r": params.get("r"), "mesh": (mesh or sc.mesh).key, "model": v.model or label,
                          "dt": task.scenario.time.dt,
                          "train_mesh": sc.mesh.key if "shape" in params else "", "law": task.scenario.contact.law}
            rows.append(row | _timing(stats, v_ref_stats)
                        | _metrics(v_ref, traj, task.scenario, stats))
    return with_ref_dt_change(with_remesh_ratio(rows))


def with_ref_dt_change(rows: list[dict]) -> list[dict]:
    """Rows with `ref_dt_change` on every row of a scenario that has a run of the reference's solver on the
    reference's mesh at a smaller time step than the reference's: that run's pos_rmse_rel against the reference
    (the smallest such dt where there are several). It is how far the reference moves when its time step is
    refined: where the error shrinks with dt the reference's own time-discretisation error is at least half of it,
    and about twice it once backward Euler is in its first-order range; a reduced model's error of that order is
    within the reference's own accuracy."""
    refs = {r["scenario"]: r for r in rows if r.get("variant") == "reference"}
    ref_dt = {name: r.get("dt") or 0.0 for name, r in refs.items()}
    finer = [r for r in rows if r["scenario"] in refs and r.get("solver") == refs[r["scenario"]].get("solver")
             and not r.get("remesh") and r.get("status") == "ok"
             and r.get("dt") is not None and r["dt"] < ref_dt.get(r["scenario"], 0.0)]
    change = {r["scenario"]: r.get("pos_rmse_rel") for r in sorted(finer, key=lambda r: -r["dt"])}  # finest last
    return [r | {"ref_dt_change": change[r["scenario"]]} if r["scenario"] in change else r for r in rows]


def _timing(stats: dict, ref_stats: dict) -> dict:
    """Timing and solver-health columns (Newton failures, line-search stalls, step retries, the linear solver that
    ran: `linear_solver` of a full-space run's stats); speedup = the reference's step time / this step time, both
    measured in this run."""
    keys = ("setup_s", "warmup_s", "train_s", "step_ms_median", "step_ms_p95", "newton_iters_mean",
            "newton_iters_max", "not_converged", "line_search_stalls", "step_retries", "linear_solver")
    row = {k: stats.get(k) for k in keys}
    if stats.get("step_ms_median") and ref_stats.get("step_ms_median"):
        row["speedup"] = ref_stats["step_ms_median"] / stats["step_ms_median"]
    return row


def _metrics(ref, traj, sc: Scenario, stats: dict) -> dict:
    """Metric columns of one row (a reduced run's trajectory carries its basis, for the projection error); a failed
    run (diverged, or no trajectory) gets `status = failed`, its reason and no accuracy metrics (a truncated
    trajectory would look accurate)."""
    if traj is None or ref is None or stats.get("failed"):
        return {"status": "failed", "failure": stats.get("failure") or "no trajectory", "finite": False}
    contact = replace(sc.contact, stiffness=stats["contact_stiffness"])  # the stiffness the run resolved
    return {"status": "ok", "failure": ""} | compare(ref, traj, plane=sc.plane, material=sc.material,
                                                     gravity=sc.gravity, basis=traj.basis,
                                                     contact=contact if sc.effects.friction else None)

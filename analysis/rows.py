"""Row building: the rows of results.csv from the stored runs of a suite (the harness, `bench.runner`, runs them
and writes the table; what a row holds is decided here).

A row is one run: a member's reference, a level of a truth ladder, or a solver variant on a member. It holds the
run's identity and parameters, its metrics against the full-space run it is compared with (`analysis.metrics`),
its timings, and with a ground truth its error against the truth and the truth's own figures (`analysis.truth`);
the figures across rows (`analysis.derived`, `analysis.truth.with_frontier`) are added last. The columns are those
of `analysis.schema`.
"""

from __future__ import annotations

from collections.abc import Mapping, Sequence
from dataclasses import replace

from tqdm import tqdm

from frictionbench.analysis.curves import with_curve_floors
from frictionbench.analysis.derived import with_ref_dt_change, with_remesh_ratio
from frictionbench.analysis.metrics import ComparedRun, pos_rmse_rel, proj_rmse_rel
from frictionbench.analysis.records import LadderRuns, RunRecord, RunTask, Trajectories
from frictionbench.analysis.outcomes import ladder_outcome_columns, outcome_cells, outcome_scene, outcome_values
from frictionbench.analysis.schema import computed_cells
from frictionbench.analysis.timescales import SceneTimescales, scene_columns
from frictionbench.analysis.transfer import transfer_to_mesh
from frictionbench.analysis.truth import (TruthEstimate, assess_ladder, certified_horizon, level_ratio,
                                          wall_s_per_sim_s, with_frontier)
from frictionbench.scenarios.meshes import bbox_diagonal
from frictionbench.scenarios.spec import Scenario
from frictionbench.scenarios.suites import Suite, TruthSpec
from frictionbench.solvers.integrators import get_integrator
from frictionbench.solvers.trajectory import Trajectory


def ladder_label(integrator: str, k: int, kind: str = "step") -> str:
    """The variant label of level k of a truth ladder with `integrator` (`[truth]` kind "step": dt / 2^k, kind
    "tolerance": time.tol = start_tol / 8^k, labelled `ladder-<integrator>-tol<k>`); the rows carry the integrator and
    k as their own columns (`ladder`, `ladder_level`), so nothing reads them back from the label."""
    return f"ladder-{integrator}-{k}" if kind == "step" else f"ladder-{integrator}-tol{k}"


def truth_columns(ladders: Mapping[str, LadderRuns], spec_tol: float, kind: str = "step"
                  ) -> tuple[dict, TruthEstimate | None, RunTask | None]:
    """(the truth columns of every row of a scenario, its estimate, the truth's task) from its ladders (the
    truth's first) of `kind` (`[truth]` kind: the Richardson estimate takes its `level_ratio`; a tolerance ladder's
    truth also gives its time.tol, `truth_tol`); no truth where its ladder's first run failed."""
    truth = next(iter(ladders.values()))
    if not truth.tasks:
        return {"truth_certified": False, "truth_integrator": truth.integrator}, None, None
    integrator = get_integrator(truth.integrator)
    est = assess_ladder(truth.differences, spec_tol, integrator, level_ratio(kind, integrator))
    finest = truth.tasks[-1]
    horizon = certified_horizon(*truth.frame_differences, spec_tol) if truth.frame_differences else None
    return ({"truth_certified": est.certified and not truth.failed, "truth_err_est": est.err_est,
             "truth_order": est.order, "truth_dt": finest.scenario.time.dt, "truth_depth": est.level,
             "truth_integrator": truth.integrator, "truth_horizon_s": horizon}
            | ({"truth_tol": finest.scenario.time.tol} if kind == "tolerance" else {}), est, finest)


def collect_rows(suite: Suite, refs: Mapping[str, RunTask], records: Sequence[RunRecord], runs: Trajectories,
                 ladders: Mapping[str, Mapping[str, LadderRuns]] | None = None, truth: TruthSpec | None = None
                 ) -> list[dict]:
    """One results row per (member, variant) plus one per reference and one per ladder run: identity, metrics,
    timings; with ladders, every row also gets err_truth (against its scenario's truth; remeshed runs carried onto
    the truth's mesh first) and err_truth_horizon (the same over the frames up to the truth's certified horizon), the
    truth's columns (`truth_columns`) and the frontier's (`with_frontier`), and every variant row its error's parts:
    err_time (the full-space run it is compared with, against the truth: the time step's share), pos_rmse_rel
    (against that run: the reduction's share) and, with a subspace, err_projection (the truth projected onto it: the
    basis's share). Every finished run's row also gets its outcome values (`analysis.outcomes`) and, with a truth,
    their errors against the truth's and each outcome's convergence over the truth's ladder. `refs` are the members'
    reference runs by scenario name, `records` the variants' runs as the harness resolved them
    (`analysis.records.RunRecord`, from `bench.runner.run_records`), in row order, and `runs` the stored runs by key
    (`bench.store.RunStore`). Every row of a scenario whose reference ran gets the scene's time scales on the
    reference's mesh with the patch of its last frame and its own step's resolution of them (`analysis.timescales`:
    computed once per mesh, material and step). A variant's `tags` are its rows' cells as they are: a point of a curve
    (`bench.matrix.step_ladder`) gives its curve's, and the finest finished row of each curve its floor
    (`analysis.curves.with_curve_floors`)."""
    rows = []
    timescales = SceneTimescales()
    by_member: dict[str, list[RunRecord]] = {}
    for rec in records:
        by_member.setdefault(rec.member, []).append(rec)
    for m in tqdm(suite.scenarios, desc="metrics", unit="scenario"):
        sc = m.scenario
        ref_task = refs[sc.name]
        ref, ref_stats = runs.load(ref_task.key)
        base = {"suite": suite.name, "scenario": sc.name, "split": m.split, "mesh": sc.mesh.key,
                "mu": sc.plane.friction if sc.plane else None, "law": sc.contact.law, "tags": " ".join(sc.tags)}
        first = len(rows)
        scales = timescales.scene_of_run(sc, ref) if ref is not None else None
        if scales is not None:
            base |= scene_columns(scales)
        scene = outcome_scene(sc, ref_stats.get("contact_stiffness"), None if ref_stats.get("failed") else ref)
        values: dict[str, dict] = {}  # outcome values by run key: a ladder level is also a row

        def outcomes_of(key: str, traj: Trajectory, values=values, scene=scene) -> dict:
            """The outcome values of the stored run `key` of the member's scene, computed once."""
            if key not in values:
                values[key] = outcome_values(traj, scene)
            return values[key]

        truth_traj = truth_early = truth_values = None
        if ladders and sc.name in ladders:
            columns, _, truth_task = truth_columns(ladders[sc.name], truth.tol if truth else 0.0,
                                                   truth.kind if truth else "step")
            base |= columns
            truth_traj = runs.load(truth_task.key)[0] if truth_task else None
            if truth_traj is not None and columns.get("truth_horizon_s") is not None:
                truth_early = truth_traj.until(columns["truth_horizon_s"])
            if truth_traj is not None:
                ladder = next(iter(ladders[sc.name].values()))
                levels = [outcomes_of(t.key, truth_traj if t is truth_task else runs.load(t.key)[0])
                          for t in ladder.tasks]
                base |= ladder_outcome_columns(levels, get_integrator(ladder.integrator),
                                               bbox_diagonal(truth_traj.X), ladder.failed)
                truth_values = levels[-1]

        def on_truth_mesh(traj, other_mesh: bool, truth_traj=truth_traj):
            """The run on the truth's mesh: carried onto it from another mesh."""
            return transfer_to_mesh(traj, truth_traj) if other_mesh and truth_traj is not None else traj

        def err_truth(here, truth_traj=truth_traj, truth_early=truth_early) -> dict:
            """err_truth and err_truth_horizon of a run on the truth's mesh (`on_truth_mesh`)."""
            if truth_traj is None or here is None:
                return {}
            return ({"err_truth": pos_rmse_rel(truth_traj, here)}
                    | ({"err_truth_horizon": pos_rmse_rel(truth_early, here)} if truth_early is not None else {}))

        def outcomes(here, key: str | None, task_scene=None, truth_traj=truth_traj, truth_values=truth_values,
                     scene=scene) -> dict:
            """The outcome cells of a run on the truth's mesh (`on_truth_mesh`): key names a run of the member's
            scene (cached); None a variant's run, with its scenario's contact law (`task_scene`, and its resolved
            stiffness) for when it first touches."""
            if here is None:
                return {}
            L = bbox_diagonal((truth_traj if truth_traj is not None else here).X)
            if key is None:
                contact = outcome_scene(*task_scene, None).contact
                values = outcome_values(here, scene if contact == scene.contact else replace(scene, contact=contact))
            else:
                values = outcomes_of(key, here)
            return outcome_cells(values, truth_values, L)

        def error_parts(traj, run_ref, other_mesh: bool, truth_traj=truth_traj) -> dict:
            """err_time: the full-space run this row is compared with, against the truth; err_projection: the
            truth (carried onto the row's mesh) projected onto the row's subspace, where it has one."""
            if truth_traj is None or run_ref is None:
                return {}
            parts = {"err_time": err_truth(on_truth_mesh(run_ref, other_mesh))["err_truth"]}
            if traj is not None and traj.basis is not None:
                truth_here = transfer_to_mesh(truth_traj, traj) if other_mesh else truth_traj
                parts["err_projection"] = proj_rmse_rel(truth_here, traj.basis,
                                                        frame=traj.meta.get("basis_frame", "world"))
            return parts

        rows.append(base | {"solver": ref_task.solver, "variant": "reference", "run": ref_task.key, "dt": sc.time.dt,
                            "integrator": sc.time.integrator}
                    | run_timing(ref_stats, ref_stats, sc.time.dt) | run_metrics(ref, ref, sc, ref_stats)
                    | (err_truth(ref) | outcomes(ref, ref_task.key) if not ref_stats.get("failed") else {}))
        for integrator, ladder in (ladders or {}).get(sc.name, {}).items():
            for k, task in enumerate(ladder.tasks):
                traj, stats = runs.load(task.key)
                label = ladder_label(integrator, k, truth.kind if truth else "step")
                rows.append(base | {"solver": task.solver, "variant": label, "ladder": integrator,
                                    "ladder_level": k, "run": task.key, "dt": task.scenario.time.dt,
                                    "integrator": integrator}
                            | run_timing(stats, ref_stats, task.scenario.time.dt) | run_metrics(ref, traj, sc, stats)
                            | err_truth(traj) | outcomes(traj, task.key))
        for rec in by_member.get(sc.name, ()):
            ident = {"solver": rec.solver, "variant": rec.variant}
            if rec.key is None:
                rows.append(base | ident | {"status": "failed", "failure": rec.failure} | rec.tags)
                continue
            task_sc = rec.scenario
            traj, stats = runs.load(rec.key)
            # metrics against the full-space run on the same mesh (the other mesh's own reference when remeshed),
            # or against the reference itself after carrying the trajectory onto its mesh (`transfer`)
            if rec.compare_key == ref_task.key:
                v_ref, v_ref_stats = ref, ref_stats
                if rec.transfer and traj is not None:
                    traj = transfer_to_mesh(traj, ref)
            else:
                v_ref, v_ref_stats = runs.load(rec.compare_key)
            row = (base | ident | {"run": rec.key} | rec.columns
                   | {"dt": task_sc.time.dt, "integrator": task_sc.time.integrator, "law": task_sc.contact.law}
                   | rec.tags)
            metrics = run_metrics(v_ref, traj, task_sc, stats)
            here = on_truth_mesh(traj, rec.other_mesh) if metrics["status"] == "ok" else None
            truth_err = (err_truth(here) | error_parts(traj, v_ref, rec.other_mesh)
                         | outcomes(here, None, (task_sc, stats.get("contact_stiffness")))
                         if here is not None else {})
            rows.append(row | run_timing(stats, v_ref_stats, task_sc.time.dt) | metrics | truth_err)
        if scales is not None:  # each run's step against the scene's time scales
            for row in rows[first:]:
                if row.get("dt") is not None:  # an adaptive run: at its median step
                    row |= timescales.resolution(scales, row["integrator"], row.get("dt_median") or row["dt"])
    return with_curve_floors(with_frontier(with_ref_dt_change(with_remesh_ratio(rows))))


#: The columns of an adaptive run (`solvers.step_stats.stats_summary`, `solvers.run.run_scenario`), on its rows only.
ADAPTIVE_COLUMNS = ("tol", "steps", "rejected_steps", "steps_over_tol", "dt_min_used", "dt_median")


def run_timing(stats: dict, ref_stats: dict, dt: float) -> dict:
    """Timing and solver-health columns (Newton failures, line-search stalls, step retries, the linear solver that
    ran: `linear_solver` of a full-space run's stats; `timed_in`: the session that ran it, `bench.runner.SESSION`);
    speedup = the reference's step time / this step time, both measured in this run; wall_s_per_sim_s = the steps'
    wall time per simulated second at time step dt [s], an adaptive run's over the sum of its steps' sizes (warm-up,
    setup and training apart), whose rows also get ADAPTIVE_COLUMNS."""
    keys = ("setup_s", "warmup_s", "train_s", "step_ms_median", "step_ms_p95", "newton_iters_mean",
            "newton_iters_max", "not_converged", "line_search_stalls", "step_retries", "linear_solver", "timed_in")
    row = {k: stats.get(k) for k in keys}
    steps = stats.get("per_step", [])
    adaptive = "tol" in stats
    row["wall_s_per_sim_s"] = wall_s_per_sim_s([s["wall_s"] for s in steps],
                                               [s["dt"] for s in steps] if adaptive else dt)
    if adaptive:
        row |= {k: stats.get(k) for k in ADAPTIVE_COLUMNS}
    if stats.get("step_ms_median") and ref_stats.get("step_ms_median"):
        row["speedup"] = ref_stats["step_ms_median"] / stats["step_ms_median"]
    return row


def run_metrics(ref: Trajectory | None, traj: Trajectory | None, sc: Scenario, stats: dict) -> dict:
    """Metric columns of one row: a finished run's status and every computed column of the schema
    (`analysis.schema.computed_cells`) against its reference `ref`, in the scenario `sc` with the contact stiffness
    the run resolved (a reduced run's trajectory carries its basis, for the projection error); a failed run
    (diverged, or no trajectory) gets `status = failed`, its reason and no accuracy metrics (a truncated trajectory
    would look accurate)."""
    if traj is None or ref is None or stats.get("failed"):
        return {"status": "failed", "failure": stats.get("failure") or "no trajectory", "finite": False}
    return {"status": "ok", "failure": ""} | computed_cells(ComparedRun(ref, traj, sc, stats["contact_stiffness"]))

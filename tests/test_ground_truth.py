"""The ground truth in the matrix: the suite's [truth] table, the ladder's runs and rows, err_truth and the frontier
columns, and undecidable gate verdicts (in `gate` and `compare`)."""

from __future__ import annotations

import io
import json
from contextlib import redirect_stderr, redirect_stdout
from dataclasses import replace
from pathlib import Path

import numpy as np
import pandas as pd
import pytest

from frictionbench.analysis.metrics import error_over_time, pos_rmse_rel, proj_rmse_rel
from frictionbench.analysis.truth import AT_MOST, MORE_ACCURATE, certified_horizon, richardson, with_frontier
from frictionbench.bench.cli import main
from frictionbench.bench.compare import compare_results
from frictionbench.bench.gates import BOUND_ONLY, NO_LADDER_COST, UNCERTIFIED, check, load_gates
from frictionbench.bench.runner import SESSION, Ladder, Variant, run_suite
from frictionbench.bench.store import RunStore
from frictionbench.scenarios.errors import ScenarioError
from frictionbench.scenarios.suites import load_suite, suite_from_dict
from frictionbench.solvers.integrators import BackwardEuler

from scenes import block_drop, mu_axis, suite_tables, write_toml

SUITE = suite_tables("ladder", block_drop(clearance=0.005, duration=0.04), mu_axis(0.3),
                     description="one short block drop",
                     truth={"tol": 1e-6, "depth": 2, "integrator": "backward-euler"})


def _suite_dict(**truth) -> dict:
    return suite_tables("s", block_drop(clearance=None, dt=None, duration=None), mu_axis(0.3), truth=truth)


def test_the_truth_table_has_defaults_and_validated_fields():
    spec = suite_from_dict(_suite_dict()).truth
    assert (spec.tol, spec.depth, spec.integrator, spec.ladders) == (0.005, 4, "bdf2", ())
    assert suite_from_dict({k: v for k, v in _suite_dict().items() if k != "truth"}).truth is None
    spec = suite_from_dict(_suite_dict(tol=0.01, depth=3, integrator="backward-euler",
                                       ladders=["bdf2", "backward-euler"])).truth
    assert (spec.tol, spec.depth, spec.integrator, spec.ladders) == (0.01, 3, "backward-euler", ("bdf2",))


@pytest.mark.parametrize(("truth", "field", "value"), [
    ({"depth": 0}, "truth.depth", "0"), ({"depth": 13}, "truth.depth", "13"), ({"depth": 2.5}, "truth.depth", "2.5"),
    ({"depth": True}, "truth.depth", "True"), ({"tol": 0.0}, "truth.tol", "0.0"), ({"tol": 0.9}, "truth.tol", "0.9"),
    ({"tol": "small"}, "truth.tol", "small"), ({"integrator": "rk4"}, "truth.integrator", "rk4"),
    ({"ladders": ["euler"]}, "truth.ladders[0]", "euler"), ({"depht": 3}, "depht", "3"),
    ({"newton_tol": 0.0}, "truth.newton_tol", "0.0"), ({"newton_tol": 0.1}, "truth.newton_tol", "0.1"),
    ({"newton_tol": True}, "truth.newton_tol", "True"), ({"chord": "yes"}, "truth.chord", "yes"),
    ({"chord_contraction": 0.5}, "truth.chord_contraction", "0.5"),
    ({"chord": True, "chord_contraction": 1.0}, "truth.chord_contraction", "1.0")])
def test_a_bad_truth_table_is_refused_naming_the_field_and_value(truth, field, value):
    with pytest.raises(ScenarioError) as err:
        suite_from_dict(_suite_dict(**truth))
    assert field in str(err.value) and value in str(err.value)


def test_a_truth_newton_tolerance_reaches_the_ladders_runs():
    suite = suite_from_dict(_suite_dict(newton_tol=1e-4))
    spec = suite.truth
    assert spec.newton_tol == 1e-4 and spec.solver_params == {"tol": 1e-4}
    assert Ladder(suite.scenarios[0], spec.integrator, spec=spec).task(2).params == {"tol": 1e-4}
    plain = suite_from_dict(_suite_dict())
    assert Ladder(plain.scenarios[0], plain.truth.integrator, spec=plain.truth).task(2).params == {}
    chord = suite_from_dict(_suite_dict(newton_tol=1e-4, chord=True)).truth
    assert chord.solver_params == {"tol": 1e-4, "chord": True} and chord.with_(depth=3).chord
    modified = suite_from_dict(_suite_dict(chord=True, chord_contraction=0.5)).truth
    assert modified.solver_params == {"chord": True, "chord_contraction": 0.5}
    assert modified.with_(depth=3).chord_contraction == 0.5


def test_the_chord_test_and_modified_newton_factorise_less_and_meet_the_same_tolerance():
    """On a damped slide under the fixed-point lag (the default suite's truth settings, a few steps in contact),
    the chord test factorises less than Newton's method, modified Newton (chord_contraction) less again, and
    either's end state lies within what the Newton tolerance allows of the plain run's."""
    from frictionbench.bench.benchmark_step import mid_contact_state, truth_scenario
    from frictionbench.scenarios.meshes import load_mesh
    from frictionbench.solvers.build import build_model
    from frictionbench.solvers.full.solver import FullSpaceSolver, NewtonSettings
    from frictionbench.solvers.model import State

    sc, params = truth_scenario("quick/p1_mu0.5", 2)
    model = build_model(sc, load_mesh(sc.mesh))
    state, _, _ = mid_contact_state(model, 1)
    ends, factorisations = {}, {}
    modes = {"off": {"chord": False, "chord_contraction": 0.0}, "test": {"chord": True, "chord_contraction": 0.0},
             "modified": {"chord": True, "chord_contraction": 0.5}}
    for mode, settings in modes.items():
        solver = FullSpaceSolver(model, settings=NewtonSettings(linear="superlu", **(params | settings)))
        calls = []
        factorize = solver.factoriser.factorize
        solver.factoriser.factorize = lambda values: (calls.append(1), factorize(values))[1]
        s = state
        for _ in range(4):
            out = State(s.x, s.v, s.t)
            assert solver.step(s, out, sc.time.dt).converged
            s = out
        ends[mode], factorisations[mode] = s.x, len(calls)
    assert factorisations["modified"] < factorisations["test"] < factorisations["off"]
    for mode in ("test", "modified"):
        drift = np.abs(ends[mode] - ends["off"]).max() / model.L
        assert 0.0 < drift < 4 * params["tol"] * sc.time.dt  # four steps' velocity errors of at most tol L each


def test_each_re_lag_starts_modified_newtons_contraction_test_afresh(monkeypatch):
    """Under the fixed-point lag a re-lag poses another problem: the first solve after it judges its chord step
    against no earlier step (residual inf), while a step's first solve does too and a solve that goes on under the
    same lag keeps its reference."""
    from frictionbench.bench.benchmark_step import mid_contact_state, truth_scenario
    from frictionbench.scenarios.meshes import load_mesh
    from frictionbench.solvers.build import build_model
    from frictionbench.solvers.full import solver as full
    from frictionbench.solvers.model import State

    sc, params = truth_scenario("quick/p1_mu0.5", 2)
    model = build_model(sc, load_mesh(sc.mesh))
    state, _, _ = mid_contact_state(model, 1)
    events = []
    relag, minimise = full._LaggedStep.relag, full.minimise
    monkeypatch.setattr(full._LaggedStep, "relag", lambda self, *a: (events.append("relag"), relag(self, *a))[1])
    monkeypatch.setattr(full, "minimise", lambda *a: (events.append(a[-1]), minimise(*a))[1])
    solver = full.FullSpaceSolver(model, settings=full.NewtonSettings(linear="superlu", **params))
    assert params["chord_contraction"] > 0 and sc.contact.lag == "fixed-point"
    for _ in range(3):
        out = State(state.x, state.v, state.t)
        solver.step(state, out, sc.time.dt)
        state = out
    after_relag = [b for a, b in zip(events, events[1:]) if a == "relag" and b != "relag"]
    assert len(after_relag) > 3 and all(r == np.inf for r in after_relag)
    carried = [b for a, b in zip(events, events[1:]) if a != "relag" and b != "relag"]
    assert all(np.isfinite(r) for r in carried)


def test_bad_truth_flags_exit_2_before_any_work(tmp_path: Path, capsys):
    suite = write_toml(tmp_path / "ladder.toml", SUITE)
    out = tmp_path / "out"
    assert main(["run", "--suite", str(suite), "--solvers", "full", "--truth-depth", "40", "--out", str(out)]) == 2
    assert "--truth-depth = 40" in capsys.readouterr().err
    assert not (out / "runs").exists()


def _ladder(tmp_path: Path, variants=(), **options) -> pd.DataFrame:
    """The results rows of SUITE (written to tmp_path, output in tmp_path / "out") run with `variants`
    (`run_suite`'s `options`); a second call resumes from the stored runs."""
    suite = tmp_path / "ladder.toml"
    if not suite.exists():
        write_toml(suite, SUITE)
    return pd.read_csv(run_suite(str(suite), tmp_path / "out", variants=list(variants), report=False, **options))


def test_the_ladder_gives_a_truth_err_truth_and_frontier_columns_and_resumes(tmp_path: Path):
    out = tmp_path / "out"
    rows = _ladder(tmp_path)
    store = RunStore(out / "runs")
    ladder = rows[rows["ladder"] == "backward-euler"].sort_values("dt", ascending=False)
    assert list(ladder["variant"]) == [f"ladder-backward-euler-{k}" for k in range(3)]
    assert ladder["dt"].tolist() == pytest.approx([0.01, 0.005, 0.0025])
    ref = rows[rows["variant"] == "reference"].iloc[0]
    assert ladder.iloc[0]["run"] == ref["run"]  # level 0 with the reference's integrator is the reference run
    trajs = [store.load(key)[0] for key in ladder["run"]]
    assert all(t.n_frames == 5 and (abs(t.t - trajs[0].t) < 1e-12).all() for t in trajs)  # frames line up
    d = [pos_rmse_rel(trajs[0], trajs[1]), pos_rmse_rel(trajs[1], trajs[2])]
    est, p, _ = richardson(d, BackwardEuler())
    assert not ref["truth_certified"] and ref["truth_depth"] == 2 and ref["truth_dt"] == pytest.approx(0.0025)
    assert ref["truth_err_est"] == pytest.approx(est) and ref["truth_order"] == pytest.approx(p)
    assert ref["err_truth"] == pytest.approx(pos_rmse_rel(trajs[2], trajs[0]))
    assert ladder.iloc[2]["err_truth"] == 0.0 and ladder.iloc[2]["frontier_note"] == "the truth"
    stats = store.load(ref["run"])[1]
    assert ref["wall_s_per_sim_s"] == pytest.approx(sum(s["wall_s"] for s in stats["per_step"]) / 0.04)
    assert ref["speedup_equal_accuracy"] == pytest.approx(1.0)  # the reference lies on its own ladder
    assert (rows["integrator"] == "backward-euler").all()
    # every run was timed in this session, the ladder's with the rest: each speed-up divides costs timed side by side
    assert (rows["timed_in"] == SESSION).all() and all(store.load(k)[1]["timed_in"] == SESSION for k in rows["run"])
    assert rows["timed_beside_ladder"].astype(bool).all()
    # a looser tolerance certifies at the first halving, from the stored runs (nothing is recomputed)
    stamps = {key: (store.folder(key) / "stats.json").stat().st_mtime_ns for key in ladder["run"]}
    rows = _ladder(tmp_path, truth_overrides={"tol": 0.5})
    ref = rows[rows["variant"] == "reference"].iloc[0]
    assert ref["truth_certified"] and ref["truth_depth"] == 1 and ref["truth_err_est"] == pytest.approx(d[0])
    assert all((store.folder(k) / "stats.json").stat().st_mtime_ns == t for k, t in stamps.items())
    assert json.loads((out / "run.json").read_text())["truth"]["tol"] == 0.5
    rows = _ladder(tmp_path, with_truth=False)
    assert "err_truth" not in rows and "ladder" not in rows


def test_a_speedup_says_whether_its_ladder_was_timed_in_its_session():
    """`timed_beside_ladder`: True where the row's run and every ladder run of its scenario were timed in one
    session, False where any was timed in another (a store resumed with a new variant), None where a run does not
    say (stores from before sessions were recorded); the speed-up itself is computed the same either way."""
    ladder = [{"scenario": "s", "solver": "full", "variant": f"ladder-bdf2-{k}", "ladder": "bdf2", "status": "ok",
               "err_truth": err, "wall_s_per_sim_s": cost, "timed_in": "A"}
              for k, (err, cost) in enumerate([(0.1, 10.0), (0.01, 40.0), (0.0, 80.0)])]
    runs = [{"scenario": "s", "solver": "pod", "variant": v, "ladder": "", "status": "ok", "err_truth": 0.03,
             "wall_s_per_sim_s": 0.5, "timed_in": t} for v, t in (("same", "A"), ("later", "B"), ("old", None))]
    out = {r["variant"]: r for r in with_frontier(ladder + runs)}
    assert out["same"]["timed_beside_ladder"] is True and out["later"]["timed_beside_ladder"] is False
    assert out["old"]["timed_beside_ladder"] is None
    assert out["same"]["speedup_equal_accuracy"] == out["later"]["speedup_equal_accuracy"] > 1.0
    ladder[1]["timed_in"] = "B"  # a ladder timed over two sessions is beside neither
    assert {r["variant"]: r["timed_beside_ladder"] for r in with_frontier(ladder + runs)}["later"] is False
    ladder[1]["timed_in"] = float("nan")  # read back from a CSV without it
    assert {r["variant"]: r["timed_beside_ladder"] for r in with_frontier(ladder + runs)}["same"] is None


def _truth_rows(certified: bool, est: float) -> pd.DataFrame:
    return pd.DataFrame([{"suite": "quick", "scenario": "quick/a", "solver": "licrom", "variant": "m", "split": "train",
                          "status": "ok", "err_truth": 0.012, "pos_rmse_rel": 0.004, "truth_certified": certified,
                          "truth_err_est": est}])


GATES = [{"suite": "quick", "variant": "licrom/m", "metric": "err_truth", "max": 0.02},
         {"suite": "quick", "variant": "licrom/m", "metric": "pos_rmse_rel", "max": 0.02},
         {"suite": "quick", "variant": "licrom/m", "metric": "pos_rmse_rel", "max": 0.02, "against_truth": True}]


def test_an_uncertified_truth_makes_a_tight_accuracy_verdict_undecidable():
    verdicts = check(_truth_rows(certified=False, est=0.01), GATES, "quick")
    assert [v.status for v in verdicts] == ["undecidable", "passed", "undecidable"]  # 0.02 < 3 x 0.01; pos_rmse_rel
    assert [v.reason for v in verdicts] == [UNCERTIFIED, "", UNCERTIFIED]  # only where marked against_truth
    assert not any(v.passed or v.failed for v in check(_truth_rows(False, 0.01), GATES[:1], "quick"))
    assert [v.status for v in check(_truth_rows(False, 0.005), GATES, "quick")] == ["passed"] * 3  # 0.02 >= 0.015
    assert [v.status for v in check(_truth_rows(True, 0.05), GATES, "quick")] == ["passed"] * 3  # certified
    failing = [g | {"max": 0.001} for g in GATES]
    assert [v.status for v in check(_truth_rows(True, 0.0001), failing, "quick")] == ["failed"] * 3


def test_every_variant_row_splits_its_error_into_projection_reduction_and_time(tmp_path: Path):
    out = tmp_path / "out"
    rows = _ladder(tmp_path, [Variant("affine", {}, label="affine12"), Variant("pod", {"r": 4}, label="r4"),
                              Variant("full", {}, label="dt-half", dt_scale=0.5)])
    store = RunStore(out / "runs")
    ref = rows[rows["variant"] == "reference"].iloc[0]
    truth = store.load(rows[rows["frontier_note"] == "the truth"].iloc[0]["run"])[0]
    runs = rows[rows["variant"].isin(["affine12", "r4", "dt-half"])].set_index("variant")
    assert runs["status"].eq("ok").all() and len(runs) == 3
    # the time step's share: the full-space run each is compared with (the reference) against the truth
    assert runs["err_time"].tolist() == pytest.approx([ref["err_truth"]] * 3)
    for label in ("affine12", "r4"):
        row = runs.loc[label]
        basis = store.load(row["run"])[0].basis
        assert row["err_projection"] == pytest.approx(proj_rmse_rel(truth, basis))
        assert row["err_projection"] <= row["err_truth"] + 1e-12  # no run in the subspace beats the projection
        assert row["err_truth"] <= row["pos_rmse_rel"] + row["err_time"] + 1e-12  # the RMS triangle inequality
    assert pd.isna(runs.loc["dt-half", "err_projection"])  # a full-space run has no subspace
    assert pd.isna(ref.get("err_time")) and "Where the error comes from" in _report(out)


def test_a_truth_is_certified_up_to_the_frame_where_its_two_finest_runs_part(tmp_path: Path):
    rows = _ladder(tmp_path)
    store = RunStore(tmp_path / "out" / "runs")
    ladder = rows[rows["ladder"] == "backward-euler"].sort_values("dt", ascending=False)
    coarse, fine = (store.load(key)[0] for key in ladder["run"].iloc[1:])
    t, e = error_over_time(coarse, fine)
    assert rows["truth_horizon_s"].iloc[0] == 0.0  # tol 1e-6: only the initial frame agrees that well
    tol = 1.0001 * max(e[:2])  # the first two frames within it, and the whole run (RMS) not: still depth 2
    assert tol < min(pos_rmse_rel(coarse, fine), ladder["err_truth"].iloc[0]) and e[-1] > tol
    again = _ladder(tmp_path, truth_overrides={"tol": tol})
    horizon = again["truth_horizon_s"].iloc[0]
    assert horizon == certified_horizon(t, e, tol) and t[1] <= horizon < t[-1]
    ref = again[again["variant"] == "reference"].iloc[0]
    assert ref["err_truth_horizon"] == pytest.approx(pos_rmse_rel(fine.until(horizon), store.load(ref["run"])[0]))
    assert ref["err_truth_horizon"] < ref["err_truth"]  # the frames where the ladder has not converged count


def _report(out: Path) -> str:
    from frictionbench.bench.reporting import build_report

    return build_report(out).read_text(encoding="utf-8")


def test_a_speedup_gate_on_a_run_more_accurate_than_the_ladder_is_undecidable():
    rows = pd.DataFrame([{"suite": "quick", "scenario": "quick/a", "solver": "licrom", "variant": "m",
                          "status": "ok", "speedup_equal_accuracy": None, "frontier_note": note}
                         for note in (MORE_ACCURATE, "no ladder")])
    gate = {"suite": "quick", "variant": "licrom/m", "metric": "speedup_equal_accuracy", "min": 10.0}
    verdicts = check(rows, [gate], "quick")
    assert [(v.status, v.reason) for v in verdicts] == [("undecidable", NO_LADDER_COST), ("failed", "")]


def test_a_speedup_gate_met_only_by_an_upper_bound_is_undecidable_and_a_bound_below_it_fails():
    note = AT_MOST
    rows = pd.DataFrame([{"suite": "quick", "scenario": f"quick/{i}", "solver": "licrom", "variant": "m",
                          "status": "ok", "speedup_equal_accuracy": s, "frontier_note": n}
                         for i, (s, n) in enumerate([(20.0, note), (5.0, note), (20.0, "")])])
    gate = {"suite": "quick", "variant": "licrom/m", "metric": "speedup_equal_accuracy", "min": 10.0}
    verdicts = check(rows, [gate], "quick")
    assert [v.status for v in verdicts] == ["undecidable", "failed", "passed"]
    assert [v.reason for v in verdicts] == [BOUND_ONLY, "", ""]


def test_the_shipped_speed_gates_bind_on_speed_at_equal_accuracy_and_not_on_per_step_speed():
    gates = load_gates()
    assert all(g.get("advisory") for g in gates if g["metric"] == "speedup")  # a ratio of step times: noise
    binding = [g for g in gates if g["metric"] == "speedup_equal_accuracy" and not g.get("advisory")]
    assert {g["suite"] for g in binding} == {"quick", "quick-undamped", "paper-damped"}
    assert all("min" in g for g in binding)
    # that their labels exist in the suites' default sets or a named set: tests/test_runner.py's guard over all gates
    damped = next(g for g in binding if g["suite"] == "paper-damped")
    bound = AT_MOST
    cases = [(1.5, ""), (0.9, ""), (2.0, bound), (0.9, bound)]  # measured: passes, fails; bounds: nothing, fails
    rows = pd.DataFrame([{"suite": "paper-damped", "scenario": f"paper-damped/{i}", "solver": "licrom",
                          "variant": damped["variant"][-1].split("/", 1)[1], "status": "ok",
                          "speedup_equal_accuracy": f * damped["min"], "frontier_note": note}
                         for i, (f, note) in enumerate(cases)])
    assert [v.status for v in check(rows, [damped], "paper-damped")] == ["passed", "failed", "undecidable", "failed"]


def test_undecidable_is_no_failure_of_gate_nor_a_regression_of_compare(tmp_path: Path):
    out = tmp_path / "out"
    out.mkdir()
    _truth_rows(certified=False, est=0.01).to_csv(out / "results.csv", index=False)
    (out / "run.json").write_text(json.dumps({"suite": "quick"}))
    gates = tmp_path / "gates.toml"
    gates.write_text('[[gate]]\nsuite = "quick"\nvariant = "licrom/m"\nmetric = "err_truth"\nmax = 0.02\n'
                     '[[gate]]\nsuite = "quick"\nvariant = "licrom/m"\nmetric = "pos_rmse_rel"\nmax = 0.02\n')
    text = io.StringIO()
    with redirect_stdout(text), redirect_stderr(io.StringIO()):
        code = main(["gate", str(out), "--gates", str(gates)])
    assert code == 0 and "UNDECIDABLE" in text.getvalue() and "1 undecidable" in text.getvalue()
    gates.write_text(gates.read_text().replace("max = 0.02\n", "max = 0.001\n", 1).replace("0.02", "0.001"))
    with redirect_stdout(io.StringIO()), redirect_stderr(io.StringIO()):
        assert main(["gate", str(out), "--gates", str(gates)]) == 1  # pos_rmse_rel 0.004 > 0.001 fails
    # the baseline passed the err_truth gate with a certified truth; the new set's truth is uncertified
    comparison = compare_results(_truth_rows(True, 0.001), _truth_rows(False, 0.01), gates=GATES[:1])
    row = comparison[comparison["metric"] == "err_truth"].iloc[0]
    assert row["verdict"] != "regression" and "undecidable" in row["reason"]


def test_the_shipped_suites_with_a_truth():
    assert all(load_suite(name).truth is not None for name in ("quick", "quick-undamped", "paper", "paper-damped"))
    assert load_suite("quick-undamped").truth.depth <= 2  # a CI-sized ladder that is not expected to certify


def test_the_deepest_ladder_run_passes_the_resource_guard_before_any_work():
    from frictionbench.bench.runner import guard_resources, truth_config

    d = _suite_dict(depth=5, integrator="backward-euler")
    d["base"]["time"] = {"dt": 1e-4, "duration": 1.0}  # 10,000 steps; the ladder's deepest run takes 320,000
    suite = suite_from_dict(d)
    guard_resources(suite, [])
    with pytest.raises(ScenarioError, match="320,000 steps"):
        guard_resources(suite, [], truth=truth_config(suite))
    guard_resources(suite, [], allow_large=True, truth=truth_config(suite))
    assert truth_config(suite, with_truth=False) is None


def test_paper_damped_is_the_papers_matrix_with_material_damping():
    paper, damped = load_suite("paper"), load_suite("paper-damped")
    assert [(m.split, dict(m.labels)) for m in damped.scenarios] == [(m.split, dict(m.labels)) for m in paper.scenarios]
    for a, b in zip(paper.scenarios, damped.scenarios):
        assert a.scenario.material.damping_ratio is None and a.scenario.material.viscosity is None
        assert b.scenario.material.damping_ratio == 0.05 and b.scenario.effects.viscosity
        assert b.scenario.plane == a.scenario.plane and b.scenario.mesh == a.scenario.mesh
    # the same ladder, under the fixed-point contact lag (friction's start-lagged pressure stalls a damped ladder),
    # stepped as quick's truth is (modified Newton at Newton's tolerance 1e-4 L/s), at a contraction of its own
    quick = load_suite("quick").truth
    assert damped.truth == replace(paper.truth, contact_lag="fixed-point", newton_tol=quick.newton_tol,
                                   chord=quick.chord, chord_contraction=damped.truth.chord_contraction)
    assert paper.truth.contact_lag == "start" and damped.truth.chord_contraction >= quick.chord_contraction > 0


def test_quick_is_quick_undamped_with_paper_dampeds_damping_and_truth_lag():
    quick, twin, damped = load_suite("quick-undamped"), load_suite("quick"), load_suite("paper-damped")
    assert [(m.split, dict(m.labels)) for m in twin.scenarios] == [(m.split, dict(m.labels)) for m in quick.scenarios]
    base = damped.scenarios[0].scenario
    for a, b in zip(quick.scenarios, twin.scenarios):
        assert a.scenario.material.damping_ratio is None and a.scenario.contact.damping_ratio is None
        assert (b.scenario.material, b.scenario.contact) == (base.material, base.contact)  # paper-damped's damping
        assert b.scenario.name == a.scenario.name.replace("quick-undamped/", "quick/")
        undamped = replace(b.scenario, name=a.scenario.name, description=a.scenario.description, tags=a.scenario.tags,
                           effects=a.scenario.effects, material=a.scenario.material, contact=a.scenario.contact)
        assert undamped == a.scenario  # only the damping differs: mesh, plane, drop and time are quick's
    assert twin.truth == replace(quick.truth, depth=5, contact_lag="fixed-point", newton_tol=1e-4, chord=True,
                                     chord_contraction=0.5)


def test_a_bdf2_truth_with_a_backward_euler_frontier_ladder(tmp_path: Path):
    bdf2_truth = SUITE["truth"] | {"integrator": "bdf2", "ladders": ["backward-euler"]}
    suite = write_toml(tmp_path / "ladder.toml", SUITE | {"truth": bdf2_truth})
    rows = pd.read_csv(run_suite(str(suite), tmp_path / "out", variants=[], report=False))
    ref = rows[rows["variant"] == "reference"].iloc[0]
    assert ref["truth_integrator"] == "bdf2" and ref["integrator"] == "backward-euler" and ref["truth_depth"] == 2
    bdf2, euler = rows[rows["ladder"] == "bdf2"], rows[rows["ladder"] == "backward-euler"]
    assert len(bdf2) == len(euler) == 3 and (bdf2["integrator"] == "bdf2").all()
    # the ladder's integrator and level are columns of their own (the label is only a name), empty on other rows
    assert bdf2["ladder_level"].tolist() == euler["ladder_level"].tolist() == [0, 1, 2]
    assert rows.loc[rows["ladder"].isna(), "ladder_level"].isna().all() and rows["ladder"].isna().sum() == 1
    truth = rows[(rows["ladder"] == ref["truth_integrator"]) & (rows["ladder_level"] == ref["truth_depth"])]
    assert len(truth) == 1 and truth.iloc[0]["err_truth"] == 0.0
    assert ref["run"] not in set(bdf2["run"]) and ref["run"] in set(euler["run"])  # BDF2 at dt is a run of its own
    assert (euler["err_truth"] > 0).all() and bdf2["err_truth"].min() == 0.0  # the truth is the finest BDF2 run


@pytest.mark.parametrize("name", ["quick", "quick-undamped", "paper", "paper-damped"])
def test_shipped_truths_pass_the_guard(name):
    from frictionbench.bench.cli import parse_variants
    from frictionbench.bench.runner import guard_resources, truth_config

    suite = load_suite(name)
    guard_resources(suite, parse_variants(None, suite=name), truth=truth_config(suite))

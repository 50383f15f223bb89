"""Adaptive, error-controlled steps (`time.tol`, docs/physics.md "Adaptive steps"): the integrators' local error
estimates against the true local error, the controller and the frame landing, a block drop under the full-space and
the reduced solvers (steps shrink at the impact and grow in free flight, rejections there, frames at the fixed
times, error falling with tol against a fine fixed-step run), fixed-step runs unchanged, validation and the resource
guard, the tolerance ladder of the truth and its Richardson ratio, the cost per simulated second and the step-size
plot."""

from __future__ import annotations

import math
from dataclasses import replace
from pathlib import Path

import numpy as np
import pandas as pd
import pytest

from frictionbench.analysis.metrics import pos_rmse_rel
from frictionbench.analysis.rows import ladder_label
from frictionbench.analysis.truth import level_ratio, richardson, wall_s_per_sim_s
from frictionbench.bench.reporting import build_report
from frictionbench.bench.runner import guard_resources, ladder_variant, run_suite
from frictionbench.bench.store import RunStore
from frictionbench.reports.plots import step_size_figure
from frictionbench.scenarios.errors import ScenarioError
from frictionbench.scenarios.load import scenario_from_dict, scenario_hash, scenario_to_dict
from frictionbench.scenarios.resources import check_resources
from frictionbench.scenarios.spec import MAX_STEPS, TimeSpec
from frictionbench.scenarios.suites import TOLERANCE_FACTOR, suite_from_dict
from frictionbench.solvers.build import build_model, initial_state
from frictionbench.solvers.full.solver import FullSpaceSolver
from frictionbench.solvers.integrators import BDF2, BackwardEuler, Integrator
from frictionbench.solvers.reduced.bases import affine_basis
from frictionbench.solvers.reduced.solver import ReducedSolver
from frictionbench.solvers.simulate import CONTROLLER, advance, error_norm, next_step, simulate

from scenes import G, block_drop, mu_axis, suite_tables, write_toml

DT, DURATION, CLEARANCE = 0.01, 0.06, 0.01
#: When the dropped block first touches the plane [s].
T_IMPACT = math.sqrt(2.0 * CLEARANCE / G)


# ----- the local error estimate ---------------------------------------------------------------------------------
def _oscillator_step(integrator: Integrator, omega: float, t0: float, h: float, w: float):
    """One step of h [s] of x'' = -omega^2 x (x = cos(omega t)) from exact data at t0 (and t0 - h / w for BDF2):
    (estimated local error, true local error, order). The implicit step of this linear system in closed form:
    x^{n+1} = (x_bar + h_eff v_bar) / (1 + h_eff^2 omega^2)."""
    x = lambda t: np.array([np.cos(omega * t)])  # noqa: E731
    v = lambda t: np.array([-omega * np.sin(omega * t)])  # noqa: E731
    prev = (x(t0 - h / w), v(t0 - h / w), h / w) if integrator.history else None
    lag = integrator.lagged(x(t0), v(t0), h, prev)
    x_new = (lag.y_bar + lag.h_eff * lag.v_bar) / (1.0 + lag.h_eff ** 2 * omega ** 2)
    est = integrator.local_error(x_new, x(t0), v(t0), h, prev)
    return float(est.error[0]), float((x_new - x(t0 + h))[0]), est.order


@pytest.mark.parametrize("integrator", [BackwardEuler(), BDF2(restart_on_step_change=False)])
@pytest.mark.parametrize("w", [0.25, 0.5, 1.0, 2.0])
def test_the_local_error_estimate_matches_the_true_local_error(integrator, w):
    """On a harmonic oscillator from exact data the estimate is the true local error within 10% at omega h = 0.03
    (and closer at half the step: its own error is of higher order), at every step ratio w."""
    ratios = []
    for h in (0.01, 0.005):
        est, true, order = _oscillator_step(integrator, 3.0, 0.3, h, w)
        assert order == integrator.order
        ratios.append(est / true)
    assert abs(ratios[0] - 1.0) < 0.1
    assert abs(ratios[1] - 1.0) < abs(ratios[0] - 1.0)


@pytest.mark.parametrize("w", [0.5, 1.0, 2.0])
def test_bdf2s_estimate_vanishes_on_a_quadratic_and_backward_eulers_is_its_curvature_term(w):
    """A quadratic trajectory (constant acceleration a): BDF2 and its predictor are exact, the estimate is 0; backward
    Euler's local error is h^2 a / 2, its estimate (y_new - y - h v) / 2 with y_new its own step."""
    a, h, t0 = -9.81, 0.01, 0.2
    y = lambda t: np.array([1.0 + 0.5 * t + 0.5 * a * t * t])  # noqa: E731
    dy = lambda t: np.array([0.5 + a * t])  # noqa: E731
    bdf2 = BDF2(restart_on_step_change=False)
    prev = (y(t0 - h / w), dy(t0 - h / w), h / w)
    lag = bdf2.lagged(y(t0), dy(t0), h, prev)
    y_new = lag.y_tilde + lag.h_eff ** 2 * a  # the implicit step: y = y_bar + h_eff (v_bar + h_eff a)
    assert y_new[0] == pytest.approx(y(t0 + h)[0], abs=1e-14)
    assert abs(bdf2.local_error(y_new, y(t0), dy(t0), h, prev).error[0]) < 1e-14
    be_new = y(t0) + h * (dy(t0) + h * a)
    est = BackwardEuler().local_error(be_new, y(t0), dy(t0), h)
    assert est.order == 1 and est.error[0] == pytest.approx((be_new - y(t0 + h))[0], rel=1e-9)
    assert bdf2.local_error(be_new, y(t0), dy(t0), h).order == 1  # BDF2's first step is backward Euler


def test_the_error_norm_is_the_rms_over_vertices_over_L():
    e = np.zeros((4, 3))
    e[0] = (3.0, 4.0, 0.0)
    assert error_norm(e, 2.0) == pytest.approx(math.sqrt(25.0 / 4.0) / 2.0)


def test_the_controller_and_the_frame_landing():
    assert CONTROLLER.factor(0.0, 1e-4, 2) == CONTROLLER.fac_max
    assert CONTROLLER.factor(1e-4, 1e-4, 2) == pytest.approx(CONTROLLER.safety)
    assert CONTROLLER.factor(1e-4 * 8.0, 1e-4, 2) == pytest.approx(CONTROLLER.safety / 2.0)  # (1/8)^(1/3)
    assert CONTROLLER.factor(1.0, 1e-4, 1) == CONTROLLER.fac_min
    assert CONTROLLER.factor(1e-9, 1e-4, 2, grow=False) == 1.0
    assert next_step(0.02, 0.05, 0.01, 1e-4) == 0.01  # never above dt
    assert next_step(0.004, 0.003, 0.01, 1e-4) == 0.003  # lands on the frame
    assert next_step(0.004, 0.006, 0.01, 1e-4) == 0.003  # two even steps rather than a step and a sliver
    assert next_step(1e-6, 0.5, 0.01, 1e-4) == 1e-4  # never below the smallest step


# ----- a block drop under the full-space solver -----------------------------------------------------------------
def _drop(block, solver: str = "full", mu: float = 0.0, **time):
    """The coarse block dropped from CLEARANCE onto a plane with friction mu under BDF2, run for DURATION by the
    full-space solver or the reduced one with the affine basis (`solver` = "affine"): (trajectory, per-step stats,
    model)."""
    sc = scenario_from_dict(block_drop(clearance=CLEARANCE, time={"dt": DT, "duration": DURATION, "integrator": "bdf2"}
                                       | time, plane={"friction": mu}) | {"name": "drop"})
    model = build_model(sc, block)
    if solver == "full":
        traj, stats = simulate(model, FullSpaceSolver(model))
    else:
        reduced = ReducedSolver(model, affine_basis(model.X))
        traj, stats = simulate(model, reduced, reduced.project(initial_state(model)))
    return traj, stats, model


@pytest.fixture(scope="module")
def drops(block):
    """The frictionless drop at tol 1e-2, 1e-3, 1e-4, and fixed at dt / 64 (the fine run the errors are taken
    against): frictionless, so that no term lags its pressure by a step and the integrator's order holds in contact
    (with friction the lag adds a first-order error the estimate does not see: docs/physics.md)."""
    runs = {tol: _drop(block, tol=tol) for tol in (1e-2, 1e-3, 1e-4)}
    runs["fine"] = _drop(block, dt=DT / 64, frame_every=64)
    return runs


def test_steps_shrink_at_the_impact_with_rejections_and_grow_in_free_flight(drops):
    _, stats, _ = drops[1e-4]
    dt = np.array([s.dt for s in stats])
    t_end = np.cumsum(dt)
    rejected = np.array([s.rejected for s in stats])
    impact = (t_end > T_IMPACT - 0.003) & (t_end < T_IMPACT + 0.005)
    assert dt[t_end < T_IMPACT - 0.005].max() == pytest.approx(DT, rel=1e-9)  # free flight: the largest step
    assert dt[impact].min() < DT / 16  # the impact: far smaller
    assert rejected[impact].sum() > 0 and rejected[impact].sum() >= rejected.sum() / 2  # most rejections there
    assert dt[t_end > T_IMPACT + 0.005].max() > 2.0 * dt[impact].min()  # and growing again after it
    assert t_end[-1] == pytest.approx(DURATION, rel=1e-12)
    assert all(s.error <= 1e-4 for s in stats)  # no step at the smallest one: every step met tol


def test_frames_stay_at_the_fixed_step_times(drops):
    traj = drops[1e-4][0]
    assert np.array_equal(traj.t, np.array([0.0] + [k * DT for k in range(1, 7)]))
    assert traj.n_frames == drops["fine"][0].n_frames


def test_a_tighter_tolerance_gives_a_smaller_error_against_a_fine_fixed_step_run(drops):
    fine = drops["fine"][0]
    errors = [pos_rmse_rel(fine, drops[tol][0]) for tol in (1e-2, 1e-3, 1e-4)]
    assert errors[0] > 1.5 * errors[1] > 1.5 * 1.5 * errors[2]
    assert errors[2] < errors[0] / 4.0
    assert 0.05 * 1e-2 < errors[0] < 1e-2  # the global error follows tol's order of magnitude (fewer decades)
    steps = [len(drops[tol][1]) for tol in (1e-2, 1e-3, 1e-4)]
    assert steps[0] < steps[1] < steps[2] < len(drops["fine"][1])


def test_an_adaptive_run_uses_the_variable_step_coefficients(drops):
    model = drops[1e-4][2]
    assert model.integrator.restart_on_step_change is False


def test_the_reduced_solver_runs_adaptive_too(block):
    traj, stats, _ = _drop(block, "affine", mu=0.5, tol=1e-4)
    fine, _, _ = _drop(block, "affine", mu=0.5, dt=DT / 32, frame_every=32)
    fixed, _, _ = _drop(block, "affine", mu=0.5)
    dt = np.array([s.dt for s in stats])
    t_end = np.cumsum(dt)
    assert np.array_equal(traj.t, np.array([0.0] + [k * DT for k in range(1, 7)])) and traj.q.shape == (7, 12)
    assert dt[t_end < T_IMPACT - 0.005].max() == pytest.approx(DT, rel=1e-9) and dt.min() < DT / 8
    assert sum(s.rejected for s in stats) > 0
    assert pos_rmse_rel(fine, traj) < pos_rmse_rel(fine, fixed) / 2.0


def test_at_the_smallest_step_a_step_over_tolerance_is_accepted_and_counted(block):
    """An unreachable tol: every step ends at time.dt_min, over tol, and is counted."""
    sc = scenario_from_dict({"name": "fall", "plane": False, "mesh": {"name": "block", "resolution": "coarse"},
                             "time": {"dt": DT, "duration": 0.02, "integrator": "bdf2", "tol": 1e-14,
                                      "dt_min": DT / 4}})
    from frictionbench.solvers.run import run_scenario

    traj, stats = run_scenario(sc, tet_mesh=block)
    over = [s["error"] > 1e-14 for s in stats["per_step"]]
    assert stats["per_step"][0]["dt"] == DT / 4 and over[0]  # backward Euler's first step: h^2 g / 4 over tol
    assert stats["dt_min_used"] == pytest.approx(DT / 4) and stats["rejected_steps"] > 0 and stats["tol"] == 1e-14
    assert stats["steps_over_tol"] == sum(over) >= 1
    assert np.array_equal(traj.t, [0.0, DT, 2 * DT])


def test_a_failed_solve_is_retried_smaller_and_counted(block):
    sc = scenario_from_dict(block_drop(clearance=None, time={"dt": DT, "duration": 0.02, "integrator": "bdf2",
                                                             "tol": 1.0}) | {"name": "flaky", "plane": False})
    model = build_model(sc, block)
    solver = FullSpaceSolver(model)
    step = solver.step

    def flaky(state_in, state_out, dt):  # a step larger than 0.004 s fails
        return replace(step(state_in, state_out, dt), converged=dt <= 0.004)

    solver.step = flaky
    traj, stats = simulate(model, solver)
    assert all(s.dt <= 0.004 and s.converged for s in stats)
    assert stats[0].retries == 2 and stats[0].rejected == 2 and stats[0].dt == DT / 4
    assert np.array_equal(traj.t, [0.0, DT, 2 * DT])


# ----- fixed-step runs unchanged --------------------------------------------------------------------------------
def test_a_fixed_step_run_is_the_plain_loop_bit_for_bit(block):
    """simulate without time.tol is the loop of `advance` at dt, its frames every frame_every steps; the scenario's
    canonical dict (its hash) has no adaptive keys and the integrator restarts on a change of step size."""
    sc = scenario_from_dict(block_drop(time={"dt": DT, "duration": DURATION, "integrator": "bdf2", "frame_every": 2})
                            | {"name": "fixed"})
    assert "tol" not in scenario_to_dict(sc)["time"] and "dt_min" not in scenario_to_dict(sc)["time"]
    adaptive = replace(sc, time=replace(sc.time, tol=1e-4))
    assert scenario_hash(adaptive) != scenario_hash(sc) and scenario_from_dict(scenario_to_dict(adaptive)) == adaptive
    model = build_model(sc, block)
    assert model.integrator.restart_on_step_change is True
    traj, stats = simulate(model, FullSpaceSolver(model))
    solver, state, xs = FullSpaceSolver(model), initial_state(model), []
    for k in range(1, sc.time.n_steps + 1):
        state, _ = advance(solver, state, DT)
        if k % 2 == 0:
            xs.append(state.x)
    assert np.array_equal(traj.x[1:], np.array(xs))
    assert all(s.dt is None and s.rejected == 0 for s in stats)
    walls = [s.wall_s for s in stats]
    assert wall_s_per_sim_s(walls, DT) == float(sum(walls)) / (len(walls) * DT)  # the fixed-step formula


def test_an_adaptive_runs_cost_is_its_wall_time_over_the_simulated_time():
    assert wall_s_per_sim_s([0.1, 0.3], [0.01, 0.002]) == pytest.approx(0.4 / 0.012)
    assert wall_s_per_sim_s([0.1, 0.3], 0.01) == pytest.approx(0.4 / 0.02)


# ----- validation and the resource guard -----------------------------------------------------------------------
@pytest.mark.parametrize(("time", "field", "value"), [
    ({"tol": 0.0}, "time.tol", "0.0"), ({"tol": -1e-3}, "time.tol", "-0.001"), ({"tol": math.nan}, "time.tol", "nan"),
    ({"tol": math.inf}, "time.tol", "inf"), ({"tol": "tight"}, "time.tol", "tight"),
    ({"tol": 1e-3, "dt_min": 0.0}, "time.dt_min", "0.0"), ({"tol": 1e-3, "dt_min": 0.02}, "time.dt_min", "0.02"),
    ({"dt_min": 1e-4}, "time.dt_min", "0.0001")])
def test_bad_adaptive_fields_are_refused_naming_the_field_and_value(time, field, value):
    with pytest.raises(ScenarioError) as err:
        scenario_from_dict(block_drop(time={"dt": DT} | time) | {"name": "bad"})
    assert field in str(err.value) and value in str(err.value)


def test_the_resource_guard_bounds_an_adaptive_run_by_its_smallest_step():
    sc = scenario_from_dict(block_drop(time={"dt": DT, "duration": 3.0, "tol": 1e-4}) | {"name": "long"})
    assert sc.time.min_step == pytest.approx(3.0 / MAX_STEPS)  # the default keeps it within the bound
    check_resources(sc, None)
    assert TimeSpec(dt=DT, duration=0.5, tol=1e-4).min_step == DT / 1024
    tiny = replace(sc, time=replace(sc.time, dt_min=1e-7))
    with pytest.raises(ScenarioError, match="time.dt_min") as err:
        check_resources(tiny, None)
    assert "3e+07 steps" in str(err.value) or "30,000,000" in str(err.value)
    check_resources(tiny, None, allow_large=True)


# ----- the tolerance ladder -------------------------------------------------------------------------------------
def _suite(**truth) -> dict:
    return suite_tables("adaptive", block_drop(clearance=0.002, duration=0.03), mu_axis(0.0), truth=truth)


def test_the_tolerance_ladder_fields_are_validated():
    spec = suite_from_dict(_suite(kind="tolerance", start_tol=1e-3)).truth
    assert spec.kind == "tolerance" and spec.level_tol(2) == pytest.approx(1e-3 / 64) and TOLERANCE_FACTOR == 8.0
    assert suite_from_dict(_suite()).truth.level_tol(1) is None
    for truth, field, value in [({"kind": "tolerance"}, "truth.start_tol", "None"),
                                ({"start_tol": 1e-3}, "truth.start_tol", "0.001"),
                                ({"kind": "tol"}, "truth.kind", "tol"),
                                ({"kind": "tolerance", "start_tol": 0.0}, "truth.start_tol", "0.0"),
                                ({"kind": "tolerance", "start_tol": "1e-3"}, "truth.start_tol", "1e-3")]:
        with pytest.raises(ScenarioError) as err:
            suite_from_dict(_suite(**truth))
        assert field in str(err.value) and value in str(err.value)


def test_a_tolerance_ladder_level_divides_tol_and_keeps_dt_and_frames():
    sc = scenario_from_dict(block_drop(time={"dt": DT, "frame_every": 2}) | {"name": "x"})
    v = ladder_variant(sc, "bdf2", 2, tol=1e-3 / 64)
    level = v.scenario(sc)
    assert (level.time.tol, level.time.dt, level.time.frame_every) == (1e-3 / 64, DT, 2)
    assert v.label == "ladder-bdf2-tol2" == ladder_label("bdf2", 2, "tolerance")
    assert ladder_label("bdf2", 2) == "ladder-bdf2-2" and ladder_variant(sc, "bdf2", 2).scenario(sc).time.dt == DT / 4


def test_richardson_takes_the_ladders_refinement_ratio():
    assert level_ratio("step", BDF2()) == 2.0 and level_ratio("tolerance", BDF2()) == 2.0  # 8^(1/3)
    r = level_ratio("tolerance", BackwardEuler())
    assert r == pytest.approx(math.sqrt(8.0))
    est, p, observed = richardson([4e-3 * r, 4e-3], BackwardEuler(), r)  # first order at ratio r
    assert observed == pytest.approx(1.0) and p == pytest.approx(1.0) and est == pytest.approx(4e-3 / (r - 1.0))
    d = [3e-3, 1e-3, 2e-4]
    assert richardson(d, BDF2(), 2.0) == richardson(d, BDF2())  # a step ladder: unchanged


def test_a_tolerance_ladder_truth_with_rows_and_a_step_size_plot(tmp_path: Path):
    suite = write_toml(tmp_path / "adaptive.toml", _suite(kind="tolerance", start_tol=4e-3, depth=2, tol=1e-6,
                                                          integrator="bdf2"))
    guard_resources(suite_from_dict(_suite(kind="tolerance", start_tol=1e-3, depth=2)), [])
    out = tmp_path / "out"
    rows = pd.read_csv(run_suite(str(suite), out, variants=[], report=False))
    ladder = rows[rows["ladder"] == "bdf2"].sort_values("ladder_level")
    assert list(ladder["variant"]) == [f"ladder-bdf2-tol{k}" for k in range(3)]
    assert ladder["tol"].tolist() == pytest.approx([4e-3, 4e-3 / 8, 4e-3 / 64])
    assert (ladder["dt"] == 0.01).all() and (ladder["rejected_steps"] >= 0).all()
    assert (ladder["steps"].diff().dropna() > 0).all()  # tighter: more steps
    ref = rows[rows["variant"] == "reference"].iloc[0]
    assert ref["truth_depth"] == 2 and ref["truth_tol"] == pytest.approx(4e-3 / 64) and "tol" not in ref.dropna()
    store = RunStore(out / "runs")
    trajs = [store.load(key)[0] for key in ladder["run"]]
    d = [pos_rmse_rel(trajs[0], trajs[1]), pos_rmse_rel(trajs[1], trajs[2])]
    est, p, _ = richardson(d, BDF2(), 2.0)
    assert ref["truth_err_est"] == pytest.approx(est) and ref["truth_order"] == pytest.approx(p)
    stats = store.stats(ladder.iloc[1]["run"])
    assert ladder.iloc[1]["wall_s_per_sim_s"] == pytest.approx(
        sum(s["wall_s"] for s in stats["per_step"]) / sum(s["dt"] for s in stats["per_step"]))
    assert sum(s["dt"] for s in stats["per_step"]) == pytest.approx(0.03)
    page = build_report(out).read_text()
    assert 'id="steps-0"' in page and "step size of the adaptive runs" in page


def test_the_step_size_figure_marks_rejected_steps():
    records = [{"dt": 0.01, "rejected": 0}, {"dt": 0.002, "rejected": 3}, {"dt": 0.004, "rejected": 0}]
    fig = step_size_figure({"full/ladder-bdf2-tol0": records}, "drop")
    line, marks = fig["data"]
    assert line["x"] == pytest.approx([0.01, 0.012, 0.016]) and line["y"] == [0.01, 0.002, 0.004]
    assert marks["x"] == pytest.approx([0.012]) and "3 rejected" in marks["hovertext"][0]
    assert fig["layout"]["yaxis"]["type"] == "log"


def test_the_adaptive_variant_set_runs_the_reference_solver_with_adaptive_bdf2():
    from frictionbench.bench.matrix import variant_set

    sc = scenario_from_dict(block_drop() | {"name": "x"})
    scenarios = [v.scenario(sc) for v in variant_set("adaptive")]
    assert [s.time.tol for s in scenarios] == [1e-3, 1e-4, 1e-5]
    assert all(s.time.integrator == "bdf2" and s.time.dt == sc.time.dt for s in scenarios)

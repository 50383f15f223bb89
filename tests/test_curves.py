"""Each reduced variant's own curve: its step ladder (`bench.variants.step_ladder`), the rows' curve columns, the
floor rule (`analysis.curves`), the frontier's line per curve and the floor table beside it."""

from __future__ import annotations

import html
from pathlib import Path

import pandas as pd
import pytest

from frictionbench.analysis.curves import (CUBATURE, CUBATURE_MARGIN, FEW_LEVELS, FLATTEN_DROP, FLOORS, REDUCTION,
                                           SUBSPACE, SUBSPACE_SHARE, TIME_STEP, TRUTH, curve_floor, with_curve_floors)
from frictionbench.analysis.truth import UNDECIDABLE_FACTOR
from frictionbench.bench.runner import Variant, run_suite
from frictionbench.bench.store import RunStore
from frictionbench.bench.variants import (AFFINE_R24, AFFINE_R24_CUB60, DEFAULT, SUITE_DEFAULTS, step_ladder,
                                          variant_set)
from frictionbench.reports.html import write_report_html
from frictionbench.reports.plots import frontier_figure
from frictionbench.scenarios.load import scenario_from_dict
from frictionbench.solvers.full.solver import NewtonSettings

from scenes import block_drop, mu_axis, suite_tables, write_toml
from test_reports import HOSTILE, check_html


def test_a_step_ladder_halves_the_step_keeps_the_frames_and_shares_the_model():
    ladder = step_ladder(AFFINE_R24_CUB60, levels=(0, 1, 2, 3), integrators=(None, "bdf2"), twin=AFFINE_R24)
    assert [v.label for v in ladder] == [
        "affine-r24-cub60", "affine-r24-cub60-dt/2", "affine-r24-cub60-dt/4", "affine-r24-cub60-dt/8",
        "affine-r24-cub60-bdf2", "affine-r24-cub60-bdf2-dt/2", "affine-r24-cub60-bdf2-dt/4",
        "affine-r24-cub60-bdf2-dt/8"]
    assert [v.dt_scale for v in ladder] == [1.0, 0.5, 0.25, 0.125] * 2
    assert [v.curve_level for v in ladder] == [0, 1, 2, 3] * 2
    assert [v.curve for v in ladder] == ["affine-r24-cub60"] * 4 + ["affine-r24-cub60-bdf2"] * 4
    assert [v.curve_twin for v in ladder] == ["affine-r24"] * 4 + ["affine-r24-bdf2"] * 4
    # one trained model: the parameters (what the training key is made of) are the base's, the model its label
    assert all(v.params == AFFINE_R24_CUB60.params and v.model == "affine-r24-cub60" for v in ladder)
    assert [v.overrides for v in ladder] == [{}] * 4 + [{"time.integrator": "bdf2"}] * 4
    sc = scenario_from_dict(block_drop(time={"dt": 0.01, "duration": 0.04, "frame_every": 2}) | {"name": "s"})
    level = ladder[6].scenario(sc)  # bdf2, dt / 4: frames every 8 steps, at the scene's frame times
    assert (level.time.dt, level.time.frame_every, level.time.integrator) == (pytest.approx(0.0025), 8, "bdf2")
    assert ladder[0].scenario(sc) is sc  # level 0 with the scene's integrator is the variant itself
    assert all(v.curve_twin == "" for v in step_ladder(AFFINE_R24, levels=(0, 1)))
    with pytest.raises(ValueError, match="levels"):
        step_ladder(AFFINE_R24, levels=(0, 0))
    with pytest.raises(ValueError, match="rk4"):
        step_ladder(AFFINE_R24, integrators=(None, "rk4"))


def test_the_licrom_ladder_set_is_two_curves_per_cubature_and_in_no_default():
    ladder = variant_set("licrom-ladder")
    assert len(ladder) == 20 and {v.curve for v in ladder} == {"affine-r24", "affine-r24-bdf2", "affine-r24-cub60",
                                                               "affine-r24-cub60-bdf2",
                                                               "affine-r24-cub60-fixed-point-bdf2"}
    assert {v.params["cubature"] for v in ladder} == {"all", "optimized:60"}
    fixed_point = [v for v in ladder if v.curve == "affine-r24-cub60-fixed-point-bdf2"]
    sc = scenario_from_dict(block_drop() | {"name": "s"})
    assert all(v.scenario(sc).contact.lag == "fixed-point" and v.model == "affine-r24-cub60" for v in fixed_point)
    assert all(v.scenario(sc).contact.lag == "start" for v in ladder if v not in fixed_point)
    assert all("licrom-ladder" not in s.split(",") for s in (DEFAULT, *SUITE_DEFAULTS.values()))


def test_the_rank_dynamics_set_runs_every_variant_at_the_truth_ladders_step_settings():
    sc = scenario_from_dict(block_drop(time={"dt": 0.01, "duration": 0.04, "frame_every": 2}) | {"name": "s"})
    rank = variant_set("rank-dynamics")
    assert len(rank) == 11 and len({v.label for v in rank}) == 11
    for v in rank:
        level = v.scenario(sc)
        assert (level.time.dt, level.time.frame_every) == (pytest.approx(0.0025), 8)
        assert (level.time.integrator, level.contact.lag) == ("bdf2", "fixed-point")
        assert v.label.endswith("-fixed-point-bdf2-dt/4")
    assert {(v.params["r"], v.training) for v in rank if v.solver == "pod"} == {
        (12, "truth"), (36, "truth"), (84, "truth"), (36, "reference"), (84, "reference")}
    assert {(v.params["r"], v.training) for v in rank if v.solver == "licrom"} == {
        (r, data) for r in (48, 96) for data in ("reference", "truth")}
    assert all("rank-dynamics" not in s.split(",") for s in (DEFAULT, *SUITE_DEFAULTS.values()))


def test_the_pod_cubature_set_draws_curves_under_three_lags():
    sc = scenario_from_dict(block_drop(time={"dt": 0.01, "duration": 0.04, "frame_every": 2}) | {"name": "s"})
    pod = variant_set("pod-cubature")
    assert len(pod) == 36 and len({v.label for v in pod}) == 36 and all(v.solver == "pod" for v in pod)
    assert {(v.params["r"], v.params["cubature"], v.training) for v in pod} == {
        (r, f"optimized:{c}", data) for r, c in ((36, 90), (84, 210)) for data in ("truth", "reference")}
    lags = []
    for v in pod:
        level = v.scenario(sc)
        assert level.time.integrator == "bdf2" and v.model == v.curve.removesuffix("-bdf2")
        assert level.time.dt in (pytest.approx(0.01), pytest.approx(0.005), pytest.approx(0.0025))
        lags.append(level.contact.lag)
        assert level.contact.lag == "start" or f"-{level.contact.lag}-" in v.label
    assert lags.count("start") == lags.count("corrected") == lags.count("fixed-point") == 12
    assert len({v.curve for v in pod}) == 12
    assert all("pod-cubature" not in s.split(",") for s in (DEFAULT, *SUITE_DEFAULTS.values()))


def test_the_pod_remesh_set_runs_pod_cubature_points_beside_their_twins_on_the_other_mesh():
    points = {v.label: v for v in variant_set("pod-cubature")}
    remesh = variant_set("pod-remesh")
    own, other = [v for v in remesh if not v.remesh], [v for v in remesh if v.remesh]
    assert len(own) == len(other) == 12 and all(points[v.label] == v for v in own)  # the same runs: stored ones reused
    for v in other:
        twin = points[v.remesh_of]
        assert v.remesh == "alt" and v.label == f"{twin.label}-remesh" and v.model == twin.model
        assert (v.params, v.overrides, v.dt_scale, v.frame_scale, v.training) == (
            twin.params, twin.overrides, twin.dt_scale, twin.frame_scale, twin.training)
        assert not v.curve and v.curve_level is None
    assert {v.remesh_of for v in other} == {v.label for v in own}
    assert all("pod-remesh" not in s.split(",") for s in (DEFAULT, *SUITE_DEFAULTS.values()))


def test_every_level_of_a_licrom_ladder_trains_nothing_of_its_own(tmp_path: Path, licrom_trainings):
    """prepare (what `bench.training.prepare_variants` calls per variant) resolves every level to the one
    checkpoint, trained once."""
    from frictionbench.solvers.registry import get_solver

    data = [tmp_path / "a.npz"]
    resolved = [get_solver(v.solver)(device="cpu", **v.params).prepare("cheese", data, tmp_path / "models", "s")
                for v in step_ladder(AFFINE_R24)]
    assert len(licrom_trainings) == 1 and len({r["checkpoint"] for r in resolved}) == 1


def _row(curve: str, level: int, err: float, **cells) -> dict:
    return {"scenario": "s", "solver": "licrom", "status": "ok", "curve": curve, "curve_level": level,
            "err_truth": err} | cells


def test_the_floor_rule_reaches_every_verdict():
    flat = (1.0 - FLATTEN_DROP) * 1.01  # the last halving lowered err_truth by just less than FLATTEN_DROP
    assert curve_floor([0], [0.1]) == FEW_LEVELS
    assert curve_floor([0, 2], [0.2, 0.1]) == FEW_LEVELS  # no successive levels: no halving to judge
    assert curve_floor([0, 1, 2], [0.4, 0.2, 0.2 * (1.0 - FLATTEN_DROP)]) == TIME_STEP
    assert curve_floor([1, 2], [0.1, 0.1 * flat], truth_err_est=0.1 / UNDECIDABLE_FACTOR) == TRUTH
    e = 0.1 * flat
    assert curve_floor([1, 2], [0.1, e], err_projection=e, twin_err_truth=CUBATURE_MARGIN * e) == CUBATURE
    assert curve_floor([1, 2], [0.1, e], err_projection=SUBSPACE_SHARE * e, twin_err_truth=0.9 * e) == SUBSPACE
    assert curve_floor([1, 2], [0.1, e], err_projection=0.4 * e, twin_err_truth=0.9 * e,
                       truth_err_est=0.1 * e) == REDUCTION
    assert curve_floor([1, 2], [0.1, 0.15]) == REDUCTION  # a rising error has flattened too
    with pytest.raises(ValueError):
        curve_floor([0, 1], [0.1])


def test_curve_floors_go_on_each_curves_finest_finished_row_with_its_twin():
    rows = [_row("cub", 0, 0.10), _row("cub", 1, 0.095, curve_twin="all", err_projection=0.01),
            _row("cub", 2, float("nan"), status="failed"),  # the finest level failed: level 1 is the finest
            _row("all", 0, 0.08), _row("all", 1, 0.05, err_projection=0.01),
            _row("all", 1, 0.01, scenario="other"),  # another scenario's level: neither its curve nor a twin here
            {"scenario": "s", "solver": "full", "status": "ok", "err_truth": 0.2}]
    out = with_curve_floors(rows)
    assert [r.get("curve_floor") for r in out] == [None, CUBATURE, None, None, TIME_STEP, FEW_LEVELS, None]
    assert with_curve_floors([r for r in rows if r.get("curve") != "all"])[1]["curve_floor"] == REDUCTION


SUITE = suite_tables("curves", block_drop(clearance=0.005, duration=0.04), mu_axis(0.3),
                     description="one short block drop", truth={"tol": 1e-6, "depth": 2, "integrator": "bdf2"})


def test_a_run_gives_curve_rows_on_one_model_and_a_frontier_line_per_curve(tmp_path: Path):
    suite = write_toml(tmp_path / "curves.toml", SUITE)
    variants = step_ladder(Variant("pod", {"r": 4}, label="r4"), levels=(0, 1), integrators=(None, "bdf2"))
    rows = pd.read_csv(run_suite(str(suite), tmp_path / "out", variants=variants, report=False))
    store = RunStore(tmp_path / "out" / "runs")
    curves = rows[rows["curve"].notna()].sort_values(["curve", "curve_level"])
    assert list(curves["variant"]) == ["r4", "r4-dt/2", "r4-bdf2", "r4-bdf2-dt/2"]
    assert curves["status"].eq("ok").all() and curves["err_truth"].notna().all()
    assert curves["dt"].tolist() == pytest.approx([0.01, 0.005] * 2)
    assert list(curves["integrator"]) == ["backward-euler"] * 2 + ["bdf2"] * 2
    assert (curves["model"] == "r4").all() and rows[rows["curve"].isna()]["curve_level"].isna().all()
    stored = [store.load(key) for key in curves["run"]]
    assert len({stats["params"]["basis"] for _, stats in stored}) == 1  # one basis for every level
    assert len({traj.n_frames for traj, _ in stored}) == 1  # every level stores the scene's frames
    floors = curves.set_index("variant")["curve_floor"]
    assert floors[["r4-dt/2", "r4-bdf2-dt/2"]].isin(FLOORS).all() and floors[["r4", "r4-bdf2"]].isna().all()
    lines = [t for t in frontier_figure(rows)["data"] if t["name"].startswith("curve ")]
    assert sorted(t["name"] for t in lines) == ["curve pod/r4", "curve pod/r4-bdf2"]
    for t in lines:
        points = curves[curves["curve"] == t["name"].removeprefix("curve pod/")]
        assert t["mode"] == "lines" and t["y"] == pytest.approx(points["err_truth"].tolist())  # level by level


def test_the_frontier_joins_each_curve_per_scenario_in_its_points_colour_and_the_report_says_its_floor(tmp_path):
    rows = [_row(curve, k, err * 0.5 ** k, scenario=scenario, variant=f"{curve}-{k}", wall_s_per_sim_s=2.0 ** k,
                 **({"curve_floor": TIME_STEP} if k == 2 else {}))
            for scenario in ("a", HOSTILE) for curve, err in (("cub", 0.2), (HOSTILE, 0.1)) for k in range(3)]
    rows.append({"scenario": "a", "solver": "full", "variant": "reference", "status": "ok", "err_truth": 0.05,
                 "wall_s_per_sim_s": 10.0})
    data = frontier_figure(pd.DataFrame(rows))["data"]
    lines = [t for t in data if t["name"].startswith("curve ")]
    assert len(lines) == 4 and sum(t["showlegend"] for t in lines) == 2  # a line per curve and scenario
    markers = {t["name"]: t["marker"]["color"] for t in data if t.get("mode") == "markers"}
    cub = [t for t in lines if t["name"] == "curve licrom/cub"]
    assert {t["line"]["color"] for t in cub} == {markers[f"licrom/cub-{k}"] for k in range(3)}
    assert cub[0]["y"] == pytest.approx([0.2, 0.1, 0.05])
    assert markers["licrom/cub-0"] != markers[f"licrom/{html.escape(HOSTILE)}-0"]
    page = write_report_html(rows, tmp_path).read_text(encoding="utf-8")
    check_html(page)
    assert HOSTILE not in page and "What floors each variant&#x27;s curve" in page
    frontier = page.split('<section id="accuracy-vs-time">', 1)[1].split("</section>", 1)[0]
    assert frontier.count(f'<td class="text">{TIME_STEP}</td>') == 4  # each curve's finest row, per scenario


def test_the_pod_cubature_size_set_grows_one_subspaces_cubature_beside_its_every_tet_twin():
    """`pod-cubature-size`: r = 84 fitted to the truths at the fast settings with the body's Hessian once a step, on
    210 and 420 optimised tets and on every tet, each a curve at dt, dt/2, dt/4 under BDF2 on one trained model, the
    cubature curves twinned with the every-tet one; the 210-tet and every-tet curves are `pod-fast`'s own (their runs
    shared)."""
    size = variant_set("pod-cubature-size")
    assert len(size) == 9 and len({v.label for v in size}) == 9
    assert all(v.params["r"] == 84 and v.params["tol"] == 1e-3 and v.params["hessian_refresh"] == "step"
               and v.overrides == {"time.integrator": "bdf2"} for v in size)
    by_cubature = {}
    for v in size:
        assert v.solver == "pod" and v.training == "truth" and v.params | {"cubature": None} == size[0].params | {
            "cubature": None} and v.model == "pod-affine-r84-cub210-truthdata"
        by_cubature.setdefault(v.params["cubature"], []).append(v)
    assert sorted(by_cubature) == ["all", "optimized:210", "optimized:420"]
    every = by_cubature.pop("all")
    assert [v.curve_level for v in every] == [0, 1, 2] and not any(v.curve_twin for v in every)
    for levels in by_cubature.values():
        assert [v.dt_scale for v in levels] == [1.0, 0.5, 0.25]
        assert all(v.curve_twin == every[0].curve for v in levels)
    fast = {v.label: v for v in variant_set("pod-fast")}
    for v in [*by_cubature["optimized:210"], *every]:  # the same runs as pod-fast's (the run key is the settings)
        assert v.label in fast and fast[v.label].params == v.params and fast[v.label].overrides == v.overrides


def test_the_pod_rank_set_sweeps_the_rank_of_one_fit_on_every_tet_at_the_truth_step():
    """`pod-rank`: POD fitted to the truths on every tet at r = 84 (pod-fast's every-tet run) to 300 at the fast
    settings with the body's Hessian once a step, each at BDF2 dt/4 with contact at the fixed point; with `pod-fast`
    the r = 84 run is kept once."""
    from frictionbench.bench.cli import parse_variants

    rank = variant_set("pod-rank")
    assert [v.params["r"] for v in rank] == [84, 120, 180, 240, 300] and len({v.label for v in rank}) == 5
    for v in rank:
        assert v.solver == "pod" and v.training == "truth" and v.params["cubature"] == "all"
        assert v.params | {"r": 0} == rank[0].params | {"r": 0} and v.params["hessian_refresh"] == "step"
        assert v.dt_scale == 0.25 and v.overrides == {"time.integrator": "bdf2", "contact.lag": "fixed-point"}
    fast = {v.label: v for v in variant_set("pod-fast")}
    assert rank[0].label in fast and fast[rank[0].label].params == rank[0].params
    assert len(parse_variants("pod-fast,pod-rank")) == len(fast) + 4
    remesh = variant_set("pod-rank-remesh")  # each beside its twin on the other mesh, on its own trained model
    assert remesh[::2] == rank and len(remesh) == 10
    assert all(o.remesh == "alt" and o.remesh_of == v.label and o.model == (v.model or v.label)
               and o.params == v.params and not o.curve for v, o in zip(remesh[::2], remesh[1::2]))


def test_the_pod_fast_set_measures_the_looser_tolerance_on_both_sides():
    """`pod-fast`: POD at r = 60 on 150 tets at the defaults; r = 36, 60, 84 at tol 1e-3 with a single-precision
    Hessian, with and without the body's Hessian once a step, on the models of their default twins (no training
    of their own), r = 84 fitted to the truths with both at the fixed point; the full-space solver at the same
    tolerance on the truth ladders' settings. Each a curve at dt, dt/2, dt/4 under BDF2; the two r = 84 truth-fitted
    curves with the body's Hessian once a step have all-tets twins on their subspace."""
    sc = scenario_from_dict(block_drop(time={"dt": 0.01, "duration": 0.04, "frame_every": 2}) | {"name": "s"})
    fast = variant_set("pod-fast")
    assert len(fast) == 57 and len({v.label for v in fast}) == 57
    pod = [v for v in fast if v.solver == "pod"]
    full = [v for v in fast if v.solver == "full"]
    assert {(v.params["r"], v.params["cubature"]) for v in pod} == {(36, "optimized:90"), (60, "optimized:150"),
                                                                     (84, "optimized:210"), (84, "all")}
    for v in pod:
        quick = v.params.get("tol") == 1e-3
        assert quick == ("-tol1e-3-single-" in v.label) == (v.params.get("hessian") == "single")
        assert ("-single-step-" in v.label) == (v.params.get("hessian_refresh") == "step") <= quick
        tets = 5 * v.params["r"] // 2  # a twin on every tet shares its cubature sibling's trained model
        assert v.model == f"pod-affine-r{v.params['r']}-cub{tets}" + ("-truthdata" if v.training == "truth" else "")
        assert quick or v.params["r"] == 60
    assert sum(v.params.get("hessian_refresh") == "step" for v in pod) == 27  # 3 ranks, 2 fits, 3 steps; 6 at r = 84
    fixed = [v for v in pod if "-fixed-point" in v.label]
    assert len(fixed) == 6 and all(v.params["r"] == 84 and v.params["hessian_refresh"] == "step" and v.model ==
                                   "pod-affine-r84-cub210-truthdata" for v in fixed)
    twins = {v.curve: v for v in pod if v.params["cubature"] == "all"}
    assert len(twins) == 2 and all(v.training == "truth" and v.params["r"] == 84 for v in twins.values())
    with_twin = [v for v in pod if v.curve_twin]
    assert len(with_twin) == 6 and {v.curve_twin for v in with_twin} == set(twins)
    for v in with_twin:  # the twin differs in its cubature alone, at every level
        twin = next(t for t in pod if t.curve == v.curve_twin and t.curve_level == v.curve_level)
        assert twin.params == v.params | {"cubature": "all"} and twin.overrides == v.overrides
        assert twin.dt_scale == v.dt_scale and v.params["cubature"] == "optimized:210"
    assert len(full) == 6 and sorted(v.params["tol"] for v in full) == [1e-5] * 3 + [1e-3] * 3
    assert NewtonSettings.tol == 1e-5  # the tol1e-5 levels are the truth ladder's own settings
    for v in fast:
        level = v.scenario(sc)
        assert level.time.integrator == "bdf2"
        assert level.contact.lag == ("fixed-point" if v.solver == "full" or "-fixed-point" in v.label else "start")
    assert sorted(v.scenario(sc).time.dt for v in full) == pytest.approx([0.0025] * 2 + [0.005] * 2 + [0.01] * 2)

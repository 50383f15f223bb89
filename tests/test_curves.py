"""Each reduced variant's own curve: its step ladder (`bench.matrix.step_ladder`), the rows' curve columns, the
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
from frictionbench.bench.matrix import step_ladder, variant_set
from frictionbench.reports.html import write_report_html
from frictionbench.reports.plots import frontier_figure
from frictionbench.scenarios.load import scenario_from_dict

from scenes import block_drop, mu_axis, suite_tables, write_toml
from test_reports import HOSTILE, check_html


AFFINE_R24, _, AFFINE_R24_CUB60 = variant_set("licrom-affine")


def test_a_step_ladder_halves_the_step_keeps_the_frames_and_shares_the_model():
    ladder = step_ladder(AFFINE_R24_CUB60, levels=(0, 1, 2, 3), integrators=(None, "bdf2"), twin=AFFINE_R24.label)
    assert [v.label for v in ladder] == [
        "affine-r24-cub60", "affine-r24-cub60-dt/2", "affine-r24-cub60-dt/4", "affine-r24-cub60-dt/8",
        "affine-r24-cub60-bdf2", "affine-r24-cub60-bdf2-dt/2", "affine-r24-cub60-bdf2-dt/4",
        "affine-r24-cub60-bdf2-dt/8"]
    assert [v.dt_scale for v in ladder] == [1.0, 0.5, 0.25, 0.125] * 2
    assert [v.tags["curve_level"] for v in ladder] == [0, 1, 2, 3] * 2
    assert [v.tags["curve"] for v in ladder] == ["affine-r24-cub60"] * 4 + ["affine-r24-cub60-bdf2"] * 4
    assert [v.tags["curve_twin"] for v in ladder] == ["affine-r24"] * 4 + ["affine-r24-bdf2"] * 4
    # one trained model: the parameters (what the training key is made of) are the base's, the model its label
    assert all(v.params == AFFINE_R24_CUB60.params and v.model == "affine-r24-cub60" for v in ladder)
    assert [v.overrides for v in ladder] == [{}] * 4 + [{"time.integrator": "bdf2"}] * 4
    sc = scenario_from_dict(block_drop(time={"dt": 0.01, "duration": 0.04, "frame_every": 2}) | {"name": "s"})
    level = ladder[6].scenario(sc)  # bdf2, dt / 4: frames every 8 steps, at the scene's frame times
    assert (level.time.dt, level.time.frame_every, level.time.integrator) == (pytest.approx(0.0025), 8, "bdf2")
    assert ladder[0].scenario(sc) is sc  # level 0 with the scene's integrator is the variant itself
    assert all("curve_twin" not in v.tags for v in step_ladder(AFFINE_R24, levels=(0, 1)))
    with pytest.raises(ValueError, match="levels"):
        step_ladder(AFFINE_R24, levels=(0, 0))
    with pytest.raises(ValueError, match="rk4"):
        step_ladder(AFFINE_R24, integrators=(None, "rk4"))


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

"""Reports: results CSV, the self-contained HTML report (headline, figures, 3D viewer) and VTU/PVD export."""

from __future__ import annotations

import base64
import html
import json
import re
import subprocess
import sys
from html.parser import HTMLParser
from pathlib import Path
from typing import ClassVar
from xml.etree import ElementTree

import meshio
import numpy as np
import pandas as pd
import pytest
import pyvista

from frictionbench.analysis import metrics
from frictionbench.analysis.derived import with_remesh_ratio
from frictionbench.analysis.schema import computed_cells, names
from frictionbench.analysis.table import (
    IDENTITY_COLUMNS,
    PROVENANCE_COLUMNS,
    column_order,
    provenance,
    write_results_csv,
)
from frictionbench.reports.export import export_vtu_series
from frictionbench.reports.headline import BASIS, BEST_AT, BEST_SPEEDUP, SPEEDUP, headline_table
from frictionbench.reports.html import ScenarioRuns, write_report_html
from frictionbench.reports.interactive import plot_div, plotly_js, script_json, typed_array
from frictionbench.reports.plots import FAMILY_RAMPS, frontier_figure, pareto_front
from frictionbench.reports.viewer import ViewerBudget, decimate_surface, viewer_figure
from frictionbench.scenarios.meshes import bbox_diagonal
from frictionbench.scenarios.spec import Plane, Scenario
from frictionbench.solvers.trajectory import Trajectory

from scenes import block_drop, mu_axis, suite_tables, write_toml

PLANE = Plane(normal=(0.0, 1.0, 0.0), offset=0.0, friction=0.5)


@pytest.fixture(scope="module")
def block() -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """A 0.2 x 0.1 x 0.15 m block of tets resting on y = 0: rest positions, tets, outward surface triangles."""
    grid = pyvista.ImageData(dimensions=(5, 3, 4), spacing=(0.05, 0.05, 0.05)).triangulate()
    surface = grid.extract_surface(algorithm="dataset_surface").triangulate()
    triangles = surface.point_data["vtkOriginalPointIds"][surface.faces.reshape(-1, 4)[:, 1:]]
    return np.asarray(grid.points, dtype=float), grid.cells_dict[pyvista.CellType.TETRA], triangles


def sliding(block: tuple[np.ndarray, np.ndarray, np.ndarray], speed: float, wobble: float = 0.0) -> Trajectory:
    """The block sliding along +x at `speed` [m/s] for 1 s (11 frames), lifted by wobble sin(5 t) [m]."""
    X, tets, surface = block
    t = np.linspace(0.0, 1.0, 11)
    offset = np.stack([speed * t, wobble * np.sin(5.0 * t), np.zeros_like(t)], axis=1)
    return Trajectory(t=t, x=X[None] + offset[:, None, :], X=X, tets=tets, surface=surface)


@pytest.fixture(scope="module")
def runs(block) -> tuple[Trajectory, dict[str, Trajectory]]:
    return sliding(block, 0.1), {"licrom/r16": sliding(block, 0.09, 0.002), "pod/r16": sliding(block, 0.0)}


def result_rows(runs) -> list[dict[str, object]]:
    """Rows as the harness writes them: a reference, two reduced variants, a remeshed run and a failed run."""
    ref, others = runs
    rows = []
    for solver, variant, traj, step_ms in [("full", "", ref, 40.0), ("licrom", "r16", others["licrom/r16"], 2.0),
                                           ("pod", "r16", others["pod/r16"], 1.0)]:
        row = {"suite": "quick", "scenario": "slide", "split": "test", "mesh": "block/coarse",
               "train_mesh": "block/coarse", "solver": solver, "variant": variant, "param_r": 16,
               "status": "ok", "failure": None, "step_ms_median": step_ms, "speedup": 40.0 / step_ms}
        row.update(computed_cells(metrics.ComparedRun(ref, traj, Scenario(name="slide", plane=PLANE))))
        rows.append(row)
    rows.append({**rows[1], "mesh": "block/coarse_alt", "pos_rmse_rel": 2.0 * rows[1]["pos_rmse_rel"]})
    rows.append({**rows[1], "variant": "r64", "status": "failed", "failure": "Newton did not converge at t=0.3",
                 "pos_rmse_rel": float("nan"), "finite": False, "step_ms_median": None})
    return rows


PROVENANCE = {column: "" for column in PROVENANCE_COLUMNS} | {"commit": "abc123", "device": "cpu"}


def test_column_order_is_identity_params_metrics_provenance() -> None:
    keys = ["numpy_version", "pos_rmse_rel", "custom_metric", "solver", "param_r", "commit", "scenario", "vtk_version",
            "status", "param_dt"]
    assert column_order(keys) == ["scenario", "solver", "param_r", "param_dt", "status", "pos_rmse_rel",
                                  "custom_metric", "commit", "numpy_version", "vtk_version"]


def test_results_csv_column_order_and_round_trip(tmp_path: Path, runs) -> None:
    rows = result_rows(runs)
    path = write_results_csv(rows, tmp_path / "out" / "results.csv", provenance_info=PROVENANCE)
    frame = pd.read_csv(path)
    columns = list(frame.columns)
    metric_columns = set(names("parameter", "accuracy", "stability", "timing"))
    kinds = ["identity" if c in IDENTITY_COLUMNS or c.startswith("param_") else
             "metric" if c in metric_columns else "provenance" if c in PROVENANCE_COLUMNS else "?" for c in columns]
    assert "?" not in kinds
    assert kinds == sorted(kinds, key=["identity", "metric", "provenance"].index)
    assert columns[:8] == ["suite", "scenario", "split", "mesh", "train_mesh", "solver", "variant", "param_r"]
    assert len(frame) == len(rows)
    for row, (_, read) in zip(rows, frame.iterrows()):
        for key, value in row.items():
            if value is None or value == "" or (isinstance(value, float) and np.isnan(value)):
                assert pd.isna(read[key]), key  # CSV has one missing value: an empty cell
            elif isinstance(value, (float, np.floating)):
                assert read[key] == pytest.approx(value, rel=1e-15), key
            else:
                assert str(read[key]) == str(value) or read[key] == value, key
    assert (frame["commit"] == "abc123").all() and (frame["device"] == "cpu").all()
    assert not list(path.parent.glob(".*.tmp"))


def test_provenance_fields_without_importing_torch() -> None:
    code = ("import sys, json; from frictionbench.analysis.table import provenance; "
            "p = provenance('cpu', gpu_name=''); "
            "print(json.dumps({'torch_imported': 'torch' in sys.modules, 'keys': list(p), 'numpy': p['numpy_version'],"
            " 'commit': p['commit']}))")
    out = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, check=True, timeout=120)
    report = json.loads(out.stdout)
    assert not report["torch_imported"]
    assert report["keys"] == list(PROVENANCE_COLUMNS)
    assert report["numpy"] == np.__version__
    assert re.fullmatch(r"[0-9a-f]{40}|", report["commit"])


def test_provenance_takes_the_given_gpu_name() -> None:
    info = provenance("cuda:0", gpu_name="Test GPU")
    assert info["device"] == "cuda:0" and info["gpu_name"] == "Test GPU" and info["cpu_name"]


def test_pareto_front() -> None:
    time = np.array([1.0, 2.0, 3.0, 4.0, 2.5, np.nan])
    error = np.array([0.5, 0.1, 0.2, 0.01, 0.1, 0.0])
    np.testing.assert_array_equal(pareto_front(time, error), [0, 1, 3])
    speedup = 1.0 / time
    np.testing.assert_array_equal(pareto_front(speedup, error, x_higher_is_better=True), [0, 1, 3])


def test_frontier_gives_each_solver_family_its_own_hue() -> None:
    """Every variant of a family takes a shade of the family's ramp, so no colour is shared between families (the
    peer engine's seven variants beside the full-space ones, say)."""
    families = {"full": 7, "newton-vbd": 7}
    frame = pd.DataFrame([{"solver": fam, "variant": f"v{k}", "scenario": "s", "err_truth": 0.1 * (k + 1),
                           "wall_s_per_sim_s": 1.0 + k} for fam, n in families.items() for k in range(n)])
    traces = {t["name"]: t for t in frontier_figure(frame)["data"] if t.get("mode") == "markers"}
    colours = {fam: {traces[f"{fam}/v{k}"]["marker"]["color"] for k in range(n)} for fam, n in families.items()}
    assert colours["full"] <= set(FAMILY_RAMPS[0]) and colours["newton-vbd"] <= set(FAMILY_RAMPS[1])
    assert not colours["full"] & colours["newton-vbd"]
    assert len(colours["newton-vbd"]) == 7  # its variants tell apart too
    assert {traces["full/v0"]["marker"]["symbol"]} != {traces["newton-vbd/v0"]["marker"]["symbol"]}


class _TagChecker(HTMLParser):
    """Collects external resource references and checks that non-void elements nest and close."""

    VOID: ClassVar[set[str]] = {"meta", "img", "br", "hr", "link", "input", "source"}

    def __init__(self) -> None:
        super().__init__()
        self.stack: list[str] = []
        self.errors: list[str] = []
        self.refs: list[str] = []
        self.ids: list[str] = []
        self.headings: list[str] = []
        self._in_h2 = False

    def handle_starttag(self, tag: str, attrs: list[tuple[str, str | None]]) -> None:
        self.refs += [value or "" for name, value in attrs if name in ("src", "href")]
        self.ids += [value or "" for name, value in attrs if name == "id"]
        self._in_h2 = tag == "h2"
        if tag not in self.VOID:
            self.stack.append(tag)

    def handle_endtag(self, tag: str) -> None:
        if not self.stack or self.stack.pop() != tag:
            self.errors.append(f"unexpected </{tag}>")
        self._in_h2 = False

    def handle_data(self, data: str) -> None:
        if self._in_h2:
            self.headings.append(data)


def check_html(page: str) -> _TagChecker:
    checker = _TagChecker()
    checker.feed(page)
    checker.close()
    assert not checker.errors and not checker.stack
    assert len(set(checker.ids)) == len(checker.ids)  # ids unique (sections, plots, figure JSON)
    return checker


FIGURE_JSON = re.compile(r'<script type="application/json" id="([\w-]+)-json">(.*?)</script>', re.DOTALL)


def figures(page: str) -> dict[str, dict]:
    """The page's embedded figures by plot id (the JSON parses as it is in the page)."""
    return {plot_id: json.loads(text) for plot_id, text in FIGURE_JSON.findall(page)}


def test_html_report_is_self_contained(tmp_path: Path, runs) -> None:
    ref, others = runs
    errors = {label: metrics.error_over_time(ref, traj) for label, traj in others.items()}
    gates = [{"gate": "accuracy", "passed": True, "value": 0.01, "limit": "<= 0.05"},
             {"gate": "speed", "scenario": "slide", "variant": "pod/r16", "metric": "speedup", "passed": False,
              "value": 3.0, "limit": ">= 5"}]
    rows = with_remesh_ratio([r | {"remesh": "alt", "model": "r16"} if r["mesh"] == "block/coarse_alt" else r
                              for r in result_rows(runs)])
    path = write_report_html(rows, tmp_path, gates=gates,
                             runs=[ScenarioRuns("slide", ref, others, errors, plane=PLANE)],
                             extra_sections=[("Notes", "<p>hand-written</p>")])
    page = path.read_text(encoding="utf-8")
    assert path == tmp_path / "report.html" and page.startswith("<!DOCTYPE html>")
    checker = check_html(page)
    assert all(ref.startswith("#") for ref in checker.refs)  # no src, no external link
    assert checker.headings == ["Summary", "Accuracy versus time", "Ground-truth ladders",
                                "Outcomes against the truth", "Where the error comes from", "Error over time",
                                "3D viewer", "Reference time-step convergence", "Stick/slip agreement",
                                "Remeshing", "Stability", "Gate verdicts", "Results", "Notes", "Provenance"]
    assert page.count(plotly_js()) == 1  # plotly.js inline, once
    summary = page[page.index('id="summary"'):page.index('id="accuracy-vs-time"')]
    assert '<p class="banner fail" id="verdict">' in summary  # one banner, red: a binding gate and a run failed
    assert summary.count('class="banner') == 1
    text = re.sub(r"<abbr title=\"[^\"]*\">|</abbr>", "", summary)  # the words, without the glossary's hovers
    assert "1 of 2 binding gates failed; 1 of 5 runs failed." in text
    assert "Binding gates failed: pod/r16 speedup on slide: 3 (limit &gt;= 5)." in text  # the failure listed
    assert "Runs failed: slide [licrom/r64]: Newton did not converge at t=0.3." in text
    assert "No ground truth in these results, so <b>licrom/r16</b> is chosen by its error" in text
    assert '<span class="step">per-step speedup 20x</span>' in text
    assert "No ground truth in this result set" in text
    assert "Newton did not converge at t=0.3" in page
    assert 'class="fail"' in page and 'class="pass"' in page
    assert "block/coarse_alt" in page  # remeshing table
    figs = figures(page)
    assert set(figs) == {"frontier", "error-0", "viewer-0"}
    frontier = {t["name"]: t for t in figs["frontier"]["data"]}
    assert {"licrom/r16", "pod/r16"} <= set(frontier)  # the reference (error 0) has no point on a log axis
    assert frontier["licrom/r16"]["x"] == [2.0, 2.0]  # step_ms_median of its two runs (no wall_s_per_sim_s)
    assert "scenario: slide" in frontier["pod/r16"]["hovertext"][0]
    assert figs["frontier"]["layout"]["xaxis"]["type"] == "log" == figs["frontier"]["layout"]["yaxis"]["type"]
    viewer = figs["viewer-0"]
    assert len(viewer["frames"]) == ref.n_frames  # 11 frames, within the budget
    assert [t["name"] for t in viewer["data"] if t["type"] == "mesh3d"] == ["plane", "reference", "licrom/r16",
                                                                            "pod/r16"]
    assert "Viewers for" not in page  # the one scenario has its viewer
    assert "Play" in json.dumps(viewer["layout"]["updatemenus"]) and len(viewer["layout"]["sliders"][0]["steps"]) == 11


def test_headline_with_ground_truth_columns(tmp_path: Path) -> None:
    rows = []
    for s, certified, est in [("drop", True, 0.001), ("slope", False, 0.02)]:
        truth = {"truth_certified": certified, "truth_err_est": est, "truth_dt": 0.00125, "truth_depth": 3,
                 "truth_integrator": "bdf2", "truth_horizon_s": 2.0 if certified else 0.55}
        for solver, variant, err, wall, speed, agree, status in [
                ("full", "reference", 0.05, 40.0, 1.0, True, "ok"), ("licrom", "r20", 0.03, 2.0, 25.0, True, "ok"),
                ("licrom", "r10", 0.08, 1.0, 30.0, False, "ok"), ("pod", "r20", 0.2, 1.5, float("nan"), False,
                                                                  "failed" if s == "slope" else "ok")]:
            rows.append({"scenario": s, "solver": solver, "variant": variant, "dt": 0.01, "status": status,
                         "err_truth": err, "pos_rmse_rel": err / 2, "wall_s_per_sim_s": wall,
                         "err_time": None if variant == "reference" else 0.05,
                         "err_projection": err / 4 if solver != "full" else None,
                         "speedup_equal_accuracy": speed, "speedup": 99.0, "stick_agree": agree,
                         "integrator": "backward-euler", "ladder": "",
                         "frontier_note": "less accurate than every ladder level" if solver == "pod" else "", **truth})
        for k, err in enumerate([0.1, 0.05, 0.02, 0.0]):
            rows.append({"scenario": s, "solver": "full", "variant": f"ladder-bdf2-{k}", "dt": 0.01 / 2 ** k,
                         "status": "ok", "err_truth": err, "wall_s_per_sim_s": 40.0 * 2 ** k, "ladder": "bdf2",
                         "integrator": "bdf2", **truth})
    frame = pd.DataFrame(rows)
    gates = [{"gate": "acc", "scenario": "slope", "variant": "licrom/r20", "metric": "err_truth", "passed": False,
              "status": "undecidable", "value": 0.03, "limit": "<= 0.01"},
             {"gate": "fin", "scenario": "drop", "variant": "licrom/r10", "metric": "finite", "passed": False,
              "status": "failed", "value": False, "limit": "= true"}]
    table = headline_table(frame, gates).set_index("solver")
    assert list(table.index) == ["full", "licrom", "pod"]  # no ladder family, no ladder variant
    # chosen on the frontier: r10 (8% of L, 30x) and r20 (3%, 25x) are both on it; r10's measured speed-up is larger
    assert table.loc["licrom", "best variant"] == "licrom/r10"
    assert table.loc["licrom", "chosen as"] == BASIS["measured"]
    assert table.loc["licrom", "median err_truth"] == pytest.approx(0.08)
    assert table.loc["licrom", SPEEDUP] == pytest.approx(30.0)
    assert table.loc["licrom", "stick/slip agreement"] == "0 of 2"
    assert table.loc["licrom", "stable runs"] == "1 of 2"  # drop's finite check failed
    assert table.loc["pod", "stable runs"] == "1 of 2"  # slope's run failed
    assert table.loc["pod", "truth certified"] == "1 of 2 scenarios"
    assert pd.isna(table.loc["pod", SPEEDUP]) and table.loc["pod", "chosen as"] == BASIS["accuracy"]
    # the family's best measured speed-up at equal accuracy, over every variant and scenario, and where it holds;
    # none where every speed-up is an upper bound (a frontier note)
    assert table.loc["licrom", BEST_SPEEDUP] == pytest.approx(30.0)
    assert table.loc["licrom", BEST_AT] in {"0.08 (licrom/r10, drop)", "0.08 (licrom/r10, slope)"}
    assert pd.isna(table.loc["pod", BEST_SPEEDUP]) and table.loc["pod", BEST_AT] == "\u2013"
    # a best speed-up whose run and ladder were timed in different sessions (a resumed store) says so
    moved = headline_table(frame.assign(timed_beside_ladder=frame["variant"] != "r10"), gates).set_index("solver")
    assert moved.loc["licrom", BEST_AT].endswith("; its ladder timed in another session")
    assert not headline_table(frame.assign(timed_beside_ladder=True), gates).set_index("solver").loc[
        "licrom", BEST_AT].endswith("session")
    page = write_report_html(frame, tmp_path, gates=gates).read_text(encoding="utf-8")
    check_html(page)
    summary = page[page.index('id="summary"'):page.index('id="accuracy-vs-time"')]
    assert "certified on 1" in summary and "No ground truth" not in summary
    assert "not certified: slope (within tolerance up to t = 0.55 s)" in summary
    text = re.sub(r"<abbr title=\"[^\"]*\">|</abbr>", "", summary)  # the words, without the glossary's hovers
    assert "Binding gates: 0 of 2 passed, 1 failed, 1 undecidable" in text
    assert '<p class="banner fail" id="verdict">1 of 2 binding gates failed; 1 of 16 runs failed.</p>' in text
    assert ("Undecidable (neither passed nor failed): licrom/r20 err_truth on slope: 0.03 (limit &lt;= 0.01)."
            in text)
    assert ("<b>licrom/r10</b> costs 1 s per simulated second, 30 times less than the full-space solver at the same "
            "accuracy" in text)
    stability = page[page.index('id="stability"'):page.index('id="gate-verdicts"')]
    assert "undecidable: err_truth" in stability and "fail: finite" in stability
    figs = figures(page)
    frontier = figs["frontier"]["data"]
    ladders = [t for t in frontier if t.get("legendgroup") == "ladder bdf2"]
    assert len(ladders) == 2 and [t["showlegend"] for t in ladders] == [True, False]  # one legend entry
    assert ladders[0]["x"] == [40.0, 80.0, 160.0]  # the truth itself (error 0) is not on the log axis
    assert figs["frontier"]["layout"]["xaxis"]["title"]["text"].startswith("wall_s_per_sim_s")
    assert any("error estimate" in t["name"] for t in figs["ladders-plot"]["data"])
    parts = {t["name"].split(":")[0]: dict(zip(t["x"], t["y"])) for t in figs["error-parts-plot"]["data"]}
    assert list(parts) == ["projection", "reduction", "time step", "total"]  # no reference, no ladder among them
    assert set(parts["total"]) == {"licrom/r10", "licrom/r20", "pod/r20"}
    assert parts["projection"]["licrom/r20"] == pytest.approx(0.0075) and parts["time step"]["pod/r20"] == 0.05
    assert parts["reduction"]["pod/r20"] == pytest.approx(0.1)  # the median of its scenarios' pos_rmse_rel


def test_headline_without_ground_truth_falls_back_to_the_reference(runs) -> None:
    frame = pd.DataFrame(result_rows(runs))
    table = headline_table(frame).set_index("solver")
    assert {"median pos_rmse_rel", "per-step speedup"} <= set(table.columns)
    assert not any("err_truth" in c for c in table.columns)
    assert table.loc["licrom", "best variant"] == "licrom/r16"  # r64 failed: no error
    assert table.loc["licrom", "per-step speedup"] == pytest.approx(20.0)
    assert (table["truth certified"] == "no truth").all()
    assert BEST_SPEEDUP not in table  # no truth, no speed-up at equal accuracy


HOSTILE = '</script><script>window.pwned=1</script><img src=x onerror="window.pwned=2">&amp;\u2028'


def test_hostile_names_are_escaped_in_html_and_in_the_figures(tmp_path: Path, runs) -> None:
    ref, others = runs
    rows = [r | {"scenario": HOSTILE, "variant": HOSTILE if r["solver"] == "pod" else r["variant"]}
            for r in result_rows(runs)]
    labels = {"licrom/r16": others["licrom/r16"], f"pod/{HOSTILE}": others["pod/r16"]}
    errors = {label: metrics.error_over_time(ref, traj) for label, traj in labels.items()}
    page = write_report_html(rows, tmp_path, gates=[{"gate": HOSTILE, "scenario": HOSTILE, "passed": False}],
                             runs=[ScenarioRuns(HOSTILE, ref, labels, errors, plane=PLANE)],
                             title=HOSTILE).read_text(encoding="utf-8")
    assert HOSTILE not in page and "<script>window.pwned" not in page and "<img" not in page
    check_html(page)
    figs = figures(page)  # every figure's JSON ends where it should and parses
    assert set(figs) == {"frontier", "error-0", "viewer-0"}
    names = [t.get("name", "") for f in figs.values() for t in f["data"]]
    assert html.escape(f"pod/{HOSTILE}") in names  # plotly shows the escaped text, not markup


def test_script_json_cannot_end_its_element() -> None:
    text = script_json({"name": "</script><!-- \u2028", "x": [1.0, float("nan")], "n": np.int64(3)})
    assert "<" not in text and ">" not in text and "\u2028" not in text
    assert json.loads(text) == {"name": "</script><!-- \u2028", "x": [1.0, None], "n": 3}


def test_figure_helpers_refuse_bad_input() -> None:
    with pytest.raises(ValueError, match="plot id 'a b'"):
        plot_div({"data": []}, "a b")
    with pytest.raises(ValueError, match="dtype 'f2'"):
        typed_array(np.zeros(3), "f2")
    assert np.frombuffer(base64.b64decode(typed_array(np.array([1.5, -2.0]))["bdata"]), "<f4").tolist() == [1.5, -2.0]


def test_decimated_surface_keeps_its_budget_and_the_original_vertices() -> None:
    sphere = pyvista.Sphere(theta_resolution=60, phi_resolution=60).triangulate()
    X, tri = np.asarray(sphere.points), sphere.faces.reshape(-1, 4)[:, 1:]
    assert len(tri) > 3000
    verts, small = decimate_surface(X, tri, 800)
    assert 200 < len(small) <= 800
    assert set(np.unique(small)) == set(range(len(verts)))  # every kept vertex is used
    assert np.all(verts < len(X)) and len(np.unique(verts)) == len(verts)
    assert np.all(np.linalg.norm(X[verts], axis=1) == pytest.approx(0.5))  # original points, not new ones
    whole_verts, whole = decimate_surface(X, tri, 10_000)
    assert len(whole) == len(tri) and np.array_equal(whole_verts[whole], tri)


def test_viewer_colours_by_distance_frames_the_bodies_and_drops_what_it_cannot_show(block, runs) -> None:
    ref, others = runs
    X, tets, surface = block
    broken = sliding(block, 0.05)
    broken.x[4] = np.nan  # a shown frame (0, 2, 4, ... of 11)
    other_mesh = Trajectory(t=ref.t, x=ref.x[:, :-1], X=X[:-1], tets=tets[:1], surface=surface[:1])
    fig, notes = viewer_figure([("ref", ref), ("pod", others["pod/r16"]), ("broken", broken),
                                ("other", other_mesh)], PLANE, ViewerBudget(max_frames=6, max_triangles=40))
    assert notes == ["broken: not shown (non-finite positions)", "other: not shown (another mesh than ref's)"]
    assert len(fig["frames"]) == 6
    meshes = [t for t in fig["data"] if t["type"] == "mesh3d"]
    assert [t["name"] for t in meshes] == ["plane", "ref", "pod"]
    assert len(meshes[1]["i"]["bdata"]) <= 4 * 40 * 4 / 3 + 4  # at most 40 triangles (int32, base64)

    def values(typed: dict) -> np.ndarray:
        return np.frombuffer(base64.b64decode(typed["bdata"]), dtype="<f4")

    last = fig["frames"][-1]["data"]
    assert np.all(values(last[0]["intensity"]) == 0.0)  # the first run against itself
    # pod stands still while the reference slides 0.1 m: its distance at t = 1 s is 0.1 m / L everywhere
    assert values(last[1]["intensity"]) == pytest.approx(0.1 / bbox_diagonal(X), rel=1e-5)
    plane_y = np.array(meshes[0]["y"])
    assert np.all(plane_y == 0.0)  # the plane y = 0
    xs = np.concatenate([values(f["data"][0]["x"]) for f in fig["frames"]])
    plane_x = np.array(meshes[0]["x"])
    assert plane_x.min() < xs.min() and plane_x.max() > xs.max()  # around the path ...
    assert plane_x.max() - plane_x.min() < 2.0 * (xs.max() - xs.min())  # ... and cropped to it
    rng = fig["layout"]["scene"]["xaxis"]["range"]
    assert rng[0] <= plane_x.min() and rng[1] >= plane_x.max()
    with pytest.raises(ValueError, match="max_frames"):
        ViewerBudget(max_frames=1)


def test_time_convergence_section_sets_the_references_time_error_beside_the_best_reduced_error(tmp_path):
    rows = [{"scenario": s, "split": "test", "solver": solver, "variant": variant, "dt": dt, "pos_rmse_rel": err,
             "status": "ok", "ref_dt_change": change}
            for s, change in [("p4", 0.284), ("p5", 0.0123)]
            for solver, variant, dt, err in [("full", "reference", 0.01, 0.0), ("full", "dt-half", 0.005, change),
                                             ("full", "other-mesh", 0.01, 0.00217), ("licrom", "r20", 0.01, 0.241),
                                             ("pod", "r20", 0.01, 0.326)]]
    page = write_report_html(pd.DataFrame(rows), tmp_path).read_text(encoding="utf-8")
    section = page[page.index('id="time-convergence"'):page.index('id="stick-slip"')]
    assert "best_reduced_pos_rmse_rel" in section and section.count("<tr>") == 3  # header + 2 scenarios
    assert "0.284" in section and "0.241" in section and "0.0123" in section
    assert "0.326" not in section and "0.00217" not in section  # the best reduced error only, no full-space rows
    bare = write_report_html(pd.DataFrame(rows).drop(columns="ref_dt_change"), tmp_path).read_text(encoding="utf-8")
    assert "No full-space run at a smaller time step" in bare


def test_html_report_from_results_alone(tmp_path: Path, runs) -> None:
    frame = pd.read_csv(write_results_csv(result_rows(runs), tmp_path / "results.csv", PROVENANCE))
    page = write_report_html(frame, tmp_path).read_text(encoding="utf-8")
    check_html(page)
    assert set(figures(page)) == {"frontier"}
    assert page.count("No trajectories were given to the report.") == 2


def test_vtu_series_reads_back(tmp_path: Path, runs) -> None:
    ref, _ = runs
    pvd = export_vtu_series(ref, tmp_path / "vtu", name="slide")
    entries = ElementTree.parse(pvd).getroot().findall("./Collection/DataSet")
    assert len(entries) == ref.n_frames
    np.testing.assert_allclose([float(e.get("timestep")) for e in entries], ref.t)
    for k in (0, ref.n_frames - 1):
        mesh = meshio.read(pvd.parent / entries[k].get("file"))
        np.testing.assert_allclose(mesh.points, ref.x[k])
        np.testing.assert_array_equal(mesh.cells_dict["tetra"], ref.tets)
        np.testing.assert_allclose(mesh.point_data["displacement"], ref.x[k] - ref.X)
        np.testing.assert_allclose(mesh.point_data["velocity"], np.tile([0.1, 0.0, 0.0], (ref.X.shape[0], 1)),
                                   atol=1e-12)


def test_build_report_shows_the_truth_run_and_errors_against_it(tmp_path: Path, block) -> None:
    from frictionbench.bench.reporting import build_report
    from frictionbench.bench.store import RunStore

    suite = write_toml(tmp_path / "tiny.toml", suite_tables("tiny", block_drop(clearance=None), mu_axis(0.3),
                                                            description="stored runs"))
    out = tmp_path / "out"
    store = RunStore(out / "runs")
    truth = {"truth_certified": True, "truth_err_est": 0.001, "truth_dt": 0.0025, "truth_depth": 2,
             "truth_integrator": "bdf2"}
    rows = []
    for key, solver, variant, ladder, level, speed in [("ref", "full", "reference", "", None, 0.1),
                                                       ("lic", "licrom", "r20", "", None, 0.09),
                                                       ("l0", "full", "ladder-bdf2-0", "bdf2", 0, 0.1),
                                                       ("l2", "full", "ladder-bdf2-2", "bdf2", 2, 0.11)]:
        traj = sliding(block, speed)
        store.save(key, traj, {})
        rows.append({"scenario": "s", "solver": solver, "variant": variant, "run": key, "ladder": ladder,
                     "ladder_level": level, "status": "ok", "err_truth": 0.01, "pos_rmse_rel": 0.01, **truth})
    rows.append({"scenario": "t", "solver": "licrom", "variant": "r20", "status": "failed"})  # no stored run
    pd.DataFrame(rows).to_csv(out / "results.csv", index=False)
    (out / "run.json").write_text(json.dumps({"suite": str(suite)}))
    page = build_report(out).read_text(encoding="utf-8")
    figs = figures(page)
    shown = [t["name"] for t in figs["viewer-0"]["data"] if t["type"] == "mesh3d"]
    assert shown == ["truth (full/ladder-bdf2-2)", "full", "licrom/r20"]  # not the other ladder level
    assert "Viewers for 1 of the 2 scenarios" in page
    errors = {t["name"]: t for t in figs["error-0"]["data"]}
    assert set(errors) == {"full", "licrom/r20"}  # the reference too, against the truth
    # the truth slides at 0.11 m/s, the reference at 0.1: every vertex 0.01 m apart at t = 1 s
    assert errors["full"]["y"][-1] == pytest.approx(0.01 / bbox_diagonal(block[0]), rel=1e-6)
    assert "error against truth (full/ladder-bdf2-2)" in figs["error-0"]["layout"]["title"]["text"]

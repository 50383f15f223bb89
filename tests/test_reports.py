"""Reports: results CSV, the self-contained HTML report, renders and VTU/PVD export."""

from __future__ import annotations

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

from analysis import metrics
from analysis.derived import with_remesh_ratio
from analysis.table import (
    IDENTITY_COLUMNS,
    METRIC_COLUMNS,
    PROVENANCE_COLUMNS,
    column_order,
    provenance,
    write_results_csv,
)
from reports import render
from reports.export import export_vtu_series
from reports.html import ScenarioRuns, write_report_html
from reports.plots import pareto_front
from reports.render import render_surface, select_renderer, view_bounds
from scenarios.model import Material, Plane
from solvers.trajectory import Trajectory

PLANE = Plane(normal=(0.0, 1.0, 0.0), offset=0.0, friction=0.5)
PNG_SIGNATURE = b"\x89PNG\r\n\x1a\n"


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
        row.update(metrics.compare(ref, traj, plane=PLANE, material=Material()))
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
    kinds = ["identity" if c in IDENTITY_COLUMNS or c.startswith("param_") else
             "metric" if c in METRIC_COLUMNS else "provenance" if c in PROVENANCE_COLUMNS else "?" for c in columns]
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
    code = ("import sys, json; from analysis.table import provenance; p = provenance('cpu', gpu_name=''); "
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


class _TagChecker(HTMLParser):
    """Collects external resource references and checks that non-void elements nest and close."""

    VOID: ClassVar[set[str]] = {"meta", "img", "br", "hr", "link", "input", "source"}

    def __init__(self) -> None:
        super().__init__()
        self.stack: list[str] = []
        self.errors: list[str] = []
        self.refs: list[str] = []
        self.headings: list[str] = []
        self._in_h2 = False

    def handle_starttag(self, tag: str, attrs: list[tuple[str, str | None]]) -> None:
        self.refs += [value or "" for name, value in attrs if name in ("src", "href")]
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
    return checker


def test_html_report_is_self_contained(tmp_path: Path, runs) -> None:
    ref, others = runs
    errors = {label: metrics.error_over_time(ref, traj) for label, traj in others.items()}
    gates = [{"gate": "accuracy", "passed": True, "value": 0.01, "threshold": 0.05},
             {"gate": "speed", "passed": False, "value": 3.0, "threshold": 5.0}]
    rows = with_remesh_ratio([r | {"remesh": "alt", "model": "r16"} if r["mesh"] == "block/coarse_alt" else r
                              for r in result_rows(runs)])
    path = write_report_html(rows, tmp_path, gates=gates,
                             runs=[ScenarioRuns("slide", ref, others, errors, plane=PLANE)], renderer="matplotlib",
                             extra_sections=[("Notes", "<p>hand-written</p>")])
    page = path.read_text(encoding="utf-8")
    assert path == tmp_path / "report.html" and page.startswith("<!DOCTYPE html>")
    assert "http://" not in page and "https://" not in page
    checker = check_html(page)
    assert all(ref.startswith(("data:image/png;base64,", "#")) for ref in checker.refs)
    assert checker.headings == ["Summary", "Accuracy versus time", "Error over time",
                                "Reference time-step convergence", "Stick/slip agreement",
                                "Remeshing", "Stability", "Renders: full versus reduced", "Notes", "Provenance"]
    images = [r for r in checker.refs if r.startswith("data:image/png")]
    assert len(images) == 2 + 3 * 3  # accuracy plot, one error plot, 3 key frames x (full + 2 reduced)
    assert "Gates: 1 of 2 passed, 1 failed." in page
    assert "Newton did not converge at t=0.3" in page
    assert 'class="fail"' in page and 'class="pass"' in page
    assert "block/coarse_alt" in page  # remeshing table
    assert "matplotlib" in page  # which renderer made the pictures


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
    assert page.count("data:image/png;base64,") == 1
    assert page.count("No trajectories were given to the report.") == 2


def test_render_makes_a_png_with_the_selected_renderer(runs) -> None:
    ref, _ = runs
    renderer = select_renderer("auto")
    assert renderer.name in ("vtk", "matplotlib")
    png = render_surface(ref.x[0], ref.surface, bounds=view_bounds(ref.x), plane=PLANE, renderer=renderer)
    assert png.startswith(PNG_SIGNATURE) and len(png) > 1000


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


def test_renderer_falls_back_to_matplotlib_without_vtk(monkeypatch: pytest.MonkeyPatch) -> None:
    monkeypatch.setattr(render, "_probe_vtk", lambda window: None)
    select_renderer.cache_clear()
    try:
        assert select_renderer("auto").name == "matplotlib"
        with pytest.raises(RuntimeError, match="off-screen"):
            select_renderer("vtk")
    finally:
        select_renderer.cache_clear()

"""A report opens in a real headless Chromium: no console errors, no network requests, figures drawn, and the
figures respond: hovering a point of the frontier names its variant, the 3D viewer advances when played.
(.ci/run also checks the quick suite's own report with `python -m frictionbench.reports.browser_check`.)"""

from __future__ import annotations

from collections.abc import Iterator
from pathlib import Path

import numpy as np
import pytest

from frictionbench.analysis.metrics import error_over_time
from frictionbench.bench.runner import run_suite
from frictionbench.reports.browser_check import CHROMIUM_ARGS, PLOT_TIMEOUT_MS, check_report, require_chromium
from frictionbench.reports.html import ScenarioRuns, write_report_html
from frictionbench.scenarios.spec import Plane
from frictionbench.solvers.trajectory import Trajectory

from scenes import block_drop, mu_axis, suite_tables, write_toml

PLANE = Plane(normal=(0.0, 1.0, 0.0), offset=0.0, friction=0.5)
HOSTILE = '</script><script>window.pwned=1</script><img src=x onerror="window.pwned=2">'


def test_report_loads_offline_without_errors(tmp_path: Path):
    suite = write_toml(tmp_path / "tiny.toml", suite_tables("tiny", block_drop(), mu_axis(0.3),
                                                            description="one block drop"))
    run_suite(str(suite), tmp_path / "out", variants=[], jobs=1)
    page = (tmp_path / "out" / "report.html").read_text(encoding="utf-8")
    assert 'id="viewer-0"' in page  # the stored reference run is in the 3D viewer
    assert check_report(tmp_path / "out" / "report.html") == []


def test_the_check_fails_on_a_page_with_external_resources(tmp_path: Path):
    page = tmp_path / "bad.html"
    page.write_text('<!DOCTYPE html><html><head><script src="http://127.0.0.1:9/x.js"></script></head>'
                    "<body><h2>Summary</h2><script>undefinedFunction()</script></body></html>")
    problems = check_report(page)
    assert any("network request" in p for p in problems)
    assert any("console error" in p or "ReferenceError" in p for p in problems)
    assert any("missing section" in p for p in problems)
    assert any("plots missing" in p for p in problems)


def _sliding(block, speed: float, name_wobble: float = 0.0) -> Trajectory:
    """The block sliding along +x at `speed` [m/s] for 0.5 s (26 frames), lifted by a small wobble [m]."""
    t = np.linspace(0.0, 0.5, 26)
    offset = np.stack([speed * t, name_wobble * np.sin(9.0 * t), np.zeros_like(t)], axis=1)
    return Trajectory(t=t, x=block.X[None] + offset[:, None, :], X=block.X, tets=block.tets, surface=block.surface)


def _report(block, out: Path, scenario: str, variant: str) -> Path:
    """A report of one scenario: a reference and two reduced variants (one named `variant`), all trajectories."""
    ref = _sliding(block, 0.2)
    others = {"licrom/r20": _sliding(block, 0.18, 0.002), f"pod/{variant}": _sliding(block, 0.1)}
    rows = [{"scenario": scenario, "solver": "full", "variant": "reference", "status": "ok", "pos_rmse_rel": 0.0,
             "step_ms_median": 40.0, "speedup": 1.0, "stick_agree": True},
            {"scenario": scenario, "solver": "licrom", "variant": "r20", "status": "ok", "pos_rmse_rel": 0.004,
             "step_ms_median": 2.0, "speedup": 20.0, "stick_agree": True},
            {"scenario": scenario, "solver": "pod", "variant": variant, "status": "ok", "pos_rmse_rel": 0.08,
             "step_ms_median": 1.0, "speedup": 40.0, "stick_agree": False}]
    errors = {label: error_over_time(ref, traj) for label, traj in others.items()}
    return write_report_html(rows, out, runs=[ScenarioRuns(scenario, ref, others, errors, plane=PLANE)],
                             gates=[{"gate": f"{variant}-{k}", "scenario": scenario, "passed": k != 7}
                                    for k in range(10)], title=scenario)


@pytest.fixture
def browser_page() -> Iterator[tuple[object, list[str]]]:
    """A Chromium page that records console errors, page errors, dialogs and requests other than file: ones."""
    from playwright.sync_api import sync_playwright

    problems: list[str] = []
    with sync_playwright() as p:
        browser = p.chromium.launch(executable_path=require_chromium(), args=CHROMIUM_ARGS)
        page = browser.new_page(viewport={"width": 1280, "height": 900})
        page.on("console", lambda m: problems.append(f"console: {m.text}") if m.type == "error" else None)
        page.on("pageerror", lambda e: problems.append(f"page error: {e}"))
        page.on("dialog", lambda d: (problems.append(f"dialog: {d.message}"), d.dismiss()))
        page.on("request", lambda r: None if r.url.startswith(("file:", "data:")) else problems.append(r.url))
        yield page, problems
        browser.close()


def _open(page, path: Path) -> None:
    page.goto(path.resolve().as_uri(), wait_until="load")
    page.wait_for_function("document.body.dataset.plotsReady === 'yes'", timeout=PLOT_TIMEOUT_MS)


def test_frontier_hover_names_the_variant_and_the_viewer_plays(tmp_path: Path, block, browser_page):
    page, problems = browser_page
    _open(page, _report(block, tmp_path, "slide", "r8"))
    # Hover the pod/r8 point with the mouse: the hover label names the variant and the scenario.
    trace = page.evaluate("Array.from(document.getElementById('frontier').data).findIndex(t => t.name === 'pod/r8')")
    point = page.locator("#frontier .scatterlayer .trace").nth(trace).locator("path.point").first
    point.scroll_into_view_if_needed()
    box = point.bounding_box()
    page.mouse.move(box["x"] + box["width"] / 2, box["y"] + box["height"] / 2)
    page.wait_for_selector("#frontier .hoverlayer .hovertext", timeout=5000)
    label = page.locator("#frontier .hoverlayer").text_content()
    assert "pod/r8" in label and "scenario: slide" in label
    # A click on its legend entry hides the variant, a second shows it again.
    entry = page.locator("#frontier .legend .traces", has_text="pod/r8")
    visible = f"document.getElementById('frontier').data[{trace}].visible"
    entry.click()
    page.wait_for_function(f"{visible} === 'legendonly'", timeout=5000)
    entry.click()
    page.wait_for_function(f"{visible} === true", timeout=5000)
    # Play the viewer: the slider (the shown frame) moves on; Pause stops it.
    viewer = page.locator("#viewer-0")
    viewer.scroll_into_view_if_needed()
    active = "document.getElementById('viewer-0')._fullLayout.sliders[0].active"
    assert page.evaluate(active) == 0
    shown = "Array.from(document.getElementById('viewer-0')._fullData[1].x)"
    x0 = page.evaluate(f"window.__x0 = {shown}")
    viewer.locator(".updatemenu-button", has_text="Play").click()
    # the slider moves on, and the shown surface follows it (it may lag the slider by a transition): the reference
    # slides along +x by more than 0.02 m
    moved = f"Math.max(...{shown}.map((v, i) => v - window.__x0[i]))"
    page.wait_for_function(f"{active} >= 3 && {moved} > 0.02", timeout=20_000)
    viewer.locator(".updatemenu-button", has_text="Pause").click()
    x1 = page.evaluate(shown)
    assert np.max(np.array(x1) - np.array(x0)) > 0.02  # the reference slid along +x between the frames
    # The headline table sorts by a column when its heading is clicked, the other way round on a second click.
    heading = page.locator("#summary table th", has_text="median pos_rmse_rel")
    first_column = "Array.from(document.querySelectorAll('#summary table tbody tr')).map(r => r.cells[0].textContent)"
    heading.click()
    assert page.evaluate(first_column) == ["full", "licrom", "pod"]  # errors 0, 0.004, 0.08
    heading.click()
    assert page.evaluate(first_column) == ["pod", "licrom", "full"]
    # The verdict table (10 rows) has a filter box: typing keeps the rows that contain every word.
    page.locator("#gate-verdicts input.filter").fill("r8-7 failed")
    visible = "#gate-verdicts tbody tr:not([hidden])"
    assert page.locator(visible).count() == 1 and "r8-7" in page.locator(visible).inner_text()
    page.locator("#gate-verdicts input.filter").fill("")
    assert page.locator(visible).count() == 10
    assert problems == []


def test_hostile_names_stay_text_in_the_browser(tmp_path: Path, block, browser_page):
    page, problems = browser_page
    _open(page, _report(block, tmp_path, HOSTILE, HOSTILE))
    assert page.evaluate("window.pwned") is None
    assert page.locator("h1").inner_text() == HOSTILE  # shown as text
    assert HOSTILE in page.locator("#viewer h3").inner_text()
    assert problems == []

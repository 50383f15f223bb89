"""A report opens in a real headless Chromium: no console errors, no network requests, plots shown.
(.ci/run also checks the quick suite's own report with `python -m reports.browser_check`.)"""

from __future__ import annotations

from pathlib import Path

from bench.runner import run_suite
from reports.browser_check import check_report


def test_report_loads_offline_without_errors(tmp_path: Path):
    suite = tmp_path / "tiny.toml"
    suite.write_text('[suite]\nname = "tiny"\ndescription = "one block drop"\n[base.mesh]\nname = "block"\n'
                     'resolution = "coarse"\n[base.initial]\nclearance = 0.01\n[base.time]\ndt = 0.01\n'
                     'duration = 0.05\n[[axis]]\nname = "mu"\nfield = "plane.friction"\nvalues = [0.3]\n')
    run_suite(str(suite), tmp_path / "out", variants=[], jobs=1)
    assert check_report(tmp_path / "out" / "report.html") == []


def test_the_check_fails_on_a_page_with_external_resources(tmp_path: Path):
    page = tmp_path / "bad.html"
    page.write_text('<!DOCTYPE html><html><head><script src="http://127.0.0.1:9/x.js"></script></head>'
                    "<body><h2>Summary</h2><script>undefinedFunction()</script></body></html>")
    problems = check_report(page)
    assert any("network request" in p for p in problems)
    assert any("console error" in p or "ReferenceError" in p for p in problems)
    assert any("missing section" in p for p in problems)

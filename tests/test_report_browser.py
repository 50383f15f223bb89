"""The quick-style report opens in a real headless Chromium: no console errors, no network requests, plots shown."""

from __future__ import annotations

import shutil
from pathlib import Path

from playwright.sync_api import sync_playwright

from bench.runner import run_suite

CHROMIUM = shutil.which("chromium") or "/usr/bin/chromium"


def test_report_loads_offline_without_errors(tmp_path: Path):
    assert Path(CHROMIUM).exists(), "Debian's chromium is required (apt-get install chromium; see .ci/run)"
    suite = tmp_path / "tiny.toml"
    suite.write_text('[suite]\nname = "tiny"\ndescription = "one block drop"\n[base.mesh]\nname = "block"\n'
                     'resolution = "coarse"\n[base.initial]\nclearance = 0.01\n[base.time]\ndt = 0.01\n'
                     'duration = 0.05\n[[axis]]\nname = "mu"\nfield = "plane.friction"\nvalues = [0.3]\n')
    run_suite(str(suite), tmp_path / "out", variants=[], jobs=1)
    page_url = (tmp_path / "out" / "report.html").resolve().as_uri()
    errors, requests = [], []
    with sync_playwright() as p:
        browser = p.chromium.launch(executable_path=CHROMIUM, args=[
            "--no-sandbox", "--disable-gpu", "--disable-background-networking", "--disable-component-update",
            "--disable-sync", "--no-first-run"])
        page = browser.new_page()
        page.on("console", lambda m: errors.append(m.text) if m.type == "error" else None)
        page.on("pageerror", lambda e: errors.append(str(e)))
        page.on("request", lambda r: requests.append(r.url))
        page.goto(page_url, wait_until="load")
        headings = page.locator("h2").all_inner_texts()
        images = page.locator("img")
        n_images = images.count()
        loaded = page.evaluate("Array.from(document.images).every(i => i.complete && i.naturalWidth > 0)")
        browser.close()
    assert errors == []
    assert [u for u in requests if u != page_url and not u.startswith("data:")] == []
    assert "Accuracy versus time" in headings and "Stability" in headings
    assert n_images >= 2 and loaded

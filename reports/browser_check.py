"""Open a report in headless Chromium (Debian's, driven by playwright) and check it as a reader would see it:
it loads with no console errors and no network requests, and its plots and renders are present.

    python -m reports.browser_check out/quick/report.html      # exit 1 with the problems listed
"""

from __future__ import annotations

import shutil
import sys
from pathlib import Path

CHROMIUM_ARGS = ["--no-sandbox", "--disable-gpu", "--disable-background-networking", "--disable-component-update",
                 "--disable-sync", "--no-first-run"]
REQUIRED_SECTIONS = ("Summary", "Accuracy versus time", "Error over time", "Stick/slip agreement", "Remeshing",
                     "Stability")


def check_report(path: str | Path, chromium: str | None = None) -> list[str]:
    """Problems found when loading the report (empty when it is fine)."""
    from playwright.sync_api import sync_playwright

    chromium = chromium or shutil.which("chromium") or "/usr/bin/chromium"
    url = Path(path).resolve().as_uri()
    errors, requests = [], []
    with sync_playwright() as p:
        browser = p.chromium.launch(executable_path=chromium, args=CHROMIUM_ARGS)
        page = browser.new_page()
        page.on("console", lambda m: errors.append(m.text) if m.type == "error" else None)
        page.on("pageerror", lambda e: errors.append(str(e)))
        page.on("request", lambda r: requests.append(r.url))
        page.goto(url, wait_until="load")
        headings = page.locator("h2").all_inner_texts()
        n_images = page.locator("img").count()
        loaded = page.evaluate("Array.from(document.images).every(i => i.complete && i.naturalWidth > 0)")
        browser.close()
    problems = [f"console error: {e}" for e in errors]
    problems += [f"network request: {u}" for u in requests if u != url and not u.startswith("data:")]
    problems += [f"missing section: {s}" for s in REQUIRED_SECTIONS if s not in headings]
    if n_images < 2 or not loaded:
        problems.append(f"plots missing or not loaded ({n_images} images, all loaded: {loaded})")
    return problems


def main() -> int:
    problems = check_report(sys.argv[1])
    for p in problems:
        print(p)
    print(f"report {sys.argv[1]}: {'OK' if not problems else f'{len(problems)} problems'}")
    return 1 if problems else 0


if __name__ == "__main__":
    raise SystemExit(main())

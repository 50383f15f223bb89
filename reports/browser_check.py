"""Open a report in headless Chromium (Debian's, driven by playwright) and check it as a reader would see it:
it loads with no console errors and no network requests, and its interactive plots are drawn.

    python -m frictionbench.reports.browser_check out/quick/report.html  # exit 1 with the problems listed
    python -m frictionbench.reports.browser_check --install              # a Chromium is there (Debian's package)

The browser is `$FRICTIONBENCH_CHROMIUM` when set, else `chromium` (or `chromium-browser`) on the PATH. Nothing
is downloaded by playwright: `--install` installs Debian's `chromium` package with apt-get when none is found
and the user is root (or has password-less sudo), and fails loudly, saying how to get one, otherwise. Without
a browser the check (and the browser tests) fail with `BrowserMissing`; they are never skipped.
"""

from __future__ import annotations

import argparse
import os
import shutil
import subprocess
import sys
from pathlib import Path

CHROMIUM_ARGS = ["--no-sandbox", "--disable-gpu", "--disable-background-networking", "--disable-component-update",
                 "--disable-sync", "--no-first-run"]
REQUIRED_SECTIONS = ("Summary", "Accuracy versus time", "Error over time", "Stick/slip agreement", "Remeshing",
                     "Stability")
ENV_VAR = "FRICTIONBENCH_CHROMIUM"
#: How long the figures may take to draw [ms] (plotly.js parses a few MB of script and data first).
PLOT_TIMEOUT_MS = 60_000
APT_PACKAGE = "chromium"
HOW_TO_GET_ONE = (f"install Debian's package as root (`apt-get install {APT_PACKAGE}`, or "
                  f"`python -m frictionbench.reports.browser_check --install`), or set {ENV_VAR} to a Chromium "
                  "executable")


class BrowserMissing(RuntimeError):
    """No Chromium executable could be found (or installed); the message says how to get one."""


def find_chromium() -> str | None:
    """The Chromium executable: `$FRICTIONBENCH_CHROMIUM` when set (None unless it is an executable file), else
    `chromium` or `chromium-browser` on the PATH; None when there is none."""
    if ENV_VAR in os.environ:
        path = os.environ[ENV_VAR]
        return path if os.path.isfile(path) and os.access(path, os.X_OK) else None
    return shutil.which("chromium") or shutil.which("chromium-browser")


def require_chromium(chromium: str | None = None) -> str:
    """`chromium` if given, else `find_chromium()`; raises BrowserMissing when there is none."""
    found = chromium or find_chromium()
    if found is None:
        where = (f"{ENV_VAR}={os.environ[ENV_VAR]!r} is not an executable file" if ENV_VAR in os.environ
                 else "no chromium or chromium-browser on the PATH")
        raise BrowserMissing(f"no Chromium for the browser check: {where}; {HOW_TO_GET_ONE}")
    return found


def install_chromium() -> str:
    """A Chromium executable, installing Debian's package with apt-get first when none is found and the user is
    root (or has password-less sudo). Raises BrowserMissing when none can be had."""
    if find_chromium() is not None or ENV_VAR in os.environ:  # an explicit choice is never overridden
        return require_chromium()
    apt = shutil.which("apt-get")
    sudo = [] if os.geteuid() == 0 else ["sudo", "-n"]
    if apt is None or (sudo and (shutil.which("sudo") is None
                                 or subprocess.run([*sudo, "true"], capture_output=True).returncode != 0)):
        raise BrowserMissing(f"no Chromium, and it cannot be installed here ("
                             f"{'no apt-get' if apt is None else 'not root and no password-less sudo'}); "
                             f"{HOW_TO_GET_ONE}")
    env = dict(os.environ, DEBIAN_FRONTEND="noninteractive")
    for command in ([*sudo, apt, "update", "-qq"], [*sudo, apt, "install", "-y", "-qq", APT_PACKAGE]):
        print("$ " + " ".join(command), flush=True)
        done = subprocess.run(command, env=env)
        if done.returncode != 0:
            raise BrowserMissing(f"`{' '.join(command)}` failed with exit code {done.returncode}; {HOW_TO_GET_ONE}")
    return require_chromium()


def check_report(path: str | Path, chromium: str | None = None) -> list[str]:
    """Problems found when loading the report (empty when it is fine)."""
    from playwright.sync_api import TimeoutError as PlaywrightTimeout
    from playwright.sync_api import sync_playwright

    chromium = require_chromium(chromium)
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
        n_plots = page.locator("div.plot").count()
        drawn = 0
        if n_plots:
            try:  # the page's boot script marks the body once every figure is drawn
                page.wait_for_function("document.body.dataset.plotsReady === 'yes'", timeout=PLOT_TIMEOUT_MS)
                drawn = page.locator("div.plot.js-plotly-plot").count()
            except PlaywrightTimeout:
                drawn = -1
        browser.close()
    problems = [f"console error: {e}" for e in errors]
    problems += [f"network request: {u}" for u in requests if u != url and not u.startswith("data:")]
    problems += [f"missing section: {s}" for s in REQUIRED_SECTIONS if s not in headings]
    if n_plots == 0 or drawn != n_plots:
        problems.append(f"plots missing or not drawn ({n_plots} plots, "
                        f"{'not all drawn within the time limit' if drawn < 0 else f'{drawn} drawn'})")
    return problems


def main(argv: list[str] | None = None) -> int:
    """Check a report (exit 1 with its problems), or with --install make sure a Chromium is there (exit 1 when
    none can be had)."""
    p = argparse.ArgumentParser(prog="python -m frictionbench.reports.browser_check",
                                description=__doc__.split("\n\n")[0])
    p.add_argument("report", nargs="?", help="report.html to check")
    p.add_argument("--install", action="store_true", help="install Debian's chromium when none is found")
    args = p.parse_args(argv)
    if not args.install and args.report is None:
        p.error("give a report to check, or --install")
    try:
        if args.install:
            print(f"chromium for the browser tests: {install_chromium()}")
        if args.report is None:
            return 0
        problems = check_report(args.report)
    except BrowserMissing as err:
        print(f"error: {err}", file=sys.stderr)
        return 1
    for problem in problems:
        print(problem)
    print(f"report {args.report}: {'OK' if not problems else f'{len(problems)} problems'}")
    return 1 if problems else 0


if __name__ == "__main__":
    raise SystemExit(main())

"""The browser the report checks need (issue 14): README command 2 runs `python -m frictionbench.reports.browser_check
--install`, which installs Debian's Chromium when none is found; without one the check fails loudly, never
skipped. A machine without Chromium is simulated: an empty PATH, or FRICTIONBENCH_CHROMIUM naming no file, and a
stand-in apt-get that records its calls."""

from __future__ import annotations

import io
import os
import shutil
from contextlib import redirect_stderr, redirect_stdout
from pathlib import Path

import pytest

from frictionbench.reports import browser_check
from frictionbench.reports.browser_check import ENV_VAR, BrowserMissing, check_report, install_chromium

CHMOD = shutil.which("chmod")


def _fake_apt(bin_dir: Path, succeed: bool = True) -> Path:
    """An apt-get in `bin_dir` that logs its arguments and, on `install`, puts an executable `chromium` beside
    itself (or fails, with `succeed` false). Returns the log's path."""
    log = bin_dir / "apt.log"
    body = (f'#!/bin/sh\necho "$@" >> "{log}"\n'
            + (f'if [ "$1" = install ]; then echo "#!/bin/sh" > "{bin_dir}/chromium"; '
               f'{CHMOD} +x "{bin_dir}/chromium"; fi\n' if succeed else "exit 100\n"))
    apt = bin_dir / "apt-get"
    apt.write_text(body)
    apt.chmod(0o755)
    return log


@pytest.fixture
def no_browser(tmp_path: Path, monkeypatch: pytest.MonkeyPatch) -> Path:
    """A PATH holding nothing but an empty folder (returned), no FRICTIONBENCH_CHROMIUM, running as root."""
    bin_dir = tmp_path / "bin"
    bin_dir.mkdir()
    monkeypatch.setenv("PATH", str(bin_dir))
    monkeypatch.delenv(ENV_VAR, raising=False)
    monkeypatch.setattr(os, "geteuid", lambda: 0)
    return bin_dir


def test_the_check_fails_loudly_without_a_browser(tmp_path: Path, monkeypatch: pytest.MonkeyPatch):
    page = tmp_path / "page.html"
    page.write_text("<!DOCTYPE html><html><body><h2>Summary</h2></body></html>")
    monkeypatch.setenv(ENV_VAR, str(tmp_path / "no-such-chromium"))
    with pytest.raises(BrowserMissing, match=f"{ENV_VAR}=.*no-such-chromium.* is not an executable file"):
        check_report(page)
    err = io.StringIO()
    with redirect_stderr(err), redirect_stdout(io.StringIO()):
        assert browser_check.main([str(page)]) == 1
        assert browser_check.main(["--install"]) == 1  # an explicit choice is not overridden by an install
    assert "apt-get install chromium" in err.getvalue()


def test_install_uses_debians_package_when_none_is_found(no_browser: Path):
    log = _fake_apt(no_browser)
    out = io.StringIO()
    with redirect_stdout(out):
        assert browser_check.main(["--install"]) == 0
    assert log.read_text().splitlines() == ["update -qq", "install -y -qq chromium"]
    assert f"chromium for the browser tests: {no_browser / 'chromium'}" in out.getvalue()
    # once there, it is found and nothing is installed again
    assert install_chromium() == str(no_browser / "chromium")
    assert len(log.read_text().splitlines()) == 2


def test_install_fails_loudly_when_apt_fails(no_browser: Path):
    _fake_apt(no_browser, succeed=False)
    with pytest.raises(BrowserMissing, match="update -qq` failed with exit code 100"):
        install_chromium()


def test_install_fails_loudly_without_root_or_apt(no_browser: Path, monkeypatch: pytest.MonkeyPatch):
    with pytest.raises(BrowserMissing, match="cannot be installed here \\(no apt-get\\)"):
        install_chromium()
    _fake_apt(no_browser)
    monkeypatch.setattr(os, "geteuid", lambda: 1000)  # not root, and no sudo on this PATH
    with pytest.raises(BrowserMissing, match="not root and no password-less sudo.*apt-get install chromium"):
        install_chromium()
    assert not (no_browser / "apt.log").exists()

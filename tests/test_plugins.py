"""Solvers from outside the repository: a package built and installed here registers solvers through the entry-point
group `frictionbench.solvers`; a solver whose required package is missing is listed as unavailable and its variants
are skipped with the reason; `frictionbench run --solvers full` does not import torch."""

from __future__ import annotations

import json
import os
import subprocess
import sys
import textwrap
from pathlib import Path

import pandas as pd
import pytest

from frictionbench.bench.runner import Variant, available_variants
from frictionbench.bench.matrix import load_matrix
from frictionbench.solvers import registry
from frictionbench.solvers.step_stats import StepStats, stats_summary

ROOT = Path(__file__).resolve().parents[1]
MISSING = "frictionbench_no_such_package"

PYPROJECT = """
[build-system]
requires = ["setuptools>=68"]
build-backend = "setuptools.build_meta"

[project]
name = "toyplug"
version = "0.1"

[tool.setuptools]
py-modules = ["toyplug", "toyplug_heavy"]

[project.entry-points."frictionbench.solvers"]
drift = "toyplug:Drift"
needy = "toyplug:Needy"
choosy = "toyplug:Choosy"
heavy = "toyplug_heavy:Heavy"
misnamed = "toyplug:Drift"
full = "toyplug:Drift"
"""

TOYPLUG = f'''
"""Solvers of a package outside frictionbench."""

import time

from frictionbench.solvers.contract import Solver
from frictionbench.solvers.step_stats import StepStats


class Drift(Solver):
    """Every vertex keeps its velocity, x' = x + h v, in a fixed two sweeps (no forces, no convergence test)."""

    name = "drift"

    def setup(self, model):
        pass

    def step(self, state_in, state_out, dt):
        t0 = time.perf_counter()
        state_out.x, state_out.v, state_out.t = state_in.x + dt * state_in.v, state_in.v.copy(), state_in.t + dt
        return StepStats(wall_s=time.perf_counter() - t0, iterations=2, counters={{"sweeps": 2}})


class Choosy(Drift):
    """Drift that needs an installed package whose import would fail: available, since nothing imports it to say so."""

    name = "choosy"
    requires = ("toyplug_heavy",)


class Needy(Drift):
    """Drift that needs a package nobody has."""

    name = "needy"
    requires = ("{MISSING}",)

'''

HEAVY = f'''
"""A solver module that imports a package nobody has."""

import {MISSING}
'''


@pytest.fixture(scope="module")
def site(tmp_path_factory) -> Path:
    """The folder the package `toyplug` was installed into by pip (built from its pyproject, offline)."""
    src = tmp_path_factory.mktemp("toyplug-src")
    (src / "pyproject.toml").write_text(PYPROJECT)
    (src / "toyplug.py").write_text(textwrap.dedent(TOYPLUG))
    (src / "toyplug_heavy.py").write_text(textwrap.dedent(HEAVY))
    site = tmp_path_factory.mktemp("toyplug-site")
    done = subprocess.run([sys.executable, "-m", "pip", "install", "--no-deps", "--no-build-isolation", "--no-index",
                           "-q", "--target", str(site), str(src)], capture_output=True, text=True, timeout=300,
                          check=False)
    assert done.returncode == 0, done.stderr
    assert (site / "toyplug.py").is_file() and list(site.glob("toyplug-0.1.dist-info/entry_points.txt"))
    return site


@pytest.fixture
def installed(site, monkeypatch):
    """The package importable in this process, the registry's view of installed packages re-read (and again after)."""
    monkeypatch.syspath_prepend(str(site))
    monkeypatch.setattr(registry, "_ENTRIES", dict(registry._ENTRIES))
    registry.installed.cache_clear()
    yield site
    registry.installed.cache_clear()


def _env(site: Path | None) -> dict[str, str]:
    """This environment with the worktree (and the installed package's folder) on PYTHONPATH."""
    paths = ([str(site)] if site else []) + [str(ROOT)]
    return dict(os.environ, PYTHONPATH=os.pathsep.join(paths))


def test_an_installed_package_registers_its_solvers_through_the_entry_point(installed):
    assert {"drift", "needy", "heavy"} <= set(registry.solver_names())
    drift = registry.get_solver("drift")
    assert drift.__module__ == "toyplug" and drift.name == "drift" and registry.unavailable("drift") is None
    # the repository's own solver keeps its name against a package claiming it
    assert registry.entries()["full"] == "frictionbench.solvers.full.plugin:FullSpace"
    assert registry.entries()["drift"] == "toyplug:Drift"  # what a worker process registers


def test_a_solver_without_its_required_package_is_unavailable_with_the_reason(installed):
    assert registry.unavailable("needy") == f"needs {MISSING!r}, which is not installed"
    with pytest.raises(registry.SolverUnavailable, match=f"solver 'needy' is unavailable: needs {MISSING!r}"):
        registry.get_solver("needy")
    assert f"No module named {MISSING!r}" in registry.unavailable("heavy")
    assert "toyplug_heavy does not import" in registry.unavailable("heavy")
    assert registry.unavailable("misnamed") == ("toyplug:Drift is not a solvers.contract.Solver subclass named "
                                                "'misnamed'")


def test_a_required_package_is_not_imported_to_say_the_solver_is_available(installed):
    """Availability asks the import system whether a required package is installed, without importing it: a
    solver's heavy packages (torch) load when it runs, not when the harness lists or plans the runs."""
    sys.modules.pop("toyplug_heavy", None)
    assert registry.unavailable("choosy") is None and "toyplug_heavy" not in sys.modules


def test_the_variants_of_an_unavailable_solver_are_skipped_with_a_note(installed, capsys, tmp_path):
    variants = [Variant("drift", label="d"), Variant("needy", label="n1"), Variant("needy", label="n2")]
    kept, skipped = available_variants(variants)
    assert kept == variants[:1]
    assert skipped == [{"solver": "needy", "variant": label, "reason": f"needs {MISSING!r}, which is not installed"}
                       for label in ("n1", "n2")]
    assert capsys.readouterr().err.count("note: skipping variant 'n") == 2
    # a matrix entry of an unavailable solver cannot check its parameters: it is read, and then skipped like the others
    (tmp_path / "m.toml").write_text('[[variant]]\nsolver = "needy"\nlabel = "x{a}"\n'
                                     'axis = [{ name = "a", param = "anything", values = [1, 2] }]\n')
    assert [v.params for v in load_matrix(tmp_path / "m.toml").variants] == [{"anything": 1}, {"anything": 2}]


def test_a_step_record_needs_only_its_wall_time_and_carries_a_solvers_own_counters():
    plain = StepStats(wall_s=0.1)
    assert (plain.iterations, plain.converged, plain.residual, plain.counters, plain.retries) == (1, True, 0.0, {}, 0)
    failed = StepStats(wall_s=0.2, iterations=5, converged=False, counters={"sweeps": 5})
    merged = failed.merged(StepStats(wall_s=0.1, iterations=2, counters={"sweeps": 2, "restarts": 1}), plain)
    assert (merged.iterations, merged.converged, merged.retries) == (8, True, 1)
    assert merged.counters == {"sweeps": 7, "restarts": 1} and merged.wall_s == pytest.approx(0.4)
    summary = stats_summary([merged, plain])
    assert summary["counters"] == {"sweeps": 7, "restarts": 1} and "line_search_stalls" not in summary
    assert summary["newton_iters_mean"] == 4.5 and summary["step_retries"] == 1
    assert stats_summary([StepStats(wall_s=0.1, counters={"stalls": 2})])["line_search_stalls"] == 2


def test_the_cli_lists_and_runs_installed_solvers_and_skips_an_unavailable_one(site, tmp_path):
    env = _env(site)
    listing = subprocess.run([sys.executable, "-m", "frictionbench.bench.cli", "list"], cwd=tmp_path, env=env,
                             capture_output=True, text=True, timeout=300, check=False)
    assert listing.returncode == 0, listing.stderr
    solvers = listing.stdout.split("solvers:\n")[1].splitlines()
    assert "  drift" in solvers and "  full" in solvers
    assert f"  needy    unavailable: needs {MISSING!r}, which is not installed" in solvers
    out = tmp_path / "out"
    run = subprocess.run([sys.executable, "-m", "frictionbench.bench.cli", "run", "--suite", "verify",
                          "--only", "verify/block_fall",
                          "--solvers", "drift,needy", "--no-truth", "--no-report", "--out", str(out)],
                         cwd=tmp_path, env=env, capture_output=True, text=True, timeout=600, check=False)
    assert run.returncode == 0, run.stderr
    assert f"note: skipping variant 'needy': solver 'needy' is unavailable: needs {MISSING!r}" in run.stderr
    rows = pd.read_csv(out / "results.csv").set_index("solver")
    assert sorted(rows.index) == ["drift", "full"]
    drift = rows.loc["drift"]  # run in a worker process, which found the package's solver too
    assert drift["status"] == "ok" and drift["newton_iters_mean"] == 2 and pd.isna(drift["line_search_stalls"])
    assert json.loads((out / "run.json").read_text())["skipped"][0]["variant"] == "needy"


def test_run_with_the_full_space_solver_does_not_import_torch(tmp_path):
    code = textwrap.dedent(f"""
        import sys
        from frictionbench.bench.cli import main
        from frictionbench.bench.matrix import variant_set
        assert [v.solver for v in variant_set("full-sweep")] == ["full"] * 5
        rc = main(["run", "--suite", "verify", "--only", "verify/block_fall", "--solvers", "full", "--no-truth",
                   "--no-report", "--out", {str(tmp_path / "out")!r}])
        assert rc == 0, rc
        print(sorted(m for m in ("torch",) if m in sys.modules))
    """)
    done = subprocess.run([sys.executable, "-c", code], cwd=tmp_path, env=_env(None), capture_output=True,
                          text=True, timeout=600, check=False)
    assert done.returncode == 0, done.stderr
    assert done.stdout.splitlines()[-1] == "[]"
    assert (tmp_path / "out" / "results.csv").is_file()

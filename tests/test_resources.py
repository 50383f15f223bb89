"""Resource guard (issue 14): oversized runs are refused before any work, naming the field, the step count and
the estimated size; an explicit override lets them through; every shipped suite passes with the default bounds."""

from __future__ import annotations

import os
import re
import subprocess
import sys
import time
from pathlib import Path

import pytest

from frictionbench.bench.cli import parse_variants
from frictionbench.bench.runner import guard_resources, run_suite
from frictionbench.bench.matrix import set_names
from frictionbench.scenarios.errors import ScenarioError
from frictionbench.scenarios.load import scenario_from_dict
from frictionbench.scenarios.resources import MAX_STEPS, check_resources, check_runs, stored_bytes, stored_frames
from frictionbench.scenarios.suites import list_suites, load_suite, suite_from_dict

from scenes import block_drop, mu_axis, suite_tables, write_toml

ROOT = Path(__file__).resolve().parents[1]


def _simulate(tmp_path: Path, time_table: dict[str, float], *extra: str) -> tuple[subprocess.CompletedProcess, float]:
    """`frictionbench simulate` of a default scenario with the given [time] entries: the process and its wall time."""
    scene = write_toml(tmp_path / "scene.toml", {"name": "oversized", "time": time_table})
    env = dict(os.environ, PYTHONPATH=str(ROOT) + os.pathsep + os.environ.get("PYTHONPATH", ""))
    t0 = time.perf_counter()
    done = subprocess.run([sys.executable, "-m", "frictionbench.bench.cli", "simulate", str(scene),
                           "--out", str(tmp_path / "out"),
                           *extra], capture_output=True, text=True, timeout=60, env=env)
    return done, time.perf_counter() - t0


@pytest.mark.parametrize(("entry", "field", "steps"), [({"dt": 1e-12}, "time.dt", "1e+12 steps"),
                                                       ({"duration": 1e12}, "time.duration", "1e+14 steps")])
def test_simulate_refuses_an_absurd_step_count_at_once(tmp_path: Path, entry: dict, field: str, steps: str):
    done, elapsed = _simulate(tmp_path, entry)
    assert done.returncode == 2, done.stderr
    assert elapsed < 5.0  # interpreter start and imports included; the guard itself needs no simulation
    message = done.stderr
    assert message.startswith(f"error: {field} = ")
    assert steps in message and "stored frames = " in message  # the step count and the estimated size
    assert re.search(r"stored frames = [0-9.]+ [TP]iB per mesh vertex in memory and on disk", message)
    assert "--allow-large" in message
    assert not (tmp_path / "out").exists()


def test_stored_frames_beyond_the_bound_name_frame_every():
    sc = scenario_from_dict({"name": "many_frames", "time": {"dt": 1e-4, "duration": 5.0}})  # 50,000 steps
    assert stored_frames(sc.time) == 50_001
    n = 3000
    assert stored_bytes(sc.time, n) == 50_001 * n * 3 * 8 * 2
    with pytest.raises(ScenarioError) as err:
        check_resources(sc, n)
    assert err.value.field == "time.frame_every" and "50,001 stored frames x 3000 vertices = 6.71 GiB" in str(err.value)
    # storing every 10th step fits
    sparse = scenario_from_dict({"name": "few_frames", "time": {"dt": 1e-4, "duration": 5.0, "frame_every": 10}})
    assert stored_frames(sparse.time) == 5_001
    check_resources(sparse, n)


def test_the_step_bound_is_inclusive_and_counts_rounded_steps():
    at = scenario_from_dict({"name": "at_bound", "time": {"dt": 1e-5, "duration": MAX_STEPS * 1e-5}})
    check_resources(at, 10)
    over = scenario_from_dict({"name": "over_bound", "time": {"dt": 1e-5, "duration": (MAX_STEPS + 1) * 1e-5}})
    with pytest.raises(ScenarioError, match="time.dt"):
        check_resources(over, 10)


def test_the_override_lets_oversized_runs_through_validation(tmp_path: Path):
    sc = scenario_from_dict({"name": "tiny_dt", "time": {"dt": 1e-12}})
    with pytest.raises(ScenarioError):
        check_runs([(sc, sc.mesh)])
    check_runs([(sc, sc.mesh)], allow_large=True)
    check_resources(sc, 10**6, allow_large=True)
    # suite level: `allow_large = true` in the [suite] table
    d = suite_tables("long", block_drop(resolution=None, clearance=None, dt=None, duration=1e12), mu_axis(0.3))
    with pytest.raises(ScenarioError, match="time.duration"):
        guard_resources(suite_from_dict(d), [])
    allowed = suite_from_dict(d | {"suite": {"name": "long", "allow_large": True}})
    assert allowed.allow_large
    guard_resources(allowed, [], allow_large=allowed.allow_large)
    with pytest.raises(ScenarioError, match="suite.allow_large"):
        suite_from_dict(d | {"suite": {"name": "long", "allow_large": "yes"}})


def test_a_suite_run_is_refused_before_any_work(tmp_path: Path):
    base = block_drop(resolution=None, clearance=None, dt=1e-9, duration=None)
    suite = write_toml(tmp_path / "long.toml", suite_tables("long", base, mu_axis(0.3)))
    t0 = time.perf_counter()
    with pytest.raises(ScenarioError, match="time.dt"):
        run_suite(str(suite), tmp_path / "out", variants=[])
    assert time.perf_counter() - t0 < 5.0
    assert not list((tmp_path / "out").rglob("*.npz")) and not (tmp_path / "out" / "results.csv").exists()


def test_a_variant_at_half_the_time_step_is_guarded_too():
    d = suite_tables("edge", block_drop(resolution=None, clearance=None, dt=1e-5, duration=1.0), mu_axis(0.3))
    suite = suite_from_dict(d)
    guard_resources(suite, [])  # 100,000 steps: at the bound
    with pytest.raises(ScenarioError, match="200,000 steps"):
        guard_resources(suite, parse_variants("full-sweep"))  # its half-step run takes 200,000


@pytest.mark.parametrize("name", list_suites())
def test_shipped_suites_pass_the_guard_with_their_default_variants(name: str):
    guard_resources(load_suite(name), parse_variants(None, suite=name))
    guard_resources(load_suite(name), parse_variants(",".join(set_names())))  # and with every shipped variant set

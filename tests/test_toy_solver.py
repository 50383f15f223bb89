"""A solver added through the contract alone: registered from this test, run in a small matrix by the CLI and the
runner (in worker processes), with no other file of the project knowing it."""

from __future__ import annotations

import time
from pathlib import Path

import numpy as np
import pandas as pd
import pytest

from frictionbench.bench.cli import main
from frictionbench.solvers import registry
from frictionbench.solvers.contract import Solver, SolverParameterError
from frictionbench.solvers.model import Model, State
from frictionbench.solvers.step_stats import StepStats

from scenes import block_drop, suite_tables, write_toml

SUITE = suite_tables("toy", block_drop(clearance=None, duration=0.1), {"name": "case", "values": [
    {"label": "fall", "plane": False}, {"label": "drop", "initial.clearance": 0.01}]},
    description="a free fall and a drop onto a plane")


class Ballistic(Solver):
    """Rigid ballistic motion under gravity, backward Euler: v' = v + h g, x' = x + h v'. Declines contact."""

    name = "ballistic"
    parameters = {"gravity_scale": 1.0}

    def skip(self, model: Model) -> str | None:
        return "ballistic motion knows no contact" if model.has("contact") else None

    def setup(self, model: Model) -> None:
        self.g = self.params["gravity_scale"] * (model.gravity if model.has("gravity") else np.zeros(3))

    def step(self, state_in: State, state_out: State, dt: float) -> StepStats:
        t0 = time.perf_counter()
        state_out.v = state_in.v + dt * self.g
        state_out.x = state_in.x + dt * state_out.v
        state_out.t = state_in.t + dt
        return StepStats(wall_s=time.perf_counter() - t0)  # one direct update: 1 iteration, converged


@pytest.fixture
def ballistic(monkeypatch):
    monkeypatch.setattr(registry, "_ENTRIES", registry.entries())  # registered for this test only
    registry.register(Ballistic)
    return Ballistic


def test_a_registered_toy_solver_runs_in_the_matrix(ballistic, tmp_path, capsys):
    suite = write_toml(tmp_path / "toy.toml", SUITE)
    out = tmp_path / "out"
    assert main(["list"]) == 0 and "ballistic" in capsys.readouterr().out
    assert main(["run", "--suite", str(suite), "--solvers", "ballistic", "--out", str(out), "--no-report"]) == 0
    # the run ends with its answer in a few lines: the verdict first (a failed run: red), one line per family
    printed = capsys.readouterr().out.splitlines()
    tail = printed[printed.index("") + 1:]
    assert tail[0] == "FAILED: 1 of 4 runs failed."
    assert [ln.split(":")[0] for ln in tail if ln[:2] == "  " and ln[2] != " "] == ["  ballistic", "  full"]
    assert "Runs: 1 of 4 failed" not in "\n".join(tail) and "runs: 1 of 4 failed." in tail[-1]
    assert len(tail) <= 8
    rows = pd.read_csv(out / "results.csv").set_index(["scenario", "solver"])
    assert set(rows.index) == {("toy/fall", "full"), ("toy/drop", "full"), ("toy/fall", "ballistic"),
                               ("toy/drop", "ballistic")}
    fall = rows.loc[("toy/fall", "ballistic")]
    # a free body under uniform gravity does not deform: the full-space reference falls ballistically too
    assert fall["status"] == "ok" and fall["pos_rmse_rel"] < 1e-6 and fall["newton_iters_mean"] == 1
    # no line search, so no stall count: the column is empty for it, counted (0 here) for the Newton reference
    assert pd.isna(fall["line_search_stalls"]) and rows.loc[("toy/fall", "full"), "line_search_stalls"] == 0
    drop = rows.loc[("toy/drop", "ballistic")]
    assert drop["status"] == "failed" and "knows no contact" in drop["failure"]


def test_a_solver_rejects_parameters_it_does_not_declare(ballistic):
    with pytest.raises(SolverParameterError, match="gravity_scal"):
        registry.get_solver("ballistic")(gravity_scal=2.0)
    assert registry.get_solver("ballistic")(gravity_scale=0.0).params == {"gravity_scale": 0.0}


def test_registering_a_non_solver_fails_clearly():
    with pytest.raises(TypeError, match="Solver subclass"):
        registry.register(Path)


def test_a_scene_whose_integrator_the_solver_lacks_is_skipped_with_the_reason(ballistic):
    from frictionbench.scenarios.spec import MeshSpec, Scenario, TimeSpec
    from frictionbench.solvers.run import Skipped, run_scenario

    sc = Scenario(name="fall", mesh=MeshSpec("block", "coarse"), plane=None,
                  time=TimeSpec(dt=0.01, duration=0.02, integrator="bdf2"))
    with pytest.raises(Skipped, match=r"time.integrator = 'bdf2': solver 'ballistic' implements \['backward-euler'\]"):
        run_scenario(sc, "ballistic")
    _, stats = run_scenario(sc, "full")  # the full-space solver implements BDF2 and says it ran it
    assert stats["integrator"] == "bdf2" and not stats["failed"]

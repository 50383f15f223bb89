"""Per-step benchmarks (pytest-benchmark): the full-space step and reduced steps on the same scene, side by side.

Run with `python -m pytest tests/benchmarks --benchmark-json out/benchmarks.json` (.ci/run does); they are not part
of the default test run. Each benchmark steps from the same mid-contact state (the quick suite's first scenario
after 10 steps), so the numbers are directly comparable; compare them as ratios within one run.
"""

from __future__ import annotations

import numpy as np
import pytest

from frictionbench.bench.cli import resolve_scenario
from frictionbench.scenarios.meshes import load_mesh
from frictionbench.solvers.build import build_model, initial_state
from frictionbench.solvers.full.solver import FullSpaceSolver, NewtonSettings
from frictionbench.solvers.model import State
from frictionbench.solvers.reduced.bases import affine_basis, mass_orthonormalise
from frictionbench.solvers.reduced.cubature import uniform_cubature
from frictionbench.solvers.reduced.solver import ReducedSolver


@pytest.fixture(scope="module")
def scene():
    sc = resolve_scenario("quick/p1_mu0.5")
    model = build_model(sc, load_mesh(sc.mesh))
    solver = FullSpaceSolver(model)
    state = initial_state(model)
    for _ in range(10):
        out = State(state.x, state.v, state.t)
        solver.step(state, out, sc.time.dt)
        state = out
    return model, solver, state


def reduced_basis(model, r: int) -> np.ndarray:
    """Affine columns plus smooth random ones (a stand-in for a trained field of the same size)."""
    W = affine_basis(model.X)
    if r > 12:
        rng = np.random.default_rng(0)
        Xh = (model.X - model.X.mean(0)) / model.X.std(0)
        feats = np.concatenate([Xh**2, Xh[:, [0]] * Xh[:, [1]], Xh[:, [1]] * Xh[:, [2]], np.sin(2 * Xh)], axis=1)
        extra = np.einsum("nf,fkr->nkr", feats, rng.standard_normal((feats.shape[1], 3, r - 12)))
        W = np.concatenate([W, extra], axis=2)
    return mass_orthonormalise(W, model.mass)


@pytest.mark.parametrize("linear", ["superlu", "direct"])
def test_full_step(benchmark, scene, linear):
    """The full-space step with SciPy's SuperLU (the original path) and the default direct solver (PARDISO)."""
    model, _, state = scene
    solver = FullSpaceSolver(model, settings=NewtonSettings(linear=linear))
    benchmark(lambda: solver.step(state, State(state.x, state.v, state.t), model.scenario.time.dt))


@pytest.mark.parametrize("r, cubature", [(12, 60), (24, 60), (24, None)])
def test_reduced_step(benchmark, scene, r, cubature):
    model, _, state = scene
    cub = uniform_cubature(model, cubature, seed=0) if cubature else None
    solver = ReducedSolver(model, reduced_basis(model, r), cub)
    state = solver.project(state)
    benchmark(lambda: solver.step(state, State(state.x, state.v, state.t), model.scenario.time.dt))

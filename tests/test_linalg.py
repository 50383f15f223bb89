"""The full-space solver's sparse direct solvers (solvers/linalg.py) and threaded element assembly
(solvers/full/assembly.py): PARDISO against SuperLU on assembled Hessians, whole trajectories with either solver,
the fallback where PARDISO is missing, and the element ranges against one launch."""

from __future__ import annotations

import os
import platform
import subprocess
import sys
from dataclasses import replace
from pathlib import Path

import numpy as np
import pytest
import scipy.sparse as sp

from frictionbench.bench.cli import resolve_scenario
from frictionbench.scenarios.meshes import load_mesh
from frictionbench.scenarios.spec import TimeSpec
from frictionbench.solvers import linalg
from frictionbench.solvers import kernels as K
from frictionbench.solvers.build import build_model
from frictionbench.solvers.full.solver import FullSpaceSolver, NewtonSettings
from frictionbench.solvers.physics.terms import StepData, lagged_at_start
from frictionbench.solvers.run import run_scenario
from frictionbench.solvers.simulate import simulate

from scenes import assert_ranges_match_one_launch

# PARDISO is a dependency on x86-64 (pyproject.toml): there a missing one fails these tests instead of skipping them
needs_pardiso = pytest.mark.skipif(platform.machine() not in ("x86_64", "AMD64"),
                                   reason="MKL PARDISO is installed on x86-64 only")


def shortened(name: str, steps: int):
    """Suite member `name` cut to its first `steps` steps."""
    sc = resolve_scenario(name)
    return replace(sc, time=TimeSpec(dt=sc.time.dt, duration=steps * sc.time.dt, frame_every=1))


@pytest.fixture(scope="module")
def contact_hessians():
    """Gradient (3n,) and block Hessian values (nnzb, 3, 3) of quick/p1_mu0.5 at two states in contact, with the
    solver that assembled them."""
    sc = shortened("quick-undamped/p1_mu0.5", 14)
    model = build_model(sc, load_mesh(sc.mesh))
    solver = FullSpaceSolver(model, settings=NewtonSettings(linear="superlu"))
    traj, _ = simulate(model, solver)
    h = sc.time.dt
    out = []
    for f in (-3, -1):
        x, v = traj.x[f], traj.v[f]
        assert (x[model.points] @ model.plane_normal < model.plane_offset).any()  # in contact
        fn = lagged_at_start(solver.terms, model, x[model.points], v[model.points])
        solver.begin(StepData(x + h * v, x, h, fn))  # backward Euler
        solver.x.assign(x + h * v)
        solver.gradient_hessian(solver.x, h)
        out.append((solver.grad.numpy().ravel().copy(), solver.values.numpy().copy()))
    return solver, out


def test_upper_csr_is_the_upper_triangle_of_the_block_matrix(contact_hessians):
    solver, states = contact_hessians
    p = solver.pattern
    upper = linalg.UpperCSR(p.offsets, p.cols, p.n)
    values = np.random.default_rng(0).standard_normal(states[0][1].shape)  # not symmetric: every entry distinct
    full = p.to_scipy(values)
    got = upper.matrix(values)
    assert got.has_sorted_indices
    assert (got != sp.triu(full)).nnz == 0


@needs_pardiso
def test_pardiso_agrees_with_superlu_on_assembled_hessians(contact_hessians):
    solver, states = contact_hessians
    p = solver.pattern
    pardiso = linalg.make_factoriser("pardiso", p.offsets, p.cols, p.n)
    superlu = linalg.make_factoriser("superlu", p.offsets, p.cols, p.n)
    assert (pardiso.name, superlu.name) == ("pardiso", "superlu")
    for g, values in states:  # the second state reuses the first one's symbolic analysis
        H = p.to_scipy(values)
        for f in (pardiso, superlu):
            f.factorize(values)
        a, b = pardiso.solve(-g), superlu.solve(-g)
        assert np.abs(a - b).max() <= 1e-10 * np.abs(b).max()
        assert np.linalg.norm(H @ a + g) <= 1e-12 * np.linalg.norm(g)


@needs_pardiso
@pytest.mark.parametrize("name, steps", [("verify/block_slide", 40), ("verify/block_stick", 40),
                                         ("hard/t30-slide", 30), ("hard/E1e9", 20), ("quick-undamped/p1_mu0.5", 20)])
def test_trajectories_agree_between_pardiso_and_superlu(name, steps):
    sc = shortened(name, steps)
    model = build_model(sc, load_mesh(sc.mesh))
    settings = NewtonSettings()
    a, sa = simulate(model, FullSpaceSolver(model, settings=replace(settings, linear="pardiso")))
    b, sb = simulate(model, FullSpaceSolver(model, settings=replace(settings, linear="superlu")))
    # each step converges to |dx|_inf < tol L h; the two solves differ by round-off, far inside it
    assert np.abs(a.x - b.x).max() < settings.tol * model.L * sc.time.dt
    assert all(abs(p.iterations - q.iterations) <= 1 for p, q in zip(sa, sb))
    assert all(s.converged for s in sa)


def test_the_fallback_is_superlu_when_pardiso_is_missing(monkeypatch, block):
    monkeypatch.setattr(linalg, "pypardiso", None)
    monkeypatch.setattr(linalg, "PARDISO_ERROR", "ImportError: no module named 'pypardiso'")
    sc = shortened("verify/block_slide", 3)
    model = build_model(sc, block)
    for linear in ("auto", "direct", "superlu"):
        assert FullSpaceSolver(model, settings=NewtonSettings(linear=linear)).info["linear_solver"] == "superlu"
    with pytest.raises(ValueError, match=r"solver.linear = 'pardiso'.*no module named 'pypardiso'"):
        FullSpaceSolver(model, settings=NewtonSettings(linear="pardiso"))
    _, stats = run_scenario(sc, "full", "cpu")
    assert stats["linear_solver"] == "superlu" and stats["not_converged"] == 0


@pytest.mark.parametrize("env, block_import, error", [
    ({"PYPARDISO_MKL_RT": "/nonexistent/libmkl_rt.so"}, False, "OSError"),  # pypardiso there, MKL not loadable
    ({}, True, "ModuleNotFoundError")])  # pypardiso not installed
def test_a_failed_import_of_pardiso_falls_back_to_superlu_and_says_why(env, block_import, error):
    code = ("import sys\n"
            + ("sys.modules['pypardiso'] = None\n" if block_import else "")
            + "from frictionbench.solvers import linalg\n"
            "f = linalg.make_factoriser('direct', [0, 1], [0], 1)\n"
            "print(f.name, '|', linalg.PARDISO_ERROR)")
    done = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, check=True,
                          cwd=Path(__file__).resolve().parents[1], env=os.environ | env)
    name, why = done.stdout.strip().split(" | ")
    assert name == "superlu" and why.startswith(error)


def test_the_linear_solver_that_ran_is_in_the_run_stats(block):
    _, stats = run_scenario(shortened("verify/block_slide", 2), "full", "cpu", {"linear": "cg"})
    assert stats["linear_solver"] == "cg"
    _, stats = run_scenario(shortened("verify/block_slide", 2), "full", "cpu")
    assert stats["linear_solver"] == ("superlu" if linalg.pypardiso is None else "pardiso")


def test_an_unknown_linear_solver_is_refused_by_name(block):
    model = build_model(shortened("verify/block_slide", 2), block)
    with pytest.raises(ValueError, match=r"solver.linear = 'lu'"):
        FullSpaceSolver(model, settings=NewtonSettings(linear="lu"))


def test_element_ranges_give_bitwise_the_single_launch(contact_hessians):
    solver, _ = contact_hessians
    m = solver.model
    rng = np.random.default_rng(2)
    solver.x.assign(m.X + 0.01 * m.L * rng.standard_normal(m.X.shape))
    ins = [solver.x, solver.tets, solver.Dm_inv, solver.vol, m.mu_snh, m.lam_snh, 1.0 + 0.75 * m.mu_snh / m.lam_snh]
    assert_ranges_match_one_launch(solver, K.elastic_hessian_kernel, ins, {1: 1, 2: 1, 3: 1, 7: 16})


@needs_pardiso
def test_the_step_benchmark_breaks_a_contact_step_down_for_each_solver():
    from frictionbench.bench.benchmark_step import benchmark

    records = benchmark(["hard/E1e9"], ["superlu:1", "pardiso:1"], steps=1, settle=1)
    assert [r["linear_solver"] for r in records] == ["superlu", "pardiso"]
    for r in records:
        parts = [r[f"{p}_ms"] for p in ("assembly", "factorisation", "solve", "line_search")]
        assert min(parts) > 0 and sum(parts) < r["step_ms"] and r["newton_iters"][0] >= 1
    assert records[1]["x_end_diff_rel"] < 1e-10 and records[1]["factor_nnz"] > 0
    assert records[0]["newton_iters"] == records[1]["newton_iters"]


@needs_pardiso
def test_the_step_benchmark_steps_the_truth_settings_beside_the_reference_settings():
    from frictionbench.bench.benchmark_step import benchmark, truth_scenario
    from frictionbench.scenarios.errors import ScenarioError

    ref, truth = benchmark(["quick/p1_mu0.5"], ["pardiso:1"], steps=1, settle=1, truth_levels=[1])
    assert (ref["integrator"], ref["contact_lag"], ref["lag_solves_per_step"]) == ("backward-euler", "start", 1.0)
    # level 1 of quick's truth: BDF2 at dt/2 with the contact lag at each step's fixed point, two steps for
    # the reference's one (the same simulated time), each one or more solves
    assert (truth["truth_level"], truth["integrator"], truth["contact_lag"]) == (1, "bdf2", "fixed-point")
    assert truth["dt"] == ref["dt"] / 2 and truth["steps"] == 2 and len(truth["newton_iters"]) == 2
    assert truth["lag_solves_per_step"] >= 1 and truth["wall_s_per_sim_s"] > 0
    assert truth["speedup"] == ref["wall_s_per_sim_s"] / truth["wall_s_per_sim_s"]
    with pytest.raises(ScenarioError, match="no \\[truth\\] table"):
        truth_scenario("hard/E1e9", 0)


def test_simulate_selects_the_linear_solver_and_stats_json_says_which_ran(tmp_path):
    import io
    import json
    from contextlib import redirect_stderr, redirect_stdout

    from frictionbench.bench.cli import main

    out = tmp_path / "s"
    with redirect_stdout(io.StringIO()):
        assert main(["simulate", "verify/block_fall", "--linear", "superlu", "--out", str(out), "--no-vtu",
                     "--quiet"]) == 0
    assert json.loads((out / "stats.json").read_text())["linear_solver"] == "superlu"
    err = io.StringIO()
    with redirect_stderr(err), redirect_stdout(io.StringIO()):
        assert main(["simulate", "verify/block_fall", "--solver", "affine", "--linear", "superlu",
                     "--out", str(tmp_path / "a"), "--quiet"]) == 2
    assert "--linear" in err.getvalue() and "superlu" in err.getvalue()


@needs_pardiso
def test_a_new_pardiso_solver_does_not_search_the_environment_for_mkl(monkeypatch):
    # pypardiso globs the whole lib tree for mkl_rt per solver unless PYPARDISO_MKL_RT names it (1.5 s each)
    def no_glob(*args, **kwargs):
        raise AssertionError("pypardiso searched for mkl_rt")

    monkeypatch.setattr(linalg.pypardiso.pardiso_wrapper.glob, "glob", no_glob)
    monkeypatch.setattr(linalg.pypardiso.pardiso_wrapper, "find_library", lambda name: None)
    f = linalg.make_factoriser("pardiso", np.array([0, 1]), np.array([0]), 1)
    f.factorize(np.diag([1.0, 2.0, 4.0])[None])
    assert np.allclose(f.solve(np.ones(3)), [1.0, 0.5, 0.25], rtol=1e-14)


@needs_pardiso
def test_pardiso_refuses_an_indefinite_matrix_by_name_and_recovers_on_the_next():
    f = linalg.make_factoriser("pardiso", np.array([0, 1]), np.array([0]), 1)
    f.factorize(np.eye(3)[None])
    with pytest.raises(RuntimeError, match=r"PARDISO phase 22 .* error -4"):
        f.factorize(np.diag([1.0, -1.0, 1.0])[None])
    with pytest.raises(RuntimeError, match="before factorize"):
        f.solve(np.ones(3))  # not with the factor of the matrix before the failed one
    f.factorize(np.diag([1.0, 2.0, 4.0])[None])
    assert np.allclose(f.solve(np.ones(3)), [1.0, 0.5, 0.25], rtol=1e-14)

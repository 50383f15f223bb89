"""Full-space solver: kernels against the numpy reference, and verification against analytic results."""

from __future__ import annotations

from dataclasses import replace

import numpy as np
import pytest

from frictionbench.scenarios.spec import Contact, Effects, Initial, MeshSpec, Scenario, TimeSpec
from frictionbench.solvers.build import build_model, initial_state
from frictionbench.solvers.full.solver import FullSpaceSolver, NewtonSettings
from frictionbench.solvers.model import State
from frictionbench.solvers.physics import contact as pc
from frictionbench.solvers.physics import friction as pf
from frictionbench.solvers.physics import material as pm
from frictionbench.solvers.physics.terms import StepData
from frictionbench.solvers.simulate import simulate

from scenes import G, com_series, free_flight, incline

def test_kernels_match_numpy_reference(block):
    sc = incline(30.0, 0.4, contact=Contact(damping=30.0), effects=Effects(damping=True))
    model = build_model(sc, block)
    assert model.terms == ("inertia", "elasticity", "gravity", "contact", "friction", "damping")
    solver = FullSpaceSolver(model)
    rng = np.random.default_rng(1)
    h = 0.01
    x_prev = initial_state(model).x - 0.002 * model.plane_normal
    x = x_prev + 0.01 * h * rng.standard_normal(x_prev.shape) - 0.003 * model.plane_normal
    x[:3] += 0.05 * rng.standard_normal((3, 3))  # a few badly deformed (possibly inverted) tets
    state = State(x_prev, rng.standard_normal(x.shape) * 0.1)
    p = model.points
    solver.begin(StepData(state.x + h * state.v, state.x, h, pf.Friction().begin_step(model, state.x[p], state.v[p])))
    solver.x.assign(x)
    solver.gradient_hessian(solver.x, h)
    c = model.scenario.contact
    fn = pc.normal_pressure(state.x[p], state.v[p], model.plane_normal, 0.0, c.stiffness, c.damping)
    assert (fn > 0).any()
    mu, lam = model.mu_snh, model.lam_snh
    cargs = (x_prev[p], model.area, model.plane_normal, 0.0, c.stiffness, c.damping, h)
    fargs = (x_prev[p], model.area, fn, model.plane_normal, 0.4, c.friction_stiffness, h)
    grad = model.mass[:, None] * (x - state.x - h * state.v) / h**2 - model.mass[:, None] * model.gravity
    grad += pm.elastic_gradient(x, model.tets, model.Dm_inv, model.vol, mu, lam)
    np.add.at(grad, p, pc.penalty_gradient(x[p], *cargs) + pf.friction_gradient(x[p], *fargs))
    assert np.allclose(solver.grad.numpy(), grad, rtol=1e-10, atol=1e-10 * np.abs(grad).max())
    H = np.zeros((3 * model.n, 3 * model.n))
    He = pm.element_hessians(x, model.tets, model.Dm_inv, model.vol, mu, lam)
    for e, tet in enumerate(model.tets):
        idx = (3 * tet[:, None] + np.arange(3)).ravel()
        H[np.ix_(idx, idx)] += He[e]
    Hp = pc.penalty_hessian(x[p], *cargs) + pf.friction_hessian(x[p], *fargs)
    for k, i in enumerate(p):
        H[3 * i:3 * i + 3, 3 * i:3 * i + 3] += Hp[k]
    H += np.kron(np.diag(model.mass / h**2), np.eye(3))
    Hw = solver.pattern.to_scipy(solver.values.numpy()).toarray()
    assert np.abs(Hw - H).max() < 1e-10 * np.abs(H).max()
    E = (0.5 / h**2 * np.sum(model.mass[:, None] * (x - state.x - h * state.v) ** 2)
         - model.mass @ (x @ model.gravity) + pm.elastic_energy(x, model.tets, model.Dm_inv, model.vol, mu, lam)
         + pc.penalty_energy(x[p], *cargs) + pf.friction_energy(x[p], *fargs))
    assert solver.energy(solver.x, h) == pytest.approx(E, rel=1e-12)


def test_free_fall_matches_backward_euler_closed_form(block):
    sc = Scenario(name="free_fall", mesh=MeshSpec("block", "coarse"), plane=None,
                  time=TimeSpec(dt=0.01, duration=0.3))
    model = build_model(sc, block)
    assert model.terms == ("inertia", "elasticity", "gravity")
    traj, stats = simulate(model, FullSpaceSolver(model))
    n = np.arange(traj.n_frames)
    y_exact = traj.x[0, :, 1][None, :] - G * 0.01**2 * (n * (n + 1) / 2)[:, None]
    assert np.abs(traj.x[:, :, 1] - y_exact).max() < 1e-12
    assert np.abs(traj.x[:, :, [0, 2]] - traj.x[0, :, [0, 2]].T[None]).max() < 1e-14
    assert all(s.converged for s in stats)


def test_free_flight_conserves_momentum_and_dissipates_energy(block):
    model = build_model(free_flight(0.4), block)
    assert "gravity" not in model.terms
    traj, _ = simulate(model, FullSpaceSolver(model, settings=NewtonSettings(tol=1e-9)))
    p = np.einsum("n,fnk->fk", model.mass, traj.v)
    assert np.abs(p - p[0]).max() < 1e-12 * np.abs(p[0]).max() + 1e-15
    kinetic = 0.5 * np.einsum("n,fnk,fnk->f", model.mass, traj.v, traj.v)
    elastic = np.array([pm.elastic_energy(x, model.tets, model.Dm_inv, model.vol, model.mu_snh, model.lam_snh)
                        for x in traj.x])
    total = kinetic + elastic - elastic[0]
    assert np.all(np.diff(total) <= 1e-9 * total[0])
    assert total[-1] < total[0]  # backward Euler dissipates a little


@pytest.mark.parametrize("theta, mu", [(30.0, 0.2), (20.0, 0.1), (30.0, np.tan(np.radians(30.0)) - 0.04)])
def test_incline_slides_with_coulomb_acceleration(block, theta, mu):
    model = build_model(incline(theta, mu), block)
    traj, _ = simulate(model, FullSpaceSolver(model))
    t = np.radians(theta)
    downhill = np.array([np.cos(t), -np.sin(t), 0.0])
    s = com_series(traj, model.mass) @ downhill
    late = traj.t > 0.2  # after the contact settles
    a = 2 * np.polyfit(traj.t[late], s[late], 2)[0]
    a_exact = G * (np.sin(t) - mu * np.cos(t))
    assert a == pytest.approx(a_exact, rel=0.03)


def test_incline_sticks_and_creep_is_bounded_by_the_friction_law(block):
    theta, mu = 30.0, 0.7
    model = build_model(incline(theta, mu, duration=0.8), block)
    traj, _ = simulate(model, FullSpaceSolver(model))
    t = np.radians(theta)
    downhill = np.array([np.cos(t), -np.sin(t), 0.0])
    v = np.einsum("n,fnk->fk", model.mass, traj.v) / model.mass.sum() @ downhill
    creep = v[-10:].mean()
    # The law's prediction: the creep speed v at which sum_i A_i min(k_f v, mu f_n,i) carries the downhill load.
    c = model.scenario.contact
    fn = pc.normal_pressure(traj.x[-1][model.points], traj.v[-1][model.points], model.plane_normal, 0.0,
                            c.stiffness, 0.0)
    lo = pf.creep_speed(model.area, fn, mu, c.friction_stiffness, model.mass.sum() * G * np.sin(t))
    assert creep > 0.0
    assert creep == pytest.approx(lo, rel=0.05)
    assert lo < 1e-3  # sticking: creep well below a millimetre per second


def test_zero_friction_builds_no_friction_term(block):
    with_mu0 = build_model(incline(25.0, 0.0), block)
    without = build_model(incline(25.0, 0.3, effects=Effects(friction=False)), block)
    assert "friction" not in with_mu0.terms and "friction" not in without.terms
    a, _ = simulate(with_mu0, FullSpaceSolver(with_mu0))
    b, _ = simulate(without, FullSpaceSolver(without))
    assert np.array_equal(a.x, b.x)


def test_cg_and_direct_linear_solvers_agree(block):
    model = build_model(replace(incline(30.0, 0.3), time=TimeSpec(dt=0.01, duration=0.1)), block)
    a, _ = simulate(model, FullSpaceSolver(model, settings=NewtonSettings(linear="direct", tol=1e-8)))
    b, sb = simulate(model, FullSpaceSolver(model, settings=NewtonSettings(linear="cg", tol=1e-8)))
    assert np.abs(a.x - b.x).max() < 1e-7 * model.L
    assert sum(s.counters["linear_iters"] for s in sb) > 0


def test_barrier_contact_never_penetrates(block):
    sc = replace(incline(10.0, 0.3, duration=0.3), contact=Contact(law="barrier"),
                 initial=Initial(clearance=0.0005, rotation=(0.0, 0.0, -10.0), velocity=(0.0, -0.5, 0.0)))
    model = build_model(sc, block)
    traj, _ = simulate(model, FullSpaceSolver(model))
    phi = traj.x[:, model.points] @ model.plane_normal - model.plane_offset
    assert phi.min() > 0.0

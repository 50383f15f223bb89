"""Reduced (LiCROM) solver: its warp kernel against the numpy reference, the complete basis against the full-space
solver, the affine basis against the incline's analytic answers, cubature quality, the paper's projected-gradient
scheme on free fall, and the baseline bases."""

from __future__ import annotations

from dataclasses import replace

import numpy as np
import pytest

from frictionbench.scenarios.spec import Contact, Effects, Initial, MeshSpec, Scenario, TimeSpec
from frictionbench.solvers.build import build_model, initial_state, rotation_matrix
from frictionbench.solvers.full.solver import FullSpaceSolver, NewtonSettings
from frictionbench.solvers.physics import contact as pc
from frictionbench.solvers.physics import friction as pf
from frictionbench.solvers.physics import material as pm
from frictionbench.solvers.reduced import kernels as K
from frictionbench.solvers.reduced.bases import affine_basis, full_basis, pod_basis, smooth_basis
from frictionbench.solvers.reduced.cubature import cubature_force_error, optimized_cubature, uniform_cubature
from frictionbench.solvers.reduced.pod import Affine
from frictionbench.solvers.reduced.solver import ReducedSolver, ReducedStep, Subspace
from frictionbench.solvers.simulate import simulate

from scenes import G, com_series, free_flight, incline


def simulate_reduced(model, solver):
    """simulate from the initial state projected to the solver's subspace (so that frame 0 has its q too)."""
    return simulate(model, solver, solver.project(initial_state(model)))


def downhill(theta_deg: float) -> np.ndarray:
    t = np.radians(theta_deg)
    return np.array([np.cos(t), -np.sin(t), 0.0])


def law_creep_speed(model, x: np.ndarray, v: np.ndarray, theta_deg: float, mu: float) -> float:
    """Slip speed at which sum_i A_i min(k_f s, mu f_n,i) carries the downhill load (the friction law's creep)."""
    c = model.scenario.contact
    fn = pc.normal_pressure(x[model.points], v[model.points], model.plane_normal, 0.0, c.stiffness, 0.0)
    load = model.mass.sum() * G * np.sin(np.radians(theta_deg))
    return pf.creep_speed(model.area, fn, mu, c.friction_stiffness, load)


def _snh_scaling_block(F: np.ndarray, mu: float, lam: float) -> np.ndarray:
    """The SNH dP/dF restricted to the scaling modes (`solvers.kernels.snh_eigensystem`'s A), (k, 3, 3) at F (k, 3,
    3), from the rotation-variant singular values."""
    U, s, Vt = np.linalg.svd(F)
    s[:, 2] *= np.sign(np.linalg.det(U)) * np.sign(np.linalg.det(Vt))
    ic, J = (s**2).sum(axis=1), s.prod(axis=1)
    a, b, c = mu * (1 - 1 / (ic + 1)), 2 * mu / (ic + 1) ** 2, lam * (J - (1 + 0.75 * mu / lam))
    g = J[:, None] / np.where(s == 0, 1.0, s)  # s_j s_k (no zero singular value among the samples)
    k = 3 - np.add.outer(np.arange(3), np.arange(3))  # the third index of an off-diagonal pair
    off = np.where(np.eye(3, dtype=bool), 0.0, np.take(s, np.where(np.eye(3, dtype=bool), 0, k), axis=1))
    return (a[:, None, None] * np.eye(3) + b[:, None, None] * s[:, :, None] * s[:, None, :]
            + lam * g[:, :, None] * g[:, None, :] + c[:, None, None] * off)


# ----- kernels ----------------------------------------------------------------------------------------------
def test_snh_kernel_matches_numpy_reference():
    rng = np.random.default_rng(3)
    mu, lam = pm.snh_parameters(1e6, 0.45)
    F = np.concatenate([np.eye(3)[None], np.eye(3) + 1e-9 * rng.standard_normal((1, 3, 3)),
                        np.diag([1.0, 1.0, -1.0])[None], rotation_matrix((30.0, -20.0, 70.0))[None],
                        np.eye(3) + 0.3 * rng.standard_normal((40, 3, 3)), rng.standard_normal((40, 3, 3))])
    psi, P, L = K.snh_evaluate(F, mu, lam, K.HESSIAN)
    assert np.abs(psi - pm.snh_energy_density(F, mu, lam)).max() < 1e-12 * mu
    assert np.abs(P - pm.snh_pk1(F, mu, lam)).max() < 1e-12 * mu
    H = L.transpose(0, 2, 1) @ L  # the kernel's factor: (dP/dF)_+ = L^T L
    H_ref = pm.project_psd(pm.snh_dpdf(F, mu, lam))
    assert np.abs(H - H_ref).max() < 1e-12 * np.abs(H_ref).max()
    dropped = ~L.any(axis=2)  # a mode of zero or negative weight is a zero row; the compressed samples have some
    assert dropped.any() and (np.linalg.matrix_rank(L[~dropped.any(axis=1)]) == 9).all()
    pd = np.linalg.eigvalsh(_snh_scaling_block(F, mu, lam)).min(axis=1) > 0
    assert pd.any() and not pd.all()  # both ways of the kernel's scaling block: Cholesky and eigendecomposition
    psi0, P0, H0 = K.snh_evaluate(F, mu, lam, K.ENERGY)
    assert np.array_equal(psi0, psi) and P0 is None and H0 is None
    assert np.array_equal(K.snh_evaluate(F, mu, lam, K.STRESS)[1], P)
    kept = L.copy()
    K.snh_evaluate(2.0 * F, mu, lam, K.HESSIAN)  # the kernel's buffers are reused; its results are not
    assert np.array_equal(L, kept)
    for m in (2.0 * mu, mu):  # a changed material reaches the recorded launch, and so does the change back
        assert np.abs(K.snh_evaluate(F, m, lam, K.ENERGY)[0] - pm.snh_energy_density(F, m, lam)).max() < 1e-12 * m
    with pytest.raises(ValueError, match="device = 'gpu'"):
        K.snh_evaluate(F, mu, lam, K.HESSIAN, device="gpu")


def test_reduced_elastic_terms_match_full_space_assembly(block):
    model = build_model(Scenario(name="rest", mesh=MeshSpec("block", "coarse"), plane=None), block)
    W = smooth_basis(model.X, 20, 0.01 * model.L)
    rs = ReducedSolver(model, W)
    elastic = next(ev for ev in rs.body_evaluations if isinstance(ev.term, pm.Elasticity))
    q = 0.5 * np.random.default_rng(0).standard_normal(20)
    x = model.X + rs.reduced.decode(q)
    args = (model.tets, model.Dm_inv, model.vol, model.mu_snh, model.lam_snh)
    rest = np.zeros(20)
    E, g, H = elastic.reduced(q, ReducedStep(0.01, 0.01, rest, rest, rest, rest, None), 2)
    assert E == pytest.approx(pm.elastic_energy(x, *args), rel=1e-12)
    Wf = W.reshape(-1, 20)
    g_ref = Wf.T @ pm.elastic_gradient(x, *args).ravel()
    assert np.abs(g - g_ref).max() < 1e-10 * np.abs(g_ref).max()
    He = pm.element_hessians(x, *args)
    H_ref = np.zeros((20, 20))
    for e, tet in enumerate(model.tets):
        We = Wf[(3 * tet[:, None] + np.arange(3)).ravel()]
        H_ref += We.T @ He[e] @ We
    assert np.abs(H - H_ref).max() < 1e-8 * np.abs(H_ref).max()


@pytest.mark.parametrize("rows", [(9,), (15,), (9, 15)])
@pytest.mark.parametrize("dense", [True, False])
def test_pull_back_of_hessian_factors_is_that_of_their_hessians(block, dense, rows):
    """The kernels' density Hessians arrive as factors L (k x 9, H9 = L^T L: 9 rows for SNH, 15 for the viscous
    term), one per term: the pull-back (G^T G for one factor, of the summed H9 for several) is
    sum_c w_c V_c B_c^T (sum_t L_tc^T L_tc) B_c, exactly symmetric, on the dense jacobians and on the sparse ones
    (a full basis); the gradient is sum_c w_c V_c B_c^T vec P_c."""
    model = build_model(Scenario(name="rest", mesh=MeshSpec("block", "coarse"), plane=None), block)
    W = smooth_basis(model.X, 20, 0.01 * model.L) if dense else full_basis(model.n)
    rng = np.random.default_rng(1)
    ids = np.sort(rng.choice(model.tets.shape[0], 30, replace=False))
    w = rng.uniform(0.0, 3.0, 30)
    rm = Subspace.build(model, W, (ids, w))
    assert (rm.B_sparse is None) == dense
    factors = [rng.standard_normal((30, k, 9)) for k in rows]
    P = rng.standard_normal((30, 3, 3))
    g, H = rm.pull_back(P, factors)
    B = rm.B  # (c, 9, r): dvec F_c / dq
    wV = w * model.vol[ids]
    H_ref = sum(wV[c] * B[c].T @ L[c].T @ L[c] @ B[c] for c in range(30) for L in factors)
    g_ref = sum(wV[c] * B[c].T @ P[c].ravel() for c in range(30))
    assert np.array_equal(H, H.T)
    assert np.abs(H - H_ref).max() < 1e-12 * np.abs(H_ref).max()
    assert np.abs(g - g_ref).max() < 1e-12 * np.abs(g_ref).max()
    assert rm.pull_back(None, None) == rm.pull_back(None, []) == (None, None)
    # the dense products in single precision: the Hessian to single's round-off, exactly symmetric, in double; the
    # gradient in double as before (the sparse products stay in double)
    single = Subspace.build(model, W, (ids, w), hessian="single")
    g32, H32 = single.pull_back(P, factors)
    assert H32.dtype == np.float64 and np.array_equal(H32, H32.T) and np.array_equal(g32, g)
    if dense:
        assert 1e-12 < np.abs(H32 - H_ref).max() / np.abs(H_ref).max() < 1e-5
    else:
        assert np.array_equal(H32, H)


def test_cubature_weights_and_ids_are_checked(block):
    model = build_model(Scenario(name="rest", mesh=MeshSpec("block", "coarse"), plane=None), block)
    W = smooth_basis(model.X, 12, 0.01 * model.L)
    with pytest.raises(ValueError, match=r"cubature weight -0\.5 at tet 1: weights must be finite and >= 0"):
        Subspace.build(model, W, (np.array([0, 1]), np.array([1.0, -0.5])))
    with pytest.raises(ValueError, match="cubature weight nan at tet 7"):
        Subspace.build(model, W, (np.array([3, 7]), np.array([1.0, np.nan])))
    m = model.tets.shape[0]
    with pytest.raises(ValueError, match=rf"cubature: 1 tet ids and 1 weights; .* in \[0, {m}\)"):
        Subspace.build(model, W, (np.array([m]), np.array([1.0])))
    with pytest.raises(ValueError, match="cubature: 2 tet ids and 1 weights"):
        Subspace.build(model, W, (np.array([0, 1]), np.array([1.0])))


# ----- the complete basis is the full-space solver ------------------------------------------------------------
@pytest.mark.parametrize("integrator", ["backward-euler", "bdf2"])
@pytest.mark.parametrize("kind", ["penalty", "penalty_damped", "viscous", "barrier", "free_fall"])
def test_full_basis_reproduces_full_space_solver(block, kind, integrator):
    short = TimeSpec(dt=0.01, duration=0.05)
    if kind == "penalty":
        sc = replace(incline(30.0, 0.2), time=short)
    elif kind in ("penalty_damped", "viscous"):
        # dropped from 1 mm: at zero clearance the lowest points start at phi = +-1e-17, where the lagged damping
        # set (phi(x^n) < 0) depends on round-off that differs between the warp and numpy evaluations
        sc = replace(incline(30.0, 0.2, contact=Contact(damping=30.0), effects=Effects(damping=True)), time=short,
                     initial=Initial(clearance=0.001, rotation=(0.0, 0.0, -30.0), velocity=(0.0, -0.3, 0.0)))
        if kind == "viscous":  # and every dissipative term at once: the material's Kelvin-Voigt damping too
            sc = replace(sc, material=replace(sc.material, viscosity=20.0))
    elif kind == "barrier":
        sc = replace(incline(10.0, 0.3), contact=Contact(law="barrier"), time=TimeSpec(dt=0.01, duration=0.03),
                     initial=Initial(clearance=0.0005, rotation=(0.0, 0.0, -10.0), velocity=(0.0, -0.5, 0.0)))
    else:
        sc = Scenario(name="free_fall", mesh=MeshSpec("block", "coarse"), plane=None, time=short)
    model = build_model(replace(sc, time=replace(sc.time, integrator=integrator)), block)
    ref, _ = simulate(model, FullSpaceSolver(model, settings=NewtonSettings(tol=1e-8)))
    solver = ReducedSolver(model, full_basis(model.n), tol=1e-8)
    traj, stats = simulate_reduced(model, solver)
    assert all(s.converged for s in stats)
    assert np.abs(traj.x - ref.x).max() < 1e-9 * model.L
    assert np.abs(traj.v - ref.v).max() < 1e-9 * model.L / 0.01
    assert np.abs(traj.q - (traj.x - model.X).reshape(traj.n_frames, -1)).max() < 1e-12 * model.L


# ----- the affine basis against the incline's analytic answers -------------------------------------------------
def test_affine_basis_slides_with_coulomb_acceleration(block):
    theta, mu = 30.0, 0.2
    model = build_model(incline(theta, mu), block)
    traj, stats = simulate_reduced(model, ReducedSolver(model, affine_basis(model.X)))
    assert all(s.converged for s in stats)
    s = com_series(traj, model.mass) @ downhill(theta)
    late = traj.t > 0.2  # after the contact settles
    a = 2 * np.polyfit(traj.t[late], s[late], 2)[0]
    assert a == pytest.approx(G * (np.sin(np.radians(theta)) - mu * np.cos(np.radians(theta))), rel=0.05)


def test_affine_basis_barrier_contact_never_penetrates(block):
    sc = replace(incline(10.0, 0.3, duration=0.3), contact=Contact(law="barrier"),
                 initial=Initial(clearance=0.0005, rotation=(0.0, 0.0, -10.0), velocity=(0.0, -0.5, 0.0)))
    model = build_model(sc, block)
    traj, stats = simulate_reduced(model, ReducedSolver(model, affine_basis(model.X)))
    phi = traj.x[:, model.points] @ model.plane_normal - model.plane_offset
    assert phi.min() > 0.0 and all(s.converged for s in stats)


def test_affine_basis_sticks_within_the_friction_laws_creep(block):
    theta, mu = 30.0, 0.7
    model = build_model(incline(theta, mu, duration=0.8), block)
    traj, _ = simulate_reduced(model, ReducedSolver(model, affine_basis(model.X)))
    speed = np.einsum("n,fnk->fk", model.mass, traj.v)[-10:].mean(axis=0) / model.mass.sum() @ downhill(theta)
    creep = law_creep_speed(model, traj.x[-1], traj.v[-1], theta, mu)
    assert creep < 1e-3  # the law itself predicts sticking (creep well below a millimetre per second)
    assert 0.0 < speed < 1.05 * creep


def test_a_retried_reduced_step_keeps_the_latent_history(block):
    model = build_model(incline(30.0, 0.2, duration=0.1), block)
    solver = ReducedSolver(model, affine_basis(model.X))
    step = solver.step

    def flaky(state_in, state_out, dt):  # every full-size step fails once, its halves succeed
        return replace(step(state_in, state_out, dt), converged=dt < 0.0099)

    solver.step = flaky
    traj, stats = simulate_reduced(model, solver)
    assert [s.retries for s in stats] == [1] * 10
    assert traj.t.size == 11 and traj.q.shape == (11, 12)  # t = 0 and every step, from the successful halves
    np.testing.assert_allclose(model.X + solver.reduced.decode(traj.q[-1]), traj.x[-1], atol=1e-12)


# ----- cubature ------------------------------------------------------------------------------------------------
def test_optimized_cubature_fits_forces_better_than_uniform(block):
    model = build_model(Scenario(name="rest", mesh=MeshSpec("block", "coarse"), plane=None), block)
    W = smooth_basis(model.X, 20, 0.01 * model.L)
    rng = np.random.default_rng(1)
    train, held_out = 0.3 * rng.standard_normal((40, 20)), 0.3 * rng.standard_normal((20, 20))
    ids, w = optimized_cubature(model, W, train, count=30)
    assert 0 < ids.size <= 30 and np.all(w > 0) and np.unique(ids).size == ids.size
    uniform = uniform_cubature(model, 30)
    assert model.vol[uniform[0]] @ uniform[1] == pytest.approx(model.vol.sum(), rel=1e-12)
    for Q in (train, held_out):
        err_opt = cubature_force_error(model, W, Q, (ids, w))
        err_uni = cubature_force_error(model, W, Q, uniform)
        assert err_opt < 0.05 and err_opt < 0.5 * err_uni


# ----- the paper's projected-gradient scheme -------------------------------------------------------------------
def test_projected_gradient_free_fall_matches_closed_form(block):
    sc = Scenario(name="free_fall", mesh=MeshSpec("block", "coarse"), plane=None, time=TimeSpec(dt=0.01, duration=0.2))
    model = build_model(sc, block)
    h, tol, alpha = 0.01, 1e-5, 0.1
    solver = ReducedSolver(model, affine_basis(model.X), cubature=uniform_cubature(model, 40), tol=tol,
                           scheme="projected_gradient", alpha=alpha, max_iter=300)
    assert alpha < solver.projected_gradient_alpha_limit(initial_state(model), h)  # stable for the stiffest mode
    traj, stats = simulate_reduced(model, solver)
    assert all(s.converged for s in stats)
    n = np.arange(traj.n_frames)
    y_exact = traj.x[0, :, 1][None, :] - G * h**2 * (n * (n + 1) / 2)[:, None]
    # Stopping at |W dq|_inf / h < tol L leaves (1 - alpha) / alpha of the last increment undone (the
    # translation converges linearly with factor 1 - alpha): at most e = (1 - alpha) / alpha tol L h per step.
    # Backward Euler carries a position error e_k of step k into x_N with weight N - k, so |y_N - exact| <=
    # N (N + 1) / 2 e.
    N = n[-1]
    bound = N * (N + 1) / 2 * (1 - alpha) / alpha * tol * model.L * h
    assert np.abs(traj.x[:, :, 1] - y_exact).max() < bound
    assert np.abs(traj.x[:, :, [0, 2]] - traj.x[0, :, [0, 2]].T[None]).max() < 1e-12 * model.L


def test_released_licrom_scales_velocity_and_runs_a_fixed_iteration_count(block):
    """LiCROM's released integrator: the latent velocity times 0.99 before each step, so that in free flight (no
    external force; the affine basis holds every translation) the momentum falls by exactly 0.99 a step; and the
    projected gradient at a fixed 3 iterations, each step counted converged (never retried)."""
    model = build_model(replace(free_flight(0.1), time=TimeSpec(dt=0.01, duration=0.1)), block)
    solver = ReducedSolver(model, affine_basis(model.X), tol=1e-10, velocity_scale=0.99)
    traj, _ = simulate_reduced(model, solver)
    p = np.einsum("n,fnk->fk", model.mass, traj.v)
    n = np.arange(traj.n_frames)
    np.testing.assert_allclose(p, 0.99 ** n[:, None] * p[0], rtol=1e-6, atol=1e-9 * np.abs(p[0]).max())
    fixed = ReducedSolver(model, affine_basis(model.X), cubature=uniform_cubature(model, 40),
                          scheme="projected_gradient", alpha=0.1, max_iter=3, fixed_iterations=True)
    _, stats = simulate_reduced(model, fixed)
    assert all(s.iterations == 3 and s.converged and s.retries == 0 for s in stats)
    with pytest.raises(ValueError, match="velocity_scale"):
        ReducedSolver(model, affine_basis(model.X), velocity_scale=1.5)
    with pytest.raises(ValueError, match="fixed iteration count"):
        ReducedSolver(model, affine_basis(model.X), fixed_iterations=True)
    with pytest.raises(ValueError, match="iterations = 0"):
        Affine(iterations=0, scheme="projected_gradient").setup(model)


# ----- baselines ------------------------------------------------------------------------------------------------
def test_bases_represent_what_they_promise(block):
    model = build_model(Scenario(name="rest", mesh=MeshSpec("block", "coarse"), plane=None), block)
    X, n = model.X, model.n
    u_rigid = (X - X.mean(0)) @ rotation_matrix((20.0, 35.0, -50.0)).T + X.mean(0) + [0.1, -0.2, 0.3] - X
    A = affine_basis(X)
    rm = Subspace.build(model, A)
    assert np.abs(rm.decode(rm.project(u_rigid)) - u_rigid).max() < 1e-12 * model.L
    assert np.array_equal(full_basis(n).reshape(3 * n, 3 * n), np.eye(3 * n))
    frames = np.einsum("nak,fk->fna", smooth_basis(X, 20, 0.01), np.random.default_rng(2).standard_normal((30, 20)))
    for affine_X in (None, X):
        W = pod_basis(frames, 20, model.mass, affine_X=affine_X)
        Wf = W.reshape(-1, 20)
        assert np.abs(Wf.T @ (np.repeat(model.mass, 3)[:, None] * Wf) - np.eye(20)).max() < 1e-10
        rm = Subspace.build(model, W)
        assert np.abs(rm.decode(rm.project(frames[7])) - frames[7]).max() < 1e-10 * np.abs(frames[7]).max()
    W = pod_basis(frames, 12, model.mass, affine_X=X)
    rm = Subspace.build(model, W)
    assert np.abs(rm.decode(rm.project(u_rigid)) - u_rigid).max() < 1e-12 * model.L


# ----- contact candidates: the point terms at the points that can be in contact -----------------------------------
def candidate_scene(kind: str, mu: float = 0.2) -> Scenario:
    """A block sliding down an incline (friction mu, none at 0) for 0.15 s under the penalty law (with contact
    damping: `penalty_damped`) or the barrier law: the bottom face in contact, the rest of the surface away."""
    short = TimeSpec(dt=0.01, duration=0.15)
    if kind == "penalty":
        return replace(incline(30.0, mu), time=short)
    if kind == "penalty_damped":
        return replace(incline(30.0, mu, contact=Contact(damping=30.0), effects=Effects(damping=True)), time=short,
                       initial=Initial(clearance=0.001, rotation=(0.0, 0.0, -30.0), velocity=(0.0, -0.5, 0.0)))
    return replace(incline(10.0, mu), contact=Contact(law="barrier"), time=short,
                   initial=Initial(clearance=0.0005, rotation=(0.0, 0.0, -10.0), velocity=(0.0, -0.5, 0.0)))


def test_the_step_norm_bounds_decide_as_the_exact_norm(block):
    """`_StepProblem.step_norm` settles most convergence tests on bounds of |W dq|_inf (the extreme rows below, the
    other rows' largest norm times |dq| above); with the bounds off (every test on the whole product) the
    trajectory is bitwise the same, and a step the upper bound settled reports that bound: at least the exact
    norm, below the tolerance."""
    sc = candidate_scene("penalty_damped")
    model = build_model(sc, block)
    W = smooth_basis(model.X, 24, 0.002 * model.L)
    rm = Subspace.build(model, W)
    Wf, rng = rm.W.reshape(-1, rm.r), np.random.default_rng(3)
    for dq in rng.standard_normal((50, rm.r)):  # the bounds' contract (`Subspace`)
        exact = np.abs(Wf @ dq).max()
        assert np.abs(rm.W_extreme @ dq).max() <= exact <= max(np.abs(rm.W_extreme @ dq).max(),
                                                                rm.W_rest_norm * np.linalg.norm(dq))
    runs, exact_norms = {}, {}
    for bounded in (True, False):
        solver = ReducedSolver(model, W, contact_candidates=True)
        if not bounded:  # no extreme rows to decide on, no finite upper bound: the exact norm every time
            solver.reduced = replace(solver.reduced, W_extreme=np.zeros((1, rm.r)), W_rest_norm=np.inf)
        calls, norm = [], solver._velocity_norm
        solver._velocity_norm = lambda dq, h, calls=calls, norm=norm: calls.append(1) or norm(dq, h)
        runs[bounded], exact_norms[bounded] = simulate_reduced(model, solver), len(calls)
    (traj, stats), (ref, ref_stats) = runs[True], runs[False]
    assert np.array_equal(traj.x, ref.x) and np.array_equal(traj.v, ref.v)
    assert [s.iterations for s in stats] == [s.iterations for s in ref_stats]
    assert all(s.converged for s in stats)
    tol_v = solver.tol * model.L
    assert all(r.residual * (1 - 1e-12) <= s.residual < tol_v for s, r in zip(stats, ref_stats))
    assert sum(s.residual > r.residual * (1 + 1e-9) for s, r in zip(stats, ref_stats)) > len(stats) / 2
    assert exact_norms[True] < exact_norms[False] / 4, exact_norms  # the bounds settle most tests


def counting_candidates(solver: ReducedSolver) -> list[int]:
    """Record the number of candidate points of every point-term evaluation of `solver` (returned list)."""
    counts, pick = [], solver._candidates

    def counted(q, st):
        ids = pick(q, st)
        counts.append(ids.size)
        return ids

    solver._candidates = counted
    return counts


@pytest.mark.parametrize("kind, integrator, lag", [("penalty", "backward-euler", "start"),
                                                    ("penalty_damped", "backward-euler", "start"),
                                                    ("penalty_damped", "bdf2", "fixed-point"),
                                                    ("barrier", "backward-euler", "start")])
def test_contact_candidates_give_the_all_points_trajectory_to_round_off(block, kind, integrator, lag):
    sc = candidate_scene(kind)
    sc = replace(sc, time=replace(sc.time, integrator=integrator), contact=replace(sc.contact, lag=lag))
    model = build_model(sc, block)
    W = smooth_basis(model.X, 24, 0.002 * model.L)
    runs = {}
    for candidates in (False, True):
        solver = ReducedSolver(model, W, contact_candidates=candidates)
        counts = counting_candidates(solver) if candidates else []
        runs[candidates] = simulate_reduced(model, solver) + (counts,)
    (ref, ref_stats, _), (traj, stats, counts) = runs[False], runs[True]
    assert all(s.converged for s in stats)
    assert [s.iterations for s in stats] == [s.iterations for s in ref_stats]
    assert np.abs(traj.x - ref.x).max() < 1e-12 * model.L
    assert np.abs(traj.v - ref.v).max() < 1e-12 * model.L / 0.01
    # the selection leaves points out (the block's top and sides) and keeps the bottom face once in contact
    p = model.points.size
    assert max(counts) < 0.5 * p and np.mean(np.array(counts) > 0) > 0.5


def test_a_single_precision_hessian_steps_as_double_does(block):
    """The Hessian's dense products in single precision (`hessian = "single"`) only perturb Newton's direction: a
    damped block dropped and sliding under friction with the fixed-point lag takes the same Newton iterations every
    step, and its trajectory is double's to round-off (Newton stops where the double gradient says)."""
    sc = candidate_scene("penalty_damped", 0.3)
    model = build_model(replace(sc, time=replace(sc.time, integrator="bdf2"),
                                contact=replace(sc.contact, lag="fixed-point")), block)
    W = smooth_basis(model.X, 24, 0.002 * model.L)
    (ref, ref_stats), (traj, stats) = (simulate_reduced(model, ReducedSolver(model, W, hessian=h))
                                       for h in ("double", "single"))
    assert all(s.converged for s in stats)
    assert [s.iterations for s in stats] == [s.iterations for s in ref_stats]
    assert 0.0 < np.abs(traj.x - ref.x).max() < 1e-9 * model.L


@pytest.mark.parametrize("lag", ["start", "fixed-point"])
def test_a_body_hessian_kept_for_the_step_converges_where_newton_does(block, lag):
    """`hessian_refresh = "step"`: the body terms' Hessian is evaluated (kernels to their Hessian factors, pulled
    back) once a step, at its first iteration, and kept for the step's other iterations and contact-lag solves. A
    damped block dropped and sliding under friction takes Newton's iterations within 5% and stops as close to a
    tightly converged run (tol 1e-9) as Newton's method at the same tolerance does, within the tolerance's
    displacement a step (tol L h)."""
    sc = candidate_scene("penalty_damped", 0.3)
    model = build_model(replace(sc, time=replace(sc.time, integrator="bdf2", duration=0.3),
                                contact=replace(sc.contact, lag=lag)), block)
    W = smooth_basis(model.X, 24, 0.002 * model.L)
    tight, _ = simulate_reduced(model, ReducedSolver(model, W, tol=1e-9))
    runs, hessians = {}, {}
    for refresh in ("iteration", "step"):
        solver = ReducedSolver(model, W, hessian_refresh=refresh)
        calls, pull = [], solver.reduced.pull_back
        solver.reduced.pull_back = lambda P, factors, calls=calls, pull=pull: calls.append(bool(factors)) or pull(
            P, factors)
        runs[refresh], hessians[refresh] = simulate_reduced(model, solver), sum(calls)
    (ref, ref_stats), (traj, stats) = runs["iteration"], runs["step"]
    assert all(s.converged for s in stats)
    iterations = sum(s.iterations for s in stats)
    assert abs(iterations - sum(s.iterations for s in ref_stats)) <= 0.05 * sum(s.iterations for s in ref_stats)
    assert hessians["step"] == len(stats) < hessians["iteration"] / 3  # one a step
    if lag == "fixed-point":
        assert sum(s.counters["lag_solves"] for s in stats) > 2 * len(stats)  # one Hessian over several solves
    tol_step = 1e-5 * model.L * sc.time.dt
    newton, kept = (np.abs(t.x - tight.x).max() for t in (ref, traj))
    assert 0.0 < kept < max(2 * newton, 0.1 * tol_step) and kept < tol_step, (kept, newton)


def test_reduced_tolerance_and_precision_are_checked(block):
    model = build_model(candidate_scene("penalty_damped", 0.3), block)
    W = smooth_basis(model.X, 12, 0.002 * model.L)
    for tol in (0.0, -1e-5, float("nan"), float("inf"), True, "1e-5"):
        with pytest.raises(ValueError, match=f"tol = {tol!r}: expected a finite tolerance > 0"):
            ReducedSolver(model, W, tol=tol)
    with pytest.raises(ValueError, match="hessian = 'half': expected one of \\['double', 'single'\\]"):
        ReducedSolver(model, W, hessian="half")
    with pytest.raises(ValueError, match="hessian_refresh = 'never': expected one of \\['iteration', 'step'\\]"):
        ReducedSolver(model, W, hessian_refresh="never")
    plugin = Affine(hessian_refresh="step", tol=1e-3, hessian="single")  # declared (experimental) ones, passed on
    plugin.setup(model)
    assert (plugin.solver.hessian_refresh, plugin.solver.tol, plugin.solver.reduced.B_hessian.dtype) == (
        "step", 1e-3, np.float32)
    assert Affine().experimental["hessian_refresh"] == Affine().params["hessian_refresh"] == "iteration"


@pytest.mark.parametrize("mu", [0.0, 0.3])
@pytest.mark.parametrize("kind", ["penalty_damped", "barrier"])
def test_point_terms_vanish_outside_the_candidates(block, kind, mu):
    """Each point term evaluated at every sample point is exactly zero (energy, gradient, Hessian) at the points
    `_candidates` leaves out, at states 3 mm (three barrier distances) around a sliding state (without friction,
    the position alone decides: the barrier's and the penalty's reach)."""
    model = build_model(candidate_scene(kind, mu), block)
    solver = ReducedSolver(model, smooth_basis(model.X, 24, 0.002 * model.L), contact_candidates=True)
    traj, _ = simulate_reduced(model, solver)
    from frictionbench.solvers.reduced.solver import ReducedState

    rm, rng = solver.reduced, np.random.default_rng(4)
    st = solver._begin(ReducedState(traj.q[-2], rm.project(traj.v[-2]), traj.t[-2]), 0.01)
    for _ in range(5):
        dq = rng.standard_normal(rm.r)
        q = traj.q[-1] + 0.003 / np.abs(rm.Wp.reshape(-1, rm.r) @ dq).max() * dq
        ids = solver._candidates(q, st)
        out = np.setdiff1d(np.arange(rm.points.size), ids)
        assert 0 < ids.size and 0 < out.size
        x = rm.point_positions(q)
        x_lag, x_bar = st.lagged_positions(model, rm.Xp, rm.Wp)
        for term in solver.point_terms:
            E_out = term.at_points(model, x[out], x_lag[out], x_bar[out], rm.area[out],
                                   None if st.fn is None else st.fn[out], st.h_eff, 2)
            assert E_out[0] == 0.0 and not E_out[1].any() and not E_out[2].any(), term.name
            _, g, H = term.at_points(model, x, x_lag, x_bar, rm.area, st.fn, st.h_eff, 2)
            assert not g[out].any() and not H[out].any(), term.name


@pytest.mark.parametrize("kind, lag", [("penalty_damped", "start"), ("penalty_damped", "fixed-point"),
                                       ("barrier", "fixed-point")])
def test_the_lag_near_the_plane_is_the_lag_at_every_point(block, kind, lag):
    """With the candidates on, a step's lag (friction's pressure, the contact-damping gate, the terms' lagged
    support) is computed at the points near the plane at the start or at the lag alone (`_lag_points`): it equals
    the lag computed at every sample point, to round-off, and leaves most points out."""
    from frictionbench.solvers.reduced.solver import ReducedState

    sc = candidate_scene(kind, 0.3)
    model = build_model(replace(sc, contact=replace(sc.contact, lag=lag)), block)
    W = smooth_basis(model.X, 24, 0.002 * model.L)
    near, every = (ReducedSolver(model, W, contact_candidates=c) for c in (True, False))
    traj, _ = simulate_reduced(model, near)
    rm = near.reduced
    latent = ReducedState(traj.q[-2], rm.project(traj.v[-2]), traj.t[-2])
    lag_at = None if lag == "start" else (traj.q[-1], rm.project(traj.v[-1]))
    ids = near._lag_points(latent.q, latent.q if lag_at is None else lag_at[0])
    assert 0 < ids.size < 0.5 * rm.points.size
    a, b = near._begin(latent, 0.01, None, lag_at), every._begin(latent, 0.01, None, lag_at)
    assert b.fn is not None and (b.fn > 0).any() and (b.lagged & ~b.gate).any() == (kind == "barrier")
    assert np.abs(a.fn - b.fn).max() <= 1e-12 * b.fn.max()
    assert np.array_equal(a.gate, b.gate) and np.array_equal(a.lagged, b.lagged)
    assert not a.lagged[np.setdiff1d(np.arange(rm.points.size), ids)].any()
    for pa, pb in zip(a.lagged_positions(model, *rm.point_rows(ids)), b.lagged_positions(model, rm.Xp, rm.Wp)):
        assert np.abs(pa - pb[ids]).max() <= 1e-15 * model.L


@pytest.mark.parametrize("kind", ["penalty_damped", "barrier"])
def test_point_kernels_match_the_numpy_terms(block, kind):
    """The reduced solver's point evaluation (the full-space warp kernels on its buffers) equals the sum of the
    terms' numpy `at_points` to round-off, at every order, on all sample points, on the candidates, and on none; a
    term without a kernel is evaluated by its numpy reference."""
    from frictionbench.solvers.reduced.solver import ReducedState, _PointSet
    from frictionbench.solvers.reduced.terms import KernelLaunch, PointEvaluations, ReferencePointLaunch

    model = build_model(candidate_scene(kind, 0.3), block)
    solver = ReducedSolver(model, smooth_basis(model.X, 24, 0.002 * model.L), contact_candidates=True)
    assert {t.name for t in solver.point_terms} >= {"friction"}
    assert all(isinstance(launch, KernelLaunch) for launch in solver.point_evaluations.launches)
    traj, _ = simulate_reduced(model, solver)
    rm = solver.reduced
    st = solver._begin(ReducedState(traj.q[-2], rm.project(traj.v[-2]), traj.t[-2]), 0.01)
    q = traj.q[-1]
    for ids in (None, solver._candidates(q, st), np.array([], dtype=np.int64)):
        pts = _PointSet.of(rm, st, ids)
        x = pts.positions(q)
        for order in (0, 1, 2):
            E, g, H = solver.point_evaluations.evaluate(pts, x, st.h_eff, order)
            ref = [t.at_points(model, x, pts.x_lag, pts.x_bar, pts.area, pts.fn, st.h_eff, order)
                   for t in solver.point_terms]
            # to round-off of the terms' own sizes, amplified by the penetration d - n.x (micrometres, a difference
            # of positions some 1e5 times larger that the two evaluations sum in different orders)
            E_ref, E_size = sum(r[0] for r in ref), sum(abs(r[0]) for r in ref)
            assert abs(E - E_ref) <= 1e-9 * E_size
            for got, i in ((g, 1), (H, 2)):
                if order >= i:
                    want, size = sum(r[i] for r in ref), sum(np.abs(r[i]).max(initial=0.0) for r in ref)
                    assert got.shape == want.shape and np.abs(got - want).max(initial=0.0) <= 1e-9 * size
    # a point term that names no kernel (a plug-in's): its numpy reference is evaluated
    friction = next(t for t in solver.point_terms if t.name == "friction")
    mine = type("MyFriction", (type(friction),), {"name": "my_friction", "kernel": None})()
    own = PointEvaluations(solver, [mine])
    assert [type(launch) for launch in own.launches] == [ReferencePointLaunch]
    pts = _PointSet.of(rm, st, None)
    x = pts.positions(q)
    E, g, H = own.evaluate(pts, x, st.h_eff, 2)
    E_ref, g_ref, H_ref = mine.at_points(model, x, pts.x_lag, pts.x_bar, pts.area, pts.fn, st.h_eff, 2)
    assert E == E_ref and np.array_equal(g, g_ref) and np.array_equal(H, H_ref) and g_ref.any()


def test_the_step_benchmark_times_the_reduced_step_beside_the_full_one():
    from frictionbench.bench.benchmark_step import REDUCED, REDUCED_PARTS, benchmark

    records = benchmark(["hard/E1e9"], ["superlu:1"], steps=1, settle=1, reduced=REDUCED, reduced_steps=3,
                        rank=12, cubature=20)
    full, every, cand, once = records
    assert (every["reduced"], cand["reduced"], once["reduced"]) == ("all-points", "candidates", "step-hessian")
    assert every["candidates_mean"] == every["points"] > cand["candidates_max"] > 0
    for r in (every, cand, once):
        parts = [r[f"{p}_ms"] for p in REDUCED_PARTS]
        assert min(parts) > 0 and sum(parts) < r["step_ms"] and r["r"] == 12 and r["cubature_tets"] <= 20
        assert r["speedup"] == pytest.approx(full["step_ms"] / r["step_ms"])
    assert cand["x_end_diff_rel"] < 1e-12 and cand["newton_iters"] == every["newton_iters"]
    assert once["x_end_diff_rel"] < 1e-5 * 0.01 * len(once["newton_iters"])  # tol L h a step

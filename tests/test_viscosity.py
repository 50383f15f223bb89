"""Kelvin-Voigt material damping (solvers.physics.viscosity): the potential's derivatives, its warp kernels and
reduced evaluation against the numpy reference, the physics it must (damped ringing) and must not (rigid motion,
Coulomb sliding) change, the damping-ratio resolution, and the scenario fields' validation."""

from __future__ import annotations

from dataclasses import replace

import numpy as np
import pytest
import scipy.linalg as sla

from frictionbench.scenarios.errors import ScenarioError
from frictionbench.scenarios.load import scenario_from_dict, scenario_hash, scenario_to_dict
from frictionbench.scenarios.meshes import TetMesh, load_mesh, make_mesh
from frictionbench.scenarios.meshgen import structured_box
from frictionbench.scenarios.spec import Initial, Material, MeshSpec, Scenario, TimeSpec
from frictionbench.solvers import kernels as K
from frictionbench.solvers.build import build_model, initial_state, rotation_matrix
from frictionbench.solvers.full.solver import FullSpaceSolver, NewtonSettings
from frictionbench.solvers.model import Model
from frictionbench.solvers.physics import material as pm
from frictionbench.solvers.physics import terms as T
from frictionbench.solvers.physics import viscosity as pv
from frictionbench.solvers.reduced import kernels as RK
from frictionbench.solvers.reduced.bases import affine_basis, full_basis
from frictionbench.solvers.reduced.solver import ReducedSolver, ReducedState
from frictionbench.solvers.reduced.terms import CubatureEvaluation
from frictionbench.solvers.run import run_scenario
from frictionbench.solvers.simulate import simulate

from scenes import G, assert_ranges_match_one_launch, com_series, incline

VISCOUS = pv.Viscosity()


@pytest.fixture(scope="module")
def box() -> TetMesh:
    """A small box with three different side lengths (no degenerate vibration modes): 60 vertices, 144 tets."""
    X, tets = structured_box((0.2, 0.1, 0.15), (4, 2, 3), (-0.1, 0.0, -0.075))
    return make_mesh(X, tets, "box")


def free_body(mesh: TetMesh, material: Material, initial: Initial, dt: float, duration: float) -> Model:
    """A weightless body with no ground."""
    sc = Scenario(name="free", plane=None, gravity=(0.0, 0.0, 0.0), material=material,
                  initial=replace(initial, clearance=None), time=TimeSpec(dt=dt, duration=duration))
    return build_model(sc, mesh)


def _step(model: Model, x_bar: np.ndarray, h: float = 0.01) -> T.StepData:
    return T.StepData(x_hat=x_bar, x_lag=x_bar, h=h, x_bar=x_bar, h_eff=h)


def _perturbed(model: Model, seed: int, scale: float) -> np.ndarray:
    return model.X + scale * np.random.default_rng(seed).standard_normal(model.X.shape)


# ----- the potential ------------------------------------------------------------------------------------------
def test_gradient_and_exact_hessian_match_finite_differences(box):
    model = free_body(box, Material(viscosity=50.0), Initial(), 0.01, 0.01)
    x_bar, x = _perturbed(model, 1, 0.01), _perturbed(model, 2, 0.01)
    step = _step(model, x_bar)
    d = np.random.default_rng(3).standard_normal(x.shape)
    eps = 1e-6
    g = VISCOUS.gradient(model, step, x)
    fd = (VISCOUS.energy(model, step, x + eps * d) - VISCOUS.energy(model, step, x - eps * d)) / (2 * eps)
    assert fd == pytest.approx(np.sum(g * d), rel=1e-7)
    dg = (VISCOUS.gradient(model, step, x + eps * d) - VISCOUS.gradient(model, step, x - eps * d)) / (2 * eps)
    c = model.viscosity / step.h_eff
    exact = T.element_blocks(model, pv.viscous_element_hessians(x, x_bar, model.tets, model.Dm_inv, model.vol, c,
                                                                project=False))
    Hd = (exact @ d.ravel()).reshape(-1, 3)
    assert np.abs(dg - Hd).max() < 1e-6 * np.abs(Hd).max()
    # the solver's Hessian (Gauss-Newton + projected rest) is PSD and differs from the exact one here (some
    # elements compress against x_bar), so the projection is active
    H = VISCOUS.hessian(model, step, x).toarray()
    assert np.linalg.eigvalsh(H).min() > -1e-9 * np.abs(H).max()
    assert np.abs(H - exact.toarray()).max() > 1e-3 * np.abs(H).max()


def test_projected_hessian_is_exact_where_every_element_stretches_against_x_bar(box):
    model = free_body(box, Material(viscosity=50.0), Initial(), 0.01, 0.01)
    x_bar = _perturbed(model, 4, 0.005)
    x = 1.03 * x_bar  # E(1.03 F) - E(F) = 0.03045 F^T F: PSD in every element
    step = _step(model, x_bar)
    H = VISCOUS.hessian(model, step, x).toarray()
    exact = T.element_blocks(model, pv.viscous_element_hessians(x, x_bar, model.tets, model.Dm_inv, model.vol,
                                                                model.viscosity / step.h_eff, project=False))
    assert np.abs(H - exact.toarray()).max() < 1e-12 * np.abs(H).max()


def test_a_rigid_motion_dissipates_nothing(box):
    model = free_body(box, Material(viscosity=50.0), Initial(), 0.01, 0.01)
    x_bar = _perturbed(model, 5, 0.01)
    R = rotation_matrix((20.0, -35.0, 50.0))
    x = x_bar @ R.T + np.array([0.3, -0.2, 0.1])
    step = _step(model, x_bar)
    assert VISCOUS.energy(model, step, x) < 1e-20
    assert np.abs(VISCOUS.gradient(model, step, x)).max() < 1e-10
    # a deformation of the same size does dissipate
    assert VISCOUS.energy(model, step, _perturbed(model, 6, 0.01)) > 1e-3


def test_warp_kernels_match_numpy_reference(box):
    model = free_body(box, Material(viscosity=50.0), Initial(), 0.01, 0.01)
    x_bar, x = _perturbed(model, 7, 0.01), _perturbed(model, 8, 0.01)
    step = _step(model, x_bar, 0.004)
    solver = FullSpaceSolver(model)
    solver.begin(step)
    viscous = next(la for la in solver.launchers if isinstance(la.term, pv.Viscosity))
    solver.x.assign(x)
    solver.energy_buf.zero_()
    viscous.launch(solver.x, step.h_eff, 0, True)
    assert float(solver.energy_buf.numpy()[0]) == pytest.approx(VISCOUS.energy(model, step, x), rel=1e-12)
    solver.grad.zero_()
    solver.values.zero_()
    viscous.launch(solver.x, step.h_eff, 1, True)
    g = VISCOUS.gradient(model, step, x)
    assert np.abs(solver.grad.numpy() - g).max() < 1e-11 * np.abs(g).max()
    H = VISCOUS.hessian(model, step, x).toarray()
    Hw = solver.pattern.to_scipy(solver.values.numpy()).toarray()
    assert np.abs(Hw - H).max() < 1e-10 * np.abs(H).max()


def test_the_threaded_hessian_launch_is_bitwise_the_single_launch():
    """Element ranges on threads (solvers.full.assembly) write the same blocks as one launch (2113 tets: 2 ranges)."""
    mesh = load_mesh(MeshSpec("cheese", "coarse"))
    model = free_body(mesh, Material(viscosity=50.0), Initial(), 0.01, 0.01)
    solver = FullSpaceSolver(model)
    solver.begin(_step(model, _perturbed(model, 11, 0.002)))
    strain_bar = next(la for la in solver.launchers if isinstance(la.term, pv.Viscosity)).arrays["E_bar"]
    solver.x.assign(_perturbed(model, 12, 0.002))
    ins = [solver.x, strain_bar, solver.tets, solver.Dm_inv, solver.vol, model.viscosity / 0.01]
    assert_ranges_match_one_launch(solver, K.viscous_hessian_kernel, ins, {1: 1, 2: 1, 3: 1, 4: 1, 6: 16})


def test_reduced_evaluation_matches_the_full_space_reference(box):
    """Full basis, every tet as cubature: the reduced energy, gradient and Hessian and the projected-gradient
    scheme's sample gradient equal the full-space reference."""
    model = free_body(box, Material(viscosity=50.0), Initial(), 0.01, 0.01)
    x_bar, x = _perturbed(model, 9, 0.01), _perturbed(model, 10, 0.01)
    rs = ReducedSolver(model, full_basis(model.n), scheme="projected_gradient")
    q_bar, q = (x_bar - model.X).ravel(), (x - model.X).ravel()
    st = rs._begin(ReducedState(q_bar, np.zeros_like(q_bar)), 0.01)
    step = _step(model, x_bar)
    viscous = next(ev for ev in rs.body_evaluations if isinstance(ev.term, pv.Viscosity))
    E, g, H = viscous.reduced(q, st, 2)
    assert E == pytest.approx(VISCOUS.energy(model, step, x), rel=1e-12)
    ref_g = VISCOUS.gradient(model, step, x)
    assert np.abs(g - ref_g.ravel()).max() < 1e-11 * np.abs(ref_g).max()
    ref_H = VISCOUS.hessian(model, step, x).toarray()
    assert np.abs(H - ref_H).max() < 1e-10 * np.abs(ref_H).max()
    pts = rs.samples
    u = (x - model.X)[pts.vertices]
    sample = viscous.sample_gradient(q, st, u, u)
    assert np.abs(sample - ref_g[pts.vertices]).max() < 1e-11 * np.abs(ref_g).max()


@pytest.mark.parametrize("basis", ["affine", "full"])
def test_the_body_terms_summed_per_tet_are_the_terms_evaluated_alone(box, basis):
    """The step sums the cubature terms' (elasticity's and viscosity's) stresses and Hessians per tet before one
    pull-back: its energy, gradient and Hessian equal the sum of every body evaluation alone (dense jacobians and
    sparse ones, a full basis). Its energy alone (order 0, the line search's with the
    candidates off) is the same to round-off: the kernels' energy-only mode rounds differently."""
    model = free_body(box, Material(viscosity=50.0), Initial(), 0.01, 0.01)
    W = affine_basis(model.X) if basis == "affine" else full_basis(model.n)
    rs = ReducedSolver(model, W)
    assert (rs.reduced.B_sparse is None) == (basis == "affine")
    assert sum(isinstance(ev, CubatureEvaluation) for ev in rs.body_evaluations) == 2
    rng = np.random.default_rng(13)
    q_bar, q = (rs.reduced.project(_perturbed(model, k, 0.01) - model.X) for k in (14, 15))
    st = rs._begin(ReducedState(q_bar, rng.standard_normal(q_bar.size)), 0.01)
    E, g, H = rs._body_terms(q, st, 2)
    alone = [ev.reduced(q, st, 2) for ev in rs.body_evaluations]
    g_ref = sum(a[1] for a in alone)
    H_ref = sum(a[2] for a in alone if a[2] is not None)
    assert E == sum(a[0] for a in alone)
    assert rs._body_terms(q, st, 0)[0] == pytest.approx(E, rel=1e-14)
    assert np.abs(g - g_ref).max() < 1e-12 * np.abs(g_ref).max()
    assert np.abs(H - H_ref).max() < 1e-12 * np.abs(H_ref).max()


def test_reduced_viscous_kernel_matches_numpy_reference():
    """The reduced solver's viscous kernel: density, stress and the factor of the projected density Hessian
    (L^T L) equal `viscous_density`, `viscous_stress` and `viscous_dpdf` at strains that stretch, compress and
    shear against F_bar (A definite and indefinite, so that the projection acts), and at rest."""
    rng = np.random.default_rng(4)
    F = np.concatenate([np.eye(3)[None], np.eye(3) + 0.3 * rng.standard_normal((40, 3, 3))])
    F_bar = np.concatenate([np.eye(3)[None], np.eye(3) + 0.3 * rng.standard_normal((40, 3, 3))])
    c = 35.0
    density, P, L = RK.viscous_evaluate(F, F_bar, c)
    assert np.abs(density - pv.viscous_density(F, F_bar, c)).max() < 1e-12 * c
    assert np.abs(P - pv.viscous_stress(F, F_bar, c)).max() < 1e-12 * c
    H_ref = pv.viscous_dpdf(F, F_bar, c)
    assert L.shape == (41, RK.VISCOUS_ROWS, 9)
    assert np.abs(L.transpose(0, 2, 1) @ L - H_ref).max() < 1e-12 * np.abs(H_ref).max()
    A = pv.green_strain(F) - pv.green_strain(F_bar)
    definite = np.linalg.eigvalsh(A).min(axis=1) >= 0
    assert definite.any() and not definite.all()  # both sides of the projection
    assert density[0] == 0.0 and not L[0, 6:].any() and L[0, :6].any()  # at rest: no rate, only the damping J^T J
    d0, P0, L0 = RK.viscous_evaluate(F, F_bar, c, RK.ENERGY)
    assert np.array_equal(d0, density) and P0 is None and L0 is None
    assert np.array_equal(RK.viscous_evaluate(F, F_bar, c, RK.STRESS)[1], P)


# ----- physics ------------------------------------------------------------------------------------------------
def _rigid_motion(model: Model, traj) -> tuple[np.ndarray, np.ndarray]:
    """Rotational kinetic energy (F,) [J] and angular momentum about the centre of mass (F, 3) [kg m^2/s]."""
    com = com_series(traj, model.mass)
    vc = np.einsum("n,fnk->fk", model.mass, traj.v) / model.mass.sum()
    r, v = traj.x - com[:, None], traj.v - vc[:, None]
    return (0.5 * np.einsum("n,fnk,fnk->f", model.mass, v, v),
            np.einsum("n,fnk->fk", model.mass, np.cross(r, v)))


def test_a_spinning_body_keeps_its_rotation(box):
    """Against the same run without viscosity (backward Euler itself loses ~14% of the kinetic energy here): a
    strong viscosity (damping ratio 1 of the first mode) changes the rotational kinetic energy and the angular
    momentum by well under 1%, while a mass-proportional damping of the same first-mode ratio would take away
    1 - exp(-2 zeta omega_1 t) > 99.9% of it."""
    ini = Initial(velocity=(0.3, -0.1, 0.2), angular_velocity=(1.0, 4.0, -2.0))
    runs = {}
    for zeta in (None, 1.0):
        model = free_body(box, Material(youngs_modulus=2e4, damping_ratio=zeta), ini, 0.01, 0.4)
        traj, stats = simulate(model, FullSpaceSolver(model, settings=NewtonSettings(tol=1e-9)))
        assert all(s.converged for s in stats)
        runs[zeta] = _rigid_motion(model, traj)
    assert "viscosity" in model.terms and model.viscosity > 0.0
    (ke0, L0), (ke, L) = runs[None], runs[1.0]
    assert np.abs(ke - ke0).max() < 5e-3 * ke0[0]
    assert np.abs(L - L0).max() < 1e-3 * np.linalg.norm(L0[0])
    omega_1 = pv.first_mode(model)[0]
    assert np.exp(-2 * omega_1 * 0.4) < 1e-3


def test_a_squashed_body_rings_down_faster_with_more_viscosity(box):
    remaining = {}
    for zeta in (None, 0.1, 0.3):
        model = free_body(box, Material(youngs_modulus=2e4, damping_ratio=zeta), Initial(squash=(1.1, 0.9, 1.0)),
                          0.002, 0.2)
        traj, stats = simulate(model, FullSpaceSolver(model, settings=NewtonSettings(tol=1e-9)))
        assert all(s.converged for s in stats)
        elastic = np.array([pm.elastic_energy(x, model.tets, model.Dm_inv, model.vol, model.mu_snh, model.lam_snh)
                            for x in traj.x[[0, -1]]])
        rest = pm.elastic_energy(model.X, model.tets, model.Dm_inv, model.vol, model.mu_snh, model.lam_snh)
        energy = 0.5 * np.einsum("n,fnk,fnk->f", model.mass, traj.v[[0, -1]], traj.v[[0, -1]]) + elastic - rest
        remaining[zeta] = energy[1] / energy[0]
    assert remaining[0.3] < 0.1 * remaining[0.1] < 0.1 * remaining[None]


def test_a_sliding_body_keeps_the_coulomb_acceleration(block):
    theta, mu = 30.0, 0.2
    t = np.radians(theta)
    downhill = np.array([np.cos(t), -np.sin(t), 0.0])
    accel = {}
    for zeta in (None, 0.3):
        sc = incline(theta, mu)
        model = build_model(replace(sc, material=replace(sc.material, damping_ratio=zeta)), block)
        traj, _ = simulate(model, FullSpaceSolver(model))
        s = com_series(traj, model.mass) @ downhill
        late = traj.t > 0.2
        accel[zeta] = 2 * np.polyfit(traj.t[late], s[late], 2)[0]
    assert model.has("viscosity")
    exact = G * (np.sin(t) - mu * np.cos(t))
    assert accel[0.3] == pytest.approx(exact, rel=0.03)
    assert accel[0.3] == pytest.approx(accel[None], rel=0.01)


def test_full_basis_reproduces_the_full_space_run_with_viscosity(box):
    model = free_body(box, Material(youngs_modulus=2e4, viscosity=30.0),
                      Initial(squash=(1.1, 0.9, 1.0), angular_velocity=(0.0, 3.0, 1.0)), 0.01, 0.05)
    ref, _ = simulate(model, FullSpaceSolver(model, settings=NewtonSettings(tol=1e-8)))
    solver = ReducedSolver(model, full_basis(model.n), tol=1e-8)
    traj, stats = simulate(model, solver, solver.project(initial_state(model)))
    assert all(s.converged for s in stats)
    assert np.abs(traj.x - ref.x).max() < 1e-9 * model.L
    # and the viscosity mattered: the undamped run differs
    undamped = replace(model, terms=tuple(t for t in model.terms if t != "viscosity"))
    other, _ = simulate(undamped, FullSpaceSolver(undamped, settings=NewtonSettings(tol=1e-8)))
    assert np.abs(other.x - ref.x).max() > 1e-4 * model.L


# ----- damping ratio ------------------------------------------------------------------------------------------
def test_the_resolved_viscosity_gives_the_first_mode_its_damping_ratio(box):
    """The damped generalised eigenproblem (lambda^2 M + lambda eta D_1 + K) phi = 0 (dense, linearised): the
    eigenvalue of the first non-rigid mode has -Re(lambda) / |lambda| = the requested ratio (to the second-order
    coupling of the other modes through the non-proportional damping)."""
    zeta = 0.05
    model = free_body(box, Material(damping_ratio=zeta), Initial(), 0.01, 0.01)
    assert model.damping_ratio == zeta and model.viscosity > 0.0
    K = T.element_blocks(model, pm.element_hessians(model.X, model.tets, model.Dm_inv, model.vol, model.mu_snh,
                                                    model.lam_snh, project=False)).toarray()
    C = VISCOUS.hessian(model, T.StepData(model.X, model.X, 1.0), model.X).toarray()  # eta D_1 (h_eff = 1)
    m = np.repeat(model.mass, 3)
    k = K.shape[0]
    A = np.block([[np.zeros((k, k)), np.eye(k)], [-K / m[:, None], -C / m[:, None]]])
    lam = sla.eigvals(A)
    omega_1 = pv.first_mode(model)[0]
    near = lam[np.argmin(np.abs(np.abs(lam) - omega_1) + (lam.imag <= 0) * 1e30)]
    assert abs(near) == pytest.approx(omega_1, rel=1e-2)
    assert -near.real / abs(near) == pytest.approx(zeta, rel=1e-3)  # measured: 0.04999999
    # proportional: twice the ratio, twice the viscosity
    double = free_body(box, Material(damping_ratio=2 * zeta), Initial(), 0.01, 0.01)
    assert double.viscosity == pytest.approx(2 * model.viscosity, rel=1e-9)


def test_run_stats_record_the_resolved_viscosity(block):
    sc = Scenario(name="stats", mesh=MeshSpec("block", "coarse"), plane=None,
                  material=Material(damping_ratio=0.1), time=TimeSpec(dt=0.01, duration=0.02))
    _, stats = run_scenario(sc)
    model = build_model(sc, block)  # the block's first mode is degenerate (square cross-section): same answer
    assert stats["damping_ratio"] == 0.1
    assert stats["viscosity"] == pytest.approx(model.viscosity, rel=1e-9) and stats["viscosity"] > 0.0
    assert "viscosity" in stats["terms"]
    _, plain = run_scenario(replace(sc, material=Material()))
    assert plain["viscosity"] == 0.0 and plain["damping_ratio"] is None and "viscosity" not in plain["terms"]


# ----- scenario fields ----------------------------------------------------------------------------------------
@pytest.mark.parametrize("material, field, value", [
    ({"viscosity": -1.0}, "material.viscosity", -1.0),
    ({"damping_ratio": -0.05}, "material.damping_ratio", -0.05),
    ({"viscosity": 10.0, "damping_ratio": 0.05}, "material.damping_ratio", 0.05),
    ({"viscosity": "high"}, "material.viscosity", "high"),
])
def test_bad_material_damping_is_refused_naming_field_and_value(material, field, value):
    with pytest.raises(ScenarioError) as err:
        scenario_from_dict({"name": "bad", "material": material})
    assert err.value.field == field and err.value.value == value
    assert field in str(err.value) and repr(value) in str(err.value)


def test_the_viscosity_effect_needs_a_material_damping():
    with pytest.raises(ScenarioError, match="effects.viscosity"):
        scenario_from_dict({"name": "bad", "effects": {"viscosity": True}})


def test_material_damping_round_trips_and_leaves_undamped_hashes_alone():
    plain = scenario_from_dict({"name": "a"})
    assert "viscosity" not in scenario_to_dict(plain)["material"]
    assert "viscosity" not in scenario_to_dict(plain)["effects"]
    for extra in ({"viscosity": 5.0}, {"damping_ratio": 0.02}):
        damped = scenario_from_dict({"name": "a", "material": extra})
        assert scenario_from_dict(scenario_to_dict(damped)) == damped
        assert scenario_hash(damped) != scenario_hash(plain)
    off = scenario_from_dict({"name": "a", "material": {"viscosity": 5.0}, "effects": {"viscosity": False}})
    assert scenario_from_dict(scenario_to_dict(off)) == off
    assert "viscosity" not in build_model(off, _tiny()).terms
    assert "viscosity" not in build_model(scenario_from_dict({"name": "z", "material": {"viscosity": 0.0}}),
                                          _tiny()).terms


def _tiny() -> TetMesh:
    X, tets = structured_box((0.1, 0.1, 0.1), (1, 1, 1), (0.0, 0.0, 0.0))
    return make_mesh(X, tets, "cube")

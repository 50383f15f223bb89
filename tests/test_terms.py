"""Physics terms as objects (solvers.physics.terms): each term's numpy reference is consistent (gradient and
Hessian against finite differences of its energy), their sum equals the full-space warp evaluation, the step hooks
(`begin_step`, `max_step`) give what the solvers used to compute by name, and a term registered from a test with its
backends' evaluations (`solvers.full.terms`, `solvers.licrom.terms`) is picked up by every solver."""

from __future__ import annotations

from dataclasses import replace

import numpy as np
import pytest
import scipy.sparse as sp

from frictionbench.scenarios.model import Contact, Effects, Initial, MeshSpec, Scenario, TimeSpec
from frictionbench.solvers.baselines import affine_basis
from frictionbench.solvers.full import terms as FT
from frictionbench.solvers.full.solver import FullSpaceSolver
from frictionbench.solvers.licrom import terms as LT
from frictionbench.solvers.licrom.reduced import ReducedSolver
from frictionbench.solvers.model import Model, build_model, initial_state
from frictionbench.solvers.newton import feasible_step
from frictionbench.solvers.physics import terms as T
from frictionbench.solvers.physics.contact import lagged_pressure
from frictionbench.solvers.simulate import simulate

from scenes import G, incline

PENALTY = incline(30.0, 0.4, contact=Contact(damping=30.0), effects=Effects(damping=True))
BARRIER = replace(incline(10.0, 0.3), contact=Contact(law="barrier"),
                  initial=Initial(clearance=0.0002, rotation=(0.0, 0.0, -10.0)))


def _scene(sc: Scenario, block, lift: float, bdf2: bool = False) -> tuple[Model, T.StepData, np.ndarray]:
    """A model, a step's constants and a perturbed point x near the plane (contact, damping, friction active);
    `bdf2`: a BDF2 step's constants (x_bar away from x_prev, h_eff = 2/3 h), else backward Euler's."""
    model = build_model(sc, block)
    rng = np.random.default_rng(3)
    h = 0.01
    x_prev = initial_state(model).x + lift * model.plane_normal
    v = 0.1 * rng.standard_normal(x_prev.shape)
    c = model.contact
    fn = lagged_pressure(c.law, x_prev[model.points], v[model.points], model.plane_normal, model.plane_offset,
                         c.stiffness, model.contact_damping, c.barrier_stiffness, c.barrier_distance)
    x = x_prev + 0.01 * h * rng.standard_normal(x_prev.shape) + lift * model.plane_normal
    if not bdf2:
        return model, T.StepData(x_prev + h * v, x_prev, h, fn), x
    x_bar, h_eff = x_prev + 0.02 * h * rng.standard_normal(x_prev.shape), 2.0 / 3.0 * h
    return model, T.StepData(x_bar + h_eff * v, x_prev, h, fn, x_bar=x_bar, h_eff=h_eff), x


@pytest.fixture(params=["penalty", "barrier", "penalty-bdf2"])
def scene(request, block):
    if request.param == "barrier":
        return _scene(BARRIER, block, 0.0)
    return _scene(PENALTY, block, -0.002, bdf2=request.param == "penalty-bdf2")


def test_every_term_of_the_scene_is_active(scene):
    model = scene[0]
    names = [t.name for t in T.terms_of(model)]
    contact = "penalty_contact" if model.contact.law == "penalty" else "barrier_contact"
    expected = ["inertia", "gravity", "elasticity", contact] + (["damping"] if model.has("damping") else [])
    assert names == expected + ["friction"]


def test_term_gradients_and_hessians_match_finite_differences(scene):
    model, step, x = scene
    d = np.random.default_rng(4).standard_normal(x.shape)
    eps = 1e-7
    for term in T.terms_of(model):
        e_p, e_m = term.energy(model, step, x + eps * d), term.energy(model, step, x - eps * d)
        g = term.gradient(model, step, x)
        tol = 1e-6 * np.abs(g * d).sum() + 1e-8 * (abs(e_p) + abs(e_m)) / eps  # truncation + energy round-off
        assert (e_p - e_m) / (2 * eps) == pytest.approx(np.sum(g * d), abs=tol), term.name
        if term.name == "elasticity":
            continue  # its Hessian is projected to PSD per element: not the derivative where Psi is indefinite
        dg = (term.gradient(model, step, x + eps * d) - term.gradient(model, step, x - eps * d)) / (2 * eps)
        Hd = (term.hessian(model, step, x) @ d.ravel()).reshape(-1, 3)
        # the barrier's third derivative is large next to the plane: truncation error up to ~1e-4 of the largest entry
        assert np.abs(dg - Hd).max() <= 1e-3 * (np.abs(Hd).max() + 1e-9), term.name


def test_the_sum_of_the_references_is_the_warp_evaluation(scene):
    model, step, x = scene
    solver = FullSpaceSolver(model)
    solver.begin(step)
    solver.x.assign(x)
    E = T.reference_energy(model, step, x)
    assert solver.energy(solver.x, step.h_eff) == pytest.approx(E, rel=1e-12)
    solver.gradient_hessian(solver.x, step.h_eff)
    g = T.reference_gradient(model, step, x)
    assert np.abs(solver.grad.numpy() - g).max() <= 1e-10 * np.abs(g).max()
    H = T.reference_hessian(model, step, x).toarray()
    assert np.abs(solver.pattern.to_scipy(solver.values.numpy()).toarray() - H).max() <= 1e-10 * np.abs(H).max()


class Push(T.BodyTerm):
    """A test term: a uniform force per unit mass f (3,) [m/s^2], potential -sum_i m_i f . x_i."""

    name = "push"
    f = np.array([2.0, 0.0, 0.0])

    def applies(self, model: Model) -> bool:
        return True

    def energy(self, model, step, x) -> float:
        return float(-model.mass @ (x @ self.f))

    def gradient(self, model, step, x) -> np.ndarray:
        return -model.mass[:, None] * self.f

    def hessian(self, model, step, x) -> sp.csr_matrix:
        return sp.csr_matrix((3 * model.n, 3 * model.n))



class PushLaunch(FT.Launcher):
    """Push on the full-space solver: the gravity kernel with f."""

    def launch(self, x, h, mode, inertia) -> None:
        import warp as wp

        from frictionbench.solvers.full import kernels as K

        s = self.solver
        wp.launch(K.inertia_gravity_kernel, s.model.n, device=s.device, inputs=[
            x, s.x_hat, s.mass, 0.0, wp.vec3d(*self.term.f), s.diag, s.grad, s.values, s.energy_buf, mode])


class PushReduced(LT.BodyEvaluation):
    """Push in the latent coordinates: -f_r . q with f_r = sum_i m_i W_i^T f."""

    def reduced(self, q, st, order):
        f_r = np.einsum("n,nak,a->k", self.rs.model.mass, self.rs.reduced.W, self.term.f)
        return -float(f_r @ q), (-f_r if order >= 1 else None), None

    def sample_gradient(self, q, st, u, u_hat):
        return self.rs.samples.weight[:, None] * -self.term.f


@pytest.mark.parametrize("solver", ["full", "reduced-newton", "reduced-pg"])
def test_a_registered_term_is_picked_up_by_every_solver(block, monkeypatch, solver):
    monkeypatch.setattr(T, "_TERMS", T.all_terms())
    T.register(Push)
    monkeypatch.setitem(FT.LAUNCHERS.classes, Push, PushLaunch)
    monkeypatch.setitem(LT.EVALUATIONS.classes, Push, PushReduced)
    # no elasticity: the projected-gradient scheme at alpha = 1 is unstable for the stiff strain modes
    sc = Scenario(name="pushed_fall", mesh=MeshSpec("block", "coarse"), plane=None,
                  time=TimeSpec(dt=0.01, duration=0.1), effects=Effects(elasticity=False))
    model = build_model(sc, block)
    assert [t.name for t in T.terms_of(model)][-1] == "push"
    if solver == "full":
        stepper, state0 = FullSpaceSolver(model), None
    else:
        scheme = "newton" if solver == "reduced-newton" else "projected_gradient"
        stepper = ReducedSolver(model, affine_basis(model.X), scheme=scheme, alpha=1.0, tol=1e-9, max_iter=5)
        state0 = stepper.project(initial_state(model))
    traj, stats = simulate(model, stepper, state0)
    n = np.arange(traj.n_frames)
    drift = 0.01**2 * (n * (n + 1) / 2)  # backward Euler under a constant acceleration a: a h^2 n (n + 1) / 2
    assert np.abs(traj.x[:, :, 0] - traj.x[0, :, 0] - 2.0 * drift[:, None]).max() < 1e-10
    assert np.abs(traj.x[:, :, 1] - traj.x[0, :, 1] + G * drift[:, None]).max() < 1e-10
    assert all(s.converged for s in stats)


def test_a_term_without_a_backend_evaluation_is_refused_by_name(block, monkeypatch):
    monkeypatch.setattr(T, "_TERMS", T.all_terms())
    T.register(Push)
    model = build_model(PENALTY, block)
    with pytest.raises(ValueError, match=r"\['push'\] have no full-space launcher"):
        FullSpaceSolver(model)
    with pytest.raises(ValueError, match=r"\['push'\] have no reduced evaluation"):
        ReducedSolver(model, affine_basis(model.X))


def test_the_step_hooks_lag_the_pressure_and_cap_the_step(scene):
    """Friction lags the contact law's pressure (`begin_step`); only the barrier law caps a step (`max_step`), by
    the feasible-step rule on the contact points' signed distances; the shared rule takes the smallest cap."""
    model, step, x = scene
    p, n = model.points, model.plane_normal
    v = np.random.default_rng(5).standard_normal((p.size, 3))
    c = model.contact
    terms = T.terms_of(model)
    expected = lagged_pressure(c.law, x[p], v, n, model.plane_offset, c.stiffness, model.contact_damping,
                               c.barrier_stiffness, c.barrier_distance)
    assert np.array_equal(T.lagged_at_start(terms, model, x[p], v), expected)
    assert [t.name for t in terms if t.begin_step(model, x[p], v) is not None] == ["friction"]
    dx = -0.01 * np.ones_like(x[p]) @ np.diag(np.abs(n) + 1.0)  # towards the plane
    capping = T.step_capping(terms)
    alpha = T.max_feasible_step(terms, model, x[p], dx)
    if c.law == "barrier":
        assert [t.name for t in capping] == ["barrier_contact"]
        assert alpha == feasible_step(x[p] @ n - model.plane_offset, dx @ n) < 1.0
    else:
        assert capping == [] and alpha == 1.0

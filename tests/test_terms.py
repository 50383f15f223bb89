"""Physics terms as objects (solvers.physics.terms): each term's numpy reference is consistent (gradient and
Hessian against finite differences of its energy), their sum equals the full-space warp evaluation, the step hooks
(`begin_step`, `max_step`) give what the solvers used to compute by name, and each backend's evaluation is derived
from the term's declaration (`solvers.full.terms.launcher_of`, `solvers.reduced.terms.body_evaluation`,
`point_launch`): toy terms registered from a test by their declaration alone, one with its numpy reference only and
one declared a `VertexTerm`, are picked up by every solver and match their numpy references there."""

from __future__ import annotations

from dataclasses import replace

import numpy as np
import pytest
import scipy.sparse as sp

from frictionbench.scenarios.spec import Contact, Effects, Initial, MeshSpec, Scenario, TimeSpec
from frictionbench.solvers import kernels as K
from frictionbench.solvers.build import build_model, initial_state
from frictionbench.solvers.full import terms as FT
from frictionbench.solvers.full.solver import FullSpaceSolver, NewtonSettings
from frictionbench.solvers.model import Model
from frictionbench.solvers.newton_method import feasible_step
from frictionbench.solvers.physics import terms as T
from frictionbench.solvers.physics.contact import BarrierContact, lagged_pressure
from frictionbench.solvers.physics.material import Elasticity
from frictionbench.solvers.reduced import terms as LT
from frictionbench.solvers.reduced.bases import affine_basis, full_basis
from frictionbench.solvers.reduced.solver import ReducedSolver, ReducedStep
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


def test_the_sum_of_the_references_is_the_warp_evaluation(scene, toys):
    """The built-in terms' kernels and the toy terms (by the inertia-gravity kernel, by their numpy reference on
    the host) sum to the references."""
    model, step, x = scene
    solver = FullSpaceSolver(model)
    assert [type(launcher) for launcher in solver.launchers][-2:] == [FT.ReferenceLauncher, FT.VertexLauncher]
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



@pytest.mark.parametrize("solver", ["full", "reduced-newton", "reduced-pg"])
def test_a_registered_term_is_picked_up_by_every_solver(block, monkeypatch, solver):
    """Push, registered by its class alone (no backend code), runs from its numpy reference in every solver."""
    monkeypatch.setattr(T, "_TERMS", T.all_terms())
    T.register(Push)
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


class Unnamed(Elasticity):
    """Elasticity declared a density term without kernels."""

    name = "unnamed"
    kernels = None


class Renamed(BarrierContact):
    """The barrier law naming its kernel by module and name."""

    name = "renamed"
    kernel = "frictionbench.solvers.kernels:barrier_contact_kernel"


class Unparametrised(BarrierContact):
    """The barrier law whose kernel misses an argument (kappa)."""

    name = "unparametrised"

    def kernel_parameters(self, model: Model) -> dict[str, float]:
        return {"offset": model.plane_offset, "dhat": model.contact.barrier_distance}


def test_each_backend_picks_the_evaluation_of_the_terms_kind(block, monkeypatch):
    """A vertex term in closed form, a density term and a point term by the kernels they name, any other (and a
    density term naming none) from its numpy reference; a kernel named "module:name" is found there; one whose
    arguments the term does not give is refused, naming them."""
    monkeypatch.setattr(T, "_TERMS", T.all_terms())
    T.register(Push)
    model = build_model(replace(PENALTY, material=replace(PENALTY.material, viscosity=20.0)), block)
    full = {launcher.term.name: type(launcher) for launcher in FullSpaceSolver(model).launchers}
    assert full == {"inertia": FT.VertexLauncher, "gravity": FT.VertexLauncher, "elasticity": FT.DensityLauncher,
                    "viscosity": FT.DensityLauncher, "penalty_contact": FT.PointLauncher,
                    "damping": FT.PointLauncher, "friction": FT.PointLauncher, "push": FT.ReferenceLauncher}
    rs = ReducedSolver(model, affine_basis(model.X))
    reduced = {e.term.name: type(e) for e in rs.body_evaluations}
    assert reduced == {"inertia": LT.VertexEvaluation, "gravity": LT.VertexEvaluation,
                       "elasticity": LT.KernelCubatureEvaluation, "viscosity": LT.KernelCubatureEvaluation,
                       "push": LT.ReferenceEvaluation}
    assert all(type(launch) is LT.KernelLaunch for launch in rs.point_evaluations.launches)
    solver = FullSpaceSolver(model)
    assert type(FT.launcher_of(solver, Unnamed())) is FT.ReferenceLauncher
    assert type(LT.body_evaluation(rs, Unnamed())) is LT.ReferenceEvaluation
    barrier = FullSpaceSolver(build_model(BARRIER, block))
    assert FT.launcher_of(barrier, Renamed()).kernel is K.barrier_contact_kernel
    with pytest.raises(ValueError, match=r"unparametrised: kernel .* takes \['kappa'\]"):
        FT.launcher_of(barrier, Unparametrised()).launch(barrier.x, 0.01, 0, True)


class Drag(T.BodyTerm):
    """A test term with only its numpy reference: mass-proportional drag c/(2 h_eff) sum_i m_i |x_i - x_bar_i|^2 [J]
    (c [1/s]) and a uniform push -sum_i m_i f . x_i."""

    name = "drag"
    c, f = 5.0, np.array([2.0, 0.0, -1.0])

    def applies(self, model: Model) -> bool:
        return True

    def energy(self, model, step, x) -> float:
        d = x - step.x_bar
        return float(0.5 * self.c / step.h_eff * model.mass @ np.sum(d * d, axis=1) - model.mass @ (x @ self.f))

    def gradient(self, model, step, x) -> np.ndarray:
        return model.mass[:, None] * (self.c / step.h_eff * (x - step.x_bar) - self.f)

    def hessian(self, model, step, x) -> sp.csr_matrix:
        return sp.diags(np.repeat(self.c / step.h_eff * model.mass, 3)).tocsr()


class DeclaredDrag(T.VertexTerm, Drag):
    """Drag declared a vertex term (y = x_bar, tau^2 = h_eff / c, a = f), with Drag's numpy reference."""

    name = "declared_drag"
    target = "x_bar"

    def tau2(self, model: Model, h: float, inertia: bool) -> float:
        return h / self.c if inertia else np.inf

    def acceleration(self, model: Model) -> np.ndarray:
        return self.f


@pytest.fixture
def toys(monkeypatch):
    """Drag and DeclaredDrag registered by their classes alone."""
    monkeypatch.setattr(T, "_TERMS", T.all_terms())
    T.register(Drag)
    T.register(DeclaredDrag)


def _reduced_step(solver: ReducedSolver, seed: int) -> tuple[ReducedStep, list[np.ndarray]]:
    """A BDF2-like ReducedStep (x_bar away from x^n, h_eff = 2/3 h) at random latent coordinates, and two more q."""
    rng = np.random.default_rng(seed)
    q_prev, q_bar, q_hat, q, q2 = 1e-3 * rng.standard_normal((5, solver.reduced.r))
    return ReducedStep(0.01, 0.01 * 2 / 3, q_prev, q_bar, q_hat, q_prev, None), [q, q2]


def test_the_reference_evaluation_is_the_projected_numpy_reference(block, toys):
    model = build_model(replace(PENALTY, material=replace(PENALTY.material, viscosity=20.0)), block)
    solver = ReducedSolver(model, affine_basis(model.X), scheme="projected_gradient")
    st, (q, q2) = _reduced_step(solver, 6)
    W, X = solver.reduced.W, model.X
    step = T.StepData(X + W @ st.q_hat, X + W @ st.q_prev, st.h, x_bar=X + W @ st.q_bar, h_eff=st.h_eff)
    (generic,) = [e for e in solver.body_evaluations if type(e.term) is Drag]
    assert type(generic) is LT.ReferenceEvaluation
    term, x = generic.term, X + W @ q
    E, g, H = generic.reduced(q, st, 2)
    assert E == pytest.approx(term.energy(model, step, x), rel=1e-14)
    g_ref = np.einsum("nak,na->k", W, term.gradient(model, step, x))
    assert np.abs(g - g_ref).max() <= 1e-13 * np.abs(g_ref).max()
    Wf = W.reshape(-1, W.shape[2])
    H_ref = Wf.T @ term.hessian(model, step, x).toarray() @ Wf
    assert np.abs(H - H_ref).max() <= 1e-13 * np.abs(H_ref).max()
    assert generic.reduced(q, st, 0) == (E, None, None) and generic.reduced(q, st, 1)[2] is None
    u, u_hat = (solver.reduced.decode(p)[solver.samples.vertices] for p in (q, st.q_hat))
    assert np.array_equal(generic.sample_gradient(q, st, u, u_hat),
                          term.gradient(model, step, x)[solver.samples.vertices])
    # every other body term's evaluation (all tets as cubature: exact) is its projected reference too, the declared
    # drag's (a vertex term about x_bar) among them
    assert [type(e) for e in solver.body_evaluations][-2:] == [LT.ReferenceEvaluation, LT.VertexEvaluation]
    for dedicated in solver.body_evaluations:
        ref = LT.ReferenceEvaluation(solver, dedicated.term)
        (E, g, H), (E_ref, g_ref, H_ref) = dedicated.reduced(q, st, 2), ref.reduced(q, st, 2)
        dE, dE_ref = E - dedicated.reduced(q2, st, 0)[0], E_ref - ref.reduced(q2, st, 0)[0]  # gravity: up to a constant
        assert dE == pytest.approx(dE_ref, rel=1e-10), dedicated.term.name
        assert np.abs(g - g_ref).max() <= 1e-11 * np.abs(g_ref).max(), dedicated.term.name
        H, H_ref = (np.zeros_like(H_ref) if H is None else H), H_ref
        assert np.abs(H - H_ref).max() <= 1e-11 * np.abs(H_ref).max() + 1e-300, dedicated.term.name
        sg, sg_ref = dedicated.sample_gradient(q, st, u, u_hat), ref.sample_gradient(q, st, u, u_hat)
        assert np.abs(sg - sg_ref).max() <= 1e-11 * np.abs(sg_ref).max(), dedicated.term.name


@pytest.mark.parametrize("integrator", ["backward-euler", "bdf2"])
@pytest.mark.parametrize("toy", [Drag, DeclaredDrag])
def test_a_declared_term_runs_in_both_solvers(block, monkeypatch, integrator, toy):
    """With the complete basis, a reduced run with a toy term registered by its class alone (Drag: from its numpy
    reference in both solvers; DeclaredDrag: a vertex term) is the full-space run."""
    monkeypatch.setattr(T, "_TERMS", T.all_terms())
    T.register(toy)
    sc = replace(incline(30.0, 0.2), time=TimeSpec(dt=0.01, duration=0.05, integrator=integrator))
    model = build_model(sc, block)
    assert [t.name for t in T.terms_of(model)][-1] == toy.name
    ref, _ = simulate(model, FullSpaceSolver(model, settings=NewtonSettings(tol=1e-8)))
    solver = ReducedSolver(model, full_basis(model.n), tol=1e-8)
    expected = LT.ReferenceEvaluation if toy is Drag else LT.VertexEvaluation
    assert type(solver.body_evaluations[-1]) is expected
    traj, stats = simulate(model, solver, solver.project(initial_state(model)))
    assert all(s.converged for s in stats)
    assert np.abs(traj.x - ref.x).max() < 1e-9 * model.L
    assert np.abs(traj.v - ref.v).max() < 1e-9 * model.L / 0.01


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

"""Where a step evaluates what contact lags (`contact.lag`, solvers.step.ContactLag): the start of the step (the
paper's) or lagged iterations to the step's own end state (`fixed-point`), in both solvers; and the contact damping
given as a damping ratio (`contact.damping_ratio`, resolved per mesh)."""

from __future__ import annotations

from dataclasses import replace

import numpy as np
import pytest

from frictionbench.scenarios.meshes import load_mesh
from frictionbench.scenarios.spec import TimeSpec
from frictionbench.solvers.build import build_model, initial_state
from frictionbench.solvers.full.solver import FullSpaceSolver, _LaggedStep
from frictionbench.solvers.model import State
from frictionbench.solvers.physics.contact import damping_for_ratio
from frictionbench.solvers.reduced.bases import affine_basis
from frictionbench.solvers.reduced.solver import ReducedSolver
from frictionbench.solvers.simulate import simulate
from frictionbench.solvers.step import ContactLag, lagged_contact, solve_lagged

from scenes import incline


def sliding_block(lag: str, dt: float = 0.01, duration: float = 0.3, zeta: float = 1.0):
    """A block released flat on a 20 degree slope with mu 0.2 (it slides), critically damped contact, 5% material
    damping, BDF2."""
    sc = incline(20.0, 0.2, duration=duration)
    return replace(sc, effects=replace(sc.effects, damping=True),
                   material=replace(sc.material, damping_ratio=0.05),
                   contact=replace(sc.contact, damping_ratio=zeta, lag=lag),
                   time=TimeSpec(dt=dt, duration=duration, integrator="bdf2"))


def test_an_unknown_lag_names_the_field() -> None:
    with pytest.raises(ValueError, match="contact.lag = 'implicit'"):
        ContactLag("implicit")


def three_steps(lag: str):
    """The sliding block under backward Euler (its step constants need no history, so a test can rebuild the last
    step) stepped three times at dt 0.01 by the full-space solver: (model, solver, end state, the last step's
    statistics); the end state's `previous` is the state before."""
    sc = replace(sliding_block(lag), time=TimeSpec(dt=0.01, duration=0.3, integrator="backward-euler"))
    model = build_model(sc, load_mesh(sc.mesh))
    solver = FullSpaceSolver(model)
    state = initial_state(model)
    for _ in range(3):
        out = State(state.x, state.v, state.t)
        stats = solver.step(state, out, 0.01)
        state = out
    return model, solver, state, stats


def flight_solves(lag: str) -> int:
    """The solves of one step of the sliding block released 5 cm above the slope (free flight)."""
    sc = sliding_block(lag)
    model = build_model(replace(sc, initial=replace(sc.initial, clearance=0.05)), load_mesh(sc.mesh))
    s0 = initial_state(model)
    return FullSpaceSolver(model).step(s0, State(s0.x, s0.v), 0.01).counters["lag_solves"]


def test_a_fixed_point_step_is_its_own_lag() -> None:
    """After a fixed-point step in contact (its solves replayed with `solve_lagged`: it ends where the solver's step
    does), lagging at its end state under the step's own gate and solving again does not move it (one Newton
    iteration below tolerance); its re-lags after the first each took one Newton iteration (the iterations are the
    first solve's, the re-lags' and at most one closing solve's); a free-flight step solves once."""
    model, solver, state, stats = three_steps("fixed-point")
    assert stats.counters["lag_solves"] >= 2 and stats.counters["lag_unconverged"] == 0
    previous = state.previous
    lag = model.integrator.lagged(previous.x, previous.v, 0.01)
    step = _LaggedStep(solver, lag, previous.x, 0.01)
    res, counters = solve_lagged(step, ContactLag("fixed-point"), previous.x, previous.v)
    assert np.array_equal(res.y, state.x) and counters.items() <= stats.counters.items()
    step.relag(state.x, state.v)
    again = step.newton(state.x)
    assert again.iters == 1 and again.converged
    p = model.points
    fn_end, gate, _ = lagged_contact(solver.terms, model, state.x[p], state.v[p], previous.x[p])
    assert gate.any()
    assert fn_end is not None and fn_end.max() > 0.0
    assert flight_solves("fixed-point") == 1


def test_the_fixed_points_gate_holds_a_point_once_damped() -> None:
    """The damping gate of a fixed-point step is monotone: a point gated at one of its lags stays gated at every
    later one, though it has risen above the plane (the rule that keeps the iteration from cycling)."""
    model, solver, state, _ = three_steps("fixed-point")
    previous = state.previous
    p = model.points
    step = _LaggedStep(solver, model.integrator.lagged(previous.x, previous.v, 0.01), previous.x, 0.01)
    step.relag(previous.x, previous.v)
    phi = state.x[p] @ model.plane_normal - model.plane_offset
    sunk, lifted = state.x.copy(), state.x.copy()
    sunk[p] -= (phi + 0.01)[:, None] * model.plane_normal  # every contact point 1 cm below the plane ...
    lifted[p] -= (phi - 0.01)[:, None] * model.plane_normal  # ... then 1 cm above it
    _, sunk_gate = step.relag(sunk, state.v)
    _, lifted_gate = step.relag(lifted, state.v)
    assert sunk_gate.all() and lifted_gate.all()
    fresh = _LaggedStep(solver, model.integrator.lagged(previous.x, previous.v, 0.01), previous.x, 0.01)
    fresh.relag(previous.x, previous.v)
    _, fresh_gate = fresh.relag(lifted, state.v)  # the same lift as a step's first re-lag: only the start's points
    start_gate = lagged_contact(solver.terms, model, previous.x[p], previous.v[p], previous.x[p])[1]
    assert np.array_equal(fresh_gate, start_gate) and 0 < fresh_gate.sum() < fresh_gate.size


def first_difference(lag: str, solver: str) -> float:
    """pos_rmse_rel between the sliding block's runs at dt 0.01 and 0.005 [fraction of L]."""
    from frictionbench.analysis.metrics import pos_rmse_rel

    trajs = []
    for k in range(2):
        sc = sliding_block(lag, dt=0.01 / 2**k)
        sc = replace(sc, time=replace(sc.time, frame_every=2**k))
        model = build_model(sc, load_mesh(sc.mesh))
        if solver == "full":
            stepper, state0 = FullSpaceSolver(model), initial_state(model)
        else:
            stepper = ReducedSolver(model, affine_basis(model.X), tol=1e-9)
            state0 = stepper.project(initial_state(model))
        trajs.append(simulate(model, stepper, state0)[0])
    return pos_rmse_rel(trajs[0], trajs[1])


@pytest.mark.parametrize("solver", ["full", "reduced"])
@pytest.mark.parametrize("lag", ["corrected", "fixed-point"])
def test_a_relagged_step_removes_the_first_order_lag_error(solver: str, lag: str) -> None:
    """Halving dt moves the start lag's slide by its O(h) lag error (8.0e-3 L measured, full-space), the fixed-point
    lag's by at most a tenth of that (1.7e-4 L measured: experiments/figures.md), and the corrected lag's, its first two
    solves, as little (1.5e-4 L measured)."""
    start, relagged = first_difference("start", solver), first_difference(lag, solver)
    assert start > 2e-3
    assert relagged < start / 10.0


def test_a_corrected_step_is_the_fixed_points_first_two_solves() -> None:
    """In contact a corrected step solves twice and ends where the fixed point's second solve does (its counters say
    so, without `lag_unconverged`: it stops there by design); in free flight it solves once."""
    model, solver, state, stats = three_steps("corrected")
    previous = state.previous
    assert stats.counters["lag_solves"] == 2 and "lag_unconverged" not in stats.counters
    lag = model.integrator.lagged(previous.x, previous.v, 0.01)
    step = _LaggedStep(solver, lag, previous.x, 0.01)
    step.relag(previous.x, previous.v)
    first = step.newton(None)
    step.relag(first.y, step.velocity(first.y))
    second = step.newton(first.y)
    assert np.array_equal(second.y, state.x)
    assert not np.array_equal(first.y, state.x)
    assert flight_solves("corrected") == 1


def test_a_contact_damping_ratio_is_resolved_per_mesh() -> None:
    sc = sliding_block("start", zeta=0.7)
    model = build_model(sc, load_mesh(sc.mesh))
    mass, area = model.mass[model.points], model.area
    kd = model.contact_damping
    assert kd == damping_for_ratio(0.7, model.contact.stiffness, mass, area) > 0.0
    zeta = kd * area / (2.0 * np.sqrt(model.contact.stiffness * area * mass))  # each vertex's oscillator
    assert np.median(zeta) == pytest.approx(0.7, rel=1e-12)
    medium = build_model(replace(sc, mesh=replace(sc.mesh, resolution="medium")),
                         load_mesh(replace(sc.mesh, resolution="medium")))
    assert medium.contact_damping != pytest.approx(kd, rel=1e-3)  # another mesh, another k_d for the same ratio


def test_a_truth_may_lag_contact_to_the_fixed_point(tmp_path) -> None:
    from frictionbench.bench.runner import ladder_variant
    from frictionbench.scenarios.errors import ScenarioError
    from frictionbench.scenarios.suites import truth_spec

    spec = truth_spec({"contact_lag": "fixed-point"})
    sc = sliding_block("start")
    level = ladder_variant(sc, spec.integrator, 2, lag=spec.contact_lag).scenario(sc)
    assert level.contact.lag == "fixed-point" and level.time.dt == pytest.approx(sc.time.dt / 4)
    assert ladder_variant(sc, spec.integrator, 2).scenario(sc).contact.lag == "start"
    with pytest.raises(ScenarioError, match="truth.contact_lag"):
        truth_spec({"contact_lag": "implicit"})


def _contact_impulses(lag: str, steps: int = 4) -> list[tuple[float, float]]:
    """A block skidding onto a 20 degree slope (2 m/s downhill, 0.3 m/s into it, mu 0.3: Coulomb's law saturated
    at every touching point), backward Euler at dt 0.002, critically damped contact: per step from the first in
    contact, the normal and tangential impulse [N s] of the plane on the body, from its momentum change less
    gravity's (the internal forces cancel): M (v^(n+1) - v^n) = h (f_gravity + f_plane)."""
    t = np.radians(20.0)
    n, down = np.array([np.sin(t), np.cos(t), 0.0]), np.array([np.cos(t), -np.sin(t), 0.0])
    sc = incline(20.0, 0.3, duration=0.1)
    sc = replace(sc, initial=replace(sc.initial, clearance=5e-4, velocity=tuple(2.0 * down - 0.3 * n)),
                 contact=replace(sc.contact, damping_ratio=1.0, lag=lag),
                 time=TimeSpec(dt=0.002, duration=0.1, integrator="backward-euler"))
    model = build_model(sc, load_mesh(sc.mesh))
    solver = FullSpaceSolver(model)
    state, out = initial_state(model), []
    for _ in range(50):
        new = State(state.x, state.v, state.t)
        solver.step(state, new, 0.002)
        J = model.mass @ (new.v - state.v) - 0.002 * model.mass.sum() * model.gravity
        state = new
        if J @ n > 1e-9 or out:
            out.append((float(J @ n), float(np.linalg.norm(J - (J @ n) * n))))
        if len(out) == steps:
            return out
    raise AssertionError("the block never touched the plane")


@pytest.mark.parametrize("lag", ["start", "corrected", "fixed-point"])
def test_friction_takes_the_pressure_the_step_applies_only_when_relagged(lag: str) -> None:
    """What stalls the damped truth ladders (experiments/figures.md, "Why the damped ladders stall"): the start lag takes
    friction's normal pressure at the step's start, so in the step where contact begins friction pushes with no
    pressure while the implicit contact applies the end's, and as the pressure falls, friction pushes with the
    larger pressure of the start: its impulse is not mu times the normal impulse (0, 0.22, 1.5, 1.8 times here). At
    the fixed point it is, in every step of the skid (every point slips, Coulomb's law is saturated), and after one
    correction within 1.3% (1.0, 0.999, 1.001, 1.013 measured)."""
    impulses = _contact_impulses(lag)
    ratios = [jt / (0.3 * jn) for jn, jt in impulses]
    if lag == "start":  # no friction as contact begins, then more than Coulomb allows as the pressure falls
        assert ratios[0] < 0.05 and max(ratios) > 1.3, ratios
    else:
        assert all(0.95 < r < 1.05 for r in ratios), ratios

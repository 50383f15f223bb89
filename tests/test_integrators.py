"""Time integrators (solvers.integrators): backward Euler and BDF2 against the closed form of free fall in every
solver, their observed orders of convergence on a smooth contact-free motion, BDF2 through a retried step and at
varying step sizes, and the registry the scenario loader validates `time.integrator` against."""

from __future__ import annotations

import subprocess
import sys
from dataclasses import replace
from itertools import pairwise

import numpy as np
import pytest

from frictionbench.scenarios.errors import ScenarioError
from frictionbench.scenarios.load import scenario_from_dict
from frictionbench.scenarios.spec import Effects, Initial, Material, MeshSpec, Scenario, TimeSpec, integrator_names
from frictionbench.solvers.build import build_model, initial_state
from frictionbench.solvers.full.solver import FullSpaceSolver, NewtonSettings
from frictionbench.solvers.integrators import BDF2, INTEGRATORS, BackwardEuler, get_integrator
from frictionbench.solvers.model import State
from frictionbench.solvers.reduced.bases import affine_basis
from frictionbench.solvers.reduced.solver import ReducedSolver
from frictionbench.solvers.simulate import simulate

from scenes import EXPERIMENTS, G


def free_fall_drop(integrator: str, n: np.ndarray) -> np.ndarray:
    """The fall (in units of g h^2) after n steps of h from rest under a constant acceleration g, exactly as the
    integrator computes it (its discrete solution, not the continuous g t^2 / 2).

    Backward Euler: v^k = k h g, x^n = h sum_k v^k, so n (n + 1) / 2. BDF2 started by one backward-Euler step: the
    velocity recurrence v^{k+1} - v^k = (v^k - v^{k-1}) / 3 + 2/3 h g starts at v^1 - v^0 = h g, its fixed point, so
    v^k = k h g again; the increments e_k = x^k - x^{k-1} then follow e_{k+1} = e_k / 3 + 2/3 h v^{k+1} from
    e_1 = h^2 g, whose solution is e_k = h^2 g (k - 1/2 + 3^{1-k} / 2), and summing, n^2 / 2 + 3/4 (1 - 3^-n).
    """
    if integrator == "bdf2":
        return n**2 / 2 + 0.75 * (1.0 - 3.0 ** -n.astype(float))
    return n * (n + 1) / 2


@pytest.mark.parametrize("integrator", ["backward-euler", "bdf2"])
@pytest.mark.parametrize("solver", ["full", "reduced-newton", "reduced-pg"])
def test_free_fall_matches_the_integrators_closed_form(block, solver, integrator):
    h, v0 = 0.01, np.array([0.3, 1.0, -0.2])
    # without elasticity for the projected-gradient scheme: at alpha = 1 it is unstable for the stiff strain modes
    # (a free fall excites none, but round-off would grow); alpha = 1 solves inertia and gravity in one iteration
    sc = Scenario(name="free_fall", mesh=MeshSpec("block", "coarse"), plane=None,
                  initial=Initial(clearance=None, velocity=tuple(v0)),
                  time=TimeSpec(dt=h, duration=0.2, integrator=integrator),
                  effects=Effects(elasticity=solver != "reduced-pg"))
    model = build_model(sc, block)
    if solver == "full":
        stepper, state0 = FullSpaceSolver(model, settings=NewtonSettings(tol=1e-9)), None
    else:
        scheme = "newton" if solver == "reduced-newton" else "projected_gradient"
        stepper = ReducedSolver(model, affine_basis(model.X), scheme=scheme, alpha=1.0, tol=1e-9, max_iter=5)
        state0 = stepper.project(initial_state(model))
    traj, stats = simulate(model, stepper, state0)
    assert all(s.converged for s in stats)
    n = np.arange(traj.n_frames)
    drift = traj.x - traj.x[0] - (n * h)[:, None, None] * v0
    expected = -G * h**2 * free_fall_drop(integrator, n)
    assert np.abs(drift[:, :, 1] - expected[:, None]).max() < 1e-12
    assert np.abs(drift[:, :, [0, 2]]).max() < 1e-12
    assert np.abs(traj.v[-1] - (v0 - G * n[-1] * h * np.array([0.0, 1.0, 0.0]))).max() < 1e-10


def spinning_block(integrator: str, dt: float, duration: float = 0.2) -> Scenario:
    """A free elastic block (no gravity, no ground) spinning about a tilted axis: smooth, contact-free motion whose
    time error (the rotation's) dominates its elastic vibrations (stiff material, slow spin)."""
    return Scenario(name="spin", mesh=MeshSpec("block", "coarse"), plane=None, gravity=(0.0, 0.0, 0.0),
                    material=Material(density=1000.0, youngs_modulus=1e7, poisson_ratio=0.3),
                    initial=Initial(clearance=None, angular_velocity=(0.0, 5.0, 2.5)),
                    time=TimeSpec(dt=dt, duration=duration, frame_every=int(round(duration / dt)),
                                  integrator=integrator))


def observed_orders(finals: list[np.ndarray]) -> np.ndarray:
    """log2 of the ratios of successive differences between end states at dt, dt/2, dt/4, ... (RMS over vertices)."""
    d = np.array([np.sqrt(np.mean(np.sum((a - b) ** 2, axis=1))) for a, b in pairwise(finals)])
    return np.log2(d[:-1] / d[1:])


@pytest.mark.parametrize("integrator", ["backward-euler", "bdf2"])
def test_bdf2_converges_at_second_order_where_backward_euler_is_first_order(block, integrator):
    finals = []
    for dt in (0.02, 0.01, 0.005, 0.0025):
        model = build_model(spinning_block(integrator, dt), block)
        traj, stats = simulate(model, FullSpaceSolver(model, settings=NewtonSettings(tol=1e-9)))
        assert all(s.converged for s in stats) and traj.t[-1] == pytest.approx(0.2)
        finals.append(traj.x[-1])
    orders = observed_orders(finals)
    if integrator == "bdf2":
        assert orders.min() >= 1.7
    else:
        assert 0.7 <= orders.min() and orders.max() <= 1.3


@pytest.mark.parametrize("solver", ["full", "reduced"])
def test_a_retried_bdf2_step_restarts_from_backward_euler_and_keeps_the_history_at_its_step(block, solver):
    """Every full-size step fails once and is redone as two half steps: the run's first half step has no history
    (a step that does not start one step dt after its predecessor is backward Euler), and from then on every half
    step finds its predecessor one half step back and is BDF2. So the run is BDF2 at half the step, exactly."""
    sc = spinning_block("bdf2", 0.01, duration=0.1)

    def run(sc: Scenario, fail_full_steps: bool = False):
        model = build_model(sc, block)
        if solver == "full":
            stepper, state0 = FullSpaceSolver(model, settings=NewtonSettings(tol=1e-10)), None
        else:
            stepper = ReducedSolver(model, affine_basis(model.X), tol=1e-10)
            state0 = stepper.project(initial_state(model))
        if fail_full_steps:
            step = stepper.step
            stepper.step = lambda s_in, s_out, dt: replace(step(s_in, s_out, dt), converged=dt < 0.0099)
        return simulate(model, stepper, state0)

    traj, stats = run(sc, fail_full_steps=True)
    assert [s.retries for s in stats] == [1] * 10 and all(s.converged for s in stats)
    half = run(replace(sc, time=replace(sc.time, dt=0.005, frame_every=20)))[0]
    assert np.abs(traj.x[-1] - half.x[-1]).max() < 1e-12
    half_be = run(replace(sc, time=replace(sc.time, dt=0.005, frame_every=20, integrator="backward-euler")))[0]
    assert np.abs(traj.x[-1] - half_be.x[-1]).max() > 1e-5  # and that is not backward Euler's answer


def test_the_bdf2_variant_set_runs_the_reference_solver_under_bdf2():
    from frictionbench.bench.cli import parse_variants
    from frictionbench.bench.runner import REFERENCE

    (variant,) = parse_variants("bdf2")
    sc = variant.scenario(Scenario(name="x", mesh=MeshSpec("block", "coarse")))
    assert variant.solver == REFERENCE and sc.time.integrator == "bdf2" and sc.time.dt == TimeSpec().dt
    assert variant in parse_variants("full-sweep")


def variable_step_final(block, n_pairs: int, restart: bool, duration: float = 0.2) -> np.ndarray:
    """The spinning block's end positions (n, 3) [m] after n_pairs pairs of steps (h, 1.5 h) filling `duration`
    (step ratios alternating 1.5 and 1/1.5) under BDF2, restarting at every change of step size or not."""
    h = duration / (2.5 * n_pairs)
    model = replace(build_model(spinning_block("bdf2", h, duration), block),
                    integrator=BDF2(restart_on_step_change=restart))
    solver = FullSpaceSolver(model, settings=NewtonSettings(tol=1e-9))
    state = initial_state(model)
    for dt in [h, 1.5 * h] * n_pairs:
        out = State(state.x, state.v, state.t)
        assert solver.step(state, out, dt).converged
        state = out
    assert state.t == pytest.approx(duration)
    return state.x


@pytest.mark.parametrize("restart", [False, True])
def test_variable_step_bdf2_converges_at_second_order(block, restart):
    """Alternating step ratios 1.5 and 1/1.5, refined by halving: the variable-step coefficients keep BDF2 second
    order; restarting from backward Euler at every change of step size (what a run does after a retry) is first
    order, so the variable-step formulas are the ones at work."""
    orders = observed_orders([variable_step_final(block, n, restart) for n in (4, 8, 16, 32)])
    if restart:
        assert orders.max() <= 1.3
    else:
        assert orders.min() >= 1.7


@pytest.mark.parametrize("w", [1.5, 1.0 / 1.5, 0.5, 3.0])
def test_the_variable_step_coefficients_are_exact_on_quadratics(w):
    """Second-order consistency at any step ratio: y(t) = a + b t + c t^2 (and its derivative) satisfies
    y^{n+1} = y_bar + h_eff y'(t_{n+1}) exactly, with y_bar from y^n, y^{n-1} and v_bar from y'^n, y'^{n-1}."""
    a, b, c, h = 0.3, -1.2, 2.5, 0.01
    t_prev, t = 0.1, 0.1 + h / w
    y, dy = (lambda s: a + b * s + c * s * s), (lambda s: b + 2.0 * c * s)
    lag = BDF2(restart_on_step_change=False).lagged(np.array([y(t)]), np.array([dy(t)]), h,
                                                    (np.array([y(t_prev)]), np.array([dy(t_prev)]), t - t_prev))
    assert lag.velocity(np.array([y(t + h)]))[0] == pytest.approx(dy(t + h), rel=1e-9)
    assert lag.y_tilde[0] + lag.h_eff ** 2 * 2.0 * c == pytest.approx(y(t + h), rel=1e-12)  # v' = y'' = 2c


def test_at_a_constant_step_bdf2_computes_the_constant_step_formulas_bit_for_bit():
    rng = np.random.default_rng(0)
    y, v, y_prev, v_prev = rng.normal(size=(4, 10, 3))
    h = 0.01
    h_prev = (0.03 - 0.02)  # a step recomputed from summed times: h up to round-off
    assert h_prev != h
    lag = BDF2().lagged(y, v, h, (y_prev, v_prev, h_prev))
    assert np.array_equal(lag.y_bar, (4.0 * y - y_prev) / 3.0) and np.array_equal(lag.v_bar, (4.0 * v - v_prev) / 3.0)
    assert lag.h_eff == 2.0 / 3.0 * h
    first = BDF2().lagged(y, v, h)  # no history: backward Euler
    assert first.y_bar is y and first.v_bar is v and first.h_eff == h
    assert BackwardEuler().lagged(y, v, h, (y_prev, v_prev, h)).y_bar is y


def test_a_run_restarts_bdf2_after_a_change_of_step_size_unless_told_otherwise():
    prev = State(np.zeros((1, 3)), np.zeros((1, 3)), 0.0)
    state = State(np.ones((1, 3)), np.ones((1, 3)), 0.01, previous=prev)
    assert BDF2().previous(state, 0.01) is prev and BDF2().previous(state, 0.005) is None
    assert BDF2(restart_on_step_change=False).previous(state, 0.005) is prev
    assert BackwardEuler().previous(state, 0.01) is None  # no history needed


def test_every_integrator_is_registered_by_name_with_its_order_and_history(block):
    assert integrator_names() == tuple(INTEGRATORS) == ("backward-euler", "bdf2")
    assert [(c.order, c.history) for c in INTEGRATORS.values()] == [(1, 0), (2, 1)]
    assert all(get_integrator(name).name == name for name in INTEGRATORS)
    sc = scenario_from_dict({"name": "x", "mesh": {"name": "block", "resolution": "coarse"},
                             "time": {"integrator": "bdf2"}})
    assert build_model(sc, block).integrator == BDF2()


def test_an_unknown_integrator_is_refused_naming_the_field_the_value_and_the_known_names():
    with pytest.raises(ScenarioError) as err:
        scenario_from_dict({"name": "x", "time": {"integrator": "rk4"}})
    assert "time.integrator" in str(err.value) and "'rk4'" in str(err.value) and "'bdf2'" in str(err.value)
    with pytest.raises(ValueError, match=r"time.integrator = 'rk4': expected one of \['backward-euler', 'bdf2'\]"):
        get_integrator("rk4")


def test_the_scenario_loader_knows_the_integrators_in_a_fresh_interpreter_without_importing_solvers():
    """The bottom layer declares the built-in names (`BUILTIN_INTEGRATORS`): a program that imports the loader alone
    validates `time.integrator` against them, and no solver module is imported on the way."""
    code = ("import frictionbench.scenarios.load as L\n"
            "print(L.scenario_from_dict({'name': 'x', 'time': {'integrator': 'bdf2'}}).time.integrator)\n"
            "try:\n    L.scenario_from_dict({'name': 'x', 'time': {'integrator': 'rk4'}})\n"
            "except L.ScenarioError as e:\n    print(e)\n"
            "import sys\nprint(sorted(m for m in sys.modules if m.startswith('frictionbench.solvers')))")
    done = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, check=True)
    assert done.stdout.splitlines()[0] == "bdf2"
    assert "time.integrator" in done.stdout and "'rk4'" in done.stdout
    assert done.stdout.splitlines()[-1] == "[]"


def test_the_declared_integrator_names_are_the_integrator_classes():
    from frictionbench.scenarios.spec import BUILTIN_INTEGRATORS

    assert tuple(INTEGRATORS) == BUILTIN_INTEGRATORS


def test_sets_that_share_variants_run_each_once_and_a_name_defined_twice_is_refused(tmp_path):
    from dataclasses import asdict

    import tomli_w

    from frictionbench.bench.cli import parse_variants
    from frictionbench.bench.matrix import set_names

    fast, size = (str(EXPERIMENTS / f"{name}.toml") for name in ("pod-fast", "pod-cubature-size"))
    fast_v, size_v = parse_variants(None, matrices=[fast]), parse_variants(None, matrices=[size])
    both = parse_variants(None, matrices=[fast, size])
    names = [v.label for v in both]
    assert len(names) == len(set(names)) == len({v.label for v in fast_v} | {v.label for v in size_v})
    assert len(names) < len(fast_v) + len(size_v)
    sweep = parse_variants("full-sweep")  # BDF2 is in both
    assert sorted(parse_variants("bdf2,full-sweep"), key=sweep.index) == sweep
    assert len(parse_variants(",".join(set_names())))  # every shipped set together: shared runs, no clash
    from frictionbench.solvers.registry import get_solver

    studied = get_solver(size_v[0].solver).experimental  # set in their own table (bench.matrix)
    params = size_v[0].params | {"tol": 1e-4}
    clash = asdict(size_v[0]) | {"params": {k: v for k, v in params.items() if k not in studied},
                                 "experimental": {k: v for k, v in params.items() if k in studied}}
    entry = {k: v for k, v in clash.items() if k in ("solver", "label", "params", "experimental", "overrides",
                                                      "dt_scale", "model", "training") and v != {}}
    (tmp_path / "clash.toml").write_text(tomli_w.dumps({"variant": [entry]}))
    with pytest.raises(ScenarioError, match=f"clash.*{size_v[0].label}"):
        parse_variants(None, matrices=[size, str(tmp_path / "clash.toml")])
    default = parse_variants(None)  # LiCROM's and POD's `r20` are two variants: a row's identity has its solver
    assert {(v.solver, v.label) for v in default} >= {("licrom", "r20"), ("pod", "r20")}
    ladder = parse_variants("licrom-affine", matrices=[str(EXPERIMENTS / "licrom-ladder.toml")])
    (affine,) = [v for v in ladder if v.label == "affine-r24"]  # in both, on a curve in the second
    assert affine.tags == {"curve": "affine-r24", "curve_level": 0}

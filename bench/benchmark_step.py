"""Benchmark of a full-space step in contact, its time broken down, with the linear solvers side by side, and
the reduced (LiCROM, Newton) step beside it.

    python -m frictionbench.bench.benchmark_step --out out/bench_step.json
    python -m frictionbench.bench.benchmark_step --cases hard/E1e9 --steps 3 --configs superlu:1 pardiso:1
    python -m frictionbench.bench.benchmark_step --cases paper/cheese_p1_mu0.5 --configs pardiso:1
    python -m frictionbench.bench.benchmark_step --cases quick/p1_mu0.5 --configs pardiso:1 --truth 2 \
        --reduced

With `--truth K [K ...]`, each case also steps at its suite's truth-ladder settings at level K (`[truth]`: its
integrator, contact lag and Newton tolerance, dt / 2^K, `bench.runner.ladder_variant`) from the same mid-contact
state, the first configuration's linear solver and threads, over the same simulated time (`--steps` x 2^K steps):
iterations, contact lag solves (`lag_solves`: a fixed-point lag's solves) and ms per step and per simulated second
beside the reference settings', so that the truth's cost per step is measured where the main job spends it.

Each case (a suite member) is advanced with the default solver until a contact point first penetrates the plane,
then `--settle` steps more: the mid-contact state. From it every configuration (`linear:threads`: the linear
solver, and the thread budget of MKL and of the element assembly, entered with `threadpool_limits`) steps the same
`--steps` steps after an untimed warm-up step, one configuration after the other in the same run. Per step it
reports the wall time and where it went: assembly (gradient and Hessian kernels, `gradient_hessian`, and the
chord test's gradient alone, `gradient`),
factorisation and solve (the factoriser's calls), line search (energy evaluations), other (the rest: copies,
residuals); Newton iterations per step; and the end state's distance to the first configuration's. `superlu:1` is
the solver's original path (SuperLU with a fresh ordering per iteration, one-thread assembly).

The reduced step (`--reduced`, one thread): a basis of `--r` columns, the 12 affine fields and POD modes of the
full-space frames that led to the mid-contact state (`solvers.reduced.bases.pod_basis`: no network to train, the
same r as the trained LiCROM variants), and `--cubature` optimised cubature tets on those frames; the projected
mid-contact state steps `--reduced-steps` steps after a warm-up step in each reduced configuration, `all-points`
(the point terms at every contact sample point), `candidates` (at the candidate points only,
`ReducedSolver._candidates`) and `step-hessian` (candidates, and the body terms' Hessian evaluated once a step:
`hessian_refresh = "step"`), the configurations interleaved step by step and each step the fastest of
`--repeats` runs from the same state (a step is deterministic), so that a shared machine's load moves the ratio
less. Parts, exclusive (a part's time leaves out the timed parts called inside it):
body (the body terms: the cubature tets' elasticity and viscosity, energy, stress and Hessian pulled back to
the latent coordinates, and inertia and gravity), points (contact, damping and friction at the sample points),
reduction (the rest of `ReducedSolver.evaluate`, the second-order evaluation that `candidates` runs in the line
search too: the products with the basis), linear solve (r x r Cholesky), line search (the rest of the energy
evaluations: `all-points` evaluates them to order 0), basis (the products with the whole basis W: the end state
X + W q, W qdot, and the step norms |W dq|_inf that no bound decides) and other; the candidate
points per evaluation; speedup against the first full-space configuration and against `all-points`; the end
state's distance to the `all-points` run's. Compare times as ratios within one run: the machine may be shared.
"""

from __future__ import annotations

import argparse
import time
from collections import defaultdict
from collections.abc import Callable

import numpy as np
from threadpoolctl import threadpool_limits

from frictionbench.solvers.reduced.bases import pod_basis, project
from frictionbench.solvers.reduced.cubature import optimized_cubature
from frictionbench.solvers.reduced.solver import ReducedSolver

from frictionbench.analysis.table import provenance
from frictionbench.bench.cli import resolve_scenario
from frictionbench.scenarios.atomic import write_json_atomic
from frictionbench.scenarios.errors import ScenarioError
from frictionbench.scenarios.meshes import load_mesh
from frictionbench.scenarios.spec import Scenario
from frictionbench.solvers.build import build_model, initial_state
from frictionbench.solvers.full.solver import FullSpaceSolver, NewtonSettings
from frictionbench.solvers.model import Model, State

CASES = ["paper/cheese_p1_mu0.5", "paper/sphere_p1_mu0.5", "hard/E1e9"]
CONFIGS = ["superlu:1", "pardiso:1", "pardiso:2"]
PARTS = ("assembly", "factorisation", "solve", "line_search")
REDUCED = ["all-points", "candidates", "step-hessian"]
REDUCED_PARTS = ("body", "points", "reduction", "linear_solve", "line_search", "basis")


class _Clock:
    """Exclusive wall time per part [s] (`totals`) of wrapped methods: a call's time less that of the wrapped calls
    made inside it."""

    def __init__(self) -> None:
        self.totals: dict[str, float] = defaultdict(float)
        self._inner: list[float] = []  # per open call, the time of the wrapped calls inside it so far

    def wrap(self, obj: object, method: str, part: str) -> None:
        """Wrap obj.method (on the instance) so that its exclusive wall time adds to totals[part]."""
        inner: Callable = getattr(obj, method)

        def wrapper(*args, **kwargs):
            self._inner.append(0.0)
            t0 = time.perf_counter()
            try:
                return inner(*args, **kwargs)
            finally:
                elapsed = time.perf_counter() - t0
                self.totals[part] += elapsed - self._inner.pop()
                if self._inner:
                    self._inner[-1] += elapsed

        setattr(obj, method, wrapper)


def in_contact(model: Model, x: np.ndarray) -> bool:
    """Whether a contact point of `model` lies below its plane at positions x (n, 3)."""
    return model.plane_normal is not None and bool(
        (x[model.points] @ model.plane_normal < model.plane_offset).any())


def mid_contact_state(model: Model, settle: int, max_steps: int = 1000) -> tuple[State, int, np.ndarray]:
    """The state `settle` steps after the first step that ends in contact (default solver), its step index, and
    the displacements x - X of every frame up to it (k + 1, n, 3) [m]."""
    solver = FullSpaceSolver(model)
    state, k, touched = initial_state(model), 0, None
    dt = model.scenario.time.dt
    frames = [state.x - model.X]
    while touched is None or k < touched + settle:
        out = State(state.x, state.v, state.t)
        solver.step(state, out, dt)
        state, k = out, k + 1
        frames.append(state.x - model.X)
        if touched is None and in_contact(model, state.x):
            touched = k
        if k >= max_steps:
            raise RuntimeError(f"{model.scenario.name}: no contact within {max_steps} steps")
    return state, k, np.asarray(frames)


def _stepped(solver: FullSpaceSolver | ReducedSolver, state: State, dt: float, steps: int,
             counters: dict[str, int] | None = None) -> tuple[State, list[float], list[int]]:
    """Advance `state` by `steps` steps of `solver` (dt [s]); the end state, each step's wall time [s] and Newton
    iterations; the steps' counters (`StepStats.counters`) are summed into `counters` where given."""
    walls, iters = [], []
    for _ in range(steps):
        out = State(state.x, state.v, state.t)
        st = solver.step(state, out, dt)
        walls.append(st.wall_s)
        iters.append(st.iterations)
        if counters is not None:
            for name, count in st.counters.items():
                counters[name] = counters.get(name, 0) + count
        state = out
    return state, walls, iters


def run_config(model: Model, state: State, linear: str, threads: int, steps: int, params: dict | None = None
               ) -> dict:
    """Step `steps` steps from `state` with one configuration (`params`: further NewtonSettings fields, e.g. a
    truth ladder's tol); per-step means [ms] of each part, iterations."""
    dt = model.scenario.time.dt
    with threadpool_limits(threads):
        solver = FullSpaceSolver(model, settings=NewtonSettings(linear=linear, **(params or {})))
        solver.step(state, State(state.x, state.v, state.t), dt)  # warm-up (kernel loading, PARDISO analysis)
        clock = _Clock()
        totals = clock.totals
        clock.wrap(solver, "gradient_hessian", "assembly")
        clock.wrap(solver, "gradient", "assembly")  # the chord test's gradient alone (`NewtonSettings.chord`)
        clock.wrap(solver, "energy", "line_search")
        if linear != "cg":
            clock.wrap(solver.factoriser, "factorize", "factorisation")
            clock.wrap(solver.factoriser, "solve", "solve")
        counters: dict[str, int] = {}
        state, walls, iters = _stepped(solver, state, dt, steps, counters)
    ms = {f"{p}_ms": 1e3 * totals[p] / steps for p in PARTS}
    step_ms = 1e3 * float(np.mean(walls))
    return {"linear": linear, "linear_solver": solver.info["linear_solver"], "threads": threads,
            "dt": dt, "integrator": model.scenario.time.integrator, "contact_lag": model.scenario.contact.lag,
            "lag_solves_per_step": counters.get("lag_solves", steps) / steps,
            "wall_s_per_sim_s": float(np.sum(walls)) / (steps * dt),
            "assembly_threads": solver.info["assembly_threads"], "step_ms": step_ms,
            "factor_nnz": getattr(solver.factoriser, "factor_nnz", None) if linear != "cg" else None,
            "step_ms_per_step": [1e3 * w for w in walls], "newton_iters": iters,
            "iter_ms": 1e3 * float(np.sum(walls)) / max(1, sum(iters)), **ms,
            "other_ms": step_ms - sum(ms.values()), "x_end": state.x}


def reduced_setup(model: Model, frames: np.ndarray, r: int, cubature: int) -> tuple[np.ndarray, tuple]:
    """The benchmark's basis W (n, 3, r): the affine fields and r - 12 POD modes of the displacement frames
    (F, n, 3) [m], mass-orthonormal; and `cubature` optimised cubature tets on the frames' latent coordinates."""
    W = pod_basis(frames, r, model.mass, affine_X=model.X)
    return W, optimized_cubature(model, W, project(W, frames, model.mass), cubature)


class _ReducedRun:
    """One reduced configuration (`mode`, one of REDUCED) stepping from the projected `state` with its parts timed
    (module doc): the fastest of `repeats` runs of each step from the same state (a step is deterministic) is kept,
    its wall time and parts."""

    def __init__(self, model: Model, state: State, W: np.ndarray, cub: tuple, mode: str) -> None:
        if mode not in REDUCED:
            raise ValueError(f"reduced configuration {mode!r}: expected one of {REDUCED}")
        self.mode, self.dt = mode, model.scenario.time.dt
        self.solver = solver = ReducedSolver(model, W, cub, contact_candidates=mode != "all-points",
                                             hessian_refresh="step" if mode == "step-hessian" else "iteration")
        self.state = solver.project(state)
        solver.step(self.state, State(self.state.x, self.state.v, self.state.t), self.dt)  # warm-up (kernels)
        self.clock, self.counts = _Clock(), []
        for obj, method, part in ((solver, "_body_terms", "body"), (solver, "_point_terms", "points"),
                                  (solver, "evaluate", "reduction"), (solver, "newton_solve", "linear_solve"),
                                  (solver, "energy", "line_search"), (solver, "_velocity_norm", "basis"),
                                  (solver, "decode", "basis")):
            self.clock.wrap(obj, method, part)
        candidates = solver._candidates

        def counted(q: np.ndarray, st: object) -> np.ndarray | None:
            ids = candidates(q, st)
            self.counts.append(solver.reduced.points.size if ids is None else ids.size)
            return ids

        solver._candidates = counted
        self.walls: list[float] = []
        self.iters: list[int] = []
        self.parts = dict.fromkeys(REDUCED_PARTS, 0.0)

    def step(self, repeats: int) -> None:
        """One step, run `repeats` times from the same state; the fastest run's wall time [s] and parts kept."""
        best = None
        for _ in range(repeats):
            before = dict(self.clock.totals)
            out = State(self.state.x, self.state.v, self.state.t)
            st = self.solver.step(self.state, out, self.dt)
            if best is None or st.wall_s < best[0].wall_s:
                best = st, out, {p: self.clock.totals[p] - before.get(p, 0.0) for p in REDUCED_PARTS}
        st, self.state, parts = best
        self.walls.append(st.wall_s)
        self.iters.append(st.iterations)
        for p in REDUCED_PARTS:
            self.parts[p] += parts[p]

    def record(self) -> dict:
        """Per-step means [ms] of each part, candidates per evaluation, the end state."""
        steps, rm = len(self.walls), self.solver.reduced
        ms = {f"{p}_ms": 1e3 * self.parts[p] / steps for p in REDUCED_PARTS}
        step_ms = 1e3 * float(np.mean(self.walls))
        return {"reduced": self.mode, "r": rm.r, "cubature_tets": int(rm.cub_ids.size), "points": int(rm.points.size),
                "candidates_mean": float(np.mean(self.counts)), "candidates_max": int(np.max(self.counts)),
                "step_ms": step_ms, "step_ms_per_step": [1e3 * w for w in self.walls], "newton_iters": self.iters,
                "iter_ms": 1e3 * float(np.sum(self.walls)) / max(1, sum(self.iters)), **ms,
                "other_ms": step_ms - sum(ms.values()), "x_end": self.state.x}


def run_reduced(model: Model, state: State, W: np.ndarray, cub: tuple, modes: list[str], steps: int,
                repeats: int = 3) -> list[dict]:
    """Step `steps` reduced steps from `state` (projected) in each configuration of `modes` (REDUCED), one
    thread, the configurations interleaved step by step so that the machine's load falls on all alike, each step
    the fastest of `repeats` runs (`_ReducedRun`); one record per configuration."""
    with threadpool_limits(1):
        runs = [_ReducedRun(model, state, W, cub, mode) for mode in modes]
        for _ in range(steps):
            for run in runs:
                run.step(repeats)
    return [run.record() for run in runs]


def truth_scenario(name: str, level: int) -> tuple[Scenario, dict]:
    """Suite member `name`'s scenario at its suite's truth-ladder settings, level `level` (dt / 2^level), and the
    ladder runs' solver parameters (`TruthSpec.solver_params`)."""
    from frictionbench.bench.runner import ladder_variant
    from frictionbench.scenarios.suites import load_suite

    suite = load_suite(name.split("/", 1)[0])
    if suite.truth is None:
        raise ScenarioError("--truth", name, f"suite {suite.name} has no [truth] table")
    if suite.truth.kind != "step":
        raise ScenarioError("--truth", name, f"suite {suite.name}'s truth is a {suite.truth.kind} ladder, not steps")
    member = next(m.scenario for m in suite.scenarios if m.scenario.name == name)
    spec = suite.truth
    return ladder_variant(member, spec.integrator, level, lag=spec.contact_lag).scenario(member), spec.solver_params


def _print_full(name: str, cfg: str, r: dict) -> None:
    print(f"{name:24s} {cfg:15s} {r['step_ms']:8.1f} ms/step ({r['speedup']:4.1f}x)  "
          f"it/step {np.mean(r['newton_iters']):4.1f}  solves/step {r['lag_solves_per_step']:4.2f}  "
          f"{r['wall_s_per_sim_s']:6.1f} s/sim s  per step: assembly {r['assembly_ms']:6.1f}  "
          f"factor {r['factorisation_ms']:7.1f}  solve {r['solve_ms']:5.1f}  line search "
          f"{r['line_search_ms']:5.1f}  other {r['other_ms']:5.1f} ms  |dx_end|/L {r['x_end_diff_rel']:.1e}",
          flush=True)


#: The truth levels' Newton variants of `--chord`: Newton's method, the chord convergence test
#: (`NewtonSettings.chord`), and modified Newton with it (`NewtonSettings.chord_contraction`, at MODIFIED_CONTRACTION).
MODIFIED_CONTRACTION = 0.5
CHORD_MODES = {"off": {"chord": False, "chord_contraction": 0.0}, "test": {"chord": True, "chord_contraction": 0.0},
               "modified": {"chord": True, "chord_contraction": MODIFIED_CONTRACTION}}


def chord_mode(params: dict) -> str:
    """The `CHORD_MODES` name of the full-space parameters `params` (`modified` at any contraction)."""
    if not params.get("chord"):
        return "off"
    return "modified" if params.get("chord_contraction") else "test"


def benchmark(cases: list[str], configs: list[str], steps: int, settle: int, reduced: list[str] | None = None,
              reduced_steps: int = 40, rank: int = 24, cubature: int = 60, repeats: int = 3,
              truth_levels: list[int] | None = None, chord: str = "suite") -> list[dict]:
    """One record per case x configuration (see the module doc), then per truth level (`truth_levels`: the
    suite's truth settings at those levels, in the first configuration; `chord`: the suite's Newton (`suite`), or
    one of CHORD_MODES, or `all` of them one after the other), then the reduced ones; speedup = first
    configuration's step time / this one's, in this run (for a truth level: its wall_s_per_sim_s over the first
    configuration's, below 1 where the truth costs more per simulated second); x_end_diff_rel against the first
    configuration's end state (the same simulated time)."""
    records = []
    for name in cases:
        sc = resolve_scenario(name)
        model = build_model(sc, load_mesh(sc.mesh))
        state, k, frames = mid_contact_state(model, settle)
        base_ms = base_x = None
        for cfg in configs:
            linear, _, threads = cfg.partition(":")
            r = run_config(model, state, linear, int(threads or 1), steps)
            x_end = r.pop("x_end")
            if base_x is None:
                base_ms, base_x, base_sim = r["step_ms"], x_end, r["wall_s_per_sim_s"]
            r |= {"case": name, "mesh": sc.mesh.key, "n_vertices": model.n, "n_tets": int(model.tets.shape[0]),
                  "from_step": k, "steps": steps, "speedup": base_ms / r["step_ms"],
                  "x_end_diff_rel": float(np.abs(x_end - base_x).max() / model.L)}
            records.append(r)
            _print_full(name, cfg, r)
        linear, _, threads = configs[0].partition(":")
        modes = {"suite": (None,), "all": tuple(CHORD_MODES)}.get(chord, (chord,))
        for level, mode in ((level, mode) for level in truth_levels or () for mode in modes):
            sc_t, params = truth_scenario(name, level)
            params = params if mode is None else params | CHORD_MODES[mode]
            r = run_config(build_model(sc_t, load_mesh(sc_t.mesh)), state, linear, int(threads or 1),
                           steps * 2 ** level, params)
            x_end = r.pop("x_end")
            r |= {"case": name, "mesh": sc.mesh.key, "n_vertices": model.n, "n_tets": int(model.tets.shape[0]),
                  "from_step": k, "steps": steps * 2 ** level, "truth_level": level,
                  "chord": chord_mode(params), "speedup": base_sim / r["wall_s_per_sim_s"],
                  "x_end_diff_rel": float(np.abs(x_end - base_x).max() / model.L)}
            records.append(r)
            _print_full(name, f"truth:{level}:{r['chord']}:{configs[0]}", r)
        if reduced:
            W, cub = reduced_setup(model, frames, rank, cubature)
            all_ms = all_x = None
            for rec in run_reduced(model, state, W, cub, reduced, reduced_steps, repeats):
                mode = rec["reduced"]
                x_end = rec.pop("x_end")
                if all_x is None:
                    all_ms, all_x = rec["step_ms"], x_end
                rec |= {"case": name, "mesh": sc.mesh.key, "n_vertices": model.n, "n_tets": int(model.tets.shape[0]),
                        "from_step": k, "steps": reduced_steps, "speedup": base_ms / rec["step_ms"],
                        "speedup_vs_first_reduced": all_ms / rec["step_ms"],
                        "x_end_diff_rel": float(np.abs(x_end - all_x).max() / model.L)}
                records.append(rec)
                print(f"{name:24s} {'reduced:' + mode:22s} {rec['step_ms']:7.3f} ms/step ({rec['speedup']:5.0f}x, "
                      f"{rec['speedup_vs_first_reduced']:4.2f}x)  it/step {np.mean(rec['newton_iters']):4.2f}  "
                      f"candidates {rec['candidates_mean']:6.1f}/{rec['points']}  per step: body "
                      f"{rec['body_ms']:5.3f}  points {rec['points_ms']:5.3f}  reduction {rec['reduction_ms']:5.3f}"
                      f"  solve {rec['linear_solve_ms']:5.3f}  line search {rec['line_search_ms']:5.3f}  basis "
                      f"{rec['basis_ms']:5.3f}  other {rec['other_ms']:5.3f} ms  |dx_end|/L "
                      f"{rec['x_end_diff_rel']:.1e}", flush=True)
    return records


def main() -> None:
    p = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    p.add_argument("--cases", nargs="+", default=CASES, help="suite members (default: %(default)s)")
    p.add_argument("--configs", nargs="+", default=CONFIGS,
                   help="linear:threads, linear in pardiso, superlu, direct, cg (default: %(default)s)")
    p.add_argument("--steps", type=int, default=5, help="timed steps per configuration")
    p.add_argument("--settle", type=int, default=4, help="steps after the first contact before timing")
    p.add_argument("--reduced", nargs="*", default=REDUCED, choices=REDUCED,
                   help="reduced configurations, none to skip them (default: %(default)s)")
    p.add_argument("--reduced-steps", type=int, default=40, help="timed reduced steps per configuration")
    p.add_argument("--r", type=int, default=24, help="reduced basis columns (12 affine + POD)")
    p.add_argument("--cubature", type=int, default=60, help="optimised cubature tets of the reduced step")
    p.add_argument("--repeats", type=int, default=3, help="runs of each reduced step, the fastest kept")
    p.add_argument("--truth", nargs="*", type=int, default=[], metavar="K",
                   help="also step at the suite's truth-ladder settings at these levels (dt / 2^K)")
    p.add_argument("--chord", default="suite", choices=["suite", *CHORD_MODES, "all"],
                   help="the truth levels' Newton: the suite's ([truth] chord, chord_contraction), Newton's (off), "
                        "the chord convergence test (test), modified Newton (modified), or all three in turn")
    p.add_argument("--out", default="out/bench_step.json")
    a = p.parse_args()
    if any(k < 0 or k > 12 for k in a.truth):
        p.error(f"--truth: levels between 0 and 12, got {a.truth}")
    records = benchmark(a.cases, a.configs, a.steps, a.settle, a.reduced, a.reduced_steps, a.r, a.cubature,
                        a.repeats, a.truth, a.chord)
    write_json_atomic(a.out, {"records": records, "provenance": provenance("cpu"),
                              "command": {"cases": a.cases, "configs": a.configs, "steps": a.steps,
                                          "settle": a.settle, "reduced": a.reduced,
                                          "reduced_steps": a.reduced_steps, "r": a.r, "cubature": a.cubature,
                                          "repeats": a.repeats, "truth": a.truth, "chord": a.chord}})


if __name__ == "__main__":
    main()

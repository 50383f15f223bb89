"""Benchmark of a full-space step in contact, its time broken down, with the linear solvers side by side.

    python -m frictionbench.bench.benchmark_step --out out/bench_step.json
    python -m frictionbench.bench.benchmark_step --cases hard/E1e9 --steps 3 --configs superlu:1 pardiso:1

Each case (a suite member) is advanced with the default solver until a contact point first penetrates the plane,
then `--settle` steps more: the mid-contact state. From it every configuration (`linear:threads`: the linear
solver, and the thread budget of MKL and of the element assembly, entered with `threadpool_limits`) steps the same
`--steps` steps after an untimed warm-up step, one configuration after the other in the same run. Per step it
reports the wall time and where it went: assembly (gradient and Hessian kernels, `gradient_hessian`),
factorisation and solve (the factoriser's calls), line search (energy evaluations), other (the rest: copies,
residuals); Newton iterations per step; and the end state's distance to the first configuration's. `superlu:1` is
the solver's original path (SuperLU with a fresh ordering per iteration, one-thread assembly). Compare times as
ratios within one run: the machine may be shared.
"""

from __future__ import annotations

import argparse
import time
from collections import defaultdict
from collections.abc import Callable

import numpy as np
from threadpoolctl import threadpool_limits

from frictionbench.analysis.table import provenance
from frictionbench.bench.cli import resolve_scenario
from frictionbench.scenarios.atomic import write_json_atomic
from frictionbench.scenarios.meshes import load_mesh
from frictionbench.solvers.full.solver import FullSpaceSolver, NewtonSettings
from frictionbench.solvers.model import Model, State, build_model, initial_state

CASES = ["paper/cheese_p1_mu0.5", "paper/sphere_p1_mu0.5", "hard/E1e9"]
CONFIGS = ["superlu:1", "pardiso:1", "pardiso:2"]
PARTS = ("assembly", "factorisation", "solve", "line_search")


def _timed(obj: object, method: str, totals: dict[str, float], part: str) -> None:
    """Wrap obj.method (on the instance) so that its wall time adds to totals[part] [s]."""
    inner: Callable = getattr(obj, method)

    def wrapper(*args, **kwargs):
        t0 = time.perf_counter()
        try:
            return inner(*args, **kwargs)
        finally:
            totals[part] += time.perf_counter() - t0

    setattr(obj, method, wrapper)


def in_contact(model: Model, x: np.ndarray) -> bool:
    """Whether a contact point of `model` lies below its plane at positions x (n, 3)."""
    return model.plane_normal is not None and bool(
        (x[model.points] @ model.plane_normal < model.plane_offset).any())


def mid_contact_state(model: Model, settle: int, max_steps: int = 1000) -> tuple[State, int]:
    """The state `settle` steps after the first step that ends in contact (default solver), and its step index."""
    solver = FullSpaceSolver(model)
    state, k, touched = initial_state(model), 0, None
    dt = model.scenario.time.dt
    while touched is None or k < touched + settle:
        out = State(state.x, state.v, state.t)
        solver.step(state, out, dt)
        state, k = out, k + 1
        if touched is None and in_contact(model, state.x):
            touched = k
        if k >= max_steps:
            raise RuntimeError(f"{model.scenario.name}: no contact within {max_steps} steps")
    return state, k


def run_config(model: Model, state: State, linear: str, threads: int, steps: int) -> dict:
    """Step `steps` steps from `state` with one configuration; per-step means [ms] of each part, iterations."""
    dt = model.scenario.time.dt
    with threadpool_limits(threads):
        solver = FullSpaceSolver(model, settings=NewtonSettings(linear=linear))
        solver.step(state, State(state.x, state.v, state.t), dt)  # warm-up (kernel loading, PARDISO analysis)
        totals: dict[str, float] = defaultdict(float)
        _timed(solver, "gradient_hessian", totals, "assembly")
        _timed(solver, "energy", totals, "line_search")
        if linear != "cg":
            _timed(solver.factoriser, "factorize", totals, "factorisation")
            _timed(solver.factoriser, "solve", totals, "solve")
        walls, iters = [], []
        for _ in range(steps):
            out = State(state.x, state.v, state.t)
            st = solver.step(state, out, dt)
            walls.append(st.wall_s)
            iters.append(st.iterations)
            state = out
    ms = {f"{p}_ms": 1e3 * totals[p] / steps for p in PARTS}
    step_ms = 1e3 * float(np.mean(walls))
    return {"linear": linear, "linear_solver": solver.info["linear_solver"], "threads": threads,
            "assembly_threads": solver.info["assembly_threads"], "step_ms": step_ms,
            "factor_nnz": getattr(solver.factoriser, "factor_nnz", None) if linear != "cg" else None,
            "step_ms_per_step": [1e3 * w for w in walls], "newton_iters": iters,
            "iter_ms": 1e3 * float(np.sum(walls)) / max(1, sum(iters)), **ms,
            "other_ms": step_ms - sum(ms.values()), "x_end": state.x}


def benchmark(cases: list[str], configs: list[str], steps: int, settle: int) -> list[dict]:
    """One record per case x configuration (see the module doc); speedup = first configuration's step time /
    this one's, in this run."""
    records = []
    for name in cases:
        sc = resolve_scenario(name)
        model = build_model(sc, load_mesh(sc.mesh))
        state, k = mid_contact_state(model, settle)
        base_ms = base_x = None
        for cfg in configs:
            linear, _, threads = cfg.partition(":")
            r = run_config(model, state, linear, int(threads or 1), steps)
            x_end = r.pop("x_end")
            if base_x is None:
                base_ms, base_x = r["step_ms"], x_end
            r |= {"case": name, "mesh": sc.mesh.key, "n_vertices": model.n, "n_tets": int(model.tets.shape[0]),
                  "from_step": k, "steps": steps, "speedup": base_ms / r["step_ms"],
                  "x_end_diff_rel": float(np.abs(x_end - base_x).max() / model.L)}
            records.append(r)
            print(f"{name:24s} {cfg:11s} {r['step_ms']:8.1f} ms/step ({r['speedup']:4.1f}x)  "
                  f"it/step {np.mean(r['newton_iters']):4.1f}  per step: assembly {r['assembly_ms']:6.1f}  "
                  f"factor {r['factorisation_ms']:7.1f}  solve {r['solve_ms']:5.1f}  line search "
                  f"{r['line_search_ms']:5.1f}  other {r['other_ms']:5.1f} ms  |dx_end|/L {r['x_end_diff_rel']:.1e}",
                  flush=True)
    return records


def main() -> None:
    p = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    p.add_argument("--cases", nargs="+", default=CASES, help="suite members (default: %(default)s)")
    p.add_argument("--configs", nargs="+", default=CONFIGS,
                   help="linear:threads, linear in pardiso, superlu, direct, cg (default: %(default)s)")
    p.add_argument("--steps", type=int, default=5, help="timed steps per configuration")
    p.add_argument("--settle", type=int, default=4, help="steps after the first contact before timing")
    p.add_argument("--out", default="out/bench_step.json")
    a = p.parse_args()
    records = benchmark(a.cases, a.configs, a.steps, a.settle)
    write_json_atomic(a.out, {"records": records, "provenance": provenance("cpu"),
                              "command": {"cases": a.cases, "configs": a.configs, "steps": a.steps,
                                          "settle": a.settle}})


if __name__ == "__main__":
    main()

"""Run one scenario with one solver: setup (untimed), a warm-up step (JIT, reported apart), the timed run."""

from __future__ import annotations

import time

import numpy as np

from frictionbench.scenarios.meshes import TetMesh, load_mesh
from frictionbench.scenarios.spec import MeshSpec, Scenario
from frictionbench.solvers.build import build_model, initial_state
from frictionbench.solvers.model import State
from frictionbench.solvers.registry import get_solver
from frictionbench.solvers.simulate import Diverged, simulate
from frictionbench.solvers.step_stats import stats_summary
from frictionbench.solvers.trajectory import Trajectory


class Skipped(RuntimeError):
    """The solver cannot run this scene (`Solver.skip` gave the reason)."""


def run_scenario(scenario: Scenario, solver: str = "full", device: str = "cpu", params: dict | None = None,
                 mesh: MeshSpec | None = None, progress: bool = False,
                 tet_mesh: TetMesh | None = None) -> tuple[Trajectory | None, dict]:
    """Simulate `scenario` (optionally on another mesh of the same shape) with the named solver; `tet_mesh` is
    the mesh itself where it was loaded elsewhere (a worker that cannot read the mesh's file), else it is loaded
    from `mesh` (default: the scenario's).

    Returns the trajectory (None if the run diverged before its first frame) and a stats dict: setup_s,
    warmup_s (first step with kernel compilation, on a throw-away state), step_ms_median/p95 and Newton figures
    of the timed run, the resolved contact stiffness (`contact_stiffness` [Pa/m]) and damping (`contact_damping`
    [Pa s/m], 0 without a damping term), the material's Kelvin-Voigt
    `viscosity` [Pa s] (0 when undamped; resolved from the scenario's `damping_ratio`, recorded too, where it gave
    one), the time `integrator`, the solver's `describe()`, `failed` and `failure` (reason) for a run that diverged;
    an adaptive run (`time.tol`) also its `tol` and the step figures of `stats_summary`.
    Raises `Skipped` for a scene the solver declines, or whose integrator it does not implement.
    """
    params = dict(params or {})
    t0 = time.perf_counter()
    model = build_model(scenario, tet_mesh if tet_mesh is not None else load_mesh(mesh or scenario.mesh))
    stepper = get_solver(solver)(device=device, **params)
    integrator = model.integrator.name
    reason = (f"time.integrator = {integrator!r}: solver {solver!r} implements {list(stepper.integrators)}"
              if integrator not in stepper.integrators else stepper.skip(model))
    if reason:
        raise Skipped(reason)
    stepper.setup(model)
    setup_s = time.perf_counter() - t0
    state0 = stepper.initial(initial_state(model))
    t0 = time.perf_counter()
    stepper.step(state0.copy(), State(state0.x.copy(), state0.v.copy()), scenario.time.dt)
    warmup_s = time.perf_counter() - t0
    meta = {"solver": solver, "params": params, "device": device, "mesh": (mesh or scenario.mesh).key}
    stats: dict = {"setup_s": setup_s, "warmup_s": warmup_s, "device": device, "solver": solver, "params": params,
                   "mesh": (mesh or scenario.mesh).key, "n_vertices": model.n, "n_tets": int(model.tets.shape[0]),
                   "terms": list(model.terms), "integrator": integrator, "contact_stiffness": model.contact.stiffness,
                   "contact_damping": model.contact_damping,
                   "viscosity": model.viscosity, "damping_ratio": model.damping_ratio, "failed": False,
                   "failure": ""}
    stats.update(stepper.describe())
    t0 = time.perf_counter()
    try:
        traj, steps = simulate(model, stepper, state0, progress=progress, meta=meta)
    except Diverged as err:
        traj, steps = err.trajectory, err.stats
        stats.update(failed=True, failure=str(err))
    traj.basis = stepper.basis
    if stepper.basis_frame != "world":
        traj.meta["basis_frame"] = stepper.basis_frame
    stats["run_s"] = time.perf_counter() - t0
    stats.update({k: v for k, v in stats_summary(steps, scenario.time.tol).items()})
    if scenario.time.adaptive:
        stats["tol"] = scenario.time.tol
    stats["finite"] = bool(np.isfinite(traj.x).all()) and not stats["failed"]
    return traj, stats

"""One truth-ladder level's step of a suite member, at the checkout's own [truth] settings (BDF2, fixed-point lag,
its Newton settings), from the mid-contact state: ms per step, Newton iterations and lag solves per step.
Works at ebb6680 and at HEAD (run with PYTHONPATH=<checkout>). Usage: SUITE MEMBER RESOLUTION LEVEL STEPS"""
import json, sys, time
from dataclasses import replace
import numpy as np
from threadpoolctl import threadpool_limits
from frictionbench.scenarios.suites import load_suite
from frictionbench.scenarios.meshes import load_mesh
from frictionbench.bench.benchmark_step import mid_contact_state
from frictionbench.solvers.full.solver import FullSpaceSolver, NewtonSettings
from frictionbench.solvers.model import State
try:
    from frictionbench.solvers.build import build_model
except ImportError:
    from frictionbench.solvers.model import build_model
suite_name, member, resolution, level, steps = sys.argv[1], sys.argv[2], sys.argv[3], int(sys.argv[4]), int(sys.argv[5])
suite = load_suite(suite_name).at_resolution(resolution)
(m,) = [m for m in suite.scenarios if m.scenario.name.endswith("/" + member)]
spec = suite.truth
sc = m.scenario
model = build_model(sc, load_mesh(sc.mesh))
state, k, _ = mid_contact_state(model, 1)
t_sc = replace(sc, time=replace(sc.time, dt=sc.time.dt / 2 ** level, integrator=spec.integrator),
               contact=replace(sc.contact, lag=spec.contact_lag))
params = dict(getattr(spec, "solver_params", {}) or {})
t_model = build_model(t_sc, load_mesh(t_sc.mesh))
with threadpool_limits(1):
    solver = FullSpaceSolver(t_model, settings=NewtonSettings(linear="pardiso", **params))
    solver.step(state, State(state.x, state.v, state.t), t_sc.time.dt)  # warm-up
    walls, iters, lags = [], [], []
    s = state
    for _ in range(steps * 2 ** level):
        out = State(s.x, s.v, s.t)
        st = solver.step(s, out, t_sc.time.dt)
        walls.append(st.wall_s); iters.append(st.iterations); lags.append(st.counters.get("lag_solves", 1))
        s = out
print(json.dumps({"suite": suite_name, "member": member, "level": level, "settings": params or "Newton 1e-5 (defaults)",
                  "steps": len(walls), "ms_per_step": round(1e3 * float(np.mean(walls)), 2),
                  "iters_per_step": round(float(np.mean(iters)), 2), "lag_solves_per_step": round(float(np.mean(lags)), 2),
                  "s_per_sim_s": round(float(np.sum(walls)) / (len(walls) * t_sc.time.dt), 2)}))

"""The time loop shared by every solver: step a `State` through a scenario's duration, store frames.

A solver is anything with `step(state_in, state_out, dt) -> stats` whose stats are a `StepStats`
(`solvers.step_stats`); where its states carry latent coordinates q (every stored frame's, the initial state's
included), the trajectory stores them. A step that fails (Newton not converged, or a non-finite state) is redone
from the same start as two half steps, recursively down to dt / 2^MAX_RETRY_DEPTH; the step's record then sums the
attempts' iterations, counters and wall time and counts the retries. A step still non-finite after that ends the
run: the loop raises `Diverged` carrying what was computed so far. Each state a solver returns remembers the one its
step started from (`State.previous`), so BDF2's history follows the steps actually taken: a retried step restarts it
with a backward-Euler half step (`solvers.integrators`).
"""

from __future__ import annotations

from typing import Protocol

import numpy as np
from tqdm import tqdm

from frictionbench.solvers.model import Model, State, initial_state
from frictionbench.solvers.step_stats import StepStats
from frictionbench.solvers.trajectory import Trajectory


class Stepper(Protocol):
    """What the loop needs of a solver."""

    name: str

    def step(self, state_in: State, state_out: State, dt: float): ...


#: Deepest halving of a failed step: dt / 2^MAX_RETRY_DEPTH.
MAX_RETRY_DEPTH = 3


def _finite(state: State) -> bool:
    return bool(np.isfinite(state.x).all() and np.isfinite(state.v).all())


def advance(solver: Stepper, state: State, dt: float, depth: int = 0) -> tuple[State, StepStats]:
    """One step of dt [s] from `state`; on failure, two steps of dt/2 from the same start (recursively).

    Returns the end state and one record: its `retries` counts the halvings done, its `iterations`, `counters` and
    `wall_s` sum every attempt, `converged` and `residual` are the last sub-step's.
    """
    out = State(state.x, state.v, state.t)
    st = solver.step(state, out, dt)
    if (st.converged and _finite(out)) or depth >= MAX_RETRY_DEPTH:
        return out, st
    mid, first = advance(solver, state, dt / 2, depth + 1)
    if not _finite(mid):
        return mid, st.merged(first)
    end, second = advance(solver, mid, dt / 2, depth + 1)
    return end, st.merged(first, second)


class Diverged(RuntimeError):
    """The simulation produced non-finite values; `trajectory` holds the frames before it and `step` the step."""

    def __init__(self, step: int, trajectory: Trajectory, stats: list) -> None:
        super().__init__(f"non-finite state at step {step}")
        self.step = step
        self.trajectory = trajectory
        self.stats = stats


def simulate(model: Model, solver: Stepper, state0: State | None = None, progress: bool = False,
             meta: dict | None = None) -> tuple[Trajectory, list]:
    """Run the scenario's time span; frame 0 is the initial state, then every `frame_every` steps.

    Returns the trajectory (positions and velocities at the stored frames) and the per-step stats.
    """
    ts = model.scenario.time
    state = state0 if state0 is not None else initial_state(model)
    frames_t, frames_x, frames_v, frames_q, stats = [state.t], [state.x.copy()], [state.v.copy()], [state.q], []

    def trajectory() -> Trajectory:
        q = np.array(frames_q) if all(q is not None for q in frames_q) else None
        return Trajectory(t=np.array(frames_t), x=np.array(frames_x), X=model.X, tets=model.tets,
                          surface=model.surface, v=np.array(frames_v), q=q,
                          meta=dict(meta or {}, scenario=model.scenario.name, solver=solver.name))

    bar = tqdm(range(1, ts.n_steps + 1), desc=f"{solver.name}:{model.scenario.name}", disable=not progress,
               leave=False, unit="step")
    for k in bar:
        state, st = advance(solver, state, ts.dt)
        stats.append(st)
        if not _finite(state):
            raise Diverged(k, trajectory(), stats)
        if k % ts.frame_every == 0 or k == ts.n_steps:
            frames_t.append(state.t)
            frames_x.append(state.x.copy())
            frames_v.append(state.v.copy())
            frames_q.append(None if state.q is None else state.q.copy())
    return trajectory(), stats

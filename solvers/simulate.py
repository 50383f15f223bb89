"""The time loop shared by every solver: step a `State` through a scenario's duration, store frames.

A solver is anything with `step(state_in, state_out, dt) -> stats` whose stats have `wall_s`, `newton_iters`
and `converged` (see `solvers.full.solver.StepStats`). The loop stops at the first non-finite state and raises
`Diverged` carrying what was computed so far.
"""

from __future__ import annotations

from typing import Protocol

import numpy as np
from tqdm import tqdm

from solvers.model import Model, State, initial_state
from solvers.trajectory import Trajectory


class Stepper(Protocol):
    """What the loop needs of a solver."""

    name: str

    def step(self, state_in: State, state_out: State, dt: float): ...


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
    frames_t, frames_x, frames_v, stats = [state.t], [state.x.copy()], [state.v.copy()], []

    def trajectory() -> Trajectory:
        return Trajectory(t=np.array(frames_t), x=np.array(frames_x), X=model.X, tets=model.tets,
                          surface=model.surface, v=np.array(frames_v),
                          meta=dict(meta or {}, scenario=model.scenario.name, solver=solver.name))

    bar = tqdm(range(1, ts.n_steps + 1), desc=f"{solver.name}:{model.scenario.name}", disable=not progress,
               leave=False, unit="step")
    for k in bar:
        out = State(state.x, state.v, state.t)
        stats.append(solver.step(state, out, ts.dt))
        state = out
        if not (np.isfinite(state.x).all() and np.isfinite(state.v).all()):
            raise Diverged(k, trajectory(), stats)
        if k % ts.frame_every == 0 or k == ts.n_steps:
            frames_t.append(state.t)
            frames_x.append(state.x.copy())
            frames_v.append(state.v.copy())
    return trajectory(), stats

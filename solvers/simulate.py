"""The time loop shared by every solver: step a `State` through a scenario's duration, store frames.

A solver is anything with `step(state_in, state_out, dt) -> stats` whose stats are a `StepStats`
(`solvers.step_stats`); where its states carry latent coordinates q (every stored frame's, the initial state's
included), the trajectory stores them. A step that fails (Newton not converged, or a non-finite state) is redone
from the same start as two half steps, recursively down to dt / 2^MAX_RETRY_DEPTH; the step's record then sums the
attempts' iterations, counters and wall time and counts the retries. A step still non-finite after that ends the
run: the loop raises `Diverged` carrying what was computed so far. Each state a solver returns remembers the one its
step started from (`State.previous`), so BDF2's history follows the steps actually taken: a retried step restarts it
with a backward-Euler half step (`solvers.integrators`).

A scenario with `time.tol` steps adaptively instead (`adaptive_step`; docs/physics.md, "Adaptive steps"): each step's
local error is estimated by the model's integrator (`Integrator.local_error`, on the decoded positions x, so the
full-space and the reduced solvers are controlled alike), measured by `error_norm` and held to tol by rejecting and
retrying a step from the same start, the step sizes chosen by a standard controller (`Controller`) within
[time.min_step, time.dt] and shortened to land exactly on the frame times of the fixed-step run (every
frame_every x dt, and the end), which the stored frames keep.
"""

from __future__ import annotations

import math
from dataclasses import dataclass
from typing import Protocol

import numpy as np
from tqdm import tqdm

from frictionbench.solvers.build import initial_state
from frictionbench.solvers.integrators import Integrator
from frictionbench.solvers.model import Model, State
from frictionbench.solvers.step_stats import StepStats, combined
from frictionbench.solvers.trajectory import Trajectory


class Stepper(Protocol):
    """What the loop needs of a solver."""

    name: str

    def step(self, state_in: State, state_out: State, dt: float): ...


#: Deepest halving of a failed step: dt / 2^MAX_RETRY_DEPTH.
MAX_RETRY_DEPTH = 3
#: Relative tolerance [-] of a step size against the smallest step and of a time against a frame time: the times
#: are sums of steps, equal to round-off.
_ROUND_OFF = 1e-9


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


@dataclass(frozen=True)
class Controller:
    """The step-size controller of adaptive runs (Hairer, Norsett and Wanner, Solving ODEs I, II.4): after a step
    of h with error err against tol, the next h_new = h min(fac_max, max(fac_min, safety (tol / err)^(1/(p+1))))
    with p the order of the formula the step used; after a rejection the step does not grow (fac_max 1).
    safety 0.9 aims below tol so the next step is likely accepted; fac_min 0.2 and fac_max 2 bound the change per
    step, and fac_max 2 keeps the step ratio w = h / h_prev of variable-step BDF2 below its zero-stability bound
    1 + sqrt(2). A step whose solve failed is retried at `failed` (1/2) of its size."""

    safety: float = 0.9
    fac_min: float = 0.2
    fac_max: float = 2.0
    failed: float = 0.5

    def factor(self, err: float, tol: float, order: int, grow: bool = True) -> float:
        """h_new / h [-] after a step of order `order` with error `err` against `tol` (both fractions of L); at most
        1 without `grow` (after a rejection)."""
        fac_max = self.fac_max if grow else 1.0
        if err <= 0.0:
            return fac_max
        return min(fac_max, max(self.fac_min, self.safety * (tol / err) ** (1.0 / (order + 1))))


#: The controller of every adaptive run.
CONTROLLER = Controller()


def error_norm(error: np.ndarray, L: float) -> float:
    """sqrt(mean over vertices i of |e_i|^2) / L [fraction of L] of a position error e (n, 3) [m]: the measure of
    `analysis.metrics.pos_rmse_rel`, so that time.tol is in the units of the benchmark's accuracy (err_truth), and
    independent of the mesh's vertex count (an RMS, not a sum)."""
    return float(np.sqrt(np.mean(np.sum(error * error, axis=-1)))) / L


def adaptive_step(solver: Stepper, integrator: Integrator, state: State, h: float, tol: float, h_min: float,
                  L: float, controller: Controller = CONTROLLER) -> tuple[State, StepStats, float]:
    """One accepted step from `state`, trying h [s] first: a step whose estimated error (`error_norm` of
    `Integrator.local_error`, body size L [m]) exceeds tol [fraction of L] is retried from the same start with the
    controller's smaller step, one whose solve failed or whose state is not finite with `controller.failed` of it,
    never below h_min [s]; at h_min a step is accepted whatever its error (`error` then above tol), or a failed
    solve with a finite state (`converged` False).

    Returns the end state (non-finite where even h_min failed), its record (`StepStats` with `dt`, the attempts'
    wall time, iterations and counters summed, `rejected` the attempts discarded, `retries` those discarded for a
    failure, `error`), and the controller's next step [s] (not yet clamped).
    """
    attempts: list[StepStats] = []
    failures = 0
    while True:
        out = State(state.x, state.v, state.t)
        st = solver.step(state, out, h)
        attempts.append(st)
        floor = h <= h_min * (1.0 + _ROUND_OFF)
        ok = st.converged and _finite(out)
        err = math.inf
        if _finite(out):
            prev = integrator.previous(state, h)
            est = integrator.local_error(out.x, state.x, state.v, h,
                                         None if prev is None else (prev.x, prev.v, state.t - prev.t))
            err = error_norm(est.error, L)
        if (ok and err <= tol) or floor:
            record = combined(attempts, retries=failures, dt=h, rejected=len(attempts) - 1,
                              error=err if math.isfinite(err) else None)
            grow = len(attempts) == 1
            return out, record, h * (controller.factor(err, tol, est.order, grow) if math.isfinite(err) else
                                     controller.failed)
        if ok:
            h = max(h_min, h * controller.factor(err, tol, est.order, grow=False))
        else:
            failures += 1
            h = max(h_min, h * controller.failed)


def next_step(h: float, remaining: float, dt: float, h_min: float) -> float:
    """The step [s] to try with `remaining` [s] to the next frame time, from the controller's proposal h [s]: h
    clamped to [h_min, dt]; all of `remaining` where that is at most the step (landing on the frame time), half of it
    where it is less than two steps (two even steps rather than one and a sliver) and that half is at least h_min."""
    h = min(dt, max(h_min, h))
    if remaining <= h * (1.0 + _ROUND_OFF):
        return remaining
    if remaining < 2.0 * h and remaining / 2.0 >= h_min:
        return remaining / 2.0
    return h


class Diverged(RuntimeError):
    """The simulation produced non-finite values; `trajectory` holds the frames before it and `step` the step."""

    def __init__(self, step: int, trajectory: Trajectory, stats: list) -> None:
        super().__init__(f"non-finite state at step {step}")
        self.step = step
        self.trajectory = trajectory
        self.stats = stats


def frame_steps(n_steps: int, frame_every: int) -> list[int]:
    """The steps (1..n_steps) after which a frame is stored: every `frame_every`-th and the last."""
    return [k for k in range(1, n_steps + 1) if k % frame_every == 0 or k == n_steps]


def simulate(model: Model, solver: Stepper, state0: State | None = None, progress: bool = False,
             meta: dict | None = None) -> tuple[Trajectory, list]:
    """Run the scenario's time span; frame 0 is the initial state, then every `frame_every` steps (an adaptive
    run: at the same times, `frame_steps` x dt).

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

    def store(s: State) -> None:
        frames_t.append(s.t)
        frames_x.append(s.x.copy())
        frames_v.append(s.v.copy())
        frames_q.append(None if s.q is None else s.q.copy())

    desc = f"{solver.name}:{model.scenario.name}"
    if ts.adaptive:
        h, h_min = ts.dt, ts.min_step
        for k in tqdm(frame_steps(ts.n_steps, ts.frame_every), desc=desc, disable=not progress, leave=False,
                      unit="frame"):
            t_frame = k * ts.dt
            while state.t < t_frame:
                remaining = t_frame - state.t
                state, st, h = adaptive_step(solver, model.integrator, state, next_step(h, remaining, ts.dt, h_min),
                                             ts.tol, h_min, model.L)
                stats.append(st)
                if not _finite(state):
                    raise Diverged(len(stats), trajectory(), stats)
                if abs(t_frame - state.t) <= _ROUND_OFF * ts.dt:
                    state.t = t_frame  # landed: the frame at its exact time
            store(state)
        return trajectory(), stats
    bar = tqdm(range(1, ts.n_steps + 1), desc=desc, disable=not progress, leave=False, unit="step")
    for k in bar:
        state, st = advance(solver, state, ts.dt)
        stats.append(st)
        if not _finite(state):
            raise Diverged(k, trajectory(), stats)
        if k % ts.frame_every == 0 or k == ts.n_steps:
            store(state)
    return trajectory(), stats

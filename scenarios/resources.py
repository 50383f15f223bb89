"""Resource guard: a run whose step count or stored frames are beyond a sane bound is refused before any work.

A scenario's time loop takes `time.duration / time.dt` steps and stores every `time.frame_every`-th state
(positions and velocities, float64, (n, 3) each) in memory and then on disk (trajectory.npz). A typo such as
`dt = 1e-12` or `duration = 1e12` would otherwise start a run with no end in sight, or one that fills the memory
hours later. The bounds are far above every shipped suite (at most 300 steps and 30 MB of frames per run) and can
be lifted on purpose: `--allow-large` on the command line, or `allow_large = true` in a suite's `[suite]` table.
"""

from __future__ import annotations

import math
from collections.abc import Iterable

from frictionbench.scenarios.errors import ScenarioError
from frictionbench.scenarios.spec import MAX_STEPS, MeshSpec, Scenario, TimeSpec

#: Most bytes the stored frames of one run may take, in memory and again on disk, without an override.
MAX_STORED_BYTES = 2 * 2**30
#: Arrays stored per frame (positions and velocities), each (n, 3) float64.
STORED_ARRAYS = 2
OVERRIDE_HINT = "pass --allow-large (or set allow_large = true in the suite's [suite] table) to run it anyway"


def step_count(time: TimeSpec, step: float | None = None) -> float:
    """Steps of the time loop, round(duration / dt) (or of another `step` [s]), as a float (no overflow for absurd
    inputs)."""
    steps = time.duration / (time.dt if step is None else step)
    return float(round(steps)) if steps < 2.0**53 else steps


def most_steps(time: TimeSpec) -> float:
    """The most steps a run may take: `step_count`, or for an adaptive run (`TimeSpec.adaptive`) the count at its
    smallest step (`TimeSpec.min_step`), whatever the step-size controller then does."""
    return step_count(time, time.min_step) if time.adaptive else step_count(time)


def stored_frames(time: TimeSpec) -> float:
    """Frames the time loop stores: the initial state, every `frame_every`-th step and the last step (an adaptive
    run stores the frames of the fixed-step run)."""
    steps = step_count(time)
    kept = math.floor(steps / time.frame_every)
    return kept + 1.0 + (1.0 if kept * time.frame_every < steps else 0.0)


def stored_bytes(time: TimeSpec, n_vertices: int) -> float:
    """Bytes of the stored frames of a mesh with `n_vertices` vertices: frames x n x 3 x 8 x STORED_ARRAYS."""
    return stored_frames(time) * n_vertices * 3 * 8 * STORED_ARRAYS


def format_bytes(size: float) -> str:
    """A byte count with a binary unit (`1.5 GiB`)."""
    units = ("B", "KiB", "MiB", "GiB", "TiB", "PiB")
    power = 0
    while size >= 1024 and power < len(units) - 1:
        size /= 1024
        power += 1
    return f"{size:.3g} {units[power]}"


def _count(x: float) -> str:
    """A count in full below a billion (`50,001`), in exponent form above (`1e+12`)."""
    return f"{x:,.0f}" if x < 1e9 else f"{x:.3g}"


def check_resources(scenario: Scenario, n_vertices: int | None, *, allow_large: bool = False) -> None:
    """Raise ScenarioError naming `time.dt`, `time.duration`, `time.dt_min` or `time.frame_every`, with the step
    count and the estimated size of the stored frames, when a run of `scenario` on a mesh of `n_vertices` vertices
    exceeds MAX_STEPS (an adaptive run: at its smallest step, `most_steps`) or MAX_STORED_BYTES; `allow_large` lifts
    both bounds. With `n_vertices` None (mesh not loaded yet) only the step count is checked and the size is given
    per vertex."""
    if allow_large:
        return
    t = scenario.time
    steps, frames = most_steps(t), stored_frames(t)
    size = (f"{_count(frames)} stored frames x {n_vertices} vertices = {format_bytes(stored_bytes(t, n_vertices))}"
            if n_vertices is not None else
            f"{_count(frames)} stored frames = {format_bytes(stored_bytes(t, 1))} per mesh vertex")
    figures = (f"{_count(steps)} steps (time.duration {t.duration:g} s / time.dt {t.dt:g} s), {size} in memory "
               "and on disk")
    if t.adaptive and t.dt_min is not None and steps > MAX_STEPS >= step_count(t):
        raise ScenarioError("time.dt_min", t.dt_min,
                            f"{scenario.name}: up to {_count(steps)} steps (time.duration {t.duration:g} s / "
                            f"time.dt_min {t.dt_min:g} s); over the bound of {MAX_STEPS} steps; {OVERRIDE_HINT}")
    if steps > MAX_STEPS:
        # name the field that strays further from the defaults (1 s at 0.01 s)
        default = TimeSpec()
        field = "time.dt" if default.dt / t.dt >= t.duration / default.duration else "time.duration"
        value = t.dt if field == "time.dt" else t.duration
        raise ScenarioError(field, value, f"{scenario.name}: {figures}; over the bound of {MAX_STEPS} steps; "
                                          f"{OVERRIDE_HINT}")
    if n_vertices is not None and stored_bytes(t, n_vertices) > MAX_STORED_BYTES:
        raise ScenarioError("time.frame_every", t.frame_every,
                            f"{scenario.name}: {figures}; over the bound of {format_bytes(MAX_STORED_BYTES)}: store "
                            f"fewer frames (a larger time.frame_every) or {OVERRIDE_HINT}")


def check_runs(runs: Iterable[tuple[Scenario, MeshSpec]], *, allow_large: bool = False) -> None:
    """`check_resources` on every (scenario, mesh) run: first every step count (no mesh is loaded, so an absurd
    time step is refused at once), then the stored frames, loading each distinct mesh once for its vertex count."""
    if allow_large:
        return
    runs = list(runs)
    for scenario, _ in runs:
        check_resources(scenario, None)
    from frictionbench.scenarios.meshes import load_mesh

    vertices: dict[MeshSpec, int] = {}
    for scenario, mesh in runs:
        if mesh not in vertices:
            vertices[mesh] = int(load_mesh(mesh).X.shape[0])
        check_resources(scenario, vertices[mesh])

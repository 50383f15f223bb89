"""Scenes and suites shared by several test modules, written as TOML files for the tests that run them (no test
pastes a suite or a scene as TOML text; only deliberately malformed input stays spelled out in its test)."""

from __future__ import annotations

from collections.abc import Mapping
from pathlib import Path
from typing import Any

import numpy as np
import tomli_w

from frictionbench.scenarios.spec import Initial, Material, MeshSpec, Plane, Scenario, TimeSpec

G = 9.81

#: The repository's experiment matrix files (the reduced-model study's variant sets, `--matrix FILE`).
EXPERIMENTS = Path(__file__).resolve().parents[1] / "experiments"


def block_drop(resolution: str | None = "coarse", clearance: float | None = 0.01, dt: float | None = 0.01,
               duration: float | None = 0.05, **tables: Any) -> dict[str, Any]:
    """A scene's tables (the `scenarios.load` schema, without a name): the block mesh at `resolution`,
    `clearance` [m] above the default plane, stepped by `dt` [s] for `duration` [s]; None leaves a value to the
    loader's default (a table left empty is left out); `tables` add or replace tables (material={...})."""
    scene = {"mesh": {"name": "block", "resolution": resolution}, "initial": {"clearance": clearance},
             "time": {"dt": dt, "duration": duration}}
    given = {table: {k: v for k, v in entries.items() if v is not None} for table, entries in scene.items()}
    return {table: entries for table, entries in given.items() if entries} | tables


def mu_axis(*values: float) -> dict[str, Any]:
    """A suite axis over the plane's friction coefficient (members labelled mu<value>, e.g. mu0.2)."""
    return {"name": "mu", "field": "plane.friction", "values": list(values)}


def suite_tables(name: str, base: Mapping[str, Any] | None, *axes: Mapping[str, Any], description: str | None = None,
          **tables: Any) -> dict[str, Any]:
    """A suite's tables (`scenarios.suites` format): its `base` scene (None: none), `axes` in order, and the other
    tables (split, truth, extra) as given."""
    header = {"name": name} | ({"description": description} if description is not None else {})
    return ({"suite": header} | ({"base": dict(base)} if base is not None else {})
            | ({"axis": [dict(a) for a in axes]} if axes else {}) | tables)


def write_toml(path: Path, tables: Mapping[str, Any]) -> Path:
    """Write `tables` (a scene or a suite: nested dicts of strings, numbers, booleans, lists) as TOML to `path`, and
    return `path`."""
    path.write_text(tomli_w.dumps(tables), encoding="utf-8")
    return path


def incline(theta_deg: float, mu: float, **kw) -> Scenario:
    """A block released at rest, flat on a plane through the origin descending towards +x."""
    t = np.radians(theta_deg)
    return Scenario(
        name=f"incline_{theta_deg}_{mu}", mesh=MeshSpec("block", "coarse"),
        material=Material(density=1000.0, youngs_modulus=1e6, poisson_ratio=0.3),
        plane=Plane(normal=(np.sin(t), np.cos(t), 0.0), offset=0.0, friction=mu),
        initial=Initial(clearance=0.0, rotation=(0.0, 0.0, -theta_deg)),
        time=TimeSpec(dt=0.01, duration=kw.pop("duration", 0.6)), **kw)


def assert_ranges_match_one_launch(solver, kernel, inputs: list, offsets: dict[int, int]) -> None:
    """A per-element Hessian kernel launched over element ranges from 1 and 2 threads (`ElementRanges`) fills
    solver.elem_blocks bitwise as one launch does, at its first launch (ranges in turn) and later ones (threads);
    `inputs` end before the output blocks, `offsets` as `ElementRanges.launch` takes them."""
    from frictionbench.solvers.full.assembly import ElementRanges

    ref = None
    for threads in (1, 2):
        ranges = ElementRanges(solver.model.tets.shape[0], solver.device, threads)
        assert ranges.threads == threads
        for _ in range(2):  # a kernel's first launch runs the ranges in turn, later ones in parallel threads
            solver.elem_blocks.zero_()
            ranges.launch(kernel, inputs + [solver.elem_blocks], offsets)
            if ref is None:
                ref = solver.elem_blocks.numpy().copy()
                assert np.abs(ref).max() > 0
            assert np.array_equal(solver.elem_blocks.numpy(), ref)


def com_series(traj, mass):
    """Centre of mass per frame, (F, 3) [m]."""
    return np.einsum("n,fnk->fk", mass, traj.x) / mass.sum()


def free_flight(duration: float) -> Scenario:
    """The block spinning and drifting in free flight (no plane, no gravity, soft: E 20 kPa), stepped by 10 ms for
    `duration` [s]: momentum is exact, energy may only fall."""
    return Scenario(name="free_flight", mesh=MeshSpec("block", "coarse"), plane=None, gravity=(0.0, 0.0, 0.0),
                    material=Material(youngs_modulus=2e4),
                    initial=Initial(velocity=(0.3, -0.1, 0.2), angular_velocity=(1.0, 4.0, -2.0)),
                    time=TimeSpec(dt=0.01, duration=duration))

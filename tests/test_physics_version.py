"""The guard of PHYSICS_VERSION (`solvers.version`), which keys the truth store: the first member's coarsest
truth-ladder level (the suite's `[truth]` settings) of each guarded suite (quick-undamped: contact lagged at the step's
start; quick: at its fixed point, material and contact damping), cut to GUARD_DURATION of simulated time,
recomputed and compared with the numbers tests/data/physics_guard.json recorded, with the version, when it was
written. A change that moves
the trajectory and leaves the version as it was fails here: bump PHYSICS_VERSION and regenerate the fixture with

    python tests/test_physics_version.py --regenerate
"""

from __future__ import annotations

import argparse
import json
from dataclasses import replace
from pathlib import Path

import numpy as np
import pytest

from frictionbench.bench.runner import REFERENCE, Task, execute, ladder_variant
from frictionbench.scenarios.atomic import write_json_atomic
from frictionbench.scenarios.meshes import bbox_diagonal, load_mesh
from frictionbench.scenarios.suites import load_suite
from frictionbench.solvers.version import PHYSICS_VERSION

FIXTURE = Path(__file__).parent / "data" / "physics_guard.json"
REGENERATE = "python tests/test_physics_version.py --regenerate"
#: The guarded suite (its first member, at its truth's level 0) and the simulated time kept [s]: the cheese falls
#: 5 cm in 0.10 s, so the run ends after 0.1 s of contact and friction
GUARD_SUITES, GUARD_DURATION = ("quick-undamped", "quick"), 0.2
#: Largest difference of a recorded number allowed [fraction of L] (round-off of another BLAS build, not physics)
TOL_REL = 1e-9


def guarded_numbers(name: str) -> dict:
    """Recompute suite `name`'s guarded run: {physics_version, suite, member, key (its store key), frames, L [m],
    final_mean (3,) [m], final_rms (about the mean) [m], vertices {index: (3,) [m]} at the last frame}."""
    suite = load_suite(name)
    member, spec = suite.scenarios[0], suite.truth
    level = ladder_variant(member.scenario, spec.integrator, 0, tol=spec.level_tol(0), lag=spec.contact_lag)
    sc = replace(level, overrides=level.overrides | {"time.duration": GUARD_DURATION}).scenario(member.scenario)
    mesh = load_mesh(sc.mesh)
    task = Task(sc, REFERENCE, spec.solver_params)
    result = execute(task, mesh, (), "cpu")
    if result.trajectory is None:
        raise RuntimeError(f"the guarded run failed: {result.stats['failure']}")
    x = result.trajectory.x[-1]
    n = x.shape[0]
    return {"physics_version": PHYSICS_VERSION, "suite": name, "member": member.scenario.name,
            "key": task.key, "frames": result.trajectory.n_frames, "L": bbox_diagonal(mesh.X),
            "final_mean": x.mean(axis=0).tolist(),
            "final_rms": float(np.sqrt(np.mean(np.sum((x - x.mean(axis=0)) ** 2, axis=1)))),
            "vertices": {str(i): x[i].tolist() for i in (0, n // 2, n - 1)}}


def moved(now: dict, then: dict) -> list[str]:
    """The recorded numbers of `then` that `now` differs from by more than TOL_REL x L (names and values)."""
    tol = TOL_REL * then["L"]
    pairs = [("frames", now["frames"], then["frames"]), ("final_rms", now["final_rms"], then["final_rms"])]
    pairs += [(f"final_mean[{k}]", a, b) for k, (a, b) in enumerate(zip(now["final_mean"], then["final_mean"]))]
    pairs += [(f"vertex {i}[{k}]", a, b) for i in then["vertices"]
              for k, (a, b) in enumerate(zip(now["vertices"][i], then["vertices"][i]))]
    return [f"{name}: {a!r} (recorded {b!r})" for name, a, b in pairs if abs(a - b) > tol]


@pytest.mark.parametrize("name", GUARD_SUITES)
def test_the_trajectory_moves_only_with_the_physics_version(name: str):
    then = json.loads(FIXTURE.read_text())[name]
    now = guarded_numbers(name)
    assert now["key"] == then["key"], (
        f"the guarded run's settings changed ({then['member']} of {then['suite']}, key {then['key']} -> "
        f"{now['key']}: its scene, the suite's [truth] or the guard itself): regenerate the fixture with `{REGENERATE}` "
        "(a changed scene has a new store key; only a change of what a key computes needs a new PHYSICS_VERSION)")
    changes = moved(now, then)
    assert then["physics_version"] == PHYSICS_VERSION or changes, (
        f"PHYSICS_VERSION is {PHYSICS_VERSION} and the fixture records {then['physics_version']}: regenerate it "
        f"with `{REGENERATE}`")
    assert not changes, (
        "the guarded trajectory moved:\n  " + "\n  ".join(changes) + "\n"
        + (f"bump PHYSICS_VERSION in solvers/version.py (now {PHYSICS_VERSION}: the truth store would reuse truths "
           f"computed before this change), then regenerate the fixture with `{REGENERATE}`"
           if then["physics_version"] == PHYSICS_VERSION else
           f"PHYSICS_VERSION was bumped ({then['physics_version']} -> {PHYSICS_VERSION}): regenerate the fixture "
           f"with `{REGENERATE}`"))


def test_a_moved_number_is_caught_and_round_off_is_not():
    then = json.loads(FIXTURE.read_text())[GUARD_SUITES[0]]
    nudged = json.loads(json.dumps(then))
    nudged["vertices"]["0"][1] += 10 * TOL_REL * then["L"]
    assert moved(nudged, then) == [f"vertex 0[1]: {nudged['vertices']['0'][1]!r} (recorded {then['vertices']['0'][1]!r})"]
    nudged = json.loads(json.dumps(then))
    nudged["final_rms"] += 0.1 * TOL_REL * then["L"]
    assert moved(nudged, then) == []


if __name__ == "__main__":
    parser = argparse.ArgumentParser(description="regenerate the physics guard's fixture (after bumping "
                                                 "PHYSICS_VERSION in solvers/version.py)")
    parser.add_argument("--regenerate", action="store_true", required=True)
    parser.parse_args()
    write_json_atomic(FIXTURE, {name: guarded_numbers(name) for name in GUARD_SUITES})
    print(f"wrote {FIXTURE} (PHYSICS_VERSION {PHYSICS_VERSION})")

"""Offline preparation of solver variants: train reduced models (or build bases) on the suite's training split.

`prepare_variants` turns each requested `Variant` into the concrete run parameters per mesh shape (e.g. the path
of a trained checkpoint), training once per (shape, settings, training runs) and caching the result under
`models_dir`. A variant trains on the training members' references (the scene's step), on their truths (the
finest run of each member's truth ladder), or on `family:N`, N scenes per shape drawn across the family the
training members span (`family_scenarios`: plane tilts and downhill directions, friction, the body's yaw), each run
by the full-space solver at the scene's step, as its `training` says (`training_kind`). A variant that needs training
data its shape does not have resolves to None, or to an `Unprepared` saying why (a failed row with the reason).
"""

from __future__ import annotations

from collections.abc import Mapping, Sequence
from dataclasses import dataclass
from pathlib import Path

import numpy as np

from frictionbench.bench.store import RunStore
from frictionbench.scenarios.load import scenario_from_dict, scenario_to_dict
from frictionbench.scenarios.spec import Scenario
from frictionbench.scenarios.suites import Suite, SuiteMember
from frictionbench.solvers.registry import get_solver

#: What a reduced variant's model trains on (`bench.runner.Variant.training`): each training member's reference
#: (the full-space run at the scene's step), or its truth (the finest good run of its truth ladder, whose frames fall
#: on the reference's frame times).
TRAINING_DATA: tuple[str, ...] = ("reference", "truth")
#: `training = "family:N"`: N drawn scenes per shape (`family_scenarios`), at most FAMILY_MAX.
FAMILY, FAMILY_MAX = "family", 1024
#: The seed of the family's draws (with N: `family:4` and `family:16` draw different scenes).
FAMILY_SEED = 0


def training_kind(training: str) -> tuple[str, int | None]:
    """(kind, N) of a variant's `training`: ("reference", None), ("truth", None) or ("family", N) for "family:N";
    ValueError naming the value otherwise."""
    kind, _, count = training.partition(":")
    if training in TRAINING_DATA:
        return training, None
    if kind == FAMILY and count.isdigit() and 1 <= int(count) <= FAMILY_MAX:
        return FAMILY, int(count)
    raise ValueError(f"training {training!r}: expected one of {list(TRAINING_DATA)} or '{FAMILY}:N' "
                     f"(N from 1 to {FAMILY_MAX})")


def family_scenarios(suite: Suite, n: int, seed: int = FAMILY_SEED) -> dict[str, list[Scenario]]:
    """N scenes per mesh shape drawn across the family of the suite's training members of that shape, by shape:
    each the shape's first training member with its plane tilted by an angle drawn uniformly between the members'
    smallest and largest tilt (from the up direction, -gravity) towards a downhill direction drawn uniformly round
    the vertical, its friction coefficient uniform between theirs, and the body turned about the vertical by a yaw
    drawn uniformly (added to its initial rotation's y angle). The held-out members take no part; the draws are
    seeded (`seed`, N). Named `<suite>/family<N>-<shape>-<i>`."""
    rng = np.random.default_rng([seed, n])
    by_shape: dict[str, list[SuiteMember]] = {}
    for m in suite.train:
        if m.scenario.plane is not None:
            by_shape.setdefault(shape_of(m), []).append(m)
    out: dict[str, list[Scenario]] = {}
    for shape, members in sorted(by_shape.items()):
        base = members[0].scenario
        up = -np.asarray(base.gravity, dtype=float) / np.linalg.norm(base.gravity)
        tilts = [float(np.arccos(np.clip(np.dot(np.asarray(m.scenario.plane.normal) /
                                              np.linalg.norm(m.scenario.plane.normal), up), -1.0, 1.0)))
                 for m in members]
        mus = [m.scenario.plane.friction for m in members]
        a = np.cross(up, [1.0, 0.0, 0.0] if abs(up[0]) < 0.9 else [0.0, 0.0, 1.0])
        a /= np.linalg.norm(a)
        b = np.cross(up, a)
        scenes = []
        for i in range(n):
            tilt, azimuth = rng.uniform(min(tilts), max(tilts)), rng.uniform(0.0, 2.0 * np.pi)
            mu, yaw = rng.uniform(min(mus), max(mus)), rng.uniform(0.0, 360.0)
            normal = np.cos(tilt) * up + np.sin(tilt) * (np.cos(azimuth) * a + np.sin(azimuth) * b)
            d = scenario_to_dict(base)
            d["name"] = f"{suite.name}/{FAMILY}{n}-{shape}-{i}"
            d["plane"] |= {"normal": [float(c) for c in normal], "friction": float(mu)}
            rx, ry, rz = d["initial"]["rotation"]
            d["initial"]["rotation"] = [rx, float(ry + yaw), rz]
            scenes.append(scenario_from_dict(d, source=f"training family of {suite.name}"))
        out[shape] = scenes
    return out

#: The failure of a variant's rows on a shape it has no entry for (no training runs there, or none trained).
NO_MODEL = "no reduced model for this mesh shape"


@dataclass(frozen=True)
class Unprepared:
    """A variant that cannot be prepared for a mesh shape, and why: its rows on that shape's members are failed
    rows with `reason`."""

    shape: str
    reason: str


def shape_of(member: SuiteMember) -> str:
    """The mesh shape a member's reduced models are trained per (its mesh name, else its mesh key)."""
    return member.scenario.mesh.name or member.scenario.mesh.key


def training_runs(suite: Suite, refs: dict, store: RunStore, ladders: Mapping | None = None,
                  data: str = "reference", family: Mapping[str, Mapping[str, Sequence]] | None = None
                  ) -> dict[str, list[Path] | str]:
    """Stored full-space trajectories of the training split, grouped by mesh shape name: with `data` "reference"
    each member's reference run (`refs`, by scenario name; members whose run is not stored are left out); with
    "truth" each member's truth, the last good run of the first ladder of `ladders` (scenario -> integrator ->
    `bench.runner.Ladder`, the truth's first), and in place of a shape's paths the reason where one of its training
    members has none (a run without a truth, or a truth ladder whose first run failed); with "family:N" the stored
    runs of `family[data]` (shape -> the tasks of `family_scenarios`), a shape's reason where one failed."""
    kind, _ = training_kind(data)
    groups: dict[str, list[Path] | str] = {}
    if kind == FAMILY:
        for shape, tasks in (family or {}).get(data, {}).items():
            failed = [t.scenario.name for t in tasks
                      if not store.done(t.key) or not (store.folder(t.key) / "trajectory.npz").is_file()]
            groups[shape] = (f"family training run {failed[0]} did not finish" if failed
                             else [store.folder(t.key) / "trajectory.npz" for t in tasks])
        return groups
    for m in suite.train:
        shape = shape_of(m)
        if data == "reference":
            key = refs[m.scenario.name].key
        else:
            by = (ladders or {}).get(m.scenario.name)
            truth = next(iter(by.values())) if by else None
            key = truth.tasks[-1].key if truth is not None and truth.tasks else None
            if key is None or not store.done(key):
                reason = ("the run has no truth (--no-truth, or a suite without [truth])" if by is None
                          else "its truth ladder's first run failed")
                if not isinstance(groups.get(shape), str):  # the shape's first member without one names it
                    groups[shape] = f"training member {m.scenario.name} has no truth to train on: {reason}"
                continue
        if store.done(key) and not isinstance(groups.get(shape), str):
            groups.setdefault(shape, []).append(store.folder(key) / "trajectory.npz")
    return groups


def prepare_variants(suite: Suite, variants: Sequence, store: RunStore, refs: dict, models_dir: Path,
                     device: str, ladders: Mapping | None = None, family: Mapping | None = None
                     ) -> list[tuple[object, dict | Unprepared | None]]:
    """(variant, params) pairs: params completed by the solver's `prepare` (training, on the training data the
    variant's `training` names; `ladders` are the run's truth ladders, `bench.runner.run_ladders`; `family` the
    tasks of its family training runs by `training` and shape), None if its
    prepare gives none, or an `Unprepared` with the reason where the shape lacks the training data.

    A variant whose solver prepares per shape gets one entry per shape, its params carrying `shape`; the runner
    applies an entry only to the members of that shape.
    """
    groups: dict[str, dict[str, list[Path] | str]] = {}
    out: list[tuple[object, dict | Unprepared | None]] = []
    for v in variants:
        solver = get_solver(v.solver)(device=device, **v.params)
        if not solver.needs_training:
            out.append((v, dict(v.params)))
            continue
        if v.training not in groups:
            groups[v.training] = training_runs(suite, refs, store, ladders, v.training, family)
        for shape, paths in sorted(groups[v.training].items()):
            if isinstance(paths, str):
                out.append((v, Unprepared(shape, paths)))
                continue
            extra = solver.prepare(shape, paths, Path(models_dir), suite.name)
            out.append((v, None if extra is None else dict(v.params) | extra))
    return out

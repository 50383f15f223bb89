"""Offline preparation of solver variants: train reduced models (or build bases) on the suite's training split.

`prepare_variants` turns each requested `Variant` into the concrete run parameters per mesh shape (e.g. the path
of a trained checkpoint), training once per (shape, settings, training runs) and caching the result under
`models_dir`. A variant trains on the training members' references (the scene's step) or on their truths (the
finest run of each member's truth ladder), as its `training` says (`TRAINING_DATA`). A variant that needs training
data its shape does not have resolves to None, or to an `Unprepared` saying why (a failed row with the reason).
"""

from __future__ import annotations

from collections.abc import Mapping, Sequence
from dataclasses import dataclass
from pathlib import Path

from frictionbench.bench.store import RunStore
from frictionbench.scenarios.suites import Suite, SuiteMember
from frictionbench.solvers.registry import get_solver

#: What a reduced variant's model trains on (`bench.runner.Variant.training`): each training member's reference
#: (the full-space run at the scene's step), or its truth (the finest good run of its truth ladder, whose frames fall
#: on the reference's frame times).
TRAINING_DATA: tuple[str, ...] = ("reference", "truth")

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
                  data: str = "reference") -> dict[str, list[Path] | str]:
    """Stored full-space trajectories of the training split, grouped by mesh shape name: with `data` "reference"
    each member's reference run (`refs`, by scenario name; members whose run is not stored are left out); with
    "truth" each member's truth, the last good run of the first ladder of `ladders` (scenario -> integrator ->
    `bench.runner.Ladder`, the truth's first), and in place of a shape's paths the reason where one of its training
    members has none (a run without a truth, or a truth ladder whose first run failed)."""
    if data not in TRAINING_DATA:
        raise ValueError(f"training data {data!r} not one of {list(TRAINING_DATA)}")
    groups: dict[str, list[Path] | str] = {}
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
                     device: str, ladders: Mapping | None = None) -> list[tuple[object, dict | Unprepared | None]]:
    """(variant, params) pairs: params completed by the solver's `prepare` (training, on the training data the
    variant's `training` names; `ladders` are the run's truth ladders, `bench.runner.run_ladders`), None if its
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
            groups[v.training] = training_runs(suite, refs, store, ladders, v.training)
        for shape, paths in sorted(groups[v.training].items()):
            if isinstance(paths, str):
                out.append((v, Unprepared(shape, paths)))
                continue
            extra = solver.prepare(shape, paths, Path(models_dir), suite.name)
            out.append((v, None if extra is None else dict(v.params) | extra))
    return out

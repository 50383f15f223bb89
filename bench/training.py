"""Offline preparation of solver variants: train reduced models (or build bases) on the suite's training split.

`prepare_variants` turns each requested `Variant` into the concrete run parameters per mesh shape (e.g. the path
of a trained checkpoint), training once per (shape, settings) and caching the result under `models_dir`.
A variant that needs training data its shape does not have resolves to None (a failed row with the reason).
"""

from __future__ import annotations

from collections.abc import Sequence
from pathlib import Path

from frictionbench.bench.store import RunStore
from frictionbench.scenarios.suites import Suite
from frictionbench.solvers.registry import get_solver


def training_runs(suite: Suite, refs: dict, store: RunStore) -> dict[str, list[Path]]:
    """Stored full-space trajectories of the training split, grouped by mesh shape name."""
    groups: dict[str, list[Path]] = {}
    for m in suite.train:
        key = refs[m.scenario.name].key
        if store.done(key):
            groups.setdefault(m.scenario.mesh.name or m.scenario.mesh.key, []).append(
                store.folder(key) / "trajectory.npz")
    return groups


def prepare_variants(suite: Suite, variants: Sequence, store: RunStore, refs: dict, models_dir: Path,
                     device: str) -> list[tuple[object, dict | None]]:
    """(variant, params) pairs: params completed by the solver's `prepare` (training) or None if impossible.

    A variant whose solver prepares per shape gets one entry per shape, its params carrying `shape`; the runner
    applies an entry only to the members of that shape.
    """
    groups = training_runs(suite, refs, store)
    out = []
    for v in variants:
        solver = get_solver(v.solver)(device=device, **v.params)
        if not solver.needs_training:
            out.append((v, dict(v.params)))
            continue
        for shape, paths in sorted(groups.items()):
            extra = solver.prepare(shape, paths, Path(models_dir), suite.name)
            out.append((v, None if extra is None else dict(v.params) | extra))
    return out

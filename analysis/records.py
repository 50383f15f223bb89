"""The records row building reads: every run of a suite resolved by the harness (`bench.runner.run_records`) into
flat data before any row is built, so that rows are a map from records and stored trajectories, and analysis asks
the harness nothing.

A `RunRecord` is one solver variant on one member: its identity (member, solver, variant label), its store key
(or why it has no run), the scenario it ran (the variant's changes applied), the full-space run it is compared
with, whether it is carried onto that run's mesh first, the columns that describe it (`columns`: its mesh, its
rank, its trained model, what it learned from) and opaque `tags` its rows carry as they are (a curve's point:
`analysis.curves`). A member's reference and its truth ladders are the harness's tasks (`RunTask`, `LadderRuns`),
which hold data only.
"""

from __future__ import annotations

from collections.abc import Sequence
from dataclasses import dataclass, field
from typing import Protocol

from frictionbench.scenarios.spec import MeshSpec, Scenario
from frictionbench.solvers.trajectory import Trajectory


class RunTask(Protocol):
    """One run of the harness (`bench.runner.Task`): its scenario, solver, mesh (None: the scenario's) and store
    key."""

    scenario: Scenario
    solver: str
    mesh: MeshSpec | None

    @property
    def key(self) -> str: ...


class LadderRuns(Protocol):
    """A member's truth ladder with one integrator (`bench.runner.Ladder`): its finished runs level by level, the
    differences d_k between successive levels [fraction of L], whether a run failed, and the per-frame difference
    (t (F,) [s], d (F,) [fraction of L]) of its last two levels."""

    integrator: str
    tasks: Sequence[RunTask]
    differences: Sequence[float]
    failed: bool
    frame_differences: tuple | None


class Trajectories(Protocol):
    """Stored runs by key (`bench.store.RunStore`): (trajectory or None, stats)."""

    def load(self, key: str) -> tuple[Trajectory | None, dict]: ...


@dataclass(frozen=True)
class RunRecord:
    """One solver variant on one member of a suite, resolved (module doc).

    member: the member's scenario name; solver and variant: the row's identity; key: the run's store key, or None
    with `failure` saying why it has none (no trained model for the member's shape, a change the scene refuses);
    scenario: the scenario the run simulates (None without a run); compare_key: the store key of the full-space run
    its metrics are taken against (the reference, or the full-space run on the variant's other mesh);
    transfer: carried onto the reference's mesh before any comparison; other_mesh: run on a mesh other than the
    truth's, and compared there with its own mesh's full-space run; columns: the row's descriptive cells (mesh, r,
    remesh, model, remesh_of, train_mesh, train_data); tags: cells carried as they are."""

    member: str
    solver: str
    variant: str
    key: str | None = None
    failure: str = ""
    scenario: Scenario | None = None
    compare_key: str = ""
    transfer: bool = False
    other_mesh: bool = False
    columns: dict = field(default_factory=dict)
    tags: dict = field(default_factory=dict)

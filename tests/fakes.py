"""Stand-ins for the harness's objects that row building reads (`analysis.rows`), shared by the tests that build rows
from made-up runs."""

from __future__ import annotations

from dataclasses import dataclass

from frictionbench.solvers.trajectory import Trajectory


@dataclass
class FakeLadder:
    """A truth ladder as row building reads it (`analysis.records.LadderRuns`)."""

    integrator: str
    tasks: list
    differences: list
    failed: bool = False
    frame_differences: tuple | None = None


class FakeStore:
    """Stored runs by key, as `bench.store.RunStore.load` gives them."""

    def __init__(self, runs: dict) -> None:
        self.runs = runs

    def load(self, key: str) -> tuple[Trajectory, dict]:
        return self.runs[key]

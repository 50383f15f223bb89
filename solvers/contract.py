"""The solver contract every solver of the benchmark follows (in the spirit of benchopt's solver classes and of
Newton's `solver.step(state_in, state_out, dt)`).

A solver is a `Solver` subclass that declares its `name`, its `parameters` (name -> default; a variant sets
some of them), its `experimental` ones (the same, for studies of the solver rather than its use: a matrix file sets
them in an entry's `experimental` table only, so that no user set reaches one by accident) and the time `integrators` it implements (names in `solvers.integrators`; backward Euler unless it
says more: a scene asking for another is skipped with the reason), the packages it `requires` (import names beyond
the benchmark's own dependencies: without one it is listed as unavailable, and its variants are skipped, with the
reason; `solvers.registry`), and implements `setup(model)` (untimed: build what the run needs on this model) and
`step(state_in, state_out, dt) -> StepStats`. Optional: `skip(model)` says why a scene cannot be run, `prepare`
does offline work once per mesh shape (training, bases, cubature) writing its artefacts into the run's output
folder, `initial(state)` adds a solver's own coordinates to the initial state, and `describe()` gives provenance
for the run's stats. Registering the class (`solvers.registry.register`, or the entry-point group
`frictionbench.solvers` of an installed package) is all the harness needs: the CLI, the runner and the reports never
name a solver.
"""

from __future__ import annotations

from abc import ABC, abstractmethod
from collections.abc import Mapping
from pathlib import Path
from typing import Any, ClassVar

import numpy as np

from frictionbench.solvers.model import Model, State
from frictionbench.solvers.step_stats import StepStats


class SolverParameterError(ValueError):
    """A solver was given a parameter it does not declare."""


#: The largest count (of iterations, substeps) a solver parameter may ask for per step.
MAX_COUNT = 100_000


def check_count(solver: str, key: str, value: Any) -> int:
    """`value` of the parameter `key` of `solver` as a count per step: an integer from 1 to MAX_COUNT, else an
    error naming the solver, the parameter and the value."""
    if isinstance(value, bool) or not isinstance(value, int) or not 1 <= value <= MAX_COUNT:
        raise ValueError(f"solver {solver!r}: {key} = {value!r}: expected an integer from 1 to {MAX_COUNT}")
    return value


class Solver(ABC):
    """Base class of the solver contract; see the module docstring.

    device: where it computes (`cpu` or `cuda`); params: values for some of the declared `parameters` and
    `experimental` ones (an unknown name is an error naming it). `basis` is the subspace (n, 3, r) [m per unit q] of a solver with latent
    coordinates once set up (x = X + basis q), stored with its trajectory; None for a full-space solver.
    """

    name: ClassVar[str] = ""
    parameters: ClassVar[Mapping[str, Any]] = {}
    experimental: ClassVar[Mapping[str, Any]] = {}
    integrators: ClassVar[tuple[str, ...]] = ("backward-euler",)
    requires: ClassVar[tuple[str, ...]] = ()
    #: The frame `basis` is in: "world" (x = X + basis q) or "body" (its deformation columns turn with the body,
    #: `solvers.reduced.frame`); the projection error fits the truth in it.
    basis_frame: ClassVar[str] = "world"

    def __init__(self, device: str = "cpu", **params: Any) -> None:
        unknown = sorted(set(params) - set(self.parameters) - set(self.experimental))
        if unknown:
            raise SolverParameterError(f"solver {self.name!r}: unknown parameter(s) {unknown}; it takes "
                                       f"{sorted(self.parameters)} (experimental: {sorted(self.experimental)})")
        self.device = device
        self.params: dict[str, Any] = dict(self.parameters) | dict(self.experimental) | params
        self.basis: np.ndarray | None = None

    def skip(self, model: Model) -> str | None:
        """Why this solver cannot run `model` (None: it can)."""
        return None

    def prepare(self, shape: str, trajectories: list[Path], out_dir: Path, suite: str) -> dict | None:
        """Offline work for one mesh shape from the suite's training trajectories (untimed), artefacts written
        under `out_dir` (inside the run's output folder); returns the parameters its runs take (e.g. an
        artefact's path), merged into the variant's, or None when the shape cannot be prepared. The default
        prepares nothing and returns no parameters, for every shape."""
        return {}

    @property
    def needs_training(self) -> bool:
        """Whether `prepare` is per mesh shape (its runs then carry `shape` and apply to that shape only)."""
        return type(self).prepare is not Solver.prepare

    @abstractmethod
    def setup(self, model: Model) -> None:
        """Build what the run needs on `model` (untimed)."""

    def initial(self, state: State) -> State:
        """The initial state as this solver starts from it (a solver with latent coordinates adds them)."""
        return state

    @abstractmethod
    def step(self, state_in: State, state_out: State, dt: float) -> StepStats:
        """Advance state_in by dt [s] into state_out; the step's statistics."""

    def describe(self) -> dict:
        """Provenance of the run, merged into its stats (JSON-serialisable): the solver's name and every parameter
        value it ran with (defaults included); subclasses add what they resolved during setup."""
        return {"solver": self.name, "parameters": dict(self.params)}

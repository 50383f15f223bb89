"""The solver registry: solver name -> its `solvers.contract.Solver` class, the one place solvers are listed.

Entries are import paths (`module:Class`), imported on first use, so that torch loads only when a
reduced solver runs, and so that a worker process can import a solver registered elsewhere (`entries`,
`register_entries`). The harness never special-cases a solver: it looks it up here by name.

Three sources, later ones winning for a name they share: the solvers an installed package declares in the entry-point
group `frictionbench.solvers` (`name = "module:Class"` in its `[project.entry-points."frictionbench.solvers"]`,
read once per process), this repository's own (`_ENTRIES`), and those `register`ed at run time. A solver whose
module does not import, or which `requires` a package that is not installed, is unavailable:
`get_solver` raises `SolverUnavailable` with the reason, which `unavailable` returns.
"""

from __future__ import annotations

import importlib
import importlib.metadata
import importlib.util
from functools import cache

from frictionbench.solvers.contract import Solver

#: The entry-point group through which an installed package registers solvers.
ENTRY_POINT_GROUP = "frictionbench.solvers"

_ENTRIES: dict[str, str] = {
    "full": "frictionbench.solvers.full.plugin:FullSpace",
    "licrom": "frictionbench.solvers.licrom.plugin:Licrom",
    "pod": "frictionbench.solvers.reduced.pod:Pod",
    "pod-frame": "frictionbench.solvers.reduced.pod:PodFrame",
    "affine": "frictionbench.solvers.reduced.pod:Affine",
    "modal": "frictionbench.solvers.reduced.modal:Modal",
    "modal-frame": "frictionbench.solvers.reduced.modal:ModalFrame",
}


class SolverUnavailable(ValueError):
    """A registered solver cannot run here: its module does not import, or a package it requires is missing."""

    def __init__(self, name: str, reason: str) -> None:
        super().__init__(f"solver {name!r} is unavailable: {reason}")
        self.reason = reason


@cache
def installed() -> dict[str, str]:
    """Solvers of installed packages (the entry-point group `ENTRY_POINT_GROUP`): name -> import path."""
    return {ep.name: ep.value for ep in importlib.metadata.entry_points(group=ENTRY_POINT_GROUP)}


def register(cls: type[Solver]) -> type[Solver]:
    """Add (or replace) the solver class under its `name`; usable as a class decorator."""
    if not (isinstance(cls, type) and issubclass(cls, Solver)) or not cls.name:
        raise TypeError(f"{cls!r}: a solver is a solvers.contract.Solver subclass with a non-empty `name`")
    _ENTRIES[cls.name] = f"{cls.__module__}:{cls.__qualname__}"
    return cls


def entries() -> dict[str, str]:
    """Every registered solver: name -> import path (what a worker process needs to register them too)."""
    return installed() | _ENTRIES


def register_entries(paths: dict[str, str]) -> None:
    """Register solvers by import path (the `entries` of another process)."""
    _ENTRIES.update(paths)


def solver_names() -> list[str]:
    """Names of the registered solvers (available or not)."""
    return list(entries())


def _requirement_missing(package: str) -> str | None:
    """Why the package (an import name) cannot be used here, None if it can: whether it is installed, asked of
    the import system without importing it (so that a solver's heavy packages, torch for `licrom`, load only when
    it runs: where they load first changes which thread pools and library modes they take)."""
    if importlib.util.find_spec(package) is None:
        return f"needs {package!r}, which is not installed"
    return None


def get_solver(name: str) -> type[Solver]:
    """The solver class registered as `name`; a clear error lists the known ones. Raises `SolverUnavailable`
    (with the reason) where its module does not import, its path names no `Solver` subclass of that name (a broken
    plug-in must not break the others), or a package it `requires` is missing."""
    try:
        path = entries()[name]
    except KeyError:
        raise ValueError(f"solver = {name!r}: unknown; known solvers: {sorted(entries())}") from None
    module, _, qualname = path.partition(":")
    try:
        obj = importlib.import_module(module)
    except ImportError as err:
        raise SolverUnavailable(name, f"its module {module} does not import ({err})") from err
    for part in qualname.split("."):
        obj = getattr(obj, part, None)
    if not (isinstance(obj, type) and issubclass(obj, Solver)) or obj.name != name:
        raise SolverUnavailable(name, f"{path} is not a solvers.contract.Solver subclass named {name!r}")
    for package in obj.requires:
        reason = _requirement_missing(package)
        if reason:
            raise SolverUnavailable(name, reason)
    return obj


def unavailable(name: str) -> str | None:
    """Why the registered solver `name` cannot run here (`SolverUnavailable`'s reason), or None when it can."""
    try:
        get_solver(name)
    except SolverUnavailable as err:
        return err.reason
    return None

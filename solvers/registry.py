"""The solver registry: solver name -> its `solvers.contract.Solver` class, the one place solvers are listed.

Entries are import paths (`module:Class`), imported on first use, so that torch and taichi load only when a
reduced solver runs, and so that a worker process can import a solver registered elsewhere (`entries`,
`register_entries`). The harness never special-cases a solver: it looks it up here by name.
"""

from __future__ import annotations

import importlib

from solvers.contract import Solver

_ENTRIES: dict[str, str] = {
    "full": "solvers.full.plugin:FullSpace",
    "licrom": "solvers.licrom.plugins:Licrom",
    "pod": "solvers.licrom.plugins:Pod",
    "affine": "solvers.licrom.plugins:Affine",
}


def register(cls: type[Solver]) -> type[Solver]:
    """Add (or replace) the solver class under its `name`; usable as a class decorator."""
    if not (isinstance(cls, type) and issubclass(cls, Solver)) or not cls.name:
        raise TypeError(f"{cls!r}: a solver is a solvers.contract.Solver subclass with a non-empty `name`")
    _ENTRIES[cls.name] = f"{cls.__module__}:{cls.__qualname__}"
    return cls


def entries() -> dict[str, str]:
    """Every registered solver: name -> import path (what a worker process needs to register them too)."""
    return dict(_ENTRIES)


def register_entries(paths: dict[str, str]) -> None:
    """Register solvers by import path (the `entries` of another process)."""
    _ENTRIES.update(paths)


def solver_names() -> list[str]:
    """Names of the registered solvers."""
    return list(_ENTRIES)


def get_solver(name: str) -> type[Solver]:
    """The solver class registered as `name`; a clear error lists the known ones."""
    try:
        module, _, qualname = _ENTRIES[name].partition(":")
    except KeyError:
        raise ValueError(f"solver = {name!r}: unknown; known solvers: {sorted(_ENTRIES)}") from None
    obj = importlib.import_module(module)
    for part in qualname.split("."):
        obj = getattr(obj, part)
    return obj

"""Solver plug-ins: one entry per solver name; the harness never special-cases a solver.

A plug-in is a function `setup(model, device, **params) -> stepper` (untimed); the stepper has `name` and
`step(state_in, state_out, dt) -> StepStats`. The parameter grids the harness runs are named variant sets in
`bench.variants`; `PREPARE[name]` is a solver's offline step (training), run once per mesh shape.
"""

from __future__ import annotations

from collections.abc import Callable

from solvers.full.solver import FullSpaceSolver, NewtonSettings
from solvers.model import Model


def setup_full(model: Model, device: str = "cpu", tol: float = 1e-5, linear: str = "auto",
               max_iter: int = 200) -> FullSpaceSolver:
    """The full-space Newton solver (the reference)."""
    return FullSpaceSolver(model, device=device, settings=NewtonSettings(tol=tol, linear=linear, max_iter=max_iter))


def _reduced(name: str) -> Callable[..., object]:
    """Lazy import of a reduced plug-in (torch and taichi load only when a reduced solver is used)."""
    def setup(model: Model, device: str = "cpu", **params):
        from solvers.licrom import plugins
        return getattr(plugins, f"setup_{name}")(model, device, **params)
    return setup


def _prepare(name: str) -> Callable[..., dict | None]:
    def prepare(**kw):
        from solvers.licrom import plugins
        return getattr(plugins, f"prepare_{name}")(**kw)
    return prepare


SOLVERS: dict[str, Callable[..., object]] = {
    "full": setup_full, "licrom": _reduced("licrom"), "pod": _reduced("pod"), "affine": _reduced("affine")}
# Offline preparation per mesh shape (training a reduced model, building a basis): name -> hook returning the
# completed run parameters (with `shape`), or None when the shape cannot be prepared.
PREPARE: dict[str, Callable[..., dict | None]] = {"licrom": _prepare("licrom"), "pod": _prepare("pod")}


def get_solver(name: str) -> Callable[..., object]:
    """The setup function of solver `name`; a clear error lists the known ones."""
    try:
        return SOLVERS[name]
    except KeyError:
        raise ValueError(f"solver = {name!r}: unknown; known solvers: {sorted(SOLVERS)}") from None

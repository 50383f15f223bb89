"""The full-space backend's evaluation of the physics terms (`solvers.physics.terms`) with warp kernels: one
`Launcher` per term, derived from what the term declares (`launcher_of`): a `VertexTerm` by the inertia-gravity kernel
(`VertexLauncher`), a `DensityTerm` and a `PointTerm` by the kernels they name (`DensityLauncher`,
`PointLauncher`), any other term, or one that names no kernel, from its numpy reference (`ReferenceLauncher`).

A launcher adds its term at positions x into the solver's buffers (mode 0: the energy into `energy_buf`; mode 1:
the gradient into `grad` and the Hessian's 3x3 blocks into `values`) and keeps what it needs across a step in its
own buffers, filled by `begin_step` from the step's constants (`StepData`): the lagged normal pressure of a point
kernel that takes `fn` (friction), the per-tet array of a density's `TetKernels.at_bar` kernel (viscosity's Green
strain at x_bar). The solver's arrays x_hat, x_lag and x_bar hold the step's positions. A kernel gets its
arguments by name (`solvers.warp_runtime.kernel_inputs`): the solver's arrays (`solver_arrays`), the launch's x, h
and mode, the launcher's own buffers and the term's `kernel_parameters`; it is launched through the solver's
`launches` (`solvers.warp_runtime.Relaunches`: recorded at its first launch, relaunched after).
"""

from __future__ import annotations

from abc import ABC, abstractmethod
from typing import TYPE_CHECKING

import numpy as np
import scipy.sparse as sp
import warp as wp

from frictionbench.solvers import kernels as K
from frictionbench.solvers.physics.terms import DensityTerm, PointTerm, StepData, Term, VertexTerm
from frictionbench.solvers.warp_runtime import kernel_inputs, kernel_named

if TYPE_CHECKING:
    from frictionbench.solvers.full.solver import FullSpaceSolver


class Launcher(ABC):
    """One term on a `FullSpaceSolver`'s warp arrays; see the module docstring."""

    def __init__(self, solver: FullSpaceSolver, term: Term) -> None:
        self.solver, self.term = solver, term

    def begin_step(self, step: StepData) -> None:
        """Take the step's constants (nothing by default)."""

    @abstractmethod
    def launch(self, x: wp.array, h: float, mode: int, inertia: bool, hessian: bool = True) -> None:
        """Add the term at x (n,) vec3d [m]: mode 0 its energy, mode 1 its gradient and Hessian blocks. h is the
        step's effective step h_eff [s]; inertia=False: static equilibrium (no inertia, no rates). hessian=False
        (mode 1): the gradient alone is wanted, so a term may skip its Hessian blocks (the element terms do; the
        point terms' diagonal blocks cost next to nothing and are added regardless: `values` is scratch then)."""


def launcher_of(solver: FullSpaceSolver, term: Term) -> Launcher:
    """The launcher of `term` on `solver`, by the term's kind and the kernels it names."""
    if isinstance(term, VertexTerm):
        return VertexLauncher(solver, term)
    if isinstance(term, DensityTerm) and term.kernels is not None:
        return DensityLauncher(solver, term)
    if isinstance(term, PointTerm) and term.kernel is not None:
        return PointLauncher(solver, term)
    return ReferenceLauncher(solver, term)


def solver_arrays(solver: FullSpaceSolver) -> dict[str, object]:
    """The solver's arrays a kernel may take, by argument name: the step's positions x_hat, x_lag, x_bar (n,) vec3d
    [m], the mesh's tets, Dm_inv, vol [m^3] and masses `mass` [kg], the contact points (vertex ids) `points`,
    their area [m^2] and the plane's `normal`, the block indices `diag` (per vertex) and `blockmap`, the outputs
    `grad`, `values`, `energy` and the per-element Hessian blocks `blocks` (16 per tet)."""
    s = solver
    arrays = {"x_hat": s.x_hat, "x_lag": s.x_lag, "x_bar": s.x_bar, "tets": s.tets, "Dm_inv": s.Dm_inv, "vol": s.vol,
              "mass": s.mass, "points": s.points, "area": s.area, "diag": s.diag, "blockmap": s.blockmap,
              "grad": s.grad, "values": s.values, "energy": s.energy_buf, "blocks": s.elem_blocks}
    if s.model.plane_normal is not None:
        arrays["normal"] = s.normal
    return arrays


class VertexLauncher(Launcher):
    """A `VertexTerm`: the inertia-gravity kernel about its target with 1/tau^2 and its acceleration."""

    def __init__(self, solver: FullSpaceSolver, term: VertexTerm) -> None:
        super().__init__(solver, term)
        self.target = getattr(solver, term.target)
        self.acceleration = wp.vec3d(*term.acceleration(solver.model))

    def launch(self, x: wp.array, h: float, mode: int, inertia: bool, hessian: bool = True) -> None:
        s = self.solver
        s.launches.launch(K.inertia_gravity_kernel, s.model.n, [
            x, self.target, s.mass, 1.0 / self.term.tau2(s.model, h, inertia), self.acceleration, s.diag, s.grad,
            s.values, s.energy_buf, mode])


#: The per-tet arrays of `solver_arrays` (one row per tet; `blocks`, 16), cut to a thread's range of tets by the
#: threaded Hessian launch (`ElementRanges.launch`).
_PER_TET = {"tets": 1, "Dm_inv": 1, "vol": 1, "blocks": 16}


class DensityLauncher(Launcher):
    """A `DensityTerm` by its kernels (`TetKernels`): energy, gradient, then the Hessian blocks per element
    (threaded over ranges of tets) summed into `values`; its `at_bar` array computed once a step. A `rate` term
    launches nothing in static equilibrium."""

    def __init__(self, solver: FullSpaceSolver, term: DensityTerm) -> None:
        super().__init__(solver, term)
        names = term.kernels
        self.energy, self.gradient, self.hessian = (kernel_named(n, K.__name__)
                                                    for n in (names.energy, names.gradient, names.hessian))
        self.arrays = solver_arrays(solver)
        self.at_bar = None if names.at_bar is None else kernel_named(names.at_bar, K.__name__)
        self.per_tet = dict(_PER_TET)
        if self.at_bar is not None:
            out = self.at_bar.adj.args[-1].label
            self.arrays[out] = wp.zeros(solver.model.tets.shape[0], dtype=wp.mat33d, device=solver.device)
            self.per_tet[out] = 1

    def begin_step(self, step: StepData) -> None:
        if self.at_bar is not None:
            s = self.solver
            s.launches.launch(self.at_bar, s.model.tets.shape[0],
                              kernel_inputs(self.at_bar, {**self.arrays, "x": s.x_bar}, self.term.name))

    def launch(self, x: wp.array, h: float, mode: int, inertia: bool, hessian: bool = True) -> None:
        if self.term.rate and not inertia:
            return
        s, m = self.solver, self.solver.model
        values = {**self.arrays, **self.term.kernel_parameters(m, h), "x": x}
        ins = lambda kernel: kernel_inputs(kernel, values, self.term.name)  # noqa: E731
        if mode == 0:
            s.launches.launch(self.energy, m.tets.shape[0], ins(self.energy))
            return
        s.launches.launch(self.gradient, m.tets.shape[0], ins(self.gradient))
        if not hessian:
            return
        if not self.term.kernels.hessian_assigns:
            s.elem_blocks.zero_()
        labels = [arg.label for arg in self.hessian.adj.args]
        s.elements.launch(self.hessian, ins(self.hessian),
                          {i: self.per_tet[label] for i, label in enumerate(labels) if label in self.per_tet})
        s.launches.launch(K.scatter_blocks_kernel, s.elem_blocks.shape[0], [s.elem_blocks, s.blockmap, s.values])


class PointLauncher(Launcher):
    """A `PointTerm` by its kernel over the contact points; a kernel that takes `fn` gets the step's lagged normal
    pressure per contact point [Pa], kept in a buffer of its own."""

    def __init__(self, solver: FullSpaceSolver, term: PointTerm) -> None:
        super().__init__(solver, term)
        self.kernel = kernel_named(term.kernel, K.__name__)
        self.values = {**solver_arrays(solver), **term.kernel_parameters(solver.model)}
        takes_fn = "fn" in (arg.label for arg in self.kernel.adj.args)
        self.fn = wp.zeros(solver.model.points.size, dtype=wp.float64, device=solver.device) if takes_fn else None
        self.values["fn"] = self.fn

    def begin_step(self, step: StepData) -> None:
        if self.fn is not None:
            self.fn.assign(np.ascontiguousarray(step.fn))

    def launch(self, x: wp.array, h: float, mode: int, inertia: bool, hessian: bool = True) -> None:
        s = self.solver
        s.launches.launch(self.kernel, s.model.points.size,
                          kernel_inputs(self.kernel, {**self.values, "x": x, "h": h, "mode": mode}, self.term.name))


class ReferenceLauncher(Launcher):
    """Any term from its numpy reference (`Term.energy`, `gradient`, `hessian`) on the host, at the step's
    positions in the solver's arrays and the lagged pressure of `begin_step`: exact, but a copy of x and a
    full-mesh numpy evaluation per launch. The Hessian must lie in the mesh's block pattern (the tets' vertex pairs
    and the diagonal); ValueError otherwise."""

    def __init__(self, solver: FullSpaceSolver, term: Term) -> None:
        super().__init__(solver, term)
        self.fn: np.ndarray | None = None
        pattern = solver.pattern
        self.keys = pattern.rows.astype(np.int64) * pattern.n + pattern.cols  # sorted row-major

    def begin_step(self, step: StepData) -> None:
        self.fn = step.fn

    def launch(self, x: wp.array, h: float, mode: int, inertia: bool, hessian: bool = True) -> None:
        s, m = self.solver, self.solver.model
        step = StepData(s.x_hat.numpy(), s.x_lag.numpy(), h, self.fn, inertia, s.x_bar.numpy(), h)
        xs = x.numpy()
        if mode == 0:
            s.energy_buf.assign(s.energy_buf.numpy() + self.term.energy(m, step, xs))
            return
        s.grad.assign(s.grad.numpy() + self.term.gradient(m, step, xs))
        if hessian:
            s.values.assign(s.values.numpy() + self._blocks(self.term.hessian(m, step, xs)))

    def _blocks(self, H: sp.spmatrix) -> np.ndarray:
        """The (3n, 3n) matrix H as block values (nnzb, 3, 3) of the solver's pattern."""
        n = self.solver.model.n
        Hb = sp.bsr_matrix(H, blocksize=(3, 3))
        keys = np.repeat(np.arange(n, dtype=np.int64), np.diff(Hb.indptr)) * n + Hb.indices
        at = np.minimum(np.searchsorted(self.keys, keys), self.keys.size - 1)
        if not np.array_equal(self.keys[at], keys):
            raise ValueError(f"term {self.term.name!r}: its Hessian couples vertices outside the mesh's block "
                             f"pattern")
        out = np.zeros((self.keys.size, 3, 3))
        np.add.at(out, at, Hb.data)
        return out

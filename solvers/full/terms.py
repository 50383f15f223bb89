"""The full-space backend's evaluation of the physics terms (`solvers.physics.terms`) with its warp kernels
(`solvers.kernels`): one `Launcher` per term class, in the table `LAUNCHERS` (`@LAUNCHERS.register(TermClass)`).

A launcher adds its term at positions x into the solver's buffers (mode 0: the energy into `energy_buf`; mode 1:
the gradient into `grad` and the Hessian's 3x3 blocks into `values`) and keeps what it needs across a step in its
own buffers, filled by `begin_step` from the step's constants (`StepData`): friction's lagged normal pressure,
viscosity's Green strain at x_bar. The solver's arrays x_hat, x_lag and x_bar hold the step's positions.
"""

from __future__ import annotations

from abc import ABC, abstractmethod
from typing import TYPE_CHECKING

import numpy as np
import warp as wp

from frictionbench.solvers import kernels as K
from frictionbench.solvers.physics.contact import BarrierContact, ContactDamping, PenaltyContact
from frictionbench.solvers.physics.friction import Friction
from frictionbench.solvers.physics.inertia import Gravity, Inertia
from frictionbench.solvers.physics.material import Elasticity
from frictionbench.solvers.physics.terms import StepData, Term, TermTable
from frictionbench.solvers.physics.viscosity import Viscosity

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


#: The launcher of each term class (`LAUNCHERS.build(solver, terms)`: one per term).
LAUNCHERS: TermTable[Launcher] = TermTable("full-space launcher (solvers.full.terms.LAUNCHERS)")


def _scatter_element_blocks(solver: FullSpaceSolver) -> None:
    """Add the per-element Hessian blocks `elem_blocks` into the block matrix `values`."""
    wp.launch(K.scatter_blocks_kernel, solver.elem_blocks.shape[0], device=solver.device,
              inputs=[solver.elem_blocks, solver.blockmap, solver.values])


@LAUNCHERS.register(Inertia)
class _Inertia(Launcher):
    def launch(self, x: wp.array, h: float, mode: int, inertia: bool, hessian: bool = True) -> None:
        s = self.solver
        wp.launch(K.inertia_gravity_kernel, s.model.n, device=s.device, inputs=[
            x, s.x_hat, s.mass, 1.0 / h**2 if inertia else 0.0, wp.vec3d(0.0, 0.0, 0.0), s.diag, s.grad, s.values,
            s.energy_buf, mode])


@LAUNCHERS.register(Gravity)
class _Gravity(Launcher):
    def __init__(self, solver: FullSpaceSolver, term: Term) -> None:
        super().__init__(solver, term)
        self.gravity = wp.vec3d(*solver.model.gravity)

    def launch(self, x: wp.array, h: float, mode: int, inertia: bool, hessian: bool = True) -> None:
        s = self.solver
        wp.launch(K.inertia_gravity_kernel, s.model.n, device=s.device, inputs=[
            x, s.x_hat, s.mass, 0.0, self.gravity, s.diag, s.grad, s.values, s.energy_buf, mode])


@LAUNCHERS.register(Elasticity)
class _Elasticity(Launcher):
    def __init__(self, solver: FullSpaceSolver, term: Term) -> None:
        super().__init__(solver, term)
        self.alpha_snh = 1.0 + 0.75 * solver.model.mu_snh / solver.model.lam_snh  # the SNH rest offset [-]

    def launch(self, x: wp.array, h: float, mode: int, inertia: bool, hessian: bool = True) -> None:
        s, m = self.solver, self.solver.model
        ins = [x, s.tets, s.Dm_inv, s.vol, m.mu_snh, m.lam_snh, self.alpha_snh]
        if mode == 0:
            wp.launch(K.elastic_energy_kernel, m.tets.shape[0], device=s.device, inputs=ins + [s.energy_buf])
        else:
            wp.launch(K.elastic_gradient_kernel, m.tets.shape[0], device=s.device, inputs=ins + [s.grad])
            if not hessian:
                return
            s.elem_blocks.zero_()
            s.elements.launch(K.elastic_hessian_kernel, ins + [s.elem_blocks], {1: 1, 2: 1, 3: 1, 7: 16})
            _scatter_element_blocks(s)


@LAUNCHERS.register(Viscosity)
class _Viscosity(Launcher):
    """Keeps the Green strain E(F(x_bar)) per tet (`strain_bar`), fixed within the step, so computed once per step
    (`begin_step`), not per Newton iteration."""

    def __init__(self, solver: FullSpaceSolver, term: Term) -> None:
        super().__init__(solver, term)
        self.strain_bar = wp.zeros(solver.model.tets.shape[0], dtype=wp.mat33d, device=solver.device)

    def begin_step(self, step: StepData) -> None:
        s = self.solver
        wp.launch(K.green_strain_kernel, s.model.tets.shape[0], device=s.device,
                  inputs=[s.x_bar, s.tets, s.Dm_inv, self.strain_bar])

    def launch(self, x: wp.array, h: float, mode: int, inertia: bool, hessian: bool = True) -> None:
        if not inertia:
            return
        s, m = self.solver, self.solver.model
        ins = [x, self.strain_bar, s.tets, s.Dm_inv, s.vol, m.viscosity / h]
        if mode == 0:
            wp.launch(K.viscous_energy_kernel, m.tets.shape[0], device=s.device, inputs=ins + [s.energy_buf])
        else:
            wp.launch(K.viscous_gradient_kernel, m.tets.shape[0], device=s.device, inputs=ins + [s.grad])
            if not hessian:
                return
            s.elements.launch(K.viscous_hessian_kernel, ins + [s.elem_blocks], {1: 1, 2: 1, 3: 1, 4: 1, 6: 16})
            _scatter_element_blocks(s)


@LAUNCHERS.register(PenaltyContact, ContactDamping)
class _Penalty(Launcher):
    def launch(self, x: wp.array, h: float, mode: int, inertia: bool, hessian: bool = True) -> None:
        s, m = self.solver, self.solver.model
        wp.launch(K.penalty_contact_kernel, m.points.size, device=s.device, inputs=[
            x, s.x_lag, s.x_bar, s.points, s.area, s.normal, m.plane_offset, self.term.ke(m), self.term.kd(m), h,
            s.diag, s.grad, s.values, s.energy_buf, mode])


@LAUNCHERS.register(BarrierContact)
class _Barrier(Launcher):
    def launch(self, x: wp.array, h: float, mode: int, inertia: bool, hessian: bool = True) -> None:
        s, m, c = self.solver, self.solver.model, self.solver.model.contact
        wp.launch(K.barrier_contact_kernel, m.points.size, device=s.device, inputs=[
            x, s.points, s.area, s.normal, m.plane_offset, c.barrier_stiffness, c.barrier_distance, s.diag, s.grad,
            s.values, s.energy_buf, mode])


@LAUNCHERS.register(Friction)
class _Friction(Launcher):
    """Keeps the step's lagged normal pressure per contact point (`fn`, [Pa])."""

    def __init__(self, solver: FullSpaceSolver, term: Term) -> None:
        super().__init__(solver, term)
        self.fn = wp.zeros(solver.model.points.size, dtype=wp.float64, device=solver.device)

    def begin_step(self, step: StepData) -> None:
        self.fn.assign(np.ascontiguousarray(step.fn))

    def launch(self, x: wp.array, h: float, mode: int, inertia: bool, hessian: bool = True) -> None:
        s, m = self.solver, self.solver.model
        wp.launch(K.friction_kernel, m.points.size, device=s.device, inputs=[
            x, s.x_bar, s.points, s.area, self.fn, s.normal, m.friction, m.contact.friction_stiffness, h, s.diag,
            s.grad, s.values, s.energy_buf, mode])

"""The full-space Newton solver under the solver contract (`solvers.contract`)."""

from __future__ import annotations

from frictionbench.solvers.contract import Solver
from frictionbench.solvers.full.solver import FullSpaceSolver, NewtonSettings
from frictionbench.solvers.integrators import INTEGRATORS
from frictionbench.solvers.model import Model, State
from frictionbench.solvers.step_stats import StepStats


class FullSpace(Solver):
    """Implicit time stepping on every vertex (`solvers.full.solver.FullSpaceSolver`; every integrator of
    `solvers.integrators`, the scenario's `time.integrator`): Newton tolerance `tol` [1/s, relative to L], `linear`
    solve (`auto`, `direct`, `pardiso`, `superlu`, `cg`; `solvers.linalg`) and `max_iter` Newton iterations per
    attempt; `chord`, Newton's convergence test with the last factorisation first (`NewtonSettings.chord`), and
    `chord_contraction`, with it modified Newton (`NewtonSettings.chord_contraction`)."""

    name = "full"
    integrators = tuple(INTEGRATORS)
    parameters = {"tol": NewtonSettings.tol, "linear": NewtonSettings.linear, "max_iter": NewtonSettings.max_iter,
                  "chord": NewtonSettings.chord, "chord_contraction": NewtonSettings.chord_contraction}

    def setup(self, model: Model) -> None:
        """The solver's kernels and buffers on `model`."""
        p = self.params
        self.solver = FullSpaceSolver(model, device=self.device, settings=NewtonSettings(
            tol=p["tol"], linear=p["linear"], max_iter=p["max_iter"], chord=p["chord"],
            chord_contraction=p["chord_contraction"]))

    def step(self, state_in: State, state_out: State, dt: float) -> StepStats:
        """One Newton-solved step of the scenario's integrator."""
        return self.solver.step(state_in, state_out, dt)

    def describe(self) -> dict:
        """The parameters, and the linear solver and assembly threads that ran (`linear_solver`,
        `assembly_threads`)."""
        return super().describe() | self.solver.info

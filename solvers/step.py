"""One step's incremental potential as a `solvers.newton.NewtonProblem`, shared by the implicit solvers: a backend
gives the energy, the Newton direction, the step norm and the contact points of its unknowns, and `StepProblem`
caps every step by the one feasible-step rule of the physics terms (`solvers.physics.terms.max_feasible_step`:
the barrier law keeps every contact point above the plane; without a capping term a step is never capped)."""

from __future__ import annotations

from abc import ABC, abstractmethod
from collections.abc import Sequence

import numpy as np

from frictionbench.solvers.newton import Direction
from frictionbench.solvers.physics.terms import Term, max_feasible_step, step_capping
from frictionbench.solvers.scene import Model


class StepProblem(ABC):
    """A step of `model`'s potential with `terms` over a backend's unknowns y (vertex positions (n, 3) [m] or
    latent coordinates (r,))."""

    def __init__(self, model: Model, terms: Sequence[Term]) -> None:
        self.model = model
        self.capping = step_capping(terms)

    @abstractmethod
    def energy(self, y: np.ndarray) -> float:
        """E(y) [J]."""

    @abstractmethod
    def direction(self, y: np.ndarray) -> Direction:
        """The Newton direction at y (from the PSD-projected Hessian)."""

    @abstractmethod
    def step_norm(self, dy: np.ndarray) -> float:
        """The size of a step dy in velocity units [m/s]."""

    @abstractmethod
    def contact_points(self, y: np.ndarray, dy: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """The contact points' positions at y and their displacement along dy, (p, 3) each [m]."""

    def max_step(self, y: np.ndarray, dy: np.ndarray) -> float:
        """Largest alpha <= 1 that every capping term allows (1 where none caps a step)."""
        if not self.capping:
            return 1.0
        return max_feasible_step(self.capping, self.model, *self.contact_points(y, dy))

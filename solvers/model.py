"""The static simulation `Model` of a scene and the changing `State` the solvers share (built by
`solvers.build.build_model`).

Newton-style split: a `Model` holds what does not change during a run (rest mesh, masses, material with its
damping, plane, contact points and their area weights, which effects exist); a `State` holds positions and
velocities; a solver advances `step(state_in, state_out, dt)`. Full-space and reduced solvers share both. This
module imports no physics, so that the physics terms (`solvers.physics`) can read the Model without an import
circle.
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import TYPE_CHECKING

import numpy as np

from frictionbench.scenarios.meshes import TetMesh
from frictionbench.scenarios.spec import Contact, Scenario

if TYPE_CHECKING:  # the integrator classes read a State back: named here for type checking only
    from frictionbench.solvers.integrators import Integrator


@dataclass
class State:
    """Positions x (n, 3) [m] and velocities v (n, 3) [m/s] at time t [s]; a solver with latent coordinates (a
    reduced one) also sets q (r,) and their rate qdot (r,) [1/s] of the same state (None: not in its subspace yet,
    e.g. an initial state, which it then projects). `previous` is the state the step that made this one started
    from (its own `previous` dropped), what a multistep integrator needs (`solvers.integrators`); None for an
    initial state."""

    x: np.ndarray
    v: np.ndarray
    t: float = 0.0
    q: np.ndarray | None = None
    qdot: np.ndarray | None = None
    previous: State | None = None

    def copy(self) -> "State":
        """A deep copy."""
        cp = lambda a: None if a is None else a.copy()  # noqa: E731
        prev = None if self.previous is None else self.previous.without_history().copy()
        return State(self.x.copy(), self.v.copy(), self.t, cp(self.q), cp(self.qdot), prev)

    def without_history(self) -> State:
        """The same state (its arrays shared, not copied) without `previous`: what the next state keeps of it."""
        return State(self.x, self.v, self.t, self.q, self.qdot)


@dataclass
class Model:
    """Static data of one scene on one mesh (float64, SI units).

    X: (n, 3) rest positions; tets: (m, 4); surface: (k, 3) boundary triangles; Dm_inv: (m, 3, 3); vol: (m,);
    mass: (n,) lumped masses; points: (p,) contact sample vertices with area weights `area` (p,) [m^2];
    mu_snh, lam_snh: stable Neo-Hookean parameters [Pa]; density [kg/m^3]; plane_normal (3,), plane_offset [m]
    (None without plane); friction: Coulomb coefficient mu [-] of the plane (0 without plane); contact: the contact
    law and its parameters with the automatic penalty stiffness resolved to a number; terms: names of the
    incremental-potential terms that exist (`inertia` always, then `elasticity`, `gravity`, `contact`, `friction`,
    `damping`, `viscosity`); L: bounding-box diagonal of the rest mesh [m]; viscosity: the Kelvin-Voigt eta [Pa s]
    (0 without material damping; a scenario's damping ratio resolved on this mesh) and damping_ratio the ratio the
    scenario asked for (None where it gave a viscosity or nothing); integrator: the time integrator
    (`solvers.integrators`) the scenario's `time.integrator` names. `scenario` is the scene it was built from (its
    name, time span and initial placement; the physics above is read from the model's own fields).
    """

    scenario: Scenario
    mesh: TetMesh
    X: np.ndarray
    tets: np.ndarray
    surface: np.ndarray
    Dm_inv: np.ndarray
    vol: np.ndarray
    mass: np.ndarray
    points: np.ndarray
    area: np.ndarray
    mu_snh: float
    lam_snh: float
    gravity: np.ndarray
    plane_normal: np.ndarray | None
    plane_offset: float
    terms: tuple[str, ...]
    L: float
    density: float
    friction: float
    contact: Contact
    integrator: Integrator
    viscosity: float = 0.0
    damping_ratio: float | None = None

    @property
    def n(self) -> int:
        """Number of vertices."""
        return int(self.X.shape[0])

    def has(self, term: str) -> bool:
        """Whether the incremental potential contains `term`."""
        return term in self.terms

    @property
    def contact_damping(self) -> float:
        """k_d [Pa s/m] of the penalty law's damping term, 0 when the scene has no damping term."""
        return self.contact.damping if self.has("damping") else 0.0

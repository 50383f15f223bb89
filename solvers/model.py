"""The static simulation `Model` built from a scenario and a mesh, and the changing `State`.

Newton-style split: a `Model` holds what does not change during a run (rest mesh, masses, material with its
damping, plane, contact points and their area weights, which effects exist); a `State` holds positions and
velocities; a solver advances `step(state_in, state_out, dt)`. Full-space and reduced solvers share both.
"""

from __future__ import annotations

from dataclasses import dataclass, replace

import numpy as np

from scenarios.meshes import TetMesh
from scenarios.model import Contact, Scenario
from solvers.integrators import Integrator, get_integrator
from solvers.physics.contact import auto_penalty_stiffness
from solvers.physics.inertia import lumped_mass
from solvers.physics.material import shape_matrices, snh_parameters
from solvers.physics.viscosity import viscosity_for_damping_ratio


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


def active_terms(scenario: Scenario) -> tuple[str, ...]:
    """The terms a scene calls for: effects switched on and physically present (mu = 0 -> no friction)."""
    eff, plane = scenario.effects, scenario.plane
    terms = ["inertia"]
    if eff.elasticity:
        terms.append("elasticity")
    if eff.gravity and any(g != 0.0 for g in scenario.gravity):
        terms.append("gravity")
    if plane is not None and eff.contact:
        terms.append("contact")
        if eff.friction and plane.friction > 0.0:
            terms.append("friction")
        if eff.damping and scenario.contact.damping > 0.0 and scenario.contact.law == "penalty":
            terms.append("damping")
    mat = scenario.material
    if eff.viscosity and ((mat.viscosity or 0.0) > 0.0 or (mat.damping_ratio or 0.0) > 0.0):
        terms.append("viscosity")
    return tuple(terms)


def resolved(scenario: Scenario, L: float) -> Scenario:
    """The scenario with its automatic settings made numbers for a body of size L [m]: an `auto` penalty
    stiffness (None) becomes `auto_penalty_stiffness` for the fastest expected approach speed, the initial speed
    |v| + |omega| L plus the speed of a fall through the initial clearance, sqrt(2 |g| clearance)."""
    c = scenario.contact
    if c.stiffness is not None:
        return scenario
    ini = scenario.initial
    speed = (float(np.linalg.norm(ini.velocity)) + float(np.linalg.norm(ini.angular_velocity)) * L
             + float(np.sqrt(2.0 * np.linalg.norm(scenario.gravity) * (ini.clearance or 0.0))))
    k = auto_penalty_stiffness(scenario.material.youngs_modulus, scenario.material.density, speed, L)
    return replace(scenario, contact=replace(c, stiffness=k))


def build_model(scenario: Scenario, mesh: TetMesh) -> Model:
    """Assemble the static model of `scenario` on `mesh` (rest positions as given by the mesh); its scenario is
    `resolved` (automatic settings made numbers) and a material damping ratio is resolved to the viscosity that
    gives this mesh's first non-rigid mode that ratio (`viscosity_for_damping_ratio`)."""
    scenario = resolved(scenario, float(mesh.bbox_diagonal()))
    X = np.ascontiguousarray(mesh.X, dtype=np.float64)
    tets = np.ascontiguousarray(mesh.tets, dtype=np.int64)
    Dm_inv, vol = shape_matrices(X, tets)
    mass = lumped_mass(vol, tets, X.shape[0], scenario.material.density)
    areas = mesh.surface_vertex_areas()
    points = np.flatnonzero(areas > 0.0)
    mu, lam = snh_parameters(scenario.material.youngs_modulus, scenario.material.poisson_ratio)
    plane = scenario.plane
    model = Model(
        scenario=scenario, mesh=mesh, X=X, tets=tets, surface=np.asarray(mesh.surface, dtype=np.int64),
        Dm_inv=Dm_inv, vol=vol, mass=mass, points=points, area=areas[points], mu_snh=mu, lam_snh=lam,
        gravity=np.asarray(scenario.gravity, dtype=np.float64),
        plane_normal=None if plane is None else np.asarray(plane.normal, dtype=np.float64),
        plane_offset=0.0 if plane is None else float(plane.offset),
        terms=active_terms(scenario), L=float(mesh.bbox_diagonal()), density=float(scenario.material.density),
        friction=0.0 if plane is None else float(plane.friction), contact=scenario.contact,
        integrator=get_integrator(scenario.time.integrator),
    )
    if not model.has("viscosity"):
        return model
    zeta = scenario.material.damping_ratio
    if zeta is None:
        return replace(model, viscosity=float(scenario.material.viscosity))
    return replace(model, viscosity=viscosity_for_damping_ratio(model, zeta), damping_ratio=float(zeta))


def rotation_matrix(euler_deg: tuple[float, float, float]) -> np.ndarray:
    """Rotation R = Rz Ry Rx from XYZ Euler angles in degrees, (3, 3)."""
    ax, ay, az = np.radians(euler_deg)
    cx, sx, cy, sy, cz, sz = np.cos(ax), np.sin(ax), np.cos(ay), np.sin(ay), np.cos(az), np.sin(az)
    Rx = np.array([[1, 0, 0], [0, cx, -sx], [0, sx, cx]])
    Ry = np.array([[cy, 0, sy], [0, 1, 0], [-sy, 0, cy]])
    Rz = np.array([[cz, -sz, 0], [sz, cz, 0], [0, 0, 1]])
    return Rz @ Ry @ Rx


def initial_state(model: Model) -> State:
    """Place the body: squash and rotate about the centroid, translate, then set the clearance above the plane
    along its normal (if both a plane and a clearance are given); velocities v + omega x (x - c)."""
    ini = model.scenario.initial
    X = model.X
    c = X.mean(axis=0)
    x = (X - c) * np.asarray(ini.squash) @ rotation_matrix(ini.rotation).T + c + np.asarray(ini.translation)
    if model.plane_normal is not None and ini.clearance is not None:
        n = model.plane_normal
        lowest = float(np.min(x @ n - model.plane_offset))
        x = x + (ini.clearance - lowest) * n
    com = model.mass @ x / model.mass.sum()
    v = np.asarray(ini.velocity, dtype=np.float64) + np.cross(np.asarray(ini.angular_velocity, float), x - com)
    return State(x=x, v=np.ascontiguousarray(v), t=0.0)

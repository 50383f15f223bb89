"""Building a scene's static `Model` (`solvers.model`) from its scenario and mesh (`build_model`), and its initial
`State`.

The classes sit in `solvers.model`, below the physics, which reads the Model; this builder sits above the physics,
whose functions it calls (the masses, the shape matrices, the contact and material damping).
"""

from __future__ import annotations

from dataclasses import replace

import numpy as np

from frictionbench.scenarios.meshes import TetMesh
from frictionbench.scenarios.spec import Scenario
from frictionbench.solvers.integrators import get_integrator
from frictionbench.solvers.model import Model, State
from frictionbench.solvers.physics.contact import auto_penalty_stiffness, damping_for_ratio
from frictionbench.solvers.physics.inertia import lumped_mass
from frictionbench.solvers.physics.material import shape_matrices, snh_parameters
from frictionbench.solvers.physics.viscosity import viscosity_for_damping_ratio


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
        if (eff.damping and (scenario.contact.damping > 0.0 or (scenario.contact.damping_ratio or 0.0) > 0.0)
                and scenario.contact.law == "penalty"):
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
    `resolved` (automatic settings made numbers), a contact damping ratio to the contact damping that gives this
    mesh's contact vertices that ratio (`damping_for_ratio`), and a material damping ratio to the viscosity that
    gives this mesh's first non-rigid mode that ratio (`viscosity_for_damping_ratio`). An adaptive scenario
    (`time.tol`) gets its integrator with the variable-step coefficients (`get_integrator`'s `variable_step`)."""
    scenario = resolved(scenario, float(mesh.bbox_diagonal()))
    X = np.ascontiguousarray(mesh.X, dtype=np.float64)
    tets = np.ascontiguousarray(mesh.tets, dtype=np.int64)
    Dm_inv, vol = shape_matrices(X, tets)
    mass = lumped_mass(vol, tets, X.shape[0], scenario.material.density)
    areas = mesh.surface_vertex_areas()
    points = np.flatnonzero(areas > 0.0)
    mu, lam = snh_parameters(scenario.material.youngs_modulus, scenario.material.poisson_ratio)
    plane = scenario.plane
    if scenario.contact.damping_ratio is not None:
        kd = damping_for_ratio(scenario.contact.damping_ratio, scenario.contact.stiffness, mass[points], areas[points])
        scenario = replace(scenario, contact=replace(scenario.contact, damping=kd))
    model = Model(
        scenario=scenario, mesh=mesh, X=X, tets=tets, surface=np.asarray(mesh.surface, dtype=np.int64),
        Dm_inv=Dm_inv, vol=vol, mass=mass, points=points, area=areas[points], mu_snh=mu, lam_snh=lam,
        gravity=np.asarray(scenario.gravity, dtype=np.float64),
        plane_normal=None if plane is None else np.asarray(plane.normal, dtype=np.float64),
        plane_offset=0.0 if plane is None else float(plane.offset),
        terms=active_terms(scenario), L=float(mesh.bbox_diagonal()), density=float(scenario.material.density),
        friction=0.0 if plane is None else float(plane.friction), contact=scenario.contact,
        integrator=get_integrator(scenario.time.integrator, variable_step=scenario.time.adaptive),
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

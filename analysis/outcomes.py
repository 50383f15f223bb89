"""Outcome metrics: what a run ends with, judged against the ground truth's (docs/metrics.md, "Outcome metrics").

An outcome is a quantity of one trajectory: how far the body slides along the plane, where its centre of mass ends
and how it is turned, when it comes to rest, how much mechanical energy the impact dissipates, its peak kinetic
energy and whether it ends at rest (stick). Each is declared once in `analysis.schema.OUTCOMES` (its columns,
units and tolerance, and the functions here that compute its value and its difference); from that table this
module computes a run's values (`outcome_values`), the row's cells with its errors against the truth's values
(`outcome_cells`) and each outcome's convergence over the truth's ladder (`ladder_outcome_columns`).

Every function is pure. Value functions take the trajectory and an `OutcomeScene` (plane, material, contact law,
gravity, the scenario's creep speed); they return None where the outcome does not apply (no plane) and NaN where
it is undefined for the run (a body not at rest has no time to rest). Difference functions take two values and
the body's size L [m]. Shapes as in `analysis.metrics`: F frames, n vertices.
"""

from __future__ import annotations

import math
import pkgutil
from collections.abc import Callable, Mapping, Sequence
from dataclasses import dataclass, field, replace
from functools import cache

import numpy as np
from scipy.spatial.transform import Rotation

from frictionbench.analysis.metrics import (ArrayLike3, body_masses, center_of_mass, creep_speed_law, energy_terms,
                                            finite, kinetic_energy, plane_speeds, plane_travel, rest_speed_tol,
                                            REST_CONTACT_TOL_REL, stick, unit_plane, vertex_velocities)
from frictionbench.analysis.schema import OUTCOMES, Outcome
from frictionbench.analysis.truth import richardson
from frictionbench.scenarios.meshes import TetMesh, bbox_diagonal
from frictionbench.scenarios.spec import GRAVITY, Contact, Material, Plane, Scenario
from frictionbench.solvers.integrators import Integrator
from frictionbench.solvers.physics.contact import barrier, lagged_pressure, penalty_energy, signed_distance
from frictionbench.solvers.trajectory import Trajectory

#: The window [s] after the last frame before the first contact over which `impact_loss` measures the mechanical
#: energy lost (docs/metrics.md, "Outcome metrics", says why 0.2 s).
IMPACT_WINDOW_S = 0.2


@dataclass(frozen=True, eq=False)
class OutcomeScene:
    """What the outcomes of a trajectory need besides it.

    plane: the contact plane (None: no plane, the plane's outcomes do not apply); material: its density gives the
    lumped vertex masses, its elastic moduli the elastic energy; contact: the contact law with its stiffness
    resolved (None: no contact law, no impact); gravity [m/s^2]; creep_speed: the friction law's creep speed [m/s]
    that `stick`'s rest rule allows (the same for every run of a scenario; None: none); masses (n,) [kg]: vertex
    masses instead of the material's lumped ones.
    """

    plane: Plane | None = None
    material: Material = field(default_factory=Material)
    contact: Contact | None = None
    gravity: ArrayLike3 = GRAVITY
    creep_speed: float | None = None
    masses: np.ndarray | None = None

    def body_masses(self, traj: Trajectory) -> np.ndarray:
        """Vertex masses (n,) [kg] of the trajectory's mesh."""
        return body_masses(traj, self.material, self.masses)


def outcome_scene(sc: Scenario, contact_stiffness: float | None, reference: Trajectory | None) -> OutcomeScene:
    """The outcome scene of a scenario: its plane, material, gravity and contact law with the stiffness a run
    resolved (`contact_stiffness` [Pa/m], None: the scenario's own), and the creep speed of the friction law for the
    reference run as it lies at the end (`analysis.metrics.creep_speed_law`, as `compare` judges stick: one rest
    rule for every run of the scenario; None without friction or without a finite reference)."""
    contact = None
    if sc.plane is not None and sc.effects.contact:
        contact = sc.contact if contact_stiffness is None else replace(sc.contact, stiffness=contact_stiffness)
        if contact.stiffness is None:
            contact = None
    creep = None
    if (contact is not None and sc.effects.friction and sc.plane.friction > 0 and reference is not None
            and finite(reference)):
        creep = creep_speed_law(reference, sc.plane, contact, sc.material, sc.gravity)
    return OutcomeScene(plane=sc.plane, material=sc.material, contact=contact, gravity=sc.gravity, creep_speed=creep)


# ----- values ----------------------------------------------------------------------------------------------------

def slide_distance(traj: Trajectory, scene: OutcomeScene) -> float | None:
    """|P (c_last - c_first)| [m]: how far the centre of mass moves along the plane from the first frame to the last
    (P = I - n n^T, c mass-weighted; `analysis.metrics.plane_travel`). None without a plane."""
    if scene.plane is None:
        return None
    return float(np.linalg.norm(plane_travel(traj.x, scene.plane.normal, scene.body_masses(traj))))


def end_com(traj: Trajectory, scene: OutcomeScene) -> np.ndarray:
    """The mass-weighted centre of the last frame, (3,) [m]."""
    return center_of_mass(traj.x[-1], scene.body_masses(traj))


def best_fit_rotation(X: np.ndarray, x: np.ndarray, masses: np.ndarray) -> Rotation:
    """The rotation R of the best-fit rigid motion from the rest shape X (n, 3) to the positions x (n, 3): the
    minimiser of sum_i m_i |(x_i - c) - R (X_i - C)|^2, c and C the mass-weighted centres (Kabsch with weights,
    `scipy.spatial.transform.Rotation.align_vectors`)."""
    rotation, _ = Rotation.align_vectors(x - center_of_mass(x, masses), X - center_of_mass(X, masses),
                                         weights=masses)
    return rotation


def end_rotation(traj: Trajectory, scene: OutcomeScene) -> Rotation:
    """The rotation of the best-fit rigid motion from the rest shape to the last frame (`best_fit_rotation`); its
    results cell is its angle [deg]."""
    return best_fit_rotation(traj.X, traj.x[-1], scene.body_masses(traj))


def time_to_rest(traj: Trajectory, scene: OutcomeScene) -> float | None:
    """The time [s] of the first frame from which the body stays at rest on the plane to the end; NaN when it is
    not at rest at the end, None without a plane.

    A frame is at rest by `analysis.metrics.stick`'s rule taken frame by frame: the centre's speed along the plane
    below `rest_speed_tol` (L the rest mesh's size, the scene's creep speed) and the lowest point within
    REST_CONTACT_TOL_REL L of the plane. At rest at the end means `stick`'s verdict (the speed averaged over the
    run's last 10%) and the last frame at rest.
    """
    if scene.plane is None:
        return None
    n, d = unit_plane(scene.plane.normal, scene.plane.offset)
    L = bbox_diagonal(traj.X)
    masses = scene.body_masses(traj)
    if not stick(traj, scene.plane.normal, L, plane_offset=scene.plane.offset, masses=masses,
                 creep_speed=scene.creep_speed)[0]:
        return math.nan
    at_rest = ((plane_speeds(traj, n, masses) < rest_speed_tol(L, scene.creep_speed))
               & (np.min(signed_distance(traj.x, n, d), axis=-1) <= REST_CONTACT_TOL_REL * L))
    moving = np.flatnonzero(~at_rest)
    first = int(moving[-1]) + 1 if moving.size else 0
    return float(traj.t[first]) if first < traj.n_frames else math.nan


def contact_energy(x: np.ndarray, area: np.ndarray, plane: Plane, contact: Contact) -> float:
    """The contact law's stored energy [J] at positions x (p, 3) of points with areas (p,) [m^2]: penalty
    sum A 1/2 k_e c^2 (c the penetration), barrier sum A kappa b(phi) (`solvers.physics.contact`)."""
    n, d = unit_plane(plane.normal, plane.offset)
    if contact.law == "penalty":
        return penalty_energy(x, x, area, n, d, contact.stiffness, 0.0, 1.0)
    return float(contact.barrier_stiffness * area @ barrier(signed_distance(x, n, d), contact.barrier_distance))


def impact_loss(traj: Trajectory, scene: OutcomeScene, window: float = IMPACT_WINDOW_S) -> float | None:
    """The mechanical energy the impact dissipates as a fraction of the kinetic energy it meets: (E_b - E_a) / K_c
    [-].

    c is the first frame where the contact law presses a surface point (penalty: one below the plane; barrier: one
    within its activation distance), b the frame before it, a the first frame at least `window` [s] after b;
    E = kinetic + elastic (stable Neo-Hookean) + gravitational + contact energy (`analysis.metrics.energy_terms`,
    `contact_energy`); K_c = K_b + G_b - G_c, the kinetic energy at c had the body kept falling freely from b (G
    the gravitational energy): the frames fall at any phase of the last free interval, and K_b alone would miss the
    energy of the rest of the fall. Friction and damping work inside the window count as dissipated; energy still
    in vibration or in a bounce at a counts as kept. NaN where there is no impact to measure (the body touches at
    the first frame or never, or the run ends before the window does, or K_c is not positive); None without a plane
    or contact law.
    """
    if scene.plane is None or scene.contact is None:
        return None
    n, d = unit_plane(scene.plane.normal, scene.plane.offset)
    c = scene.contact
    area = TetMesh(X=traj.X, tets=traj.tets, surface=traj.surface, name="trajectory").surface_vertex_areas()
    points = np.flatnonzero(area > 0.0)
    x = traj.x[:, points]
    pressed = (lagged_pressure(c.law, x, np.zeros_like(x), n, d, c.stiffness, 0.0, c.barrier_stiffness,
                               c.barrier_distance) > 0.0).any(axis=-1)
    if not pressed.any() or pressed[0]:
        return math.nan
    first = int(np.argmax(pressed))
    b = first - 1
    a = int(np.searchsorted(traj.t, traj.t[b] + window * (1.0 - 1e-9)))
    if a >= traj.n_frames:
        return math.nan
    frames = [b, a, first]
    three = Trajectory(t=traj.t[frames], x=traj.x[frames], X=traj.X, tets=traj.tets, surface=traj.surface,
                       v=vertex_velocities(traj)[frames])
    terms = energy_terms(three, scene.material, scene.gravity, scene.body_masses(traj))
    energy = sum(terms.values())[:2] + np.array([contact_energy(x[k], area[points], scene.plane, c) for k in (b, a)])
    kinetic = float(terms["kinetic"][0] + terms["gravity"][0] - terms["gravity"][2])
    return float((energy[0] - energy[1]) / kinetic) if kinetic > 0.0 else math.nan


def peak_kinetic_energy(traj: Trajectory, scene: OutcomeScene) -> float:
    """max over frames of 1/2 sum_i m_i |v_i|^2 [J] (v from `analysis.metrics.vertex_velocities`)."""
    return float(np.max(kinetic_energy(vertex_velocities(traj), scene.body_masses(traj))))


def stick_verdict(traj: Trajectory, scene: OutcomeScene) -> bool | None:
    """`analysis.metrics.stick`'s verdict with the scene's creep speed and L of the rest mesh; None without a
    plane."""
    if scene.plane is None:
        return None
    return stick(traj, scene.plane.normal, bbox_diagonal(traj.X), plane_offset=scene.plane.offset,
                 masses=scene.body_masses(traj), creep_speed=scene.creep_speed)[0]


# ----- differences (value, truth's value, L [m]) -------------------------------------------------------------------

def length_difference(a: float | np.ndarray, b: float | np.ndarray, L: float) -> float:
    """|a - b| / L for lengths or positions a, b [m]."""
    return float(np.linalg.norm(np.asarray(a, dtype=float) - np.asarray(b, dtype=float)) / L)


def rotation_difference(a: Rotation, b: Rotation, L: float) -> float:
    """The angle [deg] of b^T a, the rotation that takes one end orientation to the other (L unused)."""
    return float(np.degrees((b.inv() * a).magnitude()))


def absolute_difference(a: float, b: float, L: float) -> float:
    """|a - b| in the values' unit (L unused)."""
    return abs(float(a) - float(b))


def relative_difference(a: float, b: float, L: float) -> float:
    """|a - b| / |b| [-]; 0 where both are 0, inf where only b is (L unused)."""
    diff = abs(float(a) - float(b))
    return diff / abs(float(b)) if b != 0.0 else (0.0 if diff == 0.0 else math.inf)


def verdict_difference(a: bool, b: bool, L: float) -> float:
    """0 where two verdicts agree, 1 where they differ (L unused)."""
    return 0.0 if bool(a) == bool(b) else 1.0


# ----- the table's columns -----------------------------------------------------------------------------------------

@cache
def _function(dotted: str) -> Callable:
    """The function a declaration names by its dotted path."""
    return pkgutil.resolve_name(dotted)


def _undefined(value: object) -> bool:
    """A value NaN: the outcome is undefined for that run (e.g. no rest)."""
    return isinstance(value, float) and math.isnan(value)


def outcome_error(outcome: Outcome, value: object, truth: object, L: float) -> float | None:
    """The outcome's difference between a run's value and the truth's [its err_unit]: None where either does not
    apply, 0 where both are undefined, inf where only one is (one comes to rest and the other does not), else the
    declared difference."""
    if value is None or truth is None:
        return None
    if _undefined(value) or _undefined(truth):
        return 0.0 if _undefined(value) and _undefined(truth) else math.inf
    return _function(outcome.difference)(value, truth, L)


def cell(value: object) -> object:
    """An outcome's value as a results cell: a rotation as its angle [deg], a position as 'x y z' [m], a verdict as
    a bool, a number as a float, None as None."""
    if value is None or isinstance(value, bool | np.bool_):
        return None if value is None else bool(value)
    if isinstance(value, Rotation):
        return float(np.degrees(value.magnitude()))
    if isinstance(value, np.ndarray):
        return " ".join(f"{v:.6g}" for v in value)
    return float(value)


def outcome_values(traj: Trajectory, scene: OutcomeScene) -> dict[str, object]:
    """Every outcome's value for a trajectory (`analysis.schema.OUTCOMES`), by name; NaN (undefined) for every one
    of a trajectory with a non-finite value."""
    if not finite(traj):
        return {name: math.nan for name in OUTCOMES}
    return {o.name: _function(o.value)(traj, scene) for o in OUTCOMES.values()}


def outcome_cells(values: Mapping[str, object], truth: Mapping[str, object] | None, L: float) -> dict[str, object]:
    """A row's outcome cells: each value (outcomes with their own column) and, with the truth's values, each error
    against them (`outcome_error`, L the truth's size [m])."""
    row = {o.name: cell(values[o.name]) for o in OUTCOMES.values() if o.own_column}
    if truth is not None:
        row |= {o.err_column: outcome_error(o, values[o.name], truth[o.name], L) for o in OUTCOMES.values()}
    return row


def ladder_outcome_columns(levels: Sequence[Mapping[str, object]], integrator: Integrator, L: float,
                           failed: bool = False) -> dict[str, object]:
    """Each outcome's convergence over the truth's ladder, from its values on the levels (coarsest first, the
    truth last): the truth's value, the difference d_K of the two finest levels, the estimate of the truth's own
    error (Richardson from the differences as for positions, `analysis.truth.richardson`; a verdict's, or an
    infinite difference's, is d_K itself) and whether d_K meets the outcome's tolerance (never after a failed
    level: `failed`). L is the truth's size [m]; with one level only the value is known."""
    row: dict[str, object] = {}
    for o in OUTCOMES.values():
        values = [level[o.name] for level in levels]
        diffs = [outcome_error(o, a, b, L) for a, b in zip(values, values[1:])]
        last = diffs[-1] if diffs else None
        if last is None or o.discrete or not math.isfinite(last) or any(d is None for d in diffs):
            est = last
        else:
            est = richardson(diffs, integrator)[0]
        applies = bool(values) and values[-1] is not None
        row |= {o.truth_column: cell(values[-1]) if values else None, o.diff_column: last, o.est_column: est,
                o.certified_column: bool(last is not None and last <= o.tol and not failed) if applies else None}
    return row

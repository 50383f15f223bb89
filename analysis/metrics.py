"""Metrics of one trajectory against a reference trajectory on the same mesh (docs/metrics.md).

Every function is pure: trajectories in, numbers out. Units are SI; every `*_rel` metric is divided by the
length scale L = |max(X) - min(X)|, the diagonal of the rest mesh's bounding box, so it is dimensionless.

Shapes: F frames, n vertices, m tets, r basis columns. Positions x (F, n, 3) [m], times t (F,) [s],
vertex masses (n,) [kg]. Where a reference and a trajectory store different frame times, the metrics compare
the frames whose times they share (`align_frames`); the column `frames_compared` says how many there were.

The schema's computed columns (`analysis.schema.Column.compute`) are functions of one `ComparedRun`: a finished
run, its reference and its scenario, with the inputs they share computed once; the columns one computation gives
together (`stick_cells`, `inverted_cells`, `creep_cells`) take their cells from it by name.
"""

from __future__ import annotations

from collections.abc import Callable, Sequence
from dataclasses import dataclass, field, replace
from functools import cached_property

import numpy as np

from frictionbench.scenarios.meshes import TetMesh, bbox_diagonal
from frictionbench.scenarios.spec import GRAVITY, Contact, Material, Plane, Scenario
from frictionbench.solvers.physics.contact import lagged_pressure
from frictionbench.solvers.physics.friction import creep_speed
from frictionbench.solvers.physics.inertia import lumped_mass
from frictionbench.solvers.physics.material import shape_matrices, snh_energy_density, snh_parameters
from frictionbench.solvers.reduced.bases import body_frame_displacements, project
from frictionbench.solvers.trajectory import Trajectory

ArrayLike3 = Sequence[float] | np.ndarray


def unit_plane(normal: ArrayLike3, offset: float = 0.0) -> tuple[np.ndarray, float]:
    """(n / |n|, d / |n|): the plane n . x = d with a unit normal."""
    n = np.asarray(normal, dtype=float)
    s = np.linalg.norm(n)
    if not s > 0.0:
        raise ValueError(f"plane normal {tuple(n)} has zero length")
    return n / s, float(offset) / s


def _masses(n: int, masses: np.ndarray | None) -> np.ndarray:
    """Vertex masses (n,): the given ones, or uniform 1/n when None."""
    if masses is None:
        return np.full(n, 1.0 / n)
    masses = np.asarray(masses, dtype=float)
    if masses.shape != (n,):
        raise ValueError(f"masses have shape {masses.shape}, expected ({n},)")
    return masses


def align_frames(t_ref: np.ndarray, t: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Indices (i_ref, i) of the frames whose times agree, t_ref[i_ref] ~ t[i], in increasing time.

    Two times agree when |t_ref - t| <= 1e-6 * min(positive frame spacing of either series) + 1e-12 s.
    Raises ValueError when the series share no time.
    """
    t_ref, t = np.asarray(t_ref, dtype=float), np.asarray(t, dtype=float)
    if t_ref.shape == t.shape and np.array_equal(t_ref, t):
        idx = np.arange(t.shape[0])
        return idx, idx
    spacings = np.concatenate([np.diff(np.sort(t_ref)), np.diff(np.sort(t))])
    spacings = spacings[spacings > 0]
    tol = 1e-6 * (spacings.min() if spacings.size else 1.0) + 1e-12
    order = np.argsort(t_ref)
    pos = np.clip(np.searchsorted(t_ref[order], t), 1, max(t_ref.size - 1, 1))
    candidates = np.stack([order[pos - 1], order[np.minimum(pos, t_ref.size - 1)]], axis=1)
    nearest = candidates[np.arange(t.size), np.argmin(np.abs(t_ref[candidates] - t[:, None]), axis=1)]
    hit = np.abs(t_ref[nearest] - t) <= tol
    if not hit.any():
        raise ValueError(
            f"no common frame times: reference has {t_ref.size} frames in [{t_ref.min():g}, {t_ref.max():g}] s, "
            f"trajectory has {t.size} frames in [{t.min():g}, {t.max():g}] s")
    i, i_ref = np.nonzero(hit)[0], nearest[hit]
    by_time = np.argsort(t[i])
    return i_ref[by_time], i[by_time]


def _aligned(ref: Trajectory, traj: Trajectory) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """(t (F,), x_ref (F, n, 3), x (F, n, 3)) on the common frames of two trajectories of the same mesh."""
    if ref.X.shape != traj.X.shape or not np.allclose(ref.X, traj.X, rtol=0.0, atol=1e-6 * bbox_diagonal(ref.X)):
        raise ValueError(
            f"trajectories are on different meshes: rest positions {ref.X.shape} vs {traj.X.shape} differ")
    i_ref, i = align_frames(ref.t, traj.t)
    return traj.t[i], _frames(ref.x, i_ref), _frames(traj.x, i)


def _frames(x: np.ndarray, idx: np.ndarray) -> np.ndarray:
    """x[idx] along the frame axis, without a copy when idx selects every frame in order."""
    return x if np.array_equal(idx, np.arange(x.shape[0])) else x[idx]


def _frame_rms(x_ref: np.ndarray, x: np.ndarray) -> np.ndarray:
    """e_k = sqrt(mean_i |x_ki - x_ref_ki|^2), shape (F,) [m]."""
    return np.sqrt(np.mean(np.sum((x - x_ref) ** 2, axis=-1), axis=-1))


def error_over_time(ref: Trajectory, traj: Trajectory) -> tuple[np.ndarray, np.ndarray]:
    """Per-frame relative error: (t (F,) [s], e (F,) [-]) with e_k = sqrt(mean_i |x_ki - x_ref_ki|^2) / L."""
    t, x_ref, x = _aligned(ref, traj)
    return t, _frame_rms(x_ref, x) / bbox_diagonal(ref.X)


def pos_rmse_rel(ref: Trajectory, traj: Trajectory) -> float:
    """sqrt(mean over frames k and vertices i of |x_ki - x_ref_ki|^2) / L."""
    _, x_ref, x = _aligned(ref, traj)
    return float(np.sqrt(np.mean(np.sum((x - x_ref) ** 2, axis=-1)))) / bbox_diagonal(ref.X)


def pos_max_rel(ref: Trajectory, traj: Trajectory) -> float:
    """max over frames k of sqrt(mean_i |x_ki - x_ref_ki|^2) / L."""
    _, x_ref, x = _aligned(ref, traj)
    return float(np.max(_frame_rms(x_ref, x))) / bbox_diagonal(ref.X)


def final_err_rel(ref: Trajectory, traj: Trajectory) -> float:
    """sqrt(mean_i |x_Ki - x_ref_Ki|^2) / L at the last common frame K."""
    _, x_ref, x = _aligned(ref, traj)
    return float(_frame_rms(x_ref[-1:], x[-1:])[0]) / bbox_diagonal(ref.X)


def center_of_mass(x: np.ndarray, masses: np.ndarray | None = None) -> np.ndarray:
    """c = sum_i m_i x_i / sum_i m_i over the vertex axis: x (..., n, 3) -> (..., 3) [m]; uniform m by default."""
    m = _masses(x.shape[-2], masses)
    return np.einsum("i,...ij->...j", m, x) / m.sum()


def com_err_rel(ref: Trajectory, traj: Trajectory, masses: np.ndarray | None = None) -> float:
    """max over frames k of |c_k - c_ref_k| / L, c the mass-weighted centre (`center_of_mass`)."""
    _, x_ref, x = _aligned(ref, traj)
    d = center_of_mass(x, masses) - center_of_mass(x_ref, masses)
    return float(np.max(np.linalg.norm(d, axis=-1))) / bbox_diagonal(ref.X)


def _tangential(v: np.ndarray, n: np.ndarray) -> np.ndarray:
    """v - n (n . v): the part of vectors v (..., 3) in the plane with unit normal n."""
    return v - np.einsum("...j,j->...", v, n)[..., None] * n


def plane_travel(x: np.ndarray, plane_normal: ArrayLike3, masses: np.ndarray | None = None) -> np.ndarray:
    """s = P (c_last - c_first), P = I - n n^T: centre-of-mass displacement along the plane, (3,) [m]."""
    n, _ = unit_plane(plane_normal)
    c = center_of_mass(x[[0, -1]], masses)
    return _tangential(c[1] - c[0], n)


def slide_err_rel(ref: Trajectory, traj: Trajectory, plane_normal: ArrayLike3,
                  masses: np.ndarray | None = None, floor_rel: float = 1e-2) -> float:
    """|s - s_ref| / max(|s_ref|, floor_rel L) with s = `plane_travel` over the common frames.

    s is a vector, so sliding the right distance in the wrong direction counts as an error. The floor keeps the
    ratio finite where the reference barely moves (a body that sticks): there it is the travel error in units
    of floor_rel L.
    """
    _, x_ref, x = _aligned(ref, traj)
    s_ref, s = plane_travel(x_ref, plane_normal, masses), plane_travel(x, plane_normal, masses)
    denom = max(float(np.linalg.norm(s_ref)), floor_rel * bbox_diagonal(ref.X))
    return float(np.linalg.norm(s - s_ref)) / denom


def vertex_velocities(traj: Trajectory) -> np.ndarray:
    """Vertex velocities (F, n, 3) [m/s]: traj.v when stored, else dx/dt by finite differences of the frames.

    The differences are central inside and one-sided at the ends (`numpy.gradient`); a single frame gives zeros.
    """
    if traj.v is not None:
        return traj.v
    if traj.n_frames < 2:
        return np.zeros_like(traj.x)
    return np.gradient(traj.x, traj.t, axis=0)


#: `stick`'s rule for a body at rest on the plane: the centre's speed along it below max(REST_SPEED_TOL_REL L,
#: REST_CREEP_TOL x the law's creep speed), and its lowest point within REST_CONTACT_TOL_REL L of the plane.
REST_SPEED_TOL_REL = 1e-3
REST_CREEP_TOL = 5.0
REST_CONTACT_TOL_REL = 1e-2


def rest_speed_tol(L: float, creep_speed: float | None = None, speed_tol_rel: float = REST_SPEED_TOL_REL,
                   creep_tol: float = REST_CREEP_TOL) -> float:
    """The speed [m/s] below which a body on the plane is at rest (`stick`): max(speed_tol_rel L, creep_tol
    creep_speed), the creep speed [m/s] counted where given and finite; L [m]."""
    tol = speed_tol_rel * L
    if creep_speed is not None and np.isfinite(creep_speed):
        tol = max(tol, creep_tol * creep_speed)
    return tol


def _plane_speed(v: np.ndarray, n: np.ndarray, masses: np.ndarray | None) -> np.ndarray:
    """|P v_c|, the centre of mass's speed along the plane with unit normal n: velocities (..., n, 3) -> (...,)
    [m/s]."""
    return np.linalg.norm(_tangential(center_of_mass(v, masses), n), axis=-1)


def plane_speeds(traj: Trajectory, plane_normal: ArrayLike3, masses: np.ndarray | None = None) -> np.ndarray:
    """The centre of mass's speed along the plane in every frame, |P v_c,k| (F,) [m/s] (v from
    `vertex_velocities`, P = I - n n^T)."""
    return _plane_speed(vertex_velocities(traj), unit_plane(plane_normal)[0], masses)


def stick(traj: Trajectory, plane_normal: ArrayLike3, L: float | None = None, *,
          plane_offset: float | None = None, masses: np.ndarray | None = None, creep_speed: float | None = None,
          tail_fraction: float = 0.1, speed_tol_rel: float = REST_SPEED_TOL_REL, creep_tol: float = REST_CREEP_TOL,
          contact_tol_rel: float = REST_CONTACT_TOL_REL) -> tuple[bool, float]:
    """Is the body at rest on the plane at the end? Returns (verdict, measured speed [m/s]).

    speed = mean over the tail frames k of |P v_c,k|, the centre of mass's velocity along the plane
    (P = I - n n^T, v_c = sum_i m_i v_i / sum_i m_i, v from `vertex_velocities`). The tail is the frames with
    t >= t_end - tail_fraction (t_end - t_0), at least the last two. The body sticks when
    speed < max(speed_tol_rel * L, creep_tol * creep_speed) [m/s] and, if plane_offset d is given, it touches the
    plane at the last frame: min_i (n . x_i - d) <= contact_tol_rel * L. L defaults to the rest mesh's
    bounding-box diagonal. creep_speed [m/s] is the friction law's creep speed (`creep_speed_law`), used where
    finite: a regularised law holds a body by letting it creep at that speed, which can exceed 1e-3 L/s, and a
    body still settling at the end of a run is a small multiple of it (measured up to 2.1x in the quick suite),
    while bodies the law cannot hold move at 0.1-10 m/s on the shipped planes (hundreds of times more).
    """
    n, d = unit_plane(plane_normal, 0.0 if plane_offset is None else plane_offset)
    L = bbox_diagonal(traj.X) if L is None else L
    tail = _tail(traj.t, tail_fraction)
    speed = float(np.mean(_plane_speed(vertex_velocities(traj)[tail], n, masses)))
    at_rest = speed < rest_speed_tol(L, creep_speed, speed_tol_rel, creep_tol)
    if plane_offset is not None:
        at_rest = at_rest and float(np.min(traj.x[-1] @ n - d)) <= contact_tol_rel * L
    return bool(at_rest), speed


def stick_agree(ref: Trajectory, traj: Trajectory, plane_normal: ArrayLike3, *,
                plane_offset: float | None = None, masses: np.ndarray | None = None,
                creep_speed: float | None = None) -> bool:
    """stick(traj) == stick(ref), both judged with the reference's L and creep speed (see `stick`)."""
    L = bbox_diagonal(ref.X)
    kw = {"plane_offset": plane_offset, "masses": masses, "creep_speed": creep_speed}
    return stick(traj, plane_normal, L, **kw)[0] == stick(ref, plane_normal, L, **kw)[0]


def proj_rmse_rel(ref: Trajectory, basis: np.ndarray, masses: np.ndarray | None = None, frame: str = "world"
                  ) -> float:
    """Best relative error a subspace can reach on the reference: sqrt(mean_k,i |W_i q_k - u_ki|^2) / L.

    u_k = x_ref_k - X (F, n, 3) are the reference displacements, W the basis (n, 3, r) or (3n, r) [m], and q_k the
    per-frame least-squares fit: argmin_q |W q - u_k|^2 when masses is None (then this is the lowest
    `pos_rmse_rel` any trajectory in the subspace can have), else argmin_q (W q - u_k)^T M (W q - u_k) with the
    lumped mass matrix M (the reduced solver's own metric). The error itself is always the unweighted RMS. With
    frame = "body" (a basis whose deformation columns turn with the body, `solvers.reduced.frame`) u_k are the
    displacements in the body's frame (`body_frame_displacements`, the masses or uniform weights), whose fit errors
    are the world's, the frame being a rigid motion.
    """
    n = ref.X.shape[0]
    W = np.asarray(basis, dtype=float).reshape(n, 3, -1)
    u = (ref.x - ref.X if frame == "world"
         else body_frame_displacements(ref.X, ref.x, _masses(n, masses)))  # (F, n, 3)
    q = project(W, u, None if masses is None else _masses(n, masses))  # (F, r)
    return float(np.sqrt(np.mean(np.sum((np.einsum("ncr,fr->fnc", W, q) - u) ** 2, axis=-1)))) / bbox_diagonal(ref.X)


def finite(traj: Trajectory) -> bool:
    """True when every stored position, velocity and latent coordinate is finite."""
    return all(bool(np.isfinite(a).all()) for a in (traj.t, traj.x, traj.v, traj.q) if a is not None)


def max_penetration_rel(traj: Trajectory, plane_normal: ArrayLike3, plane_offset: float) -> float:
    """max(0, max over frames k and surface vertices i of -(n . x_ki - d)) / L for the plane n . x = d.

    Contact acts on the boundary surface (docs/physics.md, "Contact with the plane"), so penetration is the
    surface's. An interior vertex can only pass the plane while the surface stays above it if the elements between
    them invert, which `inverted_tets` reports.
    """
    n, d = unit_plane(plane_normal, plane_offset)
    points = np.unique(traj.surface) if traj.surface.size else slice(None)  # no surface given: every vertex
    depth = float(d - np.min(traj.x[:, points] @ n))
    return (depth if depth > 0.0 or np.isnan(depth) else 0.0) / bbox_diagonal(traj.X)


def inverted_tets(traj: Trajectory) -> tuple[int, int]:
    """(tets with J_e = det(F_e) <= 0 in at least one frame, the largest such count in one frame).

    J_e = det(Ds_e) / det(Dm_e), Ds and Dm the edge matrices [x1 - x0, x2 - x0, x3 - x0] of tet e now and at rest,
    so a tet listed with negative orientation at rest is not counted as inverted. Non-finite J is not counted.
    """
    det_dm = np.linalg.det(_edge_matrices(traj.X, traj.tets))
    ever = np.zeros(traj.tets.shape[0], dtype=bool)
    frame_max = 0
    for x in traj.x:
        with np.errstate(invalid="ignore"):
            bad = np.linalg.det(_edge_matrices(x, traj.tets)) / det_dm <= 0.0
        ever |= bad
        frame_max = max(frame_max, int(bad.sum()))
    return int(ever.sum()), frame_max


def volume_ratio(traj: Trajectory, frame: int = -1) -> float:
    """Total signed volume of a frame over the rest volume, sum_e det(Ds_e) / sum_e det(Dm_e) [-] (1 at rest;
    a fully mirrored body gives -1)."""
    return float(np.linalg.det(_edge_matrices(traj.x[frame], traj.tets)).sum()
                 / np.linalg.det(_edge_matrices(traj.X, traj.tets)).sum())


def inverted_tets_in_frame(traj: Trajectory, frame: int = -1) -> int:
    """Tets with J_e <= 0 in one frame (the last by default)."""
    det_dm = np.linalg.det(_edge_matrices(traj.X, traj.tets))
    with np.errstate(invalid="ignore"):
        return int((np.linalg.det(_edge_matrices(traj.x[frame], traj.tets)) / det_dm <= 0.0).sum())


def _tail(t: np.ndarray, tail_fraction: float) -> np.ndarray:
    """Frames with t >= t_end - tail_fraction (t_end - t_0), at least the last two, (F,) bool."""
    tail = t >= t[-1] - tail_fraction * (t[-1] - t[0])
    tail[-min(2, t.size):] = True
    return tail


def creep_speed_law(traj: Trajectory, plane: Plane, contact: Contact, material: Material,
                    gravity: ArrayLike3 = GRAVITY, tail_fraction: float = 0.1) -> float:
    """The friction law's creep speed [m/s] for the body as it lies at the end: the slip speed s at which
    sum_i A_i min(k_f s, mu f_n,i) carries the downhill weight M |g_t| (`solvers.physics.friction.creep_speed`).

    A_i are the surface vertices' area shares (rest mesh), f_n,i the contact law's normal pressure at their
    positions averaged over the tail frames (the frames `stick` averages the speed over; penalty: k_e times
    penetration, barrier: -kappa b'(d)), M the lumped mass of the material's density, g_t gravity's component
    along the plane. inf where friction cannot hold the body.
    """
    if contact.stiffness is None:
        raise ValueError("contact.stiffness is 'auto': pass the resolved contact (solvers.build.resolved)")
    n, d = unit_plane(plane.normal, plane.offset)
    mesh = TetMesh(X=traj.X, tets=traj.tets, surface=traj.surface, name="trajectory")
    area = mesh.surface_vertex_areas()
    pts = np.flatnonzero(area > 0.0)
    x = traj.x[_tail(traj.t, tail_fraction)][:, pts]
    fn = lagged_pressure(contact.law, x, np.zeros_like(x), n, d, contact.stiffness, 0.0, contact.barrier_stiffness,
                         contact.barrier_distance)
    weight = body_masses(traj, material, None).sum()
    g_t = float(np.linalg.norm(_tangential(np.asarray(gravity, dtype=float), n)))
    return creep_speed(area[pts], fn.mean(axis=0), plane.friction, contact.friction_stiffness, weight * g_t)


def _edge_matrices(x: np.ndarray, tets: np.ndarray) -> np.ndarray:
    """[x1 - x0, x2 - x0, x3 - x0] as columns, (m, 3, 3), for positions x (n, 3)."""
    return np.stack([x[tets[:, k]] - x[tets[:, 0]] for k in (1, 2, 3)], axis=-1)


def body_masses(traj: Trajectory, material: Material, masses: np.ndarray | None) -> np.ndarray:
    """Vertex masses (n,) [kg]: the given ones, else the lumped masses of the material's density."""
    if masses is None:
        volumes = np.abs(shape_matrices(traj.X, traj.tets)[1])  # |V_e|: a trajectory's tets may be unoriented
        return lumped_mass(volumes, traj.tets, traj.X.shape[0], material.density)
    return _masses(traj.X.shape[0], masses)


def kinetic_energy(v: np.ndarray, masses: np.ndarray) -> np.ndarray:
    """1/2 sum_i m_i |v_ki|^2 per frame: velocities (F, n, 3) [m/s], masses (n,) [kg] -> (F,) [J]."""
    return 0.5 * np.einsum("i,kij,kij->k", masses, v, v)


def energy_terms(traj: Trajectory, material: Material, gravity: ArrayLike3 = GRAVITY,
                 masses: np.ndarray | None = None) -> dict[str, np.ndarray]:
    """Per-frame energies [J], each (F,): `kinetic`, `elastic`, `gravity`.

    kinetic_k = 1/2 sum_i m_i |v_ki|^2 (v from `vertex_velocities`);
    elastic_k = sum_e V_e (Psi(F_ke) - Psi(I)), Psi the stable Neo-Hookean density with (mu, lam) from
    (E, nu) (`solvers.physics.material`), F = Ds Dm^-1; zero for the undeformed body;
    gravity_k = -M g . c_k - min_j (-M g . c_j), c the centre of mass: the potential measured from the lowest one
    reached in the trajectory, so every term is >= 0 near rest. m defaults to the lumped masses rho V_e / 4.
    Contact energy is not included (penetration is a metric of its own).
    """
    m = body_masses(traj, material, masses)
    kinetic = kinetic_energy(vertex_velocities(traj), m)
    mu, lam = snh_parameters(material.youngs_modulus, material.poisson_ratio)
    dm_inv, vol = shape_matrices(traj.X, traj.tets)
    psi_rest = float(snh_energy_density(np.eye(3), mu, lam))
    elastic = np.array([vol @ (snh_energy_density(_edge_matrices(x, traj.tets) @ dm_inv, mu, lam) - psi_rest)
                        for x in traj.x])
    potential = -(traj.x @ np.asarray(gravity, dtype=float)) @ m
    return {"kinetic": kinetic, "elastic": elastic, "gravity": potential - np.min(potential)}


def energy_ratio_max(traj: Trajectory, material: Material, gravity: ArrayLike3 = GRAVITY,
                     masses: np.ndarray | None = None) -> float:
    """max_k E_k / E_0, E = kinetic + elastic + gravity from `energy_terms`; <= 1 when energy never grows.

    When E_0 is zero up to round-off (below 1e-12 of max(max_k |E_k|, M |g| L), e.g. a body at rest at its lowest
    point), the ratio is 1 if every E_k is that small too and inf otherwise. NaN for a non-finite trajectory.
    """
    if not finite(traj):
        return float("nan")
    E = sum(energy_terms(traj, material, gravity, masses).values())
    weight = body_masses(traj, material, masses).sum() * float(np.linalg.norm(gravity)) * bbox_diagonal(traj.X)
    tiny = 1e-12 * max(float(np.max(np.abs(E))), weight)
    if E[0] <= tiny:
        return 1.0 if float(np.max(E)) <= tiny else float("inf")
    return float(np.max(E) / E[0])


@dataclass(frozen=True, eq=False)
class ComparedRun:
    """A finished run and the reference it is compared with: what every computed column of the schema takes
    (`analysis.schema.Column.compute`, evaluated by `analysis.schema.computed_cells`).

    ref, traj: the reference's and the run's trajectories on the same mesh (F frames, n vertices); scenario: the
    run's; contact_stiffness: the contact law's normal stiffness the run resolved [Pa/m] (its stats'
    `contact_stiffness`; None where not known: no creep metrics). The inputs several metrics share (`masses`,
    `contact`) are computed once per run, and so is a computation that gives several columns together (`once`).
    """

    ref: Trajectory
    traj: Trajectory
    scenario: Scenario
    contact_stiffness: float | None = None
    _once: dict = field(default_factory=dict, init=False, repr=False)

    @cached_property
    def masses(self) -> np.ndarray:
        """Vertex masses (n,) [kg] weighting centres of mass and energies: the lumped masses of the scenario's
        material on the reference's rest mesh (`body_masses`)."""
        return body_masses(self.ref, self.scenario.material, None)

    @cached_property
    def contact(self) -> Contact | None:
        """The scenario's contact law with the stiffness the run resolved, the creep metrics' input; None where
        friction is off or the stiffness is not known."""
        if not self.scenario.effects.friction or self.contact_stiffness is None:
            return None
        return replace(self.scenario.contact, stiffness=self.contact_stiffness)

    def once(self, group: Callable[[ComparedRun], dict[str, object]]) -> dict[str, object]:
        """group(self) -> {column: value}, computed on the first call for this run and kept: the cells of the
        columns one computation gives together (`analysis.schema.together`)."""
        if group not in self._once:
            self._once[group] = group(self)
        return self._once[group]


def stick_cells(run: ComparedRun) -> dict[str, object]:
    """stick, stick_ref, stick_agree, end_speed [m/s] and end_speed_ref [m/s]: `stick` of the run and of its
    reference, both judged with the reference's L and masses and, where friction acts, the friction law's creep
    speed for the reference as it lies at the end (a body the law holds creeps at it); None without a plane."""
    plane = run.scenario.plane
    if plane is None:
        return dict.fromkeys(("stick", "stick_ref", "stick_agree", "end_speed", "end_speed_ref"))
    creep = (creep_speed_law(run.ref, plane, run.contact, run.scenario.material, run.scenario.gravity)
             if run.contact is not None and plane.friction > 0 and finite(run.ref) else None)
    kw = {"plane_offset": plane.offset, "masses": run.masses, "creep_speed": creep}
    at_rest, speed = stick(run.traj, plane.normal, bbox_diagonal(run.ref.X), **kw)
    at_rest_ref, speed_ref = stick(run.ref, plane.normal, bbox_diagonal(run.ref.X), **kw)
    return {"stick": at_rest, "stick_ref": at_rest_ref, "stick_agree": at_rest == at_rest_ref, "end_speed": speed,
            "end_speed_ref": speed_ref}


def inverted_cells(run: ComparedRun) -> dict[str, object]:
    """inverted_tets and inverted_tets_frame_max [count] of the run (`inverted_tets`, one pass over its frames)."""
    ever, frame_max = inverted_tets(run.traj)
    return {"inverted_tets": ever, "inverted_tets_frame_max": frame_max}


def creep_cells(run: ComparedRun) -> dict[str, object]:
    """creep_speed_law [m/s], the friction law's creep speed for the run as it lies at the end (`creep_speed_law`),
    and creep_ratio [-], its end_speed over that (about 1 for a body the law holds, 0 for one it cannot hold: creep
    speed inf; None on level ground, creep speed 0); both None unless the run is finite and on a plane with
    friction with a known contact (`ComparedRun.contact`)."""
    plane = run.scenario.plane
    if run.contact is None or plane is None or not plane.friction > 0 or not finite(run.traj):
        return {"creep_speed_law": None, "creep_ratio": None}
    law = creep_speed_law(run.traj, plane, run.contact, run.scenario.material, run.scenario.gravity)
    return {"creep_speed_law": law, "creep_ratio": run.once(stick_cells)["end_speed"] / law if law > 0 else None}

"""Metrics on synthetic trajectories whose answers are known in closed form."""

from __future__ import annotations

import itertools

import numpy as np
import pytest

from frictionbench.analysis import metrics
from frictionbench.analysis.schema import computed_cells
from frictionbench.scenarios.spec import Material, Plane, Scenario
from frictionbench.solvers.physics.inertia import lumped_mass
from frictionbench.solvers.physics.material import shape_matrices, snh_energy_density, snh_parameters
from frictionbench.solvers.trajectory import Trajectory

GRAVITY = np.array([0.0, -9.81, 0.0])
#: The built-in metrics of one run against its reference (the schema's computed columns), in table order.
BUILT_IN = ("frames_compared", "pos_rmse_rel", "pos_max_rel", "com_err_rel", "final_err_rel", "slide_err_rel",
            "proj_rmse_rel", "stick", "stick_ref", "stick_agree", "end_speed", "end_speed_ref", "finite",
            "max_penetration_rel", "inverted_tets", "inverted_tets_frame_max", "inverted_tets_final",
            "volume_ratio_final", "energy_ratio_max", "creep_speed_law", "creep_ratio")


def unit_cube() -> tuple[np.ndarray, np.ndarray]:
    """Rest positions (8, 3) of the unit cube (vertex i has coordinates bits of i) and its 6 Kuhn tets (6, 4),
    each positively oriented."""
    X = np.array([[(i >> a) & 1 for a in range(3)] for i in range(8)], dtype=float)
    tets = []
    for perm in itertools.permutations(range(3)):
        path = [0, 1 << perm[0], (1 << perm[0]) | (1 << perm[1]), 7]
        if np.linalg.det(np.stack([X[p] - X[path[0]] for p in path[1:]], axis=-1)) < 0:
            path[1], path[2] = path[2], path[1]
        tets.append(path)
    return X, np.array(tets)


def make_traj(x: np.ndarray, t: np.ndarray | None = None, v: np.ndarray | None = None) -> Trajectory:
    """Trajectory of the unit cube with frames x (F, 8, 3) at times t (default 0.1 s apart)."""
    X, tets = unit_cube()
    t = np.arange(x.shape[0]) * 0.1 if t is None else t
    return Trajectory(t=t, x=x, X=X, tets=tets, surface=np.zeros((0, 3), dtype=int), v=v)


def moving(offsets: np.ndarray) -> Trajectory:
    """The undeformed cube translated by offsets (F, 3)."""
    X, _ = unit_cube()
    return make_traj(X[None] + offsets[:, None, :])


L = np.sqrt(3.0)  # bounding-box diagonal of the unit cube


def wobble(F: int = 6) -> np.ndarray:
    """Some non-rigid motion (F, 8, 3) of the cube."""
    X, _ = unit_cube()
    k = np.arange(F)[:, None, None]
    return X[None] * (1.0 + 0.05 * np.sin(k)) + 0.1 * k * np.array([1.0, 0.0, 0.0])


def cells(ref: Trajectory, traj: Trajectory, **scene) -> dict:
    """Every computed column of `traj` against `ref` in a scenario with the fields `scene`, through the schema."""
    return computed_cells(metrics.ComparedRun(ref, traj, Scenario(name="metrics", **scene)))


def test_rigid_offset_gives_offset_over_L() -> None:
    ref = make_traj(wobble())
    d = np.array([0.03, -0.04, 0.12])
    traj = make_traj(ref.x + d)
    expected = np.linalg.norm(d) / L
    for value in (metrics.pos_rmse_rel(ref, traj), metrics.pos_max_rel(ref, traj),
                  metrics.com_err_rel(ref, traj), metrics.final_err_rel(ref, traj)):
        assert value == pytest.approx(expected, rel=1e-12)
    masses = np.linspace(1.0, 2.0, 8)
    assert metrics.com_err_rel(ref, traj, masses) == pytest.approx(expected, rel=1e-12)
    t, e = metrics.error_over_time(ref, traj)
    np.testing.assert_allclose(t, ref.t)
    np.testing.assert_allclose(e, expected, rtol=1e-12)


def test_a_trajectory_is_stored_uncompressed_and_read_back_bitwise(tmp_path) -> None:
    """Every array of a stored trajectory comes back bitwise, and none is compressed: the matrix's client writes
    the store while workers' steps are timed, and zlib gains a few per cent on float64 frames for ~45 ms a MB."""
    import zipfile

    rng = np.random.default_rng(3)
    traj = make_traj(rng.standard_normal((5, 8, 3)), v=rng.standard_normal((5, 8, 3)))
    traj.q, traj.basis, traj.meta = rng.standard_normal((5, 2)), rng.standard_normal((8, 3, 2)), {"seed": 3}
    path = traj.save(tmp_path / "trajectory.npz")
    assert {i.compress_type for i in zipfile.ZipFile(path).infolist()} == {zipfile.ZIP_STORED}
    back = Trajectory.load(path)
    for name in ("t", "x", "X", "tets", "surface", "v", "q", "basis"):
        assert np.array_equal(getattr(back, name), getattr(traj, name)), name
    assert back.meta == traj.meta


def test_identical_trajectories_give_zero_errors() -> None:
    ref = make_traj(wobble())
    row = cells(ref, ref, plane=Plane(normal=(0.0, 1.0, 0.0), offset=-1.0))
    assert list(row) == list(BUILT_IN)
    for key in ("pos_rmse_rel", "pos_max_rel", "com_err_rel", "final_err_rel", "slide_err_rel"):
        assert row[key] == 0.0
    assert row["stick_agree"] is True
    assert row["frames_compared"] == ref.n_frames
    assert row["finite"] is True and row["inverted_tets"] == 0 and row["max_penetration_rel"] == 0.0


def test_errors_grow_over_time_and_max_is_the_worst_frame() -> None:
    ref = moving(np.zeros((5, 3)))
    drift = np.array([[0.0, 0.0, 0.1 * k] for k in range(5)])
    traj = moving(drift)
    assert metrics.pos_max_rel(ref, traj) == pytest.approx(0.4 / L)
    assert metrics.final_err_rel(ref, traj) == pytest.approx(0.4 / L)
    assert metrics.pos_rmse_rel(ref, traj) == pytest.approx(np.sqrt(np.mean((0.1 * np.arange(5)) ** 2)) / L)


def test_frames_are_aligned_on_common_times() -> None:
    ref = moving(np.array([[0.0, 0.0, 0.1 * k] for k in range(9)]))
    every_other = make_traj(ref.x[::2] + np.array([0.0, 0.2, 0.0]), t=ref.t[::2].copy())
    i_ref, i = metrics.align_frames(ref.t, every_other.t)
    np.testing.assert_array_equal(i_ref, [0, 2, 4, 6, 8])
    np.testing.assert_array_equal(i, np.arange(5))
    assert metrics.pos_rmse_rel(ref, every_other) == pytest.approx(0.2 / L)
    assert cells(ref, every_other, plane=None)["frames_compared"] == 5


def test_disjoint_times_are_an_error() -> None:
    ref = moving(np.zeros((3, 3)))
    later = make_traj(ref.x, t=ref.t + 10.0)
    with pytest.raises(ValueError, match="no common frame times"):
        metrics.pos_rmse_rel(ref, later)


def test_different_meshes_are_an_error() -> None:
    ref = moving(np.zeros((3, 3)))
    other = Trajectory(t=ref.t, x=ref.x * 2, X=ref.X * 2, tets=ref.tets, surface=ref.surface)
    with pytest.raises(ValueError, match="different meshes"):
        metrics.pos_rmse_rel(ref, other)


def sliding(speed: float, F: int = 21, dt: float = 0.1) -> Trajectory:
    """The cube resting on the plane y = 0 and sliding along +x at constant speed [m/s]."""
    t = np.arange(F) * dt
    return moving(np.stack([speed * t, np.zeros(F), np.zeros(F)], axis=1))


def test_slide_error_of_stopped_and_half_speed_bodies() -> None:
    normal = (0.0, 1.0, 0.0)
    ref = sliding(0.5)  # travels 1 m in 2 s
    assert metrics.slide_err_rel(ref, sliding(0.0), normal) == pytest.approx(1.0)
    assert metrics.slide_err_rel(ref, sliding(0.25), normal) == pytest.approx(0.5)
    # Motion along the normal is not travel along the plane.
    lifted = make_traj(ref.x + np.array([0.0, 0.3, 0.0]) * ref.t[:, None, None])
    assert metrics.slide_err_rel(ref, lifted, normal) == pytest.approx(0.0, abs=1e-12)


def test_slide_error_floor_when_reference_sticks() -> None:
    ref = sliding(0.0)
    creeping = sliding(0.01)  # travels 0.02 m
    assert metrics.slide_err_rel(ref, creeping, (0.0, 1.0, 0.0)) == pytest.approx(0.02 / (1e-2 * L))


def test_stick_detects_rest_and_sliding() -> None:
    normal, plane = (0.0, 1.0, 0.0), Plane(normal=(0.0, 1.0, 0.0), offset=0.0)
    stuck, stick_speed = metrics.stick(sliding(0.0), normal, plane_offset=0.0)
    slid, slide_speed = metrics.stick(sliding(0.5), normal, plane_offset=0.0)
    assert stuck and stick_speed == pytest.approx(0.0, abs=1e-12)
    assert not slid and slide_speed == pytest.approx(0.5)
    # At rest, but hovering above the plane: not on the plane.
    hovering = make_traj(sliding(0.0).x + np.array([0.0, 0.5, 0.0]))
    assert metrics.stick(hovering, normal)[0]
    assert not metrics.stick(hovering, normal, plane_offset=0.0)[0]
    assert not metrics.stick_agree(sliding(0.5), sliding(0.0), normal)
    row = cells(sliding(0.5), sliding(0.0), plane=plane)
    assert row["stick_ref"] is False and row["stick"] is True and row["stick_agree"] is False
    assert row["end_speed_ref"] == pytest.approx(0.5)


def test_a_body_creeping_at_the_friction_laws_speed_sticks() -> None:
    """The regularised law holds a body by letting it creep: a speed within 5x the law's creep speed is rest,
    even above 1e-3 L/s; where the law cannot hold the body (creep speed inf) the plain threshold stays."""
    normal = (0.0, 1.0, 0.0)
    creeping = sliding(3e-3 * L)
    assert not metrics.stick(creeping, normal, plane_offset=0.0)[0]
    assert metrics.stick(creeping, normal, plane_offset=0.0, creep_speed=1e-3 * L)[0]
    assert not metrics.stick(creeping, normal, plane_offset=0.0, creep_speed=0.5e-3 * L)[0]
    assert not metrics.stick(creeping, normal, plane_offset=0.0, creep_speed=float("inf"))[0]
    assert metrics.stick_agree(sliding(0.0), creeping, normal, plane_offset=0.0, creep_speed=1e-3 * L)


def test_stick_uses_stored_velocities() -> None:
    still = sliding(0.0)
    with_v = make_traj(still.x, v=np.full_like(still.x, 0.0) + np.array([0.2, 0.0, 0.0]))
    stuck, speed = metrics.stick(with_v, (0.0, 1.0, 0.0))
    assert not stuck and speed == pytest.approx(0.2)


def test_projection_error_is_zero_when_basis_contains_the_motion() -> None:
    X, _ = unit_cube()
    n = X.shape[0]
    e = np.eye(3)
    translations = [np.tile(e[a], (n, 1)) for a in range(3)]
    stretch_x = X[:, 0:1] * e[0]
    W = np.stack(translations + [stretch_x], axis=-1)  # (n, 3, 4)
    k = np.arange(7)[:, None, None]
    ref = make_traj(X[None] + 0.1 * k * translations[1] + 0.02 * k**2 * stretch_x)
    assert metrics.proj_rmse_rel(ref, W) == pytest.approx(0.0, abs=1e-12)
    assert metrics.proj_rmse_rel(ref, W.reshape(3 * n, 4), np.linspace(1.0, 2.0, n)) == pytest.approx(0.0, abs=1e-12)
    # A basis orthogonal to the motion cannot reduce it: the error is the motion itself.
    shift = moving(np.array([[0.0, 0.0, 0.0], [0.3, 0.0, 0.0], [0.6, 0.0, 0.0]]))
    only_y = translations[1][..., None]
    assert metrics.proj_rmse_rel(shift, only_y) == pytest.approx(np.sqrt((0.3**2 + 0.6**2) / 3) / L)


def test_inverted_tets_of_a_flipped_tet() -> None:
    X = np.array([[0.0, 0.0, 0.0], [1.0, 0.0, 0.0], [0.0, 1.0, 0.0], [0.0, 0.0, 1.0]])
    flipped = X.copy()
    flipped[3, 2] = -1.0  # apex mirrored through the base: det(F) = -1
    flat = X.copy()
    flat[3, 2] = 0.0  # degenerate: det(F) = 0 counts as inverted
    x = np.stack([X, flipped, X, flat])
    traj = Trajectory(t=np.arange(4.0), x=x, X=X, tets=np.array([[0, 1, 2, 3]]), surface=np.zeros((0, 3), int))
    assert metrics.inverted_tets(traj) == (1, 1)
    # A tet listed with negative orientation at rest is judged relative to its rest orientation.
    listed_negative = Trajectory(t=traj.t, x=x, X=X, tets=np.array([[0, 2, 1, 3]]), surface=traj.surface)
    assert metrics.inverted_tets(listed_negative) == (1, 1)
    assert metrics.inverted_tets(make_traj(wobble())) == (0, 0)


def test_inverted_tets_counts_distinct_tets_and_worst_frame() -> None:
    X, _ = unit_cube()
    squashed = X.copy()
    squashed[7] = [0.0, 0.0, 0.0]  # every Kuhn tet uses vertex 7 on its main diagonal: all six become degenerate
    assert metrics.inverted_tets(make_traj(np.stack([X, squashed, X]))) == (6, 6)


def test_penetration_of_a_known_offset() -> None:
    traj = moving(np.array([[0.0, 0.2, 0.0], [0.0, -0.05, 0.0], [0.0, 0.0, 0.0]]))
    assert metrics.max_penetration_rel(traj, (0.0, 1.0, 0.0), 0.0) == pytest.approx(0.05 / L)
    # The plane n . x = d is normalised: (0, 2, 0) . x = 0.2 is y = 0.1.
    assert metrics.max_penetration_rel(traj, (0.0, 2.0, 0.0), 0.2) == pytest.approx(0.15 / L)
    assert metrics.max_penetration_rel(traj, (0.0, 1.0, 0.0), -1.0) == 0.0


def test_finite() -> None:
    traj = make_traj(wobble())
    assert metrics.finite(traj)
    traj.x[3, 2, 1] = np.nan
    assert not metrics.finite(traj)
    assert np.isnan(metrics.energy_ratio_max(traj, Material()))


def test_lumped_masses_sum_to_body_mass() -> None:
    X, tets = unit_cube()
    m = lumped_mass(shape_matrices(X, tets)[1], tets, X.shape[0], 1000.0)
    assert m.sum() == pytest.approx(1000.0)
    assert np.all(m > 0)


def test_energy_ratio_of_a_static_undeformed_body_is_one() -> None:
    traj = moving(np.zeros((5, 3)) + np.array([0.0, 2.0, 0.0]))
    assert metrics.energy_ratio_max(traj, Material()) == 1.0
    terms = metrics.energy_terms(traj, Material())
    for values in terms.values():
        np.testing.assert_allclose(values, 0.0, atol=1e-9)


def test_energy_is_conserved_in_exact_free_fall() -> None:
    t = np.linspace(0.0, 1.0, 11)
    X, _ = unit_cube()
    x = X[None] + 0.5 * GRAVITY * t[:, None, None] ** 2
    v = np.broadcast_to(GRAVITY * t[:, None, None], x.shape).copy()
    traj = make_traj(x, t=t, v=v)
    material = Material(density=500.0)
    terms = metrics.energy_terms(traj, material, GRAVITY)
    total = sum(terms.values())
    np.testing.assert_allclose(total, total[0], rtol=1e-12)
    assert total[0] == pytest.approx(500.0 * 9.81 * 0.5 * 9.81)  # M g h with h = g T^2 / 2
    assert metrics.energy_ratio_max(traj, material, GRAVITY) == pytest.approx(1.0, rel=1e-12)
    # Without stored velocities the finite differences are exact inside a quadratic motion, not at the ends.
    assert metrics.energy_ratio_max(make_traj(x, t=t), material, GRAVITY) == pytest.approx(1.0, rel=0.2)


def test_elastic_energy_is_rotation_invariant_and_matches_the_density() -> None:
    X, _ = unit_cube()
    c, s = np.cos(0.7), np.sin(0.7)
    R = np.array([[c, -s, 0.0], [s, c, 0.0], [0.0, 0.0, 1.0]])
    stretch = np.diag([1.1, 0.95, 1.0])
    material = Material(youngs_modulus=2.0e5, poisson_ratio=0.35)
    traj = make_traj(np.stack([X, X @ R.T, X @ stretch.T]))
    elastic = metrics.energy_terms(traj, material, gravity=(0.0, 0.0, 0.0))["elastic"]
    mu, lam = snh_parameters(material.youngs_modulus, material.poisson_ratio)
    expected = snh_energy_density(stretch, mu, lam) - snh_energy_density(np.eye(3), mu, lam)  # volume 1
    np.testing.assert_allclose(elastic, [0.0, 0.0, expected], atol=1e-9)
    assert expected > 0


def test_energy_growth_shows_in_the_ratio() -> None:
    # Released from rest 1 m above its lowest point, then bounced back up to 2 m: energy doubled.
    heights = np.array([1.0, 0.0, 2.0])
    traj = moving(np.stack([np.zeros(3), heights, np.zeros(3)], axis=1))
    traj.v = np.zeros_like(traj.x)
    assert metrics.energy_ratio_max(traj, Material()) == pytest.approx(2.0)

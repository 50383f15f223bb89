"""A scene's time scales (solvers.physics.timescales, analysis.timescales): the elastic spectrum's top and first mode
and the exact count of unresolved modes against dense eigenvalues, the contact frequency against a mass on a spring
(formula and a simulated bounce), the barrier's stiffness at its resting gap, and the columns they give every row
and the report beside each truth."""

from __future__ import annotations

from dataclasses import replace

import numpy as np
import pandas as pd
import pytest
import scipy.linalg as sla

from frictionbench.analysis.rows import collect_rows
from frictionbench.analysis.schema import COLUMNS
from frictionbench.analysis.timescales import RESOLUTION_COLUMNS, SCENE_COLUMNS, effective_step
from frictionbench.bench.runner import Task
from frictionbench.reports.html import write_report_html
from frictionbench.scenarios.meshes import TetMesh, load_mesh, make_mesh
from frictionbench.scenarios.meshgen import structured_box
from frictionbench.scenarios.spec import Contact, Effects, Initial, Material, MeshSpec, Plane, Scenario, TimeSpec
from frictionbench.scenarios.suites import Suite, SuiteMember
from frictionbench.solvers import linalg
from frictionbench.solvers.build import build_model, initial_state
from frictionbench.solvers.full.solver import FullSpaceSolver, NewtonSettings
from frictionbench.solvers.model import Model
from frictionbench.solvers.physics import timescales as ts
from frictionbench.solvers.physics.contact import barrier_d1, barrier_d2
from frictionbench.solvers.physics.material import rest_stiffness
from frictionbench.solvers.simulate import simulate
from frictionbench.solvers.trajectory import Trajectory

from fakes import FakeLadder, FakeStore

#: The block resting on its face: edge [m], density [kg/m^3] (M = 1 kg), penalty stiffness and damping per area.
EDGE, RHO, KE, KD = 0.1, 1000.0, 1.0e6, 50.0
#: Its contact patch [m^2]: the area weights of the base's vertices (each a third of its surface triangles): the
#: base, EDGE^2, and of each of the four sides half its lowest row of quads (of each quad's two triangles, one has
#: two base vertices and one has one: (2/3 + 1/3) / 2 of the quad), 4 (EDGE EDGE/2) / 2 = EDGE^2.
PATCH = 2 * EDGE**2


@pytest.fixture(scope="module")
def box() -> TetMesh:
    """A small box with three different side lengths: 60 vertices, 144 tets."""
    X, tets = structured_box((0.2, 0.1, 0.15), (4, 2, 3), (-0.1, 0.0, -0.075))
    return make_mesh(X, tets, "box")


@pytest.fixture(scope="module")
def cube() -> TetMesh:
    """A 0.1 m cube, its base on y = 0: 27 vertices, 48 tets."""
    X, tets = structured_box((EDGE, EDGE, EDGE), (2, 2, 2), (-EDGE / 2, 0.0, -EDGE / 2))
    return make_mesh(X, tets, "cube")


def dense_spectrum(model: Model) -> np.ndarray:
    """Every eigenvalue omega^2 [1/s^2] of K phi = omega^2 M phi, ascending (dense)."""
    return sla.eigh(rest_stiffness(model).toarray(), np.diag(np.repeat(model.mass, 3)), eigvals_only=True)


def resting_cube(cube: TetMesh, law: str = "penalty", youngs_modulus: float = 1e8, friction: float = 0.5,
                 depth: float = 5e-4, dt: float = 5e-4, duration: float = 0.2) -> Model:
    """The stiff cube on the horizontal plane y = 0, its base `depth` [m] below it, at rest."""
    sc = Scenario(name="cube", material=Material(density=RHO, youngs_modulus=youngs_modulus),
                  plane=Plane(friction=friction), initial=Initial(clearance=-depth),
                  contact=Contact(law=law, stiffness=KE, damping=KD, friction_stiffness=1e5),
                  time=TimeSpec(dt=dt, duration=duration, integrator="bdf2"), effects=Effects(damping=True))
    return build_model(sc, cube)


# ----- the elastic spectrum ------------------------------------------------------------------------------------
def test_spectrum_top_and_first_mode_match_the_dense_eigenvalues(box):
    model = build_model(Scenario(name="box", plane=None, gravity=(0.0, 0.0, 0.0)), box)
    w = dense_spectrum(model)
    omega_max, omega_1 = ts.elastic_scales(model)
    assert omega_max == pytest.approx(np.sqrt(w[-1]), rel=1e-6)
    assert omega_1 == pytest.approx(np.sqrt(w[6]), rel=1e-8)  # after the six rigid modes
    assert omega_1 < omega_max


def test_the_count_of_unresolved_modes_is_exact_on_a_coarse_mesh():
    sc = Scenario(name="cheese", mesh=MeshSpec("cheese", "coarse"), material=Material(youngs_modulus=2e5))  # quick's
    model = build_model(sc, load_mesh(sc.mesh))
    w = dense_spectrum(model)
    n_elastic = 3 * model.n - 6
    for dt in (0.0025, 0.00125, 0.000625):  # the 71%, 29% and 2% of modes with omega h_eff > 1 (BDF2)
        h = effective_step("bdf2", dt)
        above = int(np.count_nonzero(w > 1.0 / h**2))
        assert ts.modes_above(model, 1.0 / h) == above
        assert ts.unresolved_share(model, h) == pytest.approx(above / n_elastic)
    assert [round(ts.unresolved_share(model, effective_step("bdf2", dt)), 2) for dt in (0.0025, 0.00125)] == \
        [0.71, 0.29]


def test_the_dense_inertia_fallback_counts_the_same(box, monkeypatch):
    model = build_model(Scenario(name="box", plane=None, gravity=(0.0, 0.0, 0.0)), box)
    w = dense_spectrum(model)
    omega = float(np.sqrt(w[100]) * 1.001)  # between two eigenvalues
    expected = int(np.count_nonzero(w > omega**2))
    assert ts.modes_above(model, omega) == expected
    monkeypatch.setattr(linalg, "pypardiso", None)
    assert ts.modes_above(model, omega) == expected


def test_bad_frequencies_and_steps_are_refused(box):
    model = build_model(Scenario(name="box", plane=None), box)
    with pytest.raises(ValueError, match="omega = -1"):
        ts.modes_above(model, -1.0)
    with pytest.raises(ValueError, match="h_eff = 0"):
        ts.unresolved_share(model, 0.0)


# ----- contact and friction ------------------------------------------------------------------------------------
def test_contact_and_friction_of_a_block_on_its_face_are_a_mass_on_a_spring(cube):
    model = resting_cube(cube)
    x = initial_state(model).x
    A, M = PATCH, RHO * EDGE**3  # the base touches; 1 kg
    assert ts.touching_area(model, x) == pytest.approx(A)
    assert ts.touching_area(model, x + [0.0, 1e-3, 0.0]) == 0.0  # lifted off
    scales = ts.time_scales(model, A)
    assert scales.omega_contact == pytest.approx(np.sqrt(KE * A / M))  # 141 rad/s
    assert scales.zeta_contact == pytest.approx(KD * A / (2 * np.sqrt(KE * A * M)))
    assert scales.tau_friction == pytest.approx(M / (1e5 * A))
    # per vertex: zeta_i = k_d / (2 k_e) omega_i and tau_i = m_i / (k_f a_i) = k_e / (k_f omega_i^2)
    omega_i = np.sqrt(KE * model.area / model.mass[model.points])
    assert scales.omega_contact_vertex == pytest.approx(omega_i.max())
    assert scales.zeta_contact_vertex == pytest.approx(KD / (2 * KE) * omega_i.min())
    assert scales.tau_friction_vertex == pytest.approx(KE / (1e5 * scales.omega_contact_vertex**2))
    res = scales.resolution(0.002)
    assert res["contact"] == pytest.approx(0.002 * np.sqrt(KE * A / M))
    assert res["friction"] == pytest.approx(0.002 / scales.tau_friction)


def test_without_friction_or_patch_the_figures_are_nan(cube):
    model = resting_cube(cube, friction=0.0)
    scales = ts.time_scales(model, 0.0)
    assert np.isnan(scales.omega_contact) and np.isnan(scales.tau_friction) and np.isnan(scales.tau_friction_vertex)
    assert scales.omega_contact_vertex > 0.0


def test_the_barrier_stiffness_is_taken_at_the_gap_that_carries_the_weight(cube):
    model = resting_cube(cube, law="barrier")
    c = model.contact
    d = 0.3 * c.barrier_distance
    pressure = float(-c.barrier_stiffness * barrier_d1(np.array([d]), c.barrier_distance)[0])
    assert ts.contact_stiffness(model, pressure) == pytest.approx(
        c.barrier_stiffness * barrier_d2(np.array([d]), c.barrier_distance)[0], rel=1e-8)
    assert ts.contact_stiffness(model, 0.0) == 0.0
    assert ts.time_scales(model, PATCH).zeta_contact == 0.0  # the barrier has no damping term


def test_a_block_on_its_face_bounces_at_the_whole_body_contact_frequency(cube):
    """Simulated: the stiff cube (elastic modes above 5,000 rad/s) pressed 0.3 mm into the plane oscillates
    about its resting depth M g / (k_e A) = 0.49 mm without leaving it, at omega_c = sqrt(k_e A / M) = 141
    rad/s (BDF2 at omega_c h_eff = 0.05: its period error is O((omega h)^2)); undamped."""
    model = replace(resting_cube(cube, friction=0.0, depth=3e-4),
                    terms=("inertia", "elasticity", "gravity", "contact"))
    traj, stats = simulate(model, FullSpaceSolver(model, settings=NewtonSettings(tol=1e-10)))
    assert all(s.converged for s in stats)
    y = traj.x[:, :, 1] @ model.mass / model.mass.sum()
    y = y - 0.5 * (y.max() + y.min())
    up = np.flatnonzero((y[:-1] < 0) & (y[1:] >= 0))
    crossings = traj.t[up] - y[up] * (traj.t[up + 1] - traj.t[up]) / (y[up + 1] - y[up])
    omega = 2 * np.pi / np.diff(crossings).mean()
    assert len(crossings) >= 3
    assert omega == pytest.approx(ts.time_scales(model, PATCH).omega_contact, rel=0.01)
    base = np.flatnonzero(model.X[:, 1] == 0.0)
    assert traj.x[:, base, 1].max() < 0.0  # the base never lifted off: a linear spring throughout


# ----- rows and report -----------------------------------------------------------------------------------------


def test_every_row_gets_the_scene_time_scales_and_its_step_resolution_and_the_report_shows_them(cube, tmp_path):
    model = resting_cube(cube, youngs_modulus=2e5, dt=0.01, duration=0.02)
    x = initial_state(model).x
    run = Trajectory(t=np.array([0.0, 0.01, 0.02]), x=np.stack([x, x, x]), X=model.X, tets=model.tets,
                     surface=model.surface)
    sc = replace(model.scenario, name="cube")
    levels = [replace(sc, time=replace(sc.time, dt=sc.time.dt / 2**k)) for k in range(3)]
    ref_task, tasks = Task(sc, "full", {}), [Task(level, "full", {"k": k}) for k, level in enumerate(levels)]
    stats = {"contact_stiffness": KE, "step_ms_median": 1.0}
    store = FakeStore({t.key: (run, stats) for t in [ref_task, *tasks]})
    ladders = {"cube": {"bdf2": FakeLadder("bdf2", tasks, [0.01, 0.004])}}
    rows = collect_rows(Suite("toy", "", (SuiteMember(sc, "test", {}),)), {"cube": ref_task},
                        [], store, ladders)
    assert set(SCENE_COLUMNS) | set(RESOLUTION_COLUMNS) <= set(COLUMNS)
    assert len(rows) == 4 and all(set(SCENE_COLUMNS) | set(RESOLUTION_COLUMNS) <= set(row) for row in rows)
    ladder = [row for row in rows if row.get("ladder_level") is not None]
    assert [row["h_eff"] for row in ladder] == pytest.approx([2 / 3 * 0.01 / 2**k for k in range(3)])
    assert ladder[0]["ts_patch_area"] == pytest.approx(PATCH)
    assert ladder[0]["ts_omega_contact"] == pytest.approx(np.sqrt(KE * PATCH / RHO / EDGE**3))
    assert ladder[1]["res_contact"] == pytest.approx(ladder[0]["ts_omega_contact"] * 2 / 3 * 0.005)
    assert ladder[2]["res_unresolved_share"] == ts.unresolved_share(model, 2 / 3 * 0.0025)
    assert ladder[0]["res_omega_max"] == pytest.approx(ts.spectrum_top(model) * 2 / 3 * 0.01)
    page = write_report_html(pd.DataFrame(rows), tmp_path).read_text(encoding="utf-8")
    section = page[page.index('<section id="ladders">'):page.index('<section id="error-parts">')]
    assert "<h3>cube</h3>" in section and "<th>share of modes unresolved</th>" in section
    assert "contact, whole body 141 rad/s" in section


def test_the_command_prints_a_suites_time_scales_and_each_ladder_levels_resolution(tmp_path, capsys):
    """`frictionbench timescales`: with --runs, the patch is the stored reference run's last frame (here the body
    pressed 1 mm into its plane)."""
    from frictionbench.bench.cli import main
    from frictionbench.bench.store import RunStore, run_key
    from frictionbench.scenarios.suites import load_suite

    sc = next(m.scenario for m in load_suite("quick-undamped").scenarios if m.scenario.name == "quick-undamped/p1_mu0.1")
    model = build_model(sc, load_mesh(sc.mesh))
    x = initial_state(model).x - (sc.initial.clearance + 1e-3) * model.plane_normal
    run = Trajectory(t=np.array([0.0]), x=x[None], X=model.X, tets=model.tets, surface=model.surface)
    RunStore(tmp_path / "runs").save(run_key(sc, "full", {}, None), run, {})
    assert main(["timescales", "--suite", "quick-undamped", "--only", "quick-undamped/p1_mu0.1", "--depth", "1",
                 "--runs", str(tmp_path)]) == 0
    out = capsys.readouterr().out
    scenes, levels = out.split("\n\n")
    line = next(row for row in scenes.splitlines() if row.startswith("quick-undamped/p1_mu0.1")).split()
    assert line[1] == "cheese/coarse" and float(line[3]) == pytest.approx(3694, rel=1e-3)  # omega_max [rad/s]
    assert float(line[5]) > 0.0  # the patch
    rows = [row.split() for row in levels.splitlines() if row.startswith("cheese/coarse")]
    assert [(row[1], float(row[2])) for row in rows] == [("0", 0.01), ("1", 0.005)]
    assert float(rows[0][-1]) == pytest.approx(0.9878, abs=1e-4)  # share of unresolved modes at dt 0.01 (BDF2)

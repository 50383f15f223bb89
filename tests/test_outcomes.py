"""Outcome metrics (analysis.outcomes) on trajectories whose answers are known in closed form, their convergence
over a made-up truth ladder, their declaration in the schema and a gate on one of them."""

from __future__ import annotations

import math
from dataclasses import replace
from pathlib import Path

import numpy as np
import pandas as pd
import pytest
from scipy.spatial.transform import Rotation

from frictionbench.analysis import outcomes
from frictionbench.analysis.metrics import body_masses, center_of_mass, stick
from frictionbench.analysis.outcomes import (OutcomeScene, ladder_outcome_columns, outcome_error, outcome_values,
                                             rotation_difference)
from frictionbench.analysis.rows import collect_rows
from frictionbench.analysis.schema import COLUMNS, OUTCOMES, outcome_of
from frictionbench.analysis.table import write_results_csv
from frictionbench.bench.gates import OUTCOME_UNCERTIFIED, check, load_gates
from frictionbench.bench.runner import Task
from frictionbench.scenarios.meshes import TetMesh, boundary_triangles
from frictionbench.scenarios.spec import Contact, Material, Plane, Scenario, TimeSpec
from frictionbench.scenarios.suites import Suite, SuiteMember
from frictionbench.solvers.integrators import BackwardEuler
from frictionbench.solvers.trajectory import Trajectory

from fakes import FakeLadder, FakeStore
from test_metrics import L, unit_cube

G = 9.81
FLOOR = Plane(normal=(0.0, 1.0, 0.0), offset=0.0, friction=0.5)  # y = 0, the cube's bottom face rests on it
MATERIAL = Material(density=1000.0)  # the unit cube weighs 1000 kg
PENALTY = Contact(law="penalty", stiffness=1.0e5)


def cube(x: np.ndarray, v: np.ndarray, t: np.ndarray) -> Trajectory:
    """The unit cube (with its boundary) with frames x (F, 8, 3) [m], velocities v (F, 8, 3) [m/s] at times t."""
    X, tets = unit_cube()
    return Trajectory(t=t, x=x, X=X, tets=tets, surface=boundary_triangles(tets), v=v)


def rigid(offsets: np.ndarray, velocity: np.ndarray, t: np.ndarray) -> Trajectory:
    """The undeformed cube translated by offsets (F, 3), every vertex at velocity (F, 3)."""
    X, _ = unit_cube()
    return cube(X[None] + offsets[:, None, :], np.repeat(velocity[:, None, :], 8, axis=1), t)


def scene(**kw) -> OutcomeScene:
    return OutcomeScene(plane=FLOOR, material=MATERIAL, contact=PENALTY, gravity=(0.0, -G, 0.0)) if not kw \
        else replace(scene(), **kw)


def test_a_translation_gives_its_slide_end_centre_and_no_rotation():
    t = np.linspace(0.0, 1.0, 5)
    d = np.array([0.3, -0.1, 0.2])
    traj = rigid(np.outer(t, d), np.tile(d, (5, 1)), t)
    tilted = Plane(normal=(1.0, 5.0, 2.0), offset=-1.5)
    n = np.array(tilted.normal) / np.linalg.norm(tilted.normal)
    assert outcomes.slide_distance(traj, scene(plane=tilted)) == pytest.approx(np.linalg.norm(d - n * (n @ d)))
    masses = body_masses(traj, MATERIAL, None)
    np.testing.assert_allclose(outcomes.end_com(traj, scene()), center_of_mass(traj.X, masses) + d, atol=1e-14)
    np.testing.assert_allclose(outcomes.end_com(traj, scene()), [0.8, 0.4, 0.7], atol=1e-14)  # the cube's centre
    assert outcomes.cell(outcomes.end_rotation(traj, scene())) == pytest.approx(0.0, abs=1e-6)
    assert outcomes.slide_distance(traj, scene(plane=None)) is None  # no plane: the outcome does not apply


def test_a_rotation_gives_its_angle_and_two_rotations_their_relative_angle():
    X, _ = unit_cube()
    turn = Rotation.from_rotvec(np.radians(40.0) * np.array([1.0, 2.0, 3.0]) / np.sqrt(14.0))
    centre = X.mean(axis=0)
    end = turn.apply(X - centre) + centre + np.array([2.0, 0.0, -1.0])
    traj = cube(np.stack([X, end]), np.zeros((2, 8, 3)), np.array([0.0, 1.0]))
    rotation = outcomes.end_rotation(traj, scene())
    assert outcomes.cell(rotation) == pytest.approx(40.0)
    assert rotation_difference(rotation, turn, L) == pytest.approx(0.0, abs=1e-6)
    # two quarter turns about orthogonal axes differ by a third of a turn; about one axis, by their difference
    x90, y90 = Rotation.from_euler("x", 90, degrees=True), Rotation.from_euler("y", 90, degrees=True)
    assert rotation_difference(x90, y90, L) == pytest.approx(120.0)
    assert rotation_difference(Rotation.from_euler("z", 40, degrees=True), Rotation.from_euler("z", 10, degrees=True),
                               L) == pytest.approx(30.0)


def decelerating(T: float = 0.5, v0: float = 1.0, lift: float = 0.0) -> Trajectory:
    """The cube on the floor (raised by `lift`) sliding along x at v0 (1 - t / T) until it stops at T, 21 frames over
    1 s."""
    t = np.linspace(0.0, 1.0, 21)
    tt = np.minimum(t, T)
    s, v = v0 * (tt - tt ** 2 / (2 * T)), v0 * (1.0 - tt / T)
    return rigid(np.stack([s, np.full_like(s, lift), 0 * s], axis=1), np.stack([v, 0 * v, 0 * v], axis=1), t)


def test_a_body_that_stops_at_a_known_frame_rests_from_that_frame():
    assert outcomes.time_to_rest(decelerating(), scene()) == pytest.approx(0.5)
    # a creep speed of 0.05 m/s allows 0.25 m/s (5x): v = 1 - 2t falls below it after t = 0.375, the frame at 0.4
    assert outcomes.time_to_rest(decelerating(), scene(creep_speed=0.05)) == pytest.approx(0.4)
    assert math.isnan(outcomes.time_to_rest(decelerating(T=2.0), scene()))  # still sliding at the end
    assert math.isnan(outcomes.time_to_rest(decelerating(lift=0.1), scene()))  # at rest, but in the air
    assert outcomes.time_to_rest(decelerating(), scene(plane=None)) is None
    assert outcomes.stick_verdict(decelerating(), scene()) is True
    assert outcomes.stick_verdict(decelerating(T=2.0), scene()) is False


def test_the_peak_kinetic_energy_of_a_known_motion():
    t = np.linspace(0.0, 1.0, 4)
    velocity = np.outer([1.0, 3.0, 2.0, 0.5], [1.0, 2.0, 2.0])  # |v| = 3 x (1, 3, 2, 0.5) m/s
    traj = rigid(np.zeros((4, 3)), velocity, t)
    assert outcomes.peak_kinetic_energy(traj, scene()) == pytest.approx(0.5 * 1000.0 * 9.0 ** 2)  # M = 1000 kg


def impact(penetration_after: float = 0.0) -> Trajectory:
    """The cube falling at 2 m/s, first pressing the floor at frame 3 (t = 0.15 s), then 0.2 s after the frame
    before (frame 6) sliding at 0.5 m/s along x, sunk `penetration_after` [m] into the floor."""
    t = np.arange(11) * 0.05
    heights = np.array([0.15, 0.1, 0.05, -0.001, 0.0, 0.0, -penetration_after, 0.0, 0.0, 0.0, 0.0])
    velocity = np.zeros((11, 3))
    velocity[:3, 1] = -2.0
    velocity[6, 0] = 0.5
    return rigid(np.stack([0 * t, heights, 0 * t], axis=1), velocity, t)


def test_the_impact_loss_of_made_up_energies():
    M = 1000.0
    before = 0.5 * M * 2.0 ** 2 + M * G * 0.05  # kinetic + gravity at frame 2 (energy measured from y = 0)
    after = 0.5 * M * 0.5 ** 2  # frame 6: sliding on the floor
    met = 0.5 * M * 2.0 ** 2 + M * G * 0.051  # kinetic at frame 3 had the cube kept falling from frame 2
    assert outcomes.impact_loss(impact(), scene()) == pytest.approx((before - after) / met)
    # energy still stored in the contact at the window's end is not lost: 1/2 k_e c^2 per area of the sunk points
    c = 1e-3
    X, tets = unit_cube()
    areas = TetMesh(X=X, tets=tets, surface=boundary_triangles(tets), name="cube").surface_vertex_areas()
    assert areas[X[:, 1] == 0.0].sum() == pytest.approx(3.0)  # the bottom face, and half of each side face
    stored = 0.5 * PENALTY.stiffness * c ** 2 * 3.0
    sunk = outcomes.impact_loss(impact(c), scene())
    assert sunk == pytest.approx((before - after - stored + M * G * c) / met)
    # no impact to measure: the body already touches at the first frame, never touches, or the run ends too early
    assert math.isnan(outcomes.impact_loss(impact(), scene(plane=Plane(offset=0.2))))
    assert math.isnan(outcomes.impact_loss(impact(), scene(plane=Plane(offset=-1.0))))
    assert math.isnan(outcomes.impact_loss(impact(), scene(), window=1.0))
    assert outcomes.impact_loss(impact(), scene(contact=None)) is None


def test_differences_of_undefined_values_and_verdicts():
    rest, stick_, peak = OUTCOMES["rest_time"], OUTCOMES["stick"], OUTCOMES["peak_ke"]
    assert outcome_error(rest, 0.7, 0.5, L) == pytest.approx(0.2)
    assert outcome_error(rest, math.nan, math.nan, L) == 0.0  # neither comes to rest: they agree
    assert outcome_error(rest, math.nan, 0.5, L) == math.inf  # only one does
    assert outcome_error(rest, None, 0.5, L) is None  # not applicable
    assert outcome_error(stick_, True, True, L) == 0.0 and outcome_error(stick_, False, True, L) == 1.0
    assert outcome_error(peak, 102.0, 100.0, L) == pytest.approx(0.02)
    assert outcome_error(OUTCOMES["slide"], 0.3, 0.3 + 0.01 * L, L) == pytest.approx(0.01)


def levels(slides: list[float], rests: list[float]) -> list[dict]:
    """Outcome values of a made-up ladder's levels: the given slides [m] and times to rest [s], the rest fixed."""
    fixed = {"end_com": np.zeros(3), "end_angle": Rotation.identity(), "impact_loss": 0.4, "peak_ke": 10.0,
             "stick": True}
    return [fixed | {"slide": s, "rest_time": r} for s, r in zip(slides, rests)]


def test_each_outcome_converges_over_the_ladder_with_its_own_estimate_and_certificate():
    # slide s_k = 1 + C 2^-k (first order): differences C 2^-k, Richardson exact: the truth's error is C 2^-K
    C, K = 0.032 * L, 3
    slides = [1.0 + C * 2.0 ** -k for k in range(K + 1)]
    rests = [0.9, math.nan, 0.6, 0.62]  # the level at dt/2 did not come to rest
    row = ladder_outcome_columns(levels(slides, rests), BackwardEuler(), L)
    assert row["truth_slide"] == pytest.approx(slides[-1])
    assert row["truth_slide_diff"] == pytest.approx(C * 2.0 ** -K / L)  # 0.004: certified at tol 0.005
    assert row["truth_slide_est"] == pytest.approx(C * 2.0 ** -K / L) and row["truth_slide_certified"]
    assert row["truth_rest_time_diff"] == pytest.approx(0.02) and row["truth_rest_time_certified"]
    assert row["truth_rest_time_est"] == pytest.approx(0.02)  # after a mismatch: no order, p clamped to 1
    assert row["truth_stick_diff"] == 0.0 and row["truth_stick_est"] == 0.0 and row["truth_stick_certified"]
    assert row["truth_end_angle"] == 0.0 and row["truth_end_com"] == "0 0 0"
    row = ladder_outcome_columns(levels(slides[:3], [0.9, 0.6, math.nan]), BackwardEuler(), L)
    assert row["truth_slide_diff"] == pytest.approx(0.008) and not row["truth_slide_certified"]
    assert row["truth_rest_time_diff"] == math.inf and row["truth_rest_time_est"] == math.inf
    assert not row["truth_rest_time_certified"] and math.isnan(row["truth_rest_time"])
    assert not ladder_outcome_columns(levels(slides, rests), BackwardEuler(), L, failed=True)["truth_slide_certified"]
    one = ladder_outcome_columns(levels(slides[:1], rests[:1]), BackwardEuler(), L)
    assert one["truth_slide_diff"] is None and one["truth_slide_certified"] is False




def test_every_row_of_a_scenario_gets_the_truths_outcome_convergence_and_its_own_errors(tmp_path: Path):
    sc = Scenario(name="slide", plane=FLOOR, material=MATERIAL, contact=PENALTY, time=TimeSpec(dt=0.1, duration=1.0))
    stops = [0.6, 0.52, 0.51]  # each level stops earlier, and slides less (v0 T / 2)
    tasks = [Task(replace(sc, time=replace(sc.time, dt=0.1 / 2 ** k)), "full", {}) for k in range(3)]
    stats = {"contact_stiffness": PENALTY.stiffness, "step_ms_median": 1.0}
    trajs = [decelerating(T=T) for T in stops]
    store = FakeStore({task.key: (traj, stats) for task, traj in zip(tasks, trajs)})
    ladder = FakeLadder("backward-euler", tasks, [0.01, 0.004])
    rows = collect_rows(Suite("s", "", (SuiteMember(sc, "train", {}),)), {sc.name: tasks[0]},
                        [], store, {sc.name: {"backward-euler": ladder}})
    frame = pd.read_csv(write_results_csv(rows, tmp_path / "results.csv", provenance_info={}))
    slides = [outcomes.slide_distance(traj, scene()) for traj in trajs]
    assert slides == pytest.approx([T / 2 for T in stops])  # v0 T / 2
    assert len(frame) == 4  # the reference (also level 0), and the ladder's three levels
    assert frame["truth_slide"].tolist() == pytest.approx([slides[-1]] * 4)
    assert frame["truth_slide_diff"].tolist() == pytest.approx([abs(slides[1] - slides[2]) / L] * 4)
    assert frame["truth_slide_certified"].all()  # 0.005 m / L = 0.0029 <= 0.005
    ref = frame[frame["variant"] == "reference"].iloc[0]
    assert ref["slide"] == pytest.approx(slides[0]) and ref["slide_err_truth"] == pytest.approx(
        abs(slides[0] - slides[2]) / L)
    assert ref["rest_time"] == pytest.approx(0.6) and ref["rest_time_err_truth"] == pytest.approx(0.05)  # 0.55
    assert (frame["truth_rest_time_diff"] == 0.0).all()  # both finest levels rest from the frame at 0.55 s
    truth = frame[frame["ladder_level"] == 2].iloc[0]
    assert truth["slide_err_truth"] == 0.0 and truth["stick_err_truth"] == 0.0
    assert (frame["stick"] == frame["truth_stick"]).all()  # the stick outcome is `compare`'s stick column
    assert stick(trajs[0], FLOOR.normal)[0]


def test_every_outcome_is_declared_once_in_the_schema_with_its_columns_and_functions():
    for o in OUTCOMES.values():
        assert callable(outcomes._function(o.value)) and callable(outcomes._function(o.difference))
        err = COLUMNS[o.err_column]
        assert (err.kind, err.better, err.unit, err.abs, err.summary) == ("accuracy", "lower", o.err_unit, o.tol, True)
        assert outcome_of(o.err_column) is o and COLUMNS[o.certified_column].better == "true"
        for name in (o.truth_column, o.diff_column, o.est_column):
            assert name in COLUMNS
        assert (COLUMNS[o.name].source == o.value) == o.own_column  # stick's value column is compare's own
    assert COLUMNS["slide"].unit == "m" and COLUMNS["end_angle_err_truth"].unit == "deg"
    assert outcome_of("err_truth") is None and outcome_of("slide") is None
    values = outcome_values(decelerating(), scene())
    assert set(values) == set(OUTCOMES) and values["stick"] is True
    diverged = decelerating()
    diverged.x[-1, 0, 0] = np.nan
    assert all(math.isnan(v) for v in outcome_values(diverged, scene()).values())  # undefined: inf off the truth


def outcome_rows(certified: bool, est: float) -> pd.DataFrame:
    """One reduced row whose slide is 0.02 L off the truth's; the truth's positions certified, its slide as given."""
    return pd.DataFrame([{"suite": "paper-damped", "scenario": "a", "solver": "licrom", "variant": "m",
                          "status": "ok", "slide_err_truth": 0.02, "truth_certified": True, "truth_err_est": 1e-4,
                          "truth_slide_certified": certified, "truth_slide_est": est}])


def test_a_gate_on_an_outcome_error_is_judged_against_that_outcomes_own_convergence():
    gate = {"suite": "paper-damped", "variant": "licrom/m", "metric": "slide_err_truth", "max": 0.025}
    status = lambda rows, g=gate: [v.status for v in check(rows, [g], "paper-damped")]  # noqa: E731
    assert status(outcome_rows(False, 0.01)) == ["undecidable"]  # 0.025 < 3 x 0.01, though positions certify
    assert [v.reason for v in check(outcome_rows(False, 0.01), [gate], "paper-damped")] == [OUTCOME_UNCERTIFIED]
    assert status(outcome_rows(False, 0.005)) == ["passed"]  # 0.025 >= 0.015
    assert status(outcome_rows(True, 0.05)) == ["passed"]  # the outcome is certified
    assert status(outcome_rows(True, 0.05), gate | {"max": 0.01}) == ["failed"]
    shipped = [g for g in load_gates() if g.get("suite") == "paper-damped" and outcome_of(g["metric"])]
    assert {g["variant"] for g in shipped} == {"full/reference", "licrom/affine-r24-cub60"}
    assert {g["metric"] for g in shipped if g["variant"] == "full/reference"} == {o.err_column for o in
                                                                                  OUTCOMES.values()}


def test_the_report_shows_each_scenarios_truth_outcomes_beside_their_convergence(tmp_path: Path):
    from frictionbench.reports.html import write_report_html

    row = {"suite": "s", "scenario": "a", "solver": "full", "variant": "reference", "status": "ok"}
    row |= ladder_outcome_columns(levels([1.0, 1.0 + 0.001], [0.5, 0.9]), BackwardEuler(), L)
    page = write_report_html(pd.DataFrame([row]), tmp_path).read_text(encoding="utf-8")
    section = page[page.index('id="outcomes"'):page.index('id="error-parts"')]
    assert section.count("<tr>") == 1 + len(OUTCOMES)  # header, then one row per outcome
    assert '<td class="pass">yes</td>' in section and '<td class="fail">no</td>' in section  # slide yes, rest no
    page = write_report_html(pd.DataFrame([{k: row[k] for k in ("suite", "scenario", "solver", "variant")}]),
                             tmp_path).read_text(encoding="utf-8")
    assert "No outcome convergence" in page

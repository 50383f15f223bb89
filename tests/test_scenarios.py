"""Scenario loading, validation, hashing and suite expansion (scenarios.load, scenarios.suites)."""

from __future__ import annotations

import copy
import math
import subprocess
import sys
import tomllib
from pathlib import Path
from typing import Any

import pytest
import tomli_w
from hypothesis import given, settings
from hypothesis import strategies as st

from frictionbench.scenarios import load
from frictionbench.scenarios.errors import ScenarioError
from frictionbench.scenarios.load import load_scenario, scenario_from_dict, scenario_hash, scenario_to_dict
from frictionbench.scenarios.spec import Effects
from frictionbench.scenarios.suites import list_suites, load_suite, suite_from_dict

from scenes import block_drop, mu_axis, suite_tables, write_toml

# The catalogue contract of scenarios.meshes (names -> resolutions); the loader is tested against it alone.
CATALOGUE = {
    "cheese": ("coarse", "medium", "fine", "coarse_alt", "medium_alt"),
    "sphere": ("coarse", "medium", "fine", "coarse_alt", "medium_alt"),
    "block": ("coarse", "medium"),
    "beam": ("coarse", "medium"),
    "slab": ("coarse", "medium"),
}

VALID: dict[str, Any] = {
    "name": "cheese_slope",
    "description": "the paper's figure 2",
    "tags": ["paper"],
    "mesh": {"name": "cheese", "resolution": "coarse"},
    "material": {"density": 1000.0, "youngs_modulus": 2.0e5, "poisson_ratio": 0.3},
    "plane": {"normal": [1.0, 5.0, 2.0], "offset": -1.5, "friction": 0.25},
    "contact": {"law": "penalty", "stiffness": 1.0e7, "damping": 0.0, "friction_stiffness": 1.0e6},
    "initial": {"clearance": 0.05},
    "time": {"dt": 0.01, "duration": 1.0, "frame_every": 1},
}

VALID_TOML = """\
name = "cheese_slope"
description = "the paper's figure 2"
tags = ["paper"]
gravity = [0.0, -9.81, 0.0]

[mesh]
name = "cheese"
resolution = "coarse"

[material]
density = 1000.0
youngs_modulus = 2.0e5
poisson_ratio = 0.3

[plane]
normal = [1.0, 5.0, 2.0]
offset = -1.5
friction = 0.25

[contact]
law = "penalty"
stiffness = 1.0e7

[initial]
clearance = 0.05
rotation = [0.0, 10.0, 0.0]

[time]
dt = 0.01
duration = 1.0
frame_every = 2

[effects]
damping = false
"""


@pytest.fixture(autouse=True, scope="module")
def _known_catalogue():
    """Validate mesh names against the catalogue contract, without the mesh module."""
    with pytest.MonkeyPatch.context() as mp:
        mp.setattr(load, "_catalogue", lambda: CATALOGUE)
        yield


def with_(d: dict[str, Any], path: str, value: object) -> dict[str, Any]:
    """A deep copy of `d` with the dotted `path` set to `value` (intermediate non-tables become tables)."""
    out = copy.deepcopy(d)
    *parents, last = path.split(".")
    node = out
    for part in parents:
        if not isinstance(node.get(part), dict):
            node[part] = {}
        node = node[part]
    node[last] = value
    return out


def without(d: dict[str, Any], path: str) -> dict[str, Any]:
    """A deep copy of `d` without the dotted `path`."""
    out = copy.deepcopy(d)
    *parents, last = path.split(".")
    node = out
    for part in parents:
        node = node[part]
    del node[last]
    return out


# ---------------------------------------------------------------------------------------------------------------
# Shipped suites


@pytest.mark.parametrize(("name", "total", "train", "test"),
                         [("verify", 12, 12, 0), ("quick", 5, 4, 1), ("quick-undamped", 5, 4, 1), ("paper", 34, 30, 4),
                          ("paper-damped", 34, 30, 4)])
def test_shipped_suite_loads_with_documented_counts(name: str, total: int, train: int, test: int) -> None:
    suite = load_suite(name)
    assert suite.name == name and suite.description
    assert (len(suite.scenarios), len(suite.train), len(suite.test)) == (total, train, test)
    names = [m.scenario.name for m in suite.scenarios]
    assert len(set(names)) == total
    assert all(n.startswith(f"{name}/") and load.is_safe_name(n) for n in names)


def test_list_suites_names_the_shipped_files() -> None:
    assert list_suites() == ["hard", "paper", "paper-damped", "quick", "quick-undamped", "verify"]


def test_frictionbench_list_aligns_the_suites_counts(capsys) -> None:
    """Every suite's member counts start in the same column, however long its name (paper-damped, quick-undamped)."""
    from frictionbench.bench.cli import main

    assert main(["list"]) == 0
    out = capsys.readouterr().out.splitlines()
    rows = out[out.index("suites:") + 1:out.index("meshes:")]
    assert len(rows) == len(list_suites())
    assert len({row.index(" train") for row in rows}) == 1


def test_paper_suite_is_the_papers_matrix_per_mesh() -> None:
    suite = load_suite("paper")
    for mesh in ("cheese", "sphere"):
        train = [m for m in suite.train if m.labels["mesh"] == mesh]
        assert len(train) == 15
        mus = {m.scenario.plane.friction for m in train}
        planes = {m.scenario.plane.normal for m in train}
        assert len(mus) == 5 and len(planes) == 3
        assert {m.scenario.mesh.key for m in train} == {f"{mesh}/medium"}
        test = [m for m in suite.test if m.labels["mesh"] == mesh]
        assert test and all(m.scenario.plane.friction not in mus and m.scenario.plane.normal not in planes
                            for m in test)
    p1 = next(m.scenario.plane for m in suite.scenarios if m.labels["plane"] == "p1")
    root30 = math.sqrt(30.0)
    assert p1.normal == pytest.approx((1 / root30, 5 / root30, 2 / root30))
    assert p1.offset == pytest.approx(-1.5 / root30)
    assert all(m.scenario.initial.clearance > 0 and m.scenario.time.duration == 2.0 for m in suite.scenarios)


def test_quick_suite_holds_out_a_new_plane_and_friction_coefficient() -> None:
    suite = load_suite("quick")
    (held_out,) = suite.test
    assert held_out.scenario.plane.friction not in {m.scenario.plane.friction for m in suite.train}
    assert held_out.scenario.plane.normal not in {m.scenario.plane.normal for m in suite.train}
    assert {m.scenario.mesh.key for m in suite.scenarios} == {"cheese/coarse"}


def test_verify_suite_covers_the_analytic_incline_regimes() -> None:
    suite = load_suite("verify")
    for mesh in ("block", "beam"):
        cases = {m.labels["case"]: m.scenario for m in suite.scenarios if m.labels["mesh"] == mesh}
        assert cases["fall"].plane is None and not cases["fall"].effects.contact
        assert cases["flight"].gravity == (0.0, 0.0, 0.0) and not cases["flight"].effects.gravity
        assert cases["flight"].initial.angular_velocity != (0.0, 0.0, 0.0)
        margin = {}
        for case in ("slide", "threshold", "stick", "frictionless"):
            plane = cases[case].plane
            tan_theta = math.hypot(plane.normal[0], plane.normal[2]) / plane.normal[1]
            margin[case] = tan_theta - plane.friction
            # The body is rotated so that its bottom face lies on the plane.
            assert cases[case].initial.rotation[2] == pytest.approx(-math.degrees(math.atan(tan_theta)))
        assert margin["slide"] > 0.2 and 0.0 < margin["threshold"] < 0.05 and margin["stick"] < 0.0
        assert cases["frictionless"].plane.friction == 0.0 and not cases["frictionless"].effects.friction


def test_shipped_suites_use_catalogue_names_of_the_mesh_module() -> None:
    meshes = pytest.importorskip("frictionbench.scenarios.meshes")
    real = meshes.catalogue()
    for name, resolutions in CATALOGUE.items():
        assert set(resolutions) <= set(real[name])


def test_loader_does_not_import_the_mesh_module() -> None:
    code = ("import sys, frictionbench.scenarios.load, frictionbench.scenarios.suites; "
            "assert 'frictionbench.scenarios.meshes' not in sys.modules")
    subprocess.run([sys.executable, "-c", code], check=True)


# ---------------------------------------------------------------------------------------------------------------
# Loading, round trip, hash


def test_load_scenario_file(tmp_path: Path) -> None:
    path = tmp_path / "s.toml"
    path.write_text(VALID_TOML)
    s = load_scenario(path)
    assert s.name == "cheese_slope" and s.tags == ("paper",)
    assert s.mesh.key == "cheese/coarse"
    assert s.initial.rotation == (0.0, 10.0, 0.0) and s.time.frame_every == 2 and s.time.n_steps == 100
    assert s.effects == Effects(gravity=True, elasticity=True, contact=True, friction=True, damping=False)


@pytest.mark.parametrize("suite", ["verify", "quick", "paper"])
def test_round_trip_of_every_shipped_member(suite: str) -> None:
    for member in load_suite(suite).scenarios:
        s = member.scenario
        assert scenario_from_dict(scenario_to_dict(s)) == s
        assert scenario_hash(scenario_from_dict(scenario_to_dict(s))) == scenario_hash(s)


def test_round_trip_of_a_file_mesh_without_plane(tmp_path: Path) -> None:
    (tmp_path / "body.vtu").write_bytes(b"mesh")
    d = with_(without(with_(VALID, "plane", False), "initial.clearance"), "mesh", {"path": "body.vtu"})
    s = scenario_from_dict(d, base_dir=tmp_path)
    assert s.mesh.path == str((tmp_path / "body.vtu").resolve()) and s.mesh.name is None
    assert s.plane is None and s.initial.clearance is None
    assert scenario_to_dict(s)["plane"] is False and scenario_to_dict(s)["initial"]["clearance"] is False
    assert scenario_from_dict(scenario_to_dict(s)) == s


def test_relative_mesh_path_resolves_against_the_scenario_file(tmp_path: Path) -> None:
    (tmp_path / "meshes").mkdir()
    (tmp_path / "meshes" / "wedge.msh").write_bytes(b"mesh")
    toml = VALID_TOML.replace('name = "cheese"\nresolution = "coarse"', 'path = "meshes/wedge.msh"')
    (tmp_path / "s.toml").write_text(toml)
    assert load_scenario(tmp_path / "s.toml").mesh.path == str((tmp_path / "meshes" / "wedge.msh").resolve())


def test_hash_is_stable_across_spellings_and_names() -> None:
    a = scenario_from_dict(VALID)
    respelled = with_(with_(VALID, "plane.normal", [2, 10, 4]), "plane.offset", -3)
    respelled = with_(with_(respelled, "material.density", 1000), "name", "other/name")
    respelled = with_(with_(respelled, "description", ""), "tags", ["x"])
    b = scenario_from_dict(respelled)
    assert scenario_hash(a) == scenario_hash(b)
    assert len(scenario_hash(a)) == 16 and int(scenario_hash(a), 16) >= 0


@pytest.mark.parametrize(("path", "value"), [
    ("material.density", 1001.0), ("material.youngs_modulus", 3e5), ("material.poisson_ratio", 0.31),
    ("plane.friction", 0.3), ("plane.offset", -1.0), ("plane.normal", [1.0, 5.0, 2.1]), ("plane", False),
    ("contact.law", "barrier"), ("contact.stiffness", 2e7), ("contact.damping", 10.0),
    ("initial.clearance", 0.06), ("initial.rotation", [0.0, 0.0, 1.0]), ("initial.velocity", [0.0, 0.0, 1e-3]),
    ("time.dt", 0.005), ("time.duration", 2.0), ("time.frame_every", 2), ("time.integrator", "bdf2"),
    ("effects.friction", False), ("contact.lag", "fixed-point"),
    ("gravity", [0.0, -9.8, 0.0]), ("mesh.resolution", "medium"), ("mesh.scale", 2.0),
])
def test_hash_changes_with_what_is_simulated(path: str, value: object) -> None:
    changed = with_(VALID, path, value)
    if path == "plane":
        changed = without(changed, "initial.clearance")
    assert scenario_hash(scenario_from_dict(changed)) != scenario_hash(scenario_from_dict(VALID))


def test_the_default_integrator_keeps_the_hashes_from_before_the_field() -> None:
    explicit = scenario_from_dict(with_(VALID, "time.integrator", "backward-euler"))
    assert explicit == scenario_from_dict(VALID) and explicit.time.integrator == "backward-euler"
    assert "integrator" not in scenario_to_dict(explicit)["time"]
    assert scenario_to_dict(scenario_from_dict(with_(VALID, "time.integrator", "bdf2")))["time"]["integrator"] == "bdf2"


def test_the_default_contact_lag_and_no_damping_ratio_keep_the_hashes_from_before_the_fields() -> None:
    explicit = scenario_from_dict(with_(VALID, "contact.lag", "start"))
    assert explicit == scenario_from_dict(VALID) and "lag" not in scenario_to_dict(explicit)["contact"]
    assert "damping_ratio" not in scenario_to_dict(explicit)["contact"]
    ratio = scenario_from_dict(with_(without(VALID, "contact.damping"), "contact.damping_ratio", 1.0))
    assert scenario_to_dict(ratio)["contact"]["damping_ratio"] == 1.0 and "damping" not in scenario_to_dict(ratio)["contact"]
    assert scenario_from_dict(scenario_to_dict(ratio)) == ratio and ratio.effects.damping
    assert scenario_hash(ratio) != scenario_hash(scenario_from_dict(VALID))


def test_hash_follows_mesh_file_content_not_location(tmp_path: Path) -> None:
    for folder in ("a", "b"):
        (tmp_path / folder).mkdir()
        (tmp_path / folder / "m.vtu").write_bytes(b"mesh")
    d = with_(VALID, "mesh", {"path": "m.vtu"})
    s_a = scenario_from_dict(d, base_dir=tmp_path / "a")
    s_b = scenario_from_dict(d, base_dir=tmp_path / "b")
    assert scenario_hash(s_a) == scenario_hash(s_b)
    (tmp_path / "b" / "m.vtu").write_bytes(b"other mesh")
    assert scenario_hash(s_a) != scenario_hash(s_b)


# ---------------------------------------------------------------------------------------------------------------
# Planes and effects


def test_plane_is_normalised_with_its_offset() -> None:
    plane = scenario_from_dict(VALID).plane
    root30 = math.sqrt(30.0)
    assert plane.normal == pytest.approx((1 / root30, 5 / root30, 2 / root30), abs=1e-15)
    assert plane.offset == pytest.approx(-1.5 / root30, abs=1e-15)
    assert math.hypot(*plane.normal) == pytest.approx(1.0, abs=1e-15)


@pytest.mark.parametrize(("downhill", "normal"), [
    (None, (0.5, math.sqrt(3) / 2, 0.0)), ("x", (0.5, math.sqrt(3) / 2, 0.0)),
    ("-x", (-0.5, math.sqrt(3) / 2, 0.0)), ("z", (0.0, math.sqrt(3) / 2, 0.5)),
    ("-z", (0.0, math.sqrt(3) / 2, -0.5)),
])
def test_slope_plane(downhill: str | None, normal: tuple[float, float, float]) -> None:
    plane_dict: dict[str, Any] = {"slope_deg": 30.0, "friction": 0.2, "offset": 0.5}
    if downhill is not None:
        plane_dict["downhill"] = downhill
    plane = scenario_from_dict(with_(VALID, "plane", plane_dict)).plane
    assert plane.normal == pytest.approx(normal, abs=1e-15)
    assert (plane.offset, plane.friction) == (0.5, 0.2)


def test_flat_slope_is_the_horizontal_plane() -> None:
    plane = scenario_from_dict(with_(VALID, "plane", {"slope_deg": 0})).plane
    assert plane.normal == (0.0, 1.0, 0.0) and plane.offset == 0.0


def test_omitted_plane_is_the_default_ground() -> None:
    s = scenario_from_dict({"name": "bare"})
    assert s.plane is not None and s.plane.normal == (0.0, 1.0, 0.0) and s.initial.clearance == 0.0
    assert s.mesh.key == "cheese/coarse"


@pytest.mark.parametrize(("changes", "expected"), [
    ({}, Effects(gravity=True, elasticity=True, contact=True, friction=True, damping=False)),
    ({"plane.friction": 0.0}, Effects(True, True, True, False, False)),
    ({"contact.damping": 5.0}, Effects(True, True, True, True, True)),
    ({"plane": False}, Effects(True, True, False, False, False)),
    ({"gravity": [0.0, 0.0, 0.0]}, Effects(False, True, True, True, False)),
    ({"effects.contact": False, "contact.damping": 5.0}, Effects(True, True, False, False, False)),
    ({"effects.friction": False, "effects.elasticity": False}, Effects(True, False, True, False, False)),
    ({"effects.friction": True, "plane.friction": 0.0}, Effects(True, True, True, True, False)),
    ({"effects.gravity": True, "gravity": [0.0, 0.0, 0.0]}, Effects(True, True, True, True, False)),
])
def test_effects_default_to_what_the_scene_implies(changes: dict[str, Any], expected: Effects) -> None:
    d = VALID
    for path, value in changes.items():
        d = with_(d, path, value)
    if d["plane"] is False:
        d = without(d, "initial.clearance")
    assert scenario_from_dict(d).effects == expected


# ---------------------------------------------------------------------------------------------------------------
# Bad input: the error names the field and shows the value

BAD_SCENARIOS: list[tuple[str, object, str]] = [
    # (dotted path to set, bad value, expected error field)
    ("material.youngs_modulu", 1e5, "material.youngs_modulu"),
    ("colour", "red", "colour"),
    ("initial.clearence", 0.1, "initial.clearence"),
    ("material.density", "1000", "material.density"),
    ("material.density", True, "material.density"),
    ("material.youngs_modulus", [1e5], "material.youngs_modulus"),
    ("gravity", [0.0, -9.81], "gravity"),
    ("gravity", [0.0, "down", 0.0], "gravity"),
    ("initial.velocity", [1.0, 2.0, 3.0, 4.0], "initial.velocity"),
    ("material.density", float("nan"), "material.density"),
    ("plane.offset", float("inf"), "plane.offset"),
    ("initial.rotation", [0.0, float("nan"), 0.0], "initial.rotation"),
    ("material.density", 0.0, "material.density"),
    ("material.youngs_modulus", -1.0, "material.youngs_modulus"),
    ("material.poisson_ratio", 0.5, "material.poisson_ratio"),
    ("material.poisson_ratio", -1.0, "material.poisson_ratio"),
    ("plane.friction", -0.1, "plane.friction"),
    ("plane.normal", [0.0, 0.0, 0.0], "plane.normal"),
    ("plane", True, "plane"),
    ("plane", 3, "plane"),
    ("material", 5, "material"),
    ("time.dt", 0.0, "time.dt"),
    ("time.duration", 0.001, "time.duration"),
    ("time.duration", -1.0, "time.duration"),
    ("time.frame_every", 0, "time.frame_every"),
    ("time.frame_every", 1.5, "time.frame_every"),
    ("time.frame_every", True, "time.frame_every"),
    ("contact.stiffness", 0.0, "contact.stiffness"),
    ("contact.damping", -1.0, "contact.damping"),
    ("contact.friction_stiffness", 0, "contact.friction_stiffness"),
    ("contact.barrier_distance", 0.0, "contact.barrier_distance"),
    ("contact.barrier_stiffness", -5.0, "contact.barrier_stiffness"),
    ("contact.law", "springs", "contact.law"),
    ("contact.lag", "implicit", "contact.lag"),
    ("contact.damping_ratio", 0.3, "contact.damping_ratio"),  # beside contact.damping
    ("initial.clearance", -0.01, "initial.clearance"),
    ("initial.clearance", True, "initial.clearance"),
    ("initial.squash", [1.0, 0.0, 1.0], "initial.squash"),
    ("mesh.scale", 0.0, "mesh.scale"),
    ("mesh.name", "teapot", "mesh.name"),
    ("mesh.resolution", "ultra", "mesh.resolution"),
    ("mesh.path", "missing.vtu", "mesh.name"),  # both name and path
    ("effects.friction", 1, "effects.friction"),
    ("name", "has space", "name"),
    ("name", "../escape", "name"),
    ("name", 7, "name"),
    ("tags", "paper", "tags"),
]


@pytest.mark.parametrize(("path", "value", "field"), BAD_SCENARIOS)
def test_bad_field_is_named_with_its_value(path: str, value: object, field: str) -> None:
    with pytest.raises(ScenarioError) as info:
        scenario_from_dict(with_(VALID, path, value))
    assert info.value.field == field
    assert repr(info.value.value) in str(info.value)
    if field == path:
        assert repr(value) in str(info.value)


@pytest.mark.parametrize(("d", "field", "shown"), [
    (without(VALID, "name"), "name", "None"),
    (with_(VALID, "material.poisson_ratio", 0.5), "material.poisson_ratio", "incompressible"),
    (with_(VALID, "material.youngs_modulu", 1.0), "material.youngs_modulu", "did you mean 'youngs_modulus'"),
    (with_(with_(VALID, "mesh.name", "block"), "mesh.resolution", "fine"), "mesh.resolution", "'fine'"),
    (with_(VALID, "plane", {"slope_deg": 90.0}), "plane.slope_deg", "90.0"),
    (with_(VALID, "plane", {"slope_deg": -1}), "plane.slope_deg", "-1.0"),
    (with_(VALID, "plane", {"slope_deg": 10.0, "normal": [0, 1, 0]}), "plane.slope_deg", "10.0"),
    (with_(VALID, "plane", {"slope_deg": 10.0, "downhill": "y"}), "plane.downhill", "'y'"),
    (with_(VALID, "plane", {"normal": [0, 1, 0], "downhill": "x"}), "plane.downhill", "'x'"),
    (with_(VALID, "plane", {"normal": [1e-300, 0, 0], "offset": 1e300}), "plane.offset", "inf"),
    (with_(VALID, "mesh", {"scale": 1.0, "path": "nowhere.vtu"}), "mesh.path", "'nowhere.vtu'"),
    (with_(VALID, "mesh", {"path": 3}), "mesh.path", "3"),
    (with_(VALID, "plane", False), "initial.clearance", "0.05"),
    (with_(without(VALID, "initial"), "contact.law", "barrier"), "initial.clearance", "0.0"),
    (with_(with_(without(VALID, "initial"), "plane", False), "effects.contact", True), "effects.contact", "True"),
    (with_(with_(without(VALID, "initial"), "plane", False), "effects.friction", True), "effects.friction",
     "True"),
    (with_(with_(VALID, "effects.contact", False), "effects.damping", True), "effects.damping", "True"),
    (with_(VALID, "material.density", 10**400), "material.density", "1000"),
    (with_(VALID, "time.integrator", "bdf3"), "time.integrator", "'bdf3'"),
    ([1, 2], "<scenario>", "[1, 2]"),
])
def test_bad_scenario_message(d: object, field: str, shown: str) -> None:
    with pytest.raises(ScenarioError) as info:
        scenario_from_dict(d, source="here.toml")
    assert info.value.field == field
    assert shown in str(info.value) and "[here.toml]" in str(info.value)


def test_malformed_toml_names_the_file_line_and_column(tmp_path: Path) -> None:
    path = tmp_path / "bad.toml"
    path.write_text('name = "x"\n[material]\ndensity = 1e5e\n')
    with pytest.raises(ScenarioError) as info:
        load_scenario(path)
    assert info.value.field == str(path)
    assert "line 3, column" in str(info.value) and "density = 1e5e" in str(info.value)


def test_missing_file_and_non_utf8(tmp_path: Path) -> None:
    with pytest.raises(ScenarioError, match="no such file") as info:
        load_scenario(tmp_path / "absent.toml")
    assert info.value.field == str(tmp_path / "absent.toml")
    (tmp_path / "latin1.toml").write_bytes(b'name = "caf\xe9"\n')
    with pytest.raises(ScenarioError, match="UTF-8"):
        load_scenario(tmp_path / "latin1.toml")
    with pytest.raises(ScenarioError, match="cannot read"):
        load_scenario(tmp_path)
    (tmp_path / "deep.toml").write_text("a = " + "[" * 10000)
    with pytest.raises(ScenarioError, match="nested too deeply"):
        load_scenario(tmp_path / "deep.toml")


# ---------------------------------------------------------------------------------------------------------------
# Suite format

SUITE: dict[str, Any] = {
    "suite": {"name": "mini", "description": "two axes and an extra"},
    "base": {"mesh": {"resolution": "coarse"}, "initial": {"clearance": 0.05}},
    "axis": [
        {"name": "mesh", "field": "mesh.name", "values": ["cheese", "sphere"]},
        {"name": "plane", "values": [{"label": "flat", "plane.normal": [0, 1, 0]},
                                     {"label": "p1", "plane": {"normal": [1, 5, 2], "offset": -1.5}}]},
        {"name": "mu", "field": "plane.friction", "values": [0.1, 0.5], "labels": ["low", "high"]},
    ],
    "split": {"test": [{"mesh": "sphere", "plane": "p1"}]},
    "extra": [{"labels": {"plane": "steep", "mu": "mu0.3"}, "across": ["mesh"],
               "overrides": {"plane.slope_deg": 40.0, "plane.friction": 0.3}}],
}


def test_suite_expansion_names_labels_and_split() -> None:
    suite = suite_from_dict(SUITE)
    names = [m.scenario.name for m in suite.scenarios]
    assert names[:3] == ["mini/cheese_flat_low", "mini/cheese_flat_high", "mini/cheese_p1_low"]
    assert names[-2:] == ["mini/cheese_steep_mu0.3", "mini/sphere_steep_mu0.3"]
    assert len(names) == 2 * 2 * 2 + 2
    assert {m.scenario.name for m in suite.test} == {"mini/sphere_p1_low", "mini/sphere_p1_high",
                                                    "mini/cheese_steep_mu0.3", "mini/sphere_steep_mu0.3"}
    member = next(m for m in suite.scenarios if m.scenario.name == "mini/sphere_p1_high")
    assert member.labels == {"mesh": "sphere", "plane": "p1", "mu": "high"}
    assert member.scenario.plane.friction == 0.5 and member.scenario.mesh.key == "sphere/coarse"
    assert member.scenario.plane.offset == pytest.approx(-1.5 / math.sqrt(30))
    assert member.scenario.description == "two axes and an extra"
    steep = suite.scenarios[-1].scenario
    assert steep.plane.normal[1] == pytest.approx(math.cos(math.radians(40.0)))
    assert suite.scenarios[-1].labels == {"mesh": "sphere", "plane": "steep", "mu": "mu0.3"}


def test_suite_axis_can_remove_the_plane() -> None:
    d = {"suite": {"name": "s"}, "base": {"plane": {"friction": 0.2}},
         "axis": [{"name": "ground", "values": [{"label": "none", "plane": False}, {"label": "yes"}]}]}
    members = suite_from_dict(d).scenarios
    assert members[0].scenario.plane is None and members[0].scenario.initial.clearance is None
    assert members[1].scenario.plane.friction == 0.2


def test_load_suite_by_path(tmp_path: Path) -> None:
    write_toml(tmp_path / "mine.toml", suite_tables("mine", None, mu_axis(0.2, 0.4)))
    assert [m.scenario.name for m in load_suite(tmp_path / "mine.toml").scenarios] == ["mine/mu0.2", "mine/mu0.4"]


def test_the_tests_suite_files_read_back_as_written(tmp_path: Path) -> None:
    """The suite files the tests write (tests/scenes.py, with tomli-w): every shape they use reads back to the same
    tables and members."""
    d = suite_tables("rt", block_drop(material={"youngs_modulus": 1e5}, effects={"damping": False}),
                     mu_axis(0.2, 0.6), {"name": "plane", "values": [{"label": "p1", "plane.normal": [1.0, 5.0, 2]}]},
                     description='a "quoted" one', split={"test": [{"mu": "mu0.6"}]}, truth={"tol": 1e-6, "depth": 2},
                     extra=[{"labels": {"case": "x"}, "overrides": {"initial.clearance": 0.0, "tags": ["resting"]}}])
    assert tomllib.loads(tomli_w.dumps(d)) == d
    written = load_suite(write_toml(tmp_path / "rt.toml", d))
    assert len(written.scenarios) == 3 and written.scenarios == suite_from_dict(d).scenarios
    assert written.truth == suite_from_dict(d).truth


@pytest.mark.parametrize(("path", "value", "field"), [
    ("suite.nme", "x", "suite.nme"),
    ("axes", [], "axes"),
    ("base.name", "x", "base.name"),
    ("axis", [{"name": "mu", "field": "plane.friction", "values": []}], "axis[0].values"),
    ("axis", [{"name": "mu", "field": "plane.friction", "values": [0.1, 0.1]}], "axis[0].values[1]"),
    ("axis", [{"name": "mu", "field": "plane.friction", "values": [0.1], "labels": ["a", "b"]}], "axis[0].labels"),
    ("axis", [{"name": "n", "field": "plane.normal", "values": [[0, 1, 0]]}], "axis[0].values[0]"),
    ("axis", [{"name": "p", "values": [{"plane.friction": 0.1}]}], "axis[0].values[0].label"),
    ("axis", [{"name": "p", "values": [{"label": "a b"}]}], "axis[0].values[0].label"),
    ("split.test", [{"mesh": "cube"}], "split.test[0].mesh"),
    ("split.test", [{"colour": "red"}], "split.test[0].colour"),
    ("extra", [{"labels": {}}], "extra[0].labels"),
    ("extra", [{"labels": {"x": "y"}, "split": "val"}], "extra[0].split"),
    ("extra", [{"labels": {"x": "y"}, "across": ["size"]}], "extra[0].across"),
    ("extra", [{"labels": {"mesh": "cheese", "plane": "flat", "mu": "low"}}], "name"),
])
def test_bad_suite_is_named(path: str, value: object, field: str) -> None:
    with pytest.raises(ScenarioError) as info:
        suite_from_dict(with_(SUITE, path, value), source="mini.toml")
    assert info.value.field == field
    assert repr(info.value.value) in str(info.value) and "[mini.toml]" in str(info.value)


def test_bad_member_names_suite_file_and_member(tmp_path: Path) -> None:
    nu = {"name": "nu", "field": "material.poisson_ratio", "values": [0.3, 0.5]}
    path = write_toml(tmp_path / "s.toml", suite_tables("s", {"material": {"poisson_ratio": 0.3}}, nu))
    with pytest.raises(ScenarioError) as info:
        load_suite(path)
    assert info.value.field == "material.poisson_ratio"
    assert str(path) in str(info.value) and "s/nu0.5" in str(info.value)


def test_unknown_suite_name() -> None:
    with pytest.raises(ScenarioError, match="quick") as info:
        load_suite("quik")
    assert info.value.field == "suite"


# ---------------------------------------------------------------------------------------------------------------
# Property tests

def finite(lo: float, hi: float) -> st.SearchStrategy[float]:
    """Finite floats in [lo, hi]."""
    return st.floats(lo, hi, allow_nan=False, allow_infinity=False)


VEC3 = st.lists(finite(-1e3, 1e3), min_size=3, max_size=3)


@st.composite
def valid_dicts(draw: st.DrawFn) -> dict[str, Any]:
    """Random valid scenario dicts: every table optional, every value in range."""
    mesh_name = draw(st.sampled_from(sorted(CATALOGUE)))
    d: dict[str, Any] = {"name": draw(st.from_regex(rf"{load.NAME_PART}(/{load.NAME_PART})*", fullmatch=True))}
    d |= draw(st.fixed_dictionaries({}, optional={
        "description": st.text(max_size=20), "tags": st.lists(st.text(max_size=5), max_size=3), "gravity": VEC3,
        "mesh": st.fixed_dictionaries({"name": st.just(mesh_name)}, optional={
            "resolution": st.sampled_from(CATALOGUE[mesh_name]), "scale": finite(1e-3, 1e3)}),
        "material": st.fixed_dictionaries({}, optional={
            "density": finite(1e-3, 1e5), "youngs_modulus": finite(1.0, 1e10),
            "poisson_ratio": finite(-0.99, 0.499)}),
        "plane": st.one_of(
            st.just(False),
            st.fixed_dictionaries({}, optional={
                "normal": VEC3.filter(lambda n: math.hypot(*n) > 1e-3), "offset": finite(-1e3, 1e3),
                "friction": finite(0.0, 2.0)}),
            st.fixed_dictionaries({"slope_deg": finite(0.0, 89.9)}, optional={
                "downhill": st.sampled_from(["x", "-x", "z", "-z"]), "offset": finite(-1e3, 1e3),
                "friction": finite(0.0, 2.0)})),
        "contact": st.fixed_dictionaries({}, optional={
            "law": st.sampled_from(["penalty", "barrier"]), "stiffness": finite(1e-3, 1e12),
            "damping": finite(0.0, 1e6), "friction_stiffness": finite(1e-3, 1e12),
            "barrier_distance": finite(1e-9, 1.0), "barrier_stiffness": finite(1e-3, 1e12)}),
        "time": st.fixed_dictionaries({}, optional={"dt": finite(1e-4, 0.1), "frame_every": st.integers(1, 10),
                                                    "integrator": st.sampled_from(["backward-euler", "bdf2"])}),
    }))
    has_plane = d.get("plane", {}) is not False
    barrier = d.get("contact", {}).get("law") == "barrier"
    initial = draw(st.fixed_dictionaries({}, optional={
        "rotation": VEC3, "translation": VEC3, "velocity": VEC3, "angular_velocity": VEC3,
        "squash": st.lists(finite(0.1, 10.0), min_size=3, max_size=3)}))
    if has_plane:
        initial["clearance"] = draw(st.one_of(st.just(False), finite(1e-6 if barrier else 0.0, 10.0)))
    d["initial"] = initial
    if "dt" in d.get("time", {}):
        d["time"]["duration"] = d["time"]["dt"] * draw(st.integers(1, 500))
    effects = {"gravity": st.booleans(), "elasticity": st.booleans()}
    if has_plane:
        effects |= {"contact": st.booleans()}
        if not draw(st.booleans()):  # friction and damping may be switched on only together with contact
            effects |= {"friction": st.just(False), "damping": st.just(False)}
    d["effects"] = draw(st.fixed_dictionaries({}, optional=effects))
    return d


# Per dotted path: values that are wrong there whatever the rest of the scenario is.
NOT_A_NUMBER = ["1.0", True, None, [1.0], {}, float("nan"), float("inf"), -float("inf"), 10**400]
NOT_A_VEC3 = ["x", [1.0, 2.0], [1.0, 2.0, 3.0, 4.0], [1.0, "a", 2.0], [1.0, float("nan"), 0.0], 3.0, {}]
BAD_VALUES: dict[str, list[object]] = {
    "material.density": NOT_A_NUMBER + [0, -1.0],
    "material.youngs_modulus": NOT_A_NUMBER + [0.0, -5],
    "material.poisson_ratio": NOT_A_NUMBER + [0.5, 0.7, -1, -2.0],
    "plane.friction": NOT_A_NUMBER + [-0.1],
    "plane.offset": NOT_A_NUMBER,
    "plane.slope_deg": NOT_A_NUMBER + [90, 120.0, -1],
    "plane.downhill": ["y", 1, None],
    "plane.normal": NOT_A_VEC3 + [[0, 0, 0]],
    "contact.law": ["springs", 1, None],
    "contact.stiffness": NOT_A_NUMBER + [0],
    "contact.damping": NOT_A_NUMBER + [-1e-3],
    "contact.friction_stiffness": NOT_A_NUMBER + [0.0],
    "contact.barrier_distance": NOT_A_NUMBER + [0.0],
    "contact.barrier_stiffness": NOT_A_NUMBER + [-1],
    "contact.lag": ["implicit", 1, None],
    "contact.damping_ratio": NOT_A_NUMBER + [-0.1],
    "initial.clearance": NOT_A_NUMBER + [-0.01],
    "initial.rotation": NOT_A_VEC3,
    "initial.translation": NOT_A_VEC3,
    "initial.velocity": NOT_A_VEC3,
    "initial.angular_velocity": NOT_A_VEC3,
    "initial.squash": NOT_A_VEC3 + [[1.0, 0.0, 1.0], [1, 1e-4, 1], [1, -2e3, 1]],
    "time.dt": NOT_A_NUMBER + [0, -0.01],
    "time.duration": NOT_A_NUMBER + [0, -1.0],
    "time.frame_every": [0, -1, 1.5, True, "2", None],
    "time.integrator": ["bdf3", "euler", "", 2, None],
    "mesh.name": ["teapot", 3, None],
    "mesh.resolution": ["ultra", 3, None],
    "mesh.scale": NOT_A_NUMBER + [0, -2.0],
    "gravity": NOT_A_VEC3,
    "name": ["", "a b", "../x", 3, None, "/x"],
    "description": [3, None, ["x"]],
    "tags": ["paper", [1], None],
    "effects.gravity": [1, "yes", None],
    "effects.contact": [0, "no", None],
    "effects.friction": [1.0, "true"],
    "plane": [True, 3, "flat"],
    "material": [3, "soft", [1.0]],
    "time": [1.0, []],
    "mesh": ["cheese", 3],
} | {f"{table}.bogus": [1.0, "x"] for table in ("material", "plane", "contact", "initial", "time", "mesh",
                                                "effects")} | {"bogus": [1.0]}


@settings(max_examples=400, deadline=None)
@given(valid_dicts())
def test_valid_random_scenarios_load_and_round_trip(d: dict[str, Any]) -> None:
    s = scenario_from_dict(d)
    assert scenario_from_dict(scenario_to_dict(s)) == s
    assert scenario_hash(scenario_from_dict(scenario_to_dict(s))) == scenario_hash(s)


@settings(max_examples=800, deadline=None)
@given(valid_dicts(), st.sampled_from(sorted(BAD_VALUES)), st.data())
def test_wrong_types_and_out_of_range_values_raise_scenario_errors(d: dict[str, Any], path: str,
                                                                  data: st.DataObject) -> None:
    value = data.draw(st.sampled_from(BAD_VALUES[path]), label="value")
    if path.startswith("plane.") and d.get("plane") is not False:  # keep one plane form: the mutated one
        d["plane"] = {k: v for k, v in d.get("plane", {}).items()
                      if k not in ("normal", "slope_deg", "downhill")}
        if path == "plane.downhill":
            d["plane"]["slope_deg"] = 10.0
    with pytest.raises(ScenarioError) as info:
        scenario_from_dict(with_(d, path, value))
    assert info.value.field == path
    assert repr(info.value.value) in str(info.value)


JUNK = st.recursive(st.none() | st.booleans() | st.integers() | st.floats() | st.text(max_size=5),
                    lambda inner: st.lists(inner, max_size=4) | st.dictionaries(st.text(max_size=5), inner,
                                                                                 max_size=4),
                    max_leaves=8)


@settings(max_examples=300, deadline=None)
@given(valid_dicts(), st.sampled_from(sorted(BAD_VALUES)), JUNK)
def test_any_junk_anywhere_raises_only_scenario_errors(d: dict[str, Any], path: str, junk: object) -> None:
    try:
        scenario_from_dict(with_(d, path, junk))
    except ScenarioError:
        pass


@pytest.fixture(scope="module")
def scratch(tmp_path_factory: pytest.TempPathFactory) -> Path:
    """A folder for the property tests' files."""
    return tmp_path_factory.mktemp("scenario_files")


@settings(max_examples=300, deadline=None)
@given(st.one_of(st.binary(max_size=300),
                 st.integers(0, len(VALID_TOML)).map(lambda n: VALID_TOML[:n].encode()),
                 st.tuples(st.integers(0, len(VALID_TOML) - 1), st.binary(min_size=1, max_size=3)).map(
                     lambda c: VALID_TOML.encode()[:c[0]] + c[1] + VALID_TOML.encode()[c[0] + 1:])))
def test_random_and_truncated_files_raise_only_scenario_errors(scratch: Path, content: bytes) -> None:
    path = scratch / "s.toml"
    path.write_bytes(content)
    try:
        load_scenario(path)
    except ScenarioError:
        pass


def test_a_normal_component_made_subnormal_by_the_normalisation_keeps_the_round_trip_hash() -> None:
    """Found by hypothesis: -2.9e-307 / 14 is subnormal; the loader flushes it as it does a given subnormal."""
    d = {"name": "0", "plane": {"normal": [0.0, 14.0, -2.9448940884523773e-307]}, "initial": {"clearance": False}}
    s = scenario_from_dict(d)
    assert s.plane.normal == (0.0, 1.0, 0.0)
    assert scenario_hash(scenario_from_dict(scenario_to_dict(s))) == scenario_hash(s)


def test_a_slope_too_small_for_a_normal_number_round_trips() -> None:
    """Found by hypothesis: sin of the smallest normal slope in radians is subnormal; the slope form flushes it as
    the normal form does."""
    s = scenario_from_dict({"name": "0", "plane": {"slope_deg": sys.float_info.min}})
    assert s.plane.normal == (0.0, 1.0, 0.0)
    assert scenario_from_dict(scenario_to_dict(s)) == s


def test_the_shipped_example_scene_loads_and_slides_down_its_incline(tmp_path):
    """examples/incline.toml (docs/scenes.md's example): mu = 0.2 below tan 20 deg = 0.36, so the body slides
    downhill (+x) once it lands; simulated through the CLI a user runs."""
    import numpy as np

    from frictionbench.solvers.trajectory import Trajectory

    example = Path(__file__).resolve().parents[1] / "examples" / "incline.toml"
    sc = load_scenario(example)
    assert sc.plane.friction < math.tan(math.radians(20.0)) and sc.material.damping_ratio == 0.05
    done = subprocess.run([sys.executable, "-m", "frictionbench.bench.cli", "simulate", str(example), "--no-vtu",
                           "-q", "--out", str(tmp_path)], capture_output=True, text=True)
    assert done.returncode == 0, done.stderr
    traj = Trajectory.load(tmp_path / "trajectory.npz")
    com = traj.x.mean(axis=1)
    assert com[-1, 0] - com[0, 0] > 0.05 and np.isfinite(traj.x).all()  # moved downhill by more than 5 cm


def test_the_suite_example_of_the_docs_reads_with_its_split(tmp_path):
    """docs/scenes.md's example suite loads: two members, mu = 0.5 held out."""
    doc = (Path(__file__).resolve().parents[1] / "docs" / "scenes.md").read_text()
    example = doc.split("```toml\n", 1)[1].split("```", 1)[0]
    (tmp_path / "mine.toml").write_text(example)
    suite = load_suite(tmp_path / "mine.toml")
    assert [m.scenario.name for m in suite.train] == ["mine/mu0.1_p1"]
    assert [m.scenario.name for m in suite.test] == ["mine/mu0.5_p1"]


def test_the_scenes_simulate_help_names_exist():
    """`frictionbench simulate --help` names an example file and a member: both resolve."""
    from frictionbench.bench.cli import resolve_scenario

    done = subprocess.run([sys.executable, "-m", "frictionbench.bench.cli", "simulate", "--help"],
                          capture_output=True, text=True, cwd=Path(__file__).resolve().parents[1])
    text = " ".join(done.stdout.split())
    assert "e.g. examples/incline.toml" in text and "e.g. verify/block_slide" in text
    root = Path(__file__).resolve().parents[1]
    assert resolve_scenario(str(root / "examples" / "incline.toml")).name == "example/cheese_incline"
    assert resolve_scenario("verify/block_slide").name == "verify/block_slide"

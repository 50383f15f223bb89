"""Hostile input (issue 5): random, truncated and mistyped suites, broken mesh files, and the CLI on bad input.

Every case must end in a `ScenarioError` (or its `MeshError`) that names the field or the file, never another
exception from deep inside, and must leave no output behind. Together with the scenario-loader properties in
test_scenarios.py these run a few thousand generated cases.
"""

from __future__ import annotations

import io
from contextlib import redirect_stderr, redirect_stdout
from pathlib import Path
from typing import Any

import meshio
import numpy as np
import pytest
import tomli_w
from hypothesis import HealthCheck, given, settings
from hypothesis import strategies as st

from frictionbench.bench.cli import main
from frictionbench.scenarios.errors import MeshError, ScenarioError
from frictionbench.scenarios.meshes import load_mesh, make_mesh
from frictionbench.scenarios.spec import MeshSpec
from frictionbench.scenarios.suites import suite_from_dict

from scenes import block_drop, mu_axis, suite_tables

FAST = settings(deadline=None, suppress_health_check=[HealthCheck.function_scoped_fixture, HealthCheck.too_slow])

# ----- suites -------------------------------------------------------------------------------------------------
VALID_SUITE: dict[str, Any] = suite_tables(
    "fuzz", block_drop(resolution=None, clearance=None, duration=0.1), mu_axis(0.1, 0.5),
    {"name": "plane", "values": [{"label": "p1", "plane.normal": [1.0, 5.0, 2.0]}]}, description="d",
    split={"test": [{"mu": "mu0.5"}]}, extra=[{"labels": {"case": "x"}, "overrides": {"plane.friction": 0.2}}])
JUNK = st.recursive(st.none() | st.booleans() | st.integers() | st.floats() | st.text(max_size=6),
                    lambda inner: st.lists(inner, max_size=3) | st.dictionaries(st.text(max_size=6), inner,
                                                                                 max_size=3),
                    max_leaves=6)
SUITE_PATHS = [("suite",), ("suite", "name"), ("suite", "description"), ("base",), ("base", "mesh"),
               ("base", "time", "dt"), ("axis",), ("axis", 0), ("axis", 0, "name"), ("axis", 0, "field"),
               ("axis", 0, "values"), ("axis", 0, "values", 1), ("axis", 1, "values", 0),
               ("axis", 1, "values", 0, "label"), ("split",), ("split", "test"), ("split", "test", 0),
               ("extra",), ("extra", 0), ("extra", 0, "labels"), ("extra", 0, "overrides"),
               ("extra", 0, "split"), ("bogus",)]


def _replaced(d: Any, path: tuple, value: object) -> Any:
    """A deep copy of nested dicts/lists with the value at `path` replaced (created for a missing dict key)."""
    if not path:
        return value
    if isinstance(d, dict):
        out = dict(d)
        out[path[0]] = _replaced(d.get(path[0]), path[1:], value)
        return out
    out = list(d)
    out[path[0]] = _replaced(d[path[0]], path[1:], value)
    return out


def test_the_fuzz_baseline_suite_is_valid() -> None:
    assert len(suite_from_dict(VALID_SUITE).scenarios) == 3


@settings(FAST, max_examples=600)
@given(st.sampled_from(SUITE_PATHS), JUNK)
def test_junk_anywhere_in_a_suite_raises_only_scenario_errors(path: tuple, junk: object) -> None:
    try:
        suite_from_dict(_replaced(VALID_SUITE, path, junk))
    except ScenarioError as err:
        assert str(err) and err.field


@settings(FAST, max_examples=300)
@given(st.sampled_from(SUITE_PATHS))
def test_a_missing_suite_part_raises_only_scenario_errors(path: tuple) -> None:
    *head, last = path
    d = _replaced(VALID_SUITE, (), VALID_SUITE)
    parent = d
    for key in head:
        parent = parent[key]
    try:
        if isinstance(parent, dict):
            parent = {k: v for k, v in parent.items() if k != last}
        d = _replaced(VALID_SUITE, tuple(head), parent) if head else parent
        suite_from_dict(d)
    except ScenarioError as err:
        assert err.field


SUITE_TOML = tomli_w.dumps(suite_tables(
    "fuzz", block_drop(resolution=None, clearance=None, dt=None, duration=None), mu_axis(0.1, 0.5),
    split={"test": [{"mu": "mu0.5"}]}))


@settings(FAST, max_examples=400)
@given(st.one_of(st.binary(max_size=200),
                 st.integers(0, len(SUITE_TOML)).map(lambda n: SUITE_TOML[:n].encode()),
                 st.tuples(st.integers(0, len(SUITE_TOML) - 1), st.binary(min_size=1, max_size=2)).map(
                     lambda c: SUITE_TOML.encode()[:c[0]] + c[1] + SUITE_TOML.encode()[c[0] + 1:])))
def test_random_and_truncated_suite_files_raise_only_scenario_errors(tmp_path_factory: pytest.TempPathFactory,
                                                                    content: bytes) -> None:
    from frictionbench.scenarios.suites import load_suite

    path = tmp_path_factory.mktemp("suite") / "s.toml"
    path.write_bytes(content)
    try:
        load_suite(path)
    except ScenarioError as err:
        assert err.field


# ----- meshes -------------------------------------------------------------------------------------------------
def _block() -> tuple[np.ndarray, np.ndarray]:
    """A 2 x 2 x 2 hex block split into 48 tets (27 vertices): small, valid, closed and manifold."""
    g = np.stack(np.meshgrid(*[np.arange(3.0)] * 3, indexing="ij"), -1).reshape(-1, 3) * 0.1
    idx = np.arange(27).reshape(3, 3, 3)
    tets = []
    for i, j, k in np.ndindex(2, 2, 2):
        c = [idx[i + a, j + b, k + e] for a, b, e in
             [(0, 0, 0), (1, 0, 0), (1, 1, 0), (0, 1, 0), (0, 0, 1), (1, 0, 1), (1, 1, 1), (0, 1, 1)]]
        for t in ([0, 1, 2, 6], [0, 2, 3, 6], [0, 3, 7, 6], [0, 7, 4, 6], [0, 4, 5, 6], [0, 5, 1, 6]):
            tets.append([c[v] for v in t])
    tets = np.array(tets)
    d = np.linalg.det(np.stack([g[tets[:, k]] - g[tets[:, 0]] for k in (1, 2, 3)], -1))
    tets[d < 0] = tets[d < 0][:, [0, 2, 1, 3]]
    return g, tets


def test_the_fuzz_baseline_mesh_is_valid() -> None:
    X, tets = _block()
    assert make_mesh(X, tets, "block").volumes().sum() == pytest.approx(0.008)


def _mutate(kind: str, X: np.ndarray, tets: np.ndarray, i: int, value: float) -> tuple[np.ndarray, np.ndarray]:
    """One way to break a mesh; i picks the tet or vertex, value a coordinate."""
    X, tets = X.copy(), tets.copy()
    t, v = i % len(tets), i % len(X)
    if kind == "inverted":
        tets[t] = tets[t][[0, 2, 1, 3]]
    elif kind == "degenerate":  # four coplanar (here: repeated) vertices
        tets[t, 3] = tets[t, 0]
    elif kind == "collapsed":  # a vertex moved onto another: zero-volume tets
        X[v] = X[(v + 1) % len(X)]
    elif kind == "nan":
        X[v, i % 3] = value
    elif kind == "index":  # a vertex index out of range (or negative)
        tets[t, i % 4] = len(X) + i if i % 2 else -1 - i
    elif kind == "dangling":  # a second body touching the first at one vertex: non-manifold
        far = X.max(axis=0) + 0.1
        X = np.vstack([X, far + [[0, 0, 0.0], [0.1, 0, 0], [0, 0.1, 0]]])
        n = len(X)
        tets = np.vstack([tets, [[tets[t, 0], n - 3, n - 2, n - 1]]])
    elif kind == "shape":
        X = X[:, :2]
    elif kind == "duplicate":  # the same tet twice: faces shared by three tets
        tets = np.vstack([tets, tets[t:t + 1]])
    return X, tets


MUTATIONS = ["inverted", "degenerate", "collapsed", "nan", "index", "dangling", "shape", "duplicate"]


@settings(FAST, max_examples=800)
@given(st.sampled_from(MUTATIONS), st.integers(0, 10_000), st.sampled_from([np.nan, np.inf, -np.inf]))
def test_broken_meshes_raise_mesh_errors_naming_the_source(kind: str, i: int, value: float) -> None:
    X, tets = _mutate(kind, *_block(), i, value)
    with pytest.raises(MeshError) as info:
        make_mesh(X, tets, "fuzzed", source="fuzzed.vtu")
    assert "fuzzed.vtu" in str(info.value)


@settings(FAST, max_examples=150)
@given(st.sampled_from([m for m in MUTATIONS if m not in ("shape", "index")]), st.integers(0, 10_000),
       st.sampled_from([np.nan, np.inf]), st.sampled_from([".vtu", ".msh", ".npz"]))
def test_broken_mesh_files_fail_with_the_file_named(tmp_path_factory: pytest.TempPathFactory, kind: str, i: int,
                                                     value: float, suffix: str) -> None:
    X, tets = _mutate(kind, *_block(), i, value)
    folder = tmp_path_factory.mktemp("mesh")
    path = folder / f"broken{suffix}"
    if suffix == ".npz":
        np.savez(path, X=X, tets=tets)
    else:
        meshio.write_points_cells(path, X, [("tetra", tets)], file_format="gmsh22" if suffix == ".msh" else None)
    with pytest.raises(MeshError) as info:
        load_mesh(MeshSpec(name=None, path=path.name), base_dir=folder)
    assert str(path) in str(info.value)


@settings(FAST, max_examples=150)
@given(st.binary(max_size=300), st.sampled_from([".vtu", ".msh", ".npz", ".vtk", ".mesh"]))
def test_garbage_mesh_files_fail_with_the_file_named(tmp_path_factory: pytest.TempPathFactory, content: bytes,
                                                     suffix: str) -> None:
    folder = tmp_path_factory.mktemp("mesh")
    path = folder / f"garbage{suffix}"
    path.write_bytes(content)
    with pytest.raises(MeshError) as info:
        load_mesh(MeshSpec(name=None, path=path.name), base_dir=folder)
    assert str(path) in str(info.value)


# ----- the CLI on bad input: a clear message, exit status 2, nothing written ----------------------------------
BAD_SCENARIOS = {
    "malformed": "name = 'x'\n[material\n",
    "nu": "name = 'x'\n[mesh]\nname = 'block'\n[material]\npoisson_ratio = 0.5\n",
    "mu": "name = 'x'\n[mesh]\nname = 'block'\n[plane]\nfriction = -0.1\n",
    "dt": "name = 'x'\n[mesh]\nname = 'block'\n[time]\ndt = 0.0\n",
    "mesh": "name = 'x'\n[mesh]\nname = 'teapot'\n",
    "file": "name = 'x'\n[mesh]\npath = 'broken.vtu'\n",
}


@pytest.mark.parametrize("case", sorted(BAD_SCENARIOS))
def test_simulate_on_bad_input_names_the_problem_and_writes_nothing(tmp_path: Path, case: str) -> None:
    X, tets = _mutate("inverted", *_block(), 3, 0.0)
    meshio.write_points_cells(tmp_path / "broken.vtu", X, [("tetra", tets)])
    (tmp_path / "s.toml").write_text(BAD_SCENARIOS[case])
    out = tmp_path / "out"
    err = io.StringIO()
    with redirect_stderr(err), redirect_stdout(io.StringIO()):
        status = main(["simulate", str(tmp_path / "s.toml"), "--out", str(out), "--quiet"])
    assert status == 2
    message = err.getvalue()
    expected = {"malformed": "s.toml", "nu": "poisson_ratio", "mu": "plane.friction", "dt": "time.dt",
                "mesh": "teapot", "file": "broken.vtu"}[case]
    assert expected in message and "Traceback" not in message
    assert not out.exists() or not any(out.iterdir())

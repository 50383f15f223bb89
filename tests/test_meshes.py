"""Mesh catalogue, validation, file loading and caching (scenarios/meshes.py, scenarios/meshgen.py)."""

from __future__ import annotations

from pathlib import Path

import meshio
import numpy as np
import pytest

from frictionbench.scenarios import meshes, meshgen
from frictionbench.scenarios.errors import MeshError
from frictionbench.scenarios.meshes import (
    CHEESE_GENUS,
    CHEESE_SHAPE,
    SHIPPED,
    SPHERE_RADIUS,
    Recipe,
    TetMesh,
    boundary_triangles,
    catalogue,
    catalogue_mesh,
    load_mesh,
    make_mesh,
    read_mesh_file,
    validate_mesh,
)
from frictionbench.scenarios.spec import MeshSpec

BOXES = {"block": (0.2, 0.1, 0.2), "beam": (1.0, 0.1, 0.1), "slab": (0.4, 0.02, 0.4)}
EULER = {"cheese": 2 - 2 * CHEESE_GENUS, "sphere": 2, "block": 2, "beam": 2, "slab": 2}
COARSE = [(name, res) for name in catalogue() for res in ("coarse", "coarse_alt")]

REAL_TETRAHEDRALIZE = meshgen.tetrahedralize
UNIT_TET = np.array([[0.0, 0.0, 0.0], [1.0, 0.0, 0.0], [0.0, 1.0, 0.0], [0.0, 0.0, 1.0]])


@pytest.fixture(autouse=True)
def isolated_cache(tmp_path_factory: pytest.TempPathFactory, monkeypatch: pytest.MonkeyPatch) -> Path:
    """Every test sees an empty mesh cache, and running TetWild (slow) is an error unless a test allows it."""
    cache = tmp_path_factory.mktemp("cache")
    monkeypatch.setenv("FRICTIONBENCH_CACHE", str(cache))

    def forbidden(*args: object, **kwargs: object) -> None:
        raise AssertionError("a test tried to run TetWild")

    monkeypatch.setattr(meshgen, "tetrahedralize", forbidden)
    return cache


def mesh_of(name: str, resolution: str = "coarse") -> TetMesh:
    return load_mesh(MeshSpec(name=name, resolution=resolution))


def edges(surface: np.ndarray) -> np.ndarray:
    """Unique undirected edges of triangles (k, 3)."""
    pairs = np.concatenate([surface[:, [0, 1]], surface[:, [1, 2]], surface[:, [2, 0]]])
    return np.unique(np.sort(pairs, axis=1), axis=0)


def euler_characteristic(surface: np.ndarray) -> int:
    return len(np.unique(surface)) - len(edges(surface)) + len(surface)


def write_vtu(path: Path, X: np.ndarray, tets: np.ndarray) -> Path:
    meshio.write_points_cells(path, X, [("tetra", tets)])
    return path


def load_error(path: Path) -> MeshError:
    """The MeshError raised by loading `path` as a scenario mesh; it must name the file."""
    with pytest.raises(MeshError) as info:
        load_mesh(MeshSpec(name=None, path=path.name), base_dir=path.parent)
    assert info.value.field == str(path)
    assert str(path) in str(info.value)
    return info.value


# --- catalogue ------------------------------------------------------------------------------------------


def test_catalogue_lists_names_and_resolutions() -> None:
    entries = catalogue()
    assert set(entries) == {"cheese", "sphere", "block", "beam", "slab"}
    for resolutions in entries.values():
        assert set(resolutions) == {"coarse", "coarse_alt", "medium", "medium_alt", "fine"}


@pytest.mark.parametrize(("name", "resolution"), COARSE)
def test_coarse_mesh_is_valid_closed_and_positive(name: str, resolution: str) -> None:
    mesh = mesh_of(name, resolution)
    assert mesh.name == f"{name}/{resolution}"
    assert mesh.X.dtype == np.float64 and mesh.tets.dtype == np.int64 and mesh.surface.dtype == np.int64
    assert 300 <= mesh.n_tets <= 3500
    assert np.all(mesh.volumes() > 0)
    X, tets, surface = validate_mesh(mesh.X, mesh.tets, "again")
    assert np.array_equal(X, mesh.X) and np.array_equal(tets, mesh.tets) and np.array_equal(surface, mesh.surface)
    assert len(mesh.surface) * 3 == 2 * len(edges(mesh.surface))  # closed: every edge in two triangles
    assert euler_characteristic(mesh.surface) == EULER[name]


@pytest.mark.parametrize(("name", "resolution"), COARSE)
def test_volume_and_area_match_the_shape(name: str, resolution: str) -> None:
    mesh = mesh_of(name, resolution)
    volume, area = mesh.volumes().sum(), mesh.surface_areas().sum()
    if name in BOXES:
        a, b, c = BOXES[name]
        assert volume == pytest.approx(a * b * c, rel=1e-12)
        assert area == pytest.approx(2 * (a * b + b * c + c * a), rel=1e-12)
        assert np.allclose(np.ptp(mesh.X, axis=0), BOXES[name])
    elif name == "sphere":
        assert volume == pytest.approx(4 / 3 * np.pi * SPHERE_RADIUS**3, rel=0.03)
        assert area == pytest.approx(4 * np.pi * SPHERE_RADIUS**2, rel=0.03)
    else:
        assert volume == pytest.approx(cheese_csg_volume(), rel=0.03)  # coarse holes: about +2%


def cheese_csg_volume() -> float:
    """Volume of the cheese's CSG surface (manifold3d, no TetWild) [m^3], by the divergence theorem."""
    V, F = meshgen.cheese_surface(**CHEESE_SHAPE, circular_segments=96)
    a, b, c = V[F[:, 0]], V[F[:, 1]], V[F[:, 2]]
    return float(np.einsum("ij,ij->i", a, np.cross(b, c)).sum() / 6.0)


@pytest.mark.parametrize("resolution", ["coarse", "coarse_alt"])
def test_tetwild_boundaries_are_snapped_onto_the_shape(resolution: str) -> None:
    sphere = mesh_of("sphere", resolution)
    radii = np.linalg.norm(sphere.X[sphere.surface_vertices()], axis=1)
    assert np.allclose(radii, SPHERE_RADIUS, atol=1e-4 * SPHERE_RADIUS)
    cheese = mesh_of("cheese", resolution)
    assert np.allclose(cheese.X.min(axis=0), [0.0, 0.0, -0.25], atol=1e-3)
    assert np.allclose(cheese.X.max(axis=0), [0.5, 0.22, 0.25], atol=1e-3)
    y = cheese.X[:, 1]
    assert y.min() == pytest.approx(0.0, abs=1e-12) and y.max() == pytest.approx(0.22, abs=1e-12)
    assert np.sum(np.abs(y) < 1e-12) > 50  # a flat bottom: many vertices exactly on y = 0


def test_cheese_surface_is_one_solid_of_the_declared_genus() -> None:
    V, F = meshgen.cheese_surface(**CHEESE_SHAPE, circular_segments=24)
    assert euler_characteristic(F) == 2 - 2 * CHEESE_GENUS  # one component: no enclosed cavity
    assert np.allclose(V.min(axis=0), [0.0, 0.0, -0.25]) and np.allclose(V.max(axis=0), [0.5, 0.22, 0.25])


@pytest.mark.parametrize("name", list(catalogue()))
def test_surface_vertex_areas_share_the_surface(name: str) -> None:
    mesh = mesh_of(name)
    shares = mesh.surface_vertex_areas()
    assert shares.shape == (mesh.n_vertices,)
    assert shares.sum() == pytest.approx(mesh.surface_areas().sum(), rel=1e-12)
    on_surface = np.zeros(mesh.n_vertices, dtype=bool)
    on_surface[mesh.surface_vertices()] = True
    assert np.all(shares[on_surface] > 0) and np.all(shares[~on_surface] == 0)
    assert 0 < on_surface.sum() < mesh.n_vertices


@pytest.mark.parametrize("name", list(catalogue()))
def test_alt_mesh_is_another_mesh_of_the_same_shape(name: str) -> None:
    mesh, alt = mesh_of(name), mesh_of(name, "coarse_alt")
    assert mesh.n_vertices != alt.n_vertices
    assert alt.volumes().sum() == pytest.approx(mesh.volumes().sum(), rel=0.02)
    assert alt.bbox_diagonal() == pytest.approx(mesh.bbox_diagonal(), rel=0.02)


@pytest.mark.parametrize(("name", "resolution"), SHIPPED)
def test_shipped_meshes_are_current_and_small(name: str, resolution: str) -> None:
    entry = meshes.recipe(name, resolution)
    path = meshes.shipped_path(entry)
    assert path.stat().st_size < 300_000
    with np.load(path) as data:
        assert str(data["key"]) == entry.key, f"{path} is stale: run `python -m frictionbench.scenarios.meshes --ship`"
        assert data["tets"].dtype == np.int32 and data["X"].dtype == np.float64


def test_structured_medium_is_finer() -> None:
    assert mesh_of("beam", "medium").n_tets == 40 * 4 * 4 * 6


def test_scale_multiplies_positions() -> None:
    mesh = load_mesh(MeshSpec(name="block", resolution="coarse", scale=2.0))
    assert np.allclose(mesh.X, 2.0 * mesh_of("block").X)
    assert mesh.volumes().sum() == pytest.approx(8 * 0.004, rel=1e-12)


@pytest.mark.parametrize(
    ("spec", "field", "choice"),
    [
        (MeshSpec(name="cheddar"), "mesh.name", "sphere"),
        (MeshSpec(name="cheese", resolution="huge"), "mesh.resolution", "medium_alt"),
        (MeshSpec(name="block", scale=0.0), "mesh.scale", "positive"),
    ],
)
def test_bad_catalogue_spec_names_the_field(spec: MeshSpec, field: str, choice: str) -> None:
    with pytest.raises(MeshError) as info:
        load_mesh(spec)
    assert info.value.field == field
    assert choice in str(info.value)


def test_mesh_arrays_are_read_only_and_digest_identifies_content() -> None:
    mesh = mesh_of("block")
    with pytest.raises(ValueError):
        mesh.X[0, 0] = 1.0
    assert mesh.digest() == mesh_of("block").digest() != mesh.scaled(2.0).digest()


# --- storage --------------------------------------------------------------------------------------------


def test_stored_recipe_is_generated_once_then_read_from_cache(isolated_cache: Path) -> None:
    calls = []

    def build_box(params: dict) -> tuple[np.ndarray, np.ndarray]:
        calls.append(params)
        return meshgen.structured_box((1.0, 1.0, 1.0), (2, 2, 2), (0.0, 0.0, 0.0))

    entry = Recipe("box", "test", build_box, {"n": 2}, stored=True)
    first, second = catalogue_mesh(entry), catalogue_mesh(entry)
    assert len(calls) == 1
    assert meshes.cache_path(entry).parent == isolated_cache / "meshes"
    assert meshes.cache_path(entry).is_file() and not list(isolated_cache.rglob("*.tmp"))
    assert np.array_equal(first.X, second.X) and np.array_equal(first.tets, second.tets)
    changed = Recipe("box", "test", build_box, {"n": 3}, stored=True)
    assert changed.key != entry.key
    catalogue_mesh(changed)
    assert len(calls) == 2


def test_invalid_generator_output_names_the_entry_and_stores_nothing(isolated_cache: Path) -> None:
    def build_flat(params: dict) -> tuple[np.ndarray, np.ndarray]:
        return np.vstack([UNIT_TET, [[0.5, 0.5, 0.0]]]), np.array([[0, 1, 2, 3], [0, 1, 2, 4]])

    with pytest.raises(MeshError, match="degenerate") as info:
        catalogue_mesh(Recipe("flat", "test", build_flat, stored=True))
    assert info.value.field == "flat/test"
    assert not list(isolated_cache.rglob("*"))


def test_tiny_tetwild_run_gives_a_valid_sphere() -> None:
    V, F = meshgen.icosphere(0.25, 1)
    X, tets = REAL_TETRAHEDRALIZE(V, F, edge_length_fac=0.3, epsilon=1e-2, stop_energy=50.0, num_opt_iter=10)
    mesh = make_mesh(X, tets, "tiny", fix_orientation=True)
    assert euler_characteristic(mesh.surface) == 2
    assert mesh.volumes().sum() == pytest.approx(4 / 3 * np.pi * 0.25**3, rel=0.2)


# --- files and validation -------------------------------------------------------------------------------


def test_meshio_file_loads_back_identically(tmp_path: Path) -> None:
    block = mesh_of("block")
    write_vtu(tmp_path / "block.vtu", block.X, block.tets)
    loaded = load_mesh(MeshSpec(name=None, path="block.vtu"), base_dir=tmp_path)
    assert np.array_equal(loaded.X, block.X) and np.array_equal(loaded.tets, block.tets)
    assert np.array_equal(loaded.surface, block.surface)
    assert loaded.name == "block.vtu"


def test_missing_unreadable_and_tetless_files(tmp_path: Path) -> None:
    assert "not found" in str(load_error(tmp_path / "absent.vtu"))
    (tmp_path / "mesh.xyz123").write_text("nothing")
    assert "meshio cannot read" in str(load_error(tmp_path / "mesh.xyz123"))
    meshio.write_points_cells(tmp_path / "tri.vtu", UNIT_TET, [("triangle", np.array([[0, 1, 2]]))])
    assert "no linear tetrahedra" in str(load_error(tmp_path / "tri.vtu"))


def test_inverted_tets_are_rejected_or_fixed(tmp_path: Path) -> None:
    block = mesh_of("block")
    tets = block.tets.copy()
    tets[[5, 9]] = tets[[5, 9]][:, [0, 2, 1, 3]]
    path = write_vtu(tmp_path / "inverted.vtu", block.X, tets)
    error = load_error(path)
    assert "2 of 648 tets are inverted" in str(error) and "first: tet 5" in str(error)
    assert "fix_orientation" in str(error)
    fixed = read_mesh_file(path, fix_orientation=True)
    assert np.all(fixed.volumes() > 0)
    assert fixed.volumes().sum() == pytest.approx(0.004, rel=1e-12)


def test_degenerate_tet_is_rejected(tmp_path: Path) -> None:
    X = np.vstack([UNIT_TET, [[0.5, 0.5, 0.0]]])
    path = write_vtu(tmp_path / "flat.vtu", X, np.array([[0, 1, 2, 3], [0, 1, 2, 4]]))
    assert "degenerate" in str(load_error(path))


def test_non_finite_coordinates_are_rejected(tmp_path: Path) -> None:
    X = UNIT_TET.copy()
    X[2, 1] = np.nan
    error = load_error(write_vtu(tmp_path / "nan.vtu", X, np.array([[0, 1, 2, 3]])))
    assert "non-finite" in str(error) and error.value == "vertex 2"


def test_out_of_range_index_is_rejected(tmp_path: Path) -> None:
    error = load_error(write_vtu(tmp_path / "range.vtu", UNIT_TET, np.array([[0, 1, 2, 7]])))
    assert "outside 0..3" in str(error)


def test_repeated_vertex_is_rejected(tmp_path: Path) -> None:
    assert "repeat a vertex" in str(load_error(write_vtu(tmp_path / "rep.vtu", UNIT_TET, np.array([[0, 1, 1, 3]]))))


TOUCHING = {  # two positive tets sharing only ...
    "vertex": (np.vstack([UNIT_TET, -UNIT_TET[1:]]), [[0, 1, 2, 3], [0, 5, 4, 6]], "join separate sheets"),
    "edge": (np.vstack([UNIT_TET, [[0.0, -1.0, 0.0], [0.0, 0.0, -1.0]]]), [[0, 1, 2, 3], [0, 1, 4, 5]],
             "not shared by exactly two"),
}


@pytest.mark.parametrize("shared", list(TOUCHING))
def test_tets_touching_at_a_vertex_or_edge_are_non_manifold(tmp_path: Path, shared: str) -> None:
    X, tets, problem = TOUCHING[shared]
    error = load_error(write_vtu(tmp_path / f"{shared}.vtu", X, np.array(tets)))
    assert "2-manifold" in str(error) and problem in str(error)


def test_two_tets_sharing_a_face_are_valid() -> None:
    X = np.vstack([UNIT_TET, [[0.4, 0.4, -1.0]]])
    mesh = make_mesh(X, np.array([[0, 1, 2, 3], [0, 2, 1, 4]]), "pair")
    assert len(mesh.surface) == 6 and euler_characteristic(mesh.surface) == 2


def test_face_shared_by_three_tets_is_rejected() -> None:
    X = np.vstack([UNIT_TET, [[0.4, 0.4, -1.0], [0.3, 0.3, 2.0]]])
    with pytest.raises(MeshError, match="more than two tets"):
        validate_mesh(X, np.array([[0, 1, 2, 3], [0, 2, 1, 4], [0, 1, 2, 5]]), "three.vtu")


def test_empty_mesh_and_bad_shapes_are_rejected() -> None:
    with pytest.raises(MeshError, match="empty"):
        validate_mesh(UNIT_TET, np.zeros((0, 4), dtype=int), "empty.vtu")
    with pytest.raises(MeshError, match=r"shape \(m, 4\)"):
        validate_mesh(UNIT_TET, np.array([[0, 1, 2]]), "tri.vtu")


def test_unreferenced_vertices_are_dropped() -> None:
    X = np.vstack([[[9.0, 9.0, 9.0]], UNIT_TET])
    X_kept, tets, _ = validate_mesh(X, np.array([[1, 2, 3, 4]]), "extra.vtu")
    assert np.array_equal(X_kept, UNIT_TET) and np.array_equal(tets, [[0, 1, 2, 3]])


def test_boundary_triangles_of_a_tet_point_outward() -> None:
    faces = boundary_triangles(np.array([[0, 1, 2, 3]]))
    a, b, c = (UNIT_TET[faces[:, i]] for i in range(3))
    normals = np.cross(b - a, c - a)
    outward = (a + b + c) / 3 - UNIT_TET.mean(axis=0)
    assert len(faces) == 4 and np.all(np.einsum("ij,ij->i", normals, outward) > 0)

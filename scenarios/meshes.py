"""Tetrahedral meshes: the `TetMesh` type, validation, the mesh catalogue, file loading and the mesh cache.

Catalogue meshes (`catalogue()` lists names and resolutions; `scenarios.meshgen` builds them):
- `cheese`: a 60 degree wedge of a 0.5 m radius, 0.22 m high cylinder with five spherical holes, every one
  cutting the surface: a tunnel through top and bottom (so the surface has genus 1) and dents in the top, a
  flat side, the curved side and the bottom. Apex edge on the y axis, bottom at y = 0. TetWild.
- `sphere`: radius 0.25 m, centred at the origin. TetWild of an icosphere.
- `block`: 0.2 x 0.1 x 0.2 m box, centred in x and z, bottom at y = 0. Structured.
- `beam`: 1.0 x 0.1 x 0.1 m cantilever along +x from x = 0, centred in y and z. Structured.
- `slab`: 0.4 x 0.02 x 0.4 m plate, centred in x and z, bottom at y = 0. Structured.
Resolutions: `coarse` (CI), `medium`, `fine` (on demand only), and `coarse_alt` / `medium_alt`: the same shape
meshed independently at another resolution, for remeshing checks.

TetWild meshes are slow to make and not repeatable (fTetWild gives a slightly different mesh on every run),
so they are stored as .npz: `coarse` and `coarse_alt` ship in `scenarios/meshes/`; the others are generated
on first use into `$FRICTIONBENCH_CACHE/meshes/` (default `~/.cache/frictionbench/meshes/`), keyed by a hash
of the recipe (`Recipe.key`); `TetMesh.digest()` identifies a mesh's content. After TetWild, boundary
vertices are snapped onto the exact shape (flat faces come out flat, sphere vertices on the sphere).
Structured meshes are rebuilt on each load. `python -m frictionbench.scenarios.meshes --help` builds cache entries and
rewrites the shipped files.
"""

from __future__ import annotations

import argparse
import hashlib
import json
import os
import time
from collections.abc import Callable, Mapping
from dataclasses import dataclass, field, replace
from importlib import metadata
from pathlib import Path
from typing import Any

import numpy as np
from scipy.sparse import coo_matrix
from scipy.sparse.csgraph import connected_components

from frictionbench.scenarios import meshgen
from frictionbench.scenarios.atomic import atomic_open
from frictionbench.scenarios.errors import MeshError
from frictionbench.scenarios.spec import MeshSpec

Array = np.ndarray

GENERATOR_VERSION = 2
"""Bump when a generator's output changes for the same parameters: it invalidates every stored mesh."""

SHIPPED_DIR = Path(__file__).resolve().parent / "meshes"
DEGENERATE_VOLUME_FACTOR = 1.0e-12
"""A tet is degenerate when |volume| < DEGENERATE_VOLUME_FACTOR * (bounding-box diagonal)^3."""

# The 4 faces of tet (v0, v1, v2, v3), each ordered so its normal points out of a positively oriented tet.
_TET_FACES = np.array([[1, 2, 3], [0, 3, 2], [0, 1, 3], [0, 2, 1]], dtype=np.int64)


@dataclass(frozen=True, eq=False)
class TetMesh:
    """A validated tetrahedral mesh at rest. Arrays are stored read-only.

    X: (n, 3) float64 rest positions [m].
    tets: (m, 4) int64 vertex indices, positively oriented: det(X1 - X0, X2 - X0, X3 - X0) > 0.
    surface: (k, 3) int64 boundary triangles, counter-clockwise seen from outside (normals point out).
    name: identity, e.g. `cheese/coarse` or a file path.
    Build from untrusted arrays with `make_mesh`, which validates.
    """

    X: Array
    tets: Array
    surface: Array
    name: str

    def __post_init__(self) -> None:
        for attr, dtype in (("X", np.float64), ("tets", np.int64), ("surface", np.int64)):
            array = np.array(getattr(self, attr), dtype=dtype, order="C")
            array.flags.writeable = False
            object.__setattr__(self, attr, array)

    @property
    def n_vertices(self) -> int:
        """Number of vertices n."""
        return len(self.X)

    @property
    def n_tets(self) -> int:
        """Number of tets m."""
        return len(self.tets)

    def volumes(self) -> Array:
        """Rest volume of each tet, (m,) [m^3]; positive."""
        return meshgen.signed_volumes(self.X, self.tets)

    def bbox_diagonal(self) -> float:
        """Length of the diagonal of the axis-aligned bounding box of X [m]."""
        return bbox_diagonal(self.X)

    def surface_areas(self) -> Array:
        """Area of each boundary triangle, (k,) [m^2]."""
        a, b, c = (self.X[self.surface[:, i]] for i in range(3))
        return 0.5 * np.linalg.norm(np.cross(b - a, c - a), axis=1)

    def surface_vertex_areas(self) -> Array:
        """Each vertex's share of the surface area, (n,) [m^2]: a third of every incident boundary triangle.

        Zero for interior vertices; sums to the total surface area.
        """
        shares = np.repeat(self.surface_areas() / 3.0, 3)
        return np.bincount(self.surface.ravel(), weights=shares, minlength=self.n_vertices)

    def surface_vertices(self) -> Array:
        """Sorted indices of the vertices on the boundary, (s,) int64."""
        return np.unique(self.surface)

    def digest(self) -> str:
        """Hash of the arrays X and tets, 16 hex digits: identifies the mesh's content, not its recipe.

        TetWild is not repeatable, so two machines may hold different meshes for one recipe key.
        """
        return hashlib.sha256(self.X.tobytes() + self.tets.tobytes()).hexdigest()[:16]

    def scaled(self, factor: float) -> TetMesh:
        """The same mesh with rest positions multiplied by `factor` (> 0) [-]."""
        return replace(self, X=self.X * factor)


def bbox_diagonal(X: Array) -> float:
    """Length of the bounding-box diagonal of points X (n, 3) [m]."""
    return float(np.linalg.norm(X.max(axis=0) - X.min(axis=0)))


def _tet_faces(tets: Array) -> tuple[Array, Array]:
    """All 4 m tet faces, outward for positive tets, (4m, 3), and how many tets use each one, (4m,)."""
    faces = tets[:, _TET_FACES].reshape(-1, 3)
    _, inverse, counts = np.unique(np.sort(faces, axis=1), axis=0, return_inverse=True, return_counts=True)
    return faces, counts[inverse.ravel()]


def boundary_triangles(tets: Array) -> Array:
    """Faces used by exactly one tet, (k, 3) int64, oriented outward when the tets are positively oriented.

    tets: (m, 4) vertex indices.
    """
    faces, counts = _tet_faces(np.asarray(tets, dtype=np.int64))
    return faces[counts == 1]


def validate_mesh(
    X: Array, tets: Array, source: str, *, fix_orientation: bool = False
) -> tuple[Array, Array, Array]:
    """Check a tet mesh and return `(X, tets, surface)` ready for `TetMesh`.

    X: (n, 3) rest positions [m]. tets: (m, 4) vertex indices. source: file path or catalogue key, named
    in every error. fix_orientation: flip inverted (negative-volume) tets instead of rejecting them.
    Unreferenced vertices are dropped and the indices remapped.
    Returns X (n', 3) float64, tets (m, 4) int64 positively oriented, surface (k, 3) int64 outward.
    Raises MeshError (field = source) for: wrong shapes, an empty mesh, non-finite coordinates, indices out
    of range, a vertex repeated within a tet, degenerate or (unless fixed) inverted tets, a face shared by
    more than two tets, a boundary that is not a closed, consistently oriented 2-manifold, and a vertex whose
    tets do not form one solid around it (tets joined only at a vertex or an edge, even inside the body).
    """
    X, tets = _checked_arrays(X, tets, source)
    X, tets = _drop_unreferenced(X, tets)
    tets = _checked_orientation(X, tets, source, fix_orientation)
    faces, counts = _tet_faces(tets)
    _require(counts <= 2, source, "face", "faces are shared by more than two tets (overlapping tets)")
    surface = faces[counts == 1]
    _check_closed_manifold(surface, source)
    _check_vertex_stars(tets, source)
    return X, tets, surface


def _require(ok: Array, source: str, what: str, problem: str, hint: str = "") -> None:
    """Raise MeshError(source) naming how many entries of `ok` (one per `what`) are False and the first one."""
    bad = np.flatnonzero(~ok)
    if len(bad):
        first = int(bad[0])
        reason = f"{len(bad)} of {len(ok)} {problem}; first: {what} {first}" + (f". {hint}" if hint else "")
        raise MeshError(source, f"{what} {first}", reason)


def _checked_arrays(X: Array, tets: Array, source: str) -> tuple[Array, Array]:
    """Shapes, emptiness, finiteness, index range and repeated vertices; returns float64 X, int64 tets."""
    X = np.asarray(X, dtype=np.float64)
    tets = np.asarray(tets)
    if X.ndim != 2 or X.shape[1] != 3:
        raise MeshError(source, X.shape, "vertex positions must have shape (n, 3)")
    if tets.ndim != 2 or tets.shape[1] != 4 or not np.issubdtype(tets.dtype, np.integer):
        raise MeshError(source, f"{tets.dtype}{tets.shape}", "tets must be integer indices of shape (m, 4)")
    if len(tets) == 0 or len(X) == 0:
        raise MeshError(source, f"{len(X)} vertices, {len(tets)} tets", "the mesh is empty")
    tets = tets.astype(np.int64)
    _require(np.isfinite(X).all(axis=1), source, "vertex", "vertices have non-finite coordinates (NaN or inf)")
    _require(((tets >= 0) & (tets < len(X))).all(axis=1), source, "tet",
             f"tets index vertices outside 0..{len(X) - 1}")
    ordered = np.sort(tets, axis=1)
    _require((ordered[:, 1:] != ordered[:, :-1]).all(axis=1), source, "tet", "tets repeat a vertex")
    return X, tets


def _drop_unreferenced(X: Array, tets: Array) -> tuple[Array, Array]:
    """Remove vertices no tet uses and renumber the tets accordingly."""
    used = np.zeros(len(X), dtype=bool)
    used[tets.ravel()] = True
    if used.all():
        return X, tets
    new_index = np.cumsum(used) - 1
    return X[used], new_index[tets]


def _checked_orientation(X: Array, tets: Array, source: str, fix_orientation: bool) -> Array:
    """Reject degenerate tets; flip (fix_orientation) or reject inverted ones. Returns positive tets."""
    volumes = meshgen.signed_volumes(X, tets)
    tolerance = DEGENERATE_VOLUME_FACTOR * bbox_diagonal(X) ** 3
    _require(np.abs(volumes) >= tolerance, source, "tet",
             f"tets are degenerate (|volume| < {tolerance:.3g} m^3: flat or collapsed)")
    inverted = volumes < 0
    if fix_orientation:
        tets = tets.copy()
        tets[inverted, 1], tets[inverted, 2] = tets[inverted, 2], tets[inverted, 1].copy()
        return tets
    _require(~inverted, source, "tet", "tets are inverted (negative volume)",
             "Tets must be ordered so that det(X1 - X0, X2 - X0, X3 - X0) > 0: swap two vertices of each "
             "inverted tet, or let read_mesh_file / validate_mesh flip them (fix_orientation=True)")
    return tets


def _check_closed_manifold(surface: Array, source: str) -> None:
    """The boundary must be a closed, consistently oriented 2-manifold.

    Every edge is shared by exactly two boundary triangles, traversed once in each direction, and the
    triangles around every boundary vertex form one fan (no two solids touching at a single vertex).
    """
    tails = surface.ravel()
    heads = surface[:, [1, 2, 0]].ravel()
    undirected, edge_counts = np.unique(np.sort(np.column_stack([tails, heads]), axis=1), axis=0,
                                        return_counts=True)
    bad = np.flatnonzero(edge_counts != 2)
    if len(bad):
        u, v = (int(i) for i in undirected[bad[0]])
        raise MeshError(source, f"edge ({u}, {v})",
                        f"the boundary is not a closed 2-manifold: {len(bad)} boundary edges are not shared by "
                        f"exactly two boundary triangles (edge ({u}, {v}) has {int(edge_counts[bad[0]])})")
    n = int(surface.max()) + 1
    directed = tails * n + heads
    order = np.argsort(directed)
    twin_position = np.searchsorted(directed[order], heads * n + tails)
    twin = order[np.minimum(twin_position, len(order) - 1)]
    if not np.array_equal(directed[twin], heads * n + tails):
        first = int(np.flatnonzero(directed[twin] != heads * n + tails)[0])
        raise MeshError(source, f"boundary triangle {first // 3}",
                        "the boundary is inconsistently oriented (two boundary triangles traverse an edge in "
                        "the same direction: folded or overlapping tets)")
    _check_vertex_fans(surface, twin, source)


def _check_vertex_fans(surface: Array, twin: Array, source: str) -> None:
    """Each boundary vertex's triangles must form a single fan; `twin[h]` is the half-edge opposite h.

    Corner 3 t + s is triangle t at its vertex surface[t, s], the tail of half-edge 3 t + s. The tail
    corner of h and the head corner of its twin sit at the same vertex in adjacent triangles: joining them
    leaves one connected group of corners per vertex exactly when every vertex's fan is a single disc.
    """
    half_edges = np.arange(surface.size)
    twin_head_corner = 3 * (twin // 3) + (twin % 3 + 1) % 3
    links = coo_matrix((np.ones(surface.size), (half_edges, twin_head_corner)), shape=(surface.size,) * 2)
    n_fans, fan = connected_components(links, directed=False)
    vertices = surface.ravel()
    if n_fans == len(np.unique(vertices)):
        return
    fans_per_vertex = np.bincount(np.unique(np.column_stack([vertices, fan]), axis=0)[:, 0])
    first = int(np.flatnonzero(fans_per_vertex > 1)[0])
    raise MeshError(source, f"vertex {first}",
                    f"the boundary is not a 2-manifold: {int((fans_per_vertex > 1).sum())} vertices join "
                    f"separate sheets of surface (e.g. two tets sharing only vertex {first})")


def _check_vertex_stars(tets: Array, source: str) -> None:
    """The tets around every vertex must be connected through faces that contain the vertex.

    Node 4 t + k is tet t at its k-th vertex. Two tets sharing a face join their nodes at the face's three
    vertices; a vertex whose nodes fall into more than one group joins solids at a single point or along an
    edge, which the boundary checks miss when the vertex is interior.
    """
    m = len(tets)
    faces = np.sort(tets[:, _TET_FACES].reshape(-1, 3), axis=1)  # face f = 4 t + j
    order = np.lexsort(faces.T[::-1])
    same = np.all(faces[order[1:]] == faces[order[:-1]], axis=1)
    f1, f2 = order[:-1][same], order[1:][same]  # interior faces: the two (tet, face) uses
    t1, t2 = f1 // 4, f2 // 4
    verts = faces[f1]  # (k, 3) the shared vertices
    a, b = (4 * t[:, None] + np.argmax(tets[t][:, :, None] == verts[:, None, :], axis=1)  # node of t at each
            for t in (t1, t2))                                                             # shared vertex
    a, b = a.ravel(), b.ravel()
    graph = coo_matrix((np.ones(a.size), (a, b)), shape=(4 * m, 4 * m))
    _, group = connected_components(graph, directed=False)
    pairs = np.unique(np.column_stack([tets.ravel(), group]), axis=0)
    stars = np.bincount(pairs[:, 0])
    bad = np.flatnonzero(stars > 1)
    if len(bad):
        first = int(bad[0])
        raise MeshError(source, f"vertex {first}",
                        f"the mesh is not a manifold solid: at {len(bad)} vertices the tets form separate solids "
                        f"joined only at the vertex or along an edge (first: vertex {first})")


def make_mesh(X: Array, tets: Array, name: str, *, source: str | None = None,
              fix_orientation: bool = False) -> TetMesh:
    """Validate arrays (see `validate_mesh`) and build a TetMesh called `name`; errors name `source` or name."""
    X, tets, surface = validate_mesh(X, tets, source or name, fix_orientation=fix_orientation)
    return TetMesh(X=X, tets=tets, surface=surface, name=name)


def read_mesh_file(path: Path, *, name: str | None = None, fix_orientation: bool = False) -> TetMesh:
    """Read the linear tets (`tetra` cells) of any file meshio reads; other cells are ignored.

    path: the file. name: the mesh's name (default: the path). fix_orientation: see `validate_mesh`.
    Raises MeshError naming the path when the file is missing, unreadable, has no tets, or is invalid.
    """
    import meshio

    source = str(path)
    if not Path(path).is_file():
        raise MeshError(source, source, "mesh file not found")
    try:
        data = meshio.read(path)
    except (Exception, SystemExit) as error:  # meshio's readers raise many types (and exit) on malformed files
        raise MeshError(source, source, f"meshio cannot read this file ({type(error).__name__}: {error})") from None
    blocks = [cells.data for cells in data.cells if cells.type == "tetra"]
    if not blocks:
        types = sorted({cells.type for cells in data.cells})
        raise MeshError(source, types, "the file has no linear tetrahedra ('tetra' cells)")
    return make_mesh(data.points, np.concatenate(blocks), name or source, source=source,
                     fix_orientation=fix_orientation)


# --- catalogue ------------------------------------------------------------------------------------------

Builder = Callable[[Mapping[str, Any]], tuple[Array, Array]]


def _build_structured(p: Mapping[str, Any]) -> tuple[Array, Array]:
    return meshgen.structured_box(p["size"], p["divisions"], p["origin"])


def _build_sphere(p: Mapping[str, Any]) -> tuple[Array, Array]:
    V, F = meshgen.icosphere(p["radius"], p["subdivisions"], p["rotation_deg"])
    # Snap onto a much finer icosphere: boundary vertices land on the sphere itself (within ~2e-5 r).
    return _tetwild_snapped(V, F, p["tetwild"], meshgen.icosphere(p["radius"], p["snap_subdivisions"]))


def _build_cheese(p: Mapping[str, Any]) -> tuple[Array, Array]:
    V, F = meshgen.cheese_surface(**p["shape"], circular_segments=p["circular_segments"])
    return _tetwild_snapped(V, F, p["tetwild"], (V, F))


def _tetwild_snapped(
    V: Array, F: Array, settings: Mapping[str, Any], snap_target: tuple[Array, Array]
) -> tuple[Array, Array]:
    """TetWild mesh of the surface (V, F), positively oriented, boundary snapped onto `snap_target` (V', F')."""
    X, tets = meshgen.tetrahedralize(V, F, **settings)
    X, tets, surface = validate_mesh(X, tets, "TetWild output", fix_orientation=True)
    return meshgen.snap_to_surface(X, tets, np.unique(surface), *snap_target), tets


@dataclass(frozen=True, eq=False)
class Recipe:
    """How one catalogue mesh is made.

    name, resolution: the catalogue entry. builder: function of `params` returning raw (X, tets).
    params: JSON-serialisable generator parameters (all lengths in metres).
    stored: True for slow (TetWild) meshes, which are kept as .npz (shipped or cached).
    """

    name: str
    resolution: str
    builder: Builder
    params: Mapping[str, Any] = field(default_factory=dict)
    stored: bool = False

    @property
    def label(self) -> str:
        """`name/resolution`."""
        return f"{self.name}/{self.resolution}"

    @property
    def key(self) -> str:
        """Hash of (name, resolution, builder, parameters, GENERATOR_VERSION), 16 hex digits."""
        identity = {"name": self.name, "resolution": self.resolution, "builder": self.builder.__name__,
                    "params": self.params, "version": GENERATOR_VERSION}
        return hashlib.sha256(json.dumps(identity, sort_keys=True).encode()).hexdigest()[:16]

    def build(self) -> tuple[Array, Array]:
        """Run the generator: raw (X, tets)."""
        return self.builder(self.params)


Triple = tuple[float, float, float]
_STRUCTURED: dict[str, tuple[Triple, Triple, dict[str, tuple[int, int, int]]]] = {
    # name: (size [m], origin [m], resolution -> hex divisions (nx, ny, nz)); 6 tets per hex.
    "block": ((0.2, 0.1, 0.2), (-0.1, 0.0, -0.1), {
        "coarse": (6, 3, 6), "coarse_alt": (8, 4, 8), "medium": (12, 6, 12), "medium_alt": (16, 8, 16),
        "fine": (34, 17, 34)}),
    "beam": ((1.0, 0.1, 0.1), (0.0, -0.05, -0.05), {
        "coarse": (20, 2, 2), "coarse_alt": (30, 3, 3), "medium": (40, 4, 4), "medium_alt": (50, 5, 5),
        "fine": (120, 12, 12)}),
    "slab": ((0.4, 0.02, 0.4), (-0.2, 0.0, -0.2), {
        "coarse": (16, 2, 16), "coarse_alt": (12, 2, 12), "medium": (30, 3, 30), "medium_alt": (24, 3, 24),
        "fine": (64, 5, 64)}),
}

SPHERE_RADIUS = 0.25
_SPHERE: dict[str, dict[str, Any]] = {
    # resolution: icosphere tessellation (subdivisions, rotation [deg]) and TetWild settings.
    "coarse": {"subdivisions": 3, "rotation_deg": [0.0, 0.0, 0.0],
               "tetwild": {"edge_length_fac": 0.1, "epsilon": 5e-3}},
    "coarse_alt": {"subdivisions": 3, "rotation_deg": [17.0, 31.0, 47.0],
                   "tetwild": {"edge_length_fac": 0.16, "epsilon": 6e-3}},
    "medium": {"subdivisions": 4, "rotation_deg": [0.0, 0.0, 0.0],
               "tetwild": {"edge_length_fac": 0.045, "epsilon": 1.5e-3}},
    "medium_alt": {"subdivisions": 4, "rotation_deg": [17.0, 31.0, 47.0],
                   "tetwild": {"edge_length_fac": 0.05, "epsilon": 1.7e-3}},
    "fine": {"subdivisions": 4, "rotation_deg": [0.0, 0.0, 0.0],
             "tetwild": {"edge_length_fac": 0.02, "epsilon": 5e-4}},
}

CHEESE_SHAPE: dict[str, Any] = {
    "radius": 0.5,
    "angle_deg": 60.0,
    "height": 0.22,
    # spheres (x, y, z, r) [m]: tunnel through top and bottom, dents in top, +z side, curved side, bottom.
    "holes": [[0.32, 0.11, 0.0, 0.12], [0.4, 0.23, 0.13, 0.05], [0.355, 0.09, 0.205, 0.06],
              [0.483, 0.13, -0.129, 0.06], [0.16, -0.01, 0.0, 0.05]],
}
CHEESE_GENUS = 1
_CHEESE: dict[str, dict[str, Any]] = {
    # resolution: segments per full circle of arc and spheres, and TetWild settings.
    "coarse": {"circular_segments": 24, "tetwild": {"edge_length_fac": 0.1, "epsilon": 5e-3}},
    "coarse_alt": {"circular_segments": 32, "tetwild": {"edge_length_fac": 0.16, "epsilon": 7e-3}},
    "medium": {"circular_segments": 48, "tetwild": {"edge_length_fac": 0.045, "epsilon": 1.5e-3}},
    "medium_alt": {"circular_segments": 40, "tetwild": {"edge_length_fac": 0.05, "epsilon": 1.7e-3}},
    "fine": {"circular_segments": 96, "tetwild": {"edge_length_fac": 0.017, "epsilon": 5e-4}},
}


def _recipes() -> dict[str, dict[str, Recipe]]:
    """Every catalogue entry: name -> resolution -> Recipe."""
    recipes: dict[str, dict[str, Recipe]] = {
        "cheese": {res: Recipe("cheese", res, _build_cheese, {"shape": CHEESE_SHAPE, **p}, stored=True)
                   for res, p in _CHEESE.items()},
        "sphere": {res: Recipe("sphere", res, _build_sphere,
                               {"radius": SPHERE_RADIUS, "snap_subdivisions": 6, **p}, stored=True)
                   for res, p in _SPHERE.items()},
    }
    for name, (size, origin, divisions) in _STRUCTURED.items():
        recipes[name] = {res: Recipe(name, res, _build_structured,
                                     {"size": size, "origin": origin, "divisions": div})
                         for res, div in divisions.items()}
    return recipes


_RECIPES = _recipes()
SHIPPED = tuple((shape, res) for shape in ("cheese", "sphere") for res in ("coarse", "coarse_alt", "medium", "medium_alt"))
"""Catalogue entries committed under scenarios/meshes/: CI never runs TetWild, and since fTetWild does not give the
same mesh twice, these are the only TetWild meshes that are the same on every machine."""


def catalogue() -> dict[str, tuple[str, ...]]:
    """Catalogue mesh names -> their resolutions."""
    return {name: tuple(entries) for name, entries in _RECIPES.items()}


def recipe(name: str | None, resolution: str) -> Recipe:
    """The Recipe of a catalogue entry; MeshError on field `mesh.name` / `mesh.resolution` if unknown."""
    if name not in _RECIPES:
        raise MeshError("mesh.name", name, f"unknown catalogue mesh; choose one of {', '.join(_RECIPES)} "
                                           "or give mesh.path")
    if resolution not in _RECIPES[name]:
        raise MeshError("mesh.resolution", resolution,
                        f"unknown resolution of mesh {name!r}; choose one of {', '.join(_RECIPES[name])}")
    return _RECIPES[name][resolution]


def load_mesh(spec: MeshSpec, base_dir: Path | None = None) -> TetMesh:
    """The rest mesh a MeshSpec names, scaled by `spec.scale`.

    A path (relative ones resolve against base_dir, default the working directory) is read with meshio;
    a catalogue entry comes from the shipped files, the cache, or its generator (then cached).
    Raises MeshError naming `mesh.name`, `mesh.resolution`, `mesh.scale` or the file path.
    """
    if not (np.isfinite(spec.scale) and spec.scale > 0):
        raise MeshError("mesh.scale", spec.scale, "the scale must be a finite positive number")
    if spec.path:
        path = Path(spec.path).expanduser()
        if not path.is_absolute():
            path = (base_dir or Path.cwd()) / path
        mesh = read_mesh_file(path, name=spec.key)
    else:
        mesh = catalogue_mesh(recipe(spec.name, spec.resolution))
    return mesh if spec.scale == 1.0 else mesh.scaled(spec.scale)


def catalogue_mesh(entry: Recipe) -> TetMesh:
    """Build a structured entry, or load a stored one (shipped file, then cache), generating it if missing."""
    if not entry.stored:
        return _built_mesh(entry)
    for path in (shipped_path(entry), cache_path(entry)):
        arrays = _read_stored(path, entry.key)
        if arrays is not None:
            return make_mesh(*arrays, entry.label, source=str(path))
    return generate_and_store(entry, cache_path(entry))


# --- storage --------------------------------------------------------------------------------------------


def cache_dir() -> Path:
    """Folder of generated meshes: `$FRICTIONBENCH_CACHE/meshes` (default `~/.cache/frictionbench/meshes`)."""
    root = os.environ.get("FRICTIONBENCH_CACHE") or Path.home() / ".cache" / "frictionbench"
    return Path(root).expanduser() / "meshes"


def cache_path(entry: Recipe) -> Path:
    """Cache file of a stored catalogue entry: `<cache_dir>/<name>_<resolution>_<key>.npz`."""
    return cache_dir() / f"{entry.name}_{entry.resolution}_{entry.key}.npz"


def shipped_path(entry: Recipe) -> Path:
    """Committed file of a catalogue entry: `scenarios/meshes/<name>_<resolution>.npz` (may not exist)."""
    return SHIPPED_DIR / f"{entry.name}_{entry.resolution}.npz"


def _read_stored(path: Path, key: str) -> tuple[Array, Array] | None:
    """(X, tets) from a stored .npz whose recipe key matches; None if missing, unreadable or stale."""
    try:
        with np.load(path, allow_pickle=False) as data:
            if str(data["key"]) != key:
                return None
            return data["X"], data["tets"]
    except (OSError, KeyError, ValueError):
        return None


def _built_mesh(entry: Recipe) -> TetMesh:
    """Run a recipe and validate its output (fixing orientation); a failure names the catalogue entry."""
    try:
        return make_mesh(*entry.build(), entry.label, fix_orientation=True)
    except MeshError as error:
        raise MeshError(entry.label, error.value, f"the generator made an invalid mesh: {error.reason}. "
                        "For TetWild entries, generating again may succeed: fTetWild is not repeatable") from error


def generate_and_store(entry: Recipe, path: Path) -> TetMesh:
    """Run a recipe, validate (fixing orientation), and write the mesh atomically to `path` (.npz).

    The file holds X (float64), tets (int32), the recipe key and parameters, and provenance: library
    versions and generation time [s].
    """
    start = time.perf_counter()
    mesh = _built_mesh(entry)
    provenance = {"seconds": round(time.perf_counter() - start, 2),
                  **{lib: _version(lib) for lib in ("pytetwild", "manifold3d", "numpy")}}
    with atomic_open(path, "wb") as file:
        np.savez_compressed(file, X=mesh.X, tets=mesh.tets.astype(np.int32), key=entry.key,
                            params=json.dumps(entry.params, sort_keys=True), provenance=json.dumps(provenance))
    return mesh


def _version(distribution: str) -> str:
    """Installed version of a distribution, or `absent`."""
    try:
        return metadata.version(distribution)
    except metadata.PackageNotFoundError:
        return "absent"


def _main(argv: list[str] | None = None) -> None:
    """Build catalogue meshes (stored ones into the cache) or rewrite shipped files; print their sizes."""
    parser = argparse.ArgumentParser(prog="python -m frictionbench.scenarios.meshes", description=_main.__doc__)
    parser.add_argument("entries", nargs="*", metavar="NAME/RESOLUTION", help="catalogue entries to build")
    parser.add_argument("--ship", action="store_true",
                        help="regenerate the shipped files of the entries (default: every shipped entry)")
    args = parser.parse_args(argv)
    labels = args.entries or ([f"{name}/{res}" for name, res in SHIPPED] if args.ship else [])
    for label in labels:
        name, _, resolution = label.partition("/")
        try:
            entry = recipe(name, resolution)
        except MeshError as error:
            parser.error(str(error))
        start = time.perf_counter()
        mesh = generate_and_store(entry, shipped_path(entry)) if args.ship else catalogue_mesh(entry)
        print(f"{entry.label}: {mesh.n_tets} tets, {mesh.n_vertices} vertices, "
              f"bbox {np.round(np.ptp(mesh.X, axis=0), 4)} m, volume {mesh.volumes().sum():.6g} m^3, "
              f"{time.perf_counter() - start:.1f} s")


if __name__ == "__main__":
    _main()

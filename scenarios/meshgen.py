"""Mesh generators for the catalogue: structured boxes (pure numpy) and TetWild meshes of CSG surfaces.

Surface generators (`icosphere`, `cheese_surface`) return (V (v, 3) [m], F (f, 3) outward triangles);
volume generators (`structured_box`, `tetrahedralize`) return raw (X (n, 3) float64 [m], tets (m, 4)).
Validity is enforced afterwards by `scenarios.meshes.validate_mesh`. The world's up axis is +y.
manifold3d, pytetwild and pyvista are imported lazily: loading a shipped or cached mesh needs none of them.
"""

from __future__ import annotations

from collections.abc import Sequence
from itertools import permutations

import numpy as np

Array = np.ndarray

# Kuhn (Freudenthal) split of the unit cube into 6 tets. Cube corner c = i + 2 j + 4 k for the offset
# (i, j, k) in {0, 1}^3; each tet walks from corner 0 to corner 7 adding one axis at a time, in every order.
# This split is conforming on a regular grid: every hex face is cut along its diagonal from its lowest
# corner, which is the same diagonal for the two hexes sharing that face.
_KUHN_TETS = np.array(
    [[0, 1 << a, (1 << a) | (1 << b), 7] for a, b, _ in permutations(range(3))], dtype=np.int64
)


def structured_box(size: Sequence[float], divisions: Sequence[int], origin: Sequence[float]) -> tuple[Array, Array]:
    """A box split into nx * ny * nz equal hexes, each hex into 6 tets (Kuhn split).

    size: edge lengths (Lx, Ly, Lz) [m].
    divisions: hex counts (nx, ny, nz) along x, y, z.
    origin: position of the corner with the smallest coordinates [m].
    Returns X ((nx+1)(ny+1)(nz+1), 3) [m] and tets (6 nx ny nz, 4), positively oriented.
    """
    nx, ny, nz = (int(n) for n in divisions)
    axes = [o + np.linspace(0.0, s, n + 1) for o, s, n in zip(origin, size, (nx, ny, nz))]
    X = np.stack(np.meshgrid(*axes, indexing="ij"), axis=-1).reshape(-1, 3)

    def vertex_index(i: Array, j: Array, k: Array) -> Array:
        return (i * (ny + 1) + j) * (nz + 1) + k

    i, j, k = (a.ravel() for a in np.meshgrid(np.arange(nx), np.arange(ny), np.arange(nz), indexing="ij"))
    corners = np.arange(8)
    hex_vertices = vertex_index(
        i[:, None] + (corners & 1), j[:, None] + ((corners >> 1) & 1), k[:, None] + ((corners >> 2) & 1)
    )  # (hexes, 8)
    tets = hex_vertices[:, _KUHN_TETS].reshape(-1, 4)
    return X, _orient_positive(X, tets)


def signed_volumes(X: Array, tets: Array) -> Array:
    """Signed volume of each tet, (m,) [m^3]: det(X1 - X0, X2 - X0, X3 - X0) / 6.

    X: (n, 3) positions [m]. tets: (m, 4) vertex indices.
    """
    x0 = X[tets[:, 0]]
    e1, e2, e3 = (X[tets[:, i]] - x0 for i in (1, 2, 3))
    return np.einsum("ij,ij->i", np.cross(e1, e2), e3) / 6.0


def _orient_positive(X: Array, tets: Array) -> Array:
    """Swap vertices 1 and 2 of every tet with negative signed volume; tets (m, 4) -> (m, 4)."""
    negative = signed_volumes(X, tets) < 0
    tets = tets.copy()
    tets[negative, 1], tets[negative, 2] = tets[negative, 2], tets[negative, 1].copy()
    return tets


_ICOSAHEDRON_FACES = np.array(
    [[0, 11, 5], [0, 5, 1], [0, 1, 7], [0, 7, 10], [0, 10, 11], [1, 5, 9], [5, 11, 4], [11, 10, 2],
     [10, 7, 6], [7, 1, 8], [3, 9, 4], [3, 4, 2], [3, 2, 6], [3, 6, 8], [3, 8, 9], [4, 9, 5],
     [2, 4, 11], [6, 2, 10], [8, 6, 7], [9, 8, 1]],
    dtype=np.int64,
)  # outward (counter-clockwise seen from outside)


def icosphere(radius: float, subdivisions: int, rotation_deg: Sequence[float] = (0.0, 0.0, 0.0)) -> tuple[Array, Array]:
    """Icosphere surface: the icosahedron, each triangle split into 4 `subdivisions` times, on the sphere.

    radius: sphere radius [m]; centre at the origin.
    subdivisions: number of 1-to-4 refinements (20 * 4^s triangles).
    rotation_deg: XYZ Euler angles [degrees] rotating the tessellation (the sphere is unchanged).
    Returns vertices V (v, 3) [m] and outward triangles F (f, 3).
    """
    from scipy.spatial.transform import Rotation

    t = (1.0 + np.sqrt(5.0)) / 2.0
    V = np.array(
        [[-1, t, 0], [1, t, 0], [-1, -t, 0], [1, -t, 0], [0, -1, t], [0, 1, t],
         [0, -1, -t], [0, 1, -t], [t, 0, -1], [t, 0, 1], [-t, 0, -1], [-t, 0, 1]],
        dtype=np.float64,
    )
    F = _ICOSAHEDRON_FACES
    for _ in range(subdivisions):
        V, F = _split_triangles(V, F)
    V = V / np.linalg.norm(V, axis=1, keepdims=True)
    V = Rotation.from_euler("xyz", rotation_deg, degrees=True).apply(V)
    return radius * V, F


def _split_triangles(V: Array, F: Array) -> tuple[Array, Array]:
    """Split each triangle of F (f, 3) into 4 at its edge midpoints; shared edges share their midpoint."""
    edges = np.sort(np.concatenate([F[:, [0, 1]], F[:, [1, 2]], F[:, [2, 0]]]), axis=1)
    unique, inverse = np.unique(edges, axis=0, return_inverse=True)
    mid = len(V) + inverse.reshape(3, -1)  # midpoint of edges (01, 12, 20) of each triangle
    a, b, c = F.T
    ab, bc, ca = mid
    F = np.concatenate([np.stack(t, axis=1) for t in ((a, ab, ca), (b, bc, ab), (c, ca, bc), (ab, bc, ca))])
    return np.concatenate([V, V[unique].mean(axis=1)]), F


def cheese_surface(
    radius: float,
    angle_deg: float,
    height: float,
    holes: Sequence[Sequence[float]],
    circular_segments: int,
) -> tuple[Array, Array]:
    """Surface of a cheese wedge: a circular-sector prism minus spheres (manifold3d CSG).

    The sector's apex edge is the y axis, the wedge spans `angle_deg` symmetrically about +x, and its
    bottom face lies at y = 0 (top at y = height).
    radius: sector radius [m]. angle_deg: sector angle [degrees]. height: prism height along y [m].
    holes: spheres (x, y, z, r) [m] to subtract.
    circular_segments: segments of the arc and of each sphere's circumference.
    Returns vertices V (v, 3) [m] and outward triangles F (f, 3).
    """
    import manifold3d

    half = np.radians(angle_deg) / 2.0
    arc = np.linspace(-half, half, circular_segments + 1)
    # Sector in the (u, v) plane, extruded along w; rotating -90 deg about x maps (u, v, w) -> (u, w, -v),
    # so the sector's +v side becomes -z. The wedge is symmetric about the x axis, so this is immaterial.
    sector = np.vstack([[0.0, 0.0], np.column_stack([radius * np.cos(arc), radius * np.sin(arc)])])
    body = manifold3d.Manifold.extrude(manifold3d.CrossSection([sector]), height).rotate([-90.0, 0.0, 0.0])
    for x, y, z, r in holes:
        body = body - manifold3d.Manifold.sphere(r, circular_segments).translate([x, y, z])
    mesh = body.to_mesh64()
    V = np.array(mesh.vert_properties[:, :3], dtype=np.float64, order="C")
    F = np.array(mesh.tri_verts, dtype=np.int64, order="C")
    return V, F


def tetrahedralize(
    V: Array,
    F: Array,
    edge_length_fac: float,
    epsilon: float,
    stop_energy: float = 10.0,
    num_opt_iter: int = 80,
    num_threads: int = 0,
) -> tuple[Array, Array]:
    """Tetrahedralise a closed surface with fTetWild (pytetwild).

    fTetWild is not repeatable: the same input and parameters give slightly different meshes from run to
    run, whatever the thread count (wildmeshing/fTetWild issue #72). Store the result; do not regenerate it.

    V (v, 3) [m], F (f, 3): the input surface.
    edge_length_fac: target edge length as a fraction of the surface's bounding-box diagonal [-].
    epsilon: envelope: the output surface stays within epsilon * bbox diagonal of the input [-].
    stop_energy, num_opt_iter: fTetWild's optimisation stopping criteria (AMIPS energy, iteration cap).
    num_threads: worker threads, 0 for all cores.
    Returns X (n, 3) [m] and tets (m, 4); fTetWild's tets come negatively oriented, the caller fixes that.
    """
    import pytetwild

    X, tets = pytetwild.tetrahedralize(
        np.array(V, dtype=np.float64, order="C"),
        np.array(F, dtype=np.int32, order="C"),
        edge_length_fac=edge_length_fac,
        epsilon=epsilon,
        stop_energy=stop_energy,
        num_opt_iter=num_opt_iter,
        num_threads=num_threads,
        quiet=True,
    )
    return np.asarray(X, dtype=np.float64), np.asarray(tets, dtype=np.int64)


def snap_to_surface(
    X: Array, tets: Array, boundary: Array, V: Array, F: Array, min_volume_ratio: float = 0.25
) -> Array:
    """Move boundary vertices onto their closest points on the surface (V, F) without spoiling any tet.

    TetWild's surface lies within its envelope of the input, not on it: a flat face comes out a few
    millimetres uneven. Snapping makes flat faces flat again (a body resting on its bottom face touches the
    plane everywhere). A vertex stays put when moving it with its neighbours would leave a tet with less
    than `min_volume_ratio` of its volume.
    X (n, 3) [m], tets (m, 4) positively oriented, boundary (s,) vertex indices, V (v, 3) [m], F (f, 3).
    Returns the new positions (n, 3) [m].
    """
    import pyvista

    _, closest = pyvista.PolyData.from_regular_faces(V, F).find_closest_cell(
        X[boundary], return_closest_point=True
    )
    target = X.copy()
    target[boundary] = closest
    moved = np.zeros(len(X), dtype=bool)
    moved[boundary] = True
    floor = min_volume_ratio * signed_volumes(X, tets)
    while True:  # each round pins at least one vertex, so this ends (at worst with nothing moved)
        snapped = np.where(moved[:, None], target, X)
        spoiled = signed_volumes(snapped, tets) < floor
        if not spoiled.any():
            return snapped
        moved[tets[spoiled].ravel()] = False

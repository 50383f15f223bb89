"""The 3D viewer of one scenario: its runs side by side in one plotly scene (Mesh3d), animated with play/pause
and a time slider, each surface coloured by the pointwise distance to the first run (the ground truth, else the
reference), the camera framed on the bodies and the plane cropped around their paths.

Size: each run adds 4 float32 values (x, y, z, distance) per shown vertex per frame, about 21 bytes in the page
(base64). Surfaces are decimated by vertex clustering in the rest shape to at most `max_triangles` triangles and
frames subsampled to at most `max_frames`; experiments/figures.md states the page's budget.
"""

from __future__ import annotations

from collections.abc import Sequence
from dataclasses import dataclass

import numpy as np

from frictionbench.reports.interactive import text, typed_array
from frictionbench.scenarios.meshes import bbox_diagonal
from frictionbench.scenarios.spec import Plane
from frictionbench.solvers.trajectory import Trajectory

#: Colours of the distance: pale at zero, red at the largest distance shown.
DISTANCE_COLORSCALE = [[0.0, "#dfe7f2"], [0.35, "#9ec5e8"], [0.7, "#f4a259"], [1.0, "#b2182b"]]


@dataclass(frozen=True)
class ViewerBudget:
    """Limits that keep the page small: frames per scenario and triangles per surface."""

    max_frames: int = 24
    max_triangles: int = 1000

    def __post_init__(self) -> None:
        if self.max_frames < 2:
            raise ValueError(f"viewer max_frames = {self.max_frames}: expected at least 2")
        if self.max_triangles < 4:
            raise ValueError(f"viewer max_triangles = {self.max_triangles}: expected at least 4")


#: The budget the report uses unless told otherwise.
DEFAULT_BUDGET = ViewerBudget()


def decimate_surface(X: np.ndarray, surface: np.ndarray, max_triangles: int) -> tuple[np.ndarray, np.ndarray]:
    """A coarser surface for display: (vertices (m,) indices into X, triangles (k, 3) indices into vertices).

    Vertex clustering in the rest shape X (n, 3) [m]: the surface vertices are binned on a grid, each bin kept as
    one of its vertices (so deformed frames are looked up, not interpolated), triangles whose corners fall in
    fewer than three bins dropped. The grid is refined from coarse until the next refinement would exceed
    max_triangles; a surface already within the budget is kept whole.
    """
    surface = np.asarray(surface, dtype=np.int64)
    used = np.unique(surface)
    if len(surface) <= max_triangles:
        return used, np.searchsorted(used, surface)
    pts = np.asarray(X, dtype=float)[used]
    lo, size = pts.min(axis=0), max(bbox_diagonal(pts), 1e-12)
    tri = np.searchsorted(used, surface)
    best = (np.arange(0), np.zeros((0, 3), dtype=np.int64))
    for cells in range(2, 513):
        cell = np.floor((pts - lo) / (size / cells)).astype(np.int64)
        _, first, bins = np.unique(cell, axis=0, return_index=True, return_inverse=True)
        t = bins.ravel()[tri]
        t = t[(t[:, 0] != t[:, 1]) & (t[:, 1] != t[:, 2]) & (t[:, 0] != t[:, 2])]
        t = np.unique(t, axis=0)
        if len(t) > max_triangles:
            break
        keep = np.unique(t)
        best = (used[first[keep]], np.searchsorted(keep, t))
    return best


def _frame_indices(t: np.ndarray, wanted: np.ndarray) -> np.ndarray:
    """For each wanted time, the index of the nearest frame time in t (F,)."""
    return np.abs(np.asarray(t, dtype=float)[None, :] - wanted[:, None]).argmin(axis=1)


def _unit(v: np.ndarray) -> np.ndarray:
    return v / max(float(np.linalg.norm(v)), 1e-300)


def viewer_figure(runs: Sequence[tuple[str, Trajectory]], plane: Plane | None = None,
                  budget: ViewerBudget = DEFAULT_BUDGET, distance_to: str = "truth") -> tuple[dict | None, list[str]]:
    """The animated viewer of a scenario's runs, and notes on the runs it could not show.

    runs: (label, trajectory) pairs, the first the one distances are measured against (the truth, else the
    reference); runs on another mesh (another vertex count or rest shape) or with non-finite positions in the
    shown frames are left out with a note. distance_to names the first run in the colour bar's title. The frames
    shown are the first run's, subsampled to budget.max_frames; each other run shows its nearest frame in time.
    The figure is None when not even the first run can be shown.
    """
    base_label, base = runs[0]
    notes: list[str] = []
    idx = np.unique(np.round(np.linspace(0, base.n_frames - 1, min(base.n_frames, budget.max_frames))).astype(int))
    times = np.asarray(base.t, dtype=float)[idx]
    verts, tris = decimate_surface(base.X, base.surface, budget.max_triangles)
    shown: list[tuple[str, np.ndarray]] = []
    for label, traj in runs:
        if traj.X.shape != base.X.shape or not np.allclose(traj.X, base.X):
            notes.append(f"{label}: not shown (another mesh than {base_label}'s)")
            continue
        x = np.asarray(traj.x, dtype=float)[_frame_indices(traj.t, times)][:, verts]  # (F, m, 3)
        if not np.isfinite(x).all():
            notes.append(f"{label}: not shown (non-finite positions)")
            continue
        shown.append((label, x))
    if not shown or shown[0][0] != base_label:
        return None, notes
    L = bbox_diagonal(base.X)
    distance = [np.linalg.norm(x - shown[0][1], axis=-1) / L for _, x in shown]  # (F, m) each
    top = max(float(max(d.max() for d in distance)), 1e-12)

    n = _unit(np.asarray(plane.normal if plane is not None else (0.0, 1.0, 0.0), dtype=float))
    path = shown[0][1].mean(axis=1)  # centre of the first run's shown vertices per frame
    travel = (path[-1] - path[0]) - ((path[-1] - path[0]) @ n) * n
    along = _unit(travel) if np.linalg.norm(travel) > 1e-9 * L else _unit(np.cross(n, [0.0, 0.0, 1.0])
                                                                          if abs(n[2]) < 0.9 else [1.0, 0.0, 0.0])
    side = _unit(np.cross(n, along))
    width = max(float(np.ptp(np.concatenate([x.reshape(-1, 3) for _, x in shown]) @ side)), 1e-6 * L)
    offsets = [(r - 0.5 * (len(shown) - 1)) * 1.3 * width * side for r in range(len(shown))]
    placed = [x + o for (_, x), o in zip(shown, offsets)]
    everything = np.concatenate([p.reshape(-1, 3) for p in placed])
    pad = 0.1 * bbox_diagonal(everything)
    lo, hi = everything.min(axis=0) - pad, everything.max(axis=0) + pad

    data: list[dict[str, object]] = []
    if plane is not None:
        d = plane.offset / max(float(np.linalg.norm(plane.normal)), 1e-300)
        a, b = everything @ along, everything @ side
        corners = [d * n + u * along + v * side for u, v in ((a.min() - pad, b.min() - pad), (a.max() + pad,
                   b.min() - pad), (a.max() + pad, b.max() + pad), (a.min() - pad, b.max() + pad))]
        quad = np.array(corners)
        lo, hi = np.minimum(lo, quad.min(axis=0)), np.maximum(hi, quad.max(axis=0))
        data.append({"type": "mesh3d", "name": "plane", "x": quad[:, 0].tolist(), "y": quad[:, 1].tolist(),
                     "z": quad[:, 2].tolist(), "i": [0, 0], "j": [1, 2], "k": [2, 3], "color": "#9a9a9a",
                     "opacity": 0.35, "hoverinfo": "skip", "showscale": False})
    first_mesh = len(data)
    faces = {"i": typed_array(tris[:, 0], "i4"), "j": typed_array(tris[:, 1], "i4"),
             "k": typed_array(tris[:, 2], "i4")}
    eye = 1.5 * _unit(0.85 * n + 0.6 * side - 0.25 * along)
    light = dict(zip("xyz", (1e5 * _unit(eye + n)).tolist()))  # from above, behind the camera
    colorbar = {"title": {"text": text(f"distance to {distance_to} / L")}, "len": 0.7}
    for r, ((label, _), p, dist) in enumerate(zip(shown, placed, distance)):
        data.append({"type": "mesh3d", "name": text(label), **faces, **_coords(p[0], dist[0]),
                     "colorscale": DISTANCE_COLORSCALE, "cmin": 0.0, "cmax": top, "showscale": r == 1 or
                     len(shown) == 1, "colorbar": colorbar, "flatshading": True,
                     "lighting": {"ambient": 0.7, "diffuse": 0.5, "specular": 0.05}, "lightposition": light,
                     "hovertemplate": f"{text(label)}<br>distance / L = %{{intensity:.3g}}<extra></extra>"})
    tops = [p.reshape(-1, 3)[np.argmax(p.reshape(-1, 3) @ n)] + 0.08 * width * n for p in placed]
    data.append({"type": "scatter3d", "mode": "text", "x": [t[0] for t in tops], "y": [t[1] for t in tops],
                 "z": [t[2] for t in tops], "text": [text(label) for label, _ in shown], "hoverinfo": "skip",
                 "showlegend": False, "textfont": {"size": 12}})
    names = [f"{t:.6g}" for t in times]
    frames = [{"name": name, "traces": list(range(first_mesh, first_mesh + len(shown))),
               "data": [_coords(p[k], dist[k]) for p, dist in zip(placed, distance)]}
              for k, name in enumerate(names)]
    axis = {"visible": False, "showbackground": False}
    scene = {"aspectmode": "data", "camera": {"eye": dict(zip("xyz", eye.tolist())),
                                              "up": dict(zip("xyz", n.tolist()))},
             **{f"{c}axis": {**axis, "range": [float(lo[i]), float(hi[i])]} for i, c in enumerate("xyz")}}
    still = {"mode": "immediate", "frame": {"duration": 0, "redraw": True}, "transition": {"duration": 0}}
    layout = {"scene": scene, "margin": {"l": 0, "r": 0, "t": 10, "b": 0}, "showlegend": False,
              "updatemenus": [{"type": "buttons", "direction": "left", "showactive": False, "x": 0.0, "y": 0.0,
                               "xanchor": "left", "yanchor": "top", "pad": {"t": 45, "r": 10},
                               "buttons": [
                                   {"label": "Play", "method": "animate",
                                    "args": [None, {"frame": {"duration": 150, "redraw": True},
                                                    "fromcurrent": True, "transition": {"duration": 0}}]},
                                   {"label": "Pause", "method": "animate", "args": [[None], still]}]}],
              "sliders": [{"active": 0, "x": 0.12, "len": 0.88, "y": 0.0, "yanchor": "top", "pad": {"t": 35},
                           "currentvalue": {"prefix": "t = ", "suffix": " s", "xanchor": "right"},
                           "steps": [{"label": f"{t:.3g}", "method": "animate", "args": [[name], still]}
                                     for t, name in zip(times, names)]}]}
    return {"data": data, "layout": layout, "frames": frames}, notes


def _coords(x: np.ndarray, distance: np.ndarray) -> dict[str, object]:
    """Mesh3d positions (m, 3) [m] and intensity (m,) as typed arrays."""
    return {"x": typed_array(x[:, 0]), "y": typed_array(x[:, 1]), "z": typed_array(x[:, 2]),
            "intensity": typed_array(distance)}

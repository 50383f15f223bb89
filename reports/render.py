"""Pictures of a body's surface at one frame, with the ground plane, as PNG bytes.

Two renderers: `vtk` (pyvista off-screen) and `matplotlib` (a Poly3DCollection of the surface triangles, used
where VTK cannot open an off-screen OpenGL context). `select_renderer` probes VTK once, in a child process (a VTK
that finds no OpenGL at all may abort the process that asks), and says which one made the pictures.

Without a display, VTK (9.4 and newer wheels) falls back from X to EGL and then OSMesa. On Debian 12 the EGL
path needs `libegl1 libegl-mesa0 libgl1-mesa-dri` (Mesa's llvmpipe renders on the CPU).
"""

from __future__ import annotations

import functools
import io
import json
import os
import subprocess
import sys
from dataclasses import dataclass

import numpy as np

from scenarios.model import Plane

#: Default picture size [pixels] (width, height).
SIZE: tuple[int, int] = (400, 300)
#: Direction from the focal point to the camera (y is up), so a body on a horizontal plane is seen from above.
VIEW_DIRECTION = np.array([1.0, 0.8, 1.6]) / np.linalg.norm([1.0, 0.8, 1.6])
UP = (0.0, 1.0, 0.0)

_PROBE = """
import json, os, sys
if not os.environ.get("DISPLAY") and not os.environ.get("WAYLAND_DISPLAY") and len(sys.argv) > 1:
    os.environ["VTK_DEFAULT_OPENGL_WINDOW"] = sys.argv[1]
import pyvista
plotter = pyvista.Plotter(off_screen=True, window_size=(64, 48))
plotter.add_mesh(pyvista.Sphere())
image = plotter.screenshot(None, return_img=True)
gl = [l.split(":", 1)[1].strip() for l in plotter.ren_win.ReportCapabilities().splitlines()
      if l.startswith("OpenGL renderer string")]
window = type(plotter.ren_win).__name__
plotter.close()
print(json.dumps({"window": window, "gl": gl[0] if gl else "", "drawn": bool(image.std() > 0)}))
"""


@dataclass(frozen=True)
class Renderer:
    """Which renderer makes the pictures: name `vtk` or `matplotlib`, and in words what it runs on."""

    name: str
    detail: str


def _probe_vtk(window: str | None) -> dict | None:
    """Render a sphere off-screen in a child process; its report (window class, OpenGL renderer) or None."""
    try:
        done = subprocess.run([sys.executable, "-c", _PROBE, *([window] if window else [])],
                              capture_output=True, text=True, timeout=180, check=False)
    except (OSError, subprocess.SubprocessError):
        return None
    if done.returncode != 0 or not done.stdout.strip():
        return None
    report = json.loads(done.stdout.strip().splitlines()[-1])
    return report if report["drawn"] else None


@functools.cache
def select_renderer(preferred: str = "auto") -> Renderer:
    """The renderer to use: `matplotlib` when preferred, else `vtk` if VTK can render off-screen here.

    Without a display the probe tries EGL first, then VTK's own fallback order; the window class that worked is
    set as VTK_DEFAULT_OPENGL_WINDOW in this process, so VTK does not try (and warn about) X first.
    """
    if preferred not in ("auto", "vtk", "matplotlib"):
        raise ValueError(f"renderer {preferred!r}: expected auto, vtk or matplotlib")
    if preferred != "matplotlib":
        headless = not os.environ.get("DISPLAY") and not os.environ.get("WAYLAND_DISPLAY")
        for window in (["vtkEGLRenderWindow", None] if headless else [None]):
            report = _probe_vtk(window)
            if report is not None:
                if headless:
                    os.environ.setdefault("VTK_DEFAULT_OPENGL_WINDOW", report["window"])
                return Renderer("vtk", f"VTK off-screen ({report['window']}, OpenGL: {report['gl']})")
        if preferred == "vtk":
            raise RuntimeError("VTK cannot open an off-screen OpenGL context here (see reports.render)")
    import matplotlib

    return Renderer("matplotlib", f"matplotlib {matplotlib.__version__} (Agg, Poly3DCollection)")


def view_bounds(frames: np.ndarray, margin: float = 0.1) -> np.ndarray:
    """Bounds (2, 3) [m] (min, max corners) of the finite points of frames (..., 3), grown by margin x diagonal."""
    pts = np.asarray(frames, dtype=float).reshape(-1, 3)
    pts = pts[np.isfinite(pts).all(axis=1)]
    if pts.size == 0:
        return np.array([[-1.0] * 3, [1.0] * 3])
    lo, hi = pts.min(axis=0), pts.max(axis=0)
    pad = margin * max(float(np.linalg.norm(hi - lo)), 1e-9)
    return np.stack([lo - pad, hi + pad])


def _plane_quad(plane: Plane, bounds: np.ndarray) -> np.ndarray:
    """Corners (4, 3) of a square of the plane n . x = d centred under the bounds' centre, side = diagonal."""
    n = np.asarray(plane.normal, dtype=float)
    n, d = n / np.linalg.norm(n), plane.offset / np.linalg.norm(n)
    centre = bounds.mean(axis=0)
    centre = centre - (centre @ n - d) * n
    a = np.cross(n, [1.0, 0.0, 0.0] if abs(n[0]) < 0.9 else [0.0, 0.0, 1.0])
    a /= np.linalg.norm(a)
    b = np.cross(n, a)
    h = 0.5 * float(np.linalg.norm(bounds[1] - bounds[0]))
    return np.array([centre + h * (sa * a + sb * b) for sa, sb in ((-1, -1), (1, -1), (1, 1), (-1, 1))])


def render_surface(x: np.ndarray, surface: np.ndarray, *, bounds: np.ndarray, plane: Plane | None = None,
                   renderer: Renderer, color: str = "#4a7fb5", size: tuple[int, int] = SIZE) -> bytes:
    """PNG of the surface triangles (k, 3) of positions x (n, 3) [m], and of the plane if given.

    bounds (2, 3) fixes the camera (looking along -VIEW_DIRECTION at the bounds' centre, fitted to them), so
    pictures rendered with the same bounds are comparable side by side. x must be finite.
    """
    if renderer.name == "vtk":
        return _render_vtk(x, surface, bounds, plane, color, size)
    return _render_matplotlib(x, surface, bounds, plane, color, size)


def _render_vtk(x: np.ndarray, surface: np.ndarray, bounds: np.ndarray, plane: Plane | None, color: str,
                size: tuple[int, int]) -> bytes:
    """`render_surface` with pyvista off-screen."""
    import pyvista

    faces = np.hstack([np.full((surface.shape[0], 1), 3), surface]).ravel()
    plotter = pyvista.Plotter(off_screen=True, window_size=size)
    try:
        plotter.set_background("white")
        plotter.add_mesh(pyvista.PolyData(np.asarray(x, dtype=float), faces), color=color, smooth_shading=False,
                         show_edges=True, edge_color="#303030", line_width=0.5)
        if plane is not None:
            quad = _plane_quad(plane, bounds)
            plotter.add_mesh(pyvista.PolyData(quad, np.array([4, 0, 1, 2, 3])), color="#b8b8b8", opacity=0.6)
        focal = bounds.mean(axis=0)
        plotter.camera_position = [tuple(focal + VIEW_DIRECTION), tuple(focal), UP]
        plotter.reset_camera(bounds=tuple(np.stack([bounds[0], bounds[1]], axis=1).ravel()))
        plotter.camera.zoom(1.4)  # reset_camera fits the bounds' bounding sphere, which leaves wide margins
        buf = io.BytesIO()
        plotter.screenshot(buf)
    finally:
        plotter.close()
    return buf.getvalue()


def _render_matplotlib(x: np.ndarray, surface: np.ndarray, bounds: np.ndarray, plane: Plane | None, color: str,
                       size: tuple[int, int]) -> bytes:
    """`render_surface` with matplotlib: flat-shaded triangles (|normal . light|), equal axes, no box."""
    from matplotlib.colors import to_rgb
    from matplotlib.figure import Figure
    from mpl_toolkits.mplot3d.art3d import Poly3DCollection

    from reports.plots import figure_png

    dpi = 100
    fig = Figure(figsize=(size[0] / dpi, size[1] / dpi))
    ax = fig.add_axes((0.0, 0.0, 1.0, 1.0), projection="3d")
    tri = np.asarray(x, dtype=float)[surface]
    normals = np.cross(tri[:, 1] - tri[:, 0], tri[:, 2] - tri[:, 0])
    normals /= np.maximum(np.linalg.norm(normals, axis=1, keepdims=True), 1e-300)
    light = VIEW_DIRECTION + np.array(UP)  # from above and behind the camera
    shade = 0.35 + 0.65 * np.abs(normals @ (light / np.linalg.norm(light)))
    ax.add_collection3d(Poly3DCollection(tri, facecolors=shade[:, None] * np.array(to_rgb(color)),
                                         edgecolors="#303030", linewidths=0.2))
    if plane is not None:
        ax.add_collection3d(Poly3DCollection([_plane_quad(plane, bounds)], facecolors="#b8b8b8", alpha=0.5))
    centre, half = bounds.mean(axis=0), 0.5 * float(np.max(bounds[1] - bounds[0]))
    ax.set_xlim(centre[0] - half, centre[0] + half)
    ax.set_ylim(centre[1] - half, centre[1] + half)
    ax.set_zlim(centre[2] - half, centre[2] + half)
    ax.set_box_aspect((1.0, 1.0, 1.0), zoom=1.4)
    # With y vertical, the camera azimuth is measured in the z-x plane.
    elev = np.degrees(np.arcsin(VIEW_DIRECTION[1]))
    azim = np.degrees(np.arctan2(VIEW_DIRECTION[0], VIEW_DIRECTION[2]))
    ax.view_init(elev=elev, azim=azim, vertical_axis="y")
    ax.set_axis_off()
    return figure_png(fig, dpi=dpi)

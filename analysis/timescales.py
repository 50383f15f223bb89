"""The time scales of a suite's scenes and how well each run's step resolves them (docs/metrics.md, "Time scales").

The physics is `solvers.physics.timescales`; here it is computed once per distinct scene: the elastic spectrum
(omega_max, omega_1) once per mesh and material, the share of unresolved modes once per mesh, material and
effective step, the contact and friction figures per scenario (they need its contact law, plane and patch).
`SceneTimescales` is that cache: row building (`analysis.rows.collect_rows`) gives every row the scene's columns
(`SCENE_COLUMNS`) and its step's resolution (`RESOLUTION_COLUMNS`), and `timescale_table` is what
`frictionbench timescales` prints for a suite.

The contact patch is that of a run's last frame (`touching_area`): the reference run's in row building, where the
body has come to rest or slides on the plane; without a run, the whole-body contact and friction figures are nan.
Material damping is left out of the model built here: no time scale below depends on it.
"""

from __future__ import annotations

import math
from collections.abc import Callable, Sequence
from dataclasses import dataclass, replace

import numpy as np

from frictionbench.scenarios.meshes import TetMesh, load_mesh
from frictionbench.scenarios.spec import Scenario
from frictionbench.solvers.build import build_model
from frictionbench.solvers.integrators import get_integrator
from frictionbench.solvers.model import Model
from frictionbench.solvers.physics.timescales import (TimeScales, elastic_scales, time_scales, touching_area,
                                                      unresolved_share)
from frictionbench.solvers.trajectory import Trajectory

#: The scene's columns: `ts_<field>` for each field of `solvers.physics.timescales.TimeScales`.
SCENE_COLUMNS: tuple[str, ...] = tuple(f"ts_{name}" for name in TimeScales.__dataclass_fields__)
#: A run's columns: its effective step, omega h_eff of each time scale (`TimeScales.resolution`), and the share
#: of the elastic modes its step does not resolve.
RESOLUTION_COLUMNS: tuple[str, ...] = ("h_eff", "res_omega_max", "res_omega_1", "res_contact", "res_contact_vertex",
                                       "res_friction", "res_friction_vertex", "res_unresolved_share")


def effective_step(integrator: str, dt: float) -> float:
    """h_eff = beta dt [s] of a run at the constant step dt [s] with the named integrator, after its start (BDF2:
    2/3 dt; backward Euler: dt)."""
    return get_integrator(integrator).coefficients(dt, dt).beta * dt


@dataclass(frozen=True)
class Scene:
    """One scene's model (undamped: `SceneTimescales.model`), its time scales and the key of its mesh and
    material (what the elastic figures depend on)."""

    model: Model
    scales: TimeScales
    elastic_key: tuple


class SceneTimescales:
    """The time scales of scenes and the resolution of steps, each computed once (module docstring)."""

    def __init__(self) -> None:
        self._elastic: dict[tuple, tuple[float, float]] = {}
        self._shares: dict[tuple, float] = {}
        self._models: dict[tuple, Model] = {}

    def model(self, scenario: Scenario, mesh: TetMesh) -> Model:
        """The scenario's model on `mesh`, without material damping (built once per scenario and mesh)."""
        key = (scenario, mesh.name, mesh.digest())
        if key not in self._models:
            undamped = replace(scenario.material, viscosity=None, damping_ratio=None)
            self._models[key] = build_model(replace(scenario, material=undamped), mesh)
        return self._models[key]

    def scene(self, scenario: Scenario, mesh: TetMesh, frame: np.ndarray | None = None) -> Scene:
        """The time scales of `scenario` on `mesh` with the contact patch of the positions `frame` (n, 3) [m]
        (None: no patch, the whole-body contact and friction figures nan)."""
        model = self.model(scenario, mesh)
        m = scenario.material
        key = (mesh.digest(), m.youngs_modulus, m.poisson_ratio, m.density)
        if key not in self._elastic:
            self._elastic[key] = elastic_scales(model)
        area = touching_area(model, frame) if frame is not None else math.nan
        return Scene(model, time_scales(model, area, self._elastic[key]), key)

    def scene_of_run(self, scenario: Scenario, run: Trajectory) -> Scene:
        """The scene a run ran: `scene` on the run's own mesh, with the patch of its last frame."""
        mesh = TetMesh(X=run.X, tets=run.tets, surface=run.surface, name=scenario.mesh.key)
        return self.scene(scenario, mesh, run.x[-1])

    def share(self, scene: Scene, h_eff: float) -> float:
        """The share of the scene's elastic modes with omega h_eff > 1 (`unresolved_share`), once per step."""
        key = (*scene.elastic_key, h_eff)
        if key not in self._shares:
            self._shares[key] = unresolved_share(scene.model, h_eff)
        return self._shares[key]

    def resolution(self, scene: Scene, integrator: str, dt: float) -> dict[str, float]:
        """The `RESOLUTION_COLUMNS` of a run at the constant step dt [s] with `integrator`."""
        h = effective_step(integrator, dt)
        res = scene.scales.resolution(h)
        return {"h_eff": h, **{f"res_{k}": v for k, v in res.items()}, "res_unresolved_share": self.share(scene, h)}


def scene_columns(scene: Scene) -> dict[str, float]:
    """The `SCENE_COLUMNS` of a scene."""
    return {f"ts_{k}": v for k, v in scene.scales.as_dict().items()}


def timescale_table(scenarios: Sequence[Scenario], dts: Callable[[Scenario], Sequence[float]],
                    integrator: Callable[[Scenario], str],
                    frame: Callable[[Scenario], np.ndarray | None] = lambda sc: None,
                    cache: SceneTimescales | None = None) -> list[dict]:
    """One row per scenario and step: its mesh, the scene's columns and the step's resolution columns, for the
    steps dts(scenario) [s] (e.g. a truth ladder's levels) with integrator(scenario); frame(scenario) gives the
    positions whose contact patch counts (None: none)."""
    cache = cache or SceneTimescales()
    meshes: dict = {}
    rows = []
    for sc in scenarios:
        if sc.mesh not in meshes:
            meshes[sc.mesh] = load_mesh(sc.mesh)
        scene = cache.scene(sc, meshes[sc.mesh], frame(sc))
        for level, dt in enumerate(dts(sc)):
            rows.append({"scenario": sc.name, "mesh": sc.mesh.key, "n_vertices": scene.model.n, "level": level,
                         "dt": dt} | scene_columns(scene) | cache.resolution(scene, integrator(sc), dt))
    return rows

"""What the reduced solvers (`solvers.reduced.pod`: `pod`, `affine`; `solvers.licrom.plugin`: `licrom`) share under
the solver contract (`solvers.contract`): `ReducedPlugin`, whose `setup(model)` builds a `ReducedSolver` (untimed)
on the basis a subclass gives (`basis_of`) with its resolved cubature, and the trained artefacts' helpers.

Where a solver needs the suite's training data, its `prepare(shape, trajectories, out_dir, suite)` trains once per
(mesh shape, settings), caches the artefact under `out_dir/<key>/` (`artefact_key`; the run's output folder), and
returns the run parameters `shape` and the artefact's path. Cubature parameter: `all` (every tet, weight 1),
`uniform:N` or `optimized:N` (An, Kim & James on the training states, `cubature_artefact`; on a mesh other than the
training mesh LiCROM's falls back to uniform:N, as LiCROM does for remeshing, and the run's stats say so, while
POD's is selected again on that mesh from the same latent training states, `cubature_on_mesh`).
"""

from __future__ import annotations

import hashlib
import json
from abc import abstractmethod
from collections.abc import Callable
from pathlib import Path

import numpy as np

from frictionbench.scenarios.atomic import atomic_open, write_json_atomic
from frictionbench.solvers.contract import Solver, check_count
from frictionbench.solvers.integrators import INTEGRATORS
from frictionbench.solvers.model import Model, State
from frictionbench.solvers.reduced.bases import body_frame_displacements, project
from frictionbench.solvers.reduced.cubature import Cubature, all_tets, optimized_cubature, uniform_cubature
from frictionbench.solvers.reduced.frame import FRAME_ANGLE, FrameSolver
from frictionbench.solvers.reduced.solver import ReducedSolver
from frictionbench.solvers.step_stats import StepStats
from frictionbench.solvers.trajectory import Trajectory


class PluginError(ValueError):
    """A reduced variant cannot run here (missing artefact, wrong mesh for a mesh-bound basis, ...)."""


def artefact_key(prefix: str, payload: dict) -> str:
    blob = json.dumps(payload, sort_keys=True, default=str)
    return f"{prefix}-{hashlib.sha256(blob.encode()).hexdigest()[:16]}"


def training_displacements(trajectory: Trajectory, mass: np.ndarray, frame: str = "world") -> np.ndarray:
    """A training trajectory's displacements (F, n, 3) [m]: x - X in the world (`frame` "world"), or in the body's
    frame ("body", `solvers.reduced.frame.body_frame_displacements`); mass (n,) [kg] the mesh's lumped masses."""
    if frame == "body":
        return body_frame_displacements(trajectory.X, trajectory.x, mass)
    return trajectory.x - trajectory.X


def training_q(W: np.ndarray, mass: np.ndarray, trajectories: list[Path], limit: int = 200, frame: str = "world"
               ) -> np.ndarray:
    """Latent training states: mass-weighted projections of up to `limit` training frames (their displacements in
    `frame`, `training_displacements`) onto W, (S, r)."""
    frames = np.concatenate([training_displacements(Trajectory.load(p), mass, frame) for p in trajectories])
    return project(W, frames[np.linspace(0, len(frames) - 1, min(limit, len(frames))).astype(int)], mass)


def _cubature(model: Model, W: np.ndarray, spec: str, seed: int, stored: dict | None) -> tuple[Cubature, str]:
    """Resolve a cubature spec on `model`'s mesh; `stored` holds an optimised cubature of the training mesh."""
    if spec == "all":
        return all_tets(model), "all"
    kind, _, count = spec.partition(":")
    if kind not in ("uniform", "optimized") or not count.isdigit():
        raise PluginError(f"cubature = {spec!r}: expected 'all', 'uniform:N' or 'optimized:N'")
    if kind == "optimized":
        if stored is not None and stored["n_vertices"] == model.n and stored["n_tets"] == len(model.tets):
            return (np.asarray(stored["ids"]), np.asarray(stored["weights"])), spec
        return uniform_cubature(model, int(count), seed), f"uniform:{count} (optimized is bound to the training mesh)"
    return uniform_cubature(model, int(count), seed), spec


#: The reduced solvers' common parameters (`Solver.parameters`; each adds its own).
COMMON_PARAMETERS = {"cubature": "all", "scheme": "newton", "seed": 0, "tol": 1e-5}
#: The reduced solvers' experimental parameters (`Solver.experimental`): LiCROM's released integrator (a fixed
#: iteration count, a latent velocity factor) and the Hessian's precision and refresh, which the study's sets vary.
EXPERIMENTAL_PARAMETERS = {"iterations": None, "velocity_scale": 1.0, "hessian": "double",
                           "hessian_refresh": "iteration"}


#: The parameter of a solver whose basis is stepped in the body's frame (`basis_frame = "body"`): how far [rad] the
#: body may turn from its frame before the frame follows it (`solvers.reduced.frame.FrameSolver`).
FRAME_PARAMETERS = {"frame_angle": FRAME_ANGLE}


class ReducedPlugin(Solver):
    """What the reduced solvers share: a `ReducedSolver` on the basis `setup` makes, with its resolved cubature.
    Parameters common to all: cubature (`all`, `uniform:N`, `optimized:N`), scheme (`newton`,
    `projected_gradient`), seed, tol: Newton's tolerance [1/s, relative to L] (the full-space solver's measure and
    default). Experimental (`EXPERIMENTAL_PARAMETERS`, a matrix entry's `experimental` table): iterations: None
    (iterate to convergence) or, with the projected gradient, a fixed count per step with no convergence test;
    velocity_scale: the latent velocity's factor before each step (1: none); hessian: "double" or "single", the
    precision of the Hessian's dense products (`solvers.reduced.solver.HESSIAN_PRECISIONS`); hessian_refresh:
    "iteration" or "step", when the body terms' Hessian is evaluated (`HESSIAN_REFRESHES` there). LiCROM's released
    integrator is the projected gradient at 3 iterations and 0.99 (the repository's
    experiments/licrom-released.toml). Every integrator of `solvers.integrators` (the scenario's `time.integrator`)
    with either scheme."""

    integrators = tuple(INTEGRATORS)
    experimental = EXPERIMENTAL_PARAMETERS

    @abstractmethod
    def basis_of(self, model: Model) -> tuple[np.ndarray, dict | None, dict]:
        """The basis W (n, 3, r) on `model`'s mesh, a stored optimised cubature (or None) and stats to report."""

    def setup(self, model: Model) -> None:
        """The reduced solver on this model's basis with the resolved cubature; `info` feeds the run's stats."""
        W, stored_cubature, info = self.basis_of(model)
        p = self.params
        cub, used = _cubature(model, W, p["cubature"], p["seed"], stored_cubature)
        fixed = p["iterations"] is not None
        if fixed:
            check_count(self.name, "iterations", p["iterations"])
        kind, extra = ((FrameSolver, {"frame_angle": p["frame_angle"]}) if self.basis_frame == "body"
                       else (ReducedSolver, {}))
        solver = kind(model, W, cub, scheme=p["scheme"], device=self.device, seed=p["seed"],
                      name=self.name, fixed_iterations=fixed, velocity_scale=float(p["velocity_scale"]),
                      tol=p["tol"], hessian=p["hessian"], hessian_refresh=p["hessian_refresh"],
                      **({"max_iter": p["iterations"]} if fixed else {}), **extra)
        self.info = {"cubature_used": used, "r": int(W.shape[2]), "cubature_count": int(len(cub[0]))}
        if p["scheme"] == "projected_gradient":
            # the paper's scheme is stable only below 2 / lambda_max(h^2 S^-1 H): take 90% of it at the start state
            from frictionbench.solvers.build import initial_state

            limit = solver.projected_gradient_alpha_limit(initial_state(model), model.scenario.time.dt)
            solver.alpha = 0.9 * limit
            self.info["pg_alpha"] = solver.alpha
        self.info |= info
        self.solver, self.basis = solver, solver.reduced.W

    def initial(self, state: State) -> State:
        """The state with its latent coordinates (mass-weighted projection)."""
        return self.solver.project(state)

    def step(self, state_in: State, state_out: State, dt: float) -> StepStats:
        """One reduced step of the scenario's integrator."""
        return self.solver.step(state_in, state_out, dt)

    def describe(self) -> dict:
        """Name, parameters, and the resolved cubature, dimension r, training time."""
        return super().describe() | self.info



def cubature_artefact(folder: Path, spec: str, basis: Callable[[Model], np.ndarray], trajectories: list[Path],
                      seed: int, frame: str = "world") -> str | None:
    """For `spec` = "optimized:N", the file of that cubature selected on the training mesh (`optimized_cubature`
    on the training frames projected onto `basis(model)`, the basis W (n, 3, r) on that mesh), computed once and
    stored in the model's folder with those latent training states (TRAINING_STATES, for a selection on another
    mesh); None for any other spec."""
    if not spec.startswith("optimized:"):
        return None
    path, states = folder / f"cubature_{spec.replace(':', '_')}.json", folder / TRAINING_STATES
    if not (path.is_file() and states.is_file()):
        traj = Trajectory.load(trajectories[0])
        model = selection_model(traj.X, traj.tets)
        W = basis(model)
        q = training_q(W, model.mass, trajectories, frame=frame)
        with atomic_open(states, "wb") as f:
            np.save(f, q, allow_pickle=False)
        if not path.is_file():
            _write_cubature(path, model, optimized_cubature(model, W, q, int(spec.split(":")[1]), seed=seed,
                                                            progress=True))
    return str(path)


#: The latent training states (S, r) an optimised cubature was selected from, stored beside it (`np.save`).
TRAINING_STATES = "training_states.npy"


def _write_cubature(path: Path, model: Model, cubature: Cubature) -> None:
    """Store a cubature selected on `model`'s mesh (JSON: tet ids, weights, the mesh's vertex and tet counts)."""
    ids, weights = cubature
    write_json_atomic(path, {"ids": ids.tolist(), "weights": weights.tolist(), "n_vertices": model.n,
                             "n_tets": int(len(model.tets))})


def cubature_on_mesh(model: Model, W: np.ndarray, spec: str, cubature_file: str, seed: int) -> dict | None:
    """For `spec` = "optimized:N" on a mesh other than the training mesh, the cubature selected on this mesh
    (`optimized_cubature` on the stored latent training states with this mesh's basis W (n, 3, r)), computed once
    and stored beside the training mesh's (named by the mesh's digest); None for any other spec or without stored
    training states (then `_cubature` falls back to uniform:N)."""
    if not spec.startswith("optimized:") or not cubature_file:
        return None
    states = Path(cubature_file).parent / TRAINING_STATES
    if not states.is_file():
        return None
    digest = hashlib.sha256(np.ascontiguousarray(model.X).tobytes() + model.tets.tobytes()).hexdigest()[:16]
    path = Path(cubature_file).parent / f"cubature_{spec.replace(':', '_')}_mesh-{digest}.json"
    if not path.is_file():
        selection = selection_model(model.X, model.tets)
        _write_cubature(path, selection, optimized_cubature(selection, W, np.load(states, allow_pickle=False),
                                                            int(spec.split(":")[1]), seed=seed))
    return stored_cubature(str(path))


def stored_cubature(path: str) -> dict | None:
    """A stored optimised cubature (`cubature_artefact`; JSON), None without one."""
    return json.loads(Path(path).read_text()) if path else None


def selection_model(X: np.ndarray, tets: np.ndarray) -> Model:
    """A model of the mesh (rest positions X (n, 3) [m], tets (m, 4)) with elasticity only, for cubature
    selection."""
    from frictionbench.scenarios.meshes import make_mesh
    from frictionbench.scenarios.spec import Scenario
    from frictionbench.solvers.build import build_model

    return build_model(Scenario(name="training-mesh", plane=None), make_mesh(X, tets, "training"))


"""Solvers of the reduced family under the solver contract (`solvers.contract`): `licrom` (trained neural field),
`pod` (SVD modes of the training mesh, carried to another mesh of the shape by interpolation), `affine` (the 12
affine fields).

Each `setup(model)` builds a `ReducedSolver` (untimed); where a solver needs the suite's training data, its
`prepare(shape, trajectories, out_dir, suite)` trains once per (mesh shape, settings), caches the artefact under
`out_dir/<key>/` (the run's output folder), and returns the run parameters `shape` and the artefact's path.
Cubature parameter: `all` (every tet, weight 1), `uniform:N` or `optimized:N` (An, Kim & James on the training
states; on a mesh other than the training mesh LiCROM's falls back to uniform:N, as LiCROM does for remeshing, and
the run's stats say so, while POD's is selected again on that mesh from the same latent training states).
"""

from __future__ import annotations

import hashlib
import json
import time
from abc import abstractmethod
from collections.abc import Callable
from pathlib import Path

import numpy as np

from frictionbench.scenarios.atomic import atomic_open, write_json_atomic
from frictionbench.solvers.baselines import affine_basis, interpolate_basis, pod_basis, project
from frictionbench.solvers.contract import Solver, check_count
from frictionbench.solvers.integrators import INTEGRATORS
from frictionbench.solvers.licrom.cubature import Cubature, all_tets, optimized_cubature, uniform_cubature
from frictionbench.solvers.licrom.reduced import ReducedSolver
from frictionbench.solvers.model import Model, State
from frictionbench.solvers.step_stats import StepStats
from frictionbench.solvers.trajectory import Trajectory


class PluginError(ValueError):
    """A reduced variant cannot run here (missing artefact, wrong mesh for a mesh-bound basis, ...)."""


def _key(prefix: str, payload: dict) -> str:
    blob = json.dumps(payload, sort_keys=True, default=str)
    return f"{prefix}-{hashlib.sha256(blob.encode()).hexdigest()[:16]}"


def _training_q(W: np.ndarray, mass: np.ndarray, trajectories: list[Path], limit: int = 200) -> np.ndarray:
    """Latent training states: mass-weighted projections of up to `limit` training frames onto W, (S, r)."""
    frames = np.concatenate([(lambda t: t.x - t.X)(Trajectory.load(p)) for p in trajectories])
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


class _Reduced(Solver):
    """What the reduced solvers share: a `ReducedSolver` on the basis `setup` makes, with its resolved cubature.
    Parameters common to all: cubature (`all`, `uniform:N`, `optimized:N`), scheme (`newton`,
    `projected_gradient`), seed; iterations: None (iterate to convergence) or, with the projected gradient, a fixed
    count per step with no convergence test; velocity_scale: the latent velocity's factor before each step (1: none);
    tol: Newton's tolerance [1/s, relative to L] (the full-space solver's measure and default); hessian: "double" or
    "single", the precision of the Hessian's dense products (`solvers.licrom.reduced.HESSIAN_PRECISIONS`);
    hessian_refresh: "iteration" or "step", when the body terms' Hessian is evaluated (`HESSIAN_REFRESHES` there).
    LiCROM's released integrator is the projected gradient at 3 iterations and 0.99 (the
    repository's experiments/licrom-released.toml). Every integrator of `solvers.integrators` (the scenario's `time.integrator`) with either
    scheme."""

    integrators = tuple(INTEGRATORS)

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
        solver = ReducedSolver(model, W, cub, scheme=p["scheme"], device=self.device, seed=p["seed"],
                               name=self.name, fixed_iterations=fixed, velocity_scale=float(p["velocity_scale"]),
                               tol=p["tol"], hessian=p["hessian"], hessian_refresh=p["hessian_refresh"],
                               **({"max_iter": p["iterations"]} if fixed else {}))
        self.info = {"cubature_used": used, "r": int(W.shape[2]), "cubature_count": int(len(cub[0]))}
        if p["scheme"] == "projected_gradient":
            # the paper's scheme is stable only below 2 / lambda_max(h^2 S^-1 H): take 90% of it at the start state
            from frictionbench.solvers.model import initial_state

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


_COMMON = {"cubature": "all", "scheme": "newton", "seed": 0, "iterations": None, "velocity_scale": 1.0, "tol": 1e-5,
           "hessian": "double", "hessian_refresh": "iteration"}


# ----- affine ------------------------------------------------------------------------------------------------
class Affine(_Reduced):
    """The 12 exact affine fields as the subspace (rigid motions and homogeneous strains only)."""

    name = "affine"
    parameters = dict(_COMMON)

    def basis_of(self, model: Model) -> tuple[np.ndarray, dict | None, dict]:
        """The affine basis of the mesh."""
        return affine_basis(model.X), None, {}


# ----- POD ---------------------------------------------------------------------------------------------------
class Pod(_Reduced):
    """POD modes of the training displacements (`r` of them, plus the affine fields with `affine`) on the training
    mesh. With `cubature = "optimized:N"` the cubature is selected on the training mesh from the training states in
    the basis (`cubature_file`, set by `prepare`), as LiCROM's is. On another mesh of the same shape the modes,
    piecewise linear on the training mesh's tets, are interpolated at its rest vertices (`interpolate_basis`), and an
    optimised cubature is selected on that mesh from the stored latent training states, which mean the same there
    (`_cubature_on_mesh`; LiCROM's falls back to uniform:N, as released)."""

    name = "pod"
    parameters = _COMMON | {"r": 20, "affine": False, "basis": "", "shape": "", "cubature_file": ""}

    def prepare(self, shape: str, trajectories: list[Path], out_dir: Path, suite: str) -> dict:
        """SVD modes of the training displacements of one shape, stored with the training mesh they belong to, and
        an optimised cubature of them if asked for."""
        basis = _pod_basis_file(shape, trajectories, self.params, out_dir, suite)
        out = {"shape": shape, "basis": basis}
        cubature = _cubature_file(Path(basis).parent, str(self.params.get("cubature", "all")),
                                  lambda model: _load_pod(basis)[0], trajectories, int(self.params.get("seed", 0)))
        return out | ({"cubature_file": cubature} if cubature else {})

    def skip(self, model: Model) -> str | None:
        """A basis stored without its training mesh's tets cannot be carried to another mesh; a mesh of another
        shape is refused by the interpolation (`_modes_on`, whose result `setup` then reuses)."""
        try:
            self._modes_on(model)
        except ValueError as err:
            return f"pod basis {self.params['basis']}: {err}"
        return None

    def basis_of(self, model: Model) -> tuple[np.ndarray, dict | None, dict]:
        """The stored modes (interpolated on another mesh), their optimised cubature (if any) and the training time;
        `basis_mesh` says which."""
        W, info = self._modes_on(model)
        if "basis_mesh" not in info:
            return W, _stored_cubature(self.params["cubature_file"]), dict(info)
        p = self.params
        cubature = _cubature_on_mesh(model, W, str(p["cubature"]), p["cubature_file"], int(p["seed"]))
        extra = {"cubature_mesh": "selected on this mesh from the training states"} if cubature is not None else {}
        return W, cubature, info | extra

    #: The model the modes were last put on and (W, info) there (`_modes_on`).
    _modes: tuple[Model, tuple[np.ndarray, dict]] | None = None

    def _modes_on(self, model: Model) -> tuple[np.ndarray, dict]:
        """The stored modes W (n, 3, r) on `model`'s mesh, interpolated at its vertices off the training mesh
        (`interpolate_basis`), and the run's stats of them (`train_s`; `basis_mesh` where interpolated); loaded and
        located once per model (`skip`, then `setup`). ValueError for a mesh of another shape, or off the training
        mesh for a basis stored without that mesh's tets."""
        if self._modes is not None and self._modes[0] is model:
            return self._modes[1]
        path = self.params["basis"]
        W, X, tets = _load_pod(path)
        info = {"train_s": json.loads((Path(path).parent / "info.json").read_text())["train_s"]}
        if not _same_mesh(X, model.X):
            if tets is None:
                raise ValueError(f"stored without its training mesh's tets, so it cannot be carried to this mesh "
                                 f"({model.n} vertices, the training mesh {len(X)}); run the matrix again to store "
                                 f"them")
            W = interpolate_basis(W, X, tets, model.X)
            info["basis_mesh"] = f"interpolated from the training mesh ({len(X)} vertices)"
        self._modes = (model, (W, info))
        return W, info


def _same_mesh(X: np.ndarray, X_run: np.ndarray) -> bool:
    """Whether rest positions X_run (n, 3) [m] are those of the mesh X (the training mesh itself)."""
    return X.shape == X_run.shape and np.allclose(X, X_run)


def _load_pod(path: str) -> tuple[np.ndarray, np.ndarray, np.ndarray | None]:
    """A stored POD basis W (n, 3, r), its training mesh's rest positions X (n, 3) [m] and tets (m, 4) (None in a
    file stored before they were kept); arrays, no pickle."""
    with np.load(path, allow_pickle=False) as z:
        return z["W"], z["X"], z["tets"] if "tets" in z.files else None


def _pod_basis_file(shape: str, trajectories: list[Path], params: dict, models_dir: Path, suite: str) -> str:
    """The POD basis file of one shape (computed once, cached under models_dir; a file stored without the training
    mesh's tets gets them, the modes unchanged)."""
    r, with_affine = int(params.get("r", 20)), bool(params.get("affine", False))
    key = _key("pod", {"shape": shape, "r": r, "affine": with_affine, "data": [str(p) for p in trajectories]})
    path = Path(models_dir) / key / "basis.npz"
    if path.is_file():
        W, X, tets = _load_pod(str(path))
        if tets is None:
            _save_pod(path, W, X, Trajectory.load(trajectories[0]).tets)
        return str(path)
    trajs = [Trajectory.load(p) for p in trajectories]
    X, tets = trajs[0].X, trajs[0].tets
    from frictionbench.solvers.physics.inertia import lumped_mass
    from frictionbench.solvers.physics.material import shape_matrices

    mass = lumped_mass(shape_matrices(X, tets)[1], tets, len(X), 1.0)
    u = np.concatenate([t.x - t.X for t in trajs])
    t0 = time.perf_counter()
    W = pod_basis(u, r, mass, affine_X=X if with_affine else None)
    _save_pod(path, W, X, tets)
    write_json_atomic(path.parent / "info.json", {"train_s": time.perf_counter() - t0, "shape": shape,
                                                  "suite": suite, "r": r, "affine": with_affine})
    return str(path)


def _save_pod(path: Path, W: np.ndarray, X: np.ndarray, tets: np.ndarray) -> None:
    """Store a POD basis W (n, 3, r) with its training mesh (X (n, 3) [m], tets (m, 4)), atomically."""
    with atomic_open(path, "wb") as f:
        np.savez_compressed(f, W=W, X=X, tets=tets)


# ----- LiCROM ------------------------------------------------------------------------------------------------
def _train_licrom(shape: str, trajectories: list[Path], params: dict, models_dir: Path, device: str,
                  suite: str) -> dict:
    """Train the neural field of one shape on its training trajectories (cached under models_dir), and, for an
    optimised cubature, select it on the training mesh; returns `shape`, `checkpoint` (and `cubature_file`)."""
    from frictionbench.solvers.licrom.train import (TrainSettings, evaluate_basis, load_checkpoint,
                                                    train_from_trajectories)

    settings = {k: params.get(k) if params.get(k) is not None else d
                for k, d in (("r", 20), ("epochs", 100), ("affine", False), ("seed", 0), ("points", 512))}
    key = _key("licrom", {"shape": shape, **settings, "data": [str(p) for p in trajectories]})
    folder = Path(models_dir) / key
    ckpt_path = folder / "model.pt"
    if not ckpt_path.is_file():
        train_from_trajectories([str(p) for p in trajectories], folder, TrainSettings(**settings), device,
                                progress=True, identity={"suite": suite, "shape": shape})
    out = {"shape": shape, "checkpoint": str(ckpt_path)}
    cubature = _cubature_file(folder, str(params.get("cubature", "all")),
                              lambda model: evaluate_basis(load_checkpoint(ckpt_path), model.X), trajectories,
                              settings["seed"])
    return out | ({"cubature_file": cubature} if cubature else {})


def _cubature_file(folder: Path, spec: str, basis: Callable[[Model], np.ndarray], trajectories: list[Path],
                   seed: int) -> str | None:
    """For `spec` = "optimized:N", the file of that cubature selected on the training mesh (`optimized_cubature`
    on the training frames projected onto `basis(model)`, the basis W (n, 3, r) on that mesh), computed once and
    stored in the model's folder with those latent training states (TRAINING_STATES, for a selection on another
    mesh); None for any other spec."""
    if not spec.startswith("optimized:"):
        return None
    path, states = folder / f"cubature_{spec.replace(':', '_')}.json", folder / TRAINING_STATES
    if not (path.is_file() and states.is_file()):
        traj = Trajectory.load(trajectories[0])
        model = _selection_model(traj.X, traj.tets)
        W = basis(model)
        q = _training_q(W, model.mass, trajectories)
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


def _cubature_on_mesh(model: Model, W: np.ndarray, spec: str, cubature_file: str, seed: int) -> dict | None:
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
        selection = _selection_model(model.X, model.tets)
        _write_cubature(path, selection, optimized_cubature(selection, W, np.load(states, allow_pickle=False),
                                                            int(spec.split(":")[1]), seed=seed))
    return _stored_cubature(str(path))


def _stored_cubature(path: str) -> dict | None:
    """A stored optimised cubature (`_cubature_file`; JSON), None without one."""
    return json.loads(Path(path).read_text()) if path else None


def _selection_model(X: np.ndarray, tets: np.ndarray) -> Model:
    """A model of the mesh (rest positions X (n, 3) [m], tets (m, 4)) with elasticity only, for cubature
    selection."""
    from frictionbench.scenarios.meshes import make_mesh
    from frictionbench.scenarios.model import Scenario
    from frictionbench.solvers.model import build_model

    return build_model(Scenario(name="training-mesh", plane=None), make_mesh(X, tets, "training"))


class Licrom(_Reduced):
    """The trained neural field evaluated on the run's mesh (any mesh of the shape): `r` latent dimensions,
    `epochs`, `points` sampled per training frame, `affine` columns added; `checkpoint` (set by `prepare`, or given)
    and `cubature_file` (an optimised cubature of the training mesh)."""

    name = "licrom"
    requires = ("torch",)  # the network (imported where it is used; pod and affine run without it)
    parameters = _COMMON | {"r": None, "epochs": 100, "affine": False, "points": 512, "checkpoint": "",
                            "shape": "", "cubature_file": ""}

    def prepare(self, shape: str, trajectories: list[Path], out_dir: Path, suite: str) -> dict:
        """Train on the shape's training trajectories (cached under out_dir)."""
        return _train_licrom(shape, trajectories, self.params, out_dir, self.device, suite)

    def basis_of(self, model: Model) -> tuple[np.ndarray, dict | None, dict]:
        """The network's basis at this mesh's rest positions, the stored optimised cubature, the training time."""
        from frictionbench.solvers.licrom.train import evaluate_basis, load_checkpoint

        p = self.params
        self.checkpoint = load_checkpoint(p["checkpoint"], expected_r=p["r"])
        return (evaluate_basis(self.checkpoint, model.X), _stored_cubature(p["cubature_file"]),
                {"train_s": self.checkpoint.train_seconds})

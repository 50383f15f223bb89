"""Solver plug-ins of the reduced family: `licrom` (trained neural field), `pod` (mesh-bound SVD modes), `affine`.

Each has a `setup_*(model, device, **params) -> ReducedSolver` (untimed) and, where it needs the suite's
training data, a `prepare_*(shape, trajectories, params, models_dir, device, suite) -> params` that trains once per
(mesh shape, settings), caches the artefact under `models_dir/<key>/`, and returns the run parameters with
`shape` and the artefact's path. Cubature parameter: `all` (every tet, weight 1), `uniform:N` or `optimized:N`
(An, Kim & James on the training states; on a mesh other than the training mesh it falls back to uniform:N, as
LiCROM does for remeshing, and the run's stats say so).
"""

from __future__ import annotations

import hashlib
import json
import time
from pathlib import Path

import numpy as np

from solvers.baselines import affine_basis, pod_basis, project
from solvers.licrom.cubature import Cubature, all_tets, optimized_cubature, uniform_cubature
from solvers.licrom.reduced import ReducedSolver
from solvers.model import Model
from scenarios.atomic import write_json_atomic
from solvers.trajectory import Trajectory


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


def _stored_basis(W: np.ndarray) -> str:
    """W saved once under the cache (keyed by its bytes), for the projection-error metric of the runs."""
    from solvers.warp_runtime import cache_root

    path = cache_root() / "bases" / f"{hashlib.sha256(W.tobytes()).hexdigest()[:16]}.npy"
    if not path.is_file():
        path.parent.mkdir(parents=True, exist_ok=True)
        np.save(path, W)
    return str(path)


def _solver(model: Model, W: np.ndarray, device: str, cubature: str, scheme: str, seed: int, name: str,
            stored_cubature: dict | None = None, basis_path: str | None = None) -> ReducedSolver:
    """The reduced solver on basis W with the resolved cubature; `info` feeds the run's stats."""
    basis_path = basis_path or _stored_basis(W)
    cub, used = _cubature(model, W, cubature, seed, stored_cubature)
    solver = ReducedSolver(model, W, cub, scheme=scheme, device=device, seed=seed, name=name)
    solver.info = {"cubature_used": used, "r": int(W.shape[2]), "cubature_count": int(len(cub[0])),
                   "basis_path": basis_path}
    if scheme == "projected_gradient":
        # the paper's scheme is stable only below 2 / lambda_max(h^2 S^-1 H): take 90% of it at the start state
        from solvers.model import initial_state

        limit = solver.projected_gradient_alpha_limit(initial_state(model), model.scenario.time.dt)
        solver.alpha = 0.9 * limit
        solver.info["pg_alpha"] = solver.alpha
    return solver


# ----- affine ------------------------------------------------------------------------------------------------
def setup_affine(model: Model, device: str = "cpu", cubature: str = "all", scheme: str = "newton",
                 seed: int = 0) -> ReducedSolver:
    """The 12 exact affine fields as the subspace (rigid motions and homogeneous strains only)."""
    return _solver(model, affine_basis(model.X), device, cubature, scheme, seed, "affine")


# ----- POD ---------------------------------------------------------------------------------------------------
def prepare_pod(shape: str, trajectories: list[Path], params: dict, models_dir: Path, device: str,
                suite: str) -> dict:
    """SVD modes of the training displacements of one shape, stored with the training mesh they belong to."""
    r, with_affine = int(params.get("r", 20)), bool(params.get("affine", False))
    key = _key("pod", {"shape": shape, "r": r, "affine": with_affine, "data": [str(p) for p in trajectories]})
    path = Path(models_dir) / key / "basis.npz"
    if not path.is_file():
        trajs = [Trajectory.load(p) for p in trajectories]
        X, tets = trajs[0].X, trajs[0].tets
        from solvers.physics.inertia import lumped_mass
        from solvers.physics.material import shape_matrices

        mass = lumped_mass(shape_matrices(X, tets)[1], tets, len(X), 1.0)
        u = np.concatenate([t.x - t.X for t in trajs])
        t0 = time.perf_counter()
        W = pod_basis(u, r, mass, affine_X=X if with_affine else None)
        path.parent.mkdir(parents=True, exist_ok=True)
        np.savez_compressed(path, W=W, X=X)
        write_json_atomic(path.parent / "info.json", {"train_s": time.perf_counter() - t0, "shape": shape,
                                                      "suite": suite, "r": r, "affine": with_affine})
    return params | {"shape": shape, "basis": str(path)}


def setup_pod(model: Model, device: str = "cpu", basis: str = "", r: int = 20, affine: bool = False,
              cubature: str = "all", scheme: str = "newton", seed: int = 0, shape: str = "") -> ReducedSolver:
    """POD modes; refuses any mesh but the one they were computed on."""
    with np.load(basis) as z:
        W, X = z["W"], z["X"]
    if X.shape != model.X.shape or not np.allclose(X, model.X):
        raise PluginError(f"pod basis {basis}: bound to its training mesh ({len(X)} vertices); this mesh has "
                          f"{model.n} vertices. POD cannot remesh: use licrom or affine")
    solver = _solver(model, W, device, cubature, scheme, seed, "pod")
    solver.info["train_s"] = json.loads((Path(basis).parent / "info.json").read_text())["train_s"]
    return solver


# ----- LiCROM ------------------------------------------------------------------------------------------------
def prepare_licrom(shape: str, trajectories: list[Path], params: dict, models_dir: Path, device: str,
                   suite: str) -> dict:
    """Train the neural field of one shape on its training trajectories (cached), and, for an optimised
    cubature, select it on the training mesh."""
    from solvers.licrom.train import TrainSettings, evaluate_basis, load_checkpoint, train_from_trajectories

    settings = {k: params.get(k, d) for k, d in (("r", 20), ("epochs", 100), ("affine", False), ("seed", 0),
                                                 ("points", 512))}
    key = _key("licrom", {"shape": shape, **settings, "data": [str(p) for p in trajectories]})
    folder = Path(models_dir) / key
    ckpt_path = folder / "model.pt"
    if not ckpt_path.is_file():
        train_from_trajectories([str(p) for p in trajectories], folder, TrainSettings(**settings), device,
                                identity={"suite": suite, "shape": shape})
    out = params | {"shape": shape, "checkpoint": str(ckpt_path)}
    spec = str(params.get("cubature", "all"))
    if spec.startswith("optimized:"):
        cub_path = folder / f"cubature_{spec.replace(':', '_')}.json"
        if not cub_path.is_file():
            traj = Trajectory.load(trajectories[0])
            model = _model_of(traj)
            W = evaluate_basis(load_checkpoint(ckpt_path), model.X)
            q = _training_q(W, model.mass, trajectories)
            ids, weights = optimized_cubature(model, W, q, int(spec.split(":")[1]), seed=settings["seed"])
            write_json_atomic(cub_path, {"ids": ids.tolist(), "weights": weights.tolist(), "n_vertices": model.n,
                                         "n_tets": int(len(model.tets))})
        out["cubature_file"] = str(cub_path)
    return out


def _model_of(traj: Trajectory) -> Model:
    """A model of the training mesh (elasticity only) for cubature selection."""
    from scenarios.meshes import make_mesh
    from scenarios.model import Scenario
    from solvers.model import build_model

    return build_model(Scenario(name="training-mesh", plane=None), make_mesh(traj.X, traj.tets, "training"))


def setup_licrom(model: Model, device: str = "cpu", checkpoint: str = "", r: int | None = None, epochs: int = 100,
                 affine: bool = False, cubature: str = "all", scheme: str = "newton", seed: int = 0,
                 points: int = 512, shape: str = "", cubature_file: str = "") -> ReducedSolver:
    """The trained neural field evaluated on this model's mesh (any mesh of the shape)."""
    from solvers.licrom.train import evaluate_basis, load_checkpoint

    ckpt = load_checkpoint(checkpoint, expected_r=r)
    W = evaluate_basis(ckpt, model.X)
    stored = json.loads(Path(cubature_file).read_text()) if cubature_file else None
    name = "licrom-affine" if ckpt.arch.get("affine") else "licrom"
    solver = _solver(model, W, device, cubature, scheme, seed, name, stored)
    solver.info["train_s"] = ckpt.train_seconds
    return solver

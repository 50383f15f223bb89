"""The data-driven and the affine subspaces under the solver contract: `pod` (SVD modes of the training mesh, carried
to another mesh of the shape by interpolation), `pod-frame` (the same in the body's frame, `solvers.reduced.frame`)
and `affine` (the 12 affine fields), all `ReducedPlugin`s (`solvers.reduced.plugin`).
"""

from __future__ import annotations

import json
import time
from pathlib import Path

import numpy as np

from frictionbench.scenarios.atomic import atomic_open, write_json_atomic
from frictionbench.solvers.model import Model
from frictionbench.solvers.reduced.bases import N_AFFINE, affine_basis, interpolate_basis, pod_basis, project
from frictionbench.solvers.reduced.plugin import (COMMON_PARAMETERS, FRAME_PARAMETERS, PluginError, ReducedPlugin,
                                                  artefact_key, cubature_artefact, cubature_on_mesh, stored_cubature,
                                                  training_displacements)
from frictionbench.solvers.trajectory import Trajectory


class Affine(ReducedPlugin):
    """The 12 exact affine fields as the subspace (rigid motions and homogeneous strains only)."""

    name = "affine"
    parameters = dict(COMMON_PARAMETERS)

    def basis_of(self, model: Model) -> tuple[np.ndarray, dict | None, dict]:
        """The affine basis of the mesh."""
        return affine_basis(model.X), None, {}


class Pod(ReducedPlugin):
    """POD modes of the training displacements (`r` of them, plus the affine fields with `affine`) on the training
    mesh. With `cubature = "optimized:N"` the cubature is selected on the training mesh from the training states in
    the basis (`cubature_file`, set by `prepare`), as LiCROM's is. On another mesh of the same shape the modes,
    piecewise linear on the training mesh's tets, are interpolated at its rest vertices (`interpolate_basis`), and an
    optimised cubature is selected on that mesh from the stored latent training states, which mean the same there
    (`cubature_on_mesh`; LiCROM's falls back to uniform:N, as released)."""

    name = "pod"
    parameters = COMMON_PARAMETERS | {"r": 20, "affine": False, "basis": "", "shape": "", "cubature_file": ""}

    def prepare(self, shape: str, trajectories: list[Path], out_dir: Path, suite: str) -> dict:
        """SVD modes of the training displacements of one shape, stored with the training mesh they belong to, and
        an optimised cubature of them if asked for."""
        basis = _pod_basis_file(shape, trajectories, self.params, out_dir, suite, self.basis_frame)
        out = {"shape": shape, "basis": basis}
        cubature = cubature_artefact(Path(basis).parent, str(self.params.get("cubature", "all")),
                                     lambda model: _load_pod(basis)[0], trajectories, int(self.params.get("seed", 0)),
                                     self.basis_frame)
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
            return W, stored_cubature(self.params["cubature_file"]), dict(info)
        p = self.params
        cubature = cubature_on_mesh(model, W, str(p["cubature"]), p["cubature_file"], int(p["seed"]))
        extra = {"cubature_mesh": "selected on this mesh from the training states"} if cubature is not None else {}
        return W, cubature, info | extra

    #: The model the modes were last put on and (W, info) there (`_modes_on`).
    _modes: tuple[Model, tuple[np.ndarray, dict]] | None = None

    @staticmethod
    def carried(W: np.ndarray, model: Model) -> np.ndarray:
        """The modes W (n, 3, r) interpolated at `model`'s vertices, as this solver takes them there (as they are)."""
        return W

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
            W = self.carried(interpolate_basis(W, X, tets, model.X), model)
            info["basis_mesh"] = f"interpolated from the training mesh ({len(X)} vertices)"
        self._modes = (model, (W, info))
        return W, info


class PodFrame(Pod):
    """POD modes of the training displacements in the body's frame (each training frame turned back by its own
    rotation, `solvers.reduced.frame.body_frame_displacements`) beyond the 12 affine fields, stepped with the
    deformation modes turned with the body (`solvers.reduced.frame.FrameSolver`): the modes hold deformation only,
    whichever way the body faced in the training data and faces in the run. Otherwise as `pod` (cubature, another
    mesh); `affine` must stay true."""

    name = "pod-frame"
    basis_frame = "body"
    parameters = Pod.parameters | {"affine": True} | FRAME_PARAMETERS

    def prepare(self, shape: str, trajectories: list[Path], out_dir: Path, suite: str) -> dict:
        """As `Pod.prepare`, in the body's frame; PluginError without the affine fields."""
        if not self.params["affine"]:
            raise PluginError(f"{self.name}: affine = false; the body's frame needs the 12 affine fields in the basis")
        return super().prepare(shape, trajectories, out_dir, suite)

    @staticmethod
    def carried(W: np.ndarray, model: Model) -> np.ndarray:
        """The interpolated modes with their first 12 columns made exactly affine on this mesh (each the affine field
        closest to it, so that the latent coordinates keep their meaning): the interpolation reproduces an affine
        field only inside the training mesh (outside, its weights are clamped), and the frame needs them exact."""
        A = affine_basis(model.X)
        C = project(A, W[:, :, :N_AFFINE].transpose(2, 0, 1))  # (12, 12): column k of W ~ A C[k]
        W = W.copy()
        W[:, :, :N_AFFINE] = np.einsum("naj,kj->nak", A, C)
        return W


def _same_mesh(X: np.ndarray, X_run: np.ndarray) -> bool:
    """Whether rest positions X_run (n, 3) [m] are those of the mesh X (the training mesh itself)."""
    return X.shape == X_run.shape and np.allclose(X, X_run)


def _load_pod(path: str) -> tuple[np.ndarray, np.ndarray, np.ndarray | None]:
    """A stored POD basis W (n, 3, r), its training mesh's rest positions X (n, 3) [m] and tets (m, 4) (None in a
    file stored before they were kept); arrays, no pickle."""
    with np.load(path, allow_pickle=False) as z:
        return z["W"], z["X"], z["tets"] if "tets" in z.files else None


def _pod_basis_file(shape: str, trajectories: list[Path], params: dict, models_dir: Path, suite: str,
                    frame: str = "world") -> str:
    """The POD basis file of one shape, of the training displacements in `frame` ("world" or "body",
    `training_displacements`) (computed once, cached under models_dir; a file stored without the training mesh's
    tets gets them, the modes unchanged)."""
    r, with_affine = int(params.get("r", 20)), bool(params.get("affine", False))
    key = artefact_key("pod", {"shape": shape, "r": r, "affine": with_affine, "data": [str(p) for p in trajectories]}
                       | ({"frame": frame} if frame != "world" else {}))
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
    u = np.concatenate([training_displacements(t, mass, frame) for t in trajs])
    t0 = time.perf_counter()
    W = pod_basis(u, r, mass, affine_X=X if with_affine else None)
    _save_pod(path, W, X, tets)
    write_json_atomic(path.parent / "info.json", {"train_s": time.perf_counter() - t0, "shape": shape,
                                                  "suite": suite, "r": r, "affine": with_affine, "frame": frame})
    return str(path)


def _save_pod(path: Path, W: np.ndarray, X: np.ndarray, tets: np.ndarray) -> None:
    """Store a POD basis W (n, 3, r) with its training mesh (X (n, 3) [m], tets (m, 4)), atomically."""
    with atomic_open(path, "wb") as f:
        np.savez_compressed(f, W=W, X=X, tets=tets)


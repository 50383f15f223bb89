"""LiCROM under the solver contract: `licrom`, the trained neural field's subspace (`solvers.licrom.train`), a
`ReducedPlugin` (`solvers.reduced.plugin`).
"""

from __future__ import annotations

from pathlib import Path

import numpy as np

from frictionbench.solvers.model import Model
from frictionbench.solvers.reduced.plugin import (COMMON_PARAMETERS, ReducedPlugin, artefact_key, cubature_artefact,
                                                  stored_cubature)


def _train_licrom(shape: str, trajectories: list[Path], params: dict, models_dir: Path, device: str,
                  suite: str) -> dict:
    """Train the neural field of one shape on its training trajectories (cached under models_dir), and, for an
    optimised cubature, select it on the training mesh; returns `shape`, `checkpoint` (and `cubature_file`)."""
    from frictionbench.solvers.licrom.train import (TrainSettings, evaluate_basis, load_checkpoint,
                                                    train_from_trajectories)

    settings = {k: params.get(k) if params.get(k) is not None else d
                for k, d in (("r", 20), ("epochs", 100), ("affine", False), ("seed", 0), ("points", 512))}
    key = artefact_key("licrom", {"shape": shape, **settings, "data": [str(p) for p in trajectories]})
    folder = Path(models_dir) / key
    ckpt_path = folder / "model.pt"
    if not ckpt_path.is_file():
        train_from_trajectories([str(p) for p in trajectories], folder, TrainSettings(**settings), device,
                                progress=True, identity={"suite": suite, "shape": shape})
    out = {"shape": shape, "checkpoint": str(ckpt_path)}
    cubature = cubature_artefact(folder, str(params.get("cubature", "all")),
                                 lambda model: evaluate_basis(load_checkpoint(ckpt_path), model.X), trajectories,
                                 settings["seed"])
    return out | ({"cubature_file": cubature} if cubature else {})


class Licrom(ReducedPlugin):
    """The trained neural field evaluated on the run's mesh (any mesh of the shape): `r` latent dimensions,
    `epochs`, `points` sampled per training frame, `affine` columns added; `checkpoint` (set by `prepare`, or given)
    and `cubature_file` (an optimised cubature of the training mesh)."""

    name = "licrom"
    requires = ("torch",)  # the network (imported where it is used; pod and affine run without it)
    parameters = COMMON_PARAMETERS | {"r": None, "epochs": 100, "affine": False, "points": 512, "checkpoint": "",
                                    "shape": "", "cubature_file": ""}

    def prepare(self, shape: str, trajectories: list[Path], out_dir: Path, suite: str) -> dict:
        """Train on the shape's training trajectories (cached under out_dir)."""
        return _train_licrom(shape, trajectories, self.params, out_dir, self.device, suite)

    def basis_of(self, model: Model) -> tuple[np.ndarray, dict | None, dict]:
        """The network's basis at this mesh's rest positions, the stored optimised cubature, the training time."""
        from frictionbench.solvers.licrom.train import evaluate_basis, load_checkpoint

        p = self.params
        self.checkpoint = load_checkpoint(p["checkpoint"], expected_r=p["r"])
        return (evaluate_basis(self.checkpoint, model.X), stored_cubature(p["cubature_file"]),
                {"train_s": self.checkpoint.train_seconds})


"""Offline LiCROM training: data from full-space trajectories, the training loop, checkpoints, inference helpers.

The model (docs/solvers.md, "LiCROM"): a PointNet encoder maps one frame's points (X, u) to a
latent code q, a neural field maps a rest position X to the basis W(X) (3 x r), and training minimises the mean
squared reconstruction error of W(X) q against u over points subsampled per frame.

Units and scales: X and u in metres. `u_scale` is the RMS (per component) of the training displacements;
`fit_scale` is the RMS of what the network fits (u itself, or with `affine=True` the residual after the exact
weighted least-squares affine fit of each frame). The loss is measured in units of fit_scale^2, so 1.0 is the
error of predicting zero. The basis W is dimensionless and q is in metres: u = W(X) q.

Learning-rate schedules: `constant` (the paper: Adam, lr 1e-3 throughout) or `cosine` (cosine annealing from lr
to lr / 100 over the epochs, stepped once per epoch).
"""

from __future__ import annotations

import csv
import importlib.metadata
import json
import logging
import os
import platform
import random
import time
from collections.abc import Sequence
from contextlib import contextmanager
from dataclasses import dataclass, field as dataclass_field
from pathlib import Path
from typing import Iterator

import numpy as np
import torch
from tqdm import tqdm

from frictionbench.scenarios.atomic import atomic_open
from frictionbench.scenarios.meshes import bbox_diagonal
from frictionbench.solvers.licrom.network import NeuralField, PointNetEncoder, fit_affine
from frictionbench.solvers.physics.inertia import lumped_mass
from frictionbench.solvers.physics.material import shape_matrices
from frictionbench.solvers.reduced.bases import N_AFFINE, project
from frictionbench.solvers.trajectory import Trajectory

log = logging.getLogger(__name__)

CHECKPOINT_FORMAT = "frictionbench.licrom.checkpoint/1"
SCHEDULES = ("constant", "cosine")
_FIT_SCALE_FLOOR = 1e-6
"""Lower bound of fit_scale relative to u_scale (a purely affine data set leaves a zero residual)."""
_CHECKPOINT_KEYS = (
    "format", "arch", "norm", "encoder_state", "field_state", "identity", "loss_history", "seed",
    "train_seconds", "config", "versions",
)


class CheckpointError(ValueError):
    """A checkpoint file is missing, unreadable, incomplete or does not match what the caller expects."""

    def __init__(self, path: str | os.PathLike, reason: str) -> None:
        self.path = Path(path)
        self.reason = reason
        super().__init__(f"{path}: {reason}")


@dataclass(frozen=True)
class TrainingData:
    """Displacement frames on one rest point set.

    X: (n, 3) float32 rest positions [m].
    u: (F, n, 3) float32 displacements [m].
    weights: (n,) float32 point weights (lumped vertex volumes when built from trajectories, else ones),
        normalised to mean 1; used by the affine fit and the affine/neural orthogonalisation.
    """

    X: torch.Tensor
    u: torch.Tensor
    weights: torch.Tensor

    @property
    def n_frames(self) -> int:
        """Number of frames F."""
        return int(self.u.shape[0])

    @property
    def n_points(self) -> int:
        """Number of points n per frame."""
        return int(self.X.shape[0])

    @classmethod
    def from_arrays(cls, X: np.ndarray, u: np.ndarray, weights: np.ndarray | None = None) -> "TrainingData":
        """Frames from arrays: X (n, 3) [m], u (F, n, 3) [m], weights (n,) >= 0 (default: uniform)."""
        X = np.asarray(X, dtype=np.float64)
        u = np.asarray(u, dtype=np.float64)
        if X.ndim != 2 or X.shape[1] != 3 or X.shape[0] < 4:
            raise ValueError(f"X has shape {X.shape}: expected (n, 3) with n >= 4")
        if u.ndim != 3 or u.shape[1:] != X.shape or u.shape[0] < 1:
            raise ValueError(f"u has shape {u.shape}: expected (F, {X.shape[0]}, 3) with F >= 1")
        if not (np.isfinite(X).all() and np.isfinite(u).all()):
            raise ValueError("X or u contains non-finite values (a diverged trajectory?)")
        w = np.ones(X.shape[0]) if weights is None else np.asarray(weights, dtype=np.float64)
        if w.shape != (X.shape[0],) or not np.isfinite(w).all() or (w < 0).any() or w.sum() <= 0:
            raise ValueError(f"weights must be (n,) = ({X.shape[0]},), finite, >= 0 and not all zero")
        return cls(
            X=torch.from_numpy(X).float(), u=torch.from_numpy(u).float(),
            weights=torch.from_numpy(w / w.mean()).float(),
        )

    @classmethod
    def from_trajectories(cls, trajs: Sequence[Trajectory]) -> "TrainingData":
        """All frames u = x - X of `trajs`, which must share one rest mesh (same X up to 1e-9 of its size).

        Point weights are the lumped vertex volumes of the first trajectory's tets (uniform without tets).
        """
        if not trajs:
            raise ValueError("no trajectories given")
        X0 = np.asarray(trajs[0].X, dtype=np.float64)
        tolerance = 1e-9 * max(bbox_diagonal(X0), 1e-300)
        for i, traj in enumerate(trajs[1:], start=1):
            if traj.X.shape != X0.shape or np.abs(np.asarray(traj.X, dtype=np.float64) - X0).max() > tolerance:
                raise ValueError(
                    f"trajectory {i} ({traj.meta.get('scenario', 'unnamed')}) has rest mesh of shape "
                    f"{traj.X.shape} different from trajectory 0 ({trajs[0].meta.get('scenario', 'unnamed')}, "
                    f"{X0.shape}): all training trajectories must share one rest mesh"
                )
        u = np.concatenate([np.asarray(t.x, dtype=np.float64) - X0 for t in trajs], axis=0)
        tets = np.asarray(trajs[0].tets)
        # lumped vertex volumes: the lumped masses of unit density (|V_e|: the tets of a trajectory may be unoriented)
        volumes = lumped_mass(np.abs(shape_matrices(X0, tets)[1]), tets, X0.shape[0], 1.0) if tets.size else None
        return cls.from_arrays(X0, u, volumes)


@dataclass
class Checkpoint:
    """A trained subspace.

    arch: {r, width, depth, affine, n_ref}; r counts all basis columns (12 affine ones included); n_ref: number
        of reference points of the affine orthogonalisation (0 without the affine variant).
    norm: {X_mean: [3 floats] [m], X_scale [m], u_scale [m], fit_scale [m]} (module docstring).
    encoder_state, field_state: torch state dicts (CPU tensors).
    identity: what the model was trained on (suite, scenario hashes, mesh name/resolution/bbox diagonal, ...).
    loss_history: mean training loss per epoch [fit_scale^2].
    seed; train_seconds: wall time of the training loop [s].
    config: {epochs, batch, points, lr, schedule, device, n_frames, n_points, ...}; versions: package versions.
    """

    arch: dict
    norm: dict
    encoder_state: dict[str, torch.Tensor]
    field_state: dict[str, torch.Tensor]
    identity: dict = dataclass_field(default_factory=dict)
    loss_history: list[float] = dataclass_field(default_factory=list)
    seed: int = 0
    train_seconds: float = 0.0
    config: dict = dataclass_field(default_factory=dict)
    versions: dict = dataclass_field(default_factory=dict)

    @property
    def r(self) -> int:
        """Total number of basis columns."""
        return int(self.arch["r"])

    @property
    def n_neural(self) -> int:
        """Number of network-learned columns (r - 12 with the affine variant)."""
        return self.r - N_AFFINE if self.arch["affine"] else self.r

    def field(self) -> NeuralField:
        """The neural field W, in eval mode, on the CPU (float32)."""
        n_ref = int(self.arch["n_ref"])
        module = NeuralField(
            self.r, int(self.arch["width"]), int(self.arch["depth"]), bool(self.arch["affine"]),
            X_mean=torch.tensor(self.norm["X_mean"]), X_scale=float(self.norm["X_scale"]),
            ref_X=torch.zeros(n_ref, 3), ref_w=torch.ones(n_ref),
        )
        module.load_state_dict(self.field_state)
        return module.eval()

    def encoder(self) -> PointNetEncoder:
        """The PointNet encoder (output: the n_neural network coordinates, in fit_scale units), in eval mode."""
        module = PointNetEncoder(self.n_neural)
        module.load_state_dict(self.encoder_state)
        return module.eval()

    def to_dict(self) -> dict:
        """Plain dict of the checkpoint (tensors, lists, numbers, strings only)."""
        return {
            "format": CHECKPOINT_FORMAT, "arch": dict(self.arch), "norm": dict(self.norm),
            "encoder_state": dict(self.encoder_state), "field_state": dict(self.field_state),
            "identity": _plain(self.identity), "loss_history": [float(x) for x in self.loss_history],
            "seed": int(self.seed), "train_seconds": float(self.train_seconds), "config": _plain(self.config),
            "versions": dict(self.versions),
        }

    def save(self, path: str | os.PathLike) -> Path:
        """Write to `path` atomically (temporary file renamed into place); returns the path."""
        with atomic_open(path, "wb") as f:
            torch.save(self.to_dict(), f)
        return Path(path)


def load_checkpoint(path: str | os.PathLike, expected_r: int | None = None) -> Checkpoint:
    """Read a checkpoint written by `Checkpoint.save`.

    Raises CheckpointError (naming the path) if the file is missing, is not a torch file, lacks keys or holds
    state dicts that do not fit the stored architecture, or if `expected_r` is given and differs from r.
    """
    path = Path(path)
    if not path.is_file():
        raise CheckpointError(path, "no such checkpoint file")
    try:
        raw = torch.load(path, map_location="cpu", weights_only=True)
    except Exception as exc:  # torch raises several types for truncated or foreign files
        raise CheckpointError(path, f"not a readable checkpoint ({type(exc).__name__}: {exc})") from exc
    if not isinstance(raw, dict):
        raise CheckpointError(path, f"not a checkpoint: holds a {type(raw).__name__}, not a dict")
    missing = [key for key in _CHECKPOINT_KEYS if key not in raw]
    if missing:
        raise CheckpointError(path, f"incomplete checkpoint: missing keys {missing}")
    if raw["format"] != CHECKPOINT_FORMAT:
        raise CheckpointError(path, f"format {raw['format']!r}, expected {CHECKPOINT_FORMAT!r}")
    try:
        ckpt = Checkpoint(**{key: raw[key] for key in _CHECKPOINT_KEYS if key != "format"})
        ckpt.field()
        ckpt.encoder()
    except Exception as exc:
        raise CheckpointError(path, f"inconsistent checkpoint ({type(exc).__name__}: {exc})") from exc
    if expected_r is not None and ckpt.r != expected_r:
        raise CheckpointError(path, f"model has r = {ckpt.r}, expected r = {expected_r}")
    return ckpt


@dataclass(frozen=True)
class TrainSettings:
    """How a LiCROM model is trained (validated on construction).

    r: total basis columns (affine: r >= 13, the network learns r - 12); epochs: passes over all frames;
    affine: prepend the 12 exact affine columns; seed: seeds python, numpy and torch (init, shuffling, point
    subsampling); batch: frames per step; points: points subsampled per frame (all if the frame has fewer);
    lr: Adam rate; width, depth: field MLP; schedule: "constant" or "cosine"; n_ref: reference points of the
    affine orthogonalisation (all points if fewer; a seeded subset otherwise).
    """

    r: int
    epochs: int
    affine: bool = False
    seed: int = 0
    batch: int = 16
    points: int = 1024
    lr: float = 1e-3
    width: int = 60
    depth: int = 5
    schedule: str = "constant"
    n_ref: int = 4096

    def __post_init__(self) -> None:
        if self.epochs < 1 or self.batch < 1 or self.points < 1 or self.n_ref < 4 or self.lr <= 0:
            raise ValueError(f"need epochs, batch, points >= 1, n_ref >= 4, lr > 0 (got {self.epochs}, {self.batch}, "
                             f"{self.points}, {self.n_ref}, {self.lr})")
        if self.affine and self.r <= N_AFFINE:
            raise ValueError(f"r = {self.r}: the affine variant needs r >= {N_AFFINE + 1} "
                             "(r counts the 12 affine columns)")
        if self.r < 1:
            raise ValueError(f"r = {self.r}: need r >= 1")
        if self.schedule not in SCHEDULES:
            raise ValueError(f"schedule = {self.schedule!r}: expected one of {SCHEDULES}")


def train(data: TrainingData, settings: TrainSettings, device: str = "cpu", progress: bool = True,
          identity: dict | None = None) -> Checkpoint:
    """Train encoder and neural field on `data` with `settings`; returns the checkpoint (not yet saved).

    device: "cpu" or "cuda"; progress: tqdm bar over epochs; identity: training identity stored in the
    checkpoint. Deterministic algorithms are enabled during training, so a seed reproduces a run on the same
    device and thread count (torch's, recorded as config["threads"]: a run pinned to fewer cores trains on fewer
    threads, and its network differs).
    """
    st = settings
    dev = torch.device(device)
    if dev.type == "cuda" and not torch.cuda.is_available():
        raise ValueError("device = 'cuda' but torch sees no CUDA device")

    X64, u64, w64 = data.X.double(), data.u.double(), data.weights.double()
    X_mean = X64.mean(dim=0).float().double()  # rounded to float32: the field's buffers hold exactly these
    X_scale = float(torch.sqrt(((X64 - X_mean) ** 2).mean()).float())
    u_scale = float(torch.sqrt((u64 ** 2).mean()))
    if u_scale == 0.0:
        raise ValueError("the training displacements are all zero: nothing to learn")
    Xhat64 = (X64 - X_mean) / X_scale
    target = fit_affine(Xhat64, u64, w64)[1] if st.affine else u64
    fit_scale = max(float(torch.sqrt((target ** 2).mean())), _FIT_SCALE_FLOOR * u_scale)

    _seed_everything(st.seed)
    generator = torch.Generator().manual_seed(st.seed)
    ref = (torch.randperm(data.n_points, generator=generator)[:st.n_ref].sort().values if st.affine
           else torch.zeros(0, dtype=torch.long))
    field_net = NeuralField(
        st.r, st.width, st.depth, st.affine, X_mean=X_mean.float(), X_scale=X_scale,
        ref_X=data.X[ref], ref_w=data.weights[ref],
    ).to(dev)
    encoder = PointNetEncoder(field_net.n_neural).to(dev)
    optimizer = torch.optim.Adam([*encoder.parameters(), *field_net.parameters()], lr=st.lr)
    scheduler = (torch.optim.lr_scheduler.CosineAnnealingLR(optimizer, T_max=st.epochs, eta_min=st.lr / 100)
                 if st.schedule == "cosine" else None)

    X_dev = data.X.to(dev)
    Xhat_dev = Xhat64.float().to(dev)
    target_dev = (target / fit_scale).float().to(dev)
    n_points = min(st.points, data.n_points)
    history: list[float] = []
    start = time.perf_counter()
    with _deterministic_algorithms():
        encoder.train()
        bar = tqdm(range(st.epochs), desc=f"LiCROM r={st.r}{' affine' if st.affine else ''}", unit="epoch",
                   disable=not progress)
        for _ in bar:
            order = torch.randperm(data.n_frames, generator=generator)
            total = 0.0
            for first in range(0, data.n_frames, st.batch):
                frames = order[first:first + st.batch]
                subset = torch.rand(len(frames), data.n_points, generator=generator).argsort(dim=1)[:, :n_points]
                loss = _batch_loss(encoder, field_net, X_dev, Xhat_dev, target_dev, frames.to(dev), subset.to(dev))
                optimizer.zero_grad(set_to_none=True)
                loss.backward()
                optimizer.step()
                total += loss.item() * len(frames)
            history.append(total / data.n_frames)
            bar.set_postfix(loss=f"{history[-1]:.3e}")
            if scheduler is not None:
                scheduler.step()
    train_seconds = time.perf_counter() - start

    return Checkpoint(
        arch={"r": st.r, "width": st.width, "depth": st.depth, "affine": st.affine, "n_ref": int(ref.numel())},
        norm={"X_mean": X_mean.tolist(), "X_scale": X_scale, "u_scale": u_scale, "fit_scale": fit_scale},
        encoder_state=_cpu_state(encoder), field_state=_cpu_state(field_net),
        identity=_plain(identity or {}), loss_history=history, seed=st.seed, train_seconds=train_seconds,
        config={"epochs": st.epochs, "batch": st.batch, "points": st.points, "lr": st.lr, "schedule": st.schedule,
                "device": str(dev), "threads": torch.get_num_threads(), "n_frames": data.n_frames,
                "n_points": data.n_points},
        versions=_versions(),
    )


def _batch_loss(
    encoder: PointNetEncoder, field_net: NeuralField, X: torch.Tensor, Xhat: torch.Tensor, target: torch.Tensor,
    frames: torch.Tensor, subset: torch.Tensor,
) -> torch.Tensor:
    """Mean squared error of W_nn q against the target on the subsampled points of a batch.

    X, Xhat: (n, 3) rest positions [m] and standardised; target: (F, n, 3) in fit_scale units;
    frames: (B,) frame indices; subset: (B, P) point indices per frame.
    """
    B, P = subset.shape
    points = target[frames[:, None], subset]  # (B, P, 3)
    q = encoder(torch.cat([Xhat[subset], points], dim=2))  # (B, k)
    W = field_net(X[subset].reshape(-1, 3)).view(B, P, 3, field_net.r)[..., field_net.r - field_net.n_neural:]
    return torch.mean((torch.einsum("bpcj,bj->bpc", W, q) - points) ** 2)


def evaluate_basis(ckpt: Checkpoint, X: np.ndarray, chunk: int = 65536) -> np.ndarray:
    """The basis W (n, 3, r) [-] at any rest points X (n, 3) [m] (float64 evaluation, no grad, CPU)."""
    X = np.array(X, dtype=np.float64)  # a writable copy: torch.from_numpy shares memory
    if X.ndim != 2 or X.shape[1] != 3:
        raise ValueError(f"X has shape {X.shape}: expected (n, 3)")
    field_net = ckpt.field().double()
    with torch.no_grad():
        Xt = torch.from_numpy(X)
        parts = [field_net(Xt[i:i + chunk]) for i in range(0, X.shape[0], chunk)]
    return torch.cat(parts).numpy() if parts else np.zeros((0, 3, ckpt.r))


def encode(ckpt: Checkpoint, X: np.ndarray, u: np.ndarray, weights: np.ndarray | None = None) -> np.ndarray:
    """Latent code q (r,) [m] of one frame: rest points X (n, 3) [m], displacements u (n, 3) [m].

    The encoder sees all n points. Affine variant: the affine coordinates are the weighted least-squares fit
    (weights (n,), default uniform) and the encoder sees the residual.
    """
    X = np.asarray(X, dtype=np.float64)
    u = np.asarray(u, dtype=np.float64)
    if X.ndim != 2 or X.shape[1] != 3 or u.shape != X.shape:
        raise ValueError(f"X {X.shape} and u {u.shape}: expected both (n, 3)")
    w = np.ones(X.shape[0]) if weights is None else np.asarray(weights, dtype=np.float64)
    return _encode_frames(ckpt, ckpt.encoder(), torch.from_numpy(X), torch.from_numpy(u)[None],
                          torch.from_numpy(w))[0].numpy()


def _encode_frames(
    ckpt: Checkpoint, encoder: PointNetEncoder, X: torch.Tensor, u: torch.Tensor, weights: torch.Tensor,
    chunk: int = 16,
) -> torch.Tensor:
    """Latent codes (F, r) float64 [m] of frames u (F, n, 3) [m] on points X (n, 3) [m], weights (n,)."""
    Xhat = (X - torch.tensor(ckpt.norm["X_mean"], dtype=torch.float64)) / ckpt.norm["X_scale"]
    fit_scale = float(ckpt.norm["fit_scale"])
    if ckpt.arch["affine"]:
        q_affine, u = fit_affine(Xhat, u, weights)
    codes = []
    with torch.no_grad():
        for i in range(0, u.shape[0], chunk):
            frames = u[i:i + chunk]
            inputs = torch.cat([Xhat.expand(frames.shape[0], -1, -1), frames / fit_scale], dim=2).float()
            codes.append(encoder(inputs).double() * fit_scale)
    q = torch.cat(codes)
    return torch.cat([q_affine, q], dim=1) if ckpt.arch["affine"] else q


def reconstruction_error(ckpt: Checkpoint, data: TrainingData) -> float:
    """Relative RMS error sqrt(sum |W q_enc - u|^2 / sum |u|^2) over all frames and points of `data`.

    q_enc = encoder code of each frame (all points), as in `encode` with the data's weights.
    """
    W = torch.from_numpy(evaluate_basis(ckpt, data.X.double().numpy()))
    u = data.u.double()
    q = _encode_frames(ckpt, ckpt.encoder(), data.X.double(), u, data.weights.double())
    squared_error = sum(float(((torch.einsum("ncj,fj->fnc", W, q[i:i + 16]) - u[i:i + 16]) ** 2).sum())
                        for i in range(0, data.n_frames, 16))
    return float(np.sqrt(squared_error / float((u ** 2).sum())))


def projection_error(ckpt: Checkpoint, data: TrainingData) -> float:
    """Relative RMS error of the best (weighted least-squares) q per frame: the subspace's own limit.

    This is the error a perfect encoder would leave; the online solver never uses the encoder.
    """
    W = evaluate_basis(ckpt, data.X.double().numpy())
    u = data.u.double().numpy()
    q = project(W, u, data.weights.double().numpy())  # (F, r)
    return float(np.linalg.norm(np.einsum("ncr,fr->fnc", W, q) - u) / np.linalg.norm(u))


def train_from_trajectories(paths: Sequence[str | os.PathLike], out: str | os.PathLike, settings: TrainSettings,
                            device: str = "cpu", progress: bool = True, identity: dict | None = None) -> Path:
    """Train on the trajectory files `paths` (.npz) as `train` does; write out/model.pt, out/loss.csv,
    out/loss.png.

    loss.png is skipped (with a log message) when matplotlib is not installed. Returns the path of model.pt.
    """
    data = TrainingData.from_trajectories([Trajectory.load(p) for p in paths])
    ckpt = train(data, settings, device, progress, identity)
    ckpt.config["sources"] = [Path(p).name for p in paths]
    out = Path(out)
    model = ckpt.save(out / "model.pt")
    write_loss_csv(ckpt.loss_history, out / "loss.csv")
    plot_loss(ckpt, out / "loss.png")
    return model


def write_loss_csv(history: Sequence[float], path: Path) -> Path:
    """Write `epoch,loss` rows (epochs from 1) to `path` atomically."""
    with atomic_open(path, "w") as f:
        writer = csv.writer(f, lineterminator="\n")
        writer.writerow(["epoch", "loss"])
        writer.writerows((epoch, repr(float(loss))) for epoch, loss in enumerate(history, start=1))
    return path


def plot_loss(ckpt: Checkpoint, path: Path) -> Path | None:
    """Plot the loss history (log scale) to `path` (PNG); returns None, with a log note, without matplotlib."""
    try:
        from matplotlib.figure import Figure
    except ImportError:
        log.warning("matplotlib is not installed: skipping %s", path)
        return None
    figure = Figure(figsize=(6, 4), dpi=100)
    axes = figure.add_subplot()
    axes.semilogy(range(1, len(ckpt.loss_history) + 1), ckpt.loss_history)
    axes.set_xlabel("epoch")
    axes.set_ylabel("training loss [fit_scale$^2$]")
    axes.set_title(f"LiCROM r = {ckpt.r}{' (affine)' if ckpt.arch['affine'] else ''}")
    axes.grid(True, which="both", alpha=0.3)
    figure.tight_layout()
    with atomic_open(path, "wb") as f:
        figure.savefig(f, format="png")
    return path


def _seed_everything(seed: int) -> None:
    """Seed python's, numpy's and torch's global generators."""
    random.seed(seed)
    np.random.seed(seed)
    torch.manual_seed(seed)


@contextmanager
def _deterministic_algorithms() -> Iterator[None]:
    """Enable torch's deterministic algorithms (warning where none exists) and restore the previous mode."""
    previous = torch.are_deterministic_algorithms_enabled(), torch.is_deterministic_algorithms_warn_only_enabled()
    os.environ.setdefault("CUBLAS_WORKSPACE_CONFIG", ":4096:8")  # needed by deterministic cuBLAS
    torch.use_deterministic_algorithms(True, warn_only=True)
    try:
        yield
    finally:
        torch.use_deterministic_algorithms(previous[0], warn_only=previous[1])


def _cpu_state(module: torch.nn.Module) -> dict[str, torch.Tensor]:
    """A module's state dict as a plain dict of detached CPU tensors."""
    return {key: value.detach().cpu().clone() for key, value in module.state_dict().items()}


def _plain(obj: dict) -> dict:
    """JSON round trip, so only plain types reach the checkpoint.

    numpy values become numbers and lists; any other non-JSON value is stored as its str().
    """
    return json.loads(json.dumps(obj, default=lambda o: o.tolist() if hasattr(o, "tolist") else str(o)))


def _versions() -> dict[str, str]:
    """Versions of the packages that produced a checkpoint."""
    try:
        frictionbench = importlib.metadata.version("frictionbench")
    except importlib.metadata.PackageNotFoundError:
        frictionbench = "unknown"
    return {"frictionbench": frictionbench, "torch": str(torch.__version__), "numpy": np.__version__,
            "python": platform.python_version()}

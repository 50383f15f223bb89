"""Offline LiCROM training on small synthetic data sets (seconds each, one thread)."""

from __future__ import annotations

import numpy as np
import pytest
import torch

from frictionbench.solvers.licrom.train import (
    CheckpointError, TrainingData, encode, evaluate_basis, load_checkpoint, projection_error,
    TrainSettings, reconstruction_error, train, train_from_trajectories,
)
from frictionbench.solvers.reduced.bases import N_AFFINE, affine_fields, project
from frictionbench.solvers.trajectory import Trajectory

BOX = np.array([1.0, 0.5, 0.3])  # [m]
# Measured with these settings (r = 6, 60 epochs, 64 points per frame, training seeds 0-7, one thread):
# first-epoch loss / mean of the last 5 epochs 24-40; relative reconstruction error 0.12-0.17 with the encoder,
# 0.10-0.12 with the best q (projection), 0.11-0.13 projected on a new point set. An untrained model gives 1.0.
MIN_LOSS_DROP = 10.0
MAX_RECONSTRUCTION_ERROR = 0.3


@pytest.fixture(scope="module", autouse=True)
def one_thread():
    """One torch thread for the whole module (set before the module-scoped trainings run)."""
    threads = torch.get_num_threads()
    torch.set_num_threads(1)
    yield
    torch.set_num_threads(threads)


def sample_box(n: int, seed: int) -> np.ndarray:
    """n points (n, 3) [m] uniformly in the box [0, BOX]."""
    return np.random.default_rng(seed).uniform(0.0, BOX, size=(n, 3))


def smooth_modes(X: np.ndarray) -> np.ndarray:
    """Four smooth displacement modes (4, n, 3) [m per unit coefficient] at points X (n, 3)."""
    x, y, z = X.T
    zero = np.zeros_like(x)
    return np.stack([
        np.stack([np.sin(np.pi * x), zero, zero], axis=1),
        np.stack([zero, np.sin(np.pi * x) * y, zero], axis=1),
        np.stack([zero, zero, np.cos(np.pi * x) * z], axis=1),
        np.stack([x * y, np.sin(2 * np.pi * y), x * z], axis=1),
    ])


def mode_coefficients(frames: int, seed: int) -> np.ndarray:
    """Random mode coefficients (frames, 4)."""
    return 0.05 * np.random.default_rng(seed).normal(size=(frames, 4))


def rotation(rng: np.random.Generator) -> np.ndarray:
    """A uniformly random rotation matrix (3, 3)."""
    q, r = np.linalg.qr(rng.normal(size=(3, 3)))
    q = q * np.sign(np.diag(r))
    return q if np.linalg.det(q) > 0 else -q


@pytest.fixture(scope="module")
def modes_data() -> TrainingData:
    X = sample_box(200, seed=1)
    return TrainingData.from_arrays(X, np.einsum("fm,mnc->fnc", mode_coefficients(32, seed=2), smooth_modes(X)))


def train_modes(data: TrainingData, seed: int = 0):
    return train(data, TrainSettings(r=6, epochs=60, seed=seed, points=64), progress=False)


@pytest.fixture(scope="module")
def modes_model(modes_data):
    return train_modes(modes_data)


def test_training_reduces_loss_and_reconstructs(modes_data, modes_model):
    history = modes_model.loss_history
    assert len(history) == 60
    assert history[0] / np.mean(history[-5:]) > MIN_LOSS_DROP
    assert reconstruction_error(modes_model, modes_data) < MAX_RECONSTRUCTION_ERROR
    assert projection_error(modes_model, modes_data) < MAX_RECONSTRUCTION_ERROR


def test_untrained_model_fails_the_accuracy_threshold(modes_data):
    model = train(modes_data, TrainSettings(r=6, epochs=1, points=16, batch=32), progress=False)
    assert reconstruction_error(model, modes_data) > MAX_RECONSTRUCTION_ERROR


def test_same_seed_same_model(modes_data, modes_model):
    again = train_modes(modes_data)
    assert again.loss_history == modes_model.loss_history
    for key, value in modes_model.field_state.items():
        assert torch.equal(value, again.field_state[key]), key
    for key, value in modes_model.encoder_state.items():
        assert torch.equal(value, again.encoder_state[key]), key


def test_basis_on_another_sampling_of_the_shape(modes_model):
    X = sample_box(300, seed=7)  # a different point set of the same box
    W = evaluate_basis(modes_model, X)
    assert W.shape == (300, 3, 6) and W.dtype == np.float64 and np.isfinite(W).all()
    u = np.einsum("fm,mnc->fnc", mode_coefficients(8, seed=8), smooth_modes(X))
    assert projection_error(modes_model, TrainingData.from_arrays(X, u)) < MAX_RECONSTRUCTION_ERROR
    q = encode(modes_model, X, u[0])
    assert q.shape == (6,) and q.dtype == np.float64


def test_project_recovers_coefficients_with_and_without_mass():
    rng = np.random.default_rng(0)
    W = rng.normal(size=(50, 3, 4))
    q = rng.normal(size=4)
    u = np.einsum("ncj,j->nc", W, q)
    np.testing.assert_allclose(project(W, u), q, rtol=1e-10)
    np.testing.assert_allclose(project(W, u, mass=rng.uniform(0.5, 2.0, size=50)), q, rtol=1e-10)
    np.testing.assert_allclose(project(W, np.stack([u, -2.0 * u])), np.stack([q, -2.0 * q]), rtol=1e-10)  # frames
    u_noisy = u + 0.1 * rng.normal(size=u.shape)
    heavy = np.where(np.arange(50) < 10, 1e6, 1.0)  # the heavy points dominate the weighted fit
    q_heavy = project(W, u_noisy, mass=heavy)
    np.testing.assert_allclose(q_heavy, project(W[:10], u_noisy[:10]), rtol=1e-3)


def test_save_load_gives_identical_basis(tmp_path, modes_model):
    path = modes_model.save(tmp_path / "model.pt")
    loaded = load_checkpoint(path, expected_r=6)
    X = sample_box(100, seed=3)
    np.testing.assert_array_equal(evaluate_basis(loaded, X), evaluate_basis(modes_model, X))
    assert loaded.loss_history == modes_model.loss_history
    assert loaded.norm == modes_model.norm and loaded.arch == modes_model.arch
    assert not list(tmp_path.glob(".*.tmp"))  # the temporary file was renamed into place


def test_checkpoint_errors_name_the_path(tmp_path, modes_model):
    missing = tmp_path / "missing.pt"
    with pytest.raises(CheckpointError, match="missing.pt"):
        load_checkpoint(missing)

    good = modes_model.save(tmp_path / "good.pt")
    truncated = tmp_path / "truncated.pt"
    truncated.write_bytes(good.read_bytes()[: good.stat().st_size // 2])
    with pytest.raises(CheckpointError, match="truncated.pt"):
        load_checkpoint(truncated)

    foreign = tmp_path / "foreign.pt"
    foreign.write_text("not a torch file")
    with pytest.raises(CheckpointError, match="foreign.pt"):
        load_checkpoint(foreign)

    incomplete = tmp_path / "incomplete.pt"
    raw = modes_model.to_dict()
    del raw["field_state"]
    torch.save(raw, incomplete)
    with pytest.raises(CheckpointError, match="incomplete.pt.*field_state"):
        load_checkpoint(incomplete)

    with pytest.raises(CheckpointError, match=r"good.pt.*r = 6, expected r = 8"):
        load_checkpoint(good, expected_r=8)
    assert issubclass(CheckpointError, ValueError)


def test_affine_variant_reproduces_rigid_motion_exactly():
    rng = np.random.default_rng(4)
    X = sample_box(150, seed=5)
    x = np.stack([X @ rotation(rng).T + rng.normal(scale=0.5, size=3) for _ in range(24)])
    data = TrainingData.from_arrays(X, x - X)
    model = train(data, TrainSettings(r=14, epochs=2, affine=True, points=32), progress=False)
    assert reconstruction_error(model, data) < 1e-3
    plain = train(data, TrainSettings(r=14, epochs=2, points=32), progress=False)
    assert reconstruction_error(plain, data) > 0.1  # the same budget without affine columns does not


def test_affine_columns_are_exact_and_neural_columns_orthogonal(modes_data):
    weights = np.random.default_rng(6).uniform(0.5, 1.5, size=modes_data.n_points)
    data = TrainingData.from_arrays(modes_data.X.double().numpy(), modes_data.u.double().numpy(), weights)
    model = train(data, TrainSettings(r=15, epochs=2, affine=True, points=32), progress=False)
    X = data.X.double().numpy()
    W = evaluate_basis(model, X)
    Xhat = (X - np.array(model.norm["X_mean"])) / model.norm["X_scale"]
    np.testing.assert_allclose(W[:, :, :N_AFFINE], affine_fields(torch.from_numpy(Xhat)).numpy(), atol=1e-12)
    w = data.weights.double().numpy()
    cross = np.einsum("n,nci,ncj->ij", w, W[:, :, :N_AFFINE], W[:, :, N_AFFINE:])  # reference = all points
    assert np.abs(cross).max() < 1e-9 * np.abs(W[:, :, N_AFFINE:]).max() * w.sum()
    q = encode(model, X, data.u[0].double().numpy(), weights=w)
    assert q.shape == (15,)


def test_invalid_training_arguments_are_rejected(modes_data):
    with pytest.raises(ValueError, match="r >= 13"):
        TrainSettings(r=12, epochs=1, affine=True)
    with pytest.raises(ValueError, match="schedule"):
        TrainSettings(r=4, epochs=1, schedule="linear")
    with pytest.raises(ValueError, match="all zero"):
        train(TrainingData.from_arrays(modes_data.X.numpy(), np.zeros((2, 200, 3))), TrainSettings(r=4, epochs=1),
              progress=False)


def test_training_data_rejects_different_rest_meshes():
    X = sample_box(20, seed=0)
    tets = np.array([[0, 1, 2, 3]])
    a = Trajectory(t=np.zeros(2), x=np.stack([X, X + 0.01]), X=X, tets=tets, surface=np.zeros((0, 3), int),
                   meta={"scenario": "a"})
    b = Trajectory(t=np.zeros(2), x=np.stack([X, X]), X=X + 1e-3, tets=tets, surface=np.zeros((0, 3), int),
                   meta={"scenario": "b"})
    with pytest.raises(ValueError, match="rest mesh"):
        TrainingData.from_trajectories([a, b])
    data = TrainingData.from_trajectories([a, a])
    assert data.u.shape == (4, 20, 3) and data.u.dtype == torch.float32
    assert data.weights.shape == (20,) and torch.isclose(data.weights.mean(), torch.tensor(1.0))


def test_train_from_trajectories_writes_model_and_loss(tmp_path):
    X = sample_box(60, seed=0)
    u = np.einsum("fm,mnc->fnc", mode_coefficients(6, seed=1), smooth_modes(X))
    tets = np.array([[0, 1, 2, 3], [1, 2, 3, 4]])
    path = Trajectory(t=np.arange(6.0), x=X + u, X=X, tets=tets, surface=np.zeros((0, 3), int)).save(
        tmp_path / "run.npz")
    identity = {"suite": "synthetic", "scenario_hashes": ["abc"], "bbox_diagonal": np.float64(1.16)}
    model = train_from_trajectories([str(path)], tmp_path / "out", TrainSettings(r=3, epochs=3, points=16,
                                    schedule="cosine"), identity=identity, progress=False)
    assert model == tmp_path / "out" / "model.pt"
    ckpt = load_checkpoint(model, expected_r=3)
    assert ckpt.config["schedule"] == "cosine" and ckpt.config["sources"] == ["run.npz"]
    assert ckpt.config["threads"] == torch.get_num_threads()  # what reproducing it needs besides the seed
    assert ckpt.identity == {"suite": "synthetic", "scenario_hashes": ["abc"], "bbox_diagonal": 1.16}
    lines = (tmp_path / "out" / "loss.csv").read_text().splitlines()
    assert lines[0] == "epoch,loss" and len(lines) == 4
    assert [float(line.split(",")[1]) for line in lines[1:]] == ckpt.loss_history
    pytest.importorskip("matplotlib")
    assert (tmp_path / "out" / "loss.png").read_bytes()[:8] == b"\x89PNG\r\n\x1a\n"


def test_affine_fields_are_one_function_for_numpy_and_torch():
    Xhat = np.random.default_rng(3).standard_normal((7, 3))
    A = affine_fields(Xhat)
    t = torch.from_numpy(Xhat).requires_grad_(True)
    A_torch = affine_fields(t)
    np.testing.assert_array_equal(A, A_torch.detach().numpy())
    q = np.arange(1.0, 13.0)
    L = q.reshape(3, 4)  # row c: (b_c, L_c0, L_c1, L_c2)
    np.testing.assert_allclose(A @ q, L[:, 0] + Xhat @ L[:, 1:].T, rtol=1e-14)  # the affine map of Xhat
    A_torch.sum().backward()  # differentiable in torch: each Xhat_j stands in 3 columns (one per component c)
    np.testing.assert_array_equal(t.grad.numpy(), np.full((7, 3), 3.0))

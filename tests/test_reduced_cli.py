"""Reduced solvers end to end: `frictionbench train`, simulate with a checkpoint on the training mesh and on
another mesh of the shape, POD carried to another mesh, and the clear errors (corrupt checkpoint, wrong r,
POD on a mesh of another shape)."""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest

from frictionbench.bench.cli import main, resolve_scenario
from frictionbench.scenarios.meshes import load_mesh
from frictionbench.scenarios.spec import MeshSpec
from frictionbench.solvers.build import build_model, initial_state
from frictionbench.solvers.licrom.plugin import Licrom
from frictionbench.solvers.licrom.train import CheckpointError
from frictionbench.solvers.reduced.pod import Pod
from frictionbench.solvers.simulate import simulate
from frictionbench.solvers.trajectory import Trajectory

from scenes import block_drop, mu_axis, suite_tables, write_toml

SUITE = suite_tables("tinytrain", block_drop(clearance=0.02, duration=0.15, material={"youngs_modulus": 1.0e5}),
                     mu_axis(0.2, 0.6), description="block drops for training")


@pytest.fixture(scope="module")
def trained(tmp_path_factory) -> tuple[Path, Path]:
    root = tmp_path_factory.mktemp("train")
    suite = write_toml(root / "tinytrain.toml", SUITE)
    out = root / "model"
    assert main(["train", "--suite", str(suite), "--r", "14", "--epochs", "3", "--affine", "--points", "64",
                 "--out", str(out)]) == 0
    return suite, out


def test_train_writes_checkpoint_and_loss(trained):
    _, out = trained
    assert (out / "model.pt").is_file() and (out / "loss.csv").read_text().count("\n") >= 4


def test_simulate_with_checkpoint_on_training_and_other_mesh(trained, tmp_path):
    suite, out = trained
    scenario = str(write_toml(suite.parent / "one.toml", {"name": "one"} | block_drop(clearance=0.02)))
    for mesh, folder in ((None, "same"), ("block/coarse_alt", "other")):
        argv = ["simulate", scenario, "--solver", "licrom", "--model", str(out / "model.pt"), "--no-vtu", "-q",
                "--out", str(tmp_path / folder)]
        assert main(argv + (["--mesh", mesh] if mesh else [])) == 0
    same = Trajectory.load(tmp_path / "same" / "trajectory.npz")
    other = Trajectory.load(tmp_path / "other" / "trajectory.npz")
    assert same.q.shape == (6, 14) and other.q.shape == (6, 14)
    assert same.X.shape != other.X.shape  # really another mesh
    # both fall under gravity the same way (the affine columns carry the rigid motion exactly)
    drop = lambda t: t.x[-1, :, 1].mean() - t.x[0, :, 1].mean()  # noqa: E731
    assert drop(same) == pytest.approx(drop(other), rel=1e-3)


def test_corrupt_checkpoint_and_wrong_r_fail_clearly(trained, tmp_path, capsys):
    suite, out = trained
    bad = tmp_path / "bad.pt"
    bad.write_bytes(b"not a checkpoint")
    code = main(["simulate", "verify/block_fall", "--solver", "licrom", "--model", str(bad), "--no-vtu", "-q",
                 "--out", str(tmp_path / "x")])
    assert code == 2 and str(bad) in capsys.readouterr().err
    model = build_model(resolve_scenario("verify/block_fall"), load_mesh(MeshSpec("block", "coarse")))
    with pytest.raises(CheckpointError, match="r"):
        Licrom(checkpoint=str(out / "model.pt"), r=20).setup(model)


def test_pod_carries_its_modes_to_another_mesh_of_the_shape(trained, tmp_path):
    """POD's modes, piecewise linear on the training mesh, are interpolated at another mesh's vertices: the affine
    columns stay affine there, the run falls under gravity as on the training mesh, and a mesh of another shape is
    skipped with the reason."""
    _, out = trained
    runs = sorted((out / "runs").glob("*/trajectory.npz"))
    params = Pod(r=14, affine=True).prepare("block", runs, tmp_path, "tinytrain")
    assert params["shape"] == "block" and Path(params["basis"]).is_relative_to(tmp_path)
    sc = resolve_scenario("verify/block_fall")
    same = build_model(sc, load_mesh(MeshSpec("block", "coarse")))
    other = build_model(sc, load_mesh(MeshSpec("block", "coarse_alt")))
    stored = np.load(params["basis"])
    assert set(stored.files) == {"W", "X", "tets"} and np.isfinite(stored["W"]).all()
    pods = {}
    for name, model in (("same", same), ("other", other)):
        pod = Pod(r=14, affine=True, **params)
        assert pod.skip(model) is None
        pod.setup(model)
        assert pod.basis.shape == (model.n, 3, 14)
        pods[name] = pod
    assert "basis_mesh" not in pods["same"].describe()
    assert "interpolated" in pods["other"].describe()["basis_mesh"]
    # the affine columns (the first 12, fields of the training mesh's standardised positions) are linear in X: their
    # interpolation at the other mesh's vertices inside the training mesh is exact
    W_same, W_other = pods["same"].basis[:, :, :12], pods["other"].basis[:, :, :12]
    fit = np.linalg.lstsq(np.c_[same.X, np.ones(same.n)], W_same.reshape(same.n, -1), rcond=None)[0]
    assert np.allclose(np.c_[other.X, np.ones(other.n)] @ fit, W_other.reshape(other.n, -1), atol=1e-9)
    drop = {}
    for name, model in (("same", same), ("other", other)):
        traj, _ = simulate(model, pods[name], pods[name].initial(initial_state(model)))
        drop[name] = traj.x[-1, :, 1].mean() - traj.x[0, :, 1].mean()
    assert drop["same"] < 0 and drop["same"] == pytest.approx(drop["other"], rel=1e-3)
    # an optimised cubature is selected again on the other mesh from the stored latent training states, once
    params = Pod(r=14, affine=True, cubature="optimized:20").prepare("block", runs, tmp_path, "tinytrain")
    folder = Path(params["cubature_file"]).parent
    assert np.load(folder / "training_states.npy", allow_pickle=False).shape[1] == 14
    infos = []
    for _ in range(2):
        pod = Pod(r=14, affine=True, cubature="optimized:20", **params)
        pod.setup(other)
        infos.append(pod.describe())
    assert len(list(folder.glob("cubature_optimized_20_mesh-*.json"))) == 1
    assert infos[0] == infos[1] and infos[0]["cubature_used"] == "optimized:20"
    assert infos[0]["cubature_mesh"] == "selected on this mesh from the training states"
    assert 1 <= infos[0]["cubature_count"] <= 20 and pod.solver.reduced.cub_ids.max() < len(other.tets)
    sphere = build_model(sc, load_mesh(MeshSpec("sphere", "coarse")))
    reason = Pod(r=14, affine=True, **params).skip(sphere)
    assert "vertex" in reason and "not a mesh of the same shape" in reason


def test_pod_stored_without_tets_gets_them_and_is_otherwise_refused_elsewhere(trained, tmp_path):
    """A basis file stored before the training mesh's tets were kept: on another mesh the run is skipped saying why;
    preparing again adds the tets and leaves the modes bitwise as they were."""
    _, out = trained
    runs = sorted((out / "runs").glob("*/trajectory.npz"))
    params = Pod(r=6).prepare("block", runs, tmp_path, "tinytrain")
    with np.load(params["basis"]) as z:
        W, X = z["W"], z["X"]
    np.savez_compressed(params["basis"], W=W, X=X)  # as stored before
    other = build_model(resolve_scenario("verify/block_fall"), load_mesh(MeshSpec("block", "coarse_alt")))
    assert "without its training mesh's tets" in Pod(r=6, **params).skip(other)
    assert Pod(r=6).prepare("block", runs, tmp_path, "tinytrain") == params
    with np.load(params["basis"]) as z:
        assert np.array_equal(z["W"], W) and np.array_equal(z["tets"], Trajectory.load(runs[0]).tets)
    assert Pod(r=6, **params).skip(other) is None


def test_pod_selects_an_optimised_cubature_on_its_training_mesh(trained, tmp_path):
    """`cubature = "optimized:N"` gives POD a cubature selected from its training states, stored once beside the
    basis and used by the solver (not the uniform fallback of a reduced model without one)."""
    _, out = trained
    runs = sorted((out / "runs").glob("*/trajectory.npz"))
    params = Pod(r=14, affine=True, cubature="optimized:20").prepare("block", runs, tmp_path, "tinytrain")
    path = Path(params["cubature_file"])
    assert path.parent == Path(params["basis"]).parent
    stamp = path.stat().st_mtime_ns
    assert Pod(r=14, affine=True, cubature="optimized:20").prepare("block", runs, tmp_path, "tinytrain") == params
    assert path.stat().st_mtime_ns == stamp  # selected once
    model = build_model(resolve_scenario("verify/block_fall"), load_mesh(MeshSpec("block", "coarse")))
    pod = Pod(r=6, affine=True, cubature="optimized:20", **params)
    pod.setup(model)
    info = pod.describe()
    assert info["cubature_used"] == "optimized:20" and 1 <= info["cubature_count"] <= 20
    ids = pod.solver.reduced.cub_ids
    assert ids.size == info["cubature_count"] and (pod.solver.reduced.wV > 0).all()
    assert "cubature_file" not in Pod(r=6).prepare("block", runs, tmp_path, "tinytrain")

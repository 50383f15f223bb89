"""Shared fixtures. Small dense linear algebra runs single-threaded in tests: BLAS threads on a busy 2-core
machine slow the reduced solver's r x r operations by an order of magnitude. Hypothesis draws its examples from a
fixed seed (`derandomize`) and keeps no example database, so that every run, CI's included, tests the same inputs;
`HYPOTHESIS_PROFILE=explore` draws fresh ones (and keeps the failures it finds) to search for new cases."""

from __future__ import annotations

import os
from pathlib import Path

import pytest
from hypothesis import settings
from threadpoolctl import threadpool_limits

from frictionbench.scenarios.meshes import load_mesh
from frictionbench.scenarios.spec import MeshSpec

settings.register_profile("deterministic", derandomize=True, database=None)
settings.register_profile("explore")
settings.load_profile(os.environ.get("HYPOTHESIS_PROFILE", "deterministic"))
threadpool_limits(1)


@pytest.fixture(autouse=True)
def private_truth_store(tmp_path_factory: pytest.TempPathFactory, monkeypatch: pytest.MonkeyPatch) -> Path:
    """Every test has a truth store of its own (`bench.store.TruthStore`), empty at its start: no test reads truths
    another test or an earlier session left, and none writes the user's; returns its folder."""
    root = tmp_path_factory.mktemp("truths")
    monkeypatch.setenv("FRICTIONBENCH_TRUTH_STORE", str(root))
    return root


@pytest.fixture(scope="session")
def block():
    """The coarse structured block (0.2 x 0.1 x 0.2 m)."""
    return load_mesh(MeshSpec(name="block", resolution="coarse"))


@pytest.fixture
def licrom_trainings(monkeypatch) -> list[dict]:
    """LiCROM's training replaced by a stub that writes an empty checkpoint; returns the list of its calls, each
    {"paths": the training trajectories, "settings": the training settings}, in order."""
    pytest.importorskip("torch")
    import frictionbench.solvers.licrom.train as train

    calls: list[dict] = []

    def fake_training(paths, folder, settings, device, progress, identity):
        calls.append({"paths": paths, "settings": settings})
        Path(folder).mkdir(parents=True, exist_ok=True)
        (Path(folder) / "model.pt").write_bytes(b"")

    monkeypatch.setattr(train, "train_from_trajectories", fake_training)
    return calls

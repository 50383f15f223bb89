"""What a reduced model trains on (`bench.runner.Variant.training`, `bench.training`): the training members'
references by default, unchanged, or their truths; the rows' `train_data`; the rank and training-data sets."""

from __future__ import annotations

import json
from pathlib import Path
from types import SimpleNamespace

import numpy as np
import pandas as pd
import pytest

from frictionbench.bench.matrix import variant_set
from frictionbench.bench.runner import Task, Variant, run_suite
from frictionbench.bench.store import RunStore
from frictionbench.bench.training import (NO_MODEL, TRAINING_DATA, Unprepared, family_scenarios, prepare_variants,
                                          training_kind, training_runs)
from frictionbench.scenarios.suites import load_suite
from frictionbench.solvers.reduced.plugin import artefact_key
from frictionbench.solvers.reduced.pod import Pod

from scenes import block_drop, mu_axis, suite_tables, write_toml

#: Two short block drops, mu0.2 the training member, with a BDF2 truth ladder (its runs differ from the references).
SUITE = suite_tables("traindata", block_drop(clearance=0.005, duration=0.04), mu_axis(0.2, 0.6),
                     description="two short block drops", split={"test": [{"mu": "mu0.6"}]},
                     truth={"tol": 1e-6, "depth": 2, "integrator": "bdf2"})
REF = Variant("pod", {"r": 4}, label="r4")
TRUTHDATA = Variant("pod", {"r": 4}, label="r4-truthdata", training="truth")


@pytest.fixture(scope="module")
def runs(tmp_path_factory) -> SimpleNamespace:
    """One run with the truth and one without (same folder: the second reuses every stored run), the paths each
    `Pod.prepare` call was given and what it returned."""
    tmp = tmp_path_factory.mktemp("traindata")
    suite = write_toml(tmp / "traindata.toml", SUITE)
    calls: list[tuple[list[Path], dict]] = []
    prepare = Pod.prepare

    def recording(self, shape, trajectories, out_dir, suite_name):
        extra = prepare(self, shape, trajectories, out_dir, suite_name)
        calls.append((list(trajectories), extra))
        return extra

    with pytest.MonkeyPatch.context() as mp:
        mp.setattr(Pod, "prepare", recording)
        with_truth = pd.read_csv(run_suite(str(suite), tmp / "out", variants=[REF, TRUTHDATA], report=False))
        n_with_truth = len(calls)
        without = pd.read_csv(run_suite(str(suite), tmp / "out", variants=[REF, TRUTHDATA], report=False,
                                        with_truth=False))
    return SimpleNamespace(out=tmp / "out", with_truth=with_truth, without=without, calls=calls,
                           n_with_truth=n_with_truth)


def test_a_reference_trained_variant_trains_on_the_references_under_the_key_it_always_had(runs):
    store = RunStore(runs.out / "runs")
    ref = runs.with_truth[(runs.with_truth["variant"] == "reference") & (runs.with_truth["split"] == "train")]
    ref_path = store.folder(ref["run"].item()) / "trajectory.npz"
    paths, extra = runs.calls[0]
    assert paths == [ref_path]
    # the cache key as it was made before the training-data choice: shape, rank, affine, the reference's path
    key = artefact_key("pod", {"shape": "block", "r": 4, "affine": False, "data": [str(ref_path)]})
    assert extra["basis"] == str(runs.out / "models" / key / "basis.npz")
    assert REF.training == "reference"
    row = runs.with_truth[runs.with_truth["variant"] == "r4"]
    assert (row["status"] == "ok").all() and (row["train_data"] == "reference").all()
    assert runs.with_truth[runs.with_truth["variant"] == "reference"]["train_data"].isna().all()


def test_a_truth_trained_variant_trains_on_the_truths_and_gets_a_model_of_its_own(runs):
    store = RunStore(runs.out / "runs")
    rows = runs.with_truth
    ladder = rows[(rows["split"] == "train") & (rows["ladder"] == "bdf2")].sort_values("ladder_level")
    truth_path = store.folder(ladder["run"].iloc[-1]) / "trajectory.npz"
    assert runs.n_with_truth == 2
    (ref_paths, ref_extra), (truth_paths, truth_extra) = runs.calls[:2]
    assert truth_paths == [truth_path] and truth_paths != ref_paths
    assert truth_extra["basis"] != ref_extra["basis"]  # another training set, another model
    trained = rows[rows["variant"] == "r4-truthdata"]
    assert (trained["status"] == "ok").all() and (trained["train_data"] == "truth").all()
    used = {json.loads((store.folder(k) / "stats.json").read_text())["params"]["basis"] for k in trained["run"]}
    assert used == {truth_extra["basis"]}


def test_a_truth_trained_variant_without_a_truth_is_a_failed_row_saying_why(runs):
    rows = runs.without
    assert len(runs.calls) == runs.n_with_truth + 1  # only the reference-trained variant was prepared
    failed = rows[rows["variant"] == "r4-truthdata"]
    assert len(failed) == 2 and (failed["status"] == "failed").all()
    assert failed["failure"].str.contains("training member traindata/mu0.2 has no truth to train on", regex=False).all()
    assert failed["failure"].str.contains("--no-truth", regex=False).all()
    assert (rows[rows["variant"] == "r4"]["status"] == "ok").all()


def test_training_runs_name_each_members_truth_or_why_it_has_none(tmp_path):
    suite = load_suite(str(write_toml(tmp_path / "s.toml", SUITE)))
    store = RunStore(tmp_path / "runs")
    train = suite.train[0].scenario
    refs = {m.scenario.name: Task(m.scenario, "full", {}) for m in suite.scenarios}
    truth = Task(train, "full", {"tol": 1e-9})
    for key in (refs[train.name].key, truth.key):
        store.folder(key).mkdir(parents=True)
        (store.folder(key) / "stats.json").write_text("{}")
    ladder = SimpleNamespace(tasks=[refs[train.name], truth])
    assert training_runs(suite, refs, store) == {"block": [store.folder(refs[train.name].key) / "trajectory.npz"]}
    assert training_runs(suite, refs, store, {train.name: {"bdf2": ladder}}, "truth") == {
        "block": [store.folder(truth.key) / "trajectory.npz"]}
    no_truth = training_runs(suite, refs, store, {}, "truth")["block"]
    assert "mu0.2" in no_truth and "--no-truth" in no_truth
    failed = training_runs(suite, refs, store, {train.name: {"bdf2": SimpleNamespace(tasks=[])}}, "truth")
    assert "first run failed" in failed["block"]
    resolved = prepare_variants(suite, [TRUTHDATA], store, refs, tmp_path / "models", "cpu", {})
    assert resolved == [(TRUTHDATA, Unprepared("block", no_truth))]
    with pytest.raises(ValueError, match="training 'truths'"):
        training_runs(suite, refs, store, {}, "truths")
    with pytest.raises(ValueError, match="training 'truths'"):
        Variant("pod", {"r": 4}, training="truths")
    assert TRAINING_DATA == ("reference", "truth") and NO_MODEL == "no reduced model for this mesh shape"



#: Block drops on a flat and on a 30 degree plane at two friction coefficients, one member held out at mu 0.9.
TILTED = suite_tables("tilted", block_drop(clearance=0.005, duration=0.04),
                      {"name": "plane", "values": [{"label": "flat", "plane.normal": [0.0, 1.0, 0.0]},
                                                   {"label": "tilt", "plane.normal": [0.5, 0.8660254, 0.0]}]},
                      mu_axis(0.2, 0.6), description="drops on two planes",
                      extra=[{"labels": {"plane": "held"}, "split": "test",
                              "overrides": {"plane.normal": [-0.5, 0.8660254, 0.0], "plane.friction": 0.9}}])


def test_a_training_family_spans_the_training_members_tilts_downhill_directions_friction_and_yaw(tmp_path):
    suite = load_suite(str(write_toml(tmp_path / "tilted.toml", TILTED)))
    assert len(suite.train) == 4 and [m.scenario.plane.friction for m in suite.test] == [0.9]
    family = family_scenarios(suite, 32)
    assert list(family) == ["block"] and len(family["block"]) == 32
    scenes = family["block"]
    assert scenes[0].name == "tilted/family32-block-0" and len({s.name for s in scenes}) == 32
    normals = np.array([s.plane.normal for s in scenes])
    tilt = np.degrees(np.arccos(normals[:, 1]))
    assert tilt.min() >= 0.0 and tilt.max() <= 30.0 + 1e-9 and tilt.max() - tilt.min() > 15.0
    azimuth = np.degrees(np.arctan2(normals[:, 2], normals[:, 0]))
    assert np.diff(np.sort(np.r_[azimuth, azimuth.min() + 360.0])).max() < 90.0  # all round the vertical
    mu = np.array([s.plane.friction for s in scenes])
    assert mu.min() >= 0.2 and mu.max() <= 0.6  # the held-out member's 0.9 takes no part
    yaw = np.array([s.initial.rotation[1] for s in scenes])
    assert 0.0 <= yaw.min() and yaw.max() <= 360.0 and yaw.std() > 60.0
    assert family_scenarios(suite, 32) == family  # seeded
    assert family_scenarios(suite, 4)["block"][0] != scenes[0]  # another N, other draws
    assert training_kind("family:16") == ("family", 16)
    for bad in ("family:0", "family:x", "family:100000", "families:4"):
        with pytest.raises(ValueError, match="family:N"):
            training_kind(bad)


def test_a_family_trained_variant_trains_on_its_drawn_scenes_runs(tmp_path):
    suite = write_toml(tmp_path / "tilted.toml", TILTED)
    calls: list[list[Path]] = []
    prepare = Pod.prepare

    def recording(self, shape, trajectories, out_dir, suite_name):
        calls.append(list(trajectories))
        return prepare(self, shape, trajectories, out_dir, suite_name)

    variant = Variant("pod", {"r": 4}, label="r4-family3", training="family:3")
    with pytest.MonkeyPatch.context() as mp:
        mp.setattr(Pod, "prepare", recording)
        rows = pd.read_csv(run_suite(str(suite), tmp_path / "out", variants=[variant], report=False,
                                     with_truth=False))
    (paths,) = calls
    store = RunStore(tmp_path / "out" / "runs")
    names = [json.loads((p.parent / "stats.json").read_text())["scenario"] for p in paths]
    assert names == [f"tilted/family3-block-{i}" for i in range(3)] and all(p.is_file() for p in paths)
    refs = set(rows[rows["variant"] == "reference"]["run"])
    assert not refs & {p.parent.name for p in paths} and store.root == paths[0].parent.parent
    trained = rows[rows["variant"] == "r4-family3"]
    assert len(trained) == 5 and (trained["status"] == "ok").all() and (trained["train_data"] == "family:3").all()


def test_a_licrom_model_is_keyed_by_its_training_runs(tmp_path: Path, licrom_trainings):
    """The same settings on another training set train another model; on the same set, none."""
    from frictionbench.solvers.registry import get_solver

    solver = get_solver("licrom")(device="cpu", **variant_set("licrom-affine")[0].params)
    references, truths = [tmp_path / "ref" / "trajectory.npz"], [tmp_path / "truth" / "trajectory.npz"]
    first, other, again = (solver.prepare("cheese", data, tmp_path / "models", "s")
                           for data in (references, truths, references))
    assert first["checkpoint"] != other["checkpoint"] and again == first
    assert [c["paths"] for c in licrom_trainings] == [[str(p) for p in references], [str(p) for p in truths]]

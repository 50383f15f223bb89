"""Task payloads: artefact folders carried by content, and the parameters that point at a worker's copy."""

from __future__ import annotations



from frictionbench.bench.payload import Artefact, artefact_folders, localised
from frictionbench.bench.store import RunStore


def test_an_artefact_is_written_once_where_its_content_says_and_parameters_follow(tmp_path):
    model = tmp_path / "client" / "models" / "pod-1"
    model.mkdir(parents=True)
    (model / "basis.npz").write_bytes(b"W")
    (model / "info.json").write_text('{"train_s": 1.0}')
    (model / ".basis.npz.tmp").write_bytes(b"half-written")  # an atomic write in progress is not part of it
    params = {"r": 8, "cubature": "all", "basis": str(model / "basis.npz"), "scheme": "newton"}
    assert artefact_folders(params) == [str(model)]
    artefact = Artefact.of(model)
    assert [name for name, _ in artefact.files] == ["basis.npz", "info.json"]
    worker = tmp_path / "worker"
    local = localised(params, (artefact,), worker)
    copy = worker / artefact.digest
    assert local == params | {"basis": str(copy / "basis.npz")}
    assert (copy / "basis.npz").read_bytes() == b"W" and (copy / "info.json").read_text() == '{"train_s": 1.0}'
    (copy / "basis.npz").write_bytes(b"seen")  # a second task finds the copy and does not write it again
    assert localised(params, (artefact,), worker) == local and (copy / "basis.npz").read_bytes() == b"seen"
    assert [p.name for p in worker.iterdir()] == [artefact.digest]  # no temporary folder left behind
    (model / "basis.npz").write_bytes(b"W2")  # other content, another copy
    assert Artefact.of(model).digest != artefact.digest
    assert localised(params, (), worker) == params  # nothing carried: parameters unchanged


def test_a_task_without_a_result_is_raised_once_the_others_are_stored(tmp_path, monkeypatch):
    """A task whose result never comes back (its workers died) does not cost the results that did."""
    from concurrent.futures import ThreadPoolExecutor, as_completed

    import pytest

    import frictionbench.bench.runner as runner
    from frictionbench.bench.runner import Task, run_tasks
    from frictionbench.scenarios.load import scenario_from_dict

    class InThread(ThreadPoolExecutor):
        slots = 1
        share = staticmethod(lambda obj: obj)
        as_completed = staticmethod(lambda futures: as_completed(list(futures)))
        abandon = staticmethod(lambda futures: None)

    def execute(task, *args):
        if task.scenario.plane.friction == 0.6:
            raise RuntimeError("every worker that tried it died")
        return real_execute(task, *args)

    real_execute = runner.execute
    monkeypatch.setattr(runner, "make_executor", lambda kind, jobs: InThread(max_workers=1))
    monkeypatch.setattr(runner, "execute", execute)
    base = {"name": "drop", "mesh": {"name": "block", "resolution": "coarse"}, "initial": {"clearance": 0.01},
            "time": {"dt": 0.01, "duration": 0.02}}
    tasks = [Task(scenario_from_dict(base | {"plane": {"friction": mu}}, source="test"), "full", {})
             for mu in (0.6, 0.2, 0.4)]
    store = RunStore(tmp_path / "runs")
    with pytest.raises(RuntimeError, match="every worker that tried it died"):
        run_tasks(tasks, store, "cpu", jobs=1, executor="process", desc="lost")
    assert [store.done(t.key) for t in tasks] == [False, True, True]

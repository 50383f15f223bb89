"""The behaviour-unchanged check (bench.unchanged) on small synthetic results tables."""

from __future__ import annotations

import json
from pathlib import Path

import pandas as pd
import pytest

from frictionbench.bench import unchanged
from frictionbench.bench.unchanged import compare_results, compare_verdicts, main, values_equal


def table() -> pd.DataFrame:
    a = {"suite": "quick", "scenario": "quick/a", "split": "test"}
    return pd.DataFrame([
        a | {"solver": "full", "variant": "reference", "pos_rmse_rel": 0.0, "max_penetration_rel": 1.5e-3,
             "stick": True, "status": "ok", "failure": None, "step_ms_median": 40.0, "commit": "aaa",
             "numpy_version": "2.0"},
        a | {"solver": "licrom", "variant": "licrom", "pos_rmse_rel": 0.03, "max_penetration_rel": 2.0e-3,
             "stick": False, "status": "ok", "failure": None, "step_ms_median": 2.0, "commit": "aaa",
             "numpy_version": "2.0"},
        a | {"solver": "pod", "variant": "pod", "pos_rmse_rel": None, "max_penetration_rel": None, "stick": None,
             "status": "failed", "failure": "Newton did not converge", "step_ms_median": None, "commit": "aaa",
             "numpy_version": "2.0"},
    ])


def changed(row: int, column: str, value: object) -> pd.DataFrame:
    frame = table()
    frame[column] = frame[column].astype(object)
    frame.at[row, column] = value
    return frame


def test_a_table_equals_itself_and_timing_and_provenance_are_not_compared() -> None:
    assert compare_results(table(), table()) == ([], [])
    other = changed(0, "step_ms_median", 99.0)
    other["commit"], other["numpy_version"] = "bbb", "2.1"
    assert compare_results(table(), other) == ([], [])


@pytest.mark.parametrize(("row", "factor", "different"), [
    (0, 1 + 1e-10, False), (0, 1 + 1e-8, True),   # the full-space row: 1e-9
    (1, 1 + 1e-7, False), (1, 1 + 1e-5, True),    # a reduced row: 1e-6
])
def test_numbers_are_compared_to_the_tolerance_of_their_row(row, factor, different) -> None:
    value = table().at[row, "max_penetration_rel"] * factor
    differences, _ = compare_results(table(), changed(row, "max_penetration_rel", value))
    assert bool(differences) == different
    if different:
        (d,) = differences
        assert d.what == "max_penetration_rel" and "solver=" in d.where and d.new == value


def test_text_booleans_missing_rows_and_columns_are_differences() -> None:
    assert [d.what for d in compare_results(table(), changed(2, "failure", "other reason"))[0]] == ["failure"]
    assert [d.what for d in compare_results(table(), changed(1, "stick", True))[0]] == ["stick"]
    assert [d.what for d in compare_results(table(), changed(1, "pos_rmse_rel", None))[0]] == ["pos_rmse_rel"]
    assert [(d.what, d.new) for d in compare_results(table(), table().drop(index=2))[0]] == [("row", "missing")]
    differences, notes = compare_results(table(), table().drop(columns="stick").assign(extra=1.0))
    assert [(d.what, d.old) for d in differences] == [("column missing", "stick")] and notes == ["new column extra"]


def test_values_equal_treats_two_missing_values_and_equal_infinities_as_equal() -> None:
    assert values_equal(None, float("nan"), 1e-9) and values_equal(float("inf"), float("inf"), 1e-9)
    assert not values_equal(None, 0.0, 1e-9) and not values_equal(float("inf"), 1e300, 1e-9)
    assert values_equal(0.0, 1e-13, 1e-9) and not values_equal(0.0, 1e-9, 1e-9)  # the absolute floor is 1e-12


def test_gate_verdicts_must_agree() -> None:
    gates = [{"suite": "quick", "variant": "licrom/licrom", "metric": "max_penetration_rel", "max": 2.5e-3}]
    assert compare_verdicts(table(), table(), "quick", gates) == []
    worse = changed(1, "max_penetration_rel", 3e-3)
    (d,) = compare_verdicts(table(), worse, "quick", gates)
    assert (d.old, d.new) == ("passed", "failed") and "quick/a" in d.where


def write_folder(folder: Path, frame: pd.DataFrame) -> Path:
    folder.mkdir()
    frame.to_csv(folder / "results.csv", index=False)
    (folder / "run.json").write_text(json.dumps({"suite": "quick"}))
    return folder


def test_main_compares_two_folders_and_exits_one_on_a_difference(tmp_path, capsys) -> None:
    old = write_folder(tmp_path / "old", table())
    assert main([str(old), str(write_folder(tmp_path / "same", table()))]) == 0
    assert "compared 3 rows" in capsys.readouterr().out
    assert main([str(old), str(write_folder(tmp_path / "new", changed(1, "pos_rmse_rel", 0.031)))]) == 1
    out = capsys.readouterr().out
    assert "DIFFERENT" in out and "pos_rmse_rel: 0.03 -> 0.031" in out and "1 differences" in out


def test_folder_paths_and_keys_in_texts_do_not_count(tmp_path) -> None:
    """A failure naming a model file differs between two runs of the same code only by folder and key."""
    def failing(folder: Path, key: str) -> pd.DataFrame:
        return changed(2, "failure", f"PluginError: pod basis {folder}/models/pod-{key}/basis.npz: bound to its mesh")

    old, new = tmp_path / "old", tmp_path / "new"
    write_folder(old, failing(old, "edd9786642b48f8d"))
    write_folder(new, failing(new, "2330b9c96b261d49"))
    assert main([str(old), str(new)]) == 0
    write_folder(tmp_path / "other", changed(2, "failure", f"PluginError: pod basis {new}/models/pod-x/basis.npz"))
    assert main([str(old), str(tmp_path / "other")]) == 1  # the reason itself changed


def test_gates_on_timing_are_not_judged() -> None:
    gates = [{"suite": "quick", "variant": "licrom/licrom", "metric": "speedup", "min": 5.0}]
    slower = table().assign(speedup=[1.0, 20.0, None])
    assert compare_verdicts(slower, slower.assign(speedup=[1.0, 2.0, None]), "quick", gates) == []


@pytest.mark.parametrize("layout, cli", [("package", "frictionbench.bench.cli"), ("top-level", "bench.cli")])
def test_a_checkout_runs_its_own_command_line(tmp_path, monkeypatch, layout, cli) -> None:
    """`--base` runs a commit's own code: a checkout with the one import name runs `frictionbench.bench.cli`, one
    from before it (its packages top-level, as at a40404c) `bench.cli`, each with the checkout first on the path."""
    if layout == "package":
        (tmp_path / "frictionbench").mkdir()
        (tmp_path / "frictionbench" / "__init__.py").write_text("")
    ran = []
    monkeypatch.setattr(unchanged.subprocess, "run", lambda cmd, cwd, env, check: ran.append((cmd, cwd, env)))
    unchanged.run_suite_at(tmp_path, "quick", tmp_path / "out", 2)
    ((cmd, cwd, env),) = ran
    assert cmd[1:4] == ["-m", cli, "run"] and cwd == tmp_path and env["PYTHONPATH"] == str(tmp_path)


def test_a_renamed_suite_is_compared_member_by_member(tmp_path, capsys) -> None:
    """`--suite OLD:NEW`: the old rows take the new suite and scenario names, then compare as one suite's."""
    old = write_folder(tmp_path / "old", table())
    renamed = table().assign(suite="quick-undamped", scenario="quick-undamped/a")
    new = write_folder(tmp_path / "new", renamed)
    (new / "run.json").write_text(json.dumps({"suite": "quick-undamped"}))
    with pytest.raises(ValueError, match="different suites"):
        main([str(old), str(new)])
    assert main([str(old), str(new), "--suite", "quick:quick-undamped"]) == 0
    assert "compared 3 rows" in capsys.readouterr().out
    moved = write_folder(tmp_path / "moved", renamed.assign(pos_rmse_rel=[0.0, 0.031, None]))
    (moved / "run.json").write_text(json.dumps({"suite": "quick-undamped"}))
    assert main([str(old), str(moved), "--suite", "quick:quick-undamped"]) == 1

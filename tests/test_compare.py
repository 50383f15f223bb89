"""`frictionbench compare` (issue 14): two result sets side by side; a planted regression fails, identical sets
pass, changes within the tolerances pass, and the report shows the comparison with every text escaped."""

from __future__ import annotations

import io
import shutil
from contextlib import redirect_stderr, redirect_stdout
from pathlib import Path

import pandas as pd
import pytest

from frictionbench.bench.cli import main
from frictionbench.bench.compare import (CompareError, compare_results, default_rules, read_results, regressions,
                           with_tolerances)
from frictionbench.bench.gates import load_gates
from frictionbench.bench.runner import run_suite
from frictionbench.reports.browser_check import check_report
from frictionbench.reports.html import comparison_section

from scenes import block_drop, mu_axis, suite_tables, write_toml

GATES = load_gates(None)


def _results() -> pd.DataFrame:
    """A small quick-suite result set: the reference and the gated reduced variant on two scenarios."""
    rows = []
    for scenario, err in (("quick/p1_mu0.1", 0.020), ("quick/p2_mu0.5", 0.030)):
        common = {"suite": "quick", "scenario": scenario, "split": "train", "mesh": "cheese/coarse", "tags": "",
                  "status": "ok", "failure": "", "finite": True, "max_penetration_rel": 0.002,
                  "energy_ratio_max": 1.0, "inverted_tets": 0}
        rows.append(common | {"solver": "full", "variant": "reference", "pos_rmse_rel": 0.0,
                              "step_ms_median": 40.0, "speedup": 1.0})
        rows.append(common | {"solver": "licrom", "variant": "affine-r24-cub60", "pos_rmse_rel": err,
                              "stick_agree": True, "step_ms_median": 2.5, "speedup": 16.0})
    return pd.DataFrame(rows)


def _write(folder: Path, frame: pd.DataFrame) -> str:
    folder.mkdir(parents=True, exist_ok=True)
    frame.to_csv(folder / "results.csv", index=False)
    return str(folder)


def _cli(*argv: str) -> tuple[int, str, str]:
    out, err = io.StringIO(), io.StringIO()
    with redirect_stdout(out), redirect_stderr(err):
        code = main(list(argv))
    return code, out.getvalue(), err.getvalue()


def _changed(**cells) -> pd.DataFrame:
    """The result set with cells of the reduced row of the first scenario changed."""
    frame = _results()
    for column, value in cells.items():
        frame.loc[1, column] = value
    return frame


def test_identical_result_sets_pass(tmp_path: Path):
    a, b = _write(tmp_path / "a", _results()), _write(tmp_path / "b", _results())
    code, out, _ = _cli("compare", a, b)
    assert code == 0
    assert "no changes beyond the tolerances" in out and "regression 0," in out


def test_a_planted_accuracy_regression_fails(tmp_path: Path):
    a = _write(tmp_path / "a", _results())
    b = _write(tmp_path / "b", _changed(pos_rmse_rel=0.024))  # +20% (tolerance 10%), still under the gate's 0.05
    code, out, _ = _cli("compare", a, b)
    assert code == 1
    line = next(x for x in out.splitlines() if x.lstrip().startswith("regression"))
    assert "quick/p1_mu0.1" in line and "licrom/affine-r24-cub60" in line and "pos_rmse_rel" in line
    assert "10%,0.0001" in line and "max 0.05" in line  # its tolerance and the gate's threshold
    assert "regression 1," in out
    # the same change the other way is an improvement, not a failure
    code, out, _ = _cli("compare", b, a)
    assert code == 0 and "improved 1," in out


def test_changes_within_the_tolerances_pass_and_tolerances_are_configurable(tmp_path: Path):
    a = _write(tmp_path / "a", _results())
    small = _write(tmp_path / "small", _changed(pos_rmse_rel=0.0215, step_ms_median=3.5))  # +7.5%, x1.4
    assert _cli("compare", a, small)[0] == 0
    slow = _write(tmp_path / "slow", _changed(step_ms_median=5.5))  # x2.2 slower: beyond the default x1.5
    code, out, _ = _cli("compare", a, slow)
    assert code == 1 and "x2.2 beyond x1.5" in out
    assert _cli("compare", a, slow, "--tol", "timing=x3")[0] == 0
    assert _cli("compare", a, small, "--tol", "pos_rmse_rel=5%")[0] == 1
    assert _cli("compare", a, small, "--tol", "accuracy=off", "--tol", "step_ms_median=x1.2")[0] == 1


def test_a_newly_failing_gate_is_a_regression_within_the_tolerance(tmp_path: Path):
    limit = next(g["max"] for g in GATES if g["suite"] == "quick" and g["metric"] == "pos_rmse_rel"
                 and g.get("split") == "train" and not g.get("advisory"))
    a = _write(tmp_path / "a", _changed(pos_rmse_rel=0.97 * limit))
    b = _write(tmp_path / "b", _changed(pos_rmse_rel=1.03 * limit))  # +6%, within 10%, but over the gate's max
    code, out, _ = _cli("compare", a, b)
    assert code == 1 and f"gate max {float(limit)} now fails" in out


def test_an_advisory_gate_crossed_within_the_tolerance_is_no_regression(tmp_path: Path):
    limit = next(g["min"] for g in GATES if g["suite"] == "quick" and g["metric"] == "speedup")
    assert next(g for g in GATES if g["suite"] == "quick" and g["metric"] == "speedup").get("advisory")
    a = _write(tmp_path / "a", _changed(speedup=1.1 * limit))
    b = _write(tmp_path / "b", _changed(speedup=0.95 * limit))  # x1.16 slower, within x1.5, under the advisory min
    assert _cli("compare", a, b)[0] == 0


@pytest.mark.parametrize(("change", "reason"), [
    ({"status": "failed", "failure": "Diverged: non-finite state at step 7", "pos_rmse_rel": None}, "run failed"),
    ({"stick_agree": False}, "no longer holds"),
    ({"inverted_tets": 1}, "worse by 1"),
    ({"energy_ratio_max": None}, "no value in the new set"),
])
def test_stability_regressions(change: dict, reason: str):
    comparison = compare_results(_results(), _changed(**change), default_rules(), GATES)
    assert regressions(comparison) == 1
    assert reason in comparison.loc[comparison["verdict"] == "regression", "reason"].iloc[0]


def test_missing_and_new_rows():
    base, new = _results(), _results()
    missing = compare_results(base, new.drop(index=3), default_rules(), GATES)
    assert regressions(missing) == 1 and missing.iloc[0]["reason"] == "missing in the new set"
    extra = new.iloc[[1]].assign(variant="r20", solver="licrom")
    grown = compare_results(base, pd.concat([new, extra], ignore_index=True), default_rules(), GATES)
    assert regressions(grown) == 0 and (grown["verdict"] == "new").sum() == 1


def test_tolerance_specs():
    rules = {r.metric: r for r in with_tolerances(default_rules(), ["pos_rmse_rel=5%,0.001", "speedup=x2",
                                                                  "my_metric=higher:1%", "finite=off"])}
    assert (rules["pos_rmse_rel"].rel, rules["pos_rmse_rel"].abs) == (0.05, 0.001)
    assert rules["speedup"].factor == 2.0 and rules["speedup"].better == "higher"
    assert (rules["my_metric"].better, rules["my_metric"].rel) == ("higher", 0.01)
    assert "finite" not in rules
    for bad in ("pos_rmse_rel", "my_metric=5%", "speedup=x0.5", "speedup=sideways:5%", "pos_rmse_rel=-1",
                "pos_rmse_rel=abc%"):
        with pytest.raises(CompareError, match="tolerance"):
            with_tolerances(default_rules(), [bad])


def test_bad_input_exits_2_naming_it(tmp_path: Path):
    a = _write(tmp_path / "a", _results())
    code, _, err = _cli("compare", a, str(tmp_path / "nowhere"))
    assert code == 2 and "nowhere" in err
    code, _, err = _cli("compare", a, a, "--tol", "speedup=x0.5")
    assert code == 2 and "speedup=x0.5" in err
    (tmp_path / "other.csv").write_text("x,y\n1,2\n")
    with pytest.raises(CompareError, match="not a results table"):
        read_results(tmp_path / "other.csv")


def test_the_report_section_escapes_every_text():
    hostile = "quick/<script>alert(1)</script>"
    base, new = _results(), _changed(status="failed", failure="<img src=x onerror=alert(2)>", pos_rmse_rel=None)
    base.loc[1, "scenario"] = new.loc[1, "scenario"] = hostile
    fragment = comparison_section(compare_results(base, new, default_rules(), GATES), "<b>base</b>")
    assert "<script>" not in fragment and "<img" not in fragment and "<b>" not in fragment
    assert "&lt;script&gt;" in fragment and "&lt;img src=x" in fragment
    assert "Regressions against the baseline &lt;b&gt;base&lt;/b&gt;: 1" in fragment


def test_report_and_compare_on_real_runs(tmp_path: Path):
    """A tiny suite run, then a baseline with a planted better figure: the report gets the comparison section and
    `compare` fails; against an identical copy it passes."""
    suite = write_toml(tmp_path / "tiny.toml", suite_tables("tiny", block_drop(duration=0.03), mu_axis(0.3)))
    out = tmp_path / "out"
    run_suite(str(suite), out, variants=[], jobs=1)
    same = tmp_path / "same"
    same.mkdir()
    shutil.copy(out / "results.csv", same / "results.csv")
    assert _cli("compare", str(same), str(out))[0] == 0
    better = read_results(out).assign(max_penetration_rel=lambda f: f["max_penetration_rel"] / 2 - 1e-3)
    base = _write(tmp_path / "base", better)
    for argv in (["report", str(out)], ["run", "--suite", str(suite), "--solvers", "full", "--out", str(out)]):
        (out / "report.html").unlink()
        code, stdout, _ = _cli(*argv, "--baseline", base)  # the run resumes: every run is stored
        assert code == 0 and "regression 1," in stdout
        page = (out / "report.html").read_text()
        assert "Comparison with the baseline" in page and "Regressions against the baseline" in page
        assert "max_penetration_rel" in page.split("Comparison with the baseline", 1)[1]
    assert check_report(out / "report.html") == []  # still opens offline in Chromium with no error
    assert _cli("compare", base, str(out))[0] == 1
    # a bad baseline is refused before a run starts
    code, _, err = _cli("run", "--suite", str(suite), "--out", str(tmp_path / "unrun"), "--baseline",
                        str(tmp_path / "nowhere"))
    assert code == 2 and "nowhere" in err and not (tmp_path / "unrun").exists()

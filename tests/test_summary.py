"""The answer in plain words (`analysis.summary`): the best variant chosen on the accuracy-cost frontier, one
sentence per family with bounds written "<=", one banner that agrees with the gates and runs, the glossary's hovers,
and the terminal summary at the end of `frictionbench run`."""

from __future__ import annotations

import pandas as pd
import pytest

from frictionbench.analysis.summary import banner, choose, gate_counts, run_counts, summarise, variant_figures
from frictionbench.analysis.truth import AT_MOST
from frictionbench.reports.glossary import GLOSSARY, defined, glossary_html
from frictionbench.reports.headline import speedup_text, with_bounds

AT = AT_MOST


def _row(scenario: str, solver: str, variant: str, err: float, wall: float, speed: float | None,
         note: str = "", **extra) -> dict:
    return {"scenario": scenario, "solver": solver, "variant": variant, "status": "ok", "finite": True,
            "not_converged": 0, "err_truth": err, "pos_rmse_rel": err / 2, "wall_s_per_sim_s": wall,
            "speedup_equal_accuracy": speed, "speedup": 40.0, "frontier_note": note, "ladder": "",
            "truth_certified": True, "truth_err_est": 1e-4, "err_time": 0.01, **extra}


def _frame(rows: list[dict]) -> pd.DataFrame:
    ladder = [_row(s, "full", f"ladder-bdf2-{k}", e, 100.0 * 2 ** k, None, ladder="bdf2")
              for s in sorted({r["scenario"] for r in rows}) for k, e in enumerate([0.02, 0.005, 0.0])]
    return pd.DataFrame(rows + ladder)


def test_the_best_variant_is_the_frontier_s_largest_measured_speedup_not_the_lowest_error():
    rows = []
    for s in ("a", "b"):
        rows += [_row(s, "full", "reference", 0.30, 50.0, 1.0),
                 _row(s, "licrom", "r40", 0.010, 10.0, 12.0),  # most accurate
                 _row(s, "licrom", "cub60", 0.012, 1.0, 80.0),  # cheapest, measured: the answer
                 _row(s, "licrom", "r20", 0.050, 12.0, 3.0)]  # dominated by cub60: off the front
    figures = {v.label: v for v in variant_figures(_frame(rows))["licrom"]}
    chosen, basis, front = choose(list(figures.values()), truth=True)
    assert (chosen.label, basis) == ("licrom/cub60", "measured")
    assert [v.label for v in front] == ["licrom/cub60", "licrom/r40"]
    family = {f.family: f for f in summarise(_frame(rows)).families}["licrom"]
    assert family.sentence == ("at 1.2% of L against the certified truth, licrom/cub60 costs 1 s per simulated "
                               "second, 80 times less than the full-space solver at the same accuracy")
    assert family.step_speedup_text == "per-step speedup 40x"


def test_a_family_with_bounds_only_says_so_with_at_most_and_the_reason():
    rows = []
    for s in ("a", "b"):
        rows += [_row(s, "full", "reference", 0.30, 50.0, 1.0, note=AT, err_time=0.30),
                 _row(s, "licrom", "r40", 0.31, 1.0, 45.0, note=AT, err_time=0.30),
                 _row(s, "licrom", "r20", 0.32, 0.9, 50.0, note=AT, err_time=0.30)]
    family = {f.family: f for f in summarise(_frame(rows)).families}["licrom"]
    assert family.basis == "bound"
    assert family.chosen.label == "licrom/r20"  # within the accuracy tolerance of r40, and cheaper
    assert family.sentence.startswith("no licrom variant reaches the full-space solver's coarsest accuracy")
    assert "at most 50 times faster (<= 50x)" in family.sentence
    assert "the full-space run at its step is 30% of L off (err_time)" in family.sentence
    assert "times less than" not in family.sentence  # a bound is never written as a measured figure


def test_without_a_truth_the_choice_is_by_error_against_the_reference():
    rows = [_row("a", "full", "reference", 0.0, 50.0, None), _row("a", "licrom", "r20", 0.02, 1.0, None),
            _row("a", "licrom", "r40", 0.01, 2.0, None)]
    frame = pd.DataFrame(rows).drop(columns=["err_truth", "truth_certified", "truth_err_est"])
    s = summarise(frame)
    fam = {f.family: f for f in s.families}
    assert fam["licrom"].chosen.label == "licrom/r40" and fam["licrom"].basis == "reference"
    assert fam["licrom"].sentence.startswith("no ground truth in these results")
    assert not s.truth.present and "no ground truth" in s.truth.text()


@pytest.mark.parametrize(("verdicts", "failed_run", "level"), [
    ([{"passed": True}, {"passed": True}], False, "pass"),
    ([{"passed": True}, {"passed": False, "status": "undecidable", "variant": "licrom/r20",
                         "metric": "speedup_equal_accuracy", "scenario": "a"}], False, "warn"),
    ([{"passed": True}, {"passed": False, "advisory": True, "variant": "full/reference", "metric": "energy_drift",
                         "scenario": "a"}], False, "warn"),
    ([{"passed": False, "variant": "licrom/r20", "metric": "err_truth", "scenario": "a", "value": 0.2,
       "limit": "<= 0.1"}, {"passed": False, "status": "undecidable"}], False, "fail"),
    ([{"passed": True}], True, "fail"),
    ([], False, "warn")])
def test_one_banner_whose_level_agrees_with_the_gates_and_runs(verdicts, failed_run, level):
    rows = [_row("a", "full", "reference", 0.3, 50.0, 1.0), _row("a", "licrom", "r20", 0.2, 1.0, 9.0)]
    if failed_run:
        rows[1] |= {"status": "failed", "failure": "RuntimeError: boom"}
    b = banner(gate_counts(verdicts), run_counts(pd.DataFrame(rows)))
    assert b.level == level
    if level == "fail" and failed_run:
        assert "1 of 2 runs failed" in b.headline and any("RuntimeError: boom" in d for d in b.details)
    if level == "fail" and not failed_run:
        assert "1 of 2 binding gates failed" in b.headline
        assert any("licrom/r20 err_truth on a: 0.2 (limit <= 0.1)" in d for d in b.details)
    if level == "warn" and verdicts and verdicts[-1].get("status") == "undecidable":
        assert "1 of 2 binding gates are undecidable" in b.headline


def test_the_terminal_summary_is_a_few_lines_with_the_verdict_first():
    rows = []
    for s in ("a", "b"):
        rows += [_row(s, "full", "reference", 0.30, 50.0, 1.0), _row(s, "licrom", "cub60", 0.012, 1.0, 80.0)]
    lines = summarise(_frame(rows), [{"passed": True}] * 3).lines()
    assert lines[0] == "PASSED: Every binding gate passed (3 of 3) and every run finished."
    assert [ln.split(":")[0] for ln in lines[1:3]] == ["  full", "  licrom"]
    assert lines[3] == "Truths certified on 2 of 2 scenarios (largest error estimate 0.01% of L)."
    assert len(lines) == 5


def test_bounds_are_written_with_at_most_in_every_table():
    frame = pd.DataFrame({"speedup_equal_accuracy": [45.6, 3.0, None], "frontier_note": [AT, "", AT]})
    out = with_bounds(frame)
    assert list(out["speedup_equal_accuracy"][:2]) == ["<= 46", 3.0] and pd.isna(out["speedup_equal_accuracy"][2])
    assert speedup_text(2.0, False) == 2.0 and speedup_text(None, True) is None


def test_every_term_gets_a_hover_on_its_first_use_and_hostile_text_stays_text():
    seen: set[str] = set()
    first = defined("the truth is certified; err_truth <b>", seen)
    assert first.count("<abbr") == 3 and "&lt;b&gt;" in first
    assert "<abbr" not in defined("the truth again", seen)  # defined once
    assert 'title="upper bound: ' in defined("an upper bound")
    assert "<abbr" not in defined("licrom/r20-truth")  # a name is not a term
    page = glossary_html()
    assert all(f">{t}</dt>" in page for t in GLOSSARY if "<" not in t and "&" not in t)

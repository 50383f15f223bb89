"""The results schema (analysis.schema): one declaration per column, from which results.csv, compare, the report,
the headline and the docs' table of metrics follow; and the one reader of a results cell."""

from __future__ import annotations

import importlib
from pathlib import Path

import numpy as np
import pandas as pd
import pytest

from frictionbench.analysis import schema
from frictionbench.analysis.metrics import ComparedRun
from frictionbench.analysis.rows import collect_rows, run_metrics
from frictionbench.analysis.schema import (COLUMNS, Column, docs_table, docs_with_table, flag, is_missing, number,
                                           stability_metrics, together, truthy)
from frictionbench.analysis.table import write_results_csv
from frictionbench.bench.compare import compare_results, default_rules
from frictionbench.bench.runner import Task, Variant, run_records
from frictionbench.reports.headline import headline_table
from frictionbench.reports.html import write_report_html
from frictionbench.scenarios.spec import Effects, Scenario
from frictionbench.scenarios.suites import Suite, SuiteMember
from frictionbench.solvers.trajectory import Trajectory

METRICS_DOC = Path(__file__).resolve().parents[1] / "docs" / "metrics.md"


def toy_drop(run: ComparedRun) -> float:
    """How far the run's centre ends below the reference's [m]."""
    return float(run.ref.x[-1, :, 1].mean() - run.traj.x[-1, :, 1].mean())


@pytest.fixture
def toy(monkeypatch) -> Column:
    """A metric declared in the schema alone."""
    column = Column("toy_drop", "accuracy", "lower", "m", "how far the centre ends below the reference's",
                    f"{__name__}.toy_drop", abs=1e-3, summary=True, compute=toy_drop)
    monkeypatch.setitem(COLUMNS, column.name, column)
    return column


def falling_tet(drop: float) -> Trajectory:
    """One tet 0.1 m above the plane y = 0, lowered by `drop` [m] over 1 s (5 frames)."""
    X = np.array([[0.0, 0.1, 0.0], [0.1, 0.1, 0.0], [0.0, 0.2, 0.0], [0.0, 0.1, 0.1]])
    t = np.linspace(0.0, 1.0, 5)
    x = X[None] - np.outer(drop * t, [0.0, 1.0, 0.0])[:, None, :]
    return Trajectory(t=t, x=x, X=X, tets=np.array([[0, 1, 2, 3]]),
                      surface=np.array([[0, 2, 1], [0, 1, 3], [0, 3, 2], [1, 2, 3]]))


class Store:
    """Stored runs by key, as `bench.store.RunStore.load` gives them."""

    def __init__(self, runs: dict[str, tuple[Trajectory, dict]]) -> None:
        self.runs = runs

    def load(self, key: str) -> tuple[Trajectory, dict]:
        return self.runs[key]


def results(tmp_path: Path, drop: float) -> pd.DataFrame:
    """results.csv of one scenario: its reference and a variant that falls `drop` [m] further, built by
    `analysis.rows.collect_rows` from stored runs and the harness's records of them (`run_records`)."""
    sc = Scenario(name="toy", effects=Effects(friction=False))
    member = SuiteMember(sc, "test", {})
    variant = Variant("full", label="slower")
    ref_task, task = Task(sc, "full", {}), Task(sc, "full", {"tag": "slower"})
    stats = {"contact_stiffness": 1e5, "step_ms_median": 1.0}
    store = Store({ref_task.key: (falling_tet(0.05), stats), task.key: (falling_tet(0.05 + drop), stats)})
    suite, refs = Suite("toy", "", (member,)), {sc.name: ref_task}
    rows = collect_rows(suite, refs, run_records(suite, refs, [(variant, {"tag": "slower"})], [variant]), store)
    return pd.read_csv(write_results_csv(rows, tmp_path / f"{drop}" / "results.csv", provenance_info={}))


def test_a_metric_declared_in_the_schema_alone_reaches_results_compare_report_and_docs(tmp_path, toy) -> None:
    base, new = results(tmp_path, 0.002), results(tmp_path, 0.01)
    assert list(base["toy_drop"]) == pytest.approx([0.0, 0.002])
    comparison = compare_results(base, new, gates=())
    judged = comparison[comparison["metric"] == "toy_drop"].set_index("variant")
    assert judged.loc["full/slower", "verdict"] == "regression" and judged.loc["full/slower", "kind"] == "accuracy"
    assert judged.loc["full/reference", "verdict"] == "ok"
    page = write_report_html(new, tmp_path / "report").read_text()
    results_section = page[page.index('<section id="results">'):page.index('<section id="provenance">')]
    assert "<th>toy_drop</th>" in results_section
    assert "| `toy_drop` | accuracy | lower | 0.001 | m |" in docs_table()
    assert f"`{__name__}.toy_drop`" in docs_table()


def test_columns_one_computation_gives_are_declared_together_and_computed_once_per_run(monkeypatch) -> None:
    """Two toy columns from one function, declared in the schema alone, land in a finished run's row (after the
    built-in metrics) from a single call of it per run."""
    calls = []

    def drops(run: ComparedRun) -> dict[str, float]:
        """How far the run's centre is below the reference's at the middle and last frames [m]."""
        calls.append(run)
        drop = run.ref.x[:, :, 1].mean(axis=1) - run.traj.x[:, :, 1].mean(axis=1)
        return {"toy_mid_drop": float(drop[drop.size // 2]), "toy_end_drop": float(drop[-1])}

    for column in together(drops, Column("toy_mid_drop", "accuracy", "lower", "m", "drop at the middle frame"),
                           Column("toy_end_drop", "accuracy", "lower", "m", "drop at the last frame")):
        monkeypatch.setitem(COLUMNS, column.name, column)
    sc = Scenario(name="toy", effects=Effects(friction=False))
    row = run_metrics(falling_tet(0.05), falling_tet(0.07), sc, {"contact_stiffness": 1e5})
    assert list(row)[-2:] == ["toy_mid_drop", "toy_end_drop"] and row["status"] == "ok" and "pos_rmse_rel" in row
    assert row["toy_mid_drop"] == pytest.approx(0.01) and row["toy_end_drop"] == pytest.approx(0.02)
    assert len(calls) == 1


def test_the_docs_table_of_metrics_is_the_generated_one() -> None:
    text = METRICS_DOC.read_text(encoding="utf-8")
    assert docs_with_table(text) == text, "run `python -m frictionbench.analysis.schema` to regenerate it"
    stale = text.replace("| `pos_rmse_rel` |", "| `pos_rmse` |")
    assert docs_with_table(stale) == text


def test_every_column_says_where_it_is_computed() -> None:
    for column in COLUMNS.values():
        module, _, attribute = column.source.rpartition(".")
        try:
            owner = importlib.import_module(module)
        except ModuleNotFoundError:  # a method: module.Class.method
            module, _, cls = module.rpartition(".")
            owner = getattr(importlib.import_module(module), cls)
        assert callable(getattr(owner, attribute)), column.name
        assert column.meaning and column.unit, column.name


def test_a_declared_name_cannot_be_declared_again() -> None:
    with pytest.raises(ValueError, match="already declared"):
        schema.register(Column("pos_rmse_rel", "accuracy"))
    with pytest.raises(ValueError, match="kind"):
        Column("x", "speed")


def test_the_stability_metrics_of_compare_the_headline_and_the_report_agree(tmp_path) -> None:
    stability = stability_metrics()
    assert {"status", "finite", "inverted_tets_frame_max", "line_search_stalls", "step_retries"} <= set(stability)
    assert "stick_agree" not in stability  # agreement with the reference: accuracy
    rules = {r.metric for r in default_rules() if r.kind == "stability"}
    assert rules == {m for m in stability if COLUMNS[m].better != "none"}
    row = {"suite": "s", "scenario": "a", "solver": "full", "variant": "v", "pos_rmse_rel": 0.01}
    frame = pd.DataFrame([row | {m: 0 for m in stability} | {"status": "ok", "finite": True, "failure": ""}])
    page = write_report_html(frame, tmp_path).read_text()
    section = page[page.index('<section id="stability">'):page.index('<section id="gate-verdicts">')]

    def failed(metric: str) -> dict:
        """A failed gate verdict on the row's metric."""
        return {"gate": "g", "scenario": "a", "variant": "full/v", "metric": metric, "passed": False,
                "status": "failed"}

    for metric in stability:
        assert f"<th>{metric}</th>" in section, metric
        assert headline_table(frame, [failed(metric)]).loc[0, "stable runs"] == "0 of 1", metric
    assert headline_table(frame, [failed("stick_agree")]).loc[0, "stable runs"] == "1 of 1"


@pytest.mark.parametrize("value, missing, as_number, as_flag", [
    (None, True, None, None),
    (float("nan"), True, None, None),
    (pd.NA, True, None, None),
    ("", False, None, None),
    ("True", False, None, True),
    (" true", False, None, True),
    ("ok", False, None, True),
    ("false", False, None, False),
    ("failed", False, None, False),
    ("undecidable", False, None, None),
    (True, False, 1.0, True),
    (np.bool_(False), False, 0.0, False),
    (0, False, 0.0, False),
    (2.5, False, 2.5, True),
    ("1.0", False, 1.0, True),
    ("0", False, 0.0, False),
    ("1e-3", False, 1e-3, None),
    (float("inf"), False, float("inf"), True),
])
def test_one_reader_of_a_results_cell(value, missing, as_number, as_flag) -> None:
    assert is_missing(value) is missing
    assert number(value) == as_number
    assert flag(value) is as_flag
    assert truthy(value) is (as_flag is True)


def test_a_finite_number_leaves_out_infinities() -> None:
    assert number(float("inf"), finite=True) is None and number("-inf", finite=True) is None
    assert number("3", finite=True) == 3.0


def test_a_cell_reads_the_same_from_csv_text_and_from_memory(tmp_path) -> None:
    flags, numbers = [True, False, None, "ok", "failed"], [0.25, None, 3.0]
    path = tmp_path / "cells.csv"
    pd.DataFrame({"flag": flags, "number": numbers + [None] * 2}).to_csv(path, index=False)
    read = pd.read_csv(path)
    assert [flag(v) for v in read["flag"]] == [flag(v) for v in flags] == [True, False, None, True, False]
    assert [number(v) for v in read["number"][:3]] == [number(v) for v in numbers] == [0.25, None, 3.0]

"""Figures derived across results rows (analysis.derived)."""

from __future__ import annotations

import pandas as pd
import pytest

from frictionbench.analysis.derived import remeshing_summary, with_remesh_ratio


def row(scenario: str, mesh: str, err: float, remesh: str = "", status: str = "ok") -> dict:
    return {"scenario": scenario, "split": "test", "solver": "licrom", "variant": "m-re" if remesh else "m",
            "model": "m", "remesh": remesh, "mesh": mesh, "train_mesh": "cheese/medium", "status": status,
            "pos_rmse_rel": err}


def test_remeshing_summary_gives_each_mesh_its_median_error_and_the_median_of_the_rows_ratios() -> None:
    rows = with_remesh_ratio([row("a", "cheese/medium", 0.01), row("b", "cheese/medium", 0.04),
                              row("a", "cheese/alt", 0.03, "alt"), row("b", "cheese/alt", 0.04, "alt")])
    table = remeshing_summary(pd.DataFrame(rows)).set_index("mesh")
    assert table.loc["cheese/medium", "median_pos_rmse_rel"] == pytest.approx(0.025)
    assert pd.isna(table.loc["cheese/medium", "median_remesh_ratio"])
    assert table.loc["cheese/alt", "median_pos_rmse_rel"] == pytest.approx(0.035)
    assert table.loc["cheese/alt", "median_remesh_ratio"] == pytest.approx((3.0 + 1.0) / 2)  # not 0.035 / 0.025
    assert list(table["runs"]) == [2, 2] and set(table["model"]) == {"licrom/m"}


def test_a_remeshed_row_is_compared_with_the_twin_its_remesh_of_names() -> None:
    """Two levels of one model on the training mesh: the remeshed dt/2 level is compared with the dt/2 level (its
    remesh_of), not with the model's base variant."""
    base, half = row("a", "cheese/medium", 0.04), row("a", "cheese/medium", 0.01) | {"variant": "m-dt/2"}
    other = row("a", "cheese/alt", 0.03, "alt") | {"variant": "m-dt/2-re", "remesh_of": "m-dt/2"}
    assert with_remesh_ratio([base, half, other])[2]["remesh_ratio"] == pytest.approx(3.0)  # not 0.03 / 0.04
    assert with_remesh_ratio([base, half, other | {"remesh_of": ""}])[2]["remesh_ratio"] == pytest.approx(0.75)


def test_remeshing_summary_is_empty_without_a_run_on_another_mesh() -> None:
    assert remeshing_summary(pd.DataFrame([row("a", "cheese/medium", 0.01)])).empty
    assert remeshing_summary(pd.DataFrame([{"scenario": "a", "pos_rmse_rel": 0.1}])).empty


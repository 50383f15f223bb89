"""Figures derived across rows of the results table: how much remeshing costs a reduced model.

Rows are the results table's rows as dicts (`bench.runner.collect_rows`) or a DataFrame read from results.csv.
"""

from __future__ import annotations

import pandas as pd

from analysis.table import variant_labels


def with_remesh_ratio(rows: list[dict]) -> list[dict]:
    """Rows with `remesh_ratio` on each row of a model run on another mesh than its training mesh: its
    pos_rmse_rel / that of the same model on the same scenario on the training mesh (1 = remeshing costs nothing;
    empty where either run failed)."""
    on_train = {(r["scenario"], r["solver"], r["variant"]): r.get("pos_rmse_rel") for r in rows
                if not r.get("remesh") and r.get("status") == "ok"}
    out = []
    for r in rows:
        if r.get("remesh") and r.get("train_mesh"):
            base, err = on_train.get((r["scenario"], r["solver"], r.get("model"))), r.get("pos_rmse_rel")
            ratio = err / base if base and err is not None and r.get("status") == "ok" else None
            r = r | {"remesh_ratio": ratio}
        out.append(r)
    return out


def remeshing_summary(frame: pd.DataFrame) -> pd.DataFrame:
    """Per model, training mesh, split and mesh it ran on: `runs`, `median_pos_rmse_rel` and
    `median_remesh_ratio` (the median of the rows' `remesh_ratio`; empty on the training mesh itself).

    A model is its solver and `model` label (variants that differ only by the mesh they ran on share it). Only
    rows with a training mesh count; the table is empty when no model ran on a mesh other than its training mesh.
    """
    if not {"train_mesh", "mesh", "solver", "pos_rmse_rel"} <= set(frame.columns):
        return pd.DataFrame()
    rows = frame[frame["train_mesh"].notna() & (frame["train_mesh"].astype(str) != "")].copy()
    if not (rows["mesh"] != rows["train_mesh"]).any():
        return pd.DataFrame()
    rows["model"] = (rows["solver"].astype(str) + "/" + rows["model"].astype(str) if "model" in rows
                     else variant_labels(rows))
    rows["pos_rmse_rel"] = pd.to_numeric(rows["pos_rmse_rel"], errors="coerce")
    rows["remesh_ratio"] = pd.to_numeric(rows.get("remesh_ratio", pd.Series(float("nan"), index=rows.index)),
                                         errors="coerce")
    keys = ["model", "train_mesh"] + (["split"] if "split" in rows else []) + ["mesh"]
    return (rows.groupby(keys, dropna=False)
            .agg(runs=("pos_rmse_rel", "count"), median_pos_rmse_rel=("pos_rmse_rel", "median"),
                 median_remesh_ratio=("remesh_ratio", "median"))
            .reset_index())

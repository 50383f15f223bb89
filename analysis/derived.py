"""Figures derived across rows of the results table: how much remeshing costs a reduced model, and how far the
reference moves when its time step is refined.

Rows are the results table's rows as dicts (`analysis.rows.collect_rows`) or a DataFrame read from results.csv.
"""

from __future__ import annotations

import pandas as pd

from frictionbench.analysis.table import variant_labels


def with_remesh_ratio(rows: list[dict]) -> list[dict]:
    """Rows with `remesh_ratio` on each row of a model run on another mesh than its training mesh: its
    pos_rmse_rel / that of its twin on the same scenario on the training mesh, the variant its `remesh_of` names
    (else its `model`) (1 = remeshing costs nothing; empty where either run failed)."""
    on_train = {(r["scenario"], r["solver"], r["variant"]): r.get("pos_rmse_rel") for r in rows
                if not r.get("remesh") and r.get("status") == "ok"}
    out = []
    for r in rows:
        if r.get("remesh") and r.get("train_mesh"):
            twin = r.get("remesh_of") or r.get("model")
            base, err = on_train.get((r["scenario"], r["solver"], twin)), r.get("pos_rmse_rel")
            ratio = err / base if base and err is not None and r.get("status") == "ok" else None
            r = r | {"remesh_ratio": ratio}
        out.append(r)
    return out


def with_ref_dt_change(rows: list[dict]) -> list[dict]:
    """Rows with `ref_dt_change` on every row of a scenario that has a run of the reference's solver on the
    reference's mesh at a smaller time step than the reference's: that run's pos_rmse_rel against the reference
    (the smallest such dt where there are several). It is how far the reference moves when its time step is
    refined: where the error shrinks with dt the reference's own time-discretisation error is at least half of it,
    and about twice it once backward Euler is in its first-order range; a reduced model's error of that order is
    within the reference's own accuracy."""
    refs = {r["scenario"]: r for r in rows if r.get("variant") == "reference"}
    ref_dt = {name: r.get("dt") or 0.0 for name, r in refs.items()}
    finer = [r for r in rows if r["scenario"] in refs and r.get("solver") == refs[r["scenario"]].get("solver")
             and not r.get("remesh") and not r.get("ladder") and r.get("status") == "ok"
             and r.get("dt") is not None and r["dt"] < ref_dt.get(r["scenario"], 0.0)]
    change = {r["scenario"]: r.get("pos_rmse_rel") for r in sorted(finer, key=lambda r: -r["dt"])}  # finest last
    return [r | {"ref_dt_change": change[r["scenario"]]} if r["scenario"] in change else r for r in rows]


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

"""The report's first screen: per solver family its best variant's accuracy, speed, stick/slip agreement,
stability and whether the truth is certified, with a truth the family's best measured speed-up at equal accuracy
(over all its variants) and the accuracy at which it holds, and the gates as a count with the failures listed.

Accuracy is against the ground truth (`err_truth`) when the results have one, else against the same-dt reference
(`pos_rmse_rel`), with the step-time speed-up in place of the speed-up at equal accuracy (`reports.plots.
accuracy_columns`). Ground-truth ladder rows (a non-empty `ladder` column) are not variants of a family.
"""

from __future__ import annotations

import dataclasses
from collections.abc import Mapping, Sequence

import numpy as np
import pandas as pd

from frictionbench.analysis.schema import flag, is_missing, stability_metrics, truthy
from frictionbench.analysis.table import variant_labels
from frictionbench.reports.plots import accuracy_columns, ladder_mask, numeric_column


def verdict_frame(gates: Sequence[object]) -> pd.DataFrame:
    """Gate verdicts (mappings, dataclasses or plain objects) as a table with a `status` column: `passed`,
    `failed` or `undecidable` (the verdicts' own `status` where they have one, else from `passed`)."""
    rows = []
    for verdict in gates:
        if isinstance(verdict, Mapping):
            rows.append(dict(verdict))
        elif dataclasses.is_dataclass(verdict) and not isinstance(verdict, type):
            rows.append(dataclasses.asdict(verdict))
        else:
            rows.append(dict(vars(verdict)))
    frame = pd.DataFrame(rows)
    if frame.empty:
        return frame
    passed = frame["passed"].map(truthy) if "passed" in frame else pd.Series(False, index=frame.index)
    own = frame["status"] if "status" in frame else pd.Series(None, index=frame.index, dtype=object)
    frame["status"] = own.where(own.notna(), passed.map({True: "passed", False: "failed"}))
    frame["passed"] = passed
    return frame


def _runs_ok(frame: pd.DataFrame) -> pd.Series:
    """Runs that finished (status ok or missing), with finite positions and no unconverged step."""
    status = frame["status"].fillna("ok").astype(str) if "status" in frame else pd.Series("ok", index=frame.index)
    finite = frame["finite"].map(lambda v: is_missing(v) or truthy(v)) if "finite" in frame \
        else pd.Series(True, index=frame.index)
    unconverged = numeric_column(frame, "not_converged").fillna(0.0)
    return (status == "ok") & finite.astype(bool) & (unconverged == 0)


def _count(mask: pd.Series) -> str:
    return f"{int(mask.sum())} of {len(mask)}" if len(mask) else "\u2013"


def ranked_variants(frame: pd.DataFrame) -> dict[str, list[str]]:
    """Solver family -> the labels (`solver/variant`) of its variants from the lowest median error over their
    finished runs (the error column of `accuracy_columns`) to the highest, those without an error last; ladder
    rows are left out."""
    cols = accuracy_columns(frame)
    f = frame[~ladder_mask(frame)]
    if f.empty or "solver" not in f:
        return {}
    err = numeric_column(f, cols.error).where(_runs_ok(f))
    medians = pd.DataFrame({"family": f["solver"].astype(str), "label": variant_labels(f), "err": err})
    medians = medians.groupby(["family", "label"], sort=True)["err"].median().reset_index()
    medians["missing"] = medians["err"].isna()
    medians = medians.sort_values(["family", "missing", "err", "label"])
    return {family: list(g["label"]) for family, g in medians.groupby("family", sort=True)}


def best_variants(frame: pd.DataFrame) -> dict[str, str]:
    """Solver family -> the label of its best variant (the first of `ranked_variants`)."""
    return {family: labels[0] for family, labels in ranked_variants(frame).items()}


def headline_table(frame: pd.DataFrame, gates: Sequence[object] = ()) -> pd.DataFrame:
    """One row per solver family: its best variant, runs, median error, median speed-up, stick/slip agreement,
    stable runs (finished, finite, converged, and every stability check of its case passed), the truth's
    certification over its scenarios and, where the results have them, the variant's frontier notes with their
    counts."""
    cols = accuracy_columns(frame)
    best = best_variants(frame)
    labels = variant_labels(frame)
    verdicts = verdict_frame(gates)
    unstable: set[tuple[str, str]] = set()
    if not verdicts.empty and {"metric", "scenario", "variant"} <= set(verdicts):
        # a gate or advisory check on a stability metric (`analysis.schema.stability_metrics`) failed
        bad = verdicts[verdicts["metric"].isin(stability_metrics()) & (verdicts["status"] == "failed")]
        unstable = set(zip(bad["scenario"].astype(str), bad["variant"].astype(str)))
    rows = []
    for family, label in best.items():
        g = frame[(labels == label) & ~ladder_mask(frame)]
        stick = g["stick_agree"].dropna().map(truthy) if "stick_agree" in g else pd.Series(dtype=bool)
        scen = g["scenario"].astype(str) if "scenario" in g else pd.Series("", index=g.index)
        stable = _runs_ok(g) & ~pd.Series([(s, label) in unstable for s in scen], index=g.index, dtype=bool)
        if "truth_certified" in g and cols.truth:
            per_scenario = g.groupby(scen)["truth_certified"].first().map(truthy)
            certified = ("yes" if per_scenario.all() else "no" if not per_scenario.any()
                         else f"{int(per_scenario.sum())} of {len(per_scenario)} scenarios")
        else:
            certified = "no truth"
        rows.append({"solver": family, "best variant": label, "runs": len(g),
                     f"median {cols.error}": numeric_column(g, cols.error).median(),
                     f"median {cols.speedup}": numeric_column(g, cols.speedup).median(),
                     "stick/slip agreement": _count(stick), "stable runs": _count(stable),
                     "truth certified": certified})
        if cols.truth:
            rows[-1] |= best_measured_speedup(frame[(frame["solver"].astype(str) == family) & ~ladder_mask(frame)])
        notes = g["frontier_note"].dropna().astype(str) if "frontier_note" in g else pd.Series(dtype=str)
        notes = notes[notes.str.strip() != ""]
        if not notes.empty:  # why a speed-up at equal accuracy is missing, e.g. more accurate than the ladder
            rows[-1]["frontier note"] = "; ".join(f"{note} ({n})" for note, n in notes.value_counts().items())
    return pd.DataFrame(rows)


#: The headline's columns of a family's best measured speed-up at equal accuracy and where it holds.
BEST_SPEEDUP, BEST_AT = "best measured speedup_equal_accuracy", "at err_truth (variant, scenario)"


def best_measured_speedup(rows: pd.DataFrame) -> dict[str, object]:
    """Of a family's finished rows (any variant, any scenario), the largest `speedup_equal_accuracy` that is
    measured, i.e. interpolated on the full-space ladder (no `frontier_note`: not an upper bound, not beyond the
    ladder), and the err_truth [fraction of L], variant and scenario at which it holds, saying so where its run
    and its ladder's were timed in different sessions (`timed_beside_ladder` False: a resumed store); NaN and an en
    dash where none is."""
    speed = numeric_column(rows, "speedup_equal_accuracy").where(_runs_ok(rows))
    if "frontier_note" in rows:
        notes = rows["frontier_note"].map(lambda v: "" if is_missing(v) else str(v).strip())
        speed = speed.where(notes == "")
    if speed.dropna().empty:
        return {BEST_SPEEDUP: np.nan, BEST_AT: "\u2013"}
    i = speed.idxmax()
    err = numeric_column(rows, "err_truth")[i]
    apart = "timed_beside_ladder" in rows and flag(rows.loc[i, "timed_beside_ladder"]) is False
    return {BEST_SPEEDUP: float(speed[i]),
            BEST_AT: f"{err:.3g} ({variant_labels(rows.loc[[i]]).iloc[0]}, {rows.loc[i, 'scenario']})"
                     + ("; its ladder timed in another session" if apart else "")}


def truth_summary(frame: pd.DataFrame) -> str:
    """A sentence on what the accuracy is measured against: the ground truth (how many scenarios have a
    certified one, the largest error estimate) or, without one, the same-dt reference."""
    cols = accuracy_columns(frame)
    if not cols.truth:
        return ("No ground truth in this result set; accuracy against the same-dt reference (pos_rmse_rel, "
                "fraction of the body's size L) and the step-time speed-up.")
    scen = frame["scenario"].astype(str) if "scenario" in frame else pd.Series("", index=frame.index)
    has = numeric_column(frame, "err_truth").notna()
    scenarios = sorted(set(scen[has]))
    certified = (frame[has].groupby(scen[has])["truth_certified"].first().map(truthy)
                 if "truth_certified" in frame else pd.Series(False, index=scenarios))
    est = numeric_column(frame[has], "truth_err_est").max()
    horizon = numeric_column(frame[has], "truth_horizon_s").groupby(scen[has]).first()
    uncertified = [s + (f" (within tolerance up to t = {horizon[s]:.3g} s)" if np.isfinite(horizon.get(s, np.nan))
                        else "")
                   for s in scenarios if not certified.get(s, False)]
    text = (f"Accuracy against the ground truth (err_truth, fraction of the body's size L) on {len(scenarios)} "
            f"scenarios, certified on {int(certified.sum())}"
            + (f" (largest error estimate {est:.2g} L)" if np.isfinite(est) else "")
            + (f"; not certified: {', '.join(uncertified)}" if uncertified else "")
            + ". Cost: stepping wall time per simulated second; speed-up at equal accuracy against the "
              "full-space ladder.")
    return text

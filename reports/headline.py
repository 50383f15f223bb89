"""The report's first-screen table: per solver family its best variant (chosen on the accuracy-cost frontier by
`analysis.summary`, the same choice its sentence and the terminal state), that variant's accuracy, cost, speed-up at
equal accuracy (written `<= x` where it is an upper bound) and per-step speed-up, stick/slip agreement, stability
and whether the truth is certified, and with a truth the family's best measured speed-up at equal accuracy (over
all its variants) and the accuracy at which it holds.

Accuracy is against the ground truth (`err_truth`) when the results have one, else against the same-dt reference
(`pos_rmse_rel`; `analysis.summary.accuracy_columns`). Ground-truth ladder rows (a non-empty `ladder` column) are
not variants of a family.
"""

from __future__ import annotations

from collections.abc import Sequence

import numpy as np
import pandas as pd

from frictionbench.analysis.schema import flag, stability_metrics, truthy
from frictionbench.analysis.summary import (FamilySummary, TruthCounts, accuracy_columns, bound_mask, fmt,
                                            family_summaries, ladder_mask, numeric_column, pct, runs_ok,
                                            verdict_frame)
from frictionbench.analysis.table import variant_labels

#: The headline's column of the chosen variant's speed-up at equal accuracy (`<= x` where an upper bound).
SPEEDUP = "speedup at equal accuracy"
#: The headline's column of the chosen variant's median per-step speed-up.
STEP_SPEEDUP = "per-step speedup"
#: The headline's columns of a family's best measured speed-up at equal accuracy and where it holds.
BEST_SPEEDUP, BEST_AT = "best measured speedup_equal_accuracy", "at err_truth (variant, scenario)"
#: How the best variant was chosen (`analysis.summary.FamilySummary.basis`), in words.
BASIS = {"measured": "frontier: largest measured speedup", "bound": "frontier: closest (bounds only)",
         "accuracy": "frontier: lowest error", "reference": "lowest error vs reference (no truth)",
         "failed": "every run failed"}


def _count(mask: pd.Series) -> str:
    return f"{int(mask.sum())} of {len(mask)}" if len(mask) else "\u2013"


def speedup_text(value: float | None, bound: bool) -> object:
    """A speed-up at equal accuracy as a table shows it: the number, `<= x` where it is an upper bound, None where
    there is none."""
    if value is None or not np.isfinite(value):
        return None
    return f"<= {fmt(value)}" if bound else float(value)


def with_bounds(frame: pd.DataFrame) -> pd.DataFrame:
    """The frame with its `speedup_equal_accuracy` written `<= x` on the rows where it is an upper bound
    (`analysis.summary.bound_mask`); unchanged without the column or without a bound."""
    if "speedup_equal_accuracy" not in frame:
        return frame
    bound = bound_mask(frame) & numeric_column(frame, "speedup_equal_accuracy").notna()
    if not bound.any():
        return frame
    out = frame.copy()
    out["speedup_equal_accuracy"] = out["speedup_equal_accuracy"].astype(object)
    out.loc[bound, "speedup_equal_accuracy"] = [speedup_text(float(v), True)
                                                 for v in numeric_column(frame, "speedup_equal_accuracy")[bound]]
    return out


def ranked_variants(frame: pd.DataFrame) -> dict[str, list[str]]:
    """Solver family -> the labels (`solver/variant`) of its variants: its best (`analysis.summary`) first, then the
    others from the lowest median error over their finished runs to the highest, those without an error last;
    ladder rows are left out."""
    cols = accuracy_columns(frame)
    f = frame[~ladder_mask(frame)]
    if f.empty or "solver" not in f:
        return {}
    best = {s.family: s.chosen.label for s in family_summaries(frame) if s.chosen is not None}
    err = numeric_column(f, cols.error).where(runs_ok(f))
    medians = pd.DataFrame({"family": f["solver"].astype(str), "label": variant_labels(f), "err": err})
    medians = medians.groupby(["family", "label"], sort=True)["err"].median().reset_index()
    medians["missing"] = medians["err"].isna()
    medians["best"] = [best.get(fam) != lab for fam, lab in zip(medians["family"], medians["label"])]
    medians = medians.sort_values(["family", "best", "missing", "err", "label"])
    return {family: list(g["label"]) for family, g in medians.groupby("family", sort=True)}


def headline_table(frame: pd.DataFrame, gates: Sequence[object] = (),
                   families: Sequence[FamilySummary] | None = None) -> pd.DataFrame:
    """One row per solver family: its best variant (`analysis.summary.family_summaries`, or `families` when given)
    and how it was chosen (BASIS), its median error and cost, speed-up at equal accuracy and per-step speed-up,
    stick/slip agreement, stable runs (finished, finite, converged, and every stability check of its case passed)
    and the truth's certification over its scenarios; with a truth, the family's best measured speed-up."""
    cols = accuracy_columns(frame)
    families = family_summaries(frame) if families is None else families
    labels = variant_labels(frame)
    ladder = ladder_mask(frame)
    verdicts = verdict_frame(gates)
    unstable: set[tuple[str, str]] = set()
    if not verdicts.empty and {"metric", "scenario", "variant"} <= set(verdicts):
        # a gate or advisory check on a stability metric (`analysis.schema.stability_metrics`) failed
        bad = verdicts[verdicts["metric"].isin(stability_metrics()) & (verdicts["status"] == "failed")]
        unstable = set(zip(bad["scenario"].astype(str), bad["variant"].astype(str)))
    rows = []
    for summary in families:
        v = summary.chosen
        label = v.label if v is not None else ""
        g = frame[(labels == label) & ~ladder] if v is not None else frame[
            (frame["solver"].astype(str) == summary.family) & ~ladder]
        stick = g["stick_agree"].dropna().map(truthy) if "stick_agree" in g else pd.Series(dtype=bool)
        scen = g["scenario"].astype(str) if "scenario" in g else pd.Series("", index=g.index)
        stable = runs_ok(g) & ~pd.Series([(s, label) in unstable for s in scen], index=g.index, dtype=bool)
        if "truth_certified" in g and cols.truth:
            per_scenario = g.groupby(scen)["truth_certified"].first().map(truthy)
            certified = ("yes" if per_scenario.all() else "no" if not per_scenario.any()
                         else f"{int(per_scenario.sum())} of {len(per_scenario)} scenarios")
        else:
            certified = "no truth"
        row = {"solver": summary.family, "best variant": label or "\u2013", "chosen as": BASIS[summary.basis],
               f"median {cols.error}": v.error if v is not None else None,
               f"median {cols.cost}": v.cost if v is not None else None}
        if cols.truth:
            row[SPEEDUP] = speedup_text(v.speedup, v.bound) if v is not None else None
        row |= {STEP_SPEEDUP: v.step_speedup if v is not None else None, "stick/slip agreement": _count(stick),
                "stable runs": _count(stable), "truth certified": certified}
        if cols.truth:
            row |= best_measured_speedup(frame[(frame["solver"].astype(str) == summary.family) & ~ladder])
        rows.append(row)
    return pd.DataFrame(rows)


def best_measured_speedup(rows: pd.DataFrame) -> dict[str, object]:
    """Of a family's finished rows (any variant, any scenario), the largest `speedup_equal_accuracy` that is
    measured, i.e. interpolated on the full-space front (no `frontier_note`: not an upper bound, not beyond it), and
    the err_truth [fraction of L], variant and scenario at which it holds, saying so where its run and its ladder's
    were timed in different sessions (`timed_beside_ladder` False: a resumed store); NaN and an en dash where none
    is."""
    speed = numeric_column(rows, "speedup_equal_accuracy").where(runs_ok(rows))
    if "frontier_note" in rows:
        notes = rows["frontier_note"].map(lambda v: "" if not isinstance(v, str) else v.strip())
        speed = speed.where(notes == "")
    if speed.dropna().empty:
        return {BEST_SPEEDUP: np.nan, BEST_AT: "\u2013"}
    i = speed.idxmax()
    err = numeric_column(rows, "err_truth")[i]
    apart = "timed_beside_ladder" in rows and flag(rows.loc[i, "timed_beside_ladder"]) is False
    return {BEST_SPEEDUP: float(speed[i]),
            BEST_AT: f"{err:.3g} ({variant_labels(rows.loc[[i]]).iloc[0]}, {rows.loc[i, 'scenario']})"
                     + ("; its ladder timed in another session" if apart else "")}


def truth_summary(truth: TruthCounts) -> str:
    """A sentence on what the accuracy is measured against: the ground truth (how many scenarios have a
    certified one, the largest error estimate, how far the uncertified ones hold) or, without one, the same-dt
    reference."""
    if not truth.present:
        return ("No ground truth in this result set (run without --no-truth for one): accuracy against the same-dt "
                "reference (pos_rmse_rel, a fraction of the body's size L) and the per-step speedup.")
    uncertified = [s + (f" (within tolerance up to t = {h:.3g} s)" if h is not None else "")
                   for s, h in truth.uncertified]
    return (f"Accuracy against the ground truth (err_truth, a fraction of the body's size L) on {truth.scenarios} "
            f"scenarios, certified on {truth.certified}"
            + (f" (largest error estimate {pct(truth.err_est_max)} of L)" if truth.err_est_max is not None else "")
            + (f"; not certified: {', '.join(uncertified)}" if uncertified else "")
            + ". Cost: wall_s_per_sim_s; speedup at equal accuracy against the full-space solver's runs.")

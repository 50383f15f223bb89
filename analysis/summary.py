"""The answer of a result set in plain words, computed once for the report's first screen (`reports.html`) and the
terminal (`frictionbench run` and `report`): per solver family one sentence on its best variant, the truths'
certification, the gate verdicts and one verdict banner.

A family is a solver (`full`, `licrom`, `pod`, ...); its variants are its rows' `solver/variant` labels, ladder rows
(a non-empty `ladder`) left out. A variant's figures are medians over its finished runs (`runs_ok`), one per
scenario: its error (err_truth against the ground truth, else pos_rmse_rel against the same-dt reference) as a
fraction of L, its cost wall_s_per_sim_s [s/s] and its speed-up at equal accuracy (`analysis.truth.with_frontier`),
an upper bound where any of its runs' is (`frontier_note` == AT_MOST: the median of values each at most its bound
is at most the median of the bounds).

The best variant of a family is chosen on the accuracy-cost frontier, not by error alone: among the variants on the
family's own Pareto front of (error, cost) (`analysis.truth.pareto_front`), the one with the largest measured speed-up
at equal accuracy; where every speed-up on the front is an upper bound, the closest to the full-space solver's
accuracy (the lowest error, errors within ACCURACY_TOL["rel"] of the lowest counting as equal and the cheapest of
those winning: a difference `compare` would not call a change); where none has a speed-up, the lowest error. Without
a ground truth there is no speed-up at equal accuracy: the lowest error against the reference (the reference itself
only where a family has nothing else).

Every function is pure: a results frame (and gate verdicts) in, plain data out.
"""

from __future__ import annotations

import dataclasses
import math
from collections.abc import Mapping, Sequence
from dataclasses import dataclass

import numpy as np
import pandas as pd

from frictionbench.analysis.schema import ACCURACY_TOL, is_missing, truthy
from frictionbench.analysis.table import variant_labels
from frictionbench.analysis.truth import AT_MOST, MORE_ACCURATE, pareto_front

#: The variant label of the same-dt full-space run every other run is compared with.
REFERENCE_VARIANT = "reference"
#: A reason names the time step when the full-space run at the variant's own step (err_time) makes at least this
#: share of the variant's error against the truth.
TIME_STEP_SHARE = 0.5
#: A speed-up within this factor of 1 reads "about as much as" the full-space solver.
PARITY = 0.05
#: Banner levels, best first: every check passed; nothing binding failed but something is undecided or advisory
#: checks failed; a binding gate or a run failed.
LEVELS: tuple[str, ...] = ("pass", "warn", "fail")


@dataclass(frozen=True)
class AccuracyColumns:
    """Which result columns measure accuracy and cost: against the ground truth when the results have one.

    error: `err_truth`, else `pos_rmse_rel` (against the same-dt reference); cost: `wall_s_per_sim_s` (stepping
    wall time per simulated second), else `step_ms_median`; speedup: `speedup_equal_accuracy`, else the step-time
    `speedup`; truth: whether err_truth has values.
    """

    error: str
    cost: str
    speedup: str
    truth: bool


def numeric_column(frame: pd.DataFrame, column: str) -> pd.Series:
    """The column as floats (NaN where missing or not a number; all NaN when the column is absent)."""
    if column not in frame:
        return pd.Series(np.nan, index=frame.index, dtype=float)
    return pd.to_numeric(frame[column], errors="coerce").astype(float)


def accuracy_columns(frame: pd.DataFrame) -> AccuracyColumns:
    """The accuracy and cost columns of these results (see `AccuracyColumns`)."""
    truth = bool(np.isfinite(numeric_column(frame, "err_truth")).any())
    wall = numeric_column(frame, "wall_s_per_sim_s")
    return AccuracyColumns(error="err_truth" if truth else "pos_rmse_rel",
                           cost="wall_s_per_sim_s" if bool((wall > 0).any()) else "step_ms_median",
                           speedup="speedup_equal_accuracy" if truth else "speedup", truth=truth)


def ladder_mask(frame: pd.DataFrame) -> pd.Series:
    """True on the rows of a ground-truth ladder (a non-empty `ladder` column)."""
    if "ladder" not in frame:
        return pd.Series(False, index=frame.index)
    return frame["ladder"].fillna("").astype(str).str.strip() != ""


def text_column(frame: pd.DataFrame, column: str) -> pd.Series:
    """The column as stripped texts ('' where missing or absent)."""
    if column not in frame:
        return pd.Series("", index=frame.index, dtype=object)
    return frame[column].map(lambda v: "" if is_missing(v) else str(v).strip())


def bound_mask(frame: pd.DataFrame) -> pd.Series:
    """True on the rows whose `speedup_equal_accuracy` is an upper bound (`frontier_note` == AT_MOST)."""
    return text_column(frame, "frontier_note") == AT_MOST


def finished(frame: pd.DataFrame) -> pd.Series:
    """Runs that finished: status ok (or missing)."""
    return text_column(frame, "status").replace("", "ok") == "ok"


def finite_runs(frame: pd.DataFrame) -> pd.Series:
    """Runs whose stored values are all finite (or that do not say)."""
    if "finite" not in frame:
        return pd.Series(True, index=frame.index)
    return frame["finite"].map(lambda v: is_missing(v) or truthy(v)).astype(bool)


def runs_ok(frame: pd.DataFrame) -> pd.Series:
    """Runs that finished (status ok or missing), with finite positions and no unconverged step."""
    unconverged = numeric_column(frame, "not_converged").fillna(0.0)
    return finished(frame) & finite_runs(frame) & (unconverged == 0)


def verdict_frame(gates: Sequence[object]) -> pd.DataFrame:
    """Gate verdicts (mappings, dataclasses or plain objects) as a table with a `status` column: `passed`,
    `failed` or `undecidable` (the verdicts' own `status` where they have one, else from `passed`), and a boolean
    `advisory` (False where a verdict does not say)."""
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
    frame["advisory"] = frame["advisory"].map(truthy) if "advisory" in frame else False
    return frame


@dataclass(frozen=True)
class VariantFigures:
    """One variant's figures over its finished runs (one per scenario).

    label: `solver/variant`; runs: its rows; ok: those that finished cleanly (`runs_ok`); error: the median error
    [fraction of L] (err_truth, else pos_rmse_rel); cost: the median cost (wall_s_per_sim_s [s/s], else
    step_ms_median [ms]); speedup: the median speed-up at equal accuracy over the runs that have one (None: none
    has); speedup_runs: those runs; bound_runs: those of them whose speed-up is an upper bound; more_accurate: runs
    more accurate than every full-space run but the truth (no speed-up); step_speedup: the median per-step speed-up
    (`speedup`); err_time, reduction: median err_time and pos_rmse_rel [fraction of L] (None: no value);
    certified, scenarios: its scenarios with a certified truth, and with a truth.
    """

    label: str
    runs: int
    ok: int
    error: float | None
    cost: float | None
    speedup: float | None
    speedup_runs: int
    bound_runs: int
    more_accurate: int
    step_speedup: float | None
    err_time: float | None
    reduction: float | None
    certified: int
    scenarios: int

    @property
    def bound(self) -> bool:
        """Whether its speed-up at equal accuracy is an upper bound."""
        return self.speedup is not None and self.bound_runs > 0

    @property
    def measured(self) -> bool:
        """Whether its speed-up at equal accuracy is measured (interpolated on the full-space front everywhere)."""
        return self.speedup is not None and self.bound_runs == 0


@dataclass(frozen=True)
class FamilySummary:
    """One solver family's answer.

    family: the solver; chosen: its best variant's figures (None: no run finished); basis: how it was chosen,
    `measured` (the largest measured speed-up on the family's front), `bound` (every speed-up on its front an upper
    bound: the closest to the full-space accuracy), `accuracy` (no speed-up: the lowest error), `reference` (no
    truth: the lowest error against the reference) or `failed`; front: the labels on the family's accuracy-cost
    front, cheapest first; runs, failed: its rows and those that did not finish; reasons: why the speed-up is only
    a bound (basis `bound`) or missing; sentence: the answer in one sentence.
    """

    family: str
    chosen: VariantFigures | None
    basis: str
    front: tuple[str, ...]
    runs: int
    failed: int
    reasons: tuple[str, ...]
    sentence: str

    @property
    def step_speedup_text(self) -> str:
        """The chosen variant's per-step speed-up, e.g. `per-step speedup 23x` ('' without one)."""
        s = self.chosen.step_speedup if self.chosen is not None else None
        return "" if s is None else f"per-step speedup {fmt(s)}x"


@dataclass(frozen=True)
class TruthCounts:
    """The ground truth of the results: present (some err_truth), scenarios with one, those certified, the largest
    error estimate [fraction of L] (None: none) and, per uncertified scenario, the end [s] of the stretch it meets
    its tolerance frame by frame (None: not known)."""

    present: bool
    scenarios: int
    certified: int
    err_est_max: float | None
    uncertified: tuple[tuple[str, float | None], ...]

    def text(self) -> str:
        """e.g. `truths certified on 3 of 5 scenarios (largest error estimate 2.8% of L)`."""
        if not self.present:
            return "no ground truth in these results (run without --no-truth for one)"
        est = f" (largest error estimate {pct(self.err_est_max)} of L)" if self.err_est_max is not None else ""
        return f"truths certified on {self.certified} of {self.scenarios} scenarios{est}"


@dataclass(frozen=True)
class GateCounts:
    """The gate verdicts counted: binding ones (passed, failed, undecidable) and advisory ones (the same), with
    what failed or was undecidable in words, grouped by variant and metric (`grouped`)."""

    binding: int
    passed: int
    failed: int
    undecidable: int
    advisory: int
    advisory_passed: int
    advisory_failed: int
    advisory_undecidable: int
    failed_items: tuple[str, ...]
    undecidable_items: tuple[str, ...]
    advisory_items: tuple[str, ...]

    def text(self) -> str:
        """e.g. `binding gates: 35 of 40 passed, 0 failed, 5 undecidable; advisory checks: 7 of 20 passed`."""
        if not self.binding and not self.advisory:
            return "no gate applies to these results"
        text = (f"binding gates: {self.passed} of {self.binding} passed, {self.failed} failed, "
                f"{self.undecidable} undecidable")
        return text + (f"; advisory checks: {self.advisory_passed} of {self.advisory} passed, {self.advisory_failed} "
                       f"failed, {self.advisory_undecidable} undecidable" if self.advisory else "")


@dataclass(frozen=True)
class RunCounts:
    """The result rows: all of them, those that did not finish (with their failures in words), those with a
    non-finite value and those with an unconverged step."""

    rows: int
    failed: int
    non_finite: int
    unconverged: int
    failed_items: tuple[str, ...]


@dataclass(frozen=True)
class Banner:
    """The one verdict of the results: level (one of LEVELS), headline (a sentence), details (what failed or is
    undecided, in words)."""

    level: str
    headline: str
    details: tuple[str, ...]


@dataclass(frozen=True)
class Summary:
    """The answer of a result set: the banner, per family its summary, the truth, the gates and the runs."""

    banner: Banner
    families: tuple[FamilySummary, ...]
    truth: TruthCounts
    gates: GateCounts
    runs: RunCounts

    def lines(self) -> list[str]:
        """The summary for a terminal: the verdict, one line per family, the truths and the gate counts."""
        word = {"pass": "PASSED", "warn": "WARNING", "fail": "FAILED"}[self.banner.level]
        lines = [f"{word}: {self.banner.headline}"]
        for f in self.families:
            step = f" [{f.step_speedup_text}]" if f.step_speedup_text else ""
            lines.append(f"  {f.family}: {f.sentence}{step}")
        lines.append(capitalised(self.truth.text()) + ".")
        lines.append(capitalised(self.gates.text()) + f"; runs: {self.runs.failed} of {self.runs.rows} failed.")
        return lines


def capitalised(text: str) -> str:
    """The text with its first letter in upper case."""
    return text[:1].upper() + text[1:]


def fmt(x: float) -> str:
    """A figure in words: 2 significant digits, whole numbers from 100 (45, 2.6, 0.83, 456)."""
    return f"{x:.0f}" if abs(x) >= 100 else f"{x:.2g}"


def pct(x: float | None) -> str:
    """A fraction of L as a percentage, 2 significant digits (0.0293 -> `2.9%`)."""
    return "\u2013" if x is None else f"{fmt(100.0 * x)}%"


def _median(values: pd.Series) -> float | None:
    values = values[np.isfinite(values)]
    return float(values.median()) if len(values) else None


def truth_counts(frame: pd.DataFrame) -> TruthCounts:
    """How many scenarios have a ground truth and a certified one, and the largest error estimate."""
    has = numeric_column(frame, "err_truth").notna()
    if not has.any():
        return TruthCounts(False, 0, 0, None, ())
    f = frame[has]
    scen = f["scenario"].astype(str) if "scenario" in f else pd.Series("", index=f.index)
    certified = (f["truth_certified"].map(truthy).groupby(scen).first() if "truth_certified" in f
                 else pd.Series(False, index=sorted(set(scen))))
    est = numeric_column(f, "truth_err_est").max()
    horizon = numeric_column(f, "truth_horizon_s").groupby(scen).first()
    uncertified = tuple((s, float(horizon[s]) if s in horizon and np.isfinite(horizon[s]) else None)
                        for s in sorted(set(scen)) if not certified.get(s, False))
    return TruthCounts(True, int(scen.nunique()), int(certified.sum()), float(est) if np.isfinite(est) else None,
                       uncertified)


def variant_figures(frame: pd.DataFrame) -> dict[str, list[VariantFigures]]:
    """Solver family -> its variants' figures (`VariantFigures`), by label; ladder rows are left out."""
    f = frame[~ladder_mask(frame)]
    if f.empty or "solver" not in f:
        return {}
    cols = accuracy_columns(frame)
    ok = runs_ok(f)
    labels = variant_labels(f)
    err, cost = numeric_column(f, cols.error).where(ok), numeric_column(f, cols.cost).where(ok)
    speed = numeric_column(f, "speedup_equal_accuracy").where(ok & np.isfinite(numeric_column(f, "err_truth")))
    bound, more = bound_mask(f), text_column(f, "frontier_note") == MORE_ACCURATE
    certified = f["truth_certified"].map(truthy) if "truth_certified" in f else pd.Series(False, index=f.index)
    has_truth = numeric_column(f, "err_truth").notna()
    out: dict[str, list[VariantFigures]] = {}
    for (family, label), g in f.groupby([f["solver"].astype(str), labels], sort=True):
        i = g.index
        with_speed = speed[i].notna()
        out.setdefault(family, []).append(VariantFigures(
            label=label, runs=len(g), ok=int(ok[i].sum()), error=_median(err[i]), cost=_median(cost[i]),
            speedup=_median(speed[i]), speedup_runs=int(with_speed.sum()), bound_runs=int((bound[i] & with_speed).sum()),
            more_accurate=int((more[i] & ok[i]).sum()), step_speedup=_median(numeric_column(g, "speedup").where(ok[i])),
            err_time=_median(numeric_column(g, "err_time").where(ok[i])),
            reduction=_median(numeric_column(g, "pos_rmse_rel").where(ok[i])),
            certified=int(certified[i][has_truth[i]].sum()), scenarios=int(has_truth[i].sum())))
    return out


def family_front(variants: Sequence[VariantFigures]) -> list[VariantFigures]:
    """The variants on the family's own Pareto front of (error, cost) (`analysis.truth.pareto_front`), cheapest
    first; those with a positive error and cost only (the reference against itself has error 0)."""
    front = pareto_front([(v.error, v.cost) for v in variants if v.error is not None and v.cost is not None])
    by_point = {(v.error, v.cost): v for v in reversed(variants) if v.error is not None and v.cost is not None}
    return [by_point[p] for p in front]


def choose(variants: Sequence[VariantFigures], truth: bool) -> tuple[VariantFigures | None, str, list[VariantFigures]]:
    """(the best variant, the basis of the choice, the family's front): see the module's docstring and
    `FamilySummary.basis`."""
    usable = [v for v in variants if v.error is not None]
    if not usable:
        return None, "failed", []
    if not truth:
        others = [v for v in usable if not v.label.endswith("/" + REFERENCE_VARIANT)] or usable
        return min(others, key=lambda v: (v.error, v.cost if v.cost is not None else math.inf)), "reference", []
    front = family_front(usable) or usable
    measured = [v for v in front if v.measured]
    if measured:
        return max(measured, key=lambda v: v.speedup), "measured", front
    bounded = [v for v in front if v.bound]
    if bounded:
        lowest = min(v.error for v in bounded)
        close = [v for v in bounded if v.error <= lowest * (1.0 + ACCURACY_TOL["rel"])]
        return min(close, key=lambda v: (v.cost if v.cost is not None else math.inf, v.error)), "bound", front
    return min(front, key=lambda v: v.error), "accuracy", front


def _against(v: VariantFigures) -> str:
    """What its error is against: `the certified truth`, `the uncertified truth` or `the truth (certified on k of
    n of its scenarios)`."""
    if v.scenarios == 0:
        return "the truth"
    if v.certified == v.scenarios:
        return "the certified truth"
    if v.certified == 0:
        return "the uncertified truth"
    return f"the truth (certified on {v.certified} of {v.scenarios} of its scenarios)"


def _cost(v: VariantFigures, cols: AccuracyColumns) -> str:
    if v.cost is None:
        return "no measured cost"
    if cols.cost == "wall_s_per_sim_s":
        return f"{fmt(v.cost)} s per simulated second"
    return f"{fmt(v.cost)} ms per step (median)"


def _cheaper(speedup: float) -> str:
    """The speed-up at equal accuracy in words, against the full-space solver."""
    if speedup > 1.0 + PARITY:
        return f"{fmt(speedup)} times less than the full-space solver at the same accuracy"
    if speedup >= 1.0 - PARITY:
        return f"about as much as the full-space solver at the same accuracy (speedup {fmt(speedup)})"
    return f"{fmt(1.0 / speedup)} times more than the full-space solver at the same accuracy"


def bound_reasons(v: VariantFigures) -> list[str]:
    """Why a variant's speed-up at equal accuracy is only an upper bound, in words: less accurate than every
    full-space run, and how much of its error is the time step's (err_time) where that is most of it (the truth's
    certification is in the sentence itself, `_against`)."""
    n = v.speedup_runs
    reasons = ["it is less accurate than every full-space run" + (f" on {v.bound_runs} of {n} scenarios"
                                                                   if v.bound_runs < n else "")]
    if v.err_time is not None and v.error and v.err_time >= TIME_STEP_SHARE * v.error:
        reduction = f", the reduction adds {pct(v.reduction)} (pos_rmse_rel)" if v.reduction is not None else ""
        reasons.append(f"most of that is the time step's: the full-space run at its step is {pct(v.err_time)} of L "
                       f"off (err_time){reduction}")
    return reasons


def family_sentence(family: str, chosen: VariantFigures | None, basis: str, failed: int, runs: int,
                    anyone_measured: bool, cols: AccuracyColumns, failure: str = "") -> tuple[str, tuple[str, ...]]:
    """(the family's sentence, the reasons it gives): see `FamilySummary`."""
    if chosen is None:
        return (f"every run of {family} failed ({runs} runs" + (f"; first: {failure}" if failure else "") + ")"), ()
    failures = f"; {failed} of {runs} of its runs failed" if failed else ""
    error, label = pct(chosen.error), chosen.label
    if basis == "reference":
        if label.endswith("/" + REFERENCE_VARIANT):
            return f"{label} is the same-dt reference every other run is compared with; it costs " \
                   f"{_cost(chosen, cols)}{failures}", ()
        return (f"no ground truth in these results, so {label} is chosen by its error against the same-dt reference "
                f"alone: {error} of L, at {_cost(chosen, cols)}{failures}"), ()
    if basis == "measured":
        partial = (f" (measured on {chosen.speedup_runs} of {chosen.ok} scenarios)"
                   if chosen.speedup_runs < chosen.ok else "")
        return (f"at {error} of L against {_against(chosen)}, {label} costs {_cost(chosen, cols)}, "
                f"{_cheaper(chosen.speedup)}{partial}{failures}"), ()
    if basis == "bound":
        reasons = bound_reasons(chosen)
        where = "" if chosen.bound_runs == chosen.speedup_runs else " on every scenario"
        which = "variant" if not anyone_measured else "variant on its accuracy-cost frontier"
        return (f"no {family} {which} reaches the full-space solver's coarsest accuracy{where}; the closest is "
                f"{label} at {error} of L against {_against(chosen)}, {_cost(chosen, cols)}, at most "
                f"{fmt(chosen.speedup)} times faster (<= {fmt(chosen.speedup)}x), because "
                + "; ".join(reasons) + failures), tuple(reasons)
    reason = ("it is more accurate than every full-space run but the truth, so there is no full-space cost to "
              "compare it with" if chosen.more_accurate else "no full-space run to compare its cost with")
    return (f"at {error} of L against {_against(chosen)}, {label} costs {_cost(chosen, cols)}; {reason}"
            f"{failures}"), (reason,)


def family_summaries(frame: pd.DataFrame) -> list[FamilySummary]:
    """Per solver family (in name order) its summary (`FamilySummary`)."""
    cols = accuracy_columns(frame)
    f = frame[~ladder_mask(frame)]
    out = []
    for family, variants in variant_figures(frame).items():
        chosen, basis, front = choose(variants, cols.truth)
        rows = f[f["solver"].astype(str) == family]
        failed = int((~finished(rows)).sum())
        failures = text_column(rows, "failure")[~finished(rows)]
        failure = next((x for x in failures if x), "")
        sentence, reasons = family_sentence(family, chosen, basis, failed, len(rows),
                                            any(v.measured for v in variants), cols, failure)
        out.append(FamilySummary(family=family, chosen=chosen, basis=basis, front=tuple(v.label for v in front),
                                 runs=len(rows), failed=failed, reasons=reasons, sentence=sentence))
    return out


def _value(value: object) -> str:
    """A verdict's value as text: floats to 3 significant digits."""
    return f"{value:.3g}" if isinstance(value, (float, np.floating)) else str(value)


def grouped(verdicts: pd.DataFrame) -> tuple[str, ...]:
    """Verdicts in words, one per variant and metric: `licrom/r20 err_truth on 3 scenarios` (`on <scenario>: value
    (limit ...)` where one), with the first verdict's reason where it has one."""
    if verdicts.empty:
        return ()
    keys = [k for k in ("variant", "metric") if k in verdicts]
    out = []
    for key, g in (verdicts.groupby(keys, sort=True, dropna=False) if keys else [((), verdicts)]):
        key = key if isinstance(key, tuple) else (key,)
        name = " ".join(str(k) for k in key if not is_missing(k)) or str(g["gate"].iloc[0] if "gate" in g else "")
        scen = g["scenario"].dropna().astype(str).unique() if "scenario" in g else []
        where = f" on {scen[0]}" if len(scen) == 1 else f" on {len(scen)} scenarios" if len(scen) else ""
        first = g.iloc[0]
        value = (f": {_value(first['value'])} (limit {first['limit']})" if len(g) == 1 and "value" in g
                 and "limit" in g and not is_missing(first["value"]) else "")
        reason = next((r for r in text_column(g, "reason") if r), "")
        out.append(name + where + value + (f" ({reason})" if reason else ""))
    return tuple(out)


def gate_counts(gates: Sequence[object]) -> GateCounts:
    """The gate verdicts counted (`GateCounts`)."""
    v = verdict_frame(gates)
    if v.empty:
        return GateCounts(0, 0, 0, 0, 0, 0, 0, 0, (), (), ())
    binding, advisory = v[~v["advisory"]], v[v["advisory"]]
    status = binding["status"]
    return GateCounts(binding=len(binding), passed=int((status == "passed").sum()),
                      failed=int((status == "failed").sum()), undecidable=int((status == "undecidable").sum()),
                      advisory=len(advisory), advisory_passed=int((advisory["status"] == "passed").sum()),
                      advisory_failed=int((advisory["status"] == "failed").sum()),
                      advisory_undecidable=int((advisory["status"] == "undecidable").sum()),
                      failed_items=grouped(binding[status == "failed"]),
                      undecidable_items=grouped(binding[status == "undecidable"]),
                      advisory_items=grouped(advisory[advisory["status"] == "failed"]))


def run_counts(frame: pd.DataFrame) -> RunCounts:
    """The result rows counted (`RunCounts`), each failed run in words: `scenario [solver/variant]: failure`."""
    done = finished(frame)
    bad = frame[~done]
    labels = variant_labels(bad) if "solver" in bad else pd.Series("", index=bad.index)
    scen = text_column(bad, "scenario")
    why = text_column(bad, "failure")
    items = tuple(f"{s} [{lab}]" + (f": {w}" if w else "") for s, lab, w in zip(scen, labels, why))
    return RunCounts(rows=len(frame), failed=int((~done).sum()), non_finite=int((done & ~finite_runs(frame)).sum()),
                     unconverged=int((done & (numeric_column(frame, "not_converged").fillna(0.0) > 0)).sum()),
                     failed_items=items)


def banner(gates: GateCounts, runs: RunCounts) -> Banner:
    """The one verdict: `fail` where a binding gate failed or a run failed or has a non-finite value, `warn` where
    nothing binding failed but a binding gate is undecidable, an advisory check failed, a step did not converge or
    no binding gate applies, else `pass`; the headline says which, the details what, in words."""
    bad = ([f"{gates.failed} of {gates.binding} binding gates failed"] if gates.failed else []) + \
          ([f"{runs.failed} of {runs.rows} runs failed"] if runs.failed else []) + \
          ([f"{runs.non_finite} runs have non-finite values"] if runs.non_finite else [])
    doubt = ([f"{gates.undecidable} of {gates.binding} binding gates are undecidable"] if gates.undecidable else []) + \
            ([f"{gates.advisory_failed} of {gates.advisory} advisory checks failed"] if gates.advisory_failed else []) + \
            ([f"{runs.unconverged} runs have unconverged steps"] if runs.unconverged else []) + \
            (["no binding gate applies to these results"] if not gates.binding else [])
    details = ([f"Binding gates failed: {'; '.join(gates.failed_items)}."] if gates.failed_items else []) + \
              ([f"Runs failed: {'; '.join(runs.failed_items)}."] if runs.failed_items else []) + \
              ([f"Undecidable (neither passed nor failed): {'; '.join(gates.undecidable_items)}."]
               if gates.undecidable_items else []) + \
              ([f"Advisory checks failed (reported, not enforced): {'; '.join(gates.advisory_items)}."]
               if gates.advisory_items else [])
    if bad:
        return Banner("fail", capitalised("; ".join(bad)) + ".", tuple(details))
    if doubt:
        return Banner("warn", "No binding gate failed, but " + "; ".join(doubt) + ".", tuple(details))
    return Banner("pass", f"Every binding gate passed ({gates.passed} of {gates.binding}) and every run finished"
                  + (f"; advisory checks: {gates.advisory_passed} of {gates.advisory} passed" if gates.advisory
                     else "") + ".", tuple(details))


def summarise(frame: pd.DataFrame, gates: Sequence[object] = ()) -> Summary:
    """The answer of a result set (`Summary`) from its results frame and its gate verdicts (mappings, dataclasses
    or objects with at least `passed`; see `verdict_frame`)."""
    truth = truth_counts(frame)
    counts, runs = gate_counts(gates), run_counts(frame)
    return Summary(banner=banner(counts, runs), families=tuple(family_summaries(frame)), truth=truth,
                   gates=counts, runs=runs)

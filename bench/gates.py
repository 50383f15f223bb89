"""CI gates: thresholds per suite and solver variant from `gates.toml`, checked against results.csv.

The shipped gates are `bench/gates.toml`, package data of `bench` (found in an installed copy too); a run may
name another file. Format:

    [[gate]]
    suite = "quick"            # which suite's results it applies to
    variant = "full/reference" # `solver/variant` label of the rows (`*` for every row), or a list of labels
    split = "test"             # optional: only rows of this split
    tag = "expect-stick"       # optional: only rows whose scenario has this tag
    exclude_tag = "free"       # optional: not rows whose scenario has this tag
    metric = "pos_rmse_rel"
    max = 0.05                 # and/or `min = ...`; boolean metrics use `equals = true`
    advisory = true            # optional: judged and shown in the report, but never fails `frictionbench gate`
    against_truth = true       # optional: the metric is an error against the ground truth (implied for err_truth)

Each gate yields one verdict per matching row; a gate that matches no row fails (a missing run is a failure).
A verdict is `passed`, `failed` or `undecidable`: a `max` gate on an error against the truth (`err_truth`, or a
gate marked `against_truth`) whose limit is below 3x the error estimate of the row's truth, where that truth is
uncertified (`analysis.truth.decidable`), is undecidable: neither passed nor failed, and no failure of
`frictionbench gate`; so is a gate on `speedup_equal_accuracy` of a row more accurate than its whole ladder, and a
`min` gate on it whose row is less accurate than every full-space run (its number is an upper bound: below the
limit it fails, at or above it nothing is proven). A `max` gate on an outcome's error against the truth
(`analysis.schema.OUTCOMES`, e.g. `slide_err_truth`) is judged against that outcome's own convergence: undecidable
where the truth's ladder did not certify the outcome (`truth_<name>_certified`) and the limit is below 3x its
estimate (`truth_<name>_est`). An undecidable verdict's `reason` says which of these it is.
"""

from __future__ import annotations

import tomllib
from dataclasses import dataclass
from importlib import resources
from pathlib import Path

import pandas as pd

from frictionbench.analysis.schema import flag, is_missing, number, outcome_of, truthy
from frictionbench.analysis.table import variant_labels
from frictionbench.analysis.truth import AT_MOST, MORE_ACCURATE, decidable

#: Metrics that are errors against the ground truth: their `max` gates can be undecidable.
TRUTH_METRICS: tuple[str, ...] = ("err_truth",)
STATUSES: tuple[str, ...] = ("passed", "failed", "undecidable")


@dataclass(frozen=True)
class Verdict:
    """One gate checked on one results row: `status` one of STATUSES, `passed` true only when it passed (an
    undecidable verdict has passed = False and is no failure either; `reason` says why it could not be judged)."""

    gate: str
    scenario: str
    variant: str
    metric: str
    value: object
    limit: str
    passed: bool
    advisory: bool = False
    status: str = "failed"
    reason: str = ""

    @property
    def failed(self) -> bool:
        """Whether the verdict is a failure (not passed, not undecidable)."""
        return self.status == "failed"


#: Name of the shipped gates file inside the `bench` package.
SHIPPED_GATES = "gates.toml"


def load_gates(path: str | Path | None = None) -> list[dict]:
    """The `[[gate]]` entries of a gates file; None reads the shipped one (package data of `bench`)."""
    if path is None:
        text = resources.files("frictionbench.bench").joinpath(SHIPPED_GATES).read_text(encoding="utf-8")
    else:
        text = Path(path).read_text(encoding="utf-8")
    return tomllib.loads(text).get("gate", [])


def _passes(value: object, gate: dict) -> bool:
    """Whether a cell meets a gate: `equals` a flag (`analysis.schema.flag`), or within `min` and `max`; a missing
    value never does."""
    if is_missing(value):
        return False
    if "equals" in gate:
        return flag(value) == flag(gate["equals"])
    v = number(value)
    if v is None:
        raise ValueError(f"gate on {gate['metric']}: {value!r} is not a number")
    return ("max" not in gate or v <= gate["max"]) and ("min" not in gate or v >= gate["min"])


#: Why a verdict is undecidable (`Verdict.reason`), per cause.
UNCERTIFIED = "the scenario's truth is uncertified and its error estimate too large to judge this limit"
OUTCOME_UNCERTIFIED = ("the truth's ladder did not certify this outcome and its estimate is too large to judge this "
                       "limit")
NO_LADDER_COST = "the row is more accurate than its whole ladder: no full-space cost to compare with"
BOUND_ONLY = ("an upper bound (the row is less accurate than every full-space run) at or above the limit proves "
              "nothing")


def undecidable_reason(row: pd.Series, gate: dict) -> str:
    """Why a gate's verdict on a row cannot be judged ("" where it can): a `max` on an error against an uncertified
    truth whose estimate is too large for the limit (`analysis.truth.decidable`; for an outcome's error, the truth's
    certificate and estimate of that outcome), or a gate on the speedup at equal accuracy of a row more accurate
    than its whole ladder (it has no number, only its `frontier_note`), or a `min` gate on it met only by an upper
    bound (a row less accurate than every full-space run: `AT_MOST`)."""
    if gate["metric"] == "speedup_equal_accuracy":
        if is_missing(row.get("speedup_equal_accuracy")):
            return NO_LADDER_COST if row.get("frontier_note") == MORE_ACCURATE else ""
        bound = row.get("frontier_note") == AT_MOST and "min" in gate and _passes(row["speedup_equal_accuracy"], gate)
        return BOUND_ONLY if bound else ""
    outcome = outcome_of(gate["metric"])
    if "max" not in gate or not (gate["metric"] in TRUTH_METRICS or gate.get("against_truth") or outcome):
        return ""
    certified, est = ((outcome.certified_column, outcome.est_column) if outcome
                      else ("truth_certified", "truth_err_est"))
    if est not in row and certified not in row:
        return ""  # no truth for these results: judged as before
    if decidable(float(gate["max"]), truthy(row.get(certified)), number(row.get(est))):
        return ""
    return OUTCOME_UNCERTIFIED if outcome else UNCERTIFIED


def check(results: pd.DataFrame, gates: list[dict], suite: str) -> list[Verdict]:
    """Verdicts of every gate of `suite` on the results table."""
    labels = variant_labels(results)
    tags = (results["tags"] if "tags" in results else pd.Series("", index=results.index)).astype(object).fillna("")
    tags = tags.astype(str)
    tag_sets = tags.str.split().apply(set)
    verdicts = []
    for i, gate in enumerate(g for g in gates if g.get("suite") == suite):
        wanted = gate.get("variant", "*")
        sel = (results["variant"].notna() if wanted == "*"
               else labels.isin(wanted if isinstance(wanted, list) else [wanted]))
        if "split" in gate:
            sel &= results["split"] == gate["split"]
        if "tag" in gate:
            sel &= tag_sets.apply(lambda t: gate["tag"] in t)
        if "exclude_tag" in gate:
            sel &= ~tag_sets.apply(lambda t: gate["exclude_tag"] in t)
        limit = " ".join(f"{k} {gate[k]}" for k in ("min", "max", "equals") if k in gate)
        name = gate.get("name", f"{gate.get('variant', '*')}:{gate['metric']}"
                                + (f"[{gate['tag']}]" if "tag" in gate else ""))
        rows = results[sel]
        advisory = bool(gate.get("advisory", False))
        if rows.empty:
            verdicts.append(Verdict(name, "(none)", str(wanted), gate["metric"], None, limit, False, advisory))
        for _, row in rows.iterrows():
            value = row.get(gate["metric"])
            reason = undecidable_reason(row, gate)
            status = "undecidable" if reason else "passed" if _passes(value, gate) else "failed"
            verdicts.append(Verdict(name, row["scenario"], labels[row.name], gate["metric"], value, limit,
                                    status == "passed", advisory, status, reason))
    return verdicts

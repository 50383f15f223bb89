"""Two result sets side by side (a baseline and a new run, e.g. two commits): per scenario, solver variant and
metric, the values, their change, the tolerance and the gates' thresholds, and a verdict.

As pytest-benchmark's `compare --fail` and asv's `continuous` do, a **regression** is a metric that moved in its
bad direction by more than its tolerance. Each metric has a `Rule`: its kind, which direction is better, and
its tolerance, by default those the results schema declares (`default_rules`, from `analysis.schema`):

- accuracy and stability figures (lower is better, a flag that should hold, a ratio that should stay at 1):
  regression when the change in the bad direction exceeds max(rel x |baseline|, abs);
- timing figures, as ratios new / baseline: regression when a lower-is-better time grows by more than the
  factor, or a higher-is-better speed-up shrinks by more than it. The default factor (1.5) is loose because
  step times on shared machines move by tens of per cent from run to run.

Also regressions: a binding gate of `gates.toml` that the baseline row met and the new row fails (whatever the
tolerance; an undecidable verdict, `bench.gates`, is no failure and says so in the reason), a run that succeeded
in the baseline and failed in the new set, a row or a value the baseline has and the new set lacks. The same tests in the good direction give **improved**; rows only in the new set are
**new**. Tolerances are configurable per metric or per kind (`with_tolerances`, `frictionbench compare --tol`).

Everything here is a pure function of DataFrames (results.csv as read by pandas) and gate dicts.
"""

from __future__ import annotations

import math
import re
from collections.abc import Iterable, Sequence
from dataclasses import dataclass, replace
from pathlib import Path

import numpy as np
import pandas as pd

from frictionbench.analysis.schema import COLUMNS, DIRECTIONS, JUDGED_KINDS, flag, is_missing, number

#: A results row's identity across result sets.
KEY: tuple[str, ...] = ("scenario", "solver", "variant")
KINDS: tuple[str, ...] = JUDGED_KINDS
VERDICTS: tuple[str, ...] = ("regression", "improved", "new", "ok")


class CompareError(ValueError):
    """Bad input to a comparison: an unreadable result set or a malformed tolerance."""


@dataclass(frozen=True)
class Rule:
    """How one metric is compared.

    metric: results column; kind: accuracy, stability, timing (or gate: a column only a gate judges);
    better: one of DIRECTIONS; rel: allowed bad change relative to |baseline| [-]; abs: allowed bad change in the
    metric's unit (the larger of the two applies); factor: timing only, the allowed ratio (>= 1) in the bad
    direction.
    """

    metric: str
    kind: str
    better: str
    rel: float = 0.0
    abs: float = 0.0
    factor: float | None = None

    def tolerance(self) -> str:
        """The tolerance as `--tol` writes it (`10%,0.0001`, `x1.5`, `0`)."""
        if self.factor is not None:
            return f"x{self.factor:g}"
        parts = ([f"{self.rel * 100:g}%"] if self.rel else []) + ([f"{self.abs:g}"] if self.abs else [])
        return ",".join(parts) or "0"


def default_rules() -> tuple[Rule, ...]:
    """The rule of every judged column of the schema (`analysis.schema.Column.judged`), in table order."""
    return tuple(Rule(c.name, c.kind, c.better, c.rel, c.abs, c.factor) for c in COLUMNS.values() if c.judged)


_TOL_RE = re.compile(r"(?:(?P<better>[a-z]+):)?(?:x(?P<factor>[^,%]+)|(?P<rel>[^,%]+)%(?:,(?P<abs>[^,%]+))?"
                     r"|(?P<abs_only>[^,%x]+))")


def read_results(path: str | Path) -> pd.DataFrame:
    """A result set: `path/results.csv` of an output folder, or a results CSV file itself."""
    path = Path(path)
    csv = path / "results.csv" if path.is_dir() else path
    try:
        frame = pd.read_csv(csv)
    except (OSError, ValueError) as err:
        raise CompareError(f"{path}: no readable results ({csv}: {err})") from None
    missing = [c for c in KEY if c not in frame]
    if missing:
        raise CompareError(f"{csv}: not a results table (no column {missing})")
    return frame


def with_tolerances(rules: Sequence[Rule], specs: Iterable[str]) -> tuple[Rule, ...]:
    """`rules` changed by `METRIC=SPEC` or `KIND=SPEC` entries, in order.

    SPEC: `off` (not compared), or `[DIRECTION:]TOL` with TOL `5%` (relative), `0.001` (absolute), `5%,0.001`
    (both; the larger applies) or `x1.5` (a timing factor). DIRECTION (one of DIRECTIONS) is required for a
    metric without a default rule, and may change a known one.
    """
    out = list(rules)
    for spec in specs:
        target, sep, text = spec.partition("=")
        target, text = target.strip(), text.strip()
        if not sep or not target:
            raise CompareError(f"tolerance {spec!r}: expected METRIC=SPEC or KIND=SPEC (KIND one of {list(KINDS)})")
        chosen = [i for i, r in enumerate(out) if target in (r.metric, r.kind)]
        if text == "off":
            out = [r for i, r in enumerate(out) if i not in chosen]
            continue
        match = _TOL_RE.fullmatch(text)
        if match is None:
            raise CompareError(f"tolerance {spec!r}: SPEC must be off, 5%, 0.001, 5%,0.001 or x1.5, "
                               "optionally after DIRECTION: (lower, higher, true, one)")
        change = _tolerance_fields(spec, match)
        if not chosen:
            if target in KINDS or "better" not in change:
                raise CompareError(f"tolerance {spec!r}: {target!r} has no default rule; name its direction, "
                                   f"e.g. {target}=lower:5%")
            out.append(Rule(target, "timing" if change.get("factor") else "accuracy", change["better"]))
            chosen = [len(out) - 1]
        for i in chosen:
            out[i] = replace(out[i], **change)
    return tuple(out)


def _tolerance_fields(spec: str, match: re.Match) -> dict:
    """The Rule fields a parsed SPEC sets."""
    fields: dict = {}
    if match["better"]:
        if match["better"] not in DIRECTIONS[:-1]:
            raise CompareError(f"tolerance {spec!r}: direction {match['better']!r} not one of {list(DIRECTIONS[:-1])}")
        fields["better"] = match["better"]
    try:
        numbers = {k: float(match[k]) for k in ("factor", "rel", "abs", "abs_only") if match[k] is not None}
    except ValueError as err:
        raise CompareError(f"tolerance {spec!r}: {err}") from None
    if not all(math.isfinite(v) and v >= 0.0 for v in numbers.values()):
        raise CompareError(f"tolerance {spec!r}: tolerances are finite numbers >= 0")
    if "factor" in numbers:
        if numbers["factor"] < 1.0:
            raise CompareError(f"tolerance {spec!r}: a factor is a ratio >= 1")
        return fields | {"factor": numbers["factor"]}
    return fields | {"rel": numbers.get("rel", 0.0) / 100, "abs": numbers.get("abs", numbers.get("abs_only", 0.0)),
                     "factor": None}


def _labels(frame: pd.DataFrame) -> pd.Series:
    """`solver/variant` per row."""
    from frictionbench.analysis.table import variant_labels

    return variant_labels(frame)


def _keyed(frame: pd.DataFrame, name: str) -> dict[tuple, dict]:
    """KEY -> the row (a dict, with its `label`); a duplicated key is an error naming it."""
    keyed: dict[tuple, dict] = {}
    for row in frame.assign(label=_labels(frame)).to_dict("records"):
        key = tuple(row[k] for k in KEY)
        if key in keyed:
            raise CompareError(f"{name}: several rows for {key} ({', '.join(KEY)})")
        keyed[key] = row
    return keyed


def _gate_index(frame: pd.DataFrame, gates: Sequence[dict]) -> dict[tuple[str, str, str], list]:
    """(scenario, label, metric) -> the verdicts of every gate on that row and metric."""
    from frictionbench.bench.gates import check

    index: dict[tuple[str, str, str], list] = {}
    for suite in frame["suite"].dropna().unique() if "suite" in frame else ():
        for v in check(frame[frame["suite"] == suite], gates, str(suite)):
            if v.scenario != "(none)":
                index.setdefault((v.scenario, v.variant, v.metric), []).append(v)
    return index


def _judge(rule: Rule, base: object, new: object) -> tuple[str, str]:
    """(verdict, reason) of one metric by its rule alone."""
    if rule.better == "true":
        b, n = flag(base), flag(new)
        if b is None or n is None or b == n:
            return ("ok", "") if n is not None or b is None else ("regression", "no value in the new set")
        return ("improved", "") if n else ("regression", "no longer holds")
    b, n = number(base), number(new)
    if n is None:
        return ("regression", "no value in the new set") if b is not None else ("ok", "")
    if b is None or rule.better == "none":
        return "ok", ""
    if rule.factor is not None:
        if b <= 0.0 or n <= 0.0:
            return "ok", "not a positive time"
        ratio = n / b if rule.better == "lower" else b / n
        if ratio > rule.factor:
            return "regression", f"x{ratio:.3g} beyond x{rule.factor:g}"
        return ("improved", "") if ratio < 1.0 / rule.factor else ("ok", "")
    bad = {"lower": n - b, "higher": b - n, "one": abs(n - 1.0) - abs(b - 1.0)}[rule.better]
    allowed = max(rule.rel * abs(b), rule.abs)
    if bad > allowed:
        return "regression", f"worse by {bad:.3g}, beyond {allowed:.3g}"
    return ("improved", "") if -bad > allowed else ("ok", "")


def compare_results(base: pd.DataFrame, new: pd.DataFrame, rules: Sequence[Rule] | None = None,
                    gates: Sequence[dict] = ()) -> pd.DataFrame:
    """One row per (scenario, solver, variant, metric) of either set: columns verdict (VERDICTS), scenario,
    variant (`solver/variant`), metric, kind, base, new, delta (new - base, numbers only), ratio (new / base),
    tolerance, gate (the thresholds of the gates on that row and metric, `(advisory)` marked), reason; sorted
    regressions first. Metrics judged only by a gate (no rule) are compared for gate crossings alone. `rules`:
    default `default_rules()`."""
    rules = default_rules() if rules is None else rules
    b, n = _keyed(base, "baseline"), _keyed(new, "new set")
    gated_b, gated_n = _gate_index(base, gates), _gate_index(new, gates)
    by_metric = {r.metric: r for r in rules}
    for _, _, metric in gated_n:
        by_metric.setdefault(metric, Rule(metric, "gate", "none"))
    rows = []
    for key in dict.fromkeys([*b, *n]):
        scenario = key[0]
        if key not in n:
            rows.append(_row("regression", scenario, b[key]["label"], "(row)", "", reason="missing in the new set"))
            continue
        label = n[key]["label"]
        if key not in b:
            rows.append(_row("new", scenario, label, "(row)", "", reason="not in the baseline"))
            continue
        rb, rn = b[key], n[key]
        if flag(rb.get("status")) is not False and flag(rn.get("status")) is False:
            failure = "" if is_missing(rn.get("failure")) else rn["failure"]
            rows.append(_row("regression", scenario, label, "status", "stability", rb.get("status"),
                             rn.get("status"), reason=f"run failed: {failure}"))
            continue
        for metric, rule in by_metric.items():
            vb, vn = rb.get(metric), rn.get(metric)
            if is_missing(vb) and is_missing(vn):
                continue
            verdict, reason = _judge(rule, vb, vn)
            gate_b, gate_n = gated_b.get((scenario, label, metric), []), gated_n.get((scenario, label, metric), [])
            crossed = [v for v in gate_n if not v.advisory and v.failed
                       and all(w.passed for w in gate_b if w.gate == v.gate)]
            if crossed and gate_b:
                verdict, reason = "regression", "; ".join(filter(None, [reason, *(f"gate {v.limit} now fails"
                                                                                  for v in crossed)]))
            undecided = [v for v in gate_n if v.status == "undecidable"]  # neither passed nor failed: no regression
            if undecided:
                reason = "; ".join(filter(None, [reason, *(f"gate {v.limit} undecidable ({v.reason})"
                                                           for v in undecided)]))
            gate = "; ".join(dict.fromkeys(f"{v.limit}{' (advisory)' if v.advisory else ''}" for v in gate_n))
            nb, nn = number(vb), number(vn)
            rows.append(_row(verdict, scenario, label, metric, rule.kind, vb, vn,
                             delta=nn - nb if nb is not None and nn is not None and rule.better != "true" else None,
                             ratio=nn / nb if nb and nn is not None and rule.better != "true" else None,
                             tolerance=rule.tolerance() if rule.better not in ("true", "none") else "", gate=gate,
                             reason=reason))
    frame = pd.DataFrame(rows, columns=["verdict", "scenario", "variant", "metric", "kind", "base", "new", "delta",
                                        "ratio", "tolerance", "gate", "reason"])
    order = frame["verdict"].map({v: i for i, v in enumerate(VERDICTS)})
    return frame.iloc[order.argsort(kind="stable")].reset_index(drop=True)


def _row(verdict: str, scenario: str, label: str, metric: str, kind: str, base: object = None, new: object = None,
         delta: float | None = None, ratio: float | None = None, tolerance: str = "", gate: str = "",
         reason: str = "") -> dict:
    return {"verdict": verdict, "scenario": scenario, "variant": label, "metric": metric, "kind": kind,
            "base": base, "new": new, "delta": delta, "ratio": ratio, "tolerance": tolerance, "gate": gate,
            "reason": reason}


def compare_folders(baseline: str | Path, new: str | Path, tolerances: Sequence[str] = (),
                    gates_file: str | Path | None = None) -> pd.DataFrame:
    """`compare_results` of two result sets (output folders or results CSV files) with the default rules changed
    by `tolerances` (`with_tolerances`) and the gates of `gates_file` (None: the shipped gates)."""
    from frictionbench.bench.gates import load_gates

    rules = with_tolerances(default_rules(), tolerances)
    try:
        gates = load_gates(gates_file)
    except (OSError, ValueError) as err:  # tomllib.TOMLDecodeError is a ValueError
        raise CompareError(f"gates file {gates_file}: {err}") from None
    return compare_results(read_results(baseline), read_results(new), rules, gates)


def regressions(comparison: pd.DataFrame) -> int:
    """How many rows of a comparison are regressions."""
    return int((comparison["verdict"] == "regression").sum())


def summary(comparison: pd.DataFrame) -> str:
    """One line: how many rows of each verdict."""
    counts = comparison["verdict"].value_counts()
    return "metric rows: " + ", ".join(f"{v} {int(counts.get(v, 0))}" for v in VERDICTS)


def format_table(comparison: pd.DataFrame, everything: bool = False) -> str:
    """The comparison as a plain-text table: the rows that changed (every row with `everything`)."""
    shown = comparison if everything else comparison[comparison["verdict"] != "ok"]
    if shown.empty:
        return "no changes beyond the tolerances"
    text = shown.drop(columns=["kind"]).copy()
    for col in ("base", "new", "delta", "ratio"):
        text[col] = text[col].map(_cell)
    return text.to_string(index=False)


def _cell(value: object) -> str:
    """A value cell: numbers to 4 significant digits, missing as `-`."""
    if is_missing(value):
        return "-"
    x = number(value)
    return f"{x:.4g}" if x is not None and not isinstance(value, (bool, np.bool_, str)) else str(value)

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

Each gate yields one verdict per matching row; a gate that matches no row fails (a missing run is a failure).
"""

from __future__ import annotations

import tomllib
from dataclasses import dataclass
from importlib import resources
from pathlib import Path

import pandas as pd

from analysis.table import variant_labels


@dataclass(frozen=True)
class Verdict:
    """One gate checked on one results row."""

    gate: str
    scenario: str
    variant: str
    metric: str
    value: object
    limit: str
    passed: bool
    advisory: bool = False


#: Name of the shipped gates file inside the `bench` package.
SHIPPED_GATES = "gates.toml"


def load_gates(path: str | Path | None = None) -> list[dict]:
    """The `[[gate]]` entries of a gates file; None reads the shipped one (package data of `bench`)."""
    if path is None:
        text = resources.files("bench").joinpath(SHIPPED_GATES).read_text(encoding="utf-8")
    else:
        text = Path(path).read_text(encoding="utf-8")
    return tomllib.loads(text).get("gate", [])


def _passes(value: object, gate: dict) -> bool:
    if value is None or (isinstance(value, float) and pd.isna(value)):
        return False
    if "equals" in gate:
        return str(value).lower() == str(gate["equals"]).lower()
    v = float(value)
    return ("max" not in gate or v <= gate["max"]) and ("min" not in gate or v >= gate["min"])


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
            verdicts.append(Verdict(name, row["scenario"], labels[row.name], gate["metric"], value, limit,
                                    _passes(value, gate), advisory))
    return verdicts

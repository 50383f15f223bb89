"""The terms the report uses, each defined once: the glossary near the top of the page and the hover (`<abbr
title>`) on a term's first use in the summary and on every table heading that names one (`defined`).

Definitions quote the numbers they depend on from where they are set (the truth's tolerance, the undecidable
factor, the frontier notes), so they cannot drift from the code.
"""

from __future__ import annotations

import html
import re
from collections.abc import Iterable

from frictionbench.analysis.schema import COLUMNS
from frictionbench.analysis.truth import AT_MOST, MORE_ACCURATE, UNDECIDABLE_FACTOR
from frictionbench.scenarios.suites import TruthSpec

#: Term -> its definition, in the glossary's order. A term written with an underscore is a results column.
GLOSSARY: dict[str, str] = {
    "L": "the body's size: the diagonal of its rest mesh's bounding box [m]. Every position error is a fraction of "
         "L (1% of L = 0.01 L).",
    "family": "a solver (full, licrom, pod, affine, ...); its variants are its settings, named solver/variant.",
    "reference": "the full-space solver at the suite's own time step: what pos_rmse_rel and the per-step speedup "
                 "compare against.",
    "truth": "the ground truth of a scenario: the finest run of its ladder.",
    "ladder": "the full-space solver run at dt, dt/2, dt/4, ... (levels 0, 1, 2, ...); it stops at the first level "
              f"within the tolerance (by default {TruthSpec.tol:.1%} of L) of the one before, or at its depth.",
    "certified": "a truth whose ladder's last two levels differ by at most the tolerance. An uncertified truth is "
                 "only as good as its error estimate err_est.",
    "err_truth": f"{COLUMNS['err_truth'].meaning} [fraction of L]: how far a run is from the truth.",
    "err_est": f"{COLUMNS['truth_err_est'].meaning} (column truth_err_est) [fraction of L], from the ladder's "
               "last differences and their observed order.",
    "pos_rmse_rel": f"{COLUMNS['pos_rmse_rel'].meaning} [fraction of L]: the reduction's own error.",
    "err_time": f"{COLUMNS['err_time'].meaning} [fraction of L].",
    "err_projection": f"{COLUMNS['err_projection'].meaning} [fraction of L].",
    "wall_s_per_sim_s": "the cost of a run: its steps' wall time per simulated second [s/s], "
                        "\"s per simulated second\" in words (lower is cheaper).",
    "accuracy-cost frontier": "the runs (or variants) that no other is both cheaper and more accurate than: the "
                              "Pareto front of (err_truth, wall_s_per_sim_s).",
    "speedup at equal accuracy": "column speedup_equal_accuracy: the full-space solver's cost at a run's err_truth "
                                 "(interpolated log-log on the front of its full-space runs) over the run's own cost. "
                                 "Larger is better; measured where the run's accuracy lies within the full-space "
                                 "runs' range.",
    "upper bound": "a run less accurate than every full-space run is compared with the least accurate one's cost, "
                   "for which the full-space solver is at least as accurate: its speedup at equal accuracy is at "
                   "most the number shown, written <= x.",
    "frontier note": f"column frontier_note: why a speedup at equal accuracy is an upper bound (\"{AT_MOST}\") or "
                     f"missing (\"{MORE_ACCURATE}\": no full-space cost to compare with; \"the truth\" itself).",
    "per-step speedup": "column speedup: the reference's median step time over the run's, at its own step: what a "
                        "step costs, whatever the accuracy.",
    "binding gate": "a check of bench/gates.toml that `frictionbench gate` enforces (exit 1 when one fails).",
    "advisory check": "a check of bench/gates.toml that is reported, not enforced.",
    "undecidable": "a verdict neither passed nor failed: an accuracy limit below "
                   f"{UNDECIDABLE_FACTOR:g}x an uncertified truth's error estimate, or a minimum speed-up met only "
                   "by an upper bound.",
    "omega_max h_eff": "the top of the elastic spectrum times the integrator's effective step h_eff (BDF2 2/3 dt, "
                       "backward Euler dt); above 1 the step does not resolve those modes.",
}

#: Other spellings of a term (singular or plural, the column's name) -> the term.
ALIASES: dict[str, str] = {
    "families": "family", "truths": "truth", "ladders": "ladder", "binding gates": "binding gate",
    "advisory checks": "advisory check", "speedup_equal_accuracy": "speedup at equal accuracy",
    "frontier_note": "frontier note", "truth_err_est": "err_est", "s per simulated second": "wall_s_per_sim_s",
    "uncertified": "certified", "upper bounds": "upper bound", "frontier": "accuracy-cost frontier",
}


def _pattern(terms: Iterable[str]) -> re.Pattern:
    """Whole-word occurrences of the terms, longest first (not inside a name: no letter, digit, _, / or - beside
    it); case-insensitive except single letters."""
    words = sorted(terms, key=len, reverse=True)
    alternatives = [(re.escape(t) if len(t) == 1 else f"(?i:{re.escape(t)})") for t in words]
    return re.compile(r"(?<![\w/\-])(?:" + "|".join(alternatives) + r")(?![\w/\-])")


_TERMS = _pattern([*GLOSSARY, *ALIASES])


def term_of(word: str) -> str | None:
    """The glossary term a spelling names (None: none)."""
    for term in GLOSSARY:
        if term.lower() == word.lower() and (len(term) > 1 or term == word):
            return term
    alias = next((a for a in ALIASES if a.lower() == word.lower()), None)
    return ALIASES[alias] if alias else None


def abbr(word: str, term: str) -> str:
    """`word` (plain text) as an <abbr> whose hover is the term's definition."""
    return f'<abbr title="{html.escape(term + ": " + GLOSSARY[term])}">{html.escape(word)}</abbr>'


def defined(text: str, seen: set[str] | None = None) -> str:
    """Plain `text` as HTML, escaped, with each glossary term wrapped in an <abbr> hover: only its first use when
    `seen` is given (the terms already defined; updated), every use otherwise."""
    out, pos = [], 0
    for m in _TERMS.finditer(text):
        term = term_of(m.group(0))
        if term is None or (seen is not None and term in seen):
            continue
        if seen is not None:
            seen.add(term)
        out += [html.escape(text[pos:m.start()]), abbr(m.group(0), term)]
        pos = m.end()
    out.append(html.escape(text[pos:]))
    return "".join(out)


def glossary_html() -> str:
    """The glossary as a definition list, every term with its definition (the definitions' own terms escaped,
    not wrapped)."""
    items = "".join(f'<dt id="term-{re.sub(r"[^a-z0-9]+", "-", t.lower())}">{html.escape(t)}</dt>'
                    f"<dd>{html.escape(d)}</dd>" for t, d in GLOSSARY.items())
    return f'<dl class="glossary">{items}</dl>'

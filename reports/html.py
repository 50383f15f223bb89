"""One self-contained `report.html`: a headline first, then interactive plots, a 3D viewer per scenario and
sortable, filterable tables; it opens offline (no request: plotly.js and the data are inline).

Sections (with these ids and headings): summary (the first screen, `analysis.summary`: one verdict banner, one
sentence per solver family on its best variant, the glossary, the per-family table), accuracy-vs-time (the
frontier), ladders, outcomes (each scenario's truth outcomes and their convergence), error-parts, error-over-time,
viewer, time-convergence, stick-slip, remeshing, stability, gate-verdicts, results, any extra sections, provenance.
Every text from the results is escaped: HTML-escaped in the page, JSON-escaped for `<script>` in the embedded
figures.
"""

from __future__ import annotations

import html
import os
from collections.abc import Mapping, Sequence
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np
import pandas as pd

from frictionbench.analysis.curves import CUBATURE_MARGIN, FLATTEN_DROP, SUBSPACE_SHARE
from frictionbench.analysis.derived import remeshing_summary
from frictionbench.analysis.schema import COLUMNS, OUTCOMES, flag, is_missing, names, stability_metrics, truthy
from frictionbench.analysis.summary import Summary, capitalised, ladder_mask, summarise, verdict_frame
from frictionbench.analysis.table import results_frame, variant_labels
from frictionbench.analysis.truth import UNDECIDABLE_FACTOR
from frictionbench.reports.glossary import defined, glossary_html
from frictionbench.reports.headline import headline_table, ranked_variants, truth_summary, with_bounds
from frictionbench.reports.interactive import page_scripts, plot_div, plotly_version
from frictionbench.reports.plots import (error_over_time_figure, error_parts_figure, frontier_figure, ladder_figure,
                                         step_size_figure)
from frictionbench.reports.viewer import DEFAULT_BUDGET, ViewerBudget, viewer_figure
from frictionbench.scenarios.atomic import write_text_atomic
from frictionbench.scenarios.spec import Plane
from frictionbench.solvers.trajectory import Trajectory

CSS = """
body { font-family: system-ui, -apple-system, "Segoe UI", sans-serif; margin: 1.5em auto; max-width: 1200px;
       padding: 0 1em; color: #1d1d1d; }
h1 { font-size: 1.6em; } h2 { border-bottom: 1px solid #ccc; padding-bottom: .2em; margin-top: 1.8em; }
nav ul { columns: 3; list-style: none; padding: 0; }
table { border-collapse: collapse; margin: .6em 0; font-size: .85em; }
th, td { border: 1px solid #ccc; padding: .25em .5em; text-align: right; }
th { background: #f0f0f0; } td.text { text-align: left; }
td.pass { background: #d7f0d7; } td.fail { background: #f6d0d0; }
.banner { padding: .6em 1em; border-radius: 4px; font-weight: 600; }
.banner.pass { background: #d7f0d7; } .banner.fail { background: #f6d0d0; } .banner.warn { background: #fbe7b5; }
td.warn { background: #fbe7b5; } ul.details { margin: .3em 0 .8em; font-size: .9em; }
ul.answer { font-size: 1.05em; padding-left: 1.2em; } ul.answer li { margin: .35em 0; }
ul.answer .step { white-space: nowrap; color: #333; background: #eef2f7; border-radius: 3px; padding: 0 .35em; }
abbr[title] { text-decoration: underline dotted #888; cursor: help; }
details.glossary-box { margin: .8em 0; font-size: .85em; } details.glossary-box summary { cursor: pointer; }
dl.glossary { columns: 2; column-gap: 2em; margin: .4em 0; }
dl.glossary dt { font-weight: 600; break-after: avoid; } dl.glossary dd { margin: 0 0 .4em 1em; break-inside: avoid; }
.note { color: #555; font-size: .9em; } .scroll { overflow-x: auto; }
th[data-sort] { background: #dde6f0; } th { cursor: pointer; } input.filter { margin: .4em 0; width: 20em; }
.headline { font-size: 1.05em; } .headline li { margin: .15em 0; } .plot { width: 100%; }
"""

#: Failed gates listed in the headline (the rest are in the verdict table).
MAX_LISTED = 12


@dataclass(frozen=True)
class ScenarioRuns:
    """Trajectories of one scenario for the 3D viewer, and their errors for the error-over-time plot.

    scenario: its name (a heading); reference: the full-space run; others: label -> run compared with it, each
    on the reference's mesh; errors: label -> (t (F,) [s], e (F,) [-]), the per-frame error of that run against
    the truth when there is one, else against the reference (`analysis.metrics.error_over_time`); plane: drawn
    in the viewer; reference_label: the reference's label; truth: the scenario's ground-truth run (None: none),
    truth_label its label; steps: label -> the per-step records (`solvers.step_stats.StepStats` as stored) of the
    scenario's adaptive runs, for the step-size plot (`reports.plots.step_size_figure`; none: no plot). The viewer
    shows the truth, the reference and, of the others, each solver family's best variant among them
    (`reports.headline.ranked_variants`; the first three where none is ranked).
    """

    scenario: str
    reference: Trajectory
    others: Mapping[str, Trajectory] = field(default_factory=dict)
    errors: Mapping[str, tuple[np.ndarray, np.ndarray]] = field(default_factory=dict)
    plane: Plane | None = None
    reference_label: str = "reference"
    truth: Trajectory | None = None
    truth_label: str = "truth"
    steps: Mapping[str, Sequence[Mapping[str, object]]] = field(default_factory=dict)


def _cell(value: object) -> str:
    """A table cell's text: floats to 3 significant digits, booleans as yes/no, missing values as an en dash."""
    if is_missing(value):
        return "&ndash;"
    if isinstance(value, (bool, np.bool_)):
        return "yes" if value else "no"
    if isinstance(value, (float, np.floating)):
        return f"{value:.3g}"
    return html.escape(str(value))


def _verdict_class(value: object) -> str:
    """CSS class of a verdict cell: pass for a true flag (True, 'ok', 'pass', `analysis.schema.flag`), fail for
    anything else, '' if missing."""
    if is_missing(value):
        return ""
    return "pass" if flag(value) else "fail"


def _table(frame: pd.DataFrame, verdicts: Sequence[str] = ()) -> str:
    """HTML table of a frame; columns named in verdicts are coloured pass/fail; a speedup_equal_accuracy that is an
    upper bound is written `<= x` (`reports.headline.with_bounds`); a heading that names a glossary term has its
    hover (`reports.glossary.defined`)."""
    frame = with_bounds(frame)
    head = "".join(f"<th>{defined(str(c))}</th>" for c in frame.columns)
    body = []
    for row in frame.itertuples(index=False):
        cells = []
        for col, value in zip(frame.columns, row):
            classes = (_verdict_class(value) if col in verdicts else "", "text" if isinstance(value, str) else "")
            cls = " ".join(c for c in classes if c)
            cells.append(f'<td class="{cls}">{_cell(value)}</td>' if cls else f"<td>{_cell(value)}</td>")
        body.append("<tr>" + "".join(cells) + "</tr>")
    return (f'<div class="scroll"><table class="sortable">\n<thead><tr>{head}</tr></thead>\n<tbody>\n'
            + "\n".join(body) + "\n</tbody>\n</table></div>")


def _note(text: str) -> str:
    """A paragraph of explanatory text."""
    return f'<p class="note">{html.escape(text)}</p>'


def _columns(frame: pd.DataFrame, wanted: Sequence[str]) -> pd.DataFrame:
    """The wanted columns that the frame has, in that order."""
    return frame[[c for c in wanted if c in frame.columns]]


def _summary(frame: pd.DataFrame, gates: Sequence[object], summary: Summary) -> str:
    """The first screen (`analysis.summary.Summary`): one banner with the verdict in words, one sentence per solver
    family with its per-step speedup beside it, what accuracy is measured against, the glossary, then per family
    its best variant's figures (`reports.headline.headline_table`). The first use of each glossary term has a hover
    with its definition."""
    seen: set[str] = set()
    b = summary.banner
    parts = [f'<p class="banner {b.level}" id="verdict">{defined(b.headline, seen)}</p>']
    if b.details:
        parts.append('<ul class="details">' + "".join(f"<li>{defined(d, seen)}</li>" for d in b.details) + "</ul>")
    if summary.families:
        items = []
        for f in summary.families:
            step = (f' <span class="step">{defined(f.step_speedup_text, seen)}</span>' if f.step_speedup_text
                    else "")
            sentence = defined(capitalised(f.sentence), seen)
            if f.chosen is not None:  # the chosen variant stands out
                label = html.escape(f.chosen.label)
                sentence = sentence.replace(label, f"<b>{label}</b>", 1)
            items.append(f"<li><b>{html.escape(f.family)}</b>: {sentence}.{step}</li>")
        parts.append('<ul class="answer">' + "".join(items) + "</ul>")
    else:
        parts.append(_note("No solver rows in these results."))
    parts.append(f'<p class="headline">{defined(truth_summary(summary.truth), seen)} '
                 f"{defined(capitalised(summary.gates.text()), seen)}; {summary.runs.rows} result rows, "
                 f"{summary.runs.failed} failed runs.</p>")
    parts.append('<details class="glossary-box" open><summary>Terms used on this page (hover a dotted term for '
                 "its definition)</summary>" + glossary_html() + "</details>")
    table = headline_table(frame, gates, summary.families)
    if not table.empty:
        parts.append(_note("Per solver family, its best variant, chosen on the family's accuracy-cost frontier "
                           "(among the variants no other of the family is both cheaper and more accurate than, the "
                           "largest measured speedup at equal accuracy; where every one is an upper bound, the "
                           "closest to the full-space accuracy), and its medians over its finished runs; stable "
                           "runs: finished with finite positions, every step converged and every stability check "
                           "of its case passed.") + _table(table))
    return "\n".join(parts)


def _cell_text(value: object) -> str:
    """A value as plain text: floats to 3 significant digits."""
    return f"{value:.3g}" if isinstance(value, (float, np.floating)) else str(value)


def _verdicts(gates: Sequence[object]) -> str:
    """Every gate verdict, filterable and sortable."""
    verdicts = verdict_frame(gates)
    if verdicts.empty:
        return _note("No gates were evaluated for these results.")
    return _table(verdicts, verdicts=["passed", "status"])


def _results(frame: pd.DataFrame) -> str:
    """The key columns of every results row: the schema's summary columns (`analysis.schema.Column.summary`), its
    flags that should hold coloured."""
    summary = _columns(frame, [c.name for c in COLUMNS.values() if c.summary])
    return _table(summary, verdicts=[c.name for c in COLUMNS.values() if c.summary and c.better == "true"])


def _frontier(frame: pd.DataFrame) -> str:
    """The interactive frontier: error against cost per run, the variants' own curves, the ladders as curves, the
    Pareto front; below it what floors each variant's curve."""
    return (_note("One point per run (hover: variant, scenario, values; click a legend entry to hide or show "
                  "it). The dotted red line is the Pareto front of the variants' medians over scenarios: no other "
                  "variant is both cheaper and more accurate. The grey curves are the full-space ladders "
                  "(halved time steps), per integrator; a coloured line joins the levels of a variant's own step "
                  "ladder (its curve), per scenario, in its family's hue.")
            + plot_div(frontier_figure(frame), "frontier", 480) + _curve_floors(frame))


#: The columns of the curve floor table: column -> heading.
_CURVE_FLOOR = {"scenario": "scenario", "solver": "solver", "curve": "curve", "curve_level": "finest level",
                "dt": "dt [s]", "err_truth": "finest err_truth", "err_projection": "err_projection",
                "curve_floor": "floor"}


def _curve_floors(frame: pd.DataFrame) -> str:
    """Per scenario and variant curve, its finest finished level and what floors it (`analysis.curves`); '' where
    no row has a floor verdict column."""
    if "curve_floor" not in frame:
        return ""
    finest = frame[frame["curve_floor"].notna()]
    if finest.empty:
        return ""
    table = _columns(finest.sort_values(["scenario", "solver", "curve"]), list(_CURVE_FLOOR)).rename(
        columns=_CURVE_FLOOR)
    return (_note(f"What floors each variant's curve, at its finest level: time step while the last halving still "
                  f"lowered err_truth by {FLATTEN_DROP:.0%} or more; once it lowers it less, the truth where the "
                  f"error is within {UNDECIDABLE_FACTOR:g}x the truth's own error estimate, the cubature where the "
                  f"all-tets twin curve is at most {CUBATURE_MARGIN:g}x as far from the truth at the same level, "
                  f"the subspace where err_projection is at least {SUBSPACE_SHARE:.0%} of err_truth, else the "
                  "reduction (the reduced dynamics); too few levels: fewer than two successive levels finished "
                  "(docs/metrics.md, \"Reduced curves\").")
            + _table(table))


def _ladders(frame: pd.DataFrame) -> str:
    """The ground-truth ladders' convergence, or why there is none."""
    figure = ladder_figure(frame)
    if figure is None:
        return _note("No ground-truth ladder in this result set.")
    return (_note("Each ladder: the reference solver at halved time steps; err_truth of each level against the "
                  "scenario's truth, with the truth's own error estimate.")
            + plot_div(figure, "ladders-plot", 420) + _ladder_resolution(frame))


#: The scene's time scales shown beside its truth: (column, label, unit).
_SCALES = (("ts_omega_max", "spectrum top omega_max", "rad/s"), ("ts_omega_1", "first mode omega_1", "rad/s"),
           ("ts_omega_contact", "contact, whole body", "rad/s"), ("ts_zeta_contact", "its damping ratio", ""),
           ("ts_omega_contact_vertex", "contact, fastest vertex", "rad/s"),
           ("ts_zeta_contact_vertex", "least vertex damping ratio", ""),
           ("ts_tau_friction", "friction relaxation, whole body", "s"),
           ("ts_tau_friction_vertex", "friction relaxation, fastest vertex", "s"))
#: Each ladder level's resolution of them: column -> heading.
_RESOLUTION = {"ladder": "ladder", "ladder_level": "level", "dt": "dt [s]", "h_eff": "h_eff [s]",
               "res_omega_max": "omega_max h_eff", "res_contact": "contact omega h_eff",
               "res_contact_vertex": "vertex contact omega h_eff", "res_friction": "h_eff / tau_friction",
               "res_unresolved_share": "share of modes unresolved"}


def _ladder_resolution(frame: pd.DataFrame) -> str:
    """Per scenario with a ladder: the scene's time scales (`analysis.timescales`) and how well each level's step
    resolves them (omega h_eff > 1: not resolved); '' where the rows have no time scales."""
    if "ladder_level" not in frame or "res_omega_max" not in frame:
        return ""
    ladder = frame[frame["ladder_level"].notna() & frame["res_omega_max"].notna()]
    if ladder.empty:
        return ""
    parts = [_note("The scenes' time scales beside their truths: the elastic spectrum at rest, the contact "
                   "(the whole body on its patch, and each contact vertex on its own spring) and the friction law's "
                   "relaxation; per ladder level, omega h_eff of each (h_eff the integrator's effective step; above "
                   "1 the step does not resolve it) and the share of the elastic modes it does not resolve.")]
    for scenario, rows in ladder.groupby("scenario", sort=False):
        first = rows.iloc[0]
        scales = "; ".join(f"{label} {_cell(first[col])}{' ' + unit if unit else ''}" for col, label, unit in _SCALES
                           if col in rows and not is_missing(first[col]))
        table = _columns(rows.sort_values(["ladder", "ladder_level"]), list(_RESOLUTION)).rename(columns=_RESOLUTION)
        parts += [f"<h3>{html.escape(str(scenario))}</h3>", f'<p class="note">{scales}</p>', _table(table)]
    return "\n".join(parts)


def _outcomes(frame: pd.DataFrame) -> str:
    """Per scenario, each outcome of its truth (`analysis.schema.OUTCOMES`): the truth's value, the difference of
    its ladder's two finest levels, the estimate of its error and whether it is certified; or why there is none."""
    table = []
    for scenario, g in (frame.groupby("scenario", sort=False) if "scenario" in frame else ()):
        for o in OUTCOMES.values():
            if o.certified_column not in g or g[o.certified_column].isna().all():
                continue
            r = g[g[o.certified_column].notna()].iloc[0]
            table.append({"scenario": scenario, "outcome": o.name, "unit": o.unit, "truth": r.get(o.truth_column),
                          "ladder difference": r.get(o.diff_column), "estimate": r.get(o.est_column),
                          "tolerance": o.tol, "of": o.err_unit, "certified": r[o.certified_column]})
    if not table:
        return _note("No outcome convergence in this result set (no ground truth, or no plane).")
    return (_note("Each outcome of each scenario's truth (docs/metrics.md, \"Outcome metrics\"): its value, the "
                  "difference between the truth ladder's two finest levels, the estimate of the truth's own error "
                  "(Richardson, as for positions; a verdict's is its last difference) and whether the difference "
                  "meets the outcome's tolerance. Each run's error against these values is a column of the results "
                  "table (<outcome>_err_truth); a gate on it is undecidable where the outcome is not certified "
                  "and the limit is below 3x its estimate.")
            + _table(pd.DataFrame(table), verdicts=["certified"]))


def _error_parts(frame: pd.DataFrame) -> str:
    """Where each variant's error against the truth comes from: subspace, reduction, time step."""
    figure = error_parts_figure(frame)
    if figure is None:
        return _note("No ground truth in this result set: the error cannot be split into its parts.")
    parts = _columns(frame[~ladder_mask(frame) & (frame["variant"].astype(str) != "reference")],
                     ["scenario", "solver", "variant", "err_truth", "err_projection", "pos_rmse_rel", "err_time"])
    return (_note("A variant's error against the truth has three sources: its subspace (err_projection: the best "
                  "any run in it could do against the truth), the reduction (pos_rmse_rel: against the full-space "
                  "run at its own time step) and the time step (err_time: that full-space run against the truth). "
                  "Where err_time dominates, a better reduced model would not help: a smaller step would.")
            + plot_div(figure, "error-parts-plot", 380) + _table(parts.dropna(subset=["err_time"])))


def _error_over_time(runs: Sequence[ScenarioRuns]) -> str:
    """One interactive error-over-time plot per scenario, and below it the step size over time of its adaptive
    runs where it has any."""
    parts = []
    for n, run in enumerate(runs):
        against = run.truth_label if run.truth is not None else run.reference_label
        fig = error_over_time_figure(run.errors, f"{run.scenario}: error against {against}")
        parts.append(plot_div(fig, f"error-{n}", 340))
        if run.steps:
            parts.append(plot_div(step_size_figure(run.steps, f"{run.scenario}: step size of the adaptive runs "
                                                              "(dips: impacts and contact events)"),
                                  f"steps-{n}", 320))
    return "\n".join(parts)


def _viewers(runs: Sequence[ScenarioRuns], frame: pd.DataFrame, budget: ViewerBudget) -> str:
    """Per scenario, the animated 3D viewer of its truth, reference and each family's best variant."""
    ranked = ranked_variants(frame)
    parts = [_note(f"Each scenario's runs side by side, coloured by the distance of each surface point to the "
                   f"first one (the truth, else the reference), as a fraction of the body's size L. Play/Pause "
                   f"and the slider step through time; drag to turn, scroll to zoom. Surfaces decimated to at "
                   f"most {budget.max_triangles} triangles, at most {budget.max_frames} frames.")]
    scenarios = frame["scenario"].dropna().astype(str).unique() if "scenario" in frame else []
    if len(runs) < len(scenarios):
        parts.append(_note(f"Viewers for {len(runs)} of the {len(scenarios)} scenarios (those whose trajectories "
                           "were given to the report), to keep the page small."))
    for n, run in enumerate(runs):
        chosen = {}
        for labels in ranked.values():  # each family's best variant among this scenario's runs
            label = next((label for label in labels if label in run.others), None)
            if label is not None:
                chosen[label] = run.others[label]
        chosen = chosen or dict(list(run.others.items())[:3])
        shown = ([(run.truth_label, run.truth)] if run.truth is not None else [])
        shown += [(run.reference_label, run.reference), *chosen.items()]
        figure, notes = viewer_figure(shown, run.plane, budget, distance_to=shown[0][0])
        parts.append(f"<h3>{html.escape(run.scenario)}</h3>")
        parts += [_note(note) for note in notes]
        parts.append(plot_div(figure, f"viewer-{n}", 520) if figure is not None
                     else _note("Nothing to show (no finite frames)."))
    return "\n".join(parts)


def _time_convergence(frame: pd.DataFrame) -> str:
    """Per scenario: how far the reference moves when its time step is halved (`ref_dt_change`), beside the best
    reduced solver's error against it."""
    if "ref_dt_change" not in frame or frame["ref_dt_change"].isna().all():
        return _note("No full-space run at a smaller time step than the reference's (variant dt-half).")
    refs = frame[frame["variant"] == "reference"][["scenario", "split", "dt", "ref_dt_change"]]
    reduced = frame[~frame["solver"].isin(frame.loc[frame["variant"] == "reference", "solver"])]
    best = (pd.to_numeric(reduced["pos_rmse_rel"], errors="coerce").groupby(reduced["scenario"]).min()
            .rename("best_reduced_pos_rmse_rel"))
    table = refs.merge(best, left_on="scenario", right_index=True, how="left")
    return (_note("ref_dt_change: pos_rmse_rel of the full-space solver at half the reference's time step against "
                  "the reference. Where the error shrinks with dt, the reference's own time-discretisation error is at "
                  "least half of it, and about twice it once backward Euler is in its first-order range: where it "
                  "exceeds an accuracy target, the target measures how differently the solvers dissipate "
                  "numerically, not how well they do physics.")
            + _table(table))


def _stick_slip(frame: pd.DataFrame) -> str:
    """Stick/slip verdicts of each run and its reference."""
    if "stick_ref" not in frame or frame["stick_ref"].isna().all():
        return _note("No stick/slip verdicts (scenes without a plane).")
    rows = frame[frame["stick_ref"].notna()]
    agree = rows["stick_agree"].map(truthy)
    table = _columns(rows, ["scenario", "mesh", "solver", "variant", "stick_ref", "stick", "stick_agree",
                            "end_speed_ref", "end_speed"])
    return (_note(f"{int(agree.sum())} of {len(rows)} runs agree with the reference on whether the body ends at "
                  "rest on the plane (end_speed: mean centre-of-mass speed along the plane over the last 10% of "
                  "the run, m/s).")
            + _table(table, verdicts=["stick_agree"]))


def _remeshing(frame: pd.DataFrame) -> str:
    """Error of each model on its training mesh and on the other meshes it ran on, and the remesh ratio."""
    table = remeshing_summary(frame)
    if table.empty:
        return _note("No remeshing rows (no run on a mesh other than its model's training mesh).")
    return (_note("Median pos_rmse_rel of each model on its training mesh and on other meshes of the same shape, "
                  "and the median remesh ratio: a run's error on the other mesh / the same model's on the same "
                  "scenario on its training mesh (1 = remeshing costs nothing).")
            + _table(table))


def _stability(frame: pd.DataFrame, gates: Sequence[object]) -> str:
    """Which cases pass their gates per solver and law, the contact laws side by side, then every run's
    stability metrics, solver health and failure reason."""
    stability = stability_metrics()
    table = _columns(frame, ["scenario", "mesh", "solver", "variant", "law", *stability])
    return (_stability_matrix(gates) + _contact_laws(frame)
            + _note("finite: every stored value finite; max_penetration_rel: deepest surface point below the plane "
                    "/ L; inverted_tets: tets with det F <= 0 in some frame (most in one frame, at the end); "
                    "volume_ratio_final: volume at the end / rest volume; energy_ratio_max: largest total energy / "
                    "initial (kinetic + elastic + gravity, > 1 means energy grew); creep_ratio: speed along the "
                    "plane at the end / the friction law's creep speed (about 1 where the law holds the body); "
                    "not_converged: steps whose Newton solve failed even after retries; line_search_stalls: Newton "
                    "iterations without decrease; step_retries: steps redone as two half steps.")
            + _table(table, verdicts=[c for c in stability if COLUMNS[c].better == "true"]))


#: The stability matrix's cell kinds, most severe first: (prefix, verdicts it lists, CSS class).
_CASE_KINDS = (("fail", "binding failed", "fail"), ("advisory fail", "advisory failed", "warn"),
               ("undecidable", "undecidable", "warn"))


def _stability_matrix(gates: Sequence[object]) -> str:
    """Case x solver variant: `pass`, or the metrics whose binding gates failed (red), whose advisory checks failed
    and whose verdicts are undecidable (amber), from the gate verdicts: the colours the summary's banner takes
    (`analysis.summary.banner`)."""
    verdicts = verdict_frame(gates)
    if verdicts.empty or not {"scenario", "variant", "metric"} <= set(verdicts):
        return _note("No gates apply to this suite, so no case is judged here.")
    verdicts = verdicts[verdicts["scenario"] != "(none)"]
    verdicts = verdicts.assign(kind=np.where(verdicts["status"] == "undecidable", "undecidable",
                                             np.where(verdicts["advisory"], "advisory ", "binding ")
                                             + verdicts["status"].astype(str)))
    keys = ["scenario", "variant"]
    cases = verdicts.groupby(keys)
    cells, classes = {}, {}
    for key, g in cases:
        listed = [f"{prefix}: {', '.join(sorted(set(g.loc[g['kind'] == kind, 'metric'].astype(str))))}"
                  for prefix, kind, _ in _CASE_KINDS if (g["kind"] == kind).any()]
        cells[key] = "; ".join(listed) or "pass"
        classes[key] = next((cls for _, kind, cls in _CASE_KINDS if (g["kind"] == kind).any()), "pass")
    index = pd.MultiIndex.from_tuples(list(cells), names=keys)
    matrix = pd.Series(list(cells.values()), index=index).unstack("variant").fillna("")
    kinds = pd.Series(list(classes.values()), index=index).unstack("variant").fillna("")
    order = sorted(matrix.columns, key=lambda c: (not str(c).startswith("full/"), str(c)))  # full first
    matrix, kinds = matrix[order], kinds[order]
    head = "".join(f"<th>{defined(str(c))}</th>" for c in ["scenario", *matrix.columns])
    body = []
    for scenario, row in matrix.iterrows():
        tds = [f'<td class="text">{html.escape(str(scenario))}</td>']
        for c in matrix.columns:
            cls = kinds.loc[scenario, c]
            tds.append(f'<td class="text {cls}">{html.escape(str(row[c]))}</td>' if cls
                       else '<td class="text"></td>')
        body.append("<tr>" + "".join(tds) + "</tr>")
    tally = []
    for c in matrix.columns:
        judged = kinds[c][kinds[c] != ""]
        n_pass, n_fail = int((judged == "pass").sum()), int((judged == "fail").sum())
        cls = "fail" if n_fail else "warn" if n_pass < len(judged) else "pass"
        tally.append(f'<td class="text {cls}">{n_pass} of {len(judged)} passed, {n_fail} failed</td>')
    body.append('<tr><td class="text">cases</td>' + "".join(tally) + "</tr>")
    return (_note("Cases against the gates and advisory checks (gates.toml) per solver variant and contact law: "
                  "pass, or the metrics whose binding gates failed (red: the banner's failures), whose advisory "
                  "checks failed (amber: reported, not enforced) and whose verdicts are undecidable (amber: an "
                  f"accuracy threshold below {UNDECIDABLE_FACTOR:g}x an uncertified truth's error estimate, or a "
                  "speed limit met only by an upper bound).")
            + f'<div class="scroll"><table class="stability-matrix">\n<thead><tr>{head}</tr></thead>\n<tbody>\n'
            + "\n".join(body) + "\n</tbody>\n</table></div>")


def _contact_laws(frame: pd.DataFrame) -> str:
    """Per solver variant and contact law: worst penetration, creep, time per step, Newton work, failures."""
    if "law" not in frame or frame["law"].dropna().nunique() < 2:
        return ""
    f = frame.copy()
    f["label"] = variant_labels(f)
    num = lambda c: pd.to_numeric(f[c], errors="coerce") if c in f else pd.Series(np.nan, index=f.index)  # noqa: E731
    f["_creep"] = num("creep_ratio").where(np.isfinite(num("creep_ratio")))
    rows = []
    for (label, law), g in f.groupby(["label", "law"], sort=True):
        rows.append({"variant": label, "law": law, "runs": len(g),
                     "failed": int((g.get("status", pd.Series("ok", index=g.index)) == "failed").sum()),
                     "max_penetration_rel": num("max_penetration_rel")[g.index].max(),
                     "creep_ratio_median": g["_creep"].median(),
                     "step_ms_median": num("step_ms_median")[g.index].median(),
                     "newton_iters_mean": num("newton_iters_mean")[g.index].mean(),
                     "step_retries": num("step_retries")[g.index].sum()})
    return (_note("Contact laws side by side (every case of the suite): the deepest penetration / L, the median "
                  "creep ratio where the law holds a body on a slope, the median time per step [ms], Newton "
                  "iterations per step and step retries.")
            + _table(pd.DataFrame(rows)))


def _provenance(frame: pd.DataFrame) -> str:
    """The distinct provenance values of the results, and the plotting library that draws the figures."""
    rows = []
    provenance = names("provenance", placed=True)  # the table's own, not each run's key
    for col in [c for c in provenance if c in frame] + [c for c in frame if c.endswith("_version")
                                                        and c not in provenance]:
        values = [str(v) for v in frame[col].dropna().unique() if str(v) != ""]
        rows.append({"field": col, "value": ", ".join(values)})
    rows.append({"field": "plots", "value": f"plotly {plotly_version()} (plotly.js inline)"})
    return _table(pd.DataFrame(rows, columns=["field", "value"])) if rows else _note("No provenance recorded.")


def comparison_section(comparison: pd.DataFrame, baseline: str, max_rows: int = 500) -> str:
    """The comparison of these results with a baseline result set (`bench.compare.compare_results`'s table): a
    banner with the count of each verdict, then the rows that are not `ok` (regressions first; only the
    regressions where there are more than `max_rows`). Every text is escaped."""
    counts = comparison["verdict"].value_counts()
    n_reg = int(counts.get("regression", 0))
    tally = ", ".join(f"{verdict} {int(n)}" for verdict, n in counts.items())
    banner = (f"Regressions against the baseline {baseline}: {n_reg}" if n_reg
              else f"No regression against the baseline {baseline}")
    parts = [f'<p class="banner {"fail" if n_reg else "pass"}">{html.escape(banner)}</p>',
             _note(f"Metric rows: {tally or 'none'}. A regression is a metric that moved in its bad direction by "
                   "more than its tolerance (relative % and absolute; timing as a ratio x), a binding gate that "
                   "the baseline met and these results fail, a failed run, or a row or value the baseline has and "
                   "these results lack. `frictionbench compare BASELINE OUT` prints the same table.")]
    changed = comparison[comparison["verdict"] != "ok"]
    if len(changed) > max_rows:
        changed = changed[changed["verdict"] == "regression"].head(max_rows)
        parts.append(_note(f"Only the first {len(changed)} regressions are listed."))
    if not changed.empty:
        parts.append(_table(changed.drop(columns=["kind"])))
    return "\n".join(parts)


def write_report_html(results: pd.DataFrame | Sequence[Mapping[str, object]], out_dir: str | os.PathLike, *,
                      gates: Sequence[object] = (), runs: Sequence[ScenarioRuns] = (),
                      extra_sections: Sequence[tuple[str, str]] = (), title: str = "frictionbench report",
                      viewer: ViewerBudget = DEFAULT_BUDGET, summary: Summary | None = None) -> Path:
    """Write `out_dir/report.html` atomically and return its path.

    results: the results table (a DataFrame as read from results.csv, or its rows).
    gates: gate verdicts, each a mapping, dataclass or object with at least a boolean `passed` (and optionally a
        `status`: passed, failed or undecidable); every field becomes a column of the verdict table.
    runs: trajectories for the error-over-time plots and the 3D viewers (none: those sections say so).
    extra_sections: (heading, HTML fragment) pairs appended before the provenance; the fragments are inserted
        as given, so they must be trusted and self-contained.
    viewer: the 3D viewers' frame and triangle budget.
    summary: the first screen's answer (`analysis.summary.summarise` of the results and gates; computed when None).
    """
    frame = results.copy() if isinstance(results, pd.DataFrame) else results_frame(results)
    summary = summarise(frame, gates) if summary is None else summary
    no_runs = _note("No trajectories were given to the report.")
    sections = [
        ("summary", "Summary", _summary(frame, gates, summary)),
        ("accuracy-vs-time", "Accuracy versus time", _frontier(frame)),
        ("ladders", "Ground-truth ladders", _ladders(frame)),
        ("outcomes", "Outcomes against the truth", _outcomes(frame)),
        ("error-parts", "Where the error comes from", _error_parts(frame)),
        ("error-over-time", "Error over time", _error_over_time(runs) if runs else no_runs),
        ("viewer", "3D viewer", _viewers(runs, frame, viewer) if runs else no_runs),
        ("time-convergence", "Reference time-step convergence", _time_convergence(frame)),
        ("stick-slip", "Stick/slip agreement", _stick_slip(frame)),
        ("remeshing", "Remeshing", _remeshing(frame)),
        ("stability", "Stability", _stability(frame, gates)),
        ("gate-verdicts", "Gate verdicts", _verdicts(gates)),
        ("results", "Results", _results(frame)),
        *((f"extra-{i}", heading, fragment) for i, (heading, fragment) in enumerate(extra_sections)),
        ("provenance", "Provenance", _provenance(frame)),
    ]
    nav = "".join(f'<li><a href="#{sid}">{html.escape(heading)}</a></li>' for sid, heading, _ in sections)
    body = "\n".join(f'<section id="{sid}">\n<h2>{html.escape(heading)}</h2>\n{content}\n</section>'
                     for sid, heading, content in sections)
    page = (f'<!DOCTYPE html>\n<html lang="en">\n<head>\n<meta charset="utf-8">\n'
            f'<meta name="viewport" content="width=device-width, initial-scale=1">\n'
            f"<title>{html.escape(title)}</title>\n<style>{CSS}</style>\n</head>\n<body>\n"
            f"<h1>{html.escape(title)}</h1>\n<nav><ul>{nav}</ul></nav>\n{body}\n{page_scripts()}\n</body>\n"
            "</html>\n")
    return write_text_atomic(Path(out_dir) / "report.html", page)

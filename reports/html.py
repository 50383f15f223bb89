"""One self-contained `report.html`: tables, plots and renders inline, no script, no external resource.

Plots are PNG images embedded as base64 `data:` URIs, styling is one inline `<style>` block, so the file opens
offline and can be mailed or archived alone. Sections (with these ids and headings):
summary (gate verdicts, results), accuracy-vs-time, error-over-time, stick-slip, remeshing, stability, renders,
any extra sections, provenance.
"""

from __future__ import annotations

import base64
import dataclasses
import html
import os
from collections.abc import Mapping, Sequence
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np
import pandas as pd

from analysis.derived import remeshing_summary
from analysis.metrics import align_frames
from analysis.table import PROVENANCE_COLUMNS, results_frame, variant_labels
from reports.plots import accuracy_vs_time_figure, error_over_time_figure, figure_png
from reports.render import Renderer, render_surface, select_renderer, view_bounds
from scenarios.atomic import write_text_atomic
from scenarios.model import Plane
from solvers.trajectory import Trajectory

REFERENCE_COLOR = "#4a7fb5"
OTHER_COLOR = "#d9822b"

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
.banner.pass { background: #d7f0d7; } .banner.fail { background: #f6d0d0; }
img { max-width: 100%; } figure { margin: .5em 0; } figcaption { font-size: .85em; color: #555; }
.note { color: #555; font-size: .9em; } .scroll { overflow-x: auto; }
"""


@dataclass(frozen=True)
class ScenarioRuns:
    """Trajectories of one scenario for the renders, and their errors for the error-over-time plot.

    scenario: its name (a heading); reference: the full-space run; others: label -> run compared with it, each
    on the reference's mesh; errors: label -> (t (F,) [s], e (F,) [-]), the per-frame error of that run against
    the reference (`analysis.metrics.error_over_time`); plane: drawn in the renders; reference_label: the
    reference's label.
    """

    scenario: str
    reference: Trajectory
    others: Mapping[str, Trajectory] = field(default_factory=dict)
    errors: Mapping[str, tuple[np.ndarray, np.ndarray]] = field(default_factory=dict)
    plane: Plane | None = None
    reference_label: str = "reference"


def _missing(value: object) -> bool:
    """None, NaN, NaT or pd.NA."""
    return value is None or (pd.api.types.is_scalar(value) and bool(pd.isna(value)))


def _cell(value: object) -> str:
    """A table cell's text: floats to 3 significant digits, booleans as yes/no, missing values as an en dash."""
    if _missing(value):
        return "&ndash;"
    if isinstance(value, (bool, np.bool_)):
        return "yes" if value else "no"
    if isinstance(value, (float, np.floating)):
        return f"{value:.3g}"
    return html.escape(str(value))


def _verdict_class(value: object) -> str:
    """CSS class of a verdict cell: pass for True / 'ok' / 'pass', fail for False / anything else, '' if missing."""
    if _missing(value):
        return ""
    if isinstance(value, (bool, np.bool_)):
        return "pass" if value else "fail"
    return "pass" if str(value).lower() in ("ok", "pass", "passed", "true") else "fail"


def _table(frame: pd.DataFrame, verdicts: Sequence[str] = ()) -> str:
    """HTML table of a frame; columns named in verdicts are coloured pass/fail."""
    head = "".join(f"<th>{html.escape(str(c))}</th>" for c in frame.columns)
    body = []
    for row in frame.itertuples(index=False):
        cells = []
        for col, value in zip(frame.columns, row):
            classes = (_verdict_class(value) if col in verdicts else "", "text" if isinstance(value, str) else "")
            cls = " ".join(c for c in classes if c)
            cells.append(f'<td class="{cls}">{_cell(value)}</td>' if cls else f"<td>{_cell(value)}</td>")
        body.append("<tr>" + "".join(cells) + "</tr>")
    return (f'<div class="scroll"><table>\n<thead><tr>{head}</tr></thead>\n<tbody>\n' + "\n".join(body)
            + "\n</tbody>\n</table></div>")


def _png(data: bytes, alt: str, caption: str = "") -> str:
    """An embedded PNG (data URI) in a figure element."""
    uri = "data:image/png;base64," + base64.b64encode(data).decode("ascii")
    cap = f"<figcaption>{html.escape(caption)}</figcaption>" if caption else ""
    return f'<figure><img src="{uri}" alt="{html.escape(alt)}">{cap}</figure>'


def _note(text: str) -> str:
    """A paragraph of explanatory text."""
    return f'<p class="note">{html.escape(text)}</p>'


def _columns(frame: pd.DataFrame, wanted: Sequence[str]) -> pd.DataFrame:
    """The wanted columns that the frame has, in that order."""
    return frame[[c for c in wanted if c in frame.columns]]


def _as_dict(verdict: object) -> dict[str, object]:
    """A gate verdict (mapping, dataclass or plain object) as a dict."""
    if isinstance(verdict, Mapping):
        return dict(verdict)
    if dataclasses.is_dataclass(verdict) and not isinstance(verdict, type):
        return dataclasses.asdict(verdict)
    return dict(vars(verdict))


def _summary(frame: pd.DataFrame, gates: Sequence[object]) -> str:
    """Gate banner and verdicts, then the key columns of every results row."""
    parts = []
    failed_runs = int((frame["status"].fillna("ok") != "ok").sum()) if "status" in frame else 0
    if gates:
        every = pd.DataFrame([_as_dict(g) for g in gates])
        advisory = every["advisory"].fillna(False).astype(bool) if "advisory" in every else pd.Series(False, every.index)
        verdicts = every[~advisory]
        n_pass = int(verdicts["passed"].astype(bool).sum())
        ok = n_pass == len(verdicts)
        parts.append(f'<p class="banner {"pass" if ok else "fail"}">Gates: {n_pass} of {len(verdicts)} passed'
                     f"{'' if ok else f', {len(verdicts) - n_pass} failed'}.</p>")
        if advisory.any():
            n_adv = int(every[advisory]["passed"].astype(bool).sum())
            parts.append(_note(f"Advisory checks (judged, not enforced; see Stability): {n_adv} of "
                               f"{int(advisory.sum())} passed."))
        shown = verdicts if len(verdicts) <= 100 else verdicts[~verdicts["passed"].astype(bool)]
        caption = "" if shown is verdicts else _note(f"{len(verdicts)} verdicts; the failed ones are listed.")
        parts.append("<h3>Gate verdicts</h3>" + caption + _table(shown, verdicts=["passed"]))
    else:
        parts.append(_note("No gates were evaluated for these results."))
    parts.append(_note(f"{len(frame)} result rows, {failed_runs} failed runs."))
    summary = _columns(frame, ["suite", "scenario", "split", "mesh", "solver", "variant", "status", "pos_rmse_rel",
                               "proj_rmse_rel", "com_err_rel", "final_err_rel", "slide_err_rel", "stick_agree",
                               "step_ms_median", "speedup"])
    parts.append("<h3>Results</h3>" + _table(summary, verdicts=["status", "stick_agree"]))
    return "\n".join(parts)


def _accuracy_vs_time(frame: pd.DataFrame) -> str:
    """The Pareto plot against step time, or against speed-up where no step times were measured."""
    step = pd.to_numeric(frame.get("step_ms_median", pd.Series(dtype=float)), errors="coerce")
    x, higher = ("step_ms_median", False) if (step > 0).any() else ("speedup", True)
    fig = accuracy_vs_time_figure(frame, x=x, y="pos_rmse_rel", x_higher_is_better=higher)
    return (_note("One point per solver variant (median over its scenarios); the red line is the Pareto front: "
                  "no other variant is both faster and more accurate.")
            + _png(figure_png(fig), "accuracy versus time", f"pos_rmse_rel versus {x}"))


def _error_over_time(runs: Sequence[ScenarioRuns]) -> str:
    """One error-over-time plot per scenario."""
    parts = []
    for run in runs:
        fig = error_over_time_figure(run.errors, f"{run.scenario}: error against {run.reference_label}")
        parts.append(_png(figure_png(fig), f"error over time, {run.scenario}", run.scenario))
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
    agree = rows["stick_agree"].astype(bool)
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
    table = _columns(frame, ["scenario", "mesh", "solver", "variant", "law", "status", "finite",
                             "max_penetration_rel", "inverted_tets", "inverted_tets_frame_max", "inverted_tets_final",
                             "volume_ratio_final", "energy_ratio_max", "creep_ratio", "not_converged",
                             "line_search_stalls", "step_retries", "failure"])
    return (_stability_matrix(gates) + _contact_laws(frame)
            + _note("finite: every stored value finite; max_penetration_rel: deepest surface point below the plane "
                    "/ L; inverted_tets: tets with det F <= 0 in some frame (most in one frame, at the end); "
                    "volume_ratio_final: volume at the end / rest volume; energy_ratio_max: largest total energy / "
                    "initial (kinetic + elastic + gravity, > 1 means energy grew); creep_ratio: speed along the "
                    "plane at the end / the friction law's creep speed (about 1 where the law holds the body); "
                    "not_converged: steps whose Newton solve failed even after retries; line_search_stalls: Newton "
                    "iterations without decrease; step_retries: steps redone as two half steps.")
            + _table(table, verdicts=["status", "finite"]))


def _stability_matrix(gates: Sequence[object]) -> str:
    """Case x solver variant: `pass`, or the metrics whose gates failed (from the gate verdicts)."""
    verdicts = pd.DataFrame([_as_dict(v) for v in gates])
    if verdicts.empty or not {"scenario", "variant", "metric"} <= set(verdicts):
        return _note("No gates apply to this suite, so no case is judged here.")
    verdicts = verdicts[verdicts["scenario"] != "(none)"]
    failed = (verdicts[~verdicts["passed"].astype(bool)].groupby(["scenario", "variant"])["metric"]
              .apply(lambda m: ", ".join(sorted(set(m)))))
    cells = verdicts.groupby(["scenario", "variant"])["passed"].all().map({True: "pass", False: "fail"})
    cells = cells.where(cells == "pass", "fail: " + failed.reindex(cells.index).fillna(""))
    matrix = cells.unstack("variant").fillna("")
    matrix = matrix[sorted(matrix.columns, key=lambda c: (not str(c).startswith("full/"), str(c)))]  # full first
    counts = (matrix == "pass").sum().astype(str) + " / " + (matrix != "").sum().astype(str)
    matrix = pd.concat([matrix, counts.to_frame("cases passed").T]).reset_index(names="scenario")
    head = "".join(f"<th>{html.escape(str(c))}</th>" for c in matrix.columns)
    body = []
    for _, row in matrix.iterrows():
        tds = [f'<td class="text">{html.escape(str(row["scenario"]))}</td>']
        for c in matrix.columns[1:]:
            v = str(row[c])
            cls = "text pass" if v == "pass" else "text fail" if v.startswith("fail") else "text"
            tds.append(f'<td class="{cls}">{html.escape(v)}</td>')
        body.append("<tr>" + "".join(tds) + "</tr>")
    return (_note("Cases against the gates and advisory checks (gates.toml) per solver variant and contact law: "
                  "pass, or the metrics that failed.")
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


def _placeholder_cell(text: str) -> str:
    """A table cell that says why a picture is missing."""
    return f'<td class="text fail">{html.escape(text)}</td>'


def _renders(runs: Sequence[ScenarioRuns], renderer: Renderer, key_frames: int) -> str:
    """Per scenario, a table of pictures: one row per key frame, the reference then the other runs."""
    parts = [_note(f"Rendered with {renderer.detail}. Same camera for every picture of a scenario.")]
    for run in runs:
        ref = run.reference
        keys = np.unique(np.round(np.linspace(0, ref.n_frames - 1, max(key_frames, 1))).astype(int))
        bounds = view_bounds(ref.x)
        columns = {run.reference_label: (ref, REFERENCE_COLOR), **{k: (v, OTHER_COLOR) for k, v in run.others.items()}}
        head = "<th>t [s]</th>" + "".join(f"<th>{html.escape(label)}</th>" for label in columns)
        body = []
        for k in keys:
            cells = [f"<td>{ref.t[k]:.3g}</td>"]
            for traj, color in columns.values():
                cells.append(_render_cell(traj, ref.t[k], bounds, run.plane, renderer, color))
            body.append("<tr>" + "".join(cells) + "</tr>")
        parts.append(f'<h3>{html.escape(run.scenario)}</h3>\n<div class="scroll"><table>\n'
                     f"<thead><tr>{head}</tr></thead>\n<tbody>\n" + "\n".join(body) + "\n</tbody>\n</table></div>")
    return "\n".join(parts)


def _render_cell(traj: Trajectory, t: float, bounds: np.ndarray, plane: Plane | None, renderer: Renderer,
                 color: str) -> str:
    """A table cell with the render of traj's frame at time t, or why there is none."""
    try:
        _, (k,) = align_frames(np.array([t]), traj.t)
    except ValueError:
        return _placeholder_cell(f"no frame at t = {t:.3g} s")
    if not np.isfinite(traj.x[k]).all():
        return _placeholder_cell("non-finite positions")
    png = render_surface(traj.x[k], traj.surface, bounds=bounds, plane=plane, renderer=renderer, color=color)
    return "<td>" + _png(png, f"frame at t = {t:.3g} s") + "</td>"


def _provenance(frame: pd.DataFrame, renderer: Renderer | None) -> str:
    """The distinct provenance values of the results, and the renderer that made the pictures."""
    rows = []
    for col in [c for c in PROVENANCE_COLUMNS if c in frame] + [c for c in frame if c.endswith("_version")
                                                                  and c not in PROVENANCE_COLUMNS]:
        values = [str(v) for v in frame[col].dropna().unique() if str(v) != ""]
        rows.append({"field": col, "value": ", ".join(values)})
    if renderer is not None:
        rows.append({"field": "renderer", "value": renderer.detail})
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
                      renderer: str = "auto", key_frames: int = 3) -> Path:
    """Write `out_dir/report.html` atomically and return its path.

    results: the results table (a DataFrame as read from results.csv, or its rows).
    gates: gate verdicts, each a mapping, dataclass or object with at least a boolean `passed`; every field
        becomes a column of the verdict table.
    runs: trajectories for the error-over-time plots and the renders (none: those sections say so).
    extra_sections: (heading, HTML fragment) pairs appended before the provenance; the fragments are inserted
        as given, so they must be trusted and self-contained.
    renderer: `auto`, `vtk` or `matplotlib` (see `reports.render.select_renderer`); key_frames: renders per run.
    """
    frame = results.copy() if isinstance(results, pd.DataFrame) else results_frame(results)
    chosen = select_renderer(renderer) if runs else None
    no_runs = _note("No trajectories were given to the report.")
    sections = [
        ("summary", "Summary", _summary(frame, gates)),
        ("accuracy-vs-time", "Accuracy versus time", _accuracy_vs_time(frame)),
        ("error-over-time", "Error over time", _error_over_time(runs) if runs else no_runs),
        ("time-convergence", "Reference time-step convergence", _time_convergence(frame)),
        ("stick-slip", "Stick/slip agreement", _stick_slip(frame)),
        ("remeshing", "Remeshing", _remeshing(frame)),
        ("stability", "Stability", _stability(frame, gates)),
        ("renders", "Renders: full versus reduced", _renders(runs, chosen, key_frames) if chosen else no_runs),
        *((f"extra-{i}", heading, fragment) for i, (heading, fragment) in enumerate(extra_sections)),
        ("provenance", "Provenance", _provenance(frame, chosen)),
    ]
    nav = "".join(f'<li><a href="#{sid}">{html.escape(heading)}</a></li>' for sid, heading, _ in sections)
    body = "\n".join(f'<section id="{sid}">\n<h2>{html.escape(heading)}</h2>\n{content}\n</section>'
                     for sid, heading, content in sections)
    page = (f'<!DOCTYPE html>\n<html lang="en">\n<head>\n<meta charset="utf-8">\n'
            f'<meta name="viewport" content="width=device-width, initial-scale=1">\n'
            f"<title>{html.escape(title)}</title>\n<style>{CSS}</style>\n</head>\n<body>\n"
            f"<h1>{html.escape(title)}</h1>\n<nav><ul>{nav}</ul></nav>\n{body}\n</body>\n</html>\n")
    return write_text_atomic(Path(out_dir) / "report.html", page)

"""Report figures as plotly figure dicts (data, layout, frames), drawn in the page by the embedded plotly.js.

Suite-provided texts (scenario and variant names) are HTML-escaped here (`reports.interactive.text`), since plotly
renders a subset of HTML in names and hover texts.
"""

from __future__ import annotations

from collections.abc import Mapping, Sequence

import numpy as np
import pandas as pd

from frictionbench.analysis.summary import accuracy_columns, ladder_mask, numeric_column
from frictionbench.analysis.table import variant_labels
from frictionbench.reports.interactive import text

#: Colours of the traces, in order (plotly's default cycle, spelled out so the legend and the viewer agree).
PALETTE = ("#1f77b4", "#ff7f0e", "#2ca02c", "#d62728", "#9467bd", "#8c564b", "#e377c2", "#7f7f7f", "#bcbd22",
           "#17becf")

#: Colour ramps of the frontier, one per solver family (in order of the families' names), its variants taking the
#: shades in turn, dark to light: a family keeps its own hue however many variants it has.
FAMILY_RAMPS = (("#08306b", "#08519c", "#2171b5", "#4292c6", "#6baed6", "#9ecae1", "#c6dbef", "#deebf7"),  # blues
                ("#7f2704", "#a63603", "#d94801", "#f16913", "#fd8d3c", "#fdae6b", "#fdd0a2", "#fee6ce"),  # oranges
                ("#00441b", "#006d2c", "#238b45", "#41ab5d", "#74c476", "#a1d99b", "#c7e9c0", "#e5f5e0"),  # greens
                ("#3f007d", "#54278f", "#6a51a3", "#807dba", "#9e9ac8", "#bcbddc", "#dadaeb", "#efedf5"),  # purples
                ("#67000d", "#a50f15", "#cb181d", "#ef3b2c", "#fb6a4a", "#fc9272", "#fcbba1", "#fee0d2"),  # reds
                ("#000000", "#252525", "#525252", "#737373", "#969696", "#bdbdbd", "#d9d9d9", "#f0f0f0"))  # greys

#: Marker symbols, one per solver family in the frontier (with its colour ramp, tells the families apart).
SYMBOLS = ("circle", "square", "diamond", "triangle-up", "cross", "x", "star", "hexagon", "pentagon",
           "triangle-down")


def pareto_front(x: np.ndarray, y: np.ndarray, x_higher_is_better: bool = False) -> np.ndarray:
    """Indices of the non-dominated points, ordered from best x to worst x; y (an error) is lower-is-better.

    Point i is dominated when another point is at least as good in both x and y and better in one. x is a cost
    (lower is better) unless x_higher_is_better (a speed-up). Points with a non-finite coordinate are ignored.
    """
    x = np.asarray(x, dtype=float)
    y = np.asarray(y, dtype=float)
    cost = -x if x_higher_is_better else x
    ok = np.flatnonzero(np.isfinite(cost) & np.isfinite(y))
    front: list[int] = []
    best_y = np.inf
    for i in ok[np.lexsort((y[ok], cost[ok]))]:  # by cost, ties by error
        if y[i] < best_y:
            front.append(int(i))
            best_y = y[i]
    return np.array(front, dtype=int)


def _log_axis(title: str) -> dict[str, object]:
    return {"type": "log", "title": {"text": text(title)}, "exponentformat": "power", "gridcolor": "#e4e4e4"}


def _layout(title: str, x_title: str, y_title: str) -> dict[str, object]:
    return {"title": {"text": text(title), "font": {"size": 14}}, "xaxis": _log_axis(x_title),
            "yaxis": _log_axis(y_title), "hovermode": "closest", "margin": {"l": 70, "r": 20, "t": 40, "b": 55},
            "legend": {"title": {"text": "click to hide / show"}}, "plot_bgcolor": "white"}


def _hover(label: str, scenario: object, values: Mapping[str, float]) -> str:
    lines = [f"<b>{text(label)}</b>", f"scenario: {text(scenario)}"]
    lines += [f"{text(k)}: {v:.3g}" for k, v in values.items() if np.isfinite(v)]
    return "<br>".join(lines)


def frontier_figure(frame: pd.DataFrame) -> dict[str, object]:
    """Error against cost, log axes: one point per run (a trace per solver variant, hover: variant, scenario,
    values), each variant's own step ladder (rows with a `curve`) joined level by level into a line per curve and
    scenario in its family's hue (its points in the same shade), the ground-truth ladders as curves per integrator
    and scenario, and the Pareto front of the variants' medians. Columns from `accuracy_columns`; rows with a zero
    or missing error or cost are left out (the reference against itself, the truth against itself)."""
    cols = accuracy_columns(frame)
    f = pd.DataFrame({"label": variant_labels(frame), "scenario": frame.get("scenario", pd.Series("", frame.index)),
                      "family": frame["solver"].astype(str) if "solver" in frame else "",
                      "x": numeric_column(frame, cols.cost), "y": numeric_column(frame, cols.error),
                      "dt": numeric_column(frame, "dt"), "ladder": ladder_mask(frame)})
    f["integrator"] = frame["ladder"].fillna("").astype(str) if "ladder" in frame else ""
    f["curve"] = frame["curve"].fillna("").astype(str) if "curve" in frame else ""
    f["level"] = numeric_column(frame, "curve_level")
    f = f[(f["x"] > 0) & (f["y"] > 0)]
    data: list[dict[str, object]] = []
    runs = f[~f["ladder"]]
    families = sorted(runs["family"].unique())
    shades: dict[str, dict[str, str]] = {}  # family -> its variants' and curves' colours: a curve's points share one

    def colour(family: str, key: str) -> str:
        """The shade of the family's ramp that `key` (a variant label, or a curve) takes, the next one at first."""
        ramp = FAMILY_RAMPS[families.index(family) % len(FAMILY_RAMPS)]
        taken = shades.setdefault(family, {})
        return taken.setdefault(key, ramp[len(taken) % len(ramp)])

    for label, g in runs.groupby("label", sort=True):
        family = g["family"].iloc[0]
        k = families.index(family)
        data.append({"type": "scatter", "mode": "markers", "name": text(label), "x": g["x"].tolist(),
                     "y": g["y"].tolist(), "marker": {"size": 9, "color": colour(family, g["curve"].iloc[0] or label),
                                "symbol": SYMBOLS[k % len(SYMBOLS)], "line": {"width": 0.5, "color": "#333333"}},
                     "hovertext": [_hover(label, s, {cols.error: y, cols.cost: x})
                                   for s, x, y in zip(g["scenario"], g["x"], g["y"])],
                     "hoverinfo": "text"})
    for (family, curve), g in runs[runs["curve"] != ""].groupby(["family", "curve"], sort=True):
        for m, (scenario, points) in enumerate(g.groupby("scenario", sort=True)):
            points = points.sort_values("level")
            data.append({"type": "scatter", "mode": "lines", "name": text(f"curve {family}/{curve}"),
                         "legendgroup": text(f"curve {family}/{curve}"), "showlegend": m == 0,
                         "x": points["x"].tolist(), "y": points["y"].tolist(),
                         "line": {"color": colour(family, curve), "width": 1.5}, "hoverinfo": "skip"})
    medians = runs.groupby("label", sort=True)[["x", "y"]].median()
    front = pareto_front(medians["x"].to_numpy(), medians["y"].to_numpy())
    if len(front):
        data.append({"type": "scatter", "mode": "lines", "name": "Pareto front (medians)",
                     "x": medians["x"].iloc[front].tolist(), "y": medians["y"].iloc[front].tolist(),
                     "line": {"shape": "hv", "color": "#c0392b", "dash": "dot", "width": 1.5},
                     "hoverinfo": "skip"})  # its corners are medians: the runs' points carry the hover
    for n, (integrator, g) in enumerate(f[f["ladder"]].groupby("integrator", sort=True)):
        for m, (scenario, curve) in enumerate(g.groupby("scenario", sort=True)):
            curve = curve.sort_values("x")
            data.append({"type": "scatter", "mode": "lines+markers", "name": text(f"ladder {integrator}"),
                         "legendgroup": text(f"ladder {integrator}"), "showlegend": m == 0,
                         "x": curve["x"].tolist(), "y": curve["y"].tolist(),
                         "line": {"color": "#555555", "width": 1, "dash": ("solid", "dash", "dot")[n % 3]},
                         "marker": {"size": 5, "symbol": "diamond"},
                         "hovertext": [_hover(label, scenario, {cols.error: y, cols.cost: x, "dt": dt})
                                       for label, x, y, dt in zip(curve["label"], curve["x"], curve["y"],
                                                                  curve["dt"])],
                         "hoverinfo": "text"})
    against = "the ground truth" if cols.truth else "the same-dt reference"
    return {"data": data, "layout": _layout(f"{cols.error} (against {against}) versus {cols.cost}",
                                            f"{cols.cost} (lower is cheaper)", f"{cols.error} (lower is better)")}


def error_over_time_figure(curves: Mapping[str, tuple[np.ndarray, np.ndarray]], title: str) -> dict[str, object]:
    """Per-frame relative error e(t) (log y) of several runs in one scenario; curves: label -> (t (F,) [s],
    e (F,) [-]). Zero errors (a run against itself) are left out of the log axis."""
    data = []
    for n, (label, (t, e)) in enumerate(curves.items()):
        e = np.asarray(e, dtype=float)
        keep = np.isfinite(e) & (e > 0)
        data.append({"type": "scatter", "mode": "lines", "name": text(label), "x": np.asarray(t)[keep].tolist(),
                     "y": e[keep].tolist(), "line": {"color": PALETTE[n % len(PALETTE)], "width": 1.6},
                     "hovertemplate": f"{text(label)}<br>t = %{{x:.3g}} s<br>e = %{{y:.3g}}<extra></extra>"})
    layout = _layout(title, "t [s]", "RMS position error / L")
    layout["xaxis"] = {"title": {"text": "t [s]"}, "gridcolor": "#e4e4e4"}
    return {"data": data, "layout": layout}


def step_size_figure(records: Mapping[str, Sequence[Mapping[str, object]]], title: str) -> dict[str, object]:
    """The step size over time of adaptive runs (log y): per label, its per-step records (`solvers.step_stats.
    StepStats` as stored, each with its accepted step `dt` [s] and the attempts `rejected` before it) drawn as a
    step line at the steps' end times, and the steps that had rejected attempts as red crosses (hover: how many).
    Impacts and contact events show as the dips of the step."""
    data: list[dict[str, object]] = []
    for n, (label, steps) in enumerate(records.items()):
        dt = np.array([float(s["dt"]) for s in steps])
        t = np.cumsum(dt)
        rejected = np.array([int(s.get("rejected", 0)) for s in steps])
        color = PALETTE[n % len(PALETTE)]
        data.append({"type": "scatter", "mode": "lines", "name": text(label), "x": t.tolist(), "y": dt.tolist(),
                     "line": {"color": color, "width": 1.4, "shape": "vh"}, "legendgroup": text(label),
                     "hovertemplate": f"{text(label)}<br>t = %{{x:.4g}} s<br>dt = %{{y:.3g}} s<extra></extra>"})
        hit = rejected > 0
        if hit.any():
            data.append({"type": "scatter", "mode": "markers", "name": text(f"{label}: rejected attempts"),
                         "x": t[hit].tolist(), "y": dt[hit].tolist(), "legendgroup": text(label),
                         "marker": {"color": "#d62728", "symbol": "x", "size": 7},
                         "hovertext": [f"{n_rej} rejected before this step" for n_rej in rejected[hit]],
                         "hoverinfo": "text+x"})
    layout = _layout(title, "t [s]", "step size dt [s]")
    layout["xaxis"] = {"title": {"text": "t [s]"}, "gridcolor": "#e4e4e4"}
    return {"data": data, "layout": layout}


def ladder_figure(frame: pd.DataFrame) -> dict[str, object] | None:
    """The ground-truth ladders: err_truth against the time step (log-log; a tolerance ladder's against its runs'
    time.tol, the `tol` column), a curve per integrator and scenario, beside the truth's own error estimate per
    scenario (a dashed level). None when there are no ladder rows."""
    ladder = ladder_mask(frame)
    if not ladder.any():
        return None
    tol = numeric_column(frame, "tol")
    step = numeric_column(frame, "dt").where(tol.isna(), tol)
    f = pd.DataFrame({"label": variant_labels(frame), "scenario": frame.get("scenario", pd.Series("", frame.index)),
                      "integrator": frame["ladder"].fillna("").astype(str), "dt": step,
                      "y": numeric_column(frame, "err_truth"), "est": numeric_column(frame, "truth_err_est")})[ladder]
    data: list[dict[str, object]] = []
    scenarios = sorted(f["scenario"].astype(str).unique())
    integrators = sorted(f["integrator"].unique())
    for (scenario, integrator), g in f.groupby(["scenario", "integrator"], sort=True):
        g = g[(g["dt"] > 0) & (g["y"] > 0)].sort_values("dt")
        color = PALETTE[scenarios.index(str(scenario)) % len(PALETTE)]
        dash = ("solid", "dash", "dot")[integrators.index(integrator) % 3]
        data.append({"type": "scatter", "mode": "lines+markers", "name": text(f"{scenario}: {integrator}"),
                     "x": g["dt"].tolist(), "y": g["y"].tolist(), "line": {"color": color, "dash": dash},
                     "hovertext": [_hover(label, scenario, {"dt": dt, "err_truth": y})
                                   for label, dt, y in zip(g["label"], g["dt"], g["y"])], "hoverinfo": "text"})
    for scenario, g in f.groupby("scenario", sort=True):
        est = g["est"].dropna()
        dts = g["dt"][g["dt"] > 0]
        if est.empty or dts.empty or not est.iloc[0] > 0:
            continue
        data.append({"type": "scatter", "mode": "lines", "name": text(f"{scenario}: truth's error estimate"),
                     "x": [dts.min(), dts.max()], "y": [est.iloc[0]] * 2,
                     "line": {"color": PALETTE[scenarios.index(str(scenario)) % len(PALETTE)], "dash": "longdashdot",
                              "width": 1}, "hoverinfo": "name"})
    x_title = "dt [s], or time.tol [L] of a tolerance ladder" if tol[ladder].notna().any() else "dt [s]"
    return {"data": data, "layout": _layout("Ground-truth ladders: error against the truth per time step",
                                            x_title, "err_truth")}


#: The parts of a variant's error against the truth (`analysis.schema`), in the order drawn.
ERROR_PARTS: tuple[tuple[str, str], ...] = (
    ("err_projection", "projection: the truth projected onto the subspace"),
    ("pos_rmse_rel", "reduction: against the full-space run at its dt"),
    ("err_time", "time step: that full-space run against the truth"),
    ("err_truth", "total: against the truth"),
)


def error_parts_figure(frame: pd.DataFrame) -> dict[str, object] | None:
    """Where each variant's error comes from: grouped bars (log y) of the medians over scenarios of its error parts
    (`ERROR_PARTS`), one group per variant that has err_time (not the references, not the ladders). None when no
    row has them."""
    if "err_time" not in frame:
        return None
    rows = ~ladder_mask(frame) & numeric_column(frame, "err_time").notna()
    if "variant" in frame:
        rows &= frame["variant"].astype(str) != "reference"
    if not rows.any():
        return None
    f = pd.DataFrame({"label": variant_labels(frame)[rows]}
                     | {column: numeric_column(frame, column)[rows] for column, _ in ERROR_PARTS})
    medians = f.groupby("label", sort=True).median()
    data = []
    for n, (column, name) in enumerate(ERROR_PARTS):
        y = medians[column].where(medians[column] > 0)
        data.append({"type": "bar", "name": text(name), "x": [text(label) for label in medians.index],
                     "y": [None if pd.isna(v) else float(v) for v in y],
                     "marker": {"color": PALETTE[n % len(PALETTE)]},
                     "hovertemplate": f"%{{x}}<br>{text(column)} = %{{y:.3g}}<extra></extra>"})
    layout = _layout("Error parts per variant (medians over scenarios)", "variant", "fraction of L")
    layout["xaxis"] = {"title": {"text": "variant"}, "automargin": True}
    layout["barmode"] = "group"
    return {"data": data, "layout": layout}

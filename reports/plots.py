"""Report figures drawn with matplotlib's object-oriented API (no pyplot, no display), returned as PNG bytes."""

from __future__ import annotations

import io
from collections.abc import Mapping

import numpy as np
import pandas as pd
from matplotlib.axes import Axes
from matplotlib.figure import Figure
from matplotlib.ticker import NullFormatter

from analysis.table import variant_labels


def figure_png(fig: Figure, dpi: int = 100) -> bytes:
    """The figure as PNG bytes (Agg, cropped to its content)."""
    buf = io.BytesIO()
    fig.savefig(buf, format="png", dpi=dpi, bbox_inches="tight")
    return buf.getvalue()


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


def _empty(fig: Figure, ax: Axes, message: str) -> Figure:
    """The figure with only `message` in it, for data that is not there."""
    ax.text(0.5, 0.5, message, ha="center", va="center", transform=ax.transAxes)
    ax.set_axis_off()
    return fig


def accuracy_vs_time_figure(results: pd.DataFrame, x: str = "step_ms_median", y: str = "pos_rmse_rel",
                            x_higher_is_better: bool = False) -> Figure:
    """Accuracy versus time: one point per solver variant, log axes, the Pareto front as a step line.

    Each point is the median over the variant's rows (scenarios) of columns x and y. A y of exactly 0 (the
    reference compared with itself) cannot sit on a log axis: it is drawn at a floor a decade below the smallest
    positive y and labelled `= 0`.
    """
    fig = Figure(figsize=(7.0, 4.5))
    ax = fig.subplots()
    if not {"solver", x, y} <= set(results.columns):
        return _empty(fig, ax, f"no columns solver, {x} and {y} in the results")
    data = pd.DataFrame({"label": variant_labels(results), "x": pd.to_numeric(results[x], errors="coerce"),
                         "y": pd.to_numeric(results[y], errors="coerce")})
    points = data.groupby("label", sort=True)[["x", "y"]].median().dropna()
    points = points[(points["x"] > 0) & (points["y"] >= 0)]
    if points.empty:
        return _empty(fig, ax, f"no rows with both {x} and {y}")
    positive = points["y"][points["y"] > 0]
    floor = positive.min() / 10.0 if not positive.empty else 1e-6
    yy = points["y"].where(points["y"] > 0, floor).to_numpy()
    xx = points["x"].to_numpy()
    front = pareto_front(xx, points["y"].to_numpy(), x_higher_is_better)
    ax.plot(xx[front], yy[front], drawstyle="steps-post", color="tab:red", lw=1.2, zorder=1, label="Pareto front")
    ax.scatter(xx, yy, s=36, color="tab:blue", zorder=2)
    for xi, yi, name, exact in zip(xx, yy, points.index, points["y"].to_numpy() == 0):
        ax.annotate(f"{name} (= 0)" if exact else name, (xi, yi), textcoords="offset points", xytext=(5, 4),
                    fontsize=8)
    ax.set_xscale("log")
    ax.set_yscale("log")
    ax.xaxis.set_minor_formatter(NullFormatter())  # minor labels of a narrow log range overlap
    ax.set_xlabel(f"{x} ({'higher' if x_higher_is_better else 'lower'} is better)")
    ax.set_ylabel(f"{y} (median over scenarios)")
    ax.grid(True, which="both", alpha=0.3)
    ax.legend(loc="best", fontsize=8)
    return fig


def error_over_time_figure(curves: Mapping[str, tuple[np.ndarray, np.ndarray]], title: str) -> Figure:
    """Per-frame relative error e(t) (log y) of several solvers in one scenario; curves: label -> (t [s], e)."""
    fig = Figure(figsize=(7.0, 3.6))
    ax = fig.subplots()
    if not any(np.any(np.asarray(e) > 0) for _, e in curves.values()):
        return _empty(fig, ax, f"{title}: no positive error to plot")
    for name, (t, e) in curves.items():
        e = np.asarray(e, dtype=float)
        ax.plot(t, np.where(e > 0, e, np.nan), label=name, lw=1.4)
    ax.set_yscale("log")
    ax.set_xlabel("t [s]")
    ax.set_ylabel("RMS position error / L")
    ax.set_title(title, fontsize=10)
    ax.grid(True, which="both", alpha=0.3)
    ax.legend(loc="best", fontsize=8)
    return fig

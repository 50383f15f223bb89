"""The ground truth of a scenario and the cost of accuracy: the time-step ladder's stopping rule, its Richardson
error estimate, undecidable verdicts, and the accuracy-for-time frontier (`speedup_equal_accuracy`).

A ladder runs the full-space solver at dt, dt/2, dt/4, ... (levels k = 0, 1, ...; frames at the same times). Its
differences d_k = pos_rmse_rel(x_{k-1}, x_k) (fractions of L, over the shared frames) decide when it stops: at the
first level whose difference is at most `tol` (certified), or at `depth` (uncertified). The truth is the finest
run; its error is estimated by Richardson from the observed order (`richardson`). A tolerance ladder (`[truth]`
kind = "tolerance") runs adaptive steps at time.tol divided by TOLERANCE_FACTOR per level instead; its levels
refine like steps shrinking by `level_ratio` (the local error of an order-p formula is O(h^(p+1)), so its steps
shrink by TOLERANCE_FACTOR^(1/(p+1)) per level), which Richardson takes in place of 2.

A truth that does not certify over the whole run may still certify over its first part: `certified_horizon` is
the end of the longest first stretch of frames on which the two finest runs differ by at most `tol` frame by frame.

The frontier of a scenario is err_truth (against the truth) versus cost, wall_s_per_sim_s (stepping wall time per
simulated second), over its full-space runs: the ladder's, and every other run of the ladder's solver on the
ladder's mesh (the same-dt reference, its step and tolerance sweeps): the cheapest full-space run the results hold
at each accuracy. `speedup_equal_accuracy` of any run is that front's cost interpolated log-log at the run's
err_truth, divided by the run's own cost (`full_space_cost`).

Every function is pure: numbers and row dicts in, numbers and row dicts out.
"""

from __future__ import annotations

import math
from collections.abc import Mapping, Sequence
from dataclasses import dataclass

from frictionbench.analysis.schema import is_missing, number
from frictionbench.scenarios.suites import TOLERANCE_FACTOR
from frictionbench.solvers.integrators import Integrator

#: Lower clamp of the observed order: a ladder whose differences shrink more slowly than 2^-0.25 per halving (or
#: not at all) is far from its asymptotic range; its estimate is then d_K / (2^0.25 - 1) = 5.3 d_K.
MIN_ORDER = 0.25
#: The order assumed with two levels only (nothing to observe it from): first order, the rate that contact and
#: friction hold every integrator to, so the estimate is the last difference itself.
TWO_LEVEL_ORDER = 1.0
#: An accuracy verdict whose threshold is below this multiple of an uncertified truth's error estimate is
#: undecidable: the truth is not known well enough to tell the run's error from the truth's own.
UNDECIDABLE_FACTOR = 3.0
#: The frontier note of a run more accurate than every full-space run but the truth (no speedup number).
MORE_ACCURATE = "more accurate than every full-space run"
#: The frontier note of a run less accurate than every full-space run: its speedup is an upper bound.
AT_MOST = "at most: less accurate than every full-space run"


@dataclass(frozen=True)
class TruthEstimate:
    """How good a ladder's finest run is as the truth.

    level: index K of the finest run (dt / 2^K); certified: d_K <= tol; err_est: the Richardson estimate of the
    finest run's error [fraction of L] (None with a single run); order: the order p the estimate used;
    order_observed: log_r(d_{K-1} / d_K) before clamping, r the ladder's `level_ratio` (None with fewer than three
    levels).
    """

    level: int
    certified: bool
    err_est: float | None
    order: float | None
    order_observed: float | None


def ladder_continues(differences: Sequence[float], tol: float, depth: int) -> bool:
    """Whether the ladder needs another level: fewer than one difference yet, or its last difference above `tol`
    and fewer than `depth` halvings done. `differences` are d_1..d_K [fraction of L]."""
    if not differences:
        return depth >= 1
    return differences[-1] > tol and len(differences) < depth


def level_ratio(kind: str, integrator: Integrator) -> float:
    """How much a ladder's step shrinks per level [-]: 2 for a step ladder (`[truth]` kind "step"), and for a
    tolerance ladder TOLERANCE_FACTOR^(1/(p+1)) with p the integrator's order (2 for BDF2, 2.83 for backward
    Euler): the steps of an adaptive run scale as tol^(1/(p+1))."""
    return 2.0 if kind == "step" else TOLERANCE_FACTOR ** (1.0 / (integrator.order + 1))


def observed_order(d_coarse: float, d_fine: float, ratio: float = 2.0) -> float:
    """p = log_ratio(d_coarse / d_fine) from two successive differences of a ladder whose step shrinks by `ratio`
    per level (inf when d_fine is 0, -inf when only d_coarse is)."""
    if d_fine <= 0.0:
        return math.inf if d_coarse > 0.0 else 0.0
    if d_coarse <= 0.0:
        return -math.inf
    return math.log2(d_coarse / d_fine) / math.log2(ratio)


def richardson(differences: Sequence[float], integrator: Integrator,
               ratio: float = 2.0) -> tuple[float | None, float | None, float | None]:
    """(err_est, p, p_observed) of the finest run of a ladder with differences d_1..d_K [fraction of L] whose step
    shrinks by `ratio` per level (`level_ratio`: 2 for halved steps): err_est = d_K / (ratio^p - 1),
    p = log_ratio(d_{K-1} / d_K) clamped to [MIN_ORDER, the integrator's formal `order`] (a larger observed order is
    pre-asymptotic luck, a smaller one gives the conservative MIN_ORDER); with one difference (two levels)
    p = TWO_LEVEL_ORDER; with none, nothing is estimated."""
    if not differences:
        return None, None, None
    d = float(differences[-1])
    if len(differences) == 1:
        p, observed = min(TWO_LEVEL_ORDER, integrator.order), None
    else:
        observed = observed_order(float(differences[-2]), d, ratio)
        p = min(max(observed, MIN_ORDER), float(integrator.order))
    return d / (ratio ** p - 1.0), p, observed


def assess_ladder(differences: Sequence[float], tol: float, integrator: Integrator,
                  ratio: float = 2.0) -> TruthEstimate:
    """The truth of a finished ladder whose step shrinks by `ratio` per level: its finest level, whether its last
    difference met `tol`, and the Richardson estimate (`richardson`)."""
    est, p, observed = richardson(differences, integrator, ratio)
    certified = bool(differences) and differences[-1] <= tol
    return TruthEstimate(level=len(differences), certified=certified, err_est=est, order=p, order_observed=observed)


def certified_horizon(t: Sequence[float], frame_differences: Sequence[float], tol: float) -> float | None:
    """The end [s] of the longest first stretch of frames on which the ladder's two finest runs differ by at most
    `tol` frame by frame (per-frame RMS over the vertices / L, `analysis.metrics.error_over_time`): up to there the
    truth meets the ladder's tolerance even where the whole run does not (a trajectory that converges early and
    drifts late). t (F,) [s] increasing; None without frames or when the first frame already differs."""
    ok = [float(e) <= tol for e in frame_differences]
    if not ok or not ok[0]:
        return None
    n = ok.index(False) if False in ok else len(ok)
    return float(t[n - 1])


def decidable(limit: float, certified: bool, err_est: float | None, factor: float = UNDECIDABLE_FACTOR) -> bool:
    """Whether an accuracy verdict `error <= limit` can be judged against a truth: always for a certified truth,
    else only when limit >= factor x its error estimate (never when the estimate is unknown)."""
    if certified:
        return True
    if err_est is None or not math.isfinite(err_est):
        return False
    return limit >= factor * err_est


def wall_s_per_sim_s(step_wall_s: Sequence[float], dt: float | Sequence[float]) -> float | None:
    """Stepping wall time per simulated second [s/s]: sum of the steps' wall times [s] (an adaptive step's includes
    its rejected attempts) / the simulated time, steps x dt [s] at a fixed step dt, or the sum of the steps' sizes dt
    (a sequence, one per step: an adaptive run's); the warm-up step is not among them (`solvers.run`). None without
    steps."""
    simulated = float(sum(dt)) if isinstance(dt, Sequence) else len(step_wall_s) * dt
    if not step_wall_s or simulated <= 0.0:
        return None
    return float(sum(step_wall_s)) / simulated


def pareto_front(points: Sequence[tuple[float, float]]) -> list[tuple[float, float]]:
    """The (err, cost) points no other point beats on both: cost increasing, err strictly decreasing. Points
    with a non-positive or non-finite err or cost are left out (a truth's own err is 0)."""
    ok = sorted((float(e), float(c)) for e, c in points
                if math.isfinite(e) and math.isfinite(c) and e > 0.0 and c > 0.0)
    front: list[tuple[float, float]] = []
    for e, c in sorted(ok, key=lambda p: (p[1], p[0])):
        if not front or e < front[-1][0]:
            front.append((e, c))
    return front


def full_space_cost(front: Sequence[tuple[float, float]], err: float) -> tuple[float | None, str]:
    """(cost, note): the full-space cost at accuracy `err` on a Pareto front of (err, cost) ladder points
    (`pareto_front`), interpolated linearly in (log err, log cost).

    A run less accurate than the coarsest point gets that point's cost with the note `AT_MOST`: the full-space
    solver reaches its accuracy for that cost or less, so a speedup from it is an upper bound (extrapolating the
    first segment instead would invent the cost of runs nobody made). A run more accurate than the most accurate
    point gets no cost and the note `MORE_ACCURATE`; no cost either with an empty front.
    """
    if not front:
        return None, "no ladder"
    if err < front[-1][0]:
        return None, MORE_ACCURATE
    if err > front[0][0]:
        return front[0][1], AT_MOST
    if len(front) == 1:
        return front[0][1], ""
    i = next(i for i in range(len(front) - 1) if front[i + 1][0] <= err)
    (e0, c0), (e1, c1) = front[i], front[i + 1]
    slope = math.log(c1 / c0) / math.log(e1 / e0)
    return c0 * math.exp(slope * math.log(err / e0)), ""


def speedup_equal_accuracy(front: Sequence[tuple[float, float]], err: float, cost: float) -> tuple[float | None, str]:
    """(speedup, note): `full_space_cost(front, err)` / `cost` [-] (None with the note where there is no cost; an
    upper bound where the note is `AT_MOST`)."""
    full, note = full_space_cost(front, err)
    return (None if full is None or cost <= 0.0 else full / cost), note


def with_frontier(rows: Sequence[Mapping[str, object]]) -> list[dict]:
    """Rows with `speedup_equal_accuracy` and `frontier_note` on every row that has err_truth and
    wall_s_per_sim_s: against the Pareto front of its scenario's full-space runs (`full_space_runs`: the cheapest
    full-space run at each accuracy), `speedup_equal_accuracy` (the truth's own run, err_truth 0, gets the note
    `the truth`); and `timed_beside_ladder`: whether the row's run was timed in the session that timed every
    ladder run of its scenario (`timed_in`; None where a run does not say, as in stores written before sessions
    were recorded). Rows of scenarios without ladder rows, and rows without the two figures, are returned
    unchanged."""
    fronts: dict[object, list[tuple[float, float]]] = {}
    sessions: dict[object, set] = {}
    full = full_space_runs(rows)
    for r, is_full in zip(rows, full):
        if is_full:
            e, c = number(r.get("err_truth"), finite=True), number(r.get("wall_s_per_sim_s"), finite=True)
            if e is not None and c is not None:
                fronts.setdefault(r["scenario"], []).append((e, c))
        if r.get("ladder") and r.get("status") == "ok":
            sessions.setdefault(r["scenario"], set()).add(_session(r))
    fronts = {k: pareto_front(v) for k, v in fronts.items() if k in sessions}
    out = []
    for r in rows:
        e, c = number(r.get("err_truth"), finite=True), number(r.get("wall_s_per_sim_s"), finite=True)
        if r.get("scenario") in fronts and e is not None and c is not None and r.get("status") == "ok":
            speedup, note = speedup_equal_accuracy(fronts[r["scenario"]], e, c) if e > 0.0 else (None, "the truth")
            ladder, own = sessions[r["scenario"]], _session(r)
            beside = None if own is None or None in ladder else ladder == {own}
            r = dict(r) | {"speedup_equal_accuracy": speedup, "frontier_note": note, "timed_beside_ladder": beside}
        out.append(dict(r))
    return out


def full_space_runs(rows: Sequence[Mapping[str, object]]) -> list[bool]:
    """Per row, whether it is one of its scenario's full-space runs: a run (status ok) of the solver of the
    scenario's ladder rows on their mesh (rows without `solver` or `mesh` columns: the ladder rows alone). A run
    carried from another mesh, or of another solver, is not: the front is what the full-space solver costs on the
    scene as given."""
    ladder = {(r.get("scenario"), r.get("solver"), r.get("mesh")) for r in rows
              if r.get("ladder") and r.get("status") == "ok"}
    return [r.get("status") == "ok" and (bool(r.get("ladder")) or (
                r.get("solver") is not None and (r.get("scenario"), r.get("solver"), r.get("mesh")) in ladder))
            for r in rows]


def _session(row: Mapping[str, object]) -> str | None:
    """The session that timed a row's run (`timed_in`), None where the row does not say."""
    value = row.get("timed_in")
    return None if is_missing(value) else str(value)

"""Per-step statistics every solver returns, the merge of a retried step's attempts, and their summary."""

from __future__ import annotations

from collections.abc import Sequence
from dataclasses import asdict, dataclass, field

import numpy as np


@dataclass(kw_only=True)
class StepStats:
    """Per-step statistics of any solver (keyword arguments; only `wall_s` is required).

    wall_s: the step's wall time [s]; iterations: iterations of its solve (Newton iterations, a fixed count, 1 for a
    direct update); converged: whether the solve met its criterion (True for a solver without one); residual: its
    final convergence measure (a Newton solver's |dx|_inf / h [m/s], the reduced solver's an upper bound of it
    where that settled convergence; 0 for a solver without one); counters: the
    solver's own counts (name -> count, summed over a retried step's attempts and over the run; the Newton solvers'
    are `line_search_halvings`, `stalls` and `linear_iters`: `solvers.newton_method.NewtonResult.step_stats`); retries:
    times the step was redone as two half steps after a failure (set by `solvers.simulate`, never by the solver; an
    adaptive run's: attempts redone smaller after a failed solve or a non-finite state).

    Set by an adaptive run's loop (`solvers.simulate`; None or 0 in a fixed-step run): dt, the accepted step's size
    [s]; rejected, the attempts of this step discarded before it (its error over the tolerance, or a retry, their
    iterations, counters and wall time included above); error, the accepted step's estimated local error [fraction
    of L] (`solvers.simulate.error_norm`).
    """

    wall_s: float
    iterations: int = 1
    converged: bool = True
    residual: float = 0.0
    counters: dict[str, int] = field(default_factory=dict)
    retries: int = 0
    dt: float | None = None
    rejected: int = 0
    error: float | None = None

    def merged(self, *later: "StepStats") -> "StepStats":
        """One record for a step redone as sub-steps: this failed attempt plus the sub-steps' records `later`.

        Iterations, counters and wall time are summed, `converged` and `residual` are the last sub-step's,
        `retries` is one (this halving) plus the sub-steps' own.
        """
        return combined((self, *later), retries=1 + sum(s.retries for s in later))


def combined(attempts: Sequence[StepStats], **fields) -> StepStats:
    """One record for a step made of several attempts: iterations, counters and wall time summed over them,
    `converged` and `residual` the last one's, the other fields from `fields` (keywords of `StepStats`)."""
    return StepStats(wall_s=sum(s.wall_s for s in attempts), iterations=sum(s.iterations for s in attempts),
                     converged=attempts[-1].converged, residual=attempts[-1].residual,
                     counters=counter_totals(attempts), **fields)


def counter_totals(stats: Sequence[StepStats]) -> dict[str, int]:
    """Each counter summed over the records (a counter a record lacks counts 0 there), in order of appearance."""
    totals: dict[str, int] = {}
    for s in stats:
        for name, count in s.counters.items():
            totals[name] = totals.get(name, 0) + count
    return totals


def stats_summary(stats: list[StepStats], tol: float | None = None) -> dict:
    """Aggregate per-step statistics: totals, medians, each counter's total (`counters`) and the per-step records.
    The iteration columns keep their Newton names (`newton_iters_mean`, `newton_iters_max`) for every solver;
    `line_search_stalls` is the total of the counter `stalls`, absent for a solver that does not report it. An
    adaptive run's records (each with its `dt`) add `rejected_steps` (attempts discarded), `dt_min_used` and
    `dt_median` [s] (its smallest and median accepted step) and, given its `tol`, `steps_over_tol` (steps accepted
    at the smallest step with their error above tol)."""
    wall = np.array([s.wall_s for s in stats]) if stats else np.zeros(1)
    iters = np.array([s.iterations for s in stats]) if stats else np.zeros(1)
    totals = counter_totals(stats)
    return {
        "steps": len(stats),
        "newton_iters_mean": float(iters.mean()),
        "newton_iters_max": int(iters.max()),
        "not_converged": int(sum(not s.converged for s in stats)),
        **({"line_search_stalls": int(totals["stalls"])} if "stalls" in totals else {}),
        "step_retries": int(sum(s.retries for s in stats)),
        "step_ms_median": float(np.median(wall) * 1e3),
        "step_ms_p95": float(np.percentile(wall, 95) * 1e3),
        "counters": totals,
        "per_step": [asdict(s) for s in stats],
    } | (adaptive_summary(stats, tol) if stats and all(s.dt is not None for s in stats) else {})


def adaptive_summary(stats: Sequence[StepStats], tol: float | None = None) -> dict:
    """The figures of an adaptive run's records (each with its `dt`): see `stats_summary`."""
    dts = np.array([s.dt for s in stats])
    return ({"rejected_steps": int(sum(s.rejected for s in stats)), "dt_min_used": float(dts.min()),
             "dt_median": float(np.median(dts))}
            | ({} if tol is None else
               {"steps_over_tol": int(sum(s.error is not None and s.error > tol for s in stats))}))

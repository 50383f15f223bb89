"""Per-step statistics every solver returns, the merge of a retried step's attempts, and their summary."""

from __future__ import annotations

from dataclasses import asdict, dataclass, field

import numpy as np


@dataclass(kw_only=True)
class StepStats:
    """Per-step statistics of any solver (keyword arguments; only `wall_s` is required).

    wall_s: the step's wall time [s]; iterations: iterations of its solve (Newton iterations, a fixed count, 1 for a
    direct update); converged: whether the solve met its criterion (True for a solver without one); residual: its
    final convergence measure (a Newton solver's |dx|_inf / h [m/s]; 0 for a solver without one); counters: the
    solver's own counts (name -> count, summed over a retried step's attempts and over the run; the Newton solvers'
    are `line_search_halvings`, `stalls` and `linear_iters`: `solvers.newton.NewtonResult.step_stats`); retries:
    times the step was redone as two half steps after a failure (set by `solvers.simulate`, never by the solver).
    """

    wall_s: float
    iterations: int = 1
    converged: bool = True
    residual: float = 0.0
    counters: dict[str, int] = field(default_factory=dict)
    retries: int = 0

    def merged(self, *later: "StepStats") -> "StepStats":
        """One record for a step redone as sub-steps: this failed attempt plus the sub-steps' records `later`.

        Iterations, counters and wall time are summed, `converged` and `residual` are the last sub-step's,
        `retries` is one (this halving) plus the sub-steps' own.
        """
        every = (self, *later)
        return StepStats(wall_s=sum(s.wall_s for s in every), iterations=sum(s.iterations for s in every),
                         converged=later[-1].converged, residual=later[-1].residual, counters=counter_totals(every),
                         retries=1 + sum(s.retries for s in later))


def counter_totals(stats: tuple[StepStats, ...] | list[StepStats]) -> dict[str, int]:
    """Each counter summed over the records (a counter a record lacks counts 0 there), in order of appearance."""
    totals: dict[str, int] = {}
    for s in stats:
        for name, count in s.counters.items():
            totals[name] = totals.get(name, 0) + count
    return totals


def stats_summary(stats: list[StepStats]) -> dict:
    """Aggregate per-step statistics: totals, medians, each counter's total (`counters`) and the per-step records.
    The iteration columns keep their Newton names (`newton_iters_mean`, `newton_iters_max`) for every solver;
    `line_search_stalls` is the total of the counter `stalls`, absent for a solver that does not report it."""
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
    }

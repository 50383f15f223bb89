"""Per-step statistics every solver returns, the merge of a retried step's attempts, and their summary."""

from __future__ import annotations

from dataclasses import asdict, dataclass

import numpy as np


@dataclass
class StepStats:
    """Per-step statistics: Newton iterations, final |dx|_inf/h [m/s], line-search halvings, wall time [s].

    stalls: Newton iterations whose line search found no decrease down to alpha = 2^-max_halvings;
    retries: times the step was redone as two half steps after a failure (see `solvers.simulate`).
    """

    newton_iters: int
    residual: float
    line_search_halvings: int
    converged: bool
    wall_s: float
    linear_iters: int = 0
    stalls: int = 0
    retries: int = 0

    def merged(self, *later: "StepStats") -> "StepStats":
        """One record for a step redone as sub-steps: this failed attempt plus the sub-steps' records `later`.

        Counts and wall time are summed, `converged` and `residual` are the last sub-step's, `retries` is one
        (this halving) plus the sub-steps' own.
        """
        every = (self, *later)
        return StepStats(
            newton_iters=sum(s.newton_iters for s in every), residual=later[-1].residual,
            line_search_halvings=sum(s.line_search_halvings for s in every), converged=later[-1].converged,
            wall_s=sum(s.wall_s for s in every), linear_iters=sum(s.linear_iters for s in every),
            stalls=sum(s.stalls for s in every), retries=1 + sum(s.retries for s in later))


def stats_summary(stats: list[StepStats]) -> dict:
    """Aggregate per-step statistics: totals, medians and the per-step records."""
    wall = np.array([s.wall_s for s in stats]) if stats else np.zeros(1)
    iters = np.array([s.newton_iters for s in stats]) if stats else np.zeros(1)
    return {
        "steps": len(stats),
        "newton_iters_mean": float(iters.mean()),
        "newton_iters_max": int(iters.max()),
        "not_converged": int(sum(not s.converged for s in stats)),
        "line_search_stalls": int(sum(s.stalls for s in stats)),
        "step_retries": int(sum(s.retries for s in stats)),
        "step_ms_median": float(np.median(wall) * 1e3),
        "step_ms_p95": float(np.percentile(wall, 95) * 1e3),
        "per_step": [asdict(s) for s in stats],
    }

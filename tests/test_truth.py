"""The ground truth's arithmetic on synthetic sequences of known order: the ladder's stopping rule, the Richardson
estimate, undecidable verdicts, and the frontier's speedup at equal accuracy."""

from __future__ import annotations

import math

import pytest

from frictionbench.analysis.truth import (AT_MOST, MIN_ORDER, MORE_ACCURATE, assess_ladder, certified_horizon,
                                          decidable, full_space_cost, ladder_continues, pareto_front, richardson,
                                          speedup_equal_accuracy, wall_s_per_sim_s, with_frontier)
from frictionbench.solvers.integrators import BDF2, BackwardEuler


def climb(C: float, p: float, dt: float, tol: float, depth: int) -> tuple[list[float], list[float]]:
    """Run the ladder on the scalar model x(h) = 1 + C h^p: (errors of every level against x = 1, differences)."""
    x = [1.0 + C * dt ** p]
    diffs: list[float] = []
    while ladder_continues(diffs, tol, depth):
        x.append(1.0 + C * (dt / 2 ** len(x)) ** p)
        diffs.append(abs(x[-2] - x[-1]))
    return [abs(v - 1.0) for v in x], diffs


@pytest.mark.parametrize("p, integrator", [(1.0, BackwardEuler()), (2.0, BDF2()), (1.5, BDF2())])
def test_the_ladder_stops_at_the_first_level_within_tol_and_estimates_its_error(p, integrator):
    C, dt, tol = 3.0, 0.01, 1e-4
    errors, diffs = climb(C, p, dt, tol, depth=12)
    # d_k = C dt^p 2^(-k p) (2^p - 1) <= tol first at k = ceil(log2(C dt^p (2^p - 1) / tol) / p)
    expected = math.ceil(math.log2(C * dt ** p * (2 ** p - 1) / tol) / p)
    assert len(diffs) == expected and diffs[-1] <= tol < diffs[-2]
    truth = assess_ladder(diffs, tol, integrator)
    assert truth.certified and truth.level == expected
    assert truth.order_observed == pytest.approx(p, rel=1e-9)
    assert truth.err_est == pytest.approx(errors[-1], rel=1e-6)  # Richardson is exact on a pure power law


def test_a_ladder_that_runs_out_of_depth_is_uncertified_but_still_estimated():
    errors, diffs = climb(C=1.0, p=1.0, dt=0.01, tol=1e-6, depth=3)
    assert len(diffs) == 3
    truth = assess_ladder(diffs, 1e-6, BDF2())
    assert not truth.certified and truth.err_est == pytest.approx(errors[-1], rel=1e-6)


def test_the_observed_order_is_clamped_to_the_formal_order_and_to_the_minimum():
    # second order observed under backward Euler: clamped to 1, so the estimate is larger (conservative)
    est, p, observed = richardson([4e-3, 1e-3], BackwardEuler())
    assert observed == pytest.approx(2.0) and p == 1.0 and est == pytest.approx(1e-3)
    # differences that grow: no convergence observed, the minimum order applies
    est, p, observed = richardson([1e-3, 2e-3], BDF2())
    assert observed < 0 and p == MIN_ORDER and est == pytest.approx(2e-3 / (2 ** MIN_ORDER - 1))
    # two levels: first order assumed, the estimate is the difference itself
    est, p, observed = richardson([5e-3], BDF2())
    assert observed is None and p == 1.0 and est == pytest.approx(5e-3)
    assert richardson([], BDF2()) == (None, None, None)
    # second order observed under BDF2: its formal order, read from the integrator, is no clamp
    assert richardson([4e-3, 1e-3], BDF2())[1] == pytest.approx(2.0)


def test_a_verdict_below_three_times_an_uncertified_estimate_is_undecidable():
    assert decidable(0.001, certified=True, err_est=0.01)  # certified: always decidable
    assert not decidable(0.02, certified=False, err_est=0.01)  # 0.02 < 3 x 0.01
    assert decidable(0.03, certified=False, err_est=0.01)
    assert not decidable(1.0, certified=False, err_est=None)


def test_wall_time_per_simulated_second():
    assert wall_s_per_sim_s([0.1, 0.2, 0.3], dt=0.01) == pytest.approx(0.6 / 0.03)
    assert wall_s_per_sim_s([], dt=0.01) is None


# a ladder with error = 0.1 (cost / 10)^-1: each halving doubles the cost and halves the error
LADDER = [(0.1, 10.0), (0.05, 20.0), (0.025, 40.0), (0.0125, 80.0)]


def test_speedup_at_equal_accuracy_interpolates_the_ladder_log_log():
    front = pareto_front(LADDER + [(0.0, 160.0), (0.2, 45.0)])  # the truth (err 0) and a dominated point drop out
    assert front == LADDER
    cost, note = full_space_cost(front, 0.035355339)  # between 0.05 and 0.025, log-midpoint: cost 20 sqrt(2)
    assert cost == pytest.approx(20 * math.sqrt(2), rel=1e-6) and note == ""
    speedup, _ = speedup_equal_accuracy(front, 0.025, 4.0)  # as accurate as the 40 s/s run at a tenth of its cost
    assert speedup == pytest.approx(10.0)
    cost, note = full_space_cost(front, 0.2)  # less accurate than the coarsest: at most the coarsest run's cost
    assert cost == pytest.approx(10.0) and note == AT_MOST
    speedup, note = speedup_equal_accuracy(front, 0.4, 2.0)  # an upper bound, never an extrapolation (2.5 here)
    assert speedup == pytest.approx(5.0) and note == AT_MOST
    assert full_space_cost(front[:1], 0.1) == (10.0, "") and full_space_cost(front[:1], 0.3) == (10.0, AT_MOST)
    speedup, note = speedup_equal_accuracy(front, 0.001, 1.0)
    assert speedup is None and note == MORE_ACCURATE


def test_with_frontier_gives_every_row_of_a_scenario_its_speedup_against_its_own_ladder():
    rows = [{"scenario": "a", "status": "ok", "ladder": "bdf2", "err_truth": e, "wall_s_per_sim_s": c}
            for e, c in LADDER]
    rows += [{"scenario": "a", "status": "ok", "ladder": "", "err_truth": 0.05, "wall_s_per_sim_s": 2.0},
             {"scenario": "a", "status": "ok", "ladder": "", "err_truth": 1e-4, "wall_s_per_sim_s": 2.0},
             {"scenario": "a", "status": "failed", "ladder": ""},
             {"scenario": "a", "status": "ok", "ladder": "bdf2", "err_truth": 0.0, "wall_s_per_sim_s": 160.0},
             {"scenario": "b", "status": "ok", "ladder": "", "err_truth": 0.05, "wall_s_per_sim_s": 2.0}]
    out = with_frontier(rows)
    assert [r["speedup_equal_accuracy"] for r in out[:4]] == pytest.approx([1.0] * 4)  # the ladder lies on itself
    assert out[4]["speedup_equal_accuracy"] == pytest.approx(10.0)
    assert out[5]["speedup_equal_accuracy"] is None and out[5]["frontier_note"] == MORE_ACCURATE
    assert out[7]["speedup_equal_accuracy"] is None and out[7]["frontier_note"] == "the truth"
    assert "speedup_equal_accuracy" not in out[6] and "speedup_equal_accuracy" not in out[8]  # failed; no ladder


def test_the_front_pools_every_full_space_run_of_the_ladders_solver_on_its_mesh():
    """A same-dt reference less accurate than the ladder's coarsest run widens the front: a reduced run between
    the two gets a measured speedup; a run of the solver carried from another mesh, or of another solver, does
    not join the front."""
    ladder = [{"scenario": "a", "status": "ok", "solver": "full", "mesh": "m", "ladder": "bdf2", "err_truth": e,
               "wall_s_per_sim_s": c} for e, c in LADDER]
    coarsest = max(e for e, _ in LADDER)
    reduced = {"scenario": "a", "status": "ok", "solver": "licrom", "mesh": "m", "ladder": "",
               "err_truth": 2 * coarsest, "wall_s_per_sim_s": 0.5}
    reference = {"scenario": "a", "status": "ok", "solver": "full", "mesh": "m", "ladder": "",
                 "err_truth": 4 * coarsest, "wall_s_per_sim_s": 1.0}
    alone = with_frontier(ladder + [reduced])[-1]
    assert alone["frontier_note"] == AT_MOST
    pooled = with_frontier(ladder + [reduced, reference])
    assert pooled[-2]["frontier_note"] == "" and pooled[-2]["speedup_equal_accuracy"] > 1.0 / 0.5
    assert pooled[-2]["speedup_equal_accuracy"] < alone["speedup_equal_accuracy"]
    for outsider in ({**reference, "mesh": "other"}, {**reference, "solver": "vbd"}):
        assert with_frontier(ladder + [reduced, outsider])[-2]["frontier_note"] == AT_MOST


def test_the_certified_horizon_ends_before_the_first_frame_out_of_tolerance():
    t = [0.0, 0.1, 0.2, 0.3, 0.4]
    assert certified_horizon(t, [0.0, 0.001, 0.004, 0.006, 0.002], 0.005) == 0.2  # a later return does not count
    assert certified_horizon(t, [0.0] * 5, 0.005) == 0.4
    assert certified_horizon(t, [0.01] * 5, 0.005) is None and certified_horizon([], [], 0.005) is None

"""The shared Newton loop (solvers.newton_method) on small problems with known answers."""

from __future__ import annotations

import numpy as np
import pytest

from frictionbench.solvers.newton_method import Direction, feasible_step, minimise


class Quartic:
    """E(y) = sum (y - c)^4 / 4 + |y - c|^2 / 2 with exact Newton directions; minimum at c."""

    def __init__(self, c: np.ndarray, finite: bool = True) -> None:
        self.c, self.finite, self.energies = c, finite, 0

    def energy(self, y: np.ndarray) -> float:
        self.energies += 1
        d = y - self.c
        return float(np.sum(d**4) / 4 + d @ d / 2)

    def direction(self, y: np.ndarray) -> Direction:
        d = y - self.c
        g, h = d**3 + d, 3 * d**2 + 1
        dy = -g / h if self.finite else np.full_like(y, np.nan)
        return Direction(dy, float(g @ dy), linear_iters=2)

    def step_norm(self, dy: np.ndarray) -> float:
        return float(np.abs(dy).max())

    def max_step(self, y: np.ndarray, dy: np.ndarray) -> float:
        return 1.0


def test_newton_converges_to_the_minimum_and_counts_linear_iterations():
    c = np.array([1.0, -2.0, 0.5])
    res = minimise(Quartic(c), np.zeros(3), tol_v=1e-12, max_iter=50)
    assert res.converged and res.stalls == 0
    np.testing.assert_allclose(res.y, c, rtol=0, atol=1e-12)
    assert res.linear_iters == 2 * res.iters
    assert 2 < res.iters < 20  # quadratic convergence from distance 2


def test_a_non_finite_direction_is_a_stall_that_keeps_the_iterate():
    y0 = np.array([3.0, 1.0])
    res = minimise(Quartic(np.zeros(2), finite=False), y0, tol_v=1e-12, max_iter=50)
    assert not res.converged
    assert res.stalls == 1 and res.iters == 1 and res.halvings == 41
    np.testing.assert_array_equal(res.y, y0)


def test_max_iter_ends_unconverged():
    res = minimise(Quartic(np.array([100.0])), np.zeros(1), tol_v=1e-12, max_iter=2)
    assert not res.converged and res.iters == 2 and res.stalls == 0


@pytest.mark.parametrize("phi, rate, expected", [
    ([1.0, 2.0], [0.5, 1.0], 1.0),            # receding points: no cap
    ([1.0, 2.0], [-0.5, -1.0], 1.0),          # approaching, but 90% of the gap is beyond alpha = 1
    ([1.0, 0.1], [-0.5, -1.0], 0.09),         # the second point may cover 90% of its 0.1 m gap
])
def test_feasible_step_stops_at_ninety_percent_of_the_gap(phi, rate, expected):
    assert feasible_step(np.array(phi), np.array(rate)) == pytest.approx(expected, rel=1e-15)

"""The one Newton loop of every implicit solver: Armijo line search, the barrier's feasible-step cap, and the
convergence test in velocity units.

A backend (full-space warp kernels, the reduced subspace, the static solver) describes its problem through a
`NewtonProblem`: the energy at a point, the Newton direction with its directional derivative, the step norm in
velocity units and the largest feasible step. `minimise` runs the loop on it; the unknown y is any numpy array
(vertex positions (n, 3) [m], latent coordinates (r,)).
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import Protocol

import numpy as np

from frictionbench.solvers.step_stats import StepStats

#: Round-off allowance of the Armijo test, relative to |E|: a trial point may exceed the sufficient-decrease line by
#: this much. Larger (1e-12 was tried) lets Newton cycle between the kinks of the penalty and friction laws (their
#: second derivatives jump) with the energy flat to 1e-12 but the iterate never settling; 1e-14 is a few ulps of the
#: summed energy.
ARMIJO_SLACK = 1e-14

#: Fraction of the distance to the plane a contact point may cover in one step of the barrier law (the barrier is
#: infinite on the plane: a step must stop short of it).
FEASIBLE_FRACTION = 0.9


@dataclass(frozen=True)
class LineSearch:
    """Armijo backtracking: sufficient-decrease factor `armijo` [-], at most `max_halvings` halvings of alpha."""

    armijo: float = 1e-4
    max_halvings: int = 40


@dataclass(frozen=True)
class Direction:
    """A Newton direction dy (shape of y), the directional derivative g . dy [J] and the linear iterations spent."""

    dy: np.ndarray
    g_dot: float
    linear_iters: int = 0


@dataclass(frozen=True)
class NewtonResult:
    """The end point y, iterations, last step norm residual [m/s], line-search halvings, linear iterations,
    stalls (iterations whose line search found no decrease) and whether the step norm fell below tolerance."""

    y: np.ndarray
    iters: int
    residual: float
    halvings: int
    linear_iters: int
    stalls: int
    converged: bool

    def then(self, later: "NewtonResult") -> "NewtonResult":
        """One result for two solves of a step, this one then `later` (from this one's end): `later`'s point,
        residual and convergence, the iterations, halvings, linear iterations and stalls of both."""
        return NewtonResult(later.y, self.iters + later.iters, later.residual, self.halvings + later.halvings,
                            self.linear_iters + later.linear_iters, self.stalls + later.stalls, later.converged)

    def step_stats(self, wall_s: float, **counters: int) -> StepStats:
        """The step's record (wall time `wall_s` [s]) with the counters `line_search_halvings`, `stalls` and
        `linear_iters`, and any further `counters`."""
        return StepStats(wall_s=wall_s, iterations=self.iters, converged=self.converged, residual=self.residual,
                         counters={"line_search_halvings": self.halvings, "stalls": self.stalls,
                                   "linear_iters": self.linear_iters} | counters)


class NewtonProblem(Protocol):
    """What `minimise` needs of a backend."""

    def energy(self, y: np.ndarray) -> float:
        """E(y) [J]."""
        ...

    def direction(self, y: np.ndarray) -> Direction:
        """The Newton direction at y (from the PSD-projected Hessian)."""
        ...

    def step_norm(self, dy: np.ndarray) -> float:
        """The size of a step dy in velocity units [m/s] (|dx|_inf / h over the mesh vertices)."""
        ...

    def max_step(self, y: np.ndarray, dy: np.ndarray) -> float:
        """Largest alpha <= 1 for which y + alpha dy is admissible (1 without a barrier)."""
        ...

    def chord_direction(self, y: np.ndarray) -> Direction | None:
        """The chord direction -H^-1 g(y) with the Hessian H of the last `direction` (its factorisation reused, the
        gradient g at y; None where no factorisation is held): the convergence test of `minimise(chord=...)`."""
        ...


def feasible_step(phi: np.ndarray, rate: np.ndarray) -> float:
    """Largest alpha <= 1 keeping every contact point strictly above the plane: phi (p,) signed distances [m],
    rate (p,) their change along the step [m]; approaching points cover at most FEASIBLE_FRACTION of phi."""
    approaching = rate < 0
    if not approaching.any():
        return 1.0
    return float(min(1.0, FEASIBLE_FRACTION * np.min(phi[approaching] / -rate[approaching])))


def minimise(problem: NewtonProblem, y: np.ndarray, tol_v: float, max_iter: int,
             search: LineSearch = LineSearch(), chord: int | None = None, contraction: float = 0.0,
             residual: float = np.inf) -> NewtonResult:
    """Newton's method from y: stop when the step norm is below tol_v [m/s] (taking that last step, capped), or
    when a line search finds no decrease down to alpha = 2^-max_halvings (a stall: y is kept, not converged), or
    after max_iter iterations (not converged).

    `chord` (None: off): from iteration `chord` on, each iteration first tests convergence with the chord direction
    (`NewtonProblem.chord_direction`: the last factorisation reused, a gradient and a back-substitution); where that
    step is below tol_v it is the last step, else the iteration takes the Newton direction as without it. The
    iteration that ends a converged solve then costs no Hessian and no factorisation; the end point differs from
    Newton's by the difference of two steps each below tol_v.

    `contraction` (with `chord`; 0: off) makes the chord iteration modified Newton's: a chord step of norm below
    `contraction` times the last step's (`residual` [m/s] at the start: the norm of the last step before this
    call, a previous solve's of the same step) whose full step, capped, passes the Armijo test is taken as the
    iteration, without a Hessian or a factorisation; the factorisation is renewed (a Newton direction) where a
    chord step contracts less or fails the test. The convergence test, and so the tolerance the end point meets,
    is the same."""
    E = problem.energy(y)
    halvings = lin_iters = stalls = 0
    it = 0
    for it in range(1, max_iter + 1):
        if chord is not None and it >= chord and (c := problem.chord_direction(y)) is not None:
            lin_iters += c.linear_iters
            step = problem.step_norm(c.dy)
            if step < tol_v:
                y = y + problem.max_step(y, c.dy) * c.dy
                return NewtonResult(y, it, step, halvings, lin_iters, stalls, True)
            if step < contraction * residual:
                alpha = problem.max_step(y, c.dy)
                E_new = problem.energy(y + alpha * c.dy)
                if _sufficient(E_new, E, alpha, c.g_dot, search):
                    y, E, residual = y + alpha * c.dy, E_new, step
                    continue
        d = problem.direction(y)
        lin_iters += d.linear_iters
        residual = problem.step_norm(d.dy)
        if residual < tol_v:
            y = y + problem.max_step(y, d.dy) * d.dy
            return NewtonResult(y, it, residual, halvings, lin_iters, stalls, True)
        alpha = problem.max_step(y, d.dy)
        while True:
            E_new = problem.energy(y + alpha * d.dy)
            if _sufficient(E_new, E, alpha, d.g_dot, search):
                break
            alpha *= 0.5
            halvings += 1
            if alpha < 2.0 ** -search.max_halvings:
                break
        if not (np.isfinite(E_new) and alpha >= 2.0 ** -search.max_halvings):
            stalls += 1  # no decrease along dy (e.g. a non-finite direction): keep y, report not converged
            break
        y = y + alpha * d.dy
        E = E_new
    return NewtonResult(y, it, residual, halvings, lin_iters, stalls, False)


def _sufficient(E_new: float, E: float, alpha: float, g_dot: float, search: LineSearch) -> bool:
    """The Armijo test of a trial step alpha along a direction with directional derivative g_dot [J]: E_new [J]
    finite and at most E + armijo alpha g_dot (with the round-off allowance ARMIJO_SLACK |E|)."""
    return bool(np.isfinite(E_new) and E_new <= E + search.armijo * alpha * g_dot + ARMIJO_SLACK * abs(E))

"""Static equilibrium with clamped vertices (verification: cantilever under self-weight).

Minimises sum_e V_e Psi(F_e) - sum_i m_i g . x_i over the free vertices by the shared Newton loop
(`solvers.newton_method`) with the full-space solver's kernels (projected Hessian, direct solve on the free degrees of
freedom, Armijo backtracking).
"""

from __future__ import annotations

import numpy as np

from frictionbench.solvers.full.solver import FullSpaceSolver, _StepProblem
from frictionbench.solvers.linalg import sparse_spd_solve
from frictionbench.solvers.newton_method import Direction, minimise


class _StaticProblem(_StepProblem):
    """The potential without inertia (h = 1, so the step norm is |dx|_inf [m]), Newton directions on the free
    degrees of freedom only: `free` (3n,) bool."""

    def __init__(self, solver: FullSpaceSolver, free: np.ndarray) -> None:
        super().__init__(solver, 1.0, inertia=False)
        self.free = free

    def direction(self, x: np.ndarray) -> Direction:
        """Newton direction with the fixed vertices held (their rows and columns removed)."""
        sv, free = self.solver, self.free
        sv.x.assign(x)
        sv.gradient_hessian(sv.x, 1.0, inertia=False)
        H = sv.pattern.to_scipy(sv.values.numpy())[free][:, free]
        g = sv.grad.numpy().ravel()[free]
        dx = np.zeros(free.size)
        dx[free] = sparse_spd_solve(H.tocsc(), -g)
        return Direction(dx.reshape(-1, 3), float(g @ dx[free]))


def static_equilibrium(solver: FullSpaceSolver, fixed: np.ndarray, tol: float = 1e-10,
                       max_iter: int = 50) -> tuple[np.ndarray, int]:
    """Equilibrium positions (n, 3) [m] starting from the rest mesh, vertices where `fixed` (n,) bool is True
    held at rest; stops when |dx|_inf < tol * L. Returns (x, Newton iterations)."""
    m = solver.model
    solver.x_lag.assign(m.X)
    solver.x_bar.assign(m.X)
    res = minimise(_StaticProblem(solver, np.repeat(~fixed, 3)), m.X.copy(), tol * m.L, max_iter)
    if not res.converged:
        raise RuntimeError(f"static equilibrium did not converge in {res.iters} Newton iterations")
    return res.y, res.iters

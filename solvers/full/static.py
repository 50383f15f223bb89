"""Static equilibrium with clamped vertices (verification: cantilever under self-weight).

Minimises sum_e V_e Psi(F_e) - sum_i m_i g . x_i over the free vertices by Newton's method with the full-space
solver's kernels (projected Hessian, direct solve on the free degrees of freedom, Armijo backtracking).
"""

from __future__ import annotations

import numpy as np
from solvers.full.solver import FullSpaceSolver
from solvers.linalg import sparse_spd_solve


def static_equilibrium(solver: FullSpaceSolver, fixed: np.ndarray, tol: float = 1e-10,
                       max_iter: int = 50) -> tuple[np.ndarray, int]:
    """Equilibrium positions (n, 3) [m] starting from the rest mesh, vertices where `fixed` (n,) bool is True
    held at rest; stops when |dx|_inf < tol * L. Returns (x, Newton iterations)."""
    m = solver.model
    free = np.repeat(~fixed, 3)
    x = m.X.copy()
    solver.x_prev.assign(x)
    solver.x.assign(x)
    E = solver.energy(solver.x, 1.0, inertia=False)
    for it in range(1, max_iter + 1):
        solver.gradient_hessian(solver.x, 1.0, inertia=False)
        H = solver.pattern.to_scipy(solver.values.numpy())[free][:, free]
        g = solver.grad.numpy().ravel()[free]
        dx = np.zeros(3 * m.n)
        dx[free] = sparse_spd_solve(H.tocsc(), -g)
        dx = dx.reshape(-1, 3)
        if np.abs(dx).max() < tol * m.L:
            return x + dx, it
        alpha, g_dot = 1.0, float(g @ dx.ravel()[free])
        while True:
            solver.x_trial.assign(x + alpha * dx)
            E_new = solver.energy(solver.x_trial, 1.0, inertia=False)
            if E_new <= E + 1e-4 * alpha * g_dot + 1e-12 * abs(E) or alpha < 1e-10:
                break
            alpha *= 0.5
        x, E = x + alpha * dx, E_new
        solver.x.assign(x)
    raise RuntimeError(f"static equilibrium did not converge in {max_iter} Newton iterations")

"""Full-space implicit time stepping as energy minimisation, solved by Newton's method with warp kernels.

Each step minimises E(x) = 1/(2h^2)|x - x_hat|_M^2 + sum_e V_e Psi(F_e) + E_gravity + E_contact + D_friction over
the vertex positions x (n, 3), x_hat = x^n + h v^n for backward Euler (docs/physics.md); with a multistep
integrator (the model's, e.g. BDF2) h is its effective step h_eff (2/3 dt for BDF2) and x_hat = x_bar + h_eff v_bar
(`solvers.integrators`). Only the terms the scene calls for are built (`solvers.physics.terms.terms_of`), each by
the launcher its declaration picks (`solvers.full.terms`); an absent term launches no kernel. Newton directions come
from the projected (PSD) Hessian, assembled into a fixed block-sparse pattern, and a backtracking (Armijo) line search
on E, in the shared loop of `solvers.newton_method`; the terms' feasible-step rule (`solvers.step`) caps the step (the barrier law: no
contact point crosses the plane). Convergence is measured in velocity units: |dx|_inf / h < tol * L [m/s], L the
rest bounding-box diagonal (h = h_eff: the velocity change of a step dx).
"""

from __future__ import annotations

import time
from dataclasses import dataclass

import numpy as np
import scipy.sparse as sp
import warp as wp
import warp.optim.linear as wpl
import warp.sparse as wps

from frictionbench.solvers.full.assembly import ElementRanges, thread_budget
from frictionbench.solvers.full.terms import launcher_of
from frictionbench.solvers.integrators import Lagged
from frictionbench.solvers.linalg import make_factoriser
from frictionbench.solvers.model import Model, State
from frictionbench.solvers.newton_method import Direction, LineSearch, NewtonResult, minimise
from frictionbench.solvers.physics.terms import StepData, terms_of
from frictionbench.solvers.step import ContactLag, StepProblem, lagged_contact, solve_lagged
from frictionbench.solvers.step_stats import StepStats
from frictionbench.solvers.warp_runtime import init_warp

@dataclass(frozen=True)
class NewtonSettings:
    """Newton tolerances: tol is relative to L per second; linear solver `pardiso` (MKL, SPD, analysis once),
    `superlu` (SciPy), `direct` (PARDISO where it loads, else SuperLU), `cg` (warp, block Jacobi) or `auto` (direct
    on the CPU, cg on CUDA); see `solvers.linalg`.

    max_iter: iterations per attempt; a 20 m/s impact on a soft body needs up to ~200 in its impact step (measured
    on the hard suite), and an attempt that runs out is retried as two half steps (`solvers.simulate`).

    chord: each Newton iteration but a step's first tests convergence first with the last factorisation (a
    gradient and a back-substitution, `solvers.newton_method.minimise`): the iteration that ends a solve, a fixed
    point's re-lag above all, then costs no Hessian and no factorisation. Off by default (the references' settings);
    the truth ladders' `[truth] chord` turns it on.

    chord_contraction (with chord; 0: off): modified Newton. A chord step of norm below chord_contraction times the
    last step's that passes the Armijo test is taken as the iteration, and the factorisation is kept; one that
    contracts less is replaced by a Newton iteration, which refactorises. A step's first iteration, and the first
    after each of a fixed point's re-lags (another problem: `_LaggedStep.relag`), takes the chord step of the last
    factorisation (at the same step size) wherever it passes the Armijo test, the next one judging its
    contraction. The truth ladders' `[truth] chord_contraction` sets it.
    """

    tol: float = 1e-5
    max_iter: int = 200
    linear: str = "auto"
    cg_tol: float = 1e-10
    armijo: float = 1e-4
    max_halvings: int = 40
    chord: bool = False
    chord_contraction: float = 0.0


class BlockPattern:
    """Fixed 3x3-block sparsity of the mesh: unique (row, col) vertex pairs of every tet plus the diagonal.

    rows, cols: (nnzb,) block coordinates sorted row-major; offsets: (n+1,) CSR row pointers;
    blockmap: (16 m,) block index of each element pair; diag: (n,) block index of each diagonal.
    """

    def __init__(self, tets: np.ndarray, n: int) -> None:
        a = np.repeat(np.arange(4), 4)
        b = np.tile(np.arange(4), 4)
        keys = (tets[:, a].astype(np.int64) * n + tets[:, b]).ravel()
        diag_keys = np.arange(n, dtype=np.int64) * (n + 1)
        uniq, inverse = np.unique(np.concatenate([keys, diag_keys]), return_inverse=True)
        self.rows = (uniq // n).astype(np.int32)
        self.cols = (uniq % n).astype(np.int32)
        self.offsets = np.searchsorted(self.rows, np.arange(n + 1)).astype(np.int32)
        self.blockmap = inverse[: keys.size].astype(np.int32)
        self.diag = inverse[keys.size:].astype(np.int32)
        self.n = n

    @property
    def nnzb(self) -> int:
        """Number of stored 3x3 blocks."""
        return int(self.rows.size)

    def to_scipy(self, values: np.ndarray) -> sp.csc_matrix:
        """The (3n, 3n) matrix with block values (nnzb, 3, 3), as CSC for a direct factorisation."""
        return sp.bsr_matrix((values, self.cols, self.offsets), shape=(3 * self.n, 3 * self.n)).tocsc()


class FullSpaceSolver:
    """Newton on the incremental potential of the model's integrator, kernels on `device` (`cpu` or `cuda`).

    Per step it holds the integrator's positions in warp arrays x_hat (the inertial target), x_lag (x^n) and x_bar
    (`solvers.integrators`); the terms' launchers (`solvers.full.terms`) hold what else they need of the step."""

    name = "full"

    def __init__(self, model: Model, device: str = "cpu", settings: NewtonSettings = NewtonSettings()) -> None:
        init_warp()
        self.model = model
        self.device = wp.get_device(device)
        self.settings = settings
        linear = settings.linear
        if linear == "auto":
            linear = "direct" if self.device.is_cpu else "cg"
        if linear not in ("direct", "pardiso", "superlu", "cg"):
            raise ValueError(f"solver.linear = {linear!r}: expected 'auto', 'direct', 'pardiso', 'superlu' or 'cg'")
        self.integrator = model.integrator
        self.contact_lag = ContactLag(model.contact.lag)
        d = self.device
        self.pattern = BlockPattern(model.tets, model.n)
        self.terms = terms_of(model)
        if linear != "cg":
            self.factoriser = make_factoriser(linear, self.pattern.offsets, self.pattern.cols, model.n)
            linear = self.factoriser.name
        self.linear = linear
        # the (h [s], inertia) of the problem whose Hessian the factoriser holds, None before the first
        # (`_StepProblem.chord_direction`)
        self.factored: tuple[float, bool] | None = None
        self.elements = ElementRanges(model.tets.shape[0], d, thread_budget())
        self.launches = self.elements.launches  # every kernel launch, recorded once (`solvers.warp_runtime.Relaunches`)
        self.info = {"linear_solver": linear, "assembly_threads": self.elements.threads}
        arr = lambda a, dt: wp.array(np.ascontiguousarray(a), dtype=dt, device=d)  # noqa: E731
        self.tets = arr(model.tets.astype(np.int32), wp.vec4i)
        self.Dm_inv = arr(model.Dm_inv, wp.mat33d)
        self.vol = arr(model.vol, wp.float64)
        self.mass = arr(model.mass, wp.float64)
        self.points = arr(model.points.astype(np.int32), wp.int32)
        self.area = arr(model.area, wp.float64)
        self.blockmap = arr(self.pattern.blockmap, wp.int32)
        self.diag = arr(self.pattern.diag, wp.int32)
        self.x = wp.zeros(model.n, dtype=wp.vec3d, device=d)
        self.x_trial = wp.zeros(model.n, dtype=wp.vec3d, device=d)
        self.x_hat = wp.zeros(model.n, dtype=wp.vec3d, device=d)
        self.x_lag = wp.zeros(model.n, dtype=wp.vec3d, device=d)
        self.x_bar = wp.zeros(model.n, dtype=wp.vec3d, device=d)
        self.grad = wp.zeros(model.n, dtype=wp.vec3d, device=d)
        self.values = wp.zeros(self.pattern.nnzb, dtype=wp.mat33d, device=d)
        self.elem_blocks = wp.zeros(16 * model.tets.shape[0], dtype=wp.mat33d, device=d)
        self.energy_buf = wp.zeros(1, dtype=wp.float64, device=d)
        if model.plane_normal is not None:
            self.normal = wp.vec3d(*model.plane_normal)
        if self.linear == "cg":
            ones = np.broadcast_to(np.eye(3), (self.pattern.nnzb, 3, 3)).copy()
            self.A = wps.bsr_from_triplets(
                model.n, model.n, arr(self.pattern.rows, wp.int32), arr(self.pattern.cols, wp.int32),
                arr(ones, wp.mat33d), prune_numerical_zeros=False)
            assert np.array_equal(self.A.columns.numpy()[: self.pattern.nnzb], self.pattern.cols)
            self.values = self.A.values
            self.rhs = wp.zeros(model.n, dtype=wp.vec3d, device=d)
            self.dx = wp.zeros(model.n, dtype=wp.vec3d, device=d)
        self.launchers = [launcher_of(self, term) for term in self.terms]

    # ----- energy, gradient and Hessian of the incremental potential -------------------------------------
    def _launch_terms(self, x: wp.array, h: float, mode: int, inertia: bool = True, hessian: bool = True) -> None:
        """Energy (mode 0, into energy_buf) or gradient + Hessian (mode 1, into grad / values; hessian=False: the
        gradient alone, `values` left as scratch) at x: the launcher of each of the model's terms
        (`solvers.full.terms`) launches its kernels.

        inertia=False drops the inertial term (static equilibrium); gravity stays if the scene has it.
        """
        for launcher in self.launchers:
            launcher.launch(x, h, mode, inertia, hessian)

    def energy(self, x: wp.array, h: float, inertia: bool = True) -> float:
        """E(x) [J] of the current step's incremental potential."""
        self.energy_buf.zero_()
        self._launch_terms(x, h, 0, inertia)
        return float(self.energy_buf.numpy()[0])

    def gradient_hessian(self, x: wp.array, h: float, inertia: bool = True) -> None:
        """Fill self.grad (n,) vec3d [N] and self.values (nnzb,) 3x3 blocks [N/m] at x."""
        self.grad.zero_()
        self.values.zero_()
        self._launch_terms(x, h, 1, inertia)

    def gradient(self, x: wp.array, h: float, inertia: bool = True) -> None:
        """Fill self.grad (n,) vec3d [N] at x (the element terms' Hessians skipped; `values` is scratch after)."""
        self.grad.zero_()
        self._launch_terms(x, h, 1, inertia, hessian=False)

    # ----- linear solve and line search ---------------------------------------------------------------
    def _solve(self, problem: tuple[float, bool]) -> tuple[np.ndarray, int]:
        """Newton direction dx = -H^-1 grad, (n, 3), and the linear iteration count (0 for direct); `problem`: the
        (h [s], inertia) of the Hessian, which a direct solve's factorisation is kept for (`factored`)."""
        if self.linear != "cg":
            self.factoriser.factorize(self.values.numpy())
            self.factored = problem
            return self.factoriser.solve(-self.grad.numpy().ravel()).reshape(-1, 3), 0
        self.launches.launch(_negate_kernel, self.model.n, [self.grad, self.rhs])
        self.dx.zero_()
        M = wpl.preconditioner(self.A, "block_jacobi_direct")
        iters, _, _ = wpl.cg(self.A, self.rhs, self.dx, tol=self.settings.cg_tol, maxiter=10 * self.model.n * 3,
                             M=M, use_cuda_graph=False)
        return self.dx.numpy(), int(iters)

    # ----- one time step --------------------------------------------------------------------------------
    def begin(self, step: StepData) -> None:
        """Take a step's constants: its positions x_hat, x_lag and x_bar (n, 3) [m] into the solver's arrays, then
        each term's (`solvers.full.terms.Launcher.begin_step`)."""
        self.x_hat.assign(step.x_hat)
        self.x_lag.assign(step.x_lag)
        self.x_bar.assign(step.x_bar)
        for launcher in self.launchers:
            launcher.begin_step(step)

    def step(self, state_in: State, state_out: State, dt: float) -> StepStats:
        """Advance state_in by dt into state_out (the model's integrator, with the history it takes from
        state_in.previous, `Integrator.previous`; the contact lag of the scene, `solvers.step.solve_lagged`);
        returns the step's statistics."""
        t0 = time.perf_counter()
        s, m = self.settings, self.model
        prev = self.integrator.previous(state_in, dt)
        history = None if prev is None else (prev.x, prev.v, state_in.t - prev.t)
        lag = self.integrator.lagged(state_in.x, state_in.v, dt, history)
        step = _LaggedStep(self, lag, state_in.x, dt)
        res, counters = solve_lagged(step, self.contact_lag, state_in.x, state_in.v)
        x = res.y
        self.x.assign(x)
        state_out.x = x
        state_out.v = lag.velocity(x)
        state_out.t = state_in.t + dt
        state_out.previous = state_in.without_history()
        return res.step_stats(time.perf_counter() - t0, **counters)


@dataclass
class _LaggedStep:
    """One step of dt [s] of a `FullSpaceSolver` for `solvers.step.solve_lagged`: the integrator's constants
    `lag`, the start positions x_start (n, 3) [m]."""

    solver: FullSpaceSolver
    lag: Lagged
    x_start: np.ndarray
    dt: float
    x_gate: np.ndarray | None = None
    residual: float = np.inf  # the norm of the step's last step so far, Newton or chord [m/s] (`minimise(residual=...)`)

    def relag(self, x_lag: np.ndarray, v_lag: np.ndarray) -> tuple[np.ndarray | None, np.ndarray]:
        """Begin the step with its lagged quantities at positions x_lag and velocities v_lag (n, 3)
        (`lagged_contact`, below the gate positions of the step's earlier lags: x_gate, the contact points' (p, 3)
        [m], kept here)."""
        sv, m, lag = self.solver, self.solver.model, self.lag
        p = m.points
        start = x_lag is self.x_start  # the step's first solve: the lag at the start
        x_start_p = self.x_start[p]
        below = x_start_p if self.x_gate is None else self.x_gate
        fn, gate, x_gate = lagged_contact(sv.terms, m, x_start_p if start else x_lag[p], v_lag[p], below)
        self.x_gate = x_gate
        if not start:  # a re-lag: the gate's positions at the contact points
            x_lag = x_lag.copy()
            x_lag[p] = x_gate
            # a re-lag poses another problem (its pressure and gate): modified Newton's contraction test starts
            # afresh, as at the step's first solve. Compared with the last lag's last step, the chord step of the
            # new problem, which carries the lag's change, was refused and refactorised nearly every re-lag
            # (measured on paper-damped/cheese_p1_mu0.8 at dt/32: 0.92 factorisations a step, 0.32 with this)
            self.residual = np.inf
        sv.begin(StepData(lag.y_tilde, x_lag, self.dt, fn, x_bar=lag.y_bar, h_eff=lag.h_eff))
        return fn, gate

    def newton(self, x0: np.ndarray | None, max_iter: int | None = None) -> NewtonResult:
        """Newton from x0, or (None) from x_hat, shortened by the feasible-step rule where a term caps steps; at
        most max_iter iterations (None: the settings')."""
        sv, lag, s = self.solver, self.lag, self.solver.settings
        problem = _StepProblem(sv, lag.h_eff)
        first = x0 is None
        if x0 is None:
            x0 = lag.y_tilde.copy()
            if problem.capping:
                reach = (lag.y_bar - self.x_start) + lag.h_eff * lag.v_bar  # x_hat - x^n (h v^n for backward Euler)
                x0 = self.x_start.copy() + reach * problem.max_step(self.x_start, reach)
        # a step's first solve starts far from the last factorisation's point (the previous step's): the chord test
        # there only from its second iteration, but modified Newton takes the previous step's factorisation as well
        chord = (2 if first and not s.chord_contraction else 1) if s.chord else None
        res = minimise(problem, x0, s.tol * sv.model.L, max_iter or s.max_iter, LineSearch(s.armijo, s.max_halvings),
                       chord, s.chord_contraction, self.residual)
        self.residual = res.residual
        return res

    def velocity(self, x: np.ndarray) -> np.ndarray:
        """The end-of-step velocities of positions x (n, 3) [m/s]."""
        return self.lag.velocity(x)


class _StepProblem(StepProblem):
    """One step's incremental potential (`solvers.step.StepProblem`) over the vertex positions (n, 3) [m]: h the
    time step [s] (1 with inertia=False: static equilibrium, where the step norm is |dx|_inf [m])."""

    def __init__(self, solver: FullSpaceSolver, h: float, inertia: bool = True) -> None:
        super().__init__(solver.model, solver.terms)
        self.solver, self.h, self.inertia = solver, h, inertia

    def energy(self, x: np.ndarray) -> float:
        """E(x) [J]."""
        self.solver.x_trial.assign(x)
        return self.solver.energy(self.solver.x_trial, self.h, self.inertia)

    def direction(self, x: np.ndarray) -> Direction:
        """Newton direction from the projected Hessian at x."""
        sv = self.solver
        sv.x.assign(x)
        sv.gradient_hessian(sv.x, self.h, self.inertia)
        dx, li = sv._solve((self.h, self.inertia))
        return Direction(dx, float(np.sum(sv.grad.numpy() * dx)), li)

    def chord_direction(self, x: np.ndarray) -> Direction | None:
        """The direction at x from the gradient at x and the factorisation of the last `direction` (None before the
        first, with the iterative `cg` solve, which keeps none, or where the last was another step size's)."""
        sv = self.solver
        if sv.factored != (self.h, self.inertia):
            return None
        sv.x.assign(x)
        sv.gradient(sv.x, self.h, self.inertia)
        g = sv.grad.numpy()
        dx = sv.factoriser.solve(-g.ravel()).reshape(-1, 3)
        return Direction(dx, float(np.sum(g * dx)), 0)

    def step_norm(self, dx: np.ndarray) -> float:
        """|dx|_inf / h [m/s]."""
        return float(np.abs(dx).max()) / self.h

    def contact_points(self, x: np.ndarray, dx: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """The contact vertices' positions and displacements, (p, 3) [m]."""
        p = self.model.points
        return x[p], dx[p]


@wp.kernel
def _negate_kernel(a: wp.array(dtype=wp.vec3d), out: wp.array(dtype=wp.vec3d)):
    """out = -a."""
    i = wp.tid()
    out[i] = -a[i]

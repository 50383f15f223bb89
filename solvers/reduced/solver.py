"""LiCROM's online latent dynamics: implicit time stepping in the linear subspace x = X + W q (docs/solvers.md,
"LiCROM").

Each step minimises the incremental potential of the full-space solver restricted to the subspace,

    E(q) = 1/(2h^2) (q - q_hat)^T M_r (q - q_hat) - g_r . q + sum_c w_c V_c Psi(F_c(q)) + E_contact + D_friction,

with q_hat = q^n + h qdot^n for backward Euler; with a multistep integrator (the model's, e.g. BDF2), h is its
effective step h_eff (2/3 dt for BDF2) and q_hat = q_bar + h_eff qdot_bar, the dissipative terms taking their
velocity from the decoded x_bar = X + W q_bar (`solvers.integrators`: the formulas hold in latent coordinates, the
decoding being linear). M_r = W^T M W (lumped M, factorised once), g_r = sum_i m_i W_i^T g, cubature tets
(c, w_c) whose F_c(q) = F_c(0) + B_c q is linear in q (B_c = dvec F_c/dq constant), and the contact and friction
laws of solvers/physics at the surface sample points x_p = X_p + W_p q (gradient W_p^T g_p, Hessian
W_p^T H_p W_p). Friction uses the normal pressure lagged from the start of the step, as the full solver does.

Schemes:
- "newton": Newton's method on the r-dimensional energy with the PSD-projected dense Hessian (Cholesky), run
  by the shared loop of `solvers.newton_method` (Armijo backtracking with its round-off slack, and, for the barrier law,
  a step cap that keeps every contact point above the plane; a line search without decrease ends the attempt).
  Converged when |W dq|_inf / h < tol * L over all mesh vertices (the full solver's measure; decoding dq costs
  one (3n x r) product).
- "projected_gradient": the LiCROM contact paper's scheme (docs/solvers.md). The sample points are the vertices of the
  cubature tets, each carrying the cubature estimate of its lumped mass w_i = rho/4 sum_{c owns i} w_c V_c,
  plus the contact points (force only, no mass). Every iteration decodes the points, evaluates the full-space
  gradient g_i of the incremental potential there (inertia w_i/h^2 (x_i - x_hat_i), gravity -w_i g, the
  cubature tets' elastic forces, contact and friction), forms the increments du_i = alpha h^2 g_i / w_i and
  projects them by the pre-factorised weighted least-squares system (sum_i w_i W_i^T W_i) dq = sum_i w_i W_i^T
  du_i, then q <- q - dq. alpha = 1 solves the inertia + gravity part in one iteration, but elasticity, contact
  and friction make it a gradient descent preconditioned by S = sum_i w_i W_i^T W_i, stable only for
  alpha < 2 / lambda_max(h^2 S^-1 H) (`projected_gradient_alpha_limit`), and then the softest mode converges
  like (1 - alpha)^k. Measured on
  the block incline (E = 1 MPa, h = 10 ms, affine basis): the limit is ~0.005-0.011 (set by the volumetric mode
  and by sticking friction, k_f / h); at 0.9 x the limit a sliding step needs ~460 iterations to reach tol = 1e-5,
  a fixed 20 iterations leave the block nearly stuck (acceleration 0.57 instead of 3.21 m/s^2), and above the
  limit the iteration oscillates or diverges. Stops when |W dq|_inf / h < tol * L or after max_iter iterations.

The solver works on the full `State` of solvers/simulate.py, whose q and qdot fields carry the latent
coordinates: it writes state_out.x = X + W q, state_out.v = W qdot, state_out.q, state_out.qdot. A state_in
without latent coordinates (an initial state) is first projected to the subspace (mass-weighted least squares,
`project`).
"""

from __future__ import annotations

import time
from collections.abc import Sequence
from dataclasses import dataclass, replace

import numpy as np
import scipy.sparse as sp
from scipy.linalg import cho_factor, cho_solve, eigh
from scipy.linalg.lapack import dpotrf, dpotrs

from frictionbench.solvers.model import Model, State
from frictionbench.solvers.newton_method import Direction, LineSearch, NewtonResult, minimise
from frictionbench.solvers.physics.contact import signed_distance
from frictionbench.solvers.physics.inertia import lumped_mass
from frictionbench.solvers.physics.material import shape_gradients
from frictionbench.solvers.physics.terms import BodyTerm, PointTerm, terms_of
from frictionbench.solvers.reduced import kernels as K
from frictionbench.solvers.reduced.bases import project
from frictionbench.solvers.reduced.cubature import Cubature, all_tets, deformation_jacobians
from frictionbench.solvers.reduced.terms import MODES, CubatureEvaluation, PointEvaluations, body_evaluation
from frictionbench.solvers.step import ContactLag, StepProblem, gate_positions, lagged_contact, solve_lagged
from frictionbench.solvers.step_stats import StepStats

SPARSE_DENSITY, SPARSE_MIN_R = 0.1, 100
"""Jacobians B with at most this fraction of non-zeros and at least this many columns (local bases such as
`full_basis`) use sparse products; below, the dense r x r work is cheaper than sparse bookkeeping."""

EXTREME_ROWS = 64
"""Rows of W (3n x r) with the largest norms whose |W dq|_inf alone decides most Newton iterations' convergence
test (`_StepProblem.step_norm`)."""

ROW_NORM_ALLOWANCE = 1e-12
"""Round-off allowance of the upper bound W_rest_norm |dq| of the other rows' |W_k dq| (relative): where the bound
decides a step converged, the product over every row would have decided the same."""

HESSIAN_PRECISIONS = {"double": np.float64, "single": np.float32}
"""Precisions of the reduced Hessian's dense products B^T (w V H9) B (`Subspace.pull_back`; the solvers'
`hessian` parameter). The Hessian only sets Newton's direction; the energy and the gradient, which decide where a
step stops, stay in double. In single the products take under half the time (half or more of an r = 84 step on
210 tets), and a run's iterations and trajectory are double's to round-off (measured on the coarse sphere at r = 60
and 84: the same iteration counts, positions within 1.1e-13 of L; experiments/figures.md)."""

HESSIAN_REFRESHES = ("iteration", "step")
"""When the body terms' Hessian (the cubature tets' elasticity and viscosity pulled back, `Subspace.pull_back`)
is evaluated: at every Newton iteration (Newton's method), or at a step's first iteration only, kept for the
step's other iterations and contact-lag solves (a modified Newton method; the solvers' `hessian_refresh`). The
point terms' and the inertia's Hessians stay exact at every iteration, and the gradient, which decides where a
step stops, is exact either way: within a step the body's strain changes little, so the kept part is close to the
current one. It drops the kernels' Hessian factors and the dense pull-back from all but one evaluation a step,
which were two thirds of a step at r = 60 on 150 tets (measured on the coarse sphere: 1.8x less time a step, the
same Newton iterations, positions within 5e-8 of L; `pod-fast` runs 1.5-1.6x cheaper in the median, err_truth the
same to 1.5e-4 of itself; experiments/figures.md). The kept part turns with the body, so a body spinning fast within a
step at a tight tolerance takes more iterations (the method converges linearly)."""

CANDIDATE_MARGIN = 1e-9
"""Round-off allowance of the contact candidates' test, relative to the body size L: a point is a candidate when
its signed distance, computed as phi_rest + N q, is below the terms' reach plus this much (the terms compute it as
n . (X_p + W_p q) - d, which differs by a few ulps of |X_p| + |W_p q|, some 1e-16 L)."""


@dataclass
class ReducedState:
    """Latent coordinates q (r,) [unit of W's columns], their rate qdot (r,) [1/s] and the time t [s]."""

    q: np.ndarray
    qdot: np.ndarray
    t: float = 0.0


@dataclass
class Subspace:
    """Static data of the reduced problem (float64).

    W: (n, 3, r) basis at the mesh vertices [m per unit q]; M_r: (r, r) reduced mass [kg]; cub_ids: (c,) cubature
    tets; wV: (c,) their weights times volumes w_c V_c [m^3]; F0: (c, 3, 3) rest deformation gradients; B: (c, 9, r)
    dvec(F_c)/dq; B_sparse: the same as a (9c, r) CSR matrix when sparse enough, else None; points, area: (p,)
    contact sample vertices and their area weights [m^2]; Xp: (p, 3) their rest positions; Wp: (p, 3, r) the basis
    there; with a plane n . x = d, phi_rest (p,) [m] the points' rest signed distances n . X_p - d and N (p, r)
    [m per unit q] the rows n^T W_p, so that phi_p(q) = phi_rest_p + N_p q (None without a plane); W_extreme
    (k, r) the EXTREME_ROWS rows of W (3n x r) with the largest norms, and W_rest_norm the largest Euclidean norm of
    the other rows (times 1 + ROW_NORM_ALLOWANCE), so that |W dq|_inf <= max(|W_extreme dq|_inf, W_rest_norm |dq|)
    [m per unit q]; device: where the elastic kernel runs ("cpu" or "cuda", `solvers.reduced.kernels`);
    B_hessian: B in the precision of the dense Hessian products (`HESSIAN_PRECISIONS`; None: B itself, double).
    """

    model: Model
    W: np.ndarray
    M_r: np.ndarray
    M_cho: tuple
    cub_ids: np.ndarray
    wV: np.ndarray
    F0: np.ndarray
    B: np.ndarray
    B_sparse: sp.csr_matrix | None
    points: np.ndarray
    area: np.ndarray
    Xp: np.ndarray
    Wp: np.ndarray
    phi_rest: np.ndarray | None
    N: np.ndarray | None
    W_extreme: np.ndarray
    W_rest_norm: float
    device: str = "cpu"
    B_hessian: np.ndarray | None = None

    @classmethod
    def build(cls, model: Model, W: np.ndarray, cubature: Cubature | None = None,
              contact_samples: int | None = None, seed: int = 0, device: str = "cpu",
              hessian: str = "double") -> "Subspace":
        """Precompute everything for the basis W (n, 3, r) on `model`'s mesh.

        cubature: (tet ids, weights), None for every tet with weight 1. contact_samples: keep that many of the
        model's contact points (uniformly at random, `seed`), areas re-weighted to keep the total; None keeps all.
        device: where the elastic kernel runs ("cpu" or "cuda"). hessian: the precision of the dense Hessian
        products (`HESSIAN_PRECISIONS`).
        """
        K.check_device(device)
        if hessian not in HESSIAN_PRECISIONS:
            raise ValueError(f"hessian = {hessian!r}: expected one of {list(HESSIAN_PRECISIONS)}")
        n, r = model.n, W.shape[2]
        if W.shape != (n, 3, r):
            raise ValueError(f"basis shape {W.shape}: expected ({n}, 3, r) for this mesh")
        W = np.ascontiguousarray(W, dtype=np.float64)
        Wf = W.reshape(3 * n, r)
        M_r = Wf.T @ (np.repeat(model.mass, 3)[:, None] * Wf)
        try:
            M_cho = cho_factor(M_r)
        except np.linalg.LinAlgError as err:
            raise ValueError("the basis columns are linearly dependent on this mesh (W^T M W is singular)") from err
        ids, w = all_tets(model) if cubature is None else (np.asarray(c) for c in cubature)
        if ids.shape != w.shape or ids.ndim != 1 or ((ids < 0) | (ids >= model.tets.shape[0])).any():
            raise ValueError(f"cubature: {ids.size} tet ids and {w.size} weights; ids must be one per weight, in "
                             f"[0, {model.tets.shape[0]})")
        bad = np.flatnonzero(~(np.isfinite(w) & (w >= 0)))
        if bad.size:  # a negative weight would make the cubature energy non-convex where every tet's is convex
            raise ValueError(f"cubature weight {w[bad[0]]:g} at tet {ids[bad[0]]}: weights must be finite and >= 0")
        F0, B = deformation_jacobians(model, W, ids)
        Bf = B.reshape(-1, r)
        sparse = r >= SPARSE_MIN_R and np.count_nonzero(Bf) <= SPARSE_DENSITY * Bf.size
        points, area = _contact_samples(model, contact_samples, seed)
        Xp, Wp, n = model.X[points], np.ascontiguousarray(W[points]), model.plane_normal
        row_norms = np.linalg.norm(Wf, axis=1)
        by_norm = np.argsort(row_norms)
        return cls(model=model, W=W, M_r=M_r, M_cho=M_cho, cub_ids=ids.astype(np.int64),
                   wV=w * model.vol[ids], F0=F0, B=B,
                   B_sparse=sp.csr_matrix(Bf) if sparse else None, points=points, area=area, Xp=Xp, Wp=Wp,
                   phi_rest=None if n is None else signed_distance(Xp, n, model.plane_offset),
                   N=None if n is None else np.ascontiguousarray(np.einsum("pak,a->pk", Wp, n)),
                   W_extreme=Wf[by_norm[-EXTREME_ROWS:]],
                   W_rest_norm=float(row_norms[by_norm[:-EXTREME_ROWS]].max(initial=0.0)) * (1 + ROW_NORM_ALLOWANCE),
                   device=device, B_hessian=None if hessian == "double" else B.astype(HESSIAN_PRECISIONS[hessian]))

    @property
    def r(self) -> int:
        """Subspace dimension."""
        return int(self.W.shape[2])

    def decode(self, q: np.ndarray) -> np.ndarray:
        """Displacements W q at the mesh vertices, (n, 3) [m]."""
        return (self.W.reshape(-1, self.r) @ q).reshape(-1, 3)

    def project(self, u: np.ndarray) -> np.ndarray:
        """Mass-weighted least-squares coordinates of a vertex field u (n, 3): argmin_q |W q - u|_M, (r,)."""
        return project(self.W, u, self.model.mass)

    def point_positions(self, q: np.ndarray) -> np.ndarray:
        """Contact sample positions X_p + W_p q, (p, 3) [m]."""
        return _positions(self.Xp, self.Wp, q)

    def point_rows(self, ids: np.ndarray | None) -> tuple[np.ndarray, np.ndarray]:
        """The rest positions X_p (k, 3) [m] and basis rows W_p (k, 3, r) of the sample points ids (k,), gathered
        once (None: all points, not copied)."""
        return (self.Xp, self.Wp) if ids is None else (self.Xp[ids], self.Wp[ids])

    def deformation_gradients(self, q: np.ndarray) -> np.ndarray:
        """F_c(q) at the cubature tets, (c, 3, 3)."""
        return self.F0 + (self.B.reshape(-1, self.r) @ q).reshape(-1, 3, 3)

    def pull_back(self, P: np.ndarray | None, factors: Sequence[np.ndarray] | None
                  ) -> tuple[np.ndarray | None, np.ndarray | None]:
        """The cubature sums of per-tet stresses P (c, 3, 3) [Pa] and of density Hessians (row-major vec) given by
        the factors of one or more terms, H9_c = sum_t L_tc^T L_tc with L_t (c, k_t, 9) [sqrt(Pa)], in the latent
        coordinates: sum_c w_c V_c B_c^T vec P_c (r,) [N] and sum_c w_c V_c B_c^T H9_c B_c (r, r) [N/m], exactly
        symmetric. One factor: G^T G with G the stacked sqrt(w_c V_c) L_c B_c (kc, r). Several: the 9x9 sums H9_c
        first, then one general product B^T (w V H9 B) symmetrised; that reduces 9 rows a tet where stacking the
        factors would reduce sum_t k_t (measured at c = 90, r = 36 with the SNH and viscous factors, 24 rows: 163
        against 221-237 us). The dense products run in the precision of `B_hessian` (their sum returned in double);
        the gradient and the sparse products in double. None where the input is None (or the factors are empty)."""
        Bf = self.B.reshape(-1, self.r)
        g = None if P is None else Bf.T @ (self.wV[:, None] * P.reshape(-1, 9)).ravel()
        if not factors:
            return g, None
        Bh = self.B if self.B_hessian is None else self.B_hessian
        if len(factors) == 1:
            Ls = np.sqrt(self.wV)[:, None, None] * factors[0]
            if self.B_sparse is None:
                G = np.matmul(Ls.astype(Bh.dtype, copy=False), Bh).reshape(-1, self.r)
                return g, (G.T @ G).astype(np.float64, copy=False)
            G = _block_diagonal(Ls) @ self.B_sparse
            return g, (G.T @ G).toarray()
        L = np.concatenate(factors, axis=1)
        wH = np.matmul(L.transpose(0, 2, 1), self.wV[:, None, None] * L)  # (c, 9, 9): w_c V_c H9_c
        if self.B_sparse is None:
            H = (Bh.reshape(-1, self.r).T @ np.matmul(wH.astype(Bh.dtype, copy=False), Bh).reshape(-1, self.r)
                 ).astype(np.float64, copy=False)
        else:
            H = (self.B_sparse.T @ (_block_diagonal(wH) @ self.B_sparse)).toarray()
        return g, 0.5 * (H + H.T)


def _block_diagonal(blocks: np.ndarray) -> sp.bsr_matrix:
    """The sparse block-diagonal matrix (c k, c l) of per-tet blocks (c, k, l)."""
    c, k, l = blocks.shape
    return sp.bsr_matrix((blocks, np.arange(c), np.arange(c + 1)), shape=(c * k, c * l))


def _positions(Xp: np.ndarray, Wp: np.ndarray, q: np.ndarray) -> np.ndarray:
    """X_p + W_p q (k, 3) [m] at points with rest positions Xp (k, 3) [m] and basis rows Wp (k, 3, r)."""
    return Xp + (Wp.reshape(-1, Wp.shape[2]) @ q).reshape(-1, 3)


def _lowest(model: Model, Xp: np.ndarray, Wp: np.ndarray, x_start: np.ndarray, q_gates: tuple[np.ndarray, ...]
            ) -> np.ndarray:
    """The gate positions (k, 3) [m] of a step's earlier lags at sample points with rest positions Xp (k, 3) [m]
    and basis rows Wp (k, 3, r): per point the lowest of its start position x_start (k, 3) [m] and its positions at
    the latent coordinates q_gates (`solvers.step.gate_positions`; x_start itself where there are none)."""
    below = x_start
    for q in q_gates:
        below = gate_positions(model, _positions(Xp, Wp, q), below)
    return below


def _scatter(values: np.ndarray, ids: np.ndarray, p: int) -> np.ndarray:
    """A (p,) array of `values` (k,) at ids (k,) and zeros (False) elsewhere."""
    out = np.zeros(p, dtype=values.dtype)
    out[ids] = values
    return out


def _contact_samples(model: Model, count: int | None, seed: int) -> tuple[np.ndarray, np.ndarray]:
    """The contact points and area weights, or a uniform random subset of `count` of them with the areas scaled
    so that their sum (the surface area) is unchanged."""
    p = model.points.size
    if count is None or count >= p:
        return model.points, model.area
    if count < 1:
        raise ValueError(f"contact_samples = {count}: need at least one point")
    keep = np.sort(np.random.default_rng(seed).choice(p, size=count, replace=False))
    return model.points[keep], model.area[keep] * (model.area.sum() / model.area[keep].sum())


@dataclass
class ReducedStep:
    """Per-step constants: dt h [s] and the integrator's effective step h_eff [s], q^n, q_bar and the inertial
    target q_hat = q_bar + h_eff qdot_bar (r,), the latent coordinates where the step lags contact q_lag (r,) (q^n
    itself for the start of the step, the default, `solvers.step.ContactLag`), the lagged normal pressure fn (p,)
    [Pa] (None without friction) and contact-damping gate (p,) bool there, and `lagged` (p,) bool, the points where
    a point term can act whatever their position (`PointTerm.lagged_support`); q_gates, the step's earlier lags'
    latent coordinates (a fixed point's re-lag: the gate is the points below the plane at the start, at any of them
    or at q_lag, `solvers.step.ContactLag`). Backward Euler: h_eff = h, q_bar = q^n. The dissipative terms' velocity
    is W (q - q_bar) / h_eff ((x - x_bar) / h_eff at the points)."""

    h: float
    h_eff: float
    q_prev: np.ndarray
    q_bar: np.ndarray
    q_hat: np.ndarray
    q_lag: np.ndarray
    fn: np.ndarray | None
    gate: np.ndarray | None = None
    lagged: np.ndarray | None = None
    q_gates: tuple[np.ndarray, ...] = ()

    def lagged_positions(self, model: Model, Xp: np.ndarray, Wp: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """At sample points with rest positions Xp (k, 3) [m] and basis rows Wp (k, 3, r)
        (`Subspace.point_rows`), the gate positions x_lag (`solvers.step.gate_positions` of the lag's, the earlier
        lags' and the start's positions: what the point terms take as x_lag) and x_bar, (k, 3) [m] each."""
        x_start = _positions(Xp, Wp, self.q_prev)
        x_lag = x_start if self.q_lag is self.q_prev else _positions(Xp, Wp, self.q_lag)
        x_bar = x_start if self.q_bar is self.q_prev else _positions(Xp, Wp, self.q_bar)
        return gate_positions(model, x_lag, _lowest(model, Xp, Wp, x_start, self.q_gates)), x_bar


@dataclass(frozen=True)
class _PointSet:
    """The contact sample points a point-term evaluation runs on: their indices ids (k,) into the sample points
    (None: all of them), rest positions Xp (k, 3) [m], basis rows Wp (k, 3, r), and the step's x_lag, x_bar (k, 3)
    [m], area (k,) [m^2] and fn (k,) [Pa] (None without friction) there."""

    ids: np.ndarray | None
    Xp: np.ndarray
    Wp: np.ndarray
    x_lag: np.ndarray
    x_bar: np.ndarray
    area: np.ndarray
    fn: np.ndarray | None

    @classmethod
    def of(cls, rm: Subspace, st: ReducedStep, ids: np.ndarray | None) -> "_PointSet":
        """The points ids (None: all) of `rm` with the step `st`'s lagged data."""
        Xp, Wp = rm.point_rows(ids)
        x_lag, x_bar = st.lagged_positions(rm.model, Xp, Wp)
        if ids is None:
            return cls(None, Xp, Wp, x_lag, x_bar, rm.area, st.fn)
        return cls(ids, Xp, Wp, x_lag, x_bar, rm.area[ids], None if st.fn is None else st.fn[ids])

    def positions(self, q: np.ndarray) -> np.ndarray:
        """X_p + W_p q at these points, (k, 3) [m]."""
        return _positions(self.Xp, self.Wp, q)


@dataclass
class _SamplePoints:
    """The projected-gradient scheme's mass-carrying sample points: the cubature tets' vertices.

    vertices: (k,) mesh vertex ids; weight: (k,) cubature lumped masses [kg]; local: (c, 4) index of each
    cubature tet's vertices in `vertices`; grad_shape: (c, 4, 3) shape gradients g_a [1/m]; S: the
    least-squares matrix sum_i w_i W_i^T W_i (r, r) [kg] and S_cho its Cholesky factor.
    """

    vertices: np.ndarray
    weight: np.ndarray
    local: np.ndarray
    grad_shape: np.ndarray
    S: np.ndarray
    S_cho: tuple

    def forces(self, wV: np.ndarray, P: np.ndarray) -> np.ndarray:
        """The cubature tets' forces w_c V_c P_c g_a summed on their vertices, (k, 3) [N]; wV (c,) [m^3], P (c, 3, 3)
        [Pa] the tets' stresses."""
        out = np.zeros((self.vertices.size, 3))
        np.add.at(out, self.local, wV[:, None, None] * np.einsum("cij,caj->cai", P, self.grad_shape))
        return out

    @classmethod
    def build(cls, rm: Subspace) -> "_SamplePoints":
        """Sample points of the cubature of `rm`."""
        m = rm.model
        tets = m.tets[rm.cub_ids]
        vertices, local = np.unique(tets, return_inverse=True)
        local = local.reshape(tets.shape)
        weight = lumped_mass(rm.wV, local, vertices.size, m.density)
        Wv = rm.W[vertices].reshape(-1, rm.r)
        S = Wv.T @ (np.repeat(weight, 3)[:, None] * Wv)
        return cls(vertices, weight, local, shape_gradients(m.Dm_inv[rm.cub_ids]), S, cho_factor(S))


class ReducedSolver:
    """Implicit time stepping (the model's integrator) in the subspace of a basis W (n, 3, r); see the module
    docstring.

    model: the scene on the mesh W was evaluated on; cubature: (tet ids, weights) or None for every tet (weight
    1); scheme: "newton" or "projected_gradient"; device: where the cubature kernel runs ("cpu" or "cuda"; the point
    terms' kernels run on the CPU, their work being small);
    tol: convergence |W dq|_inf / h < tol * L [1/s], finite and > 0; hessian: the precision of the dense Hessian
    products (`HESSIAN_PRECISIONS`); hessian_refresh: when the body terms' Hessian is evaluated, every Newton
    iteration or once a step (`HESSIAN_REFRESHES`); max_iter: iterations per step; alpha: the
    projected-gradient step size [-]; contact_samples, seed: contact point subsampling (None keeps all);
    armijo, max_halvings: Newton line search; contact_candidates: evaluate the point terms at the candidate
    points only (`_candidates`; equal to all points to round-off), False: at every sample point;
    fixed_iterations: the projected gradient runs exactly max_iter iterations a step with no convergence test
    (the step counts as converged, as LiCROM's released integrator steps); velocity_scale [-]: the latent velocity
    qdot^n is scaled by it before each step (1: none; LiCROM's released integrator damps by 0.99 a step).
    """

    name = "licrom"

    def __init__(self, model: Model, W: np.ndarray, cubature: Cubature | None = None, scheme: str = "newton",
                 device: str = "cpu", tol: float = 1e-5, max_iter: int = 50, alpha: float = 1.0,
                 contact_samples: int | None = None, seed: int = 0, name: str | None = None,
                 armijo: float = 1e-4, max_halvings: int = 40, contact_candidates: bool = True,
                 fixed_iterations: bool = False, velocity_scale: float = 1.0, hessian: str = "double",
                 hessian_refresh: str = "iteration") -> None:
        if scheme not in ("newton", "projected_gradient"):
            raise ValueError(f"scheme = {scheme!r}: expected 'newton' or 'projected_gradient'")
        if fixed_iterations and scheme != "projected_gradient":
            raise ValueError(f"scheme = {scheme!r}: a fixed iteration count is the projected gradient's only")
        if not 0.0 < velocity_scale <= 1.0:
            raise ValueError(f"velocity_scale = {velocity_scale!r}: expected a factor in (0, 1]")
        if isinstance(tol, bool) or not isinstance(tol, (int, float)) or not 0.0 < tol < np.inf:
            raise ValueError(f"tol = {tol!r}: expected a finite tolerance > 0 [1/s, relative to L]")
        if hessian_refresh not in HESSIAN_REFRESHES:
            raise ValueError(f"hessian_refresh = {hessian_refresh!r}: expected one of {list(HESSIAN_REFRESHES)}")
        self.fixed_iterations, self.velocity_scale = fixed_iterations, velocity_scale
        self.model = model
        self._build = dict(cubature=cubature, contact_samples=contact_samples, seed=seed, device=device,
                           hessian=hessian)
        self.scheme, self.tol, self.max_iter, self.alpha = scheme, tol, max_iter, alpha
        self.armijo, self.max_halvings = armijo, max_halvings
        self.hessian_refresh = hessian_refresh
        self._steps = 0  # steps begun (`step`), which key the kept body Hessian
        if name is not None:
            self.name = name
        self.integrator = model.integrator
        self.contact_lag = ContactLag(model.contact.lag)
        self.terms = terms_of(model)
        missing = [t.name for t in self.terms if not isinstance(t, (BodyTerm, PointTerm))]
        if missing:
            raise ValueError(f"terms {missing} have no reduced evaluation (neither a BodyTerm nor a PointTerm)")
        self.point_terms = [t for t in self.terms if isinstance(t, PointTerm)]
        self.reach = max((t.reach(model) for t in self.point_terms), default=-np.inf)
        self.lag_reach = max([0.0] + [t.lag_reach(model) for t in self.terms])
        self.contact_candidates = contact_candidates and model.plane_normal is not None and self.reach < np.inf
        self.use_basis(W)
        self.point_evaluations = PointEvaluations(self, self.point_terms) if self.point_terms else None

    def use_basis(self, W: np.ndarray) -> None:
        """Step in the subspace of the basis W (n, 3, r) from now on: the `Subspace` and everything built on it (the
        body terms' evaluations, the projected gradient's sample points, the contact candidates' thresholds); the
        kept evaluations are dropped. A state's latent coordinates belong to the basis they were computed in."""
        model = self.model
        self.reduced = Subspace.build(model, W, **self._build)
        self.samples = _SamplePoints.build(self.reduced) if self.scheme == "projected_gradient" else None
        self.body_evaluations = [body_evaluation(self, t) for t in self.terms if isinstance(t, BodyTerm)]
        # N q below this (p,) [m]: the signed distance below the reach plus the round-off margin
        self._near_below = (self.reach + CANDIDATE_MARGIN * model.L - self.reduced.phi_rest
                            if self.contact_candidates else None)
        # the same for the lag (`_lag_points`): what the terms lag, and the gate (below the plane), is zero above
        self._lag_below = (self.lag_reach + CANDIDATE_MARGIN * model.L - self.reduced.phi_rest
                           if self.contact_candidates and self.lag_reach < np.inf else None)
        self._point_set: tuple[ReducedStep | None, _PointSet | None] = (None, None)  # the last evaluation's
        self._memo: tuple | None = None  # (st, q's bytes, (E, g, H)) of the last `evaluate`
        self._kept: tuple[int, np.ndarray | None] | None = None  # (step, its body Hessian) under refresh "step"

    # ----- state mapping ---------------------------------------------------------------------------------
    def project(self, state: State) -> State:
        """The same state with its latent coordinates: mass-weighted least squares of x - X (q) and of v (qdot)."""
        rm = self.reduced
        return State(state.x, state.v, state.t, rm.project(state.x - self.model.X), rm.project(state.v))

    def decode(self, latent: ReducedState) -> State:
        """The full state X + W q, W qdot of a latent state, carrying q and qdot. One product with the two columns
        (q, qdot): it reads the basis (3n x r, megabytes on a medium mesh) once, where two matrix-vector products
        read it twice and leave the step's other data out of the cache (measured on cheese/medium, r = 24, in the
        reduced step: 90 against 110 us; the positions differ from the two products' by round-off, q and qdot are
        the same)."""
        rm = self.reduced
        xv = rm.W.reshape(-1, rm.r) @ np.stack((latent.q, latent.qdot), axis=1)
        return State(self.model.X + xv[:, 0].reshape(-1, 3), xv[:, 1].reshape(-1, 3), latent.t, latent.q,
                     latent.qdot)

    # ----- incremental potential -------------------------------------------------------------------------
    def _candidates(self, q: np.ndarray, st: ReducedStep) -> np.ndarray | None:
        """The sample points where a point term can be nonzero at q (k,) (None: all points, the candidates being
        off): those whose signed distance phi_rest + N q is below the terms' largest `PointTerm.reach` (plus
        CANDIDATE_MARGIN L of round-off; tested as N q < reach + margin - phi_rest) and those of the step's lagged
        support `st.lagged`. At every other point each term's energy, gradient and Hessian are exactly zero, so
        leaving them out changes sums by round-off only; the test costs one (p x r) product per evaluation."""
        if not self.contact_candidates:
            return None
        near = self.reduced.N @ q < self._near_below
        return np.flatnonzero(near if st.lagged is None else near | st.lagged)

    def _points(self, q: np.ndarray, st: ReducedStep) -> _PointSet:
        """The points the point terms are evaluated at for q (`_candidates`), their data gathered once for as
        long as the step and the set stay the same."""
        ids = self._candidates(q, st)
        last_st, last = self._point_set
        if last_st is not st or last is None or not (
                (ids is None and last.ids is None) or (ids is not None and last.ids is not None
                                                       and np.array_equal(ids, last.ids))):
            last = _PointSet.of(self.reduced, st, ids)
            self._point_set = st, last
        return last

    def _point_terms(self, q: np.ndarray, st: ReducedStep, order: int
                     ) -> tuple[float, np.ndarray | None, np.ndarray | None, np.ndarray]:
        """The point terms (contact, damping, friction) at the candidate sample points (`_points`): energy [J],
        per-point gradient (k, 3) [N] (order >= 1), Hessian blocks (k, 3, 3) [N/m] (order 2), and the basis there
        W_p (k, 3, r)."""
        pts = self._points(q, st)
        E, g, H = self.point_evaluations.evaluate(pts, pts.positions(q), st.h_eff, order)
        return E, g, H, pts.Wp

    def energy(self, q: np.ndarray, st: ReducedStep) -> float:
        """E(q) [J] of the step's incremental potential (up to a constant): the body terms' reduced energies, then
        the point terms at the sample points. With the contact candidates on, every term is evaluated to second
        order (`evaluate`; the energy is the same at any order, summed in the same order): the line search nearly
        always accepts its first trial point (2% of the iterations halve on quick), and the Newton loop then asks
        for the gradient and Hessian there, which `evaluate` keeps."""
        if self.contact_candidates:
            return self.evaluate(q, st)[0]
        E = self._body_terms(q, st, 0)[0]
        if self.point_terms:
            E += self._point_terms(q, st, 0)[0]
        return E

    def _body_terms(self, q: np.ndarray, st: ReducedStep, order: int) -> tuple[float, np.ndarray, np.ndarray]:
        """The body terms' energy [J] and, to `order`, gradient (r,) [N] and PSD-projected Hessian (r, r) [N/m]
        (zeros below it), the energies summed in the terms' order. The terms at the cubature tets
        (`CubatureEvaluation`: elasticity, viscosity) share one F_c(q), and their stresses and Hessian factors are
        summed per tet and pulled back once (`Subspace.pull_back`), after the others' reduced values; under
        `hessian_refresh = "step"` their Hessian is the one kept from the step's first second-order evaluation
        (`HESSIAN_REFRESHES`)."""
        rm = self.reduced
        E, g, H = 0.0, np.zeros(rm.r), np.zeros((rm.r, rm.r))
        F, P, factors = None, None, []
        kept = self._kept if order == 2 and self._kept is not None and self._kept[0] == self._steps else None
        for body in self.body_evaluations:
            if isinstance(body, CubatureEvaluation):
                F = rm.deformation_gradients(q) if F is None else F
                density, Pt, Lt = body.at_tets(F, st, MODES[1 if kept else order])
                E += float(rm.wV @ density)
                P = Pt if P is None else P + Pt
                if Lt is not None:
                    factors.append(Lt)
                continue
            Et, gt, Ht = body.reduced(q, st, order)
            E += Et
            if gt is not None:
                g = g + gt
            if Ht is not None:
                H = H + Ht
        gc, Hc = rm.pull_back(P, factors)
        if kept:
            Hc = kept[1]
        elif order == 2 and self.hessian_refresh == "step":
            self._kept = self._steps, Hc
        return E, g if gc is None else g + gc, H if Hc is None else H + Hc

    def gradient_hessian(self, q: np.ndarray, st: ReducedStep) -> tuple[np.ndarray, np.ndarray]:
        """dE/dq (r,) [N] and the PSD-projected d2E/dq2 (r, r) [N/m] (`evaluate`)."""
        return self.evaluate(q, st)[1:]

    def evaluate(self, q: np.ndarray, st: ReducedStep) -> tuple[float, np.ndarray, np.ndarray]:
        """E(q) [J], dE/dq (r,) [N] and the PSD-projected d2E/dq2 (r, r) [N/m]: every term to second order, the
        point terms' per-point gradients and Hessian blocks reduced by the basis at their points. The last result
        is kept and returned again for the same step and the same q, bit for bit."""
        memo = self._memo
        if memo is not None and memo[0] is st and memo[1] == q.tobytes():
            return memo[2]
        rm = self.reduced
        E, g, H = self._body_terms(q, st, 2)
        if self.point_terms:
            Ep, gp, Hp, Wp = self._point_terms(q, st, 2)
            E += Ep
            g = g + Wp.reshape(-1, rm.r).T @ gp.ravel()
            if not self.contact_candidates:  # all the sample points, most out of contact: the nonzero blocks only
                active = np.flatnonzero(Hp.any(axis=(1, 2)))
                Wp, Hp = Wp[active], Hp[active]
            if Wp.shape[0]:  # the candidates are near the plane: nearly all in contact; a zero block adds zeros
                H = H + Wp.reshape(-1, rm.r).T @ np.matmul(Hp, Wp).reshape(-1, rm.r)
        self._memo = st, q.tobytes(), (E, g, H)
        return E, g, H

    # ----- one time step ----------------------------------------------------------------------------------
    def _lag_points(self, q: np.ndarray, q_lag: np.ndarray, q_gates: tuple[np.ndarray, ...] = ()
                    ) -> np.ndarray | None:
        """The sample points where the step's lag can be nonzero (k,) (None: all points, with the candidates off):
        those whose signed distance at the start q, at the lag q_lag or at an earlier lag of the step (q_gates) is
        below the terms' largest `Term.lag_reach` (at least the plane, for the gate), plus CANDIDATE_MARGIN L of
        round-off. Elsewhere the lagged pressure is 0, the gate and every term's lagged support False."""
        if self._lag_below is None:
            return None
        near = self.reduced.N @ q < self._lag_below
        for other in (() if q_lag is q else (q_lag,)) + q_gates:
            near |= self.reduced.N @ other < self._lag_below
        return np.flatnonzero(near)

    def _begin(self, latent: ReducedState, h: float, previous: ReducedState | None = None,
               lag_at: tuple[np.ndarray, np.ndarray] | None = None, q_gates: tuple[np.ndarray, ...] = ()
               ) -> ReducedStep:
        """Per-step constants of the model's integrator, with `previous` the latent state before (the history
        `Integrator.previous` picked; None: none); what the terms lag (`Term.begin_step`: friction's normal pressure;
        the contact-damping gate) at the contact points of the latent coordinates and rates `lag_at` = (q, qdot)
        (None: the start of the step, `contact.lag = "start"`), with the gate below the plane at the step's earlier
        lags q_gates too, computed at the points where it can be nonzero (`_lag_points`)."""
        m, rm = self.model, self.reduced
        lag = self.integrator.lagged(latent.q, latent.qdot, h, None if previous is None else
                                     (previous.q, previous.qdot, latent.t - previous.t))
        q_lag, qdot_lag = (latent.q, latent.qdot) if lag_at is None else lag_at
        ids = self._lag_points(latent.q, q_lag, q_gates)
        Xp, Wp = rm.point_rows(ids)
        x_start = _positions(Xp, Wp, latent.q)
        x_lag = x_start if q_lag is latent.q else _positions(Xp, Wp, q_lag)
        v = (Wp.reshape(-1, rm.r) @ qdot_lag).reshape(-1, 3)
        fn, gate, x_gate = lagged_contact(self.terms, m, x_lag, v, _lowest(m, Xp, Wp, x_start, q_gates))
        lagged = None
        for term in self.point_terms:
            support = term.lagged_support(m, x_gate, fn)
            if support is not None:
                lagged = support if lagged is None else lagged | support
        if ids is not None:
            fn, gate, lagged = (None if a is None else _scatter(a, ids, rm.points.size) for a in (fn, gate, lagged))
        return ReducedStep(h, lag.h_eff, latent.q, lag.y_bar, lag.y_tilde, q_lag, fn, gate, lagged, q_gates)

    @staticmethod
    def newton_solve(H: np.ndarray, g: np.ndarray) -> np.ndarray:
        """The Newton step -H^-1 g (r,) of the PSD-projected Hessian H (r, r) [N/m] and gradient g (r,) [N]:
        LAPACK's Cholesky (potrf, potrs) as `cho_factor` and `cho_solve` call it, with their finiteness checks, but
        without their per-call overhead (a third of an r = 24 solve)."""
        c, info = dpotrf(np.asarray_chkfinite(H), lower=0, clean=0)
        if info != 0:
            raise np.linalg.LinAlgError(f"reduced Hessian: the {info}-th leading minor is not positive definite")
        return dpotrs(c, -np.asarray_chkfinite(g), lower=0)[0]

    def _velocity_norm(self, dq: np.ndarray, h: float) -> float:
        """|W dq|_inf / h over all mesh vertices [m/s]."""
        return float(np.abs(self.reduced.W.reshape(-1, self.reduced.r) @ dq).max()) / h

    @staticmethod
    def _initial_guess(st: ReducedStep, problem: _StepProblem) -> np.ndarray:
        """q_hat, shortened by the step's feasible-step rule (the barrier law: no contact point crosses the plane)."""
        return st.q_prev + problem.max_step(st.q_prev, st.q_hat - st.q_prev) * (st.q_hat - st.q_prev)

    def _newton(self, st: ReducedStep, q0: np.ndarray | None = None, max_iter: int | None = None) -> NewtonResult:
        """Minimise E by the shared Newton loop (`solvers.newton_method`) from q0 (None: `_initial_guess`), at most
        max_iter iterations (None: the solver's)."""
        problem = _StepProblem(self, st, self.tol * self.model.L)
        res = minimise(problem, self._initial_guess(st, problem) if q0 is None else q0, problem.tol_v,
                       max_iter or self.max_iter, LineSearch(self.armijo, self.max_halvings))
        if problem.bounded_dq is not None:  # the loop stopped unconverged on a bound: report the exact norm
            res = replace(res, residual=self._velocity_norm(problem.bounded_dq, st.h_eff))
        return res

    def _sample_gradient_rhs(self, q: np.ndarray, st: ReducedStep) -> np.ndarray:
        """sum_i W_i^T g_i over the sample points: g_i the full-space gradient of E at the decoded points [N]."""
        rm, pts = self.reduced, self.samples
        Wv = rm.W[pts.vertices]
        u, u_hat = (Wv.reshape(-1, rm.r) @ q).reshape(-1, 3), (Wv.reshape(-1, rm.r) @ st.q_hat).reshape(-1, 3)
        grad = np.zeros_like(u)
        for body in self.body_evaluations:
            grad += body.sample_gradient(q, st, u, u_hat)
        rhs = Wv.reshape(-1, rm.r).T @ grad.ravel()
        if self.point_terms:
            _, gp, _, Wp = self._point_terms(q, st, 1)
            rhs += Wp.reshape(-1, rm.r).T @ gp.ravel()
        return rhs

    def _projected_gradient(self, st: ReducedStep, q0: np.ndarray | None = None, max_iter: int | None = None
                            ) -> NewtonResult:
        """The paper's scheme (no line search: halvings, linear iterations and stalls are 0) from q0 (None:
        `_initial_guess`), at most max_iter iterations (None: the solver's)."""
        problem = _StepProblem(self, st, self.tol * self.model.L)
        q = self._initial_guess(st, problem) if q0 is None else q0
        tol_v = self.tol * self.model.L
        residual, it = np.inf, 0
        for it in range(1, (max_iter or self.max_iter) + 1):
            rhs = self.alpha * st.h_eff**2 * self._sample_gradient_rhs(q, st)
            dq = -cho_solve(self.samples.S_cho, rhs, check_finite=False)
            dq *= problem.max_step(q, dq)
            q = q + dq
            residual = self._velocity_norm(dq, st.h_eff)
            if residual < tol_v and not self.fixed_iterations:
                return NewtonResult(q, it, residual, 0, 0, 0, True)
        return NewtonResult(q, it, residual, 0, 0, 0, self.fixed_iterations)

    def projected_gradient_alpha_limit(self, state: State, dt: float) -> float:
        """Largest stable step size alpha of the projected-gradient scheme at `state` (projected to the subspace):
        2 / lambda_max(h^2 S^-1 H), H the PSD-projected Hessian of the scheme's incremental potential (inertia
        S / h^2 on the sample points) at q_hat, for a backward-Euler step of h = dt. Above it the iteration diverges
        along the stiffest mode; below it the softest mode converges like (1 - alpha)^k. A BDF2 step (h = h_eff =
        2/3 dt) has a larger limit: in h^2 S^-1 H the inertial part stays the identity and the rest shrinks."""
        rm = self.reduced
        samples = self.samples if self.samples is not None else _SamplePoints.build(rm)
        latent = ReducedState(rm.project(state.x - self.model.X), rm.project(state.v), state.t)
        st = self._begin(latent, dt)
        H = self.gradient_hessian(st.q_hat, st)[1] + (samples.S - rm.M_r) / st.h_eff**2
        return 2.0 / float(eigh(st.h_eff**2 * H, samples.S, eigvals_only=True)[-1])

    def step(self, state_in: State, state_out: State, dt: float) -> StepStats:
        """Advance state_in by dt into state_out (x = X + W q, v = W qdot); returns the step's statistics
        (`iterations` counts the iterations of either scheme; its counters are 0 for the projected gradient)."""
        t0 = time.perf_counter()
        self._steps += 1
        if state_in.q is None:
            state_in = self.project(state_in)
        latent = ReducedState(state_in.q, self.velocity_scale * state_in.qdot, state_in.t)
        prev = self.integrator.previous(state_in, dt)
        previous = None if prev is None or prev.q is None else ReducedState(prev.q, prev.qdot, prev.t)
        step = _LaggedStep(self, latent, dt, previous)
        res, counters = solve_lagged(step, self.contact_lag, latent.q, latent.qdot)
        q = res.y
        out = self.decode(ReducedState(q, step.velocity(q), latent.t + dt))
        state_out.x, state_out.v, state_out.t, state_out.q, state_out.qdot = out.x, out.v, out.t, out.q, out.qdot
        state_out.previous = state_in.without_history()
        return res.step_stats(time.perf_counter() - t0, **counters)


@dataclass
class _LaggedStep:
    """One step of dt [s] of a `ReducedSolver` from `latent` (with the history `previous`) for
    `solvers.step.solve_lagged`; `st` the step's constants at the current lag."""

    solver: ReducedSolver
    latent: ReducedState
    dt: float
    previous: ReducedState | None
    st: ReducedStep | None = None

    def relag(self, q_lag: np.ndarray, qdot_lag: np.ndarray) -> tuple[np.ndarray | None, np.ndarray]:
        """The step's constants with the lag at latent coordinates q_lag and rates qdot_lag (r,), the gate below
        the plane at the step's earlier lags too."""
        earlier = () if self.st is None or self.st.q_lag is self.latent.q else self.st.q_gates + (self.st.q_lag,)
        self.st = self.solver._begin(self.latent, self.dt, self.previous, (q_lag, qdot_lag), earlier)
        return self.st.fn, self.st.gate

    def newton(self, q0: np.ndarray | None, max_iter: int | None = None) -> NewtonResult:
        """The solver's scheme from q0 (None: its initial guess), at most max_iter iterations (None: the
        solver's)."""
        sv = self.solver
        return (sv._newton if sv.scheme == "newton" else sv._projected_gradient)(self.st, q0, max_iter)

    def velocity(self, q: np.ndarray) -> np.ndarray:
        """The latent rate (q - q_bar) / h_eff (r,) of end-of-step coordinates q."""
        return (q - self.st.q_bar) / self.st.h_eff


class _StepProblem(StepProblem):
    """One reduced step (`solvers.step.StepProblem`) over the latent coordinates q (r,), converged when the step
    norm is below tol_v [m/s]."""

    def __init__(self, solver: ReducedSolver, st: ReducedStep, tol_v: float) -> None:
        super().__init__(solver.model, solver.terms)
        self.solver, self.st, self.tol_v = solver, st, tol_v
        self.bounded_dq: np.ndarray | None = None  # the step whose norm the last `step_norm` bounded

    def energy(self, q: np.ndarray) -> float:
        """E(q) [J]."""
        return self.solver.energy(q, self.st)

    def direction(self, q: np.ndarray) -> Direction:
        """Newton direction from the PSD-projected dense Hessian (Cholesky)."""
        g, H = self.solver.gradient_hessian(q, self.st)
        dq = self.solver.newton_solve(H, g)
        return Direction(dq, float(g @ dq))

    def step_norm(self, dq: np.ndarray) -> float:
        """|W dq|_inf / h_eff over all mesh vertices [m/s], or a bound of it that decides the convergence test the
        same for a fraction of the product: where the EXTREME_ROWS rows of W with the largest norms alone reach
        the tolerance tol_v [m/s], their maximum (a lower bound: not converged; the step is kept in `bounded_dq`
        for its exact norm, should the loop stop on it); where max(that, W_rest_norm |dq| / h_eff) stays below the
        tolerance, that (an upper bound: converged, and the step's reported residual)."""
        rm, h = self.solver.reduced, self.st.h_eff
        lower = float(np.abs(rm.W_extreme @ dq).max()) / h
        if lower >= self.tol_v:
            self.bounded_dq = dq
            return lower
        self.bounded_dq = None
        upper = max(lower, rm.W_rest_norm * float(np.linalg.norm(dq)) / h)
        return upper if upper < self.tol_v else self.solver._velocity_norm(dq, h)

    def contact_points(self, q: np.ndarray, dq: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """The contact sample points X_p + W_p q and their displacements W_p dq, (p, 3) [m]."""
        rm = self.solver.reduced
        return rm.point_positions(q), (rm.Wp.reshape(-1, rm.r) @ dq).reshape(-1, 3)

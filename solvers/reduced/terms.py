"""The reduced backend's evaluation of the physics terms in the latent coordinates of a
`solvers.reduced.solver.ReducedSolver`, derived from what each term declares (`solvers.physics.terms`).

A body term (`solvers.physics.terms.BodyTerm`) gets one `BodyEvaluation` (`body_evaluation`): a `VertexTerm`
(inertia, gravity) in closed form with the reduced mass M_r = W^T M W (`VertexEvaluation`); a `DensityTerm` that
names a cubature kernel (elasticity, viscosity) at the cubature tets (`KernelCubatureEvaluation`, a
`CubatureEvaluation`: the solver sums the per-tet values of every such term before one reduction to the latent
coordinates); any other from its numpy reference (`ReferenceEvaluation`): exact, but a full-mesh evaluation per
call.

The point terms (`solvers.physics.terms.PointTerm`: contact, damping, friction) are evaluated at the contact sample
points the solver picks (`PointEvaluations`): each by its `PointLaunch` (`point_launch`), a term that names a warp
kernel by it (the full-space solver's kernels, on the CPU, into shared buffers: one launch per term,
`KernelLaunch`), any other by its numpy `at_points` (`ReferencePointLaunch`)."""

from __future__ import annotations

from abc import ABC, abstractmethod
from typing import TYPE_CHECKING

import numpy as np
import warp as wp

from frictionbench.solvers import kernels as shared
from frictionbench.solvers.physics.terms import DensityTerm, Evaluation, PointTerm, StepData, Term, VertexTerm
from frictionbench.solvers.reduced import kernels as K
from frictionbench.solvers.warp_runtime import RecordedLaunch, init_warp, kernel_inputs, kernel_named

if TYPE_CHECKING:
    from frictionbench.solvers.reduced.solver import ReducedSolver, ReducedStep, _PointSet


class BodyEvaluation(ABC):
    """A body term in the latent coordinates; see the module docstring."""

    def __init__(self, rs: ReducedSolver, term: Term) -> None:
        self.rs, self.term = rs, term

    @abstractmethod
    def reduced(self, q: np.ndarray, st: ReducedStep, order: int) -> Evaluation:
        """Energy [J], gradient (r,) [N] (order >= 1) and Hessian (r, r) [N/m] (order 2, None where it is zero)
        at latent coordinates q (r,), with the reduced step's constants st."""

    @abstractmethod
    def sample_gradient(self, q: np.ndarray, st: ReducedStep, u: np.ndarray, u_hat: np.ndarray) -> np.ndarray:
        """The full-space gradient (k, 3) [N] at the projected-gradient scheme's sample vertices, whose
        displacements are u and u_hat (k, 3) [m] at q and q_hat."""


class ReferenceEvaluation(BodyEvaluation):
    """Any body term from its numpy reference (`Term.energy`, `gradient`, `hessian`) at the decoded positions
    x = X + W q, with the step's constants decoded likewise (x_hat, x_lag and x_bar from q_hat, q^n and q_bar):
    E(x), W^T g and W^T H W, and at the projected-gradient scheme's sample vertices the full gradient's rows there.
    Exact, but slow: every call decodes q and evaluates the term over the full mesh (and the Hessian's product costs
    O(nnz(H) r + n r^2)); a term of a kind with an evaluation of its own (`body_evaluation`) is fast."""

    def __init__(self, rs: ReducedSolver, term: Term) -> None:
        super().__init__(rs, term)
        self._step: tuple[ReducedStep | None, StepData | None] = (None, None)  # the last step and its StepData

    def _positions(self, q: np.ndarray) -> np.ndarray:
        """X + W q (n, 3) [m]."""
        return self.rs.model.X + self.rs.reduced.decode(q)

    def _step_data(self, st: ReducedStep) -> StepData:
        """The full-space StepData of the reduced step st (decoded once per step)."""
        if self._step[0] is not st:
            self._step = st, StepData(self._positions(st.q_hat), self._positions(st.q_prev), st.h,
                                      x_bar=self._positions(st.q_bar), h_eff=st.h_eff)
        return self._step[1]

    def reduced(self, q: np.ndarray, st: ReducedStep, order: int) -> Evaluation:
        """E(X + W q), W^T g and W^T H W."""
        m, step, x = self.rs.model, self._step_data(st), self._positions(q)
        E = self.term.energy(m, step, x)
        if order == 0:
            return E, None, None
        Wf = self.rs.reduced.W.reshape(3 * m.n, -1)
        g = Wf.T @ self.term.gradient(m, step, x).ravel()
        return E, g, (Wf.T @ (self.term.hessian(m, step, x) @ Wf) if order == 2 else None)

    def sample_gradient(self, q: np.ndarray, st: ReducedStep, u: np.ndarray, u_hat: np.ndarray) -> np.ndarray:
        """The full gradient's rows at the sample vertices."""
        return self.term.gradient(self.rs.model, self._step_data(st), self._positions(q))[self.rs.samples.vertices]


def body_evaluation(rs: ReducedSolver, term: Term) -> BodyEvaluation:
    """The evaluation of the body term `term` on `rs`, by the term's kind and the kernels it names."""
    if isinstance(term, VertexTerm):
        return VertexEvaluation(rs, term)
    if isinstance(term, DensityTerm) and term.kernels is not None and term.kernels.cubature is not None:
        return KernelCubatureEvaluation(rs, term)
    return ReferenceEvaluation(rs, term)


class VertexEvaluation(BodyEvaluation):
    """A `VertexTerm` sum_i m_i (|x_i - y_i|^2 / (2 tau^2) - a . x_i) in the latent coordinates:
    (q - q_y)^T M_r (q - q_y) / (2 tau^2) - a_r . q with M_r = W^T M W, q_y the target's latent coordinates and the
    reduced force a_r = sum_i m_i W_i^T a (r,) [N], kept; tau^2 = inf: the linear part alone."""

    #: The latent coordinates of each target (`VertexTerm.target`) in a `ReducedStep`.
    TARGETS = {"x_hat": "q_hat", "x_lag": "q_prev", "x_bar": "q_bar"}

    def __init__(self, rs: ReducedSolver, term: VertexTerm) -> None:
        super().__init__(rs, term)
        self.a = term.acceleration(rs.model)
        self.a_r = np.einsum("n,nak,a->k", rs.model.mass, rs.reduced.W, self.a)
        self.target = self.TARGETS[term.target]

    def reduced(self, q: np.ndarray, st: ReducedStep, order: int) -> Evaluation:
        """(q - q_y)^T M_r (q - q_y) / (2 tau^2) - a_r . q, its gradient and Hessian M_r / tau^2."""
        tau2 = self.term.tau2(self.rs.model, st.h_eff, True)
        if not np.isfinite(tau2):
            return -float(self.a_r @ q), (-self.a_r if order >= 1 else None), None
        M_r, d = self.rs.reduced.M_r, q - getattr(st, self.target)
        E = 0.5 / tau2 * float(d @ M_r @ d) - float(self.a_r @ q)
        return E, (M_r @ d / tau2 - self.a_r if order >= 1 else None), (M_r / tau2 if order == 2 else None)

    def sample_gradient(self, q: np.ndarray, st: ReducedStep, u: np.ndarray, u_hat: np.ndarray) -> np.ndarray:
        """w_i ((u_i - u_y_i) / tau^2 - a) with the sample vertices' cubature masses w_i (u_y: u_hat for the target
        x_hat, else decoded)."""
        tau2 = self.term.tau2(self.rs.model, st.h_eff, True)
        w = self.rs.samples.weight[:, None]
        if not np.isfinite(tau2):
            return w * -self.a
        if self.target == "q_hat":
            u_y = u_hat
        else:
            u_y = self.rs.reduced.decode(getattr(st, self.target))[self.rs.samples.vertices]
        return w * ((u - u_y) / tau2 - self.a)


TetValues = tuple[np.ndarray, np.ndarray | None, np.ndarray | None]
"""A term at the cubature tets: its density (c,) [J/m^3], first Piola-Kirchhoff stress P (c, 3, 3) [Pa] (None
below `kernels.STRESS`) and density Hessian factor L (c, k, 9) [sqrt(Pa)], H9_c = L_c^T L_c (None below
`kernels.HESSIAN`)."""

MODES = (K.ENERGY, K.STRESS, K.HESSIAN)
"""The kernels' evaluation mode of each derivative order 0, 1, 2."""


class CubatureEvaluation(BodyEvaluation):
    """A body term given per cubature tet by a kernel of `solvers.reduced.kernels` at the tets' deformation
    gradients F_c(q) (`at_tets`). The solver sums the per-tet values of every such term of its scene at one F_c(q)
    and pulls the sums back to the latent coordinates once (`ReducedSolver.evaluate`, `Subspace.pull_back`);
    `reduced` is the term alone."""

    @abstractmethod
    def at_tets(self, F: np.ndarray, st: ReducedStep, mode: int) -> TetValues:
        """The term at the cubature tets' deformation gradients F (c, 3, 3), to `mode` (`kernels.ENERGY`, `STRESS`
        or `HESSIAN`), with the reduced step's constants st."""

    def reduced(self, q: np.ndarray, st: ReducedStep, order: int) -> Evaluation:
        """The cubature sum of this term alone: energy sum_c w_c V_c density_c, gradient and Hessian pulled back
        (`Subspace.pull_back`)."""
        rm = self.rs.reduced
        density, P, L = self.at_tets(rm.deformation_gradients(q), st, MODES[order])
        return (float(rm.wV @ density),) + rm.pull_back(P, None if L is None else [L])

    def sample_gradient(self, q: np.ndarray, st: ReducedStep, u: np.ndarray, u_hat: np.ndarray) -> np.ndarray:
        """The cubature tets' forces w_c V_c P_c g_a on their vertices."""
        rm = self.rs.reduced
        return self.rs.samples.forces(rm.wV, self.at_tets(rm.deformation_gradients(q), st, K.STRESS)[1])


class KernelCubatureEvaluation(CubatureEvaluation):
    """A `DensityTerm` by the cubature kernel it names (`TetKernels.cubature`, `kernels.evaluate`: one launch) with
    its `kernel_parameters` at the step's h_eff; a kernel that takes F_bar gets F_c(q_bar), computed once a step."""

    def __init__(self, rs: ReducedSolver, term: DensityTerm) -> None:
        super().__init__(rs, term)
        self.kernel = kernel_named(term.kernels.cubature, K.__name__)
        self.takes_bar = "F_bar" in (arg.label for arg in self.kernel.adj.args)
        self._bar: tuple[ReducedStep | None, np.ndarray | None] = (None, None)  # a step and its F_c(q_bar)

    def at_tets(self, F: np.ndarray, st: ReducedStep, mode: int) -> TetValues:
        rm, inputs = self.rs.reduced, {"F": F}
        if self.takes_bar:
            if self._bar[0] is not st:
                self._bar = st, rm.deformation_gradients(st.q_bar)
            inputs["F_bar"] = self._bar[1]
        return K.evaluate(self.kernel, inputs, self.term.kernel_parameters(self.rs.model, st.h_eff), mode,
                          self.term.kernels.rows, rm.device)


# ----- the point terms ---------------------------------------------------------------------------------------------
class PointEvaluations:
    """The point terms of a reduced solver at a set of its contact sample points, on the CPU.

    Buffers sized for all p sample points hold, in their first k rows, the evaluated points' positions x, their
    lagged x_lag and x_bar (k, 3) [m], area (k,) [m^2] and lagged pressure fn (k,) [Pa] (`load`), and receive the
    terms' energy [J], gradient (k, 3) [N] and Hessian blocks (k, 3, 3) [N/m], which every term adds into
    (`evaluate`). The warp arrays and their numpy views share memory."""

    def __init__(self, rs: ReducedSolver, terms: list[PointTerm]) -> None:
        init_warp()
        self.model, p = rs.model, rs.reduced.points.size
        self.x, self.x_lag, self.x_bar, self.grad = (wp.zeros(p, dtype=wp.vec3d, device="cpu") for _ in range(4))
        self.area, self.fn = (wp.zeros(p, dtype=wp.float64, device="cpu") for _ in range(2))
        self.values = wp.zeros(p, dtype=wp.mat33d, device="cpu")
        self.energy = wp.zeros(1, dtype=wp.float64, device="cpu")
        self.ids = wp.array(np.arange(p, dtype=np.int32), dtype=wp.int32, device="cpu")
        self.normal = wp.vec3d(*(rs.model.plane_normal if rs.model.plane_normal is not None else np.zeros(3)))
        self.views = {name: getattr(self, name).numpy()
                      for name in ("x", "x_lag", "x_bar", "grad", "area", "fn", "values", "energy")}
        self.launches = [point_launch(self, term) for term in terms]
        self._loaded: _PointSet | None = None  # the point set whose data the buffers hold
        self.k, self.has_fn = 0, False  # its size; whether it carries a lagged pressure

    def load(self, pts: _PointSet) -> None:
        """Put the point set's lagged data into the buffers (once per set)."""
        if pts is self._loaded:
            return
        v, k = self.views, pts.x_lag.shape[0]
        v["x_lag"][:k], v["x_bar"][:k], v["area"][:k] = pts.x_lag, pts.x_bar, pts.area
        v["fn"][:k] = 0.0 if pts.fn is None else pts.fn
        self._loaded, self.k, self.has_fn = pts, k, pts.fn is not None

    def evaluate(self, pts: _PointSet, x: np.ndarray, h: float, order: int
                 ) -> tuple[float, np.ndarray | None, np.ndarray | None]:
        """Energy [J], gradient (k, 3) [N] (order >= 1) and Hessian blocks (k, 3, 3) [N/m] (order 2; computed for
        order 1 too) of all the point terms at the points `pts` placed at x (k, 3) [m], h the effective step [s]."""
        self.load(pts)
        v, k = self.views, self.k
        v["x"][:k] = x
        v["energy"][0] = 0.0
        if order >= 1:
            v["grad"][:k], v["values"][:k] = 0.0, 0.0
        for launch in self.launches:
            launch.launch(self, h, 0 if order == 0 else 2)
        E = float(v["energy"][0])
        if order == 0:
            return E, None, None
        return E, v["grad"][:k].copy(), v["values"][:k].copy() if order == 2 else None


class PointLaunch(ABC):
    """One point term on `PointEvaluations`' buffers."""

    def __init__(self, points: PointEvaluations, term: PointTerm) -> None:
        self.term = term

    @abstractmethod
    def launch(self, p: PointEvaluations, h: float, mode: int) -> None:
        """Add the term at the buffers' first p.k points: mode 0 its energy, 2 its energy, gradient and Hessian; h the
        effective step [s]."""


class ReferencePointLaunch(PointLaunch):
    """Any point term from its numpy reference `PointTerm.at_points`."""

    def launch(self, p: PointEvaluations, h: float, mode: int) -> None:
        v, k = p.views, p.k
        E, g, H = self.term.at_points(p.model, v["x"][:k], v["x_lag"][:k], v["x_bar"][:k], v["area"][:k],
                                      v["fn"][:k] if p.has_fn else None, h, mode)
        v["energy"][0] += E
        if mode:
            v["grad"][:k] += g
            v["values"][:k] += H


class KernelLaunch(PointLaunch):
    """A point term by the warp kernel it names (`PointTerm.kernel`), its arguments by name from the buffers (the
    points and their diagonal blocks: the first k rows, `ids`), the term's `kernel_parameters`, h = 1 and mode = 0
    until a launch sets them: recorded once (`RecordedLaunch`) and relaunched on the first k points with the step h
    and the mode set."""

    def __init__(self, points: PointEvaluations, term: PointTerm) -> None:
        super().__init__(points, term)
        kernel = kernel_named(term.kernel, shared.__name__)
        p = points
        buffers = {"x": p.x, "x_lag": p.x_lag, "x_bar": p.x_bar, "points": p.ids, "area": p.area, "fn": p.fn,
                   "normal": p.normal, "diag": p.ids, "grad": p.grad, "values": p.values, "energy": p.energy,
                   "h": 1.0, "mode": 0}
        inputs = kernel_inputs(kernel, {**term.kernel_parameters(p.model), **buffers}, term.name)
        self.recorded = RecordedLaunch(kernel, 1, inputs, "cpu")
        labels = self.recorded.labels
        self.h_at, self.mode_at = labels.index("h") if "h" in labels else None, labels.index("mode")

    def launch(self, p: PointEvaluations, h: float, mode: int) -> None:
        if p.k == 0:
            return
        if self.h_at is not None:
            self.recorded.set(self.h_at, h)
        self.recorded.set(self.mode_at, mode)
        self.recorded.launch(p.k)


def point_launch(points: PointEvaluations, term: PointTerm) -> PointLaunch:
    """The launch of the point term `term` on `points`: by its kernel where it names one, else its reference."""
    return (KernelLaunch if term.kernel is not None else ReferencePointLaunch)(points, term)

"""The reduced backend's evaluation of the body terms (`solvers.physics.terms.BodyTerm`: inertia, gravity,
elasticity, viscosity) in the latent coordinates of a `solvers.reduced.solver.ReducedSolver`: one `BodyEvaluation`
per term class, in the table `EVALUATIONS` (`@EVALUATIONS.register(TermClass)`). A body term without an entry is
evaluated from its numpy reference (`ReferenceEvaluation`, the table's default): exact, but a full-mesh evaluation
per call; a dedicated evaluation makes it fast. A body term that is a density over the body (elasticity,
viscosity) is a `CubatureEvaluation`: a kernel gives its per-tet values at the cubature tets, and the solver sums
those of every such term before one reduction to the latent coordinates.

The point terms (`solvers.physics.terms.PointTerm`: contact, damping, friction) are evaluated at the contact sample
points the solver picks (`PointEvaluations`): each by its `PointLaunch` in the table `POINT_LAUNCHES`, the built-in
ones by the full-space solver's warp kernels (solvers/kernels.py, on the CPU, into shared buffers: one launch
per term), any other by its numpy `at_points` (`ReferencePointLaunch`, the table's default)."""

from __future__ import annotations

from abc import ABC, abstractmethod
from typing import TYPE_CHECKING

import numpy as np
import warp as wp

from frictionbench.solvers import kernels as shared
from frictionbench.solvers.physics.contact import BarrierContact, ContactDamping, PenaltyContact
from frictionbench.solvers.physics.friction import Friction
from frictionbench.solvers.physics.inertia import Gravity, Inertia
from frictionbench.solvers.physics.material import Elasticity
from frictionbench.solvers.physics.terms import Evaluation, PointTerm, StepData, Term, TermTable
from frictionbench.solvers.physics.viscosity import Viscosity
from frictionbench.solvers.reduced import kernels as K
from frictionbench.solvers.warp_runtime import RecordedLaunch, init_warp

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
    O(nnz(H) r + n r^2)); a dedicated `BodyEvaluation` in `EVALUATIONS` (as the built-in terms have) makes it fast."""

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


#: The reduced evaluation of each body term class (`EVALUATIONS.build(rs, body_terms)`: one per term; a term
#: without one gets `ReferenceEvaluation`).
EVALUATIONS: TermTable[BodyEvaluation] = TermTable("reduced evaluation (solvers.reduced.terms.EVALUATIONS)",
                                                   default=ReferenceEvaluation)


@EVALUATIONS.register(Inertia)
class _Inertia(BodyEvaluation):
    def reduced(self, q: np.ndarray, st: ReducedStep, order: int) -> Evaluation:
        """1/(2 h_eff^2) (q - q_hat)^T M_r (q - q_hat), M_r = W^T M W."""
        M_r, d, h = self.rs.reduced.M_r, q - st.q_hat, st.h_eff
        E = 0.5 / h**2 * float(d @ M_r @ d)
        return E, (M_r @ d / h**2 if order >= 1 else None), (M_r / h**2 if order == 2 else None)

    def sample_gradient(self, q: np.ndarray, st: ReducedStep, u: np.ndarray, u_hat: np.ndarray) -> np.ndarray:
        """w_i (u_i - u_hat_i) / h_eff^2 with the sample vertices' cubature masses w_i."""
        return self.rs.samples.weight[:, None] * ((u - u_hat) / st.h_eff**2)


@EVALUATIONS.register(Gravity)
class _Gravity(BodyEvaluation):
    """Keeps the reduced weight g_r = sum_i m_i W_i^T g (r,) [N]."""

    def __init__(self, rs: ReducedSolver, term: Term) -> None:
        super().__init__(rs, term)
        self.g_r = np.einsum("n,nak,a->k", rs.model.mass, rs.reduced.W, rs.model.gravity)

    def reduced(self, q: np.ndarray, st: ReducedStep, order: int) -> Evaluation:
        """-g_r . q."""
        return -float(self.g_r @ q), (-self.g_r if order >= 1 else None), None

    def sample_gradient(self, q: np.ndarray, st: ReducedStep, u: np.ndarray, u_hat: np.ndarray) -> np.ndarray:
        """-w_i g with the sample vertices' cubature masses w_i."""
        return self.rs.samples.weight[:, None] * -self.rs.model.gravity


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


@EVALUATIONS.register(Elasticity)
class _Elasticity(CubatureEvaluation):
    def at_tets(self, F: np.ndarray, st: ReducedStep, mode: int) -> TetValues:
        """Stable Neo-Hookean: Psi, P and the factor of (dP/dF)_+ (`kernels.snh_evaluate`, one launch)."""
        m = self.rs.model
        return K.snh_evaluate(F, m.mu_snh, m.lam_snh, mode, self.rs.reduced.device)


@EVALUATIONS.register(Viscosity)
class _Viscosity(CubatureEvaluation):
    def __init__(self, rs: ReducedSolver, term: Term) -> None:
        super().__init__(rs, term)
        self._bar: tuple[ReducedStep | None, np.ndarray | None] = (None, None)  # a step and its F_c(q_bar)

    def at_tets(self, F: np.ndarray, st: ReducedStep, mode: int) -> TetValues:
        """Kelvin-Voigt at F against F_c(q_bar) (computed once a step), c = eta / h_eff: the density, P and the
        15-row factor of its projected Hessian (`kernels.viscous_evaluate`, one launch)."""
        rm = self.rs.reduced
        if self._bar[0] is not st:
            self._bar = st, rm.deformation_gradients(st.q_bar)
        return K.viscous_evaluate(F, self._bar[1], self.rs.model.viscosity / st.h_eff, mode, rm.device)


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
        self.launches = POINT_LAUNCHES.build(self, terms)
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
    """A point term by a warp kernel of solvers/kernels.py whose arguments `inputs` names, recorded once
    (`RecordedLaunch`) and relaunched on the first k points with the step h and the mode set."""

    kernel: wp.Kernel

    def __init__(self, points: PointEvaluations, term: PointTerm) -> None:
        super().__init__(points, term)
        self.recorded = RecordedLaunch(self.kernel, 1, self.inputs(points), "cpu")
        labels = self.recorded.labels
        self.h_at, self.mode_at = labels.index("h") if "h" in labels else None, labels.index("mode")

    @abstractmethod
    def inputs(self, p: PointEvaluations) -> list:
        """The kernel's arguments on p's buffers (h = 1 and mode = 0 until a launch sets them)."""

    def launch(self, p: PointEvaluations, h: float, mode: int) -> None:
        if p.k == 0:
            return
        if self.h_at is not None:
            self.recorded.set(self.h_at, h)
        self.recorded.set(self.mode_at, mode)
        self.recorded.launch(p.k)


#: The point evaluation of each point term class (`POINT_LAUNCHES.build(points, point_terms)`; a term without one
#: gets `ReferencePointLaunch`).
POINT_LAUNCHES: TermTable[PointLaunch] = TermTable("reduced point launch (solvers.reduced.terms.POINT_LAUNCHES)",
                                                   default=ReferencePointLaunch)


@POINT_LAUNCHES.register(PenaltyContact, ContactDamping)
class _Penalty(KernelLaunch):
    kernel = shared.penalty_contact_kernel

    def inputs(self, p: PointEvaluations) -> list:
        m = p.model
        return [p.x, p.x_lag, p.x_bar, p.ids, p.area, p.normal, m.plane_offset, self.term.ke(m), self.term.kd(m), 1.0,
                p.ids, p.grad, p.values, p.energy, 0]


@POINT_LAUNCHES.register(BarrierContact)
class _Barrier(KernelLaunch):
    kernel = shared.barrier_contact_kernel

    def inputs(self, p: PointEvaluations) -> list:
        m, c = p.model, p.model.contact
        return [p.x, p.ids, p.area, p.normal, m.plane_offset, c.barrier_stiffness, c.barrier_distance, p.ids, p.grad,
                p.values, p.energy, 0]


@POINT_LAUNCHES.register(Friction)
class _Friction(KernelLaunch):
    kernel = shared.friction_kernel

    def inputs(self, p: PointEvaluations) -> list:
        m = p.model
        return [p.x, p.x_bar, p.ids, p.area, p.fn, p.normal, m.friction, m.contact.friction_stiffness, 1.0, p.ids,
                p.grad, p.values, p.energy, 0]

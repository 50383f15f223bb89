"""The reduced backend's evaluation of the body terms (`solvers.physics.terms.BodyTerm`: inertia, gravity,
elasticity, viscosity) in the latent coordinates of a `solvers.licrom.reduced.ReducedSolver`: one `BodyEvaluation`
per term class, in the table `EVALUATIONS` (`@EVALUATIONS.register(TermClass)`). A body term without an entry is
evaluated from its numpy reference (`ReferenceEvaluation`, the table's default): exact, but a full-mesh evaluation
per call; a dedicated evaluation makes it fast. The point terms (contact, damping, friction) need no entry: the
solver evaluates them at its contact sample points by their `at_points`."""

from __future__ import annotations

from abc import ABC, abstractmethod
from typing import TYPE_CHECKING

import numpy as np

from frictionbench.solvers.licrom import kernels as K
from frictionbench.solvers.physics.inertia import Gravity, Inertia
from frictionbench.solvers.physics.material import Elasticity
from frictionbench.solvers.physics.terms import Evaluation, StepData, Term, TermTable
from frictionbench.solvers.physics.viscosity import Viscosity, viscous_density, viscous_dpdf, viscous_stress

if TYPE_CHECKING:
    from frictionbench.solvers.licrom.reduced import ReducedSolver, ReducedStep


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
EVALUATIONS: TermTable[BodyEvaluation] = TermTable("reduced evaluation (solvers.licrom.terms.EVALUATIONS)",
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


@EVALUATIONS.register(Elasticity)
class _Elasticity(BodyEvaluation):
    def reduced(self, q: np.ndarray, st: ReducedStep, order: int) -> Evaluation:
        """The cubature elastic energy with its gradient and PSD-projected Hessian (`ReducedModel.elastic`)."""
        return self.rs.reduced.elastic(q, (K.ENERGY, K.STRESS, K.HESSIAN)[order])

    def sample_gradient(self, q: np.ndarray, st: ReducedStep, u: np.ndarray, u_hat: np.ndarray) -> np.ndarray:
        """The cubature tets' elastic forces w_c V_c P_c g_a on their vertices."""
        m, rm = self.rs.model, self.rs.reduced
        _, P, _ = K.snh_evaluate(rm.deformation_gradients(q), m.mu_snh, m.lam_snh, K.STRESS, rm.device)
        return self.rs.samples.forces(rm.wV, P)


@EVALUATIONS.register(Viscosity)
class _Viscosity(BodyEvaluation):
    def reduced(self, q: np.ndarray, st: ReducedStep, order: int) -> Evaluation:
        """The cubature sum at F_c(q) against F_c(q_bar): energy, gradient B^T (w V P) and Hessian B^T (w V H9) B."""
        rm, c = self.rs.reduced, self.rs.model.viscosity / st.h_eff
        F, F_bar = rm.deformation_gradients(q), rm.deformation_gradients(st.q_bar)
        E = float(rm.wV @ viscous_density(F, F_bar, c))
        if order == 0:
            return E, None, None
        return (E,) + rm.pull_back(viscous_stress(F, F_bar, c), viscous_dpdf(F, F_bar, c) if order == 2 else None)

    def sample_gradient(self, q: np.ndarray, st: ReducedStep, u: np.ndarray, u_hat: np.ndarray) -> np.ndarray:
        """The cubature tets' viscous forces w_c V_c P_c g_a on their vertices."""
        rm = self.rs.reduced
        P = viscous_stress(rm.deformation_gradients(q), rm.deformation_gradients(st.q_bar),
                           self.rs.model.viscosity / st.h_eff)
        return self.rs.samples.forces(rm.wV, P)

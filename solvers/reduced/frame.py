"""Deformation modes in the body's frame (a floating frame of reference, as flexible multibody codes use): the
configuration x = c + R (X - C + U q_d) of a body whose deformation U q_d is expressed in its own frame and carried
by its rotation R (docs/solvers.md, "Modes in the body's frame").

With the 12 affine fields A among the columns, every such configuration at a fixed R lies in the linear subspace of
W(R) = [A, R U]: the rigid part c - R C + (R - I) X is affine in X. So `FrameSolver` steps the linear machinery of
`ReducedSolver` unchanged in W(R), the frame held for a step, and turns the frame with the body: at the start of a
step where the body's rotation (`body_rotation`, the shape-matching rotation of its positions) has left the frame by
more than `frame_angle`, the basis becomes W(R_now) and the state (with the history a multistep integrator keeps) is
projected onto it (mass-weighted least squares). Between re-frames the modes are at most `frame_angle` behind the
body, an error of at most that angle times the deformation's size; each re-frame drops the part of the deformation
that turning it leaves outside the new subspace, of the same order.

Training data for such modes is taken in the body's frame too (`body_frame_displacements`: each frame turned back
by its own rotation and centred), so that the modes hold deformation only, whichever way the body faced.
"""

from __future__ import annotations

import time

import numpy as np

from frictionbench.solvers.model import Model, State
from frictionbench.solvers.reduced.bases import (N_AFFINE, affine_basis, body_rotation, project, rotated_basis,
                                                 rotation_angle)
from frictionbench.solvers.reduced.solver import ReducedSolver
from frictionbench.solvers.step_stats import StepStats

#: Largest angle [rad] the body may turn away from its frame before the frame follows it (`FrameSolver`).
FRAME_ANGLE = 0.05

#: The angle [rad] below which a projected state's rotation is taken as the frame's (`FrameSolver.project`): the
#: round-off of a rotation computed from positions.
START_ANGLE = 1e-9

#: Relative residual of the affine fields' projection onto the first 12 columns below which they span them.
AFFINE_SPAN_TOL = 1e-8


def check_affine_columns(W: np.ndarray, X: np.ndarray) -> None:
    """ValueError unless the first 12 columns of W (n, 3, r) span the affine fields of the rest positions X (n, 3)."""
    if W.shape[2] < N_AFFINE:
        raise ValueError(f"a basis of {W.shape[2]} columns: modes in the body's frame need the 12 affine fields first")
    A = affine_basis(X)
    fit = np.einsum("nak,sk->nas", W[:, :, :N_AFFINE], project(W[:, :, :N_AFFINE], A.transpose(2, 0, 1)))
    if np.linalg.norm(fit - A) > AFFINE_SPAN_TOL * np.linalg.norm(A):
        raise ValueError("the basis's first 12 columns do not span the affine fields: modes in the body's frame need "
                         "them (a POD basis with affine = true, a modal basis)")


class FrameSolver(ReducedSolver):
    """`ReducedSolver` in the subspace W(R) of a body-frame basis W (n, 3, r) (first the affine fields, then the
    deformation modes in the body's frame), the frame R following the body (module doc). frame_angle [rad]: how far
    the body may turn from its frame before the frame follows it; the other arguments are `ReducedSolver`'s.
    `reframes` counts the frame's turns, `reframe_s` their time [s] (inside the steps' time)."""

    def __init__(self, model: Model, W: np.ndarray, *args, frame_angle: float = FRAME_ANGLE, **kwargs) -> None:
        if isinstance(frame_angle, bool) or not isinstance(frame_angle, (int, float)) or not 0.0 <= frame_angle < np.pi:
            raise ValueError(f"frame_angle = {frame_angle!r}: expected an angle in [0, pi) [rad]")
        check_affine_columns(W, model.X)
        self.body_basis, self.frame_angle = np.ascontiguousarray(W, dtype=np.float64), float(frame_angle)
        self.frame = np.eye(3)
        self.reframes, self.reframe_s = 0, 0.0
        super().__init__(model, W, *args, **kwargs)

    def _follow(self, x: np.ndarray, angle: float | None = None) -> bool:
        """Turn the frame to the body's rotation at positions x (n, 3) [m] if it has left the frame by more than
        `angle` [rad] (None: frame_angle); whether it did."""
        R = body_rotation(self.model.X, x, self.model.mass)
        if rotation_angle(self.frame, R) <= (self.frame_angle if angle is None else angle):
            return False
        t0 = time.perf_counter()
        self.frame = R
        self.use_basis(rotated_basis(self.body_basis, R))
        self.reframes += 1
        self.reframe_s += time.perf_counter() - t0
        return True

    def project(self, state: State) -> State:
        """The state with its latent coordinates in the frame of its rotation (the frame turned to it first, unless
        within START_ANGLE), and its `previous` likewise in the same basis: a run starts in the body's frame."""
        self._follow(state.x, START_ANGLE)
        return self._projected(state)

    def _projected(self, state: State) -> State:
        """`state` and its `previous` projected onto the current basis."""
        rm = self.reduced
        prev = state.previous
        return State(state.x, state.v, state.t, rm.project(state.x - self.model.X), rm.project(state.v),
                     None if prev is None else self._projected(prev.without_history()))

    def step(self, state_in: State, state_out: State, dt: float) -> StepStats:
        """One step in the current frame, turned to the body first where it has left it (module doc)."""
        if state_in.q is None or self._follow(state_in.x):
            state_in = self._projected(state_in)
        return super().step(state_in, state_out, dt)

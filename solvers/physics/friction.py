"""Coulomb friction against the plane as a lagged dissipative potential (IPC's treatment, docs/physics.md "Friction").

Per point with area A and lagged normal pressure f_n (from the start of the step):
D = A h mu f_n f0(|v_t|), v_t = T (x - x^n) / h, T = I - n n^T, with f0' = f1, f1(s) = min(s / eps_v, 1),
eps_v = mu f_n / k_f. So the force is -A min(k_f |v_t|, mu f_n) v_t / |v_t|: viscous (k_f) below eps_v,
Coulomb above. f0(s) = s^2 / (2 eps_v) for s < eps_v, s - eps_v / 2 beyond. A body that should stick creeps
at the speed (tangential load per area) / k_f. With BDF2, x^n and h are the integrator's x_bar and effective step h_eff
(`solvers.integrators`): the functions below take them as x_prev and h.
Arrays: x, x_prev (p, 3), area (p,) [m^2], fn (p,) [Pa]; energies J, gradients (p, 3) N, Hessians (p, 3, 3).
`Friction` is the term at a model's contact points.
"""

from __future__ import annotations

import numpy as np

from frictionbench.solvers.model import Model
from frictionbench.solvers.physics.contact import lagged_pressure
from frictionbench.solvers.physics.terms import Evaluation, PointTerm, register


def f0(s: np.ndarray, eps_v: np.ndarray) -> np.ndarray:
    """Friction potential profile f0(s) [m/s]: s^2/(2 eps_v) below eps_v, s - eps_v/2 above."""
    return np.where(s < eps_v, 0.5 * s**2 / eps_v, s - 0.5 * eps_v)


def f1_over_s(s: np.ndarray, eps_v: np.ndarray) -> np.ndarray:
    """f1(s)/s = 1/eps_v below eps_v, 1/s above [s/m]."""
    return np.where(s < eps_v, 1.0 / eps_v, 1.0 / np.maximum(s, 1e-300))


def slip_velocity(x, x_prev, normal, h) -> np.ndarray:
    """Tangential velocity v_t = T (x - x^n) / h, (p, 3) [m/s]."""
    v = (x - x_prev) / h
    return v - np.outer(v @ normal, normal)


def friction_potential(x, x_prev, area, fn, normal, mu, kf, h, order: int = 2) -> Evaluation:
    """D = sum A h mu f_n f0(|v_t|) [J] (points with f_n = 0 contribute nothing); its gradient
    dD/dx = A mu f_n (f1(s)/s) v_t (p, 3) [N] (order >= 1; the friction force is its negative) and PSD Hessian
    blocks (p, 3, 3) [N/m] (order 2): A k_f / h T below eps_v, A mu f_n / (h s) (T - t t^T) above. One pass: the
    slip velocity and eps_v are computed once for all three."""
    vt = slip_velocity(x, x_prev, normal, h)
    s = np.linalg.norm(vt, axis=1)
    eps = np.maximum(mu * fn / kf, 1e-300)
    E = float(np.sum(area * h * mu * fn * f0(s, eps)))
    if order == 0:
        return E, None, None
    g = (area * mu * fn * f1_over_s(s, eps))[:, None] * vt
    if order == 1:
        return E, g, None
    T = np.eye(3) - np.outer(normal, normal)
    t = vt / np.maximum(s, 1e-300)[:, None]
    slow = s < eps
    k_slow = area * mu * fn / eps / h
    k_fast = area * mu * fn / (h * np.maximum(s, 1e-300))
    H = np.where(slow[:, None, None], k_slow[:, None, None] * T,
                 k_fast[:, None, None] * (T[None] - t[:, :, None] * t[:, None, :]))
    return E, g, H * (fn > 0)[:, None, None]


def friction_energy(x, x_prev, area, fn, normal, mu, kf, h) -> float:
    """The energy D of `friction_potential` [J]."""
    return friction_potential(x, x_prev, area, fn, normal, mu, kf, h, order=0)[0]


def friction_gradient(x, x_prev, area, fn, normal, mu, kf, h) -> np.ndarray:
    """The gradient dD/dx of `friction_potential`, (p, 3) [N]."""
    return friction_potential(x, x_prev, area, fn, normal, mu, kf, h, order=1)[1]


def friction_hessian(x, x_prev, area, fn, normal, mu, kf, h) -> np.ndarray:
    """The Hessian blocks of `friction_potential`, (p, 3, 3) [N/m]."""
    return friction_potential(x, x_prev, area, fn, normal, mu, kf, h, order=2)[2]


def creep_speed(area: np.ndarray, fn: np.ndarray, mu: float, kf: float, load: float) -> float:
    """The law's steady slip speed s [m/s] of a body held by friction: sum_i A_i min(k_f s, mu f_n,i) = load.

    area (p,) [m^2], fn (p,) [Pa] the contact points' normal pressures, load [N] the tangential force friction
    must carry (e.g. M |g_t|). The left side is piecewise linear and increasing in s with breakpoints
    eps_i = mu f_n,i / k_f, so s is exact. inf when even full Coulomb friction, mu sum A f_n, cannot carry the
    load (the body slides); 0 for no load.
    """
    if load <= 0.0:
        return 0.0
    eps = mu * fn / kf
    order = np.argsort(eps)
    eps, a, cap = eps[order], area[order], (area * mu * fn)[order]
    if cap.sum() <= load:
        return float("inf")
    # On [eps_(j-1), eps_j]: points below j are saturated (Coulomb), the rest viscous (k_f s).
    saturated = np.concatenate([[0.0], np.cumsum(cap)])[:-1]
    viscous_area = a.sum() - np.concatenate([[0.0], np.cumsum(a)])[:-1]
    s = (load - saturated) / (kf * viscous_area)
    lower = np.concatenate([[0.0], eps[:-1]])
    ok = (s >= lower) & (s <= eps)
    return float(s[np.argmax(ok)])


@register
class Friction(PointTerm):
    """The lagged Coulomb friction potential at the contact points (normal pressure `fn`)."""

    name = "friction"
    kernel = "friction_kernel"

    def kernel_parameters(self, model: Model) -> dict[str, float]:
        """The friction coefficient mu [-] and the stick stiffness k_f [Pa s/m]."""
        return {"mu": model.friction, "kf": model.contact.friction_stiffness}

    def applies(self, model: Model) -> bool:
        return model.has("friction")

    def begin_step(self, model: Model, x: np.ndarray, v: np.ndarray) -> np.ndarray:
        """The normal pressure of the scene's contact law at the start of the step (`lagged_pressure`) [Pa]."""
        c = model.contact
        return lagged_pressure(c.law, x, v, model.plane_normal, model.plane_offset, c.stiffness,
                               model.contact_damping, c.barrier_stiffness, c.barrier_distance)

    def at_points(self, model: Model, x: np.ndarray, x_lag: np.ndarray, x_bar: np.ndarray, area: np.ndarray,
                  fn: np.ndarray | None, h: float, order: int) -> Evaluation:
        """The potential with the integrator's velocity (x - x_bar) / h, h its effective step."""
        return friction_potential(x, x_bar, area, fn, model.plane_normal, model.friction,
                                  model.contact.friction_stiffness, h, order)

    def reach(self, model: Model) -> float:
        """Friction acts through the lagged pressure alone, never through the position."""
        return -np.inf

    def lagged_support(self, model: Model, x_lag: np.ndarray, fn: np.ndarray | None) -> np.ndarray | None:
        """The points with a positive lagged normal pressure (f_n = 0 zeroes the energy, gradient and Hessian)."""
        return fn > 0.0

    def lag_reach(self, model: Model) -> float:
        """The lagged pressure is zero on and above the plane (penalty) or from the activation distance on
        (barrier)."""
        c = model.contact
        return 0.0 if c.law == "penalty" else c.barrier_distance

"""Plane contact per unit surface area (docs/physics.md, "Contact with the plane"), evaluated at surface points
with area weights.

Plane: phi(x) = n . x - d (n unit). Penalty law (the paper's, from warp's soft contact): penetration
c = max(0, -phi), normal pressure k_e c + k_d max(0, -v.n), energy density 1/2 k_e c^2; the damping part is
the dissipative potential h k_d / 2 max(0, -v.n)^2 with v = (x - x^n)/h, active at the points that penetrate at
the start of the step (`damped`, lagged like friction's normal force, so that the step's potential stays
continuous; gating on the current penetration would make it jump where a point crosses the plane). With BDF2 the
velocity is the integrator's, v = (x - x_bar) / h_eff, and the potential h_eff k_d / 2 max(0, -v.n)^2
(`solvers.integrators`); the gate stays the penetration at the start of the step, x^n.
Barrier law (IPC): energy density kappa b(phi), b(d) = -(d - dhat)^2 log(d / dhat) for 0 < d < dhat, else 0.
Arrays: x (p, 3) point positions, area (p,) [m^2]; energies in J, gradients (p, 3) in N, Hessians (p, 3, 3).
The terms `PenaltyContact`, `ContactDamping` (the penalty law's damping part) and `BarrierContact` evaluate them
at a model's contact points.
"""

from __future__ import annotations

import numpy as np

from frictionbench.solvers.model import Model
from frictionbench.solvers.newton_method import feasible_step
from frictionbench.solvers.physics.terms import Evaluation, PointTerm, register


#: Penetration scale of the automatic penalty stiffness, as a fraction of the body size L.
AUTO_LAYER = 1.0e-3


def auto_penalty_stiffness(youngs_modulus: float, density: float, speed: float, L: float,
                           layer: float = AUTO_LAYER) -> float:
    """k_e = max(E, rho v^2) / (layer L) [Pa/m]: the contact layer is as stiff as a layer of the material (or, for
    an impact faster than the material's wave speed, as the ram pressure rho v^2 needs) `layer L` thick, so a
    contact pressure p penetrates p / k_e = layer L p / max(E, rho v^2), i.e. layer L times the strain it causes.
    E [Pa], density [kg/m^3], speed v [m/s] the fastest expected approach, L [m] the body's size."""
    return max(youngs_modulus, density * speed**2) / (layer * L)


def damping_for_ratio(zeta: float, ke: float, mass: np.ndarray, area: np.ndarray) -> float:
    """k_d [Pa s/m] that gives a contact vertex's oscillation the damping ratio zeta [-]: a vertex of lumped mass m
    [kg] and area weight a [m^2] on the plane is a mass on a spring k_e a [N/m] with a dashpot k_d a [N s/m], so
    zeta = k_d a / (2 sqrt(k_e a m)) and k_d = 2 zeta sqrt(k_e m / a), with m / a the median over the contact
    vertices (mass (p,), area (p,) > 0) and k_e [Pa/m] the penalty stiffness."""
    return 2.0 * zeta * float(np.sqrt(ke * np.median(mass / area)))


def signed_distance(x: np.ndarray, normal: np.ndarray, offset: float) -> np.ndarray:
    """phi(x) = n . x - d, shape (p,) [m]."""
    return x @ normal - offset


def damped_points(x_lag, normal, offset) -> np.ndarray:
    """Points whose contact damping is active during the step: penetrating at its start, (p,) bool."""
    return signed_distance(x_lag, normal, offset) < 0


def penalty_potential(x, x_lag, area, normal, offset, ke, kd, h, x_bar=None, order: int = 2) -> Evaluation:
    """The penalty law's energy, sum over points of A (1/2 k_e c^2 + h k_d / 2 max(0, -v.n)^2 [damped]) [J],
    v = (x - x_bar) / h (h the integrator's effective step, x_bar its lagged positions; None: x_lag, backward Euler);
    its gradient A (-k_e c + k_d min(0, v.n) [damped]) n (p, 3) [N] (order >= 1) and Hessian blocks
    A (k_e [c > 0] + k_d / h [damped, v.n < 0]) n n^T (p, 3, 3) [N/m] (order 2), from one pass over the points.
    A part whose coefficient (k_e or k_d) is 0 is left out (it adds exact zeros)."""
    zero = np.zeros(x.shape[0])
    e = force = k = zero
    if ke != 0.0:
        phi = signed_distance(x, normal, offset)
        c = np.maximum(0.0, -phi)
        e = e + 0.5 * ke * c**2
        if order >= 1:
            force, k = force - ke * c, k + ke * (-phi > 0)
    if kd != 0.0:
        damped = damped_points(x_lag, normal, offset)
        vraw = (x - (x_lag if x_bar is None else x_bar)) @ normal / h
        vn = np.minimum(0.0, vraw) * damped  # min(0, v.n) at the damped points, 0 elsewhere [m/s]
        e = e + 0.5 * h * kd * vn**2
        if order >= 1:
            force, k = force + kd * vn, k + kd / h * (damped & (vraw < 0))
    E = float(area @ e)
    g = (area * force)[:, None] * normal[None, :] if order >= 1 else None
    return E, g, (area * k)[:, None, None] * np.outer(normal, normal)[None] if order == 2 else None


def penalty_energy(x, x_lag, area, normal, offset, ke, kd, h, x_bar=None) -> float:
    """The energy of `penalty_potential` [J]."""
    return penalty_potential(x, x_lag, area, normal, offset, ke, kd, h, x_bar, order=0)[0]


def penalty_gradient(x, x_lag, area, normal, offset, ke, kd, h, x_bar=None) -> np.ndarray:
    """The gradient of `penalty_potential`, (p, 3) [N]."""
    return penalty_potential(x, x_lag, area, normal, offset, ke, kd, h, x_bar, order=1)[1]


def penalty_hessian(x, x_lag, area, normal, offset, ke, kd, h, x_bar=None) -> np.ndarray:
    """The Hessian blocks of `penalty_potential`, (p, 3, 3) [N/m]."""
    return penalty_potential(x, x_lag, area, normal, offset, ke, kd, h, x_bar, order=2)[2]


def normal_pressure(x, v, normal, offset, ke, kd) -> np.ndarray:
    """Penalty normal force per unit area f_n = k_e c + k_d max(0, -v.n) while penetrating, (p,) [Pa]."""
    c = np.maximum(0.0, -signed_distance(x, normal, offset))
    return (ke * c + kd * np.maximum(0.0, -(v @ normal))) * (c > 0)


def barrier(d: np.ndarray, dhat: float) -> np.ndarray:
    """IPC barrier b(d) = -(d - dhat)^2 log(d / dhat) on (0, dhat), 0 beyond; +inf for d <= 0."""
    d = np.asarray(d, dtype=float)
    out = np.zeros_like(d)
    act = d < dhat
    with np.errstate(divide="ignore", invalid="ignore"):
        out[act] = np.where(d[act] > 0, -(d[act] - dhat) ** 2 * np.log(d[act] / dhat), np.inf)
    return out


def barrier_d1(d: np.ndarray, dhat: float) -> np.ndarray:
    """b'(d) = -2 (d - dhat) log(d/dhat) - (d - dhat)^2 / d on (0, dhat), 0 beyond."""
    d = np.asarray(d, dtype=float)
    act = (d < dhat) & (d > 0)
    out = np.zeros_like(d)
    dd = d[act]
    out[act] = -2.0 * (dd - dhat) * np.log(dd / dhat) - (dd - dhat) ** 2 / dd
    return out


def barrier_d2(d: np.ndarray, dhat: float) -> np.ndarray:
    """b''(d) = -2 log(d/dhat) - 4 (d - dhat)/d + (d - dhat)^2 / d^2 on (0, dhat), 0 beyond (>= 0)."""
    d = np.asarray(d, dtype=float)
    act = (d < dhat) & (d > 0)
    out = np.zeros_like(d)
    dd = d[act]
    out[act] = -2.0 * np.log(dd / dhat) - 4.0 * (dd - dhat) / dd + (dd - dhat) ** 2 / dd**2
    return out


def barrier_pressure(x, normal, offset, kappa, dhat) -> np.ndarray:
    """Barrier normal force per unit area -kappa b'(phi) >= 0, (p,) [Pa]."""
    return -kappa * barrier_d1(signed_distance(x, normal, offset), dhat)


def lagged_pressure(law: str, x, v, normal, offset, ke, kd, kappa, dhat) -> np.ndarray:
    """Normal pressure of the scene's contact law at points x (p, 3) moving at v (p, 3), (p,) [Pa]: `penalty`
    (`normal_pressure` with k_e, k_d) or `barrier` (`barrier_pressure` with kappa, dhat). Friction lags it from
    the start of the step; the creep metric evaluates it on stored frames."""
    if law == "penalty":
        return normal_pressure(x, v, normal, offset, ke, kd)
    return barrier_pressure(x, normal, offset, kappa, dhat)



class _Penalty(PointTerm):
    """The penalty law with stiffness `ke(model)` and damping `kd(model)`."""

    kernel = "penalty_contact_kernel"

    def kernel_parameters(self, model: Model) -> dict[str, float]:
        """The plane's offset [m], k_e and k_d."""
        return {"offset": model.plane_offset, "ke": self.ke(model), "kd": self.kd(model)}

    def ke(self, model: Model) -> float:
        """The stiffness k_e [Pa/m] (0: the damping part alone)."""
        return 0.0

    def kd(self, model: Model) -> float:
        """The damping k_d [Pa s/m] (0: the stiffness part alone)."""
        return 0.0

    def at_points(self, model: Model, x: np.ndarray, x_lag: np.ndarray, x_bar: np.ndarray, area: np.ndarray,
                  fn: np.ndarray | None, h: float, order: int) -> Evaluation:
        return penalty_potential(x, x_lag, area, model.plane_normal, model.plane_offset, self.ke(model),
                                 self.kd(model), h, x_bar, order)

    def reach(self, model: Model) -> float:
        """The stiffness part acts below the plane (c > 0) only; without it, nowhere through the position."""
        return 0.0 if self.ke(model) > 0.0 else -np.inf

    def lagged_support(self, model: Model, x_lag: np.ndarray, fn: np.ndarray | None) -> np.ndarray | None:
        """The damping part acts at the damped points (`damped_points` of the gate positions x_lag) only."""
        return damped_points(x_lag, model.plane_normal, model.plane_offset) if self.kd(model) > 0.0 else None

    def lag_reach(self, model: Model) -> float:
        """The damped points lie below the plane; without damping, none."""
        return 0.0 if self.kd(model) > 0.0 else -np.inf


@register
class PenaltyContact(_Penalty):
    """1/2 k_e c^2 per unit area, c the penetration (the paper's soft contact)."""

    name = "penalty_contact"

    def applies(self, model: Model) -> bool:
        return model.has("contact") and model.contact.law == "penalty"

    def ke(self, model: Model) -> float:
        return model.contact.stiffness


@register
class BarrierContact(PointTerm):
    """kappa b(phi) per unit area, the IPC log barrier."""

    name = "barrier_contact"
    kernel = "barrier_contact_kernel"

    def kernel_parameters(self, model: Model) -> dict[str, float]:
        """The plane's offset [m], kappa [Pa] and the activation distance dhat [m]."""
        c = model.contact
        return {"offset": model.plane_offset, "kappa": c.barrier_stiffness, "dhat": c.barrier_distance}

    def applies(self, model: Model) -> bool:
        return model.has("contact") and model.contact.law == "barrier"

    def at_points(self, model: Model, x: np.ndarray, x_lag: np.ndarray, x_bar: np.ndarray, area: np.ndarray,
                  fn: np.ndarray | None, h: float, order: int) -> Evaluation:
        n, dhat = model.plane_normal, model.contact.barrier_distance
        phi = signed_distance(x, n, model.plane_offset)
        kA = model.contact.barrier_stiffness * area
        E = float(kA @ barrier(phi, dhat))
        g = (kA * barrier_d1(phi, dhat))[:, None] * n if order >= 1 else None
        H = (kA * barrier_d2(phi, dhat))[:, None, None] * np.outer(n, n) if order == 2 else None
        return E, g, H

    def reach(self, model: Model) -> float:
        """b(d) and its derivatives vanish from the activation distance dhat on."""
        return model.contact.barrier_distance

    def max_step(self, model: Model, x: np.ndarray, dx: np.ndarray) -> float:
        """The barrier is infinite on the plane: no contact point may cross it (`solvers.newton_method.feasible_step`)."""
        return feasible_step(signed_distance(x, model.plane_normal, model.plane_offset), dx @ model.plane_normal)


@register
class ContactDamping(_Penalty):
    """h k_d / 2 max(0, -v.n)^2 per unit area at the points penetrating at the start of the step."""

    name = "damping"

    def applies(self, model: Model) -> bool:
        return model.has("damping")

    def kd(self, model: Model) -> float:
        return model.contact_damping

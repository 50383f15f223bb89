"""A scene's fast time scales and how well a time step resolves them (docs/metrics.md, "Time scales").

Elastic: K phi = omega^2 M phi at rest (K the unprojected elastic Hessian `rest_stiffness`, M the lumped mass):
its top omega_max (`spectrum_top`, Lanczos), its first non-rigid mode omega_1 (`viscosity.first_mode`), and the
exact number of modes above a frequency (`modes_above`, Sylvester's law of inertia on K - omega^2 M).

Contact (penalty law, stiffness k_e [Pa/m] and damping k_d [Pa s/m] per area): the whole body of mass M on its
contact patch of area A is a mass on a spring, omega_c = sqrt(k_e A / M), zeta_c = k_d A / (2 sqrt(k_e A M)); each
contact vertex i (mass m_i, area a_i) on its own spring, omega_i = sqrt(k_e a_i / m_i), zeta_i = k_d a_i /
(2 sqrt(k_e a_i m_i)) = (k_d / (2 k_e)) omega_i. The barrier law's stiffness per area is kappa b''(d*) at the gap d*
where its pressure -kappa b'(d*) carries the body's weight on the patch, M |g.n| / A (no damping term: zeta 0).

Friction below the Coulomb limit is a viscous law, k_f |v_t| per area: it relaxes a slip of the whole body in
tau_f = M / (k_f A), of a vertex in m_i / (k_f a_i).

The patch A is an argument: what touches the plane in a frame of a run (`touching_area`), e.g. its last frame.
Per vertex, every contact point counts (any surface vertex may touch in an impact): the figures are the fastest
vertex (largest omega_i, shortest tau_i) and the most lightly damped one (smallest zeta_i).
"""

from __future__ import annotations

import math
from dataclasses import asdict, dataclass

import numpy as np
import scipy.optimize as so
import scipy.sparse as sp
import scipy.sparse.linalg as spla

from frictionbench.solvers.linalg import negative_eigenvalues
from frictionbench.solvers.model import Model
from frictionbench.solvers.physics.contact import barrier_d1, barrier_d2, signed_distance
from frictionbench.solvers.physics.material import rest_stiffness
from frictionbench.solvers.physics.viscosity import first_mode

#: Relative tolerance of the Lanczos estimate of omega_max^2 (the extreme eigenvalue converges in a few dozen
#: iterations on these meshes).
SPECTRUM_TOL = 1e-6


def _mass(model: Model) -> sp.csr_matrix:
    """The lumped mass matrix M (3n, 3n) [kg]."""
    return sp.diags(np.repeat(model.mass, 3)).tocsr()


def spectrum_top(model: Model) -> float:
    """omega_max [rad/s]: sqrt of the largest eigenvalue of K phi = omega^2 M phi at rest, by Lanczos (`eigsh`
    on M^-1/2 K M^-1/2, deterministic start vector, relative tolerance SPECTRUM_TOL)."""
    s = sp.diags(1.0 / np.sqrt(np.repeat(model.mass, 3)))
    A = (s @ rest_stiffness(model) @ s).tocsr()
    v0 = np.random.default_rng(0).standard_normal(A.shape[0])
    w = spla.eigsh(A, k=1, which="LA", v0=v0, tol=SPECTRUM_TOL, return_eigenvectors=False)
    return float(np.sqrt(w[0]))


def modes_above(model: Model, omega: float) -> int:
    """How many eigenvalues of K phi = omega_k^2 M phi exceed omega^2 (omega > 0 [rad/s]), exactly: by
    Sylvester's law of inertia, 3n minus the negative eigenvalues of K - omega^2 M (`negative_eigenvalues`)."""
    if not omega > 0.0:
        raise ValueError(f"omega = {omega!r}: expected a positive frequency [rad/s]")
    K = rest_stiffness(model)
    return int(K.shape[0] - negative_eigenvalues((K - omega**2 * _mass(model)).tocsr()))


def unresolved_share(model: Model, h_eff: float) -> float:
    """The share of the body's 3n - 6 elastic modes with omega h_eff > 1 [-] (h_eff [s] the integrator's
    effective step)."""
    if not h_eff > 0.0:
        raise ValueError(f"h_eff = {h_eff!r}: expected a positive step [s]")
    return modes_above(model, 1.0 / h_eff) / (3 * model.n - 6)


def touching_area(model: Model, x: np.ndarray) -> float:
    """The contact patch A [m^2] of positions x (n, 3) [m]: the area of the contact points where the contact law
    pushes, below the plane (penalty) or within the barrier's reach dhat (barrier); 0 without a plane."""
    if model.plane_normal is None:
        return 0.0
    phi = signed_distance(x[model.points], model.plane_normal, model.plane_offset)
    reach = model.contact.barrier_distance if model.contact.law == "barrier" else 0.0
    return float(model.area[phi < reach].sum())


def resting_load(model: Model) -> float:
    """The body's weight across the plane, M |g.n| [N] (0 without a plane)."""
    if model.plane_normal is None:
        return 0.0
    return float(model.mass.sum() * abs(model.gravity @ model.plane_normal))


def contact_stiffness(model: Model, pressure: float) -> float:
    """The contact law's normal stiffness per area [Pa/m] at a contact pressure [Pa]: k_e for the penalty law;
    kappa b''(d*) for the barrier, at the gap d* where -kappa b'(d*) = pressure (0 for no pressure: beyond dhat)."""
    c = model.contact
    if c.law == "penalty":
        return float(c.stiffness)
    if pressure <= 0.0:
        return 0.0
    dhat, kappa = c.barrier_distance, c.barrier_stiffness
    gap = so.brentq(lambda d: -kappa * barrier_d1(np.array([d]), dhat)[0] - pressure, 1e-12 * dhat,
                    (1.0 - 1e-12) * dhat, xtol=1e-15 * dhat, rtol=1e-12)
    return float(kappa * barrier_d2(np.array([gap]), dhat)[0])


@dataclass(frozen=True)
class TimeScales:
    """A scene's time scales (module docstring); nan where the scene has no such effect (no plane, no friction,
    an empty patch).

    omega_max, omega_1 [rad/s]: the elastic spectrum's top and first non-rigid mode; patch_area A [m^2];
    contact_stiffness [Pa/m] per area (the barrier's at the resting pressure M |g.n| / A); omega_contact
    [rad/s], zeta_contact [-]: the whole body on its patch; omega_contact_vertex [rad/s]: the fastest contact
    vertex, zeta_contact_vertex [-]: the most lightly damped one; tau_friction [s]: the whole body's friction
    relaxation time, tau_friction_vertex [s]: the fastest vertex's.
    """

    omega_max: float
    omega_1: float
    patch_area: float
    contact_stiffness: float
    omega_contact: float
    zeta_contact: float
    omega_contact_vertex: float
    zeta_contact_vertex: float
    tau_friction: float
    tau_friction_vertex: float

    def resolution(self, h_eff: float) -> dict[str, float]:
        """omega h_eff [-] of each time scale at the effective step h_eff [s] (h_eff / tau for the friction
        relaxations): keys omega_max, omega_1, contact, contact_vertex, friction, friction_vertex."""
        return {"omega_max": self.omega_max * h_eff, "omega_1": self.omega_1 * h_eff,
                "contact": self.omega_contact * h_eff, "contact_vertex": self.omega_contact_vertex * h_eff,
                "friction": h_eff / self.tau_friction, "friction_vertex": h_eff / self.tau_friction_vertex}

    def as_dict(self) -> dict[str, float]:
        """The fields by name."""
        return asdict(self)


def elastic_scales(model: Model) -> tuple[float, float]:
    """(omega_max, omega_1) [rad/s] of the body at rest (`spectrum_top`, `first_mode`)."""
    return spectrum_top(model), first_mode(model)[0]


def contact_scales(model: Model, patch_area: float) -> dict[str, float]:
    """The contact and friction fields of `TimeScales` for a patch of area patch_area [m^2] (nan where the scene
    has no contact, no friction, or the patch is empty)."""
    nan = math.nan
    out = dict.fromkeys(("contact_stiffness", "omega_contact", "zeta_contact", "omega_contact_vertex",
                         "zeta_contact_vertex", "tau_friction", "tau_friction_vertex"), nan)
    out["patch_area"] = float(patch_area)
    if not model.has("contact"):
        return out
    M, m, a = float(model.mass.sum()), model.mass[model.points], model.area
    A = float(patch_area)
    k = contact_stiffness(model, resting_load(model) / A if A > 0.0 else 0.0)
    kd = model.contact_damping
    omega_i = np.sqrt(k * a / m)
    out |= {"contact_stiffness": k, "omega_contact_vertex": float(omega_i.max())}
    if k > 0.0:
        out["zeta_contact_vertex"] = float((kd * a / (2.0 * np.sqrt(k * a * m))).min())
    if A > 0.0:
        out |= {"omega_contact": math.sqrt(k * A / M),
                "zeta_contact": kd * A / (2.0 * math.sqrt(k * A * M)) if k > 0.0 else nan}
    if model.has("friction"):
        kf = model.contact.friction_stiffness
        out["tau_friction_vertex"] = float((m / (kf * a)).min())
        if A > 0.0:
            out["tau_friction"] = M / (kf * A)
    return out


def time_scales(model: Model, patch_area: float, elastic: tuple[float, float] | None = None) -> TimeScales:
    """The scene's `TimeScales` on a contact patch of area patch_area [m^2]; `elastic` = (omega_max, omega_1)
    where already computed for this mesh and material (`elastic_scales`, the costly part)."""
    omega_max, omega_1 = elastic if elastic is not None else elastic_scales(model)
    return TimeScales(omega_max=omega_max, omega_1=omega_1, **contact_scales(model, patch_area))

"""Newton's Vertex Block Descent (VBD) soft-body solver as a peer engine under the solver contract.

Newton (the open, warp-based physics engine, `pip install newton`) steps a tet mesh by VBD: per (sub)step a fixed
number of block Gauss-Seidel sweeps over the vertices, each vertex moved by one 3x3 Newton step of the implicit-Euler
incremental potential with its neighbours held, vertices of one colour in parallel; no global solve and no
convergence test. This module builds, from a frictionbench `Model`, the same physical problem in Newton (docs/solvers.md
"Newton's VBD as a peer") and steps it with `newton.solvers.SolverVBD`:

- the rest mesh, density (Newton lumps tet masses to vertices as we do), and Young's modulus and Poisson ratio as
  Lame parameters (`newton_material`): Newton's Neo-Hookean energy mu/2 (I_C - 3) + (lambda + mu)/2 (J - alpha)^2,
  alpha = 1 + mu / (lambda + mu), and our stable Neo-Hookean one agree with linear elasticity at small strain;
- Kelvin-Voigt damping: Newton's `k_damp` damps the rate of C = F^T F = 2 E + I, which is our Green-strain-rate
  potential eta |E_dot|^2 with k_damp = eta / 2 (`newton_damping`);
- the plane as a static Newton plane shape with the scene's normal and offset, gravity as the scene's vector;
- contact: Newton's particle-shape penalty law is per vertex (force ke c [N] for a penetration c [m], dashpot kd
  on approach), ours per unit area (pressure k_e c): ke = k_e a and kd = k_d a with a the median contact-vertex area
  (`contact_parameters`; Newton takes one value per model). Particle radius 0, so contact starts at the plane as
  ours does. The soft and the shape sides get the same ke, kd and mu, so Newton's mixing (mean of ke and kd,
  geometric mean of mu) returns them unchanged;
- friction: Newton's IPC-style regularised Coulomb law with its own velocity threshold `friction_epsilon` [m/s]
  (its default, 0.01): below it the force grows linearly with slip, like our law below eps_v = mu f_n / k_f.

Newton's collision detection runs before every substep, as its examples do (`CollisionPipeline.collide`), with its
default detection gap. Parameters: `substeps` per scene step and `iterations` per substep. The scene's step is
implicit Euler on substeps of dt / substeps; scenes under another integrator, adaptive steps or the barrier
contact law are skipped with the reason. Newton computes in float32; a state goes in and out as float64 arrays.
"""

from __future__ import annotations

import time
from typing import Any

import numpy as np

from frictionbench.solvers.contract import Solver, check_count
from frictionbench.solvers.model import Model, State
from frictionbench.solvers.physics.material import lame_parameters
from frictionbench.solvers.step_stats import StepStats


def newton_material(youngs_modulus: float, poisson_ratio: float) -> tuple[float, float]:
    """Newton's soft-mesh `k_mu`, `k_lambda` [Pa]: the Lame parameters of E [Pa] and nu [-] (Newton converts them to
    its Neo-Hookean parameters itself)."""
    return lame_parameters(youngs_modulus, poisson_ratio)


def newton_damping(viscosity: float) -> float:
    """Newton's soft-mesh `k_damp` [Pa s] for our Kelvin-Voigt viscosity eta [Pa s]: Newton's dissipation
    k_damp/2 |C_dot|^2 per volume with C = 2 E + I is 2 k_damp |E_dot|^2, ours eta |E_dot|^2."""
    return 0.5 * viscosity


def contact_parameters(model: Model) -> tuple[float, float]:
    """Newton's per-vertex contact stiffness ke [N/m] and damping kd [N s/m]: our per-area penalty stiffness k_e
    [Pa/m] and damping k_d [Pa s/m] times the median area weight [m^2] of the model's contact vertices."""
    a = float(np.median(model.area))
    return model.contact.stiffness * a, model.contact_damping * a


def newton_model(model: Model, device: str = "cpu", fixed: np.ndarray | None = None) -> Any:
    """The `newton.Model` of `model`'s body (rest positions X, tets, material, damping), plane (if any) and gravity;
    vertices where `fixed` (n,) bool is True are kinematic (inactive, zero mass: held where their state puts them)."""
    import newton
    import warp as wp

    from frictionbench.solvers.warp_runtime import init_warp

    init_warp()
    sc = model.scenario
    builder = newton.ModelBuilder(gravity=tuple(float(g) for g in model.gravity))
    k_mu, k_lambda = newton_material(sc.material.youngs_modulus, sc.material.poisson_ratio)
    builder.add_soft_mesh(pos=wp.vec3(0.0, 0.0, 0.0), rot=wp.quat_identity(), scale=1.0, vel=wp.vec3(0.0, 0.0, 0.0),
                          vertices=[wp.vec3(*p) for p in model.X], indices=model.tets.reshape(-1).tolist(),
                          density=model.density, k_mu=k_mu, k_lambda=k_lambda, k_damp=newton_damping(model.viscosity),
                          particle_radius=0.0)
    if fixed is not None:
        for i in np.flatnonzero(fixed):
            builder.particle_mass[i] = 0.0
            builder.particle_flags[i] = builder.particle_flags[i] & ~newton.ParticleFlags.ACTIVE
    soft_contact = (0.0, 0.0, 0.0)
    if model.plane_normal is not None:
        ke, kd = contact_parameters(model)
        n = model.plane_normal
        builder.add_shape_plane(plane=(float(n[0]), float(n[1]), float(n[2]), -model.plane_offset), width=0.0,
                                length=0.0, cfg=newton.ModelBuilder.ShapeConfig(ke=ke, kd=kd, mu=model.friction))
        soft_contact = (ke, kd, model.friction)
    builder.color()
    nm = builder.finalize(device=device)
    nm.soft_contact_ke, nm.soft_contact_kd, nm.soft_contact_mu = soft_contact
    return nm


class NewtonVBD(Solver):
    """Newton's VBD solver (see the module docstring): `substeps` per scene step [-], `iterations` of block
    Gauss-Seidel per substep [-], `friction_epsilon` the slip speed [m/s] below which Newton's friction is
    regularised (Newton's default)."""

    name = "newton-vbd"
    requires = ("newton",)
    parameters = {"substeps": 1, "iterations": 10, "friction_epsilon": 1.0e-2}

    def __init__(self, device: str = "cpu", **params: Any) -> None:
        super().__init__(device, **params)
        for key in ("substeps", "iterations"):
            check_count(self.name, key, self.params[key])
        eps = self.params["friction_epsilon"]
        if not (isinstance(eps, (int, float)) and np.isfinite(eps) and eps > 0.0):
            raise ValueError(f"solver {self.name!r}: friction_epsilon = {eps!r}: must be a positive number [m/s]")

    def skip(self, model: Model) -> str | None:
        """Scenes Newton's VBD cannot pose as ours: adaptive steps, and the barrier contact law (Newton's soft
        contact is a penalty law)."""
        if model.scenario.time.adaptive:
            return f"time.tol = {model.scenario.time.tol!r}: solver {self.name!r} steps at fixed substeps only"
        if model.has("contact") and model.contact.law != "penalty":
            return f"contact.law = {model.contact.law!r}: Newton's soft contact is a penalty law"
        return None

    def setup(self, model: Model) -> None:
        """Newton's model, its VBD solver, collision pipeline and two states on `model`."""
        import newton

        self.model = model
        self.nm = newton_model(model, self.device)
        self.vbd = newton.solvers.SolverVBD(self.nm, iterations=self.params["iterations"],
                                            friction_epsilon=float(self.params["friction_epsilon"]),
                                            particle_enable_self_contact=False)
        self.pipeline = newton.CollisionPipeline(self.nm)
        self.contacts = self.pipeline.contacts()
        self.states = [self.nm.state(), self.nm.state()]
        self.control = self.nm.control()

    def step(self, state_in: State, state_out: State, dt: float) -> StepStats:
        """`substeps` VBD substeps of dt / substeps [s] from state_in; iterations counts every sweep."""
        t0 = time.perf_counter()
        substeps, iterations = self.params["substeps"], self.params["iterations"]
        s0, s1 = self.states
        s0.particle_q.assign(np.ascontiguousarray(state_in.x, dtype=np.float32))
        s0.particle_qd.assign(np.ascontiguousarray(state_in.v, dtype=np.float32))
        h = dt / substeps
        for _ in range(substeps):
            s0.clear_forces()
            self.pipeline.collide(s0, self.contacts)
            self.vbd.step(s0, s1, self.control, self.contacts, h)
            s0, s1 = s1, s0
        self.states = [s0, s1]
        state_out.x = s0.particle_q.numpy().astype(np.float64)
        state_out.v = s0.particle_qd.numpy().astype(np.float64)
        state_out.t = state_in.t + dt
        state_out.previous = state_in.without_history()
        return StepStats(wall_s=time.perf_counter() - t0, iterations=substeps * iterations)

    def describe(self) -> dict:
        """The parameters, and Newton's version and the contact stiffness and damping it was given."""
        import newton

        return super().describe() | {"newton_version": newton.__version__,
                                     "newton_contact_ke": float(self.nm.soft_contact_ke),
                                     "newton_contact_kd": float(self.nm.soft_contact_kd),
                                     "newton_k_damp": newton_damping(self.model.viscosity)}

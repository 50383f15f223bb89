"""The scenario data model: what is simulated, as plain frozen dataclasses.

A scenario is data, not code. The loader (`scenarios.load`) builds these from TOML and validates every
field; everything downstream (solvers, bench, reports) reads only these objects. Units are SI throughout:
metres, seconds, kilograms, pascals. The world's up axis is +y and gravity defaults to (0, -9.81, 0).
"""

from __future__ import annotations

from dataclasses import dataclass, field, replace

Vec3 = tuple[float, float, float]

#: Most time steps one run may take without an override of the resource guard (`scenarios.resources`; a full-space
#: step costs 1 ms to 1 s on the CPU); an adaptive run's default smallest step keeps it within (`TimeSpec.min_step`).
MAX_STEPS = 100_000
#: An adaptive run's default smallest step, as a fraction of time.dt (`TimeSpec.min_step`).
DT_MIN_FRACTION = 1.0 / 1024.0

#: The built-in integrators' names, the classes of `solvers.integrators` (a test checks that the two agree): this
#: bottom layer may not import solvers (pyproject.toml's layer contracts), so the names are declared here, where the
#: loader validates `time.integrator`, and nothing has to be imported first for them to be known.
BUILTIN_INTEGRATORS: tuple[str, ...] = ("backward-euler", "bdf2")
#: The names a scenario's `time.integrator` may take: the built-in ones, then those an extension registers
#: (`solvers.integrators.register` calls `register_integrator_name`).
_INTEGRATOR_NAMES: list[str] = list(BUILTIN_INTEGRATORS)


def register_integrator_name(name: str) -> None:
    """Accept `name` as a `time.integrator` (called by `solvers.integrators.register` for each integrator class)."""
    if name not in _INTEGRATOR_NAMES:
        _INTEGRATOR_NAMES.append(name)


def integrator_names() -> tuple[str, ...]:
    """The accepted integrator names (`BUILTIN_INTEGRATORS`, then the registered ones)."""
    return tuple(_INTEGRATOR_NAMES)


@dataclass(frozen=True)
class MeshSpec:
    """Which tetrahedral mesh: a catalogue name with a resolution, or a path to any file meshio reads.

    name: catalogue name (`cheese`, `sphere`, `block`, `beam`, ...) or None when `path` is given.
    resolution: catalogue resolution label (`coarse`, `medium`, `fine`, or `coarse_alt` / `medium_alt` for the
        independently generated second mesh used by remeshing checks).
    path: a tet mesh file; relative paths are resolved against the scenario file's folder.
    scale: uniform scale applied to the rest positions [-].
    """

    name: str | None = "cheese"
    resolution: str = "coarse"
    path: str | None = None
    scale: float = 1.0

    @property
    def key(self) -> str:
        """Short identity string, e.g. `cheese/coarse` or the file path."""
        return self.path if self.path else f"{self.name}/{self.resolution}"


@dataclass(frozen=True)
class Material:
    """Stable Neo-Hookean material: density [kg/m^3], Young's modulus [Pa], Poisson ratio [-] in (-1, 0.5), and
    its Kelvin-Voigt damping (docs/physics.md, "Material damping"), given at most one way: `viscosity` eta [Pa s],
    or `damping_ratio` zeta [-], the damping ratio of the body's first non-rigid vibration mode on its mesh,
    resolved to a viscosity when the model is built (`solvers.physics.viscosity.viscosity_for_damping_ratio`).
    Both None: undamped (no viscosity term)."""

    density: float = 1000.0
    youngs_modulus: float = 1.0e5
    poisson_ratio: float = 0.3
    viscosity: float | None = None
    damping_ratio: float | None = None


@dataclass(frozen=True)
class Plane:
    """The ground plane `n . x = d` (n unit, normalised by the loader) with Coulomb friction coefficient mu."""

    normal: Vec3 = (0.0, 1.0, 0.0)
    offset: float = 0.0
    friction: float = 0.5


#: The values of `Contact.lag`: where a step evaluates what the contact terms lag (`solvers.step.ContactLag`).
CONTACT_LAGS = ("start", "corrected", "fixed-point")


@dataclass(frozen=True)
class Contact:
    """Contact law and parameters, all per unit contact area (docs/physics.md, "Contact with the plane").

    law: `penalty` (the paper's soft contact) or `barrier` (IPC log barrier).
    stiffness: k_e [Pa/m], normal force per area per metre of penetration (penalty law); None (TOML "auto", the
        default) sets it from the material and the initial motion when the model is built:
        k_e = max(E, rho v^2) / (1e-3 L) (`solvers.physics.contact.auto_penalty_stiffness`), so the penetration is
        about 1e-3 L times the strain the contact pressure causes.
    damping: k_d [Pa s/m], normal force per area per m/s of approach speed while penetrating.
    damping_ratio: zeta [-] of the contact's own oscillation instead of a k_d (at most one of the two): the damping
        ratio of a contact vertex's lumped mass on its contact spring (the median over the contact vertices of the
        mesh), resolved to k_d when the model is built (`solvers.physics.contact.damping_for_ratio`); None: k_d as
        given.
    friction_stiffness: k_f [Pa s/m], tangential force per area per m/s of slip below the Coulomb limit.
    barrier_distance: dhat [m], activation distance of the barrier law.
    barrier_stiffness: kappa [Pa], barrier stiffness per unit area.
    lag: where a step evaluates what contact lags (friction's normal pressure, the contact-damping gate): `start`
        (the start of the step, the paper's: first order in contact), `corrected` (one re-lagged solve at the first
        solve's end state: second order where the step resolves contact) or `fixed-point` (lagged iterations to the
        step's own end state); `solvers.step.ContactLag`.
    """

    law: str = "penalty"
    stiffness: float | None = None
    damping: float = 0.0
    friction_stiffness: float = 1.0e6
    barrier_distance: float = 1.0e-3
    barrier_stiffness: float = 1.0e4
    lag: str = "start"
    damping_ratio: float | None = None


@dataclass(frozen=True)
class Initial:
    """Initial placement and motion of the body.

    clearance: gap [m] between the plane and the body's lowest point along the plane normal after rotation;
        None keeps the mesh where it is (after rotation and translation).
    rotation: XYZ Euler angles [degrees] applied about the rest centroid.
    translation: rigid translation [m] applied after rotation (before placing by clearance).
    velocity: initial linear velocity [m/s].
    angular_velocity: initial angular velocity [rad/s] about the centroid.
    squash: per-axis scale of the initial positions about the centroid (1 = undeformed; used by stress cases).
    """

    clearance: float | None = 0.0
    rotation: Vec3 = (0.0, 0.0, 0.0)
    translation: Vec3 = (0.0, 0.0, 0.0)
    velocity: Vec3 = (0.0, 0.0, 0.0)
    angular_velocity: Vec3 = (0.0, 0.0, 0.0)
    squash: Vec3 = (1.0, 1.0, 1.0)


@dataclass(frozen=True)
class TimeSpec:
    """Time stepping: step dt [s], duration [s], store a frame every `frame_every` steps, and the `integrator` of
    the implicit solvers (a name of `integrator_names()`).

    Adaptive steps (docs/physics.md, "Adaptive steps"): `tol` [fraction of L] is the local error allowed per step
    (RMS over the vertices of the estimated position error / L); None (the default) steps by dt throughout. With a
    tol, dt is the first and the largest step, `dt_min` [s] the smallest (None: `min_step`'s default), and the
    frames stay at the fixed-step times, every frame_every x dt."""

    dt: float = 0.01
    duration: float = 1.0
    frame_every: int = 1
    integrator: str = "backward-euler"
    tol: float | None = None
    dt_min: float | None = None

    @property
    def n_steps(self) -> int:
        """Number of steps, round(duration / dt) (of a fixed-step run; an adaptive run's frames are those of the
        fixed-step run)."""
        return int(round(self.duration / self.dt))

    @property
    def adaptive(self) -> bool:
        """Whether the step size is error-controlled (a `tol` is given)."""
        return self.tol is not None

    @property
    def min_step(self) -> float:
        """An adaptive run's smallest step [s]: `dt_min`, by default dt x DT_MIN_FRACTION (dt / 1024) or
        duration / MAX_STEPS where that is larger, so that a run with the default never takes more steps than the
        resource guard allows (but never above dt)."""
        if self.dt_min is not None:
            return self.dt_min
        return min(self.dt, max(self.dt * DT_MIN_FRACTION, self.duration / MAX_STEPS))


@dataclass(frozen=True)
class Effects:
    """Which terms of the incremental potential exist. Absent terms are not built and cost nothing. `damping` is
    the contact's normal damping, `viscosity` the material's Kelvin-Voigt damping (built only where the material
    gives a positive viscosity or damping ratio)."""

    gravity: bool = True
    elasticity: bool = True
    contact: bool = True
    friction: bool = True
    damping: bool = False
    viscosity: bool = True


#: Default gravity [m/s^2] (y is up): a scenario's, and the metrics' (`analysis.metrics`) where none is given.
GRAVITY: Vec3 = (0.0, -9.81, 0.0)


@dataclass(frozen=True)
class Scenario:
    """One simulation scene. `plane` is None for scenes without ground (no contact, no friction)."""

    name: str
    mesh: MeshSpec = field(default_factory=MeshSpec)
    material: Material = field(default_factory=Material)
    plane: Plane | None = field(default_factory=Plane)
    contact: Contact = field(default_factory=Contact)
    initial: Initial = field(default_factory=Initial)
    time: TimeSpec = field(default_factory=TimeSpec)
    effects: Effects = field(default_factory=Effects)
    gravity: Vec3 = GRAVITY
    description: str = ""
    tags: tuple[str, ...] = ()

    def with_(self, **changes) -> "Scenario":
        """A copy with top-level fields replaced."""
        return replace(self, **changes)

"""Scenario loading and validation: TOML (or a plain dict) -> a validated, frozen `Scenario`.

Every problem raises `ScenarioError(field, value, reason)` before any simulation work. `field` is the dotted path
of the offending entry (`material.poisson_ratio`, `plane.normal`, ...) or, for an unreadable or malformed file,
the file's path; the message always contains the offending value.

Format (one scenario per file; tables mirror the dataclasses of `scenarios.spec`; every key except `name` is
optional and defaults to the dataclass default unless said otherwise below):

    name = "cheese_slope"            # required; letters, digits, `_ . + -`, parts joined by `/`
    description = "..."
    tags = ["paper"]
    gravity = [0.0, -9.81, 0.0]      # [m/s^2]

    [mesh]        # either a catalogue entry (`name`, `resolution`) or a file (`path`), never both
    name = "cheese"                  # a name of `scenarios.meshes.catalogue()`; default "cheese"
    resolution = "coarse"            # one of that name's resolutions; not allowed with `path`
    # path = "wedge.vtu"             # must exist; relative to the scenario file's folder (to `base_dir`
    #                                # for `scenario_from_dict`); stored resolved to an absolute path
    scale = 1.0                      # > 0

    [material]    density > 0 [kg/m^3], youngs_modulus > 0 [Pa], -1 < poisson_ratio < 0.5; optional Kelvin-Voigt
                  damping, at most one of: viscosity >= 0 [Pa s], or damping_ratio >= 0 [-] (of the body's first
                  non-rigid mode on its mesh; resolved to a viscosity when the model is built)

    [plane]       # the ground n . x = d
    normal = [1.0, 5.0, 2.0]         # non-zero; the loader divides normal AND offset by |normal|
    offset = -1.5
    friction = 0.25                  # Coulomb mu >= 0
    # or, instead of `normal`:
    # slope_deg = 20.0               # in [0, 90): a plane tilted by this angle that descends towards
    # downhill = "x"                 # "x" (default), "-x", "z" or "-z"; "x" gives normal (sin t, cos t, 0);
    #                                # `offset` still applies (default 0: through the origin)

    No ground at all: write `plane = false` at the top level. Omitting the plane entirely gives the model's
    default plane (horizontal through the origin, mu = 0.5), so a scene without ground always says so.

    [contact]     law = "penalty" | "barrier", stiffness > 0 or "auto" (default; see Contact), damping >= 0,
                  friction_stiffness > 0, barrier_distance > 0, barrier_stiffness > 0,
                  lag = "start" (default) | "corrected" | "fixed-point" (see Contact); instead of damping,
                  damping_ratio >= 0 [-] (of a contact vertex on its contact spring; resolved to a damping when the
                  model is built; not with damping)
    [initial]     clearance >= 0 [m], rotation [deg], translation [m], velocity [m/s],
                  angular_velocity [rad/s], squash (per-axis scale, components
                  nonzero, magnitude in [1e-3, 1e3]; a negative component mirrors the body: every tet starts inverted)
                  `clearance = false` keeps the mesh where it is (Initial.clearance = None). Without a plane
                  there is nothing to measure a clearance from: it defaults to false and a number is an error.
                  The barrier law needs a positive initial gap, so `clearance = 0` with it is an error.
    [time]        dt > 0, duration >= dt, frame_every >= 1 (an integer),
                  integrator = a name of `scenarios.spec.integrator_names()` (the integrators of
                  `solvers.integrators`); default TimeSpec.integrator, backward Euler;
                  optional adaptive steps (docs/physics.md, "Adaptive steps"): tol > 0 (finite; the local error
                  allowed per step, a fraction of L; absent: fixed steps of dt), then dt is the first and largest
                  step, and dt_min (only with tol) in (0, dt] the smallest [s] (default dt / 1024, or
                  duration / 100,000 where larger: `TimeSpec.min_step`)
    [effects]     gravity, elasticity, contact, friction, damping, viscosity (booleans)

Effects default to what the scene implies: gravity = the gravity vector is non-zero; elasticity = true;
contact = a plane exists; friction = contact and mu > 0; damping = contact and a contact damping or damping ratio > 0; viscosity =
true (the term exists where the material gives a viscosity or a damping ratio). An explicit entry may turn any
term off; turning on a term the scene cannot have (contact without a plane, friction or damping without contact,
viscosity without a material viscosity or damping ratio) is an error. `friction = true` with mu = 0 (or
`damping = true` with a zero contact damping, `gravity = true` with a zero gravity vector, a zero viscosity) is
allowed: the term is then identically zero and a solver builds nothing for it.

`scenario_to_dict` writes the canonical dict of a scenario (every field explicit, plane normalised, effects
resolved; the material's viscosity and damping ratio only where given, and the viscosity effect only where the
material has one of them, so that undamped scenes keep the hashes they had before material damping existed;
likewise `time.integrator` only where it is not the default, backward Euler, `time.tol`, `time.dt_min` and
`contact.damping_ratio` only where given, and `contact.lag` only where it is not `start`);
`scenario_from_dict(scenario_to_dict(s)) == s` for every loaded scenario, so it also validates a scenario built or
modified in code. `scenario_hash` hashes what is simulated, not what it is called.
"""

from __future__ import annotations

import hashlib
import json
import math
import numbers
import os
import re
import sys
import tomllib
from collections.abc import Collection, Mapping
from pathlib import Path
from typing import Any

from frictionbench.scenarios.errors import ScenarioError, checked_table
from frictionbench.scenarios.spec import (CONTACT_LAGS, Contact, Effects, Initial, Material, MeshSpec, Plane, Scenario, TimeSpec,
                                           Vec3, integrator_names)

TOP_KEYS = ("name", "description", "tags", "gravity", "mesh", "material", "plane", "contact", "initial", "time",
            "effects")
MESH_KEYS = ("name", "resolution", "path", "scale")
MATERIAL_KEYS = ("density", "youngs_modulus", "poisson_ratio", "viscosity", "damping_ratio")
PLANE_KEYS = ("normal", "offset", "friction", "slope_deg", "downhill")
CONTACT_KEYS = ("law", "stiffness", "damping", "friction_stiffness", "barrier_distance", "barrier_stiffness", "lag",
                "damping_ratio")
INITIAL_KEYS = ("clearance", "rotation", "translation", "velocity", "angular_velocity", "squash")
TIME_KEYS = ("dt", "duration", "frame_every", "integrator", "tol", "dt_min")
EFFECT_KEYS = ("gravity", "elasticity", "contact", "friction", "damping", "viscosity")
CONTACT_LAWS = ("penalty", "barrier")
DOWNHILL_AXES = {"x": (1.0, 0.0), "-x": (-1.0, 0.0), "z": (0.0, 1.0), "-z": (0.0, -1.0)}

# One name part: starts with a letter or digit, then letters, digits, `_ . + -` (safe in file names).
NAME_PART = r"[A-Za-z0-9][A-Za-z0-9_.+-]*"
_NAME_RE = re.compile(rf"{NAME_PART}(/{NAME_PART})*")
# Normals this close to unit length are kept bit for bit, so that normalisation is idempotent.
_UNIT_TOLERANCE = 8 * 2.0**-52


def load_scenario(path: str | os.PathLike[str]) -> Scenario:
    """Read and validate one scenario TOML file; relative mesh paths resolve against the file's folder."""
    path = Path(path)
    return scenario_from_dict(read_toml(path), source=str(path), base_dir=path.parent)


def scenario_from_dict(d: Mapping[str, Any], source: str = "<dict>",
                       base_dir: str | os.PathLike[str] | None = None) -> Scenario:
    """Validate a scenario dict (the TOML schema above) and build the `Scenario`.

    source: where the dict came from, appended to error messages (a file, a suite member).
    base_dir: folder that relative `mesh.path` entries resolve against (default: the working directory).
    """
    try:
        return _scenario(d, Path(base_dir) if base_dir is not None else Path.cwd())
    except ScenarioError as err:
        raise type(err)(err.field, err.value, f"{err.reason} [{source}]") from None


def scenario_to_dict(s: Scenario) -> dict[str, Any]:
    """The canonical dict of a scenario: every field explicit (but `time.integrator` at its default, see the module
    docstring), TOML types only (`false` for absent values)."""
    mesh: dict[str, Any] = ({"path": s.mesh.path} if s.mesh.path
                            else {"name": s.mesh.name, "resolution": s.mesh.resolution})
    mesh["scale"] = s.mesh.scale
    plane: dict[str, Any] | bool = False
    if s.plane is not None:
        plane = {"normal": list(s.plane.normal), "offset": s.plane.offset, "friction": s.plane.friction}
    initial = _as_dict(s.initial, INITIAL_KEYS)
    if s.initial.clearance is None:
        initial["clearance"] = False
    return {
        "name": s.name,
        "description": s.description,
        "tags": list(s.tags),
        "gravity": list(s.gravity),
        "mesh": mesh,
        "material": {k: v for k, v in _as_dict(s.material, MATERIAL_KEYS).items() if v is not None},
        "plane": plane,
        "contact": (_as_dict(s.contact, tuple(k for k in CONTACT_KEYS if _given(s.contact, k)))
                    | ({"stiffness": "auto"} if s.contact.stiffness is None else {})),
        "initial": initial,
        "time": {k: v for k, v in _as_dict(s.time, TIME_KEYS).items()
                 if (k != "integrator" or v != TimeSpec.integrator) and (k not in ("tol", "dt_min") or v is not None)},
        "effects": {k: v for k, v in _as_dict(s.effects, EFFECT_KEYS).items()
                    if k != "viscosity" or _damped(s.material)},
    }


def scenario_hash(s: Scenario) -> str:
    """Stable 16-hex-digit sha256 of what is simulated: the canonical dict without name, description and tags.

    A file mesh enters by the sha256 of its bytes rather than its path, so the hash survives moving the checkout
    and changes when the file does. Two scenarios that simulate the same thing share a hash whatever they are
    called, which is what a trajectory cache wants.
    """
    payload = scenario_to_dict(s)
    for key in ("name", "description", "tags"):
        del payload[key]
    if s.mesh.path:
        try:
            payload["mesh"]["path"] = "sha256:" + hashlib.sha256(Path(s.mesh.path).read_bytes()).hexdigest()
        except OSError as err:
            raise ScenarioError("mesh.path", s.mesh.path, f"cannot read the mesh file to hash it: {err}") from None
    text = json.dumps(payload, sort_keys=True, separators=(",", ":"), allow_nan=False)
    return hashlib.sha256(text.encode()).hexdigest()[:16]


def read_toml(path: Path) -> dict[str, Any]:
    """Parse a TOML file; any failure is a ScenarioError naming the file, with the parser's line and column."""
    field = str(path)
    try:
        raw = path.read_bytes()
    except (OSError, ValueError) as err:
        reason = "no such file" if isinstance(err, FileNotFoundError) else f"cannot read: {err}"
        raise ScenarioError(field, field, reason) from None
    try:
        text = raw.decode("utf-8")
    except UnicodeDecodeError as err:
        raise ScenarioError(field, raw[max(0, err.start - 20):err.end + 20], f"not UTF-8 text: {err}") from None
    try:
        return tomllib.loads(text)
    except tomllib.TOMLDecodeError as err:
        raise ScenarioError(field, _offending_line(text, str(err)), f"invalid TOML: {err}") from None
    except RecursionError:
        raise ScenarioError(field, text[:40], "invalid TOML: nested too deeply") from None


def is_safe_name(name: str) -> bool:
    """Whether `name` is usable as a scenario name (and as a relative file path): see NAME_PART."""
    return _NAME_RE.fullmatch(name) is not None


def _catalogue() -> Mapping[str, Collection[str]]:
    """The mesh catalogue (name -> resolutions), imported lazily so that loading never touches mesh code."""
    from frictionbench.scenarios.meshes import catalogue

    return catalogue()


def _offending_line(text: str, message: str) -> str:
    """The source line a TOML parser message points at (`at line N`), else the document's last line."""
    lines = text.splitlines() or [""]
    match = re.search(r"at line (\d+)", message)
    return lines[min(int(match.group(1)), len(lines)) - 1] if match else lines[-1]


def _as_dict(obj: object, keys: tuple[str, ...]) -> dict[str, Any]:
    """The named attributes of a dataclass instance, tuples as lists."""
    values = {key: getattr(obj, key) for key in keys}
    return {key: list(v) if isinstance(v, tuple) else v for key, v in values.items()}


def _scenario(d: object, base_dir: Path) -> Scenario:
    """Validate the whole dict; fields are read in order so the first error is the first bad field."""
    t = _table(d, "", TOP_KEYS)
    if "name" not in t:
        raise ScenarioError("name", None, "missing: every scenario needs a name")
    name = _string(t["name"], "name")
    if not is_safe_name(name):
        raise ScenarioError("name", name, f"not a safe name: parts matching {NAME_PART!r} joined by '/'")
    description = _string(t.get("description", ""), "description")
    tags = _tags(t.get("tags", []))
    gravity = _vec3(t.get("gravity", Scenario.gravity), "gravity")
    mesh = _mesh(t.get("mesh", {}), base_dir)
    material = _material(t.get("material", {}))
    plane = _plane(t.get("plane", {}))
    contact = _contact(t.get("contact", {}))
    initial = _initial(t.get("initial", {}), plane)
    time = _time(t.get("time", {}))
    effects = _effects(t.get("effects", {}), gravity, plane, contact, material)
    if effects.contact and contact.law == "barrier" and initial.clearance == 0.0:
        raise ScenarioError("initial.clearance", initial.clearance, "the barrier law needs a positive initial gap")
    return Scenario(name=name, mesh=mesh, material=material, plane=plane, contact=contact, initial=initial,
                    time=time, effects=effects, gravity=gravity, description=description, tags=tags)


def _mesh(raw: object, base_dir: Path) -> MeshSpec:
    """The [mesh] table: a catalogue name and resolution, or an existing file."""
    t = _table(raw, "mesh", MESH_KEYS)
    d = MeshSpec()
    scale = _number(t.get("scale", d.scale), "mesh.scale", gt=0.0)
    if "path" in t:
        for key in ("name", "resolution"):
            if key in t:
                raise ScenarioError(f"mesh.{key}", t[key], "give either a catalogue name or a path, not both")
        path = _string(t["path"], "mesh.path")
        return MeshSpec(name=None, path=_existing_file(path, base_dir), scale=scale)
    name = _string(t.get("name", d.name), "mesh.name")
    resolution = _string(t.get("resolution", d.resolution), "mesh.resolution")
    catalogue = _catalogue()
    if name not in catalogue:
        raise ScenarioError("mesh.name", name, f"not in the mesh catalogue {sorted(catalogue)}")
    if resolution not in catalogue[name]:
        raise ScenarioError("mesh.resolution", resolution,
                            f"mesh {name!r} has resolutions {list(catalogue[name])}")
    return MeshSpec(name=name, resolution=resolution, scale=scale)


def _existing_file(path: str, base_dir: Path) -> str:
    """`path` (`~` expanded) resolved against `base_dir` to an absolute path; a ScenarioError unless a file."""
    resolved = base_dir / path
    try:
        resolved = base_dir / Path(path).expanduser()
        exists = resolved.is_file()
    except (OSError, ValueError, RuntimeError):  # unreadable, NUL in the name, unknown ~user
        exists = False
    if not exists:
        raise ScenarioError("mesh.path", path, f"no such mesh file (looked for {resolved})")
    return str(resolved.resolve())


def _material(raw: object) -> Material:
    """The [material] table."""
    t = _table(raw, "material", MATERIAL_KEYS)
    d = Material()
    nu = _number(t.get("poisson_ratio", d.poisson_ratio), "material.poisson_ratio", gt=-1.0)
    if nu >= 0.5:
        raise ScenarioError("material.poisson_ratio", nu,
                            "must be < 0.5: 0.5 is the incompressible limit, where the Lame parameter is infinite")
    viscosity, ratio = (None if t.get(key) is None else _number(t[key], f"material.{key}", ge=0.0)
                        for key in ("viscosity", "damping_ratio"))
    if viscosity is not None and ratio is not None:
        raise ScenarioError("material.damping_ratio", ratio,
                            f"give either material.viscosity (here {viscosity!r}) or material.damping_ratio, not both")
    return Material(density=_number(t.get("density", d.density), "material.density", gt=0.0),
                    youngs_modulus=_number(t.get("youngs_modulus", d.youngs_modulus), "material.youngs_modulus",
                                           gt=0.0),
                    poisson_ratio=nu, viscosity=viscosity, damping_ratio=ratio)


def _damped(material: Material) -> bool:
    """Whether the material gives a Kelvin-Voigt damping (a viscosity or a damping ratio, possibly zero)."""
    return material.viscosity is not None or material.damping_ratio is not None


def _plane(raw: object) -> Plane | None:
    """The [plane] table (normal or slope form), or None for `plane = false`."""
    if raw is False:
        return None
    if raw is True:
        raise ScenarioError("plane", raw, "expected a [plane] table, or false for no plane")
    t = _table(raw, "plane", PLANE_KEYS)
    d = Plane()
    friction = _number(t.get("friction", d.friction), "plane.friction", ge=0.0)
    offset = _number(t.get("offset", d.offset), "plane.offset")
    if "slope_deg" in t:
        if "normal" in t:
            raise ScenarioError("plane.slope_deg", t["slope_deg"], "give either normal or slope_deg, not both")
        theta = math.radians(_number(t["slope_deg"], "plane.slope_deg", ge=0.0, lt=90.0))
        downhill = _string(t.get("downhill", "x"), "plane.downhill")
        if downhill not in DOWNHILL_AXES:
            raise ScenarioError("plane.downhill", downhill, f"expected one of {list(DOWNHILL_AXES)}")
        hx, hz = DOWNHILL_AXES[downhill]
        # a component that a tiny slope makes subnormal becomes 0.0, as in a given normal (`_finite`)
        x, y, z = (_finite(c, "plane.slope_deg", "") for c in (hx * math.sin(theta), math.cos(theta),
                                                               hz * math.sin(theta)))
        return Plane(normal=(x, y, z), offset=offset, friction=friction)
    if "downhill" in t:
        raise ScenarioError("plane.downhill", t["downhill"], "only meaningful with slope_deg")
    normal = _vec3(t.get("normal", d.normal), "plane.normal")
    norm = math.hypot(*normal)
    if norm == 0.0:
        raise ScenarioError("plane.normal", list(normal), "must be non-zero")
    if abs(norm - 1.0) > _UNIT_TOLERANCE:
        x, y, z = (_finite(c / norm, "plane.normal", "after dividing by |normal|") for c in normal)
        normal = (x, y, z)  # a component the division makes subnormal becomes 0.0 (`_finite`)
        offset = _finite(offset / norm, "plane.offset", "after dividing by |normal|")
    return Plane(normal=normal, offset=offset, friction=friction)


def _contact(raw: object) -> Contact:
    """The [contact] table."""
    t = _table(raw, "contact", CONTACT_KEYS)
    d = Contact()
    law = _string(t.get("law", d.law), "contact.law")
    if law not in CONTACT_LAWS:
        raise ScenarioError("contact.law", law, f"expected one of {list(CONTACT_LAWS)}")
    ratio = None
    if "damping_ratio" in t:
        ratio = _number(t["damping_ratio"], "contact.damping_ratio", ge=0.0)
        if "damping" in t:
            raise ScenarioError("contact.damping_ratio", ratio,
                                f"give either contact.damping (here {t['damping']!r}) or contact.damping_ratio, not both")
    lag = _string(t.get("lag", d.lag), "contact.lag")
    if lag not in CONTACT_LAGS:
        raise ScenarioError("contact.lag", lag, f"expected one of {list(CONTACT_LAGS)}")
    return Contact(
        law=law,
        stiffness=_stiffness(t.get("stiffness", "auto")),
        damping=_number(t.get("damping", d.damping), "contact.damping", ge=0.0),
        friction_stiffness=_number(t.get("friction_stiffness", d.friction_stiffness), "contact.friction_stiffness",
                                   gt=0.0),
        barrier_distance=_number(t.get("barrier_distance", d.barrier_distance), "contact.barrier_distance",
                                 gt=0.0),
        barrier_stiffness=_number(t.get("barrier_stiffness", d.barrier_stiffness), "contact.barrier_stiffness",
                                  gt=0.0),
        lag=lag,
        damping_ratio=ratio,
    )


def _given(contact: Contact, key: str) -> bool:
    """Whether the canonical dict writes `key` of the [contact] table: always, but `lag` only where it is not the
    default, and either `damping` or (where given) `damping_ratio` (so that scenes without the two keep the hashes
    they had before them)."""
    if key == "lag":
        return contact.lag != Contact.lag
    if key in ("damping", "damping_ratio"):
        return (contact.damping_ratio is not None) == (key == "damping_ratio")
    return True


def _stiffness(value: object) -> float | None:
    """contact.stiffness: a positive number [Pa/m], or "auto" (None: set when the model is built)."""
    if isinstance(value, str):
        if value != "auto":
            raise ScenarioError("contact.stiffness", value, 'expected a positive number or "auto"')
        return None
    return _number(value, "contact.stiffness", gt=0.0)


def _initial(raw: object, plane: Plane | None) -> Initial:
    """The [initial] table; the clearance is measured from the plane, so it needs one."""
    t = _table(raw, "initial", INITIAL_KEYS)
    d = Initial()
    clearance_raw = t.get("clearance", d.clearance if plane is not None else False)
    clearance = None if clearance_raw is False else _number(clearance_raw, "initial.clearance", ge=0.0)
    if clearance is not None and plane is None:
        raise ScenarioError("initial.clearance", clearance, "there is no plane to measure it from (plane = false)")
    squash = _vec3(t.get("squash", d.squash), "initial.squash")
    if not all(1e-3 <= abs(c) <= 1e3 for c in squash):
        raise ScenarioError("initial.squash", list(squash),
                            "every component must be nonzero with magnitude in [1e-3, 1e3] (negative mirrors)")
    return Initial(clearance=clearance,
                   rotation=_vec3(t.get("rotation", d.rotation), "initial.rotation"),
                   translation=_vec3(t.get("translation", d.translation), "initial.translation"),
                   velocity=_vec3(t.get("velocity", d.velocity), "initial.velocity"),
                   angular_velocity=_vec3(t.get("angular_velocity", d.angular_velocity), "initial.angular_velocity"),
                   squash=squash)


def _time(raw: object) -> TimeSpec:
    """The [time] table."""
    t = _table(raw, "time", TIME_KEYS)
    d = TimeSpec()
    dt = _number(t.get("dt", d.dt), "time.dt", gt=0.0)
    duration = _number(t.get("duration", d.duration), "time.duration", gt=0.0)
    if duration < dt:
        raise ScenarioError("time.duration", duration, f"must be >= dt = {dt}")
    frame_every = t.get("frame_every", d.frame_every)
    if isinstance(frame_every, bool) or not isinstance(frame_every, numbers.Integral) or frame_every < 1:
        raise ScenarioError("time.frame_every", frame_every, "expected an integer >= 1")
    integrator = _string(t.get("integrator", d.integrator), "time.integrator")
    if integrator not in integrator_names():
        raise ScenarioError("time.integrator", integrator, f"expected one of {list(integrator_names())}")
    tol = t.get("tol")
    if tol is not None:
        tol = _number(tol, "time.tol", gt=0.0)
    dt_min = t.get("dt_min")
    if dt_min is not None:
        dt_min = _number(dt_min, "time.dt_min", gt=0.0)
        if tol is None:
            raise ScenarioError("time.dt_min", dt_min, "only with time.tol (an adaptive run's smallest step)")
        if dt_min > dt:
            raise ScenarioError("time.dt_min", dt_min, f"must be <= time.dt = {dt:g} (the largest step)")
    return TimeSpec(dt=dt, duration=duration, frame_every=int(frame_every), integrator=integrator, tol=tol,
                    dt_min=dt_min)


def _effects(raw: object, gravity: Vec3, plane: Plane | None, contact: Contact, material: Material) -> Effects:
    """The [effects] table over the defaults the scene implies; a term the scene cannot have is an error."""
    t = _table(raw, "effects", EFFECT_KEYS)
    flags = {key: _bool(value, f"effects.{key}") for key, value in t.items()}
    has_contact = flags.get("contact", plane is not None)
    if has_contact and plane is None:
        raise ScenarioError("effects.contact", True, "there is no plane to touch (plane = false)")
    for key, present in (("friction", plane is not None and plane.friction > 0.0),
                         ("damping", contact.damping > 0.0 or (contact.damping_ratio or 0.0) > 0.0)):
        if flags.get(key) and not has_contact:
            raise ScenarioError(f"effects.{key}", True, "needs the contact term, which this scene does not have")
        flags.setdefault(key, has_contact and present)
    if flags.get("viscosity") and not _damped(material):
        raise ScenarioError("effects.viscosity", True, "needs material.viscosity or material.damping_ratio")
    return Effects(gravity=flags.get("gravity", any(g != 0.0 for g in gravity)),
                   elasticity=flags.get("elasticity", True),
                   contact=has_contact, friction=flags["friction"], damping=flags["damping"],
                   viscosity=flags.get("viscosity", True) or not _damped(material))  # canonical where moot


def _table(value: object, field: str, allowed: tuple[str, ...]) -> Mapping[str, Any]:
    """`value` as a table whose keys are all in `allowed` (`checked_table`; the document is "<scenario>")."""
    return checked_table(value, field, allowed, "<scenario>")


def _number(value: object, field: str, *, gt: float | None = None, ge: float | None = None,
            lt: float | None = None) -> float:
    """A finite real number (never a bool) within the given bounds, as a float."""
    if isinstance(value, bool) or not isinstance(value, numbers.Real):
        raise ScenarioError(field, value, "expected a number")
    try:
        x = float(value)
    except OverflowError:
        raise ScenarioError(field, value, "not representable as a float") from None
    x = _finite(x, field, "")
    if gt is not None and not x > gt:
        raise ScenarioError(field, x, f"must be > {gt:g}")
    if ge is not None and not x >= ge:
        raise ScenarioError(field, x, f"must be >= {ge:g}")
    if lt is not None and not x < lt:
        raise ScenarioError(field, x, f"must be < {lt:g}")
    return x + 0.0  # -0.0 -> 0.0, so equal scenarios have equal canonical dicts


def _finite(x: float, field: str, context: str) -> float:
    """`x` unless it is nan or infinite; -0.0 and subnormal values become 0.0, so that equal scenarios hash
    equally even in a process whose floating-point unit flushes subnormals to zero (as torch sets)."""
    if not math.isfinite(x):
        raise ScenarioError(field, x, f"must be finite {context}".rstrip())
    return 0.0 if abs(x) < sys.float_info.min else x


def _vec3(value: object, field: str) -> Vec3:
    """A list (or tuple) of exactly three finite numbers."""
    if not isinstance(value, (list, tuple)) or len(value) != 3:
        raise ScenarioError(field, value, "expected a list of 3 numbers")
    try:
        x, y, z = (_number(v, field) for v in value)
    except ScenarioError as err:
        raise ScenarioError(field, list(value), f"component {err.value!r}: {err.reason}") from None
    return (x, y, z)


def _string(value: object, field: str) -> str:
    """A string."""
    if not isinstance(value, str):
        raise ScenarioError(field, value, "expected a string")
    return value


def _bool(value: object, field: str) -> bool:
    """A boolean (true / false, not 0 / 1)."""
    if not isinstance(value, bool):
        raise ScenarioError(field, value, "expected true or false")
    return value


def _tags(value: object) -> tuple[str, ...]:
    """A list of strings."""
    if not isinstance(value, (list, tuple)) or not all(isinstance(v, str) for v in value):
        raise ScenarioError("tags", value, "expected a list of strings")
    return tuple(value)

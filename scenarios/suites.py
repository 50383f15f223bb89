"""Suites: a scenario matrix (the cartesian product of axes applied to a base scenario) with a train/test split.

Format (TOML; the shipped suites live in `scenarios/suites/<name>.toml`):

    [suite]
    name = "quick"                  # members are named `<suite>/<labels joined by _>`
    description = "..."
    allow_large = false             # optional: lift the resource guard's bounds (`scenarios.resources`)

    [base]                          # a scenario dict (`scenarios.load` schema) without `name`, shared by all
    [base.material]
    youngs_modulus = 2.0e5

    [[axis]]                        # a field axis: one dotted field and its values
    name = "mu"
    field = "plane.friction"
    values = [0.1, 0.5]
    labels = ["lo", "hi"]           # optional; default: a string value itself, a number `<name><value>` (mu0.1);
                                    # required for any other value (lists, booleans)

    [[axis]]                        # an override axis: every value is a table of overrides with its `label`
    name = "plane"
    values = [{ label = "p1", "plane.normal" = [1.0, 5.0, 2.0], "plane.offset" = -1.5 }]

    [split]                         # optional: product members whose labels match any rule (all of its
    test = [{ plane = "p1" }]       # axis = label pairs) are test members, all others train

    [truth]                         # optional: a ground truth per member (bench/runner.py `build_truths`)
    tol = 0.005                     # stop when two successive runs differ by at most this (pos_rmse_rel,
                                    # fraction of L; in [1e-6, 0.5]); default 0.005
    depth = 4                       # at most this many halvings of dt (integer in [1, 12]); default 4
    integrator = "bdf2"             # the ladder's time integrator; default "bdf2"
    ladders = ["backward-euler"]    # optional: integrators whose ladders also run (to the truth's level) as
                                    # cost-accuracy curves of the frontier
    kind = "step"                   # "step" (default): level k runs at dt / 2^k; "tolerance": level k runs adaptive
    start_tol = 1e-4                # steps (time.tol, docs/physics.md "Adaptive steps") with time.tol =
                                    # start_tol / 8^k (required with and only with kind = "tolerance"; a fraction of
                                    # L in [1e-12, 0.5]): TOLERANCE_FACTOR
    contact_lag = "start"           # the ladder runs' contact.lag: "start" (default, the scenario's),
                                    # "corrected" (one re-lagged solve) or "fixed-point" (lagged iterations;
                                    # docs/physics.md "Contact with the plane")
    newton_tol = 1e-4               # optional: the ladder runs' Newton tolerance [fraction of L per second, in
                                    # [1e-12, 0.01]; default the solver's, 1e-5]: a run of T seconds drifts by at
                                    # most newton_tol T L, so keep newton_tol T well below tol
    chord = true                    # optional (default false): the ladder runs test Newton's convergence with the
                                    # last factorisation first (`NewtonSettings.chord`): the same tolerance test,
                                    # no Hessian or factorisation on the iteration that ends a solve
    chord_contraction = 0.5         # optional (default 0, off; in [0, 0.9], needs chord): modified Newton, a chord
                                    # step shorter than this times the last step is taken without refactorising
                                    # (`NewtonSettings.chord_contraction`); the same tolerance test ends a solve

    [[extra]]                       # a member outside the product, e.g. a held-out plane and friction coefficient
    labels = { plane = "p4", mu = "mu0.35" }
    across = ["mesh"]               # optional: one member per value of these axes, whose overrides apply first
    split = "test"                  # default "test"
    overrides = { "plane.normal" = [-1.0, 5.0, -2.0], "plane.friction" = 0.35 }

Overrides use dotted keys (`"plane.friction"`, or TOML's own dotted keys): a table merges into the table it
lands on key by key, any other value replaces what was there, so `plane = false` removes the plane and a `plane.*`
key on a base without a plane creates one. They apply in order: base, axes in order, then (for an extra) its
crossed axes and its own overrides; a later value for the same field wins. A member's labels map axis names (and
an extra's own label keys) to labels; its name joins the labels in axis order, an extra's own labels last. A
suite without axes has only its extras. Members without a `description` get the suite's.

Every member is validated by `scenarios.load.scenario_from_dict`; errors name the suite file and the member.
"""

from __future__ import annotations

import fnmatch
import itertools
import numbers
import os
import re
from collections.abc import Iterator, Mapping, Sequence
from dataclasses import dataclass, replace
from pathlib import Path
from typing import Any, Literal

from frictionbench.scenarios.errors import ScenarioError, checked_table
from frictionbench.scenarios.load import NAME_PART, read_toml, scenario_from_dict
from frictionbench.scenarios.spec import CONTACT_LAGS, Scenario, integrator_names

Split = Literal["train", "test"]
SPLITS: tuple[Split, ...] = ("train", "test")
SUITES_DIR = Path(__file__).parent / "suites"
SUITE_KEYS = ("suite", "base", "axis", "split", "extra", "truth")
#: Bounds of a truth ladder's tolerance [fraction of L] and depth [halvings].
TRUTH_TOL_RANGE = (1e-6, 0.5)
TRUTH_DEPTH_RANGE = (1, 12)
#: The kinds of truth ladder: halved time steps, or adaptive runs at divided tolerances.
TRUTH_KINDS = ("step", "tolerance")
#: Bounds of a tolerance ladder's first time.tol [fraction of L].
TRUTH_START_TOL_RANGE = (1e-12, 0.5)
#: Bounds of a truth ladder's Newton tolerance [fraction of L per second].
TRUTH_NEWTON_TOL_RANGE = (1e-12, 1e-2)
#: Bounds of a truth ladder's chord contraction (a ratio of step norms; 0 off, below 1 so that modified Newton's steps
#: shrink).
TRUTH_CHORD_CONTRACTION_RANGE = (0.0, 0.9)
#: A tolerance ladder divides time.tol by this from level to level: a local error of order p + 1 = 3 (BDF2) then
#: shrinks the steps by 8^(1/3) = 2 and the global error by 4 per level, as a halving of dt does.
TOLERANCE_FACTOR = 8.0

_LABEL_RE = re.compile(NAME_PART)


@dataclass(frozen=True)
class SuiteMember:
    """One scenario of a suite, its split and its labels (axis name -> label, e.g. {"mesh": "cheese"})."""

    scenario: Scenario
    split: Split
    labels: Mapping[str, str]


@dataclass(frozen=True)
class TruthSpec:
    """How a suite's ground truths are made (`[truth]` table): the ladder's tolerance `tol` [fraction of L], its
    `depth` (most levels after the first), its `integrator`, the integrators of further `ladders` run for the
    frontier only, and its `kind`: `step` (level k at dt / 2^k) or `tolerance` (level k adaptive with time.tol =
    `start_tol` / TOLERANCE_FACTOR^k, `level_tol`; start_tol None for the step kind); `contact_lag`: the
    `contact.lag` of its runs (`start`: the scenario's own; a numerical choice, so every lag converges to the same
    truth); `newton_tol`: its runs' Newton tolerance [fraction of L per second] (None: the solver's default, 1e-5).
    A step's test bounds its velocity error by newton_tol L, so a run of duration T drifts by at most
    newton_tol T L: a tolerance with newton_tol T well below `tol` cannot move the truth by more than that.
    `chord`: its runs test Newton's convergence with the last factorisation first (`NewtonSettings.chord`);
    `chord_contraction`: with it, modified Newton (`NewtonSettings.chord_contraction`; 0, off)."""

    tol: float = 0.005
    depth: int = 4
    integrator: str = "bdf2"
    ladders: tuple[str, ...] = ()
    kind: str = "step"
    start_tol: float | None = None
    contact_lag: str = "start"
    newton_tol: float | None = None
    chord: bool = False
    chord_contraction: float = 0.0

    @property
    def solver_params(self) -> dict:
        """The full-space solver's parameters of the ladder's runs: its Newton tolerance where `newton_tol` sets
        one, the chord test where `chord` is on, and modified Newton where `chord_contraction` sets it."""
        return ({} if self.newton_tol is None else {"tol": self.newton_tol}) | ({"chord": True} if self.chord else {}) \
            | ({"chord_contraction": self.chord_contraction} if self.chord_contraction else {})

    def level_tol(self, k: int) -> float | None:
        """time.tol [fraction of L] of level k of a tolerance ladder; None for a step ladder."""
        return None if self.start_tol is None else self.start_tol / TOLERANCE_FACTOR ** k

    def with_(self, tol: float | None = None, depth: int | None = None, integrator: str | None = None,
              where: str = "truth", sep: str = ".") -> "TruthSpec":
        """A validated copy with the given fields changed (None keeps a field); errors name `<where><sep><key>`
        (e.g. `--truth-depth` for command-line flags)."""
        d = ({"tol": self.tol, "depth": self.depth, "integrator": self.integrator, "ladders": list(self.ladders),
             "kind": self.kind, "contact_lag": self.contact_lag}
             | ({} if self.start_tol is None else {"start_tol": self.start_tol})
             | ({} if self.newton_tol is None else {"newton_tol": self.newton_tol}) | {"chord": self.chord}
             | ({"chord_contraction": self.chord_contraction} if self.chord_contraction else {}))
        d |= {k: v for k, v in (("tol", tol), ("depth", depth), ("integrator", integrator)) if v is not None}
        return truth_spec(d, where, sep)


@dataclass(frozen=True)
class Suite:
    """A named, validated list of scenarios with a train/test split."""

    name: str
    description: str
    scenarios: tuple[SuiteMember, ...]
    allow_large: bool = False
    truth: TruthSpec | None = None

    def only(self, pattern: str | None) -> "Suite":
        """The members whose names match a shell pattern (`fnmatch`, e.g. `paper/cheese_*`); None keeps all.
        Raises ScenarioError when nothing matches."""
        if pattern is None:
            return self
        kept = tuple(m for m in self.scenarios if fnmatch.fnmatchcase(m.scenario.name, pattern))
        if not kept:
            raise ScenarioError("--only", pattern, f"matches no member of suite {self.name}")
        return replace(self, scenarios=kept)

    def at_resolution(self, resolution: str | None) -> "Suite":
        """Every member on the catalogue mesh of its shape at `resolution` (e.g. `coarse`: paper-damped where a
        2-core machine can afford certified truths); None keeps the members' own. Raises ScenarioError naming
        `--resolution` when a member's mesh is a file or its shape has no mesh at that resolution."""
        if resolution is None:
            return self
        from frictionbench.scenarios.meshes import catalogue  # lazily: loading a suite never touches mesh code

        meshes = catalogue()
        for m in self.scenarios:
            mesh = m.scenario.mesh
            if mesh.path is not None or resolution not in meshes.get(mesh.name, ()):
                raise ScenarioError("--resolution", resolution,
                                    f"member {m.scenario.name}'s mesh {mesh.path or mesh.name!r} has no such catalogue "
                                    f"resolution; catalogue: { {k: sorted(v) for k, v in meshes.items()} }")
        return replace(self, scenarios=tuple(
            replace(m, scenario=replace(m.scenario, mesh=replace(m.scenario.mesh, resolution=resolution)))
            for m in self.scenarios))

    @property
    def train(self) -> tuple[SuiteMember, ...]:
        """The training members, in suite order."""
        return tuple(m for m in self.scenarios if m.split == "train")

    @property
    def test(self) -> tuple[SuiteMember, ...]:
        """The held-out members, in suite order."""
        return tuple(m for m in self.scenarios if m.split == "test")


@dataclass(frozen=True)
class _Axis:
    """A parsed axis: its name and, per value, the label and the nested overrides."""

    name: str
    values: tuple[tuple[str, dict[str, Any]], ...]


@dataclass(frozen=True)
class _Draft:
    """A member before validation: its name, scenario dict, split and labels."""

    name: str
    scenario: dict[str, Any]
    split: Split
    labels: dict[str, str]


def list_suites() -> list[str]:
    """Names of the shipped suites."""
    return sorted(p.stem for p in SUITES_DIR.glob("*.toml"))


def load_suite(name_or_path: str | os.PathLike[str]) -> Suite:
    """Load a shipped suite by name (`quick`) or any suite file by path, expanded and validated."""
    text = os.fspath(name_or_path)
    if isinstance(name_or_path, os.PathLike) or text.endswith(".toml") or os.sep in text or "/" in text:
        path = Path(text)
    else:
        path = SUITES_DIR / f"{text}.toml"
        if not path.is_file():
            raise ScenarioError("suite", text, f"no such suite; shipped suites: {list_suites()}")
    return suite_from_dict(read_toml(path), source=str(path), base_dir=path.parent)


def suite_from_dict(d: Mapping[str, Any], source: str = "<dict>",
                    base_dir: str | os.PathLike[str] | None = None) -> Suite:
    """Expand a suite dict (the format above) and validate every member.

    source: where the dict came from, appended to error messages.
    base_dir: folder that relative `mesh.path` entries resolve against (default: the working directory).
    """
    try:
        name, description, allow_large, drafts = _expand(d)
        truth = truth_spec(d["truth"]) if "truth" in d else None
    except ScenarioError as err:
        raise type(err)(err.field, err.value, f"{err.reason} [{source}]") from None
    members = tuple(
        SuiteMember(scenario_from_dict(draft.scenario, source=f"{source}, member {draft.name}", base_dir=base_dir),
                    draft.split, draft.labels)
        for draft in drafts)
    return Suite(name=name, description=description, scenarios=members, allow_large=allow_large, truth=truth)


def truth_spec(raw: object, where: str = "truth", sep: str = ".") -> TruthSpec:
    """A validated `[truth]` table; errors name the field `<where><sep><key>` (`truth.depth`)."""
    t = _table(raw, where, ("tol", "depth", "integrator", "ladders", "kind", "start_tol", "contact_lag", "newton_tol",
                            "chord", "chord_contraction"))
    d = TruthSpec()
    tol = _number_in(t.get("tol", d.tol), TRUTH_TOL_RANGE, f"{where}{sep}tol", "a fraction of L")
    depth = t.get("depth", d.depth)
    lo_d, hi_d = TRUTH_DEPTH_RANGE
    if isinstance(depth, bool) or not isinstance(depth, int) or not lo_d <= depth <= hi_d:
        raise ScenarioError(f"{where}{sep}depth", depth, f"expected an integer in [{lo_d}, {hi_d}] (halvings of dt)")
    integrator = t.get("integrator", d.integrator)
    names = integrator_names()
    if integrator not in names:
        raise ScenarioError(f"{where}{sep}integrator", integrator, f"expected one of {list(names)}")
    ladders = _array(t.get("ladders", []), f"{where}{sep}ladders")
    for i, name in enumerate(ladders):
        if name not in names:
            raise ScenarioError(f"{where}{sep}ladders[{i}]", name, f"expected one of {list(names)}")
    kind = t.get("kind", d.kind)
    if kind not in TRUTH_KINDS:
        raise ScenarioError(f"{where}{sep}kind", kind, f"expected one of {list(TRUTH_KINDS)}")
    start_tol = t.get("start_tol")
    if kind == "tolerance" and start_tol is None:
        raise ScenarioError(f"{where}{sep}start_tol", start_tol, f"required with {where}{sep}kind = 'tolerance' (the "
                                                                 "first level's time.tol, a fraction of L)")
    if kind != "tolerance" and start_tol is not None:
        raise ScenarioError(f"{where}{sep}start_tol", start_tol, f"only with {where}{sep}kind = 'tolerance'")
    if start_tol is not None:
        start_tol = _number_in(start_tol, TRUTH_START_TOL_RANGE, f"{where}{sep}start_tol", "a fraction of L")
    lag = t.get("contact_lag", d.contact_lag)
    if lag not in CONTACT_LAGS:
        raise ScenarioError(f"{where}{sep}contact_lag", lag, f"expected one of {list(CONTACT_LAGS)}")
    newton_tol = t.get("newton_tol")
    if newton_tol is not None:
        newton_tol = _number_in(newton_tol, TRUTH_NEWTON_TOL_RANGE, f"{where}{sep}newton_tol",
                                "a fraction of L per second")
    chord = t.get("chord", d.chord)
    if not isinstance(chord, bool):
        raise ScenarioError(f"{where}{sep}chord", chord, "expected true or false")
    contraction = _number_in(t.get("chord_contraction", d.chord_contraction), TRUTH_CHORD_CONTRACTION_RANGE,
                             f"{where}{sep}chord_contraction", "a ratio of step norms")
    if contraction and not chord:
        raise ScenarioError(f"{where}{sep}chord_contraction", contraction, f"needs {where}{sep}chord = true")
    return TruthSpec(tol=tol, depth=depth, integrator=integrator,
                     ladders=tuple(dict.fromkeys(x for x in ladders if x != integrator)), kind=kind,
                     start_tol=start_tol, contact_lag=lag, newton_tol=newton_tol,
                     chord=chord, chord_contraction=contraction)


def _number_in(value: object, bounds: tuple[float, float], field: str, unit: str) -> float:
    """`value` as a float when it is a number (not a bool) within `bounds` (inclusive); else an error naming
    `field`, the bounds and the unit."""
    lo, hi = bounds
    if isinstance(value, bool) or not isinstance(value, (int, float)) or not lo <= value <= hi:
        raise ScenarioError(field, value, f"expected a number in [{lo:g}, {hi:g}] ({unit})")
    return float(value)


def _expand(d: object) -> tuple[str, str, bool, list[_Draft]]:
    """Check the suite's structure and build every member's scenario dict (not yet validated)."""
    t = _table(d, "", SUITE_KEYS)
    header = _table(t.get("suite"), "suite", ("name", "description", "allow_large"))
    name = _label(header.get("name"), "suite.name")
    description = header.get("description", "")
    if not isinstance(description, str):
        raise ScenarioError("suite.description", description, "expected a string")
    allow_large = header.get("allow_large", False)
    if not isinstance(allow_large, bool):
        raise ScenarioError("suite.allow_large", allow_large, "expected true or false")
    base = dict(_table(t.get("base", {}), "base", None))
    if "name" in base:
        raise ScenarioError("base.name", base["name"], "members are named by the suite, not by the base")
    base.setdefault("description", description)
    axes = _axes(t.get("axis", []))
    rules = _split_rules(t.get("split", {}), axes)
    drafts = list(_product(name, base, axes, rules))
    drafts += _extras(t.get("extra", []), name, base, axes)
    seen: set[str] = set()
    for draft in drafts:
        if draft.name in seen:
            raise ScenarioError("name", draft.name, "two members of the suite have this name")
        seen.add(draft.name)
    if not drafts:
        raise ScenarioError("axis", [], "the suite has no members: give at least one axis or extra")
    return name, description, allow_large, drafts


def _product(suite: str, base: dict[str, Any], axes: Sequence[_Axis],
             rules: Sequence[Mapping[str, str]]) -> Iterator[_Draft]:
    """The members of the cartesian product of the axes; none without axes."""
    if not axes:
        return
    for combo in itertools.product(*(axis.values for axis in axes)):
        labels = {axis.name: label for axis, (label, _) in zip(axes, combo)}
        scenario = base
        for _, overrides in combo:
            scenario = _merged(scenario, overrides)
        split: Split = "test" if any(_matches(labels, rule) for rule in rules) else "train"
        yield _draft(suite, scenario, split, labels)


def _extras(raw: object, suite: str, base: dict[str, Any], axes: Sequence[_Axis]) -> list[_Draft]:
    """The [[extra]] members, each repeated over the axes it is crossed with."""
    by_name = {axis.name: axis for axis in axes}
    drafts = []
    for i, entry in enumerate(_array(raw, "extra")):
        where = f"extra[{i}]"
        t = _table(entry, where, ("labels", "across", "split", "overrides"))
        own = _table(t.get("labels"), f"{where}.labels", None)
        if not own:
            raise ScenarioError(f"{where}.labels", own, "an extra needs at least one label to be named by")
        own_labels = {_label(k, f"{where}.labels"): _label(v, f"{where}.labels.{k}") for k, v in own.items()}
        split = t.get("split", "test")
        if split not in SPLITS:
            raise ScenarioError(f"{where}.split", split, f"expected one of {list(SPLITS)}")
        across = _array(t.get("across", []), f"{where}.across")
        for axis_name in across:
            if axis_name not in by_name:
                raise ScenarioError(f"{where}.across", axis_name, f"not an axis of this suite {list(by_name)}")
            if axis_name in own_labels:
                raise ScenarioError(f"{where}.labels.{axis_name}", own_labels[axis_name],
                                    "this label comes from the crossed axis")
        crossed = [axis for axis in axes if axis.name in across]
        overrides = _overrides(t.get("overrides", {}), f"{where}.overrides")
        for combo in itertools.product(*(axis.values for axis in crossed)):
            labels = {axis.name: label for axis, (label, _) in zip(crossed, combo)} | own_labels
            scenario = base
            for _, axis_overrides in combo:
                scenario = _merged(scenario, axis_overrides)
            drafts.append(_draft(suite, _merged(scenario, overrides), split, labels))
    return drafts


def _draft(suite: str, scenario: dict[str, Any], split: Split, labels: dict[str, str]) -> _Draft:
    """A named draft member: `<suite>/<labels joined by _>`."""
    name = f"{suite}/{'_'.join(labels.values())}"
    return _Draft(name=name, scenario={**scenario, "name": name}, split=split, labels=labels)


def _axes(raw: object) -> list[_Axis]:
    """The [[axis]] entries: field axes and override axes, names and labels unique."""
    axes: list[_Axis] = []
    for i, entry in enumerate(_array(raw, "axis")):
        where = f"axis[{i}]"
        t = _table(entry, where, ("name", "field", "values", "labels"))
        name = _label(t.get("name"), f"{where}.name")
        if any(axis.name == name for axis in axes):
            raise ScenarioError(f"{where}.name", name, "two axes have this name")
        values = _array(t.get("values"), f"{where}.values")
        if not values:
            raise ScenarioError(f"{where}.values", values, "an axis needs at least one value")
        if "field" in t:
            pairs = _field_values(t, name, values, where)
        else:
            if "labels" in t:
                raise ScenarioError(f"{where}.labels", t["labels"], "override values carry their own `label`")
            pairs = [_override_value(v, f"{where}.values[{j}]") for j, v in enumerate(values)]
        labels = [label for label, _ in pairs]
        for j, label in enumerate(labels):
            if label in labels[:j]:
                raise ScenarioError(f"{where}.values[{j}]", label, "two values of this axis have this label")
        axes.append(_Axis(name=name, values=tuple(pairs)))
    return axes


def _field_values(t: Mapping[str, Any], name: str, values: list[Any],
                  where: str) -> list[tuple[str, dict[str, Any]]]:
    """(label, overrides) per value of a field axis."""
    field = t["field"]
    if not isinstance(field, str):
        raise ScenarioError(f"{where}.field", field, "expected a dotted field name")
    if "labels" in t:
        labels = _array(t["labels"], f"{where}.labels")
        if len(labels) != len(values):
            raise ScenarioError(f"{where}.labels", labels, f"expected {len(values)} labels, one per value")
    else:
        labels = [_default_label(name, v, f"{where}.values[{j}]") for j, v in enumerate(values)]
    return [(_label(label, f"{where}.labels[{j}]"), _overrides({field: v}, f"{where}.field"))
            for j, (label, v) in enumerate(zip(labels, values))]


def _override_value(value: object, where: str) -> tuple[str, dict[str, Any]]:
    """(label, overrides) of one value of an override axis."""
    t = _table(value, where, None)
    if "label" not in t:
        raise ScenarioError(f"{where}.label", None, "missing: an override value needs a label")
    label = _label(t["label"], f"{where}.label")
    return label, _overrides({k: v for k, v in t.items() if k != "label"}, where)


def _default_label(axis: str, value: object, where: str) -> str:
    """A string value itself, `<axis><value>` for a number; other values need explicit labels."""
    if isinstance(value, str):
        return value
    if isinstance(value, numbers.Real) and not isinstance(value, bool):
        return f"{axis}{value}"
    raise ScenarioError(where, value, "give the axis `labels` for values that are neither strings nor numbers")


def _split_rules(raw: object, axes: Sequence[_Axis]) -> list[dict[str, str]]:
    """The [split] test rules: tables of axis name -> label, each naming existing axes and labels."""
    t = _table(raw, "split", ("test",))
    rules = []
    for i, rule in enumerate(_array(t.get("test", []), "split.test")):
        where = f"split.test[{i}]"
        conditions = _table(rule, where, tuple(axis.name for axis in axes))
        if not conditions:
            raise ScenarioError(where, conditions, "an empty rule would match every member")
        for axis in axes:
            if axis.name in conditions and conditions[axis.name] not in [label for label, _ in axis.values]:
                raise ScenarioError(f"{where}.{axis.name}", conditions[axis.name],
                                    f"not a label of axis {axis.name!r}")
        rules.append(dict(conditions))
    return rules


def _matches(labels: Mapping[str, str], rule: Mapping[str, str]) -> bool:
    """Whether every axis = label pair of the rule holds."""
    return all(labels[axis] == label for axis, label in rule.items())


def _overrides(raw: Mapping[str, Any], where: str) -> dict[str, Any]:
    """Dotted-key overrides as one nested dict (`{"plane.friction": 0.1}` -> `{"plane": {"friction": 0.1}}`)."""
    nested: dict[str, Any] = {}
    for key, value in _table(raw, where, None).items():
        parts = key.split(".") if isinstance(key, str) else []
        if not parts or not all(parts):
            raise ScenarioError(f"{where}.{key}", value, "expected a dotted field name like `plane.friction`")
        for part in reversed(parts):
            value = {part: value}
        nested = _merged(nested, value)
    return nested


def _merged(base: Mapping[str, Any], over: Mapping[str, Any]) -> dict[str, Any]:
    """A copy of `base` with `over` applied: tables merge key by key, any other value replaces."""
    out = dict(base)
    for key, value in over.items():
        if isinstance(value, Mapping) and isinstance(out.get(key), Mapping):
            out[key] = _merged(out[key], value)
        else:
            out[key] = value
    return out


def _table(value: object, field: str, allowed: Sequence[str] | None) -> Mapping[str, Any]:
    """`value` as a table whose keys are in `allowed` if given (`checked_table`; the document is "<suite>")."""
    return checked_table(value, field, allowed, "<suite>")


def _array(value: object, field: str) -> list[Any]:
    """`value` as a list."""
    if not isinstance(value, (list, tuple)):
        raise ScenarioError(field, value, "expected a list")
    return list(value)


def _label(value: object, field: str) -> str:
    """A file-name-safe label (letters, digits, `_ . + -`, starting with a letter or digit)."""
    if not isinstance(value, str) or not _LABEL_RE.fullmatch(value):
        raise ScenarioError(field, value, f"expected a name matching {NAME_PART!r}")
    return value

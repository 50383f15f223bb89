"""Variant sets as data: a matrix file (TOML) lists solver variants, read here into `bench.runner.Variant`s.

The sets `frictionbench run --solvers NAME` knows are the files of `bench/matrices/` (NAME.toml); `--matrix FILE`
runs any other file (the reduced-model study's sets are in the repository's `experiments/`). docs/variants.md
describes the format; in short::

    [matrix]
    name = "my-set"                  # optional: the file's stem
    description = "what it measures"

    [[variant]]                      # one entry: a variant, or one per point of its axes
    solver = "licrom"                # a registered solver
    label = "affine-r{r}"            # the rows' name; {axis} is the axis point's tag
    preset = "licrom-affine"         # parameters of bench/matrices/presets.toml (or of the file's [preset.NAME])
    params = { cubature = "all" }    # on top of the preset
    axis = [{ name = "r", param = "r", values = [24, 48] }]
    then = [{ lag = "fixed-point" }, { ladder = { levels = [0, 1], integrators = ["bdf2"] } }]

An entry's other keys are `Variant` fields (overrides, dt_scale, remesh, model, remesh_of, transfer, training);
`from = LABEL` (or a list) starts from variants the file defined before (a `[[base]]` entry defines without
running); `include = SET` puts a shipped set's variants there (`include = "FILE.toml"`: another file's, beside
this one), through the entry's `then` where it has one. `then` applies named transforms in turn, each to
every variant the previous one gave: `ladder` (`step_ladder`), `lag` (`at_lag`; "scene" keeps the scene's), `retune`
(solver settings that train nothing, on the same model), `other_mesh` ("only": `on_other_mesh`; "beside": the variant
and it). Every parameter must be one its solver declares (`Solver.parameters`), checked where the solver imports;
its experimental ones (`Solver.experimental`: knobs for studies of the solver) go in an `experimental` table of the
entry (or of a `retune`), nowhere else.
"""

from __future__ import annotations

import itertools
import tomllib
from collections.abc import Mapping, Sequence
from dataclasses import dataclass, replace
from pathlib import Path
from typing import Any

from frictionbench.bench.runner import Variant
from frictionbench.scenarios.errors import ScenarioError, checked_table
from frictionbench.scenarios.spec import CONTACT_LAGS, integrator_names

#: The shipped variant sets (one file each) and the shared parameter presets.
MATRICES = Path(__file__).with_name("matrices")
PRESETS = MATRICES / "presets.toml"

#: The sets `frictionbench run` runs without --solvers: DEFAULT, or the suite's own in SUITE_DEFAULTS.
DEFAULT = "licrom,licrom-affine,pod,pod-frame,affine,full-sweep"
SUITE_DEFAULTS = {"hard": "hard", "paper": "paper", "paper-damped": "paper"}

#: `--epochs` replaces this parameter of the variants that train.
EPOCHS_PARAM = "epochs"

_FIELDS = ("solver", "label", "params", "remesh", "model", "remesh_of", "overrides", "dt_scale", "transfer",
           "training")
_ENTRY = (*_FIELDS, "experimental", "preset", "axis", "then", "from", "include")
_TRANSFORMS = ("ladder", "lag", "retune", "other_mesh")
_SCENE = "scene"  # the scene's own integrator or contact lag, where a transform takes a list of them


@dataclass(frozen=True)
class Matrix:
    """One matrix file read: its name, description and variants (in the file's order)."""

    name: str
    description: str
    variants: tuple[Variant, ...]


def set_names() -> list[str]:
    """The names of the shipped variant sets (`bench/matrices/*.toml`, presets aside), sorted."""
    return sorted(p.stem for p in MATRICES.glob("*.toml") if p != PRESETS)


def variant_set(name: str) -> list[Variant]:
    """The variants of the shipped set `name` (`bench/matrices/<name>.toml`); an unknown name is a ScenarioError."""
    if name not in set_names():
        raise ScenarioError("--solvers", name, f"unknown variant set; known: {set_names()}")
    return list(load_matrix(MATRICES / f"{name}.toml").variants)


def load_matrix(path: str | Path) -> Matrix:
    """The matrix file at `path`, every entry expanded and transformed; a bad file is a ScenarioError naming the
    field (`<file>:variant[3].then[1].ladder.levels`) and its value."""
    path = Path(path)
    try:
        doc = tomllib.loads(path.read_text())
    except (OSError, UnicodeDecodeError, tomllib.TOMLDecodeError) as err:
        raise ScenarioError(str(path), "", f"cannot read the matrix file: {err}") from None
    top = checked_table(doc, "", ("matrix", "preset", "base", "variant"), str(path))
    head = checked_table(top.get("matrix", {}), "matrix", ("name", "description"), str(path))
    presets = {**_presets(PRESETS), **checked_table(top.get("preset", {}), f"{path}:preset", None, str(path))}
    defined: dict[str, Variant] = {}
    out: list[Variant] = []
    for kind in ("base", "variant"):
        for i, entry in enumerate(top.get(kind, [])):
            made = _entry(entry, f"{path}:{kind}[{i}]", presets, defined, path.parent)
            defined.update({v.label or v.solver: v for v in made})
            if kind == "variant":
                out.extend(made)
    return Matrix(str(head.get("name", path.stem)), str(head.get("description", "")), tuple(out))


def _presets(path: Path) -> dict[str, Any]:
    return tomllib.loads(path.read_text()).get("preset", {}) if path.exists() else {}


def _entry(raw: object, where: str, presets: Mapping[str, Any], defined: Mapping[str, Variant],
           here: Path) -> list[Variant]:
    """One `[[variant]]` or `[[base]]` entry -> its variants (`here`: the folder a `.toml` include is read from)."""
    t = checked_table(raw, where, _ENTRY, where)
    if "include" in t:
        if set(t) - {"include", "then"}:
            raise ScenarioError(where, sorted(t), "an include entry has no other key than then")
        name = str(t["include"])
        starts = load_matrix(here / name).variants if name.endswith(".toml") else variant_set(name)
        return _then(t, list(starts), where)
    labels = [t["from"]] if isinstance(t.get("from"), str) else t.get("from")
    if labels is not None:
        unknown = [s for s in labels if s not in defined]
        if unknown:
            raise ScenarioError(f"{where}.from", unknown, f"not defined above; defined: {sorted(defined)}")
    bases = [defined[s] for s in labels] if labels is not None else [None]
    return [w for base in bases for tags, point in _points(t.get("axis", []), f"{where}.axis")
            for w in _then(t, [_variant(t, point, tags, base, presets, where)], where)]


def _then(t: Mapping[str, Any], made: list[Variant], where: str) -> list[Variant]:
    """The variants `made` through the entry's transforms (`then`), in turn."""
    for j, step in enumerate(t.get("then", [])):
        made = [w for x in made for w in _transform(step, x, f"{where}.then[{j}]")]
    return made


def _points(axes: object, where: str) -> list[tuple[dict[str, str], dict[str, Any]]]:
    """The cartesian product of an entry's axes (first axis outermost): ({axis name: tag}, fields to merge)."""
    expanded = []
    for k, axis in enumerate(axes if isinstance(axes, list) else [axes]):
        a = checked_table(axis, f"{where}[{k}]", ("name", "param", "values"), where)
        if "name" not in a or not isinstance(a.get("values"), list) or not a["values"]:
            raise ScenarioError(f"{where}[{k}]", dict(a), "an axis needs a name and a non-empty list of values")
        points = []
        for value in a["values"]:
            if "param" in a:
                points.append((str(value), {"params": {a["param"]: value}}))
            else:
                p = dict(checked_table(value, f"{where}[{k}].values", (*_FIELDS, "tag"), where))
                points.append((str(p.pop("tag", "")), p))
        expanded.append([(a["name"], tag, p) for tag, p in points])
    out = []
    for combo in itertools.product(*expanded):
        merged: dict[str, Any] = {}
        for _, _, p in combo:
            merged = {**merged, **p, "params": {**merged.get("params", {}), **p.get("params", {})},
                      "overrides": {**merged.get("overrides", {}), **p.get("overrides", {})}}
        out.append(({name: tag for name, tag, _ in combo}, merged))
    return out


def _variant(t: Mapping[str, Any], point: Mapping[str, Any], tags: Mapping[str, str], base: Variant | None,
             presets: Mapping[str, Any], where: str) -> Variant:
    """The entry's variant at one axis point, on `base` (a `from` variant) when given."""
    names = [t["preset"]] if isinstance(t.get("preset"), str) else t.get("preset", [])
    missing = [n for n in names if n not in presets]
    if missing:
        raise ScenarioError(f"{where}.preset", missing, f"unknown preset; known: {sorted(presets)}")
    params = {k: v for n in names for k, v in presets[n].items()}
    named = {**params, **t.get("params", {}), **point.get("params", {})}
    experimental = dict(checked_table(t.get("experimental", {}), f"{where}.experimental", None, where))
    params = {**(base.params if base else {}), **named, **experimental}
    given = {k: t[k] for k in _FIELDS if k in t and k not in ("params", "overrides")} | \
        {k: v for k, v in point.items() if k not in ("params", "overrides")}
    if "label" in given:
        try:
            given["label"] = str(given["label"]).format(**tags)
        except KeyError as err:
            raise ScenarioError(f"{where}.label", given["label"], f"no axis named {err}") from None
    overrides = {**(base.overrides if base else {}), **t.get("overrides", {}), **point.get("overrides", {})}
    try:
        v = replace(base, params=params, overrides=overrides, **given) if base else \
            Variant(params=params, overrides=overrides, **given)
    except (TypeError, ValueError) as err:
        raise ScenarioError(where, dict(t), str(err)) from None
    _check_params(v, where, named, experimental)
    return v


def _check_params(v: Variant, where: str, named: Mapping[str, Any], experimental: Mapping[str, Any]) -> None:
    """Every parameter of `v` is one its solver declares (not checked for a solver unavailable here): those the
    entry names under `params` (`named`, its presets' included) among its `parameters`, those under `experimental`
    among its `experimental` ones (`Solver.experimental`)."""
    from frictionbench.solvers.registry import get_solver, solver_names, unavailable

    if v.solver not in solver_names():
        raise ScenarioError(f"{where}.solver", v.solver, f"unknown solver; known: {sorted(solver_names())}")
    if unavailable(v.solver) is not None:
        return
    cls = get_solver(v.solver)
    declared, studied = set(cls.parameters), set(cls.experimental)
    if misplaced := sorted(set(named) & studied):
        raise ScenarioError(f"{where}.params", misplaced, f"experimental parameter(s) of solver {v.solver!r}: set "
                            f"them in the entry's `experimental` table")
    if wrong := sorted(set(experimental) - studied):
        raise ScenarioError(f"{where}.experimental", wrong, f"not an experimental parameter of solver {v.solver!r};"
                            f" its experimental ones: {sorted(studied)}")
    if unknown := sorted(set(v.params) - declared - studied):
        raise ScenarioError(f"{where}.params", unknown, f"unknown parameter(s) of solver {v.solver!r}; it "
                            f"declares {sorted(declared)}")


def _transform(raw: object, v: Variant, where: str) -> list[Variant]:
    """One named transform of `then` applied to `v`."""
    t = checked_table(raw, where, _TRANSFORMS, where)
    if len(t) != 1:
        raise ScenarioError(where, dict(t), f"one transform per entry of then, one of {list(_TRANSFORMS)}")
    (name, arg), = t.items()
    if name == "ladder":
        a = checked_table(arg, f"{where}.ladder", ("levels", "integrators", "twin"), where)
        try:
            return step_ladder(v, levels=a.get("levels", (0, 1, 2, 3)),
                               integrators=[None if i == _SCENE else i for i in a.get("integrators", [_SCENE, "bdf2"])],
                               twin=a.get("twin"))
        except ValueError as err:
            raise ScenarioError(f"{where}.ladder", dict(a), str(err)) from None
    if name == "lag":
        lags = [arg] if isinstance(arg, str) else arg
        bad = [lag for lag in lags if lag != _SCENE and lag not in CONTACT_LAGS]
        if bad:
            raise ScenarioError(f"{where}.lag", bad, f"expected {_SCENE!r} or one of {list(CONTACT_LAGS)}")
        return [v if lag == _SCENE else at_lag(v, lag) for lag in lags]
    if name == "retune":
        a = checked_table(arg, f"{where}.retune", ("params", "experimental", "suffix"), where)
        named, experimental = dict(a.get("params", {})), dict(a.get("experimental", {}))
        tuned = replace(v, label=f"{v.label}{a.get('suffix', '')}", params=v.params | named | experimental,
                        model=v.model or v.label)
        _check_params(tuned, f"{where}.retune", named, experimental)
        return [tuned]
    if arg not in ("only", "beside"):
        raise ScenarioError(f"{where}.other_mesh", arg, "expected 'only' or 'beside'")
    return [on_other_mesh(v)] if arg == "only" else [v, on_other_mesh(v)]


def curve_name(label: str, integrator: str | None = None) -> str:
    """The name of a step ladder's curve (`step_ladder`): its base variant's label, and the integrator where the
    ladder sets one (None: the scene's own)."""
    return f"{label}-{integrator}" if integrator else label


def step_ladder(variant: Variant, levels: Sequence[int] = (0, 1, 2, 3),
                integrators: Sequence[str | None] = (None, "bdf2"), twin: str | None = None) -> list[Variant]:
    """The variant's own accuracy-for-time curves: per integrator (None: the scene's own; a name of
    `scenarios.spec.integrator_names()` sets time.integrator) and level k of `levels`, the variant at dt / 2^k
    (its `dt_scale` x 2^-k) storing its frames at the same times (frame_every x 2^k), as the truth's ladder does.

    Labels are `<label>[-<integrator>][-dt/<2^k>]` (`affine-r24-cub60-bdf2-dt/4`; level 0 with the scene's
    integrator is the variant itself, its label unchanged). Every level shares the variant's trained model (`model`:
    the variant's, else its label; no level trains anything). Each carries its curve (`curve_name` of the variant's
    label and the integrator), its level and, with `twin` (the label of the same variant with every tet, where this
    one runs an optimised cubature), the twin's curve with the same integrator, which `analysis.curves` compares it
    with. Pure: nothing runs."""
    if not levels or any(not isinstance(k, int) or isinstance(k, bool) or k < 0 for k in levels) \
            or len(set(levels)) != len(levels):
        raise ValueError(f"step_ladder of {variant.label!r}: levels must be distinct integers >= 0, got {levels}")
    unknown = [i for i in integrators if i is not None and i not in integrator_names()]
    if unknown or not integrators or len(set(integrators)) != len(integrators):
        raise ValueError(f"step_ladder of {variant.label!r}: integrators {list(integrators)} must be distinct, "
                         f"{_SCENE!r} or one of {list(integrator_names())}")
    base = variant.label or variant.solver
    out = []
    for integrator in integrators:
        curve = curve_name(base, integrator)
        overrides = variant.overrides | ({"time.integrator": integrator} if integrator else {})
        for k in sorted(levels):
            out.append(replace(variant, label=curve if k == 0 else f"{curve}-dt/{2 ** k}", model=variant.model or base,
                               overrides=overrides, dt_scale=variant.dt_scale * 0.5 ** k,
                               frame_scale=variant.frame_scale * 2 ** k,
                               tags={"curve": curve, "curve_level": k}
                               | ({"curve_twin": curve_name(twin, integrator)} if twin else {})))
    return out


def at_lag(variant: Variant, lag: str) -> Variant:
    """The variant with contact lagged by the rule `lag` (`contact.lag`: "corrected", one re-lagged solve at the
    first solve's end; "fixed-point", as the truth ladders run) instead of the scene's; labelled `<label>-<lag>`."""
    return replace(variant, label=f"{variant.label}-{lag}", overrides=variant.overrides | {"contact.lag": lag})


def on_other_mesh(variant: Variant) -> Variant:
    """The variant on the other mesh of the shape (`remesh="alt"`: coarse -> coarse_alt), on the variant's trained
    model and compared with the variant itself (`remesh_of`, for `remesh_ratio`); labelled `<label>-remesh`, a point
    of no curve (its accuracy-for-time curve is the variant's own)."""
    return replace(variant, label=f"{variant.label}-remesh", remesh="alt", model=variant.model or variant.label,
                   remesh_of=variant.label, tags={})



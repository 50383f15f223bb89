"""Named variant sets for `frictionbench run --solvers`: each name expands to solver variants of the matrix.

`remesh="alt"` runs the variant on the independently generated mesh of the same shape (coarse -> coarse_alt),
compared with the full-space run on that mesh. Reduced models train on the suite's training split per shape.
A set is a list of variants, or, for a grid (which imports its solver to check its parameters), a function building
it when it is asked for (`variant_set`): importing this module imports no solver.
"""

from __future__ import annotations

import itertools
from collections.abc import Callable, Sequence
from dataclasses import replace

from frictionbench.bench.runner import Variant
from frictionbench.scenarios.model import integrator_names
from frictionbench.solvers.registry import get_solver, unavailable

EPOCHS = 30  # CI-sized default; `frictionbench run --epochs 1000` for the paper's figure
POINTS = 128
LICROM = {"r": 20, "epochs": EPOCHS, "points": POINTS, "affine": False, "cubature": "all", "scheme": "newton"}
LICROM_AFFINE = {"r": 24, "epochs": EPOCHS, "points": POINTS, "affine": True, "cubature": "all", "scheme": "newton"}

def grid(solver: str, label: str, base: dict | None = None, **axes: list) -> list[Variant]:
    """The variants of `solver` over the cartesian product of `axes` (parameter name -> values) on top of the
    parameters `base`, labelled `label.format(**point)` (e.g. grid("licrom", "r{r}", LICROM, r=[8, 16])). Every
    axis and base parameter must be one the solver declares (`Solver.parameters`): an unknown one is an error
    naming it and the declared ones; for a solver unavailable here (`solvers.registry.unavailable`) they are not
    checked, and the runner skips its variants with the reason."""
    declared = get_solver(solver).parameters if unavailable(solver) is None else None
    unknown = sorted((set(axes) | set(base or {})) - set(declared)) if declared is not None else []
    if unknown:
        raise ValueError(f"grid of solver {solver!r}: unknown parameter(s) {unknown}; it declares {sorted(declared)}")
    names = list(axes)
    return [Variant(solver, dict(base or {}) | dict(zip(names, values)),
                    label=label.format(**dict(zip(names, values))))
            for values in itertools.product(*(axes[n] for n in names))]


def curve_name(label: str, integrator: str | None = None) -> str:
    """The name of a step ladder's curve (`step_ladder`): its base variant's label, and the integrator where the
    ladder sets one (None: the scene's own)."""
    return f"{label}-{integrator}" if integrator else label


def step_ladder(variant: Variant, levels: Sequence[int] = (0, 1, 2, 3),
                integrators: Sequence[str | None] = (None, "bdf2"), twin: Variant | None = None) -> list[Variant]:
    """The variant's own accuracy-for-time curves: per integrator (None: the scene's own; a name of
    `scenarios.model.integrator_names()` sets time.integrator) and level k of `levels`, the variant at dt / 2^k
    (its `dt_scale` x 2^-k) storing its frames at the same times (frame_every x 2^k), as the truth's ladder does.

    Labels are `<label>[-<integrator>][-dt/<2^k>]` (`affine-r24-cub60-bdf2-dt/4`; level 0 with the scene's
    integrator is the variant itself, its label unchanged). Every level shares the variant's trained model (`model`:
    the variant's, else its label; its parameters, which the training key is made of, are the variant's own: no
    level trains anything). Each carries its curve (`curve_name` of the variant's label and the integrator), its
    level and, with `twin` (the same variant with every tet, where this one runs an optimised cubature), the twin's
    curve with the same integrator, which `analysis.curves` compares it with. Pure: nothing runs, nothing is
    imported."""
    if not levels or any(not isinstance(k, int) or isinstance(k, bool) or k < 0 for k in levels) \
            or len(set(levels)) != len(levels):
        raise ValueError(f"step_ladder of {variant.label!r}: levels must be distinct integers >= 0, got {levels}")
    unknown = [i for i in integrators if i is not None and i not in integrator_names()]
    if unknown or not integrators or len(set(integrators)) != len(integrators):
        raise ValueError(f"step_ladder of {variant.label!r}: integrators {list(integrators)} must be distinct, None "
                         f"or one of {list(integrator_names())}")
    base = variant.label or variant.solver
    out = []
    for integrator in integrators:
        curve = curve_name(base, integrator)
        overrides = variant.overrides | ({"time.integrator": integrator} if integrator else {})
        for k in sorted(levels):
            out.append(replace(variant, label=curve if k == 0 else f"{curve}-dt/{2 ** k}", model=variant.model or base,
                               overrides=overrides, dt_scale=variant.dt_scale * 0.5 ** k,
                               frame_scale=variant.frame_scale * 2 ** k, curve=curve, curve_level=k,
                               curve_twin=curve_name(twin.label or twin.solver, integrator) if twin else ""))
    return out


#: The full-space solver at half the reference's time step: how far the reference itself is from time-converged
#: (results rows get it as `ref_dt_change`, analysis/derived.py `with_ref_dt_change`).
DT_HALF = Variant("full", {}, label="dt-half", dt_scale=0.5)

#: The full-space solver with BDF2 (second order, `solvers.integrators`) instead of the reference's backward Euler, at
#: the same time step: how much of the reference's time error the integrator alone removes.
BDF2 = Variant("full", {}, label="bdf2", overrides={"time.integrator": "bdf2"})

#: The local error tolerances [fraction of L] of the `adaptive` set's runs.
ADAPTIVE_TOLS = (1e-3, 1e-4, 1e-5)

#: The local error tolerance [fraction of L] of the hard suite's adaptive runs.
HARD_TOL = 1e-4

#: The full-space solver with the barrier contact law (same friction potential) instead of the reference's penalty law.
BARRIER = Variant("full", {}, label="barrier", overrides={"contact.law": "barrier"})

#: The full-space solver under backward Euler with the barrier law, and under BDF2 and adaptive BDF2 with either law.
INTEGRATORS = [
    BARRIER,
    BDF2,
    Variant("full", {}, label="bdf2-barrier", overrides={"time.integrator": "bdf2", "contact.law": "barrier"}),
    Variant("full", {}, label="adaptive", overrides={"time.integrator": "bdf2", "time.tol": HARD_TOL}),
    Variant("full", {}, label="adaptive-barrier",
            overrides={"time.integrator": "bdf2", "time.tol": HARD_TOL, "contact.law": "barrier"}),
]

#: Newton's VBD solver (a peer engine, `solvers.newton_vbd`) at its defaults: one substep of 10 iterations.
NEWTON_VBD_DEFAULT = Variant("newton-vbd", {"substeps": 1, "iterations": 10}, label="s1-i10")

#: Newton's VBD ladder: substeps at its default 10 iterations, and iterations at one substep.
NEWTON_VBD = [NEWTON_VBD_DEFAULT,
              *(Variant("newton-vbd", {"substeps": s, "iterations": 10}, label=f"s{s}-i10") for s in (4, 16, 64)),
              *(Variant("newton-vbd", {"substeps": 1, "iterations": i}, label=f"s1-i{i}") for i in (5, 20, 50))]

#: LiCROM with the 12 affine columns, r = 24, on every tet and on 60 optimised cubature tets (its all-tets twin).
AFFINE_R24 = Variant("licrom", LICROM_AFFINE, label="affine-r24")
AFFINE_R24_CUB60 = Variant("licrom", LICROM_AFFINE | {"cubature": "optimized:60"}, label="affine-r24-cub60")


def at_lag(variant: Variant, lag: str) -> Variant:
    """The variant with contact lagged by the rule `lag` (`contact.lag`: "corrected", one re-lagged solve at the
    first solve's end; "fixed-point", as the truth ladders of paper-damped run) instead of the scene's start of the
    step; labelled `<label>-<lag>`."""
    return replace(variant, label=f"{variant.label}-{lag}", overrides=variant.overrides | {"contact.lag": lag})


def at_fixed_point(variant: Variant) -> Variant:
    """The variant with contact lagged to each step's fixed point (`at_lag`); labelled `<label>-fixed-point`."""
    return at_lag(variant, "fixed-point")


#: The cubature variant at the fixed point, on its trained model: whether a reduced curve's floor is the reduced
#: dynamics or the start-of-step lag of friction's normal pressure.
AFFINE_R24_CUB60_FIXED_POINT = replace(at_fixed_point(AFFINE_R24_CUB60), model=AFFINE_R24_CUB60.label)

#: The `rank-dynamics` set, before it is moved to the truth ladders' step settings: POD with the affine columns
#: trained on the truths (the best a linear subspace of its size holds, the members' own answers in it) at r = 12
#: (the affine fields alone), 36 and 84 on every tet, and at 36 and 84 on the references (what a user without a
#: truth can fit); LiCROM+affine at r = 48 and 96 on an optimised cubature of 2.5 r tets, trained on the references
#: and on the truths; r = 96 on every tet as well (the cubature's share).
RANK_DYNAMICS = [
    *(Variant("pod", {"r": r, "affine": True}, label=f"pod-affine-r{r}-truthdata", training="truth")
      for r in (12, 36, 84)),
    *(Variant("pod", {"r": r, "affine": True}, label=f"pod-affine-r{r}") for r in (36, 84)),
    *(Variant("licrom", LICROM_AFFINE | {"r": r, "cubature": cubature}, label=f"affine-r{r}{tag}{data_tag}",
              training=data)
      for r, cubature, tag in ((48, "optimized:120", "-cub120"), (96, "optimized:240", "-cub240"), (96, "all", ""))
      for data, data_tag in (("reference", ""), ("truth", "-truthdata"))),
]


#: The `pod-cubature` set's variants: POD with the affine columns at the ranks the reduced dynamics need
#: (`rank-dynamics`: 36 and 84) on an optimised cubature of 2.5 r tets (90, 210) instead of every tet, trained on the
#: truths and on the references: whether those ranks keep their accuracy at a cubature's cost.
POD_CUBATURE = [Variant("pod", {"r": r, "affine": True, "cubature": f"optimized:{5 * r // 2}"},
                        label=f"pod-affine-r{r}-cub{5 * r // 2}{tag}", training=data)
                for r in (36, 84) for data, tag in (("truth", "-truthdata"), ("reference", ""))]


#: POD with the affine columns at r = 60 on an optimised cubature of 150 tets (2.5 r, as `POD_CUBATURE`), fitted to
#: the truths and to the references: the rank between the two of `pod-cubature`.
POD_R60 = [Variant("pod", {"r": 60, "affine": True, "cubature": "optimized:150"}, label=f"pod-affine-r60-cub150{tag}",
                   training=data) for data, tag in (("truth", "-truthdata"), ("reference", ""))]

#: The `pod-fast` points' solver settings: Newton's tolerance of the full-space `tol1e-3` sweep (1e-3 L/s, where the
#: default is 1e-5) and the reduced Hessian's dense products in single precision (`solvers.licrom.reduced`,
#: `HESSIAN_PRECISIONS`); and with them, the body terms' Hessian evaluated once a step (`HESSIAN_REFRESHES`).
FAST = {"tol": 1e-3, "hessian": "single"}
FAST_STEP = FAST | {"hessian_refresh": "step"}


def fast(variant: Variant, settings: dict = FAST) -> Variant:
    """The variant at the `FAST` settings, or at `FAST_STEP`'s, on its trained model (no setting is a training
    parameter); labelled `<label>-tol1e-3-single`, and `-step` after it for `FAST_STEP`."""
    tag = "-tol1e-3-single" + ("-step" if settings.get("hessian_refresh") == "step" else "")
    return replace(variant, label=f"{variant.label}{tag}", params=variant.params | settings,
                   model=variant.model or variant.label)


#: `pod-cubature`'s r = 84 variant fitted to the truths, and the same on every tet, on its subspace (its model): the
#: all-tets twin of the r = 84 truth-fitted cubature curves.
POD_R84_TRUTH = next(v for v in POD_CUBATURE if v.params["r"] == 84 and v.training == "truth")
POD_R84_EVERY_TET = replace(POD_R84_TRUTH, label="pod-affine-r84-truthdata", model=POD_R84_TRUTH.label,
                            params=POD_R84_TRUTH.params | {"cubature": "all"})
#: The optimised cubatures' sizes of `pod-cubature-size` [tets]: 2.5 r (as `POD_CUBATURE`) and 5 r (the greedy
#: selection slows as it grows: 420 tets took 8 minutes on the coarse sphere's training states, 210 two).
CUBATURE_SIZES = (210, 420)


def _pod_fast() -> list[Variant]:
    """The `pod-fast` set: under BDF2 with the start lag at dt, dt/2 and dt/4, POD at r = 60 on 150 tets at the
    default settings (r = 36 and 84 at them are `pod-cubature`'s), and at r = 36, 60 and 84 (on 90, 150 and 210 tets)
    at `FAST`'s and at `FAST_STEP`'s, each fitted to the truths and to the references; r = 84 fitted to the truths at
    `FAST_STEP`'s with contact at each step's fixed point (where the frictional members are accurate, its several
    solves a step sharing one body Hessian); the two r = 84 truth-fitted `FAST_STEP` curves again on every tet, their
    twins (the same subspace: where a curve flattens, whether its cubature floors it, `analysis.curves`); and the
    full-space solver at FAST's tolerance on the paper-damped truth ladders' settings (BDF2, contact at each step's
    fixed point) at dt, dt/2 and dt/4, so that the looser tolerance is measured on both sides, and at the default
    tolerance (the truth ladder's levels again, measured beside the rest of the set rather than in whichever run
    built the ladder)."""
    by_rank = sorted([*POD_CUBATURE, *POD_R60], key=lambda v: v.params["r"])
    full = [at_fixed_point(Variant("full", {"tol": tol}, label=label))
            for label, tol in (("tol1e-3", FAST["tol"]), ("tol1e-5", 1e-5))]
    r84, every_tet = fast(POD_R84_TRUTH, FAST_STEP), fast(POD_R84_EVERY_TET, FAST_STEP)
    twins = {r84.label: every_tet, at_fixed_point(r84).label: at_fixed_point(every_tet)}
    curves = (*POD_R60, *map(fast, by_rank), *(fast(v, FAST_STEP) for v in by_rank), at_fixed_point(r84),
              *twins.values(), *full)
    return [level for v in curves
            for level in step_ladder(v, levels=(0, 1, 2), integrators=("bdf2",), twin=twins.get(v.label))]


def _pod_cubature_size() -> list[Variant]:
    """The `pod-cubature-size` set: POD r = 84 fitted to the truths at `FAST_STEP`'s (the start lag) on
    CUBATURE_SIZES optimised tets and on every tet, each a curve at dt, dt/2 and dt/4 under BDF2 on the same subspace,
    the cubature curves with the all-tets one as their twin: what a larger cubature buys, and costs, where the
    cubature floors a curve."""
    every_tet = fast(POD_R84_EVERY_TET, FAST_STEP)
    sizes = [fast(replace(POD_R84_TRUTH, label=f"pod-affine-r84-cub{c}-truthdata", model=POD_R84_TRUTH.label,
                          params=POD_R84_TRUTH.params | {"cubature": f"optimized:{c}"}), FAST_STEP)
             for c in CUBATURE_SIZES]
    return [level for v in (*sizes, every_tet)
            for level in step_ladder(v, levels=(0, 1, 2), integrators=("bdf2",), twin=None if v is every_tet
                                     else every_tet)]


#: The ranks of `pod-rank` above r = 84 (POD fitted to the truths, every tet): a held-out member's error falls with the
#: rank long after its err_projection is small (docs/figures.md), and every tet keeps the cubature out of the sweep.
HELD_OUT_RANKS = (120, 180, 240, 300)


def _pod_rank() -> list[Variant]:
    """The `pod-rank` set: POD fitted to the truths on every tet at r = 84 (`pod-fast`'s every-tet twin, the same
    run) and HELD_OUT_RANKS, at `FAST_STEP`'s settings and the truth ladders' step settings (`at_truth_step`): the
    reduced dynamics' error against rank where the time step no longer decides it."""
    ranks = [POD_R84_EVERY_TET, *(Variant("pod", {"r": r, "affine": True, "cubature": "all"},
                                          label=f"pod-affine-r{r}-truthdata", training="truth")
                               for r in HELD_OUT_RANKS)]
    return [at_truth_step(fast(v, FAST_STEP)) for v in ranks]


def on_other_mesh(variant: Variant) -> Variant:
    """The variant on the other mesh of the shape (`remesh="alt"`: coarse -> coarse_alt), on the variant's trained
    model and compared with the variant itself (`remesh_of`, for `remesh_ratio`); labelled `<label>-remesh`, a point
    of no curve (its accuracy-for-time curve is the variant's own)."""
    return replace(variant, label=f"{variant.label}-remesh", remesh="alt", model=variant.model or variant.label,
                   remesh_of=variant.label, curve="", curve_level=None, curve_twin="")


def at_truth_step(variant: Variant) -> Variant:
    """The variant under the paper-damped truth ladders' integrator and contact lag (BDF2, contact at each step's
    fixed point, `contact.lag = "fixed-point"`) at dt/4 of the scene's step, where those ladders are about 1% of L
    from their truths: what a variant misses there is its reduction's error, not its step's. Labelled
    `<label>-fixed-point-bdf2-dt/4`; a one-level `step_ladder` of `at_fixed_point`."""
    return step_ladder(at_fixed_point(variant), levels=(2,), integrators=("bdf2",))[0]


#: The ranks of the `licrom-rank` sweep: LiCROM with the affine columns, every tet (r counts the 12 affine columns,
#: so r = 12 is the affine subspace alone, the `affine12` baseline, which the set runs as its first point).
RANKS = (24, 48, 96)

#: The 12 affine columns alone (`solvers.baselines`): the rank sweep's r = 12.
AFFINE12 = Variant("affine", {}, label="affine12")

#: The two variants above trained on the training members' truths instead of their references (`Variant.training`).
AFFINE_R24_TRUTHDATA = replace(AFFINE_R24, label="affine-r24-truthdata", training="truth")
AFFINE_R24_CUB60_TRUTHDATA = replace(AFFINE_R24_CUB60, label="affine-r24-cub60-truthdata", training="truth")


def _pod_remesh_points() -> list[Variant]:
    """The `pod-cubature` points that `pod-remesh` carries to the other mesh: BDF2 at dt and dt/2 with the start lag,
    at dt/4 with the fixed point."""
    return [level for v in POD_CUBATURE
            for lagged, levels in ((v, (0, 1)), (at_fixed_point(v), (2,)))
            for level in step_ladder(lagged, levels=levels, integrators=("bdf2",))]


VARIANTS: dict[str, list[Variant] | Callable[[], list[Variant]]] = {
    "licrom": [Variant("licrom", LICROM, label="r20")],
    "licrom-affine": [Variant("licrom", LICROM_AFFINE, label="affine-r24"),
                      Variant("licrom", LICROM_AFFINE, label="affine-r24-remesh", remesh="alt", model="affine-r24"),
                      Variant("licrom", LICROM_AFFINE | {"cubature": "optimized:60"}, label="affine-r24-cub60")],
    # the paper's projected-gradient scheme, iterated to convergence (hundreds of iterations a step, 0.2-0.5 s a
    # step on the coarse cheese): on demand, and in the hard set; the paper set runs it on the optimised cubature
    "licrom-pg": [Variant("licrom", LICROM_AFFINE | {"scheme": "projected_gradient"}, label="affine-r24-pg")],
    # LiCROM's online integrator as released: the projected gradient at a fixed 3 iterations a step, the latent
    # velocity scaled by 0.99 before each step; on demand, beside ours (issue 22, point 4)
    "licrom-released": [Variant("licrom", LICROM_AFFINE | {"scheme": "projected_gradient", "iterations": 3,
                                                          "velocity_scale": 0.99}, label="affine-r24-released"),
                        Variant("licrom", LICROM_AFFINE | {"cubature": "optimized:60", "scheme": "projected_gradient",
                                                          "iterations": 3, "velocity_scale": 0.99},
                                label="affine-r24-cub60-released")],
    "pod": [Variant("pod", {"r": 20}, label="r20"),
            Variant("pod", {"r": 20}, label="r20-remesh", remesh="alt", model="r20")],
    "affine": [AFFINE12],
    # LiCROM+affine r = 24 (every tet, 60 optimised cubature tets) each on its own step ladder: dt, dt/2, dt/4, dt/8
    # under the scene's integrator and BDF2, each level on the base variant's trained model, and the cubature one
    # under BDF2 with contact lagged to the fixed point; each curve on the frontier beside the full-space ladder, with
    # what floors it (`analysis.curves`; issue 22, point 1; on demand)
    "licrom-ladder": [*step_ladder(AFFINE_R24), *step_ladder(AFFINE_R24_CUB60, twin=AFFINE_R24),
                      *step_ladder(AFFINE_R24_CUB60_FIXED_POINT, integrators=("bdf2",))],
    # LiCROM's rank swept, every tet (the affine subspace alone as r = 12, then a grid over the solver's declared
    # parameters; on demand): what the subspace can hold against what it costs (issue 22, point 3)
    "licrom-rank": lambda: [AFFINE12, *grid("licrom", "affine-r{r}", LICROM_AFFINE, r=list(RANKS))],
    # LiCROM+affine r = 24 (every tet, 60 optimised cubature tets) trained on the training members' references, as
    # every other set, and on their truths, side by side (issue 22, point 3; on demand; a run without a truth gives
    # the truth-trained ones failed rows saying so)
    "licrom-training": [AFFINE_R24, AFFINE_R24_TRUTHDATA, AFFINE_R24_CUB60, AFFINE_R24_CUB60_TRUTHDATA],
    # the reduced dynamics against rank at the truth ladders' own step settings (`at_truth_step`; issue 22, point 3;
    # on demand; needs a truth): which rank the reduced dynamics, not only the subspace, need to reach the ladder's
    # range, and what it costs
    "rank-dynamics": lambda: [at_truth_step(v) for v in RANK_DYNAMICS],
    # those ranks on an optimised cubature, each three curves under BDF2 at dt, dt/2 and dt/4: contact lagged to the
    # start of the step (the scene's own, and cheapest), corrected once at the first solve's end (two solves; second
    # order where the step resolves contact) and to each step's fixed point (the truth ladders' settings) (issue 22;
    # on demand; the truth-trained ones need a truth)
    "pod-cubature": lambda: [level for v in POD_CUBATURE for lagged in (v, at_lag(v, "corrected"), at_fixed_point(v))
                             for level in step_ladder(lagged, levels=(0, 1, 2), integrators=("bdf2",))],
    # POD at r = 60 (between pod-cubature's ranks) and, at a looser Newton tolerance with the Hessian's products in
    # single precision (and with the body's Hessian once a step as well), at r = 36, 60 and 84, each a curve at dt,
    # dt/2 and dt/4 (r = 84 also at the fixed point, and its two truth-fitted curves once a step on every tet too);
    # the full-space solver at the looser tolerance and at the default on the truth ladders' settings (issue 22's
    # 100x; on demand; the truth-trained ones need a truth)
    "pod-fast": _pod_fast,
    # r = 84 fitted to the truths, the body's Hessian once a step, on 210 and 420 optimised tets and on every
    # tet, each a curve at dt, dt/2 and dt/4 under BDF2 on one subspace: where the cubature floors a curve, what a
    # larger one buys and costs (issue 22; on demand; needs a truth)
    "pod-cubature-size": _pod_cubature_size,
    # POD fitted to the truths on every tet at r = 84 to 300, at the fast settings with the body's Hessian once a
    # step, at the truth ladders' step settings: the rank a held-out member needs (issue 22; on demand; needs a truth)
    "pod-rank": _pod_rank,
    # those on the other mesh of the shape beside themselves (modes interpolated there, every tet): whether the rank
    # that brings a held-out member's dynamics into range does the same for the other mesh (issue 22; on demand)
    "pod-rank-remesh": lambda: [v for level in _pod_rank() for v in (level, on_other_mesh(level))],
    # the same POD variants on the other mesh of the shape beside themselves (their modes interpolated there, the
    # optimised cubature selected there from the same latent training states): BDF2 at dt and dt/2 with the start
    # lag and at dt/4 with the fixed point, the points where they were most accurate for their cost (issue 22's
    # other-mesh target: at most 1.5x the own-mesh error; on demand)
    "pod-remesh": lambda: [v for level in _pod_remesh_points() for v in (level, on_other_mesh(level))],
    # accuracy-for-time sweeps of the full-space solver: looser Newton tolerance, larger time step, coarser mesh
    # (the other mesh of the shape, carried onto the reference mesh for the comparison), the second-order integrator
    "full-sweep": [Variant("full", {"tol": 1e-3}, label="tol1e-3"),
                   Variant("full", {}, label="dt2x", dt_scale=2.0),
                   DT_HALF,
                   Variant("full", {}, label="other-mesh", remesh="alt", transfer=True),
                   BDF2],
    # any suite with the full-space solver under BDF2 beside its backward-Euler reference
    "bdf2": [BDF2],
    # the full-space solver under BDF2 with adaptive, error-controlled steps (docs/design.md "Adaptive steps"), at
    # three local tolerances: points of the accuracy-for-time frontier (not in the default set)
    "adaptive": [Variant("full", {}, label=f"bdf2-tol{tol:g}", overrides={"time.integrator": "bdf2", "time.tol": tol})
                 for tol in ADAPTIVE_TOLS],
    # the barrier contact law beside the penalty law of the reference
    "barrier": [BARRIER],
    # Newton's VBD (needs the optional `newton`; skipped with the reason without it): its ladder on the frontier
    "newton-vbd": NEWTON_VBD,
    # Newton's VBD at its defaults only (the hard suite's advisory gates)
    "newton-vbd-default": [NEWTON_VBD_DEFAULT],
    # the full-space solver under each integrator (backward Euler is the reference) and both contact laws: the hard
    # suite's stability gates hold under every one (docs/design.md "Hard cases")
    "integrators": INTEGRATORS,
    # hard suite: the integrators above, every reduced solver family and LiCROM's variants, LiCROM+affine under both
    # contact laws, and Newton's VBD at its defaults (no remeshing or accuracy sweeps: those are about accuracy, and
    # remeshing doubles the references)
    "hard": [*INTEGRATORS,
             Variant("licrom", LICROM, label="r20"),
             Variant("licrom", LICROM_AFFINE, label="affine-r24"),
             Variant("licrom", LICROM_AFFINE, label="affine-r24-barrier", model="affine-r24",
                     overrides={"contact.law": "barrier"}),
             Variant("licrom", LICROM_AFFINE | {"cubature": "optimized:60"}, label="affine-r24-cub60"),
             Variant("licrom", LICROM_AFFINE | {"scheme": "projected_gradient"}, label="affine-r24-pg"),
             Variant("pod", {"r": 20}, label="r20"),
             Variant("affine", {}, label="affine12"),
             NEWTON_VBD_DEFAULT],
    # paper suite (medium meshes, issue targets): every reduced family, LiCROM+affine on the other mesh, the paper's
    # projected-gradient scheme on the optimised cubature (as the paper runs it: all tets costs ~1 s a step there),
    # the full-space solver on the other mesh carried back, and at half the time step (the reference's own time
    # error; the tol1e-3 and dt2x sweeps would add references without bearing on the targets)
    "paper": [Variant("licrom", LICROM, label="r20"),
              Variant("licrom", LICROM_AFFINE, label="affine-r24"),
              Variant("licrom", LICROM_AFFINE, label="affine-r24-remesh", remesh="alt", model="affine-r24"),
              Variant("licrom", LICROM_AFFINE | {"cubature": "optimized:60"}, label="affine-r24-cub60"),
              Variant("licrom", LICROM_AFFINE | {"cubature": "optimized:60", "scheme": "projected_gradient"},
                      label="affine-r24-cub60-pg"),
              Variant("pod", {"r": 20}, label="r20"),
              Variant("pod", {"r": 20}, label="r20-remesh", remesh="alt", model="r20"),
              Variant("affine", {}, label="affine12"),
              Variant("full", {}, label="other-mesh", remesh="alt", transfer=True),
              DT_HALF],
}


def variant_set(name: str) -> list[Variant]:
    """The variants of the set `name` of `VARIANTS` (a grid built now)."""
    variants = VARIANTS[name]
    return variants() if callable(variants) else variants


DEFAULT = "licrom,licrom-affine,pod,affine,full-sweep"
SUITE_DEFAULTS = {"hard": "hard", "paper": "paper", "paper-damped": "paper"}
"""Default variant sets of suites that need another matrix than DEFAULT (`frictionbench run` without --solvers)."""

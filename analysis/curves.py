"""Reduced curves on the frontier: a solver variant run on its own step ladder (dt / 2^k, k = 0, 1, ...; rows with a
`curve` and its `curve_level`, `bench.matrix.step_ladder`) draws its own err_truth-versus-cost curve beside the
full-space ladder, and where the curve stops improving, `curve_floor` says what holds it up.

The rule, per scenario and curve, from its finished rows (status ok, a finite err_truth), on its finest one:

1. `too few levels` with fewer than two finished levels, or when its two finest are not successive levels (no
   halving to judge);
2. `time step` while the last halving still lowered err_truth by at least FLATTEN_DROP (the curve has not
   flattened: a finer step still pays);
3. else (flattened) `truth` where the finest err_truth is within UNDECIDABLE_FACTOR x the truth's own error
   estimate: the truth is not known well enough to see the curve go lower;
4. else `cubature` where the all-tets twin curve (the same variant with every tet, `curve_twin`; it shares the
   trained model, hence the subspace) is at most CUBATURE_MARGIN x as far from the truth at the same level;
5. else `subspace` where err_projection (the truth projected onto the subspace: no run in it can do better) is at
   least SUBSPACE_SHARE of the finest err_truth;
6. else `reduction`: neither the step, the cubature nor the subspace: the reduced dynamics themselves.

Every function is pure: numbers and row dicts in, verdicts and row dicts out.
"""

from __future__ import annotations

from collections.abc import Mapping, Sequence

from frictionbench.analysis.schema import number
from frictionbench.analysis.truth import UNDECIDABLE_FACTOR

#: A curve has flattened when its last halving of the step lowered err_truth by less than this share [-]. Where the
#: step's error dominates, a halving lowers it by about half (first order: backward Euler) or three quarters
#: (second order: BDF2); a drop below 20% means that the step's share s of what is left is under about 40% (backward
#: Euler: 0.5 s < 0.2) or 27% (BDF2: 0.75 s < 0.2): most of the error is something a finer step does not touch.
FLATTEN_DROP = 0.2
#: A flattened curve is floored by its subspace when err_projection is at least this share of its err_truth [-]: at
#: least half of its error is beyond any run in the subspace, so nothing but a richer subspace could even halve it.
SUBSPACE_SHARE = 0.5
#: A flattened curve is floored by its cubature when its all-tets twin, at the same integrator and level, is at most
#: this multiple of its err_truth [-]: every tet instead of the cubature alone removes at least the share a halving
#: must remove to count (FLATTEN_DROP), on the same trained subspace.
CUBATURE_MARGIN = 1.0 - FLATTEN_DROP

#: The verdicts of `curve_floor`.
FEW_LEVELS, TIME_STEP, TRUTH, CUBATURE, SUBSPACE, REDUCTION = ("too few levels", "time step", "truth", "cubature",
                                                              "subspace", "reduction")
FLOORS: tuple[str, ...] = (FEW_LEVELS, TIME_STEP, TRUTH, CUBATURE, SUBSPACE, REDUCTION)


def curve_floor(levels: Sequence[int], err_truth: Sequence[float], err_projection: float | None = None,
                twin_err_truth: float | None = None, truth_err_est: float | None = None) -> str:
    """What floors a curve (module doc, rule 1-6): `levels` (K,) its finished levels k (dt / 2^k) in increasing
    order and `err_truth` (K,) their errors against the truth [fraction of L]; of its finest level, the truth's
    projection onto its subspace `err_projection` [fraction of L] (None: no subspace), the all-tets twin's
    err_truth at that level `twin_err_truth` (None: no twin, or it did not finish) and the truth's error estimate
    `truth_err_est` [fraction of L] (None: unknown). Returns one of FLOORS."""
    if len(levels) != len(err_truth):
        raise ValueError(f"{len(levels)} levels but {len(err_truth)} errors")
    if len(levels) < 2 or levels[-1] != levels[-2] + 1:
        return FEW_LEVELS
    coarse, fine = float(err_truth[-2]), float(err_truth[-1])
    if fine <= (1.0 - FLATTEN_DROP) * coarse:
        return TIME_STEP
    if truth_err_est is not None and fine <= UNDECIDABLE_FACTOR * truth_err_est:
        return TRUTH
    if twin_err_truth is not None and twin_err_truth <= CUBATURE_MARGIN * fine:
        return CUBATURE
    if err_projection is not None and err_projection >= SUBSPACE_SHARE * fine:
        return SUBSPACE
    return REDUCTION


def _finished(row: Mapping[str, object]) -> bool:
    """A curve row that ran: status ok, a level and a finite err_truth."""
    return (row.get("status") == "ok" and number(row.get("curve_level")) is not None
            and number(row.get("err_truth"), finite=True) is not None)


def with_curve_floors(rows: Sequence[Mapping[str, object]]) -> list[dict]:
    """Rows with `curve_floor` (`curve_floor`'s verdict) on the finest finished row of each (scenario, solver,
    curve), from the curve's finished rows, its twin's (`curve_twin`) at the same level and the scenario's
    `truth_err_est`; every other row unchanged. Rows without curves come back as they were."""
    curves: dict[tuple, list[Mapping[str, object]]] = {}
    for r in rows:
        if r.get("curve") and _finished(r):
            curves.setdefault((r.get("scenario"), r.get("solver"), r["curve"]), []).append(r)
    verdicts: dict[int, str] = {}
    for (scenario, solver, _), members in curves.items():
        members = sorted(members, key=lambda r: number(r["curve_level"]))
        finest = members[-1]
        twins = curves.get((scenario, solver, finest.get("curve_twin") or None), [])
        level = number(finest["curve_level"])
        twin = next((number(t["err_truth"]) for t in twins if number(t["curve_level"]) == level), None)
        verdicts[id(finest)] = curve_floor([int(number(r["curve_level"])) for r in members],
                                           [number(r["err_truth"]) for r in members],
                                           number(finest.get("err_projection"), finite=True), twin,
                                           number(finest.get("truth_err_est"), finite=True))
    return [dict(r) | {"curve_floor": verdicts[id(r)]} if id(r) in verdicts else dict(r) for r in rows]

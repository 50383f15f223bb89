"""The results schema: every column results.csv can hold, declared once, and the one reader of a results cell.

A `Column` says what a column is (kind), which way it is better and by how much it may move before `frictionbench
compare` calls it a regression, its unit and meaning, and the function that computes it. Everything else is derived
from `COLUMNS`: the table's column order (`analysis.table`), the comparison rules (`bench.compare.default_rules`),
the stability metrics of the headline, the report and the comparison, the report's column groups, the columns
`bench.unchanged` leaves out, and the table of metrics in docs/metrics.md (`docs_table`, checked by a test).

A metric needs only its declaration here: a `Column` with `compute` (a function of the finished run,
`analysis.metrics.ComparedRun`: its trajectory, its reference's, its scenario) is evaluated on every finished run by
row building (`computed_cells`, from `analysis.rows.run_metrics`); columns one computation gives together are declared
with `together`. Plug-ins and tests add columns with `register`.

Cells are read by `is_missing`, `number` and `flag` (and `truthy`), whether they come from rows built in memory or
from results.csv as pandas reads it back.
"""

from __future__ import annotations

import math
from collections.abc import Callable
from dataclasses import dataclass, replace
from functools import partial

import pandas as pd

from frictionbench.analysis import metrics

#: What a column is: identity (which row: the key of a row across result sets), parameter (what ran: scene and
#: solver settings), accuracy (against a reference or the truth), stability (of the run itself), timing (measured
#: on this machine, never compared for behaviour), provenance (where and with what the results were made).
KINDS: tuple[str, ...] = ("identity", "parameter", "accuracy", "stability", "timing", "provenance")
#: The kinds `compare` judges (a tolerance may be set per kind: `frictionbench compare --tol KIND=SPEC`).
JUDGED_KINDS: tuple[str, ...] = ("accuracy", "stability", "timing")
#: Which value is better: lower / higher: the smaller / larger; true: a flag that should hold (status `ok` counts
#: as true); one: the closer to 1; none: not judged by `compare` (only gates may judge it).
DIRECTIONS: tuple[str, ...] = ("lower", "higher", "true", "one", "none")
#: The tolerance of accuracy figures: 10% of the baseline, never less than 1e-4 (of L for *_rel).
ACCURACY_TOL: dict[str, float] = {"rel": 0.10, "abs": 1e-4}
#: The tolerance of timing figures, a ratio: loose, since step times on shared machines move by tens of per cent.
TIMING_FACTOR = 1.5
#: Distribution name -> column of its version in `analysis.table.provenance`.
VERSIONED_PACKAGES: dict[str, str] = {
    "frictionbench": "frictionbench_version",
    "numpy": "numpy_version",
    "scipy": "scipy_version",
    "torch": "torch_version",
    "warp-lang": "warp_version",
    "mkl": "mkl_version",  # MKL PARDISO, the full-space solver's default linear solver (`linear_solver` per row)
}


@dataclass(frozen=True)
class Column:
    """One results column.

    name: the column; kind: one of KINDS; better: one of DIRECTIONS; rel [-], abs [unit], factor [-]: the
    tolerance of `compare` (a bad change beyond max(rel |baseline|, abs), or for timing beyond the ratio factor);
    unit: its unit (`-` dimensionless, `L` a fraction of the body's size, `text`, `flag`, `count`); meaning: one line;
    source: the dotted name of the function that computes it; placed: True where the table gives it a fixed place
    (the identity columns first, the provenance columns last, the others between, in the order of COLUMNS), False
    where it follows those in the order the rows first hold it (the columns results.csv has always placed so);
    summary: shown in the report's results table; compute: for a metric computed per finished run by row
    building, f(run) -> value, run the `analysis.metrics.ComparedRun` (the run's and its reference's trajectories,
    its scenario, the inputs metrics share); None where the column is computed elsewhere (`source` says where).
    Columns one computation gives together are declared with `together`.
    """

    name: str
    kind: str
    better: str = "none"
    unit: str = "-"
    meaning: str = ""
    source: str = ""
    rel: float = 0.0
    abs: float = 0.0
    factor: float | None = None
    placed: bool = True
    summary: bool = False
    compute: Callable[[metrics.ComparedRun], object] | None = None

    def __post_init__(self) -> None:
        if self.kind not in KINDS:
            raise ValueError(f"column {self.name!r}: kind {self.kind!r} not one of {list(KINDS)}")
        if self.better not in DIRECTIONS:
            raise ValueError(f"column {self.name!r}: better {self.better!r} not one of {list(DIRECTIONS)}")

    @property
    def judged(self) -> bool:
        """Whether `compare` judges it (a judged kind and a direction)."""
        return self.kind in JUDGED_KINDS and self.better != "none"

    def tolerance(self) -> str:
        """The tolerance as `compare --tol` writes it (`10%,0.0001`, `x1.5`, `0`), '' where not judged."""
        if not self.judged or self.better == "true":
            return ""
        if self.factor is not None:
            return f"x{self.factor:g}"
        parts = ([f"{self.rel * 100:g}%"] if self.rel else []) + ([f"{self.abs:g}"] if self.abs else [])
        return ",".join(parts) or "0"


def together(group: Callable[[metrics.ComparedRun], dict[str, object]], *columns: Column) -> tuple[Column, ...]:
    """Columns one computation gives together: `group(run)` -> {column name: value} runs once per run
    (`ComparedRun.once`), and each column's compute takes its own cell from it."""
    return tuple(replace(c, compute=partial(_cell, group, c.name)) for c in columns)


def _cell(group: Callable[[metrics.ComparedRun], dict[str, object]], name: str, run: metrics.ComparedRun) -> object:
    """The cell `name` of the columns `group` computes together for `run`."""
    return run.once(group)[name]


def _accuracy(name: str, meaning: str, source: str, **kw) -> Column:
    """An error that should stay small: lower is better, within ACCURACY_TOL, a fraction of L unless told."""
    return Column(name, "accuracy", "lower", kw.pop("unit", "L"), meaning, source, **ACCURACY_TOL, **kw)


def _timing(name: str, better: str, unit: str, meaning: str, source: str, **kw) -> Column:
    """A measured time (or a ratio of times), judged as a ratio within TIMING_FACTOR where it has a direction."""
    factor = TIMING_FACTOR if better != "none" else None
    return Column(name, "timing", better, unit, meaning, source, factor=factor, **kw)


@dataclass(frozen=True)
class Outcome:
    """One outcome metric (docs/metrics.md, "Outcome metrics"): a quantity of a run judged against the truth's, with
    its own convergence over the truth's ladder. Declared once in OUTCOMES; its columns follow (`columns`) and
    `analysis.outcomes` computes them.

    name: the value column; unit, meaning: the value's; value: dotted name of f(trajectory, scene) -> the value
    (`analysis.outcomes.OutcomeScene`; None where the outcome does not apply, NaN where it is undefined for the
    run, e.g. no rest); difference: dotted name of f(value, truth's value, L [m]) -> the error [err_unit];
    err_meaning: the error's; tol: the outcome's tolerance [err_unit]: the truth's ladder certifies it when its two
    finest levels differ by at most tol, and `compare` calls a change of its error below tol no regression;
    own_column: False where the value column is already declared (it is not redeclared nor rewritten);
    discrete: a verdict, whose ladder estimate is its last difference (no order to extrapolate with).
    """

    name: str
    unit: str
    meaning: str
    value: str
    difference: str
    err_unit: str
    err_meaning: str
    tol: float
    own_column: bool = True
    discrete: bool = False

    @property
    def err_column(self) -> str:
        """The run's error against the truth's value."""
        return f"{self.name}_err_truth"

    @property
    def truth_column(self) -> str:
        """The truth's value."""
        return f"truth_{self.name}"

    @property
    def diff_column(self) -> str:
        """The difference between the truth ladder's two finest levels."""
        return f"truth_{self.name}_diff"

    @property
    def est_column(self) -> str:
        """The estimate of the truth's own error in this outcome."""
        return f"truth_{self.name}_est"

    @property
    def certified_column(self) -> str:
        """Whether the truth's two finest levels agree within tol."""
        return f"truth_{self.name}_certified"

    def columns(self) -> tuple[Column, ...]:
        """Its results columns: the value (unless own_column is False), the error against the truth, and the truth's
        value, ladder difference, estimate and certificate."""
        source = "frictionbench.analysis.outcomes"
        tol = {"rel": ACCURACY_TOL["rel"], "abs": self.tol}
        value = Column(self.name, "accuracy", unit=self.unit, meaning=self.meaning, source=self.value)
        return ((value,) if self.own_column else ()) + (
            Column(self.err_column, "accuracy", "lower", self.err_unit, f"{self.err_meaning} (tolerance {self.tol:g})",
                   self.difference, summary=True, **tol),
            Column(self.truth_column, "accuracy", unit=self.unit, meaning=f"the truth's {self.name}",
                   source=self.value),
            Column(self.diff_column, "accuracy", "lower", self.err_unit,
                   f"{self.name}: difference of the truth ladder's two finest levels",
                   f"{source}.ladder_outcome_columns", **tol),
            Column(self.est_column, "accuracy", "lower", self.err_unit,
                   f"{self.name}: estimate of the truth's own error", f"{source}.ladder_outcome_columns", **tol),
            Column(self.certified_column, "accuracy", "true", "flag",
                   f"{self.name}: the truth ladder's two finest levels differ by at most {self.tol:g} {self.err_unit}",
                   f"{source}.ladder_outcome_columns"))


_OUT = "frictionbench.analysis.outcomes"
#: The outcome metrics, each declared once (docs/metrics.md, "Outcome metrics").
OUTCOMES: dict[str, Outcome] = {o.name: o for o in (
    Outcome("slide", "m", "distance the centre of mass travels along the plane, start to end",
            f"{_OUT}.slide_distance", f"{_OUT}.length_difference", "L", "|slide - the truth's slide| / L", 0.005),
    Outcome("end_com", "m", "centre of mass at the end, as 'x y z'", f"{_OUT}.end_com",
            f"{_OUT}.length_difference", "L", "distance between the run's and the truth's end centres / L", 0.005),
    Outcome("end_angle", "deg", "rotation angle of the best-fit rigid motion from the rest shape to the last frame",
            f"{_OUT}.end_rotation", f"{_OUT}.rotation_difference", "deg",
            "angle of R_truth^T R, the end rotations' difference", 1.0),
    Outcome("rest_time", "s", "time from which the body stays at rest on the plane (empty: not at rest at the end)",
            f"{_OUT}.time_to_rest", f"{_OUT}.absolute_difference", "s",
            "|rest_time - the truth's| (inf: only one of them comes to rest)", 0.05),
    Outcome("impact_loss", "-", "mechanical energy lost from the frame before the first contact to 0.2 s later, over "
            "the kinetic energy the impact meets (empty: no impact)", f"{_OUT}.impact_loss",
            f"{_OUT}.absolute_difference", "-", "|impact_loss - the truth's| (inf: only one of them has an impact)",
            0.02),
    Outcome("peak_ke", "J", "largest kinetic energy over the run", f"{_OUT}.peak_kinetic_energy",
            f"{_OUT}.relative_difference", "-", "|peak_ke - the truth's| / the truth's", 0.02),
    Outcome("stick", "flag", "the body ends at rest on the plane", f"{_OUT}.stick_verdict",
            f"{_OUT}.verdict_difference", "count", "1 where the stick verdict differs from the truth's, else 0", 0.0,
            own_column=False, discrete=True),
)}


def outcome_of(column: str) -> Outcome | None:
    """The outcome whose error against the truth `column` is (`Outcome.err_column`), None for any other column."""
    return next((o for o in OUTCOMES.values() if o.err_column == column), None)


_ROWS = "frictionbench.analysis.rows.collect_rows"
_METRICS = "frictionbench.analysis.metrics"
_STATS = "frictionbench.solvers.run.run_scenario"

#: Every column, in table order (see `Column.placed`).
COLUMNS: dict[str, Column] = {c.name: c for c in (
    Column("suite", "identity", unit="text", meaning="the suite the row belongs to", source=_ROWS, summary=True),
    Column("scenario", "identity", unit="text", meaning="the scenario (a suite member)", source=_ROWS, summary=True),
    Column("split", "identity", unit="text", meaning="train or test split of the member", source=_ROWS,
           summary=True),
    Column("mesh", "identity", unit="text", meaning="the mesh the run ran on", source=_ROWS, summary=True),
    Column("train_mesh", "identity", unit="text", meaning="the mesh a reduced model trained on ('' without one)",
           source=_ROWS),
    Column("solver", "identity", unit="text", meaning="the solver that ran", source=_ROWS, summary=True),
    Column("variant", "identity", unit="text", meaning="the solver variant's label (`reference`, a ladder level)",
           source=_ROWS, summary=True),
    Column("status", "stability", "true", "text", "`ok`, or `failed` for a run without a usable trajectory",
           "frictionbench.analysis.rows.run_metrics", summary=True),
    Column("failure", "stability", unit="text", meaning="why a run failed (the exception), '' otherwise",
           source="frictionbench.analysis.rows.run_metrics", summary=True),
    Column("frames_compared", "accuracy", unit="count", meaning="frames whose times the run and its reference share",
           source=f"{_METRICS}.align_frames",
           compute=lambda run: int(metrics.align_frames(run.ref.t, run.traj.t)[0].size)),
    _accuracy("pos_rmse_rel", "RMS over frames and vertices of the position error against the same-dt reference",
              f"{_METRICS}.pos_rmse_rel", summary=True, compute=lambda run: metrics.pos_rmse_rel(run.ref, run.traj)),
    _accuracy("pos_max_rel", "largest per-frame RMS position error", f"{_METRICS}.pos_max_rel",
              compute=lambda run: metrics.pos_max_rel(run.ref, run.traj)),
    _accuracy("com_err_rel", "largest distance between the mass-weighted centres", f"{_METRICS}.com_err_rel",
              summary=True, compute=lambda run: metrics.com_err_rel(run.ref, run.traj, run.masses)),
    _accuracy("final_err_rel", "RMS position error at the last frame", f"{_METRICS}.final_err_rel", summary=True,
              compute=lambda run: metrics.final_err_rel(run.ref, run.traj)),
    _accuracy("slide_err_rel", "error of the centre's travel along the plane over the reference's (floor 1% of L)",
              f"{_METRICS}.slide_err_rel", unit="-", summary=True,
              compute=lambda run: None if run.scenario.plane is None else metrics.slide_err_rel(
                  run.ref, run.traj, run.scenario.plane.normal, run.masses)),
    _accuracy("proj_rmse_rel", "the reference projected onto the run's subspace: the least pos_rmse_rel in it",
              f"{_METRICS}.proj_rmse_rel", summary=True,
              compute=lambda run: None if run.traj.basis is None else metrics.proj_rmse_rel(
                  run.ref, run.traj.basis, frame=run.traj.meta.get("basis_frame", "world"))),
    *together(metrics.stick_cells,
              Column("stick", "accuracy", unit="flag", meaning="the body ends at rest on the plane",
                     source=f"{_METRICS}.stick"),
              Column("stick_ref", "accuracy", unit="flag", meaning="the reference ends at rest on the plane",
                     source=f"{_METRICS}.stick"),
              Column("stick_agree", "accuracy", "true", "flag", "stick and stick_ref agree", f"{_METRICS}.stick_agree",
                     summary=True),
              Column("end_speed", "accuracy", unit="m/s",
                     meaning="centre speed along the plane over the last 10% of the run", source=f"{_METRICS}.stick"),
              Column("end_speed_ref", "accuracy", unit="m/s", meaning="the reference's end_speed",
                     source=f"{_METRICS}.stick")),
    Column("finite", "stability", "true", "flag", "every stored position, velocity and latent coordinate is finite",
           f"{_METRICS}.finite", compute=lambda run: metrics.finite(run.traj)),
    Column("max_penetration_rel", "stability", "lower", "L", "deepest surface point below the plane",
           f"{_METRICS}.max_penetration_rel", **ACCURACY_TOL,
           compute=lambda run: None if run.scenario.plane is None else metrics.max_penetration_rel(
               run.traj, run.scenario.plane.normal, run.scenario.plane.offset)),
    *together(metrics.inverted_cells,
              Column("inverted_tets", "stability", "lower", "count", "tets with det F <= 0 in some frame",
                     f"{_METRICS}.inverted_tets"),
              Column("inverted_tets_frame_max", "stability", "lower", "count", "most tets with det F <= 0 in one frame",
                     f"{_METRICS}.inverted_tets")),
    Column("inverted_tets_final", "stability", "lower", "count", "tets with det F <= 0 in the last frame",
           f"{_METRICS}.inverted_tets_in_frame", compute=lambda run: metrics.inverted_tets_in_frame(run.traj)),
    Column("volume_ratio_final", "stability", "one", "-", "volume at the end over the rest volume",
           f"{_METRICS}.volume_ratio", abs=0.002,
           compute=lambda run: metrics.volume_ratio(run.traj) if metrics.finite(run.traj) else None),
    Column("energy_ratio_max", "stability", "lower", "-", "largest total energy over the initial (> 1: energy grew)",
           f"{_METRICS}.energy_ratio_max", abs=0.002,
           compute=lambda run: metrics.energy_ratio_max(run.traj, run.scenario.material, run.scenario.gravity,
                                                        run.masses)),
    *together(metrics.creep_cells,
              Column("creep_speed_law", "stability", unit="m/s",
                     meaning="the friction law's creep speed for the body at the end",
                     source=f"{_METRICS}.creep_speed_law"),
              Column("creep_ratio", "stability", "lower", "-",
                     "end speed along the plane over creep_speed_law (~1: held)", f"{_METRICS}.creep_cells",
                     rel=0.10, abs=0.01)),
    _timing("setup_s", "none", "s", "per-run setup", _STATS),
    _timing("train_s", "none", "s", "training of the reduced model (offline, per shape)",
            "frictionbench.solvers.contract.Solver.prepare"),
    _timing("step_ms_median", "lower", "ms", "median wall time of a step", _STATS, summary=True),
    _timing("step_ms_p95", "lower", "ms", "95th percentile of a step's wall time", _STATS),
    _timing("speedup", "higher", "-", "the reference's step_ms_median over this run's, same run",
            "frictionbench.analysis.rows.run_timing", summary=True),
    Column("integrator", "parameter", unit="text", meaning="the run's time integrator", source=_ROWS, summary=True),
    _accuracy("err_truth", "pos_rmse_rel against the scenario's ground truth (another mesh carried onto its mesh)",
              _ROWS, summary=True),
    _accuracy("err_truth_horizon", "err_truth over the frames up to truth_horizon_s", _ROWS, summary=True),
    _accuracy("err_time", "the full-space run the row is compared with, against the truth: the time step's share",
              _ROWS, summary=True),
    _accuracy("err_projection", "the truth projected onto the row's subspace: the basis's share", _ROWS,
              summary=True),
    _timing("wall_s_per_sim_s", "lower", "s/s", "the steps' wall time per simulated second",
            "frictionbench.analysis.truth.wall_s_per_sim_s", summary=True),
    _timing("speedup_equal_accuracy", "higher", "-", "full-space ladder's cost at this row's err_truth over its cost",
            "frictionbench.analysis.truth.with_frontier", summary=True),
    _timing("frontier_note", "none", "text", "why speedup_equal_accuracy is missing or an upper bound",
            "frictionbench.analysis.truth.with_frontier", summary=True),
    _timing("timed_beside_ladder", "none", "flag", "this run and every ladder run of its scenario were timed in one "
            "session (False: speedup_equal_accuracy divides costs timed apart)",
            "frictionbench.analysis.truth.with_frontier", summary=True),
    _timing("timed_in", "none", "text", "the session that ran and timed this run (a resumed store keeps it)",
            "frictionbench.bench.runner.run_tasks"),
    Column("truth_certified", "accuracy", "true", "flag", "the truth's last ladder difference met the tolerance",
           "frictionbench.analysis.rows.truth_columns", summary=True),
    Column("truth_horizon_s", "accuracy", unit="s", meaning="end of the first stretch the truth meets tol frame by "
           "frame", source="frictionbench.analysis.truth.certified_horizon", summary=True),
    _accuracy("truth_err_est", "Richardson estimate of the truth's own error",
              "frictionbench.analysis.truth.richardson",
              summary=True),
    Column("truth_order", "accuracy", meaning="the order the truth's error estimate used",
           source="frictionbench.analysis.truth.richardson"),
    Column("truth_dt", "parameter", unit="s", meaning="the truth's time step",
           source="frictionbench.analysis.rows.truth_columns"),
    Column("truth_depth", "parameter", unit="count", meaning="the truth's ladder level (dt / 2^depth)",
           source="frictionbench.analysis.rows.truth_columns"),
    Column("truth_integrator", "parameter", unit="text", meaning="the truth's time integrator",
           source="frictionbench.analysis.rows.truth_columns"),
    Column("ladder", "parameter", unit="text", meaning="on a truth-ladder row: its ladder's integrator", source=_ROWS,
           summary=True),
    Column("ladder_level", "parameter", unit="count", meaning="on a truth-ladder row: its level k (dt / 2^k)",
           source=_ROWS),
    Column("curve", "parameter", unit="text", meaning="on a row of a variant's own step ladder: its curve (base "
           "label, and the integrator the ladder sets)", source="frictionbench.bench.matrix.step_ladder",
           summary=True),
    Column("curve_level", "parameter", unit="count", meaning="on a curve's row: its level k (dt / 2^k)",
           source="frictionbench.bench.matrix.step_ladder"),
    Column("curve_twin", "parameter", unit="text", meaning="on a curve with an optimised cubature: the curve of "
           "the same variant with every tet", source="frictionbench.bench.matrix.step_ladder"),
    Column("curve_floor", "accuracy", unit="text", meaning="on a curve's finest row: what floors it (time step, "
           "truth, cubature, subspace, reduction, too few levels)", source="frictionbench.analysis.curves.curve_floor",
           summary=True),
    Column("mu", "parameter", meaning="the plane's friction coefficient", source=_ROWS, placed=False),
    Column("law", "parameter", unit="text", meaning="the contact law", source=_ROWS, placed=False),
    Column("tags", "parameter", unit="text", meaning="the scenario's tags", source=_ROWS, placed=False),
    Column("run", "provenance", unit="text", meaning="the run's key in the run store",
           source="frictionbench.bench.store.run_key",
           placed=False),
    Column("dt", "parameter", unit="s", meaning="the run's time step", source=_ROWS, placed=False, summary=True),
    _timing("warmup_s", "none", "s", "first step with kernel compilation, apart", _STATS, placed=False),
    Column("newton_iters_mean", "stability", meaning="Newton iterations per step", source=_STATS, placed=False),
    Column("newton_iters_max", "stability", unit="count", meaning="most Newton iterations in a step", source=_STATS,
           placed=False),
    Column("not_converged", "stability", "lower", "count", "steps whose Newton solve failed even after retries",
           _STATS, placed=False),
    Column("line_search_stalls", "stability", "lower", "count", "Newton iterations without decrease", _STATS,
           placed=False),
    Column("step_retries", "stability", "lower", "count", "steps redone as two half steps", _STATS, placed=False),
    Column("linear_solver", "parameter", unit="text", meaning="the linear solver that ran", source=_STATS,
           placed=False),
    Column("remesh", "parameter", unit="text", meaning="the other mesh resolution a remeshed variant ran on",
           source=_ROWS, placed=False),
    Column("r", "parameter", unit="count", meaning="a reduced variant's subspace dimension", source=_ROWS,
           placed=False),
    Column("model", "parameter", unit="text", meaning="the trained model a variant uses", source=_ROWS, placed=False),
    Column("remesh_of", "parameter", unit="text",
           meaning="the variant on the training mesh a remeshed variant is compared with (remesh_ratio)",
           source=_ROWS, placed=False),
    Column("train_data", "parameter", unit="text",
           meaning="what a reduced model trained on: `reference` (the training members' runs at the scene's step) "
                   "or `truth` (their truths); '' without one", source=_ROWS, placed=False),
    _accuracy("remesh_ratio", "pos_rmse_rel on another mesh over that on the training mesh",
              "frictionbench.analysis.derived.with_remesh_ratio", unit="-", placed=False),
    _accuracy("ref_dt_change", "the full-space run at a smaller dt against the reference: its own time error",
              "frictionbench.analysis.derived.with_ref_dt_change", placed=False),
    Column("tol", "parameter", unit="L", meaning="an adaptive run's local error tolerance per step (time.tol)",
           source="frictionbench.analysis.rows.run_timing", placed=False),
    Column("steps", "stability", unit="count", meaning="an adaptive run's accepted steps",
           source="frictionbench.solvers.step_stats.stats_summary", placed=False),
    Column("rejected_steps", "stability", unit="count",
           meaning="an adaptive run's step attempts discarded (error over tol, or a failed solve)",
           source="frictionbench.solvers.step_stats.adaptive_summary", placed=False),
    Column("steps_over_tol", "stability", "lower", "count",
           "an adaptive run's steps accepted at its smallest step with their error over tol",
           "frictionbench.solvers.step_stats.adaptive_summary", placed=False),
    Column("dt_min_used", "stability", unit="s", meaning="an adaptive run's smallest accepted step",
           source="frictionbench.solvers.step_stats.adaptive_summary", placed=False),
    Column("dt_median", "stability", unit="s", meaning="an adaptive run's median accepted step",
           source="frictionbench.solvers.step_stats.adaptive_summary", placed=False),
    Column("truth_tol", "parameter", unit="L", meaning="a tolerance ladder's truth: its time.tol",
           source="frictionbench.analysis.rows.truth_columns", placed=False),
    # the scene's time scales (the same on every row of a scenario) and how well the row's step resolves them
    *(Column(f"ts_{name}", "parameter", unit=unit, meaning=meaning,
             source="frictionbench.analysis.timescales.scene_columns") for name, unit, meaning in (
        ("omega_max", "rad/s", "top of the elastic spectrum at rest (K phi = omega^2 M phi, Lanczos)"),
        ("omega_1", "rad/s", "first non-rigid elastic mode at rest"),
        ("patch_area", "m^2", "contact patch: area of the contact points touching the plane in the reference's "
                              "last frame"),
        ("contact_stiffness", "Pa/m", "the contact law's normal stiffness per area (barrier: at the resting "
                                      "pressure)"),
        ("omega_contact", "rad/s", "the whole body bouncing on its patch, sqrt(k A / M)"),
        ("zeta_contact", "-", "its damping ratio, k_d A / (2 sqrt(k A M))"),
        ("omega_contact_vertex", "rad/s", "the fastest contact vertex on its own spring, max sqrt(k a_i / m_i)"),
        ("zeta_contact_vertex", "-", "the most lightly damped contact vertex, min k_d a_i / (2 sqrt(k a_i m_i))"),
        ("tau_friction", "s", "the friction law's relaxation time of the whole body, M / (k_f A)"),
        ("tau_friction_vertex", "s", "the fastest contact vertex's, min m_i / (k_f a_i)"))),
    Column("h_eff", "parameter", unit="s",
           meaning="the run's effective step (BDF2 2/3 dt, backward Euler dt; adaptive: of its median step)",
           source="frictionbench.analysis.timescales.effective_step"),
    *(Column(f"res_{name}", "parameter", unit="-", meaning=meaning,
             source="frictionbench.analysis.timescales.SceneTimescales.resolution") for name, meaning in (
        ("omega_max", "omega_max h_eff (> 1: the spectrum's top is not resolved)"),
        ("omega_1", "omega_1 h_eff"), ("contact", "omega_contact h_eff"),
        ("contact_vertex", "omega_contact_vertex h_eff"), ("friction", "h_eff / tau_friction"),
        ("friction_vertex", "h_eff / tau_friction_vertex"),
        ("unresolved_share", "share of the elastic modes with omega h_eff > 1 (exact count, Sylvester)"))),
    *(c for o in OUTCOMES.values() for c in o.columns()),
    *(Column(name, "provenance", unit="text", meaning=meaning, source="frictionbench.analysis.table.provenance")
      for name, meaning in (
        ("commit", "git HEAD of the source tree"), ("commit_dirty", "tracked files differ from HEAD"),
        ("timestamp_utc", "when the table was written"), ("device", "the device the solvers ran on"),
        ("cpu_name", "the CPU model"), ("gpu_name", "the first GPU's name"), ("platform", "the operating system"),
        ("python_version", "the Python version"))),
    *(Column(column, "provenance", unit="text", meaning=f"installed version of {dist}",
             source="frictionbench.analysis.table.provenance") for dist, column in VERSIONED_PACKAGES.items()),
)}


def register(column: Column) -> Column:
    """Add a column to the schema (after every other); a name already declared is an error. Returns it."""
    if column.name in COLUMNS:
        raise ValueError(f"column {column.name!r} is already declared")
    COLUMNS[column.name] = column
    return column


def names(*kinds: str, placed: bool | None = None) -> tuple[str, ...]:
    """The columns of these kinds (every kind when none is given), in table order; only the placed (or unplaced)
    ones when `placed` is given."""
    return tuple(c.name for c in COLUMNS.values()
                 if (not kinds or c.kind in kinds) and (placed is None or c.placed == placed))


def stability_metrics() -> tuple[str, ...]:
    """The stability metrics (kind `stability`): what the headline, the report and `compare` call stability."""
    return names("stability")


def computed() -> tuple[Column, ...]:
    """The columns row building computes per finished run (`Column.compute`), in table order."""
    return tuple(c for c in COLUMNS.values() if c.compute is not None)


def computed_cells(run: metrics.ComparedRun) -> dict[str, object]:
    """The cells of every computed column (`computed`) of one finished run against its reference, in table order
    (what row building, `analysis.rows.run_metrics`, gives a finished run's row)."""
    return {c.name: c.compute(run) for c in computed()}


def docs_table() -> str:
    """The table of metrics in docs/metrics.md (Markdown): every column but identity and provenance, by kind."""
    lines = ["| column | kind | better | tolerance | unit | meaning | computed in |",
             "|---|---|---|---|---|---|---|"]
    for kind in KINDS[1:-1]:
        lines += [f"| `{c.name}` | {c.kind} | {c.better} | {c.tolerance() or '-'} | {c.unit} | {c.meaning} | "
                  f"`{c.source}` |" for c in COLUMNS.values() if c.kind == kind]
    return "\n".join(lines) + "\n"


#: The lines around the table of metrics in docs/metrics.md.
DOCS_TABLE_BEGIN = "<!-- metrics table: analysis.schema.docs_table -->\n"
DOCS_TABLE_END = "<!-- end of metrics table -->"


def docs_with_table(text: str) -> str:
    """docs/metrics.md's text with its table of metrics (between DOCS_TABLE_BEGIN and DOCS_TABLE_END) replaced
    by `docs_table()`."""
    begin = text.index(DOCS_TABLE_BEGIN) + len(DOCS_TABLE_BEGIN)
    return text[:begin] + docs_table() + text[text.index(DOCS_TABLE_END, begin):]


def is_missing(value: object) -> bool:
    """Whether a results cell holds no value: None, NaN, NaT, pd.NA (an empty CSV cell read back)."""
    return value is None or (pd.api.types.is_scalar(value) and bool(pd.isna(value)))


def number(value: object, finite: bool = False) -> float | None:
    """A cell as a float; None when missing or not a number (and, with `finite`, when infinite)."""
    if is_missing(value):
        return None
    try:
        x = float(value)  # type: ignore[arg-type]
    except (TypeError, ValueError):
        return None
    return None if finite and not math.isfinite(x) else x


_TRUE = frozenset({"true", "yes", "1", "1.0", "ok", "pass", "passed"})
_FALSE = frozenset({"false", "no", "0", "0.0", "failed", "fail"})


def flag(value: object) -> bool | None:
    """A boolean cell: True for True, 1 and the texts true/yes/1/1.0/ok/pass/passed (any case), False for False, 0
    and false/no/0/0.0/failed/fail; None when missing or any other text."""
    if is_missing(value):
        return None
    if isinstance(value, str):
        text = value.strip().lower()
        return True if text in _TRUE else False if text in _FALSE else None
    return bool(value)


def truthy(value: object) -> bool:
    """Whether a boolean cell holds true (`flag`); missing and unknown texts are false."""
    return flag(value) is True


if __name__ == "__main__":  # python -m frictionbench.analysis.schema: rewrite the table of metrics in docs/metrics.md
    from pathlib import Path

    page = Path(__file__).resolve().parents[1] / "docs" / "metrics.md"
    page.write_text(docs_with_table(page.read_text(encoding="utf-8")), encoding="utf-8")

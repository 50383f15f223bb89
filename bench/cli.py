"""The `frictionbench` command line: list, simulate, train, run, report, gate, compare, timescales."""

from __future__ import annotations

import argparse
import signal
import sys
import threading
from collections.abc import Sequence
from pathlib import Path

from frictionbench.bench.executors import usable_cores
from frictionbench.scenarios.errors import ScenarioError
from frictionbench.scenarios.spec import MeshSpec, Scenario
from frictionbench.scenarios.suites import TruthSpec

JOBS_HELP = ("runs at a time, each with cores / jobs threads (default: on the CPU this machine's usable cores, "
             f"{usable_cores()} here; on CUDA 1, the GPU's runs one after another). Results do not depend on it; "
             "per-step timings do a little, so compare timings at equal --jobs")


def jobs_arg(text: str) -> int:
    """--jobs: a positive whole number."""
    try:
        jobs = int(text)
    except ValueError:
        jobs = 0
    if jobs < 1:
        raise argparse.ArgumentTypeError(f"--jobs = {text!r}: expected a whole number >= 1")
    return jobs


def resolve_jobs(jobs: int | None, device: str) -> int:
    """--jobs as given, else the default of JOBS_HELP for `device`."""
    return jobs if jobs is not None else (1 if device == "cuda" else usable_cores())


def resolve_scenario(ref: str) -> Scenario:
    """A scenario from a TOML path, a suite member name (`quick/p1_mu0.1`) or a unique member name."""
    from frictionbench.scenarios.load import load_scenario
    from frictionbench.scenarios.suites import list_suites, load_suite

    if ref.endswith(".toml") or Path(ref).is_file():
        return load_scenario(ref)
    suites = [ref.split("/", 1)[0]] if "/" in ref and ref.split("/", 1)[0] in list_suites() else list_suites()
    found = [m.scenario for s in suites for m in load_suite(s).scenarios
             if m.scenario.name == ref or m.scenario.name.split("/", 1)[1] == ref]
    if len(found) != 1:
        raise ScenarioError("scenario", ref, "not a TOML file nor exactly one suite member "
                            f"({len(found)} matches); see `frictionbench list`")
    return found[0]


def parse_mesh(ref: str | None) -> MeshSpec | None:
    """`name/resolution` or a mesh file path -> MeshSpec (None passes through)."""
    if ref is None:
        return None
    if Path(ref).suffix:
        return MeshSpec(name=None, resolution="", path=str(Path(ref).resolve()))
    name, _, res = ref.partition("/")
    return MeshSpec(name=name, resolution=res or "coarse")


def cmd_list(args: argparse.Namespace) -> int:
    """Print suites (with member counts), catalogue meshes, solvers (an unavailable one with the reason) and the
    shipped variant sets (with --verbose, each one's description)."""
    from frictionbench.bench.matrix import DEFAULT, MATRICES, SUITE_DEFAULTS, load_matrix, set_names
    from frictionbench.scenarios.meshes import catalogue
    from frictionbench.scenarios.suites import list_suites, load_suite
    from frictionbench.solvers.registry import get_solver, solver_names, unavailable

    print("suites:")
    names = list_suites()
    width = max(map(len, names), default=0)
    for name in names:
        s = load_suite(name)
        print(f"  {name:{width}s} {len(s.train):3d} train {len(s.test):3d} test  {s.description}")
        if args.verbose:
            for m in s.scenarios:
                print(f"      {m.split:5s} {m.scenario.name}")
    print("meshes:")
    for name, res in catalogue().items():
        print(f"  {name:8s} {', '.join(res)}")
    print("solvers:")
    for name in solver_names():
        reason = unavailable(name)
        print(f"  {name:8s} unavailable: {reason}" if reason else f"  {name}")
        if args.verbose and not reason:
            cls = get_solver(name)
            print(f"      parameters: {', '.join(f'{k}={v!r}' for k, v in cls.parameters.items()) or 'none'}")
            if cls.experimental:
                print(f"      experimental: {', '.join(f'{k}={v!r}' for k, v in cls.experimental.items())}")
    print("variant sets (--solvers; a file of your own: --matrix FILE):")
    width = max(map(len, set_names()), default=0)
    for name in set_names():
        print(f"  {name:{width}s} {load_matrix(MATRICES / f'{name}.toml').description}" if args.verbose
              else f"  {name}")
    print(f"  default: {DEFAULT}; " + "; ".join(f"suite {k}: {v}" for k, v in SUITE_DEFAULTS.items()))
    return 0


def cmd_simulate(args: argparse.Namespace) -> int:
    """Simulate one scenario; write trajectory.npz, stats.json and a VTU/PVD series into --out. The resource guard
    (`scenarios.resources`) refuses an oversized run before anything heavy is imported."""
    from frictionbench.scenarios.resources import check_runs

    scenario = resolve_scenario(args.scenario)
    check_runs([(scenario, parse_mesh(args.mesh) or scenario.mesh)], allow_large=args.allow_large)

    from frictionbench.reports.export import export_vtu_series
    from frictionbench.scenarios.atomic import write_json_atomic
    from frictionbench.solvers.registry import get_solver
    from frictionbench.solvers.run import run_scenario

    params = {}
    if args.model:
        if "checkpoint" not in get_solver(args.solver).parameters:
            raise ScenarioError("--model", args.model, f"solver {args.solver!r} takes no checkpoint")
        params["checkpoint"] = args.model
    if args.linear:
        if args.solver != "full":
            raise ScenarioError("--linear", args.linear, "the linear solver is the full-space solver's (--solver full)")
        params["linear"] = args.linear
    traj, stats = run_scenario(scenario, args.solver, args.device, params, parse_mesh(args.mesh),
                               progress=not args.quiet)
    out = Path(args.out)
    traj.save(out / "trajectory.npz")
    if not args.no_vtu:
        export_vtu_series(traj, out / "vtu")
    write_json_atomic(out / "stats.json", stats)
    adaptive = (f" (adaptive at tol {stats['tol']:g}: {stats['rejected_steps']} rejected, smallest "
                f"{stats['dt_min_used']:.3g} s)" if "tol" in stats else "")
    print(f"{scenario.name}: {stats['steps']} steps{adaptive}, {stats['newton_iters_mean']:.2f} Newton "
          f"iterations/step, {stats['step_ms_median']:.2f} ms/step (median), warm-up {stats['warmup_s']:.2f} s "
          f"-> {out}")
    if stats["failed"]:
        print(f"FAILED: {stats['failure']}", file=sys.stderr)
        return 1
    return 0


def parse_variants(spec: str | None, epochs: int | None = None, suite: str | None = None,
                   matrices: Sequence[str] = ()) -> list:
    """`--solvers` list and `--matrix` files -> Variants: names of the shipped variant sets (`bench/matrices/`, e.g.
    `licrom,affine,pod`) or of registered solvers (one variant with the solver's default parameters), then each
    matrix file's variants (`bench.matrix.load_matrix`); without either, the suite's own set (SUITE_DEFAULTS) or
    DEFAULT. The reference solver's name adds nothing (its runs are always there); `epochs` overrides the training
    epochs of the variants that train. A variant that two sets share is kept once, and two different runs of one
    solver under one name are refused, naming the set (`bench.runner.distinct_variants`)."""
    from dataclasses import replace

    from frictionbench.bench.matrix import DEFAULT, EPOCHS_PARAM, SUITE_DEFAULTS, load_matrix, set_names, variant_set
    from frictionbench.bench.runner import REFERENCE, Variant, distinct_variants
    from frictionbench.solvers.registry import solver_names

    if spec is None and not matrices:
        spec = SUITE_DEFAULTS.get(suite or "", DEFAULT)
    sets = [(name, "--solvers") for name in (spec or "").split(",") if name and name != REFERENCE]
    out = []
    for name, field in [*sets, *((path, "--matrix") for path in matrices)]:
        if field == "--matrix":
            variants = list(load_matrix(name).variants)
        elif name in set_names():
            variants = variant_set(name)
        elif name in solver_names():
            variants = [Variant(name)]
        else:
            raise ScenarioError("--solvers", name, "unknown variant set or solver; known: "
                                f"{sorted(set(set_names()) | set(solver_names()))} (a file of your own: --matrix)")
        with_epochs = [replace(v, params=v.params | {EPOCHS_PARAM: epochs}) if epochs and EPOCHS_PARAM in v.params
                       else v for v in variants]
        try:
            out = distinct_variants([*out, *with_epochs])
        except ValueError as err:
            raise ScenarioError(field, name, str(err)) from None
    return out


def cmd_run(args: argparse.Namespace) -> int:
    """Run a suite's matrix into --out (results.csv, report.html); resumes what is already done. Prints the results'
    summary (`print_summary`) and the report's path at the end."""
    from frictionbench.bench.runner import run_suite

    with_baseline = args.baseline is not None and not args.no_report
    if with_baseline:  # a bad baseline or tolerance is refused before the run, not after it
        from frictionbench.bench.compare import CompareError, default_rules, read_results, with_tolerances

        try:
            read_results(args.baseline)
            with_tolerances(default_rules(), args.tol)
        except CompareError as err:
            print(f"error: {err}", file=sys.stderr)
            return 2
    csv = run_suite(args.suite, args.out, parse_variants(args.solvers, args.epochs, args.suite, args.matrix), device=args.device,
                    jobs=resolve_jobs(args.jobs, args.device), executor=args.executor,
                    report=not args.no_report and not with_baseline,
                    only=args.only, resolution=args.resolution, allow_large=args.allow_large,
                    with_truth=not args.no_truth,
                    truth_overrides={"tol": args.truth_tol, "depth": args.truth_depth,
                                     "integrator": args.truth_integrator},
                    truth_store=args.truth_store, use_truth_store=not args.no_truth_store)
    print(f"results: {csv}")
    if with_baseline:
        return cmd_report(argparse.Namespace(dir=args.out, baseline=args.baseline, tol=args.tol))
    print_summary(args.out)
    if not args.no_report:
        print(f"report:  {Path(args.out) / 'report.html'}")
    return 0


def print_summary(out: str | Path, width: int = 118) -> None:
    """Print a results folder's answer in a few lines (`bench.reporting.folder_summary`, the report's first
    screen): the verdict, one sentence per solver family, the truths certified and the gate counts."""
    import textwrap

    from frictionbench.bench.reporting import folder_summary

    print()
    for line in folder_summary(out).lines():
        print(textwrap.fill(line, width, initial_indent="", subsequent_indent="      " if line[:1] == " " else "  ",
                            break_on_hyphens=False, break_long_words=False))


def cmd_train(args: argparse.Namespace) -> int:
    """Train a LiCROM model on the full-space trajectories of a suite's training split (generated and cached)."""
    from frictionbench.bench.runner import REFERENCE, Task, run_tasks
    from frictionbench.bench.store import RunStore
    from frictionbench.scenarios.resources import check_runs
    from frictionbench.scenarios.suites import load_suite
    from frictionbench.solvers.licrom.train import TrainSettings, train_from_trajectories

    suite = load_suite(args.suite)
    members = [m for m in suite.train if args.mesh in (None, m.scenario.mesh.name)]
    if not members:
        raise ScenarioError("--mesh", args.mesh, f"no training member of suite {suite.name} has this mesh")
    shapes = {m.scenario.mesh.key for m in members}
    if len(shapes) > 1:
        raise ScenarioError("--mesh", args.mesh, f"training members span several meshes {sorted(shapes)}; pick one")
    check_runs([(m.scenario, m.scenario.mesh) for m in members], allow_large=args.allow_large or suite.allow_large)
    out = Path(args.out)
    store = RunStore(Path(args.store) if args.store else out / "runs")
    tasks = [Task(m.scenario, REFERENCE, {}) for m in members]
    data_device = args.device if args.data_device else "cpu"
    run_tasks(tasks, store, data_device, resolve_jobs(args.jobs, data_device), "process", "training data")
    settings = TrainSettings(r=args.r, epochs=args.epochs, affine=args.affine, seed=args.seed, points=args.points)
    path = train_from_trajectories([store.folder(t.key) / "trajectory.npz" for t in tasks], out, settings,
                                   args.device, identity={"suite": suite.name, "mesh": shapes.pop(),
                                                          "scenarios": [t.key for t in tasks]})
    print(f"checkpoint: {path}")
    return 0


def cmd_timescales(args: argparse.Namespace) -> int:
    """Print a suite's scenes' time scales (one line per member) and, per mesh, the resolution of each level of
    its truth ladder (`analysis.timescales`); with --runs, the whole-body contact patch of each member is its
    stored reference run's last frame."""
    import pandas as pd

    from frictionbench.analysis.timescales import SCENE_COLUMNS, timescale_table
    from frictionbench.bench.runner import REFERENCE
    from frictionbench.bench.store import RunStore, run_key
    from frictionbench.scenarios.suites import load_suite

    suite = load_suite(args.suite).only(args.only).at_resolution(args.resolution)
    spec = (suite.truth or TruthSpec()).with_(depth=args.depth, integrator=args.integrator, where="--", sep="")
    scenarios = [m.scenario for m in suite.scenarios]
    store = RunStore(Path(args.runs) / "runs") if args.runs else None

    def last_frame(sc: Scenario):
        key = run_key(sc, REFERENCE, {}, None)
        if store is None or not store.done(key):
            return None
        traj = store.load(key)[0]
        return None if traj is None else traj.x[-1]

    rows = pd.DataFrame(timescale_table(scenarios, lambda sc: [sc.time.dt / 2**k for k in range(spec.depth + 1)],
                                        lambda sc: spec.integrator, last_frame))
    pd.set_option("display.width", 250)
    scenes = rows[rows["level"] == 0][["scenario", "mesh", "n_vertices", *SCENE_COLUMNS]]
    print(f"time scales of suite {suite.name} ([rad/s], [s], [m^2]; nan: no such effect, or no run for the patch)")
    print(scenes.rename(columns=lambda c: c.removeprefix("ts_")).to_string(index=False, float_format="%.4g"))
    levels = rows.groupby(["mesh", "level", "dt"], sort=False).agg(
        h_eff=("h_eff", "first"), omega_max_h=("res_omega_max", "max"), omega_1_h=("res_omega_1", "max"),
        contact_vertex_h=("res_contact_vertex", "max"), contact_h=("res_contact", "max"),
        friction_h=("res_friction", "max"), unresolved_share=("res_unresolved_share", "max")).reset_index()
    print(f"\nresolution of each truth-ladder level ({spec.integrator}, dt / 2^level; per mesh and step the largest "
          "over its scenes (their materials and patches); unresolved_share: elastic modes with omega h_eff > 1)")
    print(levels.to_string(index=False, float_format="%.4g"))
    return 0


def cmd_report(args: argparse.Namespace) -> int:
    """Rebuild report.html from a results folder (with a section comparing it with --baseline, if given) and print
    its summary (`print_summary`)."""
    from frictionbench.bench.compare import CompareError, compare_folders, summary
    from frictionbench.bench.reporting import build_report

    try:
        report = build_report(args.dir, baseline=args.baseline, tolerances=args.tol)
        print_summary(args.dir)
        print(f"report:  {report}")
        if args.baseline is not None:
            print(f"against the baseline {args.baseline}: "
                  f"{summary(compare_folders(args.baseline, args.dir, args.tol))}")
    except CompareError as err:
        print(f"error: {err}", file=sys.stderr)
        return 2
    return 0


def cmd_compare(args: argparse.Namespace) -> int:
    """Compare a result set with a baseline per scenario, variant and metric; exit 1 on a regression."""
    from frictionbench.bench.compare import CompareError, compare_folders, format_table, regressions, summary

    try:
        comparison = compare_folders(args.baseline, args.new, args.tol, args.gates)
    except CompareError as err:
        print(f"error: {err}", file=sys.stderr)
        return 2
    print(format_table(comparison, everything=args.all))
    print(f"{args.baseline} -> {args.new}: {summary(comparison)}")
    return 1 if regressions(comparison) else 0


def cmd_gate(args: argparse.Namespace) -> int:
    """Check gates.toml against a results folder; non-zero exit with a list of what fell short."""
    import pandas as pd

    from frictionbench.bench.gates import check, load_gates
    from frictionbench.bench.store import load_run_info

    from frictionbench.scenarios.suites import load_suite

    suite = load_suite(load_run_info(args.dir)["suite"]).name  # gates name suites; a run may name a suite file
    verdicts = check(pd.read_csv(Path(args.dir) / "results.csv"), load_gates(args.gates), suite)
    binding = [v for v in verdicts if not v.advisory]
    failed = [v for v in binding if v.failed]
    undecidable = [v for v in binding if v.status == "undecidable"]
    for v in failed:
        print(f"FAIL {v.gate}: {v.scenario} [{v.variant}] {v.metric} = {v.value} (limit: {v.limit})")
    for v in undecidable:
        print(f"UNDECIDABLE {v.gate}: {v.scenario} [{v.variant}] {v.metric} = {v.value} (limit: {v.limit}; "
              f"{v.reason})")
    advisory = [v for v in verdicts if v.advisory]
    if advisory:
        print(f"advisory checks (reported, not enforced): {sum(v.passed for v in advisory)} of {len(advisory)} met; "
              "see the report's stability section")
    print(f"gate verdicts: {sum(v.passed for v in binding)} of {len(binding)} met"
          + (f", {len(undecidable)} undecidable (not failures)" if undecidable else ""))
    return 1 if failed or not binding else 0


def _add_allow_large_arg(s: argparse.ArgumentParser) -> None:
    """--allow-large: the override of the resource guard."""
    s.add_argument("--allow-large", action="store_true", help="lift the resource guard's bounds on step count "
                   "and stored frames (scenarios.resources)")


def _add_tolerance_arg(s: argparse.ArgumentParser) -> None:
    """--tol: the tolerances of a comparison with a baseline."""
    s.add_argument("--tol", action="append", default=[], metavar="METRIC=SPEC",
                   help="change a comparison tolerance (repeatable): METRIC or KIND (accuracy, stability, timing) = "
                        "off, 5%%, 0.001, 5%%,0.001 or x1.5, optionally after DIRECTION: (lower, higher, true, one); "
                        "see bench/compare.py")


def _add_baseline_args(s: argparse.ArgumentParser) -> None:
    """--baseline and --tol: the report's comparison with another result set."""
    s.add_argument("--baseline", help="another output folder: the report gets a section comparing with it")
    _add_tolerance_arg(s)


def build_parser() -> argparse.ArgumentParser:
    """The argument parser of every sub-command."""
    p = argparse.ArgumentParser(prog="frictionbench", description=__doc__)
    sub = p.add_subparsers(dest="command", required=True)

    s = sub.add_parser("list", help="show suites, meshes and solvers")
    s.add_argument("-v", "--verbose", action="store_true", help="also list every suite member")
    s.set_defaults(func=cmd_list)

    s = sub.add_parser("simulate", help="simulate one scenario")
    s.add_argument("scenario", help="TOML path (e.g. examples/incline.toml) or suite member name (e.g. verify/block_slide)")
    s.add_argument("--solver", default="full", help="a registered solver (see `list`)")
    s.add_argument("--device", default="cpu", choices=["cpu", "cuda"])
    s.add_argument("--model", help="checkpoint of a trained reduced model (licrom)")
    s.add_argument("--mesh", help="another mesh of the same shape: name/resolution or a file")
    s.add_argument("--linear", choices=["auto", "direct", "pardiso", "superlu", "cg"],
                   help="the full-space solver's linear solver (default auto: PARDISO where it loads, else SuperLU, "
                   "on the CPU; cg on CUDA; see solvers/linalg.py); stats.json says which ran")
    s.add_argument("--out", required=True)
    s.add_argument("--no-vtu", action="store_true", help="skip the VTU/PVD export")
    s.add_argument("-q", "--quiet", action="store_true")
    _add_allow_large_arg(s)
    s.set_defaults(func=cmd_simulate)

    s = sub.add_parser("run", help="run a suite's matrix and write results.csv and report.html")
    s.add_argument("--suite", required=True)
    s.add_argument("--solvers", default=None, help="comma list of shipped variant sets (bench/matrices/*.toml; "
                   "`frictionbench list` names them and the defaults) or solver names, besides the reference (default: "
                   "the suite's own sets, else the default sets; the reference's name for the reference only)")
    s.add_argument("--matrix", action="append", default=[], metavar="FILE",
                   help="a variant set of your own: a matrix file (docs/variants.md); repeatable, with --solvers")
    s.add_argument("--epochs", type=int, help="training epochs of the variants that train (default: their preset's, "
                   "30: CI-sized)")
    s.add_argument("--only", help="run only the members whose names match this shell pattern, e.g. 'paper/cheese_*'")
    s.add_argument("--resolution", help="every member on its shape's catalogue mesh at this resolution instead of "
                                        "the suite's (e.g. coarse: a suite's truths where a small machine can "
                                        "afford them); rows name the mesh run")
    s.add_argument("--jobs", type=jobs_arg, help=JOBS_HELP)
    s.add_argument("--device", default="cpu", choices=["cpu", "cuda"])
    s.add_argument("--executor", default="process", choices=["process", "dask"])
    s.add_argument("--out", required=True)
    s.add_argument("--no-report", action="store_true")
    s.add_argument("--no-truth", action="store_true", help="skip the ground truth (the suite's [truth] ladder)")
    s.add_argument("--truth-tol", type=float, help="the truth ladder's tolerance: stop when two successive runs "
                   "differ by at most this fraction of L (default: the suite's [truth], else 0.005)")
    s.add_argument("--truth-depth", type=int, help="the truth ladder's most halvings of dt (default: the suite's)")
    s.add_argument("--truth-integrator", help="the truth ladder's time integrator (default: the suite's, else "
                   f"{TruthSpec.integrator})")
    store = s.add_mutually_exclusive_group()
    store.add_argument("--truth-store", metavar="DIR", help="the truth store: truth-ladder runs kept for every "
                       "results folder, reused instead of recomputed (default: $FRICTIONBENCH_TRUTH_STORE, else "
                       "$FRICTIONBENCH_CACHE/truths, else ~/.cache/frictionbench/truths; delete it to clear it)")
    store.add_argument("--no-truth-store", action="store_true", help="neither read nor write the truth store")
    _add_baseline_args(s)
    _add_allow_large_arg(s)
    s.set_defaults(func=cmd_run)

    s = sub.add_parser("train", help="train a LiCROM model on a suite's training split")
    s.add_argument("--suite", required=True)
    s.add_argument("--mesh", help="mesh shape name (cheese, sphere, ...) when the suite has several")
    s.add_argument("--r", type=int, default=20)
    s.add_argument("--epochs", type=int, default=1000)
    s.add_argument("--affine", action="store_true", help="the 12 affine columns exactly in the subspace")
    s.add_argument("--points", type=int, default=1024, help="points subsampled per frame")
    s.add_argument("--seed", type=int, default=0)
    s.add_argument("--device", default="cpu", choices=["cpu", "cuda"])
    s.add_argument("--data-device", action="store_true", help="also simulate the training data on --device")
    s.add_argument("--jobs", type=jobs_arg, help=JOBS_HELP)
    s.add_argument("--store", help="run store for the training trajectories (default OUT/runs)")
    s.add_argument("--out", required=True)
    _add_allow_large_arg(s)
    s.set_defaults(func=cmd_train)

    s = sub.add_parser("report", help="rebuild report.html from stored results")
    s.add_argument("dir")
    _add_baseline_args(s)
    s.set_defaults(func=cmd_report)

    s = sub.add_parser("timescales", help="print a suite's time scales and the resolution of its truth ladder")
    s.add_argument("--suite", required=True)
    s.add_argument("--only", help="only the members whose names match this shell pattern")
    s.add_argument("--resolution", help="every member on this mesh resolution instead (coarse, medium, ...)")
    s.add_argument("--depth", type=int, help="ladder levels 0..depth (default: the suite's [truth])")
    s.add_argument("--integrator", help="the ladder's integrator (default: the suite's [truth])")
    s.add_argument("--runs", help="a `run` output folder: each member's contact patch from its stored reference "
                   "run's last frame (without: no whole-body contact or friction figures)")
    s.set_defaults(func=cmd_timescales)

    s = sub.add_parser("gate", help="check gates.toml against stored results (exit 1 if any fails)")
    s.add_argument("dir")
    s.add_argument("--gates", help="gates file (default: the gates.toml shipped with the package)")
    s.set_defaults(func=cmd_gate)

    s = sub.add_parser("compare", help="compare two result sets per scenario, variant and metric "
                                       "(exit 1 on a regression beyond the tolerances or a newly failing gate)")
    s.add_argument("baseline", help="the baseline: an output folder (its results.csv) or a results CSV")
    s.add_argument("new", help="the result set judged against it")
    s.add_argument("--gates", help="gates file (default: the gates.toml shipped with the package)")
    s.add_argument("--all", action="store_true", help="list the unchanged rows too")
    _add_tolerance_arg(s)
    s.set_defaults(func=cmd_compare)
    return p


def _exit_on_sigterm(signum: int, frame: object) -> None:
    raise SystemExit(128 + signum)


def main(argv: list[str] | None = None) -> int:
    """Entry point of the `frictionbench` console script. SIGTERM exits like Ctrl-C does (the run's workers are
    stopped with it; what is stored stays)."""
    args = build_parser().parse_args(argv)
    in_main_thread = threading.current_thread() is threading.main_thread()
    previous = signal.signal(signal.SIGTERM, _exit_on_sigterm) if in_main_thread else None
    try:
        return int(args.func(args) or 0)
    except ScenarioError as err:
        print(f"error: {err}", file=sys.stderr)
        return 2
    except ValueError as err:  # checkpoint and plug-in errors name their file and value
        if type(err).__name__ not in ("CheckpointError", "PluginError", "SolverParameterError", "SolverUnavailable"):
            raise
        print(f"error: {err}", file=sys.stderr)
        return 2
    finally:
        if in_main_thread:
            signal.signal(signal.SIGTERM, previous)


if __name__ == "__main__":
    raise SystemExit(main())

"""Build report.html of a results folder from its stored results (results.csv, run store, gates), and its answer in
plain words for the terminal (`folder_summary`: the same `analysis.summary.Summary` as the report's first screen)."""

from __future__ import annotations

from collections.abc import Sequence
from pathlib import Path

import pandas as pd

from frictionbench.analysis.metrics import error_over_time
from frictionbench.analysis.summary import Summary, ladder_mask, numeric_column, summarise
from frictionbench.bench.gates import Verdict, check, load_gates
from frictionbench.bench.store import RunStore, load_run_info
from frictionbench.reports.html import ScenarioRuns, comparison_section, write_report_html
from frictionbench.scenarios.suites import Suite, load_suite
from frictionbench.solvers.trajectory import Trajectory


def _truth(rows: pd.DataFrame, store: RunStore) -> tuple[str, Trajectory] | None:
    """A scenario's ground-truth run, (label, trajectory): its ladder row of the truth's integrator and level
    (`ladder` = truth_integrator, `ladder_level` = truth_depth) when the rows name one and the store holds it, else
    None."""
    if (not {"truth_integrator", "truth_depth", "ladder", "ladder_level", "run"} <= set(rows)
            or rows["truth_depth"].isna().all()):
        return None
    first = rows[rows["truth_depth"].notna()].iloc[0]
    match = rows[(rows["ladder"] == first["truth_integrator"]) & (rows["ladder_level"] == first["truth_depth"])
                 & rows["run"].notna()]
    if match.empty or not store.done(match.iloc[0]["run"]):
        return None
    traj, _ = store.load(match.iloc[0]["run"])
    return (f"truth ({match.iloc[0]['solver']}/{match.iloc[0]['variant']})", traj) if traj is not None else None


def _judged(out: Path, gates_file: str | Path | None) -> tuple[pd.DataFrame, Suite, list[Verdict]]:
    """A results folder's results table, its suite and the verdicts of `gates_file` (None: the shipped gates)."""
    results = pd.read_csv(out / "results.csv")
    suite = load_suite(load_run_info(out)["suite"])  # a shipped name or a suite file's path
    return results, suite, check(results, load_gates(gates_file), suite.name)


def folder_summary(out: str | Path, gates_file: str | Path | None = None) -> Summary:
    """The answer of a results folder (`analysis.summary.summarise` of its results and gate verdicts)."""
    results, _, verdicts = _judged(Path(out), gates_file)
    return summarise(results, verdicts)


def build_report(out: str | Path, gates_file: str | Path | None = None, max_scenarios: int = 4,
                 baseline: str | Path | None = None, tolerances: Sequence[str] = ()) -> Path:
    """Rebuild `out/report.html` from `out/results.csv` and the run store, judged by `gates_file` (None: the
    shipped gates); renders the first scenarios. With a `baseline` result set (an output folder), the report gets a
    section comparing the results with it (`bench.compare`, its default tolerances changed by `tolerances`)."""
    out = Path(out)
    results, suite, verdicts = _judged(out, gates_file)
    planes = {m.scenario.name: m.scenario.plane for m in suite.scenarios}
    store = RunStore(out / "runs")
    runs = []
    ladder = ladder_mask(results)
    for scenario in list(dict.fromkeys(results["scenario"]))[:max_scenarios]:
        rows = results[(results["scenario"] == scenario) & ~ladder]
        ref_rows = rows[rows["variant"] == "reference"]
        if ref_rows.empty or not store.done(ref_rows.iloc[0]["run"]):
            continue
        ref, _ = store.load(ref_rows.iloc[0]["run"])
        truth = _truth(results[results["scenario"] == scenario], store)
        others = {}
        for _, row in rows[(rows["variant"] != "reference") & rows["run"].notna()].iterrows():
            remeshed = isinstance(row.get("remesh"), str) and row.get("remesh")
            if not remeshed and store.done(row["run"]):
                traj, _ = store.load(row["run"])
                if traj is not None:
                    others[f"{row['solver']}/{row['variant']}"] = traj
        ref_label = str(ref_rows.iloc[0]["solver"])
        against = truth[1] if truth is not None else ref
        compared = ({ref_label: ref} if truth is not None else {}) | others
        errors = {label: error_over_time(against, traj) for label, traj in compared.items()}
        scenario_rows = results[results["scenario"] == scenario]
        adaptive = scenario_rows[numeric_column(scenario_rows, "tol").notna() & scenario_rows["run"].notna()]
        steps = {f"{row['solver']}/{row['variant']}": store.stats(row["run"]).get("per_step", [])
                 for _, row in adaptive.iterrows() if store.done(row["run"])}
        runs.append(ScenarioRuns(scenario=scenario, reference=ref, others=others, errors=errors,
                                 plane=planes.get(scenario), reference_label=ref_label,
                                 truth=truth[1] if truth is not None else None,
                                 truth_label=truth[0] if truth is not None else "truth",
                                 steps={label: records for label, records in steps.items() if records}))
    extra = []
    if baseline is not None:
        from frictionbench.bench.compare import compare_folders

        comparison = compare_folders(baseline, out, tolerances, gates_file)
        extra.append(("Comparison with the baseline", comparison_section(comparison, str(baseline))))
    return write_report_html(results, out, gates=verdicts, runs=runs, extra_sections=extra,
                             title=f"frictionbench: {suite.name} suite")

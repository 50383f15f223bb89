"""Build report.html of a results folder from its stored results (results.csv, run store, gates)."""

from __future__ import annotations

from pathlib import Path

import pandas as pd

from bench.gates import check, load_gates
from bench.store import RunStore
from reports.html import ScenarioRuns, write_report_html

GATES_FILE = Path(__file__).resolve().parent.parent / "gates.toml"


def build_report(out: str | Path, gates_file: str | Path = GATES_FILE, max_scenarios: int = 4) -> Path:
    """Rebuild `out/report.html` from `out/results.csv` and the run store; renders the first scenarios."""
    from bench.runner import load_run_info

    out = Path(out)
    results = pd.read_csv(out / "results.csv")
    from scenarios.suites import load_suite

    suite = load_suite(load_run_info(out)["suite"])  # a shipped name or a suite file's path
    verdicts = check(results, load_gates(gates_file), suite.name) if Path(gates_file).is_file() else []
    planes = {m.scenario.name: m.scenario.plane for m in suite.scenarios}
    store = RunStore(out / "runs")
    runs = []
    for scenario in list(dict.fromkeys(results["scenario"]))[:max_scenarios]:
        rows = results[results["scenario"] == scenario]
        ref_rows = rows[rows["variant"] == "reference"]
        if ref_rows.empty or not store.done(ref_rows.iloc[0]["run"]):
            continue
        ref, _ = store.load(ref_rows.iloc[0]["run"])
        others = {}
        for _, row in rows[(rows["variant"] != "reference") & rows["run"].notna()].iterrows():
            remeshed = isinstance(row.get("remesh"), str) and row.get("remesh")
            if not remeshed and store.done(row["run"]):
                traj, _ = store.load(row["run"])
                if traj is not None:
                    others[f"{row['solver']}/{row['variant']}"] = traj
        runs.append(ScenarioRuns(scenario=scenario, reference=ref, others=others, plane=planes.get(scenario),
                                 reference_label=str(ref_rows.iloc[0]["solver"])))
    return write_report_html(results, out, gates=verdicts, runs=runs, title=f"frictionbench: {suite.name} suite")

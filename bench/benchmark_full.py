"""Benchmark of the full-space solver: per-step time and Newton iterations on catalogue meshes.

    python -m frictionbench.bench.benchmark_full --meshes cheese/coarse cheese/medium --device cpu \
        --out out/bench_full.json

Runs the quick suite's first scenario (a drop onto the paper's plane with friction) on each mesh for --steps steps
after an untimed warm-up step, and writes the figures with the machine's provenance as JSON.
"""

from __future__ import annotations

import argparse
from dataclasses import replace

from frictionbench.analysis.table import provenance
from frictionbench.bench.cli import parse_mesh
from frictionbench.scenarios.atomic import write_json_atomic
from frictionbench.scenarios.spec import TimeSpec
from frictionbench.scenarios.suites import load_suite
from frictionbench.solvers.run import run_scenario


def benchmark(meshes: list[str], device: str, steps: int, linear: str) -> list[dict]:
    """One record per mesh: vertex/tet counts, step time median/p95 [ms], Newton iterations mean/max."""
    base = load_suite("quick").scenarios[0].scenario
    sc = replace(base, time=TimeSpec(dt=base.time.dt, duration=steps * base.time.dt))
    records = []
    for ref in meshes:
        _, st = run_scenario(sc, "full", device, {"linear": linear}, parse_mesh(ref))
        records.append({k: st[k] for k in ("mesh", "n_vertices", "n_tets", "step_ms_median", "step_ms_p95",
                                           "newton_iters_mean", "newton_iters_max", "warmup_s", "not_converged")}
                       | {"device": device, "linear": linear, "scenario": sc.name, "steps": steps})
        r = records[-1]
        print(f"{r['mesh']:22s} {r['n_tets']:7d} tets  {r['step_ms_median']:9.1f} ms/step (p95 {r['step_ms_p95']:.1f})"
              f"  {r['newton_iters_mean']:.2f} Newton it/step  warm-up {r['warmup_s']:.1f} s")
    return records


def main() -> None:
    p = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    p.add_argument("--meshes", nargs="+", default=["cheese/coarse", "cheese/medium"])
    p.add_argument("--device", default="cpu")
    p.add_argument("--linear", default="auto", choices=["auto", "direct", "pardiso", "superlu", "cg"])
    p.add_argument("--steps", type=int, default=40)
    p.add_argument("--out", default="out/bench_full.json")
    a = p.parse_args()
    records = benchmark(a.meshes, a.device, a.steps, a.linear)
    write_json_atomic(a.out, {"records": records, "provenance": provenance(a.device)})


if __name__ == "__main__":
    main()

"""Check the reduced solver's kernels on a device (CUDA by default) against the numpy references.

    python -m frictionbench.bench.device_check --out out/device_check.json          # on the GPU
    python -m frictionbench.bench.device_check --device cpu --out out/cpu_check.json  # the same checks on the CPU

CI has no GPU, so the CUDA path of the cubature kernels (`solvers.reduced.kernels`, `device = "cuda"`) is checked
here, on a machine that has one. Two checks:

- kernels: the Stable Neo-Hookean and Kelvin-Voigt kernels at `--tets` random deformation gradients (a tenth of them
  inverted), to each output (the density, the stress P and the Hessian factor L, compared as L^T L), against the
  numpy references of `solvers.physics.material` and `solvers.physics.viscosity`: the largest difference relative to
  the reference's largest entry, and the mean wall time of a Hessian call [us] (launch and copies included).
- run: a block spinning and drifting in free flight with Kelvin-Voigt damping (no plane: the point terms' kernels
  run on the CPU only), stepped by a reduced solver whose body terms are evaluated by the numpy references
  (`solvers.reduced.terms.ReferenceEvaluation`, the Hessian every iteration), then by the device's kernels with the
  body Hessian every iteration and once a step (`hessian_refresh`): Newton iterations, convergence and the largest
  distance of each kernel run from the reference run [fraction of L].

A check passes when every kernel output is within KERNEL_RTOL of its reference and each kernel run is within RUN_ATOL
of L of its reference run, converged; the exit status is 1 otherwise. The results go to `--out` as JSON.
"""

from __future__ import annotations

import argparse
import sys
import time

import numpy as np
from frictionbench.scenarios.atomic import write_json_atomic
from frictionbench.scenarios.meshes import load_mesh
from frictionbench.scenarios.spec import Effects, Initial, Material, MeshSpec, Scenario, TimeSpec
from frictionbench.solvers.build import build_model, initial_state
from frictionbench.solvers.physics import material as pm
from frictionbench.solvers.physics import viscosity as pv
from frictionbench.solvers.reduced import kernels as K
from frictionbench.solvers.reduced.bases import smooth_basis
from frictionbench.solvers.reduced.solver import HESSIAN_REFRESHES, ReducedSolver
from frictionbench.solvers.reduced.terms import ReferenceEvaluation
from frictionbench.solvers.simulate import simulate

KERNEL_RTOL = 1e-12
"""Largest difference of a kernel output from its numpy reference, relative to the reference's largest entry."""
RUN_ATOL = 1e-10
"""Largest distance of a kernel-evaluated run from its reference-evaluated twin [fraction of L] (tol 1e-9 L/s)."""


def _relative(a: np.ndarray, ref: np.ndarray) -> float:
    """max |a - ref| / max |ref| (0 where both are zero)."""
    scale = float(np.abs(ref).max())
    return float(np.abs(a - ref).max()) / scale if scale else float(np.abs(a).max())


def check_kernels(device: str, tets: int, seed: int = 0, repeats: int = 20) -> dict:
    """The kernels at `tets` random deformation gradients on `device` against the numpy references (module doc)."""
    rng = np.random.default_rng(seed)
    mu, lam = pm.snh_parameters(1e6, 0.45)
    c = 12.5  # eta / h_eff [Pa]
    F = np.eye(3) + 0.3 * rng.standard_normal((tets, 3, 3))
    F[: max(1, tets // 10)] *= -0.5  # inverted tets
    F_bar = np.eye(3) + 0.3 * rng.standard_normal((tets, 3, 3))
    psi, P, L = K.snh_evaluate(F, mu, lam, K.HESSIAN, device)
    d, Pv, Lv = K.viscous_evaluate(F, F_bar, c, K.HESSIAN, device)
    t0 = time.perf_counter()
    for _ in range(repeats):
        K.snh_evaluate(F, mu, lam, K.HESSIAN, device)
    call_us = 1e6 * (time.perf_counter() - t0) / repeats
    return {"tets": tets,
            "snh_density": _relative(psi, pm.snh_energy_density(F, mu, lam)),
            "snh_stress": _relative(P, pm.snh_pk1(F, mu, lam)),
            "snh_hessian": _relative(L.transpose(0, 2, 1) @ L, pm.project_psd(pm.snh_dpdf(F, mu, lam))),
            "viscous_density": _relative(d, pv.viscous_density(F, F_bar, c)),
            "viscous_stress": _relative(Pv, pv.viscous_stress(F, F_bar, c)),
            "viscous_hessian": _relative(Lv.transpose(0, 2, 1) @ Lv, pv.viscous_dpdf(F, F_bar, c)),
            "snh_hessian_call_us": call_us}


def spinning_block() -> Scenario:
    """A soft damped block spinning and drifting in free flight for 0.3 s (no plane, no gravity), BDF2 at 10 ms."""
    return Scenario(name="device_check", mesh=MeshSpec("block", "coarse"), plane=None, gravity=(0.0, 0.0, 0.0),
                    material=Material(youngs_modulus=2e4, viscosity=5.0), effects=Effects(damping=True),
                    initial=Initial(velocity=(0.3, -0.1, 0.2), angular_velocity=(1.0, 4.0, -2.0)),
                    time=TimeSpec(dt=0.01, duration=0.3, integrator="bdf2"))


def check_run(device: str, r: int = 24, seed: int = 0) -> list[dict]:
    """The spinning block on a smooth basis of r columns (`solvers.reduced.bases.smooth_basis`), its body terms
    by the numpy references (the Hessian every iteration), then by the device's kernels under each
    `HESSIAN_REFRESHES`, each compared with the first (module doc)."""
    model = build_model(spinning_block(), load_mesh(MeshSpec("block", "coarse")))
    W = smooth_basis(model.X, r, 0.002 * model.L, seed)
    records, reference = [], None
    for how, refresh in (("reference", "iteration"), *((device, h) for h in HESSIAN_REFRESHES)):
        solver = ReducedSolver(model, W, device=device, hessian_refresh=refresh, tol=1e-9)
        if how == "reference":
            solver.body_evaluations = [ReferenceEvaluation(solver, ev.term) for ev in solver.body_evaluations]
        t0 = time.perf_counter()
        traj, stats = simulate(model, solver, solver.project(initial_state(model)))
        reference = traj.x if reference is None else reference
        records.append({"evaluation": how, "hessian_refresh": refresh, "wall_s": time.perf_counter() - t0,
                        "terms": [ev.term.name for ev in solver.body_evaluations],
                        "iterations": int(sum(s.iterations for s in stats)),
                        "converged": all(s.converged for s in stats),
                        "dx_vs_reference_L": float(np.abs(traj.x - reference).max() / model.L)})
    return records


def device_check(device: str, tets: list[int]) -> dict:
    """Both checks on `device`, with the verdict `passed` (module doc)."""
    kernels = [check_kernels(device, c) for c in tets]
    runs = check_run(device)
    ok_kernels = all(v <= KERNEL_RTOL for k in kernels for name, v in k.items() if name not in ("tets",
                                                                                                 "snh_hessian_call_us"))
    ok_runs = all(r["converged"] and r["dx_vs_reference_L"] <= RUN_ATOL for r in runs)
    return {"device": device, "kernels": kernels, "runs": runs, "passed": ok_kernels and ok_runs}


def main(argv: list[str] | None = None) -> int:
    p = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    p.add_argument("--device", default="cuda", choices=K.DEVICES, help="where the kernels run (default: cuda)")
    p.add_argument("--tets", type=int, nargs="+", default=[60, 150, 5000], help="tets per kernel check")
    p.add_argument("--out", default="out/device_check.json")
    a = p.parse_args(argv)
    result = device_check(a.device, a.tets)
    for k in result["kernels"]:
        print(" ".join(f"{name} {v:.3g}" for name, v in k.items()), flush=True)
    for r in result["runs"]:
        print(f"{r['evaluation']:9s} {r['hessian_refresh']:9s} iterations {r['iterations']:4d} converged "
              f"{r['converged']} |x - reference|/L {r['dx_vs_reference_L']:.2e} ({r['wall_s']:.2f} s)", flush=True)
    write_json_atomic(a.out, result)
    print("passed" if result["passed"] else "FAILED", flush=True)
    return 0 if result["passed"] else 1


if __name__ == "__main__":
    sys.exit(main())

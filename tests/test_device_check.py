"""The device check (`bench.device_check`) on the CPU: CI has no GPU, so its CUDA run is a figure, not a test; here
its checks run on the CPU kernels and must pass, and a kernel off its reference must fail them."""

from __future__ import annotations

import json

import numpy as np
from frictionbench.bench import device_check as dc
from frictionbench.solvers.reduced import kernels as K


def test_the_device_check_passes_on_the_cpu_kernels(tmp_path, capsys):
    out = tmp_path / "check.json"
    assert dc.main(["--device", "cpu", "--tets", "40", "--out", str(out)]) == 0
    result = json.loads(out.read_text())
    assert result["passed"] and result["device"] == "cpu"
    (kernels,) = result["kernels"]
    assert kernels["tets"] == 40 and max(v for k, v in kernels.items() if k.endswith(("density", "stress",
                                                                                          "hessian"))) < 1e-12
    runs = {(r["evaluation"], r["hessian_refresh"]): r for r in result["runs"]}
    assert set(runs) == {("reference", "iteration"), ("cpu", "iteration"), ("cpu", "step")}
    assert runs["cpu", "iteration"]["iterations"] == runs["reference", "iteration"]["iterations"]
    assert all(r["converged"] and r["dx_vs_reference_L"] < 1e-10 for r in runs.values())
    assert all(r["terms"] == ["inertia", "elasticity", "viscosity"] for r in runs.values())
    assert "passed" in capsys.readouterr().out


def test_a_kernel_off_its_reference_fails_the_check(tmp_path, monkeypatch):
    snh = K.snh_evaluate

    def off(F, mu, lam, mode=K.HESSIAN, device="cpu"):
        psi, P, L = snh(F, mu, lam, mode, device)
        return psi * (1 + 1e-9), P, L

    monkeypatch.setattr(dc.K, "snh_evaluate", off)
    result = dc.check_kernels("cpu", 20)
    assert 1e-10 < result["snh_density"] < 1e-8 and result["snh_stress"] < 1e-12
    monkeypatch.setattr(dc, "check_run", lambda device: [])
    assert dc.main(["--device", "cpu", "--tets", "20", "--out", str(tmp_path / "c.json")]) == 1
    assert not json.loads((tmp_path / "c.json").read_text())["passed"]
    assert np.isfinite(result["snh_hessian_call_us"])

"""The training-free modal subspace (`solvers.reduced.modal`): its linear modes against a dense eigensolver, its modal
derivatives against the equation they solve with the Hessian's derivative taken independently (second differences
of the elastic forces), the basis it builds, and the solver through the harness."""

from __future__ import annotations

import numpy as np
import pandas as pd
import pytest
import scipy.linalg as sla

from frictionbench.bench.cli import main
from frictionbench.scenarios.meshes import make_mesh
from frictionbench.scenarios.meshgen import structured_box
from frictionbench.scenarios.spec import Material, Scenario
from frictionbench.solvers.build import build_model
from frictionbench.solvers.physics.material import elastic_gradient, rest_stiffness
from frictionbench.solvers.reduced.bases import affine_basis
from frictionbench.solvers.reduced.modal import Modal, modal_basis, modal_derivatives, vibration_modes

from scenes import block_drop, mu_axis, suite_tables, write_toml


@pytest.fixture(scope="module")
def box():
    """A free 0.2 x 0.1 x 0.15 m box (60 vertices) of a soft material."""
    X, tets = structured_box((0.2, 0.1, 0.15), (4, 2, 3), (-0.1, 0.0, -0.075))
    sc = Scenario(name="box", material=Material(density=1000.0, youngs_modulus=1e5, poisson_ratio=0.3))
    return build_model(sc, make_mesh(X, tets, "box"))


def test_the_linear_modes_are_the_lowest_elastic_eigenpairs(box):
    phi, w2 = vibration_modes(box, 8)
    M = np.repeat(box.mass, 3)
    dense = sla.eigh(rest_stiffness(box).toarray(), np.diag(M), eigvals_only=True)
    assert np.abs(dense[:6]).max() < 1e-8 * dense[-1]  # six rigid motions
    assert w2 == pytest.approx(dense[6:14], rel=1e-9)
    P = phi.reshape(-1, 8)
    assert np.einsum("ik,i,il->kl", P, M, P) == pytest.approx(np.eye(8), abs=1e-10)
    K = rest_stiffness(box)
    assert np.abs(K @ P - M[:, None] * P * w2).max() < 1e-7 * np.abs(K @ P).max()
    with pytest.raises(ValueError, match="modes = 0"):
        vibration_modes(box, 0)


def test_a_modal_derivative_solves_its_equation_with_the_hessians_derivative_taken_independently(box):
    """K Psi_ij = -(dK/dq_j) phi_i beyond the rigid motions (K's null space, where the right-hand side's part has no
    solution: the derivative of the forces' zero torque is not zero), where (dK/dq_j) phi_i is here the mixed second
    difference of the elastic forces along phi_i and phi_j (no element Hessian involved); and Psi_ij = Psi_ji (third
    derivatives commute)."""
    phi, _ = vibration_modes(box, 3)
    psi = modal_derivatives(box, phi)
    args = (box.tets, box.Dm_inv, box.vol, box.mu_snh, box.lam_snh)
    h = 1e-3 * box.L / np.abs(phi).max()
    K = rest_stiffness(box)
    Xc = box.X - box.X.mean(0)
    rigid = [np.tile(np.eye(3)[a], (box.n, 1)) for a in range(3)] + [np.cross(np.eye(3)[a], Xc) for a in range(3)]
    R, _ = np.linalg.qr(np.stack(rigid, axis=2).reshape(-1, 6))
    for i, j in ((0, 0), (0, 2), (1, 2)):
        f = {(a, b): elastic_gradient(box.X + h * (a * phi[:, :, i] + b * phi[:, :, j]), *args).ravel()
             for a in (-1, 1) for b in (-1, 1)}
        dK_phi = (f[1, 1] - f[1, -1] - f[-1, 1] + f[-1, -1]) / (4 * h * h)
        dK_phi -= R @ (R.T @ dK_phi)
        residual = K @ psi[:, :, i, j].ravel() + dK_phi
        assert np.abs(residual).max() < 1e-4 * np.abs(dK_phi).max()
        assert np.abs(psi[:, :, i, j] - psi[:, :, j, i]).max() < 1e-4 * np.abs(psi[:, :, i, j]).max()
        # mass-orthogonal to the rigid motions (the solve's complement): no momentum, no angular momentum
        u = psi[:, :, i, j]
        scale = np.abs(box.mass[:, None] * u).sum()
        assert np.abs(box.mass @ u).max() < 1e-9 * scale
        assert np.abs(np.cross(box.X - box.X.mean(0), box.mass[:, None] * u).sum(0)).max() < 1e-9 * scale * box.L


def test_the_basis_holds_the_affine_fields_the_modes_and_the_derivatives_mass_orthonormal(box):
    W, info = modal_basis(box, modes=6, derivatives=4, derivative_modes=3)
    assert W.shape == (box.n, 3, 12 + 6 + 4)
    M = np.repeat(box.mass, 3)
    Wf = W.reshape(-1, W.shape[2])
    assert Wf.T @ (M[:, None] * Wf) == pytest.approx(np.eye(W.shape[2]), abs=1e-10)
    for fields in (affine_basis(box.X), vibration_modes(box, 6)[0]):  # both in its span exactly
        F = fields.reshape(-1, fields.shape[2])
        assert np.abs(F - Wf @ (Wf.T @ (M[:, None] * F))).max() < 1e-9 * np.abs(F).max()
    assert 0 < info["omega_first"] <= info["omega_last"]
    with pytest.raises(ValueError, match="derivatives = 7"):
        modal_basis(box, modes=6, derivatives=7, derivative_modes=3)


def test_the_modal_solver_runs_in_a_matrix_on_any_mesh_and_its_modes_lower_the_affine_error(tmp_path):
    """A soft block dropped on a plane, `modal` beside `affine` (the same affine fields with no modes), on the
    member's mesh and on the other mesh of the shape, no training: the larger subspace is closer to the full-space
    reference (by little: a free body's low modes hold little of a contact's squash, docs/solvers.md)."""
    soft = {"youngs_modulus": 3e3, "poisson_ratio": 0.3, "density": 1000.0}
    suite = write_toml(tmp_path / "soft.toml", suite_tables("soft", block_drop(duration=0.3, material=soft),
                                                            mu_axis(0.5)))
    matrix = tmp_path / "modal.toml"
    matrix.write_text('[[variant]]\nsolver = "modal"\nlabel = "m8"\nparams = { modes = 16, derivatives = 8 }\n'
                      'then = [{ other_mesh = "beside" }]\n\n[[variant]]\nsolver = "affine"\n')
    out = tmp_path / "out"
    assert main(["run", "--suite", str(suite), "--matrix", str(matrix), "--no-truth", "--no-report", "--jobs", "1",
                 "--out", str(out)]) == 0
    rows = pd.read_csv(out / "results.csv").set_index("variant")
    assert (rows.loc[["m8", "m8-remesh", "affine"], "status"] == "ok").all()
    assert rows.loc["m8", "pos_rmse_rel"] < rows.loc["affine", "pos_rmse_rel"]
    assert rows.loc["m8-remesh", "mesh"] != rows.loc["m8", "mesh"]


def test_the_modal_solver_declares_its_parameters():
    assert {"modes", "derivatives", "derivative_modes"} <= set(Modal.parameters)
    assert Modal(modes=4).params["modes"] == 4

"""Cantilever under self-weight at small strain: full-space statics against scikit-fem and beam theory."""

from __future__ import annotations

import numpy as np
import pytest
import skfem
from skfem.models.elasticity import lame_parameters, linear_elasticity

from frictionbench.scenarios.meshes import load_mesh
from frictionbench.scenarios.spec import Material, MeshSpec, Scenario
from frictionbench.solvers.build import build_model
from frictionbench.solvers.full.solver import FullSpaceSolver
from frictionbench.solvers.full.static import static_equilibrium

E, NU, RHO, G = 1e9, 0.3, 1000.0, 9.81


def skfem_self_weight(X: np.ndarray, tets: np.ndarray, clamped: np.ndarray) -> np.ndarray:
    """Linear-elastic displacement (n, 3) under self-weight with P1 tets, scikit-fem's own assembly."""
    mesh = skfem.MeshTet(X.T.copy(), tets.T.copy())
    basis = skfem.Basis(mesh, skfem.ElementVector(skfem.ElementTetP1()))
    K = skfem.asm(linear_elasticity(*lame_parameters(E, NU)), basis)

    @skfem.LinearForm
    def weight(v, w):
        return -RHO * G * v[1]

    f = skfem.asm(weight, basis)
    dofs = basis.get_dofs(lambda p: np.isin(np.arange(p.shape[1]), np.flatnonzero(clamped))).all()
    u = skfem.solve(*skfem.condense(K, f, D=dofs))
    return u[basis.nodal_dofs.T]


def test_cantilever_tip_matches_scikit_fem_and_beam_theory():
    mesh = load_mesh(MeshSpec("beam", "coarse"))
    sc = Scenario(name="cantilever", mesh=MeshSpec("beam", "coarse"), plane=None,
                  material=Material(density=RHO, youngs_modulus=E, poisson_ratio=NU))
    model = build_model(sc, mesh)
    X = model.X
    length = np.ptp(X[:, 0])
    thickness = np.ptp(X[:, 1])
    clamped = X[:, 0] <= X[:, 0].min() + 1e-9
    tip = X[:, 0] >= X[:, 0].max() - 1e-9
    x, _ = static_equilibrium(FullSpaceSolver(model), clamped)
    ours = (x - X)[tip, 1].mean()
    ref = skfem_self_weight(X, model.tets, clamped)[tip, 1].mean()
    assert ours == pytest.approx(ref, rel=0.05)
    # Euler-Bernoulli tip deflection 3 rho g L^4 / (2 E h^2); linear tets are stiff in bending on coarse meshes,
    # so the FEM value lies below it and approaches it under refinement (see docs/results.md).
    beam = -3 * RHO * G * length**4 / (2 * E * thickness**2)
    assert 0.3 * abs(beam) < abs(ours) < 1.02 * abs(beam)

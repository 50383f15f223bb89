"""Variant grids are built from a solver's declared parameters (`bench.variants.grid`)."""

import pytest

from frictionbench.bench.variants import LICROM, grid, variant_set
from frictionbench.solvers.registry import get_solver


def test_a_grid_is_the_cartesian_product_of_declared_parameters() -> None:
    variants = grid("licrom", "r{r}-{scheme}", LICROM, r=[8, 16], scheme=["newton", "projected_gradient"])
    assert [v.label for v in variants] == ["r8-newton", "r8-projected_gradient", "r16-newton",
                                           "r16-projected_gradient"]
    assert all(v.solver == "licrom" and v.params["epochs"] == LICROM["epochs"] for v in variants)
    assert [v.params["r"] for v in variants] == [8, 8, 16, 16]


def test_a_grid_over_an_undeclared_parameter_is_refused() -> None:
    with pytest.raises(ValueError, match=r"unknown parameter\(s\) \['rank'\]"):
        grid("licrom", "r{rank}", rank=[8])
    with pytest.raises(ValueError, match="unknown parameter"):
        grid("full", "x", {"r": 4}, tol=[1e-3])


def test_the_rank_sweep_set_is_a_grid() -> None:
    ranks = variant_set("licrom-rank")
    assert [(v.solver, v.params.get("r")) for v in ranks] == [("affine", None), ("licrom", 24), ("licrom", 48),
                                                              ("licrom", 96)]
    for v in ranks:  # every point a valid solver: r counts the affine columns, so LiCROM+affine needs r > 12
        get_solver(v.solver)(device="cpu", **v.params)

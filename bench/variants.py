"""Named variant sets for `frictionbench run --solvers`: each name expands to solver variants of the matrix."""

from __future__ import annotations

from bench.runner import Variant

VARIANTS: dict[str, list[Variant]] = {
    # accuracy-for-time sweeps of the full-space solver: looser Newton tolerance, coarser mesh
    "full-sweep": [Variant("full", {"tol": 1e-3}, label="tol1e-3")],
}

"""Shared fixtures. Small dense linear algebra runs single-threaded in tests: BLAS threads on a busy 2-core
machine slow the reduced solver's r x r operations by an order of magnitude."""

from __future__ import annotations

import pytest
from threadpoolctl import threadpool_limits

from frictionbench.scenarios.meshes import load_mesh
from frictionbench.scenarios.model import MeshSpec

threadpool_limits(1)


@pytest.fixture(scope="session")
def block():
    """The coarse structured block (0.2 x 0.1 x 0.2 m)."""
    return load_mesh(MeshSpec(name="block", resolution="coarse"))

"""Scenes shared by several test modules."""

from __future__ import annotations

import numpy as np

from scenarios.model import Initial, Material, MeshSpec, Plane, Scenario, TimeSpec

G = 9.81


def incline(theta_deg: float, mu: float, **kw) -> Scenario:
    """A block released at rest, flat on a plane through the origin descending towards +x."""
    t = np.radians(theta_deg)
    return Scenario(
        name=f"incline_{theta_deg}_{mu}", mesh=MeshSpec("block", "coarse"),
        material=Material(density=1000.0, youngs_modulus=1e6, poisson_ratio=0.3),
        plane=Plane(normal=(np.sin(t), np.cos(t), 0.0), offset=0.0, friction=mu),
        initial=Initial(clearance=0.0, rotation=(0.0, 0.0, -theta_deg)),
        time=TimeSpec(dt=0.01, duration=kw.pop("duration", 0.6)), **kw)


def assert_ranges_match_one_launch(solver, kernel, inputs: list, offsets: dict[int, int]) -> None:
    """A per-element Hessian kernel launched over element ranges from 1 and 2 threads (`ElementRanges`) fills
    solver.elem_blocks bitwise as one launch does, at its first launch (ranges in turn) and later ones (threads);
    `inputs` end before the output blocks, `offsets` as `ElementRanges.launch` takes them."""
    from solvers.full.assembly import ElementRanges

    ref = None
    for threads in (1, 2):
        ranges = ElementRanges(solver.model.tets.shape[0], solver.device, threads)
        assert ranges.threads == threads
        for _ in range(2):  # a kernel's first launch runs the ranges in turn, later ones in parallel threads
            solver.elem_blocks.zero_()
            ranges.launch(kernel, inputs + [solver.elem_blocks], offsets)
            if ref is None:
                ref = solver.elem_blocks.numpy().copy()
                assert np.abs(ref).max() > 0
            assert np.array_equal(solver.elem_blocks.numpy(), ref)


def com_series(traj, mass):
    """Centre of mass per frame, (F, 3) [m]."""
    return np.einsum("n,fnk->fk", mass, traj.x) / mass.sum()

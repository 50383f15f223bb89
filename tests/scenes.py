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


def com_series(traj, mass):
    """Centre of mass per frame, (F, 3) [m]."""
    return np.einsum("n,fnk->fk", mass, traj.x) / mass.sum()

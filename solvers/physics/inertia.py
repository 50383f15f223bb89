"""Inertia and gravity: lumped mass and the backward-Euler inertial term of the incremental potential."""

from __future__ import annotations

import numpy as np


def lumped_mass(vol: np.ndarray, tets: np.ndarray, n_vertices: int, density: float) -> np.ndarray:
    """Vertex masses (n,) [kg]: each tet gives rho V_e / 4 to each of its 4 vertices."""
    m = np.zeros(n_vertices)
    np.add.at(m, tets, np.repeat((density * vol / 4.0)[:, None], 4, axis=1))
    return m


def inertia_energy(x: np.ndarray, x_hat: np.ndarray, mass: np.ndarray, h: float) -> float:
    """1/(2 h^2) |x - x_hat|_M^2 [J] with x_hat = x^n + h v^n, positions (n, 3), mass (n,)."""
    d = x - x_hat
    return float(0.5 / h**2 * np.einsum("i,ij,ij->", mass, d, d))


def inertia_gradient(x: np.ndarray, x_hat: np.ndarray, mass: np.ndarray, h: float) -> np.ndarray:
    """M (x - x_hat) / h^2, (n, 3) [N]."""
    return mass[:, None] * (x - x_hat) / h**2


def gravity_energy(x: np.ndarray, mass: np.ndarray, gravity: np.ndarray) -> float:
    """Potential of a uniform field: -sum_i m_i g . x_i [J]; gravity (3,) [m/s^2]."""
    return float(-mass @ (x @ gravity))


def gravity_gradient(mass: np.ndarray, gravity: np.ndarray) -> np.ndarray:
    """-m_i g (n, 3) [N], constant."""
    return -mass[:, None] * gravity[None, :]

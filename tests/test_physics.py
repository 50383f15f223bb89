"""Shared physics: finite-difference checks of every energy's gradient and Hessian, rest state, small strain."""

from __future__ import annotations

import numpy as np
import pytest


@pytest.fixture
def rng() -> np.random.Generator:
    return np.random.default_rng(7)

from frictionbench.solvers.physics import contact as pc
from frictionbench.solvers.physics import friction as pf
from frictionbench.solvers.physics import inertia as pi
from frictionbench.solvers.physics import material as pm



def fd_gradient(f, x: np.ndarray, eps: float = 1e-6) -> np.ndarray:
    """Central differences of a scalar function of an array."""
    g = np.zeros_like(x)
    for idx in np.ndindex(x.shape):
        d = np.zeros_like(x)
        d[idx] = eps
        g[idx] = (f(x + d) - f(x - d)) / (2 * eps)
    return g


def one_tet():
    X = np.array([[0, 0, 0], [1, 0, 0], [0, 1, 0], [0, 0, 1.0]]) * 0.1
    tets = np.array([[0, 1, 2, 3]])
    return X, tets, *pm.shape_matrices(X, tets)


@pytest.mark.parametrize("scale", [0.05, 0.4])
def test_snh_stress_is_energy_gradient_and_dpdf_its_jacobian(rng, scale):
    mu, lam = pm.snh_parameters(1e5, 0.4)
    F = np.eye(3) + scale * rng.standard_normal((3, 3))
    P = pm.snh_pk1(F, mu, lam)
    assert np.allclose(P, fd_gradient(lambda G: pm.snh_energy_density(G, mu, lam), F), rtol=1e-6, atol=1e-3)
    H = pm.snh_dpdf(F, mu, lam)
    Hfd = np.stack([fd_gradient(lambda G: pm.snh_pk1(G, mu, lam)[i, j], F).ravel()
                    for i in range(3) for j in range(3)])
    assert np.allclose(H, Hfd, rtol=1e-5, atol=1e-2)
    assert np.allclose(H, H.T)


def test_rest_state_has_zero_stress_and_zero_energy(rng):
    mu, lam = pm.snh_parameters(1e6, 0.45)
    assert np.allclose(pm.snh_pk1(np.eye(3), mu, lam), 0.0, atol=1e-9 * mu)
    # Energy at rest is a constant (the log term); its gradient vanishes, so rigid rotations are stress free.
    R = np.linalg.qr(rng.standard_normal((3, 3)))[0]
    R *= np.sign(np.linalg.det(R))
    assert np.allclose(pm.snh_pk1(R, mu, lam), 0.0, atol=1e-9 * mu)


def test_small_strain_matches_linear_elasticity(rng):
    E, nu = 2e5, 0.3
    mu, lam = pm.snh_parameters(E, nu)
    mu_l, lam_l = pm.lame_parameters(E, nu)
    eps = 1e-6 * rng.standard_normal((3, 3))
    eps = 0.5 * (eps + eps.T)
    sigma_lin = 2 * mu_l * eps + lam_l * np.trace(eps) * np.eye(3)
    P = pm.snh_pk1(np.eye(3) + eps, mu, lam)
    assert np.allclose(P, sigma_lin, rtol=1e-4, atol=1e-6 * np.abs(sigma_lin).max())


def test_projected_element_hessian_is_psd_and_exact_when_convex(rng):
    X, tets, Dm_inv, vol = one_tet()
    mu, lam = pm.snh_parameters(1e5, 0.3)
    x = X + 0.02 * rng.standard_normal(X.shape)
    x[3] = x[0] + 0.5 * (x[3] - x[0]) - 0.2 * np.array([0, 0, 0.1])  # strongly compressed: indefinite
    Hp = pm.element_hessians(x, tets, Dm_inv, vol, mu, lam)[0]
    assert np.linalg.eigvalsh(Hp).min() > -1e-8 * np.abs(Hp).max()
    g = lambda y: pm.elastic_gradient(y.reshape(4, 3), tets, Dm_inv, vol, mu, lam).ravel()  # noqa: E731
    x_small = X + 1e-4 * rng.standard_normal(X.shape)
    H_exact = np.stack([fd_gradient(lambda y: g(y)[k], x_small.ravel()) for k in range(12)])
    H = pm.element_hessians(x_small, tets, Dm_inv, vol, mu, lam)[0]
    assert np.allclose(H, H_exact, rtol=1e-4, atol=1e-4 * np.abs(H).max())


def test_elastic_gradient_is_energy_gradient(rng):
    X, tets, Dm_inv, vol = one_tet()
    mu, lam = pm.snh_parameters(1e5, 0.3)
    x = X + 0.02 * rng.standard_normal(X.shape)
    E = lambda y: pm.elastic_energy(y, tets, Dm_inv, vol, mu, lam)  # noqa: E731
    assert np.allclose(pm.elastic_gradient(x, tets, Dm_inv, vol, mu, lam), fd_gradient(E, x), rtol=1e-5, atol=1e-6)


def test_inertia_and_gravity_gradients(rng):
    x, xh, m, g = rng.random((5, 3)), rng.random((5, 3)), rng.random(5), np.array([0, -9.81, 0])
    assert np.allclose(pi.inertia_gradient(x, xh, m, 0.01),
                       fd_gradient(lambda y: pi.inertia_energy(y, xh, m, 0.01), x), rtol=1e-6)
    assert np.allclose(pi.gravity_gradient(m, g), fd_gradient(lambda y: pi.gravity_energy(y, m, g), x), rtol=1e-6)
    tets = np.array([[0, 1, 2, 3], [1, 2, 3, 4]])
    assert np.isclose(pi.lumped_mass(np.array([1.0, 3.0]), tets, 5, 2.0).sum(), 8.0)


def contact_case(rng):
    n = np.array([1.0, 5.0, 2.0]) / np.sqrt(30)
    x = rng.random((6, 3)) * 0.02
    x_prev = x + 0.001 * rng.standard_normal((6, 3))
    return x, x_prev, rng.random(6) * 1e-3, n, 0.01


def test_penalty_contact_gradient_and_hessian(rng):
    x, xp, A, n, d = contact_case(rng)
    args = (xp, A, n, d, 1e6, 50.0, 0.01)
    assert (pc.signed_distance(x, n, d) < 0).any()
    E = lambda y: pc.penalty_energy(y, *args)  # noqa: E731
    assert np.allclose(pc.penalty_gradient(x, *args), fd_gradient(E, x, 1e-8), rtol=1e-5, atol=1e-9)
    H = pc.penalty_hessian(x, *args)
    for p in range(len(x)):
        Hfd = np.stack([fd_gradient(lambda y: pc.penalty_gradient(y, *args)[p, k], x, 1e-9)[p] for k in range(3)])
        assert np.allclose(H[p], Hfd, rtol=1e-4, atol=1e-6)


def test_barrier_derivatives():
    d = np.linspace(1e-4, 2e-3, 50)
    dhat = 1e-3
    e = 1e-9
    assert np.allclose(pc.barrier_d1(d, dhat), (pc.barrier(d + e, dhat) - pc.barrier(d - e, dhat)) / (2 * e),
                       rtol=1e-5, atol=1e-12)
    assert np.allclose(pc.barrier_d2(d, dhat), (pc.barrier_d1(d + e, dhat) - pc.barrier_d1(d - e, dhat)) / (2 * e),
                       rtol=1e-4, atol=1e-9)
    assert np.all(pc.barrier_d2(d, dhat) >= 0) and np.isinf(pc.barrier(np.array([0.0]), dhat)).all()


@pytest.mark.parametrize("slip", [1e-5, 1.0])  # viscous (below eps_v) and Coulomb regimes
def test_friction_potential_gradient_hessian_and_force_law(rng, slip):
    x, _, A, n, _ = contact_case(rng)
    h, mu, kf = 0.01, 0.4, 1e5
    fn = 100.0 + rng.random(len(x)) * 100
    direction = rng.standard_normal((len(x), 3))
    xp = x - h * slip * direction / np.linalg.norm(direction, axis=1, keepdims=True)
    args = (xp, A, fn, n, mu, kf, h)
    E = lambda y: pf.friction_energy(y, *args)  # noqa: E731
    G = pf.friction_gradient(x, *args)
    assert np.allclose(G, fd_gradient(E, x, 1e-10 if slip < 1e-3 else 1e-7), rtol=1e-4, atol=1e-10)
    # force magnitude is A min(k_f |v_t|, mu f_n), tangential
    vt = pf.slip_velocity(x, xp, n, h)
    expected = A * np.minimum(kf * np.linalg.norm(vt, axis=1), mu * fn)
    assert np.allclose(np.linalg.norm(G, axis=1), expected, rtol=1e-10)
    assert np.allclose(G @ n, 0.0, atol=1e-12)
    H = pf.friction_hessian(x, *args)
    for p in range(len(x)):
        Hfd = np.stack([fd_gradient(lambda y: pf.friction_gradient(y, *args)[p, k], x, 1e-10)[p] for k in range(3)])
        assert np.allclose(H[p], Hfd, rtol=1e-3, atol=1e-6 * np.abs(H[p]).max())
        assert np.linalg.eigvalsh(H[p]).min() > -1e-9 * np.abs(H[p]).max()

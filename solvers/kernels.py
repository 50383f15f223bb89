"""Warp kernels of the physics terms (float64, CPU and CUDA); each mirrors a numpy reference in `solvers.physics`
and is tested against it. The terms name theirs (`solvers.physics.terms`: `DensityTerm.kernels`, `PointTerm.kernel`)
and the backends pass the arguments by name: the full-space solver launches them all (`solvers.full.terms`); the
reduced solver launches the point terms' kernels at its contact candidates and calls the SNH functions from its
cubature kernels (`solvers.reduced.kernels`).

Hessians are accumulated into the values of a block-sparse (BSR, 3x3 blocks) matrix whose pattern is fixed
by the mesh: `blockmap[16 e + 4 a + b]` is the block of the (tets[e, a], tets[e, b]) pair, `diag[i]` the
diagonal block of vertex i. Scalars are summed into a one-element array with atomics.
"""

from __future__ import annotations

import warp as wp

f64 = wp.float64


@wp.func
def snh_psi(F: wp.mat33d, mu: f64, lam: f64, alpha: f64) -> f64:
    """Stable Neo-Hookean energy density Psi(F) [J/m^3]."""
    ic = wp.ddot(F, F)
    J = wp.determinant(F)
    return f64(0.5) * mu * (ic - f64(3.0)) + f64(0.5) * lam * (J - alpha) * (J - alpha) - f64(0.5) * mu * wp.log(
        f64(1.0) + ic
    )


@wp.func
def cofactor(F: wp.mat33d) -> wp.mat33d:
    """dJ/dF: columns f1 x f2, f2 x f0, f0 x f1."""
    f0 = wp.vec3d(F[0, 0], F[1, 0], F[2, 0])
    f1 = wp.vec3d(F[0, 1], F[1, 1], F[2, 1])
    f2 = wp.vec3d(F[0, 2], F[1, 2], F[2, 2])
    c0 = wp.cross(f1, f2)
    c1 = wp.cross(f2, f0)
    c2 = wp.cross(f0, f1)
    return wp.mat33d(c0[0], c1[0], c2[0], c0[1], c1[1], c2[1], c0[2], c1[2], c2[2])


@wp.func
def deformation_gradient(x: wp.array(dtype=wp.vec3d), tet: wp.vec4i, Dm_inv: wp.mat33d) -> wp.mat33d:
    """F = Ds Dm^-1 for one tet."""
    x0 = x[tet[0]]
    d1 = x[tet[1]] - x0
    d2 = x[tet[2]] - x0
    d3 = x[tet[3]] - x0
    Ds = wp.mat33d(d1[0], d2[0], d3[0], d1[1], d2[1], d3[1], d1[2], d2[2], d3[2])
    return Ds * Dm_inv


@wp.func
def shape_gradient(Dm_inv: wp.mat33d, a: int) -> wp.vec3d:
    """g_a with F = sum_a x_a g_a^T: rows of Dm^-1 for a = 1..3, minus their sum for a = 0."""
    if a == 0:
        return -(Dm_inv[0] + Dm_inv[1] + Dm_inv[2])
    return Dm_inv[a - 1]


@wp.func
def add_mode(blocks: wp.array(dtype=wp.mat33d), base: int, Q: wp.mat33d, lam_v: f64, Dm_inv: wp.mat33d):
    """blocks[base + 4a + b] += lam_v (Q g_a)(Q g_b)^T for one mode Q of dP/dF with weight lam_v (`snh_mode`; none
    where lam_v <= 0)."""
    if lam_v > f64(0.0):
        w0 = Q * shape_gradient(Dm_inv, 0)
        w1 = Q * shape_gradient(Dm_inv, 1)
        w2 = Q * shape_gradient(Dm_inv, 2)
        w3 = Q * shape_gradient(Dm_inv, 3)
        for a in range(4):
            wa = w0
            if a == 1:
                wa = w1
            elif a == 2:
                wa = w2
            elif a == 3:
                wa = w3
            wa = lam_v * wa
            blocks[base + 4 * a + 0] += wp.outer(wa, w0)
            blocks[base + 4 * a + 1] += wp.outer(wa, w1)
            blocks[base + 4 * a + 2] += wp.outer(wa, w2)
            blocks[base + 4 * a + 3] += wp.outer(wa, w3)


@wp.kernel
def elastic_energy_kernel(
    x: wp.array(dtype=wp.vec3d),
    tets: wp.array(dtype=wp.vec4i),
    Dm_inv: wp.array(dtype=wp.mat33d),
    vol: wp.array(dtype=f64),
    mu: f64,
    lam: f64,
    alpha: f64,
    energy: wp.array(dtype=f64),
):
    """energy[0] += V_e Psi(F_e)."""
    e = wp.tid()
    F = deformation_gradient(x, tets[e], Dm_inv[e])
    wp.atomic_add(energy, 0, vol[e] * snh_psi(F, mu, lam, alpha))


@wp.kernel
def elastic_gradient_kernel(
    x: wp.array(dtype=wp.vec3d),
    tets: wp.array(dtype=wp.vec4i),
    Dm_inv: wp.array(dtype=wp.mat33d),
    vol: wp.array(dtype=f64),
    mu: f64,
    lam: f64,
    alpha: f64,
    grad: wp.array(dtype=wp.vec3d),
):
    """grad[x_a] += V_e P g_a with P = mu (1 - 1/(I_C + 1)) F + lam (J - alpha) cof(F)."""
    e = wp.tid()
    tet = tets[e]
    Dmi = Dm_inv[e]
    F = deformation_gradient(x, tet, Dmi)
    ic = wp.ddot(F, F)
    J = wp.determinant(F)
    P = mu * (f64(1.0) - f64(1.0) / (ic + f64(1.0))) * F + lam * (J - alpha) * cofactor(F)
    for a in range(4):
        wp.atomic_add(grad, tet[a], vol[e] * (P * shape_gradient(Dmi, a)))


#: Jacobi sweeps of `sym_eig3` at most; it stops once the off-diagonal part is at round-off (EIG_OFF_TOL), which
#: takes 3-5 sweeps (quadratic convergence), and at once on a non-finite input: the cap is a safety bound only.
EIG_MAX_SWEEPS = wp.constant(12)
#: `sym_eig3` stops when the off-diagonal entries' squares sum to at most this share of the diagonal's: each is then
#: below 1e-17 of the largest diagonal entry, under double precision's round-off of it.
EIG_OFF_TOL = wp.constant(1.0e-34)


@wp.func
def sym_eig3(A: wp.mat33d):
    """The eigenvectors (columns of Q, orthonormal) and eigenvalues lam of a symmetric 3x3 A, A = Q diag(lam) Q^T,
    by cyclic Jacobi rotations (each zeroes one off-diagonal pair exactly; Golub and Van Loan's symmetric Schur
    step), in no particular order. Backward stable: Q is orthonormal and Q diag(lam) Q^T is A to round-off of |A|;
    half the cost of warp's `eig3` and `svd3` (fixed sweeps of approximate rotations) on these 3x3 matrices, and
    closer to A (tests/test_kernel_linalg.py)."""
    D = A
    Q = wp.identity(n=3, dtype=f64)
    for _sweep in range(EIG_MAX_SWEEPS):
        off = D[0, 1] * D[0, 1] + D[0, 2] * D[0, 2] + D[1, 2] * D[1, 2]
        if not (off > f64(EIG_OFF_TOL) * (D[0, 0] * D[0, 0] + D[1, 1] * D[1, 1] + D[2, 2] * D[2, 2])):
            break
        for pair in range(3):
            p = pair // 2  # pairs (0, 1), (0, 2), (1, 2)
            q = 1 + (pair + 1) // 2
            dpq = D[p, q]
            if dpq != f64(0.0):
                theta = (D[q, q] - D[p, p]) / (f64(2.0) * dpq)
                t = f64(1.0) / (wp.abs(theta) + wp.sqrt(theta * theta + f64(1.0)))
                if theta < f64(0.0):
                    t = -t
                c = f64(1.0) / wp.sqrt(t * t + f64(1.0))
                sn = t * c
                r = 3 - p - q
                drp = D[r, p]
                drq = D[r, q]
                D[p, p] = D[p, p] - t * dpq
                D[q, q] = D[q, q] + t * dpq
                D[p, q] = f64(0.0)
                D[q, p] = f64(0.0)
                D[r, p] = c * drp - sn * drq
                D[p, r] = D[r, p]
                D[r, q] = sn * drp + c * drq
                D[q, r] = D[r, q]
                for i in range(3):
                    qip = Q[i, p]
                    qiq = Q[i, q]
                    Q[i, p] = c * qip - sn * qiq
                    Q[i, q] = sn * qip + c * qiq
    return Q, wp.vec3d(D[0, 0], D[1, 1], D[2, 2])


@wp.func
def svd3_rotations(F: wp.mat33d):
    """The rotation-variant SVD F = U diag(s) V^T with U and V rotations (det +1), s[0] >= s[1] >= |s[2]| (to
    round-off) and s[2] negative where det F < 0 (an inverted element): V from the eigenvectors of F^T F
    (`sym_eig3`, sorted), then U and s from the columns of F V by Gram-Schmidt, u2 = u0 x u1 and s2 = u2 . (F v2),
    as a QR factorisation of F V would give them; a zero or rank-one F gets an arbitrary orthonormal completion.
    F = U diag(s) V^T to round-off of |F|, small singular values to round-off of |F| (not of F^T F)."""
    V, d = sym_eig3(wp.transpose(F) * F)
    for k in range(2):  # sort the eigenpairs by decreasing eigenvalue (three compare-and-swaps)
        for j in range(2 - k):
            if d[j] < d[j + 1]:
                dj = d[j]
                d[j] = d[j + 1]
                d[j + 1] = dj
                for i in range(3):
                    vij = V[i, j]
                    V[i, j] = V[i, j + 1]
                    V[i, j + 1] = vij
    if wp.determinant(V) < f64(0.0):
        for i in range(3):
            V[i, 2] = -V[i, 2]
    B = F * V
    b0 = wp.vec3d(B[0, 0], B[1, 0], B[2, 0])
    b1 = wp.vec3d(B[0, 1], B[1, 1], B[2, 1])
    b2 = wp.vec3d(B[0, 2], B[1, 2], B[2, 2])
    s0 = wp.length(b0)
    u0 = wp.vec3d(f64(1.0), f64(0.0), f64(0.0))
    if s0 > f64(0.0):
        u0 = b0 / s0
    w1 = b1 - wp.dot(u0, b1) * u0
    s1 = wp.length(w1)
    u1 = wp.vec3d()
    if s1 > f64(0.0):
        u1 = w1 / s1
    else:  # F of rank one or zero: any unit vector orthogonal to u0
        a = wp.vec3d(f64(1.0), f64(0.0), f64(0.0))
        if wp.abs(u0[0]) > f64(0.5):
            a = wp.vec3d(f64(0.0), f64(1.0), f64(0.0))
        u1 = wp.normalize(a - wp.dot(u0, a) * u0)
    u2 = wp.cross(u0, u1)
    U = wp.mat33d(u0[0], u1[0], u2[0], u0[1], u1[1], u2[1], u0[2], u1[2], u2[2])
    return U, wp.vec3d(s0, s1, wp.dot(u2, b2)), V


@wp.func
def scaling_factor(A: wp.mat33d):
    """A factor Qs and weights ls of the PSD part A_+ of a symmetric 3x3 A, A_+ = sum_m ls[m] q_m q_m^T with q_m the
    columns of Qs: where A is positive definite (its Cholesky pivots all positive), A's Cholesky factor L (A = L L^T)
    with unit weights, which costs a tenth of an eigendecomposition; else its eigenvectors and eigenvalues
    (`sym_eig3`), the negative ones to be dropped by the caller."""
    Qs = wp.mat33d()
    ls = wp.vec3d(f64(1.0), f64(1.0), f64(1.0))
    pd = False
    if A[0, 0] > f64(0.0):
        Qs[0, 0] = wp.sqrt(A[0, 0])
        Qs[1, 0] = A[1, 0] / Qs[0, 0]
        Qs[2, 0] = A[2, 0] / Qs[0, 0]
        d1 = A[1, 1] - Qs[1, 0] * Qs[1, 0]
        if d1 > f64(0.0):
            Qs[1, 1] = wp.sqrt(d1)
            Qs[2, 1] = (A[2, 1] - Qs[2, 0] * Qs[1, 0]) / Qs[1, 1]
            d2 = A[2, 2] - Qs[2, 0] * Qs[2, 0] - Qs[2, 1] * Qs[2, 1]
            if d2 > f64(0.0):
                Qs[2, 2] = wp.sqrt(d2)
                pd = True
    if not pd:
        Qs, ls = sym_eig3(A)
    return Qs, ls


@wp.func
def snh_eigensystem(F: wp.mat33d, mu: f64, lam: f64, alpha: f64):
    """The analytic eigensystem of the SNH dP/dF (9x9) at F, in the rotation-variant SVD F = U diag(s) V^T
    (det U = det V = 1, `svd3_rotations`): returns (U, s, V, Qs, ls, ca, cc) for `snh_mode`.

    dP/dF = a I + b f f^T + d g g^T + c d2J/dF2 with a = mu (1 - 1/(I_C+1)), b = 2 mu/(I_C+1)^2, c = lam (J -
    alpha), d = lam, f = vec F, g = vec cof F. Its eigen-matrices are, per index pair (i, j) with k the third, a
    twist U (e_i e_j^T - e_j e_i^T) V^T / sqrt 2 with eigenvalue a + c s_k, a flip with + and eigenvalue a - c s_k,
    and three scaling modes U diag(w) V^T spanning the block of the 3x3 matrix A_ij = a delta_ij + b s_i s_j + d g_i
    g_j + c s_k [i != j], g = (s1 s2, s0 s2, s0 s1): with (Qs, ls) = `scaling_factor(A)`, w the columns of Qs and
    ls their weights (A's eigenvectors and eigenvalues, or where A is positive definite its Cholesky factor's
    columns with weight 1: the same block, A_+ = A); ca = a, cc = c.
    """
    U, s, V = svd3_rotations(F)
    ic = s[0] * s[0] + s[1] * s[1] + s[2] * s[2]
    J = s[0] * s[1] * s[2]
    ca = mu * (f64(1.0) - f64(1.0) / (ic + f64(1.0)))
    cb = f64(2.0) * mu / ((ic + f64(1.0)) * (ic + f64(1.0)))
    cc = lam * (J - alpha)
    cd = lam
    g = wp.vec3d(s[1] * s[2], s[0] * s[2], s[0] * s[1])
    A = wp.mat33d()
    for i in range(3):
        for j in range(3):
            A[i, j] = cb * s[i] * s[j] + cd * g[i] * g[j]
            if i == j:
                A[i, j] = A[i, j] + ca
            else:
                A[i, j] = A[i, j] + cc * s[3 - i - j]
    Qs, ls = scaling_factor(A)
    return U, s, V, Qs, ls, ca, cc


@wp.func
def snh_mode(U: wp.mat33d, s: wp.vec3d, V: wp.mat33d, Qs: wp.mat33d, ls: wp.vec3d, ca: f64, cc: f64, m: int):
    """Mode m of dP/dF = sum_m l_m vec(Q_m) vec(Q_m)^T from `snh_eigensystem`'s output: (Q_m, l_m). m = 0-2 the
    scaling block's factor columns (eigen-matrices of unit Frobenius norm, or Cholesky columns with weight 1), then
    per k = 0, 1, 2 the twist (m = 3 + 2k) and the flip (m = 4 + 2k) about axis k (eigen-matrices of unit norm with
    their eigenvalues). Keeping the modes of positive weight gives the PSD projection (dP/dF)_+."""
    Vt = wp.transpose(V)
    if m < 3:
        return U * wp.diag(wp.vec3d(Qs[0, m], Qs[1, m], Qs[2, m])) * Vt, ls[m]
    k = (m - 3) // 2
    i = (k + 1) % 3
    j = (k + 2) % 3
    r = f64(0.7071067811865476)
    E = wp.mat33d()
    E[i, j] = r
    if (m - 3) % 2 == 0:
        E[j, i] = -r
        return U * E * Vt, ca + cc * s[k]
    E[j, i] = r
    return U * E * Vt, ca - cc * s[k]


@wp.kernel
def elastic_hessian_kernel(
    x: wp.array(dtype=wp.vec3d),
    tets: wp.array(dtype=wp.vec4i),
    Dm_inv: wp.array(dtype=wp.mat33d),
    vol: wp.array(dtype=f64),
    mu: f64,
    lam: f64,
    alpha: f64,
    blocks: wp.array(dtype=wp.mat33d),
):
    """Per-element projected Hessian blocks (16 per tet) from the analytic SNH eigensystem (`snh_eigensystem`):
    every mode with a positive eigenvalue (PSD projection)."""
    e = wp.tid()
    tet = tets[e]
    Dmi = Dm_inv[e]
    U, s, V, Qs, ls, ca, cc = snh_eigensystem(deformation_gradient(x, tet, Dmi), mu, lam, alpha)
    for m in range(9):
        Q, lam_v = snh_mode(U, s, V, Qs, ls, ca, cc, m)
        add_mode(blocks, 16 * e, Q, vol[e] * lam_v, Dmi)


@wp.kernel
def scatter_blocks_kernel(
    blocks: wp.array(dtype=wp.mat33d), blockmap: wp.array(dtype=wp.int32), values: wp.array(dtype=wp.mat33d)
):
    """values[blockmap[k]] += blocks[k] (element blocks into the BSR matrix)."""
    k = wp.tid()
    wp.atomic_add(values, blockmap[k], blocks[k])


@wp.kernel
def inertia_gravity_kernel(
    x: wp.array(dtype=wp.vec3d),
    x_hat: wp.array(dtype=wp.vec3d),
    mass: wp.array(dtype=f64),
    inv_h2: f64,
    gravity: wp.vec3d,
    diag: wp.array(dtype=wp.int32),
    grad: wp.array(dtype=wp.vec3d),
    values: wp.array(dtype=wp.mat33d),
    energy: wp.array(dtype=f64),
    mode: int,
):
    """Inertia 1/(2h^2)|x - x_hat|_M^2 plus gravity -m g.x; mode 0: energy, 1: gradient and Hessian."""
    i = wp.tid()
    d = x[i] - x_hat[i]
    m = mass[i]
    if mode == 0:
        wp.atomic_add(energy, 0, f64(0.5) * inv_h2 * m * wp.dot(d, d) - m * wp.dot(gravity, x[i]))
    else:
        grad[i] = grad[i] + m * inv_h2 * d - m * gravity
        values[diag[i]] = values[diag[i]] + m * inv_h2 * wp.identity(n=3, dtype=f64)


@wp.kernel
def penalty_contact_kernel(
    x: wp.array(dtype=wp.vec3d),
    x_lag: wp.array(dtype=wp.vec3d),
    x_bar: wp.array(dtype=wp.vec3d),
    points: wp.array(dtype=wp.int32),
    area: wp.array(dtype=f64),
    normal: wp.vec3d,
    offset: f64,
    ke: f64,
    kd: f64,
    h: f64,
    diag: wp.array(dtype=wp.int32),
    grad: wp.array(dtype=wp.vec3d),
    values: wp.array(dtype=wp.mat33d),
    energy: wp.array(dtype=f64),
    mode: int,
):
    """Penalty law per unit area (see solvers.physics.contact.penalty_*); mode 0: energy, 1: grad + Hessian,
    2: all three.

    Damping acts at points that penetrated at the start of the step (x_lag below the plane), with the velocity
    (x - x_bar) / h of the integrator (h its effective step)."""
    p = wp.tid()
    i = points[p]
    c = offset - wp.dot(normal, x[i])
    vn = f64(0.0)
    if wp.dot(normal, x_lag[i]) < offset:
        vn = wp.min(f64(0.0), wp.dot(x[i] - x_bar[i], normal) / h)
    if c <= f64(0.0) and vn == f64(0.0):
        return
    c = wp.max(c, f64(0.0))
    A = area[p]
    if mode != 1:
        wp.atomic_add(energy, 0, A * (f64(0.5) * ke * c * c + f64(0.5) * h * kd * vn * vn))
    if mode >= 1:
        wp.atomic_add(grad, i, A * (-ke * c + kd * vn) * normal)
        k = f64(0.0)
        if c > f64(0.0):
            k = A * ke
        if vn < f64(0.0):
            k = k + A * kd / h
        wp.atomic_add(values, diag[i], k * wp.outer(normal, normal))


@wp.kernel
def barrier_contact_kernel(
    x: wp.array(dtype=wp.vec3d),
    points: wp.array(dtype=wp.int32),
    area: wp.array(dtype=f64),
    normal: wp.vec3d,
    offset: f64,
    kappa: f64,
    dhat: f64,
    diag: wp.array(dtype=wp.int32),
    grad: wp.array(dtype=wp.vec3d),
    values: wp.array(dtype=wp.mat33d),
    energy: wp.array(dtype=f64),
    mode: int,
):
    """IPC log barrier kappa A b(phi) (see solvers.physics.contact.barrier*); mode 0: energy, 1: grad + Hessian, 2:
    all three."""
    p = wp.tid()
    i = points[p]
    d = wp.dot(normal, x[i]) - offset
    if d >= dhat:
        return
    A = area[p]
    if mode != 1:
        if d <= f64(0.0):
            wp.atomic_add(energy, 0, f64(1.0e300))
        else:
            wp.atomic_add(energy, 0, -kappa * A * (d - dhat) * (d - dhat) * wp.log(d / dhat))
    if mode >= 1:
        b1 = -f64(2.0) * (d - dhat) * wp.log(d / dhat) - (d - dhat) * (d - dhat) / d
        b2 = -f64(2.0) * wp.log(d / dhat) - f64(4.0) * (d - dhat) / d + (d - dhat) * (d - dhat) / (d * d)
        wp.atomic_add(grad, i, kappa * A * b1 * normal)
        wp.atomic_add(values, diag[i], kappa * A * b2 * wp.outer(normal, normal))


@wp.kernel
def friction_kernel(
    x: wp.array(dtype=wp.vec3d),
    x_bar: wp.array(dtype=wp.vec3d),
    points: wp.array(dtype=wp.int32),
    area: wp.array(dtype=f64),
    fn: wp.array(dtype=f64),
    normal: wp.vec3d,
    mu: f64,
    kf: f64,
    h: f64,
    diag: wp.array(dtype=wp.int32),
    grad: wp.array(dtype=wp.vec3d),
    values: wp.array(dtype=wp.mat33d),
    energy: wp.array(dtype=f64),
    mode: int,
):
    """Lagged friction potential A h mu f_n f0(|v_t|) (see solvers.physics.friction), v = (x - x_bar) / h with the
    integrator's x_bar and effective step h; mode 0 energy, 1 grad+H, 2 all three."""
    p = wp.tid()
    if fn[p] <= f64(0.0):
        return
    i = points[p]
    v = (x[i] - x_bar[i]) / h
    vt = v - wp.dot(v, normal) * normal
    s = wp.length(vt)
    A = area[p]
    cap = mu * fn[p]
    eps = cap / kf
    T = wp.identity(n=3, dtype=f64) - wp.outer(normal, normal)
    if mode != 1:
        f0 = s - f64(0.5) * eps
        if s < eps:
            f0 = f64(0.5) * s * s / eps
        wp.atomic_add(energy, 0, A * h * cap * f0)
    if mode >= 1:
        if s < eps:
            wp.atomic_add(grad, i, A * kf * vt)
            wp.atomic_add(values, diag[i], (A * kf / h) * T)
        else:
            t = vt / s
            wp.atomic_add(grad, i, A * cap * t)
            wp.atomic_add(values, diag[i], (A * cap / (h * s)) * (T - wp.outer(t, t)))


@wp.func
def green_strain(F: wp.mat33d) -> wp.mat33d:
    """E = (F^T F - I) / 2."""
    return f64(0.5) * (wp.transpose(F) * F - wp.identity(n=3, dtype=f64))


@wp.func
def strain_change(F: wp.mat33d, E_bar: wp.mat33d) -> wp.mat33d:
    """A = E(F) - E(F_bar): the Green strain at F minus that at the integrator's x_bar (the viscous term's rate
    times h_eff)."""
    return green_strain(F) - E_bar


@wp.kernel
def green_strain_kernel(
    x: wp.array(dtype=wp.vec3d),
    tets: wp.array(dtype=wp.vec4i),
    Dm_inv: wp.array(dtype=wp.mat33d),
    E_bar: wp.array(dtype=wp.mat33d),
):
    """E_bar[e] = E(F_e(x)), the Green strain of each tet: the viscous term's E(F_bar) at x = x_bar, once per step
    (`solvers.physics.terms.TetKernels.at_bar`)."""
    e = wp.tid()
    E_bar[e] = green_strain(deformation_gradient(x, tets[e], Dm_inv[e]))


@wp.kernel
def viscous_energy_kernel(
    x: wp.array(dtype=wp.vec3d),
    E_bar: wp.array(dtype=wp.mat33d),
    tets: wp.array(dtype=wp.vec4i),
    Dm_inv: wp.array(dtype=wp.mat33d),
    vol: wp.array(dtype=f64),
    eta_over_h: f64,
    energy: wp.array(dtype=f64),
):
    """energy[0] += V_e eta / h_eff |E(F) - E(F_bar)|_F^2 (see solvers.physics.viscosity)."""
    e = wp.tid()
    A = strain_change(deformation_gradient(x, tets[e], Dm_inv[e]), E_bar[e])
    wp.atomic_add(energy, 0, vol[e] * eta_over_h * wp.ddot(A, A))


@wp.kernel
def viscous_gradient_kernel(
    x: wp.array(dtype=wp.vec3d),
    E_bar: wp.array(dtype=wp.mat33d),
    tets: wp.array(dtype=wp.vec4i),
    Dm_inv: wp.array(dtype=wp.mat33d),
    vol: wp.array(dtype=f64),
    eta_over_h: f64,
    grad: wp.array(dtype=wp.vec3d),
):
    """grad[x_a] += 2 c F A g_a with c = V_e eta / h_eff and A = E(F) - E(F_bar)."""
    e = wp.tid()
    tet = tets[e]
    Dmi = Dm_inv[e]
    F = deformation_gradient(x, tet, Dmi)
    FA = F * strain_change(F, E_bar[e])
    c = vol[e] * eta_over_h
    for a in range(4):
        wp.atomic_add(grad, tet[a], f64(2.0) * c * (FA * shape_gradient(Dmi, a)))


@wp.kernel
def viscous_hessian_kernel(
    x: wp.array(dtype=wp.vec3d),
    E_bar: wp.array(dtype=wp.mat33d),
    tets: wp.array(dtype=wp.vec4i),
    Dm_inv: wp.array(dtype=wp.mat33d),
    vol: wp.array(dtype=f64),
    eta_over_h: f64,
    blocks: wp.array(dtype=wp.mat33d),
):
    """Per-element Hessian blocks (16 per tet, written, not added): with c = V_e eta / h_eff and A = E(F) -
    E(F_bar), the block of the vertex pair (a, b) is c [(g_a . g_b) F F^T + (F g_b)(F g_a)^T] (Gauss-Newton)
    + 2 c (g_a^T A_+ g_b) I (the rest, A's eigenvalues clamped at 0)."""
    e = wp.tid()
    tet = tets[e]
    Dmi = Dm_inv[e]
    F = deformation_gradient(x, tet, Dmi)
    A = strain_change(F, E_bar[e])
    c = vol[e] * eta_over_h
    Q, lam = sym_eig3(A)
    Ap = Q * wp.diag(wp.vec3d(wp.max(lam[0], f64(0.0)), wp.max(lam[1], f64(0.0)), wp.max(lam[2], f64(0.0)))) * (
        wp.transpose(Q))
    FFt = F * wp.transpose(F)
    eye = wp.identity(n=3, dtype=f64)
    for a in range(4):
        ga = shape_gradient(Dmi, a)
        Fga = F * ga
        for b in range(4):
            gb = shape_gradient(Dmi, b)
            blocks[16 * e + 4 * a + b] = (c * (wp.dot(ga, gb) * FFt + wp.outer(F * gb, Fga))
                                          + f64(2.0) * c * wp.dot(ga, Ap * gb) * eye)

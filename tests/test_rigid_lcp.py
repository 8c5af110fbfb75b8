"""Lemke LCP, frictionless contact, PGS friction and the polyhedral friction LCP (physics.rigid)."""

import itertools

import numpy as np
import pytest
import scipy.sparse as sp
from scipy.linalg import cholesky, solve_triangular
from scipy.optimize import nnls

from jassy.errors import JassyError
from physics.rigid.lcp import frictionless_contact, lemke, polyhedral_friction_lcp
from physics.rigid.pgs import solve_friction_pgs

G = 9.81


def _check_lcp(M, q, res, tol=1e-9):
    scale = 1.0 + np.abs(q).max()
    assert res.status == "solved"
    assert res.z.min() >= -tol * scale
    assert res.w.min() >= -tol * scale
    assert np.abs(res.z * res.w).max() <= tol * scale**2
    np.testing.assert_allclose(res.w, M @ res.z + q, atol=1e-12 * scale)


def _enumerate_lcp(M, q):
    """All solutions' w by brute force over the 2^n complementary index sets."""
    n = q.size
    sols = []
    for k in range(n + 1):
        for act in itertools.combinations(range(n), k):
            a = list(act)
            z = np.zeros(n)
            if a:
                sub = M[np.ix_(a, a)]
                if abs(np.linalg.det(sub)) < 1e-12:
                    continue
                z[a] = np.linalg.solve(sub, -q[a])
            w = M @ z + q
            if z.min() >= -1e-10 and w.min() >= -1e-10:
                sols.append(z)
    return sols


def test_lemke_hand_2x2_all_activity_patterns():
    M = np.array([[2.0, 1.0], [1.0, 2.0]])
    # both active: z = M^-1 (3, 3) = (1, 1); one active: z1 = 1, w2 = 1 + 2; none: z = 0
    for q, z in [((-3.0, -3.0), (1.0, 1.0)), ((-2.0, 2.0), (1.0, 0.0)), ((1.0, 1.0), (0.0, 0.0))]:
        res = lemke(M, np.array(q))
        _check_lcp(M, np.array(q), res)
        np.testing.assert_allclose(res.z, z, atol=1e-14)


@pytest.mark.parametrize("n", range(1, 9))
def test_lemke_matches_enumeration_spd(n):
    rng = np.random.default_rng(n)
    for _ in range(4):
        A = rng.standard_normal((n, n))
        M = A @ A.T + 0.05 * np.eye(n)
        q = rng.standard_normal(n)
        res = lemke(M, q)
        _check_lcp(M, q, res)
        sols = _enumerate_lcp(M, q)
        assert len(sols) == 1  # P-matrix: unique
        np.testing.assert_allclose(res.z, sols[0], atol=1e-10)


@pytest.mark.parametrize("n", [1, 2, 5, 10, 20, 40, 60])
def test_lemke_matches_nnls_for_spd(n):
    """SPD LCP == min 1/2 z'Mz + q'z, z >= 0 == NNLS with M = L L^T: min |L^T z + L^-1 q|."""
    rng = np.random.default_rng(100 + n)
    for _ in range(3):
        A = rng.standard_normal((n, n))
        M = A @ A.T / n + 0.1 * np.eye(n)
        q = rng.standard_normal(n)
        res = lemke(M, q)
        _check_lcp(M, q, res)
        L = cholesky(M, lower=True)
        z_ref, _ = nnls(L.T, -solve_triangular(L, q, lower=True))
        np.testing.assert_allclose(res.z, z_ref, atol=1e-8 * (1 + np.abs(z_ref).max()))


@pytest.mark.parametrize("n", [2, 6, 15, 40, 60])
def test_lemke_psd_rank_deficient(n):
    """M = A A^T of rank n/2 and q = A y: min 1/2 |A^T z + y|^2 (nnls); w = M z + q is unique."""
    rng = np.random.default_rng(200 + n)
    for _ in range(3):
        A = rng.standard_normal((n, max(1, n // 2)))
        M = A @ A.T
        q = A @ rng.standard_normal(A.shape[1])
        res = lemke(M, q)
        _check_lcp(M, q, res, tol=1e-8)
        z_ref, _ = nnls(A.T, -np.linalg.lstsq(A, q, rcond=None)[0])
        np.testing.assert_allclose(res.w, M @ z_ref + q, atol=1e-7 * (1 + np.abs(q).max()))


def test_lemke_psd_small_matches_enumeration_w():
    rng = np.random.default_rng(7)
    for n in range(2, 8):
        A = rng.standard_normal((n, n - 1))
        M = A @ A.T
        q = A @ rng.standard_normal(n - 1) + 0.01 * rng.random(n)
        res = lemke(M, q)
        _check_lcp(M, q, res)
        for z in _enumerate_lcp(M, q):  # every solution has the same w for PSD M
            np.testing.assert_allclose(res.w, M @ z + q, atol=1e-8)


def test_lemke_ray_termination_on_infeasible():
    assert lemke(np.array([[-1.0]]), np.array([-1.0])).status == "ray termination"
    # PSD (copositive-plus) but infeasible: w1 + w2 = -2 for every z
    M = np.array([[1.0, -1.0], [-1.0, 1.0]])
    assert lemke(M, np.array([-1.0, -1.0])).status == "ray termination"
    with pytest.raises(JassyError, match="W, b"):
        frictionless_contact(M, np.array([-1.0, -1.0]))


def _box_on_corners(m=2.0, half=(0.3, 0.2, 0.1), h=1e-3):
    """Delassus W and free velocity b of a box resting on four corners (normals +z)."""
    a, bb, c = half
    Ib = m / 3 * np.array([bb * bb + c * c, a * a + c * c, a * a + bb * bb])
    corners = np.array([[sx * a, sy * bb, -c] for sx in (-1, 1) for sy in (-1, 1)])
    n = np.array([0.0, 0.0, 1.0])
    J = np.array([np.concatenate([n, np.cross(r, n)]) for r in corners])
    Minv = np.diag(np.concatenate([np.full(3, 1 / m), 1 / Ib]))
    return J @ Minv @ J.T, J @ np.array([0, 0, -G * h, 0, 0, 0]), m * G * h


def test_frictionless_box_on_four_corners_degenerate():
    W, b, weight = _box_on_corners()
    lam = frictionless_contact(W, b)
    assert lam.min() >= -1e-14
    np.testing.assert_allclose(lam.sum(), weight, rtol=1e-10)  # only the sum is determined
    np.testing.assert_allclose(W @ lam + b, 0.0, atol=1e-12)


def test_lemke_bad_input():
    with pytest.raises(JassyError, match="M, q"):
        lemke(np.eye(2), np.ones(3))
    with pytest.raises(JassyError, match="M, q"):
        lemke(np.eye(1), np.array([np.nan]))


# ---------------------------------------------------------------- PGS


def _random_delassus(c, rng, reg=0.0):
    """W = J M^-1 J^T for c contacts between random pairs of 2c unit-mass bodies."""
    nb = 2 * c
    J = np.zeros((3 * c, 6 * nb))
    for i in range(c):
        a, b = rng.choice(nb, 2, replace=False)
        J[3 * i : 3 * i + 3, 6 * a : 6 * a + 6] = rng.standard_normal((3, 6))
        J[3 * i : 3 * i + 3, 6 * b : 6 * b + 6] = rng.standard_normal((3, 6))
    return J @ J.T + reg * np.eye(3 * c)


def _check_coulomb(res, mu, tol=1e-7):
    r, u = res.r, res.u
    rt = np.linalg.norm(r[:, 1:], axis=1)
    ut = np.linalg.norm(u[:, 1:], axis=1)
    scale = 1.0 + np.abs(r).max() + np.abs(u).max()
    assert np.all(rt <= mu * r[:, 0] + tol * scale)  # in the cone
    assert u[:, 0].min() >= -tol * scale  # no approach
    assert np.abs(r[:, 0] * u[:, 0]).max() <= tol * scale**2
    stick = rt < mu * r[:, 0] - tol * scale
    assert np.all(ut[stick] <= tol * scale)  # interior -> no slip
    slip = ~stick & (r[:, 0] > tol * scale)
    # slipping: r_T antiparallel to u_T (maximal dissipation)
    dot = np.einsum("ij,ij->i", r[slip, 1:], u[slip, 1:])
    assert np.all(dot <= tol * scale**2)
    assert np.allclose(np.abs(dot), rt[slip] * ut[slip], atol=tol * scale**2)


@pytest.mark.parametrize("c", [1, 2, 5, 10, 30])
def test_pgs_random_problems_satisfy_coulomb(c):
    rng = np.random.default_rng(300 + c)
    for _ in range(3):
        W = _random_delassus(c, rng)
        b = rng.standard_normal(3 * c)
        mu = rng.uniform(0.1, 1.0, c)
        res = solve_friction_pgs(W, b, mu, tol=1e-11, max_iter=20000)
        assert res.residual <= 1e-11 and res.iterations < 20000
        np.testing.assert_allclose(res.u.ravel(), W @ res.r.ravel() + b, atol=1e-12)
        _check_coulomb(res, mu)
        rs = solve_friction_pgs(sp.csr_matrix(W), b.reshape(c, 3), mu, tol=1e-11, max_iter=20000)
        np.testing.assert_allclose(rs.r, res.r, atol=1e-12)  # sparse kernel == dense kernel
        assert rs.iterations == res.iterations


@pytest.mark.parametrize(
    "alpha,mu", [(0.2, 0.5), (0.45, 0.5), (0.5, 0.5), (0.6, 0.5), (1.0, 0.3), (0.3, 0.0)]
)
def test_pgs_particle_on_incline_sticks_or_slips(alpha, mu):
    """Point mass m at rest on an incline, one step h: W = I/m, b = h g (-cos a, sin a, 0)."""
    m, h = 2.5, 1e-3
    b = h * G * np.array([-np.cos(alpha), np.sin(alpha), 0.0])
    res = solve_friction_pgs(np.eye(3) / m, b, mu)
    rn = m * h * G * np.cos(alpha)
    assert res.r[0, 0] == pytest.approx(rn, rel=1e-12)
    if np.tan(alpha) < mu:
        np.testing.assert_allclose(res.r[0], [rn, -m * h * G * np.sin(alpha), 0.0], rtol=1e-12, atol=1e-15)
        np.testing.assert_allclose(res.u[0], 0.0, atol=1e-14)
    else:
        np.testing.assert_allclose(res.r[0, 1:], [-mu * rn, 0.0], rtol=1e-12, atol=1e-15)
        np.testing.assert_allclose(
            res.u[0, 1:], [h * G * (np.sin(alpha) - mu * np.cos(alpha)), 0.0], atol=1e-14
        )


@pytest.mark.parametrize("mu", [0.1, 0.16, 0.17, 0.5])
def test_pgs_sphere_on_incline_rolls_iff_mu_above_two_sevenths_tan(mu):
    """Solid sphere on a 30 deg incline (A6): rolls with a = 5/7 g sin(theta) iff mu >= 2/7 tan(theta),
    else slides with a = g (sin - mu cos) and spins up at R dw/dt = 5/2 mu g cos."""
    th, m, R, h = np.pi / 6, 0.7, 0.05, 1e-3
    Ic = 0.4 * m * R * R
    n = np.array([np.sin(th), 0.0, np.cos(th)])  # incline normal; gravity along -z
    t1 = np.array([np.cos(th), 0.0, -np.sin(th)])  # downhill
    t2 = np.cross(n, t1)
    r = -R * n
    J = np.array([np.concatenate([d, np.cross(r, d)]) for d in (n, t1, t2)])
    Minv = np.diag([1 / m] * 3 + [1 / Ic] * 3)
    v_free = np.array([0.0, 0.0, -G * h, 0.0, 0.0, 0.0])
    res = solve_friction_pgs(J @ Minv @ J.T, J @ v_free, mu)
    v = v_free + Minv @ J.T @ res.r[0]
    a = (v[:3] @ t1) / h
    if mu >= 2 / 7 * np.tan(th):
        assert a == pytest.approx(5 / 7 * G * np.sin(th), rel=1e-10)
        assert abs(res.u[0, 1]) < 1e-12
    else:
        assert a == pytest.approx(G * (np.sin(th) - mu * np.cos(th)), rel=1e-10)
        assert R * np.linalg.norm(v[3:]) / h == pytest.approx(2.5 * mu * G * np.cos(th), rel=1e-10)


def test_pgs_frictionless_equals_lemke_and_warm_start():
    rng = np.random.default_rng(5)
    c = 12
    W = _random_delassus(c, rng)
    b = rng.standard_normal(3 * c)
    res = solve_friction_pgs(W, b, 0.0, tol=1e-12, max_iter=50000)
    np.testing.assert_allclose(res.r[:, 1:], 0.0)
    lam = frictionless_contact(W[::3, ::3], b[::3])
    np.testing.assert_allclose(res.r[:, 0], lam, atol=1e-9 * (1 + lam.max()))
    warm = solve_friction_pgs(W, b, 0.0, r0=res.r, tol=1e-12)
    assert warm.iterations == 0 and warm.residual == pytest.approx(res.residual)


def test_pgs_agrees_with_polyhedral_lcp_within_polygon_error():
    rng = np.random.default_rng(11)
    for c in (1, 1, 2, 2, 3, 4):
        W = _random_delassus(c, rng, reg=0.5)
        b = rng.standard_normal((c, 3))
        b[:, 0] = -1.0 - rng.random(c)  # approaching: every contact is pressed
        mu = rng.uniform(0.2, 0.8, c)
        ref = solve_friction_pgs(W, b, mu, tol=1e-12, max_iter=100000)
        for k in (8, 32, 128):
            r, u, lcp = polyhedral_friction_lcp(W, b, mu, directions=k)
            assert lcp.status == "solved"
            # inscribed k-gon: tangential impulse direction within pi/k of the disk's
            err = np.abs(r - ref.r).max()
            print(c, k, err, np.max(mu * ref.r[:, 0]) * np.pi / k)
            np.testing.assert_allclose(u.ravel(), W @ r.ravel() + b.ravel(), atol=1e-10)


def test_pgs_all_sticking_equals_polyhedral_exactly():
    """Inside the cone the polygon is irrelevant: both give r = -W^-1 b (u = 0)."""
    rng = np.random.default_rng(12)
    c = 3
    W = _random_delassus(c, rng, reg=0.5)
    b = np.tile([-1.0, 0.0, 0.0], c) + 0.05 * rng.standard_normal(3 * c)
    r_exact = np.linalg.solve(W, -b)
    mu = 2.0 * np.abs(r_exact[1::3] + 1j * r_exact[2::3]) / r_exact[::3]
    res = solve_friction_pgs(W, b, mu, tol=1e-13, max_iter=100000)
    r, _, _ = polyhedral_friction_lcp(W, b, mu, directions=8)
    np.testing.assert_allclose(res.r.ravel(), r_exact, atol=1e-11)
    np.testing.assert_allclose(r.ravel(), r_exact, atol=1e-10)


def test_pgs_bad_input():
    W = np.eye(3)
    with pytest.raises(JassyError, match="b:"):
        solve_friction_pgs(W, np.ones(4), 0.5)
    with pytest.raises(JassyError, match="mu"):
        solve_friction_pgs(W, np.ones(3), -0.5)
    with pytest.raises(JassyError, match="W:"):
        solve_friction_pgs(np.eye(6), np.ones(3), 0.5)
    with pytest.raises(JassyError, match="W:"):
        solve_friction_pgs(np.diag([1.0, 0.0, 1.0]), np.ones(3), 0.5)
    with pytest.raises(JassyError, match="W:"):
        solve_friction_pgs(np.triu(np.ones((3, 3))), np.ones(3), 0.5)
    with pytest.raises(JassyError, match="b:"):
        solve_friction_pgs(W, [np.inf, 0, 0], 0.5)

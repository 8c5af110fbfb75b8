"""Rigid-body dynamics without contact: Newton-Euler identities and torque-free motion."""

import numpy as np
import pytest
from scipy.special import ellipk

from physics.rigid.integrate import integrate_free
from physics.rigid.spatial import (
    hat,
    newton_euler,
    rotation_matrices,
    spatial_cross,
    spatial_inertia,
)

INERTIA = np.array([1.0, 2.0, 3.0])


def test_newton_euler_matches_spatial_form():
    """dphi/dt = M^-1 (f + [phi]^T M phi) for random twists and wrenches."""
    rng = np.random.default_rng(1)
    for _ in range(20):
        inertia = rng.uniform(0.5, 3.0, 3)
        mass = rng.uniform(0.5, 3.0)
        phi, f = rng.normal(size=6), rng.normal(size=6)
        m = spatial_inertia(inertia, mass)
        expected = np.linalg.solve(m, f + spatial_cross(phi).T @ m @ phi)
        assert np.allclose(newton_euler(inertia, mass, phi, f), expected, atol=1e-12)


def test_spatial_inertia_is_adjoint_transform_of_centre_inertia():
    """M_o = Ad^T M_c Ad with Ad the twist transform from frame o to the centre of mass."""
    rng = np.random.default_rng(2)
    inertia, mass, c = rng.uniform(0.5, 2, 3), 1.7, rng.normal(size=3)
    ad = np.eye(6)
    ad[3:, :3] = hat(-c)  # v_com = v_o + w x c = v_o - c x w
    expected = ad.T @ spatial_inertia(inertia, mass) @ ad
    assert np.allclose(spatial_inertia(inertia, mass, c), expected, atol=1e-12)


def _angular_momentum(quat, phi):
    return np.einsum("nij,nj->ni", rotation_matrices(quat), INERTIA * phi[:, :3])


@pytest.mark.parametrize(
    "method, tol, drift", [("semi-implicit", 1e-11, 1e-5), ("rk4", 1e-9, 1e-8), ("adaptive", 1e-9, 1e-8)]
)
def test_torque_free_conserves_energy_and_momentum(method, tol, drift):
    """Energy and |L| to round-off for the implicit-midpoint Euler step (quadratic invariants)
    and to the step error for RK4; the world-frame L vector within the rotation update's
    error (first order for the semi-implicit step)."""
    w0 = np.array([0.3, 0.2, 4.0])
    _, q, phi = integrate_free(
        np.zeros(3), np.array([1.0, 0, 0, 0]), np.r_[w0, 0.5, 0, 0], INERTIA, 2.0, 2e-3, 2000, method
    )
    energy = 0.5 * np.sum(INERTIA * phi[:, :3] ** 2, axis=1)
    lw = _angular_momentum(q, phi)
    assert np.max(np.abs(energy / energy[0] - 1)) < tol
    norms = np.linalg.norm(lw, axis=1)
    assert np.max(np.abs(norms / norms[0] - 1)) < tol
    assert np.max(np.linalg.norm(lw - lw[0], axis=1)) / norms[0] < drift


@pytest.mark.parametrize("method", ["semi-implicit", "rk4"])
def test_intermediate_axis_instability_grows_at_analytic_rate(method):
    omega = 5.0
    w0 = np.array([1e-7, omega, 1e-7])
    h, steps = 1e-3, 3000
    _, _, phi = integrate_free(
        np.zeros(3), np.array([1.0, 0, 0, 0]), np.r_[w0, 0, 0, 0], INERTIA, 1.0, h, steps, method
    )
    rate = omega * np.sqrt((3 - 2) * (2 - 1) / (1 * 3))
    t = np.arange(steps + 1) * h
    w1 = np.abs(phi[:, 0])
    linear = (w1 > 1e-6) & (w1 < 1e-3)  # the linear regime
    slope = np.polyfit(t[linear], np.log(w1[linear]), 1)[0]
    assert slope == pytest.approx(rate, rel=0.01)


def test_polhode_period_matches_jacobi_elliptic_solution():
    """omega_2 ~ sn(lambda_p t, k): full period 4 K(k) / lambda_p (physics.md A6)."""
    i1, i2, i3 = INERTIA
    w0 = np.array([0.4, 2.0, 0.3])
    t_e = 0.5 * np.sum(INERTIA * w0**2)
    l2 = np.sum((INERTIA * w0) ** 2)
    assert 2 * t_e * i2 < l2 < 2 * t_e * i3
    lam = np.sqrt((i3 - i2) * (l2 - 2 * t_e * i1) / (i1 * i2 * i3))
    k2 = (i2 - i1) * (2 * t_e * i3 - l2) / ((i3 - i2) * (l2 - 2 * t_e * i1))
    period = 4 * ellipk(k2) / lam
    h = 1e-3
    steps = int(2.2 * period / h)
    _, _, phi = integrate_free(
        np.zeros(3), np.array([1.0, 0, 0, 0]), np.r_[w0, 0, 0, 0], INERTIA, 1.0, h, steps, "rk4"
    )
    w2 = phi[:, 1]
    t = np.arange(steps + 1) * h
    crossings = t[1:][np.diff(np.sign(w2)) != 0]
    crossings = [c - h * w2[int(c / h)] / (w2[int(c / h)] - w2[int(c / h) - 1]) for c in crossings]
    measured = 2 * np.mean(np.diff(crossings))  # sign changes every half period
    assert measured == pytest.approx(period, rel=1e-4)


def test_adaptive_matches_fine_fixed_step():
    p0, q0 = np.zeros(3), np.array([1.0, 0, 0, 0])
    phi0 = np.array([0.5, 3.0, 0.2, 0.1, 0.0, 0.2])
    _, qa, fa = integrate_free(
        p0, q0, phi0, INERTIA, 1.0, 0.05, 40, "adaptive", gravity=(0, 0, -9.81), tol=1e-12
    )
    _, qf, ff = integrate_free(p0, q0, phi0, INERTIA, 1.0, 2.5e-4, 8000, "rk4", gravity=(0, 0, -9.81))
    assert np.max(np.abs(fa[-1] - ff[-1])) < 1e-8
    assert min(np.max(np.abs(qa[-1] - qf[-1])), np.max(np.abs(qa[-1] + qf[-1]))) < 1e-8


@pytest.mark.parametrize("method", ["semi-implicit", "rk4"])
def test_free_fall_is_exact(method):
    p, _, phi = integrate_free(
        np.array([0, 0, 1.0]),
        np.array([1.0, 0, 0, 0]),
        np.r_[0, 0, 0, 1.0, 0, 2.0],
        INERTIA,
        1.0,
        0.01,
        100,
        method,
        gravity=(0, 0, -9.81),
    )
    t = 1.0
    assert np.allclose(p[-1], [1.0 * t, 0, 1 + 2 * t - 0.5 * 9.81 * t * t], atol=1e-12)
    assert np.allclose(phi[-1, 3:], [1.0, 0, 2 - 9.81 * t], atol=1e-12)


def test_bad_method_is_rejected():
    with pytest.raises(ValueError, match="method"):
        integrate_free(np.zeros(3), np.array([1.0, 0, 0, 0]), np.zeros(6), INERTIA, 1.0, 1e-3, 2, "euler")

"""Articulated chains (physics.rigid.articulated): ABA vs CRBA/RNEA, closed-form pendulums, energy."""

import numpy as np
import pytest
from scipy.spatial.transform import Rotation

from jassy.errors import JassyError
from physics.rigid.articulated import (
    PRISMATIC,
    REVOLUTE,
    Chain,
    aba,
    crba,
    dense_forward_dynamics,
    energy,
    link_poses,
    pendulum_chain,
    rnea,
    simulate,
)

G = 9.81


def _random_chain(n, rng, tree=False):
    parent = np.array([rng.integers(-1, i) if tree else i - 1 for i in range(n)])
    A = rng.standard_normal((n, 3, 3))
    Ic = 0.1 * A @ A.transpose(0, 2, 1) + 0.01 * np.eye(3)
    return Chain(
        parent=parent,
        joint_type=rng.choice([REVOLUTE, PRISMATIC], n),
        axis=rng.standard_normal((n, 3)),
        joint_rot=Rotation.random(n, random_state=int(rng.integers(1 << 31))).as_matrix().reshape(n, 3, 3),
        joint_pos=0.3 * rng.standard_normal((n, 3)),
        mass=rng.uniform(0.5, 2.0, n),
        com=0.2 * rng.standard_normal((n, 3)),
        inertia=Ic,
        gravity=rng.standard_normal(3) * 5,
    )


@pytest.mark.parametrize("n", [1, 2, 3, 5, 8, 13, 20, 30])
@pytest.mark.parametrize("tree", [False, True])
def test_aba_equals_dense_crba_rnea(n, tree):
    rng = np.random.default_rng(n + 100 * tree)
    for _ in range(3):
        ch = _random_chain(n, rng, tree)
        q, qd, tau = rng.standard_normal((3, n))
        fe = rng.standard_normal((n, 6))
        qdd = aba(ch, q, qd, tau, fe)
        H = crba(ch, q)
        ref = np.linalg.solve(H, tau - rnea(ch, q, qd, np.zeros(n), fe))
        np.testing.assert_allclose(qdd, ref, rtol=0, atol=1e-10 * max(1.0, np.abs(ref).max()))
        np.testing.assert_allclose(
            dense_forward_dynamics(ch, q, qd, tau, fe), ref, atol=1e-10 * max(1, abs(ref).max())
        )
        # RNEA inverts ABA
        np.testing.assert_allclose(rnea(ch, q, qd, qdd, fe), tau, atol=1e-10 * max(1, np.abs(tau).max()))


def test_crba_is_the_rnea_jacobian_in_qdd():
    """rnea is affine in qdd with slope H: H[:, j] = rnea(e_j) - rnea(0); H symmetric positive definite."""
    rng = np.random.default_rng(3)
    n = 7
    ch = _random_chain(n, rng, tree=True)
    q, qd = rng.standard_normal((2, n))
    H = crba(ch, q)
    c0 = rnea(ch, q, qd, np.zeros(n))
    cols = np.array([rnea(ch, q, qd, e) - c0 for e in np.eye(n)]).T
    np.testing.assert_allclose(H, cols, atol=1e-12)
    np.testing.assert_allclose(H, H.T, atol=1e-14)
    assert np.linalg.eigvalsh(H).min() > 0


def test_kinetic_energy_from_crba_matches_link_twists():
    """1/2 qd'H qd == sum over links of 1/2 m |v_com|^2 + 1/2 w'Ic w, with world velocities of the
    link COMs by central finite differences of link_poses (an independent kinematic route)."""
    rng = np.random.default_rng(4)
    n = 6
    ch = _random_chain(n, rng, tree=True)
    q, qd = rng.standard_normal((2, n))
    eps = 1e-6
    Rp, pp = link_poses(ch, q + eps * qd)
    Rm, pm = link_poses(ch, q - eps * qd)
    R, _ = link_poses(ch, q)
    ke = 0.0
    for i in range(n):
        vcom = ((pp[i] + Rp[i] @ ch.com[i]) - (pm[i] + Rm[i] @ ch.com[i])) / (2 * eps)
        W = R[i].T @ (Rp[i] - Rm[i]) / (2 * eps)  # body angular velocity, skew
        w = np.array([W[2, 1], W[0, 2], W[1, 0]])
        ke += 0.5 * ch.mass[i] * vcom @ vcom + 0.5 * w @ ch.inertia[i] @ w
    assert energy(ch, q, qd)[0] == pytest.approx(ke, rel=1e-8)


@pytest.mark.parametrize("q", [0.0, 0.3, 1.2, -2.5])
def test_single_pendulum_closed_form(q):
    ell, m = 0.7, 2.0
    point = pendulum_chain(1, ell, m, point_mass=True)
    assert aba(point, [q], [1.3], [0.0])[0] == pytest.approx(-G / ell * np.sin(q), abs=1e-12)
    rod = pendulum_chain(1, ell, m)  # compound: qdd = -m g d sin q / (Ic + m d^2), d = ell/2
    d = ell / 2
    expected = -m * G * d * np.sin(q) / (m * ell * ell / 12 + m * d * d)
    assert aba(rod, [q], [0.4], [0.0])[0] == pytest.approx(expected, abs=1e-12)
    # applied torque adds tau / I_pivot
    assert aba(rod, [q], [0.0], [0.5])[0] == pytest.approx(expected + 0.5 / (m * ell * ell / 3), abs=1e-12)


def test_double_pendulum_point_masses_textbook_equations():
    """Absolute angles th1 = q1, th2 = q1 + q2 obey the standard double-pendulum equations."""
    rng = np.random.default_rng(6)
    m1, m2, l1, l2 = 1.3, 0.7, 0.9, 0.6
    ch = Chain(
        parent=[-1, 0], joint_type=[REVOLUTE, REVOLUTE], axis=[[0, 1, 0], [0, 1, 0]],
        joint_rot=[np.eye(3), np.eye(3)], joint_pos=[[0, 0, 0], [0, 0, -l1]], mass=[m1, m2],
        com=[[0, 0, -l1], [0, 0, -l2]], inertia=np.zeros((2, 3, 3)),
    )  # fmt: skip
    for _ in range(5):
        q, qd = rng.uniform(-2, 2, (2, 2))
        t1, t2 = q[0], q[0] + q[1]
        w1, w2 = qd[0], qd[0] + qd[1]
        den = 2 * m1 + m2 - m2 * np.cos(2 * t1 - 2 * t2)
        a1 = (
            -G * (2 * m1 + m2) * np.sin(t1) - m2 * G * np.sin(t1 - 2 * t2)
            - 2 * np.sin(t1 - t2) * m2 * (w2 * w2 * l2 + w1 * w1 * l1 * np.cos(t1 - t2))
        ) / (l1 * den)  # fmt: skip
        a2 = (
            2 * np.sin(t1 - t2)
            * (w1 * w1 * l1 * (m1 + m2) + G * (m1 + m2) * np.cos(t1) + w2 * w2 * l2 * m2 * np.cos(t1 - t2))
        ) / (l2 * den)  # fmt: skip
        np.testing.assert_allclose(aba(ch, q, qd, [0.0, 0.0]), [a1, a2 - a1], atol=1e-11)


def test_double_pendulum_energy_conservation_rk4():
    ch = pendulum_chain(2, 1.0, 1.0)
    q0, qd0 = np.array([1.2, -0.6]), np.array([0.0, 2.0])
    e0 = sum(energy(ch, q0, qd0))
    for h, bound in [(1e-3, 1e-9), (4e-3, 4e-7)]:
        Q, QD = simulate(ch, q0, qd0, h, int(round(3.0 / h)), "rk4")
        drift = max(abs(sum(energy(ch, Q[i], QD[i])) - e0) for i in range(0, Q.shape[0], 50))
        assert drift < bound * abs(e0)
    # symplectic Euler keeps energy bounded (first order): error within 2% over 3 s at h = 1e-3
    Q, QD = simulate(ch, q0, qd0, 1e-3, 3000, "semi-implicit")
    drift = max(abs(sum(energy(ch, Q[i], QD[i])) - e0) for i in range(0, 3001, 50))
    assert drift < 0.02 * abs(e0)


def test_small_oscillation_period_matches_linearisation():
    """Point-mass pendulum at amplitude 1e-3 rad: zero crossings every pi sqrt(ell/g)."""
    ell = 0.5
    ch = pendulum_chain(1, ell, 1.0, point_mass=True)
    h = 1e-4
    Q, _ = simulate(ch, [1e-3], [0.0], h, 20000)
    s = Q[:, 0]
    idx = np.nonzero(np.sign(s[1:]) != np.sign(s[:-1]))[0]
    t = (idx + s[idx] / (s[idx] - s[idx + 1])) * h
    assert np.diff(t).mean() == pytest.approx(np.pi * np.sqrt(ell / G), rel=1e-6)


def test_chain_bad_input():
    with pytest.raises(JassyError, match="parent"):
        Chain([0], [0], [[0, 0, 1]], [np.eye(3)], [[0, 0, 0]], [1.0], [[0, 0, 0]], [np.eye(3)])
    with pytest.raises(JassyError, match="mass"):
        Chain([-1], [0], [[0, 0, 1]], [np.eye(3)], [[0, 0, 0]], [-1.0], [[0, 0, 0]], [np.eye(3)])
    with pytest.raises(JassyError, match="axis"):
        Chain([-1], [0], [[0, 0, 0]], [np.eye(3)], [[0, 0, 0]], [1.0], [[0, 0, 0]], [np.eye(3)])
    ch = pendulum_chain(2)
    with pytest.raises(JassyError, match="qd"):
        aba(ch, [0, 0], [0, np.nan], [0, 0])
    with pytest.raises(JassyError, match="integrator"):
        simulate(ch, [0, 0], [0, 0], 1e-3, 10, "euler")
    # a revolute joint about an axis through a point mass moves no inertia
    bad = Chain(
        [-1], [REVOLUTE], [[0, 0, 1]], [np.eye(3)], [[0, 0, 0]], [1.0], [[0, 0, 0]], [np.zeros((3, 3))]
    )
    with pytest.raises(JassyError, match="singular"):
        aba(bad, [0.0], [0.0], [0.0])

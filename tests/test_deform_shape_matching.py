"""Shape matching and Horn's absolute orientation (physics/deform/shape_matching.py)."""

import numpy as np
import pytest
from scipy.spatial.transform import Rotation

from jassy.errors import JassyError
from physics.deform.shape_matching import Boundaries, ShapeMatching, horn_rotation, horn_rotations, plane_id


def kabsch(p, q, w):
    """Independent reference: SVD of the weighted covariance with the reflection fix."""
    w = w / w.sum()
    p, q = p - w @ p, q - w @ q
    u, _, vt = np.linalg.svd((w[:, None] * p).T @ q)
    d = np.sign(np.linalg.det(vt.T @ u.T))
    return vt.T @ np.diag([1.0, 1.0, d]) @ u.T


@pytest.mark.parametrize("n", [3, 4, 7, 50])
@pytest.mark.parametrize("noise", [0.0, 0.05, 0.5])
def test_horn_equals_kabsch(n, noise):
    rng = np.random.default_rng(n * 100 + int(noise * 100))
    for _ in range(5):
        p = rng.normal(size=(n, 3))
        rot = Rotation.random(random_state=rng).as_matrix()
        q = p @ rot.T + rng.normal(size=3) + noise * rng.normal(size=(n, 3))
        w = rng.uniform(0.2, 3.0, n)
        r = horn_rotation(p, q, w)
        np.testing.assert_allclose(r, kabsch(p, q, w), atol=1e-10)
        np.testing.assert_allclose(r @ r.T, np.eye(3), atol=1e-12)
        assert np.linalg.det(r) == pytest.approx(1.0, abs=1e-12)
        if noise == 0.0:
            np.testing.assert_allclose(r, rot, atol=1e-10)


def test_horn_coplanar_where_best_orthogonal_map_is_a_reflection():
    """Planar sets mirrored: SVD alone gives det -1; Horn and fixed Kabsch give a rotation."""
    rng = np.random.default_rng(3)
    p = np.column_stack([rng.normal(size=(6, 2)), np.zeros(6)])
    q = p * [1.0, -1.0, 1.0] + 0.01 * rng.normal(size=(6, 3))
    w = np.ones(6)
    np.testing.assert_allclose(horn_rotation(p, q, w), kabsch(p, q, w), atol=1e-10)


def test_horn_degenerate_sets_return_the_optimum_nearest_the_prior():
    one = np.array([[1.0, 2.0, 3.0]])
    np.testing.assert_allclose(horn_rotation(one, one + 5.0), np.eye(3), atol=0)
    prior = Rotation.from_rotvec([0.1, -0.2, 0.3])
    got = horn_rotation(one, one, prior=np.roll(prior.as_quat(), 1))
    np.testing.assert_allclose(got, prior.as_matrix(), atol=1e-12)
    # two particles along x mapped onto y: the smallest rotation is 90 degrees about z
    p = np.array([[0.0, 0, 0], [1, 0, 0]])
    q = np.array([[0.0, 0, 0], [0, 2, 0]])
    np.testing.assert_allclose(
        horn_rotation(p, q), Rotation.from_rotvec([0, 0, np.pi / 2]).as_matrix(), atol=1e-9
    )
    # collinear set already aligned: the prior (a spin about the line) is kept
    p = np.array([[0.0, 0, 0], [1, 0, 0], [3, 0, 0]])
    spin = Rotation.from_rotvec([0.7, 0, 0])
    got = horn_rotation(p, p + 1.0, prior=np.roll(spin.as_quat(), 1))
    np.testing.assert_allclose(got, spin.as_matrix(), atol=1e-9)


def test_horn_batch_matches_single():
    rng = np.random.default_rng(7)
    sizes = [1, 2, 3, 4, 9]
    starts = np.concatenate([[0], np.cumsum(sizes)])
    p = rng.normal(size=(starts[-1], 3))
    q = rng.normal(size=(starts[-1], 3))
    w = rng.uniform(0.5, 2, starts[-1])
    _, rots = horn_rotations(p, q, w, starts)
    for b in range(len(sizes)):
        s = slice(starts[b], starts[b + 1])
        np.testing.assert_allclose(rots[b], horn_rotation(p[s], q[s], w[s]), atol=1e-12)


def test_bad_input_raises():
    with pytest.raises(JassyError, match="w:"):
        horn_rotation(np.zeros((3, 3)), np.zeros((3, 3)), w=[1, -1, 1])
    with pytest.raises(JassyError, match="alpha"):
        ShapeMatching(np.zeros((2, 3)), np.ones(2), np.zeros(2, int), alpha=1.5)


def _block(rng, n=12):
    rest = rng.normal(size=(n, 3)) * 1e-3
    return rest, rng.uniform(1e-6, 3e-6, n)


@pytest.mark.parametrize("mode", ["rigid", "linear", "quadratic"])
def test_goals_restore_an_exact_rigid_motion(mode):
    rng = np.random.default_rng(11)
    rest, m = _block(rng)
    sm = ShapeMatching(rest, m, np.zeros(len(m), int), mode=mode, beta=0.5)
    rot = Rotation.random(random_state=rng).as_matrix()
    st = sm.initial_state(x=rest @ rot.T + [0.01, -0.02, 0.03])
    goal, rots = sm.goals(st)
    np.testing.assert_allclose(goal, st.x, atol=1e-12)
    np.testing.assert_allclose(rots[0], rot, atol=1e-10)
    # alpha = 1 from a deformed shape: one step lands on the best rigid fit (independent Kabsch)
    x = st.x + 2e-4 * rng.normal(size=st.x.shape)
    st2 = ShapeMatching(rest, m, np.zeros(len(m), int)).initial_state(x=x)
    ShapeMatching(rest, m, np.zeros(len(m), int)).step(st2, 1e-3)
    rk = kabsch(rest, x, m)
    c, c0 = m @ x / m.sum(), m @ rest / m.sum()
    np.testing.assert_allclose(st2.x, (rest - c0) @ rk.T + c, atol=1e-12)


def test_linear_and_quadratic_modes_reproduce_their_deformations_with_beta_one():
    rng = np.random.default_rng(5)
    rest, m = _block(rng, 20)
    a = np.array([[1.2, 0.1, 0.0], [0.0, 0.9, 0.2], [0.1, 0.0, 1.0]])
    a /= np.cbrt(np.linalg.det(a))  # volume preserving: the linear mode normalises det A = 1
    c0 = m @ rest / m.sum()
    sm = ShapeMatching(rest, m, np.zeros(20, int), mode="linear", beta=1.0)
    st = sm.initial_state(x=(rest - c0) @ a.T)
    np.testing.assert_allclose(sm.goals(st)[0], st.x, atol=1e-15)
    # quadratic mode, beta = 1: goals = c + B q~ with B the mass-weighted least-squares fit of
    # p = x - c on q~ = (q, q^2, cross terms), solved here independently with lstsq
    qd = rest - c0
    x = qd @ a.T + 300.0 * np.column_stack([qd[:, 0] ** 2, qd[:, 1] * qd[:, 2], qd[:, 2] ** 2]) + 1.0
    sm = ShapeMatching(rest, m, np.zeros(20, int), mode="quadratic", beta=1.0)
    st = sm.initial_state(x=x)
    c = m @ x / m.sum()
    qt = np.column_stack([qd, qd**2, qd[:, 0] * qd[:, 1], qd[:, 1] * qd[:, 2], qd[:, 2] * qd[:, 0]])
    sw = np.sqrt(m)[:, None]
    b = np.linalg.lstsq(sw * qt, sw * (x - c), rcond=None)[0]
    np.testing.assert_allclose(sm.goals(st)[0], c + qt @ b, atol=1e-12)
    rigid = ShapeMatching(rest, m, np.zeros(20, int)).goals(st)[0]
    assert np.abs(c + qt @ b - x).max() < 0.5 * np.abs(rigid - x).max()  # fits better than rigid


def test_free_bodies_conserve_momentum():
    rng = np.random.default_rng(2)
    rest = rng.normal(size=(30, 3)) * 1e-3
    m = rng.uniform(1e-6, 2e-6, 30)
    body = np.repeat([0, 1, 2], 10)
    body[27:] = [2, 2, 2]
    for damping in (0.0, 1.0):
        sm = ShapeMatching(rest, m, body, alpha=0.7, damping=damping)
        st = sm.initial_state(
            x=rest + 1e-4 * rng.normal(size=rest.shape), v=0.05 * rng.normal(size=rest.shape)
        )
        p0, l0 = sm.momentum(st)
        for _ in range(200):
            sm.step(st, 1e-3)
        p1, l1 = sm.momentum(st)
        np.testing.assert_allclose(p1, p0, atol=1e-15 * 1e3)
        np.testing.assert_allclose(l1, l0, atol=1e-12 * np.abs(l0).max())


def test_dropped_fragment_comes_to_rest_above_the_plane():
    g = np.arange(3) * 1e-3
    rest = np.stack(np.meshgrid(g, g, g, indexing="ij"), -1).reshape(-1, 3)
    n = len(rest)
    r = 0.3e-3
    sm = ShapeMatching(rest, np.full(n, 1e-6), np.zeros(n, int), radius=r, damping=1.0, friction=0.5)
    tilt = Rotation.from_rotvec([0.3, 0.2, 0.1]).as_matrix()
    st = sm.initial_state(x=(rest - 1e-3) @ tilt.T + [0, 0, 6e-3])
    floor = Boundaries(planes=[[0, 0, 1, 0]])
    h = 1e-3
    first_speed = None
    for _ in range(800):
        c = sm.step(st, h, gravity=(0, 0, -9.81), boundaries=floor)
        if first_speed is None and c.particle.size:
            first_speed = c.speed.max()
            assert set(c.boundary.tolist()) == {plane_id(0)}
    # first impact faster than a free fall from the lowest corner's height, slower than from the top
    lowest = ((rest - 1e-3) @ tilt.T)[:, 2].min() + 6e-3 - r
    assert np.sqrt(2 * 9.81 * lowest) * 0.9 < first_speed < np.sqrt(2 * 9.81 * 6e-3) * 1.1
    x_end = st.x.copy()
    for _ in range(100):
        sm.step(st, h, gravity=(0, 0, -9.81), boundaries=floor)
    assert np.abs(st.x - x_end).max() < 1e-7  # at rest (< 1 um/s)
    goal, _ = sm.goals(st)
    assert goal[:, 2].min() > r - 5 * h * h * 9.81  # the rigid pose sits on the plane
    assert np.ptp(goal[:, 2].reshape(-1)) > 1.9e-3  # a face down, not balanced on an edge or tip

"""Rod contact: DFCP solver (analytic single contacts, random problems, enumeration), contact
geometry against dense sampling, broad phase against brute force, and stick/slip of bodies on planes."""

import itertools

import numpy as np
import pytest

from jassy.errors import JassyError
from physics.rod import geometry
from physics.rod.dfcp import cone_project, natural_map_residual, solve_dfcp
from physics.rod.system import Plane, RigidBody, RodSystem

G = 9.81


# ---------------------------------------------------------------- DFCP
@pytest.mark.parametrize("wt", [0.0, 0.3, -0.5, 0.5])
def test_single_contact_stick(wt):
    res = solve_dfcp(np.eye(2), [-1.0, wt], 0.5)
    np.testing.assert_allclose(res.r[0], [1.0, -wt], atol=1e-12)
    np.testing.assert_allclose(res.u[0], [0.0, 0.0], atol=1e-12)


@pytest.mark.parametrize("wt", [0.6, -2.0])
def test_single_contact_slip(wt):
    res = solve_dfcp(np.eye(2), [-1.0, wt], 0.5)
    np.testing.assert_allclose(res.r[0], [1.0, -0.5 * np.sign(wt)], atol=1e-12)
    np.testing.assert_allclose(res.u[0], [0.0, wt - 0.5 * np.sign(wt)], atol=1e-12)


def test_take_off():
    res = solve_dfcp(np.eye(2), [0.2, 1.0], 0.5)
    np.testing.assert_array_equal(res.r, 0.0)


def test_cone_projection_is_the_euclidean_projection():
    rng = np.random.default_rng(0)
    for _ in range(40):
        rn, rt, mu = rng.normal(), rng.normal(), rng.uniform(0, 2)
        pn, pt = cone_project(rn, rt, mu)
        assert abs(pt) <= mu * pn + 1e-12
        # brute force: closest cone point on a fine grid of the two boundary rays and the apex
        s = np.linspace(0, 5, 50001)
        cand = np.concatenate([np.column_stack([s, mu * s]), np.column_stack([s, -mu * s])])
        if abs(rt) <= mu * rn:
            cand = np.vstack([cand, [rn, rt]])
        best = cand[np.argmin(np.hypot(cand[:, 0] - rn, cand[:, 1] - rt))]
        assert np.hypot(pn - rn, pt - rt) <= np.hypot(*(best - [rn, rt])) + 1e-8


def _random_problem(rng, c):
    B = rng.normal(size=(2 * c, 2 * c + 3))
    W = B @ B.T / (2 * c) + 0.05 * np.eye(2 * c)
    w = rng.normal(size=2 * c)
    mu = rng.uniform(0.1, 1.0, c)
    return W, w, mu


def _check_coulomb(W, w, mu, r, tol):
    u = (W @ r.reshape(-1) + w).reshape(-1, 2)
    assert np.all(r[:, 0] >= -tol)
    assert np.all(np.abs(r[:, 1]) <= mu * r[:, 0] + tol)
    assert np.all(u[:, 0] >= -tol)
    assert np.all(np.abs(r[:, 0] * u[:, 0]) <= tol)
    slipping = np.abs(u[:, 1]) > tol
    np.testing.assert_allclose(
        r[slipping, 1], -mu[slipping] * r[slipping, 0] * np.sign(u[slipping, 1]), atol=tol
    )
    inside = np.abs(r[:, 1]) < mu * r[:, 0] - tol
    assert np.all(np.abs(u[inside, 1]) <= tol)
    # Siconos-style natural map with rho = 1, computed independently
    ut = u[:, 0] + mu * np.abs(u[:, 1])
    proj = np.array(
        [cone_project(a, b, m) for a, b, m in zip(r[:, 0] - ut, r[:, 1] - u[:, 1], mu, strict=True)]
    )
    assert np.linalg.norm(r - proj) / (1 + np.linalg.norm(w)) < tol


@pytest.mark.parametrize("seed", range(6))
def test_random_problems_satisfy_coulomb_at_convergence(seed):
    rng = np.random.default_rng(seed)
    W, w, mu = _random_problem(rng, int(rng.integers(2, 30)))
    res = solve_dfcp(W, w, mu, tol=1e-12, max_iter=100000)
    assert res.converged and res.residual < 1e-8
    assert natural_map_residual(W, w, res.r, mu) == pytest.approx(res.residual, abs=1e-14)
    _check_coulomb(W, w, mu, res.r, 1e-8)


def _enumerate(W, w, mu):
    """All solutions by enumerating take-off / stick / slip+ / slip- per contact (linear solves)."""
    c = len(mu)
    sols = []
    for modes in itertools.product(range(4), repeat=c):
        M, rhs = np.zeros((2 * c, 2 * c)), np.zeros(2 * c)
        for i, m in enumerate(modes):
            n, t = 2 * i, 2 * i + 1
            if m == 0:  # r = 0
                M[n, n], M[t, t] = 1, 1
            elif m == 1:  # u = 0
                M[n], M[t], rhs[n], rhs[t] = W[n], W[t], -w[n], -w[t]
            else:  # u_N = 0, r_T = -s mu r_N
                s = 1 if m == 2 else -1
                M[n], rhs[n] = W[n], -w[n]
                M[t, t], M[t, n] = 1, s * mu[i]
        r = np.linalg.solve(M, rhs).reshape(c, 2)
        u = (W @ r.reshape(-1) + w).reshape(c, 2)
        ok = (
            np.all(r[:, 0] >= -1e-12)
            and np.all(np.abs(r[:, 1]) <= mu * r[:, 0] + 1e-12)
            and np.all(u[:, 0] >= -1e-12)
        )
        for i, m in enumerate(modes):
            ok &= m < 2 or (u[i, 1] * (1 if m == 2 else -1) >= -1e-12)
        if ok:
            sols.append(r)
    return sols


def test_matches_enumeration_when_unique():
    rng = np.random.default_rng(7)
    checked = 0
    for _ in range(30):
        W, w, mu = _random_problem(rng, 3)
        sols = _enumerate(W, w, mu)
        distinct = [s for k, s in enumerate(sols) if all(np.abs(s - t).max() > 1e-9 for t in sols[:k])]
        if len(distinct) != 1:
            continue
        res = solve_dfcp(W, w, mu, tol=1e-12, max_iter=100000)
        np.testing.assert_allclose(res.r, distinct[0], atol=1e-8)
        checked += 1
    assert checked >= 10


def test_stops_on_iteration_limit_and_bad_input():
    rng = np.random.default_rng(3)
    W, w, mu = _random_problem(rng, 20)
    res = solve_dfcp(W, w, mu, tol=1e-14, max_iter=1)
    assert res.iterations == 1 and not res.converged
    with pytest.raises(JassyError, match="mu"):
        solve_dfcp(W, w, -1.0)
    with pytest.raises(JassyError, match="W, w"):
        solve_dfcp(W[:3, :3], w, mu)


# ---------------------------------------------------------------- geometry
def _sample(arc, n=20001):
    s = np.linspace(0, arc[4], n)
    h = arc[3] * s / 2
    c = s * np.sinc(h / np.pi)
    return s, np.column_stack([arc[0] + c * np.cos(arc[2] + h), arc[1] + c * np.sin(arc[2] + h)])


def _random_arc(rng):
    k = rng.choice([0.0, 1e-7, 1e-3, rng.uniform(-4, 4), rng.uniform(-4, 4)])
    return np.array([*rng.normal(size=2), rng.uniform(-3, 3), k, rng.uniform(0.1, 2.0)])


def test_arc_disk_and_plane_match_dense_sampling():
    rng = np.random.default_rng(1)
    for _ in range(60):
        arc = _random_arc(rng)
        _, P = _sample(arc)
        c, R, r = rng.normal(size=(1, 2)), np.array([0.1]), np.array([0.01])
        out = geometry.arc_disk(arc[None], np.array([0]), c, R, r)[0]
        ref = np.min(np.linalg.norm(P - c, axis=1)) - 0.11
        assert ref - 1e-6 <= out[8] <= ref + 1e-12
        np.testing.assert_allclose(np.linalg.norm(out[2:4] - c[0]) - 0.11, out[8], atol=1e-12)
        nrm = rng.normal(size=2)
        nrm /= np.linalg.norm(nrm)
        out = geometry.arc_plane(arc[None], np.array([0]), np.zeros(2), nrm, 0.01)[0]
        ref = np.min(P @ nrm) - 0.01
        assert ref - 1e-6 <= out[8] <= ref + 1e-12


def test_arc_arc_matches_dense_sampling():
    rng = np.random.default_rng(2)
    done = 0
    while done < 30:
        a, b = _random_arc(rng), _random_arc(rng)
        _, P = _sample(a, 1501)
        _, Q = _sample(b, 1501)
        d = np.linalg.norm(P[:, None] - Q[None], axis=2).min()
        if d < 1e-2:  # crossing centre lines are out of scope
            continue
        out = geometry.arc_arc(
            np.array([a, b]), np.array([0]), np.array([1]), np.array([0.01]), np.array([0.02])
        )[0]
        assert d - 0.03 - 4e-5 <= out[8] <= d - 0.03 + 1e-12
        np.testing.assert_allclose(out[6:8], (out[2:4] - out[4:6]) / np.linalg.norm(out[2:4] - out[4:6]))
        done += 1


def test_nearly_straight_arc_is_continuous():
    base = np.array([0.0, 0.0, 0.3, 0.0, 1.0])
    c = np.array([[0.4, 0.5]])
    g0 = geometry.arc_disk(base[None], np.array([0]), c, np.array([0.1]), np.array([0.0]))[0, 8]
    for k in (1e-9, 1e-6, 1e-5, 2e-4):
        arc = base.copy()
        arc[3] = k
        g = geometry.arc_disk(arc[None], np.array([0]), c, np.array([0.1]), np.array([0.0]))[0, 8]
        assert abs(g - g0) < 2 * k


def test_broad_phase_matches_brute_force():
    rng = np.random.default_rng(4)
    centres, radii = rng.uniform(0, 1, (300, 2)), rng.uniform(0.001, 0.03, 300)
    pairs = {tuple(p) for p in geometry.broad_phase(centres, radii, 0.01)}
    d = np.linalg.norm(centres[:, None] - centres[None], axis=2)
    i, j = np.nonzero(np.triu(d <= radii[:, None] + radii[None] + 0.01, 1))
    assert pairs == set(zip(i.tolist(), j.tolist(), strict=True))


# ---------------------------------------------------------------- bodies on planes
def _slide(alpha, mu, steps=100, h=1e-3, push=0.0):
    """A two-footed rigid sled on a plane inclined by alpha: velocity along the slope after steps."""
    n = np.array([-np.sin(alpha), np.cos(alpha)])
    t = np.array([np.cos(alpha), np.sin(alpha)])
    sled = RigidBody(2.0, 0.01, ((-0.05, 0.0, 0.01), (0.05, 0.0, 0.01)))
    system = RodSystem(bodies=[sled], obstacles=[Plane((0.0, 0.0), tuple(n))], mu=mu)
    state = system.initial_state(poses=[[*(0.01 * n), alpha]])
    infos = []
    for _ in range(steps):
        state, info = system.step(state, h, forces={0: (*(push * t), 0.0)})
        infos.append(info)
    return state.v[0, :2] @ t / (steps * h), state, infos


@pytest.mark.parametrize("alpha, mu", [(0.2, 0.3), (0.29, 0.3), (0.35, 0.3), (0.6, 0.3), (0.5, 0.0)])
def test_incline_stick_or_slide(alpha, mu):
    a, state, infos = _slide(alpha, mu)
    ref = -G * (np.sin(alpha) - mu * np.cos(alpha)) if np.tan(alpha) > mu else 0.0
    assert a == pytest.approx(ref, abs=1e-6)
    assert max(i.residual for i in infos) < 1e-8


@pytest.mark.parametrize("push", [0.5, 0.9, 1.1, 2.0])
def test_tangential_push_below_and_above_mu_n(push):
    mu = 0.4
    f = push * mu * 2.0 * G
    a, _, _ = _slide(0.0, mu, push=f)
    assert a == pytest.approx(max(0.0, (f - mu * 2.0 * G) / 2.0), abs=1e-6)


@pytest.mark.parametrize("alpha, mu", [(0.3, 0.3), (0.9, 0.2)])
def test_disk_rolls_or_slips_on_incline(alpha, mu):
    n = np.array([-np.sin(alpha), np.cos(alpha)])
    t = np.array([np.cos(alpha), np.sin(alpha)])
    R, m = 0.1, 2.0
    system = RodSystem(
        bodies=[RigidBody(m, 0.5 * m * R * R, ((0.0, 0.0, R),))], obstacles=[Plane((0, 0), tuple(n))], mu=mu
    )
    state = system.initial_state(poses=[[*(R * n), 0.0]])
    for _ in range(100):
        state, _ = system.step(state, 1e-3)
    a = state.v[0, :2] @ t / 0.1
    rolls = np.tan(alpha) <= 3 * mu
    ref = -2 / 3 * G * np.sin(alpha) if rolls else -G * (np.sin(alpha) - mu * np.cos(alpha))
    assert a == pytest.approx(ref, abs=1e-6)
    if rolls:  # no slip at the contact: v + omega x (-R n) has no tangential part
        assert abs(state.v[0, :2] @ t + state.v[0, 2] * R) < 1e-8


# ---------------------------------------------------------------- system: Schur Delassus vs direct
def _compare_paths(system_factory, state, steps, h, **kw):
    fast, slow = system_factory(True), system_factory(False)
    for _ in range(steps):
        a, ia = fast.step(state, h, **kw)
        b, ib = slow.step(state, h, **kw)
        assert len(ia.r) == len(ib.r)
        np.testing.assert_allclose(ia.r, ib.r, atol=1e-7 * (1 + np.abs(ib.r).max(initial=0.0)))
        for ra, rb in zip(a.rods, b.rods, strict=True):
            np.testing.assert_allclose(ra.v, rb.v, atol=1e-7 * (1 + np.abs(rb.v).max()))
        state = b
    return state


def test_schur_delassus_matches_direct_kkt_solves():
    from physics.rod.contact_bench import peg_scene

    sysm, state = peg_scene(60, 6)
    for _ in range(3):
        state, info = sysm.step(state, 1e-3)
    assert len(info.r) == 6
    _compare_paths(lambda schur: peg_scene(60, 6, schur=schur)[0], state, 3, 1e-3)


def test_schur_delassus_matches_direct_for_stacked_rods():
    from physics.rod.mixed import MixedRod
    from physics.rod.model import RodModel

    rods = [
        MixedRod(
            RodModel(
                6,
                0.3,
                5e-3,
                0.1,
                radius=2e-3,
                rest_curvature=-1 / 0.1,
                start=(-0.1, 0.003 + 0.03 * k, np.pi / 2),
                start_bc="free",
                end_bc="free",
            )
        )
        for k in range(2)
    ]
    make = lambda schur: RodSystem(rods, obstacles=[Plane((0, 0), (0, 1))], mu=0.3, margin=2e-3, schur=schur)  # noqa: E731
    sysm = make(True)
    state = sysm.initial_state()
    for _ in range(60):
        state, info = sysm.step(state, 2e-3)
    assert np.any(info.bodies[:, 1] == 1)  # rod-rod contacts present
    _compare_paths(make, state, 3, 2e-3)


# ---------------------------------------------------------------- rolling on a rod
def test_disk_rolls_on_a_straight_rod_at_r_omega_without_slip():
    from physics.rod.mixed import MixedRod
    from physics.rod.model import RodModel
    from physics.rod.system import contact_events

    r, R, v0 = 5e-3, 0.05, 0.4
    rod = MixedRod(RodModel(20, 1.0, 1e3, 1.0, radius=r, end_bc="roller"))  # stiff: sags < 1e-4 m
    disk = RigidBody(1.0, 0.5 * R * R, ((0.0, 0.0, R),))
    system = RodSystem([rod], [disk], mu=1.0, margin=1e-3)
    state = system.initial_state(poses=[[0.3, r + R, 0.0]], velocities=[[v0, 0.0, -v0 / R]])
    infos = []
    for _ in range(60):
        prev = state
        state, info = system.step(state, 1e-3)
        infos.append(info)
    assert len(info.r) == 1 and info.r[0, 0] > 0
    omega = state.v[0, 2]
    assert info.rolling[0] == pytest.approx(R * abs(omega), rel=1e-3)
    assert R * abs(omega) == pytest.approx(v0, rel=1e-2)
    assert abs(info.u[0, 1]) < 1e-8  # no slip between the surfaces
    # u_T of the last step from the surface point velocities (geometry at its start, velocities at
    # its end), computed independently (n points from the disk to the rod): the rod's surface point
    # (centre line - r n) turns with the cross-section (tangent angle theta + kappa s), the disk's
    # (centre + R n) with omega
    n = info.normals[0]
    t = np.array([-n[1], n[0]])
    det = system.detect(prev)
    e, s = int(det["meta"][0, 2]), float(det["geo"][0, 0])
    q, vr = prev.rods[0].q, state.rods[0].v
    _, cols, J = rod.point_jacobian(q, e, s)
    phi_dot = vr[4 * e + 2] + s * vr[4 * e + 3]

    def turn(w, arm):  # w e_z x arm
        return w * np.array([-arm[1], arm[0]])

    v_rod = J @ vr[cols] + turn(phi_dot, -r * n)
    v_disk = state.v[0, :2] + turn(omega, R * n)
    assert abs(t @ (v_rod - v_disk) - info.u[0, 1]) < 1e-9 * v0
    _, tracks = contact_events(infos)
    track = next(tr for tr in tracks if tr.bodies == (0, 1))
    assert track.rolling_speed[-1] == pytest.approx(R * abs(omega), rel=1e-3)
    assert track.slip_speed[-1] < 1e-8

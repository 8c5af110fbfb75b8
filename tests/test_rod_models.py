"""Rod models: arc kinematics, Jacobians/Hessians vs finite differences, mass and gravity vs
adaptive quadrature, gyroscopic forces vs Lagrange's equations, KKT solvers, statics agreement
between the chained and mixed formulations, large-step stability."""

import numpy as np
import pytest
import scipy.sparse as sp
from scipy.integrate import quad_vec

from jassy.errors import JassyError
from physics.rod import arc
from physics.rod.chained import ChainedRod
from physics.rod.mixed import MixedRod
from physics.rod.model import PointLoad, RodModel, RodState
from physics.rod.statics import solve_static

FORMS = (ChainedRod, MixedRod)


def dense(a):
    return a.toarray() if sp.issparse(a) else np.asarray(a)


def random_q(form, rng, scale=0.8):
    """A glued configuration with random curvatures (and a random start pose)."""
    k = rng.normal(size=form.n) * scale
    if isinstance(form, ChainedRod):
        return np.concatenate((rng.normal(size=2), [rng.normal()], k))
    q = form.initial_state(k).q
    q[:3] = rng.normal(size=3)
    return form.project(q)


def fd(f, x, eps=1e-6):
    cols = [(np.asarray(f(x + eps * e)) - np.asarray(f(x - eps * e))) / (2 * eps) for e in np.eye(x.size)]
    return np.stack(cols, axis=-1)


def test_end_pose_matches_quadrature_of_the_tangent_and_the_closed_form():
    for th, k, seg in ((0.3, 2.0, 0.7), (-1.0, -0.05, 1.3), (2.0, 1e-9, 0.4), (0.1, 4.0, 1.0)):
        tang = quad_vec(lambda s, th=th, k=k: np.array([np.cos(th + k * s), np.sin(th + k * s)]), 0, seg,
                        epsabs=1e-15, epsrel=1e-14)[0]  # fmt: skip
        x, y, t = arc.end_pose(0.2, -0.1, th, k, seg)
        assert np.allclose([x - 0.2, y + 0.1], tang, atol=1e-14, rtol=0)
        assert t == pytest.approx(th + k * seg)
        if abs(k) > 1e-3:  # the talk's division-by-kappa form
            assert x - 0.2 == pytest.approx((np.sin(th + k * seg) - np.sin(th)) / k, abs=1e-13)
            assert y + 0.1 == pytest.approx(-(np.cos(th + k * seg) - np.cos(th)) / k, abs=1e-13)


def test_moments_are_continuous_through_kappa_zero_and_the_series_switch():
    s = 0.8
    for z in (0.5 * (1 - 1e-12), 0.5 * (1 + 1e-12), -0.5 * (1 + 1e-12)):  # series / recurrence boundary
        quad = [quad_vec(lambda u, m=m, z=z: np.array([u**m * np.cos(z * u), u**m * np.sin(z * u)]), 0, 1,
                         epsabs=1e-16, epsrel=1e-15)[0] for m in range(3)]  # fmt: skip
        f = arc.moments(z / s, s)
        for m in range(3):
            assert abs(f[m] / s ** (m + 1) - complex(*quad[m])) < 1e-14
    small = arc.moments(np.array([-1e-10, 0.0, 1e-10]), s)
    limit = np.array([s, s**2 / 2, s**3 / 3])
    assert np.allclose(small, limit[:, None], atol=1e-10 * s, rtol=0)
    assert np.all(np.isfinite(arc.end_pose_jacobian(0.3, np.array([0.0, 1e-300]), 0.5)))


def test_end_pose_jacobian_and_position_hessian_match_finite_differences():
    rng = np.random.default_rng(1)
    for k in (0.0, 1e-7, 0.9, -3.0):
        x = np.array([0.3, -0.2, rng.normal(), k])
        phi = lambda p: np.array(arc.end_pose(p[0], p[1], p[2], p[3], 0.6))  # noqa: E731
        assert np.allclose(arc.end_pose_jacobian(x[2], x[3], 0.6), fd(phi, x), atol=1e-8)
        h = arc.position_hessian(x[2], x[3], 0.6)
        jac = lambda p: arc.end_pose_jacobian(p[0], p[1], 0.6)[:2, 2:]  # noqa: E731
        num = fd(jac, x[2:])
        assert np.allclose(h.real, num[0], atol=1e-7) and np.allclose(h.imag, num[1], atol=1e-7)


@pytest.mark.parametrize("cls", FORMS)
def test_point_jacobian_and_hessian_match_finite_differences(cls):
    rng = np.random.default_rng(2)
    form = cls(RodModel(n=5, length=1.3, EI=1.0, rho_A=1.0))
    q = random_q(form, rng)
    for e, s in ((0, 0.1), (3, 0.2), (4, form.l[-1])):
        p, cols, J = form.point_jacobian(q, e, s)
        num = fd(lambda qq, e=e, s=s: form.point_jacobian(qq, e, s)[0], q)
        full = np.zeros((2, form.ndof))
        full[:, cols] = J
        assert np.allclose(full, num, atol=1e-8)
        hc, H = form.point_hessian(q, e, s)
        num_h = fd(lambda qq, e=e, s=s, cols=cols: form.point_jacobian(qq, e, s)[2], q)
        ref = np.zeros((2, form.ndof, form.ndof))
        ref[:, cols, :] = num_h
        got = np.zeros_like(ref)
        got[:, hc[:, None], hc[None, :]] = H
        assert np.allclose(got, ref, atol=1e-7)


@pytest.mark.parametrize("cls", FORMS)
def test_mass_matrix_is_the_quadrature_of_JtJ_and_spd(cls):
    rng = np.random.default_rng(3)
    m = RodModel(n=4, length=1.0, EI=1.0, rho_A=2.5)
    form = cls(m)
    q = random_q(form, rng, scale=2.0)
    M = dense(form.dynamics(q, np.zeros(form.ndof)).M)
    ref = np.zeros_like(M)
    for e in range(m.n):

        def integrand(s, e=e):
            _, cols, J = form.point_jacobian(q, e, s)
            full = np.zeros((2, form.ndof))
            full[:, cols] = J
            return full.T @ full

        ref += m.rho_A * quad_vec(integrand, 0.0, form.l[e], epsabs=1e-13, epsrel=1e-12)[0]
    assert np.allclose(M, ref, atol=1e-12, rtol=1e-10)
    assert M.shape == ((m.n + 3,) * 2 if cls is ChainedRod else (4 * m.n,) * 2)
    assert np.all(np.linalg.eigvalsh(M) > 0)


@pytest.mark.parametrize("cls", FORMS)
def test_potential_gradient_hessian(cls):
    rng = np.random.default_rng(4)
    m = RodModel(
        n=4, length=1.2, EI=0.7, rho_A=1.5, gravity=9.0, rest_curvature=np.array([0.1, -0.3, 0.2, 0.0])
    )
    form = cls(m)
    q = random_q(form, rng)
    V, grad, K = form.potential(q)
    arcs = form.arcs(q)
    y_int = sum(
        quad_vec(lambda s, e=e: form.point_jacobian(q, e, s)[0][1], 0, arcs.l[e], epsabs=1e-14)[0]
        for e in range(m.n)
    )
    bend = 0.5 * m.EI * np.sum((arcs.kappa - m.kappa0) ** 2 * arcs.l)
    assert pytest.approx(m.rho_A * m.gravity * y_int + bend, rel=1e-12, abs=1e-13) == V
    # each formulation's own potential: gradient and Hessian by finite differences
    assert np.allclose(grad, fd(lambda qq: form.potential(qq)[0], q), atol=1e-7)
    assert np.allclose(dense(K), fd(lambda qq: form.potential(qq)[1], q), atol=1e-7)
    Kpsd = dense(form.dynamics(q, np.zeros(form.ndof)).K)
    assert np.min(np.linalg.eigvalsh(Kpsd)) > -1e-10


@pytest.mark.parametrize("cls", FORMS)
def test_gyroscopic_force_satisfies_lagrange_equations(cls):
    rng = np.random.default_rng(5)
    form = cls(RodModel(n=4, length=1.0, EI=1.0, rho_A=1.3))
    q = random_q(form, rng)
    v = rng.normal(size=form.ndof)
    M = lambda qq: dense(form.dynamics(qq, v).M)  # noqa: E731
    eps = 1e-6
    mdot_v = (M(q + eps * v) - M(q - eps * v)) @ v / (2 * eps)
    dT = fd(lambda qq: v @ M(qq) @ v, q)
    assert np.allclose(form.dynamics(q, v).gyro, -(mdot_v - 0.5 * dT), atol=1e-8)


@pytest.mark.parametrize("cls", FORMS)
def test_constraints_jacobian_and_hessian(cls):
    rng = np.random.default_rng(6)
    form = cls(RodModel(n=4, length=1.0, EI=1.0, rho_A=1.0, start_bc="pinned", end_bc="clamped"))
    q = random_q(form, rng)
    if cls is MixedRod:  # unglued configuration: gluing rows must be exact too
        q = q + 0.05 * rng.normal(size=q.size)
    C, g = form.constraints(q)
    assert np.allclose(C.toarray(), fd(lambda qq: form.constraints(qq)[1], q), atol=1e-8)
    lam = rng.normal(size=g.size)
    num = fd(lambda qq: lam @ form.constraints(qq)[0].toarray(), q)
    assert np.allclose(dense(form.constraint_hessian(q, lam)), num, atol=1e-7)


def test_banded_kkt_matches_splu_and_dense_with_several_rhs():
    rng = np.random.default_rng(7)
    form = MixedRod(RodModel(n=30, length=1.0, EI=1.0, rho_A=1.0, end_bc="pinned", rest_curvature=0.7))
    state = RodState(random_q(form, rng), rng.normal(size=form.ndof))
    A, b, C, c = form.linear_system(state, 0.01)
    B = np.column_stack((b, rng.normal(size=(form.ndof, 2))))
    cc = np.column_stack((c, rng.normal(size=(c.size, 2))))
    v, lam = form.kkt_factor(A, C).solve(B, cc)
    kkt = np.block([[dense(A), C.toarray().T], [C.toarray(), np.zeros((c.size, c.size))]])
    ref = np.linalg.solve(kkt, np.vstack((B, cc)))
    assert np.allclose(v, ref[: form.ndof], rtol=1e-9, atol=1e-9 * np.abs(ref).max())
    assert np.allclose(lam, ref[form.ndof :], rtol=1e-9, atol=1e-9 * np.abs(ref).max())
    v2, _ = form.kkt_factor(A, C, method="splu").solve(b, c)
    assert np.allclose(v2, v[:, 0], atol=1e-9 * np.abs(v).max())


@pytest.mark.parametrize(
    "kw",
    [dict(gravity=10.0), dict(gravity=3.0, rest_curvature=1.5, end_bc="pinned", start_bc="clamped"),
     dict(gravity=0.0, start_bc="pinned", end_bc="roller", rest_curvature=-0.4, start=(0, 0, 0.2))],
)  # fmt: skip
def test_chained_and_mixed_statics_agree(kw):
    m = RodModel(n=12, length=1.0, EI=1.0, rho_A=1.0, **kw)
    loads = [PointLoad(5, m.length / 12, (0.3, -2.0))]
    tips = []
    for cls in FORMS:
        form = cls(m)
        res = solve_static(form, loads=loads, load_steps=3)
        assert res.converged
        C, g = form.constraints(res.q)
        assert np.abs(g).max() < 1e-10
        _, grad, _ = form.potential(res.q)
        _, gl, _ = form.load_terms(res.q, loads)
        assert np.abs(grad + gl + C.T @ res.lam).max() < 1e-8  # KKT stationarity
        tips.append(np.concatenate([form.point_jacobian(res.q, e, form.l[e] / 2)[0] for e in range(m.n)]))
    assert np.allclose(tips[0], tips[1], atol=1e-10)


@pytest.mark.parametrize("cls", FORMS)
def test_large_implicit_steps_stay_stable(cls):
    m = RodModel(n=20, length=1.0, EI=0.01, rho_A=1.0, gravity=9.81, rest_curvature=2.0)
    form = cls(m)
    state = form.initial_state(np.zeros(m.n))
    e0 = form.energy(state)
    energies = []
    for _ in range(60):
        state = form.step(state, 0.1)  # ~50x the explicit limit of the stiffest mode
        energies.append(form.energy(state))
    assert np.all(np.isfinite(state.q)) and np.all(np.isfinite(energies))
    assert max(energies) <= e0 + 1e-9 * abs(e0)
    assert form.arcs(state.q).y.min() > -1.0 - 1e-9  # inextensible: never below the length


def test_dynamics_of_both_models_converge_to_each_other():
    m = RodModel(n=6, length=1.0, EI=1.0, rho_A=1.0)
    diffs = []
    for h in (2e-3, 5e-4):
        tips = []
        for cls in FORMS:
            form = cls(m)
            state = form.initial_state()
            for _ in range(int(round(0.2 / h))):
                state = form.step(state, h)
            tips.append(form.point_jacobian(state.q, 5, form.l[-1])[0])
        diffs.append(np.abs(tips[0] - tips[1]).max())
    assert diffs[1] < diffs[0] / 2.5  # first-order schemes with the same limit


def test_mixed_advance_keeps_elements_glued():
    form = MixedRod(RodModel(n=10, length=1.0, EI=1.0, rho_A=1.0, start_bc="free"))
    state = form.initial_state()
    rng = np.random.default_rng(8)
    state = form.advance(state, rng.normal(size=form.ndof), 0.1)
    _, g = form.constraints(state.q)
    assert np.abs(g).max() < 1e-14


def test_bad_input_raises_jassy_error():
    with pytest.raises(JassyError, match="RodModel.n"):
        RodModel(n=0, length=1.0, EI=1.0, rho_A=1.0)
    with pytest.raises(JassyError, match="end_bc"):
        RodModel(n=2, length=1.0, EI=1.0, rho_A=1.0, end_bc="glued")
    with pytest.raises(JassyError, match="rest_curvature"):
        RodModel(n=2, length=1.0, EI=1.0, rho_A=1.0, rest_curvature=[1.0, 2.0, 3.0])
    form = MixedRod(RodModel(n=2, length=1.0, EI=1.0, rho_A=1.0))
    with pytest.raises(JassyError, match="element"):
        form.point_jacobian(form.initial_state().q, 2, 0.1)
    with pytest.raises(JassyError, match="h"):
        form.step(form.initial_state(), -1.0)
    with pytest.raises(JassyError, match="v_next"):
        form.advance(form.initial_state(), np.full(form.ndof, np.nan), 0.1)

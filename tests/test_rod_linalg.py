"""Rod linear algebra against dense numpy: band LU / solves, the per-element band KKT assembly
against the generic sparse linear_system, the vectorised contact Jacobians, the partitioned
Schur-complement Delassus operator against H inv(K) H^T, and the element/disk broad phase."""

import numpy as np
import pytest
import scipy.sparse as sp

from physics.rod import geometry
from physics.rod.band import BandOrder, band_lu, band_residual, band_solve, band_solve_vec
from physics.rod.chained import ChainedRod
from physics.rod.delassus import BandKKT, DirectDelassus, SchurDelassus, SparseKKT
from physics.rod.mixed import BAND, MixedRod
from physics.rod.model import FormulationBase, RodModel, RodState
from physics.rod.system import Anchor, Disk, Joint, Plane, RigidBody, RodSystem


def _random_band(rng, n, kl, ku, blocks=()):
    """Dense random band matrix (tiny diagonal, so partial pivoting must swap rows), zero outside
    the diagonal blocks given by their boundaries."""
    A = np.zeros((n, n))
    for i in range(n):
        for j in range(max(0, i - kl), min(n, i + ku + 1)):
            A[i, j] = rng.normal() * (1e-6 if i == j else 1.0)
    for cut in blocks:
        A[cut:, :cut] = 0.0
        A[:cut, cut:] = 0.0
    return A


def _to_band(A, kl, ku):
    n = A.shape[0]
    ab = np.zeros((n, 2 * kl + ku + 1))
    for j in range(n):
        for i in range(max(0, j - ku), min(n, j + kl + 1)):
            ab[j, kl + ku + i - j] = A[i, j]
    return ab


def _from_band(ab, kl, ku):
    n = ab.shape[0]
    A = np.zeros((n, n))
    for j in range(n):
        for i in range(max(0, j - ku), min(n, j + kl + 1)):
            A[i, j] = ab[j, kl + ku + i - j]
    return A


@pytest.mark.parametrize("kl, ku", [(1, 1), (4, 4), (2, 5), (6, 3)])
def test_band_lu_solves_match_dense(kl, ku):
    rng = np.random.default_rng(kl * 10 + ku)
    n = 40
    A = _random_band(rng, n, kl, ku)
    lu = _to_band(A, kl, ku)
    piv = np.empty(n, dtype=np.int64)
    assert band_lu(lu, kl, ku, piv) == 0
    assert np.any(piv != np.arange(n))  # pivoting happened
    B = rng.normal(size=(n, 3))
    X = B.copy()
    band_solve(lu, kl, ku, piv, X, 0, n)
    np.testing.assert_allclose(X, np.linalg.solve(A, B), rtol=1e-9, atol=1e-9 * np.abs(X).max())
    x = B[:, 0].copy()
    band_solve_vec(lu, kl, ku, piv, x, 0, n)
    np.testing.assert_allclose(x, X[:, 0], rtol=1e-12, atol=1e-12 * np.abs(x).max())
    y = x * (1.0 + 1e-3 * rng.normal(size=n))  # a residual well above round-off
    res, omega = band_residual(_to_band(A, kl, ku), kl, ku, y, B[:, 0])
    np.testing.assert_allclose(res, B[:, 0] - A @ y, rtol=1e-9, atol=1e-12 * np.abs(A @ y).max())
    ref = np.max(np.abs(B[:, 0] - A @ y) / (np.abs(A) @ np.abs(y) + np.abs(B[:, 0])))
    assert omega == pytest.approx(ref, rel=1e-9)


def test_band_solve_of_one_diagonal_block():
    rng = np.random.default_rng(3)
    n, kl, ku = 30, 3, 4
    A = _random_band(rng, n, kl, ku, blocks=(12, 21))
    lu = _to_band(A, kl, ku)
    piv = np.empty(n, dtype=np.int64)
    assert band_lu(lu, kl, ku, piv) == 0
    b = rng.normal(size=(9, 2))
    x = b.copy()
    band_solve(lu, kl, ku, piv, x, 12, 21)
    np.testing.assert_allclose(x, np.linalg.solve(A[12:21, 12:21], b), rtol=1e-9, atol=1e-12)
    v = b[:, 1].copy()
    band_solve_vec(lu, kl, ku, piv, v, 12, 21)
    np.testing.assert_allclose(v, x[:, 1], rtol=1e-12, atol=1e-14)


def test_band_order_reproduces_the_matrix_and_detects_new_entries():
    rng = np.random.default_rng(5)
    n = 25
    P = rng.permutation(n)
    T = _random_band(rng, n, 2, 2)
    A = T[np.ix_(P, P)]  # banded only after reordering
    rows, cols = np.nonzero(A)
    order = BandOrder(rows, cols, n)
    ab, kl, ku, pos = order.band(rows, cols, A[rows, cols])
    assert max(kl, ku) <= 4
    np.testing.assert_array_equal(_from_band(ab, kl, ku)[np.ix_(pos, pos)], A)
    assert order.fits(rows, cols)
    far = np.argmax(np.abs(pos - pos[0]))
    assert not order.fits(np.array([0]), np.array([far]))


@pytest.mark.parametrize(
    "kw",
    [dict(), dict(end_bc="pinned", rest_curvature=0.7), dict(start_bc="free", end_bc="clamped"),
     dict(start_bc="roller", end_bc="roller", damping=0.3)],
)  # fmt: skip
def test_kkt_band_equals_the_generic_linear_system(kw):
    rng = np.random.default_rng(9)
    form = MixedRod(RodModel(n=7, length=1.0, EI=1.0, rho_A=1.0, **kw))
    q = form.initial_state(rng.normal(size=7)).q
    q[:3] = rng.normal(size=3)
    q = form.project(q) + 0.01 * rng.normal(size=q.size)  # not glued: gluing rows matter too
    state = RodState(q, rng.normal(size=form.ndof), rng.normal(size=form.n_constraints))
    A, b, C, c = FormulationBase.linear_system(form, state, 0.01)  # sparse sums of M, D, K, d2g
    kkt = np.block([[A.toarray(), C.toarray().T], [C.toarray(), np.zeros((c.size, c.size))]])
    K, rhs = form.kkt_band(state, 0.01)
    dense = _from_band(K, BAND, BAND)
    np.testing.assert_allclose(dense[np.ix_(form.perm, form.perm)], kkt, atol=1e-14 * np.abs(kkt).max())
    np.testing.assert_allclose(rhs, np.concatenate([b, c]), atol=1e-14 * np.abs(rhs).max())
    rows, cols = np.nonzero(kkt)
    assert np.max(np.abs(form.perm[rows] - form.perm[cols])) <= BAND
    A2, b2, C2, c2 = form.linear_system(state, 0.01)
    np.testing.assert_allclose(A2.toarray(), A.toarray(), atol=1e-14 * np.abs(kkt).max())
    np.testing.assert_allclose(C2.toarray(), C.toarray(), atol=1e-15)
    nxt = form.step(state, 0.01)
    v, lam = form.kkt_factor(A, C, method="splu").solve(b, c)
    np.testing.assert_allclose(nxt.v, v, rtol=1e-9, atol=1e-9 * np.abs(v).max())
    np.testing.assert_allclose(nxt.lam, lam, rtol=1e-9, atol=1e-9 * np.abs(lam).max())


@pytest.mark.parametrize("cls", [ChainedRod, MixedRod])
def test_point_jacobians_match_point_jacobian(cls):
    rng = np.random.default_rng(2)
    form = cls(RodModel(n=6, length=1.2, EI=1.0, rho_A=1.0, rest_curvature=0.5))
    q = form.initial_state().q + 0.1 * rng.normal(size=form.ndof)
    if cls is MixedRod:
        q = form.project(q)
    elems = np.array([0, 3, 5, 3])
    s = rng.uniform(0, 0.2, 4)
    pts, cols, J = form.point_jacobians(q, elems, s)
    for m, (e, si) in enumerate(zip(elems, s, strict=True)):
        p, c, Jm = form.point_jacobian(q, int(e), float(si))
        np.testing.assert_allclose(pts[m], p, atol=1e-14)
        full = np.zeros((2, form.ndof))
        np.add.at(full.T, cols[m], J[m].T)
        ref = np.zeros((2, form.ndof))
        ref[:, c] = Jm
        np.testing.assert_allclose(full, ref, atol=1e-14)


def _dense_reference(system, state, h):
    """W, x_free and K (natural order) of one step, by numpy on the dense KKT matrix."""
    det = system.detect(state)
    band, K, rhs = system._bilateral(state, h, {}, {})
    H, _ = system._contact_rows(state, det["meta"], det["geo"])
    ab, kl, ku, pos = band
    Kd = _from_band(ab, kl, ku)[np.ix_(pos, pos)]
    E = np.zeros((rhs.size, H.shape[0]))
    E[: system.ndof] = H.toarray().T
    Kinv_E = np.linalg.solve(Kd, E)
    return band, H, rhs, Kd, E.T @ Kinv_E, np.linalg.solve(Kd, rhs), E


def _check_delassus(solver, W, x_free, Kd, E, rhs, rng):
    scale = np.abs(W).max()
    np.testing.assert_allclose(solver.W, W, atol=1e-9 * scale)
    np.testing.assert_allclose(solver.x_free, x_free, atol=1e-9 * np.abs(x_free).max())
    r = rng.uniform(0, 1e-3, W.shape[0])
    x = solver.solution(r)
    ref = np.linalg.solve(Kd, rhs + E @ r)
    np.testing.assert_allclose(x, ref, atol=1e-9 * np.abs(ref).max())


def test_schur_delassus_equals_dense_H_Kinv_Ht_on_a_rod_on_pegs():
    from physics.rod.contact_bench import peg_scene

    system, state = peg_scene(40, 5)
    for _ in range(2):
        state, _ = system.step(state, 1e-3)
    band, H, rhs, Kd, W, x_free, E = _dense_reference(system, state, 1e-3)
    assert H.shape[0] == 10
    rng = np.random.default_rng(0)
    schur = SchurDelassus(*band, system.ndof, H, rhs)
    assert schur.bidx.size < Kd.shape[0] // 2  # a partition, not the whole matrix
    _check_delassus(schur, W, x_free, Kd, E, rhs, rng)
    _check_delassus(DirectDelassus(BandKKT(*band), system.ndof, H, rhs), W, x_free, Kd, E, rhs, rng)
    sparse_kkt = SparseKKT(sp.csr_matrix(Kd), system.ndof)
    _check_delassus(DirectDelassus(sparse_kkt, system.ndof, H, rhs), W, x_free, Kd, E, rhs, rng)


def test_schur_delassus_equals_dense_for_two_rods_a_disk_body_and_a_joint():
    rods = [
        MixedRod(RodModel(12, 0.6, 1e-2, 0.1, radius=2e-3, start=(0.0, 0.01 + 0.02 * k, 0.0)))
        for k in range(2)
    ]
    ball = RigidBody(0.05, 1e-5, ((0.0, 0.0, 0.01),))
    joints = [Joint(Anchor(2), None, world=(0.45, 0.047))]  # the ball hangs on a pin
    system = RodSystem(rods, [ball], [Disk((0.3, -0.012), 0.01), Plane((0, -0.05), (0, 1))], joints,
                       margin=0.02)  # fmt: skip
    state = system.initial_state(poses=[[0.45, 0.047, 0.0]])
    band, H, rhs, Kd, W, x_free, E = _dense_reference(system, state, 1e-3)
    bodies = set(map(int, system.detect(state)["meta"][:, :2].ravel()))
    assert {0, 1, 2, 3} <= bodies  # rod-rod, rod-ball, rod-disk contacts
    _check_delassus(
        SchurDelassus(*band, system.ndof, H, rhs), W, x_free, Kd, E, rhs, np.random.default_rng(1)
    )


def test_cross_pairs_match_brute_force():
    rng = np.random.default_rng(4)
    ca, ra = rng.uniform(0, 1, (200, 2)), rng.uniform(0.001, 0.02, 200)
    cb, rb = rng.uniform(0, 1, (60, 2)), rng.uniform(0.001, 0.05, 60)
    cb[0] = ca[0]  # coincident centres
    pairs = geometry.cross_pairs(ca, ra, cb, rb, 0.01)
    d = np.linalg.norm(ca[:, None] - cb[None], axis=2)
    i, j = np.nonzero(d <= ra[:, None] + rb[None] + 0.01)
    np.testing.assert_array_equal(pairs, np.column_stack([i, j]))
    assert geometry.cross_pairs(ca, ra, cb[:0], rb[:0], 0.01).shape == (0, 2)


def test_rods_only_band_system_is_the_rods_kkt_matrices():
    rng = np.random.default_rng(6)
    rods = [MixedRod(RodModel(n, 0.5, 1.0, 1.0, start_bc=bc)) for n, bc in ((5, "clamped"), (4, "pinned"))]
    system = RodSystem(rods, obstacles=[Plane((0, -1.0), (0, 1))])
    states = [RodState(f.initial_state().q, rng.normal(size=f.ndof)) for f in rods]
    state = system.initial_state(states)
    (ab, kl, ku, pos), K, rhs = system._bilateral(state, 1e-2, {}, {})
    assert K is None
    dense = _from_band(ab, kl, ku)[np.ix_(pos, pos)]
    parts = [f.linear_system(st, 1e-2) for f, st in zip(rods, states, strict=True)]
    A = sp.block_diag([p[0] for p in parts]).toarray()
    C = sp.block_diag([p[2] for p in parts]).toarray()
    ref = np.block([[A, C.T], [C, np.zeros((C.shape[0], C.shape[0]))]])
    np.testing.assert_allclose(dense, ref, atol=1e-15 * np.abs(ref).max())
    np.testing.assert_allclose(rhs, np.concatenate([p[1] for p in parts] + [p[3] for p in parts]))

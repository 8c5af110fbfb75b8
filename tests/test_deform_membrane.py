"""Mass-spring membrane: static sag, tearing (physics/deform/membrane.py)."""

import numpy as np
import pytest
from scipy.optimize import minimize
from scipy.sparse import coo_matrix
from scipy.sparse.csgraph import connected_components

from jassy.errors import JassyError
from physics.deform.membrane import ANCHORED, FREE, SCRIPTED, Membrane, grid_mesh, membrane_from_mesh

G = 9.81


def settle(mem, st, seconds, h=1e-3, script=None):
    for _ in range(int(round(seconds / h))):
        mem.step(st, h, script)


@pytest.mark.parametrize("top", [ANCHORED, SCRIPTED])
def test_hanging_chain_matches_the_analytic_static_stretch(top):
    n, m, k, dz = 6, 2e-3, 40.0, 0.01
    pts = np.zeros((n, 3))
    pts[:, 2] = -dz * np.arange(n)
    kind = np.full(n, FREE)
    kind[0] = top
    mem = Membrane(
        pts,
        np.full(n, m),
        np.stack([np.arange(n - 1), np.arange(1, n)], 1),
        k,
        0.0,
        np.inf,
        kind,
        viscosity=20.0,
    )
    st = mem.initial_state()
    settle(mem, st, 3.0, script=lambda t: pts[:1])
    stretch = -np.diff(st.x[:, 2]) - dz
    np.testing.assert_allclose(stretch, m * G * np.arange(n - 1, 0, -1) / k, rtol=1e-8)
    if top == SCRIPTED:  # the forceps feels the weight of everything below it
        np.testing.assert_allclose(st.forceps_force, [0, 0, -(n - 1) * m * G], rtol=1e-8, atol=1e-12)


def test_hanging_sheet_matches_the_energy_minimum():
    pts, tri = grid_mesh(6, 5, 0.02, 0.016)
    pts = pts[:, [0, 2, 1]]  # vertical sheet in the x-z plane
    top = np.flatnonzero(pts[:, 2] == pts[:, 2].max())
    mem = membrane_from_mesh(
        pts, tri, thickness=1e-3, density=1000.0, stiffness=0.3, anchored=top, viscosity=15.0
    )
    st = mem.initial_state()
    settle(mem, st, 4.0)
    free = np.flatnonzero(mem.kind == FREE)
    sp, L0, k, m = mem.springs, mem.rest_length, mem.stiffness, mem.masses

    def energy(y):
        x = mem.rest.copy()
        x[free] = y.reshape(-1, 3)
        d = x[sp[:, 1]] - x[sp[:, 0]]
        L = np.linalg.norm(d, axis=1)
        e = 0.5 * np.sum(k * (L - L0) ** 2) + G * np.sum(m * x[:, 2])
        fs = (k * (L - L0) / L)[:, None] * d
        grad = np.zeros_like(x)
        np.add.at(grad, sp[:, 0], -fs)
        np.add.at(grad, sp[:, 1], fs)
        grad[:, 2] += G * m
        return e, grad[free].ravel()

    res = minimize(
        energy,
        mem.rest[free].ravel(),
        jac=True,
        method="L-BFGS-B",
        options={"ftol": 1e-15, "gtol": 1e-13, "maxiter": 20000},
    )
    x_ref = res.x.reshape(-1, 3)
    sag = np.abs(x_ref - mem.rest[free]).max()
    assert sag > 1e-3  # a real sag, not a trivial equilibrium
    assert np.abs(st.x[free] - x_ref).max() < 1e-4 * sag


def test_tearing_conserves_particles_and_mass_and_removes_bending_partners():
    pts, tri = grid_mesh(8, 4, 0.014, 0.006)
    left = np.flatnonzero(pts[:, 0] == 0)
    right = np.flatnonzero(pts[:, 0] == pts[:, 0].max())
    mem = membrane_from_mesh(
        pts,
        tri,
        thickness=1e-3,
        stiffness=2.0,
        bending=0.2,
        tear_strain=0.3,
        anchored=left,
        scripted=right,
        viscosity=5.0,
        gravity=(0, 0, 0),
    )
    n_edges = int((mem.partner >= 0).sum()) + int(np.sum(mem.tear_strain < np.inf) - (mem.partner >= 0).sum())
    interior = np.unique(mem.tri_springs.ravel(), return_counts=True)[1]
    assert (mem.partner >= 0).sum() == (interior == 2).sum()  # one bending spring per interior edge
    assert n_edges == len(interior)
    st = mem.initial_state()
    start = pts[right].copy()
    tears = []
    for _ in range(400):
        tears += mem.step(st, 1e-3, lambda t: start + [0.03 * t, 0, 0])
    assert len(tears) > 0
    assert st.x.shape == pts.shape and np.all(np.isfinite(st.x))
    assert mem.masses.sum() == pytest.approx(1000 * 1e-3 * 0.014 * 0.006, rel=1e-12)
    torn = np.array([t.spring for t in tears])
    assert len(set(torn.tolist())) == len(torn)
    assert not st.alive[torn].any()
    assert not st.alive[mem.partner[torn][mem.partner[torn] >= 0]].any()
    # only torn structural springs and their partners are gone
    gone = np.flatnonzero(~st.alive)
    np.testing.assert_array_equal(
        np.sort(gone), np.sort(np.concatenate([torn, mem.partner[torn][mem.partner[torn] >= 0]]))
    )
    assert all(t.strain > 0.3 for t in tears)


def test_scripted_pull_tears_along_the_weak_line_only():
    pts, tri = grid_mesh(10, 5, 0.018, 0.008)
    left = np.flatnonzero(pts[:, 0] == 0)
    right = np.flatnonzero(pts[:, 0] == pts[:, 0].max())
    mem0 = membrane_from_mesh(
        pts,
        tri,
        thickness=1e-3,
        stiffness=2.0,
        anchored=left,
        scripted=right,
        viscosity=5.0,
        gravity=(0, 0, 0),
    )
    mid = 0.009
    sp = mem0.springs
    weak = (pts[sp[:, 0], 0] < mid) != (pts[sp[:, 1], 0] < mid)  # springs crossing x = mid
    tear = np.where(weak, 0.15, 2.0)
    mem = Membrane(
        mem0.rest,
        mem0.masses,
        sp,
        mem0.stiffness,
        mem0.damping,
        tear,
        mem0.kind,
        mem0.triangles,
        mem0.tri_springs,
        None,
        (0, 0, 0),
        5.0,
    )
    st = mem.initial_state()
    start = pts[right].copy()
    tears = []
    for _ in range(600):
        tears += mem.step(st, 1e-3, lambda t: start + [0.01 * t, 0, 0])
        if not st.alive[weak].any():
            break
    torn = np.array([t.spring for t in tears])
    assert set(torn.tolist()) == set(np.flatnonzero(weak).tolist())
    assert all(t.strain > 0.15 for t in tears)
    assert np.all(mem.strain(st)[st.alive] < 2.0)
    live = sp[st.alive]
    graph = coo_matrix((np.ones(len(live)), (live[:, 0], live[:, 1])), shape=(len(pts),) * 2)
    k, lab = connected_components(graph, directed=False)
    assert k == 2 and len(set(lab[left])) == 1 and len(set(lab[right])) == 1 and lab[left[0]] != lab[right[0]]
    assert (
        len(mem.live_triangles(st)) == len(tri) - np.isin(mem.tri_springs, np.flatnonzero(weak)).any(1).sum()
    )


def test_bad_input_raises():
    pts, tri = grid_mesh(3, 3, 0.01, 0.01)
    with pytest.raises(JassyError, match="triangles"):
        membrane_from_mesh(pts, tri + 100)
    mem = membrane_from_mesh(pts, tri, scripted=[0])
    with pytest.raises(JassyError, match="script"):
        mem.step(mem.initial_state(), 1e-3)
    with pytest.raises(JassyError, match="script"):
        mem.step(mem.initial_state(), 1e-3, lambda t: np.zeros((2, 3)))

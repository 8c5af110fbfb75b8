"""Tet particle solids: removal primitives, erosion, fragments, collisions (physics/deform/fragments.py)."""

import numpy as np
import pytest

from jassy.errors import JassyError
from physics.deform.fragments import (
    FragmentParams,
    FragmentSim,
    TetMesh,
    external_count,
    fragment_labels,
    lattice_mesh,
)
from physics.deform.shape_matching import Boundaries, plane_id

CUBE = np.array([[i, j, k] for i in (0, 1) for j in (0, 1) for k in (0, 1)], dtype=float) * 1e-3
# 5-tet split: a central tet on corners 0, 3, 5, 6 and four corner tets with 3 external faces
FIVE = [[0, 3, 5, 6], [1, 0, 3, 5], [2, 0, 3, 6], [4, 0, 5, 6], [7, 3, 5, 6]]
NOGRAV = FragmentParams(gravity=(0.0, 0.0, 0.0), radius=1e-4)


def alive_vertices(mesh, alive):
    used = np.zeros(len(mesh.points), bool)
    used[mesh.tets[alive].ravel()] = True
    return used


def check_bookkeeping(sim):
    st, mesh = sim.state, sim.mesh
    used = alive_vertices(mesh, st.alive)
    np.testing.assert_array_equal(sim.matcher.body >= 0, used)
    np.testing.assert_array_equal(st.masses > 0, used)
    assert st.masses.sum() == pytest.approx(sim.params.density * mesh.volumes[st.alive].sum(), rel=1e-12)


def test_three_external_faces_removes_the_corner_particle():
    sim = FragmentSim(TetMesh(CUBE, FIVE), NOGRAV)
    np.testing.assert_array_equal(external_count(sim.mesh, sim.state.alive), [0, 3, 3, 3, 3])
    with pytest.raises(JassyError, match="not removable"):
        sim.remove([0])  # interior tet
    assert sim.remove([1]).tolist() == [3]
    assert sim.matcher.body[1] == -1 and np.all(sim.matcher.body[[0, 2, 3, 4, 5, 6, 7]] >= 0)
    np.testing.assert_array_equal(external_count(sim.mesh, sim.state.alive), [1, -1, 3, 3, 3])
    assert sim.remove([0]).tolist() == [1]  # one external face now: the centre goes, no particle lost
    assert (sim.matcher.body >= 0).sum() == 7
    check_bookkeeping(sim)
    np.testing.assert_array_equal(sim.state.removed_by_kind, [1, 0, 1, 0])


def test_two_external_faces_in_a_kuhn_cube():
    mesh = lattice_mesh(lambda p: np.ones(len(p), bool), (0, 0, 0), (1e-3, 1e-3, 1e-3), 1e-3)
    assert mesh.tets.shape == (6, 4) and mesh.volumes.sum() == pytest.approx(1e-9, rel=1e-12)
    sim = FragmentSim(mesh, NOGRAV)
    np.testing.assert_array_equal(external_count(mesh, sim.state.alive), [2] * 6)
    assert sim.remove([0]).tolist() == [2]
    assert (sim.matcher.body >= 0).sum() == 8  # every vertex still used by another tet
    counts = external_count(mesh, sim.state.alive)
    # the two tets that shared a face with tet 0 gain an external face
    assert sorted(counts[1:].tolist()) == [2, 2, 2, 3, 3]
    check_bookkeeping(sim)


def test_cutting_a_bridge_makes_two_fragments():
    pts = (
        np.array(
            [
                [0, 0, 0],
                [1, 0, 0],
                [0, 1, 0],
                [0, 0, 1],
                [1, 1, 1],
                [2, 1, 1],
                [1, 2, 1],
                [1, 1, 2],
                [2, 2, 2],
            ],
            float,
        )
        * 1e-3
    )
    tets = [[0, 1, 2, 3], [1, 2, 3, 4], [4, 5, 6, 7], [5, 6, 7, 8]]
    mesh = TetMesh(pts, tets)
    k, plab, tlab = fragment_labels(mesh, np.ones(4, bool))
    assert k == 1  # tets 1 and 2 share only vertex 4: shared-vertex connectivity joins them
    sim = FragmentSim(mesh, NOGRAV)
    assert sim.remove([1]).tolist() == [3]
    assert sim.n_fragments == 2
    lab = sim.matcher.body
    assert len({lab[i] for i in (0, 1, 2, 3)}) == 1 and len({lab[i] for i in (4, 5, 6, 7, 8)}) == 1
    assert lab[0] != lab[4]
    assert sorted(sim.state.fragment_ids.tolist()) == [0, 1]
    check_bookkeeping(sim)


def union_find_components(mesh, alive):
    """Independent reference: union-find over the vertices of live tets."""
    parent = list(range(len(mesh.points)))

    def find(a):
        while parent[a] != a:
            parent[a] = parent[parent[a]]
            a = parent[a]
        return a

    for t in mesh.tets[alive]:
        for v in t[1:]:
            parent[find(v)] = find(t[0])
    used = alive_vertices(mesh, alive)
    return {
        frozenset(np.flatnonzero(used & (np.array([find(i) for i in range(len(parent))]) == r)))
        for r in {find(i) for i in np.flatnonzero(used)}
    }


def test_erosion_removes_only_removable_tets_inside_the_tool_and_splits_a_bar():
    mesh = lattice_mesh(lambda p: np.ones(len(p), bool), (0, 0, 0), (6e-3, 1e-3, 1e-3), 0.5e-3)
    sim = FragmentSim(mesh, NOGRAV)
    centre, radius = np.array([3e-3, 0.5e-3, 0.5e-3]), 0.6e-3
    removed_all = []
    for _ in range(40):
        before = sim.state.alive.copy()
        kinds = external_count(mesh, before)
        cen = sim.centroids()
        got = sim.erode(centre, radius, budget=7)
        assert got.size <= 7
        assert np.all(np.linalg.norm(cen[got] - centre, axis=1) < radius)
        assert np.all(kinds[got] >= 1)
        np.testing.assert_array_equal(before & ~sim.state.alive, np.isin(np.arange(len(before)), got))
        removed_all += got.tolist()
        check_bookkeeping(sim)
        if got.size == 0:
            break
    assert sim.n_fragments == 2
    comps = union_find_components(mesh, sim.state.alive)
    ours = {frozenset(np.flatnonzero(sim.matcher.body == b)) for b in range(sim.n_fragments)}
    assert ours == comps
    cen = mesh.points[mesh.tets].mean(1)
    assert np.all(np.linalg.norm(cen[removed_all] - centre, axis=1) < radius)


def test_split_fragments_fall_separately_and_hit_the_floor_at_free_fall_speed():
    mesh = lattice_mesh(lambda p: np.ones(len(p), bool), (0, 0, 0), (4e-3, 1e-3, 1e-3), 0.5e-3)
    drop = 5e-3
    mesh = TetMesh(mesh.points + [0, 0, drop], mesh.tets)
    r = 0.1e-3
    sim = FragmentSim(
        mesh, FragmentParams(radius=r, viscosity=0.0, restitution=0.0), Boundaries(planes=[[0, 0, 1, 0]])
    )
    for _ in range(20):
        sim.erode((2e-3, 0.5e-3, 0.5e-3 + drop), 0.6e-3, 50)
    assert sim.n_fragments == 2
    impacts = []
    for _ in range(60):
        impacts += sim.step(1e-3)
    first = {}
    for imp in impacts:
        assert imp.bodies[1] == plane_id(0) and imp.bodies[0] in (0, 1)
        first.setdefault(imp.bodies[0], imp)
    assert set(first) == {0, 1}
    v_free = np.sqrt(2 * 9.81 * (drop - r))  # bottom face starts at z = drop
    for imp in first.values():
        assert imp.speed == pytest.approx(v_free, rel=0.05)
        assert imp.impulse > 0 and np.isfinite(imp.impulse)
    check_bookkeeping(sim)


def test_fragments_collide_conserving_momentum():
    mesh = lattice_mesh(lambda p: np.ones(len(p), bool), (0, 0, 0), (1e-3, 1e-3, 1e-3), 0.5e-3)
    shift = np.array([1.5e-3, 0, 0])
    pts = np.concatenate([mesh.points, mesh.points + shift])
    mesh2 = TetMesh(pts, np.concatenate([mesh.tets, mesh.tets + len(mesh.points)]))
    sim = FragmentSim(mesh2, FragmentParams(gravity=(0, 0, 0), radius=0.2e-3, viscosity=0.0, restitution=0.5))
    assert sim.n_fragments == 2
    n = len(mesh.points)
    u = 0.2
    sim.state.body.v[:n, 0] = u
    sim.state.body.v[n:, 0] = -u
    m = sim.state.masses
    p0 = (m[:, None] * sim.state.body.v).sum(0)
    impacts = []
    for _ in range(20):
        impacts += sim.step(1e-4)
    pairs = [imp for imp in impacts if imp.bodies == (0, 1)]
    assert pairs and pairs[0].speed == pytest.approx(2 * u, rel=0.02)
    np.testing.assert_allclose((m[:, None] * sim.state.body.v).sum(0), p0, atol=1e-12)
    vx = [np.average(sim.state.body.v[s, 0], weights=m[s]) for s in (slice(0, n), slice(n, None))]
    assert vx[0] < 0 < vx[1]  # they bounced apart

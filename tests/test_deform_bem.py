"""physics.deform: BEM quadrature and assembly against analytic elastostatics, Green's
functions and their cache, and the capacitance-matrix algorithm against direct solves."""

from __future__ import annotations

import numpy as np
import pytest
import trimesh

from jassy.errors import JassyError
from physics.deform.bem import (
    SOFT_GEL_DENSITY,
    assemble,
    dof_columns,
    face_geometry,
    mesh_arrays,
    solve_mixed,
    solve_traction,
)
from physics.deform.capacitance import CapacitanceSolver, smw_solve
from physics.deform.greens import reference_greens
from physics.deform.quadrature import integrate
from physics.modal.materials import Material

MAT = Material("gel", 1e6, 0.3, SOFT_GEL_DENSITY)


def _sphere(sub, radius=1.0):
    m = trimesh.creation.icosphere(sub, radius=radius)
    return np.asarray(m.vertices), np.asarray(m.faces), np.asarray(m.vertex_normals)


def test_traction_kernel_integrates_to_minus_identity_inside():
    """For any interior source, the integral of p* over the closed surface is -I (outward
    normals); the points near the surface exercise the near-singular subdivision."""
    V, F, _ = _sphere(2)
    V, F = mesh_arrays(V, F)
    normals, areas = face_geometry(V, F)
    X = np.array([[0.0, 0.0, 0.0], [0.3, -0.2, 0.5], [0.0, 0.0, 0.9], [0.5, 0.5, 0.6]])
    H, _ = integrate(
        X, -np.ones(len(X), dtype=np.int64), V, F, normals, areas, MAT.shear_modulus, MAT.poisson
    )
    sums = H.reshape(len(X), 3, -1, 3).sum(axis=2)
    for s in sums:
        np.testing.assert_allclose(s, -np.eye(3), atol=1e-5)


def test_rigid_translation_gives_zero_traction():
    V, F, _ = _sphere(2, radius=0.1)
    H, G = assemble(V, F, MAT)
    n = len(V)
    c = np.array([1e-3, -2e-3, 0.5e-3])
    assert np.abs(H @ np.tile(c, n)).max() < 1e-12 * np.abs(H).max() * 1e-3
    # Dirichlet problem: every vertex translated by c
    u, p = solve_mixed(H, G, np.ones(n, dtype=bool), np.tile(c, (n, 1)))
    scale = MAT.youngs * np.linalg.norm(c) / 0.1
    assert np.abs(p).max() < 1e-9 * scale
    # mixed: the base translated, the rest traction-free -> the whole body translates
    base = V[:, 2] < -0.08
    u, p = solve_mixed(H, G, base, np.where(base[:, None], c, 0.0))
    np.testing.assert_allclose(u, np.tile(c, (n, 1)), atol=1e-9 * np.linalg.norm(c))
    assert np.abs(p).max() < 1e-9 * scale


def _pressure_error(sub):
    """Max displacement error (relative to |u_r|) of a unit sphere under uniform pressure:
    u = -p (1 - 2 nu) x / E, rigid modes removed."""
    V, F, N = _sphere(sub)
    H, G = assemble(V, F, MAT)
    p = 1e3
    u = solve_traction(H, G, V, -p * N)
    scale = p * (1 - 2 * MAT.poisson) / MAT.youngs
    return np.abs(u + scale * V).max() / scale


def test_sphere_under_pressure_converges():
    errors = [_pressure_error(sub) for sub in (1, 2, 3)]
    assert errors[0] > errors[1] > errors[2]
    assert errors[2] < 2e-3 and errors[0] / errors[2] > 10


def _uniaxial_error(sub):
    """Sphere with its bottom cap displaced as the uniaxial-stress field (sigma_zz = s) and
    the exact traction sigma n elsewhere: max error of u (relative) and of the cap tractions."""
    V, F, N = _sphere(sub)
    H, G = assemble(V, F, MAT)
    s = 2e3
    strain = np.diag([-MAT.poisson * s / MAT.youngs, -MAT.poisson * s / MAT.youngs, s / MAT.youngs])
    exact_u = V @ strain
    exact_p = np.zeros_like(V)
    exact_p[:, 2] = s * N[:, 2]
    base = V[:, 2] < -0.7
    u, p = solve_mixed(H, G, base, np.where(base[:, None], exact_u, exact_p))
    return np.abs(u - exact_u).max() / (s / MAT.youngs), np.abs(p[base] - exact_p[base]).max() / s


def test_mixed_uniaxial_field_converges():
    errs = np.array([_uniaxial_error(sub) for sub in (1, 2, 3)])
    assert np.all(np.diff(errs[:, 0]) < 0)
    assert errs[2, 0] < 5e-3 and errs[2, 1] < 2e-2


@pytest.fixture(scope="module")
def ball(tmp_path_factory):
    """A 162-vertex ball of radius 5 cm with its bottom cap fixed, H, G and Green's functions."""
    V, F, _ = _sphere(2, radius=0.05)
    mat = Material("gel", 2e5, 0.4, SOFT_GEL_DENSITY)
    fixed = V[:, 2] < -0.04
    H, G = assemble(V, F, mat)
    g = reference_greens(V, F, mat, fixed, cache_dir=tmp_path_factory.mktemp("greens"))
    return V, F, mat, fixed, H, G, g


def test_greens_functions_reproduce_the_reference_problem(ball):
    V, F, mat, fixed, H, G, g = ball
    rng = np.random.default_rng(1)
    loads = rng.normal(0, 50.0, (len(V), 3))
    loads[fixed] = 0.0
    u_direct, p_direct = solve_mixed(H, G, fixed, loads)
    v = g.xi @ loads[g.free].ravel()
    np.testing.assert_allclose(
        v.reshape(-1, 3)[~fixed], u_direct[~fixed], rtol=0, atol=1e-10 * np.abs(u_direct).max()
    )
    np.testing.assert_allclose(
        v.reshape(-1, 3)[fixed], p_direct[fixed], rtol=0, atol=1e-10 * np.abs(p_direct).max()
    )


def test_smw_equals_direct_solve_of_switched_system(ball):
    V, F, mat, fixed, H, G, g = ball
    rng = np.random.default_rng(2)
    for s in (1, 4, 9):
        S = rng.choice(g.free, s, replace=False)
        uS = rng.normal(0, 1e-3, (s, 3))
        loads = rng.normal(0, 20.0, (len(V), 3))
        u, p = smw_solve(g, S, uS, loads)
        switched = fixed.copy()
        switched[S] = True
        vals = np.where(fixed[:, None], 0.0, loads)
        vals[S] = uS
        u2, p2 = solve_mixed(H, G, switched, vals)
        assert np.abs(u - u2).max() <= 1e-10 * np.abs(u2).max()
        assert np.abs(p - p2).max() <= 1e-10 * np.abs(p2).max()


def test_capacitance_solver_forces_displacements_and_reuse(ball):
    V, F, mat, fixed, H, G, g = ball
    rng = np.random.default_rng(3)
    S = np.sort(rng.choice(g.free, 5, replace=False))
    uS = rng.normal(0, 1e-3, (5, 3))
    u_ref, p_ref = smw_solve(g, S, uS)
    cs = CapacitanceSolver(g)
    assert cs.set_contacts(S)
    forces = cs.solve(uS)
    np.testing.assert_allclose(
        forces, g.areas[S, None] * p_ref[S], rtol=1e-10, atol=1e-12 * np.abs(forces).max()
    )
    np.testing.assert_allclose(cs.displacements(forces), u_ref, atol=1e-10 * np.abs(u_ref).max())
    assert not cs.set_contacts(S) and cs.refactors == 1
    assert cs.set_contacts(S[:3]) and cs.refactors == 2


def test_vertex_masks_match_a_direct_constrained_solve(ball):
    """Masked constraints (traction tau F over the mask, mean displacement prescribed) against
    a dense solve of H u = G p with the constraint rows appended (Lagrange form)."""
    V, F, mat, fixed, H, G, g = ball
    n = len(V)
    cs = CapacitanceSolver(g, mask_radius=0.02)
    S = np.array([g.free[np.argmax(V[g.free, 2])], g.free[np.argmax(V[g.free, 0])]])
    uS = np.array([[0.0, 0.0, -2e-3], [-1e-3, 5e-4, 0.0]])
    cs.set_contacts(S)
    forces = cs.solve(uS)
    assert np.all(np.diff(cs.ptr)[S] > 3)  # the masks span several vertices
    free, fx = g.free, np.flatnonzero(fixed)
    cu, cp = dof_columns(n, free), dof_columns(n, fx)
    A = np.zeros((3 * n + 6, 3 * n + 6))
    b = np.zeros(3 * n + 6)
    A[: 3 * n, : cu.size] = H[:, cu]
    A[: 3 * n, cu.size : 3 * n] = -G[:, cp]
    for a, c in enumerate(S):
        sl = slice(cs.ptr[c], cs.ptr[c + 1])
        verts = cs.verts[sl]
        pos = np.searchsorted(free, verts)
        for k in range(3):
            A[: 3 * n, 3 * n + 3 * a + k] = -(G[:, 3 * verts + k] @ cs.tau[sl])
            A[3 * n + 3 * a + k, 3 * pos + k] = cs.omega[sl]
        b[3 * n + 3 * a : 3 * n + 3 * a + 3] = uS[a]
    x = np.linalg.solve(A, b)
    np.testing.assert_allclose(forces, x[3 * n :].reshape(2, 3), rtol=1e-9, atol=1e-9 * np.abs(forces).max())
    u = cs.displacements(forces)
    np.testing.assert_allclose(u[free], x[: cu.size].reshape(-1, 3), atol=1e-9 * np.abs(u).max())


def test_greens_cache_round_trip(tmp_path):
    V, F, _ = _sphere(1, radius=0.05)
    mat = Material("gel", 2e5, 0.4, SOFT_GEL_DENSITY)
    fixed = V[:, 2] < -0.03
    g1 = reference_greens(V, F, mat, fixed, cache_dir=tmp_path)
    files = list(tmp_path.glob("*.npz"))
    assert not g1.from_cache and [f.name for f in files] == [f"{g1.key}.npz"]
    g2 = reference_greens(V, F, mat, fixed, cache_dir=tmp_path)
    assert g2.from_cache and np.array_equal(g1.xi, g2.xi)
    g3 = reference_greens(V, F, Material("gel", 2e5, 0.3, SOFT_GEL_DENSITY), fixed, cache_dir=tmp_path)
    assert not g3.from_cache and g3.key != g1.key
    g4 = reference_greens(V, F, mat, np.flatnonzero(fixed)[:-1], cache_dir=tmp_path)
    assert g4.key not in (g1.key, g3.key)
    files[0].write_bytes(b"not an npz")
    g5 = reference_greens(V, F, mat, fixed, cache_dir=tmp_path)
    assert not g5.from_cache and np.array_equal(g5.xi, g1.xi)
    assert reference_greens(V, F, mat, fixed, cache_dir=tmp_path).from_cache


def test_bad_input_raises():
    V, F, _ = _sphere(1)
    with pytest.raises(JassyError, match="nu"):
        Material("gel", 1e6, 0.5, SOFT_GEL_DENSITY)
    with pytest.raises(JassyError, match="E"):
        Material("gel", -1.0, 0.3, SOFT_GEL_DENSITY)
    with pytest.raises(JassyError, match="closed"):
        mesh_arrays(V, F[:-1])
    with pytest.raises(JassyError, match="outward"):
        mesh_arrays(V, F[:, ::-1])
    with pytest.raises(JassyError, match="fixed"):
        reference_greens(V, F, MAT, [0, 1], use_cache=False)

"""Finite element modes from meshes (physics.modal): element, voxels, solver, validation
against Euler-Bernoulli and Lamb's sphere, gains, texture maps, materials, CLI, shipped bowl."""

from __future__ import annotations

import argparse
from pathlib import Path

import numpy as np
import pytest

from jassy import ModalModel
from jassy.errors import JassyError
from physics.modal import analytic, fem, meshes, solver
from physics.modal.materials import MATERIALS, Material, material
from physics.modal.subdivision import SurfaceMap, loop_subdivide, subdivide_values, surface_frames

ALU = material("aluminium")


# ----------------------------------------------------------------------------- element


@pytest.mark.parametrize("incompatible", [True, False])
def test_hex_element_rigid_modes_and_constant_strain(incompatible):
    k1, m1 = fem.hex_matrices(0.3, incompatible)
    np.testing.assert_allclose(k1, k1.T, atol=1e-14)
    w = np.linalg.eigvalsh(k1)
    assert np.all(np.abs(w[:6]) < 1e-12) and w[6] > 1e-3  # exactly six rigid-body modes
    assert abs(m1.sum() / 3 - 1.0) < 1e-12  # unit cube, unit density: mass 1 per direction
    # patch test: u = eps x gives energy 1/2 eps^T D eps V exactly (incompatible modes included)
    eps = np.array([1e-3, -2e-3, 5e-4, 3e-4, -1e-3, 2e-3])  # xx yy zz, engineering yz xz xy
    grad = np.array(
        [[eps[0], eps[5] / 2, eps[4] / 2], [eps[5] / 2, eps[1], eps[3] / 2], [eps[4] / 2, eps[3] / 2, eps[2]]]
    )
    u = (fem.CORNERS @ grad.T).ravel()  # corner coordinates in [0, 1]^3
    d = fem.elasticity_matrix(1.0, 0.3)
    assert abs(0.5 * u @ k1 @ u / (0.5 * eps @ d @ eps) - 1.0) < 1e-12


def test_incompatible_element_bends_exactly_and_trilinear_locks():
    """One cube in pure bending u = -xz, w = x^2/2: incompatible modes recover the exact
    energy of the bending field; trilinear shape functions add parasitic shear."""
    x = fem.CORNERS.astype(float) - 0.5
    u = np.column_stack([-x[:, 0] * x[:, 2], np.zeros(8), 0.5 * x[:, 0] ** 2]).ravel()
    nu = 0.0  # no Poisson coupling: exact energy = 1/2 E I kappa^2 L = 1/2 * 1/12
    exact = 0.5 / 12
    k_inc, _ = fem.hex_matrices(nu, True)
    k_tri, _ = fem.hex_matrices(nu, False)
    assert abs(0.5 * u @ k_inc @ u / exact - 1) < 1e-12
    assert 0.5 * u @ k_tri @ u / exact > 1.5


# ----------------------------------------------------------------------------- voxels


def test_voxelise_box_exactly_and_sphere_volume():
    grid = fem.voxelize(meshes.bar(0.3, 0.012, 0.006), 0.003)
    assert grid.filled.shape == (100, 4, 2) and grid.n_elements == 800 and grid.dropped == 0
    a, pitch = 0.05, 0.005
    sph = fem.voxelize(meshes.sphere(a, 5), pitch)
    assert abs(sph.n_elements * pitch**3 / (4 / 3 * np.pi * a**3) - 1) < 0.03
    c = sph.centres()
    assert np.all(np.linalg.norm(c, axis=1) < a)  # every voxel centre is inside


def test_open_mesh_and_bad_pitch_are_rejected(tmp_path):
    import trimesh

    box = meshes.bar()
    small_hole = trimesh.Trimesh(box.vertices, box.faces[1:])
    meshes.check_closed(small_hole)  # a one-triangle hole is filled
    assert small_hole.is_watertight
    open_box = trimesh.Trimesh(box.vertices, box.faces[:6])  # half the box
    open_box.export(tmp_path / "open.stl")
    with pytest.raises(JassyError, match="not watertight"):
        meshes.load_mesh(tmp_path / "open.stl")
    (tmp_path / "junk.obj").write_text("this is not a mesh\n")
    with pytest.raises(JassyError, match="junk.obj"):
        meshes.load_mesh(tmp_path / "junk.obj")
    with pytest.raises(JassyError, match="pitch: expected a length > 0"):
        fem.voxelize(meshes.bar(), -1.0)
    with pytest.raises(JassyError, match="no voxel centre"):
        fem.voxelize(meshes.bar(0.3, 0.012, 0.006), 0.05)


def test_pitch_for_elements_keeps_thickness_whole():
    bar = meshes.bar(0.3, 0.012, 0.006)
    p = fem.pitch_for_elements(bar, 4000)
    assert abs(0.006 / p - round(0.006 / p)) < 1e-9


# ----------------------------------------------------------------------------- assembly and solver


def small_model(pitch=0.003):
    return fem.assemble(fem.voxelize(meshes.bar(0.06, 0.012, 0.006), pitch), ALU)


def test_assembly_mass_and_rigid_motions():
    model = small_model()
    n = model.nodes.shape[0]
    ux = np.zeros(3 * n)
    ux[0::3] = 1.0
    assert abs(ux @ model.mass @ ux - ALU.density * 0.06 * 0.012 * 0.006) < 1e-12
    rot = np.zeros((n, 3))  # small rotation about z: u = (-y, x, 0)
    rot[:, 0], rot[:, 1] = -model.nodes[:, 1], model.nodes[:, 0]
    f = model.stiffness @ rot.ravel()
    assert np.max(np.abs(f)) < 1e-6 * abs(model.stiffness).max() * 0.06


def test_multifrontal_cholesky_solves_like_scipy():
    from scipy.sparse.linalg import spsolve

    model = small_model()
    a = (model.stiffness + 1e6 * model.mass).tocsc()
    coords = np.rint((model.nodes - model.grid.origin) / model.grid.pitch).astype(int)
    order, tree = solver.nested_dissection(coords, leaf=8)
    assert np.array_equal(np.sort(order), np.arange(model.nodes.shape[0]))
    chol = solver.MultifrontalCholesky(a, order, tree, fem.node_adjacency(model))
    rhs = np.random.default_rng(0).standard_normal((a.shape[0], 3))
    x = chol.solve(rhs)
    ref = np.column_stack([spsolve(a, rhs[:, i]) for i in range(3)])
    assert np.linalg.norm(x - ref) < 1e-9 * np.linalg.norm(ref)
    assert np.linalg.norm(chol.solve(rhs[:, 0]) - ref[:, 0]) < 1e-9 * np.linalg.norm(ref[:, 0])


def test_eigensolver_matches_scipy_eigsh():
    from scipy.sparse.linalg import eigsh

    model = small_model()
    modes = fem.solve(model, 10)
    sigma = fem.default_shift(model)
    ref = np.sort(eigsh(model.stiffness, k=16, M=model.mass, sigma=sigma, which="LM")[0])[6:]
    np.testing.assert_allclose((2 * np.pi * modes.frequencies) ** 2, ref, rtol=1e-9)
    gram = modes.shapes.T @ (model.mass @ modes.shapes)
    np.testing.assert_allclose(gram, np.eye(10), atol=1e-8)
    assert np.all(np.abs(modes.rigid) < 1e-6 * ref[0])


# ----------------------------------------------------------------------------- validation


def bending_modes(model, modes, axis=2, count=3):
    """Frequencies of the first ``count`` modes whose displacement is mostly along ``axis``."""
    u = modes.shapes.reshape(-1, 3, modes.shapes.shape[1])
    dominant = np.argmax((u**2).sum(axis=0), axis=0) == axis
    return modes.frequencies[dominant][:count]


def test_free_free_bar_against_euler_bernoulli_and_convergence():
    """A 300 x 12 x 6 mm aluminium bar, bending across the 6 mm side: within 2 % of
    Euler-Bernoulli (beta L = 4.7300, 7.8532, 10.9956) at pitch h/2 (800 elements); the
    successive changes under refinement (h/1, h/2, h/3) shrink. (The converged 3D values lie
    0.1-0.7 % below Euler-Bernoulli: shear and rotary inertia, as Timoshenko predicts.)"""
    length, width, h = 0.3, 0.012, 0.006
    expected = analytic.free_free_beam_frequencies(length, width, h, ALU.youngs, ALU.density)
    results = []
    for div in (1, 2, 3):
        model = fem.assemble(fem.voxelize(meshes.bar(length, width, h), h / div), ALU)
        results.append(bending_modes(model, fem.solve(model, 12)))
    err = results[1] / expected - 1
    assert np.all(np.abs(err) < 0.02), err
    assert np.all(err < 0) and np.all(np.diff(np.abs(err)) > 0)  # Timoshenko: below, growing with n
    step1, step2 = np.abs(results[1] - results[0]), np.abs(results[2] - results[1])
    assert np.all(step2 < step1)


def test_trilinear_hexahedra_lock_in_bending():
    length, width, h = 0.3, 0.012, 0.006
    expected = analytic.free_free_beam_frequencies(length, width, h, ALU.youngs, ALU.density)
    model = fem.assemble(fem.voxelize(meshes.bar(length, width, h), h / 2), ALU, incompatible=False)
    err = bending_modes(model, fem.solve(model, 12)) / expected - 1
    assert np.all(err > 0.04)  # too stiff: why the incompatible modes are used


def test_analytic_references():
    np.testing.assert_allclose(analytic.free_free_beta_l(3), [4.7300407, 7.8532046, 10.9956078], atol=1e-6)
    assert abs(analytic.sphere_torsional_roots(2)[0] - 2.5011) < 1e-4  # Lamb 1882
    assert abs(analytic.sphere_spheroidal_roots(2, 0.25)[0] - 2.6399) < 1e-3  # Lamb: 2.640 at nu = 1/4
    # the n = 0 (breathing) root satisfies the textbook form tan(xi)/xi = 1/(1 - xi^2 c_p^2/(4 c_s^2))
    nu = 0.3
    ratio = np.sqrt((1 - 2 * nu) / (2 * (1 - nu)))
    xi = analytic.sphere_spheroidal_roots(0, nu)[0] * ratio
    assert abs(np.tan(xi) / xi - 1 / (1 - xi**2 / (4 * ratio**2))) < 1e-9


def test_sphere_against_lamb_and_convergence():
    """A free steel sphere (nu = 0.3): the 5-fold torsional n = 2 and spheroidal n = 2 modes
    (x = omega a / c_s = 2.5011 and 2.6462, Lamb 1882). The voxel staircase converges at first
    order: torsional -3.2 % at a/6, -2.6 % at a/8 (-1.0 % at a/12); spheroidal within 1 %."""
    a, nu = 0.05, 0.3
    steel = material("steel", poisson=nu)
    ft = analytic.sphere_frequency(analytic.sphere_torsional_roots(2)[0], a, steel.youngs, nu, steel.density)
    fs = analytic.sphere_frequency(
        analytic.sphere_spheroidal_roots(2, nu)[0], a, steel.youngs, nu, steel.density
    )
    errs = []
    for div in (6, 8):
        model = fem.assemble(fem.voxelize(meshes.sphere(a, 5), a / div), steel)
        f = fem.solve(model, 10).frequencies
        errs.append((f[:5].mean() / ft - 1, f[5:10].mean() / fs - 1))
    (t6, s6), (t8, s8) = errs
    assert abs(t8) < abs(t6) < 0.04 and abs(t8) < 0.03
    assert abs(s6) < 0.01 and abs(s8) < 0.01


# ----------------------------------------------------------------------------- gains


def test_bar_gains_match_the_euler_bernoulli_driving_point_response():
    """Mode 1 at the free end: (n.phi)^2/omega = W(0)^2 / (m omega) with W(0) = 2 for the
    mode normalised to int W^2 = L; the centre/end ratio is the squared shape ratio; the
    centre is a node of the antisymmetric mode."""
    length, width, h = 0.3, 0.012, 0.006
    pts = {"end": (length / 2, 0.0, h / 2), "centre": (0.0, 0.0, h / 2)}
    model, report, surface = fem.modes_from_mesh(
        meshes.bar(length, width, h), ALU, n_modes=4, pitch=h / 2, points=pts
    )
    assert surface is None and model.points == ("end", "centre")
    mass = ALU.density * length * width * h
    f1 = model.frequencies[0]
    assert abs(model.gains[0, 0] / (4 / (mass * 2 * np.pi * f1)) - 1) < 0.02
    x = 4.730040745
    sigma = (np.cosh(x) - np.cos(x)) / (np.sinh(x) - np.sin(x))
    shape_mid = np.cosh(x / 2) + np.cos(x / 2) - sigma * (np.sinh(x / 2) + np.sin(x / 2))
    assert abs(model.gains[1, 0] / model.gains[0, 0] / (shape_mid / 2) ** 2 - 1) < 0.01
    # mode 1 bends in the width (y) direction: no normal motion of the top face; mode 2 (the
    # first antisymmetric bending mode across the thickness) has a node at the centre
    assert model.gains[0, 1] < 1e-12 * model.gains[0, 0]
    assert model.gains[1, 2] < 1e-6 * model.gains[0, 2]
    np.testing.assert_allclose(model.decays, ALU.decay(model.frequencies))


def test_radiation_and_normalisation():
    bar = meshes.bar(0.3, 0.012, 0.006)
    pts = {"end": (0.15, 0.0, 0.003)}
    disp, _, _ = fem.modes_from_mesh(bar, ALU, n_modes=3, pitch=0.003, points=pts)
    vel, _, _ = fem.modes_from_mesh(bar, ALU, n_modes=3, pitch=0.003, points=pts, radiation="velocity")
    np.testing.assert_allclose(vel.gains, disp.gains * 2 * np.pi * disp.frequencies, rtol=1e-9)
    norm, rep, _ = fem.modes_from_mesh(bar, ALU, n_modes=3, pitch=0.003, points=pts, normalise=True)
    assert abs(np.max(np.abs(norm.gains)) - 1) < 1e-12
    np.testing.assert_allclose(norm.gains / rep.gain_scale, disp.gains, rtol=1e-9)
    with pytest.raises(JassyError, match="--radiation"):
        fem.modes_from_mesh(bar, ALU, n_modes=3, pitch=0.003, radiation="loud")


def test_square_bar_keeps_degenerate_bending_pairs_with_their_own_gains():
    """A 300 x 10 x 10 mm bar bends alike across y and z: each bending frequency is a pair
    (multiplicity 2) within 2 % of Euler-Bernoulli, kept as two modes. Struck on the top
    face at the end, only the pair's z-bending mode rings, with the Euler-Bernoulli
    driving-point gain W(0)^2 / (m omega) = 4 / (m omega); on the side face at the end only
    the other (y-bending) mode rings, with the same gain."""
    length, h = 0.3, 0.01
    pts = {"top": (length / 2, 0.0, h / 2), "side": (length / 2, h / 2, 0.0)}
    model, report, _ = fem.modes_from_mesh(meshes.bar(length, h, h), ALU, n_modes=6, pitch=h / 2, points=pts)
    expected = analytic.free_free_beam_frequencies(length, h, h, ALU.youngs, ALU.density)
    groups = fem.degenerate_groups(model.frequencies)
    pairs = [g for g in groups if g.size == 2]
    assert len(pairs) >= 2 and report.multiplicity[pairs[0][0]] == 2
    assert "2 pairs" in report.families() or "3 pairs" in report.families()
    mass = ALU.density * length * h * h
    for g, f_eb in zip(pairs[:2], expected[:2], strict=True):
        f = model.frequencies[g]
        assert abs(f[1] / f[0] - 1) < 1e-6 and abs(f[0] / f_eb - 1) < 0.02
        top, side = model.gains[0, g], model.gains[1, g]
        ref = 4 / (mass * 2 * np.pi * f[0])
        assert abs(top[0] / ref - 1) < 0.03 and top[1] < 1e-9 * top[0]
        assert abs(side[1] / ref - 1) < 0.03 and side[0] < 1e-6 * side[1]


def test_align_degenerate_rotates_only_families():
    """A family's normal displacements are rotated (orthogonally) so the first point moves
    one mode; sums of squares per point are unchanged, single modes untouched."""
    rng = np.random.default_rng(1)
    un = rng.standard_normal((4, 5))
    groups = fem.degenerate_groups(
        np.array([100.0, 200.0, 200.0 * (1 + 1e-9), 200.0 * (1 - 1e-10) + 1e-7, 300.0])
    )
    assert [g.tolist() for g in groups] == [[0], [1, 2, 3], [4]]
    out = fem.align_degenerate(un, groups)
    np.testing.assert_allclose(out[:, [0, 4]], un[:, [0, 4]])
    np.testing.assert_allclose(out[0, 2:4], 0.0, atol=1e-12)
    assert out[0, 1] > 0
    np.testing.assert_allclose((out[:, 1:4] ** 2).sum(axis=1), (un[:, 1:4] ** 2).sum(axis=1), rtol=1e-12)


# ----------------------------------------------------------------------------- texture maps


def test_loop_subdivision_of_values_is_consistent_with_geometry():
    mesh = meshes.sphere(0.05, 1)
    refined, counts = loop_subdivide(mesh, 2)
    assert counts == [len(mesh.vertices), len(refined.vertices)] or len(counts) == 3
    np.testing.assert_allclose(subdivide_values(mesh, mesh.vertices, 2), refined.vertices, atol=1e-15)
    const = subdivide_values(mesh, np.full(len(mesh.vertices), 3.0), 2)
    np.testing.assert_allclose(const, 3.0)  # Loop stencils are affine (weights sum to 1)


def test_surface_map_interpolates_barycentrically():
    mesh = meshes.bar(0.3, 0.012, 0.006)
    smap = SurfaceMap(mesh)
    values = np.asarray(mesh.vertices)[:, 0:1] * 10 + 1  # linear in x: exact under interpolation
    for p in [(0.1, 0.001, 0.003), (-0.07, -0.006, 0.0005)]:
        loc = smap.location(p)
        assert abs(sum(loc["weights"]) - 1) < 1e-12 and len(loc["vertices"]) == 3
        assert abs(smap.interpolate(values, p)[0] - (10 * p[0] + 1)) < 1e-9
    close, normals = surface_frames(mesh, [[0.1, 0.0, 0.01], [0.2, 0.0, 0.0]])
    np.testing.assert_allclose(close, [[0.1, 0.0, 0.003], [0.15, 0.0, 0.0]], atol=1e-12)
    np.testing.assert_allclose(normals, [[0, 0, 1], [1, 0, 0]], atol=1e-12)  # creases keep face normals


def test_vertex_model_rows_are_the_sampled_surface_vertices():
    bar = meshes.bar(0.3, 0.012, 0.006)
    model, report, surface = fem.modes_from_mesh(bar, ALU, n_modes=3, pitch=0.003, subdivide=2)
    assert model.n_points == len(surface.vertices) == report.n_surface_points
    # every sampled vertex lies on the bar's surface
    v = np.asarray(surface.vertices)
    on_face = np.isclose(np.abs(v), [0.15, 0.006, 0.003], atol=1e-12).any(axis=1)
    assert on_face.all()


# ----------------------------------------------------------------------------- materials


def test_materials_table_and_damping_law():
    for name in ("steel", "aluminium", "glass", "wood", "ceramic", "plastic", "bone"):
        m = MATERIALS[name]
        assert m.youngs > 0 and 0 < m.poisson < 0.5 and m.density > 0
    m = Material("x", 1e9, 0.3, 1000.0, loss=1e-3, d0=2.0, beta=1e-7)
    f = np.array([100.0, 1000.0])
    np.testing.assert_allclose(m.decay(f), 2.0 + np.pi * 1e-3 * f + 0.5e-7 * (2 * np.pi * f) ** 2)
    assert material("Steel", density=7000.0).density == 7000.0
    with pytest.raises(JassyError, match="unknown material 'gold'"):
        material("gold")
    with pytest.raises(JassyError, match="poisson: expected in"):
        material("steel", poisson=0.5)


# ----------------------------------------------------------------------------- CLI


def run_cli(argv):
    from jassy.apps.cli import main

    return main(argv)


def test_modes_command_writes_a_model(tmp_path, capsys):
    out = tmp_path / "bar.toml"
    surf = tmp_path / "bar.ply"
    rc = run_cli(["modes", "bar", "--material", "aluminium", "-o", str(out), "--modes", "4",
                  "--pitch", "0.003", "--subdivide", "1", "--surface", str(surf)])  # fmt: skip
    assert rc == 0
    model = ModalModel.load(out)
    assert model.n_modes == 4 and surf.is_file()
    assert "4 modes" in capsys.readouterr().out
    rc = run_cli(["modes", "bar", "-o", str(tmp_path / "p.npz"), "--modes", "3", "--pitch", "0.003",
                  "--point", "end=0.15,0,0.003", "--loss", "0.01", "-q"])  # fmt: skip
    model = ModalModel.load(tmp_path / "p.npz")
    assert rc == 0 and model.points == ("end",)
    np.testing.assert_allclose(model.decays, material("steel", loss=0.01).decay(model.frequencies))


def test_modes_command_reads_mesh_files(tmp_path):
    path = tmp_path / "bar_mm.stl"
    meshes.bar(300.0, 12.0, 6.0).export(path)
    out = tmp_path / "m.toml"
    assert run_cli(["modes", str(path), "--scale", "0.001", "--material", "aluminium", "-o", str(out),
                    "--modes", "3", "--pitch", "0.003", "-q"]) == 0  # fmt: skip
    f1 = analytic.free_free_beam_frequencies(0.3, 0.012, 0.006, ALU.youngs, ALU.density)[0]
    assert abs(ModalModel.load(out).frequencies[0] / f1 - 1) < 0.02


@pytest.mark.parametrize(
    "argv, message",
    [
        (["modes", "missing.obj", "-o", "x.toml"], "no such mesh file"),
        (["modes", "bar", "-o", "x.wav"], "expected a .toml or .npz"),
        (["modes", "bar", "-o", "x.toml", "--material", "gold"], "unknown material"),
        (["modes", "bar", "-o", "x.toml", "--modes", "0"], "--modes: expected an integer > 0"),
        (["modes", "bar", "-o", "x.toml", "--point", "a=1,2"], "--point: expected NAME=X,Y,Z"),
        (["modes", "bar", "-o", "x.toml", "--pitch", "0.01", "--elements", "10"], "give one of them"),
    ],
)
def test_modes_command_errors_exit_2(argv, message, capsys, tmp_path, monkeypatch):
    monkeypatch.chdir(tmp_path)
    assert run_cli(argv) == 2
    err = capsys.readouterr().err
    assert message in err and err.count("\n") == 1


def test_add_commands_and_describe_model(tmp_path):
    from physics.modal.cli import add_commands, describe_model

    parser = argparse.ArgumentParser()
    add_commands(parser.add_subparsers(dest="command"))
    args = parser.parse_args(["fit", "a.wav", "-o", "m.toml"])
    assert args.func.__name__ == "cmd_fit"
    m = ModalModel([100.0, 250.0], [1.0, 2.0], [[1.0, 0.5], [0.2, 0.1]], ("a", "b"), "demo")
    m.save(tmp_path / "demo.toml")
    text = describe_model(tmp_path / "demo.toml")
    assert "2 modes" in text and "100.00" in text and "250.00" in text and "T60" in text
    assert f"{np.log(1000) / 2.0:.3f}" in text  # T60 of the second mode
    pair = ModalModel(
        [100.0, 100.0, 250.0], [1.0, 1.0, 2.0], [[1.0, 0.0, 0.5]], attack=np.ones(48), attack_rate=48000.0
    )
    pair.save(tmp_path / "pair.toml")
    rows = describe_model(tmp_path / "pair.toml").splitlines()
    assert "attack: 48 samples (1.0 ms at 48000 Hz)" in rows
    assert [r.split()[2] for r in rows if r.split()[0] in ("0", "1")] == ["2", "2"]  # a pair: multiplicity 2
    with pytest.raises(JassyError):
        describe_model(tmp_path / "missing.toml")


# ----------------------------------------------------------------------------- shipped bowl


def test_shipped_bowl_model_is_the_builders_output():
    import patches
    from physics.modal.shipped import SHIPPED

    for filename, builder in SHIPPED.items():
        shipped = ModalModel.load(Path(patches.__file__).parent / filename)
        built = builder()
        np.testing.assert_allclose(shipped.frequencies, built.frequencies, rtol=1e-7)
        np.testing.assert_allclose(shipped.decays, built.decays, rtol=1e-7)
        np.testing.assert_allclose(
            shipped.gains, built.gains, rtol=1e-5, atol=1e-6 * np.abs(built.gains).max()
        )
        assert shipped.points == built.points


def test_bowl_patch_renders_the_computed_partials():
    from jassy.engines.offline import render
    from jassy.patchfile import load_patch

    patch = load_patch("bowl")
    model = ModalModel.load(Path(__import__("patches").__file__).parent / "bowl_model.toml")
    res = render(patch.graph, patch.score, 1.9, sample_rate=48000, block=256)
    x = res.audio[0][int(0.06 * 48000) :]
    assert -9.0 < 20 * np.log10(np.abs(x).max()) < -3.0
    spec = np.abs(np.fft.rfft(x * np.hanning(x.size)))
    freqs = np.fft.rfftfreq(x.size, 1 / 48000)
    top = freqs[np.argmax(spec)]
    assert np.min(np.abs(model.frequencies - top)) < 1.0  # the loudest partial is a computed mode
    assert model.frequencies[0] < top < model.frequencies[2]  # ... the fundamental doublet

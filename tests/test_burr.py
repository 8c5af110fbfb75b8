"""physics.burr (burr-bone contact, octree, erosion, descent) and ugens.drill.DrillSource."""

from __future__ import annotations

import math

import numpy as np
import pytest

from jassy import Event, Graph, render
from physics.burr.contact import R_VOXEL, brute_moments, cap_volume, depth_from_m0, lens_volume
from physics.burr.loop import BurrParams, BurrSim, descent_experiment
from physics.burr.octree import Octree
from physics.burr.volume import Volume, phantom, uniform_block


def _plane_volume(n, unit, offset):
    """255 where (x - centre) . unit <= offset (grid units), else 0."""
    g = np.indices((n, n, n)).reshape(3, -1).T - (n - 1) / 2
    d = (g @ unit <= offset).reshape(n, n, n).astype(np.uint8) * 255
    return d


def test_lens_volume_reference_values_and_monte_carlo():
    for d, ref in [(0.8, 0.102265), (1.0, 0.050187), (1.2, 0.006741)]:
        assert lens_volume(d, 1.0, 0.3) == pytest.approx(ref, abs=2e-6)
    rng = np.random.default_rng(0)
    p = rng.uniform(-0.3, 0.3, (400000, 3))
    p = p[np.sum(p * p, 1) <= 0.09]
    frac = np.mean(np.sum((p + [0.9, 0, 0]) ** 2, 1) <= 1.0)
    assert lens_volume(0.9, 1.0, 0.3) == pytest.approx(frac * 4 / 3 * math.pi * 0.027, rel=0.01)
    assert lens_volume(0.5, 1.0, 0.3) == pytest.approx(4 / 3 * math.pi * 0.027)
    assert lens_volume(1.3, 1.0, 0.3) == 0.0


def test_depth_inverts_cap_formula():
    R = 2.0
    for h in np.linspace(0, 2 * R, 17):
        assert depth_from_m0(cap_volume(h, R) * 7.0, 7.0, R) == pytest.approx(h, abs=1e-9)


@pytest.mark.parametrize("R", [6.0, 14.0])
def test_half_space_m0_matches_cap_and_normal(R):
    """Uniform half-space: m0 = pi rho0 R^3 (h/R)^2 (1 - h/3R) and n = plane normal, for several
    depths and orientations. Stated bound: |h error| <= 0.25 voxel, angle <= 2/R rad."""
    n = int(4 * R + 6)
    rng = np.random.default_rng(1)
    errs = []
    for unit in [np.array([0, 0, 1.0]), np.array([1.0, 1, 1]) / math.sqrt(3), rng.normal(size=3)]:
        unit = unit / np.linalg.norm(unit)
        d = _plane_volume(n, unit, 0.0)
        c0 = np.full(3, (n - 1) / 2)
        for h_over_R in (0.1, 0.3, 0.5, 1.0, 1.5):
            centre = c0 + unit * (R - h_over_R * R)
            out = np.zeros(4)
            brute_moments(d, *centre, R, out)
            h = depth_from_m0(out[0], 255.0, R)
            errs.append(abs(h - h_over_R * R))
            normal = -out[1:] / np.linalg.norm(out[1:])
            assert math.acos(min(1.0, normal @ unit)) < 2.0 / R
    assert max(errs) < 0.25


def test_half_space_error_converges_with_resolution():
    """Same physical burr, finer voxels: relative m0 error at h/R = 0.3 shrinks."""
    unit = np.array([0.3, -0.5, 0.81])
    unit /= np.linalg.norm(unit)
    rel = []
    for R in (4.0, 8.0, 16.0):
        n = int(4 * R + 6)
        d = _plane_volume(n, unit, 0.0)
        errs = []
        for shift in np.linspace(0, 1, 5):  # average over sub-voxel placements
            centre = np.full(3, (n - 1) / 2) + unit * (0.7 * R + shift)
            out = np.zeros(4)
            brute_moments(d, *centre, R, out)
            h = R - 0.7 * R - shift
            errs.append(abs(out[0] / (255 * cap_volume(h, R)) - 1))
        rel.append(np.mean(errs))
    assert rel[2] < rel[1] < rel[0]


def test_normal_of_a_sphere_points_to_the_burr():
    n, Rb = 48, 14.0
    g = np.indices((n, n, n)) - (n - 1) / 2
    d = ((g**2).sum(0) <= Rb * Rb).astype(np.uint8) * 200
    sim = BurrSim(Volume(d, 1e-4), BurrParams(radius=6e-4))
    for u in [np.array([0, 0, 1.0]), np.array([1.0, -1, 0.5])]:
        u /= np.linalg.norm(u)
        centre = sim.volume.to_world(np.full(3, (n - 1) / 2) + u * (Rb + 6.0 - 2.0))
        s = sim.step(centre, erode=False)
        assert math.acos(min(1.0, s.normal @ u)) < 0.05
        assert s.elastic @ u > 0


def test_force_grows_as_h_to_three_halves():
    vol = uniform_block((48, 48, 48), 1e-4, 255, top=30)
    sim = BurrSim(vol, BurrParams(radius=1.2e-3))
    surf = 30.5e-4
    fs, hs = [], []
    for h in (0.1e-3, 0.2e-3, 0.4e-3, 0.8e-3):
        s = sim.step([2.4e-3, 2.4e-3, surf + 1.2e-3 - h], erode=False)
        fs.append(np.linalg.norm(s.elastic))
        hs.append(h)
        assert s.depth == pytest.approx(h, abs=0.25e-4)
    slope = np.polyfit(np.log(hs), np.log(fs), 1)[0]
    assert slope == pytest.approx(1.5, abs=0.05)
    assert fs[2] == pytest.approx(5e6 * 1.2e-3**2 * (0.4 / 1.2) ** 1.5, rel=0.05)


def test_fully_immersed_burr_has_no_normal_and_full_depth():
    vol = uniform_block((40, 40, 40), 1e-4, 255)
    sim = BurrSim(vol, BurrParams(radius=1e-3))
    s = sim.step(vol.to_world([19.5, 19.5, 19.5]), omega=(0, 0, 3000.0), erode=False)
    assert np.all(s.normal == 0) and np.all(s.elastic == 0)
    assert s.depth == pytest.approx(2e-3, rel=1e-6)
    assert s.power > 0  # the load still cuts all around


def test_octree_equals_brute_force_on_random_volumes():
    rng = np.random.default_rng(3)
    for shape in [(37, 41, 29), (64, 20, 33)]:
        d = rng.integers(0, 256, shape).astype(np.uint8)
        d[rng.random(shape) < 0.3] = 0
        o = Octree(d)
        out = np.zeros(4)
        for _ in range(6):
            c = rng.uniform(-3, np.array(shape) + 3)
            R = rng.uniform(1.5, 12.0)
            brute_moments(d, *c, R, out)
            m, _ = o.moments(c, R, 1)
            np.testing.assert_allclose(m, out, rtol=1e-10, atol=1e-6 * max(1.0, out[0]))


def test_octree_partial_volume_bound_on_smooth_volume():
    """leaf=4 partial-volume rule on a half-space: m0 within 3 % (stated bound ~ leaf/R times
    the shell share) and the normal within 3 degrees, at R = 16 voxels."""
    n, R = 64, 16.0
    unit = np.array([0.2, 0.4, 0.89])
    unit /= np.linalg.norm(unit)
    d = _plane_volume(n, unit, 0.0)
    o = Octree(d)
    out = np.zeros(4)
    for hr in (0.3, 0.7, 1.2):
        c = np.full(3, (n - 1) / 2) + unit * (R - hr * R)
        brute_moments(d, *c, R, out)
        m, _ = o.moments(c, R, 4)
        assert m[0] == pytest.approx(out[0], rel=0.03)
        cosang = -(m[1:] @ unit) / np.linalg.norm(m[1:])
        assert cosang > math.cos(math.radians(3))


def test_octree_coarse_leaf_is_exact_where_the_burr_barely_touches():
    """leaf=4 at 0.5-1 voxel depth into a half-space (axis-aligned and oblique, several
    offsets and lateral positions): the blocks the burr barely reaches or that hold a density
    gradient are refined to voxels, so m0 and m1 equal the brute-force sum (bound 5 %, 1e-9
    measured) and so does the recovered depth."""
    n, R = 48, 15.0
    rng = np.random.default_rng(7)
    for unit in ([0.0, 0.0, 1.0], [0.2, 0.4, 0.89], [0.1, -0.3, 0.95]):
        unit = np.array(unit) / np.linalg.norm(unit)
        for offset in (0.0, 0.3, 1.7):
            d = _plane_volume(n, unit, offset)
            o = Octree(d)
            out = np.zeros(4)
            for h in (0.5, 0.6, 0.75, 1.0):
                lateral = rng.uniform(-2, 2, 3)
                lateral -= (lateral @ unit) * unit
                c = np.full(3, (n - 1) / 2) + unit * (offset + R - h) + lateral
                brute_moments(d, *c, R, out)
                m, _ = o.moments(c, R, 4)
                assert m[0] == pytest.approx(out[0], rel=0.05)
                np.testing.assert_allclose(m, out, rtol=1e-9, atol=1e-9 * max(out[0], 1.0))
                assert depth_from_m0(m[0], 255.0, R) == pytest.approx(
                    depth_from_m0(out[0], 255.0, R), abs=1e-6
                )


def test_octree_coarse_leaf_against_closed_form_cap():
    """A flat face between voxel layers, the burr h voxels into it: leaf=4 m0 against the cap
    volume pi R^3 (h/R)^2 (1 - h/3R). The voxel-sphere model itself is 7 % low at 0.5 voxel
    (the spheres' bumps), 4 % at 0.6, within 1.2 % from 0.75 voxel on."""
    n, R = 48, 15.0
    d = np.zeros((n, n, n), np.uint8)
    d[:, :, :24] = 255  # the face at z = 23.5
    o = Octree(d)
    rng = np.random.default_rng(8)
    for h, low, high in (
        (0.5, -0.08, -0.06),
        (0.6, -0.05, -0.03),
        (0.75, -0.02, 0.0),
        (1.0, 0.0, 0.012),
        (3.0, -0.01, 0.01),
    ):
        for _ in range(3):
            c = np.array([23.5 + rng.uniform(-2, 2), 23.5 + rng.uniform(-2, 2), 23.5 + R - h])
            m, _ = o.moments(c, R, 4)
            assert low < m[0] / 255.0 / cap_volume(h, R) - 1.0 < high


def test_octree_follows_erosion_exactly():
    """The haptic loop refreshes the octree by subtracting each eroded voxel's decrement on
    its path to the root: after many eroding steps its moments equal a pyramid rebuilt from
    the eroded density bit for bit, and the moments at the burr equal the brute-force sum."""
    vol = uniform_block((40, 40, 40), 1e-4, 200, top=25)
    sim = BurrSim(vol, BurrParams(radius=1e-3, erosion=5e-5, leaf=4), seed=1)
    removed = 0.0
    for step in range(60):
        centre = vol.to_world([19.5 + 0.05 * step, 19.5, 25.5 + 10 - 3 - 0.03 * step])
        removed += sim.step(centre, omega=(2000.0, 0, 2000.0), dt=1e-3).removed
    assert removed > 0
    np.testing.assert_array_equal(sim.octree.mom, Octree(vol.density.copy()).mom)
    g = vol.to_grid(centre)
    brute = np.zeros(4)
    brute_moments(vol.density, g[0], g[1], g[2], 10.0, brute)
    np.testing.assert_allclose(sim.octree.moments(g, 10.0, 4)[0], brute, rtol=1e-9, atol=1e-6)


@pytest.mark.parametrize("method", ["octree", "brute"])
def test_one_call_step_equals_its_parts(method):
    """BurrSim.step runs moments, normal, depth and load in one compiled call: each equals the
    same quantity computed apart in Python (BurrSim.moments, n = -m1/|m1|, the cap-depth
    inversion, F_e = c_e R^2 (h/R)^(3/2) n), bit for bit, over eroding steps, and the force
    is elastic + friction; a step with erode=False removes nothing and leaves the density
    and octree as they were; a step out of contact (burr 1 voxel above the block) is all
    zeros."""
    vol = uniform_block((40, 40, 40), 1e-4, 200, top=25)
    p = BurrParams(radius=1e-3, erosion=5e-5, method=method, leaf=4)
    sim = BurrSim(vol, p, seed=3)
    for step in range(20):
        centre = vol.to_world([19.5 + 0.3 * step, 19.7, 25.5 + 10 - 2.5 - 0.05 * step])
        m0, m1 = sim.moments(centre)
        s = sim.step(centre, omega=(2000.0, 0, 2000.0), dt=1e-3)
        assert s.removed > 0
        normal = -m1 / math.sqrt(float(m1[0] * m1[0] + m1[1] * m1[1] + m1[2] * m1[2]))
        h = float(depth_from_m0(m0, p.rho0, p.radius))
        assert s.m0 == m0 and np.array_equal(s.m1, m1) and np.array_equal(s.normal, normal)
        elastic = p.c_e * p.radius**2 * (h / p.radius) ** 1.5 * normal
        assert s.depth == h and np.array_equal(s.elastic, elastic)
        assert np.array_equal(s.force, s.elastic + s.friction) and np.any(s.friction != 0)
    mom = sim.octree.mom.copy() if sim.octree is not None else None
    density = vol.density.copy()
    s = sim.step(centre, omega=(2000.0, 0, 2000.0), dt=1e-3, erode=False)
    assert s.power > 0 and s.removed == 0 and s.expected == 0 and np.array_equal(vol.density, density)
    assert mom is None or np.array_equal(sim.octree.mom, mom)
    s = sim.step(vol.to_world([19.5, 19.5, 25.5 + 10 + 1]), omega=(2000.0, 0, 2000.0), dt=1e-3)
    vectors = (s.force, s.elastic, s.friction, s.torque, s.normal, s.m1)
    assert all(np.array_equal(v, np.zeros(3)) for v in vectors)
    assert (s.m0, s.depth, s.power, s.removed, s.expected, s.contact_area, s.slip_speed) == (0,) * 7


def test_erosion_bookkeeping_and_roulette_expectation():
    """Removed mass = sum of counter decrements x voxel mass exactly; and, for rates far below
    one count per step, the mean decrement over many seeds equals the continuous law
    (K_er x frictional work) within 4 standard errors."""
    ratios = []
    for seed in range(40):
        vol = uniform_block((40, 40, 40), 1e-4, 255, top=25)
        before = vol.density.astype(np.int64).sum()
        sim = BurrSim(vol, BurrParams(radius=1e-3, erosion=2e-8), seed=seed)
        tot_rem = tot_exp = 0.0
        for _ in range(20):
            s = sim.step(vol.to_world([19.5, 19.5, 25.5 + 10 - 3]), omega=(2000.0, 0, 2000.0), dt=1e-3)
            tot_rem += s.removed
            tot_exp += s.expected
        assert (before - vol.density.astype(np.int64).sum()) * vol.mass_per_count == pytest.approx(tot_rem)
        assert tot_exp == pytest.approx(2e-8 * sim.work_total, rel=1e-9)
        ratios.append(tot_rem / tot_exp)
    ratios = np.array(ratios)
    assert abs(ratios.mean() - 1) < 4 * ratios.std() / math.sqrt(ratios.size) + 1e-3


def test_descent_depth_increases_with_force_and_time():
    depths = {}
    for push in (1.0, 3.0):
        vol = uniform_block((48, 48, 48), 1e-4, 200, top=38)
        res, surface, sim = descent_experiment(vol, 0.8, push=push, params=BurrParams(radius=1e-3))
        depth = surface - (res.centres[:, 2] - 1e-3)
        assert depth[-1] > depth[400] > depth[100]
        assert res.removed[-1] > 0
        depths[push] = depth[-1]
    assert depths[3.0] > depths[1.0]


def test_volume_io_and_phantom(tmp_path):
    v = phantom(32, 2e-4, seed=2)
    col = v.density[16, 16]
    assert col[-1] == 0 and col.max() == 255 and (col == 25).any()
    v.save(tmp_path / "p.npz")
    w = Volume.load(tmp_path / "p.npz")
    assert np.array_equal(w.density, v.density) and w.voxel == v.voxel
    v.density.tofile(tmp_path / "p.raw")
    r = Volume.load(tmp_path / "p.raw", shape=(32, 32, 32), voxel=2e-4)
    assert np.array_equal(r.density, v.density)
    assert R_VOXEL**3 * 4 / 3 * math.pi == pytest.approx(1.0)


# ----------------------------------------------------------------------------- sound
def _drill_render(block, events=(), duration=0.3, **params):
    from ugens.drill import DrillSource

    d = DrillSource(name="d", **params)
    return render(Graph(d), list(events), duration=duration, block=block, limiter=False).audio[0]


def test_drill_block_size_invariance():
    ev = [
        Event(0.05, "d", "set", {"force": 2.0, "removal": 5.0}),
        Event(0.1, "d", "set", {"rpm": 45000.0}, ramp=0.05),
        Event(0.2, "d", "set", {"force": 0.5}, jump=True),
    ]
    outs = [_drill_render(b, ev) for b in (1, 64, 1000)]
    assert np.max(np.abs(outs[0] - outs[1])) < 1e-6
    assert np.max(np.abs(outs[0] - outs[2])) < 1e-6


def test_drill_spectrum_has_tooth_passing_peak_and_noise_scales():
    fs = 48000
    x = _drill_render(1000, duration=1.0, rpm=24000.0, force=1.0, noise=0.0, chips=0.0, flutes=6)
    spec = np.abs(np.fft.rfft(x * np.hanning(x.size)))
    f = np.fft.rfftfreq(x.size, 1 / fs)
    assert f[np.argmax(spec)] == pytest.approx(6 * 400.0, abs=2.0)
    a = _drill_render(1000, duration=0.5, force=1.0, ripple=0.0)
    b = _drill_render(1000, duration=0.5, force=3.0, ripple=0.0)
    assert np.std(b) / np.std(a) == pytest.approx(3.0, rel=0.02)
    c = _drill_render(1000, duration=0.5, force=0.0, ripple=0.0, removal=10.0, chips=0.1)
    assert np.std(c) == pytest.approx(1.0 / math.sqrt(3), rel=0.03)  # uniform noise of peak 1


def test_render_drill_writes_files(tmp_path):
    import soundfile

    from patches.drill import render_drill

    info = render_drill(tmp_path / "d.wav", tmp_path / "h.csv", tmp_path / "d.csv", duration=0.6, n=48)
    audio, sr = soundfile.read(tmp_path / "d.wav")
    assert sr == 48000 and audio.shape[0] == 28800
    assert np.max(np.abs(audio)) == pytest.approx(10 ** (-6 / 20), rel=1e-3)
    rows = np.loadtxt(tmp_path / "d.csv", delimiter=",", skiprows=1)
    assert rows.shape == (600, 6)
    assert np.all(np.diff(rows[:, 4]) >= 0) and rows[-1, 4] == pytest.approx(info["removed_mass_kg"])
    assert rows[-1, 1] > 0  # below the initial surface
    h = np.loadtxt(tmp_path / "h.csv", delimiter=",", skiprows=1)
    assert h.shape == (600, 5)

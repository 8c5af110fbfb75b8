"""physics.deform.haptic (probe loop on Green's functions) and the patches.poke scene."""

from __future__ import annotations

import numpy as np
import pytest
import soundfile

from jassy.errors import JassyError
from jassy.events import ContactTrack, HapticFrame
from physics.deform.bem import SOFT_GEL_DENSITY, assemble, solve_mixed
from physics.deform.greens import reference_greens
from physics.deform.haptic import PokeSim, poke_path, run_poke, soft_ball
from physics.modal.materials import Material

R, RP = 0.05, 0.015


@pytest.fixture(scope="module")
def ball(tmp_path_factory):
    V, F, fixed = soft_ball(R, 2)
    mat = Material("gel", 2e5, 0.45, SOFT_GEL_DENSITY)
    g = reference_greens(V, F, mat, fixed, cache_dir=tmp_path_factory.mktemp("greens"))
    return V, F, fixed, mat, g


def _press(sim, k, depth):
    """Probe centred on vertex k's outward normal, indenting it by ``depth`` m."""
    return sim.step(sim.greens.vertices[k] + sim.normals[k] * (RP - depth))


def test_no_force_without_contact(ball):
    sim = PokeSim(ball[4], RP)
    k = int(np.argmax(ball[0][:, 2]))
    st = _press(sim, k, -1e-3)
    assert st.contacts.size == 0 and np.all(st.force == 0.0)
    st = sim.step([0.0, 0.0, 1.0])
    assert st.contacts.size == 0 and np.all(st.force == 0.0)


def test_single_vertex_force_matches_direct_bem_solve(ball):
    """One contact vertex: the force on the probe is -a_k p_k of the mixed problem with the
    vertex's displacement prescribed (a dense direct solve of H u = G p)."""
    V, F, fixed, mat, g = ball
    sim = PokeSim(g, RP)
    k = int(np.argmax(V[:, 2]))
    st = _press(sim, k, 2e-3)
    assert list(st.contacts) == [k]
    H, G = assemble(V, F, mat)
    disp = fixed.copy()
    disp[k] = True
    vals = np.zeros_like(V)
    vals[k] = -2e-3 * sim.normals[k]
    _, p = solve_mixed(H, G, disp, vals)
    np.testing.assert_allclose(st.force, -g.areas[k] * p[k], rtol=1e-9, atol=1e-12)


def test_force_along_normal_grows_with_indentation_and_compresses(ball):
    V, F, fixed, mat, g = ball
    sim = PokeSim(g, RP)
    k = int(np.argmax(V[:, 2]))
    n = sim.normals[k]
    mags = []
    for depth in np.linspace(5e-4, 1.2e-2, 24):
        st = _press(sim, k, depth)
        f = np.linalg.norm(st.force)
        assert st.force @ n > 0.97 * f  # pushes the probe out, along the normal
        assert np.all(np.einsum("ij,ij->i", st.contact_forces, sim.normals[st.contacts]) <= 0)
        mags.append(f)
    assert np.all(np.diff(mags) > 0)


def test_contact_set_is_reused_while_unchanged(ball):
    sim = PokeSim(ball[4], RP)
    k = int(np.argmax(ball[0][:, 2]))
    first = _press(sim, k, 3e-3)
    count = sim.solver.refactors
    again = _press(sim, k, 3.2e-3)
    assert np.array_equal(first.contacts, again.contacts)
    assert first.refactored and not again.refactored and sim.solver.refactors == count
    assert np.linalg.norm(again.force) > np.linalg.norm(first.force)


def test_run_poke_emits_frames_and_track(ball):
    sim = PokeSim(ball[4], RP)
    res = run_poke(sim, poke_path(R, RP, 0.008), 4.0)
    assert len(res.frames) == 4000 and all(isinstance(f, HapticFrame) for f in res.frames[:5])
    tr = res.track
    assert isinstance(tr, ContactTrack) and tr.times.size == 4000 and len(tr.locations) == 4000
    assert np.all(np.isfinite(res.forces)) and np.all(tr.rolling_speed == 0)
    touching = res.counts > 0
    assert touching.any() and (~touching).any()
    assert np.all(tr.normal_force[~touching] == 0) and np.all(tr.slip_speed[~touching] == 0)
    sliding = (tr.times > 2.1) & (tr.times < 2.7) & touching
    assert np.median(tr.slip_speed[sliding]) > 0.02  # the probe slides over the top there
    assert res.refactored.sum() < touching.sum() / 4  # contact sets are reused
    with pytest.raises(JassyError, match="path"):
        run_poke(sim, lambda t: [0.0, 0.0], 0.01)


def test_poke_scene_renders(tmp_path):
    from patches.poke import render_poke
    from patches.scene_io import PEAK

    out = tmp_path / "poke.wav"
    info = render_poke(out, tmp_path / "f.csv", tmp_path / "t.csv", duration=4.0, subdivisions=2,
                       cache_dir=tmp_path)  # fmt: skip
    audio, fs = soundfile.read(out)
    assert fs == 48000 and audio.shape == (4 * 48000,)
    assert np.all(np.isfinite(audio)) and np.max(np.abs(audio)) == pytest.approx(PEAK, rel=1e-3)
    rows = np.loadtxt(tmp_path / "t.csv", delimiter=",", skiprows=1)
    touching = rows[:, -1] > 0
    t_audio = np.arange(audio.size) / fs
    in_contact = touching[np.minimum((t_audio * 1000).astype(int), 3999)]
    rms_on = np.sqrt(np.mean(audio[in_contact] ** 2))
    before = t_audio < 0.3  # nothing has touched yet
    assert rms_on > 0.01 and np.max(np.abs(audio[before])) < 1e-6
    assert info["max_contacts"] >= 1 and info["haptic_steps"] == 4000
    with pytest.raises(JassyError, match="duration"):
        render_poke(out, duration=-1.0)

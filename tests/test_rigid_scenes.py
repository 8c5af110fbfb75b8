"""The wok and drop scenes: physics stays plausible, events drive sound, files are written."""

import numpy as np
import pytest
import soundfile as sf

from physics.rigid.events import contact_wrench, impacts
from physics.rigid.shapes import mass_properties


@pytest.fixture(scope="module")
def wok():
    from patches.wok import simulate_wok

    return simulate_wok(duration=2.2, n_food=8)


def _food_height_above_wok(world, result, k):
    """Height (m) of every food centre above the wok surface below it, at sample k."""
    from patches.wok import WOK_CURVATURE, hand_path
    from physics.rigid.spatial import rotation_matrices

    p, q = hand_path(result.times[k])
    local = (result.pos[k, 1:] - p[0]) @ rotation_matrices(q)[0]
    r2 = np.sum(local[:, :2] ** 2, axis=1)
    return local[:, 2] - (WOK_CURVATURE - np.sqrt(WOK_CURVATURE**2 - r2))


def test_wok_food_lands_settles_and_flies_when_tossed(wok):
    world, _, result = wok
    settled = np.searchsorted(result.times, 1.5)
    height = _food_height_above_wok(world, result, settled)
    assert np.all(height > -2e-3) and np.all(height < 0.03)  # resting in the bowl, not through it
    toss = (result.times > 1.6) & (result.times < 2.2)
    peak = max(np.max(_food_height_above_wok(world, result, k)) for k in np.flatnonzero(toss))
    assert peak > 0.02  # the toss throws food clear of the wok
    assert np.all(np.linalg.norm(result.pos[-1, 1:, :2], axis=1) < 0.2)  # and it lands back inside


def test_wok_impacts_and_handle_force(wok):
    world, _, result = wok
    hits = impacts(result)
    assert len(hits) > 8
    assert all(h.impulse > 0 and h.speed > world.params.bounce_threshold for h in hits)
    times, force, _ = contact_wrench(result, world.index("wok"))
    food_mass = sum(mass_properties(b.shape, b.material.density).mass for b in world.bodies[1:])
    resting = (times > 1.0) & (times < 1.5)
    # while the food rests, the wok carries its weight (force on the wok is downward)
    assert np.mean(force[resting, 2]) == pytest.approx(-food_mass * 9.81, rel=0.1)


def test_render_wok_writes_audio_haptics_and_csv(tmp_path):
    from patches.wok import render_wok

    wav, hap, csv = tmp_path / "wok.wav", tmp_path / "wok_force.csv", tmp_path / "wok.csv"
    summary = render_wok(wav, hap, csv, duration=1.0, n_food=6)
    audio, rate = sf.read(wav)
    assert rate == 48000 and len(audio) == 48000
    assert np.all(np.isfinite(audio)) and np.max(np.abs(audio)) == pytest.approx(10 ** (-6 / 20), rel=1e-3)
    assert summary["impacts"] > 0
    # the sound starts with the first impact, not before
    first = np.loadtxt(csv, delimiter=",", skiprows=1, ndmin=2)[0, 0]
    onset = np.argmax(np.abs(audio) > 1e-4) / rate
    assert onset == pytest.approx(first, abs=2e-3)
    frames = np.loadtxt(hap, delimiter=",", skiprows=1)
    assert frames.shape[0] == 1000 and np.all(np.isfinite(frames))


def test_render_drop_comes_to_rest_and_sounds_the_table(tmp_path):
    from patches.drop import render_drop

    wav = tmp_path / "drop.wav"
    summary = render_drop(wav, duration=4.0)
    assert max(summary["final_speeds_ms"].values()) < 0.02  # bounced, slid and rolled to rest
    audio, rate = sf.read(wav)
    spectrum = np.abs(np.fft.rfft(audio * np.hanning(len(audio))))
    freqs = np.fft.rfftfreq(len(audio), 1 / rate)
    from jassy.modal_model import ModalModel
    from patches.drop import __file__ as here

    board = ModalModel.load(here.replace("drop.py", "wood_board_model.toml"))
    low = (freqs > 100) & (freqs < 2000)
    peak = freqs[low][np.argmax(spectrum[low])]
    assert np.min(np.abs(board.frequencies - peak) / board.frequencies) < 0.01  # a table mode


def test_contact_curves_join_a_pairs_tracks_with_zeros_between():
    from jassy import ContactTrack
    from patches.rigid_sound import contact_curves

    def track(t0, n, force, slip):
        t = t0 + 1e-3 * np.arange(n)
        return ContactTrack((1, 2), t, np.full(n, force), np.full(n, slip), np.zeros(n))

    # the second track starts half a step after the first ends; the third after a silence
    first, touching, later = track(0.10, 50, 2.0, 0.3), track(0.1495, 20, 3.0, 0.0), track(0.30, 10, 1.0, 0.2)
    times, force, slip, rolling = contact_curves([later, touching, first])
    assert np.all(np.diff(times) > 0)
    assert force[0] == 0.0 and force[-1] == 0.0 and np.all(rolling == 0.0)
    assert np.interp(0.2, times, force) == 0.0  # silent between the contacts
    assert np.interp(0.12, times, force) == 2.0 and np.interp(0.16, times, force) == 3.0
    assert np.interp(0.305, times, slip) == pytest.approx(0.2)

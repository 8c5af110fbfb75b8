"""The attack of a fitted model: the first strike's non-modal start stored in the ModalModel
(file round trip), played by StrikeAttack for every strike (closed-form convolution), and
the fit keeping a known contact transient that the modes do not explain."""

from __future__ import annotations

import numpy as np
import pytest
from helpers import ArraySource

from jassy import Graph, ModalModel, render
from jassy.errors import ModelError
from physics.modal.fit import fit_recordings, resynthesise
from ugens.attack import StrikeAttack
from ugens.mix import Mixer
from ugens.modal import ModalBank

RATE = 48000


def run(node, duration):
    r = render(Graph(node), (), duration=duration, sample_rate=RATE, block=64, limiter=False)
    return r.audio[0]


def test_attack_is_stored_in_model_files(tmp_path):
    rng = np.random.default_rng(0)
    model = ModalModel([440.0], [3.0], [[1.0]], attack=rng.standard_normal(50), attack_rate=44100.0)
    for ext in (".toml", ".npz"):
        model.save(tmp_path / f"m{ext}")
        back = ModalModel.load(tmp_path / f"m{ext}")
        np.testing.assert_array_equal(back.attack, model.attack)
        assert back.attack_rate == 44100.0
    np.testing.assert_array_equal(model.below(1000.0).attack, model.attack)
    assert model.truncated(1).attack_rate == 44100.0
    with pytest.raises(ModelError, match="attack_rate"):
        ModalModel([440.0], [3.0], [[1.0]], attack=[0.1, 0.2])
    with pytest.raises(ModelError, match="attack: expected finite"):
        ModalModel([440.0], [3.0], [[1.0]], attack=[0.1, np.nan], attack_rate=48000.0)
    (tmp_path / "bad.toml").write_text(
        "frequencies = [1.0]\ndecays = [1.0]\ngains = [[1.0]]\nattack = [0.5]\n"
    )
    with pytest.raises(ModelError, match="attack_rate"):
        ModalModel.load(tmp_path / "bad.toml")


def test_strike_attack_convolves_the_force_with_the_attack():
    """y[n] = sum_m attack[m] F[n - m] / fs: two taps (a unit impulse, 1 N s, and a later
    half-strength one overlapping it) and a 3-sample force, against numpy's convolution, at
    blocks that split the attack; a model without an attack is silent."""
    rng = np.random.default_rng(1)
    attack = rng.standard_normal(300)
    model = ModalModel([440.0], [3.0], [[1.0]], attack=attack, attack_rate=float(RATE))
    force = np.zeros(2000)
    force[10] = RATE
    force[200] = 0.5 * RATE
    force[900:903] = [100.0, -50.0, 25.0]
    y = run(StrikeAttack(ArraySource(force), model=model, gain=2.0, name="a"), 2000 / RATE)
    expected = 2.0 * np.convolve(force, attack)[:2000] / RATE
    np.testing.assert_allclose(y, expected, atol=1e-12 * np.abs(expected).max())
    silent = run(StrikeAttack(ArraySource(force), model=ModalModel([440.0], [3.0], [[1.0]]), name="s"), 0.01)
    assert not np.any(silent)


def test_strike_attack_resamples_to_the_render_rate():
    """An attack stored at 96 kHz (a 3 kHz Gaussian-windowed tone, well inside both bands)
    plays at 48 kHz as the same waveform sampled at 48 kHz."""
    t96 = np.arange(400) / 96000.0
    shape = lambda t: np.exp(-(((t - 2e-3) / 5e-4) ** 2)) * np.sin(2 * np.pi * 3000 * t)  # noqa: E731
    model = ModalModel([440.0], [3.0], [[1.0]], attack=shape(t96), attack_rate=96000.0)
    force = np.zeros(400)
    force[0] = RATE
    y = run(StrikeAttack(ArraySource(force), model=model, name="a"), 400 / RATE)
    np.testing.assert_allclose(y[:200], shape(np.arange(200) / RATE), atol=2e-3)


def test_fit_keeps_a_contact_transient_and_plays_it_back():
    """Three known modes plus a 2 ms contact transient that no mode explains (a noise burst
    under a raised-cosine window): each mode is fitted once, the stored attack is that burst
    (correlation > 0.95), it
    brings the model's first 3 ms within -20 dB of the recording (relative to the burst's
    energy) where the modes alone leave the burst (error within 3 dB of it), and a ModalBank
    with a StrikeAttack on the same unit impulse renders the model with its attack."""
    rng = np.random.default_rng(2)
    n, pre = int(0.8 * RATE), int(0.02 * RATE)
    t = (np.arange(n) - pre) / RATE
    live = t >= 0
    freqs, decays, gains = (
        np.array([523.0, 1404.0, 2811.0]),
        np.array([4.0, 9.0, 15.0]),
        np.array([1.0, 0.6, 0.4]),
    )
    x = np.zeros(n)
    for f, d, a in zip(freqs, decays, gains, strict=True):
        x[live] += a * np.exp(-d * t[live]) * np.sin(2 * np.pi * f * t[live])
    m = int(0.002 * RATE)
    burst = rng.standard_normal(m) * np.hanning(m) * 0.8
    x[pre : pre + m] += burst
    x += 1e-4 * rng.standard_normal(n)
    res = fit_recordings(x, RATE, onset=pre / RATE)
    model = res.model
    assert (
        model.attack is not None and model.attack_rate == RATE and m / RATE < model.attack.size / RATE <= 0.02
    )
    assert np.corrcoef(model.attack[:m], burst)[0, 1] > 0.95
    # each mode fitted once (not twice with cancelling amplitudes), with its gain within 1 dB
    for f, a in zip(freqs, gains, strict=True):
        near = np.flatnonzero(np.abs(model.frequencies - f) < 1.0)
        assert near.size == 1 and abs(20 * np.log10(model.gains[0, near[0]] / a)) < 1.0
    head, tail = slice(pre, pre + int(0.003 * RATE)), slice(pre + int(0.005 * RATE), pre + int(0.1 * RATE))

    def err_db(y, span, ref):
        return 10 * np.log10(np.sum((x[span] - y[span]) ** 2) / ref)

    with_attack = resynthesise(model, n, RATE, pre / RATE, 0, res.phases[0])
    without = resynthesise(model, n, RATE, pre / RATE, 0, res.phases[0], attack=False)
    # the error relative to the burst's energy, then to the recording's
    burst_energy = np.sum(burst**2)
    assert err_db(with_attack, head, burst_energy) < -20 and err_db(without, head, burst_energy) > -3
    assert err_db(with_attack, tail, np.sum(x[tail] ** 2)) < -40  # the fitted phases: sin(2 pi f t + phi)
    # the same model in a patch: a unit impulse into a ModalBank and a StrikeAttack, mixed
    force = np.zeros(4800)
    force[0] = RATE
    src = ArraySource(force)
    mix = Mixer(
        ModalBank(src, model=model, name="bank"), StrikeAttack(src, model=model, name="attack"), name="mix"
    )
    y = render(Graph(mix), (), duration=0.1, sample_rate=RATE, block=64, limiter=False).audio[0]
    # from sample 1 on (sample 0 holds the bank's direct term, its end correction)
    np.testing.assert_allclose(y[1:], resynthesise(model, 4800, RATE)[1:], atol=1e-6 * np.abs(y).max())

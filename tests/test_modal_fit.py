"""Fitting modal models to recordings (physics.modal.fit): synthetic recordings with known
modes, noise and reverberation; a signal synthesised by another method (finite element modes
rendered through jassy's ModalBank); several recordings; CLI and plot option."""

from __future__ import annotations

import sys

import numpy as np
import pytest
from scipy.signal import fftconvolve

from jassy import ModalModel
from jassy.errors import JassyError
from physics.modal.fit import fit_recordings, resynthesise

RATE = 48000
# twelve modes; decays are below half the room's (27.6 1/s), as for ringing objects; the last
# mode is deliberately weak (below 20 dB) and is not checked
FREQS = np.array(
    [220.0, 347.0, 563.0, 811.0, 1190.0, 1733.0, 2450.0, 3320.0, 4870.0, 6410.0, 8800.0, 11500.0]
)
DECAYS = np.array([1.2, 2.5, 1.8, 5.0, 3.5, 8.0, 6.0, 10.0, 9.0, 12.0, 11.0, 12.0])
GAINS = np.array([1.0, 0.5, 0.8, 0.3, 0.6, 0.25, 0.4, 0.15, 0.2, 0.1, 0.04, 0.01])


def modal_sum(n, rate, f, d, a, start):
    t = np.arange(n) / rate - start
    out = np.zeros(n)
    live = t >= 0
    for fk, dk, ak in zip(f, d, a, strict=True):
        out[live] += ak * np.exp(-dk * t[live]) * np.sin(2 * np.pi * fk * t[live])
    return out


def recording(seed=0, snr_db=30.0, drr_db=30.0, rt60=0.25, duration=2.0, pre=0.05):
    """Known modes, convolved with a room (direct sound plus an exponentially decaying noise
    tail of the given RT60 holding 10^(-DRR/10) of the energy), plus white noise at SNR dB
    (power over the whole recording). Returns (recording, noise sigma, samples after onset)."""
    rng = np.random.default_rng(seed)
    n = int(duration * RATE)
    dry = modal_sum(n, RATE, FREQS, DECAYS, GAINS, pre)
    m = int(rt60 * RATE)
    tail = rng.standard_normal(m) * np.exp(-np.log(1000) * np.arange(m) / RATE / rt60)
    tail[0] = 0.0
    tail *= np.sqrt(10 ** (-drr_db / 10) / np.sum(tail**2))
    tail[0] = 1.0
    wet = fftconvolve(dry, tail)[:n]
    sigma = np.sqrt(np.mean(wet**2) / 10 ** (snr_db / 10))
    return wet + sigma * rng.standard_normal(n), sigma, n - int(pre * RATE)


def levels_above_noise(sigma, n):
    """Each mode's periodogram peak over the noise's periodogram level, in dB, over the n
    samples after the onset: (a fs (1 - e^{-dT}) / (2 d))^2 / (sigma^2 n)."""
    peak = GAINS * RATE * (1 - np.exp(-DECAYS * n / RATE)) / (2 * DECAYS)
    return 10 * np.log10(peak**2 / (sigma**2 * n))


def decay_crb(a, f, d, sigma, n):
    """Cramer-Rao bound (standard deviation, 1/s) of the decay of a e^{-dt} sin(2 pi f t + phi)
    in white noise of standard deviation sigma over n samples: no unbiased estimate does better."""
    t = np.arange(n) / RATE
    e, w = np.exp(-d * t), 2 * np.pi * f * t
    jac = np.stack(
        [e * np.sin(w), a * e * np.cos(w), a * e * np.cos(w) * 2 * np.pi * t, -a * t * e * np.sin(w)], 1
    )
    return float(np.sqrt(np.linalg.inv(jac.T @ jac / sigma**2)[3, 3]))


def matched(model, f):
    return int(np.argmin(np.abs(model.frequencies - f)))


def test_fit_noisy_reverberant_recording():
    """SNR 30 dB and a room (RT60 0.25 s, direct-to-reverberant 30 dB): every mode at least
    20 dB above the noise within 0.1 % (frequency), 5 % or 3 Cramer-Rao bounds (decay; the
    bound is 2 % for the weakest mode here) and 10 % (gain)."""
    rec, sigma, n = recording(seed=1)
    levels = levels_above_noise(sigma, n)
    assert levels[-1] < 20 and np.sum(levels >= 20) == 11  # the test covers the 20 dB edge
    result = fit_recordings(rec, RATE)
    model = result.model
    assert abs(result.onset - 0.05) < 0.001
    for k in np.flatnonzero(levels >= 20):
        j = matched(model, FREQS[k])
        assert abs(model.frequencies[j] / FREQS[k] - 1) < 1e-3, k
        crb = decay_crb(GAINS[k], FREQS[k], DECAYS[k], sigma, n)
        assert abs(model.decays[j] - DECAYS[k]) < max(0.05 * DECAYS[k], 3 * crb), k
        assert abs(model.gains[0, j] / GAINS[k] - 1) < 0.10, k
    assert result.residual_db[0] < -20  # the rest is noise and reverberation
    assert "residual" in result.report()


def test_fit_without_reverberation_is_tighter():
    rec, sigma, n = recording(seed=2, drr_db=200.0)
    model = fit_recordings(rec, RATE).model
    for k in np.flatnonzero(levels_above_noise(sigma, n) >= 30):
        j = matched(model, FREQS[k])
        assert abs(model.frequencies[j] / FREQS[k] - 1) < 1e-4
        assert abs(model.decays[j] / DECAYS[k] - 1) < 0.03
        assert abs(model.gains[0, j] / GAINS[k] - 1) < 0.03


def test_fit_signal_rendered_by_modalbank_from_fem_modes():
    """A different synthesis: finite element modes of an aluminium plate rendered by jassy's
    impulse-invariant resonators, struck by a 1 - cos pulse (0.2 ms). The fit must find the
    FE frequencies and decays, and gains a_k |P(f_k)| (P = the pulse's spectrum)."""
    from jassy import Event, Graph, render
    from physics.modal import fem, meshes
    from physics.modal.materials import material
    from ugens import ImpactForce, ModalBank

    plate = meshes.plate(0.2, 0.15, 0.004)
    model, _, _ = fem.modes_from_mesh(
        plate, material("aluminium"), n_modes=10, pitch=0.004, points={"p": (0.061, 0.037, 0.002)}
    )
    tau = 0.0002
    hit = ImpactForce(name="hit", duration=tau)
    graph = Graph(ModalBank(model, name="plate")(hit))
    out = render(graph, [Event(0.05, "hit", "impact", {"impulse": 1.0, "location": "p"})], 2.0, limiter=False)
    fitted = fit_recordings(out.audio[0], RATE, skip=2 * tau).model
    f = model.frequencies
    pulse = np.abs(np.sinc(f * tau) / (1 - (f * tau) ** 2))  # |P(f)| of the unit-impulse 1 - cos pulse
    energy = model.gains[0] ** 2 / model.decays
    strong = np.flatnonzero(energy >= 1e-4 * energy.max())  # within 40 dB of the loudest
    assert strong.size >= 6
    for k in strong:
        j = matched(fitted, f[k])
        assert abs(fitted.frequencies[j] / f[k] - 1) < 1e-3
        assert abs(fitted.decays[j] / model.decays[k] - 1) < 0.05
        assert abs(fitted.gains[0, j] / (model.gains[0, k] * pulse[k]) - 1) < 0.10


def test_several_recordings_share_modes_and_get_one_gain_row_each():
    rng = np.random.default_rng(3)
    f, d = np.array([300.0, 710.0, 1250.0]), np.array([2.0, 4.0, 6.0])
    rows = np.array([[1.0, 0.5, 0.2], [0.1, 0.8, 0.4]])  # the second location nearly misses mode 0
    recs = [modal_sum(RATE, RATE, f, d, a, 0.02) + 1e-4 * rng.standard_normal(RATE) for a in rows]
    result = fit_recordings(recs, RATE, points=("a", "b"))
    model = result.model
    assert model.points == ("a", "b") and model.n_modes == 3
    np.testing.assert_allclose(model.frequencies, f, rtol=1e-5)
    np.testing.assert_allclose(model.gains, rows, rtol=0.02)


def test_progress_bar_ends_at_its_total(monkeypatch):
    """The fit's bar never counts more steps than its total and ends at 100 % when the
    search rounds stop early (a round that finds nothing skips the next)."""
    import physics.modal.fit as fit

    ends = []
    close = fit._Work.close

    def record(work):
        ends.append((work.bar.n, work.bar.total))
        close(work)
        ends.append((work.bar.n, work.bar.total))

    monkeypatch.setattr(fit._Work, "close", record)
    rng = np.random.default_rng(5)
    x = modal_sum(RATE, RATE, [300.0, 710.0], [2.0, 4.0], [1.0, 0.5], 0.02) + 1e-4 * rng.standard_normal(RATE)
    fit_recordings(x, RATE, progress=True)
    (taken, total), (shown, _) = ends
    assert 0 < taken <= total and shown == total
    # every search round finding a new pole: every step is taken, exactly the total
    ends.clear()
    detect = fit._detect

    def detect_more(poles, *args):
        out = detect(poles, *args)
        return out + [fit.Pole(2000.0 + 100.0 * len(out), 3.0)] if len(out) == len(poles) else out

    monkeypatch.setattr(fit, "_detect", detect_more)
    fit_recordings(x, RATE, progress=True)
    (taken, total), (shown, _) = ends
    assert taken == total == shown


def test_resynthesis_and_cli(tmp_path, capsys):
    import soundfile as sf

    from jassy.apps.cli import main

    rec, _, _ = recording(seed=4, drr_db=200.0, duration=1.0)
    path = tmp_path / "hit.wav"
    sf.write(path, rec / np.abs(rec).max() * 0.5, RATE, subtype="FLOAT")
    out = tmp_path / "hit.toml"
    assert main(["fit", str(path), "-o", str(out), "--normalise", "--fmax", "10000"]) == 0
    model = ModalModel.load(out)
    assert abs(np.max(model.gains) - 1) < 1e-12 and model.frequencies.max() < 10000
    assert model.points == ("hit",)
    assert "fitted" in capsys.readouterr().out
    y = resynthesise(model, 1000, RATE, onset=0.01)
    assert np.all(y[:480] == 0) and np.any(y[481:] != 0)


def test_plot_option(tmp_path, monkeypatch, capsys):
    import soundfile as sf

    from jassy.apps.cli import main

    rec, _, _ = recording(seed=5, drr_db=200.0, duration=0.5)
    path = tmp_path / "hit.wav"
    sf.write(path, rec * 0.1, RATE)
    png = tmp_path / "hit.png"
    try:
        import matplotlib  # noqa: F401
    except ImportError:
        have_mpl = False
    else:
        have_mpl = True
    if have_mpl:
        assert main(["fit", str(path), "-o", str(tmp_path / "a.toml"), "--plot", str(png), "-q"]) == 0
        assert png.stat().st_size > 10000
    monkeypatch.setitem(sys.modules, "matplotlib", None)  # as if not installed
    assert main(["fit", str(path), "-o", str(tmp_path / "b.toml"), "--plot", str(png), "-q"]) == 2
    assert "matplotlib is not installed" in capsys.readouterr().err


@pytest.mark.parametrize(
    "argv, message",
    [
        (["fit", "missing.wav", "-o", "m.toml"], "no such recording"),
        (["fit", "silent.wav", "-o", "m.toml"], "silent"),
        (["fit", "silent.wav", "-o", "m.txt"], "expected a .toml or .npz"),
        (["fit", "silent.wav", "-o", "m.toml", "--fmin", "500", "--fmax", "100"], "--fmax: expected more"),
        (["fit", "silent.wav", "-o", "m.toml", "--plot", "p.gif"], "--plot"),
    ],
)
def test_fit_errors_exit_2(argv, message, tmp_path, monkeypatch, capsys):
    import soundfile as sf

    from jassy.apps.cli import main

    monkeypatch.chdir(tmp_path)
    sf.write(tmp_path / "silent.wav", np.zeros(4800), RATE)
    assert main(argv) == 2
    err = capsys.readouterr().err
    assert message in err and err.count("\n") == 1


def test_noise_only_gives_a_clear_error():
    noise = np.random.default_rng(0).standard_normal(RATE)
    with pytest.raises(JassyError, match="no decaying modes found"):
        fit_recordings(noise, RATE)


def test_distinct_merges_only_poles_the_refinement_put_together():
    """Two modes half a half-width apart stay two; two poles on one mode become one; a pole
    that moved onto another goes back to its value before the refinement."""
    from physics.modal.fit import Pole, _distinct

    assert _distinct([Pole(1000, 5), Pole(1002, 5.5)]) == [Pole(1000, 5), Pole(1002, 5.5)]
    assert _distinct([Pole(1000, 70), Pole(1000.05, 72)]) == [Pole(1000, 70)]
    before = [Pole(1000, 70), Pole(1060, 70)]
    assert _distinct([Pole(1000, 70), Pole(1000.05, 72)], before) == before
    # the earlier pole moved onto the later one: the earlier goes back
    before = [Pole(940, 70), Pole(1000, 70)]
    assert _distinct([Pole(1000.05, 72), Pole(1000, 70)], before) == before

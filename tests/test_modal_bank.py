"""ModalBank against the closed-form modal impulse response and physical expectations."""

import numpy as np
import pytest
from helpers import ArraySource

from jassy import Event, Graph, ModalModel, PatchError, render
from ugens.modal import ModalBank, design

FS = 48000


def spread_model(n=40, seed=3):
    """Modes log-spread over 20 Hz - 20 kHz with decays 0.5 - 500 1/s (the spec's range)."""
    rng = np.random.default_rng(seed)
    f = np.geomspace(20.0, 20000.0, n)
    d = np.geomspace(0.5, 500.0, n)[rng.permutation(n)]
    a = rng.uniform(-1.0, 1.0, (2, n))
    return ModalModel(f, d, a)


def impulse_response(model, seconds, location=0, block=64):
    """Bank response to the unit impulse F = fs * delta[n] (1 N s in one sample)."""
    x = np.zeros(int(seconds * FS))
    x[0] = FS
    bank = ModalBank(model, location=location, name="bank")(ArraySource(x))
    return render(Graph(bank), [], seconds, FS, block, limiter=False).audio[0]


def error_db(y, ref):
    return 20 * np.log10(np.max(np.abs(y - ref)) / np.max(np.abs(ref)))


def test_impulse_response_matches_closed_form_within_minus_60_db():
    model = spread_model()
    y = impulse_response(model, 2.0)
    ref = model.impulse_response(2.0, FS)  # a e^{-d t} sin(2 pi f t) at t = n / fs: no lead
    assert error_db(y[1:], ref[1:]) < -60.0
    # in fact the recursion is exact up to rounding: far below the bound
    assert error_db(y[1:], ref[1:]) < -120.0
    # sample 0 carries only the direct term: the quadrature's end correction h'(0) / (12 fs)
    direct = np.sum(model.gains_at(0) * 2 * np.pi * model.frequencies) / (12 * FS)
    assert y[0] == pytest.approx(direct, rel=1e-9)


def exact_tap_response(frequency, decay, t0, samples, frames):
    """The continuous convolution of h(t) = e^{-d t} sin(2 pi f t) with the raised-cosine
    pulse F(t) = A (1 - cos(2 pi (t fs - t0) / T)) of 1 N s, at t = n / fs (closed form of
    the integral of exponentials), for frames n."""
    amplitude = FS / samples  # sum F / fs = 1 N s for an integer T
    lam = complex(-decay, 2 * np.pi * frequency) / FS  # pole per sample
    omega = 2 * np.pi / samples
    out = np.zeros(frames.size)
    for i, n in enumerate(frames):
        hi = min(n - t0, samples)  # pulse time x = t - t0 in (0, hi], in samples
        if hi <= 0:
            continue

        def integral(rate, hi=hi, n=n):  # int_0^hi e^{lam (n - t0 - x)} e^{rate x} dx
            k = rate - lam
            return np.exp(lam * (n - t0)) * (np.expm1(k * hi) / k if abs(k) > 0 else hi)

        value = integral(0) - 0.5 * (integral(1j * omega) + integral(-1j * omega))
        out[i] = amplitude * value.imag / FS
    return out


@pytest.mark.parametrize("frequency", [440.0, 3000.0, 9000.0])
def test_a_smooth_tap_matches_the_exact_convolution(frequency):
    """The resonators (trapezoidal rule on the sample grid) plus the direct term (its
    Euler-Maclaurin end correction) follow the exact response to a 1 ms raised-cosine tap
    closely; the JASS form (sample n = response at (n + 1) / fs) would be 6-15 % off."""
    from ugens.impact import ImpactForce

    decay, t0, samples = 20.0, 100.3, 48
    hit = ImpactForce(name="hit", duration=samples / FS)
    bank = ModalBank(ModalModel([frequency], [decay], [[1.0]]), name="bank")(hit)
    score = [Event(t0 / FS, "hit", "impact", {"impulse": 1.0})]
    y = render(Graph(bank, haptic=hit), score, 0.01, FS, 64, limiter=False).audio[0]
    frames = np.arange(y.size)
    exact = exact_tap_response(frequency, decay, t0, samples, frames)
    error = np.max(np.abs(y - exact)) / np.max(np.abs(exact))
    assert error < {440.0: 2e-5, 3000.0: 2e-4, 9000.0: 5e-3}[frequency]
    lead = np.max(np.abs(np.r_[y[1:], 0] - exact)) / np.max(np.abs(exact))  # one sample early
    assert lead > 0.05


@pytest.mark.parametrize("block", [1, 64, 4096])
def test_a_taps_sound_and_force_start_on_the_same_frame(block):
    """The first non-zero frame of the sound is the first non-zero frame of the force (the
    frame after the impact's time), at any block size, wherever the tap falls in a block."""
    from ugens.impact import ImpactForce
    from ugens.mix import Gain

    hit = ImpactForce(name="hit", duration=0.001)
    bank = ModalBank(spread_model(12), name="bank")(hit)
    times = [0.0123 + 0.37 / FS, 0.05, 0.1 + 63.5 / FS]
    for t in times:
        score = [Event(t, "hit", "impact", {"impulse": 0.01})]
        r = render(Graph(Gain(bank, gain=0.1), haptic=hit), score, 0.12, FS, block, limiter=False)
        sound, force = np.flatnonzero(r.audio[0]), np.flatnonzero(r.haptic[0])
        assert sound[0] == force[0] == int(np.floor(t * FS)) + 1


def test_float32_state_would_fail_the_accuracy_bound():
    """Why the state is float64: the same recursion with float32 state drifts (low, light modes)."""
    model = ModalModel([20.0, 31.0, 45.0], [0.5, 0.6, 0.8], [[1.0, 1.0, 1.0]])
    c1, c2, s = design(model.frequencies, model.decays, FS)
    n = 2 * FS
    y1 = np.zeros(3, np.float32)
    y2 = np.zeros(3, np.float32)
    c1f, c2f, gf = c1.astype(np.float32), c2.astype(np.float32), s.astype(np.float32)
    out = np.zeros(n)
    for i in range(n):  # plain numpy reference of a float32 bank (3 modes, loop is fine)
        v = c1f * y1 - c2f * y2 + (gf if i == 0 else np.float32(0))
        y2, y1 = y1, v.astype(np.float32)
        out[i] = float(v.sum())
    ref = model.impulse_response(2.0, FS)
    assert error_db(out, ref) > -60.0
    assert error_db(impulse_response(model, 2.0), ref) < -60.0


def test_impulse_of_one_newton_second_is_sample_rate_independent():
    model = ModalModel([440.0], [5.0], [[1.0]])
    peaks = []
    for fs in (44100, 96000):
        x = np.zeros(fs // 10)
        x[0] = fs
        bank = ModalBank(model)(ArraySource(x))
        y = render(Graph(bank), [], 0.1, fs, 64, limiter=False).audio[0]
        peaks.append(np.max(np.abs(y)))
    assert peaks[0] == pytest.approx(peaks[1], rel=2e-3)
    assert peaks[0] == pytest.approx(1.0, rel=2e-2)  # e^{-d t} ~ 1 at the first peak


def test_location_gains_are_barycentric_and_response_is_linear_in_them():
    model = spread_model(12)
    loc = {"vertices": [0, 1], "weights": [0.25, 0.75]}
    y = impulse_response(model, 0.2, loc)
    y0 = impulse_response(model, 0.2, 0)
    y1 = impulse_response(model, 0.2, 1)
    np.testing.assert_allclose(y, 0.25 * y0 + 0.75 * y1, atol=1e-9 * np.max(np.abs(y)))
    np.testing.assert_allclose(model.gains_at(loc), 0.25 * model.gains[0] + 0.75 * model.gains[1])


def test_freq_scale_jump_moves_the_spectral_peak():
    model = ModalModel([1000.0], [2.0], [[1.0]])
    x = np.zeros(FS)
    x[0] = FS
    x[FS // 2] = FS
    bank = ModalBank(model, name="bank")(ArraySource(x))
    score = [Event(0.5, "bank", "set", {"freq_scale": 1.5}, jump=True)]
    y = render(Graph(bank), score, 1.0, FS, 64, limiter=False).audio[0]
    tail = y[FS // 2 + 100 :]
    spec = np.abs(np.fft.rfft(tail * np.hanning(tail.size)))
    peak = np.fft.rfftfreq(tail.size, 1 / FS)[np.argmax(spec)]
    assert peak == pytest.approx(1500.0, abs=3.0)


def test_silent_modes_are_zeroed_and_skipped():
    model = ModalModel([300.0, 3000.0], [400.0, 900.0], [[1.0, 1.0]])
    x = np.zeros(FS)
    x[0] = FS
    bank = ModalBank(model, name="bank")(ArraySource(x))
    y = render(Graph(bank), [], 1.0, FS, 64, limiter=False).audio[0]
    # e^{-400 t} falls below 1e-10 well before 0.1 s: state flushed, active count zero
    assert bank.meta[0] == 0
    assert np.all(bank.y == 0.0)
    assert np.all(y[FS // 10 :] == 0.0)
    assert not np.any((y != 0) & (np.abs(y) < np.finfo(float).tiny))  # no subnormal output


def test_floor_zero_computes_every_mode_as_a_scan_that_zeroes_nothing():
    # e^{-400 t} is 1e-174 after 1 s: a floor of 1e-300 is scanned for but never reached,
    # and floor 0 (no scan at all) must give the same bits and keep every mode active
    model = ModalModel([300.0, 3000.0], [400.0, 9.0], [[1.0, 1.0]])
    x = np.zeros(FS)
    x[0] = FS
    out = {}
    for floor in (0.0, 1e-300):
        bank = ModalBank(model, name="bank", floor=floor)(ArraySource(x))
        out[floor] = render(Graph(bank), [], 1.0, FS, 64, limiter=False).audio[0]
        assert bank.meta[0] == 2 and np.all(bank.y != 0.0)
    assert np.array_equal(out[0.0], out[1e-300])


@pytest.mark.parametrize("precision", ["float64", "mixed"])
def test_state_save_and_restore_continues_identically(precision):
    model = spread_model(8)
    x = np.random.default_rng(0).standard_normal(FS)
    bank = ModalBank(model, name="bank", precision=precision)(ArraySource(x))
    from jassy import OfflineEngine

    eng = OfflineEngine(Graph(bank), [], FS, 64, limiter=False)
    eng.render(0.25)
    saved = bank.get_state()
    a = eng.render(0.25).audio
    bank.set_state(saved)
    eng.scheduler.frame -= int(0.25 * FS)
    b = eng.render(0.25).audio
    np.testing.assert_array_equal(a, b)


def test_mode_above_nyquist_is_a_clear_error():
    model = ModalModel([100.0, 30000.0], [1.0, 1.0], [[1.0, 1.0]])
    bank = ModalBank(model, name="bank")(ArraySource(np.zeros(10)))
    with pytest.raises(PatchError, match=r"nodes\.bank\.model.*frequencies\[1\].*Nyquist"):
        render(Graph(bank), [], 0.01, FS)


def band_error_db(model, direct, low=16000.0, high=24000.0):
    """Power of the bank's impulse response in [low, high) Hz at 48 kHz over that of the
    continuous system's closed-form response sum_k a_k w_k / ((s + d_k)^2 + w_k^2), dB."""
    x = np.zeros(FS)
    x[0] = FS
    bank = ModalBank(model, name="bank", direct=direct)(ArraySource(x))
    y = render(Graph(bank), [], 1.0, FS, 64, limiter=False).audio[0]
    f = np.fft.rfftfreq(y.size, 1.0 / FS)
    band = (f >= low) & (f < high)
    w = 2 * np.pi * model.frequencies
    s = 2j * np.pi * f[band, None]
    exact = (model.gains_at(0) * w / ((s + model.decays) ** 2 + w**2)).sum(axis=1)
    measured = np.fft.rfft(y)[band] / FS  # sum of h(n / fs) e^{-j omega n} ~ fs H(j omega fs)
    return 10 * np.log10(np.sum(np.abs(measured) ** 2) / np.sum(np.abs(exact) ** 2))


def test_band_direct_term_removes_the_folded_tails_and_keeps_the_ringing():
    """Impulse invariance folds the 1/f^2 tails of many modes about Nyquist (+1.4 dB
    in 16-24 kHz here); direct = "band" matches the continuous response there (within
    0.75 dB) while samples 1, 2, ... of the impulse response stay the closed form."""
    rng = np.random.default_rng(5)
    f = np.sort(rng.uniform(200.0, 15000.0, 120))
    model = ModalModel(f, 0.05 * np.pi * f, [rng.uniform(0.2, 1.0, f.size)])  # loss factor 0.05
    assert band_error_db(model, "taylor") > 1.0
    assert abs(band_error_db(model, "band")) < 0.75  # -0.55 dB
    x = np.zeros(FS // 10)
    x[0] = FS
    bank = ModalBank(model, name="bank", direct="band")(ArraySource(x))
    y = render(Graph(bank), [], 0.1, FS, 64, limiter=False).audio[0]
    ref = model.impulse_response(0.1, FS)
    assert error_db(y[1:], ref[1:]) < -120.0


def located_render(graph, rate):
    """0.1 s of ``graph`` at ``rate`` with location, gain and ramped retuning events."""
    score = [
        Event(0.02, "bank", "set", {"location": 1, "gain": 0.5}),
        Event(0.04, "bank", "set", {"freq_scale": 1.2}, ramp=0.01),
        Event(0.06, "bank", "set", {"freq_scale": 1.0}, ramp=0.005),  # the first design's poles again
        Event(0.07, "bank", "set", {"location": {"vertices": [0, 1], "weights": [0.5, 0.5]}}),
    ]
    return render(graph, score, 0.1, rate, 64, limiter=False).audio[0]


def test_rendering_a_graph_again_gives_the_bits_of_a_fresh_graph():
    """A second render of the same graph (the bank keeps its designs between renders of the
    same model and rate) matches a graph built afresh, and at a new rate a fresh graph there."""
    model = spread_model(30)
    x = np.random.default_rng(5).normal(size=FS // 4)

    def graph():
        return Graph(ModalBank(model, name="bank")(ArraySource(x)))

    reused = graph()
    first = located_render(reused, FS)
    np.testing.assert_array_equal(located_render(reused, FS), first)
    np.testing.assert_array_equal(first, located_render(graph(), FS))
    np.testing.assert_array_equal(located_render(reused, 44100), located_render(graph(), 44100))


def test_a_model_is_validated_again_at_a_new_rate():
    model = ModalModel([100.0, 30000.0], [1.0, 1.0], [[1.0, 1.0]])
    graph = Graph(ModalBank(model, name="bank")(ArraySource(np.zeros(10))))
    render(graph, [], 0.01, 96000)  # 30 kHz is below Nyquist here
    for _ in range(2):
        with pytest.raises(PatchError, match=r"nodes\.bank\.model.*frequencies\[1\].*Nyquist"):
            render(graph, [], 0.01, FS)


def test_a_set_of_several_keys_redesigns_once_and_applies_every_key():
    """One ``set`` event of three keys: the bank designs its coefficients once for it (not once
    per key), and after the ramp they are those of a bank built with the three values."""
    model = spread_model(12)
    x = np.zeros(FS // 10)
    x[0] = FS
    bank = ModalBank(model, name="bank")(ArraySource(x))
    designs = []
    design_now = bank._design

    def counted():
        designs.append(1)
        return design_now()

    bank._design = counted
    render(Graph(bank), [], 0.1, FS, 64, limiter=False)
    at_start = len(designs)  # the designs of a render with no event
    designs.clear()
    change = {"freq_scale": 1.5, "decay_scale": 3.0, "gain": 2.0}
    render(Graph(bank), [Event(0.05, "bank", "set", change, ramp=0.01)], 0.1, FS, 64, limiter=False)
    assert len(designs) == at_start + 1
    fresh = ModalBank(model, name="fresh", **change)(ArraySource(x))
    render(Graph(fresh), [], 0.001, FS, 64, limiter=False)
    np.testing.assert_allclose(bank.coef, fresh.coef, rtol=1e-12, atol=0.0)

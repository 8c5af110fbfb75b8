"""Friction (elasto-plastic bristles in a closed loop) and Engine (firing pulses through an
exhaust waveguide), and their patches, against closed forms and measured spectra."""

import math
from pathlib import Path

import numpy as np
import pytest
from helpers import ArraySource, max_abs_diff
from hypothesis import HealthCheck, given, settings
from hypothesis import strategies as st

import ugens.engine  # noqa: F401  (registers Engine for patch files)
import ugens.friction  # noqa: F401  (registers Friction for patch files)
from jassy import Event, Graph, ModalModel, PatchError, render
from jassy.patchfile import load_patch
from patches import models_machines
from ugens.engine import Engine
from ugens.friction import Friction
from ugens.modal import ModalBank

FS = 48000
BLOCKS = (1, 64, 1000)
PATCHES = Path(models_machines.__file__).parent


def run(graph_outputs, score=(), duration=0.5, block=64):
    return render(Graph(graph_outputs), list(score), duration, FS, block, limiter=False).audio


def f_ss(v, fn, static=0.8, dynamic=0.2, v_s=0.1):
    """Steady-state (Coulomb + Stribeck) friction of the elasto-plastic model."""
    return np.sign(v) * (dynamic * fn + (static - dynamic) * fn * np.exp(-((v / v_s) ** 2)))


def autocorrelation_pitch(x, fmin, fmax):
    """(f0 in Hz, normalised autocorrelation at its lag): the highest peak in the lag range,
    refined by a parabola."""
    x = x - np.mean(x)
    n = x.size
    spec = np.fft.rfft(x, 2 * n)
    ac = np.fft.irfft(np.abs(spec) ** 2)[:n]
    ac = ac / ac[0]
    lo, hi = int(FS / fmax), int(FS / fmin) + 1
    k = lo + int(np.argmax(ac[lo:hi]))
    a, b, c = ac[k - 1], ac[k], ac[k + 1]
    return FS / (k + 0.5 * (a - c) / (a - 2 * b + c)), b


def harmonic_sum_pitch(x, fmin, fmax, harmonics=8):
    """Pitch by harmonic summation: the f0 in [fmin, fmax] maximising sum_k |X(k f0)|
    (Hann window, 8x zero padding, linear interpolation of the magnitude spectrum)."""
    x = x - np.mean(x)
    nfft = 8 * (1 << int(np.ceil(np.log2(x.size))))
    mag = np.abs(np.fft.rfft(x * np.hanning(x.size), nfft))
    freqs = np.arange(mag.size) * FS / nfft
    cands = np.arange(fmin, fmax, FS / nfft / 2)
    score = sum(np.interp(k * cands, freqs, mag) for k in range(1, harmonics + 1))
    return cands[int(np.argmax(score))]


# =============================================================================== Friction
#: A resonator too heavy to move: one 50 Hz mode with a tiny driving-point gain.
RIGID = ModalModel([50.0], [1.0], [[1e-9]])


@pytest.mark.parametrize("speed", [0.01, 0.05, 0.1, 0.2, 0.5, -0.07, -1.0])
@pytest.mark.parametrize("fn", [0.5, 3.0])
def test_steady_sliding_force_is_the_stribeck_curve(speed, fn):
    sigma2 = 0.05
    fr = Friction(RIGID, name="fr", force=fn, speed=speed, sigma2=sigma2, sigma1=0.3)
    force = run(fr.tap("force"), duration=0.1)[0]
    expected = f_ss(speed, fn) + sigma2 * speed
    assert abs(np.mean(force[-480:]) / expected - 1) < 0.02


def test_static_friction_holds_a_load_below_fs_without_drift():
    # a soft damped spring (one 1 Hz mode, stiffness k = (w^2 + d^2) / (a w) = 50 N/m) dragged
    # by the exciter at 1 cm/s for 0.9 s, then held: the load k x stays below f_s = 0.8 N
    w, d, k = 2 * np.pi, 20.0, 50.0
    spring = ModalModel([1.0], [d], [[(w * w + d * d) / (k * w)]])
    fr = Friction(spring, name="fr", force=1.0, sigma0=1e5)
    score = [Event(0.0, "fr", "set", {"speed": 0.01}, jump=True), Event(0.9, "fr", "set", {"speed": 0.0})]
    x, force = run([fr, fr.tap("force")], score, duration=2.0)
    travelled = 0.01 * (0.9 + 0.0025)  # the 5 ms ramp to rest adds half its length
    assert np.max(np.abs(force)) < 0.8
    # no sliding: the contact followed the exciter to within 1 %, and once the spring's
    # transient has died out (d = 20/s) it stays put: no creep under a constant load
    assert abs(x[FS] - travelled) < 0.01 * travelled
    assert abs(x[-1] - x[3 * FS // 2]) < 1e-6 * travelled
    # the load is carried by the bristles: f = sigma0 z (at rest) = k x, and |z| <= f_s / sigma0
    assert abs(force[-1] - k * x[-1]) < 1e-3 * k * x[-1]
    assert abs(fr.state[0]) <= 0.8 / 1e5


def test_a_load_above_fs_breaks_away_and_slides():
    w, d, k = 2 * np.pi, 20.0, 50.0
    spring = ModalModel([1.0], [d], [[(w * w + d * d) / (k * w)]])
    fr = Friction(spring, name="fr", force=1.0, speed=0.01)
    x, force = run([fr, fr.tap("force")], duration=3.0)
    # the force can never exceed f_s; the spring load rises to it, then the exciter slides
    # on (f_ss(0.01 m/s) = 0.794 N) and the spring stops stretching
    assert np.max(force) <= 0.8 * (1 + 1e-9)
    assert np.max(force) > 0.97 * 0.8
    assert abs(x[-1] - x[-FS // 2]) < 1e-3 * x[-1]
    assert x[-1] < 0.8 / k * 1.01


def test_stick_slip_on_one_mode_is_periodic_at_the_mode_frequency():
    mode = ModalModel([200.0], [3.0], [[0.05]])
    fr = Friction(mode, name="fr", force=0.5, speed=0.1)
    x, force = run([fr, fr.tap("force")], duration=1.0)
    f0, peak = autocorrelation_pitch(x[FS // 2 :], 50.0, 2000.0)
    assert peak > 0.9
    assert abs(f0 / 200.0 - 1) < 0.04
    # stick-slip: the force swings between sticking (above f_c) and sliding levels
    assert np.ptp(force[FS // 2 :]) > 0.05


@pytest.mark.parametrize("force, speed", [(2.0, 0.0), (0.0, 0.3)])
def test_no_exciter_speed_or_no_contact_is_silent(force, speed):
    mode = ModalModel([200.0], [3.0], [[0.05]])
    fr = Friction(mode, name="fr", force=force, speed=speed, noise=0.5)
    x, f = run([fr, fr.tap("force")])
    assert np.all(x == 0.0) and np.all(f == 0.0)


def test_main_output_is_a_modal_bank_driven_by_the_force_output():
    model = models_machines.bowed_string_model(n_modes=20)
    fr = Friction(model, name="fr", location="normale")
    score = [Event(0.01, "fr", "set", {"force": 1.5, "speed": 0.2}, ramp=0.1)]
    x, force = run([fr, fr.tap("force")], score, duration=0.4)
    bank = ModalBank(model, location="normale", floor=0.0)(ArraySource(force))
    y = run(bank, duration=0.4)[0]
    assert np.max(np.abs(x)) > 1e-5
    # the bank's sample n is the response at n / fs plus its direct term D F[n]; the loop's
    # resonator reports the response at (n + 1) / fs (its force acts from the next sample)
    gains = model.gains_at(bank.values["location"])
    direct = np.sum(gains * 2 * np.pi * model.frequencies) / (12 * FS**2)
    ahead = y[1:] - direct * force[1:]
    assert max_abs_diff(x[:-1], ahead) < 1e-9 * np.max(np.abs(x))


def friction_score():
    return [
        Event(0.013, "fr", "set", {"force": 1.5, "speed": 0.3}, ramp=0.1),
        Event(0.2011, "fr", "set", {"speed": -0.2}, ramp=0.0771),
        Event(0.3, "fr", "set", {"force": 0.7}, jump=True),
        Event(0.35, "fr", "set", {"location": "tasto", "sigma0": 3e4, "noise": 0.2}),
        Event(0.42, "fr", "set", {"force": 0.0, "speed": 0.0}, ramp=0.03),
    ]


def test_friction_is_block_size_invariant():
    model = models_machines.bowed_string_model(n_modes=24)
    outs = []
    for block in BLOCKS:
        fr = Friction(model, name="fr", location="normale", noise=0.05, seed=9)
        outs.append(run([fr, fr.tap("force")], friction_score(), duration=0.5, block=block))
    assert np.max(np.abs(outs[0][0])) > 1e-5
    for other in outs[1:]:
        assert max_abs_diff(outs[0], other) < 1e-6 * np.max(np.abs(outs[0]), axis=1).max()


def test_friction_noise_is_seeded():
    model = models_machines.bowed_string_model(n_modes=8)

    def render_seed(seed):
        fr = Friction(model, name="fr", location="normale", noise=0.3, seed=seed)
        return run(fr, friction_score(), duration=0.3)[0]

    a, b, c = render_seed(1), render_seed(1), render_seed(2)
    np.testing.assert_array_equal(a, b)
    assert max_abs_diff(a, c) > 1e-3 * np.max(np.abs(a))


@settings(max_examples=25, deadline=None, suppress_health_check=[HealthCheck.too_slow])
@given(
    force=st.floats(0.0, 1e4),
    speed=st.floats(-100.0, 100.0),
    sigma0=st.floats(1.0, 1e9),
    sigma1=st.floats(0.0, 1e4),
    sigma2=st.floats(0.0, 1e4),
    noise=st.floats(0.0, 1e3),
    static=st.floats(0.0, 10.0),
    dynamic=st.floats(1e-3, 10.0),
    stribeck=st.floats(1e-3, 100.0),
    breakaway=st.floats(0.0, 0.99),
    gain=st.floats(1e-9, 1e3),
    freq=st.floats(1.0, 20000.0),
)
def test_friction_output_is_finite_for_extreme_settings(
    force, speed, sigma0, sigma1, sigma2, noise, static, dynamic, stribeck, breakaway, gain, freq
):
    model = ModalModel([freq, 1.7 * freq % 23000 + 1.0], [0.0, 50.0], [[gain, 0.1 * gain]])
    fr = Friction(
        model,
        name="fr",
        force=force,
        sigma0=sigma0,
        sigma1=sigma1,
        sigma2=sigma2,
        noise=noise,
        static=static,
        dynamic=dynamic,
        stribeck=stribeck,
        breakaway=breakaway,
    )
    score = [
        Event(0.001, "fr", "set", {"speed": speed}, ramp=0.004),
        Event(0.015, "fr", "set", {"speed": 0.0}),
    ]
    x, force_out = run([fr, fr.tap("force")], score, duration=0.03)
    assert np.all(np.isfinite(x)) and np.all(np.isfinite(force_out))


def test_friction_rejects_bad_settings():
    signed = ModalModel([100.0, 200.0], [1.0, 1.0], [[1.0, -1.0], [1.0, 1.0]])
    with pytest.raises(PatchError, match="driving-point"):
        Friction(signed, name="fr", location=0)
    with pytest.raises(PatchError, match="signed gains"):  # its positive row is no driving point either
        Friction(signed, name="fr", location=1)
    Friction(
        ModalModel(signed.frequencies, signed.decays, signed.gains, driving=[[1, 1], [1, 1]]), location=0
    )
    with pytest.raises(PatchError, match="driving-point"):  # the default location, checked at prepare
        run(Friction(signed, name="fr", speed=0.1, force=1.0), duration=0.01)
    for key, value in [
        ("sigma0", 0.0),
        ("dynamic", 0.0),
        ("stribeck", 0.0),
        ("force", -1.0),
        ("breakaway", 1.0),
    ]:
        with pytest.raises(PatchError, match=key):
            Friction(RIGID, name="fr", **{key: value})


# ================================================================================= Engine
def firing_frequency(rpm, cylinders, strokes):
    return rpm / 60.0 * cylinders / (2.0 if strokes == 4 else 1.0)


@pytest.mark.parametrize(
    "rpm, cylinders, strokes",
    [(800, 4, 4), (3000, 4, 4), (2000, 1, 2), (6000, 8, 4), (1500, 6, 2), (1100, 3, 4), (4500, 2, 2)],
)
def test_engine_fundamental_is_the_firing_frequency(rpm, cylinders, strokes):
    eng = Engine(name="e", rpm=rpm, cylinders=cylinders, strokes=strokes, throttle=0.8, irregularity=0.1)
    x = run(eng, duration=2.0)[0][FS // 2 :]
    f = firing_frequency(rpm, cylinders, strokes)
    f0 = harmonic_sum_pitch(x, 0.4 * f, 2.6 * f)
    assert abs(f0 / f - 1) < 0.02


def pulse_onsets(p, tau):
    """Exact onsets (fractional samples) of non-overlapping alpha pulses A (x/tau) e^(1 - x/tau):
    from two consecutive samples of a pulse, p[n] / p[n+1] = x / ((x + 1) r), x = n - onset."""
    r = math.exp(-1.0 / (tau * FS))
    on = p > 1e-9 * np.max(p)
    firsts = np.flatnonzero(on[1:] & ~on[:-1]) + 1
    rho = p[firsts] / p[firsts + 1]
    return firsts - rho * r / (1.0 - rho * r)


def test_rpm_ramp_moves_the_firings_continuously():
    # rpm 1000 -> 3000 over 1 s from 0.2 s (4 cylinders, 4 strokes: f = rpm / 30 Hz). The
    # firing k is where the accumulated phase, sum over frames 0..n of f / fs, reaches k
    # (linear between frames); no phase reset anywhere, so every onset is where it belongs.
    tau = 1e-4
    eng = Engine(name="e", rpm=1000.0, throttle=1.0, irregularity=0.0, pulse=tau)
    score = [Event(0.2, "e", "set", {"rpm": 3000.0}, ramp=1.0)]
    pulses = run(eng.tap("pulses"), score, duration=1.5)[0]
    onsets = pulse_onsets(pulses, tau)
    frames = np.arange(pulses.size)
    a, m = round(0.2 * FS), round(1.0 * FS)  # the ramp: old value at frame a, target from a + m
    rpm = np.clip(1000.0 + 2000.0 * (frames - a) / m, 1000.0, 3000.0)
    phase = np.cumsum(rpm / 30.0 / FS)
    expected = np.interp(np.arange(1, int(phase[-1]) + 1), phase, frames.astype(float))
    assert onsets.size == expected.size
    assert np.max(np.abs(onsets - expected)) < 1e-3  # samples
    # the firing rate follows the rpm: 1000 rpm -> 33.3 Hz before, 3000 rpm -> 100 Hz after
    intervals = np.diff(onsets)
    assert abs(FS / intervals[0] / (1000 / 30) - 1) < 1e-6
    assert abs(FS / intervals[-1] / (3000 / 30) - 1) < 1e-6


def test_engine_without_irregularity_is_exactly_periodic():
    eng = Engine(name="e", rpm=3000.0, throttle=0.7, irregularity=0.0, misfire=0.0)  # 100 Hz: 480 samples
    x, pulses = run([eng, eng.tap("pulses")], duration=1.5)
    period = 480
    p = pulses[FS // 10 :]
    assert max_abs_diff(p[period:], p[:-period]) < 1e-9 * np.max(p)
    y = x[FS:]
    assert max_abs_diff(y[period:], y[:-period]) < 1e-6 * np.max(np.abs(y))
    # a differing period is clearly visible: the check could fail
    assert max_abs_diff(p[period + 1 :], p[: -period - 1]) > 0.01 * np.max(p)
    eng2 = Engine(name="e", rpm=3000.0, throttle=0.7, irregularity=0.2)
    q = run(eng2.tap("pulses"), duration=1.5)[0][FS // 10 :]
    assert max_abs_diff(q[period:], q[:-period]) > 0.05 * np.max(q)


def test_engine_output_scale_and_throttle():
    full = Engine(name="e", rpm=3000.0, throttle=1.0, irregularity=0.0)
    half = Engine(name="e", rpm=3000.0, throttle=0.5, irregularity=0.0)
    a = run(full, duration=1.0)[0][FS // 2 :]
    b = run(half, duration=1.0)[0][FS // 2 :]
    assert abs(np.max(np.abs(a)) - 0.5) < 0.01
    assert max_abs_diff(b, 0.5 * a) < 1e-9


def test_misfire_probability():
    tau = 1e-4
    eng = Engine(name="e", rpm=3000.0, throttle=1.0, irregularity=0.0, misfire=0.3, pulse=tau, seed=5)
    pulses = run(eng.tap("pulses"), duration=4.0)[0]
    fired = pulse_onsets(pulses, tau).size
    expected = int(4.0 * 100)  # firings at 100 Hz
    assert abs(1 - fired / expected - 0.3) < 0.07  # binomial std 0.023


def test_engine_is_seeded_and_reproducible():
    def render_seed(seed):
        return run(Engine(name="e", rpm=2000.0, irregularity=0.5, misfire=0.1, seed=seed), duration=0.5)[0]

    a, b, c = render_seed(3), render_seed(3), render_seed(4)
    np.testing.assert_array_equal(a, b)
    assert max_abs_diff(a, c) > 0.01 * np.max(np.abs(a))


def test_engine_is_block_size_invariant():
    score = [
        Event(0.05, "e", "set", {"rpm": 5000.0}, ramp=0.3),
        Event(0.1, "e", "set", {"throttle": 1.0}, ramp=0.05),
        Event(0.2503, "e", "set", {"irregularity": 0.6, "misfire": 0.2, "port_reflection": 0.5}),
        Event(0.4, "e", "set", {"rpm": 700.0, "throttle": 0.1}, ramp=0.2),
        Event(0.55, "e", "set", {"rpm": 2500.0}, jump=True),
    ]
    outs = []
    for block in BLOCKS:
        eng = Engine(name="e", irregularity=0.3, seed=2)
        outs.append(run([eng, eng.tap("pulses")], score, 0.7, block))
    assert np.max(np.abs(outs[0][0])) > 0.01
    for other in outs[1:]:
        assert max_abs_diff(outs[0], other) < 1e-6


@settings(max_examples=25, deadline=None, suppress_health_check=[HealthCheck.too_slow])
@given(
    rpm=st.floats(0.0, 20000.0),
    cylinders=st.integers(1, 16),
    strokes=st.sampled_from([2, 4]),
    throttle=st.floats(0.0, 1.0),
    irregularity=st.floats(0.0, 1.0),
    misfire=st.floats(0.0, 1.0),
    pulse=st.floats(1e-5, 0.1),
    length=st.floats(0.01, 50.0),
    c=st.floats(100.0, 5000.0),
    radius=st.floats(1e-6, 1.0),
    port=st.floats(0.0, 0.99),
)
def test_engine_output_is_finite_for_extreme_settings(
    rpm, cylinders, strokes, throttle, irregularity, misfire, pulse, length, c, radius, port
):
    length = max(length, 1.01 * c / FS)  # at least one sample of pipe
    eng = Engine(
        name="e",
        rpm=rpm,
        cylinders=cylinders,
        strokes=strokes,
        throttle=throttle,
        irregularity=irregularity,
        misfire=misfire,
        pulse=pulse,
        exhaust_length=length,
        c=c,
        radius=radius,
        port_reflection=port,
    )
    score = [Event(0.01, "e", "set", {"rpm": 20000.0 - rpm, "throttle": 1.0 - throttle}, ramp=0.02)]
    x, pulses = run([eng, eng.tap("pulses")], score, duration=0.05)
    assert np.all(np.isfinite(x)) and np.all(np.isfinite(pulses))


def test_engine_rejects_bad_settings():
    for key, value, match in [
        ("strokes", 3, "2 or 4 strokes"),
        ("c", 0.0, "c"),
        ("c", -340.0, "c"),
        ("pulse", 0.0, "pulse"),
        ("exhaust_length", -1.0, "exhaust_length"),
        ("cylinders", 0, "cylinders"),
        ("throttle", 1.5, "throttle"),
        ("port_reflection", 1.0, "port_reflection"),
    ]:
        with pytest.raises(PatchError, match=match):
            Engine(name="e", **{key: value})
    with pytest.raises(PatchError, match="at least one sample"):
        run(Engine(name="e", exhaust_length=0.005), duration=0.01)


# ================================================================================ Patches
def test_string_model_is_a_driving_point_string():
    model = models_machines.bowed_string_model()
    n = np.arange(1, model.n_modes + 1)
    assert model.n_modes <= 60
    np.testing.assert_allclose(model.frequencies / (n * 196.0), 1.0, atol=0.05)  # nearly harmonic
    assert np.all(np.diff(model.frequencies / n) > 0)  # stiffness: partials slightly sharp
    assert np.all(model.gains >= 0)
    beta = models_machines.BOW_POINTS["normale"]
    shape = np.sin(n * np.pi * beta) ** 2 / model.frequencies
    np.testing.assert_allclose(model.gains_at("normale") / model.gains_at("normale")[0], shape / shape[0])


def test_bowed_string_patch_sustains_the_fundamental():
    patch = load_patch(PATCHES / "bowed-string.toml")
    x = render(patch.graph, patch.score, patch.duration, FS, 64).audio[0]
    f1 = models_machines.bowed_string_model().frequencies[0]
    assert 0.25 < np.max(np.abs(x)) < 0.8  # around -6 dBFS
    for start, stop in [(0.6, 2.2), (3.0, 4.4)]:  # down-bow and up-bow sustains
        seg = x[int(start * FS) : int(stop * FS)]
        f0, peak = autocorrelation_pitch(seg, 60.0, 1000.0)
        assert peak > 0.9
        assert abs(f0 / f1 - 1) < 0.03
        assert np.sqrt(np.mean(seg**2)) > 0.05  # sustained, not decaying
    tail = x[int(5.5 * FS) :]
    assert np.sqrt(np.mean(tail**2)) < 0.01  # released: the string rings down


def test_engine_patch_follows_the_rpm():
    patch = load_patch(PATCHES / "engine.toml")
    x = render(patch.graph, patch.score, patch.duration, FS, 64).audio[0]
    assert 0.25 < np.max(np.abs(x)) < 0.8
    for start, stop, rpm in [(0.2, 1.4, 800.0), (3.7, 4.2, 4500.0), (7.0, 8.0, 850.0)]:
        seg = x[int(start * FS) : int(stop * FS)]
        f = firing_frequency(rpm, 4, 4)
        f0 = harmonic_sum_pitch(seg, 0.4 * f, 2.6 * f)
        assert abs(f0 / f - 1) < 0.03

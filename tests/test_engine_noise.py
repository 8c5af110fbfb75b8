"""Engine intake and mechanical noise: the airbox-filtered suction train, the block noise
band and its firing-rate bursts, and the sum into the main output."""

import math

import numpy as np
from scipy import signal

from jassy import Event, Graph, render
from ugens.engine import Engine

FS = 48000


def run(eng, duration=1.0, block=64, score=()):
    taps = [eng.tap("pulses"), eng.tap("intake"), eng.tap("mechanical")]
    r = render(Graph(eng, taps), score, duration=duration, sample_rate=FS, block=block, limiter=False)
    return r.audio[0], r.haptic


def rbj_bandpass(f, q):
    """RBJ cookbook band-pass, 0 dB peak gain (b, a)."""
    w = 2 * math.pi * f / FS
    alpha = math.sin(w) / (2 * q)
    return np.array([alpha, 0.0, -alpha]), np.array([1 + alpha, -2 * math.cos(w), 1 - alpha])


def test_intake_is_the_inverted_pulse_train_through_the_airbox():
    eng = Engine(
        name="e", rpm=2400.0, throttle=0.8, intake_level=0.5, hiss=0.0, airbox_freq=160.0, airbox_q=4.0
    )
    _, (pulses, intake, mech) = run(eng)
    b, a = rbj_bandpass(160.0, 4.0)
    np.testing.assert_allclose(intake, 0.5 * signal.lfilter(b, a, -pulses), atol=1e-12)
    assert np.all(mech == 0.0)


def test_main_output_is_exhaust_plus_intake_plus_mechanical():
    quiet, _ = run(Engine(name="e", rpm=3000.0, throttle=0.7, seed=4))
    loud, (_, intake, mech) = run(Engine(name="e", rpm=3000.0, throttle=0.7, seed=4, intake_level=0.4,
                                         mechanical_level=0.3))  # fmt: skip
    assert np.max(np.abs(intake)) > 0.01 and np.max(np.abs(mech)) > 0.01
    np.testing.assert_allclose(loud, quiet + intake + mech, atol=1e-12)


def test_mechanical_noise_is_above_the_block_cutoff_in_bursts_at_the_firing_rate():
    rpm, block_freq = 3000.0, 2000.0  # 4 cylinders, 4 strokes: 100 firings per second
    eng = Engine(
        name="e", rpm=rpm, throttle=1.0, irregularity=0.0, mechanical_level=1.0, block_freq=block_freq
    )
    _, (_, _, mech) = run(eng, duration=2.0)
    f, p = signal.welch(mech[FS // 2 :], FS, nperseg=4096)
    assert p[f < block_freq / 4].sum() < 0.01 * p.sum()
    # the power envelope (mech^2) repeats at the firing rate: its spectrum peaks there
    fe, pe = signal.welch(mech[FS // 2 :] ** 2, FS, nperseg=FS // 2)
    band = (fe > 20) & (fe < 1000)
    assert abs(fe[band][np.argmax(pe[band])] - rpm / 60 * 2) <= 2.0


def test_mechanical_level_grows_as_rpm_squared():
    def rms(rpm):
        e = Engine(name="e", rpm=rpm, throttle=1.0, irregularity=0.0, mechanical_level=1.0, block_freq=100.0)
        _, (_, _, m) = run(e, duration=1.0)
        return np.sqrt(np.mean(m[FS // 2 :] ** 2))

    # noise of variance 1/3 times |pulse train|: the power per firing is fixed, the firings
    # per second double, so power ~ rpm^4 * rpm: RMS ~ rpm^2.5
    assert abs(rms(3000.0) / rms(1500.0) / 2**2.5 - 1) < 0.1


def test_block_size_invariance():
    def case():
        return Engine(name="e", irregularity=0.3, seed=2, intake_level=0.3, mechanical_level=0.2), [
            Event(0.05, "e", "set", {"rpm": 3000.0}, ramp=0.1),
            Event(0.1, "e", "set", {"intake_level": 0.6, "hiss": 0.5}),
        ]

    outs = []
    for block in (1, 64, 1000):
        eng, score = case()
        outs.append(run(eng, duration=0.3, block=block, score=score)[0])
    for out in outs[1:]:
        assert np.max(np.abs(out - outs[0])) < 1e-12

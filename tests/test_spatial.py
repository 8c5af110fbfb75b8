"""Spatialiser: per-ear response to a sine against the closed forms (1/r, r/c, Woodworth
ITD, Brown-Duda head shadow, air absorption, equal-power pan)."""

import math

import numpy as np
import pytest
from helpers import ArraySource
from scipy import signal

from jassy import Event, Graph, render
from ugens.oscillators import Sine
from ugens.spatial import Spatialiser

FS = 48000
A, C = 0.0875, 343.0


def ears(node, score=(), duration=0.5, block=64):
    r = render(Graph([node, node.tap("right")]), score, duration=duration, sample_rate=FS, block=block,
               limiter=False)  # fmt: skip
    return r.audio


def phasor(y, f):
    """Complex gain H of y = |H| sin(w n + arg H) (least squares over y)."""
    n = np.arange(y.size)
    w = 2 * np.pi * f / FS
    (p, q), *_ = np.linalg.lstsq(np.column_stack([np.cos(w * n), np.sin(w * n)]), y, rcond=None)
    return complex(q, p)


def expected(f, position, ear, mode):
    """Closed-form complex response of one ear (-1 left, +1 right) to a sine at f Hz."""
    x, y, z = position
    r = math.sqrt(x * x + y * y + z * z)
    s = x / r
    w = 2 * np.pi * f / FS
    delay = r / C * FS
    gain = 1.0 / r
    if mode == "binaural":
        theta = math.asin(s) * ear  # positive when the source is on this ear's side
        delay += (-A / C * math.sin(theta) if theta >= 0 else A / C * abs(theta)) * FS
        phi = math.acos(s * ear)  # angle between the source and this ear's axis
        alpha = 1.05 + 0.95 * math.cos(phi / math.radians(150.0) * math.pi)
        w0, k = C / A, 2 * FS  # Brown & Duda's one-pole one-zero, bilinear transform
        b = [(2 * w0 + alpha * k), (2 * w0 - alpha * k)]
        a = [(2 * w0 + k), (2 * w0 - k)]
        shadow = signal.freqz(b, a, worN=[w])[1][0]
    else:
        angle = math.pi / 4 * (1 + s)
        gain *= math.cos(angle) if ear < 0 else math.sin(angle)
        shadow = 1.0
    k = 1 - math.exp(-2 * math.pi * 53800.0 / math.sqrt(r) / FS)
    air = signal.freqz([k], [1, -(1 - k)], worN=[w])[1][0]
    return gain * shadow * air * np.exp(-1j * w * delay)


@pytest.mark.parametrize("mode", ["binaural", "stereo"])
@pytest.mark.parametrize("position", [(1.0, 1.5, 0.0), (-3.0, 0.5, 1.0), (0.0, -2.0, 0.0), (5.0, 0.0, 0.0)])
@pytest.mark.parametrize("f", [300.0, 2500.0])
def test_ear_responses_match_the_closed_form(mode, position, f):
    x, y, z = position
    node = Spatialiser(Sine(freq=f, name="s"), name="p", x=x, y=y, z=z, mode=mode)
    left, right = ears(node, duration=0.3)
    for ear, out in ((-1, left), (1, right)):
        got = phasor(out[FS // 10 :], f)
        want = expected(f, position, ear, mode) * np.exp(1j * 2 * np.pi * f / FS * (FS // 10))
        assert abs(got / want - 1) < 2e-3, (ear, got, want)


def brown_duda(f, phi):
    """The analog head-shadow filter at the bilinear transform's warped frequency for the
    digital frequency f (where the digital filter equals it exactly)."""
    omega = 2 * FS * math.tan(math.pi * f / FS)
    alpha = 1.05 + 0.95 * math.cos(math.pi * phi / math.radians(150.0))
    return (1 + 1j * alpha * omega / (2 * C / A)) / (1 + 1j * omega / (2 * C / A))


@pytest.mark.parametrize("azimuth", [30.0, 90.0])
def test_itd_is_woodworths_and_the_ild_brown_dudas(azimuth):
    """Source on the right at ``azimuth`` degrees: the right ear leads by (a / c)(theta +
    sin theta) once the head-shadow filters' own phases are taken out, and the level
    difference is that of the two ears' shadow filters."""
    theta = math.radians(azimuth)
    x, y = 2.0 * math.sin(theta), 2.0 * math.cos(theta)
    for f in (200.0, 1000.0, 6000.0):
        node = Spatialiser(Sine(freq=f, name="s"), name="p", x=x, y=y, air_absorption=False)
        left, right = ears(node, duration=0.2)
        ratio = phasor(right[FS // 20 :], f) / phasor(left[FS // 20 :], f)
        shadow = brown_duda(f, math.pi / 2 - theta) / brown_duda(f, math.pi / 2 + theta)
        itd = np.angle(ratio / shadow) / (2 * math.pi * f)
        if f < 700.0:  # below the phase ambiguity of a 0.66 ms ITD (f ITD < 1/2)
            assert abs(itd / (A / C * (theta + math.sin(theta))) - 1) < 0.01
        assert (
            abs(20 * np.log10(abs(ratio)) - 20 * np.log10(abs(shadow))) < 0.1
        )  # the Hermite read: -0.08 dB at 6 kHz at worst


def test_equal_power_pan_and_inverse_distance():
    powers = []
    for x in (-2.0, -0.5, 0.0, 1.0, 3.0):
        y = math.sqrt(9.0 - x * x)  # 3 m away
        left, right = ears(Spatialiser(Sine(freq=200.0, name="s"), name="p", x=x, y=y, mode="stereo",
                                       air_absorption=False), duration=0.2)  # fmt: skip
        powers.append(np.mean(left[FS // 20 :] ** 2 + right[FS // 20 :] ** 2))
    assert np.allclose(powers, 0.5 / 9.0, rtol=2e-3)  # sine power 1/2, gain 1/r


def test_position_inputs_override_the_parameters():
    n = FS // 5
    xs = ArraySource(np.full(n, 2.0))
    ys = ArraySource(np.zeros(n))
    node = Spatialiser(Sine(freq=300.0, name="s"), name="p", x=-4.0, y=1.0, mode="stereo")
    node.connect(xs, "track_x")
    node.connect(ys, "track_y")
    left, right = ears(node, duration=0.2)
    assert np.max(np.abs(left[FS // 20 :])) < 1e-9  # hard right at x = 2, y = 0
    assert abs(np.max(np.abs(right[FS // 20 :])) - 0.5) < 1e-3


def test_block_size_invariance():
    def case():
        return Spatialiser(Sine(freq=440.0, name="s"), name="u", x=-3.0, y=1.0), [
            Event(0.05, "u", "set", {"x": 3.0, "y": 0.5, "z": 1.0}, ramp=0.2)
        ]

    outs = []
    for block in (1, 64, 1000):
        node, score = case()
        outs.append(np.concatenate(ears(node, score, duration=0.3, block=block)))
    assert np.any(outs[0] != 0)
    for out in outs[1:]:
        assert np.max(np.abs(out - outs[0])) < 1e-9


def per_sample_reference(x, xs, ys, zs, mode="binaural", ref=1.0, min_r=0.2):
    """The Spatialiser's model evaluated independently at every sample (numpy geometry,
    a plain loop for the delay line and the filters): distance gain, r / c delay read by
    4-point Hermite interpolation, air-absorption one-pole, Brown-Duda head shadow."""
    r = np.maximum(np.sqrt(xs**2 + ys**2 + zs**2), min_r)
    s = np.clip(xs / r, -1.0, 1.0)
    delay = r / C * FS
    k = 1 - np.exp(-2 * np.pi * 53800.0 / np.sqrt(r) / FS)
    if mode == "binaural":
        theta = np.arcsin(s)
        near, far = -A / C * np.abs(s) * FS, A / C * np.abs(theta) * FS
        d = {1: delay + np.where(theta >= 0, near, far), -1: delay + np.where(theta >= 0, far, near)}
        g = {1: ref / r, -1: ref / r}
        w0, kb = C / A, 2 * FS
        coef = {}
        for ear in (-1, 1):
            alpha = 1.05 + 0.95 * np.cos(np.pi * np.arccos(s * ear) / math.radians(150.0))
            coef[ear] = ((2 * w0 + alpha * kb) / (2 * w0 + kb), (2 * w0 - alpha * kb) / (2 * w0 + kb))
        a1 = (2 * w0 - kb) / (2 * w0 + kb)
    else:
        d = {1: delay, -1: delay}
        angle = np.pi / 4 * (1 + s)
        g = {1: ref / r * np.sin(angle), -1: ref / r * np.cos(angle)}
    outs = []
    padded = np.r_[np.zeros(4096), x]
    for ear in (-1, 1):
        dd = np.clip(d[ear], 2.0, None)
        n = np.arange(x.size) + 4096
        i = np.floor(dd).astype(int)
        t = dd - i
        x0, x1, x2, x3 = padded[n - i + 1], padded[n - i], padded[n - i - 1], padded[n - i - 2]
        c1, c2, c3 = 0.5 * (x2 - x0), x0 - 2.5 * x1 + 2 * x2 - 0.5 * x3, 0.5 * (x3 - x0) + 1.5 * (x1 - x2)
        y = g[ear] * (((c3 * t + c2) * t + c1) * t + x1)
        out = np.empty_like(y)
        lp = hx = hy = 0.0
        for j in range(y.size):
            lp += k[j] * (y[j] - lp)
            v = lp
            if mode == "binaural":
                v = coef[ear][0][j] * lp + coef[ear][1][j] * hx - a1 * hy
                hx, hy = lp, v
            out[j] = v
        outs.append(out)
    return outs


def spatialised(x, xs, ys, zs, mode="binaural", block=64):
    node = Spatialiser(ArraySource(x), name="p", mode=mode)
    for key, track in zip("xyz", (xs, ys, zs), strict=True):
        node.connect(ArraySource(track), f"track_{key}")
    return ears(node, duration=x.size / FS, block=block)


@pytest.mark.parametrize("mode", ["binaural", "stereo"])
def test_a_still_source_is_rendered_as_with_per_sample_geometry(mode):
    """The geometry is evaluated every CONTROL_PERIOD samples and ramped in between; for a
    still source the ramps are flat, so the output is the per-sample model's to rounding."""
    n = FS // 10
    x = np.random.default_rng(1).normal(size=n)
    place = [np.full(n, v) for v in (-0.7, 1.3, 0.4)]
    got = spatialised(x, *place, mode=mode)
    want = per_sample_reference(x, *place, mode=mode)
    for g, w in zip(got, want, strict=True):
        assert np.max(np.abs(g - w)) < 1e-12 * np.max(np.abs(w))


MOTIONS = {  # (x, y, z) m of t s; the bound on the rms error relative to the output's rms
    # walking pace, passing half a metre in front of the head
    "pass at 2 m/s": (lambda t: (-0.2 + 2.0 * t, 0.5 + 0 * t, 0.1 + 0 * t), 1e-4),
    # circling the head at 1 m once a second (6.3 m/s); crossing the ear axis is a kink of
    # the Woodworth ITD in time, which a ramp rounds off over one period
    "circle at 1 rev/s": (lambda t: (np.sin(2 * np.pi * t), np.cos(2 * np.pi * t), 0 * t), 3e-3),
}


@pytest.mark.parametrize("mode", ["binaural", "stereo"])
@pytest.mark.parametrize("motion", list(MOTIONS))
def test_a_moving_source_stays_close_to_per_sample_geometry(mode, motion):
    """White noise from a moving source: the control-rate ramps (each aimed at the geometry
    of the position extrapolated one period on) stay within the stated rms error of the
    per-sample model, at any block size."""
    n = FS // 5
    path, bound = MOTIONS[motion]
    xs, ys, zs = path(np.arange(n) / FS)
    x = np.random.default_rng(2).normal(size=n)
    want = per_sample_reference(x, xs, ys, zs, mode=mode)
    for block in (64, 5):
        got = spatialised(x, xs, ys, zs, mode=mode, block=block)
        for g, w in zip(got, want, strict=True):
            assert np.sqrt(np.mean((g - w) ** 2)) < bound * np.sqrt(np.mean(w**2))

"""Stochastic controllers (Crumple, Break, Bounce), bubbles (Bubble, BubbleStream), their
models and the crumple / wok-sizzle patches: against closed forms, distributions and
measured spectra."""

import math
from pathlib import Path

import numpy as np
import pytest
from helpers import max_abs_diff
from numpy.polynomial.legendre import leggauss
from scipy import signal, stats
from scipy.linalg import eigh

from jassy import Event, Graph, ModalModel, PatchError, render
from jassy.patchfile import load_patch
from patches.models_stochastic import free_plate_roots, paper_sheet_model
from ugens.bubbles import Bubble, BubbleStream, bubble_decay
from ugens.stochastic import Bounce, Break, Crumple

FS = 48000
BLOCKS = (1, 64, 1000)


def run(node, events, seconds, block=64, taps=()):
    """Render ``node`` (and its taps) without the limiter: rows main, then the taps."""
    graph = Graph(node, haptic=[node.tap(t) for t in taps])
    r = render(graph, events, seconds, FS, block, limiter=False)
    return np.vstack([r.audio, r.haptic])


def pulses_from_force(force, log, T):
    """Impulse of each logged pulse (t0, T samples) integrated from the force signal."""
    out = []
    for t0 in log[:, 0] * FS:
        lo, hi = math.floor(t0) + 1, math.ceil(t0 + T)
        out.append(force[lo:hi].sum() / FS)
    return np.asarray(out)


# ------------------------------------------------------------------ Crumple / Break
def test_crumple_count_is_poisson_and_intervals_exponential():
    rate, seconds = 400.0, 20.0
    c = Crumple(name="c", density=rate, seed=5)
    c.log_capacity = 20000
    run(c, [Event(0.0, "c", "start", {})], seconds)
    mean = rate * seconds
    assert abs(c.events - mean) < 4 * math.sqrt(mean)
    times = c.event_log()[:, 0]
    assert times.size == c.events
    p = stats.kstest(np.diff(times), "expon", args=(0, 1 / rate)).pvalue
    assert p > 1e-3
    # a per-sample Bernoulli draw (SDT) would quantise the intervals to the sample grid
    assert np.mean(np.abs(times * FS - np.round(times * FS)) > 1e-3) > 0.9


def test_crumple_energies_and_sizes_follow_sdt_distributions():
    e0, frag = 2e-3, 0.4
    c = Crumple(name="c", density=2000.0, crushing_energy=e0, fragment=frag, seed=11)
    c.log_capacity = 40000
    run(c, [Event(0.0, "c", "start", {})], 8.0)
    log = c.event_log()
    x = log[:, 1] / e0
    assert x.min() >= 0.1 - 1e-12 and x.max() <= 10.0 + 1e-12
    # clip(Exp(1.45), 0.1, 10): an atom of 1 - e^-0.145 at 0.1, an exponential above
    p_low = 1 - math.exp(-1.45 * 0.1)
    n = x.size
    low = np.isclose(x, 0.1, rtol=1e-12)
    assert abs(low.sum() - n * p_low) < 4 * math.sqrt(n * p_low * (1 - p_low))
    inside = x[~low & (x < 10.0)] - 0.1
    assert stats.kstest(inside, "expon", args=(0, 1 / 1.45)).pvalue > 1e-3
    assert stats.kstest(log[:, 2], "uniform", args=(0.5 * frag, 0.5 * frag)).pvalue > 1e-3


def test_each_pulse_carries_sqrt_2_m_e_and_starts_after_its_time():
    mass, tau = 2e-3, 1e-4
    c = Crumple(name="c", density=60.0, mass=mass, duration=tau, seed=3)
    c.log_capacity = 1000
    force, size = run(c, [Event(0.0, "c", "start", {})], 2.0, taps=("size",))
    log = c.event_log()
    T = tau * FS
    t0 = log[:, 0] * FS
    gaps = np.diff(t0)
    alone = np.concatenate([[True], gaps > T + 1]) & np.concatenate([gaps > T + 1, [True]])
    assert alone.sum() > 0.9 * alone.size  # pulses that overlap no other can be read apart
    J = pulses_from_force(force, log[alone], T)
    np.testing.assert_allclose(J, np.sqrt(2 * mass * log[alone, 1]), rtol=1e-9)
    np.testing.assert_allclose(J, log[alone, 3], rtol=1e-9)
    first = np.floor(t0).astype(int) + 1
    assert np.all(force[first] > 0) and np.all(force[first[alone] - 1] == 0)
    # the size output holds the latest fragment size from the pulse's first sample on
    np.testing.assert_array_equal(size[first], log[:, 2])
    np.testing.assert_array_equal(size[first[1:] - 1], log[:-1, 2])
    assert force.sum() / FS == pytest.approx(log[:, 3].sum(), rel=1e-9)


def test_crumple_with_an_energy_budget_stops_when_spent():
    budget = 0.02
    c = Crumple(name="c", density=500.0, crushing_energy=1e-3, seed=2)
    c.log_capacity = 10000
    force = run(c, [Event(0.1, "c", "start", {"energy": budget})], 3.0)[0]
    log = c.event_log()
    assert log[:, 1].sum() == pytest.approx(budget, rel=1e-12)
    assert c.events == log.shape[0] < 100
    last_end = math.ceil(log[-1, 0] * FS + c.values["duration"] * FS)
    assert np.all(force[last_end:] == 0.0) and force[:last_end].max() > 0


def test_break_full_scaling_energies_sum_to_the_budget_and_the_cascade_thins_out():
    budget, mass, tau = 0.05, 1e-3, 5e-5
    b = Break(name="b", density=800.0, crushing_energy=1e-3, mass=mass, duration=tau, seed=11, scaling="full")
    b.log_capacity = 10000
    force = run(b, [Event(0.05, "b", "break", {"energy": budget})], 4.0)[0]
    log = b.event_log()
    T = max(tau * FS, 2.0)
    t0 = log[:, 0] * FS
    assert np.all(np.diff(t0) > T + 1)  # no overlaps for this seed: pulses can be read apart
    J = pulses_from_force(force, log, T)
    # energy from each measured impulse, E = J^2 / (2 m): they add up to the stored energy
    assert np.sum(J**2 / (2 * mass)) == pytest.approx(budget, rel=1e-9)
    assert force.sum() / FS == pytest.approx(np.sqrt(2 * mass * log[:, 1]).sum(), rel=1e-9)
    gaps = np.diff(log[:, 0])
    q = gaps.size // 4
    assert gaps[-q:].mean() > 2 * gaps[:q].mean()  # the rate falls with the energy left
    end = math.ceil(t0[-1] + T)
    assert np.all(force[end:] == 0.0)


def test_seeded_reproducibility():
    def go(seed):
        c = Crumple(name="c", density=300.0, seed=seed)
        return run(c, [Event(0.0, "c", "start", {})], 1.0)[0]

    a, b, other = go(9), go(9), go(10)
    np.testing.assert_array_equal(a, b)
    assert max_abs_diff(a, other) > 0.0


def test_invalid_values_are_rejected():
    with pytest.raises(PatchError, match="mass"):
        Crumple(mass=-1.0)
    with pytest.raises(PatchError, match="restitution"):
        Bounce(restitution=1.5)
    with pytest.raises(PatchError, match="min_radius"):
        BubbleStream(min_radius=0.0)
    b = Bounce(name="b")
    with pytest.raises(PatchError, match="height"):
        run(b, [Event(0.0, "b", "drop", {})], 0.1)


# ------------------------------------------------------------------------- Bounce
def test_bounce_times_and_impulses_follow_the_closed_form():
    g, e, m, h, t_drop = 9.81, 0.75, 0.02, 0.4, 0.05
    b = Bounce(name="b", restitution=e, mass=m, gravity=g, min_speed=0.05, duration=3e-4)
    b.log_capacity = 1000
    force = run(b, [Event(t_drop, "b", "drop", {"height": h})], 3.0)[0]
    log = b.event_log()
    v0 = math.sqrt(2 * g * h)
    count = math.floor(math.log(0.05 / v0) / math.log(e)) + 1  # the last impact rebounds below min_speed
    assert log.shape[0] == count
    v = v0 * e ** np.arange(count)
    t = t_drop + math.sqrt(2 * h / g) + np.concatenate([[0.0], np.cumsum(2 * e * v[:-1] / g)])
    np.testing.assert_allclose(log[:, 0], t, rtol=0, atol=1e-9)
    np.testing.assert_allclose(np.diff(log[:, 0]), 2 * v[1:] / g, rtol=1e-9)
    np.testing.assert_allclose(log[:, 3], m * (1 + e) * v, rtol=1e-12)
    assert force.sum() / FS == pytest.approx(m * (1 + e) * v.sum(), rel=1e-9)


def test_bounce_speed_drop_and_irregularity():
    b = Bounce(name="b", restitution=0.8, irregularity=0.6, mass=0.01, seed=1)
    b.log_capacity = 1000
    run(b, [Event(0.1, "b", "drop", {"speed": 2.0})], 2.0)
    log = b.event_log()
    assert log[0, 0] == pytest.approx(0.1, abs=1e-12)  # speed: hits at the event time
    v = np.sqrt(2 * log[:, 1] / 0.01)
    ratio = v[1:] / v[:-1]
    assert np.all(ratio <= 0.8 + 1e-12) and np.all(ratio >= 0.8 * 0.4 - 1e-12)
    assert np.std(ratio) > 0.02  # irregular


# --------------------------------------------------------------- block invariance
def _controllers_and_scores():
    c = Crumple(name="n", density=300.0, duration=3e-4, seed=1)
    c_score = [
        Event(0.01, "n", "start", {}),
        Event(0.2, "n", "set", {"density": 3000.0, "crushing_energy": 3e-3}),
        Event(0.4, "n", "set", {"fragment": 0.3}, jump=True),
        Event(0.5, "n", "stop", {}),
        Event(0.55, "n", "start", {"energy": 0.01}),
    ]
    k = Break(name="n", duration=2e-3, seed=2)
    k_score = [Event(0.0301, "n", "break", {"energy": 0.04}), Event(0.3, "n", "set", {"density": 200.0})]
    b = Bounce(name="n", restitution=0.6, irregularity=0.3, seed=3)
    b_score = [Event(0.0123, "n", "drop", {"height": 0.05}), Event(0.4, "n", "drop", {"speed": 1.0})]
    return [(c, c_score), (k, k_score), (b, b_score)]


@pytest.mark.parametrize("index", [0, 1, 2])
def test_controllers_block_size_invariant(index):
    node, score = _controllers_and_scores()[index]
    outs = [run(node, score, 0.8, block, taps=("size",)) for block in BLOCKS]
    assert np.max(np.abs(outs[0][0])) > 0 and np.max(outs[0][1]) > 0
    for other in outs[1:]:
        assert max_abs_diff(outs[0], other) < 1e-6


# -------------------------------------------------------------------------- bubbles
def bubble_closed_form(n, t0_samples, radius, depth, rise, gain=1.0):
    """van den Doel's bubble sampled at frames n, born at fractional sample t0."""
    t = (n - t0_samples) / FS
    f0, d = 3.0 / radius, 0.13 / radius + 0.0072 * radius**-1.5
    p = (
        gain
        * depth
        * (radius / 1e-3) ** 1.5
        * np.exp(-d * t)
        * np.sin(2 * np.pi * f0 * (t + 0.5 * rise * d * t * t))
    )
    return np.where(t > 0, p, 0.0)


def test_single_bubble_is_the_closed_form():
    b = Bubble(name="b", rise=0.1, gain=0.5, floor=1e-12)
    events = [
        Event(0.01001, "b", "bubble", {"radius": 2e-3, "depth": 0.7}),
        Event(0.03, "b", "bubble", {"radius": 0.5e-3, "depth": 2.0}),
    ]
    y = run(b, events, 0.2)[0]
    n = np.arange(y.size)
    ref = bubble_closed_form(n, 0.01001 * FS, 2e-3, 0.7, 0.1, 0.5) + bubble_closed_form(
        n, 0.03 * FS, 0.5e-3, 2.0, 0.1, 0.5
    )
    assert max_abs_diff(y, ref) < 1e-8 * np.max(np.abs(ref))


@pytest.mark.parametrize("radius", [1e-3, 2e-3, 4e-3])
def test_bubble_spectrum_peak_is_minnaert_and_decay_matches(radius):
    b = Bubble(name="b", gain=1.0, rise=0.0, floor=1e-9)
    y = run(b, [Event(0.0, "b", "bubble", {"radius": radius, "depth": 1.0})], 0.3)[0]
    d = bubble_decay(radius)
    seg = y[: int(2.0 / d * FS)]  # initial segment: two time constants
    spec = np.abs(np.fft.rfft(seg * np.hanning(seg.size), 64 * seg.size))
    k = int(np.argmax(spec))
    a, b0, c = np.log(spec[k - 1 : k + 2])
    peak = (k + 0.5 * (a - c) / (a - 2 * b0 + c)) * FS / (64 * seg.size)
    assert peak == pytest.approx(3.0 / radius, rel=0.005)
    env = np.abs(signal.hilbert(y))
    t = np.arange(y.size) / FS
    fit = (t > 0.5 / d) & (t < 4.0 / d)
    slope = np.polyfit(t[fit], np.log(env[fit]), 1)[0]
    assert -slope == pytest.approx(d, rel=0.05)
    # amplitude ~ r^(3/2)
    assert np.max(np.abs(y)) == pytest.approx((radius / 1e-3) ** 1.5, rel=0.05)


def test_bubble_frequency_glides_up_as_f0_1_plus_sigma_d_t():
    radius, rise = 3e-3, 0.3
    b = Bubble(name="b", gain=1.0, rise=rise, floor=1e-9)
    y = run(b, [Event(0.0, "b", "bubble", {"radius": radius, "depth": 1.0})], 0.2)[0]
    f0, d = 3.0 / radius, bubble_decay(radius)
    # upward zero crossings (linear interpolation) must fall where the phase is 2 pi k
    i = np.flatnonzero((y[:-1] < 0) & (y[1:] >= 0))
    tz = (i + y[i] / (y[i] - y[i + 1])) / FS
    tz = tz[tz < 5.0 / d]
    cycles = f0 * (tz + 0.5 * rise * d * tz**2)
    np.testing.assert_allclose(cycles, np.round(cycles), atol=0.01)
    # the measured frequency (1 / period) rises along f0 (1 + rise d t)
    period_mid = 0.5 * (tz[1:] + tz[:-1])
    f_meas = 1.0 / np.diff(tz)
    np.testing.assert_allclose(f_meas, f0 * (1 + rise * d * period_mid), rtol=0.003)
    assert f_meas[-1] > f0 * (1 + 0.9 * rise * d * period_mid[-1])


def test_stream_birth_rate_and_radius_power_law():
    lo, hi, rate, seconds = 2e-4, 4e-3, 800.0, 10.0
    for exponent in (2.5, 1.0):
        s = BubbleStream(
            gain=1.0, name="s", rate=rate, min_radius=lo, max_radius=hi, exponent=exponent, seed=6
        )
        s.log_capacity = 20000
        run(s, [], seconds)
        mean = rate * seconds
        assert abs(s.births - mean) < 4 * math.sqrt(mean)
        log = s.birth_log()
        assert stats.kstest(np.diff(log[:, 0]), "expon", args=(0, 1 / rate)).pvalue > 1e-3
        q = 1 - exponent
        if q == 0:
            cdf = lambda r: np.log(r / lo) / np.log(hi / lo)  # noqa: E731
        else:
            cdf = lambda r: (r**q - lo**q) / (hi**q - lo**q)  # noqa: E731, B023
        assert stats.kstest(log[:, 1], cdf).pvalue > 1e-3
        assert stats.kstest(log[:, 2], "uniform", args=(0.5, 0.5)).pvalue > 1e-3


def test_polyphony_cap_and_single_voice_closed_form():
    s = BubbleStream(name="s", gain=1.0, rate=3000.0, min_radius=1e-3, max_radius=3e-3, max_voices=3, seed=2)
    s.prepare(FS, 64)
    most = 0
    for start in range(0, FS // 4, 64):
        s.process(start, 64)
        most = max(most, s.active_voices)
    assert most == 3  # full, never above the cap
    # one voice: between births the output is exactly the latest bubble
    one = BubbleStream(
        gain=1.0, name="s", rate=200.0, min_radius=1e-3, max_radius=3e-3, max_voices=1, rise=0.1, seed=4
    )
    one.log_capacity = 1000
    y = run(one, [], 0.5)[0]
    log = one.birth_log()
    n = np.arange(y.size)
    checked = 0
    for (t0, r, depth), t_next in zip(log, np.append(log[1:, 0], 0.5), strict=True):
        lo, hi = math.floor(t0 * FS) + 1, math.floor(t_next * FS) + 1
        ref = bubble_closed_form(n[lo:hi], t0 * FS, r, depth, 0.1)
        keep = np.abs(ref) > 1e-4 * np.max(np.abs(ref))  # above the voice's floor
        assert max_abs_diff(y[lo:hi][keep], ref[keep]) < 1e-8
        checked += 1
    assert checked > 50


def test_the_quietest_voice_is_reused():
    b = Bubble(name="b", gain=1.0, max_voices=2, rise=0.1, floor=1e-12)
    big, small, third = (0.01, 5e-3), (0.02, 0.5e-3), (0.03, 2e-3)
    events = [Event(t, "b", "bubble", {"radius": r, "depth": 1.0}) for t, r in (big, small, third)]
    y = run(b, events, 0.1)[0]
    n = np.arange(y.size)
    after = n > 0.03 * FS + 1
    ref = bubble_closed_form(n, big[0] * FS, big[1], 1.0, 0.1) + bubble_closed_form(
        n, third[0] * FS, third[1], 1.0, 0.1
    )
    assert max_abs_diff(y[after], ref[after]) < 1e-8 * np.max(np.abs(ref))


@pytest.mark.parametrize("kind", ["Bubble", "BubbleStream"])
def test_bubbles_block_size_invariant(kind):
    if kind == "Bubble":
        node = Bubble(name="n", gain=1.0, max_voices=4)
        score = [
            Event(t, "n", "bubble", {"radius": r, "depth": 1.0})
            for t, r in [
                (0.01, 1e-3),
                (0.0101234, 3e-3),
                (0.05, 0.3e-3),
                (0.2, 6e-3),
                (0.2, 1e-3),
                (0.3, 2e-3),
            ]
        ]
        taps = ()
    else:
        node = BubbleStream(name="n", gain=1.0, rate=500.0, max_voices=8, seed=7)
        score = [Event(0.1, "n", "set", {"rate": 4000.0}), Event(0.3, "n", "set", {"rate": 0.0}, jump=True)]
        taps = ("radius",)
    outs = [run(node, score, 0.5, block, taps) for block in BLOCKS]
    assert np.max(np.abs(outs[0][0])) > 0.01
    for other in outs[1:]:
        assert max_abs_diff(outs[0], other) < 1e-6


# --------------------------------------------------------------------------- models
def ritz_free_plate(n, nu, terms=10):
    """lambda^2 of a free circular plate by Rayleigh-Ritz on the bending energy, basis r^(n+2j)."""
    x, w = leggauss(200)
    r, w = 0.5 * (x + 1), 0.5 * w
    p = n + 2 * np.arange(terms)
    W = r[None] ** p[:, None]
    W1 = p[:, None] * r[None] ** (p[:, None] - 1)
    W2 = p[:, None] * (p[:, None] - 1) * r[None] ** (p[:, None] - 2.0)
    A = W1 / r - n * n * W / r**2
    B = W1 / r - W / r**2

    def inner(f, g):
        return np.einsum("iq,jq,q->ij", f, g, w * r)

    K = inner(W2 + A, W2 + A) - (1 - nu) * (inner(W2, A) + inner(A, W2)) + 2 * (1 - nu) * n * n * inner(B, B)
    ev = eigh(K, inner(W, W), eigvals_only=True)
    return np.sqrt(ev[ev > 1e-6][:3])


@pytest.mark.parametrize("n", [0, 1, 2, 3, 5])
def test_free_plate_roots_match_an_independent_ritz_solution(n):
    np.testing.assert_allclose(free_plate_roots(n, 3, 0.3) ** 2, ritz_free_plate(n, 0.3), rtol=1e-7)


def test_wok_model_follows_soedels_shallow_shell_analogy():
    model = ModalModel.load(Path(__file__).parents[1] / "patches" / "wok_model.toml")
    E, rho, h, a, Rc, nu = 200e9, 7850.0, 1.8e-3, 0.18, 0.6, 0.3
    ring = np.sqrt(E / rho) / (2 * np.pi * Rc)
    plate = np.sqrt(E * h**2 / (12 * (1 - nu**2) * rho)) / (2 * np.pi * a**2)
    assert model.n_modes <= 300 and model.frequencies.min() >= ring
    for n in (0, 2, 3):
        lam2 = ritz_free_plate(n, nu)[0]
        f = np.hypot(lam2 * plate, ring)
        assert np.min(np.abs(model.frequencies / f - 1)) < 0.003  # a singlet or doublet there
    # the rim moves more than the bottom for the lowest (two-diameter) doublet
    g = model.gains
    assert g[0, :2].sum() > 10 * g[2, :2].sum()


def test_paper_sheet_modes_are_simply_supported_plate_modes():
    model = paper_sheet_model()
    c = 0.5 * np.pi * np.sqrt(3e9 * 1e-4**3 / (12 * (1 - 0.09)) / (700 * 1e-4))
    m, n = np.meshgrid(np.arange(1, 200), np.arange(1, 200))
    allf = np.sort((c * ((m / 0.297) ** 2 + (n / 0.21) ** 2)).ravel())
    idx = np.clip(np.searchsorted(allf, model.frequencies), 1, allf.size - 1)
    near = np.minimum(np.abs(allf[idx] - model.frequencies), np.abs(allf[idx - 1] - model.frequencies))
    assert np.all(near < 1e-9 * model.frequencies)
    np.testing.assert_allclose(model.decays, 40 + np.pi * model.frequencies * 0.05)
    assert model.n_modes <= 300 and np.all(model.gains >= 0)


@pytest.fixture(scope="module")
def rendered():
    out = {}
    for name in ("crumple", "wok-sizzle"):
        patch = load_patch(name)
        r = render(patch.graph, patch.score, patch.duration, FS, 64)
        out[name] = (patch, r)
    return out


def segment(x, t0, t1):
    return x[int(t0 * FS) : int(t1 * FS)]


def centroid(x):
    f, p = signal.welch(x, FS, nperseg=2048)
    return float(np.sum(f * p) / np.sum(p))


@pytest.mark.parametrize("name", ["crumple", "wok-sizzle"])
def test_patches_render_at_about_minus_6_dbfs(rendered, name):
    patch, r = rendered[name]
    assert 4.0 <= patch.duration <= 8.0
    assert np.all(np.isfinite(r.audio))
    peak_db = 20 * np.log10(np.max(np.abs(r.audio)))
    assert -9.0 < peak_db < -4.0


def test_crumple_density_rises_where_the_score_raises_it(rendered):
    _, r = rendered["crumple"]
    force, audio = r.haptic[0], r.audio[0]
    onsets = np.flatnonzero((force[1:] > 0) & (force[:-1] == 0)) / FS
    slow = np.sum((onsets >= 0.3) & (onsets < 1.5)) / 1.2
    fast = np.sum((onsets >= 3.7) & (onsets < 4.4)) / 0.7
    assert 20 < slow < 80  # density 40/s there
    assert fast > 10 * slow  # 1500/s there (overlapping pulses merge, so fewer onsets)
    power = [np.mean(segment(audio, *s) ** 2) for s in ((0.3, 1.5), (3.7, 4.4))]
    assert power[1] > 30 * power[0]
    assert centroid(segment(audio, 3.7, 4.4)) > 3000.0  # crackly, not a thud


def test_wok_sizzle_is_broadband_and_the_wok_rings_after_a_stir(rendered):
    patch, r = rendered["wok-sizzle"]
    audio = r.audio[0]
    assert centroid(segment(audio, 1.2, 2.15)) > 2000.0  # sizzle only
    assert centroid(segment(audio, 0.35, 0.6)) > 2000.0
    # the strongest modes of the wok struck on its wall must stand out after the stir at 2.2 s
    model = patch.graph.nodes["wok"].model
    a = model.gains_at("wall")
    energy = a**2 / model.decays
    top = model.frequencies[np.argsort(energy)[-3:]]
    f, before = signal.welch(segment(audio, 1.55, 2.15), FS, nperseg=8192)
    _, after = signal.welch(segment(audio, 2.2, 2.8), FS, nperseg=8192)
    for fk in top:
        band = np.abs(f - fk) < 8.0
        assert 10 * np.log10(after[band].max() / before[band].max()) > 15.0
    # and the sizzle stays: high frequencies keep their level across the stir
    hi = f > 6000
    assert 0.5 < after[hi].sum() / before[hi].sum() < 2.0


@pytest.mark.parametrize("name", ["crumple", "wok-sizzle"])
def test_patches_block_size_invariant(name):
    patch = load_patch(name)
    outs = [render(patch.graph, patch.score, 1.0, FS, b, limiter=False).audio for b in BLOCKS]
    for other in outs[1:]:
        assert max_abs_diff(outs[0], other) < 1e-6

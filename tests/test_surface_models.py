"""Surface profiles, scraping and rolling forces, and the scrape/roll patches.

Checked against closed forms and measured spectra: the PSD slope of fractal profiles, the
spectral scaling of a profile read at the contact speed, the sqrt(F v) amplitude law, a
resonance tracking f0 + slope v, the -3 dB point of the speed-dependent roll low-pass,
momentum balance of the rolling filter (mean contact force = load), block-size invariance.
"""

import math

import numpy as np
import pytest
import soundfile
from helpers import ArraySource, max_abs_diff
from scipy import signal

from jassy import ContactTrack, Event, Graph, ModalModel, PatchError, render
from jassy.events import track_events
from jassy.patchfile import load_patch
from patches.models_surface import Plate, ss_plate_model
from ugens.mix import Mixer
from ugens.modal import ModalBank
from ugens.noise import WhiteNoise
from ugens.profile import ProfileError, fractal_profile, load_profile
from ugens.roll import GRAVITY, RathRoll, Roll
from ugens.scrape import ResonantScrape, Scrape

FS = 48000
BLOCKS = (1, 64, 1000)


def run(ugen, score=(), duration=1.0, block=256, haptic=None):
    r = render(Graph(ugen, haptic=haptic), score, duration, FS, block, limiter=False)
    return (r.audio[0], r.haptic) if haptic is not None else r.audio[0]


def rms(x):
    return float(np.sqrt(np.mean(np.square(x))))


def centroid(x, fs=FS):
    f, p = signal.welch(x, fs, nperseg=4096)
    return float(np.sum(f * p) / np.sum(p))


def loglog_slope(x, y):
    return float(np.polyfit(np.log(x), np.log(y), 1)[0])


# ------------------------------------------------------------------------------ profiles
@pytest.mark.parametrize("beta", [0.5, 1.0, 2.0, 3.0])
def test_fractal_profile_psd_slope_and_rms(beta):
    dx, rms_h = 1e-4, 2e-5
    h = fractal_profile(2**17, beta, rms_h, seed=3, dx=dx)
    assert h.shape == (2**17,) and h.dtype == np.float64
    assert abs(h.mean()) < 1e-12 * rms_h
    assert rms(h) == pytest.approx(rms_h, rel=1e-12)
    k, p = signal.welch(h, fs=1.0 / dx, nperseg=4096)  # spatial PSD, k in cycles per m
    band = (k > 4 / (4096 * dx)) & (k < 0.4 / dx)
    assert abs(loglog_slope(k[band], p[band]) + beta) < 0.1


def test_fractal_profile_cutoffs_seeds_and_errors():
    dx = 1e-4
    h = fractal_profile(2**16, 1.0, 1.0, seed=1, dx=dx, k_low=200.0, k_high=1000.0)
    spectrum = np.abs(np.fft.rfft(h)) ** 2
    k = np.fft.rfftfreq(h.size, dx)
    inside = spectrum[(k >= 200) & (k <= 1000)].sum()
    assert spectrum[(k < 200) | (k > 1000)].sum() < 1e-20 * inside
    assert np.array_equal(h, fractal_profile(2**16, 1.0, 1.0, seed=1, dx=dx, k_low=200.0, k_high=1000.0))
    assert not np.allclose(h, fractal_profile(2**16, 1.0, 1.0, seed=2, dx=dx, k_low=200.0, k_high=1000.0))
    with pytest.raises(ProfileError, match="no spatial frequency"):
        fractal_profile(64, 1.0, 1.0, dx=dx, k_low=1e6)
    with pytest.raises(ProfileError, match="dx: expected a spacing > 0"):
        fractal_profile(64, 1.0, 1.0, dx=0.0)
    with pytest.raises(ProfileError, match="n: expected an integer"):
        fractal_profile(3, 1.0)


def test_load_profile_formats_and_errors(tmp_path):
    data = np.sin(np.linspace(0, 20, 500)) * 0.5
    np.save(tmp_path / "p.npy", data)
    soundfile.write(tmp_path / "p.wav", np.stack([data, -data], axis=1), 48000, subtype="DOUBLE")
    np.savetxt(tmp_path / "p.csv", data, delimiter=",", header="height")
    for name in ("p.npy", "p.wav", "p.csv"):
        np.testing.assert_allclose(load_profile(tmp_path / name), data, atol=1e-12)
    np.savetxt(tmp_path / "two.csv", np.stack([data, data], axis=1), delimiter=",")
    np.save(tmp_path / "nan.npy", np.array([1.0, np.nan, 2.0, 3.0]))
    np.save(tmp_path / "short.npy", np.array([1.0, 2.0]))
    (tmp_path / "text.csv").write_text("a,b\nc,d\n")
    cases = {
        "missing.npy": "no such profile file",
        "p.txt": "unknown profile format",
        "two.csv": r"single column.*\(500, 2\)",
        "nan.npy": "NaN or Inf",
        "short.npy": "at least 4 points",
        "text.csv": "cannot read profile",
    }
    for name, message in cases.items():
        with pytest.raises(ProfileError, match=message) as info:
            load_profile(tmp_path / name)
        assert name in str(info.value)


def test_scrape_reads_given_profiles_and_names_bad_files(tmp_path):
    data = np.cos(np.linspace(0, 40, 1000)) + 3.0
    np.save(tmp_path / "p.npy", data)
    node = Scrape(name="s", profile_file=str(tmp_path / "p.npy"), roughness=2e-6)
    expected = (data - data.mean()) / rms(data - data.mean()) * 2e-6
    np.testing.assert_allclose(node.heights(), expected, rtol=1e-12)
    np.testing.assert_allclose(Scrape(name="s", profile=list(data), roughness=2e-6).heights(), expected)
    with pytest.raises(PatchError, match=r"nodes\.s\.profile_file: .*nope\.npy: no such profile file"):
        Scrape(name="s", where="nodes.s", profile_file=str(tmp_path / "nope.npy"))
    with pytest.raises(PatchError, match="either profile or profile_file"):
        Scrape(name="s", profile=list(data), profile_file=str(tmp_path / "p.npy"))
    with pytest.raises(PatchError, match="flat"):
        Scrape(name="s", profile=[1.0, 1.0, 1.0, 1.0])


@pytest.mark.parametrize(
    ("cls", "key", "value"),
    [
        (Scrape, "roughness", 0.0),
        (Scrape, "dx", -1e-5),
        (Scrape, "force", -1.0),
        (Scrape, "law", "cubic"),
        (Scrape, "patch", -0.1),
        (Roll, "fc0", 0.0),
        (Roll, "v0", 0.0),
        (RathRoll, "mass", -0.1),
        (RathRoll, "grain", 1.5),
        (RathRoll, "depth", -1.0),
        (ResonantScrape, "damping", 0.0),
    ],
)
def test_invalid_parameters_are_rejected(cls, key, value):
    with pytest.raises(PatchError, match=rf"{key}: expected"):
        cls(name="x", **{key: value})


def test_bad_generated_profile_fails_when_the_node_is_made():
    with pytest.raises(PatchError, match=r"nodes\.s: .*no spatial frequency"):
        Scrape(name="s", where="nodes.s", k_low=1e7)


# ------------------------------------------------------------------------------ Scrape
def band_profile(k_low=500.0, n=2**13, dx=3e-5, seed=4):
    """A profile without long waves, so that short renders see its full variance."""
    return fractal_profile(n, 1.0, 1.0, seed=seed, dx=dx, k_low=k_low)


def test_scrape_spectrum_scales_with_speed():
    profile = band_profile()
    speeds = (0.1, 0.2, 0.4)
    cents = [centroid(run(Scrape(name="s", profile=profile, speed=v), duration=2.0)) for v in speeds]
    assert cents[0] < cents[1] < cents[2]
    for a, b in zip(cents[:-1], cents[1:], strict=True):
        assert b / a == pytest.approx(2.0, rel=0.2)


def test_scrape_contact_patch_low_pass_darkens_the_scrape():
    profile = band_profile()
    bare = centroid(run(Scrape(name="s", profile=profile, speed=0.4), duration=1.0))
    patched = centroid(run(Scrape(name="s", profile=profile, speed=0.4, patch=4e-4), duration=1.0))
    assert patched < 0.7 * bare


def test_scrape_loudness_grows_as_sqrt_of_force_times_speed():
    profile = band_profile()
    roughness, stiffness = 5e-6, 1e5
    speeds = np.array([0.1, 0.2, 0.4, 0.8])
    by_speed = [
        rms(run(Scrape(name="s", profile=profile, speed=v, force=1.0), duration=2.0)[4800:]) for v in speeds
    ]
    assert abs(loglog_slope(speeds, by_speed) - 0.5) < 0.05
    forces = np.array([0.25, 1.0, 4.0])
    by_force = [rms(run(Scrape(name="s", profile=profile, speed=0.3, force=f))) for f in forces]
    assert abs(loglog_slope(forces, by_force) - 0.5) < 0.05
    # at the reference contact (1 N, 1 m/s) the RMS force is stiffness * roughness
    ref = rms(run(Scrape(name="s", profile=profile, speed=1.0, force=1.0, interp="cubic"), duration=2.0))
    assert ref == pytest.approx(stiffness * roughness, rel=0.1)
    linear = [rms(run(Scrape(name="s", profile=profile, speed=0.3, force=f, law="linear"))) for f in forces]
    assert abs(loglog_slope(forces, linear) - 1.0) < 0.05


def test_scrape_is_silent_without_speed_or_force():
    assert np.all(run(Scrape(name="s", speed=0.0, force=2.0), duration=0.2) == 0.0)
    assert np.all(run(Scrape(name="s", speed=0.5, force=0.0), duration=0.2) == 0.0)
    assert np.all(run(Scrape(name="s", speed=0.009, force=1.0, min_speed=0.01), duration=0.2) == 0.0)
    assert np.all(run(ResonantScrape(name="r", speed=0.0, force=1.0), duration=0.2) == 0.0)
    # a stop: silent from the frame the speed reaches zero
    x = run(Scrape(name="s", speed=0.3, patch=1e-4), [Event(0.1, "s", "set", {"speed": 0.0}, jump=True)], 0.2)
    assert rms(x[:4800]) > 0 and np.all(x[4800:] == 0.0)


# ---------------------------------------------------------------------- ResonantScrape
@pytest.mark.parametrize("speed", [0.2, 0.5, 1.0])
def test_resonant_scrape_peak_tracks_speed(speed):
    f0, slope = 300.0, 2000.0
    x = run(
        ResonantScrape(name="r", speed=speed, f0=f0, slope=slope, damping=40.0, damping_slope=60.0), (), 3
    )
    f, p = signal.welch(x, FS, nperseg=8192)
    p = np.convolve(p, np.ones(5) / 5, mode="same")
    assert f[np.argmax(p)] == pytest.approx(f0 + slope * speed, rel=0.03)


def test_resonant_scrape_rms_is_gain_times_sqrt_fv_and_bandwidth_grows():
    x = run(ResonantScrape(name="r", speed=0.5, force=2.0, gain=0.3, damping=2000.0), (), 4)
    assert rms(x) == pytest.approx(0.3 * math.sqrt(2.0 * 0.5), rel=0.05)

    def width(speed):  # -3 dB bandwidth of the measured PSD
        y = run(ResonantScrape(name="r", speed=speed, damping=100.0, damping_slope=1000.0), (), 4)
        f, p = signal.welch(y, FS, nperseg=8192)
        p = np.convolve(p, np.ones(7) / 7, mode="same")
        return np.ptp(f[p > p.max() / 2])

    # bandwidth ~ d / pi Hz with d = 100 + 1000 v
    assert width(0.1) == pytest.approx(200 / np.pi, rel=0.35)
    assert width(0.9) == pytest.approx(1000 / np.pi, rel=0.35)


# ------------------------------------------------------------------------------- Roll
def test_roll_loudness_grows_with_speed():
    levels = [rms(run(Roll(name="r", speed=v, force=1.0), duration=2.0)[FS // 2 :]) for v in (0.1, 0.2, 0.4)]
    assert levels[0] < levels[1] < levels[2]


@pytest.mark.parametrize("speed", [0.1, 0.2, 0.4])
def test_roll_low_pass_cutoff_follows_speed(speed):
    fc0, v0, dx = 100.0, 0.2, 1e-4
    node = Roll(name="r", speed=speed, force=1.0, fc0=fc0, v0=v0, dx=dx, length=2**14, beta=1.0)
    y = run(node, duration=4.0)
    # the profile read at the same speed, computed independently (linear interpolation)
    h = node.prof
    pos = np.arange(y.size) * speed / (dx * FS)
    x = np.interp(pos % h.size, np.arange(h.size + 1), np.append(h, h[0]))
    f, pxy = signal.csd(x, y, FS, nperseg=2**15)
    _, pxx = signal.welch(x, FS, nperseg=2**15)
    gain2 = np.abs(pxy / pxx) ** 2
    s = node.values["stiffness"] * math.sqrt(1.0 * speed / (1.0 * v0))  # amplitude law at (1 N, v)
    fc = fc0 * speed / v0
    low = (f > fc / 20) & (f < fc / 5)
    assert np.median(gain2[low]) == pytest.approx(s**2, rel=0.02)
    measured = f[np.argmax(gain2 < 0.5 * s**2)]  # first bin below -3 dB
    assert measured == pytest.approx(fc, rel=0.05, abs=2 * f[1])


def test_roll_on_a_speed_sweep_matches_a_low_pass_redesigned_every_sample():
    """The kernel redesigns the speed-tracking low-pass only when the cutoff should move by
    more than 1% (CUTOFF_STEP); an independent reference redesigns it every sample (RBJ
    cookbook, direct form II transposed). A 1% cutoff error moves a Butterworth response by
    < 0.09 dB, so the outputs agree to about 1%."""
    n, dx, fc0, v0 = 12000, 1e-4, 100.0, 0.2
    t = np.arange(n) / FS
    speed = 0.05 + 0.5 * t / t[-1]  # a sweep: cutoff 25 -> 275 Hz
    node = Roll(name="r", dx=dx, fc0=fc0, v0=v0, length=2**14, seed=5)
    node.follow(t, np.ones(n), speed)
    y = run(node, duration=n / FS)
    h = node.prof
    pos = np.r_[0.0, np.cumsum(speed[:-1])] / (dx * FS)
    x = np.interp(pos % h.size, np.arange(h.size + 1), np.append(h, h[0]))
    w0 = 2 * np.pi * np.clip(fc0 * speed / v0, 0.5, 0.45 * FS) / FS
    alpha = np.sin(w0) / (2 / math.sqrt(2))
    a0 = 1 + alpha
    b0, b1, a1, a2 = (1 - np.cos(w0)) / 2 / a0, (1 - np.cos(w0)) / a0, -2 * np.cos(w0) / a0, (1 - alpha) / a0
    ref = np.zeros(n)
    s1 = s2 = 0.0
    for i in range(n):
        z = b0[i] * x[i] + s1
        s1 = b1[i] * x[i] - a1[i] * z + s2
        s2 = b0[i] * x[i] - a2[i] * z
        ref[i] = z
    ref *= node.values["stiffness"] * np.sqrt(speed / v0)  # amplitude law at 1 N
    assert rms(ref) > 0
    assert rms(y - ref) < 0.01 * rms(ref)


# --------------------------------------------------------------------------- RathRoll
def rath_reference(x, speed, load, mass, grain, depth):
    """SDT's rolling filter (ground trace, bump, flight) with the momentum bookkeeping of the
    RathRoll docstring, in plain Python; x is the surface signal. Returns the output and
    the take-off samples."""
    trace, airborne, c, bump, takeoffs = 0.0, False, 0.0, 0.0, []
    decay = min(2 * grain * abs(speed), 2.0)
    out = np.zeros(x.size)
    for i, xi in enumerate(x):
        ground = max(trace - decay, xi)
        if airborne:
            c -= load
            if c <= 0:  # landed in this sample: on the ground for the rest of it
                out[i], airborne = bump - c - load, False
            else:
                out[i] = -load
        if not airborne and ground > trace and decay > 0:
            bump = (ground - trace) * depth * 0.5 * mass * speed**2 / math.sqrt(decay)
            c, airborne = 2 * bump, True
            out[i] += bump
            takeoffs.append(i)
        trace = ground
    return out, np.array(takeoffs)


def sdt_takeoffs(x, speed, load, mass, grain, depth):
    """Take-off samples of SDT's ``SDTRolling_dsp`` (transcribed: ballFlight = 2 bump at a
    take-off, then max(0, ballFlight - gravity) every sample) with gravity = load."""
    trace, flight, kinetic = 0.0, 0.0, 0.5 * mass * speed**2
    decay = min(2 * grain * abs(speed), 2.0)
    takeoffs = []
    for i, xi in enumerate(x):
        ground = max(trace - decay, xi)
        if ground > trace and not flight and decay:
            flight = 2.0 * (ground - trace) * depth * kinetic / math.sqrt(decay)
            takeoffs.append(i)
        trace = ground
        flight = max(0.0, flight - load)
    return np.array(takeoffs)


def test_rath_roll_matches_the_rolling_filter_on_an_input_signal():
    x = np.random.default_rng(0).uniform(-1, 1, 3000)
    node = RathRoll(
        ArraySource(x), name="r", speed=0.7, force=0.3, mass=0.05, grain=0.1, depth=3000.0, contact_cutoff=0.0
    )
    y = run(node, duration=3000 / FS, block=64)
    ref, takeoffs = rath_reference(x, 0.7, 0.05 * GRAVITY + 0.3, 0.05, 0.1, 3000.0)
    assert np.max(np.abs(y - ref)) < 1e-9 * np.max(np.abs(ref))
    assert np.sum(ref < 0) > 100  # the ball does fly
    # the take-offs are SDT's: flights last the ballistic time rounded up to the sample
    sdt = sdt_takeoffs(x, 0.7, 0.05 * GRAVITY + 0.3, 0.05, 0.1, 3000.0)
    assert sdt.size > 30
    np.testing.assert_array_equal(takeoffs, sdt)


#: Dense micro-impacts (a take-off every few samples at 0.5 m/s): a 50 g ball, the trace
#: falling fast, shallow bumps, no contact low-pass.
DENSE = {"mass": 0.05, "grain": 0.5, "depth": 50.0, "contact_cutoff": 0.0}


def test_rath_roll_impact_rate_grows_with_speed_and_force_is_dc_free():
    rates = []
    for v in (0.4, 0.55, 0.75):
        node = RathRoll(name="r", speed=v, **DENSE)
        y, (contact,) = run(node, duration=1.0, haptic=node.tap("contact"))
        air = contact == 0.0
        rates.append(int(np.sum(air[1:] & ~air[:-1])))  # take-offs that leave the surface
        assert np.all(np.isfinite(y)) and rms(y) > 0
        # every flight's impulses balance: zero mean, and mean contact force = weight
        assert abs(np.mean(y)) < 1e-3 * rms(y)
        assert np.mean(contact) == pytest.approx(0.05 * GRAVITY, rel=1e-3)
        assert np.min(contact) >= 0.0
    assert rates[0] < rates[1] < rates[2]
    assert rates[0] > 100
    # no speed: no bumps, the ball rests on the surface
    node = RathRoll(name="r", speed=0.0, **DENSE)
    y, (contact,) = run(node, duration=0.1, haptic=node.tap("contact"))
    assert np.all(y == 0.0) and np.allclose(contact, 0.05 * GRAVITY)


def test_rath_roll_contact_low_pass_keeps_it_dc_free():
    y = run(RathRoll(name="r", speed=0.6, **{**DENSE, "contact_cutoff": 2000.0}), duration=1.0)
    bare = run(RathRoll(name="r", speed=0.6, **DENSE), duration=1.0)
    assert abs(np.mean(y)) < 1e-3 * rms(y)
    f, p = signal.welch(y, FS, nperseg=1024)
    _, p0 = signal.welch(bare, FS, nperseg=1024)
    # second-order Butterworth: -24 dB at 4 fc, flat far below fc
    assert p[f >= 8000].sum() < 10 ** (-2.4) * p0[f >= 8000].sum()
    low = (f > 100) & (f < 500)
    assert p[low].sum() == pytest.approx(p0[low].sum(), rel=0.05)


# ------------------------------------------------------------------ block-size invariance
def invariance_graph():
    scrape = Scrape(name="scrape", speed=0.2, force=0.5, patch=2e-4, interp="cubic", length=4096)
    reson = ResonantScrape(name="reson", speed=0.3)
    roll = Roll(name="roll", speed=0.1, length=4096)
    rath = RathRoll(name="rath", speed=0.5, mass=0.08, contact_cutoff=3000.0, length=4096)
    rath_in = RathRoll(WhiteNoise(name="noise", seed=9), name="rath_in", speed=0.5, depth=2000.0)
    model = ModalModel([220.0, 1300.0], [3.0, 8.0], [[1.0, 0.5], [0.2, -1.0]])
    bank = ModalBank(model, name="bank")(scrape)
    forces = [scrape, reson, roll, rath, rath_in, rath.tap("contact")]
    return Graph(Mixer(bank, roll, name="mix"), haptic=forces)


def invariance_score():
    t = np.arange(0.0, 0.5, 0.003) + 0.0117  # a physics track at ~333 Hz, off the audio grid
    track = ContactTrack(
        (0, 1),
        t,
        1.0 + 0.5 * np.sin(2 * np.pi * 3 * t),
        0.2 + 0.15 * np.sin(2 * np.pi * 2 * t) ** 2,
        0.3 + 0.25 * np.cos(2 * np.pi * 1.5 * t),
    )
    score = track_events(track, {"normal_force": ("scrape", "force"), "slip_speed": ("scrape", "speed")})
    score += track_events(track, {"normal_force": ("rath", "force"), "rolling_speed": ("rath", "speed")})
    score += [
        Event(0.0501, "reson", "set", {"speed": 1.2, "force": 2.0}, ramp=0.2),
        Event(0.3303, "reson", "set", {"speed": 0.0}, jump=True),
        Event(0.4007, "reson", "set", {"speed": 0.4}),
        Event(0.1003, "roll", "set", {"speed": 0.6}, ramp=0.1333),
        Event(0.2999, "roll", "set", {"speed": -0.3, "force": 3.0}, jump=True),
        Event(0.2004, "rath_in", "set", {"speed": 1.5}),
        Event(0.4444, "rath_in", "set", {"force": 2.0}, ramp=0.05),
        Event(0.0777, "bank", "set", {"location": {"vertices": [0, 1], "weights": [0.3, 0.7]}}, ramp=0.2),
    ]
    return score


def test_block_size_invariance_with_ramps_jumps_and_contact_tracks():
    outs = [render(invariance_graph(), invariance_score(), 0.55, FS, b, limiter=False) for b in BLOCKS]
    assert np.all(np.max(np.abs(outs[0].haptic), axis=1) > 1e-3)
    for other in outs[1:]:
        assert max_abs_diff(outs[0].audio, other.audio) < 1e-6
        assert max_abs_diff(outs[0].haptic, other.haptic) < 1e-6


def test_contact_track_drives_force_and_speed():
    t = np.linspace(0.0, 0.5, 51)
    speed = np.linspace(0.0, 0.5, 51)
    track = ContactTrack((0, 1), t, np.full(51, 2.0), speed, np.zeros(51))
    node = ResonantScrape(name="r", gain=1.0, damping=3000.0)
    x = run(node, track_events(track, {"normal_force": ("r", "force"), "slip_speed": ("r", "speed")}), 0.5)
    # loudness follows sqrt(F v) along the track: compare quarters (v ~ 0.19 and 0.44 m/s)
    q1 = rms(x[int(0.1875 * FS) - 2400 : int(0.1875 * FS) + 2400])
    q3 = rms(x[int(0.4375 * FS) - 2400 : int(0.4375 * FS) + 2400])
    assert q3 / q1 == pytest.approx(math.sqrt(0.4375 / 0.1875), rel=0.15)


# -------------------------------------------------------------------------------- patches
def segment(x, t0, t1):
    return x[int(t0 * FS) : int(t1 * FS)]


def test_plate_model_matches_kirchhoff_formula():
    a, b, h, rho, e, nu = 0.5, 0.4, 0.002, 7850.0, 200e9, 0.3
    m = ss_plate_model(
        Plate(a, b, h, rho, e, e, nu, 1e-4, 1.0), ((0.1, 0.1), (0.5, 0.5)), (0.3, 0.7), n_modes=5
    )
    d = e * h**3 / (12 * (1 - nu**2))
    pairs = sorted(((i / a) ** 2 + (j / b) ** 2, i, j) for i in range(1, 6) for j in range(1, 6))[:5]
    expected = [np.pi / 2 * np.sqrt(d / (rho * h)) * s for s, _, _ in pairs]
    np.testing.assert_allclose(m.frequencies, expected, rtol=1e-12)
    # the plate's centre (track point t8 here, x = y = 0.5) is a node of the (1, 2) mode
    k12 = [i for i, (_, p, q) in enumerate(pairs) if (p, q) == (1, 2)][0]
    assert abs(m.gains[-1, k12]) < 1e-12


def test_scrape_patch_renders_and_brightens_with_speed():
    patch = load_patch("scrape")
    x = render(patch.graph, patch.score, patch.duration).audio[0]
    assert np.all(np.isfinite(x))
    assert -9.0 < 20 * np.log10(np.max(np.abs(x))) < -3.0
    # the stylus at 0.15 m/s (0.45-0.9 s) against 1.1 m/s (1.5-2.1 s)
    slow, fast = centroid(segment(x, 0.45, 0.9)), centroid(segment(x, 1.5, 2.1))
    assert fast > 2.0 * slow
    # the resonant scrape's pitch: 300 + 1600 * 0.15 Hz at 4.8 s against 300 + 1600 * 1.0 at 5.3 s
    assert centroid(segment(x, 5.05, 5.35)) > 1.5 * centroid(segment(x, 4.6, 4.85))


def test_roll_patch_renders_and_gets_louder_with_speed():
    patch = load_patch("roll")
    x = render(patch.graph, patch.score, patch.duration).audio[0]
    assert np.all(np.isfinite(x))
    assert -9.0 < 20 * np.log10(np.max(np.abs(x))) < -3.0
    # rising speed: ~0.2, ~0.4 and 0.6 m/s (the ramp from 0.2 s to 1.0 s, then cruising)
    levels = [rms(segment(x, t, t + 0.15)) for t in (0.4, 0.65, 1.1)]
    assert levels[0] < levels[1] < levels[2]
    # and quieter again as it slows down after the rebound (0.3 -> 0 m/s from 1.4 s to 4.4 s)
    assert rms(segment(x, 3.6, 3.9)) < 0.5 * levels[2]


@pytest.mark.parametrize("name", ["scrape", "roll"])
def test_patches_are_block_size_invariant(name):
    patch = load_patch(name)
    outs = [render(patch.graph, patch.score, 0.3, FS, b, limiter=False).audio for b in BLOCKS]
    assert max_abs_diff(outs[0], outs[1]) < 1e-6 and max_abs_diff(outs[0], outs[2]) < 1e-6


def test_follow_curves_equal_the_track_event_score():
    """Scrape and Roll driven by follow() sound exactly like the same ContactTrack sent as
    ramped events (both are the piecewise-linear interpolation; track times on the 1 ms grid
    fall on samples), at any block size. The track starts at 0 (before its first event the
    evented generator plays its default parameters)."""
    t = 1e-3 * np.arange(450)
    force = 1.0 + 0.5 * np.sin(2 * np.pi * 3 * t)
    slip = 0.2 + 0.15 * np.sin(2 * np.pi * 2 * t) ** 2
    rolling = 0.3 + 0.25 * np.cos(2 * np.pi * 1.5 * t)
    track = ContactTrack((0, 1), t, force, slip, rolling)
    for make in (Scrape, Roll):
        evented = make(name="g", seed=3)
        score = track_events(track, {"normal_force": ("g", "force"), "slip_speed": ("g", "speed")})
        reference = run(evented, score, 0.5)
        for block in BLOCKS:
            followed = make(name="g", seed=3)
            followed.follow(t, force, slip)
            assert max_abs_diff(run(followed, (), 0.5, block), reference) < 1e-9 * np.max(np.abs(reference))
        assert np.max(np.abs(reference)) > 0


def test_curves_fill_is_linear_interpolation_held_at_the_ends():
    from ugens.scrape import curves_fill

    rng = np.random.default_rng(7)
    times = np.sort(rng.uniform(0.01, 0.09, 12))
    a, b = rng.normal(size=12), rng.normal(size=12)
    out_a, out_b = np.empty(700), np.empty(700)
    for first in (0, 1234, 4000):
        curves_fill(out_a, out_b, first, 700, 48000.0, times, a, b)
        frames = (first + np.arange(700)) / 48000.0
        assert np.allclose(out_a, np.interp(frames, times, a), atol=1e-12)
        assert np.allclose(out_b, np.interp(frames, times, b), atol=1e-12)


def test_follow_names_bad_curves():
    node = Scrape(name="s")
    with pytest.raises(PatchError, match="s.follow: times"):
        node.follow([0.0, 0.0], [1.0, 1.0], [0.1, 0.1])
    with pytest.raises(PatchError, match="s.follow: speed"):
        node.follow([0.0, 1.0], [1.0, 1.0], [0.1])
    with pytest.raises(PatchError, match=">= 0"):
        node.follow([0.0, 1.0], [-1.0, 1.0], [0.1, 0.1])

"""ImpactTrain (micro-collisions, bouncing), HuntCrossleyImpact (closed loop) and the marble patch.

References computed here independently: bounce closed forms, Hertz contact time by
numerical integration, the Hunt-Crossley restitution relation, the ZOH discretisation of
each mode by scipy, ModalBank, onset detection on the rendered audio.
"""

import math

import numpy as np
import pytest
from helpers import ArraySource, max_abs_diff
from hypothesis import given, settings
from hypothesis import strategies as st
from scipy.integrate import solve_ivp
from scipy.signal import butter, cont2discrete, lfilter, sosfilt, welch
from scipy.special import gamma
from scipy.stats import kstest

from jassy import Event, Graph, ModalModel, PatchError, render
from jassy.patchfile import load_patch
from patches.models_impacts import plate_model
from ugens.impact import ImpactForce
from ugens.impact_train import ImpactTrain, auto_micro, effective_modulus, hertz_duration, micro_schedule
from ugens.modal import ModalBank
from ugens.nonlinear_impact import (
    HammerParams,
    HuntCrossleyImpact,
    StepSums,
    energy_safeguard,
    power,
    step_energy,
)

FS = 48000
BLOCKS = (1, 64, 1000)
RIGID = ModalModel([500.0, 3000.0], [1.0, 5.0], [[1e-12, 1e-12]])  # an immovable surface


def train_force(events, seconds=0.1, block=64, **params):
    node = ImpactTrain(name="train", **params)
    return render(Graph(node), events, seconds, FS, block, limiter=False).audio[0], node


def runs(f):
    """(first index, last index + 1) of each run of non-zero samples."""
    nz = np.concatenate([[0], (f != 0).astype(np.int8), [0]])
    d = np.diff(nz)
    return np.flatnonzero(d == 1), np.flatnonzero(d == -1)


# ----------------------------------------------------------------- ImpactTrain
@settings(max_examples=40, deadline=None)
@given(
    t=st.floats(0.0, 0.01),
    impulse=st.floats(1e-5, 10.0),
    micro=st.integers(1, 12),
    spread=st.floats(0.001, 0.015),
    tau=st.floats(5e-5, 0.002),
)
def test_micro_collisions_sum_to_the_impulse_within_the_spread(t, impulse, micro, spread, tau):
    args = {"impulse": impulse, "micro": micro, "spread": spread, "duration": tau}
    f, node = train_force([Event(t, "train", "impact", args)], seconds=0.04)
    assert f.sum() / FS == pytest.approx(impulse, rel=1e-12)
    assert np.all(f >= 0)
    nz = np.flatnonzero(f)
    assert nz[0] == math.floor(t * FS + 1e-6) + 1  # the first micro-collision starts at t
    assert nz[-1] < (t + spread + max(tau, 2 / FS)) * FS + 1


def test_micro_collision_schedule_has_the_documented_distribution():
    """t_j / spread ~ U[0, 1) for j >= 1 (KS test), t_0 = 0, and w_j / exp(-2 t_j / s) ~ U[c/2, c)."""
    rng = np.array([12345], dtype=np.uint64)
    n, spread = 6, 0.01
    times, weights = np.zeros(n), np.zeros(n)
    later, ratios = [], []
    for _ in range(3000):
        micro_schedule(rng, n, spread, times, weights)
        assert times[0] == 0.0 and np.all(np.diff(times) >= 0)
        assert weights.sum() == pytest.approx(1.0, rel=1e-12)
        later.extend(times[1:] / spread)
        r = weights / np.exp(-2 * times / spread)
        ratios.append(r / r.max())
    assert kstest(later, "uniform").pvalue > 1e-3
    ratios = np.concatenate(ratios)
    assert ratios.min() > 0.5 - 1e-12  # (1 + u)/2 in [1/2, 1)
    assert 0.7 < np.median(ratios) < 0.9


def test_one_micro_collision_is_exactly_an_impact_force_pulse():
    ev = {"impulse": 0.3, "duration": 0.0007}
    events = [Event(0.0123456, "train", "impact", {**ev, "micro": 1})]
    f, _ = train_force(events, seconds=0.03)
    ref = ImpactForce(name="train")
    g = render(Graph(ref), [Event(0.0123456, "train", "impact", ev)], 0.03, FS, 64, limiter=False).audio[0]
    np.testing.assert_array_equal(f, g)


def test_automatic_micro_count_grows_with_hardness():
    assert auto_micro(0.002) == 1 and auto_micro(0.001) == 1
    assert auto_micro(0.0005) == 2 and auto_micro(0.00025) == 3 and auto_micro(1e-7) == 8
    soft, _ = train_force([Event(0.001, "train", "impact", {"impulse": 0.1})], hardness=0.002)
    hard, _ = train_force([Event(0.001, "train", "impact", {"impulse": 0.1})], hardness=0.0002, spread=0.01)
    assert len(runs(soft)[0]) == 1
    assert len(runs(hard)[0]) >= 2  # several micro-collisions (some may overlap)


@pytest.mark.parametrize("v0, e, min_speed", [(2.0, 0.8, 0.05), (1.0, 0.5, 0.01), (3.0, 0.9, 0.3)])
def test_bounce_times_and_impulses_match_the_closed_form(v0, e, min_speed):
    m, g, t0 = 0.01, 9.81, 0.0104167
    # closed form: v_i = e^i v0, t_{i+1} = t_i + 2 e v_i / g, impulse m (1 + e) v_i
    i = np.arange(int(math.floor(math.log(min_speed / v0) / math.log(e))) + 1)
    v = v0 * e**i
    times = t0 + np.concatenate([[0.0], np.cumsum(2 * e * v[:-1] / g)])
    args = {"speed": v0, "restitution": e, "mass": m, "min_speed": min_speed}
    f, _ = train_force([Event(t0, "train", "bounce", args)], seconds=times[-1] + 0.01, hardness=2e-4)
    starts, ends = runs(f)
    assert len(starts) == len(times)
    np.testing.assert_array_equal(starts, np.floor(times * FS + 1e-6).astype(int) + 1)
    impulses = np.array([f[a:b].sum() / FS for a, b in zip(starts, ends, strict=True)])
    np.testing.assert_allclose(impulses, m * (1 + e) * v, rtol=1e-10)


def test_bounce_until_stops_the_train():
    args = {"speed": 2.0, "restitution": 0.8, "mass": 0.01, "until": 0.5, "min_speed": 1e-3}
    f, _ = train_force([Event(0.0, "train", "bounce", args)], seconds=1.5, hardness=2e-4)
    starts, _ = runs(f)
    expected = np.concatenate([[0.0], np.cumsum(2 * 0.8 * 2.0 * 0.8 ** np.arange(20) / 9.81)])
    assert len(starts) == np.count_nonzero(expected <= 0.5)


def test_hertz_constant_against_numerical_integration():
    """tau = 2.87 (m^2 / (R E*^2 v))^(1/5) vs integrating m x'' = -(4/3) E* sqrt(R) x^(3/2)."""
    m, R, E, v = 0.0054, 0.008, 3.3e10, 2.0
    K = 4 / 3 * E * math.sqrt(R)

    def rhs(t, y):
        return [y[1], -K / m * max(y[0], 0.0) ** 1.5]

    def released(t, y):
        return y[0]

    released.terminal, released.direction = True, -1
    guess = hertz_duration(v, R, m, E)
    sol = solve_ivp(rhs, (0, 10 * guess), [1e-30, v], events=released, rtol=1e-11, atol=1e-20)
    assert sol.t_events[0][0] == pytest.approx(guess, rel=2e-3)
    # the constant from the Beta integral: 2 (15/16)^(2/5) B(2/5, 1/2) / (5/2)
    assert 2 * (15 / 16) ** 0.4 * gamma(0.4) * gamma(0.5) / gamma(0.9) / 2.5 == pytest.approx(2.868, abs=5e-4)


def test_effective_modulus():
    assert effective_modulus(70e9, 0.22, None, 0.3) == pytest.approx(70e9 / (2 * (1 - 0.22**2)))
    steel_glass = effective_modulus(200e9, 0.3, 70e9, 0.22)
    assert steel_glass == pytest.approx(1 / (0.91 / 200e9 + (1 - 0.0484) / 70e9))


def test_rendered_hertz_durations_scale_as_speed_to_the_minus_one_fifth():
    """Soft rubber ball: pulse durations of 40-170 samples; fit log tau vs log v."""
    params = {"radius": 0.01, "mass": 0.01, "youngs": 1e7, "poisson": 0.5, "micro": 1}
    speeds = np.geomspace(0.1, 10.0, 7)
    durations = []
    for v in speeds:
        f, node = train_force(
            [Event(0.001, "train", "impact", {"impulse": 0.01, "speed": float(v)})], **params
        )
        durations.append((np.count_nonzero(f) + 1) / FS)  # T samples span count + 1 intervals
    slope, _ = np.polyfit(np.log(speeds), np.log(durations), 1)
    assert slope == pytest.approx(-0.2, abs=0.01)
    e_star = effective_modulus(1e7, 0.5, None, 0.5)
    np.testing.assert_allclose(durations, [hertz_duration(v, 0.01, 0.01, e_star) for v in speeds], rtol=0.03)
    assert node.contact_duration(1.0) == pytest.approx(2.868 * (1e-4 / (0.01 * e_star**2)) ** 0.2)


def test_mass_from_density_and_missing_mass_is_an_error():
    node = ImpactTrain(radius=0.01, density=2500.0)
    assert node.ball_mass() == pytest.approx(4 / 3 * math.pi * 1e-6 * 2500)
    with pytest.raises(PatchError, match="mass"):
        train_force([Event(0.0, "train", "bounce", {"speed": 1.0})])


@pytest.mark.parametrize(
    "params, match",
    [({"hardness": 0.0}, "hardness"), ({"radius": -1.0}, "radius"), ({"poisson": 0.7}, "poisson")],
)
def test_invalid_train_params_are_rejected(params, match):
    with pytest.raises(PatchError, match=match):
        ImpactTrain(**params)


def test_invalid_bounce_args_are_rejected():
    for args in ({"speed": 1.0, "restitution": 1.0}, {"speed": 0.0}, {"restitution": 0.5}):
        with pytest.raises(PatchError):
            train_force([Event(0.0, "train", "bounce", {"mass": 0.01, **args})])


def test_impact_train_is_block_size_invariant():
    rng = np.random.default_rng(4)
    events = []
    for _ in range(60):
        t = float(rng.uniform(0, 0.8))
        if rng.random() < 0.8:
            args = {"impulse": float(rng.uniform(0.01, 0.1)), "micro": int(rng.integers(1, 6))}
            events.append(Event(t, "train", "impact", args))
        else:
            args = {"speed": float(rng.uniform(0.5, 2)), "restitution": 0.7, "mass": 0.01, "micro": 2}
            events.append(Event(t, "train", "bounce", args))
    outs = [train_force(events, 1.0, b, hardness=3e-4)[0] for b in BLOCKS]
    assert np.max(outs[0]) > 1.0
    assert max_abs_diff(outs[0], outs[1]) < 1e-9 and max_abs_diff(outs[0], outs[2]) < 1e-9


# ---------------------------------------------------------- HuntCrossleyImpact
def strike(model, speed, seconds=0.05, t=0.01 + 0.37 / FS, block=64, **params):
    hc = HuntCrossleyImpact(model, name="hc", **params)
    graph = Graph(hc, haptic=[hc.tap("force"), hc.tap("energy")])
    r = render(graph, [Event(t, "hc", "strike", {"speed": speed})], seconds, FS, block, limiter=False)
    return r.audio[0], r.haptic[0], r.haptic[1], hc


def hunt_crossley_rebound(v_in, lam):
    """v_out from v_out - v_in = (1/lam) ln((1 + lam v_out) / (1 + lam v_in)), v_out in (-1/lam, 0).

    Derivation: m x'' = -k x^a (1 + lam x') with x'' = x' dx'/dx gives
    m x' dx' / (1 + lam x') = -k x^a dx; over a whole contact x goes 0 -> x_max -> 0, so the
    right side integrates to 0, and int_{v_in}^{v_out} u / (1 + lam u) du = 0, i.e.
    (v_out - v_in)/lam - ln((1 + lam v_out)/(1 + lam v_in))/lam^2 = 0 (k, a and m drop out).
    """
    if lam == 0:
        return -v_in
    # fixed point of 1 + lam u = (1 + lam v_in) exp(lam (u - v_in)): a contraction for u < 0
    # (slope 1 + lam u < 1), and exact where brentq cannot resolve 1 + lam u ~ 1e-17
    u = 0.0
    for _ in range(100000):
        nxt = ((1 + lam * v_in) * math.exp(lam * (u - v_in)) - 1) / lam
        if abs(nxt - u) < 1e-15:
            break
        u = nxt
    return nxt


@pytest.mark.parametrize(
    "lam, v_in, alpha",
    [(0.0, 1.0, 1.5), (0.5, 1.0, 1.5), (2.0, 0.5, 1.0), (0.3, 3.0, 2.5), (5.0, 1.0, 1.5), (20.0, 2.0, 1.2)],
)
def test_restitution_against_a_rigid_surface_follows_hunt_crossley(lam, v_in, alpha):
    # stiffness chosen so that contacts last > 60 samples
    k = {1.0: 4e3, 1.2: 2e4, 1.5: 1e5, 2.5: 1e7}[alpha]
    _, f, _, hc = strike(RIGID, v_in, seconds=0.06, mass=0.01, stiffness=k, alpha=alpha, dissipation=lam)
    assert np.count_nonzero(f) > 60
    expected = hunt_crossley_rebound(v_in, lam)
    assert hc.rebound_velocity == pytest.approx(expected, rel=0.01)
    assert hc.rebound_speed == -hc.rebound_velocity
    if lam * v_in >= 5:  # strongly dissipative: most of the energy is lost
        assert abs(expected) < 0.3 * v_in


def test_force_pulse_duration_follows_hertz_scaling_with_stiffness():
    """alpha = 1.5, lambda = 0 on a rigid surface: t = 2.9432 (5 m / (4 k))^(2/5) v^(-1/5)."""
    m, v = 0.01, 0.7
    const = 2 * gamma(0.4) * gamma(0.5) / gamma(0.9) / 2.5  # 2 int_0^1 (1 - s^2.5)^-1/2 ds
    measured = []
    for k in (1e5, 1e6, 1e7):
        _, f, _, hc = strike(RIGID, v, seconds=0.05, mass=m, stiffness=k, alpha=1.5, dissipation=0.0)
        starts, ends = runs(f)
        assert len(starts) == 1
        duration = (ends[0] - starts[0] + 0.5) / FS  # contact spans the run plus part of a sample
        expected = const * (5 * m / (4 * k)) ** 0.4 * v**-0.2
        assert duration == pytest.approx(expected, rel=0.05)
        assert hc.contact_time == pytest.approx(expected, rel=0.01)
        measured.append(duration)
    ratios = np.array(measured[:-1]) / np.array(measured[1:])
    np.testing.assert_allclose(ratios, 10**0.4, rtol=0.05)  # t ~ k^(-2/5)


def test_hertz_stiffness_reproduces_the_impact_train_hertz_duration():
    """k = (4/3) E* sqrt(R) in the closed loop gives the contact time of ImpactTrain's Hertz formula."""
    R, m, E, v = 0.01, 0.01, 2e8, 0.5
    e_star = effective_modulus(E, 0.3, None, 0.3)
    k = 4 / 3 * e_star * math.sqrt(R)
    _, _, _, hc = strike(RIGID, v, mass=m, stiffness=k, alpha=1.5, dissipation=0.0)
    assert hc.contact_time == pytest.approx(hertz_duration(v, R, m, e_star), rel=0.01)


def random_model(rng, n_modes, modal_mass):
    f = np.sort(rng.uniform(60, 12000, n_modes))
    d = rng.uniform(0, 40, n_modes)
    gains = rng.uniform(0, 1, n_modes) / (modal_mass * 2 * np.pi * f)  # a = phi^2 / (M w)
    return ModalModel(f, d, gains)


@settings(max_examples=25, deadline=None)
@given(
    seed=st.integers(0, 2**32 - 1),
    n_modes=st.integers(1, 24),
    modal_mass=st.floats(1e-3, 10.0),
    mass=st.floats(1e-3, 1.0),
    stiffness=st.floats(1e4, 1e10),
    alpha=st.floats(1.0, 3.0),
    lam=st.floats(0.0, 20.0),
    speed=st.floats(0.01, 10.0),
)
def test_energy_never_increases_and_force_is_never_negative(
    seed, n_modes, modal_mass, mass, stiffness, alpha, lam, speed
):
    model = random_model(np.random.default_rng(seed), n_modes, modal_mass)
    params = {"mass": mass, "stiffness": stiffness, "alpha": alpha, "dissipation": lam}
    _, f, e, hc = strike(model, speed, seconds=0.04, **params)
    start = math.ceil(0.01 * FS + 0.37)
    e = e[start:]
    assert e[0] > 0
    assert np.max(np.diff(e)) <= 1e-9 * e[0]
    assert np.all(f >= 0) and np.max(f) > 0
    assert hc.energy() == pytest.approx(e[-1], rel=1e-9)  # Python recomputation from the state
    assert hc.corrections == 0  # the discrete-gradient force never needs the safeguard


def test_energy_is_conserved_without_losses():
    """lambda = 0 and undamped modes: E stays constant (checks the energy accounting itself)."""
    rng = np.random.default_rng(7)
    f = np.sort(rng.uniform(100, 5000, 10))
    model = ModalModel(f, np.zeros(10), rng.uniform(0.2, 1, 10) / (0.05 * 2 * np.pi * f))
    _, force, e, hc = strike(model, 1.0, seconds=0.05, mass=0.05, stiffness=1e8, alpha=1.5, dissipation=0.0)
    start = math.ceil(0.01 * FS + 0.37)
    assert np.max(np.abs(e[start:] / e[start] - 1)) < 1e-9
    assert hc.stats[5] >= 1 and np.count_nonzero(force) > 20  # there was a contact
    assert e[start] == pytest.approx(0.5 * 0.05 * 1.0**2, rel=1e-3)  # starts as the hammer's kinetic energy


def test_energy_safeguard_returns_the_force_nearest_to_the_energy_bound():
    """E(f) (hammer kinetic + modal quadratic + V) is convex: the safeguard returns the force
    closest to f on {E <= e_prev}, or the minimiser when that set is empty."""
    sums = StepSums(vh_free=0.3, s0=1e-3, s1=-2e-6, s2=1e-9, x_free=2e-5)
    params = HammerParams(
        mass=0.01,
        stiffness=1e7,
        alpha=1.5,
        dissipation=0.0,
        step=1 / FS,
        compliance=1e-9,
        gain_sum=0.0,
        energy_gain=1e-9,
        floor=0.0,
    )
    args = (sums, params)
    f = np.linspace(0, 300, 30001)
    e = np.array([step_energy(x, *args)[0] for x in f])
    f_min, e_min = f[np.argmin(e)], e.min()
    assert 50 < f_min < 250  # the minimum lies between 0 and the force to correct
    f_hc = 250.0
    bound = 0.5 * (e_min + step_energy(f_hc, *args)[0])
    good = energy_safeguard(f_hc, bound, *args)
    assert step_energy(good, *args)[0] <= bound * (1 + 1e-15)
    assert good == pytest.approx(f[(f > f_min) & (e <= bound)].max(), abs=0.02)
    assert energy_safeguard(f_hc, e_min - 1e-6, *args) == pytest.approx(f_min, abs=0.02)


def test_power_special_cases():
    for alpha in (1.0, 1.5, 2.0, 2.3):
        assert power(0.37, alpha) == pytest.approx(0.37**alpha, rel=1e-15)


def zoh_reference(model, force, location=0):
    """Sum over modes of the exact zero-order-hold response (scipy cont2discrete), output at t_{n+1}."""
    a = model.gains_at(location)
    y = np.zeros(force.size)
    for f, d, g in zip(model.frequencies, model.decays, a, strict=True):
        w = 2 * np.pi * f
        A = np.array([[0.0, 1.0], [-(w * w + d * d), -2 * d]])
        B = np.array([[0.0], [g * w]])
        Ad, Bd, *_ = cont2discrete((A, B, np.eye(2), np.zeros((2, 1))), 1 / FS, method="zoh")
        # y[n] = q(t_{n+1}) = C (zI - Ad)^-1 Bd z F: numerator b0 + b1 z^-1
        b0 = Bd[0, 0]
        b1 = Ad[0, 1] * Bd[1, 0] - Ad[1, 1] * Bd[0, 0]
        y += lfilter([b0, b1], [1.0, -np.trace(Ad), np.linalg.det(Ad)], force)
    return y


def test_sound_is_the_resonator_driven_by_the_contact_force():
    """A light resonator (modal masses ~ the hammer's): record force, drive independent models."""
    rng = np.random.default_rng(3)
    model = random_model(rng, 16, 0.02)
    params = {"mass": 0.02, "stiffness": 3e7, "alpha": 1.5, "dissipation": 0.4}
    y, force, _, hc = strike(model, 1.0, seconds=0.2, **params)
    _, rigid_force, _, _ = strike(RIGID, 1.0, seconds=0.2, **params)
    # the resonator matters: the force differs from the one against a rigid surface
    assert max_abs_diff(force, rigid_force) > 0.1 * np.max(rigid_force)
    peak = np.max(np.abs(y))
    # the same modes discretised by scipy (zero-order hold), driven by the recorded force (the
    # mean of each sample's sub-step forces): equal but for the force's shape within a sample
    assert max_abs_diff(y, zoh_reference(model, force)) < 2e-3 * peak  # 9.4e-4 measured
    # ModalBank (the response at t_n to the smooth force through the samples) differs only
    # by the hold and the output time t_{n+1}: sinc(f/fs) e^{-i pi f/fs} e^{2 i pi f/fs}
    bank = ModalBank(model, name="mb")(ArraySource(force))
    longer = render(Graph(bank), [], 0.25, FS, 64, limiter=False).audio[0]  # the shift wraps its end
    yb = longer[: y.size]
    spectrum = np.fft.rfft(longer, 2 * longer.size)
    freqs = np.fft.rfftfreq(2 * longer.size, 1 / FS)
    held = np.fft.irfft(spectrum * np.sinc(freqs / FS) * np.exp(1j * np.pi * freqs / FS))[: y.size]
    assert max_abs_diff(y, held) < 1e-3 * peak
    assert max_abs_diff(y, yb) < 0.1 * peak  # uncorrected: within the half-sample shift


def test_hc_is_block_size_invariant_with_strikes_locations_and_parameter_changes():
    rng = np.random.default_rng(11)
    model = ModalModel(
        np.geomspace(200, 9000, 30),
        rng.uniform(2, 40, 30),
        rng.uniform(0, 1, (3, 30)) * 1e-5,
        ("a", "b", "c"),
    )
    events = []
    for i in range(12):
        t = 0.013 + i * 0.061 + float(rng.uniform(0, 0.01))
        events.append(
            Event(t, "hc", "strike", {"speed": float(rng.uniform(0.2, 3)), "location": "abc"[i % 3]})
        )
    events.append(Event(0.3, "hc", "set", {"stiffness": 5e8, "dissipation": 1.0}))
    events.append(Event(0.5, "hc", "set", {"mass": 0.05}))
    outs = []
    for b in BLOCKS:
        hc = HuntCrossleyImpact(model, name="hc", mass=0.01, stiffness=1e8)
        outs.append(
            render(Graph(hc, haptic=[hc.tap("force"), hc.tap("energy")]), events, 1.0, FS, b, limiter=False)
        )
    assert np.max(outs[0].haptic[0]) > 1.0
    for other in outs[1:]:
        assert max_abs_diff(outs[0].audio, other.audio) < 1e-6 * np.max(np.abs(outs[0].audio))
        assert max_abs_diff(outs[0].haptic, other.haptic) < 1e-6 * np.max(np.abs(outs[0].haptic))


def test_hc_rejects_invalid_params_and_signed_gains_without_driving_point_gains():
    with pytest.raises(PatchError, match="mass"):
        HuntCrossleyImpact(RIGID, mass=0.0)
    with pytest.raises(PatchError, match="alpha"):
        HuntCrossleyImpact(RIGID, alpha=0.5)
    with pytest.raises(PatchError, match="dissipation"):
        HuntCrossleyImpact(RIGID, dissipation=-1.0)
    # signed strike-to-pickup gains: a contact needs the driving-point gains as well
    signed = ModalModel([300.0, 900.0], [1.0, 1.0], [[1e-4, 1e-4], [1e-4, -1e-4]], name="two")
    for location in (0, 1):
        with pytest.raises(
            PatchError, match=r"model two has signed gains \(mode 1: -0\.0001\) and no driving"
        ):
            HuntCrossleyImpact(signed, location=location)
    driven = ModalModel(signed.frequencies, signed.decays, signed.gains, driving=[[1e-4, 1e-4], [1e-4, 1e-4]])
    hc = HuntCrossleyImpact(driven, name="hc")
    with pytest.raises(PatchError, match="speed"):
        render(Graph(hc), [Event(0.0, "hc", "strike", {"speed": 0.0})], 0.01)


# -------------------------------------------------------------------- the patch
def test_plate_model_is_a_kirchhoff_plate():
    # f_11 of a simply supported 300 x 200 x 5 mm glass plate, from the plate wave speed
    E, nu, rho, h, a, b = 70e9, 0.22, 2500.0, 0.005, 0.3, 0.2
    bending = math.sqrt(E * h**2 / (12 * rho * (1 - nu**2)))  # sqrt(D / (rho h)) in m^2/s
    model = plate_model()
    assert model.frequencies[0] == pytest.approx(math.pi / 2 * (1 / a**2 + 1 / b**2) * bending, rel=1e-12)
    assert model.frequencies[1] == pytest.approx(math.pi / 2 * (4 / a**2 + 1 / b**2) * bending, rel=1e-12)
    assert np.all(model.gains >= 0) and model.frequencies[-1] < 20000
    # driving point at the centre: unit impulse on mode (1,1) moves it by 1 / (M w)
    assert model.gains[0, 0] == pytest.approx(1 / (rho * h * a * b / 4 * 2 * math.pi * model.frequencies[0]))


def marble_times(v0=2.215, e=0.85, g=9.81, min_speed=0.03, t0=0.3):
    times, speeds, t, v = [], [], t0, v0
    while v >= min_speed:
        times.append(t)
        speeds.append(v)
        t += 2 * e * v / g
        v *= e
    return np.array(times), np.array(speeds)


def test_marble_patch_is_block_size_invariant():
    patch = load_patch("marble")
    score = [ev for ev in patch.score] + [Event(0.9, "mallet", "strike", {"speed": 1.0})]
    outs = [render(patch.graph, score, 1.2, FS, b).audio for b in BLOCKS]
    assert np.max(np.abs(outs[0])) > 0.1
    assert max_abs_diff(outs[0], outs[1]) < 1e-6 and max_abs_diff(outs[0], outs[2]) < 1e-6


def detect_onsets(y, fs):
    """Onsets where the > 8 kHz energy in 0.25 ms frames exceeds 4x its maximum over the
    previous 2 ms (a bounce excites the fast-decaying high plate modes afresh)."""
    high = sosfilt(butter(4, 8000, "highpass", fs=fs, output="sos"), y)
    hop = int(fs / 4000)
    energy = np.add.reduceat(high * high, np.arange(0, high.size, hop))
    onsets = []
    floor = 1e-6 * energy.max()
    for i in range(8, energy.size):
        rises = energy[i] > 4 * energy[i - 8 : i].max() and energy[i] > floor
        if rises and (not onsets or i * hop - onsets[-1] > 0.002 * fs):
            onsets.append(i * hop)
    return np.array(onsets) / fs


def test_marble_patch_renders_and_bounce_onsets_match_the_closed_form():
    patch = load_patch("marble")  # the imports above register ImpactTrain and HuntCrossleyImpact
    assert 4.0 <= patch.duration <= 8.0
    y = render(patch.graph, patch.score, patch.duration, FS, 64).audio[0]  # speed: jassy bench contact
    peak_db = 20 * np.log10(np.max(np.abs(y)))
    assert -8.0 < peak_db < -4.5
    bounce = next(ev for ev in patch.score if ev.action == "bounce")
    assert (bounce.time, bounce.args["speed"], bounce.args["restitution"]) == (0.3, 2.215, 0.85)
    times, speeds = marble_times()
    onsets = detect_onsets(y[: int(3.5 * FS)], FS)
    # every detected onset is a bounce, and every bounce faster than 0.2 m/s is detected
    assert all(np.min(np.abs(times - o)) < 0.001 for o in onsets)
    for tb in times[speeds >= 0.2]:
        assert np.min(np.abs(onsets - tb)) < 0.001
    # the plate rings at its modes: the strongest spectral peaks sit on model frequencies
    model = plate_model()
    f, p = welch(y[int(0.3 * FS) : int(2.9 * FS)], FS, nperseg=8192)
    for fp in f[np.argsort(p)[-5:]]:
        assert np.min(np.abs(model.frequencies - fp)) < 2 * FS / 8192
    centroid = np.sum(f * p) / np.sum(p)
    assert 1500 < centroid < 8000  # a bright glass clink
    # the closing mallet tap is heard: energy after 4 s
    assert np.max(np.abs(y[int(4.0 * FS) : int(4.5 * FS)])) > 0.1

"""SoundPressure against the closed forms of the pulsating sphere and the monopole."""

from __future__ import annotations

import math
import textwrap

import numpy as np
import pytest

from jassy import Graph, render
from jassy.errors import PatchError
from jassy.levels import P_REF, spl_db
from ugens import Sine, SoundPressure
from ugens.pressure import AIR_DENSITY, SPEED_OF_SOUND

FS = 48000
PASCAL = 20 * math.log10(1 / P_REF)  # full_scale_spl for an output in Pa


def steady_amplitude(freq: float, duration: float = 0.5, **pressure) -> float:
    """Amplitude of the output's last 0.2 s when the input is a unit sine at ``freq`` Hz
    (least squares fit of a sine and a cosine: exact for a steady sinusoid)."""
    sine = Sine(name="u", freq=freq, amp=1.0)
    pressure.setdefault("full_scale_spl", PASCAL)
    out = SoundPressure(sine, name="p", **pressure)
    y = render(Graph(out), [], duration=duration, sample_rate=FS, limiter=False).audio[0]
    n = int(0.2 * FS)
    t = np.arange(len(y))[-n:] / FS
    basis = np.stack([np.sin(2 * np.pi * freq * t), np.cos(2 * np.pi * freq * t)], axis=1)
    coef, *_ = np.linalg.lstsq(basis, y[-n:], rcond=None)
    return float(np.hypot(*coef))


@pytest.mark.parametrize("a", [0.01, 0.1])
@pytest.mark.parametrize("freq", [100.0, 546.0, 2000.0, 5460.0, 10000.0])
def test_velocity_gives_the_pulsating_sphere_pressure(freq, a):
    """|p| = rho c u (a/r) ka / sqrt(1 + (ka)^2) (Kinsler et al. 7.4.8) at r = 1 m; the
    corner c / 2 pi a is 546 Hz for a = 0.1 m, 5.46 kHz for a = 0.01 m."""
    r = 1.0
    ka = 2 * math.pi * freq * a / SPEED_OF_SOUND
    expected = AIR_DENSITY * SPEED_OF_SOUND * (a / r) * ka / math.sqrt(1 + ka * ka)
    got = steady_amplitude(freq, radius=a, distance=r)
    assert 20 * math.log10(got / expected) == pytest.approx(0.0, abs=0.3)


def test_a_small_sphere_is_the_monopole_and_pressure_falls_as_one_over_r():
    """ka << 1: p = omega rho Q / (4 pi r), Q = 4 pi a^2 u (Kinsler et al. 7.3.4)."""
    a, freq = 0.005, 200.0  # ka = 0.018
    near = steady_amplitude(freq, radius=a, distance=0.5)
    far = steady_amplitude(freq, radius=a, distance=2.0)
    q = 4 * math.pi * a * a * 1.0
    monopole = 2 * math.pi * freq * AIR_DENSITY * q / (4 * math.pi * 0.5)
    assert near == pytest.approx(monopole, rel=2e-3)
    assert 20 * math.log10(near / far) == pytest.approx(20 * math.log10(4.0), abs=1e-6)


def test_displacement_input_is_differentiated_and_full_scale_rescales():
    """A displacement X sin(w t) is a velocity w X: the same pressure, within the first
    difference's 2 sin(w T / 2) / (w T) at 1 kHz (-0.006 dB); by default 1.0 is 105 dB SPL."""
    freq, a = 1000.0, 0.05
    by_velocity = steady_amplitude(freq, radius=a)
    by_displacement = steady_amplitude(freq, radius=a, input_kind="displacement")
    w = 2 * math.pi * freq
    first_difference = 2 * math.sin(w / FS / 2) * FS / w
    assert by_displacement == pytest.approx(w * by_velocity * first_difference, rel=2e-3)
    cinema = steady_amplitude(freq, radius=a, full_scale_spl=105.0)
    assert cinema == pytest.approx(by_velocity / (P_REF * 10 ** (105 / 20)), rel=1e-9)
    assert SoundPressure.param_specs["full_scale_spl"].default == 105.0


def test_a_pressure_input_is_spread_as_one_over_r_without_filtering():
    """Explosion-like sources give Pa at a reference distance (radius): heard at distance r
    the pressure is p radius / r at every frequency."""
    for freq in (50.0, 5000.0):
        assert steady_amplitude(freq, input_kind="pressure", radius=2.0, distance=8.0) == pytest.approx(
            0.25, rel=1e-9
        )


def test_spl_of_one_pascal_rms_is_94_db():
    assert spl_db(1.0) == pytest.approx(20 * math.log10(1 / P_REF))
    assert spl_db(P_REF) == pytest.approx(0.0)


def test_a_listener_inside_the_body_is_refused():
    with pytest.raises(PatchError, match=r"nodes.p.distance: expected a distance >= radius"):
        render(Graph(SoundPressure(Sine(name="u"), name="p", radius=0.5, distance=0.2)), [], duration=0.01)


def test_render_reports_the_peak_as_a_sound_pressure_level(tmp_path, capsys):
    """A patch heard through SoundPressure: the summary reads the peak as dB SPL (dBFS +
    full_scale_spl) at the listening distance; the peak of a unit velocity sine far above the
    corner is rho c a / r."""
    from jassy.apps.cli import main

    patch = tmp_path / "p.toml"
    patch.write_text(
        textwrap.dedent(
            """
            [patch]
            name = "p"
            duration = 0.2
            [nodes.u]
            type = "Sine"
            freq = 10000.0
            [nodes.p]
            type = "SoundPressure"
            input = "u"
            radius = 0.05
            distance = 2.0
            full_scale_spl = 120.0
            [outputs]
            audio = "p"
            """
        )
    )
    assert main(["render", str(patch), "-o", str(tmp_path / "p.wav")]) == 0
    out = capsys.readouterr().out
    ka = 2 * math.pi * 10000.0 * 0.05 / SPEED_OF_SOUND
    peak = AIR_DENSITY * SPEED_OF_SOUND * 0.05 / 2.0 * ka / math.sqrt(1 + ka * ka)
    spl = float(out.split(" dB SPL at 2 m")[0].rsplit("= ", 1)[1])
    assert spl == pytest.approx(spl_db(peak), abs=0.1)


@pytest.mark.parametrize(("speed", "span", "distance"), [(10.0, 0.5, 2.0), (25.0, 0.01, 1.0)])
def test_a_wire_in_the_wind_gives_the_curle_dipole_pressure(speed, span, distance):
    """KarmanWhistle with a span: the lift per correlated length l = min(3 d, L), rms
    0.5 (rho v^2 / 2) d l at omega = 2 pi St v / d, radiates dp = omega F' / (4 pi c r)
    (Curle), N = L / l lengths add in power: p_rms = sqrt(L / l) omega F' / (4 pi c r)."""
    from ugens import KarmanWhistle

    d, st, lift = 0.003, 0.2, 0.5
    wire = KarmanWhistle(name="k", speed=speed, diameter=d, q=2.0, span=span, distance=distance, seed=4)
    y = render(Graph(wire), [], duration=4.0, sample_rate=FS, limiter=False).audio[0][FS // 10 :]
    length = min(3 * d, span)
    force = lift * 0.5 * AIR_DENSITY * speed**2 * d * length
    omega = 2 * math.pi * st * speed / d
    expected = math.sqrt(span / length) * omega * force / (4 * math.pi * SPEED_OF_SOUND * distance)
    assert np.sqrt(np.mean(y**2)) == pytest.approx(expected, rel=0.08)


@pytest.mark.parametrize("kind", ["velocity", "displacement", "pressure"])
def test_the_program_kernel_renders_the_same_bits_as_the_node(kind):
    """A struck plate heard through SoundPressure runs as one compiled program (no Python per
    node) with exactly the output of the node-by-node path, at block sizes 1, 64 and 4096."""
    from jassy import Event, ModalModel
    from jassy.engines.offline import OfflineEngine
    from ugens import ImpactForce, ModalBank

    model = ModalModel(np.geomspace(90.0, 12000.0, 12), np.linspace(3.0, 40.0, 12), np.ones((1, 12)))
    score = [
        Event(0.01 + 0.021 * k + 0.3 / FS * k, "tap", "impact", {"impulse": 1e-3 * (k + 1)}) for k in range(8)
    ]
    for block in (1, 64, 4096):
        rendered = []
        for program in (False, True):
            tap = ImpactForce(name="tap")
            plate = ModalBank(model, name="plate")(tap)
            heard = SoundPressure(plate, name="p", input_kind=kind, radius=0.05, distance=2.0)
            engine = OfflineEngine(Graph(heard), score, FS, block, program=program)
            assert (engine.program is not None) == program, engine.why_not_program
            rendered.append(engine.render(0.25).audio)
        assert np.any(rendered[0] != 0)
        np.testing.assert_array_equal(rendered[1], rendered[0])

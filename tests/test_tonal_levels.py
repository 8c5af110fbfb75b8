"""Tonal force sources calibrated to the model they drive (ugens/tonal_level.py): at the
reference operating point a calibrated ModalBank rings at TONAL_RMS_DBFS RMS, mean power
over the model's locations, measured on rendered output."""

from __future__ import annotations

import numpy as np
import pytest

import ugens
from jassy import Event, Graph, ModalModel, PatchError, render
from jassy.levels import TONAL_RMS_DBFS, band_line_power

FS = 48000
TARGET = 10 ** (TONAL_RMS_DBFS / 20)


def bank_rms(model, source, event, location, duration, settle):
    bank = ugens.ModalBank(model, name="bank", level="calibrated", location=location)(source)
    y = render(Graph(bank), [event], duration=duration, sample_rate=FS, limiter=False).audio[0]
    return float(np.sqrt(np.mean(y[int(settle * FS) :] ** 2)))


@pytest.mark.timeout(300)  # a cold numba compile on a loaded machine, not a hang
def test_a_calibrated_drill_rings_its_model_at_the_tonal_level_at_any_rpm():
    """Lines only (no cutting noise) through one broad mode at 1.1 kHz (two locations), at
    30000 rpm (lines 500 Hz apart, 100 Hz from the mode) and 12000 rpm (200 Hz apart, the
    emphasised 6th harmonic 100 Hz above it): uncalibrated 5 dB apart, calibrated both at
    TONAL_RMS_DBFS within 2 % (the table averages each line over its 195 rpm step and
    interpolates; one mode: no cross terms). The steady response is periodic, so its RMS over
    whole periods is exact."""
    model = ModalModel(np.array([1100.0]), np.array([150.0]), np.array([[1.0], [0.4]]))
    rms = {}
    for level in ("calibrated", "raw"):
        for rpm in (30000.0, 12000.0):
            powers = []
            for location in (0, 1):
                drill = ugens.DrillSource(model, name="d", level=level, rpm=rpm, noise=0.0, chips=0.0)
                event = Event(0.0, "d", "set", {"force": 1.0, "removal": 1.0}, jump=True)
                powers.append(bank_rms(model, drill, event, location, 0.8, 0.3) ** 2)
            rms[level, rpm] = np.sqrt(np.mean(powers))
    assert abs(20 * np.log10(rms["raw", 30000.0] / rms["raw", 12000.0])) > 3
    for rpm in (30000.0, 12000.0):
        assert rms["calibrated", rpm] == pytest.approx(TARGET, rel=0.02), rpm


def test_the_band_averaged_line_power_is_the_mean_over_the_band():
    """band_line_power's closed form against the numerical mean of sum_k a_k^2 |H_k|^2 over
    each band (10^5 points, trapezoids): quasi-static, on a resonance, between modes."""
    model = ModalModel(
        np.array([50.0, 980.0, 2980.0, 5210.0]),
        np.array([3.0, 40.0, 25.0, 60.0]),
        np.array([[0.2, 1.0, 0.5, 2.0], [0.1, 0.3, 1.0, 0.1]]),
    )
    edges = np.array([[0.0, 900.0, 2970.0], [10.0, 1100.0, 2990.0], [60.0, 1500.0, 5400.0]])
    amplitudes = np.array([1.0, 0.5, 2.0])
    w, d = 2 * np.pi * model.frequencies[:, None], model.decays[:, None]
    weight = (model.gains**2).mean(axis=0)
    expected = np.zeros(2)
    for s in range(2):
        for line in range(3):
            f = np.linspace(edges[s, line], edges[s + 1, line], 100001)
            h2 = w**2 / np.abs((d + 2j * np.pi * f) ** 2 + w**2) ** 2
            mean = np.trapezoid(weight @ h2, f) / (f[-1] - f[0])
            expected[s] += amplitudes[line] ** 2 / 2 * mean
    np.testing.assert_allclose(band_line_power(model, edges, amplitudes, FS), expected, rtol=1e-7)


@pytest.mark.timeout(300)  # a cold numba compile on a loaded machine, not a hang
@pytest.mark.parametrize("speed", [1.0, 0.3])
def test_a_calibrated_resonant_scrape_rings_its_model_at_the_tonal_level_at_any_speed(speed):
    """Noise band at the reference contact (1 m/s: 2.3 kHz, ~220 Hz wide) and at 0.3 m/s
    (900 Hz, ~110 Hz wide) through four modes, one in each band and two on its skirts; the
    level follows the amplitude law sqrt(F v / (f_ref v_ref)) whatever modes the band meets.
    16 s of steady scraping per location (measured within 0.4 dB over two seeds)."""
    model = ModalModel(
        np.array([880.0, 1800.0, 2350.0, 3100.0]),
        np.array([25.0, 30.0, 20.0, 45.0]),
        np.array([[0.3, 1.0, 0.4, 1.5], [1.0, 0.5, 1.0, 0.7]]),
    )
    powers = []
    for location in (0, 1):
        scrape = ugens.ResonantScrape(model, name="s", level="calibrated", seed=5 + location)
        event = Event(0.0, "s", "set", {"speed": speed}, jump=True)
        powers.append(bank_rms(model, scrape, event, location, 16.5, 0.5) ** 2)
    expected = TARGET * np.sqrt(speed)  # s(F, v) at F = f_ref = 1 N
    assert 20 * np.log10(np.sqrt(np.mean(powers)) / expected) == pytest.approx(0.0, abs=0.6)
    assert abs(10 * np.log10(powers[0] / powers[1])) > 3  # calibrated on the mean, not each


@pytest.mark.parametrize("source", ["ResonantScrape", "DrillSource"])
def test_the_default_level_is_calibrated_with_a_model_and_raw_without(source):
    """level = 'auto' (the default): the same bits as 'calibrated' when the source is given
    the model it drives, as 'raw' (the force in N) when not; calibrating changes the sound."""
    model = ModalModel(np.array([700.0, 2300.0]), np.array([20.0, 30.0]), np.array([[1.0, 0.6]]))
    drive = {"ResonantScrape": {"speed": 0.6}, "DrillSource": {"force": 1.0, "removal": 1.0}}[source]

    def force(*given, **params):
        node = getattr(ugens, source)(*given, name="s", **params)
        return render(Graph(node), [Event(0.0, "s", "set", drive, jump=True)], 0.05, FS).audio[0]

    assert getattr(ugens, source).param_specs["level"].default == "auto"
    auto = force(model)
    np.testing.assert_array_equal(auto, force(model, level="calibrated"))
    np.testing.assert_array_equal(force(), force(level="raw"))
    np.testing.assert_array_equal(force(model, level="raw"), force())
    assert np.any(auto != 0) and not np.allclose(auto, force())


def test_calibrated_without_a_model_is_one_clear_error():
    scrape = ugens.ResonantScrape(name="s", level="calibrated")
    bank = ugens.ModalBank(ModalModel(np.array([500.0]), np.array([5.0]), np.array([[1.0]])), name="b")(
        scrape
    )
    with pytest.raises(PatchError, match=r"nodes\.s\.level: 'calibrated' needs `model`"):
        render(Graph(bank), [], duration=0.01, sample_rate=FS)


def test_the_compiled_program_reads_the_level_table():
    """A calibrated ResonantScrape swept through its speeds renders the same bits node by node
    and as one compiled program (which reads its settings and level table from ``cfg``)."""
    from jassy.engines.offline import OfflineEngine

    model = ModalModel(np.array([700.0, 1900.0]), np.array([20.0, 30.0]), np.array([[1.0, 0.6]]))
    score = [
        Event(0.0, "s", "set", {"speed": 0.2}, jump=True),
        Event(0.05, "s", "set", {"speed": 1.5}, ramp=0.1),
    ]
    rendered = []
    for program in (False, True):
        scrape = ugens.ResonantScrape(model, name="s", level="calibrated")
        bank = ugens.ModalBank(model, name="bank", level="calibrated")(scrape)
        engine = OfflineEngine(Graph(bank), score, FS, 64, program=program)
        assert (engine.program is not None) == program, engine.why_not_program
        rendered.append(engine.render(0.2).audio)
    raw = ugens.ResonantScrape(model, name="s", level="raw")
    raw_out = render(
        Graph(ugens.ModalBank(model, name="bank", level="calibrated")(raw)), score, 0.2, FS
    ).audio
    assert np.any(rendered[0] != 0) and not np.allclose(rendered[0], raw_out)  # the table acts
    np.testing.assert_array_equal(rendered[1], rendered[0])

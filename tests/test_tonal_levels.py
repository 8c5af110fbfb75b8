"""Tonal force sources calibrated to the model they drive (ugens/tonal_level.py): at the
reference operating point a calibrated ModalBank rings at TONAL_RMS_DBFS RMS, mean power
over the model's locations, measured on rendered output."""

from __future__ import annotations

import numpy as np
import pytest

import ugens
from jassy import Event, Graph, ModalModel, PatchError, render
from jassy.levels import TONAL_RMS_DBFS

FS = 48000
TARGET = 10 ** (TONAL_RMS_DBFS / 20)


def bank_rms(model, source, event, location, duration, settle):
    bank = ugens.ModalBank(model, name="bank", level="calibrated", location=location)(source)
    y = render(Graph(bank), [event], duration=duration, sample_rate=FS, limiter=False).audio[0]
    return float(np.sqrt(np.mean(y[int(settle * FS) :] ** 2)))


@pytest.mark.timeout(60)
def test_a_calibrated_drill_rings_its_model_at_the_tonal_level():
    """Lines only (no cutting noise): 500 Hz rotation harmonics through three modes, one of
    them 20 Hz off the tooth-passing line at 3 kHz, at two locations. The steady response
    is periodic (1 s holds 500 periods), so its RMS is exact."""
    model = ModalModel(
        np.array([980.0, 2980.0, 5210.0]),
        np.array([40.0, 25.0, 60.0]),
        np.array([[1.0, 0.5, 2.0], [0.3, 1.0, 0.1]]),
    )
    powers = []
    for location in (0, 1):
        drill = ugens.DrillSource(model, name="d", level="calibrated", noise=0.0, chips=0.0)
        event = Event(0.0, "d", "set", {"force": 1.0, "removal": 1.0}, jump=True)
        powers.append(bank_rms(model, drill, event, location, 1.6, 0.6) ** 2)
    assert np.sqrt(np.mean(powers)) == pytest.approx(TARGET, rel=0.01)
    # the two locations differ: the calibration is of the mean, not of each
    assert abs(10 * np.log10(powers[0] / powers[1])) > 3


@pytest.mark.timeout(60)
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
    raw = ugens.ResonantScrape(model, name="s")
    raw_out = render(
        Graph(ugens.ModalBank(model, name="bank", level="calibrated")(raw)), score, 0.2, FS
    ).audio
    assert np.any(rendered[0] != 0) and not np.allclose(rendered[0], raw_out)  # the table acts
    np.testing.assert_array_equal(rendered[1], rendered[0])

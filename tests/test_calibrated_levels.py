"""Calibrated levels: every shipped model struck by a default impact sounds within -30..-6 dBFS
with unit gains, and the reference gain matches the closed-form peak of a single mode."""

from __future__ import annotations

import math
from pathlib import Path

import numpy as np
import pytest

from jassy import Event, Graph, ModalModel, render
from jassy.errors import ModelError
from jassy.levels import REFERENCE_DURATION, REFERENCE_IMPULSE, REFERENCE_PEAK_DBFS, reference_gain
from patches.objects import OBJECTS
from patches.shipped import shipped_models
from ugens import ImpactForce, ModalBank

PATCHES = Path(__file__).resolve().parents[1] / "patches"
SHIPPED = sorted(set(shipped_models()) | {info.file for info in OBJECTS.values()})


def strike_peak_dbfs(model: ModalModel, **bank) -> float:
    hit = ImpactForce(name="hit")
    out = ModalBank(model, name="bank", **bank)(hit)
    result = render(Graph(out), [Event(0.01, "hit", "impact", {})], duration=0.3, sample_rate=48000)
    return 20 * math.log10(float(np.abs(result.audio).max()))


@pytest.mark.parametrize("filename", SHIPPED)
def test_every_shipped_model_struck_by_default_sounds_between_minus_30_and_minus_6_dbfs(filename):
    model = ModalModel.load(PATCHES / filename)
    level = strike_peak_dbfs(model, level="calibrated")
    assert -30.0 <= level <= -6.0, f"{filename}: {level:.1f} dBFS"


def test_reference_gain_of_one_mode_matches_the_fourier_transform_of_the_pulse():
    """Undamped mode a sin(w t) struck by a 1 - cos pulse of J over tau: afterwards it rings
    at amplitude a J |sinc(f tau)| / |1 - (f tau)^2| (the pulse's Fourier transform)."""
    f, a = 300.0, 7.0
    model = ModalModel([f], [0.0], [[a]])
    x = f * REFERENCE_DURATION
    amplitude = a * REFERENCE_IMPULSE * abs(math.sin(math.pi * x) / (math.pi * x) / (1 - x * x))
    expected = 10 ** (REFERENCE_PEAK_DBFS / 20) / amplitude
    assert reference_gain(model, 48000) == pytest.approx(expected, rel=1e-4)
    # and the bank, calibrated, rings at -18 dBFS
    assert strike_peak_dbfs(model, level="calibrated") == pytest.approx(REFERENCE_PEAK_DBFS, abs=0.01)


def test_a_stored_reference_gain_is_used_and_raw_level_is_unchanged():
    model = ModalModel.load(PATCHES / "bell_model.toml")
    raw = strike_peak_dbfs(model)
    assert raw == pytest.approx(strike_peak_dbfs(model, level="raw"))
    computed = reference_gain(model, 48000)
    stored = ModalModel(
        model.frequencies, model.decays, model.gains, model.points, reference_gain=2 * computed
    )
    assert strike_peak_dbfs(stored, level="calibrated") == pytest.approx(
        raw + 20 * math.log10(2 * computed), abs=1e-6
    )


@pytest.mark.parametrize("suffix", [".toml", ".npz"])
def test_reference_gain_round_trips_through_model_files(tmp_path, suffix):
    model = ModalModel([100.0, 230.0], [1.0, 2.0], [[1.0, 0.5]], ("a",), "m", reference_gain=3.5e-4)
    model.save(tmp_path / f"m{suffix}")
    assert ModalModel.load(tmp_path / f"m{suffix}").reference_gain == 3.5e-4
    plain = ModalModel([100.0], [1.0], [[1.0]])
    plain.save(tmp_path / f"p{suffix}")
    assert ModalModel.load(tmp_path / f"p{suffix}").reference_gain is None


def test_a_bad_reference_gain_is_refused_naming_the_key(tmp_path):
    path = tmp_path / "bad.toml"
    path.write_text("frequencies = [100.0]\ndecays = [1.0]\ngains = [[1.0]]\nreference_gain = -2.0\n")
    with pytest.raises(ModelError, match="reference_gain: expected a number > 0"):
        ModalModel.load(path)

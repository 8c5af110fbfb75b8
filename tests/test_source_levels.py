"""Every shipped model driven by every force source at its default parameters, through a
calibrated ModalBank with unit gains, peaks within -30..-6 dBFS (the level convention of
jassy.levels: sources output forces in N with everyday defaults); so do the sources that
sound by themselves, in full scale."""

from __future__ import annotations

import math
from pathlib import Path

import numpy as np
import pytest

import ugens
from jassy import Event, Graph, ModalModel, render
from jassy.levels import FORCE_SOURCES, SOUND_SOURCES, calibrated
from patches.objects import OBJECTS
from patches.shipped import shipped_models

PATCHES = Path(__file__).resolve().parents[1] / "patches"
SHIPPED = sorted(set(shipped_models()) | {info.file for info in OBJECTS.values()})
#: Seconds rendered: a stochastic source's peak is that of ~100 micro-impacts.
DURATION = 1.0


def once_calibrated(model: ModalModel) -> ModalModel:
    """The model with its reference gain stored (computed here once, not by every bank)."""
    return model if model.reference_gain is not None else calibrated(model)


def peak_dbfs(model: ModalModel, source: str) -> float:
    drive = FORCE_SOURCES[source]
    src = getattr(ugens, source)(name="src")
    bank = ugens.ModalBank(model, name="bank", level="calibrated")(src)
    events = [Event(0.01, "src", drive.action, drive.args)]
    y = render(Graph(bank), events, duration=DURATION, sample_rate=48000, limiter=False).audio[0]
    return 20 * math.log10(max(float(np.abs(y).max()), 1e-30))


@pytest.mark.timeout(60)
@pytest.mark.parametrize("filename", SHIPPED)
def test_every_default_force_source_on_a_shipped_model_peaks_between_minus_30_and_minus_6_dbfs(filename):
    model = once_calibrated(ModalModel.load(PATCHES / filename))
    levels = {s: peak_dbfs(model, s) for s in FORCE_SOURCES}
    outside = {s: round(db, 1) for s, db in levels.items() if not -30.0 <= db <= -6.0}
    assert not outside, f"{filename}: {outside} dBFS"


#: Sources that sound by themselves in full scale (jassy.levels.SOUND_SOURCES). Not here:
#: Explosion, whose output is a pressure in Pa (a firecracker's 50 Pa peak at 10 m is
#: 128 dB SPL, above any full scale meant for everyday sounds; see SoundPressure).
FULL_SCALE = sorted(name for name, level in SOUND_SOURCES.items() if level.unit == "full scale")


@pytest.mark.timeout(60)
@pytest.mark.parametrize("source", FULL_SCALE)
def test_a_standalone_source_at_its_defaults_peaks_between_minus_30_and_minus_6_dbfs(source):
    src = getattr(ugens, source)(name="src")
    events = [Event(0.01, "src", action, args) for action, args in SOUND_SOURCES[source].events]
    y = render(Graph(src), events, duration=2.0, sample_rate=48000, limiter=False).audio[0]
    level = 20 * math.log10(max(float(np.abs(y).max()), 1e-30))
    assert -30.0 <= level <= -6.0, f"{source}: {level:.1f} dBFS"

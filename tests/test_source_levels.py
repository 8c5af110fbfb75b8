"""Every shipped model driven by every force source at its default parameters, through a
calibrated ModalBank with unit gains, peaks within -30..-6 dBFS (the level convention of
jassy.levels: sources output forces in N with everyday defaults; tonal ones calibrated to the
model they drive); so do the sources that sound by themselves, in full scale."""

from __future__ import annotations

import math
from pathlib import Path

import numpy as np
import pytest

import ugens
from jassy import Event, Graph, ModalModel, render
from jassy.levels import (
    FORCE_SOURCES,
    MODEL_CALIBRATED_SOURCES,
    SOUND_SOURCES,
    TONAL_DRIVES,
    Drive,
    calibrated,
    driven_source,
)
from patches.objects import OBJECTS
from patches.shipped import shipped_models
from ugens.nonlinear_impact import DEFAULT_STRIKE_SPEED

PATCHES = Path(__file__).resolve().parents[1] / "patches"
SHIPPED = sorted(set(shipped_models()) | {info.file for info in OBJECTS.values()})
#: Seconds rendered: a stochastic source's peak is that of ~100 micro-impacts.
DURATION = 1.0


def once_calibrated(model: ModalModel) -> ModalModel:
    """The model with its reference gain stored (computed here once, not by every bank)."""
    return model if model.reference_gain is not None else calibrated(model)


def peak_dbfs(model: ModalModel, source: str, drive: Drive | None = None) -> float:
    src, event = driven_source(source, model, drive=drive)
    bank = ugens.ModalBank(model, name="bank", level="calibrated")(src)
    y = render(Graph(bank), [event], duration=DURATION, sample_rate=48000, limiter=False).audio[0]
    return 20 * math.log10(max(float(np.abs(y).max()), 1e-30))


@pytest.mark.timeout(300)  # a cold numba compile on a loaded machine, not a hang
@pytest.mark.parametrize("filename", SHIPPED)
def test_every_default_force_source_on_a_shipped_model_peaks_between_minus_30_and_minus_6_dbfs(filename):
    model = once_calibrated(ModalModel.load(PATCHES / filename))
    levels = {s: peak_dbfs(model, s) for s in [*FORCE_SOURCES, *MODEL_CALIBRATED_SOURCES]}
    for source, drives in TONAL_DRIVES.items():  # the tonal ones over their operating range
        levels.update({f"{source} {d.args}": peak_dbfs(model, source, d) for d in drives})
    outside = {s: round(db, 1) for s, db in levels.items() if not -30.0 <= db <= -6.0}
    assert not outside, f"{filename}: {outside} dBFS"


#: Sources that sound by themselves in full scale (jassy.levels.SOUND_SOURCES). Not here:
#: Explosion, whose output is a pressure in Pa (a firecracker's 50 Pa peak at 10 m is
#: 128 dB SPL, above any full scale meant for everyday sounds; see SoundPressure).
FULL_SCALE = sorted(name for name, level in SOUND_SOURCES.items() if level.unit == "full scale")


@pytest.mark.timeout(300)  # a cold numba compile on a loaded machine, not a hang
@pytest.mark.parametrize("source", FULL_SCALE)
def test_a_standalone_source_at_its_defaults_peaks_between_minus_30_and_minus_6_dbfs(source):
    src = getattr(ugens, source)(name="src")
    events = [Event(0.01, "src", action, args) for action, args in SOUND_SOURCES[source].events]
    y = render(Graph(src), events, duration=2.0, sample_rate=48000, limiter=False).audio[0]
    level = 20 * math.log10(max(float(np.abs(y).max()), 1e-30))
    assert -30.0 <= level <= -6.0, f"{source}: {level:.1f} dBFS"


#: Shipped models a default HuntCrossleyImpact strike is not meant to fit into the window,
#: and why (the level convention calibrates what is heard, not the contact: the hammer's
#: bounce depends on the model's driving-point receptance in m per N s).
HC_OUTSIDE = {
    "bar_model.toml": "signed gains without driving-point rows: no contact can be solved against it",
    "bell_model.toml": "gains in arbitrary units (a formula's profile), not a receptance: far too compliant",
    "bottle_cavity_model.toml": "an air cavity's two modes in arbitrary units, not a structure to strike",
    "bowed_string_model.toml": "a string's driving point yields far more than the contact: a long push",
    "paper_sheet_model.toml": "an 80 g/m^2 sheet yields far more than the contact: a long push",
}


def hertz_contact_time(mass: float, stiffness: float, speed: float) -> float:
    """Duration (s) of an elastic Hertz impact (alpha = 1.5) of ``mass`` at ``speed`` on a
    rigid, immovable surface: 2.9432 x_max / v with x_max = (5 m v^2 / (4 k))^(2/5)
    (Johnson, *Contact Mechanics*, 1985, section 11.4)."""
    return 2.9432 * (5.0 * mass * speed**2 / (4.0 * stiffness)) ** 0.4 / speed


def default_hertz_time() -> float:
    """The rigid-surface contact time of HuntCrossleyImpact's default hammer and strike."""
    specs = ugens.HuntCrossleyImpact.param_specs
    assert specs["alpha"].default == 1.5
    return hertz_contact_time(specs["mass"].default, specs["stiffness"].default, DEFAULT_STRIKE_SPEED)


def hc_strike(model: ModalModel) -> tuple[float, float]:
    """(peak dBFS, seconds from the first to the last sample of contact force) of a default
    strike on a calibrated model at its default location."""
    hc = ugens.HuntCrossleyImpact(model, name="hc", level="calibrated")
    events = [Event(0.01, "hc", "strike", {})]
    r = render(Graph(hc, haptic=[hc.tap("force")]), events, 0.5, sample_rate=48000, limiter=False)
    touching = np.flatnonzero(r.haptic[0])
    peak = 20 * math.log10(max(float(np.abs(r.audio[0]).max()), 1e-30))
    return peak, (touching[-1] - touching[0]) / 48000 if touching.size else 0.0


@pytest.mark.timeout(300)  # a cold numba compile on a loaded machine, not a hang
@pytest.mark.parametrize("filename", sorted(set(SHIPPED) - set(HC_OUTSIDE)))
def test_a_default_hammer_strike_on_a_shipped_model_peaks_between_minus_30_and_minus_6_dbfs(filename):
    peak, contact = hc_strike(once_calibrated(ModalModel.load(PATCHES / filename)))
    assert -30.0 <= peak <= -6.0, f"{filename}: {peak:.1f} dBFS"
    # the reason it fits: the surface is stiff and heavy next to the 10 g hammer, which
    # bounces off as from a rigid one
    rigid = default_hertz_time()
    assert abs(contact / rigid - 1) < 0.1, (
        f"{filename}: contact {contact * 1e3:.2f} ms, rigid {rigid * 1e3:.2f} ms"
    )


@pytest.mark.timeout(300)  # a cold numba compile on a loaded machine, not a hang
@pytest.mark.parametrize("filename", sorted(set(HC_OUTSIDE) - {"bar_model.toml"}))
def test_the_models_left_out_of_the_hammer_window_are_those_that_yield_to_it(filename):
    _, contact = hc_strike(once_calibrated(ModalModel.load(PATCHES / filename)))
    assert contact > 3 * default_hertz_time(), f"{filename}: {contact * 1e3:.2f} ms"

"""The level convention of calibrated modal models.

Raw modal gains are in whatever units a model was made in (m per N s for a finite-element
model, arbitrary for a formula or a fitted one), so the same strike can sound at -160 dBFS
on one model and clip on another. The convention fixes that with one number per model:

    The reference strike -- the default ImpactForce impact, a 1 - cos pulse of
    REFERENCE_IMPULSE = 1e-3 N s lasting REFERENCE_DURATION = 1 ms -- at the model's
    loudest location (the gain row whose response peaks highest) peaks at
    REFERENCE_PEAK_DBFS = -18 dBFS.

A ModalBank with ``level = "calibrated"`` multiplies its gains by the model's reference
gain (``ModalModel.reference_gain`` if the model file gives one, otherwise computed here
by the rule), so with ``gain = 1`` the default strike sounds at -18 dBFS at the loudest
point and lower elsewhere, and sound scales linearly with the impulse: 1e-2 N s peaks at
-(18 - 20) = +2 dBFS there (the final limiter catches it), 1e-4 N s at -38 dBFS.

The peak is that of the exact continuous response sampled at the render's rate: per mode
the convolution of a e^{-d t} sin(2 pi f t) with the pulse in closed form (complex
exponentials), so the calibration does not depend on the resonator code it calibrates.
"""

from __future__ import annotations

from typing import NamedTuple

import numpy as np

from jassy.modal_model import ModalModel

#: The reference strike: the default impulse (N s) and contact duration (s) of ImpactForce.
REFERENCE_IMPULSE = 1e-3
REFERENCE_DURATION = 1e-3
#: Peak level (dBFS) of the reference strike at a calibrated model's loudest location.
REFERENCE_PEAK_DBFS = -18.0

_CHUNK = 256  # time samples per block of the closed-form evaluation


def _segment(q: np.ndarray, u: np.ndarray) -> np.ndarray:
    """int_0^u e^{-q s} ds = (1 - e^{-q u}) / q, with its limit u for q u -> 0."""
    qu = q * u
    small = np.abs(qu) < 1e-8
    safe = np.where(small, 1.0, q)
    return np.where(small, u * (1 - qu / 2), (1 - np.exp(-qu)) / safe)


def strike_response(
    model: ModalModel,
    frames: int,
    sample_rate: float,
    impulse: float = REFERENCE_IMPULSE,
    duration: float = REFERENCE_DURATION,
) -> np.ndarray:
    """Exact response (P locations x ``frames``, at t = n / sample_rate) of the model's
    unscaled gain rows to a 1 - cos force pulse of ``impulse`` N s over ``duration`` s from
    t = 0: y(t) = sum_k a_k Im(e^{p_k t} C_k(t)), p_k = -d_k + i 2 pi f_k, with
    C_k(t) = int_0^min(t, tau) F(s) e^{-p_k s} ds, constant once the pulse is over."""
    p = -model.decays + 2j * np.pi * model.frequencies
    beta = 2j * np.pi / duration
    gains = model.gains.astype(complex)

    def integral(u):
        pk = p[:, None]
        return (impulse / duration) * (
            _segment(pk, u) - (_segment(pk - beta, u) + _segment(pk + beta, u)) / 2
        )

    t = np.arange(frames) / sample_rate
    out = np.empty((model.n_points, frames))
    during = int(np.count_nonzero(t < duration))
    head = t[None, :during]
    out[:, :during] = (gains @ (np.exp(p[:, None] * head) * integral(head))).imag
    weights = gains * integral(np.array([[duration]]))[:, 0]  # P x K: a_k C_k after the pulse
    step = np.exp(p[:, None] * (np.arange(_CHUNK) / sample_rate))  # K x CHUNK
    for i in range(during, frames, _CHUNK):
        m = min(_CHUNK, frames - i)
        out[:, i : i + m] = ((weights * np.exp(p * t[i])) @ step[:, :m]).imag
    return out


def strike_peaks(model: ModalModel, sample_rate: float) -> np.ndarray:
    """Peak |response| of each location (gain row) to the reference strike, sampled at
    ``sample_rate`` over max(0.1 s, 3 periods of the lowest mode), at most 1 s. Modes at or
    above Nyquist are left out, as a ModalBank leaves them silent."""
    audible = model.frequencies < sample_rate / 2
    if not audible.any():
        return np.zeros(model.n_points)
    model = ModalModel(model.frequencies[audible], model.decays[audible], model.gains[:, audible])
    window = min(1.0, max(0.1, 3.0 / float(model.frequencies.min())))
    return np.abs(strike_response(model, int(window * sample_rate), sample_rate)).max(axis=1)


def reference_gain(model: ModalModel, sample_rate: float) -> float:
    """The gain that makes the reference strike at the loudest location peak at
    REFERENCE_PEAK_DBFS: the model's own ``reference_gain`` if it has one, otherwise
    computed (1 for a model that cannot sound at this rate)."""
    if model.reference_gain is not None:
        return float(model.reference_gain)
    peak = float(strike_peaks(model, sample_rate).max())
    return 10 ** (REFERENCE_PEAK_DBFS / 20) / peak if peak > 0 else 1.0


def calibrated(model: ModalModel, sample_rate: float = 48000.0) -> ModalModel:
    """The model with its reference gain stored (e.g. to ship it in the model file)."""
    gain = reference_gain(ModalModel(model.frequencies, model.decays, model.gains), sample_rate)
    return ModalModel(
        model.frequencies, model.decays, model.gains, model.points, model.name, model.source, gain,
        model.driving,
    )  # fmt: skip


class Drive(NamedTuple):
    """The score event that sets a force source going at its default parameters."""

    action: str
    args: dict


#: Force sources and how level checks set them going: the default parameters are everyday
#: contacts (a 1e-3 N s tap, 0.2 g fragments at 1 m/s, a 0.5 g button dropped 10 cm, an 8 g
#: ball rolled at 0.2 m/s, a 30 g ball hopping over a wooden table's asperities), so through
#: a calibrated bank with unit gains they peak within -30..-6 dBFS (tests/test_source_levels.py,
#: examples/source_levels.py).
FORCE_SOURCES = {
    "ImpactForce": Drive("impact", {}),
    "ImpactTrain": Drive("impact", {}),
    "Crumple": Drive("start", {}),
    "Break": Drive("break", {}),
    "Bounce": Drive("drop", {"height": 0.1}),
    "Scrape": Drive("set", {"speed": 0.2}),
    "Roll": Drive("set", {"speed": 0.2}),
    "RathRoll": Drive("set", {"speed": 0.2}),
}

#: Reference sound pressure of dB SPL (Pa).
P_REF = 20e-6


def spl_db(pressure: float) -> float:
    """Sound pressure level (dB re 20 uPa) of a pressure in Pa (an RMS or a peak value); a
    SoundPressure node's output x is at spl_db(|x|) + full_scale_spl - 93.98 dB."""
    return 20.0 * float(np.log10(pressure / P_REF))


def spl_summary(audio_nodes, peak_dbfs: float) -> str:
    """ " = 97.6 dB SPL at 1 m" when every audio output is a SoundPressure node, all with the
    same full scale and distance (the render's peak read as a sound pressure level), else ""."""
    if not all(node.type_name == "SoundPressure" for node in audio_nodes):
        return ""
    kinds = {(node.values["full_scale_spl"], node.values["distance"]) for node in audio_nodes}
    if len(kinds) != 1:
        return ""
    full_scale, distance = kinds.pop()
    return f" = {peak_dbfs + full_scale:.1f} dB SPL at {distance:g} m"

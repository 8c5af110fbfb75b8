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

from collections.abc import Callable
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
        model.driving, surface=model.surface,
    )  # fmt: skip


class ForceSpectrum(NamedTuple):
    """A steady force: sinusoidal lines plus a broadband part."""

    line_frequencies: np.ndarray  #: Hz
    line_amplitudes: np.ndarray  #: N, the peak of each sinusoid
    density: Callable[[np.ndarray], np.ndarray]  #: one-sided PSD (N^2/Hz) of the rest, at given Hz


#: RMS level (dBFS) at which a calibrated tonal force source, at its reference operating
#: point, rings a calibrated model (mean power over the model's locations): 8 dB under the
#: reference strike's peak, so that the peaks stay within -30..-6 dBFS over TONAL_DRIVES too
#: (ResonantScrape at 0.2 m/s is 7 dB under its 1 m/s reference by its amplitude law).
TONAL_RMS_DBFS = -26.0


def response_power(model: ModalModel, spectrum: ForceSpectrum, sample_rate: float) -> np.ndarray:
    """Mean square (per gain row, in the model's gain units squared; a row per operating point
    if the density gives one) of the model's response to a steady force. Modes at or above
    Nyquist are silent, as in a ModalBank. Lines: the exact sum over modes of a_k H_k(f),
    H_k(f) = w_k / ((d_k + i 2 pi f)^2 + w_k^2) the transfer function of a_k e^{-d_k t}
    sin(w_k t) per N s. Broadband part: each mode passes the density at its own frequency
    over its noise bandwidth, G(f_k) a_k^2 / (8 d_k) x w_k^2 / (w_k^2 + d_k^2) (half of
    int h_k^2 dt; modes much narrower than the band, cross terms of overlapping modes left
    out)."""
    audible = model.frequencies < sample_rate / 2
    f, d, a = model.frequencies[audible], model.decays[audible], model.gains[:, audible]
    w = 2.0 * np.pi * f
    lines = np.asarray(spectrum.line_frequencies, dtype=np.float64)
    s = 2j * np.pi * lines[None, :]
    transfer = w[:, None] / ((d[:, None] + s) ** 2 + (w * w)[:, None])  # K x L
    amplitudes = np.asarray(spectrum.line_amplitudes, dtype=np.float64)
    power = (np.abs(a @ transfer) ** 2 * amplitudes**2 / 2).sum(axis=1)
    noise_bandwidth = w * w / (w * w + d * d) / (8.0 * np.maximum(d, 1e-12))
    return power + (spectrum.density(f) * noise_bandwidth) @ (a * a).T


def _mode_power_integral(omega: np.ndarray, w: np.ndarray, d: np.ndarray) -> np.ndarray:
    """G(W) with dG/dW = |H(W)|^2, H(W) = w / ((d + i W)^2 + w^2) one mode's transfer
    function at angular frequency W: H = (1 / (2 i)) (1 / A - 1 / C), A = d + i (W - w),
    C = d + i (W + w), so |H|^2 = (|1/A|^2 + |1/C|^2 - 2 Re 1 / (A conj(C))) / 4; the last
    term by partial fractions over A + conj(C) = 2 (d - i w), whose logs (Re > 0) are
    ln|.| + i atan(Im / d)."""
    below, above = np.arctan((omega - w) / d), np.arctan((omega + w) / d)
    log_ratio = 0.5 * np.log((d * d + (omega + w) ** 2) / (d * d + (omega - w) ** 2))
    cross = (d * (below + above) - w * log_ratio) / (d * d + w * w)
    return ((below + above) / d - cross) / 4.0


def band_line_power(
    model: ModalModel, edges: np.ndarray, amplitudes: np.ndarray, sample_rate: float
) -> np.ndarray:
    """Mean square (mean over the model's locations) of the response to sinusoids of peak
    ``amplitudes`` (N; L values, or S x L) whose frequencies are each averaged over a band,
    band s of line l spanning edges[s, l]..edges[s + 1, l] Hz (``edges``: S + 1 x L,
    rising): per band, sum over lines A^2 / 2 sum_k a_k^2 <|H_k|^2>, the mean of |H_k|^2 over
    the band in closed form (_mode_power_integral); cross terms of overlapping modes left
    out, as in response_power's broadband part. Modes at or above Nyquist are silent, and so
    is a band of zero width."""
    audible = model.frequencies < sample_rate / 2
    w = 2.0 * np.pi * model.frequencies[audible][:, None]
    d = np.maximum(model.decays[audible], 1e-12)[:, None]
    weight = (model.gains[:, audible] ** 2).mean(axis=0)  # a_k^2, mean over locations
    omega = 2.0 * np.pi * np.asarray(edges, float)
    integral = np.stack([weight @ _mode_power_integral(row[None, :], w, d) for row in omega])  # S + 1 x L
    span = np.diff(omega, axis=0)
    mean = np.divide(np.diff(integral, axis=0), span, out=np.zeros_like(span), where=span > 0)
    return (mean * np.asarray(amplitudes, float) ** 2 / 2.0).sum(axis=-1)


def tonal_level_factor(model: ModalModel, power: np.ndarray, sample_rate: float) -> np.ndarray:
    """The factor on a tonal source's force that makes a calibrated ModalBank of ``model``
    ring at TONAL_RMS_DBFS RMS when the unscaled force's response has mean square ``power``
    (mean over the model's locations, per operating point; 1 where the model cannot hear it)."""
    rms = reference_gain(model, sample_rate) * np.sqrt(power)
    return np.where(rms > 0, 10 ** (TONAL_RMS_DBFS / 20) / np.where(rms > 0, rms, 1.0), 1.0)


def tonal_level_gain(model: ModalModel, spectrum: ForceSpectrum, sample_rate: float) -> np.ndarray:
    """The factor on a tonal source's force that makes a calibrated ModalBank of ``model``
    ring at TONAL_RMS_DBFS RMS (mean power over the model's locations) under ``spectrum``
    (1 where the model cannot hear it). A spectrum whose density gives one row per operating
    point (S x modes) gets S factors."""
    power = response_power(model, spectrum, sample_rate).mean(axis=-1)
    return tonal_level_factor(model, power, sample_rate)


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

#: Force sources whose force is a line spectrum or a narrow band (ResonantScrape's resonance,
#: the drill burr's rotation harmonics): in N their level on a model depends on whether a line
#: meets a mode (at 0.2 m/s and 1 N over the 17 shipped models: -28.5..+6.1 and -35.7..-1.3
#: dBFS), so they are given the model they drive and then (``level = "auto"``, the default)
#: scale their force by its response at their own frequencies (tonal_level_gain, level tables
#: over speed and rpm). Events as FORCE_SOURCES, at the reference operating point:
#: ResonantScrape's reference contact (1 N, 1 m/s), the drill's light cut (1 N, 1 mm^3/s).
MODEL_CALIBRATED_SOURCES = {
    "ResonantScrape": Drive("set", {"speed": 1.0}),
    "DrillSource": Drive("set", {"force": 1.0, "removal": 1.0}),
}


#: Further operating points of the tonal force sources at which their defaults, given the
#: model, stay within -30..-6 dBFS: ResonantScrape at the everyday scraping speed of
#: FORCE_SOURCES (0.2 m/s), the drill's light cut at 10000 and 100000 rpm (its level table).
TONAL_DRIVES = {
    "ResonantScrape": (Drive("set", {"speed": 0.2}),),
    "DrillSource": tuple(Drive("set", {"force": 1.0, "removal": 1.0, "rpm": rpm}) for rpm in (1e4, 1e5)),
}


def driven_source(type_name: str, model: ModalModel, name: str = "src", drive: Drive | None = None):
    """A force source of FORCE_SOURCES or MODEL_CALIBRATED_SOURCES at its defaults (the
    latter given ``model``, so calibrated to it) and the event, at 0.01 s, that sets it going
    (``drive``, default: the source's own)."""
    import ugens  # ugens import jassy
    from jassy import Event

    cls = getattr(ugens, type_name)
    if type_name in MODEL_CALIBRATED_SOURCES:
        drive = drive or MODEL_CALIBRATED_SOURCES[type_name]
        source = cls(model, name=name)
    else:
        drive = drive or FORCE_SOURCES[type_name]
        source = cls(name=name)
    return source, Event(0.01, name, drive.action, drive.args)


#: Sources that own their resonator: ``level = "calibrated"`` scales what they output by the
#: model's reference gain, as a calibrated ModalBank does (the loop stays in N and m).
CALIBRATED_LOOPS = ("Friction", "HuntCrossleyImpact")
#: Signals, not sounds: unit-scale oscillators, noises and envelopes, a mixer, and a sample
#: player that plays its file as it is.
SIGNALS = ("Envelope", "FractalNoise", "Mixer", "Sampler", "Sine", "WhiteNoise")


class SoundLevel(NamedTuple):
    """How a source that sounds by itself (no resonator) sets its level."""

    unit: str  #: "full scale" (1.0 = 105 dB SPL at the listener, as SoundPressure) or "Pa"
    statistic: str  #: "peak" or "rms"
    rule: str  #: the level in terms of the parameters, at a stated operating point
    events: tuple  #: (action, args) pairs, at 0.01 s, that make it sound at its defaults


#: Sources that sound by themselves. Their output is a sound pressure at the listener: in
#: full scale, 1.0 = 105 dB SPL (SoundPressure's default ``full_scale_spl``, so dB SPL =
#: dBFS + 105, the same reading as a heard modal model), or in Pa (Explosion: a blast is far
#: louder than any full scale meant for everyday sounds; feed it to SoundPressure with
#: ``input_kind = "pressure"`` and a raised ``full_scale_spl``). Each has one level parameter
#: defined at an operating point; the rules are tested on rendered output against closed
#: forms (tests/test_sound_source_levels.py, tests/test_gases.py,
#: tests/test_stochastic_models.py, tests/test_friction_engine.py, tests/test_dcmotor.py) and
#: the defaults peak within -30..-6 dBFS (tests/test_source_levels.py).
SOUND_SOURCES = {
    "Bubble": SoundLevel(
        "full scale",
        "peak",
        "one bubble peaks at gain * depth * (radius / 1 mm)^1.5; Pa in water: bubble_gain",
        (("bubble", {}),),
    ),
    "BubbleStream": SoundLevel("full scale", "rms", "bubble_stream_rms (Campbell's theorem)", ()),
    "Wind": SoundLevel("full scale", "rms", "level * (speed / 10 m/s)^3 without gusts", ()),
    "KarmanWhistle": SoundLevel(
        "full scale", "rms", "level * (speed / 10 m/s)^3; with a span: Pa at distance (aeolian_pressure)", ()
    ),
    "CavityTone": SoundLevel(
        "full scale", "rms", "cavity_tone_rms: the jet noise's share at the resonance", ()
    ),
    "Engine": SoundLevel("full scale", "peak", "0.5 * throttle at 3000 rpm without irregularity", ()),
    "DCMotor": SoundLevel(
        "full scale", "peak", "each component's level at 3000 rpm and 1 A (rotor ~ w^2, gears ~ w, ...)", ()
    ),
    "Explosion": SoundLevel(
        "Pa", "peak", "overpressure (Pa at 1 m) / distance, Friedlander wave", (("blast", {}),)
    ),
}


def level_convention(type_name: str) -> str:
    """One line on how a ugen's output level is set (for ``jassy doc``), "" for processors."""
    if type_name in FORCE_SOURCES:
        return (
            "a force in N: through a calibrated ModalBank with unit gain its defaults peak within "
            "-30..-6 dBFS on every shipped model"
        )
    if type_name in MODEL_CALIBRATED_SOURCES:
        return (
            "a force in N with a line or narrow-band spectrum; given the model it drives (level "
            f"'auto', the default): {TONAL_RMS_DBFS:g} dBFS RMS through a calibrated ModalBank at "
            "its reference operating point, at any speed or rpm (a level table)"
        )
    if type_name in CALIBRATED_LOOPS:
        return "level = 'calibrated' scales what it outputs by the model's reference gain (as ModalBank)"
    if type_name in SOUND_SOURCES:
        level = SOUND_SOURCES[type_name]
        scale = "1.0 = 105 dB SPL" if level.unit == "full scale" else "Pa"
        return f"sound pressure at the listener ({scale}), {level.statistic}: {level.rule}"
    if type_name in SIGNALS:
        return "a signal, not a sound: unit scale (Sampler: its file as it is)"
    return ""


#: Density of water (kg/m^3), the medium of bubble_gain.
WATER_DENSITY = 998.0


def bubble_gain(wall_amplitude: float, distance: float, full_scale_spl: float = 105.0) -> float:
    """The Bubble/BubbleStream ``gain`` that makes their output a physical pressure in water:
    a bubble of radius R whose wall oscillates by ``wall_amplitude`` x R (at R = 1 mm and
    depth 1; van den Doel's amplitude law r^1.5 makes it grow as sqrt(R), Longuet-Higgins's
    scaling) radiates as a pulsating sphere, p = rho w0^2 R^3 epsilon / r at ``distance`` r
    (Kinsler et al., *Fundamentals of Acoustics*, 7.4; w0 = 2 pi 3 / R), here in full scale
    (1.0 = ``full_scale_spl`` dB SPL; 93.98 gives Pa). The default gain 0.125 (105 dB full
    scale) is epsilon / r = 1.25e-3 per m: a 1 mm bubble ringing at 0.125 % of its radius,
    1 m away. What is heard in air from bubbles at a surface is weaker (not modelled)."""
    omega = 2.0 * np.pi * 3.0 / 1e-3
    pascal = WATER_DENSITY * omega**2 * 1e-9 * wall_amplitude / distance
    return pascal / (P_REF * 10 ** (full_scale_spl / 20.0))


def bubble_stream_rms(rate, min_radius, max_radius, exponent, min_depth, max_depth, gain, points=4096):
    """RMS of a BubbleStream's output (full scale) at a steady ``rate`` (1/s), by Campbell's
    theorem for a Poisson shot noise: mean square = rate E[int p^2 dt] + (rate E[int p dt])^2.
    A bubble p = a e^{-d t} sin(w0 t) has int p^2 dt = a^2 (1 / (4 d) - d / (4 (d^2 + w0^2)))
    and int p dt = a w0 / (d^2 + w0^2), with van den Doel's a = gain depth (r / 1 mm)^1.5,
    w0 = 2 pi 3 / r, d = 0.13 / r + 0.0072 r^-1.5 (its rising pitch changes only the
    w0-dependent terms, themselves < 0.1 % of the energy); radius r drawn with density
    ~ r^-exponent on [min_radius, max_radius], depth uniform. The stream's voice limit is
    not modelled."""
    from ugens.bubbles import R_REF, bubble_decay, minnaert_frequency  # ugens import jassy

    u = (np.arange(points) + 0.5) / points  # midpoints of the radius CDF
    lo, hi = min(min_radius, max_radius), max(min_radius, max_radius)
    q = 1.0 - exponent
    if hi <= lo:
        r = np.full(points, lo)
    elif abs(q) < 1e-12:
        r = lo * (hi / lo) ** u
    else:
        r = (lo**q + u * (hi**q - lo**q)) ** (1.0 / q)
    d = bubble_decay(r)
    w0 = 2.0 * np.pi * minnaert_frequency(r)
    energy = (r / R_REF) ** 3 * (1.0 / (4.0 * d) - d / (4.0 * (d * d + w0 * w0)))
    area = (r / R_REF) ** 1.5 * w0 / (d * d + w0 * w0)
    depth2 = (min_depth**2 + min_depth * max_depth + max_depth**2) / 3.0
    mean = rate * gain * (min_depth + max_depth) / 2.0 * area.mean()
    return float(np.sqrt(rate * gain**2 * depth2 * energy.mean() + mean**2))


def cavity_tone_rms(level, speed, mouth, resonance, strouhal=0.2, q=1.0):
    """RMS (full scale) of a steady CavityTone without gusts: the jet noise has RMS level (v /
    10 m/s)^3 in a band-pass of quality q at f_j = St v / w; the cavity passes the jet's
    spectral density at its resonance f_H over its own noise bandwidth, and the tone is
    scaled so that a jet centred on f_H keeps its RMS: level (v / 10)^3 |H(f_H)|, |H(f)| =
    1 / sqrt(1 + q^2 (f / f_j - f_j / f)^2) (the second-order band-pass with 0 dB peak; a
    cavity much narrower than the jet band)."""
    f_jet = strouhal * speed / mouth
    ratio = resonance / f_jet
    return level * (speed / 10.0) ** 3 / float(np.sqrt(1.0 + q * q * (ratio - 1.0 / ratio) ** 2))


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

"""``--normalise``: scale a render to a peak level (dBFS) or an integrated loudness (LUFS).

Loudness is ITU-R BS.1770-4 integrated loudness (K-weighting, 400 ms blocks, absolute and
relative gating) measured by pyloudnorm (Steinmetz & Reiss 2021). The render is made without
the final limiter, scaled, then limited: a loudness target can ask for more peak level than full
scale, and the limiter then reports what it cut.
"""

from __future__ import annotations

import math
import os

import numpy as np

from jassy.errors import JassyError
from jassy.safety import CEILING, LimiterMeter, limit, release_coefficient

#: Default targets: -1 dBFS peak; -16 LUFS (a common streaming level).
TARGETS = {"peak": -1.0, "lufs": -16.0}
LIMITER_RELEASE = 0.05  # s, as the offline engine's default


def integrated_loudness(audio: np.ndarray, sample_rate: float) -> float:
    """BS.1770 integrated loudness (LUFS) of (channels, frames) audio; -inf for silence or
    audio shorter than one 400 ms gating block."""
    import pyloudnorm

    if audio.shape[1] < int(0.4 * sample_rate):
        return -math.inf
    with np.errstate(divide="ignore"):
        return float(pyloudnorm.Meter(sample_rate).integrated_loudness(audio.T))


def normalising_gain(audio: np.ndarray, sample_rate: float, mode: str, target: float) -> float:
    """Linear gain that brings ``audio`` to ``target`` (dBFS peak or LUFS)."""
    if mode == "peak":
        peak = float(np.max(np.abs(audio))) if audio.size else 0.0
        if peak == 0.0:
            raise JassyError("--normalise peak: the render is silent")
        return 10 ** (target / 20) / peak
    level = integrated_loudness(audio, sample_rate)
    if not math.isfinite(level):
        raise JassyError("--normalise lufs: the render is silent or shorter than 0.4 s (nothing to measure)")
    return 10 ** ((target - level) / 20)


def render_normalised(engine, path: str | os.PathLike, duration: float, sample_format: str, haptic_path,
                      mode: str, target: float, progress: bool = False) -> dict:  # fmt: skip
    """Render with ``engine`` (made with ``limiter=False``), scale to the target, limit, and
    write the file(s) atomically. Returns the render summary with ``gain_db`` and the level
    reached."""
    from jassy.files import AtomicAudioWriter, write_signal

    rendering = engine.render(duration, progress)
    audio = rendering.audio
    gain = normalising_gain(audio, engine.sample_rate, mode, target)
    audio *= gain
    meter = LimiterMeter(CEILING)
    meter.before(audio)
    limit(
        audio, audio.shape[1], np.ones(1), CEILING, release_coefficient(LIMITER_RELEASE, engine.sample_rate)
    )
    meter.after(audio, audio.shape[1])
    with AtomicAudioWriter(path, int(engine.sample_rate), audio.shape[0], sample_format) as out:
        out.write(audio)
        if haptic_path:
            write_signal(haptic_path, rendering.haptic, engine.sample_rate)
    reached = (
        integrated_loudness(audio, engine.sample_rate)
        if mode == "lufs"
        else 20 * math.log10(float(np.max(np.abs(audio))))
    )
    warning = meter.warning(engine.sample_rate)
    return {
        "frames": audio.shape[1],
        "duration": audio.shape[1] / engine.sample_rate,
        "peak": float(np.max(np.abs(audio))),
        "haptic_peak": float(np.max(np.abs(rendering.haptic))) if rendering.haptic.size else None,
        "warnings": rendering.warnings + ([warning] if warning else []),
        "limiter": meter.report(engine.sample_rate),
        "gain_db": 20 * math.log10(gain),
        "level": reached,
    }

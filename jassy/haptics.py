"""The haptic channel: safety (force clamp, slew-rate limit, stall watchdog) and
per-channel offsets in exact samples. The UDP frames for kinesthetic devices:
:mod:`jassy.engines.hapticframes` (format) and :mod:`jassy.engines.hapticsender` (pacing)."""

from __future__ import annotations

import math
from dataclasses import dataclass

import numba as nb
import numpy as np

from jassy.errors import JassyError


@dataclass(frozen=True)
class HapticSafety:
    """Limits applied to every haptic sample before it reaches a device or file.

    max_force: |force| clamp (N); max_slew: rate limit (N/s); watchdog: seconds within
    which force fades to zero when the producer stalls (at most 0.01 s).
    """

    max_force: float = math.inf
    max_slew: float = math.inf
    watchdog: float = 0.01

    def __post_init__(self):
        if not self.max_force > 0:
            raise JassyError(f"--max-force: expected newtons > 0, got {self.max_force}")
        if not self.max_slew > 0:
            raise JassyError(f"--max-slew: expected N/s > 0, got {self.max_slew}")
        if not 0 < self.watchdog <= 0.01:
            raise JassyError(f"watchdog: expected seconds in (0, 0.01], got {self.watchdog}")

    def step(self, sample_rate: float) -> float:
        """Largest change per sample (N)."""
        return self.max_slew / sample_rate


@nb.njit(cache=True, inline="always")  # inlined, as jassy.safety.copy_finite
def limit_force(buf, n, last, max_force, max_step):
    """Clamp |force| and its change per sample, channel by channel, in place.

    buf: (channels, frames); last: previous output per channel (updated). Non-finite
    samples count as 0. Returns flags (FLAG_CLAMPED | FLAG_SLEW) of what was limited.
    """
    flags = 0
    for c in range(buf.shape[0]):
        y = last[c]
        for i in range(n):
            x = buf[c, i]
            if not math.isfinite(x):
                x = 0.0
            if x > max_force:
                x = max_force
                flags |= 2
            elif x < -max_force:
                x = -max_force
                flags |= 2
            d = x - y
            if d > max_step:
                x = y + max_step
                flags |= 4
            elif d < -max_step:
                x = y - max_step
                flags |= 4
            y = x
            buf[c, i] = y
        last[c] = y
    return flags


def channel_delays(
    offsets_ms: dict[str, float], n_audio: int, n_haptic: int, sample_rate: float
) -> np.ndarray:
    """Per output channel delay (frames) from offsets in ms for "audio" and "haptic".

    Positive offset = later. Offsets are applied exactly in samples (rounded to the
    nearest sample); both kinds are shifted so the earliest has zero delay, e.g.
    {"haptic": 2.0} at 48 kHz delays the haptic channels by 96 samples.
    """
    for key in offsets_ms:
        if key not in ("audio", "haptic"):
            raise JassyError(f"offsets: unknown channel kind {key!r}; expected audio or haptic")
    a = offsets_ms.get("audio", 0.0)
    h = offsets_ms.get("haptic", 0.0)
    base = min(a, h)
    da = int(round((a - base) * sample_rate / 1000.0))
    dh = int(round((h - base) * sample_rate / 1000.0))
    return np.array([da] * n_audio + [dh] * n_haptic, dtype=np.int64)


@nb.njit(cache=True, inline="always")  # inlined, as jassy.safety.copy_finite
def delay_channels(buf, n, history, delays, pos):
    """Delay each channel of buf[:, :n] by delays[c] frames in place.

    history: (channels, H) ring of past input, H > max delay; pos: [write index]."""
    H = history.shape[1]
    p = pos[0]
    for i in range(n):
        for c in range(buf.shape[0]):
            history[c, (p + i) % H] = buf[c, i]
            buf[c, i] = history[c, (p + i - delays[c]) % H]
    pos[0] = (p + n) % H


class ChannelDelay:
    """Stateful per-channel delay line (see :func:`delay_channels`)."""

    def __init__(self, delays: np.ndarray):
        self.delays = np.asarray(delays, dtype=np.int64)
        self.history = np.zeros((self.delays.size, int(self.delays.max(initial=0)) + 1))
        self.pos = np.zeros(1, dtype=np.int64)
        self.active = bool(np.any(self.delays))

    def __call__(self, buf: np.ndarray, n: int) -> None:
        if self.active:
            delay_channels(buf, n, self.history, self.delays, self.pos)

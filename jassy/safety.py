"""Output safety: non-finite sample removal and the final brick-wall limiter."""

from __future__ import annotations

import math

import numba as nb
import numpy as np

#: Default ceiling of the final limiter: -0.1 dBFS.
CEILING = 10 ** (-0.1 / 20)


@nb.njit(cache=True)
def scan_chunk(audio, haptic):
    """One read pass over an output chunk: (number of NaN/Inf samples in both 2-D buffers,
    largest |finite audio sample|)."""
    bad = 0
    peak = 0.0
    for c in range(audio.shape[0]):
        for i in range(audio.shape[1]):
            x = audio[c, i]
            if not math.isfinite(x):
                bad += 1
            elif abs(x) > peak:
                peak = abs(x)
    for c in range(haptic.shape[0]):
        for i in range(haptic.shape[1]):
            if not math.isfinite(haptic[c, i]):
                bad += 1
    return bad, peak


@nb.njit(cache=True)
def peak_abs(buf):
    """Largest |sample| of a finite 2-D buffer, without a temporary array."""
    peak = 0.0
    for c in range(buf.shape[0]):
        for i in range(buf.shape[1]):
            a = abs(buf[c, i])
            if a > peak:
                peak = a
    return peak


@nb.njit(cache=True)
def zero_nonfinite(buf):
    """Replace NaN/Inf samples of a 2-D buffer by 0 in place."""
    for c in range(buf.shape[0]):
        for i in range(buf.shape[1]):
            if not math.isfinite(buf[c, i]):
                buf[c, i] = 0.0


@nb.njit(cache=True)
def limit(buf, n, state, ceiling, release_coeff):
    """Linked brick-wall limiter over buf[:, :n] in place.

    Gain drops at once to ceiling/|x| when a sample would exceed the ceiling (no lookahead,
    so no delay) and recovers towards 1 with a one-pole of coefficient ``release_coeff``.
    Non-finite samples become 0. state = [gain]. |output| <= ceiling always holds.
    While the gain is exactly 1 (fully released: 1 - 0 * release stays 1) and samples are
    finite and within the ceiling, they pass unchanged, so those are only read.
    """
    g = state[0]
    channels = buf.shape[0]
    start = 0
    if g == 1.0:
        while start < n:
            inside = True
            for c in range(channels):
                x = buf[c, start]
                if not (abs(x) <= ceiling):  # also NaN
                    inside = False
            if not inside:
                break
            start += 1
    for i in range(start, n):
        peak = 0.0
        for c in range(channels):
            x = buf[c, i]
            if not math.isfinite(x):
                buf[c, i] = 0.0
                x = 0.0
            a = abs(x)
            if a > peak:
                peak = a
        g = 1.0 - (1.0 - g) * release_coeff
        if peak * g > ceiling:
            g = ceiling / peak
        for c in range(channels):
            y = buf[c, i] * g
            # guard against rounding of x * (ceiling / x) just above the ceiling
            if y > ceiling:
                y = ceiling
            elif y < -ceiling:
                y = -ceiling
            buf[c, i] = y
    state[0] = g


@nb.njit(cache=True)
def pinned_samples(buf, n, ceiling, run):
    """Frames of buf[:, :n] where some channel sits at the limiter's ceiling (within 1e-9):
    (count, longest run, run still open at the end), runs carried over from ``run`` frames."""
    count = 0
    longest = run
    threshold = ceiling * (1.0 - 1e-9)
    for i in range(n):
        pinned = False
        for c in range(buf.shape[0]):
            if abs(buf[c, i]) >= threshold:
                pinned = True
        if pinned:
            count += 1
            run += 1
            longest = max(longest, run)
        else:
            run = 0
    return count, longest, run


class LimiterMeter:
    """What the final limiter did over a render: frames held at the ceiling, the longest run
    of them (frames) and the largest input peak (linear, before limiting)."""

    def __init__(self, ceiling: float = CEILING):
        self.ceiling = ceiling
        self.pinned = 0
        self.longest = 0
        self._run = 0
        self.input_peak = 0.0
        self.frames = 0

    def before(self, buf: np.ndarray) -> None:
        """Record the peak of a chunk about to be limited (finite samples)."""
        if buf.size:
            self.input_peak = max(self.input_peak, peak_abs(buf))

    def after(self, buf: np.ndarray, n: int) -> None:
        """Count the frames of a limited chunk held at the ceiling."""
        count, longest, self._run = pinned_samples(buf, n, self.ceiling, self._run)
        self.longest = max(self.longest, longest)
        self.pinned += count
        self.frames += n

    def limit(self, buf: np.ndarray, n: int, state: np.ndarray, release_coeff: float, peak: float) -> None:
        """Limit buf[:, :n] in place (see :func:`limit`) and meter it, given its finite input
        peak. A fully released limiter (gain exactly 1) passes a chunk whose peak is below
        the pinned threshold unchanged, so such a chunk is not read again."""
        self.input_peak = max(self.input_peak, peak)
        if state[0] == 1.0 and peak < self.ceiling * (1.0 - 1e-9):
            self._run = 0
            self.frames += n
            return
        limit(buf, n, state, self.ceiling, release_coeff)
        self.after(buf, n)

    @property
    def reduction_db(self) -> float:
        """Peak gain reduction in dB (0 when the input never exceeded the ceiling)."""
        return max(0.0, 20 * math.log10(self.input_peak / self.ceiling)) if self.input_peak > 0 else 0.0

    def report(self, sample_rate: float) -> dict:
        return {
            "pinned_frames": self.pinned,
            "longest_pinned_s": self.longest / sample_rate,
            "peak_reduction_db": self.reduction_db,
        }

    def warning(self, sample_rate: float) -> str | None:
        """A warning when the limiter cut peaks, else None."""
        if self.reduction_db <= 0.0:
            return None
        share = 100.0 * self.pinned / max(self.frames, 1)
        longest_ms = 1e3 * self.longest / sample_rate
        return (
            f"limiter: peaks reduced by {self.reduction_db:.1f} dB; {self.pinned} frames ({share:.2f} %) "
            f"held at the ceiling, the longest run {longest_ms:.1f} ms; lower a gain or use --normalise"
        )


def release_coefficient(release: float, sample_rate: float) -> float:
    """One-pole coefficient for a release time constant ``release`` (s)."""
    return float(np.exp(-1.0 / (release * sample_rate))) if release > 0 else 0.0

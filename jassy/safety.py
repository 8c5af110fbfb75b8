"""Output safety: non-finite sample removal and the final brick-wall limiter."""

from __future__ import annotations

import math

import numba as nb
import numpy as np

#: Default ceiling of the final limiter: -0.1 dBFS.
CEILING = 10 ** (-0.1 / 20)


@nb.njit(cache=True)
def count_nonfinite(buf):
    """Number of NaN/Inf samples in a 2-D buffer."""
    count = 0
    for c in range(buf.shape[0]):
        for i in range(buf.shape[1]):
            if not math.isfinite(buf[c, i]):
                count += 1
    return count


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
    """
    g = state[0]
    channels = buf.shape[0]
    for i in range(n):
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


def release_coefficient(release: float, sample_rate: float) -> float:
    """One-pole coefficient for a release time constant ``release`` (s)."""
    return float(np.exp(-1.0 / (release * sample_rate))) if release > 0 else 0.0

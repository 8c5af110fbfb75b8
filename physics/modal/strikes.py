"""Strikes in a recording: onsets of the hits and the clipped samples to leave out."""

from __future__ import annotations

from typing import NamedTuple

import numpy as np


class Hit(NamedTuple):
    """One strike: samples [onset, end) of the recording; ``first`` = the first sample after
    the onset that the fit uses (after the clipped samples and the contact)."""

    onset: int
    first: int
    end: int


def clipped_samples(x: np.ndarray, min_run: int = 2) -> np.ndarray:
    """Indices of clipped samples of one channel: those within 0.01 % of the channel's peak
    magnitude when at least one run of ``min_run`` consecutive such samples exists (a signal
    that is not clipped reaches its peak once)."""
    peak = float(np.max(np.abs(x))) if x.size else 0.0
    if peak == 0:
        return np.zeros(0, dtype=np.int64)
    at = np.abs(x) >= peak * (1 - 1e-4)
    runs = at[1:] & at[:-1]
    if not runs.any():
        return np.zeros(0, dtype=np.int64)
    return np.flatnonzero(at)


def _frame_peaks(x: np.ndarray, hop: int) -> np.ndarray:
    n_frames = x.size // hop
    return np.abs(x[: n_frames * hop]).reshape(n_frames, hop).max(axis=1)


def _rising(env: np.ndarray, rise_db: float, floor_db: float, look: int = 10) -> np.ndarray:
    """Frames whose peak exceeds every one of the ``look`` frames before the previous one by
    ``rise_db`` (an onset late in a frame rises over two frames) and lies within ``floor_db``
    of the loudest frame."""
    peak = float(env.max())
    if peak == 0:
        return np.zeros(env.size, dtype=bool)
    pad = np.concatenate([np.full(look + 1, np.median(env[:look])), env])
    before = np.lib.stride_tricks.sliding_window_view(pad[:-2], look)[: env.size].max(axis=1)
    return (env > before * 10 ** (rise_db / 20)) & (env >= peak * 10 ** (-floor_db / 20))


def prediction_error(x: np.ndarray, order: int = 32) -> np.ndarray:
    """The residual of an order-``order`` linear predictor fitted to the whole signal
    (autocorrelation method): ringing modes are predicted from their past and vanish from
    it, a new strike is not (Makhoul 1975, "Linear prediction: a tutorial review")."""
    from scipy.linalg import solve_toeplitz

    n_fft = 1 << int(np.ceil(np.log2(2 * x.size)))
    r = np.fft.irfft(np.abs(np.fft.rfft(x, n_fft)) ** 2, n_fft)[: order + 1]
    if not r[0] > 0:
        return np.zeros_like(x)
    r[0] *= 1 + 1e-9  # white-noise correction keeps the Toeplitz system definite
    a = solve_toeplitz(r[:order], r[1 : order + 1])
    return x - np.convolve(x, np.concatenate([[0.0], a]))[: x.size]


def detect_onsets(x: np.ndarray, rate: float, rise_db: float = 12.0, floor_db: float = 40.0,
                  min_gap: float = 0.05) -> list[int]:  # fmt: skip
    """Sample indices of the strikes in a mono signal: 1 ms frames whose peak magnitude rises
    ``rise_db`` above every frame of the previous 10 ms, at most ``floor_db`` below the
    loudest frame, at least ``min_gap`` s apart. Two envelopes are searched: of the signal
    (low modes starting from silence) and of its linear-prediction error (a new strike stands
    out over modes still ringing from earlier strikes). The onset is
    the first sample of that frame (or the frame before) above a quarter of the frame's peak."""
    hop = max(int(rate / 1000), 1)
    if x.size // hop < 2:
        return []
    candidates = set()
    # the prediction error is white where nothing new happens, so a smaller rise stands out
    for sig, rise in ((x, rise_db), (prediction_error(x), rise_db - 3.0)):
        env = _frame_peaks(sig, hop)
        for f in np.flatnonzero(_rising(env, rise, floor_db)):
            lo = max(f - 1, 0) * hop
            seg = np.abs(sig[lo : (f + 1) * hop])
            candidates.add(lo + int(np.argmax(seg >= 0.25 * env[f])))
    onsets: list[int] = []
    for n0 in sorted(candidates):
        if onsets and n0 - onsets[-1] < min_gap * rate:
            continue
        onsets.append(n0)
    if not onsets and np.any(x != 0):  # a recording that starts with the strike
        peak = float(np.max(np.abs(x)))
        onsets.append(int(np.argmax(np.abs(x) >= 10 ** (-floor_db / 20) * peak)))
    return onsets


def hits_of(onsets: list[int], n: int, clipped: np.ndarray, rate: float, skip: float) -> list[Hit]:
    """Hits from onsets: each lasts until the next onset; its fit starts ``skip`` s after the
    onset and after the hit's last clipped sample (the poles are estimated from unclipped
    samples only)."""
    hits = []
    for i, n0 in enumerate(onsets):
        end = onsets[i + 1] if i + 1 < len(onsets) else n0 + (n - n0)
        end = min(end, n)
        first = n0 + int(round(skip * rate))
        near = clipped[(clipped >= n0) & (clipped < end)]
        if near.size:
            first = max(first, int(near[-1]) + 1)
        hits.append(Hit(n0, min(first, end), end))
    return hits

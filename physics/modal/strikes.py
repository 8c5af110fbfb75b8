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


def detect_onsets(x: np.ndarray, rate: float, rise_db: float = 12.0, floor_db: float = 40.0,
                  min_gap: float = 0.05) -> list[int]:  # fmt: skip
    """Sample indices of the strikes in a mono signal: 1 ms frames whose peak magnitude of the
    sample-to-sample difference (which weights the broadband attack over the low modes still
    ringing from earlier strikes) rises ``rise_db`` above every frame of the previous 10 ms,
    at most ``floor_db`` below its peak, at least ``min_gap`` s apart. The onset is the first
    sample of that frame (or the frame before) above a quarter of the frame's peak."""
    x = np.concatenate([[0.0], np.diff(x)])
    hop = max(int(rate / 1000), 1)
    n_frames = x.size // hop
    if n_frames < 2:
        return []
    env = np.abs(x[: n_frames * hop]).reshape(n_frames, hop).max(axis=1)
    peak = float(env.max())
    if peak == 0:
        return []
    look = 10
    pad = np.concatenate([np.full(look, np.median(env[:look])), env])
    windows = np.lib.stride_tricks.sliding_window_view(pad[:-1], look)[:n_frames]
    before = windows.max(axis=1)
    rising = (env > before * 10 ** (rise_db / 20)) & (env >= peak * 10 ** (-floor_db / 20))
    onsets: list[int] = []
    for f in np.flatnonzero(rising):
        lo = max(f - 1, 0) * hop
        seg = np.abs(x[lo : (f + 1) * hop])
        n0 = lo + int(np.argmax(seg >= 0.25 * env[f]))
        if onsets and n0 - onsets[-1] < min_gap * rate:
            continue
        onsets.append(n0)
    if not onsets:  # a recording that starts with the strike
        onsets.append(int(np.argmax(np.abs(x) >= 10 ** (-floor_db / 20) * peak)))
    return onsets


def hits_of(onsets: list[int], n: int, clipped: np.ndarray, rate: float, skip: float) -> list[Hit]:
    """Hits from onsets: each lasts until the next onset; its fit starts ``skip`` s after the
    onset and after the last clipped sample within the first 50 ms of the hit."""
    hits = []
    for i, n0 in enumerate(onsets):
        end = onsets[i + 1] if i + 1 < len(onsets) else n0 + (n - n0)
        end = min(end, n)
        first = n0 + int(round(skip * rate))
        near = clipped[(clipped >= n0) & (clipped < min(end, n0 + int(0.05 * rate)))]
        if near.size:
            first = max(first, int(near[-1]) + 1)
        hits.append(Hit(n0, min(first, end), end))
    return hits

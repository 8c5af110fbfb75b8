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


def band_rise(x: np.ndarray, hop: int, width: int, n_bands: int = 32, look: int = 10) -> np.ndarray:
    """Per frame (frame t ends at sample t ``hop``): the mean over ``n_bands`` equal
    frequency bands of the rise of the band's log energy over the largest of the ``look``
    frames before it that do not overlap it (0 where it falls) - a band-wise spectral flux
    (Bello et al. 2005, "A tutorial on onset detection in music signals"). A strike raises
    every band at once; noise and ringing modes raise few, so the mean stands out even where
    the level rises by a few dB only."""
    from scipy.ndimage import maximum_filter1d

    padded = np.concatenate([np.zeros(width), x])
    frames = np.lib.stride_tricks.sliding_window_view(padded, width)[::hop] * np.hanning(width)
    power = np.abs(np.fft.rfft(frames, axis=1)) ** 2
    edges = np.linspace(1, power.shape[1], n_bands + 1).astype(int)[:-1]
    power = np.add.reduceat(power, edges, axis=1)
    # bands 100 dB below the loudest are silent: their round-off does not rise
    level = np.log(power + 1e-10 * max(float(power.max()), 1e-300))
    latest = maximum_filter1d(level, size=look, axis=0, origin=(look - 1) // 2)  # max of t-look+1 .. t
    shift = width // hop
    before = np.full_like(level, np.inf)
    before[shift + look :] = latest[look - 1 : level.shape[0] - shift - 1]
    return np.clip(level - before, 0, None).mean(axis=1)


def change_point(e: np.ndarray, guard: int = 8) -> int:
    """The index n that best splits ``e`` into two parts of constant variance, the second
    louder: the maximum-likelihood change point, min n log var(e[:n]) + (N - n) log var(e[n:])
    (Hinkley 1970, "Inference about the change-point in a sequence of random variables")."""
    power = np.cumsum(e**2)
    n = np.arange(guard, e.size - guard)
    if n.size == 0:
        return 0
    v1 = power[n - 1] / n
    v2 = (power[-1] - power[n - 1]) / (e.size - n)
    cost = n * np.log(v1 + 1e-300) + (e.size - n) * np.log(v2 + 1e-300)
    cost[v2 <= v1] = np.inf
    return int(n[np.argmin(cost)]) if np.isfinite(cost).any() else 0


def detect_onsets(x: np.ndarray, rate: float, threshold: float = 11.0, min_rise: float = 0.25,
                  floor_db: float = 40.0, min_gap: float = 0.05) -> list[int]:  # fmt: skip
    """Sample indices of the strikes in a mono signal. Found by the band-wise rise of the
    spectrum (:func:`band_rise`, 1 ms hops, ~10 ms frames): peaks more than ``threshold``
    median absolute deviations above its median and above ``min_rise`` (a mean rise of 1.1
    dB: a recording without noise has no spread) whose frame peaks at most ``floor_db`` below
    the loudest, at least ``min_gap`` s apart (the larger rise kept). Each is placed to the
    sample by the change point of the variance (:func:`change_point`) of the linear-
    prediction error (:func:`prediction_error`: a new strike stands out of modes still
    ringing) around the frame."""
    hop = max(int(rate / 1000), 1)
    width = 1 << int(np.ceil(np.log2(8 * hop)))
    chosen = (
        _rising_frames(x, hop, width, threshold, min_rise, floor_db, min_gap * rate)
        if x.size >= 4 * width
        else []
    )
    error = prediction_error(x) if chosen else x
    onsets = []
    for t in chosen:
        lo, hi = max(t * hop - width - 5 * hop, 0), min(t * hop + 2 * hop, x.size)
        onsets.append(lo + change_point(error[lo:hi]))
    if not onsets and np.any(x != 0):  # a recording that starts with the strike
        peak_level = float(np.max(np.abs(x)))
        onsets.append(int(np.argmax(np.abs(x) >= 10 ** (-floor_db / 20) * peak_level)))
    return onsets


def _rising_frames(x, hop, width, threshold, min_rise, floor_db, min_gap) -> list[int]:
    """Frames (ending at sample t ``hop``) where :func:`band_rise` peaks above the
    threshold of :func:`detect_onsets`, at least ``min_gap`` samples apart."""
    score = band_rise(x, hop, width)
    median = float(np.median(score))
    spread = float(np.median(np.abs(score - median))) + 1e-12
    loud = _frame_peaks(np.concatenate([np.zeros(width), x]), hop)
    loud_enough = np.zeros(score.size, dtype=bool)
    # the frame of samples [t hop - width, t hop) counts when its loudest 1 ms is within floor_db
    frames_loud = np.lib.stride_tricks.sliding_window_view(loud, width // hop).max(axis=1)
    m = min(score.size, frames_loud.size)
    loud_enough[:m] = frames_loud[:m] >= loud.max() * 10 ** (-floor_db / 20)
    peak = (score > max(median + threshold * spread, min_rise)) & loud_enough
    peak &= score >= np.concatenate([[0.0], score[:-1]])
    peak &= score >= np.concatenate([score[1:], [0.0]])
    chosen: list[tuple[int, float]] = []
    for t in np.flatnonzero(peak):
        if chosen and (t - chosen[-1][0]) * hop < min_gap:
            if score[t] > chosen[-1][1]:
                chosen[-1] = (int(t), float(score[t]))
            continue
        chosen.append((int(t), float(score[t])))
    return [t for t, _ in chosen]


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

"""Modal models (frequencies, decay rates, gains) fitted to recordings of struck objects
(``jassy fit``).

Why subspace estimation: a spectral peak picker needs each mode to stand out of the
spectrum, which a fast-decaying (broad) mode or a mode inside a dense cluster does not;
ESPRIT counts modes by the eigenvalues of the signal's Hankel Gram matrix above the noise,
resolves poles closer than a bin, and estimates decay and frequency together. Running it in
decimated sub-bands keeps each eigenproblem small (Laroche 1993; Badeau, David & Richard 2006).

Method: pooled subspace estimation (ESPRIT, :mod:`physics.modal.esprit`) at five time-
frequency resolutions (zoom bands of 50 Hz below 2 kHz for d <= 10 /s besides those below),
each on what the previous ones left:

1. **Strikes.** Onsets are detected (:mod:`physics.modal.strikes`); each hit lasts until the
   next one. Clipped samples are left out of every least-squares fit, and each hit's
   analysis starts after its last clipped sample.
2. **Narrow bands** (200 Hz apart, 400 Hz wide, decimated to 1 kHz, the whole hit): slowly
   decaying modes (d <= 40 /s), closely spaced pairs. Every hit and channel adds its Hankel
   rows to one Gram matrix per band, so poles are pooled over all of them.
3. **Medium bands** (200 Hz apart, tapers to 400 Hz, the first 0.5 s): modes of 8-100 /s
   that a narrow band misses - its filter transient (40 ms, cut away) holds most of a
   20 /s mode's energy and its whole-hit window adds the noise of seconds after the mode
   has decayed, so a weak mode 10-20 Hz from a stronger one stayed under the noise edge
   and the stronger one's decay and gain absorbed it (``jassy bench fit``).
4. **Wide bands** (2 kHz apart, the first 0.3 s of the hit minus the modes found so far):
   modes of 20-800 /s, which are too broad and too short for a narrow band's filter.
5. **Full rate** (the first 40 ms, minus everything found so far): modes up to 3000 /s
   (wood, small objects, high frequencies), with no band filter in the way. Faster
   "modes" (T60 < 2.3 ms) are the contact itself: a noise burst fits as dozens of them,
   so they are left to the attack; each remaining pole must stand out of the larger of
   the noise and what the poles leave under its own envelope (:func:`_local_noise`).
   Limit: the burst stays in that residual, so the test does not separate a contact from
   broad modes in general (a 2 ms noise burst beside one slow mode still gives a few
   spurious 700-1200 /s modes). A new pole here is the leftover of one found earlier
   only within the window's resolution (25 Hz) or the narrower one's half-width
   (:func:`_duplicate`), so a broad mode is kept beside slow poles 60-150 Hz away.
6. **Joint refinement** of every pole by maximum likelihood on whole segments, pooled over
   all hits and channels (:mod:`physics.modal.varpro`: variable projection on the DFT bins
   around each group of overlapping poles, the other poles subtracted; a pole the
   refinement moved onto another goes back, :func:`_distinct`), then the stages
   again on what the refined poles leave (a weak mode on a strong one's skirt, a cluster's
   missed member), and the joint refinement again with what they found (up to
   ``EXTRA_PASSES`` such rounds).
7. **Amplitudes.** With the poles fixed, complex amplitudes of every hit and channel by
   linear least squares at the full rate (closed-form Gram matrix), minus what the previous
   hits still ring; gain = |amplitude| at the onset.

A band's model order is the number of Gram eigenvalues above the noise (the Marchenko-Pastur
edge of the noise level measured in the spectrum), so a mode needs no spectral peak above a
running median to be found: a broad fast mode and a mode in a dense cluster count alike.

Gains are in the recording's units per unit impulse (the model struck with 1 N s at the
recorded point reproduces the recording). The model keeps magnitudes only; the phases of a
real strike (contact duration, propagation) are reported. The **attack** - the first hit's
residual (recording minus modal resynthesis) over its first milliseconds, the contact and the
unresolved high modes - is kept in the model (``ModalModel.attack``) and played with every
strike (van den Doel, Kry & Pai 2001, "FoleyAutomatic", use the same residual excitation).
"""

from __future__ import annotations

import math
import os
import sys
import time
import warnings
from dataclasses import dataclass, field
from typing import NamedTuple

import numpy as np

from jassy.errors import JassyError
from jassy.modal_model import ModalModel
from physics.modal import esprit, varpro
from physics.modal.strikes import Hit, clipped_samples, detect_onsets, hits_of


class Stage(NamedTuple):
    """One resolution of the pole search: bands ``spacing`` Hz apart with a flat part of
    ``spacing`` Hz and tapers to ``edge`` Hz from the centre (0 = full rate, no bands),
    analysing at most ``seconds`` of each hit; poles with decay in (d_min, d_max] 1/s and
    bands below ``f_max`` Hz kept."""

    name: str
    spacing: float
    edge: float
    seconds: float
    d_min: float
    d_max: float
    f_max: float = math.inf


#: Fastest home stage (its d_max, 1/s) whose poles the joint refinement refines.
POLISH_MAX_DECAY = 40.0

#: Least energy of a mode relative to the noise variance per sample (matched filter SNR, 13 dB:
#: the best damped sinusoid fitted to white noise somewhere in 20 kHz x 1 s reaches ~10 dB).
MIN_SNR = 20.0

#: Rounds of (the stages on what the refined poles leave, the joint refinement) after the
#: first; a round that finds no new pole ends them (``jassy bench fit``: the second round
#: +1.6 % of decays within 5 %, +0.4 % of gains within 1 dB, about +20 % CPU).
EXTRA_PASSES = 2

#: Sweeps of the spectral refinement per round (each from the previous sweep's residual).
SWEEPS = 2

STAGES = (
    Stage("zoom bands", 50.0, 50.0, 6.0, 0.0, 10.0, 2000.0),
    Stage("narrow bands", 200.0, 200.0, 6.0, 0.0, 40.0),
    Stage("medium bands", 200.0, 400.0, 0.5, 8.0, 100.0),
    Stage("wide bands", 2000.0, 1500.0, 0.3, 20.0, 800.0),
    Stage("full rate", 0.0, 0.0, 0.04, 200.0, 3000.0),
)


class Segment(NamedTuple):
    """The samples of one hit in one channel (from ``hit.first``), with what the fit needs."""

    recording: int
    channel: int
    hit: Hit
    x: np.ndarray
    excluded: np.ndarray  # clipped sample indices relative to x
    noise: np.ndarray  # noise |X_k|^2 level per bin of the segment's FFT (length n_fft // 2 + 1)
    n_fft: int


@dataclass
class FitResult:
    """A fitted model plus diagnostics (times in s from the start of each recording)."""

    model: ModalModel
    sample_rate: float
    onsets: list[list[float]]
    residual_db: list[float]
    phases: np.ndarray  # per hit and channel: phi_k of a_k e^{-d_k t} sin(2 pi f_k t + phi_k) (rad)
    levels_db: np.ndarray
    noise_db: float
    notes: list[str] = field(default_factory=list)

    @property
    def attack(self) -> np.ndarray:
        """The stored attack (``ModalModel.attack``; empty if none)."""
        return np.zeros(0) if self.model.attack is None else self.model.attack

    @property
    def onset(self) -> float:
        """The first strike of the first recording (s)."""
        return self.onsets[0][0]

    def report(self) -> str:
        m = self.model
        hits = sum(len(o) for o in self.onsets)
        lines = [
            f"fitted {m.n_modes} modes from {hits} strike(s) in {len(self.onsets)} recording(s) at "
            f"{self.sample_rate:g} Hz; {m.n_points} gain row(s)"
            + (f"; attack {self.attack.size / self.sample_rate * 1e3:.1f} ms" if self.attack.size else ""),
            "onsets (s): " + "; ".join(", ".join(f"{t:.3f}" for t in o) for o in self.onsets),
            "residual (recording - resynthesis, energy per hit and channel): "
            + ", ".join(f"{r:.1f} dB" for r in self.residual_db),
            f"{'#':>3} {'f (Hz)':>10} {'d (1/s)':>9} {'T60 (s)':>8} {'level dB':>8}  gains",
        ]
        for k in range(m.n_modes):
            t60 = math.log(1000) / m.decays[k] if m.decays[k] > 0 else float("inf")
            g = " ".join(f"{v:.4g}" for v in m.gains[:, k][:8]) + (" ..." if m.n_points > 8 else "")
            f, d, lv = m.frequencies[k], m.decays[k], self.levels_db[k]
            lines.append(f"{k:>3} {f:>10.2f} {d:>9.3f} {t60:>8.3f} {lv:>8.1f}  {g}")
        lines.extend(self.notes)
        return "\n".join(lines)


# ----------------------------------------------------------------------------- noise


def noise_floor(
    x: np.ndarray, rate: float, n_fft: int, span: float = 1000.0, q_time: float = 0.2, q_freq: float = 0.2
) -> np.ndarray:
    """Noise level |X_k|^2 of every bin of the length-``n_fft`` FFT of ``x`` (white noise of
    variance s^2 gives s^2 len(x)), by minimum statistics (Martin 2001, "Noise power spectral
    density estimation based on optimal smoothing and minimum statistics"): frames under a
    4-term Blackman-Harris window (sidelobes -92 dB, so a loud mode's skirt stays within a
    few bins), the ``q_time`` quantile over time of each bin (decaying modes leave the later
    frames), then the ``q_freq`` quantile over the bins within +-``span`` Hz (the window
    shrinks at 0 Hz and Nyquist; a low quantile, because below a few hundred Hz slow modes
    that never leave the frames can fill most bins), divided by the value those two
    quantiles take for white noise of unit level: the j-th smallest of k exponentials has
    F = Beta(j, k + 1 - j) (David & Nagaraja 2003, "Order statistics")."""
    from scipy.signal.windows import blackmanharris
    from scipy.special import betaincinv

    width = int(np.clip(1 << int(math.log2(max(x.size // 8, 1))), 64, 2048))
    if x.size < width:
        width = 1 << int(math.log2(max(x.size, 2)))
    window = blackmanharris(width, sym=False)
    frames = np.lib.stride_tricks.sliding_window_view(x, width)[:: width // 2] * window
    power = np.abs(np.fft.rfft(frames, axis=1)) ** 2 / np.sum(window**2)
    k = power.shape[0]
    j = max(int(round(q_time * k)), 1)
    level = np.partition(power, j - 1, axis=0)[j - 1]
    bin_hz = rate / width
    half = max(int(span / bin_hz), 1)
    padded = np.concatenate([np.full(half, np.inf), level, np.full(half, np.inf)])
    near = np.sort(np.lib.stride_tricks.sliding_window_view(padded, 2 * half + 1), axis=1)
    i = np.arange(level.size)
    count = np.minimum(i + half, level.size - 1) - np.maximum(i - half, 0) + 1
    level = near[i, (q_freq * (count - 1)).astype(int)]
    level = level / -math.log1p(-betaincinv(j, k + 1 - j, q_freq))
    freqs = np.arange(n_fft // 2 + 1) * rate / n_fft
    return np.interp(freqs, np.arange(level.size) * bin_hz, level) * x.size


# ----------------------------------------------------------------------------- poles


class Pole(NamedTuple):
    frequency: float  # Hz
    decay: float  # 1/s


def _z(poles: list[Pole], rate: float) -> np.ndarray:
    f = np.array([p.frequency for p in poles])
    d = np.array([p.decay for p in poles])
    return np.exp((-d + 2j * np.pi * f) / rate)


def _duplicate(p: Pole, poles: list[Pole], resolution: float | None = None) -> bool:
    """Whether ``p`` is the leftover of subtracting a pole already found.

    Default (the band stages): within the mean of the two half-power half-widths d / (2 pi)
    (at least 0.5 Hz). There a damped pole beside a slow one is most often what a cluster of
    slow modes that beat leaves (``jassy bench fit``: the narrower width instead lost 10
    decays within 5 %, 7 of them in one 55-63 Hz cluster). With ``resolution`` (Hz; the
    full-rate stage, 1 / its window): within the larger of that and the narrower pole's
    half-width. A broad mode (800 /s, 127 Hz half-width) 60 Hz from a slow pole, beyond
    what the window resolves, is a mode of its own, not that pole's leftover."""
    if resolution is None:
        return any(
            abs(p.frequency - q.frequency) < max(0.5, (p.decay + q.decay) / (4 * np.pi)) for q in poles
        )
    return any(
        abs(p.frequency - q.frequency) < max(0.5, resolution, min(p.decay, q.decay) / (2 * np.pi))
        for q in poles
    )


def _band_centres(stage: Stage, f_lo: float, f_hi: float) -> np.ndarray:
    f_hi = min(f_hi, stage.f_max)
    return np.arange(f_lo + stage.spacing / 2, f_hi + stage.spacing / 2, stage.spacing)


class StageSpectra(NamedTuple):
    """The FFTs (one common size ``n_fft``, so every signal's bands are shifted by the same
    frequency and pool) of the first ``keep[i]`` samples of each signal, for one stage."""

    specs: list
    n_fft: int
    keep: list


def _stage_spectra(stage: Stage, signals, rate: float) -> StageSpectra:
    keep = [min(x.size, int(stage.seconds * rate)) for x in signals]
    n_fft = 1 << int(math.ceil(math.log2(2 * max(max(keep), 16))))
    return StageSpectra([np.fft.rfft(x[:n], n_fft) for x, n in zip(signals, keep, strict=True)], n_fft, keep)


class BandSignals(NamedTuple):
    """One band of a stage over all signals: ``ys[j]`` = the band of signal ``kept[j]``
    (signals too short for the band filter's transients are left out), with ``trim``
    decimated samples cut from each end; ``band`` = the last :class:`esprit.Band` (rate and
    exact centre are the same for all); ``noise`` = the largest band noise level."""

    ys: list
    kept: list
    band: esprit.Band | None
    noise: float
    trim: int


def _band_signals(stage: Stage, spectra: StageSpectra, rate: float, centre: float, noises) -> BandSignals:
    """Each signal's band around ``centre`` Hz (:func:`esprit.band_signal`); ``noises`` =
    each signal's noise |X_k|^2 per bin of the stage's FFT."""
    trim_s = 4.0 / (stage.edge - stage.spacing / 2)
    ys, kept, noise, band, trim = [], [], 0.0, None, 0
    for i, (spec, n, nb) in enumerate(zip(spectra.specs, spectra.keep, noises, strict=True)):
        band = esprit.band_signal(spec, spectra.n_fft, n, rate, centre, stage.spacing / 2, stage.edge, nb)
        trim = int(math.ceil(trim_s * band.rate))
        if band.y.size > 2 * trim + 16:
            ys.append(band.y[trim:-trim])
            kept.append(i)
            noise = max(noise, band.noise)
    return BandSignals(ys, kept, band, noise, trim)


def _band_poles(stage: Stage, residuals, segments, rate, f_lo, f_hi, margin, work) -> list[Pole]:
    """Poles of one banded stage from the residual signals (one per segment)."""
    spectra = _stage_spectra(stage, residuals, rate)
    out: list[Pole] = []
    # the noise of each segment at this stage's FFT size (|X|^2 scales with the length)
    bins_hz = np.arange(spectra.n_fft // 2 + 1) * rate / spectra.n_fft
    noises = [
        np.interp(bins_hz, np.arange(seg.noise.size) * rate / seg.n_fft, seg.noise) * n / seg.x.size
        for seg, n in zip(segments, spectra.keep, strict=True)
    ]
    for centre in _band_centres(stage, f_lo, f_hi):
        work.step(stage.name)
        ys, _, band, noise, _ = _band_signals(stage, spectra, rate, centre, noises)
        if not ys:
            continue
        shortest = min(y.size for y in ys)
        width = int(np.clip(shortest // 3, 8, 160))
        gram, rows = esprit.pooled_gram(ys, width)
        if rows == 0:
            continue
        z = esprit.esprit_poles(gram, rows, noise, margin, max_order=width // 2)
        brate = band.rate
        # refine the poles in and next to the band (the others are filter edges and noise)
        near = np.abs(np.angle(z) * brate / (2 * np.pi)) <= stage.edge
        z, amps = esprit.refine(ys, brate, z[near])
        for k, zk in enumerate(z):
            if not 0 < abs(zk) < math.inf:  # a pole refined away (decay beyond the float range)
                continue
            f = band.centre + np.angle(zk) * brate / (2 * np.pi)
            d = -math.log(abs(zk)) * brate
            snr = max(_matched_snr(a[k], zk, y.size, noise) for a, y in zip(amps, ys, strict=True))
            inside = abs(f - centre) <= 0.55 * stage.spacing and f_lo <= f <= f_hi
            if inside and stage.d_min <= d <= stage.d_max and snr >= MIN_SNR:
                p = Pole(float(f), float(d))
                if not _duplicate(p, out):
                    out.append(p)
    return out


def _full_rate_poles(stage: Stage, residuals, segments, rate, f_lo, f_hi, margin, work) -> list[Pole]:
    """Poles of damped sinusoids in the first ``stage.seconds`` of the residuals (real signals
    at the full rate: each mode is a conjugate pair)."""
    n = min(int(stage.seconds * rate), min(r.size for r in residuals))
    if n < 64:
        return []
    ys = [r[:n].astype(np.complex128) for r in residuals]
    width = int(min(n // 3, 320))
    gram, rows = esprit.pooled_gram(ys, width)
    # the broadband noise level (a broad mode lifts the floor of the bins around it)
    noise = max(float(np.median(s.noise)) / s.x.size for s in segments)
    z = esprit.esprit_poles(gram, rows, noise, margin, max_order=width // 2)
    fz, dz = _frequency_decay(z, rate)
    z = z[(fz >= f_lo) & (fz <= f_hi) & (dz > stage.d_min / 2) & (dz <= 2 * stage.d_max)]
    real = [r[:n] for r in residuals]
    z, _ = esprit.refine(real, rate, z, real=True)
    fz, dz = _frequency_decay(z, rate)
    # faster poles are the contact: their part of the signal is left as noise for the others
    z = z[np.isfinite(dz) & (fz >= f_lo) & (fz <= f_hi) & (dz > stage.d_min) & (dz <= stage.d_max)]
    amps = [esprit.amplitudes(y, z) for y in real]
    local = _local_noise(real, z, amps)
    out = []
    for k, zk in enumerate(z):
        f = np.angle(zk) * rate / (2 * np.pi)
        d = -math.log(abs(zk)) * rate
        # a real sinusoid of amplitude |c| has |c|^2 / 2 the power of a complex one
        snr = max(_matched_snr(a[k], zk, n, max(noise, v[k])) / 2 for a, v in zip(amps, local, strict=True))
        if snr >= MIN_SNR:
            out.append(Pole(float(f), float(d)))
    return out


def _frequency_decay(z: np.ndarray, rate: float) -> tuple[np.ndarray, np.ndarray]:
    """(frequency Hz, decay 1/s) of poles z at ``rate`` Hz (decay inf for z = 0)."""
    with np.errstate(divide="ignore"):
        return np.angle(z) * rate / (2 * np.pi), -np.log(np.abs(z)) * rate


def _local_noise(signals, z: np.ndarray, amps) -> list[np.ndarray]:
    """Per signal and pole: the mean square per sample (signal units^2) of what the poles
    leave of the signal, weighted by the pole's own energy envelope |z|^(2n) (where the
    pole has its energy). A
    pole fitted to a contact's noise burst explains a few of its degrees of freedom and
    leaves the rest beside it; a damped sinusoid leaves only the noise."""
    out = []
    for y, c in zip(signals, amps, strict=True):
        r = y - esprit.resynthesis(y.size, z, c)
        n = np.arange(y.size)
        w = np.abs(z)[None, :] ** (2 * n[:, None])
        out.append((r**2) @ w / np.maximum(w.sum(axis=0), 1e-300))
    return out


def _detect(poles: list[Pole], segments, rate, f_lo, f_hi, margin, work) -> list[Pole]:
    """``poles`` plus those each stage finds in what the poles found so far leave."""
    poles = list(poles)
    for stage in STAGES:
        z = _z(poles, rate) if poles else np.zeros(0, dtype=complex)
        res = _residuals(segments, z, rate, stage.seconds)
        finder = _band_poles if stage.spacing else _full_rate_poles
        new = finder(stage, res, segments, rate, f_lo, f_hi, margin, work)
        resolution = None if stage.spacing else 1.0 / stage.seconds
        poles.extend(p for p in new if not _duplicate(p, poles, resolution))
        if not stage.spacing:
            work.step(stage.name)
    return poles


def _matched_snr(c: complex, z: complex, n: int, noise: float) -> float:
    """Energy of c z^m over m < n relative to the noise variance per sample."""
    r2 = abs(z) ** 2
    energy = abs(c) ** 2 * (n if abs(1 - r2) < 1e-12 else (1 - r2**n) / (1 - r2))
    return energy / max(noise, 1e-300)


def _home_stage(p: Pole) -> Stage | None:
    """The first banded stage whose bands and decay range hold the pole (None: full rate)."""
    for st in STAGES:
        if st.spacing and p.decay <= st.d_max and p.frequency < st.f_max:
            return st
    return None


def _polish(poles: list[Pole], segments, rate, f_lo, f_hi, work) -> list[Pole]:
    """Every band's poles refined jointly, by maximum likelihood over all hits and channels
    (:func:`esprit.refine`), on the recording minus every other pole.

    Each stage found its poles on what the earlier stages left, with their poles fixed; a
    pole fitted early absorbs part of a neighbour found later (a cluster, a weak mode on a
    strong one's skirt), and nothing corrected it. Here each pole is refined in the band of
    the first stage that holds it (its "home"): the band signal of the full residual plus
    the band's own modes, which are added back in closed form (a mode c z^n appears in the
    analytic band signal as c / 2 (z e^{-i 2 pi f_c / fs})^(m D) at decimated sample m).
    A refined pole that leaves its band or stops decaying keeps its old value. Only the
    stages of slow modes (d <= ``POLISH_MAX_DECAY``) are refined: there modes crowd (a few Hz
    apart); refining the broad, short, often weak modes of the wide bands jointly over 0.3 s
    moved weak ones away (two of 27 modes lost in the random two-strike test)."""
    out = list(poles)
    for stage in STAGES:
        if not stage.spacing:
            continue
        work.step("band refinement")
        if stage.d_max > POLISH_MAX_DECAY:
            continue
        members = [i for i, p in enumerate(out) if _home_stage(p) is stage]
        if not members:
            continue
        z = _z(out, rate)
        keep = [min(seg.x.size, int(stage.seconds * rate)) for seg in segments]
        amps = [
            esprit.amplitudes(seg.x[:n], z, seg.excluded[seg.excluded < n])
            for seg, n in zip(segments, keep, strict=True)
        ]
        residuals = [
            seg.x[:n] - esprit.resynthesis(n, z, c) for seg, n, c in zip(segments, keep, amps, strict=True)
        ]
        spectra = _stage_spectra(stage, residuals, rate)
        flat = [np.zeros(spectra.n_fft // 2 + 1)] * len(segments)
        centres = _band_centres(stage, f_lo, f_hi)
        if centres.size == 0:
            continue
        home = {}
        for i in members:
            home.setdefault(int(np.argmin(np.abs(centres - out[i].frequency))), []).append(i)
        for b, idx in home.items():
            f = np.array([out[i].frequency for i in idx])
            d = np.array([out[i].decay for i in idx])
            sig = _band_signals(stage, spectra, rate, centres[b], flat)
            if not sig.ys:
                continue
            brate, centre = sig.band.rate, sig.band.centre
            s_band = (-d + 2j * np.pi * (f - centre)) / brate
            # the band's own modes added back: c / 2 (z e^{-i 2 pi f_c / fs})^(m D) at sample m
            ys = [
                y + np.exp(np.outer(sig.trim + np.arange(y.size), s_band)) @ (amps[i][idx] / 2)
                for y, i in zip(sig.ys, sig.kept, strict=True)
            ]
            z1, _ = esprit.refine(ys, brate, np.exp(s_band), max_nfev=20)
            for i, zk in zip(idx, z1, strict=True):
                if not 0 < abs(zk) < 1:
                    continue
                f_new = centre + np.angle(zk) * brate / (2 * np.pi)
                d_new = -math.log(abs(zk)) * brate
                if abs(f_new - centres[b]) <= 0.55 * stage.spacing and f_lo <= f_new <= f_hi:
                    out[i] = Pole(float(f_new), float(d_new))
    return out


#: Two refined poles closer than this fraction of the half-power half-width of their summed
#: decays, with decays within it of each other, are one mode fitted twice (their amplitudes
#: cancel). For equal decays 5x below :func:`_duplicate`'s widths, so a pair the detection
#: accepted as two modes is never merged here unless the refinement moved them together.
SAME_POLE = 0.1


def _same_pole(p: Pole, q: Pole) -> bool:
    return abs(p.frequency - q.frequency) < SAME_POLE * varpro.half_width(p.decay + q.decay) and abs(
        p.decay - q.decay
    ) < SAME_POLE * (p.decay + q.decay)


def _distinct(poles: list[Pole], before: list[Pole] | None = None) -> list[Pole]:
    """``poles`` without duplicates the refinement made: a pole may move by up to its
    refinement window, which is wider than the spacing of a group, onto a neighbour's peak,
    merging two poles into one. Of two that collide, the one that moved goes back to its
    value in ``before`` (the poles before the refinement, same order; default: ``poles``);
    it is dropped only if that value also lies on a kept pole."""
    before = poles if before is None else before
    kept: list[list[Pole]] = []  # [value, value before the refinement]
    for p, b in zip(poles, before, strict=True):
        clash = [k for k in kept if _same_pole(p, k[0])]
        if clash and p != b:
            p, clash = b, [k for k in kept if _same_pole(b, k[0])]
        for k in clash:
            if k[0] != k[1] and not _same_pole(p, k[1]):
                k[0] = k[1]  # the kept pole moved onto this one: it goes back instead
        if not any(_same_pole(p, k[0]) for k in kept):
            kept.append([p, b])
    return [k[0] for k in kept]


def _pole_groups(poles: list[Pole], bin_hz: float, max_size: int = 10) -> list[list[int]]:
    """Indices of poles (sorted by frequency) whose resonances overlap: neighbours closer than
    twice their half-widths plus two bins share a group; a group larger than ``max_size`` is
    split at its widest gap (relative to the half-widths)."""
    order = sorted(range(len(poles)), key=lambda i: poles[i].frequency)
    hw = {i: max(varpro.half_width(poles[i].decay), bin_hz) for i in order}

    def gap(i, j):
        return (poles[j].frequency - poles[i].frequency) / (hw[i] + hw[j])

    groups, cur = [], order[:1]
    for i, j in zip(order, order[1:], strict=False):
        if poles[j].frequency - poles[i].frequency < 2 * (hw[i] + hw[j]) + 2 * bin_hz:
            cur.append(j)
        else:
            groups.append(cur)
            cur = [j]
    if cur:
        groups.append(cur)
    out = []
    while groups:
        g = groups.pop()
        if len(g) <= max_size:
            out.append(g)
            continue
        cut = 1 + int(np.argmax([gap(i, j) for i, j in zip(g, g[1:], strict=False)]))
        groups += [g[:cut], g[cut:]]
    return out


def _spectral_refine(poles: list[Pole], segments, rate, f_lo, f_hi, work, sweeps: int = SWEEPS) -> list[Pole]:
    """Every pole refined by maximum likelihood over all hits and channels on the whole of
    each segment (:func:`varpro.refine` on the DFT bins within 6 half-power half-widths plus
    10 bins of each group of overlapping poles, where a mode holds most of the information
    on its decay; the other poles subtracted with their least-squares amplitudes); ``sweeps``
    rounds, each from the residual of the previous one. A pole that leaves its window, its
    frequency range or stops decaying keeps its old value."""
    out = list(poles)
    for _ in range(sweeps):
        work.step("spectral refinement")
        z = _z(out, rate)
        specs = []
        for seg in segments:
            n = varpro.fast_length(seg.x.size)
            exc = seg.excluded[seg.excluded < n]
            c = esprit.amplitudes(seg.x[:n], z, exc)
            r = seg.x[:n] - esprit.resynthesis(n, z, c)
            r[exc] = 0.0  # clipped samples: taken as the model (no evidence either way)
            specs.append((np.fft.rfft(r), n, c))
        bin_hz = rate / min(n for _, n, _ in specs)
        new = list(out)
        for idx in _pole_groups(out, bin_hz):
            f = np.array([out[i].frequency for i in idx])
            d = np.array([out[i].decay for i in idx])
            reach = 6 * varpro.half_width(d) + 10 * bin_hz
            lo, hi = max(float(np.min(f - reach)), 0.0), float(np.max(f + reach))
            spectra = []
            for spec, n, c in specs:
                bins = np.arange(max(int(lo * n / rate), 1), min(int(hi * n / rate) + 1, n // 2))
                phi, _, _ = varpro.model_columns(z[idx], bins, n)
                own = phi[:, 0::2] @ c[idx].real + phi[:, 1::2] @ c[idx].imag
                spectra.append(varpro.Spectrum(bins, spec[bins] + own, n))
            ref = varpro.refine(spectra, rate, f, d)
            for i, f_new, d_new, f_old, w in zip(idx, ref.frequencies, ref.decays, f, reach, strict=True):
                # a decay at the clamp is a pole that stopped decaying (varpro holds d >= MIN_DECAY)
                ok_d = varpro.MIN_DECAY < d_new <= 2 * STAGES[-1].d_max
                if abs(f_new - f_old) <= w and f_lo <= f_new <= f_hi and ok_d:
                    new[i] = Pole(float(f_new), float(d_new))
        out = _distinct(new, out)
    return out


# ----------------------------------------------------------------------------- amplitudes


def _segment_amplitudes(segments: list[Segment], z: np.ndarray) -> tuple[list[np.ndarray], list[np.ndarray]]:
    """(own, total) complex amplitudes per segment at its first sample: total = everything
    ringing there; own = total minus the ringing of the previous hit of the same recording
    and channel, propagated to this hit's start."""
    own, total = [], []
    prev: dict[tuple[int, int], tuple[int, np.ndarray]] = {}
    for seg in segments:
        c = esprit.amplitudes(seg.x, z, seg.excluded)
        key = (seg.recording, seg.channel)
        mine = c.copy()
        if key in prev:
            start, c_prev = prev[key]
            mine = c - c_prev * z ** (seg.hit.first - start)
        prev[key] = (seg.hit.first, c)
        own.append(mine)
        total.append(c)
    return own, total


def _residuals(segments: list[Segment], z: np.ndarray, rate: float, seconds: float) -> list[np.ndarray]:
    n_max = int(seconds * rate)
    out = []
    for seg in segments:
        x = seg.x[:n_max]
        if z.size:
            c = esprit.amplitudes(x, z, seg.excluded[seg.excluded < x.size])
            x = x - esprit.resynthesis(x.size, z, c)
        out.append(x)
    return out


# ----------------------------------------------------------------------------- driver


def _as_channels(sig, k: int) -> np.ndarray:
    x = np.asarray(sig, dtype=np.float64)
    if x.ndim == 1:
        x = x[:, None]
    if x.ndim != 2:
        raise JassyError(f"recording {k}: expected a mono or multichannel signal (frames x channels)")
    if not np.all(np.isfinite(x)):
        raise JassyError(f"recording {k}: contains NaN or Inf")
    return x


class _Work:
    """Progress of the fit (a tqdm bar on stderr when ``enabled``) and its time limit: each
    step past ``time_limit`` seconds of wall-clock time stops the fit with a JassyError."""

    def __init__(self, enabled: bool, total: int, time_limit: float | None):
        from tqdm import tqdm

        self.bar = tqdm(total=total, desc="fit", disable=not enabled, leave=False,
                        bar_format="{desc}: {bar:30} {percentage:3.0f}% {postfix} [{elapsed}]")  # fmt: skip
        self.start, self.time_limit = time.monotonic(), time_limit

    def step(self, label: str) -> None:
        if self.time_limit is not None and time.monotonic() - self.start > self.time_limit:
            self.bar.close()
            raise JassyError(
                f"fit: stopped after {self.time_limit:g} s (--max-time); fit less with --duration, "
                "--fmin/--fmax, or allow more time"
            )
        self.bar.set_postfix_str(label, refresh=False)
        self.bar.update(1)

    def close(self) -> None:
        """The bar to its end (search rounds that found nothing skip their steps), then off."""
        self.bar.update(max(0, self.bar.total - self.bar.n))
        self.bar.close()


def fit_recordings(
    signals,
    sample_rate: float,
    max_modes: int = 60,
    f_min: float = 20.0,
    f_max: float | None = None,
    onset: float | None = None,
    skip: float = 0.0,
    duration: float | None = None,
    name: str = "fit",
    points: tuple[str, ...] = (),
    locations: tuple[str, ...] | None = None,
    margin: float = 4.0,
    attack_ms: float = 20.0,
    progress: bool = False,
    time_limit: float | None = None,
) -> FitResult:
    """Fit one modal model to recordings (1-D arrays or frames x channels, or a list of them).

    Poles are pooled over every hit and channel. Gains: one row per hit when ``locations``
    names them (in order over all recordings; x channels as ``name:ch``); otherwise one row
    per recording and channel (``points`` names the recordings), the hits' gains averaged
    after scaling each hit to the loudest. ``skip`` (s) leaves out the contact after each
    onset, ``duration`` (s) caps each hit, ``onset`` (s) gives a single strike's time instead
    of detecting strikes. ``margin`` = how far a mode's Gram eigenvalue must exceed the noise
    edge. ``progress`` shows a bar on stderr; past ``time_limit`` s (wall clock) the fit stops.
    Raises JassyError with one clear line for unusable input.
    """
    from physics.modal._blas import single_threaded

    with warnings.catch_warnings(), np.errstate(all="ignore"), single_threaded():
        warnings.simplefilter("ignore", RuntimeWarning)
        return _fit(signals, sample_rate, max_modes, f_min, f_max, onset, skip, duration, name, points,
                    locations, margin, attack_ms, progress, time_limit)  # fmt: skip


def _fit(signals, rate, max_modes, f_min, f_max, onset, skip, duration, name, points, locations, margin,
         attack_ms, progress, time_limit) -> FitResult:  # fmt: skip
    """:func:`fit_recordings` inside its warning and thread guards: input checks, the
    segments, the pole search, the modes that stand out, the gains and the attack."""
    if not (rate > 0 and math.isfinite(rate)):
        raise JassyError(f"sample rate: expected > 0 Hz, got {rate}")
    if isinstance(signals, np.ndarray):
        signals = [signals]
    recs = [_as_channels(s, k) for k, s in enumerate(signals)]
    f_hi = min(f_max or 20000.0, 0.49 * rate)
    if f_hi <= f_min:
        raise JassyError(f"--fmax: expected more than --fmin ({f_min:g} Hz) and below Nyquist, got {f_hi:g}")
    notes: list[str] = []
    segments, onsets_s = _all_segments(recs, rate, onset, skip, duration, notes)
    if locations is not None and len(locations) != sum(len(o) for o in onsets_s):
        raise JassyError(
            f"--locations: expected {sum(len(o) for o in onsets_s)} names (one per strike found at "
            + "; ".join(", ".join(f"{t:.3f}" for t in o) for o in onsets_s)
            + f" s), got {len(locations)}"
        )
    work = _Work(progress, _steps(f_min, f_hi), time_limit)
    poles, amps, totals = _standing_out(_search(segments, rate, f_min, f_hi, margin, work), segments, rate)
    work.step("amplitudes")
    modes = _loudest(poles, amps, totals, segments, rate, max_modes)
    rows, names = _gain_rows(segments, modes.mags, recs, locations, points)
    residual = [_residual_db(seg, modes.z, c) for seg, c in zip(segments, modes.totals, strict=True)]
    attack = _stored_attack(segments, recs, modes, rows[0], rate, attack_ms)
    work.step("done")
    work.close()
    levels = 10 * np.log10(modes.energy / modes.energy.max())
    kept = attack if attack.size else None
    model = ModalModel(modes.frequencies, modes.decays, rows, names, name, attack=kept,
                       attack_rate=float(rate) if attack.size else None)  # fmt: skip
    noise_db = 10 * math.log10(max(float(np.median(segments[0].noise)) / segments[0].x.size, 1e-300))
    # Re(c z^n) = |c| sin(omega n + arg(c) + pi / 2)
    phases = np.angle(1j * modes.at_onset)
    return FitResult(model, float(rate), onsets_s, residual, phases, levels, noise_db, notes)


def _all_segments(recs, rate, onset, skip, duration, notes: list[str]):
    """(segments of every hit and channel, onsets in s per recording)."""
    segments: list[Segment] = []
    onsets_s: list[list[float]] = []
    for r, x in enumerate(recs):
        clipped = [clipped_samples(x[:, c]) for c in range(x.shape[1])]
        hits = _recording_hits(r, x, clipped, rate, onset, skip, notes)
        onsets_s.append([h.onset / rate for h in hits])
        segments += _hit_segments(r, x, clipped, hits, rate, skip, duration)
    return segments, onsets_s


def _recording_hits(r: int, x: np.ndarray, clipped, rate, onset, skip, notes: list[str]) -> list[Hit]:
    """The hits of recording ``r`` (frames x channels; ``clipped`` = each channel's clipped
    sample indices): at ``onset`` (s) or at the detected strikes, each starting after its
    clipped samples (a warning in ``notes``)."""
    mono = x.mean(axis=1)
    if not np.any(mono != 0) and not np.any(x != 0):
        raise JassyError(f"recording {r}: the signal is silent")
    n_clip = sum(c.size for c in clipped)
    if n_clip:
        notes.append(
            f"warning: recording {r}: {n_clip} of {x.size} samples ({100 * n_clip / x.size:.1f} %) are "
            "clipped; they are left out of the fit (record with less gain for a better fit)"
        )
        print(notes[-1], file=sys.stderr)
    if onset is not None:
        n0 = int(round(onset * rate))
        if not 0 <= n0 < x.shape[0]:
            raise JassyError(f"--onset: {onset:g} s is outside the recording ({x.shape[0] / rate:g} s)")
        ons = [n0]
    else:
        ons = detect_onsets(mono, rate)
        if not ons:
            raise JassyError(f"recording {r}: no strike found (no sudden rise of the level)")
    return hits_of(ons, x.shape[0], np.unique(np.concatenate(clipped)), rate, skip)


def _hit_segments(r: int, x: np.ndarray, clipped, hits: list[Hit], rate, skip, duration) -> list[Segment]:
    """One :class:`Segment` per hit and channel of recording ``r`` (at most ``duration`` s
    each), with its clipped samples and noise floor; a hit with under 20 ms left is an error."""
    out = []
    for h in hits:
        stop = h.end if duration is None else min(h.end, h.first + int(round(duration * rate)))
        if stop - h.first < int(0.02 * rate):
            if h.first > h.onset + int(round(skip * rate)):
                raise JassyError(
                    f"recording {r}: the strike at {h.onset / rate:.3f} s is clipped until "
                    f"{(h.first - 1) / rate:.3f} s, leaving {(stop - h.first) / rate * 1e3:.1f} ms of "
                    "unclipped decay (need >= 20 ms); record with less gain"
                )
            raise JassyError(
                f"recording {r}: the strike at {h.onset / rate:.3f} s is too short to fit "
                f"({(stop - h.first) / rate * 1e3:.1f} ms after the onset; need >= 20 ms)"
            )
        for c in range(x.shape[1]):
            seg_x = x[h.first : stop, c]
            exc = clipped[c][(clipped[c] >= h.first) & (clipped[c] < stop)] - h.first
            n_fft = 1 << int(math.ceil(math.log2(2 * seg_x.size)))
            out.append(Segment(r, c, h, seg_x, exc.astype(np.int64), noise_floor(seg_x, rate, n_fft), n_fft))
    return out


def _steps(f_min: float, f_hi: float) -> int:
    """Progress steps of a fit: each search pass (a band each, one for the full rate), the
    band refinement of each banded stage, each refinement sweep, the amplitudes and the end."""
    search = sum(_band_centres(st, f_min, f_hi).size if st.spacing else 1 for st in STAGES)
    banded = sum(1 for st in STAGES if st.spacing)
    return search * (1 + EXTRA_PASSES) + banded + SWEEPS * (1 + EXTRA_PASSES) + 2


def _search(segments, rate, f_min, f_hi, margin, work) -> list[Pole]:
    """The poles of every hit and channel (sorted): the stages, the band refinement, the
    spectral refinement, then up to ``EXTRA_PASSES`` rounds of the stages on what the
    refined poles leave and the spectral refinement again."""
    poles = _detect([], segments, rate, f_min, f_hi, margin, work)
    if poles:
        poles = _polish(poles, segments, rate, f_min, f_hi, work)
        poles = _spectral_refine(poles, segments, rate, f_min, f_hi, work)
        for _ in range(EXTRA_PASSES):
            found = len(poles)
            poles = _detect(poles, segments, rate, f_min, f_hi, margin, work)
            if len(poles) == found:
                break
            poles = _spectral_refine(poles, segments, rate, f_min, f_hi, work)
    if not poles:
        raise JassyError(
            "fit: no decaying modes found above the noise; check the recording (a strike of a "
            "resonant object), --fmin/--fmax or --onset"
        )
    return sorted(poles)


def _standing_out(poles: list[Pole], segments, rate):
    """(poles, own amplitudes, total amplitudes per segment) of the poles whose joint
    amplitudes stand ``MIN_SNR`` above the noise in some segment: a pole fitted to the skirt
    of a broad mode found later loses its amplitude to that mode in the joint fit."""
    z = _z(poles, rate)
    amps, totals = _segment_amplitudes(segments, z)
    snr = np.zeros(z.size)
    for seg, c in zip(segments, totals, strict=True):
        bins = np.clip((np.angle(z) / (2 * np.pi) * seg.n_fft).astype(int), 0, seg.noise.size - 1)
        sigma2 = seg.noise[bins] / seg.x.size
        snr = np.maximum(
            snr, [_matched_snr(ck, zk, seg.x.size, s2) / 2 for ck, zk, s2 in zip(c, z, sigma2, strict=True)]
        )
    if np.all(snr >= MIN_SNR):
        return poles, amps, totals
    poles = [p for p, ok in zip(poles, snr >= MIN_SNR, strict=True) if ok]
    if not poles:
        raise JassyError("fit: no decaying modes found above the noise; check the recording")
    return (poles, *_segment_amplitudes(segments, _z(poles, rate)))


class Modes(NamedTuple):
    """The fitted modes (ascending frequency) with their amplitudes per segment."""

    frequencies: np.ndarray  # Hz
    decays: np.ndarray  # 1/s
    z: np.ndarray  # poles per sample
    at_onset: np.ndarray  # (segments, modes): complex amplitude of each hit's own ringing at its onset
    mags: np.ndarray  # |at_onset|
    energy: np.ndarray  # the loudest hit's energy of each mode
    totals: list  # per segment: complex amplitudes of everything ringing at its first sample


def _loudest(poles: list[Pole], amps, totals, segments, rate, max_modes: int) -> Modes:
    """The ``max_modes`` modes of most energy (in the hit where each is loudest)."""
    freqs = np.array([p.frequency for p in poles])
    decays = np.array([p.decay for p in poles])
    z = _z(poles, rate)
    # referred to each hit's onset: c e^{s (t - t_first)} = (c e^{-s (first - onset)}) e^{s (t - t_onset)}
    c0 = np.array([a * z ** -(s.hit.first - s.hit.onset) for a, s in zip(amps, segments, strict=True)])
    energy = (np.abs(c0) ** 2).max(axis=0) / (4 * np.maximum(decays, 1e-3))
    keep = np.sort(np.argsort(energy)[::-1][:max_modes])
    c0 = c0[:, keep]
    return Modes(freqs[keep], decays[keep], z[keep], c0, np.abs(c0), energy[keep], [a[keep] for a in totals])


def _residual_db(seg: Segment, z: np.ndarray, c: np.ndarray) -> float:
    """Energy of the segment minus its resynthesis relative to the segment's (dB, clipped
    samples left out)."""
    own = np.delete(np.arange(seg.x.size), seg.excluded)
    err = seg.x - esprit.resynthesis(seg.x.size, z, c)
    return 10 * math.log10(max(np.sum(err[own] ** 2) / max(np.sum(seg.x[own] ** 2), 1e-300), 1e-30))


def _stored_attack(segments, recs, modes: Modes, row: np.ndarray, rate, attack_ms) -> np.ndarray:
    """The first segment's attack (:func:`_attack`) on the scale of gain row ``row``."""
    first = segments[0]
    sigma = math.sqrt(float(np.median(first.noise)) / first.x.size)
    onset_x = recs[first.recording][first.hit.onset : first.hit.end, first.channel]
    attack = _attack(onset_x, modes.z, modes.at_onset[0], sigma, rate, attack_ms)
    mags = modes.mags[0]
    strong = mags >= 0.1 * mags.max()
    return attack * float(np.median(row[strong] / mags[strong]))


def _gain_rows(segments, mags, recs, locations, points):
    """(gain rows, row names): per hit (with locations) or per recording and channel."""
    multi = any(x.shape[1] > 1 for x in recs)
    if locations is not None:
        hit_ids = sorted({(s.recording, s.hit.onset) for s in segments})
        rows, names = [], []
        for (r, n0), loc in zip(hit_ids, locations, strict=True):
            for i, s in enumerate(segments):
                if (s.recording, s.hit.onset) == (r, n0):
                    rows.append(mags[i])
                    names.append(f"{loc}:{s.channel}" if multi else loc)
        return np.array(rows), tuple(names)
    rows, names = [], []
    for r, x in enumerate(recs):
        for c in range(x.shape[1]):
            idx = [i for i, s in enumerate(segments) if (s.recording, s.channel) == (r, c)]
            g = mags[idx]
            if len(idx) > 1:  # scale each hit to the loudest, then average
                ref = g[int(np.argmax(np.sum(g**2, axis=1)))]
                strong = ref >= 0.1 * ref.max()
                scale = np.array([np.median(row[strong] / ref[strong]) for row in g])
                g = g / np.maximum(scale, 1e-12)[:, None]
            rows.append(g.mean(axis=0))
            base = points[r] if r < len(points) else f"r{r}"
            names.append(f"{base}:{c}" if multi else base)
    if len(recs) == 1 and not multi and not points:
        names = []
    return np.array(rows), tuple(names)


def _attack(
    x: np.ndarray, z: np.ndarray, c: np.ndarray, sigma: float, rate: float, attack_ms: float
) -> np.ndarray:
    """The first hit's residual from its onset (``x`` starts there; ``c`` = the modes'
    complex amplitudes at the onset) over up to ``attack_ms``, until its 0.5 ms peaks stay
    below 4 ``sigma`` (the noise's standard deviation), faded out over its last quarter: the
    contact and what no mode explains. Clipped samples stay in (the residual there is the
    clipped recording minus the modes)."""
    n = min(int(attack_ms * 1e-3 * rate), x.size)
    if n <= 0:
        return np.zeros(0)
    res = x[:n] - esprit.resynthesis(n, z, c)
    hop = max(int(rate / 2000), 1)
    env = np.abs(np.pad(res, (0, -n % hop))).reshape(-1, hop).max(axis=1)
    loud = np.flatnonzero(env > 4 * sigma)
    if loud.size == 0:
        return np.zeros(0)
    m = min(n, (loud[-1] + 1) * hop)
    out = res[:m].copy()
    fade = max(m // 4, 1)
    out[m - fade :] *= 0.5 + 0.5 * np.cos(np.linspace(0, np.pi, fade))
    return out


# ----------------------------------------------------------------------------- resynthesis, files


def resynthesise(model: ModalModel, n: int, sample_rate: float, onset: float = 0.0, row: int = 0,
                 phases=None, attack: bool = True) -> np.ndarray:  # fmt: skip
    """The model's response to a unit impulse at ``onset`` (s), n samples: sum a e^{-dt} sin(wt)
    with optional per-mode phases (e.g. ``FitResult.phases[row]``), plus, with ``attack``,
    the model's stored attack (resampled to ``sample_rate``) from the onset."""
    t = np.arange(n) / sample_rate - onset
    live = t >= 0
    tt = t[live]
    out = np.zeros(n)
    ph = np.zeros(model.n_modes) if phases is None else np.asarray(phases)
    for k in range(model.n_modes):
        out[live] += (
            model.gains[row, k]
            * np.exp(-model.decays[k] * tt)
            * np.sin(2 * np.pi * model.frequencies[k] * tt + ph[k])
        )
    if attack and model.attack is not None and model.attack.size:
        samples = model.attack_at(float(sample_rate))
        i0 = int(np.argmax(live)) if live.any() else n
        m = min(samples.size, n - i0)
        out[i0 : i0 + m] += samples[:m]
    return out


def read_recording(path: str | os.PathLike) -> tuple[np.ndarray, float]:
    """(float64 samples, frames x channels, sample rate) of an audio file soundfile reads."""
    import soundfile as sf

    if not os.path.isfile(path):
        raise JassyError(f"{path}: no such recording")
    try:
        data, rate = sf.read(str(path), dtype="float64", always_2d=True)
    except Exception as exc:  # soundfile raises RuntimeError / LibsndfileError
        raise JassyError(f"{path}: cannot read audio ({exc})") from None
    if data.shape[0] == 0:
        raise JassyError(f"{path}: the recording is empty")
    return data, float(rate)


def fit_files(paths, **kwargs) -> FitResult:
    """:func:`fit_recordings` on audio files (all at the same sample rate)."""
    sigs, rates = [], []
    for p in paths:
        x, r = read_recording(p)
        sigs.append(x)
        rates.append(r)
    if len(set(rates)) > 1:
        raise JassyError(f"recordings: expected one sample rate, got {sorted(set(rates))}")
    kwargs.setdefault("points", tuple(os.path.splitext(os.path.basename(str(p)))[0] for p in paths))
    return fit_recordings(sigs, rates[0], **kwargs)


def plot_fit(result: FitResult, recording: np.ndarray, path: str | os.PathLike, row: int = 0) -> None:
    """Spectrograms of the recording (first channel), the resynthesis of its first strike
    (fitted phases, with the attack) and their difference."""
    try:
        import matplotlib

        matplotlib.use("Agg")
        import matplotlib.pyplot as plt
    except ImportError:
        raise JassyError(
            "--plot: matplotlib is not installed (pip install 'jassy[plot]' or pip install matplotlib)"
        ) from None
    from scipy.signal import spectrogram

    rate = result.sample_rate
    x = np.asarray(recording, dtype=np.float64)
    x = x[:, 0] if x.ndim == 2 else x
    y = resynthesise(result.model, x.size, rate, result.onset, row, result.phases[row])
    nper = 1024 if rate > 30000 else 512
    fig, axes = plt.subplots(3, 1, figsize=(9, 9), sharex=True, sharey=True)
    ref = None
    for ax, sig, title in zip(
        axes, (x, y, x - y), ("recording", "resynthesis", "residual (recording - resynthesis)"), strict=True
    ):
        f, t, s = spectrogram(sig, rate, nperseg=nper, noverlap=nper * 3 // 4)
        db = 10 * np.log10(s + 1e-20)
        ref = db.max() if ref is None else ref
        mesh = ax.pcolormesh(t, f, db, vmin=ref - 90, vmax=ref, shading="auto", cmap="magma")
        ax.set_title(title)
        ax.set_ylabel("Hz")
    axes[-1].set_xlabel("s")
    fig.colorbar(mesh, ax=axes, label="dB")
    fig.savefig(str(path), dpi=110)
    plt.close(fig)

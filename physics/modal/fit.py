"""Fit modal parameters (frequencies, decay rates, gains) to impact recordings.

Method (peak picking, then a high-resolution subband estimator, then least squares):

1. **Onset.** The first sample whose magnitude exceeds ``onset_db`` below the peak (or, with a
   quiet pre-roll, 8 noise standard deviations), or the time given.
2. **Candidates.** Peaks of the magnitude spectrum (pyfftw, zero-padded 4x, the end of the
   segment tapered) that stand ``threshold_db`` above a running-median noise floor, at most
   ``dynamic_range`` dB below the strongest peak and inside [f_min, f_max].
3. **Subband matrix pencil** (Hua & Sarkar 1990, "Matrix pencil method for estimating
   parameters of exponentially damped/undamped sinusoids in noise"; the subband form as in
   Laroche 1993 / Badeau et al. 2006 ESPRIT). For each candidate the spectrum of the
   zero-padded segment is multiplied by a Hann band window around it and moved to baseband
   with a short inverse FFT, which is the signal band-pass filtered and decimated to a few
   hundred complex samples. A damped sinusoid stays a damped sinusoid with the same pole
   through any linear filter, so the pencil of that short signal (model order = peaks in
   the band + 2, samples away from both ends so the filter transients are excluded) gives
   the mode's frequency and decay rate with sub-bin precision, over the whole time the
   mode is above the noise.
4. **Gains.** With the poles fixed, complex amplitudes by linear least squares on the full-rate
   signal (all modes at once, so overlapping modes are separated); gain = |amplitude|
   referred back to the onset. Gains are in the recording's units per unit impulse: the
   resynthesis of the model for a 1 N s impulse reproduces the recording (phases aside, see
   below). Several recordings (one per strike location) share the poles and get one gain
   row each.

Phases: a recorded impact has a finite contact time, a microphone and a propagation delay,
so the fitted phases are not those of a pure sin(); the model keeps magnitudes only (the
report lists the phases). The residual (recording minus resynthesis with the fitted phases)
is reported in dB relative to the recording over the fitted window.
"""

from __future__ import annotations

import math
import os
from dataclasses import dataclass, field

import numpy as np

from jassy.errors import JassyError
from jassy.modal_model import ModalModel


def _fft():
    """pyfftw's numpy-compatible interface with its plan cache (numpy.fft if missing)."""
    try:
        import pyfftw
        import pyfftw.interfaces.numpy_fft as fft

        pyfftw.interfaces.cache.enable()
        return fft
    except ImportError:  # pragma: no cover - pyfftw is a dependency
        return np.fft


@dataclass
class FitResult:
    """A fitted model plus diagnostics (times in s relative to the start of the recording)."""

    model: ModalModel
    sample_rate: float
    onset: float
    window: tuple[float, float]
    residual_db: list[float]
    phases: np.ndarray
    levels_db: np.ndarray
    noise_db: float
    candidates: int
    notes: list[str] = field(default_factory=list)

    def report(self) -> str:
        m = self.model
        lines = [
            f"fitted {m.n_modes} modes ({self.candidates} spectral peaks) from {m.n_points} recording(s) "
            f"at {self.sample_rate:g} Hz; onset {self.onset * 1e3:.1f} ms; fit window "
            f"{self.window[0]:.3f}-{self.window[1]:.3f} s",
            "residual (recording - resynthesis, energy over the window): "
            + ", ".join(f"{r:.1f} dB" for r in self.residual_db),
            f"{'#':>3} {'f (Hz)':>10} {'d (1/s)':>9} {'T60 (s)':>8} {'level dB':>8}  gains",
        ]
        for k in range(m.n_modes):
            t60 = math.log(1000) / m.decays[k] if m.decays[k] > 0 else float("inf")
            g = " ".join(f"{v:.4g}" for v in m.gains[:, k])
            f, d, lv = m.frequencies[k], m.decays[k], self.levels_db[k]
            lines.append(f"{k:>3} {f:>10.2f} {d:>9.3f} {t60:>8.3f} {lv:>8.1f}  {g}")
        lines.extend(self.notes)
        return "\n".join(lines)


# --------------------------------------------------------------------------- helpers


def matrix_pencil(
    y: np.ndarray, order: int, rate: float, max_pencil: int = 160
) -> tuple[np.ndarray, np.ndarray]:
    """(poles, amplitudes): complex poles s = -d + i 2 pi f (1/s) of a sum of ``order`` damped
    complex exponentials sampled at ``rate`` (Hua & Sarkar's pencil with SVD truncation; the
    pencil parameter is N/3, capped at ``max_pencil``), and their complex amplitudes at
    sample 0 by least squares."""
    n = y.size
    lp = int(np.clip(n // 3, order + 1, max(max_pencil, order + 1)))
    rows = n - lp
    if rows < order + 1:
        raise ValueError("too few samples for the pencil")
    hank = np.lib.stride_tricks.sliding_window_view(y, lp + 1)[:rows]
    _, _, vh = np.linalg.svd(hank, full_matrices=False)
    v = vh[:order].T  # (lp + 1, order): the rows of vh span the row space of the Hankel matrix
    z = np.linalg.eigvals(np.linalg.pinv(v[:-1]) @ v[1:])
    z = z[np.abs(z) > 1e-12]
    vander = z[None, :] ** np.arange(n)[:, None]
    amp, *_ = np.linalg.lstsq(vander, y, rcond=None)
    return np.log(z) * rate, amp


def detect_onset(x: np.ndarray, rate: float, onset_db: float = 20.0) -> int:
    """Index of the impact: the first sample above the peak minus ``onset_db`` dB, or, when
    the recording starts with >= 10 ms before it, the first above 8 pre-roll noise sigmas."""
    peak = float(np.max(np.abs(x)))
    if peak == 0:
        raise JassyError("recording: the signal is silent")
    first = int(np.argmax(np.abs(x) >= peak * 10 ** (-onset_db / 20)))
    pre = int(0.010 * rate)
    if first > pre:
        sigma = float(np.std(x[: first - pre // 2]))
        above = np.flatnonzero(np.abs(x[: first + 1]) > 8 * sigma)
        if above.size:
            return int(above[0])
    return first


def _peaks(mag_db: np.ndarray, freqs: np.ndarray, f_min, f_max, threshold_db, dynamic_range, max_modes):
    from scipy.ndimage import median_filter
    from scipy.signal import find_peaks

    df = freqs[1] - freqs[0]
    width = max(int(round(200.0 / df)) | 1, 31)
    floor = median_filter(mag_db, size=width, mode="nearest")
    band = (freqs >= f_min) & (freqs <= f_max)
    idx, props = find_peaks(mag_db, prominence=threshold_db, distance=3)
    ok = band[idx] & (mag_db[idx] >= floor[idx] + threshold_db)
    idx = idx[ok]
    if idx.size == 0:
        return idx, floor
    top = mag_db[idx].max()
    idx = idx[mag_db[idx] >= top - dynamic_range]
    if idx.size > max_modes:
        idx = np.sort(idx[np.argsort(mag_db[idx])[::-1][:max_modes]])
    return idx, floor


def _half_power_width(mag_db: np.ndarray, i: int, df: float) -> float:
    """-3 dB width (Hz) of the peak at bin i."""
    target = mag_db[i] - 3.0
    lo = i
    while lo > 0 and mag_db[lo] > target:
        lo -= 1
    hi = i
    while hi < mag_db.size - 1 and mag_db[hi] > target:
        hi += 1
    return (hi - lo) * df


# --------------------------------------------------------------------------- fitting


@dataclass
class _Segment:
    x: np.ndarray  # the analysed samples (from the fit start)
    start: int  # index of x[0] in the recording
    onset: int


def _poles_of(seg: _Segment, rate: float, opts: dict) -> tuple[list[tuple[float, float]], int, float]:
    """(list of (f, d) poles, number of candidate peaks, noise floor dB) from one segment."""
    fft = _fft()
    x = seg.x
    n = x.size
    taper = np.ones(n)
    m = n // 4
    taper[n - m :] = 0.5 * (1 + np.cos(np.linspace(0, np.pi, m)))
    nf = 4 * (1 << int(math.ceil(math.log2(n))))
    spec = np.abs(fft.rfft(x * taper, nf))
    freqs = np.arange(spec.size) * rate / nf
    mag_db = 20 * np.log10(spec + 1e-30)
    f_max = min(opts["f_max"] or rate / 2 * 0.98, rate / 2 * 0.98)
    idx, floor = _peaks(
        mag_db, freqs, opts["f_min"], f_max, opts["threshold_db"], opts["dynamic_range"], opts["max_modes"]
    )
    noise_db = float(np.median(floor))
    if idx.size == 0:
        return [], 0, noise_db
    df = freqs[1]
    # full spectrum of the untapered segment, zero-padded to >= 2n (no circular wrap)
    n2 = 1 << int(math.ceil(math.log2(2 * n)))
    full = fft.fft(x, n2)
    bin_hz = rate / n2
    cand_f = freqs[idx]
    poles = []
    for i, fc in zip(idx, cand_f, strict=True):
        width = _half_power_width(mag_db, int(i), df)
        bw = float(np.clip(max(0.02 * fc, 12 * width), opts["band_min"], opts["band_max"]))
        half = max(int(round(bw / 2 / bin_hz)), 4)
        kc = int(round(fc / bin_hz))
        ks = np.arange(kc - half, kc + half + 1)
        win = 0.5 + 0.5 * np.cos(np.pi * (ks - kc) / (half + 1))
        size = 4 * (2 * half + 1)  # 2x oversampled, complex
        sub = np.zeros(size, dtype=complex)
        sub[(ks - kc) % size] = full[ks % n2] * win
        y = fft.ifft(sub) * size / n2  # decimated by n2 / size, shifted by -kc bins
        sub_rate = size * bin_hz
        # valid part: skip the band filter's transients at both ends and the zero padding
        margin = int(math.ceil(4.0 * sub_rate / bw))
        valid_end = int(n / (n2 / size))
        env = np.abs(y[:valid_end])
        if valid_end - margin < 16:
            continue
        tail = env[max(valid_end - max(valid_end // 5, 4), margin) : valid_end - margin]
        noise = float(np.median(tail)) if tail.size else 0.0
        above = np.flatnonzero(env[margin : valid_end - margin] > 4 * noise) + margin
        stop = int(above[-1]) + 1 if above.size else valid_end - margin
        stop = min(max(stop, margin + 16), valid_end - margin)
        seg_y = y[margin:stop]
        near = np.abs(cand_f - fc) < bw / 2
        in_band = int(np.sum(near))
        order = min(in_band + opts["extra_order"], seg_y.size // 3 - 1)
        if order < 1:
            continue
        try:
            s, amp = matrix_pencil(seg_y, order, sub_rate)
        except (ValueError, np.linalg.LinAlgError):
            continue
        # one starting pole per candidate in the band: the strongest pencil pole near it
        starts = []
        for fo in cand_f[near]:
            f_est = s.imag / (2 * np.pi) + kc * bin_hz
            ok = (np.abs(f_est - fo) < max(2 * df, width)) & (-s.real > -1e-3)
            if ok.any():
                j = np.flatnonzero(ok)[np.argmax(np.abs(amp[ok]))]
                starts.append(complex(max(-s[j].real, 0.0), f_est[j] - kc * bin_hz))
            else:
                starts.append(complex(np.pi * width / 2, fo - kc * bin_hz))
        target = int(np.argmin(np.abs(cand_f[near] - fc)))
        y_fit = y[margin : valid_end - margin]
        d_hat, f_hat = _refine(y_fit, sub_rate, starts, target)
        f_hat += kc * bin_hz
        if abs(f_hat - fc) < max(2 * df, width) and d_hat >= 0:
            poles.append((float(f_hat), float(d_hat)))
    return poles, int(idx.size), noise_db


def _refine(y: np.ndarray, rate: float, starts: list[complex], target: int) -> tuple[float, float]:
    """Nonlinear least squares (variable projection: amplitudes solved linearly) of a sum of
    damped complex exponentials to y, from starting (decay, frequency offset) pairs given as
    complex numbers d + i f; returns the refined (d, f) of ``starts[target]``. This is the
    maximum-likelihood estimate in white noise, which the pencil alone is not (at low SNR it
    also splits a mode into two nearby poles)."""
    from scipy.optimize import least_squares

    t = np.arange(y.size) / rate
    x0 = np.array([[z.real, z.imag] for z in starts]).ravel()

    def resid(p):
        d, f = p[0::2], p[1::2]
        basis = np.exp(np.outer(t, -d + 2j * np.pi * f))
        c, *_ = np.linalg.lstsq(basis, y, rcond=None)
        r = y - basis @ c
        return np.concatenate([r.real, r.imag])

    scale = np.tile([max(1.0, abs(x0[0::2]).max()), rate / y.size], len(starts))
    try:
        sol = least_squares(resid, x0, x_scale=scale, method="lm", xtol=1e-12, ftol=1e-12, max_nfev=400)
        p = sol.x
    except (ValueError, np.linalg.LinAlgError):  # pragma: no cover - degenerate input
        p = x0
    return float(p[2 * target]), float(p[2 * target + 1])


def _refine_full_rate(x: np.ndarray, rate: float, freqs, decays, c, sweeps: int = 2):
    """Space-alternating refinement at the full sample rate: for each mode in turn (loudest
    first), subtract all the others and fit (f, d, amplitude, phase) of one damped sinusoid
    by Gauss-Newton (scipy least_squares, analytic Jacobian) over the time the mode is above
    the noise (at most until it has decayed by 60 dB). No band filter is involved, so
    fast-decaying modes keep all their early samples. Returns refined (freqs, decays, c)."""
    from scipy.optimize import least_squares

    freqs, decays, c = freqs.copy(), decays.copy(), c.copy()
    n = x.size
    t_all = np.arange(n) / rate
    parts = np.array([_one(t_all, freqs[k], decays[k], c[k]) for k in range(freqs.size)])
    total = parts.sum(axis=0)
    order = np.argsort(-np.abs(c))
    for _ in range(sweeps):
        for k in order:
            target = x - (total - parts[k])
            # up to where the mode has fallen by 60 dB (beyond, it only adds noise)
            end = n if decays[k] <= 0 else int(min(n, rate * max(np.log(1000.0) / decays[k], 0.05)))
            end = max(end, min(n, 64))
            t = t_all[:end]
            y = target[:end]

            def resid(p, t=t, y=y):
                return _one(t, p[0], p[1], complex(p[2], p[3])) - y

            def jac(p, t=t):
                f, d, cs, cc = p
                e = np.exp(-d * t)
                w = 2 * np.pi * f * t
                sn, cs_ = np.sin(w), np.cos(w)
                j = np.empty((t.size, 4))
                j[:, 0] = e * 2 * np.pi * t * (cs * cs_ - cc * sn)
                j[:, 1] = -t * e * (cs * sn + cc * cs_)
                j[:, 2] = e * sn
                j[:, 3] = e * cs_
                return j

            p0 = np.array([freqs[k], decays[k], c[k].real, c[k].imag])
            try:
                sol = least_squares(resid, p0, jac=jac, method="lm", xtol=1e-12, ftol=1e-12, max_nfev=50)
            except (ValueError, np.linalg.LinAlgError):  # pragma: no cover
                continue
            f, d, cs, cc = sol.x
            if not (np.isfinite(sol.x).all() and d >= 0 and abs(f - freqs[k]) < 0.01 * freqs[k]):
                continue
            freqs[k], decays[k], c[k] = f, d, complex(cs, cc)
            new = _one(t_all, f, d, c[k])
            total += new - parts[k]
            parts[k] = new
    return freqs, decays, c


def _one(t, f, d, c):
    """Im(c e^{(-d + i 2 pi f) t}) = e^{-dt} (Re c sin + Im c cos)."""
    w = 2 * np.pi * f * t
    return np.exp(-d * t) * (c.real * np.sin(w) + c.imag * np.cos(w))


def _merge_poles(poles: list[tuple[float, float]], resolution: float) -> list[tuple[float, float]]:
    poles = sorted(poles)
    out: list[tuple[float, float]] = []
    for f, d in poles:
        if out and f - out[-1][0] < max(resolution, 2e-4 * f):
            continue
        out.append((f, d))
    return out


def _amplitudes(x: np.ndarray, rate: float, freqs: np.ndarray, decays: np.ndarray) -> np.ndarray:
    """Complex c_k with x[n] ~ sum_k Im(c_k e^{(-d_k + i w_k) n / rate}) (least squares)."""
    t = np.arange(x.size) / rate
    env = np.exp(-np.outer(t, decays))
    ph = np.outer(t, 2 * np.pi * freqs)
    basis = np.hstack([env * np.sin(ph), env * np.cos(ph)])
    coef, *_ = np.linalg.lstsq(basis, x, rcond=None)
    k = freqs.size
    return coef[:k] + 1j * coef[k:]  # Im(c e^{iwt}) = Re(c) sin + Im(c) cos


def fit_recordings(
    signals,
    sample_rate: float,
    max_modes: int = 60,
    f_min: float = 20.0,
    f_max: float | None = None,
    threshold_db: float = 15.0,
    dynamic_range: float = 70.0,
    onset: float | None = None,
    skip: float = 0.0,
    duration: float | None = None,
    name: str = "fit",
    points: tuple[str, ...] = (),
) -> FitResult:
    """Fit one modal model to one or more impact recordings (1-D arrays, or (frames, ch)).

    Poles (f, d) are estimated from every recording and merged; gains get one row per
    recording. ``skip`` (s) leaves out the contact itself after the onset; ``duration``
    (s) caps the analysed length.
    """
    if sample_rate <= 0:
        raise JassyError(f"sample rate: expected > 0 Hz, got {sample_rate}")
    if isinstance(signals, np.ndarray) and signals.ndim == 1:
        signals = [signals]
    opts = dict(
        f_min=f_min,
        f_max=f_max,
        threshold_db=threshold_db,
        dynamic_range=dynamic_range,
        max_modes=max_modes,
        band_min=20.0,
        band_max=400.0,
        extra_order=2,
        ls_seconds=4.0,
    )
    segments = []
    for k, sig in enumerate(signals):
        x = np.asarray(sig, dtype=np.float64)
        if x.ndim == 2:
            x = x.mean(axis=1)
        if x.ndim != 1 or x.size < 64:
            raise JassyError(f"recording {k}: expected a mono or multichannel signal of >= 64 samples")
        if not np.all(np.isfinite(x)):
            raise JassyError(f"recording {k}: contains NaN or Inf")
        n0 = int(round(onset * sample_rate)) if onset is not None else detect_onset(x, sample_rate)
        if not 0 <= n0 < x.size - 64:
            raise JassyError(f"--onset: {n0 / sample_rate:g} s is outside the recording")
        start = n0 + int(round(skip * sample_rate))
        stop = x.size if duration is None else min(x.size, start + int(round(duration * sample_rate)))
        if stop - start < 64:
            raise JassyError(f"recording {k}: less than 64 samples after the onset")
        segments.append(_Segment(x[start:stop], start, n0))
    all_poles: list[tuple[float, float]] = []
    n_cand = 0
    noise = []
    for seg in segments:
        p, c, nd = _poles_of(seg, sample_rate, opts)
        all_poles.extend(p)
        n_cand = max(n_cand, c)
        noise.append(nd)
    resolution = 0.25 * sample_rate / max(s.x.size for s in segments)
    poles = _merge_poles(all_poles, resolution)
    if not poles:
        raise JassyError(
            "fit: no modes found (no spectral peak stands out of the noise); check the recording, "
            "--fmin/--fmax or lower --threshold"
        )
    freqs = np.array([p[0] for p in poles])
    decays = np.array([p[1] for p in poles])
    # refine the poles at the full rate on the first (or only) recording
    seg0 = segments[0]
    n_ls = min(seg0.x.size, int(opts["ls_seconds"] * sample_rate))
    c = _amplitudes(seg0.x[:n_ls], sample_rate, freqs, decays)
    freqs, decays, c = _refine_full_rate(seg0.x[:n_ls], sample_rate, freqs, decays, c)
    order = np.argsort(freqs)
    freqs, decays = freqs[order], decays[order]
    gains = np.zeros((len(segments), freqs.size))
    phases = np.zeros((len(segments), freqs.size))
    residual = []
    for r, seg in enumerate(segments):
        n_ls = min(seg.x.size, int(opts["ls_seconds"] * sample_rate))
        c = _amplitudes(seg.x[:n_ls], sample_rate, freqs, decays)
        back = np.exp(decays * (seg.start - seg.onset) / sample_rate)
        # refer amplitude and phase to the onset: c e^{s (t - t_start)} = c e^{-s dt0} e^{s (t - t0)}
        c0 = c * back * np.exp(-1j * 2 * np.pi * freqs * (seg.start - seg.onset) / sample_rate)
        gains[r] = np.abs(c0)
        phases[r] = np.angle(c0)
        resyn = _synth(seg.x.size, sample_rate, freqs, decays, c)
        err = np.sum((seg.x - resyn) ** 2) / max(np.sum(seg.x**2), 1e-300)
        residual.append(10 * math.log10(max(err, 1e-30)))
    # level of each mode: its energy a^2 / (4 d) relative to the loudest
    energy = np.max(gains, axis=0) ** 2 / (4 * np.maximum(decays, 1e-3))
    levels = 10 * np.log10(energy / energy.max())
    model = ModalModel(freqs, decays, gains, points if len(points) == len(segments) else (), name)
    seg0 = segments[0]
    window = (seg0.start / sample_rate, (seg0.start + seg0.x.size) / sample_rate)
    return FitResult(
        model,
        float(sample_rate),
        seg0.onset / sample_rate,
        window,
        residual,
        phases,
        levels,
        float(np.mean(noise)),
        n_cand,
    )


def _synth(n: int, rate: float, freqs, decays, c) -> np.ndarray:
    t = np.arange(n) / rate
    out = np.zeros(n)
    for f, d, ck in zip(freqs, decays, c, strict=True):
        out += np.exp(-d * t) * (ck.real * np.sin(2 * np.pi * f * t) + ck.imag * np.cos(2 * np.pi * f * t))
    return out


def resynthesise(
    model: ModalModel, n: int, sample_rate: float, onset: float = 0.0, row: int = 0, phases=None
):
    """The model's response to a unit impulse at ``onset`` (s), n samples: sum a e^{-dt} sin(wt),
    with optional per-mode phases (e.g. ``FitResult.phases[row]``)."""
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
    return out


def read_recording(path: str | os.PathLike) -> tuple[np.ndarray, float]:
    """(mono float64 samples, sample rate) of an audio file soundfile reads (WAV, FLAC, ...)."""
    import soundfile as sf

    if not os.path.isfile(path):
        raise JassyError(f"{path}: no such recording")
    try:
        data, rate = sf.read(str(path), dtype="float64", always_2d=True)
    except Exception as exc:  # soundfile raises RuntimeError / LibsndfileError
        raise JassyError(f"{path}: cannot read audio ({exc})") from None
    return data.mean(axis=1), float(rate)


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
    """Spectrograms of the recording, the resynthesis (fitted phases) and their difference."""
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

"""Compiled pole design and retune of a ModalBank (ugens.modal), one loop per mode.

:func:`pole_rows` designs each mode's resonator (c1, c2, R sin theta, the direct ratio
d / g) for given frequencies (Hz) and decay rates (1/s); :func:`retune_state` moves a
ringing bank to a new design keeping every mode's amplitude and phase and returns the
kink's end correction. A fragment-size input (Crumple) retunes the bank at every event,
thousands of times a second of sound, so neither allocates or leaves the loop.
"""

from __future__ import annotations

import math
from typing import NamedTuple

import numba as nb
import numpy as np

#: Normalised frequencies (rad per sample) where the ``"band"`` direct ratio matches each
#: mode's continuous response: 16 midpoints of the top third of the band, [2 pi / 3, pi).
TOP_BAND = 2.0 * np.pi / 3.0 + (np.arange(16) + 0.5) * (np.pi / 3.0) / 16

#: cos and sin of TOP_BAND (z = e^{i omega} on the unit circle).
TOP_BAND_COS = np.cos(TOP_BAND)
TOP_BAND_SIN = np.sin(TOP_BAND)


class TopBand(NamedTuple):
    """Where the ``"band"`` direct ratio matches the continuous response: normalised
    frequencies (rad per sample) and their cos and sin."""

    omega: np.ndarray
    cos: np.ndarray
    sin: np.ndarray


#: Rows of a bank's coefficient array ``coef`` (4, K) and of a design ``fresh``: the
#: recursion's c1 = 2 R cos theta and c2 = R^2, the input gain g and the direct gain d.
COEF_C1, COEF_C2, COEF_GAIN, COEF_DIRECT = 0, 1, 2, 3
#: Rows of a pole design ``poles`` (4, K) (:func:`pole_rows`): c1, c2, s = R sin theta
#: and the direct ratio d / g.
POLE_C1, POLE_C2, POLE_SIN, POLE_RATIO = 0, 1, 2, 3
#: Rows of ``tuning`` (6, K) (:func:`retune_state`): c1, c2 of the last new tuning and its
#: cos theta, sin theta, theta and ln R.
TUNE_C1, TUNE_C2, TUNE_COS, TUNE_SIN, TUNE_THETA, TUNE_LOG_R = 0, 1, 2, 3, 4, 5

#: Longest ring-out (s, to -60 dB) of a mode that a retune moves to or above Nyquist.
LEAVING_FADE = 1e-3


@nb.njit(cache=True, error_model="numpy", fastmath={"reassoc", "contract"})
def band_ratio(f, decay, c1, c2, s, fs, band, band_cos, band_sin):
    """The ``"band"`` direct ratio d / g of one sounding mode (ugens.modal.direct_ratio):
    the constant d minimising sum over TOP_BAND of |H_c|^-2 Re(H_c - H_d - d)^2, with the
    continuous response H_c = w / ((i omega fs + decay)^2 + w^2) = w / q and the discrete
    one H_d = g z / A(z), z = e^{-i omega}, A = 1 - c1 z + c2 z^2, g = s / fs. With
    weight |q|^2 / w^2: d = (w sum Re q - g sum |q|^2 Re(z conj A) / |A|^2) / sum |q|^2."""
    w = 2.0 * math.pi * f
    g = s / fs
    num_c = 0.0
    num_d = 0.0
    den = 0.0
    for j in range(band.size):
        zr = band_cos[j]
        zi = -band_sin[j]
        z2r = zr * zr - zi * zi
        z2i = 2.0 * zr * zi
        ar = 1.0 - c1 * zr + c2 * z2r
        ai = -c1 * zi + c2 * z2i
        x = band[j] * fs
        qr = decay * decay - x * x + w * w
        qi = 2.0 * x * decay
        q2 = qr * qr + qi * qi
        num_c += qr
        num_d += q2 * (zr * ar + zi * ai) / (ar * ar + ai * ai)
        den += q2
    return (w * num_c - g * num_d) / den / g


def resonator(f, decay, fs):
    """(c1, c2, s, theta) = (2 R cos theta, R^2, R sin theta, theta) of a mode of f Hz
    decaying at ``decay`` 1/s, R = e^{-decay / fs}, theta = 2 pi f / fs: the one formula of
    every modal resonator. Numbers or arrays; numpy's exp rounds differently from numba's
    (libm's) in the last bit, so each caller keeps the bits of where it runs: compiled per
    mode in :func:`pole_rows` (ModalBank), vectorised by numpy in ugens.modal.design."""
    r = np.exp(-decay / fs)
    theta = 2.0 * np.pi * f / fs
    return 2.0 * r * np.cos(theta), r * r, r * np.sin(theta), theta


compiled_resonator = nb.njit(cache=True, inline="always", error_model="numpy")(resonator)


@nb.njit(cache=True, error_model="numpy")
def pole_rows(freqs, decays, freq_scale, decay_scale, fs, fit_band, top_band, poles, sin2, inv):
    """Per mode into poles (4, K): c1 = 2 R cos theta, c2 = R^2, s = R sin theta and the
    direct ratio d / g (theta / (12 s), or :func:`band_ratio` over the TopBand ``top_band``
    if ``fit_band``); sin2 =
    sin^2 theta (1 for silent modes), inv = 1 / (R^2 sin^2 theta) (0 for silent modes).
    f = freqs * freq_scale (Hz), decay = decays * decay_scale (1/s), R = e^{-decay / fs},
    theta = 2 pi f / fs; modes at or above Nyquist are silent (zeros)."""
    band, band_cos, band_sin = top_band
    for k in range(freqs.size):
        f = freqs[k] * freq_scale
        decay = decays[k] * decay_scale
        c1 = c2 = s = ratio = theta = 0.0
        if f < fs / 2:
            c1, c2, s, theta = compiled_resonator(f, decay, fs)
        if c2 > 0.0:  # R underflows for decays beyond ~700 fs: silent
            if fit_band:
                ratio = band_ratio(f, decay, c1, c2, s, fs, band, band_cos, band_sin)
            else:
                ratio = theta / (12.0 * s)
        poles[POLE_C1, k] = c1
        poles[POLE_C2, k] = c2
        poles[POLE_SIN, k] = s
        poles[POLE_RATIO, k] = ratio
        if c2 > 0.0:
            sn = max(1.0 - c1 * c1 / (4.0 * c2), 1e-12)
            sin2[k] = sn
            inv[k] = 1.0 / (c2 * sn)
        else:
            sin2[k] = 1.0
            inv[k] = 0.0


@nb.njit(cache=True, error_model="numpy")
def tuning_of(c1, r):
    """(cos theta, sin theta, theta, ln R) of a resonator with c1 = 2 R cos theta, R = r."""
    cos_t = c1 / (2.0 * r)
    sin_t = math.sqrt(max(1.0 - cos_t * cos_t, 1e-24))
    return cos_t, sin_t, math.atan2(sin_t, cos_t), math.log(r)


@nb.njit(cache=True, error_model="numpy")
def retune_state(coef, fresh, old_poles, new_poles, y1, y2, fp, fs, tuning):
    """Retune a bank from its current coefficients ``coef`` (4, K: c1, c2, g, d) to the
    design ``fresh`` (4, K) at the next frame n0, in place on coef and the state (y1, y2),
    keeping each ringing mode's amplitude and phase; fp: the force sample before n0.
    Returns the kink's end correction for frame n0 (ugens.modal.ModalBank._retune).

    Per mode, complex state Z = A R^k e^{i (k theta + phi)}, y = Im Z; a force sample F
    enters a step as Z <- p (Z + F g / (R sin theta)), p = R e^{i theta}. Frame n0 rings at
    the old tuning; the new tuning's state before n0 is the one that reaches the same Z
    there. The kink correction per mode is the direct gain per unit initial slope, K /
    theta with K = (d / g) R sin theta, for the sine part (Re Z, slope theta) and the
    cosine part (Im Z, slope -delta, delta = -ln R) of the slope jump. A mode moved to or
    above Nyquist keeps ringing at its old pole, damped to -60 dB within LEAVING_FADE s.

    tuning (6, K): per mode, the (c1, c2) of the last new tuning and its cos theta,
    sin theta, theta and ln R (:func:`tuning_of`); the next retune starts from those
    coefficients unless a ramp or a parameter changed them, so it reuses them (they are a
    function of (c1, c2) alone, so the reuse is exact); NaN rows match nothing."""
    fade = math.exp(-math.log(1000.0) / (LEAVING_FADE * fs))
    correction = 0.0
    for k in range(coef.shape[1]):
        c1 = coef[COEF_C1, k]
        c2 = coef[COEF_C2, k]
        g_old = coef[COEF_GAIN, k]
        kink_old = old_poles[POLE_RATIO, k] * old_poles[POLE_SIN, k]
        kink_new = new_poles[POLE_RATIO, k] * new_poles[POLE_SIN, k]
        n1 = fresh[COEF_C1, k]
        n2 = fresh[COEF_C2, k]
        coef[COEF_GAIN, k] = fresh[COEF_GAIN, k]
        coef[COEF_DIRECT, k] = fresh[COEF_DIRECT, k]
        if not c2 > 0.0:  # silent before: stays silent until the next force
            coef[COEF_C1, k] = n1
            coef[COEF_C2, k] = n2
            y1[k] = 0.0
            y2[k] = 0.0
            continue
        r = math.sqrt(c2)
        if not n2 > 0.0:  # leaving: ring out at the old pole
            shrink = min(1.0, fade / r)
            n1 = c1 * shrink
            n2 = c2 * shrink * shrink
            kink_new = kink_old
        coef[COEF_C1, k] = n1
        coef[COEF_C2, k] = n2
        if not n2 > 0.0:  # the fade itself underflowed
            y1[k] = 0.0
            y2[k] = 0.0
            continue
        if c1 == tuning[TUNE_C1, k] and c2 == tuning[TUNE_C2, k]:
            cos_t = tuning[TUNE_COS, k]
            sin_t = tuning[TUNE_SIN, k]
            theta = tuning[TUNE_THETA, k]
            log_r = tuning[TUNE_LOG_R, k]
        else:
            cos_t, sin_t, theta, log_r = tuning_of(c1, r)
        r_new = math.sqrt(n2)
        cos_n, sin_n, theta_new, log_r_new = tuning_of(n1, r_new)
        tuning[TUNE_C1, k] = n1
        tuning[TUNE_C2, k] = n2
        tuning[TUNE_COS, k] = cos_n
        tuning[TUNE_SIN, k] = sin_n
        tuning[TUNE_THETA, k] = theta_new
        tuning[TUNE_LOG_R, k] = log_r_new
        u1 = y1[k]
        # Z at the last output sample, then frame n0 at the old tuning
        zr = (u1 * cos_t - r * y2[k]) / sin_t + fp * g_old / (r * sin_t)
        zi = u1
        z0r = r * (cos_t * zr - sin_t * zi)
        z0i = r * (cos_t * zi + sin_t * zr)
        # divide by the new pole, remove the force's entry at the new tuning
        vr = (cos_n * z0r + sin_n * z0i) / r_new - fp * coef[COEF_GAIN, k] / (r_new * sin_n)
        vi = (cos_n * z0i - sin_n * z0r) / r_new
        y1[k] = vi
        y2[k] = (cos_n * vi - sin_n * vr) / r_new
        sine = kink_new - kink_old
        cosine = -log_r_new * kink_new / theta_new + log_r * kink_old / theta
        correction += z0r * sine - z0i * cosine
    return correction


@nb.njit(cache=True)
def size_changes(sizes, n, current):
    """Offsets in sizes[:n] where the size is positive and differs from the one before it
    (``current`` before sizes[0]); a size <= 0 means no event yet and changes nothing."""
    count = 0
    out = np.empty(n, dtype=np.int64)
    before = current
    for i in range(n):
        s = sizes[i]
        if s > 0.0 and s != before:
            out[count] = i
            count += 1
        before = s
    return out[:count]

"""Surface profiles for the contact models: fractal (1/k^beta) heights and profile files.

A profile is a 1-D array of surface heights h[i] at positions x = i dx along a track
(dx in m per point); the sliding and rolling models read it in a loop at the contact
speed (ugens/scrape.py, ugens/roll.py).

:func:`fractal_profile` shapes seeded complex Gaussian noise in the spatial-frequency
domain (FoleyAutomatic, van den Doel, Kry & Pai 2001: surfaces modelled as fractal noise
with power spectrum ~ 1/k^beta) and transforms it with an FFTW real inverse FFT (pyfftw,
with its plan cache enabled). Being an inverse FFT of one period, the profile is exactly
periodic, so it loops without a seam. :func:`load_profile` reads a measured or designed
profile from .npy, .wav or single-column .csv files.
"""

from __future__ import annotations

import math
import os
from pathlib import Path

import numpy as np

from jassy.errors import JassyError

#: File extensions :func:`load_profile` understands.
PROFILE_FORMATS = (".npy", ".wav", ".csv")


class ProfileError(JassyError):
    """A surface profile cannot be generated or read as given."""


def fractal_profile(
    n: int,
    beta: float = 1.0,
    rms: float = 1.0,
    seed: int = 0,
    dx: float = 1.0,
    k_low: float | None = None,
    k_high: float | None = None,
) -> np.ndarray:
    """A periodic fractal surface profile of ``n`` points, heights in the units of ``rms``.

    The one-sided power spectral density is S(k) ~ k^-beta for spatial frequencies
    k_low <= k <= k_high (cycles per m; k = j / (n dx) for FFT bin j) and zero outside,
    DC included (zero mean). Each bin gets an independent complex Gaussian coefficient
    (Rayleigh amplitude, uniform phase) from ``numpy.random.default_rng(seed)``, so the
    profile is a sample of a stationary Gaussian process; the result is scaled to an
    RMS height of exactly ``rms``.

    n: points (>= 4); beta: spectral exponent (0 white, 1 pink, 2 Brownian, ...);
    dx: spacing in m per point; k_low: low cutoff, default 1 / (n dx) (the loop length,
    i.e. every bin but DC); k_high: high cutoff, default 1 / (2 dx) (the grid's Nyquist).
    """
    if isinstance(n, bool) or not isinstance(n, (int, np.integer)) or n < 4:
        raise ProfileError(f"fractal_profile: n: expected an integer number of points >= 4, got {n!r}")
    for name, value in (("beta", beta), ("rms", rms), ("dx", dx)):
        if not isinstance(value, (int, float, np.number)) or not math.isfinite(value):
            raise ProfileError(f"fractal_profile: {name}: expected a finite number, got {value!r}")
    if not -1.0 <= beta <= 6.0:
        raise ProfileError(f"fractal_profile: beta: expected a number in [-1, 6], got {beta!r}")
    if rms < 0:
        raise ProfileError(f"fractal_profile: rms: expected an RMS height >= 0, got {rms!r}")
    if dx <= 0:
        raise ProfileError(f"fractal_profile: dx: expected a spacing > 0 (m per point), got {dx!r}")
    n = int(n)
    k = np.arange(n // 2 + 1) / (n * dx)  # spatial frequency of each rfft bin, cycles per m
    lo = k[1] if k_low is None else float(k_low)
    hi = 0.5 / dx if k_high is None else float(k_high)
    band = (k >= lo * (1 - 1e-12)) & (k <= hi * (1 + 1e-12)) & (k > 0)
    if not np.any(band):
        raise ProfileError(
            f"fractal_profile: no spatial frequency of the grid lies in [k_low, k_high] = [{lo:g}, {hi:g}] "
            f"cycles/m (the grid has {k[1]:g} .. {k[-1]:g})"
        )
    m = k.size
    noise = np.random.default_rng(seed).standard_normal(2 * m)  # real parts, then imaginary parts
    amp = np.zeros(m)
    amp[band] = k[band] ** (-0.5 * beta)
    noise[:m] *= amp
    noise[m:] *= amp
    spectrum = np.empty(m, np.complex128)
    spectrum.real, spectrum.imag = noise[:m], noise[m:]
    if n % 2 == 0:
        spectrum[-1] = spectrum[-1].real * math.sqrt(2.0)  # the Nyquist bin is real (same variance)
    from jassy.fftw import import_pyfftw  # imported on use (slow to import)

    pyfftw = import_pyfftw()
    pyfftw.interfaces.cache.enable()
    profile = pyfftw.interfaces.numpy_fft.irfft(spectrum, n=n)
    scale = math.sqrt(float(profile @ profile) / n)
    return profile * (rms / scale) if scale > 0 else profile


def load_profile(path: str | os.PathLike) -> np.ndarray:
    """Read a profile (1-D float64 heights) from .npy, .wav (first channel) or .csv (one column).

    Raises ProfileError naming the file for a missing file, an unknown extension, an
    unreadable file, a shape that is not one column, fewer than 4 points or non-finite values.
    """
    path = Path(path)
    ext = path.suffix.lower()
    if ext not in PROFILE_FORMATS:
        raise ProfileError(
            f"{path}: unknown profile format {ext!r}; expected one of {', '.join(PROFILE_FORMATS)}"
        )
    if not path.is_file():
        raise ProfileError(f"{path}: no such profile file")
    try:
        if ext == ".npy":
            data = np.load(path, allow_pickle=False)
        elif ext == ".wav":
            import soundfile

            data, _ = soundfile.read(str(path), dtype="float64", always_2d=True)
            data = data[:, 0]
        else:
            data = np.loadtxt(path, delimiter=",", dtype=np.float64, ndmin=1, comments="#")
    except (OSError, ValueError, RuntimeError) as exc:
        raise ProfileError(f"{path}: cannot read profile ({exc})") from None
    data = np.asarray(data)
    if data.dtype.kind not in "iuf":
        raise ProfileError(f"{path}: expected numbers, got an array of {data.dtype}")
    if data.ndim == 2 and 1 in data.shape:
        data = data.reshape(-1)
    if data.ndim != 1:
        raise ProfileError(f"{path}: expected a single column of heights, got shape {data.shape}")
    if data.size < 4:
        raise ProfileError(f"{path}: expected at least 4 points, got {data.size}")
    data = data.astype(np.float64)
    if not np.all(np.isfinite(data)):
        raise ProfileError(f"{path}: expected finite heights, found NaN or Inf")
    return data

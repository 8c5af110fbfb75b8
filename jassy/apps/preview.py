"""Previews of rendered sound: waveform, spectrogram and level meter in one PNG.

``jassy plot FILE`` draws any WAV/FLAC file; ``jassy render ... --plot OUT.png`` draws the render
it just wrote. Levels are in dBFS (0 dB = full scale); the meter shows the peak and the RMS of
50 ms windows (IEC 60268-18 style fast ballistics are not modelled: plain windows).
"""

from __future__ import annotations

import argparse
import os

import numpy as np

from jassy.errors import JassyError

METER_WINDOW = 0.05  # s, level meter window
FLOOR_DB = -120.0  # dB, lowest level drawn


def require_matplotlib(option: str) -> None:
    """Fail before any work when matplotlib (the ``plot`` extra) is missing."""
    try:
        import matplotlib  # noqa: F401
    except ImportError:
        raise JassyError(f"{option}: needs matplotlib; install it with pip install 'jassy[plot]'") from None


def check_png(path: str, option: str) -> None:
    """Fail before any work when ``path`` cannot become a PNG file."""
    if not str(path).lower().endswith(".png"):
        raise JassyError(f"{option} {path}: expected a .png file name")
    if os.path.isdir(path):
        raise JassyError(f"{option} {path}: is a directory")
    directory = os.path.dirname(os.path.abspath(path))
    if not os.path.isdir(directory):
        raise JassyError(f"{option} {path}: directory {directory} does not exist")


def levels_db(mono: np.ndarray, sample_rate: float, window: float = METER_WINDOW):
    """(window centre times s, peak dBFS, RMS dBFS) of consecutive windows of ``mono``."""
    hop = max(1, int(round(window * sample_rate)))
    frames = mono.size // hop
    if frames == 0:
        return np.zeros(0), np.zeros(0), np.zeros(0)
    blocks = np.abs(mono[: frames * hop]).reshape(frames, hop)
    with np.errstate(divide="ignore"):
        peak = np.maximum(20 * np.log10(blocks.max(axis=1)), FLOOR_DB)
        rms = np.maximum(10 * np.log10(np.mean(blocks**2, axis=1)), FLOOR_DB)
    return (np.arange(frames) + 0.5) * hop / sample_rate, peak, rms


def plot_audio(audio: np.ndarray, sample_rate: float, path: str, title: str = "") -> None:
    """Write a PNG with the waveform of every channel, the spectrogram of their mix (power
    spectrum in dB re full scale, Hann windows of ~21 ms at 75 % overlap, log frequency from
    20 Hz to fs/2) and the level meter; atomically."""
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt
    from scipy.signal import spectrogram

    from jassy.files import atomic_path

    audio = np.atleast_2d(np.asarray(audio, dtype=np.float64))
    if audio.shape[1] == 0:
        raise JassyError(f"{path}: nothing to plot (no samples)")
    t = np.arange(audio.shape[1]) / sample_rate
    mono = audio.mean(axis=0)
    fig, axes = plt.subplots(3, 1, figsize=(10, 8), sharex=True, gridspec_kw={"height_ratios": [1, 2, 1]})
    wave, spec, meter = axes
    for c, channel in enumerate(audio):
        wave.plot(t, channel, lw=0.5, label=f"channel {c + 1}" if audio.shape[0] > 1 else None)
    wave.set_ylabel("amplitude (FS)")
    wave.set_ylim(-1.05, 1.05)
    if audio.shape[0] > 1:
        wave.legend(loc="upper right", fontsize="small")
    nfft = 1 << max(6, int(np.log2(0.021 * sample_rate)))
    nfft = min(nfft, max(16, mono.size))
    f, ts, power = spectrogram(
        mono, fs=sample_rate, window="hann", nperseg=nfft, noverlap=3 * nfft // 4, scaling="spectrum"
    )
    with np.errstate(divide="ignore"):
        power_db = np.maximum(10 * np.log10(2 * power[1:]), FLOOR_DB)  # a full-scale sine: 0 dB
    top = float(power_db.max()) if power_db.size else 0.0
    image = spec.pcolormesh(ts, f[1:], power_db, shading="auto", vmin=top - 90, vmax=top, cmap="magma")
    spec.set_yscale("log")
    spec.set_ylim(20, sample_rate / 2)
    spec.set_ylabel("frequency (Hz)")
    fig.colorbar(image, ax=spec, label="power (dB)", pad=0.01, fraction=0.03)
    tm, peak, rms = levels_db(mono, sample_rate)
    meter.plot(tm, peak, lw=0.8, label="peak")
    meter.plot(tm, rms, lw=0.8, label=f"RMS ({METER_WINDOW * 1000:.0f} ms)")
    meter.set_ylim(max(FLOOR_DB, float(min(rms.min(initial=0), -60)) - 6), 3)
    meter.set_ylabel("level (dBFS)")
    meter.set_xlabel("time (s)")
    meter.legend(loc="lower right", fontsize="small")
    for ax in axes:
        ax.grid(alpha=0.3)
    if title:
        fig.suptitle(title)
    fig.tight_layout()
    with atomic_path(path) as tmp:
        fig.savefig(tmp, format="png", dpi=100)
    plt.close(fig)


def plot_file(audio_path: str, png_path: str) -> None:
    """Preview of a WAV/FLAC file (any channel count)."""
    import soundfile as sf

    try:
        data, rate = sf.read(audio_path, dtype="float64", always_2d=True)
    except (OSError, RuntimeError, sf.LibsndfileError) as exc:
        raise JassyError(f"{audio_path}: cannot read it as audio ({exc})") from None
    if not np.all(np.isfinite(data)):
        raise JassyError(f"{audio_path}: holds non-finite samples")
    plot_audio(data.T, rate, png_path, title=os.path.basename(audio_path))


def _cmd_plot(args: argparse.Namespace) -> int:
    out = args.output or os.path.splitext(args.file)[0] + ".png"
    require_matplotlib("plot")
    check_png(out, "-o")
    if not os.path.isfile(args.file):
        raise JassyError(f"{args.file}: no such file")
    plot_file(args.file, out)
    if not args.quiet:
        print(f"wrote {out}")
    return 0


def add_command(sub) -> None:
    """Register ``jassy plot``."""
    p = sub.add_parser("plot", help="draw a WAV/FLAC file: waveform, spectrogram, level meter (PNG)")
    p.add_argument("file", help="audio file (.wav or .flac)")
    p.add_argument("-o", "--output", help="PNG file (default: FILE with .png)")
    p.add_argument("-q", "--quiet", action="store_true", help="no summary line")
    p.set_defaults(func=_cmd_plot)

"""Output of physics scenes: the rendered sound normalised to a -6 dBFS peak, and CSV tables,
both written atomically (a failed run leaves no file behind)."""

from __future__ import annotations

from pathlib import Path

import numpy as np

from jassy.errors import JassyError

PEAK = 10 ** (-6.0 / 20.0)  # -6 dBFS


def render_normalised(graph, score, duration: float, out_wav, sample_rate: int, block: int):
    """Render (graph, score) for ``duration`` s and write ``out_wav`` scaled to a -6 dBFS peak.
    Returns (audio (channels, frames) as written, the engine's warnings)."""
    from jassy.files import AtomicAudioWriter
    from jassy.offline import OfflineEngine

    rendering = OfflineEngine(graph, score, sample_rate, block, limiter=False).render(duration)
    audio = rendering.audio
    if not np.all(np.isfinite(audio)):
        raise JassyError(f"{out_wav}: the rendered audio is not finite; nothing written")
    peak = float(np.max(np.abs(audio))) if audio.size else 0.0
    if peak > 0:
        audio = audio * (PEAK / peak)
    with AtomicAudioWriter(out_wav, int(sample_rate), audio.shape[0]) as out:
        out.write(audio)
    return audio, list(rendering.warnings)


def write_csv(path, columns, header: str) -> None:
    """Write columns (a 2-D array, rows x columns) with a header line, atomically."""
    from jassy.files import atomic_path

    rows = np.asarray(columns, dtype=float)
    if not np.all(np.isfinite(rows)):
        raise JassyError(f"{path}: non-finite values; nothing written")
    with atomic_path(Path(path)) as tmp:
        np.savetxt(tmp, rows, delimiter=",", fmt="%.9g", comments="", header=header)

"""Output of physics scenes: the rendered sound normalised to a -6 dBFS peak, and CSV tables,
both written atomically (a failed run leaves no file behind)."""

from __future__ import annotations

import contextlib
from collections.abc import Iterator
from pathlib import Path

import numpy as np

from jassy.errors import JassyError

PEAK = 10 ** (-6.0 / 20.0)  # -6 dBFS

#: Lists that collect (audio as written, score) of every render (see captured_renders).
_CAPTURES: list[list] = []


@contextlib.contextmanager
def captured_renders() -> Iterator[list]:
    """Collect (audio as written, score) of each scene render inside the block (for
    ``jassy check-audio``, which needs the scheduled event times of a scene)."""
    found: list = []
    _CAPTURES.append(found)
    try:
        yield found
    finally:
        _CAPTURES.remove(found)


def render_normalised(graph, score, duration: float, out_wav, sample_rate: int, block: int,
                      radius: float = 0.1):  # fmt: skip
    """Render (graph, score) for ``duration`` s through the radiation stage (a body of
    ``radius`` m, see ugens.radiation) and write ``out_wav`` scaled to a -6 dBFS peak.
    Returns (audio (channels, frames) as written, the engine's warnings)."""
    from jassy.engines.offline import OfflineEngine
    from jassy.files import AtomicAudioWriter
    from jassy.graph import Graph
    from ugens.radiation import Radiation

    radiated = [Radiation(node, radius=radius, name=f"radiated{i}") for i, node in enumerate(graph.audio)]
    graph = Graph(radiated, graph.haptic, graph.budget)
    rendering = OfflineEngine(graph, score, sample_rate, block, limiter=False).render(duration)
    audio = rendering.audio
    if not np.all(np.isfinite(audio)):
        raise JassyError(f"{out_wav}: the rendered audio is not finite; nothing written")
    peak = float(np.max(np.abs(audio))) if audio.size else 0.0
    if peak > 0:
        audio = audio * (PEAK / peak)
    with AtomicAudioWriter(out_wav, int(sample_rate), audio.shape[0]) as out:
        out.write(audio)
    for found in _CAPTURES:
        found.append((audio, list(score)))
    return audio, list(rendering.warnings)


def write_csv(path, columns, header: str) -> None:
    """Write columns (a 2-D array, rows x columns) with a header line, atomically."""
    from jassy.files import atomic_path

    rows = np.asarray(columns, dtype=float)
    if not np.all(np.isfinite(rows)):
        raise JassyError(f"{path}: non-finite values; nothing written")
    with atomic_path(Path(path)) as tmp:
        np.savetxt(tmp, rows, delimiter=",", fmt="%.9g", comments="", header=header)

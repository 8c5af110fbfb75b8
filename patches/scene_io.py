"""Output of physics scenes: the rendered sound normalised to a -6 dBFS peak, and CSV tables,
both written atomically (a failed run leaves no file behind)."""

from __future__ import annotations

import contextlib
from collections.abc import Iterator
from functools import partial
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

    graph = _radiated(graph, radius)
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


def _radiated(graph, radius: float):
    """``graph`` with each audio output through the radiation stage of a body of ``radius`` m."""
    from jassy.graph import Graph
    from ugens.radiation import Radiation

    radiated = [Radiation(node, radius=radius, name=f"radiated{i}") for i, node in enumerate(graph.audio)]
    return Graph(radiated, graph.haptic, graph.budget)


#: The sound render's compile units are shared out one by one up to this many (the rest in
#: the last): the wok's graph has eight (its modal banks, the radiation, the mixer, the
#: strikes, the scrape, the roll, the strike records, the block loop).
SOUND_PARTS = 8


def render_units(world, voices, sample_rate: int, block: int, radius: float = 0.18) -> list:
    """Compile units of a rigid scene's sound render, for the step's helper before the
    physics has run (physics.rigid.world.simulate): :func:`compile_events`, then
    :func:`compile_render` one unit of the graph at a time, the modal banks' (the largest)
    last, so that the helper, which takes units from the back, starts the sound with it
    while this process, from the front, takes the others as it gets there. Empty on a
    filled kernel cache or for a scene with no voices."""
    from jassy.engines.coldstart import kernels_cached

    if not voices or kernels_cached():
        return []
    render = partial(compile_render, world, voices, sample_rate, block, radius)
    others = [slice(i, i + 1) for i in range(1, SOUND_PARTS - 1)] + [slice(SOUND_PARTS - 1, None)]
    return [
        partial(compile_events, world),
        *(partial(render, part=part) for part in others),
        partial(render, part=slice(0, 1)),
    ]


def compile_events(world) -> None:
    """Compile the kernels that turn a run's contact records into impacts, contact tracks and
    the contact wrench on a body (physics.rigid.events), by running them on a stand-in run of
    ``world``: two records (an impact and a sustained contact of body 0 on body 1, or on
    itself alone) in an array of the real run's type, so the kernels for the real run's types."""
    from physics.rigid.codes import REC_B, REC_IMPACT, REC_WIDTH
    from physics.rigid.events import contact_tracks, contact_wrench, impacts
    from physics.rigid.world import RunResult

    records = np.zeros((2, REC_WIDTH))
    records[:, REC_B] = min(1, len(world.bodies) - 1)
    records[0, REC_IMPACT] = 1.0
    state = world.initial_state()
    state.time = world.params.h
    run = RunResult(world, 0.0, records, np.zeros(0), *(np.zeros((0, 0, k)) for k in (3, 4, 6)), state, {})
    impacts(run)
    contact_tracks(run)
    contact_wrench(run, 0, lambda times: np.zeros((len(times), 3)))


def compile_render(
    world, voices, sample_rate: int, block: int, radius: float = 0.18, part: slice = slice(None)
) -> None:
    """Compile the kernels of a rigid scene's sound render (the units of jassy.engines.coldstart's
    compile_graph in ``part``) for the graph scene_graph builds from one impact, with a
    location change, and one sustained contact of the first sounding body on another,
    rendered as render_normalised renders: the node kinds and parameter changes, so the
    kernels for the types, of the real render."""
    from jassy.engines.coldstart import compile_graph
    from jassy.events import ContactTrack, Impact
    from jassy.modal_model import Location
    from patches.rigid_sound import scene_graph

    body = min(voices)
    other = 1 if body == 0 and len(world.bodies) > 1 else 0  # any other body (or itself, alone)
    pair = (min(body, other), max(body, other))
    times = np.linspace(0.0, 0.01, 11)
    ones = np.ones_like(times)
    track = ContactTrack(pair, times, ones, ones, ones)
    moved = Location((0, 1), (0.5, 0.5))  # a location change: the banks' jump to a new location
    hit = Impact(0.0, pair, 1e-3, 0.5, locations=(moved, moved))
    graph, score = scene_graph(world.bodies, [hit], [track], voices)
    options = dict(sample_rate=sample_rate, block=block, limiter=False)
    compile_graph(_radiated(graph, radius), options, score, part)


def write_csv(path, columns, header: str) -> None:
    """Write columns (a 2-D array, rows x columns) with a header line, atomically."""
    from jassy.files import atomic_path

    rows = np.asarray(columns, dtype=float)
    if not np.all(np.isfinite(rows)):
        raise JassyError(f"{path}: non-finite values; nothing written")
    with atomic_path(Path(path)) as tmp:
        np.savetxt(tmp, rows, delimiter=",", fmt="%.9g", comments="", header=header)

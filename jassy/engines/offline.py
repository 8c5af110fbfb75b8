"""Offline engine: render a graph and its score to arrays or to an audio file.

The engine runs the scheduler chunk by chunk (a chunk is only a unit of output handling:
chunks end on block boundaries of the absolute clock, so the sub-blocks, and the output
bits, are those of the block size and the events alone: arrays and files get the same
bits). Each chunk is checked for NaN/Inf, which are replaced by silence and reported once
with the node that produced them, and the audio passes the final limiter so it stays
within [-CEILING, CEILING].

A graph whose every node has a program kernel renders on the device callback's code path
instead (jassy.engines.program_offline): events, program and this output stage in compiled
runs, written straight into the result, with the same bits.
"""

from __future__ import annotations

import math
import os
import time
from collections.abc import Iterator, Sequence
from dataclasses import dataclass, field

import numpy as np

from jassy import stopflag
from jassy.engines.coldstart import graph_units
from jassy.errors import PatchError
from jassy.events import Event
from jassy.files import AtomicAudioWriter, audio_format, write_signal
from jassy.forked_compile import compile_on_two_cores
from jassy.graph import Graph
from jassy.haptics import ChannelDelay, HapticSafety, channel_delays, limit_force
from jassy.safety import CEILING, LimiterMeter, peak_abs, release_coefficient, scan_chunk, zero_nonfinite
from jassy.scheduler import Scheduler

#: Frames of an output chunk, rounded up to whole blocks (a chunk's end cuts no sub-block).
CHUNK_FRAMES = 8192
#: Frames of a program graph's first compiled run into the result; each next run takes
#: about half of RENDER_CHECK (s of this thread's CPU time) between checks for a stop
#: signal, at the pace of the run before (at most RUN_GROWTH times its length, never fewer
#: than RENDER_FRAMES; whole blocks, so that a run's end cuts no sub-block the scheduler
#: would not cut: the output bits do not depend on the runs): a 10 s bell of 1000 modes
#: renders in 2-3 runs. Each run costs about
#: 0.1 ms of CPU (Python between runs, and the compiled loop's caches filled again), so the
#: pace is CPU time: on a loaded machine wall-time pacing kept runs at RENDER_FRAMES (8
#: runs: +0.8 ms, 1.6 %, of that bell at load 16). The wall time between checks grows with
#: the load (about 0.4 s with a fifth of a core).
RENDER_FRAMES = 65536
RENDER_CHECK = 0.1
RUN_GROWTH = 8


@dataclass
class Rendering:
    """Rendered signals: audio (channels, frames) in [-1, 1], haptic force (channels, frames) in N."""

    audio: np.ndarray
    haptic: np.ndarray
    sample_rate: float
    warnings: list[str] = field(default_factory=list)


def _nonfinite_nodes(graph: Graph) -> list[str]:
    bad = []
    for node in graph.order:
        arrays = [node.out, *node.state_arrays().values()]
        if any(a.dtype.kind == "f" and not np.all(np.isfinite(a)) for a in arrays):
            bad.append(node.name)
    return bad


#: Default block (frames) of offline renders. The output does not depend on the block
#: (events land on their own frame), and a large block spends less Python per frame: the
#: wok's sound renders in 84 ms at 4096, 104 ms at 1024 and about 2.5x that at 64.
OFFLINE_BLOCK = 4096


class OfflineEngine:
    """Steps a graph through its score on one sample clock, faster than real time."""

    def __init__(
        self,
        graph: Graph,
        score: Sequence[Event] = (),
        sample_rate: float = 48000,
        block: int = OFFLINE_BLOCK,
        limiter: bool = True,
        release: float = 0.05,
        haptic_safety: HapticSafety | None = None,
        offsets_ms: dict[str, float] | None = None,
        program: bool = True,
    ):
        """Render ``graph`` through ``score`` at ``sample_rate`` Hz in blocks of ``block``.

        With ``program``, a graph whose every node has a kernel in jassy.program runs as one
        numba function (same output as node by node; ``self.program`` is None otherwise and
        ``self.why_not_program`` says why).

        The output stage, in order: NaN/Inf quarantine, the audio limiter, the haptic
        safety limits (if given) and per-kind offsets in ms applied exactly in samples
        (e.g. {"haptic": 2.0}: haptics 96 samples after audio at 48 kHz).
        """
        if not (isinstance(sample_rate, (int, float)) and 1000 <= sample_rate <= 768000):
            raise PatchError(f"sample_rate: expected a rate in [1000, 768000] Hz, got {sample_rate!r}")
        if not isinstance(block, int) or block < 1:
            raise PatchError(f"block: expected an integer >= 1, got {block!r}")
        self.graph = graph
        self.sample_rate = float(sample_rate)
        options = dict(sample_rate=sample_rate, block=block, limiter=limiter, release=release)
        options.update(haptic_safety=haptic_safety, offsets_ms=offsets_ms, program=program)
        compile_on_two_cores(graph_units(graph, options, score))  # a cold cache: half the compiling
        graph.prepare(self.sample_rate, block)
        from jassy.program import why_not_compiled  # imports the ugens: not at import time

        self.limiter = limiter
        self._limiter_state = np.ones(1)
        self.limiter_meter = LimiterMeter(CEILING)
        self._release = release_coefficient(release, self.sample_rate)
        self.haptic_safety = haptic_safety
        self._haptic_last = np.zeros(len(graph.haptic))
        self.haptic_flags = 0
        self.delays = channel_delays(offsets_ms or {}, len(graph.audio), len(graph.haptic), self.sample_rate)
        self._delay = ChannelDelay(self.delays)
        self.warnings: list[str] = []
        self.why_not_program = why_not_compiled(graph) if program else "not asked for"
        self.compiled = None
        if self.why_not_program is None:
            from jassy.engines.program_offline import OfflineProgram

            self.compiled = OfflineProgram(
                graph,
                self.sample_rate,
                block,
                limiter,
                self._release,
                self.limiter_meter,
                haptic_safety,
                self._delay,
            )
        self.program = self.compiled.program if self.compiled is not None else None
        self.scheduler = Scheduler(graph, score, self.sample_rate, block)
        if self.compiled is not None:
            self.compiled.attach(self.scheduler)

    @property
    def frame(self) -> int:
        """Frames rendered so far (the sample clock)."""
        return self.scheduler.frame

    def chunks(self, frames: int, progress: bool = False) -> Iterator[tuple[np.ndarray, np.ndarray]]:
        """Yield (audio, haptic) chunks covering the next ``frames`` frames."""
        graph = self.graph
        n_audio = len(graph.audio)
        block = self.scheduler.block
        chunk = -(-CHUNK_FRAMES // block) * block
        buf = np.zeros((len(graph.bus_rows), min(chunk, max(frames, 1))))
        abuf, hbuf = buf[:n_audio], buf[n_audio:]

        bar = _progress_bar(frames / self.sample_rate) if progress else None
        try:
            done = 0
            while done < frames:
                stopflag.check()  # a SIGTERM whose KeyboardInterrupt was lost still stops here
                n = min(chunk - self.frame % block, frames - done)  # to a block boundary
                self.produce(buf, n)
                a, h = abuf[:, :n], hbuf[:, :n]
                done += n
                if bar is not None:
                    bar.update(round(n / self.sample_rate, 6))
                yield a, h
        finally:
            if bar is not None:
                bar.close()

    def produce(self, buf: np.ndarray, n: int) -> None:
        """Render the next n frames into buf[:, :n] (audio rows, then haptic rows) through
        the whole output stage."""
        if self.compiled is not None:
            self._produce_compiled(buf, 0, n)
            return
        self.scheduler.run(n, buf)
        n_audio = len(self.graph.audio)
        a, h = buf[:n_audio, :n], buf[n_audio:, :n]
        bad, peak = scan_chunk(a, h)
        if bad:
            self._quarantine(a, h)
            peak = peak_abs(a)
        if self.limiter:
            self.limiter_meter.limit(a, n, self._limiter_state, self._release, peak)
        if self.haptic_safety is not None and h.shape[0]:
            s = self.haptic_safety
            self.haptic_flags |= limit_force(h, n, self._haptic_last, s.max_force, s.step(self.sample_rate))
        self._delay(buf, n)

    def _produce_compiled(self, out: np.ndarray, offset: int, n: int, ahead: int = 0) -> None:
        """:meth:`produce` into out[:, offset : offset + n] through the graph's program, in
        compiled runs (jassy.engines.program_offline); NaN/Inf are zeroed there, and the nodes that
        produced them are reset after the sub-block that met them. The score's events of the
        next ``max(n, ahead)`` frames are translated into records now."""
        done = 0
        while done < n:
            nonfinite = self.compiled.nonfinite
            got, flags = self.compiled.render(out, offset + done, n - done, ahead - done)
            self.haptic_flags |= flags
            done += got
            if self.compiled.nonfinite != nonfinite:
                self._reset_nonfinite_nodes()
                self.compiled.program.sync()

    def _quarantine(self, audio: np.ndarray, haptic: np.ndarray) -> None:
        """Replace NaN/Inf by silence, reset the nodes that hold them, report once per node."""
        self._reset_nonfinite_nodes()
        zero_nonfinite(audio)
        zero_nonfinite(haptic)

    def _reset_nonfinite_nodes(self) -> None:
        """Reset the nodes that hold NaN/Inf and report each once."""
        t = self.frame / self.sample_rate
        for name in _nonfinite_nodes(self.graph):
            msg = f"node {name!r} produced NaN/Inf near t = {t:.3f} s; replaced by silence and reset"
            if msg.split(" near")[0] not in " ".join(self.warnings):
                self.warnings.append(msg)
            self.graph.nodes[name].reset()
        if not self.warnings:
            self.warnings.append(f"NaN/Inf in the output near t = {t:.3f} s; replaced by silence")

    def render(self, duration: float, progress: bool = False) -> Rendering:
        """Render ``duration`` seconds into arrays (rows of one array: audio, then haptic)."""
        frames = frames_for(duration, self.sample_rate)
        n_audio = len(self.graph.audio)
        signals = np.empty((len(self.graph.bus_rows), frames))  # every frame is written below
        if self.compiled is not None:  # straight into the result, in growing runs
            bar = _progress_bar(frames / self.sample_rate) if progress else None
            block = self.compiled.block
            pos, run = 0, -(-RENDER_FRAMES // block) * block
            while pos < frames:
                stopflag.check()
                n = min(run - self.frame % block, frames - pos)  # to a block boundary
                began = time.thread_time()
                self._produce_compiled(signals, pos, n, frames - pos)
                pos += n
                took = max(time.thread_time() - began, 1e-6)
                run = max(RENDER_FRAMES, min(RUN_GROWTH * n, int(n * RENDER_CHECK / 2 / took)))
                run = -(-run // block) * block  # whole blocks: the same sub-blocks
                if bar is not None:
                    bar.update(round(n / self.sample_rate, 6))
            if bar is not None:
                bar.close()
        else:
            pos = 0
            for a, h in self.chunks(frames, progress):
                n = a.shape[1]
                signals[:n_audio, pos : pos + n] = a
                signals[n_audio:, pos : pos + n] = h
                pos += n
        return Rendering(signals[:n_audio], signals[n_audio:], self.sample_rate, self._final_warnings())

    def _final_warnings(self) -> list[str]:
        """The render's warnings, with the limiter's report if it cut peaks."""
        limited = self.limiter_meter.warning(self.sample_rate) if self.limiter else None
        return list(self.warnings) + ([limited] if limited else [])

    def render_to_file(
        self,
        path: str | os.PathLike,
        duration: float,
        sample_format: str = "float32",
        haptic_path: str | os.PathLike | None = None,
        progress: bool = False,
    ) -> dict:
        """Stream ``duration`` seconds to an audio file (and the haptic track), atomically.

        Returns a summary: frames, duration, peak, haptic peak, warnings.
        """
        frames = frames_for(duration, self.sample_rate)
        audio_format(path, sample_format)  # fail before rendering
        if self.sample_rate != int(self.sample_rate):
            raise PatchError(f"sample_rate: files need an integer rate, got {self.sample_rate}")
        haptic = np.zeros((len(self.graph.haptic), frames)) if haptic_path else None
        peak = 0.0
        pos = 0
        with AtomicAudioWriter(path, int(self.sample_rate), len(self.graph.audio), sample_format) as out:
            for a, h in self.chunks(frames, progress):
                out.write(a)
                peak = max(peak, float(np.max(np.abs(a))) if a.size else 0.0)
                if haptic is not None:
                    haptic[:, pos : pos + a.shape[1]] = h
                pos += a.shape[1]
            if haptic is not None:
                clipped = write_signal(haptic_path, haptic, self.sample_rate)
                if clipped:
                    self.warnings.append(clipped)
        return {
            "frames": frames,
            "duration": frames / self.sample_rate,
            "peak": peak,
            "haptic_peak": float(np.max(np.abs(haptic))) if haptic is not None and haptic.size else None,
            "warnings": self._final_warnings(),
            "limiter": self.limiter_meter.report(self.sample_rate),
        }


def _progress_bar(seconds: float):
    """A progress bar of seconds of audio rendered (shown after 2 s)."""
    from tqdm import tqdm

    return tqdm(
        total=round(seconds, 2),
        unit="s",
        delay=2.0,
        desc="render",
        leave=False,
        bar_format="{l_bar}{bar}| {n:.1f}/{total:.1f} s audio [{elapsed}<{remaining}]",
    )


def frames_for(duration: float, sample_rate: float) -> int:
    """Number of frames in ``duration`` seconds (rounded); PatchError if not positive."""
    if not isinstance(duration, (int, float)) or not math.isfinite(duration) or duration <= 0:
        raise PatchError(f"duration: expected seconds > 0, got {duration!r}")
    return max(1, int(round(duration * sample_rate)))


def render(
    graph: Graph,
    score: Sequence[Event] = (),
    duration: float = 1.0,
    sample_rate: float = 48000,
    block: int = OFFLINE_BLOCK,
    limiter: bool = True,
    progress: bool = False,
    haptic_safety: HapticSafety | None = None,
    offsets_ms: dict[str, float] | None = None,
    path: str | os.PathLike | None = None,
    haptic_path: str | os.PathLike | None = None,
    sample_format: str = "float32",
) -> Rendering:
    """Render a graph and score offline into arrays (see :class:`OfflineEngine`). With
    ``path`` (.wav or .flac, ``sample_format`` float32, pcm24 or pcm16) the audio is also
    written there atomically, and the haptic track to ``haptic_path`` (.wav, .npz or .csv)."""
    engine = OfflineEngine(
        graph, score, sample_rate, block, limiter, haptic_safety=haptic_safety, offsets_ms=offsets_ms
    )
    if path is not None:
        audio_format(path, sample_format)  # a bad name fails before the render
    elif haptic_path is not None:
        raise PatchError("haptic_path: give path too (the haptic track is written beside the audio)")
    rendering = engine.render(duration, progress)
    if path is not None:
        with AtomicAudioWriter(path, int(engine.sample_rate), rendering.audio.shape[0], sample_format) as out:
            out.write(rendering.audio)
            if haptic_path is not None:
                clipped = write_signal(haptic_path, rendering.haptic, engine.sample_rate)
                if clipped:
                    rendering.warnings.append(clipped)
    return rendering

"""A render to a file has the bits of a render to arrays, at any block size.

The engine hands its output over in chunks; a chunk's end must not cut a sub-block the
block size and the events would not cut. A probe ugen marks the first frame of every
sub-block it is asked for, so the cuts are seen directly and compared with the ones the
clock defines: every multiple of the block and the frame of each event that splits blocks.
"""

import numpy as np
import pytest
import soundfile as sf

from jassy import Graph, OfflineEngine
from jassy.engines.offline import CHUNK_FRAMES
from jassy.events import Event
from jassy.ugen import UGen
from ugens.impact import ImpactForce
from ugens.mix import Gain

FS = 48000
MARK = 0.5  # within the limiter's ceiling, exact in float32
#: a ramped gain change 3 frames after a block boundary below CHUNK_FRAMES (a non-inline
#: node's event: it splits that block) and a strike across CHUNK_FRAMES
SET_FRAME = CHUNK_FRAMES - 30
STRIKE_FRAME = CHUNK_FRAMES - 20


class SubBlockStarts(UGen):
    """Outputs MARK at the first frame of each sub-block it processes, else 0."""

    type_name = "SubBlockStarts"

    def process(self, start, n):
        self.out[:n] = 0.0
        self.out[0] = MARK


def engine(block: int) -> OfflineEngine:
    force = Gain(ImpactForce(duration=0.002, name="hit"), gain=1.0, name="force")
    graph = Graph(SubBlockStarts(name="probe"), haptic=force)
    score = [
        Event(SET_FRAME / FS, "force", args={"gain": 0.25}, ramp=0.01),
        Event((STRIKE_FRAME - 0.5) / FS, "hit", "impact", {"impulse": 0.3}),
    ]
    return OfflineEngine(graph, score, FS, block)


@pytest.mark.parametrize("block", [48, 100])
def test_file_and_array_renders_cut_the_same_sub_blocks_and_give_the_same_bits(tmp_path, block):
    assert CHUNK_FRAMES % block  # the case a chunk end would cut a block
    duration = 0.45
    frames = round(duration * FS)
    starts = sorted({*range(0, frames, block), SET_FRAME})
    expected = np.zeros(frames)
    expected[starts] = MARK

    arrays = engine(block).render(duration)
    summary = engine(block).render_to_file(tmp_path / "a.wav", duration, haptic_path=tmp_path / "h.npz")
    audio, rate = sf.read(tmp_path / "a.wav", dtype="float32", always_2d=True)

    assert summary["frames"] == frames and rate == FS
    np.testing.assert_array_equal(np.flatnonzero(arrays.audio[0]), starts)
    np.testing.assert_array_equal(np.flatnonzero(audio[:, 0]), starts)
    np.testing.assert_array_equal(audio[:, 0], expected.astype(np.float32))
    haptic = np.load(tmp_path / "h.npz")["data"]  # float64: every bit of the force
    assert np.max(np.abs(arrays.haptic[0, STRIKE_FRAME - 5 : STRIKE_FRAME + 200])) > 0
    np.testing.assert_array_equal(haptic, arrays.haptic)


def test_a_second_render_keeps_the_block_phase():
    """Two renders in a row continue the clock: frames that end mid-block do not shift the
    next render's cuts off the block grid."""
    block = 100
    whole = engine(block).render(0.4).audio[0]
    split = engine(block)
    first = split.render(1234 / FS).audio[0]
    rest = split.render(0.4 - 1234 / FS).audio[0]
    joined = np.concatenate([first, rest])
    starts = set(np.flatnonzero(whole))
    assert set(np.flatnonzero(joined)) - {1234} == starts


@pytest.mark.parametrize("block", [48, 100])
def test_compiled_graph_file_and_array_renders_have_the_same_bits(tmp_path, block):
    """The same graph without the probe runs as one compiled program: render() in growing
    runs, the file in chunks; both cut where the clock does."""
    force = Gain(ImpactForce(duration=0.002, name="hit"), gain=1.0, name="force")
    sound = Gain(force, gain=0.2, name="sound")
    score = [
        Event(SET_FRAME / FS, "sound", args={"gain": 0.05}, ramp=0.01),
        Event((STRIKE_FRAME - 0.5) / FS, "hit", "impact", {"impulse": 0.3}),
    ]
    engines = [OfflineEngine(Graph(sound, haptic=force), score, FS, block) for _ in range(2)]
    assert engines[0].why_not_program is None
    arrays = engines[0].render(0.3)
    engines[1].render_to_file(tmp_path / "a.wav", 0.3, haptic_path=tmp_path / "h.npz")
    audio, _ = sf.read(tmp_path / "a.wav", dtype="float32", always_2d=True)
    np.testing.assert_array_equal(audio[:, 0], arrays.audio[0].astype(np.float32))
    np.testing.assert_array_equal(np.load(tmp_path / "h.npz")["data"], arrays.haptic)
    assert np.max(np.abs(arrays.audio[0, STRIKE_FRAME:])) > 0.01

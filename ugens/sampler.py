"""Sampler: a recorded buffer (WAV, FLAC, ... read by soundfile) played with loop points
and varispeed (JASS ``LoopBuffer``).

The file is mixed to mono and read at a position p (in file samples) that advances by
``rate`` * file rate / output rate per output sample (varispeed: rate 2 plays an octave
up in half the time), with 4-point Hermite interpolation between samples. With ``loop``,
p wraps from ``loop_end`` back to ``loop_start`` (seconds in the file; loop_end 0 means
the end of the file), so a loop of L s repeats every L / rate s; without it, playback
stops at the end. ``play`` {at} starts (again) at ``at`` s into the file at the event's
sample, ``stop`` silences it. Output: the samples times ``gain``, e.g. a recorded scrape
profile as the force driving a ModalBank.
"""

from __future__ import annotations

import math
from pathlib import Path
from typing import Any, NamedTuple

import numba as nb
import numpy as np

from jassy.errors import PatchError
from jassy.jit import specialise
from jassy.params import Control, ParamSpec
from jassy.registry import register
from jassy.ugen import UGen
from ugens.cells import slot
from ugens.kernels import FASTMATH


class PlayState(NamedTuple):
    """The player's state, stored in this order in the float64 array ``st`` (read through the
    slots below, cells.slot)."""

    pos: float  #: read position (file samples)
    playing: float  #: 1.0 while playing


_POS, _PLAYING = (slot(PlayState, key) for key in PlayState._fields)


def load_audio(path: str, where: str) -> tuple[np.ndarray, float]:
    """(mono float64 samples, sample rate) of an audio file; PatchError naming ``where``."""
    import soundfile as sf

    if not Path(path).is_file():
        raise PatchError(f"{where}: {path}: no such file")
    try:
        data, rate = sf.read(path, dtype="float64", always_2d=True)
    except (RuntimeError, sf.LibsndfileError) as exc:
        raise PatchError(f"{where}: {path}: cannot read audio ({exc})") from None
    mono = data.mean(axis=1)
    if mono.size == 0:
        raise PatchError(f"{where}: {path}: the file holds no samples")
    if not np.all(np.isfinite(mono)):
        raise PatchError(f"{where}: {path}: the file holds NaN or infinite samples")
    return np.ascontiguousarray(mono), float(rate)


@nb.njit(fastmath=FASTMATH, cache=True)
def _sample(data, k):
    """data[k], clamped to the ends."""
    if k < 0:
        return data[0]
    if k >= data.size:
        return data[data.size - 1]
    return data[k]


@nb.njit(fastmath=FASTMATH, cache=True)
def play_buffer(out, n, data, rates, st, step, gain, loop, loop_start, loop_end):
    """n samples from position st[_POS] (file samples) while st[_PLAYING]."""
    pos = st[_POS]
    playing = st[_PLAYING] != 0.0
    span = loop_end - loop_start
    for i in range(n):
        if not playing:
            out[i] = 0.0
            continue
        k = int(math.floor(pos))
        t = pos - k
        x0 = _sample(data, k - 1)
        x1 = _sample(data, k)
        x2 = _sample(data, k + 1)
        x3 = _sample(data, k + 2)
        c1 = 0.5 * (x2 - x0)
        c2 = x0 - 2.5 * x1 + 2.0 * x2 - 0.5 * x3
        c3 = 0.5 * (x3 - x0) + 1.5 * (x1 - x2)
        out[i] = gain * (((c3 * t + c2) * t + c1) * t + x1)
        pos += rates[i] * step
        if loop and span > 0.0:
            while pos >= loop_end:
                pos -= span
        elif pos > data.size - 1:
            playing = False
    st[_POS] = pos
    st[_PLAYING] = 1.0 if playing else 0.0


@register
class Sampler(UGen):
    """A sound file played with loop points and varispeed (JASS ``LoopBuffer``);
    ``play`` {at}, ``stop``. Relative file names are relative to the working folder."""

    type_name = "Sampler"
    param_specs = {
        "file": ParamSpec("str", None, required=True, fixed=True, doc="audio file (WAV, FLAC, ...)"),
        "rate": ParamSpec(
            "float", 1.0, low=0.0, high=16.0, smooth=True, doc="playback speed (varispeed: 2 = octave up)"
        ),
        "gain": ParamSpec("float", 1.0, low=-1e6, high=1e6, doc="output scale (e.g. to newtons)"),
        "loop": ParamSpec("bool", False, doc="repeat between loop_start and loop_end"),
        "loop_start": ParamSpec("float", 0.0, low=0.0, high=1e6, unit="s", doc="loop start in the file"),
        "loop_end": ParamSpec(
            "float", 0.0, low=0.0, high=1e6, unit="s", doc="loop end in the file (0: the end of the file)"
        ),
        "playing": ParamSpec("bool", True, fixed=True, doc="start playing at frame 0 (else on 'play')"),
    }
    actions = {
        "play": {"at": ParamSpec("float", 0.0, low=0.0, high=1e6, unit="s", doc="position in the file")},
        "stop": {},
    }

    def _prepare(self) -> None:
        where = f"nodes.{self.name}.file"
        self.data, self.file_rate = load_audio(self.values["file"], where)
        self.st = np.zeros(len(PlayState._fields))
        self.rate = self.smoothed("rate")
        self._rates = Control(self.rate, self.max_block)
        self.step = self.file_rate / self.sample_rate
        self._run = specialise(
            play_buffer, self.out, 0, self.data, self._rates.buffer, self.st, 1.0, 1.0, False, 0.0, 1.0
        )

    def _loop_points(self) -> tuple[float, float]:
        """(start, end) of the loop in file samples."""
        v = self.values
        end = v["loop_end"] * self.file_rate if v["loop_end"] > 0.0 else float(self.data.size)
        start = min(v["loop_start"] * self.file_rate, end)
        return start, min(end, float(self.data.size))

    def _reset(self) -> None:
        self.st[_POS] = 0.0
        self.st[_PLAYING] = 1.0 if self.values["playing"] else 0.0
        self.rate.set(self.rate.target, 0, jump=True)

    def _param_changed(self, key: str, value: Any, jump: bool) -> None:
        if key == "rate":
            self.rate.set(value, self.ramp_samples(), jump)

    def act(self, action: str, args: dict[str, Any], sample_time: float) -> None:
        """``play`` {at}: start at ``at`` s into the file; ``stop``: silence."""
        if action == "play":
            self.st[_POS] = min(args["at"] * self.file_rate, self.data.size - 1.0)
            self.st[_PLAYING] = 1.0
        elif action == "stop":
            self.st[_PLAYING] = 0.0
        else:
            super().act(action, args, sample_time)

    def process(self, start: int, n: int) -> None:
        loop_start, loop_end = self._loop_points()
        self._run(
            self.out,
            n,
            self.data,
            self._rates.values(n),
            self.st,
            self.step,
            float(self.values["gain"]),
            bool(self.values["loop"]),
            loop_start,
            loop_end,
        )

    def state_arrays(self) -> dict[str, np.ndarray]:
        return {"st": self.st, "rate": self.rate.ramp}

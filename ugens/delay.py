"""Delay: a whole-sample delay line, the ugen that may close a feedback loop.

out[n] = x[n - D] with D = round(time * fs) >= 1 samples (silence before the first input).
``process`` emits the sub-block from the last D committed inputs, and ``commit`` (run by
the graph after every node has processed the sub-block) appends the current input. On a
cycle the graph keeps sub-blocks at most D long, so ``process`` never needs the current
input and the loop is exact at any block size. Off a cycle the delay is ordered after its
source, so for a sub-block longer than D the frames i >= D come from the current input.
"""

from __future__ import annotations

import numba as nb
import numpy as np

from jassy.errors import PatchError
from jassy.params import ParamSpec
from jassy.registry import register
from jassy.ugen import UGen


@nb.njit(cache=True)
def delay_read(x, out, n, ring, pos):
    """out[i] = input D = len(ring) frames earlier.

    ring holds the last D committed inputs, the oldest at pos[0]; frames i >= D of a
    sub-block longer than D come from the current input x[i - D].
    """
    d = ring.size
    w = pos[0]
    for i in range(n):
        if i < d:
            j = w + i
            out[i] = ring[j - d if j >= d else j]
        else:
            out[i] = x[i - d]


@nb.njit(cache=True)
def delay_write(x, n, ring, pos):
    """Append x[:n] to the ring (keeping its last len(ring) samples)."""
    d = ring.size
    w = pos[0]
    for i in range(n):
        ring[w] = x[i]
        w += 1
        if w == d:
            w = 0
    pos[0] = w


@register
class Delay(UGen):
    """out = input delayed by ``time`` (s), rounded to whole samples (at least one)."""

    type_name = "Delay"
    inputs = ("input",)
    is_delay = True
    param_specs = {
        "time": ParamSpec(
            "float",
            None,
            low=0.0,
            low_open=True,
            high=60.0,
            unit="s",
            fixed=True,
            required=True,
            doc="delay time, rounded to whole samples",
        ),
    }

    def _prepare(self) -> None:
        time = self.values["time"]
        d = int(round(time * self.sample_rate))
        if d < 1:
            raise PatchError(
                f"nodes.{self.name}.time: {time!r} s rounds to 0 samples at {self.sample_rate:g} Hz; "
                f"expected a time > {0.5 / self.sample_rate:.3g} s"
            )
        self.ring = np.zeros(d)
        self.pos = np.zeros(1, dtype=np.int64)

    def _reset(self) -> None:
        self.ring[:] = 0.0
        self.pos[0] = 0

    def min_delay_samples(self) -> int:
        """The delay D in samples: the longest sub-block a loop through this node allows."""
        return self.ring.size

    def process(self, start: int, n: int) -> None:
        delay_read(self.sources["input"].out, self.out, n, self.ring, self.pos)

    def commit(self, start: int, n: int) -> None:
        """Store the sub-block's input, after every node has processed it."""
        delay_write(self.sources["input"].out, n, self.ring, self.pos)

    def state_arrays(self):
        return {"ring": self.ring, "pos": self.pos}

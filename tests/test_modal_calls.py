"""ModalBank.process's fast path (the compiled call on one handle per bank, without the
Python around it) against the closed-form response: a parameter change between calls or
queued inside one must end it."""

import numpy as np
import pytest

from jassy import ModalModel
from ugens.modal import ModalBank

FS = 48000
BLOCK = 64


class _Source:
    """Stand-in for an upstream ugen: a force buffer read as ``.out``."""

    def __init__(self, out: np.ndarray):
        self.out = out


@pytest.mark.parametrize("precision", ["float64", "mixed"])
@pytest.mark.parametrize("inline", [False, True])
def test_a_gain_change_during_the_ringing_reaches_the_next_strike(precision, inline):
    """Two 1 N s strikes on one mode, the gain doubled between them (at a block boundary,
    or queued mid-block): y = h(t) + 2 h(t - t2), h = a e^{-d t} sin(2 pi f t)."""
    f, d, a = 440.0, 3.0, 0.7
    frames, change, second = 40 * BLOCK, 10 * BLOCK, 20 * BLOCK + 5
    force = np.zeros(frames)
    force[[0, second]] = FS  # 1 N s in one sample each
    bank = ModalBank(ModalModel([f], [d], [[a]]), precision=precision)
    source = _Source(np.zeros(BLOCK))
    bank.sources["input"] = source
    bank.prepare(FS, BLOCK)
    out = np.empty(frames)
    for start in range(0, frames, BLOCK):
        if start == change:
            if inline:
                bank.set_param_at(start + 17, "gain", 2.0, True, None)
            else:
                bank.set_param("gain", 2.0, jump=True)
        source.out = force[start : start + BLOCK]
        bank.process(start, BLOCK)
        out[start : start + BLOCK] = bank.out[:BLOCK]
    t = np.arange(frames) / FS

    def h(t):
        return np.where(t > 0, a * np.exp(-d * t) * np.sin(2 * np.pi * f * t), 0.0)

    exact = h(t) + 2.0 * h(t - second / FS)
    ringing = np.ones(frames, dtype=bool)
    ringing[[0, second]] = False  # the strikes' own samples carry the direct term
    error = np.max(np.abs(out - exact)[ringing]) / np.max(np.abs(exact))
    assert error < (1e-9 if precision == "float64" else 10 ** (-70 / 20))


def test_a_mixed_bank_in_a_graph_renders_in_mixed_precision():
    """A graph the program could run (taps into a bank) holding a mixed-precision bank runs
    node by node, and its bank's float32 modes are heard: the render differs from the
    float64 bank's by more than nothing and less than -70 dB (the compiled program, which
    has only the float64 kernel, rendered the float64 bits)."""
    from jassy import Event, Graph
    from jassy.engines.offline import OfflineEngine
    from ugens import ImpactForce

    model = ModalModel([30.0, 440.0, 3000.0], [0.7, 3.0, 20.0], [[1.0, 0.5, 0.3]])
    score = [Event(0.01 * k, "tap", "impact", {"impulse": 0.001 * (k + 1)}) for k in range(3)]
    rendered = {}
    for precision in ("float64", "mixed"):
        tap = ImpactForce(name="tap", duration=0.0007)
        graph = Graph(ModalBank(model, name="bank", precision=precision)(tap))
        engine = OfflineEngine(graph, score, FS, BLOCK, program=True)
        rendered[precision] = engine.render(0.3).audio[0]
        if precision == "mixed":
            assert engine.program is None and "mixed precision" in engine.why_not_program
    error = np.max(np.abs(rendered["mixed"] - rendered["float64"])) / np.max(np.abs(rendered["float64"]))
    assert 0.0 < error < 10 ** (-70 / 20), error

"""The flush-frame cell and the compiled ramp setter against independent references."""

import numpy as np
import pytest

from jassy.params import RAMP_INCREMENT, RAMP_NEXT, RAMP_SAMPLES, RAMP_TARGET, Smoothed, ramp_fill, ramp_to
from ugens.cells import FLUSH_PERIOD, is_flush_frame, until_flush


def test_flush_pieces_end_at_the_clock_multiples_whatever_the_block():
    """Cutting any span of frames by until_flush gives pieces that end exactly at the
    multiples of FLUSH_PERIOD inside the span (and at its end), as a frame-by-frame scan finds."""
    rng = np.random.default_rng(3)
    for start, n in [(0, 1), (0, FLUSH_PERIOD), (FLUSH_PERIOD - 1, 2), (5, 3 * FLUSH_PERIOD + 7)] + [
        (int(s), int(k)) for s, k in zip(rng.integers(0, 10**7, 40), rng.integers(1, 5000, 40), strict=True)
    ]:
        ends, i = [], 0
        while i < n:
            m = until_flush(start + i, n - i)
            assert m >= 1
            i += m
            ends.append(start + i)
        expected = [f for f in range(start + 1, start + n + 1) if f % FLUSH_PERIOD == 0 or f == start + n]
        assert ends == expected
        assert [is_flush_frame(f) for f in ends[:-1]] == [True] * (len(ends) - 1)


@pytest.mark.parametrize("samples", [0, 1, 7, 100])
def test_compiled_ramp_set_matches_smoothed(samples):
    """ramp_to (the callback's compiled ramp set) leaves the ramp Smoothed.set leaves, and the
    values it then fills are the straight line to the target."""
    reference = Smoothed(0.25)
    reference.fill(np.zeros(3), 3)
    reference.set(-1.5, samples)
    ramp = np.array([0.25, 0.25, 0.0, 0.0])
    ramp_to(ramp, -1.5, samples)
    np.testing.assert_array_equal(ramp, reference.ramp)
    out = np.zeros(samples + 3)
    ramp_fill(ramp, out, out.size)
    line = 0.25 + (-1.5 - 0.25) * np.arange(out.size) / max(samples, 1)
    expected = np.where(np.arange(out.size) >= samples, -1.5, line)
    np.testing.assert_allclose(out, expected, rtol=0, atol=1e-13)  # 100 summed increments
    assert ramp[RAMP_NEXT] == ramp[RAMP_TARGET] == -1.5
    assert ramp[RAMP_SAMPLES] == 0 and (samples < 1) == (ramp[RAMP_INCREMENT] == 0.0)

"""The fit bench's joint Cramer-Rao bound of decays (physics/modal/fit_bench.py,
joint_decay_bounds, closed-form integrals) against the Fisher information summed sample by
sample from the signal's derivatives (an independent, numerical computation)."""

import numpy as np
import pytest

from physics.modal.fit_bench import Truth, crb_bounds, joint_decay_bounds

pytestmark = pytest.mark.timeout(60)


def numeric_decay_bounds(f, d, gains, onsets, sigma, rate, n, phases):
    """sqrt(diag F^-1) for the decays: every mode's (f, d) shared, (a, b) of a e^{-dt} cos +
    b e^{-dt} sin per mode and strike segment, derivatives summed over the samples."""
    t_all = np.arange(n) / rate
    ends = np.append((np.asarray(onsets) * rate).round().astype(int)[1:], n)
    starts = (np.asarray(onsets) * rate).round().astype(int)
    k, hits = f.size, len(onsets)
    cols = np.zeros((n, 2 * k * hits + 2 * k))
    for h, (i0, i1) in enumerate(zip(starts, ends, strict=True)):
        t = t_all[i0:i1] - t_all[i0]
        for j in range(k):
            # the mode's total ringing in this segment, from this and earlier strikes
            total = sum(
                gains[g, j] * np.exp(-d[j] * (t + t_all[i0] - t_all[starts[g]]))
                * np.sin(2 * np.pi * f[j] * (t + t_all[i0] - t_all[starts[g]]) + phases[g, j])
                for g in range(h + 1)
            )  # fmt: skip
            e = np.exp(-d[j] * t)
            cols[i0:i1, 2 * k * h + 2 * j] = e * np.cos(2 * np.pi * f[j] * t)
            cols[i0:i1, 2 * k * h + 2 * j + 1] = e * np.sin(2 * np.pi * f[j] * t)
            quad = sum(
                gains[g, j] * np.exp(-d[j] * (t + t_all[i0] - t_all[starts[g]]))
                * np.cos(2 * np.pi * f[j] * (t + t_all[i0] - t_all[starts[g]]) + phases[g, j])
                for g in range(h + 1)
            )  # fmt: skip
            cols[i0:i1, 2 * k * hits + j] = -t * total
            cols[i0:i1, 2 * k * hits + k + j] = t * quad
    inv = np.linalg.inv(cols.T @ cols / sigma**2)
    return np.sqrt(np.diag(inv)[2 * k * hits : 2 * k * hits + k])


def test_one_mode_one_strike_is_the_single_sinusoid_bound():
    truth = Truth(
        np.array([1000.0]), np.array([10.0]), np.array([[1.0]]), np.array([0.0]), 0.01, 48000.0, 96000
    )
    single = crb_bounds(1.0, 1000.0, 10.0, 0.01, 48000.0, 96000).decay
    assert joint_decay_bounds(truth)[0] == pytest.approx(single, rel=1e-3)


def test_strikes_and_a_close_neighbour_against_the_sample_sums():
    rate, n, sigma = 8000.0, 16000, 0.02
    f = np.array([500.0, 501.5, 900.0])
    d = np.array([3.0, 4.0, 20.0])
    gains = np.array([[1.0, 0.7, 0.5], [0.6, 0.9, 0.8]])
    onsets = np.array([0.0, 0.9])
    truth = Truth(f, d, gains, onsets, sigma, rate, n)
    joint = joint_decay_bounds(truth)
    numeric = numeric_decay_bounds(f, d, gains, onsets, sigma, rate, n, np.zeros_like(gains))
    np.testing.assert_allclose(joint, numeric, rtol=0.03)
    # the neighbour 1.5 Hz away raises the bound of mode 0 (same strikes, neighbour removed)
    apart = joint_decay_bounds(Truth(f[[0, 2]], d[[0, 2]], gains[:, [0, 2]], onsets, sigma, rate, n))
    assert joint[0] > 1.2 * apart[0]
    # the second strike lowers the bound of the isolated mode below its first strike's alone
    alone = crb_bounds(gains[0, 2], f[2], d[2], sigma, rate, int(0.9 * rate)).decay
    assert joint[2] < 0.95 * alone

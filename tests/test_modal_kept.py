"""The kernels that render a mode budget's kept modes (ugens.modal_kept)."""

import numpy as np
import pytest

from ugens.modal import bank_step
from ugens.modal_budget import line_aligned_zeros
from ugens.modal_kept import kept_step

FS = 48000


def ringing_rows(width, rng):
    """Compact-bank rows (c1, c2, g, d, y1, y2) of ``width`` modes ringing as
    A R^n sin(n theta + phi) from n = 0, and their (A, R, theta, phi)."""
    rows = line_aligned_zeros((6, width))
    amp, theta, phi = rng.uniform(0.5, 2.0, width), rng.uniform(0.01, 3.0, width), rng.uniform(0, 6, width)
    radius = np.exp(-rng.uniform(1.0, 30.0, width) / FS)
    rows[0], rows[1], rows[2] = 2 * radius * np.cos(theta), radius**2, 1e-3
    rows[4] = amp / radius * np.sin(phi - theta)  # y[-1]
    rows[5] = amp / radius**2 * np.sin(phi - 2 * theta)  # y[-2]
    return rows, (amp, radius, theta, phi)


def test_free_ringing_follows_the_decaying_sinusoids():
    """With no force the kept modes ring as sum_k A_k R_k^n sin(n theta_k + phi_k),
    over stretches of every length the eight-sample passes and their remainder take
    (flush frames at 1024 and 2048 inside)."""
    rng = np.random.default_rng(1)
    rows, (amp, radius, theta, phi) = ringing_rows(24, rng)
    n = np.arange(3001)[:, None]
    expected = np.sum(amp * radius**n * np.sin(n * theta + phi), axis=1)
    out, at, meta, last = np.zeros(3001), 0, np.array([24, 0, 24]), np.zeros(1)
    for size in (5, 8, 1000, 13, 1975):  # 3001 frames in spans of awkward lengths
        kept_step(np.zeros(size), out[at : at + size], at, size, rows, meta, 1e-12, last, np.zeros(0))
        at += size
    assert np.max(np.abs(out - expected)) < 1e-9 * np.max(np.abs(expected))
    assert meta[0] == 24 and last[0] == 0.0


def test_kept_modes_match_the_full_bank_kernel_with_forces_and_silences():
    """A force, then ringing, then a force again, then silence to the floor: the kept
    kernel gives the full bank kernel's output (ugens.modal.bank_step on the same rows),
    its silent modes flushed at the same frames, and the force copied to the ring."""
    rng = np.random.default_rng(2)
    rows, _ = ringing_rows(16, rng)
    rows[0] *= np.exp(-2000.0 / FS)  # decay fast enough to fall silent within the render
    rows[1] *= np.exp(-4000.0 / FS)
    frames = 6000
    force = np.zeros(frames)
    force[100:140] = rng.normal(size=40)
    force[3000:3010] = 1.0
    full_rows, kept_rows = rows.copy(), rows.copy()
    full_meta, kept_meta = np.array([16, 0, 16]), np.array([16, 0, 16])
    full, kept, ring = np.zeros(frames), np.zeros(frames), np.zeros(2048)
    full_last, kept_last = np.zeros(1), np.zeros(1)
    for at in range(0, frames, 700):
        size = min(700, frames - at)
        f = force[at : at + size]
        bank_step(f, full[at : at + size], at, size, full_rows, full_meta, 1e-10, full_last)
        kept_step(f, kept[at : at + size], at, size, kept_rows, kept_meta, 1e-10, kept_last, ring)
    assert np.max(np.abs(full[:3000])) > 1e-3
    assert np.max(np.abs(kept - full)) < 1e-12 * np.max(np.abs(full))
    assert kept_meta[0] == full_meta[0] == 0  # every mode fell silent and was flushed
    assert np.array_equal(ring[(np.arange(4096, 6000)) % 2048], force[4096:6000])


def test_ramp_passes_match_the_per_sample_ramp():
    """Coefficients ramping linearly under a force, the ramp ending inside a call and
    calls of lengths that are not multiples of four: the four-sample passes give
    ugens.modal.resonate_ramp's output (the same recursion, each sample with the
    current coefficients) to rounding, end the ramp on the same sample, on the target."""
    from ugens.modal import Ramp, resonate_ramp
    from ugens.modal_kept import ramp_passes

    rng = np.random.default_rng(3)
    width, frames, length = 16, 3000, 1234
    start, _ = ringing_rows(width, rng)
    end, _ = ringing_rows(width, rng)
    coef = np.vstack([start[:2], rng.uniform(0.5, 1.5, (2, width))])
    target = np.vstack([end[:2], rng.uniform(0.5, 1.5, (2, width))])
    force = rng.normal(size=frames)
    outputs, lefts = [], []
    for kernel in (resonate_ramp, ramp_passes):
        c = coef.copy()
        ramp = Ramp(c, (target - coef) / length, target.copy())
        y1, y2 = start[4].copy(), start[5].copy()
        out, last, left, at = np.zeros(frames), np.zeros(1), length, 0
        for size in (7, 1001, 3, 226, 1763):  # the ramp ends inside the fourth call
            left = kernel(force[at : at + size], out[at : at + size], size, ramp, y1, y2, left, width, last)
            lefts.append(left)
            at += size
        assert np.array_equal(c, target)
        outputs.append(out)
    reference, passes = outputs
    assert np.max(np.abs(reference)) > 1.0
    assert np.max(np.abs(passes - reference)) < 1e-11 * np.max(np.abs(reference))
    assert lefts[:5] == lefts[5:] and lefts[4] == 0


def test_force_scan_finds_every_kind_of_nonzero_sample():
    """jassy.anytime_rank.has_force (the kept and full bank kernels' and the budget's
    force test, a vectorised sum of magnitudes) against numpy's ``!= 0`` on stretches
    holding one sample of each awkward kind (a subnormal, -0.0, NaN, inf) at positions
    around its 64-sample blocks, and on samples whose signed sum cancels or overflows."""
    from jassy.anytime_rank import has_force

    rng = np.random.default_rng(4)
    kinds = (5e-324, -5e-324, -0.0, np.nan, np.inf, -np.inf, 1e300, -2.0)
    checked = found = 0
    for size in (0, 1, 63, 64, 65, 200, 4096):
        for kind in kinds:
            for at in sorted({0, size // 2, size - 1, 63, 64, 127}):
                if not 0 <= at < size:
                    continue
                force = np.zeros(size)
                force[at] = kind
                for begin, end in (
                    (0, size),
                    (at, at + 1),
                    (at + 1, size),
                    (0, at),
                    (at // 2, min(size, at + 70)),
                ):
                    expected = bool(np.any(force[begin:end] != 0.0))
                    assert has_force(force, begin, end) == expected, (size, kind, at, begin, end)
                    checked += 1
                    found += expected
    big = rng.normal(size=4096) * 1e300  # magnitudes whose sum overflows to inf
    assert has_force(big, 0, 4096) and not has_force(np.zeros(4096), 0, 4096)
    cancelling = np.zeros(128)
    cancelling[[70, 71]] = 1.0, -1.0  # a signed sum would miss them
    assert has_force(cancelling, 0, 128) and has_force(cancelling, 64, 128)
    assert checked > 900 and 0 < found < checked


@pytest.mark.parametrize("width, audible", [(32, 29), (8, 3)])
def test_flush_leaving_part_of_a_vector_gives_the_full_kernels_output(width, audible):
    """Kept modes past ``audible`` decay fast and are flushed at frame 1024: the kernel
    goes on computing whole vectors (29 of 32: their columns hold exact zeros) or, at most
    half a vector audible (3 of 8), the audible modes alone, and gives the full bank
    kernel's output (which computes the audible modes past its last whole vector one by
    one), its active count the last audible mode + 1."""
    rng = np.random.default_rng(5)
    rows, _ = ringing_rows(width, rng)
    fast = np.exp(-20000.0 / FS)  # -180 dB within 1024 frames
    rows[0, audible:] *= fast
    rows[1, audible:] *= fast**2
    frames = 4096
    full_rows, kept_rows = rows.copy(), rows.copy()
    full_meta, kept_meta = np.array([width, 0, width]), np.array([width, 0, width])
    full, kept = np.zeros(frames), np.zeros(frames)
    for at in range(0, frames, 1500):
        size = min(1500, frames - at)
        f = np.zeros(size)
        bank_step(f, full[at : at + size], at, size, full_rows, full_meta, 1e-10, np.zeros(1))
        kept_step(f, kept[at : at + size], at, size, kept_rows, kept_meta, 1e-10, np.zeros(1), np.zeros(0))
    assert kept_meta[0] == full_meta[0] == audible
    assert not np.any(kept_rows[4:, audible:])  # the flushed modes' state: exact zeros
    assert np.max(np.abs(kept - full)) < 1e-12 * np.max(np.abs(full))


@pytest.mark.parametrize("modes", [8, 24, 32, 64, 80])
def test_ring_passes_in_explicit_vectors_give_rings_samples_and_state(modes):
    """ugens.modal_kept.ring_kept (whole vectors of modes: eight-sample passes in explicit
    LLVM vectors, by the squared pole's recursion, the sums reduced together) gives ring's
    samples and state to rounding, over a stretch that is not whole passes; a count of
    modes that is not whole vectors runs ring itself (the same bits)."""
    from ugens.modal_kept import ring, ring_kept

    rng = np.random.default_rng(modes)
    rows, _ = ringing_rows(modes, rng)
    for active in (modes, modes - 3):
        ours, theirs = rows.copy(), rows.copy()
        out, reference = np.full(1001, np.nan), np.full(1001, np.nan)
        ring_kept(out, 1001, ours[0], ours[1], ours[4], ours[5], active)
        ring(reference, 1001, theirs[0], theirs[1], theirs[4], theirs[5], active)
        if active % 8:
            assert np.array_equal(out, reference) and np.array_equal(ours, theirs)
        else:
            # the squared pole's recursion rounds differently: up to ~5e-12 over 200 seeds
            assert np.max(np.abs(out - reference)) < 1e-11 * np.max(np.abs(reference))
            assert np.max(np.abs(ours - theirs)) < 1e-11 * np.max(np.abs(theirs))


@pytest.mark.parametrize("modes", [8, 32, 48])
def test_forced_passes_in_explicit_vectors_give_resonates_samples_and_state(modes):
    """ugens.modal_kept.resonate_kept (whole vectors of modes: eight-sample passes in
    explicit LLVM vectors, the direct term added after) gives ugens.modal.resonate's
    samples, state and last force sample to rounding, over a force with silent stretches
    and a length that is not whole passes; a count of modes that is not whole vectors
    runs resonate itself (the same bits)."""
    from ugens.cells import ModeRows
    from ugens.modal import resonate
    from ugens.modal_kept import resonate_kept

    rng = np.random.default_rng(modes)
    rows, _ = ringing_rows(modes, rng)
    rows[2] = rng.uniform(1e-4, 1e-3, modes)  # g
    rows[3] = rng.uniform(1e-7, 1e-6, modes)  # d
    force = rng.normal(size=1003)
    force[200:500] = 0.0
    for active in (modes, modes - 3):
        ours, theirs = rows.copy(), rows.copy()
        out, reference = np.full(1003, np.nan), np.full(1003, np.nan)
        last, last_reference = np.array([0.4]), np.array([0.4])
        resonate_kept(force, out, 1003, ModeRows(*ours), active, last)
        resonate(force, reference, 1003, ModeRows(*theirs), active, last_reference)
        assert last[0] == last_reference[0] == force[-1]
        if active % 8:
            assert np.array_equal(out, reference) and np.array_equal(ours, theirs)
        else:
            assert np.max(np.abs(out - reference)) < 1e-12 * np.max(np.abs(reference))
            assert np.max(np.abs(ours - theirs)) < 1e-12 * np.max(np.abs(theirs))


def test_hear_copies_the_last_period_of_any_span_into_the_ring():
    """ugens.modal_kept.hear: frame t of a span goes to ring[t % size], spans shorter and
    longer than the ring and wrapping around its end; samples outside it stay."""
    from ugens.modal_kept import hear

    rng = np.random.default_rng(4)
    size = 64
    for start, n in ((0, 10), (60, 9), (5, 64), (37, 200), (128, 64)):
        ring = rng.normal(size=size)
        want = ring.copy()
        force = rng.normal(size=n)
        frames = np.arange(start, start + n)[-size:]
        want[frames % size] = force[-size:]
        hear(force, n, ring, start)
        assert np.array_equal(ring, want), (start, n)


def test_silence_writes_zeros_past_the_known_ones_and_extends_them():
    """ugens.modal_kept.silence on a buffer of non-zero samples whose first ``zeros[b]``
    are known zero: the span [offset, offset + n) reads zero afterwards, the samples
    before the known count and outside the span keep their values (were not written),
    and the count reaches the span's end only if the span joins the known zeros."""
    from jassy.jit import address
    from ugens.modal_kept import silence

    for known, offset, n, count in (
        (100, 20, 50, 100),
        (100, 80, 50, 130),
        (100, 100, 8, 108),
        (40, 60, 8, 40),
    ):
        out = np.arange(1.0, 201.0)  # none zero: a sample the call skips keeps its value
        zeros = np.array([0, known])
        silence(address(out), zeros, 1, offset, n)
        want = np.arange(1.0, 201.0)
        want[max(offset, known) : offset + n] = 0.0
        assert np.array_equal(out, want) and zeros[1] == count, (known, offset, n)

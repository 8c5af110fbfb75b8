"""ModalBank precision="mixed": float32 delta-form modes where the error bound allows, float64
for the rest, against the closed-form modal response and the float64 bank."""

import numpy as np
import pytest
from helpers import ArraySource
from test_modal_bank import FS, error_db, spread_model

from jassy import Event, Graph, ModalModel, render
from ugens.cells import ModeRows
from ugens.modal import ModalBank, design, split_by_precision
from ugens.modal_f32 import (
    HELD_MODES,
    LANES,
    TOLERANCE,
    WIDE_LANES,
    DeltaRows,
    decay_factor_error,
    delta_coefficients,
    factor_coefficient,
    float32_error,
    flush_silent_delta,
    narrow_rows,
    order_by_form,
    resonate_delta,
    resonate_narrow,
)
from ugens.modal_meta import DELTA_END, NARROW_ALL

FREQS = np.geomspace(20.0, 20000.0, 7)
DECAYS = np.geomspace(0.5, 500.0, 7)


def mixed_impulse_response(model, seconds, precision="mixed", block=4096):
    x = np.zeros(int(seconds * FS))
    x[0] = FS
    bank = ModalBank(model, precision=precision)(ArraySource(x))
    return render(Graph(bank), [], seconds, FS, block, limiter=False).audio[0]


def test_mixed_bank_holds_minus_60_db_over_the_whole_decay_on_the_grid():
    """Each mode of the grid 20 Hz - 20 kHz x 0.5 - 500 /s alone, until e^{-d t} < e^-8,
    against a e^{-d t} sin(2 pi f t); the bound that chose its precision and form is never
    below the measured error, most modes run in float32, and both forms are used."""
    n32 = by_factor = 0
    for f in FREQS:
        for d in DECAYS:
            model = ModalModel([f], [d], [[1.0]])
            seconds = min(8.0 / d, 16.0)
            y = mixed_impulse_response(model, seconds)
            ref = model.impulse_response(seconds, FS)
            err = error_db(y[1:], ref[1:])
            assert err < -60.0, (f, d, err)
            c1, c2, _ = design(model.frequencies, model.decays, FS)
            bound = float32_error(c1, c2, FS)[0]
            if bound <= TOLERANCE:
                n32 += 1
                factor_bound = decay_factor_error(c1, c2, FS)[0]
                if factor_bound <= TOLERANCE:
                    by_factor += 1
                    bound = factor_bound
                assert err < 20 * np.log10(bound) + 1.0, (f, d, err, bound)
    assert n32 >= 0.9 * FREQS.size * DECAYS.size
    assert 0.5 * n32 <= by_factor < n32


def float32_only_response(f, d, seconds, decay_factor=False):
    """A single mode forced into float32 (no bound), through the kernel in the delta form
    or the decay-factor form."""
    c1, c2, s = design(np.array([f]), np.array([d]), FS)
    c0, b2 = delta_coefficients(c1, c2)
    zero = np.zeros(1)
    delta_end = 0 if decay_factor else LANES
    coef, state = narrow_rows(c0, b2, s, zero, zero, zero, delta_end)
    x = np.zeros(int(seconds * FS))
    x[0] = 1.0
    out = np.full(x.size, np.nan)  # (written, not added to)
    resonate_narrow(x, out, x.size, DeltaRows(*coef, *state), 1, None, 0, np.zeros(1), delta_end)
    return out


def test_the_bound_is_needed_very_high_q_modes_fail_in_float32():
    """20 kHz, d = 0.5 /s (omega / d = 2.5e5): the delta form's coefficient rounding alone
    moves the response by more than -60 dB, and the bound says so; the mixed bank keeps it
    in float64."""
    f, d, seconds = 20000.0, 0.5, 6.0
    ref = ModalModel([f], [d], [[1.0]]).impulse_response(seconds, FS)
    assert error_db(float32_only_response(f, d, seconds)[1:], ref[1:]) > -60.0
    c1, c2, _ = design(np.array([f]), np.array([d]), FS)
    assert float32_error(c1, c2, FS)[0] > 10 ** (-60 / 20)
    # the same kernel on a low, light mode (where the two-pole float32 form fails) is fine
    f, d = 20.0, 0.5
    ref = ModalModel([f], [d], [[1.0]]).impulse_response(seconds, FS)
    assert error_db(float32_only_response(f, d, seconds)[1:], ref[1:]) < -80.0
    # in the decay-factor form (R^2 rounded) its decay drifts past -70 dB, and that bound says so
    c1, c2, _ = design(np.array([f]), np.array([d]), FS)
    assert error_db(float32_only_response(f, d, seconds, decay_factor=True)[1:], ref[1:]) > -70.0
    assert decay_factor_error(c1, c2, FS)[0] > TOLERANCE


def test_mixed_bank_passes_where_float32_two_pole_fails():
    """The modes of test_modal_bank's float32 failure (low, lightly damped): in float32."""
    model = ModalModel([20.0, 31.0, 45.0], [0.5, 0.6, 0.8], [[1.0, 1.0, 1.0]])
    c1, c2, _ = design(model.frequencies, model.decays, FS)
    assert np.all(float32_error(c1, c2, FS) <= TOLERANCE)
    ref = model.impulse_response(2.0, FS)
    assert error_db(mixed_impulse_response(model, 2.0, block=64)[1:], ref[1:]) < -80.0


def render_bank(model, precision, score=(), seconds=0.5, block=64):
    """(audio, the ModalBank that rendered it) for a broadband force that then stops."""
    x = np.random.default_rng(0).standard_normal(int(seconds * FS))
    x[FS // 4 :] = 0.0  # then ring out (silent-mode skipping in both parts)
    bank = ModalBank(model, name="bank", precision=precision)(ArraySource(x))
    return render(Graph(bank), list(score), seconds, FS, block, limiter=False).audio[0], bank


def render_noise(model, precision, score=(), seconds=0.5, block=64):
    return render_bank(model, precision, score, seconds, block)[0]


def takes_a_held_kernel(split):
    """Whether ugens.modal_f32.resonate_narrow runs this split's passes with the rows held on
    the stack (resonate_held): no float64 modes, the decay-factor form, at most HELD_MODES
    float32 modes."""
    meta = split.rows.narrow_meta
    return split.wide.size == 0 and meta[DELTA_END] == 0 and 0 < meta[NARROW_ALL] <= HELD_MODES


@pytest.mark.parametrize("block", [1, 64, 1000])
@pytest.mark.parametrize("modes", ["split", "all_float32", "small"])
def test_mixed_bank_follows_the_float64_bank_with_noise_and_parameter_changes(block, modes):
    """Broadband force, a ramped freq_scale change (run in float64, then back to mixed) and a
    location jump: within -60 dB of the float64 bank at any block size, with and without
    float64 modes in the split, and for a bank small enough for a held kernel (which the
    rendered bank's own split takes after the changes)."""
    model = spread_model(12 if modes == "small" else 40)
    if modes != "split":  # (the small bank's modes kept below 10 kHz: at 24 kHz it would need float64)
        top = 0.5 if modes == "small" else 1.0
        model = ModalModel(top * model.frequencies, np.maximum(model.decays, 5.0), model.gains)
    score = [
        Event(0.1, "bank", "set", {"freq_scale": 1.2}, ramp=0.01),
        Event(0.2, "bank", "set", {"location": 1}, jump=True),
    ]
    ref = render_noise(model, "float64", score, block=block)
    y, bank = render_bank(model, "mixed", score, block=block)
    assert takes_a_held_kernel(bank._split) == (modes == "small")
    assert error_db(y, ref) < -60.0


@pytest.mark.parametrize("count", [16, 17, 64, 65])
def test_banks_of_up_to_64_float32_modes_take_a_held_kernel(count):
    """Around the held kernels' sizes (16, 32, 64 modes; HELD_MODES = 64): the rendered
    bank's own split holds its rows on the stack up to 64 modes, runs the general kernel
    at 65, and each follows the float64 bank within -60 dB."""
    model = spread_model(count)
    model = ModalModel(0.5 * model.frequencies, np.maximum(model.decays, 5.0), model.gains)
    ref = render_noise(model, "float64")
    y, bank = render_bank(model, "mixed")
    assert bank._split.rows.narrow_meta[NARROW_ALL] == count
    assert takes_a_held_kernel(bank._split) == (count <= HELD_MODES)
    assert error_db(y, ref) < -60.0


def _narrow_and_general(count, wide_count, seed, delta_end=0):
    """resonate_narrow and resonate_delta run on the same rows of ``count`` random float32
    modes (the first ``delta_end`` in the delta form, the rest in the decay-factor form; and
    ``wide_count`` float64 modes, on rows padded with silent modes to whole WIDE_LANES as
    split_by_precision pads them) over calls of odd lengths (the 4-sample passes and the
    tail, the force sample carried between calls), with the direct term: the force, then
    (out, state, float64 rows, last force sample) of each."""
    rng = np.random.default_rng(seed)
    f, d = np.geomspace(100.0, 15000.0, count), rng.uniform(5.0, 200.0, count)
    c1, c2, s = design(f, d, FS)
    c0, b2 = delta_coefficients(c1, c2)
    zeros = np.zeros(count)
    coef, _ = narrow_rows(c0, b2, s, 0.1 * s, zeros, zeros, delta_end)
    padded = np.zeros((3, -(-wide_count // WIDE_LANES) * WIDE_LANES))
    padded[:, :wide_count] = design(np.geomspace(6000.0, 9000.0, wide_count), np.full(wide_count, 0.5), FS)
    w1, w2, ws = padded
    force = rng.standard_normal(3001)
    runs = []
    for kernel, out in (
        (resonate_narrow, np.full(force.size, np.nan)),
        (resonate_delta, np.zeros(force.size)),
    ):
        state = np.zeros((2, coef.shape[1]), np.float32)
        z = np.zeros(w1.size)
        wide = ModeRows(w1, w2, ws, 0.1 * ws, z.copy(), z.copy()) if wide_count else None
        rows, last, start = DeltaRows(*coef, *state), np.zeros(1), 0
        for n in (1, 7, 1000, 993, 1000):
            kernel(force[start:], out[start:], n, rows, count, wide, wide_count, last, delta_end)
            start += n
        runs.append((out, state, wide, last[0]))
    return force, runs


@pytest.mark.parametrize("count", [5, 16, 17, 40, 64])
def test_the_held_kernels_compute_what_the_general_kernel_does(count):
    """resonate_narrow's held kernels (rows on the stack, 16, 32 or 64 of them; they write
    the output) against resonate_delta's general loop (which adds to it) on the same rows:
    same outputs and state to float32 rounding over calls of odd lengths (the 4-sample
    passes and the tail, the force sample carried between calls), with the direct term."""
    force, runs = _narrow_and_general(count, 0, seed=5)
    (out, state, _, last), (ref, ref_state, _, ref_last) = runs
    assert np.max(np.abs(ref)) > 0 and last == ref_last == force[-1]
    np.testing.assert_allclose(out, ref, rtol=1e-6, atol=1e-6 * np.max(np.abs(ref)))
    state, ref_state = state[:, :count], ref_state[:, :count]  # (the padding modes run apart)
    np.testing.assert_allclose(state, ref_state, rtol=1e-6, atol=1e-6 * np.max(np.abs(ref_state)))


@pytest.mark.parametrize(
    "count, wide_count, delta_end",
    [
        (20, 2, 0),
        (100, 0, 0),
        (100, 3, 0),
        (100, 8, 0),
        (100, 9, 0),
        (100, 17, 0),
        (100, 0, 32),
        (100, 3, 64),
        (100, 0, 128),
    ],
)
def test_the_vector_pass_kernel_computes_what_the_general_kernel_does(count, wide_count, delta_end):
    """resonate_narrow's kernel for banks a held kernel does not take (more than 64 float32
    modes, float64 modes or modes in the delta form: resonate_chunks, 32 modes per explicit
    vector step in the form of their chunk; it writes the output) against resonate_delta's
    general loop (which adds to it) on the same rows: same outputs and states to float32
    rounding over calls of odd lengths, with the direct term and float64 modes updated in
    the same passes to float64 rounding (up to 2 WIDE_LANES as vectors: 2, 3, 8, 9 of
    them; 17 in the scalar pass), in the decay-factor form, the delta form and both."""
    force, runs = _narrow_and_general(count, wide_count, seed=6, delta_end=delta_end)
    (out, state, wide, last), (ref, ref_state, ref_wide, ref_last) = runs
    assert np.max(np.abs(ref)) > 0 and last == ref_last == force[-1]
    np.testing.assert_allclose(out, ref, rtol=1e-6, atol=1e-6 * np.max(np.abs(ref)))
    state, ref_state = state[:, :count], ref_state[:, :count]
    np.testing.assert_allclose(state, ref_state, rtol=1e-6, atol=1e-6 * np.max(np.abs(ref_state)))
    if wide_count:
        assert np.max(np.abs(ref_wide.y1)) > 0
        np.testing.assert_allclose(wide.y1, ref_wide.y1, rtol=1e-12, atol=1e-12 * np.max(np.abs(ref_wide.y1)))


@pytest.mark.parametrize("wrong", ["force", "out"])
def test_the_explicit_vector_kernels_refuse_float32_force_or_output(wrong):
    """The explicit-vector passes (ugens.vector_pass) read the force and write the output
    as float64 vectors: resonate_narrow with a float32 force or output is refused at typing
    (at 16 modes it gave a relative error of 0.62 and read or wrote past the array)."""
    count = 16
    from numba.core.errors import TypingError

    c1, c2, s = design(np.geomspace(100.0, 15000.0, count), np.full(count, 20.0), FS)
    c0, b2 = delta_coefficients(c1, c2)
    zeros = np.zeros(count)
    coef, state = narrow_rows(c0, b2, s, zeros, zeros, zeros, delta_end=0)
    arrays = {"force": np.ones(64), "out": np.zeros(64)}
    arrays[wrong] = arrays[wrong].astype(np.float32)
    with pytest.raises(TypingError, match="write_four|add_chunk|write_sums"):
        resonate_narrow(
            arrays["force"], arrays["out"], 64, DeltaRows(*coef, *state), count, None, 0, np.zeros(1), 0
        )


def test_rows_shorter_than_a_held_kernel_take_the_general_loop():
    """20 modes on rows of exactly 20 (not padded by narrow_rows to 32): the 32-mode held
    kernel would read past them, so resonate_narrow runs the general loop (resonate_delta,
    which stops at the rows' end) and writes what it adds."""
    rng = np.random.default_rng(7)
    count = 20
    c1, c2, s = design(np.geomspace(100.0, 15000.0, count), rng.uniform(5.0, 200.0, count), FS)
    c0, b2 = delta_coefficients(c1, c2)
    coef = np.stack([c0, b2, s, 0.1 * s]).astype(np.float32)
    coef[1] = factor_coefficient(c0, b2)
    force = rng.standard_normal(1001)
    outs = []
    for kernel, out in (
        (resonate_narrow, np.full(force.size, np.nan)),
        (resonate_delta, np.zeros(force.size)),
    ):
        rows = DeltaRows(*coef, *np.zeros((2, count), np.float32))
        kernel(force, out, force.size, rows, count, None, 0, np.zeros(1), 0)
        outs.append(out)
    assert np.max(np.abs(outs[1])) > 0
    np.testing.assert_array_equal(outs[0], outs[1])


def test_zero_gain_modes_stay_in_float64_and_keep_ringing_after_their_gain_drops():
    """The float32 state is scaled by 1 / g, so modes with g = 0 stay in float64; a mode
    still ringing when a location jump sets its gain to 0 rings on (the gain weighs the
    input, not the state), as in the float64 bank."""
    model = ModalModel([200.0, 700.0, 1500.0], [3.0, 5.0, 8.0], [[1.0, 0.5, -0.8], [1.0, 0.0, 0.0]])
    c1, c2, s = design(model.frequencies, model.decays, FS)
    bank = np.stack([c1, c2, s * model.gains[1], np.zeros(3), np.zeros(3), np.zeros(3)])
    split = split_by_precision(bank, FS)
    assert split.wide.tolist() == [1, 2] and split.narrow.tolist() == [0]
    score = [Event(0.3, "bank", "set", {"location": 1}, jump=True)]
    ref = render_noise(model, "float64", score)
    y = render_noise(model, "mixed", score)
    tail = slice(int(0.3 * FS), None)  # after the jump: only the rings of modes 2 and 3 (and mode 1)
    assert np.max(np.abs(ref[tail])) > 0.1 * np.max(np.abs(ref))
    assert error_db(y, ref) < -60.0


def test_the_benchmarks_c_float32_reference_computes_the_two_pole_recursion():
    """The bench's C loop (compiled now with cc) against the float64 kernel: it is the same
    recursion, to float32 rounding, on mid-band well-damped modes."""
    from jassy.apps.bench_c import c_runner, compile_modal_f32
    from ugens.modal import resonate

    fn, note = compile_modal_f32()
    if fn is None:
        pytest.skip(note)
    f, d = np.array([300.0, 1000.0, 3000.0, 5000.0, 7000.0]), np.full(5, 50.0)
    c1, c2, s = design(f, d, FS)
    force = np.random.default_rng(2).standard_normal(4099)
    run = c_runner(fn, force, c1, c2, s)
    run()
    ref = np.zeros(force.size)
    z = np.zeros(5)
    resonate(force, ref, force.size, ModeRows(c1, c2, s, z, z.copy(), z.copy()), 5, np.zeros(1))
    assert error_db(run.output.astype(np.float64), ref) < -60.0
    # loading the -ffast-math library must not switch the process to flush-to-zero
    tiny = np.finfo(np.float64).smallest_subnormal
    assert np.float64(tiny) * np.float64(3.0) / np.float64(2.0) > 0.0


def test_the_float32_bench_compares_like_for_like():
    """``jassy bench float32`` on one small bank: its jassy kernel (padded rows, as the
    ModalBank) computes the float64 recursion to -80 dB, more closely than the C float32
    two-pole loop it is timed against."""
    from jassy.apps.bench_f32 import float32_bench

    (row,) = float32_bench((20,), rounds=1, repeats=1)
    assert row["kernel_error_db"] < -80.0
    if "c_error_db" in row:
        assert row["c_error_db"] > row["kernel_error_db"]
        assert all(r > 0 for r in row["kernel_vs_c"] + row["bank_vs_c"])


def test_only_the_chunk_of_modes_that_need_it_runs_in_the_delta_form():
    """100 modes, 3 of them low and light (20, 40 and 60 Hz at d = 0.5 /s, where the
    decay-factor form misses the tolerance, :func:`decay_factor_error`): the split puts
    those 3 first, the first chunk of LANES float32 modes in the delta form (row 1 b2) and
    the rest in the decay-factor form (R^2 - c0); the mixed bank follows the float64 bank
    within -60 dB."""
    f, d = np.geomspace(100.0, 8000.0, 100), np.full(100, 20.0)
    light = [10, 50, 90]
    f[light], d[light] = [20.0, 40.0, 60.0], 0.5
    model = ModalModel(f, d, np.random.default_rng(3).uniform(0.5, 1.0, (1, 100)))
    c1, c2, s = design(model.frequencies, model.decays, FS)
    order, delta_end = order_by_form(c1, c2, FS)
    assert sorted(order[:3]) == light and sorted(order) == list(range(100)) and delta_end == LANES
    split = split_by_precision(np.stack([c1, c2, s, 0 * s, 0 * s, 0 * s]), FS)
    assert split.rows.narrow_meta[DELTA_END] == LANES and split.rows.narrow_meta[NARROW_ALL] == 100
    c0, b2 = delta_coefficients(c1[split.narrow], c2[split.narrow])
    row = split.rows.narrow_coef[1, :100]
    np.testing.assert_array_equal(row[:LANES], b2[:LANES].astype(np.float32))
    np.testing.assert_array_equal(row[LANES:], factor_coefficient(c0, b2)[LANES:])
    ref = render_noise(model, "float64")
    assert error_db(render_noise(model, "mixed"), ref) < -60.0


def test_the_flush_zeroes_silent_float32_modes_and_counts_to_the_last_audible_one():
    """flush_silent_delta (written without branches): the modes whose g y and g dy are both
    below the floor get zero state, the others keep theirs, and the active count becomes
    the last audible mode + 1 (the silent tail is not counted)."""
    rng = np.random.default_rng(8)
    y, dy = (rng.standard_normal(40) * 10 ** rng.uniform(-9, 0, 40) for _ in range(2))
    y, dy = y.astype(np.float32), dy.astype(np.float32)
    y[30:], dy[30:] = 1e-12, -1e-12
    g = rng.uniform(0.5, 2.0, 40).astype(np.float32)
    floor = 1e-6
    silent = (np.abs(g * y) < floor) & (np.abs(g * dy) < floor)
    assert 0 < silent[:30].sum() < 30
    expect_y, expect_dy = np.where(silent, 0.0, y), np.where(silent, 0.0, dy)
    active = flush_silent_delta(y, dy, g, 40, floor)
    assert active == np.flatnonzero(~silent).max() + 1 <= 30
    np.testing.assert_array_equal(y, expect_y)
    np.testing.assert_array_equal(dy, expect_dy)


@pytest.mark.parametrize("delta_end", [5, 40])
def test_a_delta_end_within_a_chunk_takes_the_general_loop(delta_end):
    """resonate_chunks runs whole 32-mode chunks of one form: a delta_end inside a chunk
    takes resonate_delta (before, chunks overlapped, skipped modes and wrote past rows of
    exactly the bank's length)."""
    from ugens.modal import design
    from ugens.modal_f32 import DeltaRows, delta_coefficients, narrow_rows, resonate_delta, resonate_narrow

    count, frames = 64, 64
    c1, c2, gain = design(np.geomspace(100.0, 8000.0, count), np.full(count, 20.0), 48000.0)
    c0, b2 = delta_coefficients(c1, c2)
    force = np.random.default_rng(0).standard_normal(frames)
    coefficients, state = narrow_rows(c0, b2, gain, 0 * gain, 0 * gain, 0 * gain, delta_end)
    guarded = [np.full(count + 16, 777.0, np.float32) for _ in range(6)]  # rows, then 16 guards
    for buffer, row in zip(guarded, [*coefficients[:, :count], *state[:, :count]], strict=True):
        buffer[:count] = row
    out, reference = np.zeros(frames), np.zeros(frames)
    rows = DeltaRows(*(buffer[:count] for buffer in guarded))
    resonate_narrow(force, out, frames, rows, count, None, 0, np.zeros(1), delta_end)
    general = DeltaRows(*coefficients[:, :count].copy(), *state[:, :count].copy())
    resonate_delta(force, reference, frames, general, count, None, 0, np.zeros(1), delta_end)
    assert all(np.all(buffer[count:] == 777.0) for buffer in guarded)
    assert np.array_equal(out, reference)

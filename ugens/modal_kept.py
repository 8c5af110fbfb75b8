"""Kernels that render a mode budget's kept modes (jassy.anytime): each budgeted bank's
compact bank of kept modes (ugens.modal_budget), all banks in one compiled call.

A compact bank holds only the modes the budget computes, in whole vectors of KEPT_LANES
(its padding holds exact zeros). Most of a struck object's sound is free ringing: a
stretch (between two flush frames) with no force sample and no force before it runs
:func:`ring_kept`, the recursion without its input term, eight samples per pass; a
stretch with a force runs ugens.modal's full recursion (:func:`resonate_kept`, as
:func:`ugens.modal.resonate`).
The free recursion is the same sum of the same products with a zero input, so it changes
no more than rounding: c1 y1 - c2 y2 + g * 0.
"""

from __future__ import annotations

import numba as nb
import numpy as np
from llvmlite import ir
from numba.core import cgutils, types
from numba.extending import intrinsic

from jassy import anytime_rank, record_views
from jassy.anytime_rank import (
    ANY_EXPECTED,
    DECISIONS,
    EVERY_PERIOD,
    FADING,
    INLINE,
    PEAK,
    RENDERS,
    Hearing,
    Kicks,
    has_force,
    hearing_at,
    kicks_at,
    note_decided,
    scan_forces,
    steady_forces,
)
from jassy.jit import drop_stale_cache, void_pointer
from jassy.record_views import FIELD, bool_row, int_row
from ugens import (
    cells,
    kernels,
    modal,
    modal_block,
    modal_budget,
    modal_meta,
    modal_retune,
    real_fft,
    vector_ir,
)
from ugens.cells import ModeRows, is_flush_frame, mode_rows, two_pole, until_flush
from ugens.kernels import FASTMATH
from ugens.modal import Ramp, flush_silent, resonate, resonate_ramp
from ugens.modal_block import BLOCK_MODES, block_resonate, current_table
from ugens.modal_budget import (
    BANK_ROWS,
    COEF_ROWS,
    FLOOR,
    KEPT_LANES,
    RAMP_DELTA,
    RAMP_TARGET,
    RING_POWER,
    TABLE_FIELDS,
    Rates,
    compact_bank,
    decide,
    decision_at,
    load_impacts,
    settle_compact,
    tables_at,
)
from ugens.modal_meta import ACTIVE, ALLOWED, RAMP_LEFT, WIDTH
from ugens.modal_retune import COEF_C1, COEF_C2, COEF_DIRECT, COEF_GAIN
from ugens.vector_ir import DOUBLE, UPDATE_FLAGS, broadcast, contiguous, fma, row_pointer, shuffle

drop_stale_cache(
    __file__,
    [
        anytime_rank,
        cells,
        kernels,
        modal,
        modal_block,
        modal_budget,
        modal_meta,
        modal_retune,
        real_fft,
        record_views,
        vector_ir,
    ],
)  # the cache holds copies of their kernels (real_fft through modal_budget.decide) and FASTMATH


@nb.njit(fastmath=FASTMATH, cache=True)
def ring(out, n, c1, c2, y1, y2, active):
    """Modes [0, active) ringing freely (no force now or in the sample before) for n
    samples: y[n] = c1 y[n-1] - c2 y[n-2], their sum into out[:n] (overwritten). Eight
    samples per pass over the modes: each mode's state and coefficients are loaded once
    per eight samples, and the sums' reduction across the mode vector is shared by more
    samples (a four-sample pass cost 4.6 against 3.7 ns per sample for 32 modes)."""
    i = 0
    while i + 8 <= n:
        s0 = s1 = s2 = s3 = s4 = s5 = s6 = s7 = 0.0
        for k in range(active):
            p = c1[k]
            q = c2[k]
            v0 = p * y1[k] - q * y2[k]
            v1 = p * v0 - q * y1[k]
            v2 = p * v1 - q * v0
            v3 = p * v2 - q * v1
            v4 = p * v3 - q * v2
            v5 = p * v4 - q * v3
            v6 = p * v5 - q * v4
            v7 = p * v6 - q * v5
            y2[k] = v6
            y1[k] = v7
            s0 += v0
            s1 += v1
            s2 += v2
            s3 += v3
            s4 += v4
            s5 += v5
            s6 += v6
            s7 += v7
        out[i] = s0
        out[i + 1] = s1
        out[i + 2] = s2
        out[i + 3] = s3
        out[i + 4] = s4
        out[i + 5] = s5
        out[i + 6] = s6
        out[i + 7] = s7
        i += 8
    while i < n:
        s = 0.0
        for k in range(active):
            v = c1[k] * y1[k] - c2[k] * y2[k]
            y2[k] = y1[k]
            y1[k] = v
            s += v
        out[i] = s
        i += 1


def _transposed_sum(builder, sums):
    """The vector of the lane sums of ``sums`` (KEPT_LANES vectors of KEPT_LANES lanes):
    lane j holds the sum of sums[j]'s lanes. Pairs of vectors are interleaved and added,
    then pairs of those, log2(KEPT_LANES) times: 14 shuffles and 7 adds for eight sums
    of eight lanes, where reducing each alone takes 24 of each."""
    level, width = list(sums), 1
    while len(level) > 1:
        first = [i if (i // width) % 2 == 0 else i - width + KEPT_LANES for i in range(KEPT_LANES)]
        second = [i + width if (i // width) % 2 == 0 else i + KEPT_LANES for i in range(KEPT_LANES)]
        level = [
            builder.fadd(shuffle(builder, a, b, first), shuffle(builder, a, b, second), flags=UPDATE_FLAGS)
            for a, b in zip(level[::2], level[1::2], strict=True)
        ]
        width *= 2
    return level[0]


#: Vectors of modes whose ringing coefficients :func:`ring_passes` holds at once (on the
#: stack: :data:`RING_COEFFICIENTS` vectors each), and those coefficients per vector.
RING_CHUNK, RING_COEFFICIENTS = 8, 6


def _ring_coefficients(builder, c1, c2):
    """The coefficients of :func:`_free_response` for modes (vectors) c1, c2: c1, c1^2 - c2,
    -c2, -c1 c2, c1^2 - 2 c2 and -c2^2."""
    minus_c2 = builder.fneg(c2, flags=UPDATE_FLAGS)
    c1_squared = builder.fmul(c1, c1, flags=UPDATE_FLAGS)
    return [
        c1,
        builder.fadd(c1_squared, minus_c2, flags=UPDATE_FLAGS),
        minus_c2,
        builder.fmul(minus_c2, c1, flags=UPDATE_FLAGS),
        fma(builder, minus_c2, ir.Constant(c1.type, [2.0] * KEPT_LANES), c1_squared),
        builder.fneg(builder.fmul(c2, c2, flags=UPDATE_FLAGS), flags=UPDATE_FLAGS),
    ]


def _free_response(builder, coefficients, y1, y2):
    """The next KEPT_LANES samples of modes (vectors) ringing freely from y1 = y[-1],
    y2 = y[-2] (``coefficients``: :func:`_ring_coefficients`): y[0] and y[1] from the
    state (y[1] = (c1^2 - c2) y1 - c1 c2 y2), then the even and the odd samples each by
    the recursion of the squared pole, y[j] = (c1^2 - 2 c2) y[j-2] - c2^2 y[j-4]: two
    chains of four multiply-adds instead of one of eight, so fewer modes keep the vector
    units busy (the same samples in exact arithmetic)."""
    c1, first, minus_c2, mixed, twice, minus_squared = coefficients
    samples = [
        fma(builder, c1, y1, builder.fmul(minus_c2, y2, flags=UPDATE_FLAGS)),
        fma(builder, first, y1, builder.fmul(mixed, y2, flags=UPDATE_FLAGS)),
    ]
    before = [y2, y1]  # y[-2], y[-1]
    for j in range(2, KEPT_LANES):
        four_back = samples[j - 4] if j >= 4 else before[j - 2]
        samples.append(
            fma(builder, twice, samples[j - 2], builder.fmul(minus_squared, four_back, flags=UPDATE_FLAGS))
        )
    return samples


@intrinsic
def ring_passes(typingctx, out, c1, c2, y1, y2, passes, vectors, adding):
    """:func:`ring` of modes [0, KEPT_LANES * vectors) (at most RING_CHUNK vectors) for
    ``passes`` passes of KEPT_LANES (eight) samples into out[:8 passes] (added to it if
    ``adding``), in explicit LLVM vectors of eight modes (:func:`_free_response`, its
    coefficients made once per call: 1.78 -> 1.49 ns per sample at 32 modes), each
    sample's sums kept as vectors over the mode loop and reduced together at the pass's
    end (:func:`_transposed_sum`), its eight samples stored as one vector. Per sample:
    1.27 / 1.38 / 1.49 ns at 8 / 24 / 32 modes against ring's 1.65 / 1.84 / 2.14;
    rounding only: ~1e-11 of the peak over seconds of ringing for mid-band modes, up to
    ~3e-8 (about -150 dB) for modes within 1e-3 rad of DC or Nyquist, where c1^2 - 2 c2 and
    c2^2 round worse than c1 and c2 (ring's own: 1e-10 to 1e-13)."""
    arrays = (out, c1, c2, y1, y2)
    if not (
        all(contiguous(a) for a in arrays)
        and all(isinstance(x, types.Integer) for x in (passes, vectors))
        and adding == types.boolean
    ):
        return None

    def codegen(context, builder, signature, args):
        vector, zero = ir.VectorType(DOUBLE, KEPT_LANES), cgutils.intp_t(0)
        pointers = [
            row_pointer(context, builder, kind, a, zero, vector)
            for kind, a in zip(signature.args[:5], args[:5], strict=True)
        ]
        out_at, (c1_at, c2_at, y1_at, y2_at) = pointers[0], pointers[1:]
        held = cgutils.alloca_once(builder, ir.ArrayType(vector, RING_CHUNK * RING_COEFFICIENTS))
        count = builder.sext(args[6], cgutils.intp_t)

        def coefficient(index, i):  # the address of coefficient i of vector ``index``
            at = builder.add(builder.mul(index, cgutils.intp_t(RING_COEFFICIENTS)), cgutils.intp_t(i))
            return builder.gep(held, [zero, at])

        with cgutils.for_range(builder, count) as each_vector:
            c1, c2 = (builder.load(builder.gep(r, [each_vector.index]), align=8) for r in (c1_at, c2_at))
            for i, value in enumerate(_ring_coefficients(builder, c1, c2)):
                builder.store(value, coefficient(each_vector.index, i))
        sums = [cgutils.alloca_once(builder, vector) for _ in range(KEPT_LANES)]
        with cgutils.for_range(builder, builder.sext(args[5], cgutils.intp_t)) as each_pass:
            for s in sums:
                builder.store(ir.Constant(vector, [0.0] * KEPT_LANES), s)
            with cgutils.for_range(builder, count) as each_vector:
                at = [builder.gep(r, [each_vector.index]) for r in (y1_at, y2_at)]
                held_now = [builder.load(coefficient(each_vector.index, i)) for i in range(RING_COEFFICIENTS)]
                samples = _free_response(builder, held_now, *(builder.load(x, align=8) for x in at))
                for s, v in zip(sums, samples, strict=True):
                    builder.store(builder.fadd(builder.load(s), v, flags=UPDATE_FLAGS), s)
                builder.store(samples[-2], at[1], align=8)
                builder.store(samples[-1], at[0], align=8)
            total = _transposed_sum(builder, [builder.load(s) for s in sums])
            where = builder.gep(out_at, [each_pass.index])
            added = builder.fadd(builder.load(where, align=8), total, flags=UPDATE_FLAGS)
            builder.store(builder.select(args[7], added, total), where, align=8)
        return context.get_dummy_value()

    return types.void(out, c1, c2, y1, y2, passes, vectors, adding), codegen


@intrinsic
def resonate_passes(typingctx, force, out, c1, c2, g, y1, y2, passes, vectors, before):
    """ugens.modal.resonate without its direct term, of modes [0, KEPT_LANES * vectors) for
    ``passes`` passes of eight samples over force[:8 passes] into out[:8 passes], in
    explicit LLVM vectors of eight modes: y[j] = c1 y[j-1] - c2 y[j-2] + g x[j] with
    x[j] = force[j-1] (``before`` for j = 0, each broadcast to the lanes), each sample's
    sums reduced together at the pass's end (:func:`_transposed_sum`). Returns the force
    sample before the next pass. Per sample at 32 / 64 / 208 modes: 2.5 / 4.0 / 10.7 ns
    against resonate's 3.5 / 4.6 / 11.2; rounding only."""
    arrays = (force, out, c1, c2, g, y1, y2)
    scalars = (passes, vectors)
    if not (
        all(contiguous(a) for a in arrays)
        and all(isinstance(x, types.Integer) for x in scalars)
        and before == types.float64
    ):
        return None

    def codegen(context, builder, signature, args):
        vector, zero = ir.VectorType(DOUBLE, KEPT_LANES), cgutils.intp_t(0)
        force_at = context.make_array(signature.args[0])(context, builder, args[0]).data
        pointers = [
            row_pointer(context, builder, kind, a, zero, vector)
            for kind, a in zip(signature.args[1:7], args[1:7], strict=True)
        ]
        out_at, rows = pointers[0], pointers[1:]
        sums = [cgutils.alloca_once(builder, vector) for _ in range(KEPT_LANES)]
        before_slot = cgutils.alloca_once_value(builder, args[9])

        with cgutils.for_range(builder, builder.sext(args[7], cgutils.intp_t)) as each_pass:
            first = builder.mul(each_pass.index, cgutils.intp_t(KEPT_LANES))
            samples = [
                builder.load(builder.gep(force_at, [builder.add(first, cgutils.intp_t(j))]))
                for j in range(KEPT_LANES)
            ]
            inputs = [broadcast(builder, x, KEPT_LANES) for x in [builder.load(before_slot), *samples[:-1]]]
            for s in sums:
                builder.store(ir.Constant(vector, [0.0] * KEPT_LANES), s)
            with cgutils.for_range(builder, builder.sext(args[8], cgutils.intp_t)) as each_vector:
                at = [builder.gep(row, [each_vector.index]) for row in rows]
                p, q, gain, old, older = (builder.load(x, align=8) for x in at)
                minus_q = builder.fneg(q, flags=UPDATE_FLAGS)
                for s, x in zip(sums, inputs, strict=True):
                    driven = fma(builder, minus_q, older, builder.fmul(gain, x, flags=UPDATE_FLAGS))
                    v = fma(builder, p, old, driven)
                    builder.store(builder.fadd(builder.load(s), v, flags=UPDATE_FLAGS), s)
                    older, old = old, v
                builder.store(older, at[4], align=8)
                builder.store(old, at[3], align=8)
            total = _transposed_sum(builder, [builder.load(s) for s in sums])
            builder.store(total, builder.gep(out_at, [each_pass.index]), align=8)
            builder.store(samples[-1], before_slot)
        return builder.load(before_slot)

    return types.float64(force, out, c1, c2, g, y1, y2, passes, vectors, before), codegen


@nb.njit(fastmath=FASTMATH, cache=True)
def resonate_kept(force, out, n, rows, active, last):
    """ugens.modal.resonate of modes [0, active) of ``rows`` over force[:n] into out[:n]
    (last[0]: the force sample before force[0], left at force[n - 1]): by
    :func:`resonate_passes` plus the direct term if ``active`` is whole vectors of
    KEPT_LANES (the samples past the last whole pass by resonate)."""
    if active % KEPT_LANES:
        resonate(force, out, n, rows, active, last)
        return
    passes = n // KEPT_LANES
    done = passes * KEPT_LANES
    if passes:
        c1, c2, g, d, y1, y2 = rows
        last[0] = resonate_passes(force, out, c1, c2, g, y1, y2, passes, active // KEPT_LANES, last[0])
        if has_force(force, 0, done):
            direct = 0.0
            for k in range(active):
                direct += d[k]
            for i in range(done):
                out[i] += direct * force[i]
    if done < n:
        resonate(force[done:], out[done:], n - done, rows, active, last)


@nb.njit(fastmath=FASTMATH, cache=True)
def ring_kept(out, n, c1, c2, y1, y2, active):
    """:func:`ring` of modes [0, active) for n samples: by :func:`ring_passes` (RING_CHUNK
    vectors at a time) if ``active`` is whole vectors of KEPT_LANES (the samples past the
    last whole pass by :func:`ring`)."""
    if active % KEPT_LANES:
        ring(out, n, c1, c2, y1, y2, active)
        return
    passes = n // KEPT_LANES
    for first in range(0, active, RING_CHUNK * KEPT_LANES):
        last = min(active, first + RING_CHUNK * KEPT_LANES)
        vectors = (last - first) // KEPT_LANES
        ring_passes(
            out, c1[first:last], c2[first:last], y1[first:last], y2[first:last], passes, vectors, first > 0
        )
    done = passes * KEPT_LANES
    if done < n:
        ring(out[done:], n - done, c1, c2, y1, y2, active)


@nb.njit(cache=True)
def hear(force, n, heard, start):
    """Copy force[:n] (frames start ..) into the ring ``heard`` (one budget period, frame
    t at t modulo its length; only the last period of a longer sub-block stays). Whether
    it is non-zero the budget knows already (jassy.anytime_rank.scan_forces). An element
    loop on slices from 0: numba's slice assignment costs 0.19 against 0.05 ns per sample."""
    size = heard.size
    i = max(0, n - size)
    while i < n:
        at = (start + i) % size
        m = min(n - i, size - at)
        into, source = heard[at : at + m], force[i : i + m]
        for j in range(m):
            into[j] = source[j]
        i += m


@nb.njit(inline="always", cache=True)
def whole_vectors(active, width):
    """The modes a compact bank's kernels compute: ``active`` rounded up to whole vectors
    of KEPT_LANES (at most ``width``), or ``active`` itself if at most half a vector. The
    modes past the last audible one hold exact zeros (padding, or flushed), so computing
    them changes no sample, while a count that is not a whole number of vectors leaves a
    scalar remainder loop: 30 modes ringing freely (:func:`ring`) cost 5.9 ns per sample,
    32 modes 4.1 ns. Up to half a vector the scalar loop is the cheaper one (it sums
    without a reduction across lanes): 1-4 modes 2.5-2.6 ns, a vector of 8 3.2 ns."""
    if active <= KEPT_LANES // 2:
        return active
    return min((active + KEPT_LANES - 1) // KEPT_LANES * KEPT_LANES, width)


@nb.njit(fastmath=FASTMATH, cache=True)
def kept_step(force, out, start, n, compact, meta, floor, last, heard, blocks=None):
    """One sub-block of a budgeted bank's kept modes: rows c1, c2, g, d, y1, y2 of the
    compact bank (whole vectors of KEPT_LANES modes: its padding and flushed modes hold
    exact zeros, so the modes computed are rounded up to whole vectors: :func:`whole_vectors`;
    meta[ACTIVE] keeps the last audible mode + 1), meta [active, gathered, width], last[0]
    the force sample before force[0]. As ugens.modal.bank_step (flushes at multiples of
    FLUSH_PERIOD on the clock, so the output does not depend on the block size), with
    force-free stretches by :func:`ring_kept`, forced ones by :func:`resonate_kept`. The
    force also goes to the budget period's ring
    ``heard`` (empty: the force is zero and the ring holds zeros). ``blocks``: a bank of at
    most four kept modes renders its stretches, forced or ringing, by ugens.modal_block
    with this block table (made again first if the coefficients changed)."""
    width, rows = meta[WIDTH], mode_rows(compact)
    if blocks is not None:
        current_table(blocks, rows.c1, rows.c2, rows.g, rows.d)
    meta[ACTIVE] = whole_vectors(meta[ACTIVE], width)
    i = 0
    while i < n:
        m = until_flush(start + i, n - i)
        f = force[i : i + m]
        o = out[i : i + m]
        forced = last[0] != 0.0 or has_force(f, 0, m)
        if forced:
            meta[ACTIVE] = width
        active = whole_vectors(meta[ACTIVE], width)
        if active == 0:
            for j in range(m):
                o[j] = 0.0
            last[0] = 0.0
        elif blocks is not None:  # (ringing too: 0.66-0.68 against ring's 1.3-1.5 ns per sample)
            block_resonate(f, o, m, rows, blocks, last)
        elif forced:
            resonate_kept(f, o, m, rows, active, last)
        else:
            ring_kept(o, m, rows.c1, rows.c2, rows.y1, rows.y2, active)
        i += m
        if active > 0 and is_flush_frame(start + i):
            meta[ACTIVE] = flush_silent(rows.y1, rows.y2, active, floor)
    if heard.size:
        hear(force, n, heard, start)


@nb.njit(cache=True)
def heard_lately(h, b):
    """Whether bank b hears a force in this stretch, heard one since it was last rendered,
    or in this or the last period (``h``: jassy.anytime_rank.Hearing): else its ring of
    the period's force holds zeros and keeps them. (Never for a ``struck_only`` bank,
    whose force jassy.anytime_rank.scan_forces leaves unscanned, unless it is also
    ``unseen``.)"""
    return h.forced[b] or h.unrendered[b] or h.heard_now[b] or h.heard_before[b]


@nb.njit(fastmath=FASTMATH, cache=True)
def ramp_passes(force, out, n, ramp, y1, y2, remaining, active, last):
    """As ugens.modal.resonate_ramp (each sample with the current coefficients, which then
    step by their increments; ``remaining`` samples to the ramp's target) over modes
    [0, active), four samples per pass over the modes while the ramp goes on past them:
    each mode's coefficients, increments and state are loaded and stored once per four
    samples (resonate_ramp loads and stores the four coefficient rows every sample, and
    reduces the sums across the mode vector every sample: 4x the cost of the steady
    recursion). The same products and sums (reassociated); the sample where the ramp ends
    by resonate_ramp, the samples after it by ugens.modal.resonate. Returns the samples
    of the ramp left."""
    coef, delta, _ = ramp
    c1, c2, g, d = coef[COEF_C1], coef[COEF_C2], coef[COEF_GAIN], coef[COEF_DIRECT]
    e1, e2, eg, ed = delta[COEF_C1], delta[COEF_C2], delta[COEF_GAIN], delta[COEF_DIRECT]
    fp = last[0]
    i = 0
    while i + 4 <= n and remaining > 4:
        f0 = force[i]
        f1 = force[i + 1]
        f2 = force[i + 2]
        f3 = force[i + 3]
        s0 = s1 = s2 = s3 = 0.0
        t0 = t1 = t2 = t3 = 0.0  # the direct gains' sums at each sample
        for k in range(active):
            p, q, gk, dk = c1[k], c2[k], g[k], d[k]
            a, b, h, e = e1[k], e2[k], eg[k], ed[k]
            u1 = y1[k]
            u2 = y2[k]
            v0 = two_pole(p, q, u1, u2, gk * fp)
            t0 += dk
            v1 = two_pole(p + a, q + b, v0, u1, (gk + h) * f0)
            t1 += dk + e
            v2 = two_pole(p + 2.0 * a, q + 2.0 * b, v1, v0, (gk + 2.0 * h) * f1)
            t2 += dk + 2.0 * e
            v3 = two_pole(p + 3.0 * a, q + 3.0 * b, v2, v1, (gk + 3.0 * h) * f2)
            t3 += dk + 3.0 * e
            c1[k] = p + 4.0 * a
            c2[k] = q + 4.0 * b
            g[k] = gk + 4.0 * h
            d[k] = dk + 4.0 * e
            y2[k] = v2
            y1[k] = v3
            s0 += v0
            s1 += v1
            s2 += v2
            s3 += v3
        out[i] = s0 + t0 * f0
        out[i + 1] = s1 + t1 * f1
        out[i + 2] = s2 + t2 * f2
        out[i + 3] = s3 + t3 * f3
        fp = f3
        remaining -= 4
        i += 4
    last[0] = fp
    if i < n and remaining > 0:
        m = min(n - i, remaining)
        remaining = resonate_ramp(force[i : i + m], out[i : i + m], m, ramp, y1, y2, remaining, active, last)
        i += m
    if i < n:
        resonate(force[i:n], out[i:n], n - i, ModeRows(c1, c2, g, d, y1, y2), active, last)
    return remaining


@nb.njit(fastmath=FASTMATH, cache=True)
def ramp_kept(t, b, force, out, start, n, ring_of_force):
    """Bank b's kept modes over force[:n] into out[:n] while its coefficients ramp (its
    RAMP_LEFT > 0): :func:`ramp_passes` on its compact bank (every column, no flushes),
    then the force into the ring of the period's force (empty: it is zero)."""
    compact, meta = compact_bank(t, b), t.compact_meta[b]
    meta[ACTIVE] = meta[WIDTH]
    ramp = Ramp(compact[:COEF_ROWS], compact[RAMP_DELTA:RAMP_TARGET], compact[RAMP_TARGET:])
    rows, last = mode_rows(compact), t.last[b : b + 1]
    t.meta[b, RAMP_LEFT] = ramp_passes(
        force, out, n, ramp, rows.y1, rows.y2, t.meta[b, RAMP_LEFT], meta[WIDTH], last
    )
    if ring_of_force.size:
        hear(force, n, ring_of_force, start)


@nb.njit(cache=True)
def none_kept(t, b, force, start, n, ring_of_force):
    """Budgeted bank b with no mode kept (and no ramp) over force[:n], frames
    [start, start + n), as :func:`render_bank` leaves it but for its output (zeros, which
    the caller writes) and its compact bank, left as it is (it would gather no column:
    nothing reads one while none is kept): nothing active, no force sample before the next
    span, the force into ``ring_of_force`` (empty: it is zero)."""
    t.meta[b, ACTIVE] = 0
    t.last[b] = 0.0
    if ring_of_force.size:
        hear(force, n, ring_of_force, start)


@nb.njit(fastmath=FASTMATH, cache=True)
def render_bank(t, b, force, out, start, n, ring_of_force):
    """Budgeted bank b (its rows in the tables ``t``) over force[:n] into out[:n], frames
    [start, start + n): :func:`kept_step` on its compact bank (gathered if stale), or
    :func:`ramp_kept` while its coefficients ramp; the force into ``ring_of_force`` (empty:
    it is zero). Returns its active modes after the span (also its meta's)."""
    meta = t.compact_meta[b]
    if t.meta[b, RAMP_LEFT] > 0:
        ramp_kept(t, b, force, out, start, n, ring_of_force)
    else:
        compact = compact_bank(t, b)
        floor, last = t.values[FLOOR, b], t.last[b : b + 1]
        if t.meta[b, ALLOWED] <= BLOCK_MODES and meta[WIDTH] == KEPT_LANES:
            blocks = t.blocks[b]
            kept_step(force, out, start, n, compact[:BANK_ROWS], meta, floor, last, ring_of_force, blocks)
        else:
            kept_step(force, out, start, n, compact[:BANK_ROWS], meta, floor, last, ring_of_force)
    active = min(meta[ACTIVE], t.meta[b, ALLOWED])
    t.meta[b, ACTIVE] = active
    return active


@nb.njit(cache=True)
def silence(address, zeros, b, offset, n):
    """Zeros into samples [offset, offset + n) of bank b's output (float64s at ``address``)
    but where ``zeros[b]`` (the samples from the buffer's start known to be zero) says they
    are zero already; ``zeros[b]`` extended over them if they join its zeros."""
    if offset + n > zeros[b]:
        first = max(offset, zeros[b])
        out = nb.carray(void_pointer(address + 8 * first), (offset + n - first,), np.float64)
        for i in range(out.size):
            out[i] = 0.0
        if offset <= zeros[b]:
            zeros[b] = offset + n


@nb.njit(fastmath=FASTMATH, cache=True)
def render_kept(t, h, outputs, by_python, zeros, start, n, offset):
    """Every budgeted bank b but those ``by_python`` (rendered after the step: only their
    force into their ring here, so that :func:`steady_forces` judges what they heard up to
    this frame, as for the others) over frames [start, start + n), from
    samples [offset, offset + n) of its input (``h``: jassy.anytime_rank.Hearing) into
    its output (float64 arrays at ``outputs``) by :func:`render_bank` from the tables ``t``
    (ugens.modal_budget); its force into its ring unless ``struck_only`` (never judged).
    A bank with nothing to compute (no ramp, and no mode kept, or not
    :func:`heard_lately` with no mode sounding and no force sample before) writes zeros
    (:func:`silence`; a ``struck_only`` bank only when its span holds no force sample
    either, since scan_forces leaves it unscanned), and not even those where its output
    already holds them: ``zeros[b]``
    counts the samples from the start of its output buffer known to be zero (most of the
    wok scene's fourteen 4-mode banks are silent most of the time: writing 4096 zeros
    costs about as much as the kernel's bookkeeping); one with no mode kept only copies
    its force into its ring if it heard one lately (as render_bank, without a pass per
    flush period). Returns the modes computed times frames (each bank's active count
    after its span)."""
    work = 0
    for b in range(by_python.size):
        busy = heard_lately(h, b)
        force = nb.carray(void_pointer(h.inputs[b] + 8 * offset), (n,), np.float64)
        ring_of_force = t.rings[b] if busy and not h.struck_only[b] else t.rings[b, :0]
        if by_python[b]:
            if ring_of_force.size:
                hear(force, n, ring_of_force, start)
            continue
        ramping = t.meta[b, RAMP_LEFT] > 0
        idle = not busy and t.meta[b, ACTIVE] == 0 and t.last[b] == 0.0
        if idle and h.struck_only[b] and t.meta[b, ALLOWED] > 0 and not ramping:
            idle = not has_force(force, 0, n)  # (scan_forces leaves it unscanned)
        if not ramping and (idle or t.meta[b, ALLOWED] == 0):
            if not idle:
                none_kept(t, b, force, start, n, ring_of_force)
            silence(outputs[b], zeros, b, offset, n)
            continue
        out = nb.carray(void_pointer(outputs[b] + 8 * offset), (n,), np.float64)
        work += render_bank(t, b, force, out, start, n, ring_of_force) * n
        zeros[b] = min(zeros[b], offset)
    return work


@nb.njit(cache=True)
def expect_impacts(h, kicks, count, at, period, state):
    """A period starts at frame ``at``: mark the banks struck by a positive impulse in
    [at, at + period) as expecting it (``h.expected``); return whether any impact applies in
    [at, at + 2 period) (then the budget decides). The first ``count`` rows of ``kicks``
    are in frame order: the period's are found by bisection."""
    if state[ANY_EXPECTED]:
        h.expected[:] = False
    state[ANY_EXPECTED] = 0
    j = np.searchsorted(kicks.frames[:count], at)
    coming = j < count and kicks.frames[j] < at + 2 * period
    while j < count and kicks.frames[j] < at + period:
        if kicks.positive[j]:
            state[ANY_EXPECTED] = 1
            if kicks.slots[j] >= 0:
                h.expected[kicks.slots[j]] = True
        j += 1
    return coming


#: Fields of a :class:`jassy.anytime_rank.Hearing`.
HEARING_FIELDS = len(Hearing._fields)

#: Slots of a budget's step handle (jassy.record_views) where its records start: the
#: tables (ugens.modal_budget.BudgetTables), the Hearing, the banks' outputs (addresses,
#: the by-Python mask and the zeros they hold, :func:`render_kept`), the Kicks
#: (jassy.anytime_rank), the step state, the Decision.
HEARING_AT = TABLE_FIELDS * FIELD
OUTPUTS_AT = HEARING_AT + HEARING_FIELDS * FIELD
OUTPUT_FIELDS = 3
KICKS_AT = OUTPUTS_AT + OUTPUT_FIELDS * FIELD
STATE_AT = KICKS_AT + len(Kicks._fields) * FIELD
DECISION_AT = STATE_AT + FIELD


@nb.njit(cache=True)
def impacts_at(a, count, at, period):
    """ugens.modal_budget.load_impacts on the tables and Kicks of step handle ``a`` for a
    decision at frame ``at``."""
    return load_impacts(tables_at(a, 0), kicks_at(a, KICKS_AT), count, at, period)


@nb.njit(cache=True)
def decide_at(a, rates):
    """ugens.modal_budget.decide on the records of step handle ``a``, its impacts loaded
    (:func:`impacts_at`), a force heard lately meaning in this or the last period; the
    step state counts the decision and the most modes kept, and holds whether a mode
    fades. Returns (whether a mode fades, modes computed)."""
    t, h, d = tables_at(a, 0), hearing_at(a, HEARING_AT), decision_at(a, DECISION_AT)
    state = int_row(a, STATE_AT)
    for b in range(d.heard.size):
        d.heard[b] = h.heard_now[b] or h.heard_before[b]
    fading, total = decide(t, d, rates)
    note_decided(h, t.values[RING_POWER], d.heard, state)
    state[FADING] = fading
    state[DECISIONS] += 1
    state[PEAK] = max(state[PEAK], total)
    return fading, total


@nb.njit(cache=True)
def advance_at(a, count, period, start, n, at, rendered, rates):
    """A mode budget's step over frames [at, start + n) of the sub-block [start, start + n)
    (the banks rendered up to ``rendered``), in one compiled call, on the records of step
    handle ``a`` (jassy.record_views; see DECISION_AT). At each period's start the
    impacts expected (:func:`expect_impacts`, from the first ``count`` rows of the
    Kicks), in each stretch to the next period the forces heard
    (jassy.anytime_rank.scan_forces), and, if the step RENDERS, the banks rendered
    (:func:`render_kept`) up to each frame where the budget decides: an impact comes in
    this or the next period, a force was heard in the last one, a mode fades or every
    period is decided (``state``: jassy.anytime_rank's step fields), or a force nobody
    scheduled wakes a bank. With INLINE the step decides there itself (:func:`impacts_at`,
    :func:`decide_at`, ``rates`` with the stretch's input samples) and goes on; else it
    returns there. Returns (that frame or the sub-block's end, the frame rendered up to,
    modes computed times frames, whether Python decides there)."""
    t, h, kicks = tables_at(a, 0), hearing_at(a, HEARING_AT), kicks_at(a, KICKS_AT)
    outputs, by_python = int_row(a, OUTPUTS_AT), bool_row(a, OUTPUTS_AT + FIELD)
    zeros = int_row(a, OUTPUTS_AT + 2 * FIELD)
    state = int_row(a, STATE_AT)
    renders = state[RENDERS] > 0
    end, work = start + n, 0
    while at < end:
        stop = min(end, (at // period + 1) * period)
        rotate = at % period == 0
        coming = rotate and expect_impacts(h, kicks, count, at, period, state)
        heard, woken = scan_forces(h, at - start, stop - start, rotate)
        if woken or (rotate and (state[FADING] > 0 or state[EVERY_PERIOD] > 0 or coming or heard)):
            if at > rendered and renders:
                work += render_kept(
                    t, h, outputs, by_python, zeros, rendered, at - rendered, rendered - start
                )
                h.unrendered[:] = False
            rendered = max(rendered, at)
            only_heard = not (woken or coming or state[FADING] > 0 or state[EVERY_PERIOD] > 0)
            if only_heard and renders and steady_forces(h, t.rings, t.meta[:, RAMP_LEFT], state):
                at = stop
                continue
            if state[INLINE] == 0:
                return at, rendered, work, True
            impacts_at(a, count, at, period)
            spans = Rates(
                rates.sample_rate, rates.limit, rates.bonus, rates.shrink, at - start, stop - start,
                rates.window_power, at,
            )  # fmt: skip
            decide_at(a, spans)
        at = stop
    if end > rendered and renders:
        work += render_kept(t, h, outputs, by_python, zeros, rendered, end - rendered, rendered - start)
        h.unrendered[:] = False
    return end, max(rendered, end), work, False


@nb.njit(fastmath=FASTMATH, cache=True)
def kept_span(a, b, force, out, start, n):
    """Budgeted bank b (its rows in the tables of handle ``a``, jassy.record_views) over
    force[:n] into out[:n], frames [start, start + n), as :func:`render_kept` renders it
    (for a bank that renders through its own ``process``): :func:`render_bank`, the force
    into its ring unless the step renders (its :func:`render_kept` copied it already)."""
    t = tables_at(a, 0)
    renders = int_row(a, STATE_AT)[RENDERS] > 0
    render_bank(t, b, force, out, start, n, t.rings[b, :0] if renders else t.rings[b])


@nb.njit(cache=True)
def settle_at(a, b):
    """ugens.modal_budget.settle_compact of bank b on the tables of handle ``a``."""
    settle_compact(tables_at(a, 0), b)

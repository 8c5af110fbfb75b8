"""A budgeted bank of at most four kept modes, eight samples at a time as one block update
in explicit LLVM vectors (ugens.modal_kept renders such banks' compact banks with it).

Run sample by sample, such a bank costs what eight modes cost (~2.9 ns per sample: one
SIMD vector of modes per sample, its lanes summed at every sample, each sample's update
waiting on the last), so the wok's fourteen four-mode food banks cost as much kept as
full; this form costs ~1.3 ns per sample. Over eight samples the two-pole recursion
y[n] = c1 y[n-1] - c2 y[n-2] + g x[n] (x[n] = F[n-1], ugens.modal) is linear in the
state before the pass (y1, y2) and the pass's inputs x[0..7]:

    y[j] = h[j+1] y1 - c2 h[j] y2 + g sum_{m <= j} h[j-m] x[m],   j = 0 .. 7,

h the mode's impulse response (h[0] = 1, h[1] = c1, h[l] = c1 h[l-1] - c2 h[l-2]). So
the pass's eight output samples are one vector: a basis row per state value (4 modes x
y1, y2: eight rows) times that value, plus the bank's impulse response sum_k g_k h_k as
a Toeplitz matrix (eight rows) times x, plus the direct term (sum_k d_k) F; the next state
[y1' | y2'] (lanes 0-3 and 4-7) is a row times [y1 | y1], one times [y2 | y2] and eight
rows times x. The rows are the bank's :func:`fill_table`, made again when the
coefficients change (a location jump, a new kept set: :func:`current_table`). Per pass:
27 vector multiply-adds, no sum across lanes, and a chain of two multiply-adds from one
pass's state to the next (the sample-by-sample recursion has eight). Exact in exact
arithmetic; in floating point its outputs differ from ugens.modal.resonate's by rounding
(the same products, grouped otherwise). Used for the bank's free ringing too (a zero
force): 0.66-0.68 ns per sample for 1-4 modes against ugens.modal_kept.ring's 1.3-1.5
(its scalar chain per mode is latency-bound); its rounding drifts more over a long ring:
the eight-sample state map stored in float64 turns by an angle off by about one ulp over
sin(8 theta), so a slowly decaying mode's phase drifts linearly with the ring's length
(of the peak, against the exact recursion of the stored c1, c2: ~1e-9 per second at 20 Hz,
~1.5e-11 at 220 Hz, ~3e-12 at 2 kHz; ring's ~3e-13 per second at 20 Hz), without bound
for an undamped mode (6e-8, about -145 dB, after 60 s at 20 Hz), far below anything heard.
"""

from __future__ import annotations

import numba as nb
import numpy as np
from llvmlite import ir
from numba.core import cgutils, types
from numba.extending import intrinsic

from jassy.jit import drop_stale_cache
from ugens import cells, kernels, vector_ir
from ugens.cells import two_pole
from ugens.kernels import FASTMATH
from ugens.vector_ir import DOUBLE, INDEX, UPDATE_FLAGS, broadcast, contiguous, fma, row_pointer, shuffle

drop_stale_cache(__file__, [cells, kernels, vector_ir])  # its cache holds their kernels and code

#: The most kept modes a bank may have to be rendered by blocks, and the samples per block.
BLOCK_MODES, BLOCK = 4, 8

#: Rows (of BLOCK lanes) of a bank's block table: the output's basis rows (y1 of modes 0-3,
#: then y2 of modes 0-3), the Toeplitz rows of the bank's impulse response (input m),
#: the next state's rows for [y1 | y1] and [y2 | y2] and for each input, then the
#: coefficients the table was made from (c1 | c2, then g | d).
BASIS, TOEPLITZ, NEXT_Y1, NEXT_Y2, NEXT_INPUT, MADE_FROM = 0, 8, 16, 17, 18, 26
BLOCK_ROWS = MADE_FROM + 2
#: Floats of a block table (rows of BLOCK lanes, flat).
BLOCK_TABLE = BLOCK_ROWS * BLOCK


@nb.njit(cache=True)
def fill_table(table, c1, c2, g, d):
    """The block table (flat, BLOCK_TABLE floats) of modes 0-3 with coefficients c1, c2, g
    and direct gains d (module docstring)."""
    rows = table.reshape((BLOCK_ROWS, BLOCK))
    rows[:, :] = 0.0
    h = np.zeros(BLOCK + 2)
    for k in range(BLOCK_MODES):
        h[0], h[1] = 1.0, c1[k]
        for q in range(2, BLOCK + 2):
            h[q] = c1[k] * h[q - 1] - c2[k] * h[q - 2]
        for j in range(BLOCK):
            rows[BASIS + k, j] = h[j + 1]
            rows[BASIS + BLOCK_MODES + k, j] = -c2[k] * h[j]
        for m in range(BLOCK):
            for j in range(m, BLOCK):
                rows[TOEPLITZ + m, j] += g[k] * h[j - m]
            rows[NEXT_INPUT + m, k] = g[k] * h[BLOCK - 1 - m]
            if m < BLOCK - 1:
                rows[NEXT_INPUT + m, BLOCK_MODES + k] = g[k] * h[BLOCK - 2 - m]
        rows[NEXT_Y1, k], rows[NEXT_Y1, BLOCK_MODES + k] = h[BLOCK], h[BLOCK - 1]
        rows[NEXT_Y2, k], rows[NEXT_Y2, BLOCK_MODES + k] = -c2[k] * h[BLOCK - 1], -c2[k] * h[BLOCK - 2]
        rows[MADE_FROM, k], rows[MADE_FROM, BLOCK_MODES + k] = c1[k], c2[k]
        rows[MADE_FROM + 1, k], rows[MADE_FROM + 1, BLOCK_MODES + k] = g[k], d[k]


@nb.njit(cache=True)
def current_table(table, c1, c2, g, d):
    """Bank ``table`` made for modes 0-3 of c1, c2, g, d (refilled if they changed)."""
    made = table.reshape((BLOCK_ROWS, BLOCK))
    for k in range(BLOCK_MODES):
        same = made[MADE_FROM, k] == c1[k] and made[MADE_FROM, BLOCK_MODES + k] == c2[k]
        if not (same and made[MADE_FROM + 1, k] == g[k] and made[MADE_FROM + 1, BLOCK_MODES + k] == d[k]):
            fill_table(table, c1, c2, g, d)
            return


def _accumulated(builder, terms, chains):
    """The sum of the products a b of ``terms`` (pairs of vectors) in ``chains``
    interleaved chains of multiply-adds, added at the end: no chain longer than
    len(terms) / chains."""
    sums = [None] * chains
    for t, (a, b) in enumerate(terms):
        c = t % chains
        sums[c] = builder.fmul(a, b, flags=UPDATE_FLAGS) if sums[c] is None else fma(builder, a, b, sums[c])
    sums = [x for x in sums if x is not None]
    while len(sums) > 1:
        pairs = [builder.fadd(a, b, flags=UPDATE_FLAGS) for a, b in zip(sums[::2], sums[1::2], strict=False)]
        sums = pairs + ([sums[-1]] if len(sums) % 2 else [])
    return sums[0]


@intrinsic
def block_passes(typingctx, table, y1, y2, force, out, passes, fp, direct):
    """Advance modes 0-3 (state y1[0:4], y2[0:4]) by ``passes`` passes of eight samples
    with the bank's block ``table`` (:func:`fill_table`) into out[:8 passes]: the inputs
    are fp (the force before sample 0) and force[:8 passes - 1], plus the direct term
    ``direct`` force[j]. Each state value and input is read by a broadcast load (lane
    shuffles of 512-bit vectors cost more). Returns the force sample before the next pass.
    A non-finite input (NaN, inf) makes the whole pass non-finite, its samples before that
    input too (the Toeplitz matrix's zeros times it), where the recursion is non-finite
    only from that sample on; the output stage keeps either from any file or device."""
    if not (
        all(contiguous(a) for a in (table, y1, y2, force, out))
        and isinstance(passes, types.Integer)
        and fp == types.float64
        and direct == types.float64
    ):
        return None

    def codegen(context, builder, signature, args):
        table, y1, y2, force, out, passes, fp, direct = args
        kinds = signature.args
        vector, half = ir.VectorType(DOUBLE, BLOCK), ir.VectorType(DOUBLE, BLOCK_MODES)
        base = row_pointer(context, builder, kinds[0], table, cgutils.intp_t(0), vector)

        # the rows, loaded once before the passes: held in registers, not reloaded
        rows = [builder.load(builder.gep(base, [cgutils.intp_t(r)]), align=8) for r in range(MADE_FROM)]

        low = row_pointer(context, builder, kinds[1], y1, cgutils.intp_t(0), half)
        high = row_pointer(context, builder, kinds[2], y2, cgutils.intp_t(0), half)
        scalars = [builder.bitcast(p, DOUBLE.as_pointer()) for p in (low, high)]
        force_at = context.make_array(kinds[3])(context, builder, force).data
        out_at = row_pointer(context, builder, kinds[4], out, cgutils.intp_t(0), vector)
        before_slot = cgutils.alloca_once_value(builder, fp)
        direct_lanes = broadcast(builder, direct, BLOCK)
        with cgutils.for_range(builder, builder.sext(passes, cgutils.intp_t)) as loop:
            states = [
                builder.load(builder.gep(scalars[k // 4], [cgutils.intp_t(k % 4)])) for k in range(BLOCK)
            ]
            terms = [(rows[BASIS + k], broadcast(builder, states[k], BLOCK)) for k in range(BLOCK)]
            ones = shuffle(
                builder, builder.load(low, align=8), ir.Constant(half, ir.Undefined), [0, 1, 2, 3] * 2
            )
            twos = shuffle(
                builder, builder.load(high, align=8), ir.Constant(half, ir.Undefined), [0, 1, 2, 3] * 2
            )
            first = builder.mul(loop.index, cgutils.intp_t(BLOCK))
            inputs = [builder.load(before_slot)] + [
                builder.load(builder.gep(force_at, [builder.add(first, cgutils.intp_t(m - 1))]))
                for m in range(1, BLOCK)
            ]
            spreads = [broadcast(builder, x, BLOCK) for x in inputs]
            samples = builder.load(
                builder.bitcast(builder.gep(force_at, [first]), vector.as_pointer()), align=8
            )
            terms += [(rows[TOEPLITZ + m], spreads[m]) for m in range(BLOCK)]
            terms.append((direct_lanes, samples))
            driven = _accumulated(builder, [(rows[NEXT_INPUT + m], spreads[m]) for m in range(BLOCK)], 2)
            following = fma(builder, rows[NEXT_Y2], twos, fma(builder, rows[NEXT_Y1], ones, driven))
            builder.store(builder.extract_element(samples, INDEX(BLOCK - 1)), before_slot)
            builder.store(_accumulated(builder, terms, 4), builder.gep(out_at, [loop.index]), align=8)
            builder.store(shuffle(builder, following, following, [0, 1, 2, 3]), low, align=8)
            builder.store(shuffle(builder, following, following, [4, 5, 6, 7]), high, align=8)
        return builder.load(before_slot)

    return types.float64(table, y1, y2, force, out, passes, fp, direct), codegen


@nb.njit(fastmath=FASTMATH, cache=True)
def block_resonate(force, out, n, rows, table, last):
    """ugens.modal.resonate of modes 0-3 of ``rows`` (ugens.cells.ModeRows) over force[:n]
    into out[:n] (last[0]: the force sample before force[0], left at force[n - 1]) by
    :func:`block_passes` with ``table`` (current), the last n % 8 samples one by one."""
    c1, c2, g, d, y1, y2 = rows
    direct = d[0] + d[1] + d[2] + d[3]
    passes = n // BLOCK
    fp = block_passes(table, y1, y2, force, out, passes, last[0], direct)
    for i in range(passes * BLOCK, n):
        s = 0.0
        for k in range(BLOCK_MODES):
            v = two_pole(c1[k], c2[k], y1[k], y2[k], g[k] * fp)
            y2[k] = y1[k]
            y1[k] = v
            s += v
        fp = force[i]
        out[i] = s + direct * fp
    last[0] = fp

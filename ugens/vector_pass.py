"""One four-sample pass of float32 modes written as explicit LLVM vectors.

ugens.modal_f32's held kernels keep a bank's rows (16, 32 or 64 modes) on the stack, where
LLVM holds them in vector registers across the passes. From the per-mode loop, LLVM's
vectoriser summed each of the pass's four output samples over the lanes on its own (four
horizontal reductions, each a chain of extracts, shuffles and adds), then converted and
stored the four sums one by one and added the direct term in a pass of its own.
:func:`write_four` reduces the four sums together (:func:`_sum_four`: within each 128-bit
block first, then the blocks), adds the direct term to the four at once and converts and
stores them as one vector: against the C two-pole loop, 0.98x -> 1.09x at 16 modes, 0.96x
-> 1.02x at 32, 0.94x -> 1.03x at 64 (one run each, on an earlier machine).
Larger banks, whose rows stay in memory (ugens.modal_f32.resonate_chunks), run
:func:`add_chunk` per 32 modes, the per-lane sums kept in four stack rows, and
:func:`write_sums` at the end of each pass; a few float64 modes beside them run as one
float64 vector (:func:`add_wide_chunk`) whose outputs join the first lanes of those sums.

The arithmetic per mode is ugens.modal_f32's update (``_four_samples``): with p = y[n-2] /
g, v = Delta[n-1] / g and the preceding forces fp, f0, f1, f2, u = p + v, in the
decay-factor form v' = b v + (f - c0 p) as two fused multiply-adds, in the delta form
(add_chunk only) v' = (f - c0 u) + (v - b v), in the same order.
"""

from __future__ import annotations

from llvmlite import ir
from numba.core import cgutils, types
from numba.extending import intrinsic

from ugens.vector_ir import (
    DOUBLE,
    FLOAT,
    INDEX,
    UPDATE_FLAGS,
    broadcast,
    contiguous,
    fma,
    row_pointer,
    shuffle,
)

#: float32 lanes of one AVX-512 vector: the reduction first folds wider rows to this.
VECTOR = 16

#: Flags of the reduction's adds: any order (the sums of a pass are independent of its
#: state, so the order only moves their float32 rounding).
_SUM_FLAGS = ("fast",)


def _fold(builder, v, width):
    """v's lanes summed down to VECTOR lanes (halves added)."""
    while width > VECTOR:
        half = width // 2
        low, high = list(range(half)), list(range(half, width))
        v = builder.fadd(shuffle(builder, v, v, low), shuffle(builder, v, v, high), flags=_SUM_FLAGS)
        width = half
    return v


def _sum_four(builder, a0, a1, a2, a3):
    """<4 x float> (sum(a0), sum(a1), sum(a2), sum(a3)) of four VECTOR-lane vectors: first
    within each 128-bit block (shuffles that stay in their block, two-source shufps: the
    four vectors' block sums side by side in two steps), then the blocks added (halves of
    the vector). Halving the lanes of pairs across the whole vector at each step (cross-block
    shuffles, 11 of them) cost the bank of 256 modes about 5 % more."""

    def within(x, y):  # per block of four lanes: [x0 + x1, x2 + x3, y0 + y1, y2 + y3]
        even = [i for b in range(0, VECTOR, 4) for i in (b, b + 2, VECTOR + b, VECTOR + b + 2)]
        odd = [i + 1 for i in even]
        return builder.fadd(shuffle(builder, x, y, even), shuffle(builder, x, y, odd), flags=_SUM_FLAGS)

    z = within(within(a0, a1), within(a2, a3))  # per block: its sums of a0, a1, a2, a3
    width = VECTOR
    while width > 4:
        half = width // 2
        z = builder.fadd(
            shuffle(builder, z, z, list(range(half))),
            shuffle(builder, z, z, list(range(half, width))),
            flags=_SUM_FLAGS,
        )
        width = half
    return z


def _pass(builder, lanes, c0v, bv, p, v, forces, by_factor=True):
    """The four-sample update of vectors of modes with rows c0, b and state p = y[n-2] / g,
    v = Delta[n-1] / g, whose preceding forces are ``forces`` (four float32 scalars):
    (the new p, the new v, the four outputs y / g). Decay-factor form (``by_factor``, b =
    R^2 - c0): v' = b v + (f - c0 y[n-2]); delta form (b = b2): v' = (f - c0 y[n-1]) + (v -
    b2 v), two FMA and an add."""
    minus_c0 = builder.fneg(c0v)
    minus_b = builder.fneg(bv)

    def next_delta(v, older, newer, f):
        force = fma(builder, minus_c0, older if by_factor else newer, broadcast(builder, f, lanes))
        if by_factor:
            return fma(builder, bv, v, force)
        return builder.fadd(force, fma(builder, minus_b, v, v), flags=UPDATE_FLAGS)

    fp, f0, f1, f2 = forces
    u = builder.fadd(p, v, flags=UPDATE_FLAGS)
    v = next_delta(v, p, u, fp)
    u0 = builder.fadd(u, v, flags=UPDATE_FLAGS)
    v = next_delta(v, u, u0, f0)
    u1 = builder.fadd(u0, v, flags=UPDATE_FLAGS)
    v = next_delta(v, u0, u1, f1)
    u2 = builder.fadd(u1, v, flags=UPDATE_FLAGS)
    v = next_delta(v, u1, u2, f2)
    u3 = builder.fadd(u2, v, flags=UPDATE_FLAGS)
    return u2, v, (u0, u1, u2, u3)


def _is_literal_width(width) -> bool:
    """Whether ``width`` is a literal int, a multiple of VECTOR (the lanes the code folds to)."""
    return isinstance(width, types.IntegerLiteral) and width.literal_value % VECTOR == 0


def _contiguous_arrays(record, count: int, dtype) -> bool:
    """Whether ``record`` is a tuple type of ``count`` arrays passing :func:`ugens.vector_ir.contiguous`."""
    return (
        isinstance(record, types.BaseTuple)
        and len(record) == count
        and all(contiguous(t, dtype) for t in record.types)
    )


def _scalars(record, count: int, dtype) -> bool:
    """Whether ``record`` is a tuple type of ``count`` scalars of ``dtype``."""
    return (
        isinstance(record, types.BaseTuple) and len(record) == count and all(t == dtype for t in record.types)
    )


def _row_pointers(context, builder, record_type, record, at, vector):
    """:func:`ugens.vector_ir.row_pointer` of each array of a record (a tuple of arrays)."""
    values = cgutils.unpack_tuple(builder, record, len(record_type))
    return [
        row_pointer(context, builder, t, v, at, vector)
        for t, v in zip(record_type.types, values, strict=True)
    ]


@intrinsic
def write_four(typingctx, width, rows, fp, force, out, i, direct):
    """Advance the first ``width`` (a literal multiple of VECTOR) modes of ``rows``, float32
    rows (c0, b = R^2 - c0, g, y = y[n-2] / g, dy = Delta[n-1] / g) on 64-byte lines (the
    held kernels' stack rows, ugens.stack_rows), by the samples i .. i + 3 of ``force``
    (float64, N; fp = the force before sample i, float32), storing y and dy, and write
    out[i + j] = sum_k g_k y_k + direct force[i + j] (float64 out in the bank's output
    units; the sums rounded to float32, the direct term added in float32). Typing refuses
    (numba raises a TypingError) other dtypes, non-contiguous arrays and other widths."""
    if not (
        _is_literal_width(width)
        and _contiguous_arrays(rows, 5, types.float32)
        and fp == types.float32
        and contiguous(force, types.float64)
        and contiguous(out, types.float64)
        and isinstance(i, types.Integer)
        and direct == types.float64
    ):
        return None
    lanes = width.literal_value

    def codegen(context, builder, signature, args):
        _, rows, fp, force, out, at, direct = args
        vector = ir.VectorType(FLOAT, lanes)
        four_doubles = ir.VectorType(DOUBLE, 4)
        pointers = _row_pointers(context, builder, signature.args[1], rows, cgutils.intp_t(0), vector)
        c0v, bv, gv, p, v = (builder.load(row, align=64) for row in pointers)
        samples = row_pointer(context, builder, signature.args[3], force, at, four_doubles)
        forces = builder.fptrunc(builder.load(samples, align=8), ir.VectorType(FLOAT, 4))
        f0, f1, f2 = (builder.extract_element(forces, INDEX(j)) for j in range(3))
        y_next, v, outputs = _pass(builder, lanes, c0v, bv, p, v, (fp, f0, f1, f2))
        builder.store(y_next, pointers[3], align=64)
        builder.store(v, pointers[4], align=64)
        terms = [builder.fmul(gv, uj, flags=UPDATE_FLAGS) for uj in outputs]
        total = _sum_four(builder, *(_fold(builder, t, lanes) for t in terms))
        total = fma(builder, broadcast(builder, builder.fptrunc(direct, FLOAT), 4), forces, total)
        target = row_pointer(context, builder, signature.args[4], out, at, four_doubles)
        builder.store(builder.fpext(total, four_doubles), target, align=8)
        return context.get_dummy_value()

    return types.none(width, rows, fp, force, out, i, direct), codegen


@intrinsic
def add_chunk(typingctx, width, rows, k, forces, sums, by_factor):
    """Advance the modes [k, k + width) (``width`` a literal multiple of VECTOR, k a multiple
    of it) of ``rows`` (c0, b, g, y, dy as in :func:`write_four`) by four samples whose
    preceding forces are ``forces`` (four float32, N), storing y and dy, and add g_k y_k / g_k
    of sample j to the lanes of sums[j] (four float32 rows of ``width`` lanes: per-lane
    partial sums over the chunks of a pass, :func:`write_sums`); in the decay-factor form
    if ``by_factor`` (a literal bool: b = R^2 - c0), else in the delta form (b = b2). The
    mode rows may lie anywhere (ugens.modal_f32.narrow_rows puts them on 64-byte lines, a
    caller's own rows may not be: loads aligned to 64 bytes faulted on them); the sums
    must be on 64-byte lines (ugens.stack_rows)."""
    if not (
        _is_literal_width(width)
        and _contiguous_arrays(rows, 5, types.float32)
        and isinstance(k, types.Integer)
        and _scalars(forces, 4, types.float32)
        and _contiguous_arrays(sums, 4, types.float32)
        and isinstance(by_factor, types.BooleanLiteral)
    ):
        return None
    lanes, form = width.literal_value, by_factor.literal_value

    def codegen(context, builder, signature, args):
        _, rows, at, forces, sums, _ = args
        vector = ir.VectorType(FLOAT, lanes)
        pointers = _row_pointers(context, builder, signature.args[1], rows, at, vector)
        c0v, bv, gv, p, v = (builder.load(row, align=4) for row in pointers)
        forces = cgutils.unpack_tuple(builder, forces, 4)
        y_next, v, outputs = _pass(builder, lanes, c0v, bv, p, v, forces, form)
        builder.store(y_next, pointers[3], align=4)
        builder.store(v, pointers[4], align=4)
        for row, uj in zip(
            _row_pointers(context, builder, signature.args[4], sums, cgutils.intp_t(0), vector),
            outputs,
            strict=True,
        ):
            builder.store(fma(builder, gv, uj, builder.load(row, align=64)), row, align=64)
        return context.get_dummy_value()

    return types.none(width, rows, k, forces, sums, by_factor), codegen


@intrinsic
def write_sums(typingctx, width, sums, out, i, wide):
    """out[i + j] = sum(sums[j]) + wide[j] for j = 0 .. 3: the four float32 rows of ``width``
    lanes (a literal multiple of VECTOR) of :func:`add_chunk` reduced together, converted
    and stored as one vector in ``out`` (float64, the bank's output units), with the four
    float64 ``wide`` (the float64 modes' outputs) added."""
    if not (
        _is_literal_width(width)
        and _contiguous_arrays(sums, 4, types.float32)
        and contiguous(out, types.float64)
        and isinstance(i, types.Integer)
        and _scalars(wide, 4, types.float64)
    ):
        return None
    lanes = width.literal_value

    def codegen(context, builder, signature, args):
        _, sums, out, at, wide = args
        vector = ir.VectorType(FLOAT, lanes)
        four_doubles = ir.VectorType(DOUBLE, 4)
        pointers = _row_pointers(context, builder, signature.args[1], sums, cgutils.intp_t(0), vector)
        rows = [_fold(builder, builder.load(row, align=64), lanes) for row in pointers]
        total = builder.fpext(_sum_four(builder, *rows), four_doubles)
        wide_vector = ir.Constant(four_doubles, ir.Undefined)
        for j, tj in enumerate(cgutils.unpack_tuple(builder, wide, 4)):
            wide_vector = builder.insert_element(wide_vector, tj, INDEX(j))
        target = row_pointer(context, builder, signature.args[2], out, at, four_doubles)
        builder.store(builder.fadd(total, wide_vector), target, align=8)
        return context.get_dummy_value()

    return types.none(width, sums, out, i, wide), codegen


#: float64 lanes of one AVX-512 vector: the float64 modes' chunk (:func:`add_wide_chunk`).
WIDE_VECTOR = 8


@intrinsic
def add_wide_chunk(typingctx, wide, k, forces, sums):
    """Advance the float64 modes [k, k + WIDE_VECTOR) of ``wide`` (the rows c1, c2, g, d,
    y1 = y[n-1], y2 = y[n-2] of ugens.cells.ModeRows, float64, at least k + WIDE_VECTOR
    long) by four samples of the two-pole recursion y[n] = c1 y[n-1] - c2 y[n-2] + g F[n-1]
    (ugens.cells.two_pole, as c1 y[n-1] + (g F - c2 y[n-2])) whose preceding forces are
    ``forces`` (four float64, N), storing y1 and y2, and add sample j's outputs, rounded to
    float32, to the first WIDE_VECTOR lanes of sums[j] (:func:`add_chunk`'s four float32
    rows, on 64-byte lines): no reduction of their own.
    As scalars, two float64 modes took 10-12 % of the time of 254 float32 modes (an FMA
    unit's slot per mode and operation)."""
    if not (
        _contiguous_arrays(wide, 6, types.float64)
        and isinstance(k, types.Integer)
        and _scalars(forces, 4, types.float64)
        and _contiguous_arrays(sums, 4, types.float32)
    ):
        return None

    def codegen(context, builder, signature, args):
        wide, at, forces, sums = args
        vector = ir.VectorType(DOUBLE, WIDE_VECTOR)
        pointers = _row_pointers(context, builder, signature.args[0], wide, at, vector)
        c1v, c2v, gv = (builder.load(row, align=8) for row in pointers[:3])
        y1, y2 = (builder.load(row, align=8) for row in pointers[4:])
        minus_c2 = builder.fneg(c2v)
        narrow = ir.VectorType(FLOAT, WIDE_VECTOR)
        rows = _row_pointers(context, builder, signature.args[3], sums, cgutils.intp_t(0), narrow)
        for f, row in zip(cgutils.unpack_tuple(builder, forces, 4), rows, strict=True):
            drive = builder.fmul(gv, broadcast(builder, f, WIDE_VECTOR), flags=UPDATE_FLAGS)
            y1, y2 = fma(builder, c1v, y1, fma(builder, minus_c2, y2, drive)), y1
            total = builder.fadd(builder.load(row, align=32), builder.fptrunc(y1, narrow), flags=_SUM_FLAGS)
            builder.store(total, row, align=32)
        builder.store(y1, pointers[4], align=8)
        builder.store(y2, pointers[5], align=8)
        return context.get_dummy_value()

    return types.none(wide, k, forces, sums), codegen

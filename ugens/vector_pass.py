"""One four-sample pass of float32 decay-factor modes written as explicit LLVM vectors.

ugens.modal_f32's held kernels keep a bank's rows (16, 32 or 64 modes) on the stack, where
LLVM holds them in vector registers across the passes. From the per-mode loop, LLVM's
vectoriser summed each of the pass's four output samples over the lanes on its own (four
horizontal reductions, each a chain of extracts, shuffles and adds), then converted and
stored the four sums one by one and added the direct term in a pass of its own.
:func:`write_four` reduces the four sums together (pairs of vectors interleaved, halving
the lanes at each step: about half the shuffles and adds), adds the direct term to the
four at once and converts and stores them as one vector: against the C two-pole loop,
0.98x -> 1.09x at 16 modes, 0.96x -> 1.02x at 32, 0.94x -> 1.03x at 64 (one run each).
Larger banks, whose rows stay in memory (ugens.modal_f32.resonate_factor), run
:func:`add_chunk` per 32 modes, the per-lane sums kept in four stack rows, and
:func:`write_sums` at the end of each pass.

The arithmetic per mode is ugens.modal_f32's decay-factor update (``_four_samples``):
with p = y[n-2] / g, v = Delta[n-1] / g and the preceding forces fp, f0, f1, f2,
u = p + v, v' = b v + (f - c0 p) as two fused multiply-adds, in the same order.
"""

from __future__ import annotations

from llvmlite import ir
from numba.core import cgutils, types
from numba.extending import intrinsic

#: float32 lanes of one AVX-512 vector: the reduction first folds wider rows to this.
VECTOR = 16

#: Flags of the update's adds (as ugens.modal_f32's: contraction, no reassociation).
_UPDATE_FLAGS = ("contract", "nsz", "arcp")

#: Flags of the reduction's adds: any order (the sums of a pass are independent of its
#: state, so the order only moves their float32 rounding).
_SUM_FLAGS = ("fast",)

_FLOAT = ir.FloatType()
_INDEX = ir.IntType(32)


def _fma(builder, a, b, c):
    """a b + c, rounded once, lane by lane (llvm.fma)."""
    fnty = ir.FunctionType(a.type, [a.type] * 3)
    return builder.call(
        cgutils.get_or_insert_function(builder.module, fnty, f"llvm.fma.v{a.type.count}f32"), [a, b, c]
    )


def _lanes(builder, a, b, picks):
    """The lanes ``picks`` of a and b concatenated (shufflevector)."""
    return builder.shuffle_vector(a, b, ir.Constant(ir.VectorType(_INDEX, len(picks)), picks))


def _broadcast(builder, x, width):
    vector = ir.VectorType(_FLOAT, width)
    one = builder.insert_element(ir.Constant(vector, ir.Undefined), x, _INDEX(0))
    return _lanes(builder, one, ir.Constant(vector, ir.Undefined), [0] * width)


def _fold(builder, v, width):
    """v's lanes summed down to VECTOR lanes (halves added)."""
    while width > VECTOR:
        half = width // 2
        low, high = list(range(half)), list(range(half, width))
        v = builder.fadd(_lanes(builder, v, v, low), _lanes(builder, v, v, high), flags=_SUM_FLAGS)
        width = half
    return v


def _sum_four(builder, a0, a1, a2, a3):
    """<4 x float> (sum(a0), sum(a1), sum(a2), sum(a3)) of four VECTOR-lane vectors: each
    step adds two shuffles of a pair, so the lanes holding each sum halve together."""

    def pair(x, y, width):  # [x's halves summed, y's halves summed]
        half = width // 2
        low = list(range(half)) + list(range(width, width + half))
        high = list(range(half, width)) + list(range(width + half, 2 * width))
        return builder.fadd(_lanes(builder, x, y, low), _lanes(builder, x, y, high), flags=_SUM_FLAGS)

    x, y = pair(a0, a1, VECTOR), pair(a2, a3, VECTOR)  # groups of VECTOR / 2 lanes: a0 a1 | a2 a3
    group = VECTOR // 2
    quarter = group // 2
    low = [g * group + j for g in range(4) for j in range(quarter)]
    high = [i + quarter for i in low]
    z = builder.fadd(_lanes(builder, x, y, low), _lanes(builder, x, y, high), flags=_SUM_FLAGS)  # VECTOR / 4
    group = quarter
    while group > 1:
        half = group // 2
        low = [g * group + j for g in range(4) for j in range(half)]
        high = [i + half for i in low]
        z = builder.fadd(_lanes(builder, z, z, low), _lanes(builder, z, z, high), flags=_SUM_FLAGS)
        group = half
    return z


def _pass(builder, lanes, c0v, bv, p, v, forces):
    """The four-sample update of vectors of modes with rows c0, b and state p = y[n-2] / g,
    v = Delta[n-1] / g, whose preceding forces are ``forces`` (four float32 scalars):
    (the new p, the new v, the four outputs y / g)."""
    minus_c0 = builder.fneg(c0v)

    def next_delta(v, p, f):  # b v + (f - c0 p)
        return _fma(builder, bv, v, _fma(builder, minus_c0, p, _broadcast(builder, f, lanes)))

    fp, f0, f1, f2 = forces
    u = builder.fadd(p, v, flags=_UPDATE_FLAGS)
    v = next_delta(v, p, fp)
    u0 = builder.fadd(u, v, flags=_UPDATE_FLAGS)
    v = next_delta(v, u, f0)
    u1 = builder.fadd(u0, v, flags=_UPDATE_FLAGS)
    v = next_delta(v, u0, f1)
    u2 = builder.fadd(u1, v, flags=_UPDATE_FLAGS)
    v = next_delta(v, u1, f2)
    u3 = builder.fadd(u2, v, flags=_UPDATE_FLAGS)
    return u2, v, (u0, u1, u2, u3)


@intrinsic
def write_four(typingctx, width, c0, b, g, y, dy, fp, force, out, i, direct):
    """Advance the first ``width`` (a literal multiple of VECTOR) modes of the float32 rows
    c0, b (= R^2 - c0), g, y (= y[n-2] / g), dy (= Delta[n-1] / g) by the four samples i ..
    i + 3 of ``force`` (float64; fp = the force before sample i, float32), storing y and
    dy, and write out[i + j] = sum_k g_k y_k + direct force[i + j] (float64 out; the sums,
    rounded to float32, and the direct term in float32). The rows must start on 64-byte
    lines (the held kernels' stack rows do, ugens.stack_rows)."""
    if not isinstance(width, types.IntegerLiteral) or width.literal_value % VECTOR:
        return None
    if any(not isinstance(a, types.Array) or a.layout != "C" for a in (c0, b, g, y, dy, force, out)):
        return None
    lanes = width.literal_value

    def codegen(context, builder, signature, args):
        vector = ir.VectorType(_FLOAT, lanes)
        four_doubles = ir.VectorType(ir.DoubleType(), 4)

        def data(value, array_type):
            return context.make_array(array_type)(context, builder, value).data

        rows = [
            builder.bitcast(data(value, t), vector.as_pointer())
            for value, t in zip(args[1:6], signature.args[1:6], strict=True)
        ]
        c0v, bv, gv, p, v = (builder.load(row, align=64) for row in rows)
        at = args[9]
        forces = builder.fptrunc(
            builder.load(
                builder.bitcast(
                    builder.gep(data(args[7], signature.args[7]), [at]), four_doubles.as_pointer()
                ),
                align=8,
            ),
            ir.VectorType(_FLOAT, 4),
        )
        f0, f1, f2 = (builder.extract_element(forces, _INDEX(j)) for j in range(3))
        y_next, v, outputs = _pass(builder, lanes, c0v, bv, p, v, (args[6], f0, f1, f2))
        builder.store(y_next, rows[3], align=64)
        builder.store(v, rows[4], align=64)
        terms = [builder.fmul(gv, uj, flags=_UPDATE_FLAGS) for uj in outputs]
        total = _sum_four(builder, *(_fold(builder, t, lanes) for t in terms))
        direct = _broadcast(builder, builder.fptrunc(args[10], _FLOAT), 4)
        total = _fma(builder, direct, forces, total)
        target = builder.gep(data(args[8], signature.args[8]), [at])
        builder.store(
            builder.fpext(total, four_doubles), builder.bitcast(target, four_doubles.as_pointer()), align=8
        )
        return context.get_dummy_value()

    return types.none(width, c0, b, g, y, dy, fp, force, out, i, direct), codegen


def _row_pointer(context, builder, array_type, value, at, vector):
    """The address of element ``at`` of a C-contiguous array as a pointer to ``vector``."""
    data = context.make_array(array_type)(context, builder, value).data
    return builder.bitcast(builder.gep(data, [at]), vector.as_pointer())


def _contiguous(*arrays) -> bool:
    return all(isinstance(a, types.Array) and a.layout == "C" for a in arrays)


@intrinsic
def add_chunk(typingctx, width, c0, b, g, y, dy, k, fp, f0, f1, f2, s0, s1, s2, s3):
    """Advance the modes [k, k + width) (``width`` a literal multiple of VECTOR, k a multiple
    of it) of the float32 rows c0, b (= R^2 - c0), g, y (= y[n-2] / g), dy (= Delta[n-1] /
    g) by four samples whose preceding forces are fp, f0, f1, f2 (float32), storing y and
    dy, and add g_k y_k / g_k of sample j to the lanes of the float32 row s_j (of
    ``width`` lanes: per-lane partial sums over the chunks of a pass, :func:`write_sums`).
    The mode rows may lie anywhere (ugens.modal_f32.narrow_rows puts them on 64-byte lines,
    a caller's own rows may not be: loads aligned to 64 bytes faulted on them); the sums
    must be on 64-byte lines (ugens.stack_rows)."""
    if not isinstance(width, types.IntegerLiteral) or width.literal_value % VECTOR:
        return None
    if not _contiguous(c0, b, g, y, dy, s0, s1, s2, s3):
        return None
    lanes = width.literal_value

    def codegen(context, builder, signature, args):
        vector = ir.VectorType(_FLOAT, lanes)
        at = args[6]
        rows = [
            _row_pointer(context, builder, t, value, at, vector)
            for value, t in zip(args[1:6], signature.args[1:6], strict=True)
        ]
        c0v, bv, gv, p, v = (builder.load(row, align=4) for row in rows)
        y_next, v, outputs = _pass(builder, lanes, c0v, bv, p, v, args[7:11])
        builder.store(y_next, rows[3], align=4)
        builder.store(v, rows[4], align=4)
        for value, t, uj in zip(args[11:15], signature.args[11:15], outputs, strict=True):
            sums = _row_pointer(context, builder, t, value, cgutils.intp_t(0), vector)
            builder.store(_fma(builder, gv, uj, builder.load(sums, align=64)), sums, align=64)
        return context.get_dummy_value()

    return types.none(width, c0, b, g, y, dy, k, fp, f0, f1, f2, s0, s1, s2, s3), codegen


@intrinsic
def write_sums(typingctx, width, s0, s1, s2, s3, out, i, t0, t1, t2, t3):
    """out[i + j] = sum(s_j) + t_j for j = 0 .. 3: the four float32 rows of ``width`` lanes
    (a literal multiple of VECTOR) of :func:`add_chunk` reduced together, converted and
    stored as one vector, with the float64 t_j (the float64 modes' outputs) added."""
    if not isinstance(width, types.IntegerLiteral) or width.literal_value % VECTOR:
        return None
    if not _contiguous(s0, s1, s2, s3, out):
        return None
    lanes = width.literal_value

    def codegen(context, builder, signature, args):
        vector = ir.VectorType(_FLOAT, lanes)
        four_doubles = ir.VectorType(ir.DoubleType(), 4)
        sums = [
            builder.load(_row_pointer(context, builder, t, value, cgutils.intp_t(0), vector), align=64)
            for value, t in zip(args[1:5], signature.args[1:5], strict=True)
        ]
        total = builder.fpext(_sum_four(builder, *(_fold(builder, s, lanes) for s in sums)), four_doubles)
        wide = ir.Constant(four_doubles, ir.Undefined)
        for j, tj in enumerate(args[7:11]):
            wide = builder.insert_element(wide, tj, _INDEX(j))
        target = _row_pointer(context, builder, signature.args[5], args[5], args[6], four_doubles)
        builder.store(builder.fadd(total, wide), target, align=8)
        return context.get_dummy_value()

    return types.none(width, s0, s1, s2, s3, out, i, t0, t1, t2, t3), codegen

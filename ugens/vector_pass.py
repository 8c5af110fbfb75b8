"""One four-sample pass of float32 decay-factor modes written as explicit LLVM vectors.

ugens.modal_f32's held kernels keep a bank's rows on the stack, where LLVM holds them in
vector registers across the passes. At 64 modes (four AVX-512 vectors per row), the code
LLVM vectorises from the per-mode loop sums each of the pass's four output samples over
the lanes on its own (four horizontal reductions, each a chain of extracts, shuffles and
adds); :func:`four_samples` reduces the four together (pairs of vectors interleaved,
halving the lanes at each step: about half the shuffles and adds), which took the
64-mode kernel from 0.94x to 0.99x the C two-pole loop. At 16 and 32 modes LLVM's own
code was faster (0.98x against 0.94x at 16), so only the 64-mode kernel uses this.

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


@intrinsic
def four_samples(typingctx, width, c0, b, g, y, dy, fp, f0, f1, f2):
    """Advance the first ``width`` (a literal multiple of VECTOR) modes of the float32 rows
    c0, b (= R^2 - c0), g, y (= y[n-2] / g), dy (= Delta[n-1] / g) by four samples whose
    preceding forces are fp, f0, f1, f2 (float32), storing y and dy; return the four
    output sums sum_k g_k y_k[n + j] (float32). The rows must start on 64-byte lines (the
    held kernels' stack rows do, ugens.stack_rows)."""
    if not isinstance(width, types.IntegerLiteral) or width.literal_value % VECTOR:
        return None
    lanes = width.literal_value
    result = types.UniTuple(types.float32, 4)

    def codegen(context, builder, signature, args):
        vector = ir.VectorType(_FLOAT, lanes)

        def load_row(value, array_type):
            data = context.make_array(array_type)(context, builder, value).data
            return builder.bitcast(data, vector.as_pointer())

        rows = [load_row(value, t) for value, t in zip(args[1:6], signature.args[1:6], strict=True)]
        c0v, bv, gv, p, v = (builder.load(row, align=64) for row in rows)
        minus_c0 = builder.fneg(c0v)

        def next_delta(v, p, f):  # b v + (f - c0 p)
            return _fma(builder, bv, v, _fma(builder, minus_c0, p, _broadcast(builder, f, lanes)))

        fp, f0, f1, f2 = args[6:]
        u = builder.fadd(p, v, flags=_UPDATE_FLAGS)
        v = next_delta(v, p, fp)
        u0 = builder.fadd(u, v, flags=_UPDATE_FLAGS)
        v = next_delta(v, u, f0)
        u1 = builder.fadd(u0, v, flags=_UPDATE_FLAGS)
        v = next_delta(v, u0, f1)
        u2 = builder.fadd(u1, v, flags=_UPDATE_FLAGS)
        v = next_delta(v, u1, f2)
        u3 = builder.fadd(u2, v, flags=_UPDATE_FLAGS)
        builder.store(u2, rows[3], align=64)
        builder.store(v, rows[4], align=64)
        terms = [builder.fmul(gv, uj, flags=_UPDATE_FLAGS) for uj in (u0, u1, u2, u3)]
        total = _sum_four(builder, *(_fold(builder, t, lanes) for t in terms))
        return context.make_tuple(
            builder, result, [builder.extract_element(total, _INDEX(j)) for j in range(4)]
        )

    return result(width, c0, b, g, y, dy, fp, f0, f1, f2), codegen

"""Building blocks of the explicit-vector intrinsics (llvmlite IR inside numba intrinsics):
the fused multiply-add, lane shuffles and broadcasts, the address of an array element as a
vector pointer, the argument check and the fast-math flags of their state updates they share.
Used by ugens.vector_pass (float32 modal passes), ugens.modal_block (block kernels of small
banks), ugens.modal_kept (a mode budget's kept modes) and ugens.real_fft (its butterflies)."""

from __future__ import annotations

from llvmlite import ir
from numba.core import cgutils, types

DOUBLE = ir.DoubleType()
FLOAT = ir.FloatType()
INDEX = ir.IntType(32)

#: Fast-math flags of a state update's multiplies and adds (as ugens.modal_f32's numba
#: kernels): contraction into fused multiply-adds, no reassociation.
UPDATE_FLAGS = ("contract", "nsz", "arcp")


def fma(builder, a, b, c):
    """a b + c, rounded once, lane by lane (llvm.fma; float32 or float64 vectors)."""
    fnty = ir.FunctionType(a.type, [a.type] * 3)
    element = "f64" if isinstance(a.type.element, ir.DoubleType) else "f32"
    return builder.call(
        cgutils.get_or_insert_function(builder.module, fnty, f"llvm.fma.v{a.type.count}{element}"), [a, b, c]
    )


def shuffle(builder, a, b, picks):
    """The lanes ``picks`` of a and b concatenated (shufflevector)."""
    return builder.shuffle_vector(a, b, ir.Constant(ir.VectorType(INDEX, len(picks)), picks))


def broadcast(builder, x, width):
    """A vector of ``width`` lanes, each the scalar x (float32 or float64; insert, shuffle)."""
    vector = ir.VectorType(x.type, width)
    one = builder.insert_element(ir.Constant(vector, ir.Undefined), x, INDEX(0))
    return shuffle(builder, one, one, [0] * width)


def contiguous(array, dtype=types.float64) -> bool:
    """Whether ``array`` is a 1-D C-contiguous array of ``dtype``: the intrinsics read and
    write its data as vectors of that type."""
    return isinstance(array, types.Array) and array.ndim == 1 and array.layout == "C" and array.dtype == dtype


def row_pointer(context, builder, array_type, value, at, vector):
    """The address of element ``at`` of a C-contiguous array as a pointer to ``vector``."""
    data = context.make_array(array_type)(context, builder, value).data
    return builder.bitcast(builder.gep(data, [at]), vector.as_pointer())

"""Float32 rows on a kernel's own stack, for state that should stay in registers.

A kernel that keeps a few modes' state in arrays it was handed loads and stores that state
through memory on every pass: LLVM cannot prove that the output it writes in between does
not overlap it, so it may not keep the state in registers. Rows in a stack slot of the
kernel (an ``alloca`` whose address never leaves the inlined code) cannot overlap any
argument: when their size is a compile-time constant and the loops over them are fully
unrolled, LLVM keeps them in vector registers across the whole sample loop.
"""

from __future__ import annotations

from llvmlite import ir
from numba.core import cgutils, types
from numba.extending import intrinsic
from numba.np.arrayobj import make_array, populate_array

#: Stack rows start on a cache line (one AVX-512 vector of float32).
ALIGN = 64


@intrinsic
def stack_row(typingctx, width):
    """A float32 array of ``width`` (a literal int) in the calling function's stack frame,
    64-byte aligned, allocated once in its entry block and not initialised. It lives until
    that function returns: never return it or keep it elsewhere, and call it only from an
    njit function compiled on its own (numba inlines ``inline="always"`` functions into
    their callers' loops). One slot per row: LLVM kept five rows of 64 modes in registers
    as five slots, not as one (5, 64) slot."""
    if not isinstance(width, types.IntegerLiteral) or width.literal_value < 1:
        return None
    count = width.literal_value
    array_type = types.Array(types.float32, 1, "C")

    def codegen(context, builder, signature, args):
        with builder.goto_entry_block():
            slot = builder.alloca(ir.ArrayType(ir.FloatType(), count))
            slot.align = ALIGN
        array = make_array(array_type)(context, builder)
        populate_array(
            array,
            data=builder.bitcast(slot, ir.PointerType(ir.FloatType())),
            shape=[cgutils.intp_t(count)],
            strides=[cgutils.intp_t(4)],
            itemsize=cgutils.intp_t(4),
            meminfo=None,
        )
        return array._getvalue()

    return array_type(width), codegen

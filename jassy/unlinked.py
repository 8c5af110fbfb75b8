"""Calls of numba kernels compiled apart: not linked into their callers, so compiled once.

numba links the code of every kernel a kernel calls into the caller's module (as
``linkonce_odr`` copies) and LLVM optimises and generates code for the whole linked tree
again at each level. A large callee called from three levels is optimised four times, and
the top of a deep tree (the rigid step) re-optimises everything below it: on a fresh install
that is most of the first compile. :func:`call_apart` calls a kernel through the address of
its compiled code instead. Its caller's module holds only an indirect call; the callee is
compiled (or loaded from numba's cache) alone, and two processes can compile callee and
caller side by side.

The address is an argument, known only at run time (an address differs from process to
process, and numba's cache keeps a caller across processes): :func:`entry` gives it in
Python as an :class:`Entry`, with a checksum of the callee's compiled argument types. The
call compares that checksum with the one of the types it passes and raises a RuntimeError
if they differ (an entry point made for other types would read its arguments wrongly). The
checksum covers what numba's type names leave out: a NamedTuple's class (module and name)
and field names, and the record a reference points to.

The callee runs as its own compiled code, not as a copy optimised inside the caller: no
floating-point operation changes for kernels compiled without fastmath (LLVM keeps IEEE
semantics across inlining). The call passes numba's native arguments, as a call of a linked
kernel that LLVM does not inline does: a record (NamedTuple) of arrays is flattened into
all its arrays' fields (hundreds of scalars for a large one), so a callee called often
should take large records by reference (physics.rigid.record_ref) and read the fields it
uses once. A kernel called apart may also be linked into other kernels: numba finalises a
callee's library and adds it to the JIT before any caller links it (``_get_module_for_linking``
calls ``_ensure_finalized``), the linked copies are ``linkonce_odr`` clones that do not
replace its symbol, and numba never removes a module, so an address stays valid for the
process.

Checked against numba 0.68.1: ``numba/core/callconv.py`` (``CPUCallConv.get_function_type``,
``call_function``, ``return_status_propagate``, ``return_user_exc``: the native calling
convention the indirect call follows) and ``numba/core/codegen.py``
(``CPUCodeLibrary.get_pointer_to_function``, ``_get_module_for_linking``, ``add_linking_library``).
"""

from __future__ import annotations

import zlib
from typing import NamedTuple

import numba as nb
from llvmlite import ir as llvmir
from numba.core import cgutils, config, types
from numba.core.typing import signature
from numba.extending import intrinsic


class Entry(NamedTuple):
    """A compiled kernel's entry point: the address of its native function and a checksum of
    the argument and result types it was compiled for (:func:`types_checksum`). With numba's
    JIT off, ``address`` is the kernel's Python function."""

    address: int
    types: int


def described(numba_type):
    """``numba_type``'s repr, with what the repr leaves out made explicit, recursively: a
    NamedTuple's class (module, qualified name) and field names, a tuple's members, and the
    record type of a reference to a record (a type with ``record_type``)."""
    if isinstance(numba_type, types.BaseNamedTuple):
        cls = numba_type.instance_class
        members = tuple(described(t) for t in numba_type.types)
        return (cls.__module__, cls.__qualname__, tuple(numba_type.fields), members)
    if isinstance(numba_type, types.BaseTuple):
        return ("tuple", tuple(described(t) for t in numba_type.types))
    record_type = getattr(numba_type, "record_type", None)
    if isinstance(record_type, types.Type):
        return (repr(numba_type), described(record_type))
    return repr(numba_type)


def types_checksum(argument_types, result_type) -> int:
    """A checksum (CRC-32) of numba argument and result types (:func:`described`), the same
    in every process."""
    text = repr((tuple(described(t) for t in argument_types), described(result_type)))
    return zlib.crc32(text.encode())


def entry(kernel, *example_args) -> Entry:
    """The :class:`Entry` of numba ``kernel`` compiled (or loaded from numba's cache) for
    the types of ``example_args``; :func:`call_apart` passes it arguments of those types."""
    if config.DISABLE_JIT:
        return Entry(kernel, 0)
    key = tuple(nb.typeof(a) for a in example_args)
    kernel.compile(key)
    compiled = kernel.overloads[key]
    address = compiled.library.get_pointer_to_function(compiled.fndesc.llvm_func_name)
    if not address:
        raise RuntimeError(f"entry: numba gave no address for {kernel.__name__}{key}")
    return Entry(int(address), types_checksum(compiled.signature.args, compiled.signature.return_type))


def unset(entries_class, **given):
    """A record (NamedTuple) ``entries_class`` of entry points with every field not in
    ``given`` an unset :class:`Entry` (address 0): an example argument of the record's
    types, for compiling a caller ahead."""
    return entries_class(**{name: given.get(name, Entry(0, 0)) for name in entries_class._fields})


def entries_of(entries_class, calls: dict):
    """The record ``entries_class`` of the :func:`entry` of each of its fields' (kernel,
    example arguments) in ``calls``."""
    return entries_class(*(entry(calls[name][0], *calls[name][1]) for name in entries_class._fields))


@intrinsic
def _call_apart(typingctx, where, args, result):
    """Compiled :func:`call_apart`: an indirect call of numba's native calling convention,
    the callee's status (an exception) passed on; a RuntimeError if ``where``'s checksum is
    not that of ``args``' types and ``result``."""
    is_entry = isinstance(where, types.BaseNamedTuple) and where.instance_class is Entry
    if not is_entry or not isinstance(args, types.BaseTuple) or not isinstance(result, types.NumberClass):
        return None
    argument_types = tuple(types.unliteral(t) for t in args)
    result_type = result.instance_type
    checksum = types_checksum(argument_types, result_type)

    def codegen(context, builder, sig, llargs):
        where_value, tuple_value, _ = llargs
        address = builder.extract_value(where_value, 0)
        found = builder.extract_value(where_value, 1)
        wrong = builder.icmp_signed("!=", found, llvmir.Constant(found.type, checksum))
        with builder.if_then(wrong, likely=False):
            message = f"call_apart: the entry point was compiled for other types than {argument_types}"
            context.call_conv.return_user_exc(builder, RuntimeError, (message,))
        values = [
            context.cast(builder, builder.extract_value(tuple_value, i), have, want)
            for i, (have, want) in enumerate(zip(args, argument_types, strict=True))
        ]
        function_type = context.call_conv.get_function_type(result_type, argument_types)
        pointer = builder.inttoptr(address, function_type.as_pointer())
        status, value = context.call_conv.call_function(builder, pointer, result_type, argument_types, values)
        with cgutils.if_unlikely(builder, status.is_error):
            context.call_conv.return_status_propagate(builder, status)
        return value

    return signature(result_type, where, args, result), codegen


def _call_in_python(where: Entry, args: tuple, result):
    """call_apart with numba's JIT off: the kernel's Python function, called."""
    return where.address(*args)


#: call_apart(where, args, result): ``kernel(*args)`` for the kernel whose :func:`entry`
#: ``where`` is, called through its address (not linked into the caller: module doc);
#: ``result`` is its numba result type (``numba.int64``, ``numba.float64``, ...). Typing the
#: caller compiles nothing of the callee. Raises a RuntimeError when ``where`` was compiled
#: for other types than ``args``' and ``result``. The intrinsic itself, not an overload
#: inlined at numba's level: numba runs its dead-code elimination over a kernel each time it
#: inlines an overload there, and that elimination drops writes into arrays taken out of a
#: record by tuple unpacking (``a, b = rec.a, rec.b``) that nothing reads afterwards. With
#: numba's JIT off, calls the Python function.
call_apart = _call_in_python if config.DISABLE_JIT else _call_apart

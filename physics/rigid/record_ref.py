"""Records of arrays passed to compiled code by reference: one pointer instead of the record.

numba holds a record (a NamedTuple of arrays, such as the rigid step's Model or Data) as one
LLVM value of all its arrays' fields (data pointer, shape, strides, ...: about 7 scalars an
array, some 400 for Data). Every read of a field of a record variable loads that whole value
and every call of a kernel inlined at numba's level copies it into new variables, so a kernel
that reads many fields of a large record gives LLVM tens of thousands of scalar loads and
stores to take apart again (its SROA pass: most of the rigid step's first compile).

:func:`ref` stores a record once, in its caller's stack frame, and gives a
:class:`RecordRef`: a pointer to it, typed by the record's numba type. ``r.field`` reads only
that field through the pointer (a nested record comes back as a value; :func:`ref` it too
if it is large), and ``deref(r)`` gives the whole record back. While the reference stays in
the kernel that made it (used in kernels inlined at numba's level, not passed to another
kernel), LLVM turns the stored record back into its values: the same code as the record
itself. Passed to another kernel it is one argument, but its fields are then read from memory
at each use.

A ref owns nothing. It points into the frame of the kernel that called :func:`ref` (never
keep, return or store it), at a copy of the record's array descriptors, not at the arrays'
owners: numba's reference counting (NRT) may free a record's arrays after the record's last
use, which can be the ``ref`` call itself, and reads through the ref would then see freed
memory. So :func:`ref` is refused (a compile error) in a kernel compiled with reference
counting: only kernels compiled with ``_nrt=False`` (whose arrays belong to the caller for
the whole call) may make refs; a kernel given a ref may count references. One ``ref`` call
site stores into one stack slot however often it runs: a ref made in an earlier iteration of
a loop reads the record stored by the latest one. With numba's JIT off (NUMBA_DISABLE_JIT=1)
both functions return their argument, whose fields read the same.
"""

from __future__ import annotations

from numba import typeof
from numba.core import cgutils, config, errors, ir_utils, types
from numba.core.datamodel import models
from numba.core.imputils import impl_ret_borrowed
from numba.core.typing.templates import AttributeTemplate
from numba.extending import (
    infer_getattr,
    intrinsic,
    lower_getattr_generic,
    register_model,
    typeof_impl,
)

#: Why :func:`ref` is refused in a kernel that counts references (module docstring).
NRT_REFUSED = (
    "record_ref.ref in a kernel compiled with reference counting: the record's arrays may be "
    "freed while the ref is read; compile the kernel with _nrt=False"
)


class RecordRef(types.Type):
    """numba type of a pointer to a stored record of numba type ``record_type`` (a
    NamedTuple type)."""

    def __init__(self, record_type):
        self.record_type = record_type
        super().__init__(name=f"RecordRef({record_type})")

    @property
    def key(self):
        return self.record_type


class RefExample:
    """An example argument of :class:`RecordRef` type, for compiling a kernel ahead for the
    types its callers pass (``numba.typeof`` gives RecordRef of ``record``'s type); a kernel
    cannot be called with it."""

    def __init__(self, record):
        self.record = record


@typeof_impl.register(RefExample)
def _typeof_ref_example(example, context):
    return RecordRef(typeof(example.record))


@register_model(RecordRef)
class _RecordRefModel(models.PrimitiveModel):
    """A RecordRef is the address of the record's data representation."""

    def __init__(self, dmm, fe_type):
        super().__init__(dmm, fe_type, dmm.lookup(fe_type.record_type).get_data_type().as_pointer())


@infer_getattr
class _RecordRefFields(AttributeTemplate):
    key = RecordRef

    def generic_resolve(self, ref_type, attr):
        record = ref_type.record_type
        if attr in record.fields:
            return record.types[record.fields.index(attr)]
        return None


@lower_getattr_generic(RecordRef)
def _field(context, builder, ref_type, pointer, attr):
    """Load one field of the record through the pointer (its data representation)."""
    record = ref_type.record_type
    index = record.fields.index(attr)
    field_pointer = cgutils.gep_inbounds(builder, pointer, 0, index)
    field_type = record.types[index]
    value = context.data_model_manager[field_type].load_from_data_pointer(builder, field_pointer)
    return impl_ret_borrowed(context, builder, field_type, value)  # a new reference, as numba expects


@intrinsic(prefer_literal=False)
def _ref(typingctx, record):
    if not isinstance(record, types.BaseNamedTuple):
        return None

    def codegen(context, builder, signature, args):
        # Checked here, where the calling kernel is lowered, not at typing: numba types an
        # intrinsic once per argument types and reuses that for kernels with other flags.
        if context.enable_nrt:
            raise errors.TypingError(NRT_REFUSED)
        model = context.data_model_manager[record]
        slot = cgutils.alloca_once(builder, model.get_data_type())
        builder.store(model.as_data(builder, args[0]), slot)
        return slot

    return RecordRef(record)(record), codegen


@intrinsic(prefer_literal=False)
def _deref(typingctx, record_ref):
    if not isinstance(record_ref, RecordRef):
        return None

    def codegen(context, builder, signature, args):
        record = record_ref.record_type
        value = context.data_model_manager[record].load_from_data_pointer(builder, args[0])
        return impl_ret_borrowed(context, builder, record, value)

    return record_ref.record_type(record_ref), codegen


@intrinsic(prefer_literal=True)
def _field_ref(typingctx, record_ref, name):
    if not isinstance(record_ref, RecordRef) or not isinstance(name, types.StringLiteral):
        return None
    record = record_ref.record_type
    if name.literal_value not in record.fields:
        return None
    index = record.fields.index(name.literal_value)
    field_type = record.types[index]
    if not isinstance(field_type, types.BaseNamedTuple):
        return None

    def codegen(context, builder, signature, args):
        return cgutils.gep_inbounds(builder, args[0], 0, index)

    return RecordRef(field_type)(record_ref, name), codegen


def _aliases_its_record(lhs, args, alias_map, arg_aliases):
    """numba's alias analysis: a ref (or a deref) aliases its argument. Without this, numba's
    dead code elimination (run where an overload is inlined) takes a ref for new memory and
    drops the writes through it made in a kernel inlined at numba's level."""
    ir_utils._add_alias(lhs, args[0].name, alias_map, arg_aliases)


# numba's find_callname names a call by the function's __name__ when it was imported by name
# (``ref(x)``: "_ref") and by the attribute read when called through the module
# (``record_ref.ref(x)``: "ref"): both spellings are registered.
ir_utils.alias_func_extensions.update(
    {
        (name, __name__): _aliases_its_record
        for name in ("_ref", "ref", "_deref", "deref", "_field_ref", "field_ref")
    }
)


def _itself(value):
    return value


def _field_itself(record, name):
    return getattr(record, name)


#: ref(record): a reference to ``record`` (module doc); deref(ref): the record it refers to;
#: field_ref(ref, "name"): a reference to the record's field ``name`` (a record itself,
#: ``name`` a string constant), pointing into the referred record: nothing is copied.
#: Intrinsics, so that the record is stored in the frame of the kernel that calls ref. With
#: numba's JIT off (an intrinsic cannot run as Python) ref and deref return their argument,
#: field_ref the field.
ref, deref, field_ref = (
    (_itself, _itself, _field_itself) if config.DISABLE_JIT else (_ref, _deref, _field_ref)
)

"""numba's typing of a call to a builtin (``a * b``, ``x[i, j]``, ``bool(c)``, ...) done once per
argument types, not once per call site and pass.

numba types each call by trying every typing template registered for the callee (for
``operator.mul``: numba's own tables, its NumPy rules, and every ``@overload`` of ``*`` in
numba's modules) until one matches, and collects an error message for each one that does not.
Type inference repeats this for every call site in every pass over a function, and a kernel
with many inlined helpers has thousands of identical ones: a first ``jassy render wok`` in one
process, without this module (``NUMBA_CACHE_DIR=$(mktemp -d) python
benchmarks/typing_repeats.py``), made 28826 resolutions, 28371 of them with callee and types
resolved before (9.2 s of the 22.5 s of CPU, counter included, spent in them). Here a
resolution whose winning template is one of numba's plain typing tables (its implementation
key is the function's typing key, the same for every signature) is remembered, by the callee's
type, the typing context, the target and the argument types, and returned again. A resolution
won by an ``@overload`` or ``@intrinsic`` template is not remembered: its implementation
(which the lowering looks up by the argument types) is compiled per calling kernel's compiler
flags, so numba types it again as before. Failures are not remembered either (numba raises
them again). Installed by :mod:`jassy.jit`; left out, with numba's behaviour kept, if numba's
function types are shaped otherwise (see :func:`install`).

Checked against numba 0.68.1's ``numba/core/types/functions.py``
(``BaseFunction.get_call_type``, which records ``_impl_keys[sig.args]``) and
``numba/core/target_extension.py`` (``get_local_target``).
"""

from __future__ import annotations

from numba.core.types import functions


def remembers(function_type, signature) -> bool:
    """Whether the resolution of ``function_type`` to ``signature`` that numba just made may
    be returned again for the same argument types: the winning template's implementation
    key (recorded by numba for ``signature.args``) is the function's typing key itself."""
    return function_type._impl_keys.get(signature.args) is function_type.typing_key


def shaped_as_expected() -> bool:
    """Whether numba's ``BaseFunction`` records implementation keys by argument types and
    has a typing key, as :func:`remembers` reads them."""
    base = getattr(functions, "BaseFunction", None)
    if base is None or not callable(getattr(base, "get_call_type", None)):
        return False
    try:
        import operator

        from numba.core import types
        from numba.core.registry import cpu_target
        from numba.core.target_extension import get_local_target  # noqa: F401 (install's)

        context = cpu_target.typing_context
        context.refresh()
        function_type = context.resolve_value_type(operator.add)
        signature = function_type.get_call_type(context, (types.float64, types.float64), {})
    except Exception:  # noqa: BLE001 (any other shape: keep numba's behaviour)
        return False
    return isinstance(getattr(function_type, "_impl_keys", None), dict) and remembers(
        function_type, signature
    )


def install() -> bool:
    """Remember plain-table resolutions in ``BaseFunction.get_call_type``; True if installed
    (now or before), False if numba is shaped otherwise (numba's typing left as it is)."""
    base = getattr(functions, "BaseFunction", None)
    if base is not None and getattr(base.get_call_type, "remembers_resolutions", False):
        return True
    if not shaped_as_expected():
        return False
    from numba.core.target_extension import get_local_target

    get_call_type = base.get_call_type
    remembered: dict[tuple, object] = {}

    def get_call_type_remembered(self, context, args, kws):
        try:
            key = (self, context, get_local_target(context), tuple(args), tuple(sorted(kws.items())))
            found = remembered.get(key)
        except TypeError:  # an unhashable argument type
            return get_call_type(self, context, args, kws)
        if found is not None:
            return found
        signature = get_call_type(self, context, args, kws)
        if signature is not None and remembers(self, signature):
            remembered[key] = signature
        return signature

    get_call_type_remembered.remembers_resolutions = True
    get_call_type_remembered.numbas = get_call_type
    base.get_call_type = get_call_type_remembered
    return True

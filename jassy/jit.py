"""numba helpers shared by the engine and the ugens."""

from __future__ import annotations

from collections.abc import Callable

import numba as nb


def specialise(kernel: Callable, *example_args) -> Callable:
    """The compiled entry point of numba ``kernel`` for the types of ``example_args``.

    A numba dispatcher re-derives the types of its arguments on every call (about 0.3 us
    for a handful of arrays), which matters for kernels called once per 64-frame block.
    A ugen whose kernel arguments are arrays it allocated itself (C-contiguous float64,
    as every ``UGen.out`` is) can call the typed entry point directly. The caller must
    pass arguments of exactly those types. Falls back to the dispatcher if numba does
    not expose the entry point.
    """
    signature = tuple(nb.typeof(a) for a in example_args)
    try:
        kernel.compile(signature)
        return kernel.overloads[signature].entry_point
    except (AttributeError, KeyError, TypeError):
        return kernel

"""numba helpers shared by the engine and the ugens."""

from __future__ import annotations

import contextlib
import ctypes
import fcntl
import os
import sys
from collections.abc import Callable
from types import ModuleType
from typing import Any, NamedTuple

import numba as nb
import numpy as np
from llvmlite import binding as llvm
from llvmlite import ir as llvmir
from numba.core import caching, cgutils, codegen, dispatcher, errors, event, targetconfig, types
from numba.core.compiler import Flags
from numba.extending import intrinsic

from jassy import inline_copies, remembered_typing


def address(array: np.ndarray) -> int:
    """The address of ``array``'s first element, as ``array.ctypes.data`` gives it (which
    builds a ctypes helper object per call: about 3x slower for the arrays a program's
    table and control slots point to, a few dozen per render)."""
    try:
        return ctypes.addressof(ctypes.c_char.from_buffer(array))
    except (TypeError, ValueError, BufferError):  # read-only, not contiguous, or empty
        return array.ctypes.data


@intrinsic
def void_pointer(typingctx, address):
    """The int64 ``address`` (an array's ``ctypes.data``) as a ``void *``, for numba.carray
    views of arrays kept alive elsewhere."""
    sig = types.voidptr(types.int64)

    def codegen(context, builder, signature, args):
        return builder.inttoptr(args[0], cgutils.voidptr_t)

    return sig, codegen


@intrinsic
def call_void(typingctx, function, a, b, c, d):
    """Call the compiled C function ``void f(int64, int64, int64, int64)`` at address
    ``function`` (a cached ``numba.cfunc``: compiled once, not linked into its callers)."""
    sig = types.void(types.int64, types.int64, types.int64, types.int64, types.int64)

    def codegen(context, builder, signature, args):
        i64 = llvmir.IntType(64)
        pointer = builder.inttoptr(args[0], llvmir.FunctionType(llvmir.VoidType(), [i64] * 4).as_pointer())
        builder.call(pointer, args[1:])
        return context.get_dummy_value()

    return sig, codegen


@intrinsic
def prefetch_for_write(typingctx, address):
    """Ask for the cache line holding ``address`` ahead of a write (LLVM's ``prefetch``
    hint: write, high locality, data cache); never faults, and changes no value."""
    sig = types.void(types.int64)

    def codegen(context, builder, signature, args):
        byte_pointer, i32 = llvmir.IntType(8).as_pointer(), llvmir.IntType(32)
        kind = llvmir.FunctionType(llvmir.VoidType(), [byte_pointer, i32, i32, i32])
        prefetch = cgutils.get_or_insert_function(builder.module, kind, "llvm.prefetch.p0i8")
        write, keep, data = (llvmir.Constant(i32, v) for v in (1, 3, 1))
        builder.call(prefetch, [builder.inttoptr(args[0], byte_pointer), write, keep, data])
        return context.get_dummy_value()

    return sig, codegen


#: Entry points found by :func:`specialise`, by (kernel, type key of the arguments).
_ENTRY_POINTS: dict[tuple, Callable] = {}


def _type_key(value: Any) -> Any:
    """A key that determines numba's type of ``value`` (arrays, small ints, floats, bools and
    tuples or NamedTuple records of them), or None for anything else."""
    kind = type(value)
    if kind is np.ndarray:
        f = value.flags
        return (value.dtype, value.ndim, f.c_contiguous, f.f_contiguous, f.writeable, f.aligned)
    if kind is float or kind is bool or (kind is int and -(2**62) < value < 2**62):
        return kind
    if kind is tuple or (isinstance(value, tuple) and hasattr(kind, "_fields")):  # NamedTuple records too
        keys = tuple(_type_key(v) for v in value)
        return None if None in keys else (kind, keys)
    return None


def specialise(kernel: Callable, *example_args) -> Callable:
    """The compiled entry point of numba ``kernel`` for the types of ``example_args``.

    A numba dispatcher re-derives the types of its arguments on every call (about 0.3 us
    for a handful of arrays), which matters for kernels called once per 64-frame block.
    A ugen whose kernel arguments are arrays it allocated itself (C-contiguous float64,
    as every ``UGen.out`` is) can call the typed entry point directly. The caller must
    pass arguments of exactly those types. Falls back to the dispatcher if numba does
    not expose the entry point. Entry points are remembered by a cheap key of the argument
    types (numba's own typing of a handful of arrays takes tens of microseconds).
    """
    key = _type_key(example_args)
    found = _ENTRY_POINTS.get((kernel, key)) if key is not None else None
    if found is not None:
        return found
    signature = tuple(nb.typeof(a) for a in example_args)
    try:
        kernel.compile(signature)
        entry = kernel.overloads[signature].entry_point
    except (AttributeError, KeyError, TypeError):
        return kernel
    if key is not None:
        _ENTRY_POINTS[(kernel, key)] = entry
    return entry


#: The callee modules each module passed to :func:`drop_stale_cache`, by its ``__file__``.
_RECORDED_CALLEES: dict[str, tuple[ModuleType, ...]] = {}


def callee_closure(module_file: str) -> list[ModuleType]:
    """The modules recorded as callees of ``module_file``, their recorded callees, and so on
    (sorted by name, without ``module_file``'s own module)."""
    found: dict[str, ModuleType] = {}
    pending = list(_RECORDED_CALLEES.get(module_file, ()))
    while pending:
        module = pending.pop()
        if module.__name__ in found or module.__file__ == module_file:
            continue
        found[module.__name__] = module
        pending.extend(_RECORDED_CALLEES.get(module.__file__, ()))
    return [found[name] for name in sorted(found)]


def cache_folder(module_file: str) -> str | None:
    """The folder numba caches ``module_file``'s functions in, found by numba's own cache
    locators in numba's order (``NUMBA_CACHE_DIR``'s mirror of the source folder if set,
    else the module's ``__pycache__`` if writable, else the user-wide cache folder), or None
    if none accepts the file. Creates the folder, as numba does when it caches there."""

    def stand_in():
        """A function of ``module_file`` as numba's locators see it (its code's file name)."""

    stand_in.__code__ = stand_in.__code__.replace(co_filename=module_file)
    try:
        return caching.CompileResultCacheImpl(stand_in).locator.get_cache_path()
    except RuntimeError:  # no locator available for the file
        return None


def drop_stale_cache(module_file: str, callees: list[ModuleType]) -> None:
    """Delete numba's cache of ``module_file`` if a module whose kernels it calls changed.

    numba caches a function together with copies of the kernels it calls but checks only
    its own file's time stamp, so after an edit of a callee the cached copy would run the
    old kernel. Call at the top of a module whose functions call kernels of ``callees``
    (before any of them is compiled or loaded), listing the modules it calls directly: the
    callees' own recorded callees (imported, so recorded, before this call) are stamped
    too. The stamp is one line ``name mtime_ns size`` per module of the closure."""
    _RECORDED_CALLEES[module_file] = tuple(callees)
    folder = cache_folder(module_file)
    if folder is None:
        return  # numba does not cache this file's functions either
    stem = os.path.splitext(os.path.basename(module_file))[0]
    stamps = []
    for module in callee_closure(module_file):
        info = os.stat(module.__file__)
        stamps.append(f"{module.__name__} {info.st_mtime_ns} {info.st_size}")
    stamp = "\n".join(stamps)
    marker = os.path.join(folder, f"{stem}.callees")
    try:
        with open(marker) as fh:
            if fh.read() == stamp:
                return
    except OSError:
        pass
    try:
        for name in os.listdir(folder):
            if name.startswith(stem + ".") and (name.endswith(".nbi") or name.endswith(".nbc")):
                os.remove(os.path.join(folder, name))
        with open(marker, "w") as fh:
            fh.write(stamp)
    except OSError:
        return  # no cache folder (or not writable): numba does not cache there either


def _keep_linked_copies_private() -> None:
    """Make every kernel run the machine code compiled with it, whether this process compiled
    it or loaded it from numba's cache.

    numba links a copy of each called kernel into its caller's module, re-optimised there
    (with ``reassoc`` a reduction can be vectorised differently, which rounds differently),
    and leaves the copy a weak symbol. The JIT resolves a weak symbol to the first definition
    it has seen: in a process that compiles, the callee's own code (compiled first); in a
    process that loads from the cache, the copy in whichever caller was loaded first. Renders
    then differed at 1e-15 between a fresh install and later runs, and with the order in which
    a process first called its kernels. Internal linkage after linking binds every call to
    the caller's own copy, which is in its cached object too."""
    library = getattr(codegen, "CPUCodeLibrary", None)
    optimise = getattr(library, "_optimize_final_module", None)
    if optimise is None or getattr(optimise, "keeps_copies_private", False):
        return

    def optimise_with_private_copies(self):
        for function in self._final_module.functions:
            if not function.is_declaration and function.linkage == llvm.Linkage.linkonce_odr:
                function.linkage = llvm.Linkage.internal
        optimise(self)

    optimise_with_private_copies.keeps_copies_private = True
    library._optimize_final_module = optimise_with_private_copies


def _lock_cache_index_updates() -> None:
    """Make numba's update of a function's cache index atomic across processes.

    numba saves a new specialisation by reading the function's index, adding an entry
    under the first free data-file number and writing the index back. Two processes that
    save different specialisations of one function at once (``jassy warm``'s scenes, or a
    render and its compile helper, jassy.engines.coldstart) can both pick the same number, and one
    index would then name the other's data. An exclusive ``flock`` on the cache folder
    around the update serialises them; each file is still written to a temporary name and
    renamed by numba."""
    cache_file = getattr(caching, "IndexDataCacheFile", None)
    save = getattr(cache_file, "save", None)
    if save is None or getattr(save, "locks_the_folder", False):
        return

    def save_locked(self, key, data):
        try:
            folder = os.open(self._cache_path, os.O_RDONLY)
        except OSError:
            return save(self, key, data)
        try:
            fcntl.flock(folder, fcntl.LOCK_EX)
            return save(self, key, data)
        finally:
            os.close(folder)  # releases the lock

    save_locked.locks_the_folder = True
    cache_file.save = save_locked


def _no_c_wrappers_for_kernels() -> None:
    """Compile ``numba.njit`` kernels without numba's C-callable wrapper.

    numba lowers and optimises, for every specialisation, a C wrapper that lets the kernel
    be used as a first-class function value (``types.FunctionType``). jassy never uses a
    kernel that way (kernels passed to kernels are typed as dispatchers and called
    directly), and the wrappers were 5-9 % of a cold bell render's CPU (the same output
    bits without them). ``numba.cfunc`` compiles keep theirs: it is their entry point."""
    compiler = getattr(dispatcher, "_FunctionCompiler", None)
    customise = getattr(compiler, "_customize_flags", None)
    if customise is None or getattr(customise, "drops_c_wrapper", False):
        return

    def customise_without_c_wrapper(self, flags):
        flags = customise(self, flags)
        flags.no_cfunc_wrapper = True
        return flags

    customise_without_c_wrapper.drops_c_wrapper = True
    compiler._customize_flags = customise_without_c_wrapper


class FlagComparison(NamedTuple):
    """How a ``TargetConfig`` (numba's compiler flags) lists, compares and hashes its options."""

    values: Callable  #: flags -> {option name: value}, every option in the class's order
    equal: Callable  #: (flags, other) -> bool, or NotImplemented
    hashed: Callable  #: flags -> int


def _overlaid_flag_comparison(config: type) -> FlagComparison:
    """``TargetConfig`` comparisons without building a dict of every option per compare:
    ``values()`` is the class's defaults overlaid with the options set (the same dict, in
    the same order), flags with equal set options are equal without building it, and the
    hash is the sorted option names', as numba's (a constant per class)."""
    defaults: dict[type, dict] = {}
    hashes: dict[type, int] = {}

    def values(self):
        kind = type(self)
        found = defaults.get(kind)
        if found is None:
            found = defaults[kind] = {name: option.default for name, option in kind.options.items()}
        merged = dict(found)
        merged.update(self._values)
        return merged

    def equal(self, other):
        if not isinstance(other, config):
            return NotImplemented
        if type(self) is type(other) and self._values == other._values:
            return True
        return values(self) == values(other)

    def hashed(self):
        kind = type(self)
        found = hashes.get(kind)
        if found is None:
            found = hashes[kind] = hash(tuple(sorted(kind.options)))
        return found

    values.overlays_defaults = True
    return FlagComparison(values, equal, hashed)


def flag_variants() -> list:
    """numba ``Flags``: the defaults, fastmath set on and off, nrt set on and off (off is its
    default: equal to the defaults with different options set), and both set."""
    variants = [Flags() for _ in range(6)]
    variants[1].fastmath = True
    variants[2].fastmath = False
    variants[3].nrt = True
    variants[4].nrt = False
    variants[5].fastmath = True
    variants[5].nrt = True
    return variants


def flag_comparisons_agree(reference: FlagComparison, candidate: FlagComparison, variants: list) -> bool:
    """Whether ``candidate`` lists (same keys, same order as the class's options), compares and
    hashes every one of ``variants`` (and every pair of them) as ``reference`` does."""
    for flags in variants:
        listed = candidate.values(flags)
        if list(listed) != list(type(flags).options) or listed != reference.values(flags):
            return False
        if candidate.hashed(flags) != reference.hashed(flags):
            return False
        for other in variants:
            if candidate.equal(flags, other) != reference.equal(flags, other):
                return False
    return True


def _faster_flag_comparisons() -> None:
    """Compare numba's compiler flags without building a dict of every option per compare.

    Typing a call looks its implementation up in a cache keyed by the compiler flags, and
    numba's ``TargetConfig`` hashes and compares flags by building ``{option: value}`` for
    all ~20 options through their properties, twice per compare (tens of thousands of
    compares in a first render). Installs :func:`_overlaid_flag_comparison` only where it
    gives numba's results on :func:`flag_variants` (another numba version may differ)."""
    config = getattr(targetconfig, "TargetConfig", None)
    if config is None or getattr(config.values, "overlays_defaults", False):
        return
    if "_values" not in getattr(config, "__slots__", ()):
        return
    numbas = FlagComparison(config.values, config.__eq__, config.__hash__)
    faster = _overlaid_flag_comparison(config)
    try:
        agree = flag_comparisons_agree(numbas, faster, flag_variants())
    except (AttributeError, KeyError, TypeError, ValueError):  # flags shaped otherwise
        agree = False
    if agree:
        config.values, config.__eq__, config.__hash__ = faster


def _plain_error_text() -> None:
    """Build numba's error messages without terminal colours, for the whole process.

    Typing a call tries each candidate implementation and keeps an error message for every
    one that does not fit (thousands in a first render, nearly all discarded); with
    colorama installed each message is wrapped for colours, which initialises colorama's
    stream wrappers again per message. This switches numba's error colouring off in every
    numba module (each keeps its colour scheme as a module global ``_termcolor``), as
    ``NUMBA_DISABLE_ERROR_MESSAGE_HIGHLIGHTING`` would: messages that reach a user read the
    same, uncoloured."""

    class PlainText:
        def code(self, message):
            return message

        errmsg = filename = indicate = highlight = reset = code

    plain = PlainText()
    errors._termcolor_inst = plain  # what errors.termcolor() returns, also to modules imported later
    for name, module in list(sys.modules.items()):
        if name.startswith("numba.") and hasattr(module, "_termcolor"):
            module._termcolor = plain


def _blas_checked_when_used() -> None:
    """Let numba decide whether it has a BLAS by finding scipy's BLAS module, not importing it.

    numba imports its array library the first time a process compiles or loads a kernel, and
    that import asks whether np.dot and friends can be offered by importing
    ``scipy.linalg.cython_blas`` (which imports ``scipy.linalg``: about 0.15 s of CPU per
    process, for kernels that use no linear algebra). During that one import, numba's check
    only looks for the module's file in scipy's folder; afterwards numba's own check
    runs, as before, where a kernel really calls BLAS or LAPACK (and raises there if scipy's
    module cannot be imported)."""
    from importlib.machinery import EXTENSION_SUFFIXES
    from importlib.util import find_spec

    from numba.core import cpu

    load = cpu.CPUContext.load_additional_registries

    def blas_present():
        scipy = find_spec("scipy")  # finding a submodule would import its package
        folders = (scipy.submodule_search_locations or ()) if scipy is not None else ()
        names = [
            os.path.join(folder, "linalg", "cython_blas" + end)
            for folder in folders
            for end in EXTENSION_SUFFIXES
        ]
        if not any(os.path.exists(name) for name in names):
            raise ImportError("scipy 0.16+ is required for linear algebra")

    def load_additional_registries(self):
        if "numba.np.arraymath" in sys.modules:
            return load(self)
        from numba.np import linalg  # imported here by numba anyway, not at jassy's import

        check, linalg.ensure_blas = linalg.ensure_blas, blas_present
        try:
            return load(self)
        finally:
            linalg.ensure_blas = check

    cpu.CPUContext.load_additional_registries = load_additional_registries


_keep_linked_copies_private()
_lock_cache_index_updates()
_no_c_wrappers_for_kernels()
_faster_flag_comparisons()
_plain_error_text()
_blas_checked_when_used()


class _InstallAtFirstCompile(event.Listener):
    """Runs ``installers`` when numba starts its first compile in this process, before any of
    its passes (they import numba's compiler parts and type a call: ~0.4 s that a process
    which only loads cached kernels does not pay); a no-op afterwards (it stays registered:
    numba is iterating its listener list when it calls this)."""

    def __init__(self, *installers: Callable[[], bool]):
        self.installers = installers

    def on_start(self, ev):
        installers, self.installers = self.installers, ()
        for install in installers:
            # A numba whose parts an installer probes are shaped otherwise may make it raise:
            # numba's behaviour is then kept, and the next installer still runs.
            with contextlib.suppress(Exception):
                install()

    def on_end(self, ev):
        pass


event.register("numba:compile", _InstallAtFirstCompile(inline_copies.install, remembered_typing.install))

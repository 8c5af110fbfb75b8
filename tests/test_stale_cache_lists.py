"""Every module whose numba kernels call kernels of another project module names that
module, directly or through a callee's own list, in its ``jassy.jit.drop_stale_cache``
call (numba checks only a cached function's own file, so an unlisted callee's edit would
leave the old copy running). Imports modules only; compiles nothing."""

from __future__ import annotations

import importlib
import os
import pathlib
import types

import numba
from numba.core.dispatcher import Dispatcher
from numba.core.extending import _Intrinsic

from jassy.jit import callee_closure, drop_stale_cache

ROOT = pathlib.Path(__file__).resolve().parent.parent
PACKAGES = ("jassy", "ugens", "physics", "patches")


def kernel_module_names() -> list[str]:
    """Dotted names of the project's modules whose source mentions numba."""
    names = []
    for package in PACKAGES:
        for path in sorted((ROOT / package).rglob("*.py")):
            if "numba" in path.read_text(encoding="utf-8"):
                names.append(".".join(path.relative_to(ROOT).with_suffix("").parts))
    return names


def is_project(name: str) -> bool:
    return name.split(".")[0] in PACKAGES


def own_kernels(module: types.ModuleType) -> list[Dispatcher]:
    return [
        value
        for value in vars(module).values()
        if isinstance(value, Dispatcher) and value.py_func.__module__ == module.__name__
    ]


def global_names(code: types.CodeType) -> set[str]:
    """Names ``code`` and the functions nested in it look up (globals among them)."""
    names = set(code.co_names)
    for constant in code.co_consts:
        if isinstance(constant, types.CodeType):
            names |= global_names(constant)
    return names


def defining_module(value: object) -> str | None:
    """The module defining ``value`` if it is compiled into the kernels that call it: a numba
    kernel (a dispatcher) or a numba intrinsic (its code generator emits the caller's code)."""
    if isinstance(value, Dispatcher):
        return value.py_func.__module__
    if isinstance(value, _Intrinsic):
        return value._defn.__module__
    return None


def called_modules(module: types.ModuleType) -> set[str]:
    """Project modules whose kernels or intrinsics ``module``'s kernels can have copies of:
    those defining the other modules' dispatchers and intrinsics among its globals, and those
    defining the ones its kernels reach through a project module global (``cells.two_pole``
    inside a kernel, also when ``cells`` only re-exports ``two_pole``)."""
    found = set()
    for value in vars(module).values():
        defined_in = defining_module(value)
        if defined_in is not None and is_project(defined_in):
            found.add(defined_in)
    for kernel in own_kernels(module):
        names = global_names(kernel.py_func.__code__)
        for name in names:
            value = vars(module).get(name)
            if not (isinstance(value, types.ModuleType) and is_project(value.__name__)):
                continue
            for attribute in names:  # cells.two_pole: 'two_pole' is among the names too
                defined_in = defining_module(getattr(value, attribute, None))
                if defined_in is not None and is_project(defined_in):
                    found.add(defined_in)
    found.discard(module.__name__)
    return found


def test_the_finder_sees_imported_kernels_and_kernel_modules():
    """ugens.filters' biquad kernel stores its state with cells.store (imported by name);
    ugens.scrape's kernels use ugens.cells and ugens.noise; cells calls no project kernel."""
    assert called_modules(importlib.import_module("ugens.filters")) == {"ugens.cells"}
    assert {"ugens.cells", "ugens.noise"} <= called_modules(importlib.import_module("ugens.scrape"))
    assert not called_modules(importlib.import_module("ugens.cells"))


def test_the_finder_sees_intrinsics():
    """ugens.modal_f32's kernels call the intrinsics of ugens.stack_rows and ugens.vector_pass
    (through the modules); jassy.record_views' views call jassy.jit.void_pointer (imported)."""
    assert {"ugens.stack_rows", "ugens.vector_pass"} <= called_modules(
        importlib.import_module("ugens.modal_f32")
    )
    assert called_modules(importlib.import_module("jassy.record_views")) == {"jassy.jit"}


def test_an_edit_of_a_callee_of_a_callee_drops_the_cache(tmp_path, monkeypatch):
    """c lists only b, b lists a: touching a drops c's cached kernels (and only once)."""
    for stem in "abc":
        (tmp_path / f"{stem}_stale.py").write_text("X = 1\n")
    cache = tmp_path / "__pycache__"
    cache.mkdir()
    monkeypatch.syspath_prepend(str(tmp_path))
    a, b, c = (importlib.import_module(f"{stem}_stale") for stem in "abc")
    drop_stale_cache(b.__file__, [a])
    drop_stale_cache(c.__file__, [b])
    assert [m.__name__ for m in callee_closure(c.__file__)] == ["a_stale", "b_stale"]
    kept = cache / "c_stale.kernel-1.py312.nbi"
    kept.write_text("index")
    drop_stale_cache(c.__file__, [b])
    assert kept.exists()  # nothing changed
    info = os.stat(a.__file__)
    os.utime(a.__file__, ns=(info.st_atime_ns, info.st_mtime_ns + 10**9))
    drop_stale_cache(c.__file__, [b])
    assert not kept.exists()


def test_an_edit_of_a_callee_drops_the_cache_in_numba_cache_dir(tmp_path, monkeypatch):
    """With NUMBA_CACHE_DIR set numba caches outside the source tree: the cache it wrote
    there (found by listing that folder) goes when a listed callee changes."""
    source, cache = tmp_path / "source", tmp_path / "cache"
    source.mkdir()
    (source / "a_dir_stale.py").write_text("X = 1\n")
    (source / "c_dir_stale.py").write_text(
        "import numba\n\n\n@numba.njit(cache=True)\ndef plus_one(x):\n    return x + 1\n"
    )
    monkeypatch.setattr(numba.config, "CACHE_DIR", str(cache))
    monkeypatch.syspath_prepend(str(source))
    a, c = (importlib.import_module(f"{stem}_dir_stale") for stem in "ac")
    drop_stale_cache(c.__file__, [a])
    assert c.plus_one(1) == 2
    assert list(cache.rglob("c_dir_stale.plus_one-*.nbi"))  # numba cached it there
    drop_stale_cache(c.__file__, [a])
    assert list(cache.rglob("c_dir_stale.plus_one-*.nbi"))  # nothing changed
    info = os.stat(a.__file__)
    os.utime(a.__file__, ns=(info.st_atime_ns, info.st_mtime_ns + 10**9))
    drop_stale_cache(c.__file__, [a])
    assert not list(cache.rglob("c_dir_stale.*.nb[ic]"))


def test_every_called_kernel_module_is_listed():
    missing = []
    for name in kernel_module_names():
        module = importlib.import_module(name)
        if not own_kernels(module):
            continue
        listed = {m.__name__ for m in callee_closure(module.__file__)}
        for callee in sorted(called_modules(module) - listed):
            missing.append(f"{name} -> {callee}")
    assert not missing, "drop_stale_cache lists lack:\n" + "\n".join(missing)

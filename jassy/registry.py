"""Name -> UGen class registry, filled by ``@register`` in the ugens package.

jassy does not import ugens at module import time; :func:`ugen_class` imports the
``ugens`` package on first use so that patch files can name any built-in ugen.
"""

from __future__ import annotations

import importlib

from jassy.errors import PatchError, suggest

_REGISTRY: dict[str, type] = {}


def register(cls):
    """Class decorator: make ``cls`` available under ``cls.type_name``, with a constructor
    signature and a parameter section in its docstring generated from its ParamSpecs (what
    ``help()`` and ``inspect.signature`` show)."""
    from jassy.ugendoc import document_class

    _REGISTRY[cls.type_name] = cls
    document_class(cls)
    return cls


def _load_builtin_ugens() -> None:
    importlib.import_module("ugens")


def ugen_types() -> dict[str, type]:
    """All registered ugen classes by type name."""
    _load_builtin_ugens()
    return dict(sorted(_REGISTRY.items()))


def ugen_class(type_name: str, where: str = "type") -> type:
    """The class registered as ``type_name``; PatchError naming ``where`` if unknown."""
    _load_builtin_ugens()
    try:
        return _REGISTRY[type_name]
    except KeyError:
        known = ", ".join(sorted(_REGISTRY))
        hint = suggest(type_name, _REGISTRY)
        raise PatchError(f"{where}: unknown ugen type {type_name!r}; expected one of {known}{hint}") from None

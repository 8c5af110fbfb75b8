"""Every model file shipped beside the built-in patches, with the builder that makes it.

Regenerate them all with ``python -m patches.shipped``; a test checks that each shipped
file equals its builder's output, so the numbers in them trace back to formulas.
"""

from __future__ import annotations

import importlib
from collections.abc import Callable
from pathlib import Path

from jassy.modal_model import ModalModel

#: Modules that define ``SHIPPED = {file name: builder}``.
MODEL_MODULES = (
    "patches.models",
    "patches.models_bottle",
    "patches.models_impacts",
    "patches.models_machines",
    "patches.models_stochastic",
    "patches.models_surface",
    "patches.models_vessels",
    "physics.modal.shipped",
)


def shipped_models() -> dict[str, Callable[[], ModalModel]]:
    """File name -> builder, over all model modules."""
    out: dict[str, Callable[[], ModalModel]] = {}
    for name in MODEL_MODULES:
        out.update(importlib.import_module(name).SHIPPED)
    return out


def write_models(folder: Path | None = None) -> None:
    """Write every shipped model file into ``folder`` (default: this package)."""
    folder = Path(__file__).parent if folder is None else folder
    for filename, builder in shipped_models().items():
        builder().save(folder / filename)


if __name__ == "__main__":
    write_models()

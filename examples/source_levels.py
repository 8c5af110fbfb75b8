"""Peak level (dBFS) of every force source at its default parameters through calibrated banks.

    python examples/source_levels.py                                  # four library objects
    python examples/source_levels.py patches/door_model.toml

Each source drives a ModalBank with ``level = "calibrated"`` (the default 1e-3 N s strike at
the model's loudest point peaks at -18 dBFS) at the model's first location for 1 s: the
sources output forces in N, so their level follows from their physical defaults (a 0.5 g
button dropped 10 cm exchanges 1.2e-3 N s, 1.5 dB over the reference strike; the events
are jassy.levels.FORCE_SOURCES).
"""

from __future__ import annotations

import math
import sys
from pathlib import Path

import numpy as np

import ugens
from jassy import Graph, ModalModel, render
from jassy.levels import FORCE_SOURCES, MODEL_CALIBRATED_SOURCES, calibrated, driven_source

ROOT = Path(__file__).resolve().parents[1]
MODELS = ("tin_sheet_model.toml", "wine_glass_model.toml", "pot_model.toml", "bar_model.toml")


def once_calibrated(model: ModalModel) -> ModalModel:
    """The model with its reference gain stored (computed here once, not by every bank)."""
    return model if model.reference_gain is not None else calibrated(model)


def peak_dbfs(model: ModalModel, source: str) -> float:
    src, event = driven_source(source, model)
    bank = ugens.ModalBank(model, name="bank", level="calibrated")(src)
    y = render(Graph(bank), [event], duration=1.0, sample_rate=48000, limiter=False).audio[0]
    return 20 * math.log10(max(float(np.abs(y).max()), 1e-30))


def main() -> None:
    files = sys.argv[1:] or [str(ROOT / "patches" / name) for name in MODELS]
    sources = [*FORCE_SOURCES, *MODEL_CALIBRATED_SOURCES]
    print("model | " + " | ".join(sources))
    for file in files:
        model = once_calibrated(ModalModel.load(file))
        print(f"{model.name} | " + " | ".join(f"{peak_dbfs(model, s):.1f}" for s in sources), flush=True)


if __name__ == "__main__":
    main()

"""Levels of the tonal force sources over their operating range, given the model they drive.

    python examples/tonal_levels.py                        # the 17 shipped models
    python examples/tonal_levels.py patches/door_model.toml

ResonantScrape (defaults, 1 N) scraped at 0.1 .. 2 m/s and DrillSource (defaults, a light
cut: 1 N, 1 mm^3/s) started at 30000 rpm and set to 10000 .. 100000 rpm, each given the
model (``level = "auto"``: calibrated) and, for the drill, also raw (the force in N), through
a calibrated ModalBank with unit gain at the model's first location, 1 s: peak dBFS per
model, then the range over the models (the window of jassy.levels is -30..-6 dBFS).
"""

from __future__ import annotations

import argparse
import math
from pathlib import Path

import numpy as np

import ugens
from jassy import Event, Graph, JassyError, ModalModel, render
from jassy.levels import calibrated
from patches.objects import OBJECTS
from patches.shipped import shipped_models

ROOT = Path(__file__).resolve().parents[1]
SPEEDS = (0.1, 0.2, 0.5, 1.0, 2.0)  #: m/s
RPMS = (10000.0, 30000.0, 60000.0, 100000.0)


def peak_dbfs(model: ModalModel, source, events) -> float:
    bank = ugens.ModalBank(model, name="bank", level="calibrated")(source)
    y = render(Graph(bank), events, duration=1.0, sample_rate=48000, limiter=False).audio[0]
    return 20 * math.log10(max(float(np.abs(y).max()), 1e-30))


def scrape(model: ModalModel, speed: float) -> float:
    return peak_dbfs(
        model, ugens.ResonantScrape(model, name="s"), [Event(0.01, "s", "set", {"speed": speed})]
    )


def drill(model: ModalModel, rpm: float, level: str) -> float:
    source = ugens.DrillSource(model, name="d", level=level, rpm=30000.0)
    events = [Event(0.01, "d", "set", {"force": 1.0, "removal": 1.0, "rpm": rpm}, jump=True)]
    return peak_dbfs(model, source, events)


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("models", nargs="*", help="model files (default: the 17 shipped models)")
    args = parser.parse_args()
    names = sorted(set(shipped_models()) | {info.file for info in OBJECTS.values()})
    files = args.models or [str(ROOT / "patches" / name) for name in names]
    columns = [f"scrape {v:g} m/s" for v in SPEEDS]
    columns += [f"drill {r / 1000:g}k rpm" for r in RPMS] + [f"raw drill {r / 1000:g}k" for r in RPMS]
    print("model | " + " | ".join(columns))
    rows = []
    for file in files:
        try:
            model = ModalModel.load(file)
        except JassyError as exc:
            parser.error(str(exc))
        model = model if model.reference_gain is not None else calibrated(model)
        row = [scrape(model, v) for v in SPEEDS]
        row += [drill(model, r, "auto") for r in RPMS] + [drill(model, r, "raw") for r in RPMS]
        rows.append(row)
        print(f"{model.name or Path(file).stem} | " + " | ".join(f"{x:.1f}" for x in row), flush=True)
    table = np.array(rows)
    print(
        "range | "
        + " | ".join(f"{lo:.1f}..{hi:.1f}" for lo, hi in zip(table.min(0), table.max(0), strict=True))
    )


if __name__ == "__main__":
    main()

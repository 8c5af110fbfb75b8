"""Which mode a Friction exciter makes sing, at which normal force and speed.

    python examples/friction_regimes.py                          # the wine glass's rim
    python examples/friction_regimes.py patches/pot_model.toml rim --sigma0 1e7

For each normal force (N) and exciter speed (m/s) of a grid the rub is pressed and moved
(ramped over ``smooth`` s), and the last half of a ``duration`` s render is analysed: the
strongest spectral peak (Hz) and the RMS level in dBFS at the calibrated level (a 1e-3 N s
strike at the model's loudest point peaks at -18 dBFS) of what remains after removing the
mean (the static deflection under the mean friction force), or "-" when the contact slides
steadily without sounding (RMS below -80 dBFS).
"""

from __future__ import annotations

import argparse
import math

import numpy as np

from jassy import Event, Graph, ModalModel, render
from ugens import Friction

FORCES = (0.5, 1.0, 2.0, 3.0, 5.0)
SPEEDS = (0.02, 0.05, 0.1, 0.2, 0.5)


def regime(model, location, force, speed, duration=1.0, rate=48000, **friction) -> tuple[float, float]:
    """(strongest frequency in Hz, RMS in dBFS) of the last half of a steady rub."""
    rub = Friction(model, name="rub", location=location, level="calibrated", smooth=0.1, **friction)
    events = [Event(0.0, "rub", "set", {"force": force, "speed": speed})]
    y = render(Graph(rub), events, duration=duration, sample_rate=rate, limiter=False).audio[0]
    tail = y[len(y) // 2 :]
    tail = tail - tail.mean()  # the static deflection under the mean friction force is no sound
    rms = math.sqrt(float(np.mean(tail**2)))
    spectrum = np.abs(np.fft.rfft(tail * np.hanning(len(tail))))
    peak = float(np.fft.rfftfreq(len(tail), 1 / rate)[int(np.argmax(spectrum))])
    return peak, 20 * math.log10(max(rms, 1e-30))


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("model", nargs="?", default="patches/wine_glass_model.toml")
    parser.add_argument("location", nargs="?", default="rim")
    parser.add_argument("--sigma0", type=float, default=1e7, help="bristle stiffness (N/m)")
    parser.add_argument("--static", type=float, default=0.6)
    parser.add_argument("--dynamic", type=float, default=0.3)
    parser.add_argument("--stribeck", type=float, default=0.05, help="m/s")
    args = parser.parse_args()
    model = ModalModel.load(args.model)
    friction = {
        "sigma0": args.sigma0,
        "static": args.static,
        "dynamic": args.dynamic,
        "stribeck": args.stribeck,
    }
    print(f"{model.name} at {args.location}: strongest peak (Hz) / RMS (dBFS, calibrated)")
    print("force (N) \\ speed (m/s) | " + " | ".join(f"{v:g}" for v in SPEEDS))
    for force in FORCES:
        cells = []
        for speed in SPEEDS:
            peak, level = regime(model, args.location, force, speed, **friction)
            cells.append("-" if level < -80 else f"{peak:.0f} / {level:.0f}")
        print(f"{force:g} | " + " | ".join(cells), flush=True)


if __name__ == "__main__":
    main()

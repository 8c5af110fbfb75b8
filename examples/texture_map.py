"""The sound texture map: strike a bar at 33 points along its length and print how the
partials' levels change (gains interpolated barycentrically between the model's 9 points).

Run: python examples/texture_map.py
"""

import numpy as np

from jassy import Event, Graph, render
from patches.models import free_bar_model
from ugens import ImpactForce, ModalBank


def main() -> None:
    model = free_bar_model()
    hit = ImpactForce(name="hit", duration=0.0003)
    graph = Graph(ModalBank(model, name="bar")(hit))
    print(" x/L   " + "  ".join(f"{f:7.0f} Hz" for f in model.frequencies))
    for x in np.linspace(0.0, 1.0, 33):
        i = min(int(x * 8), 7)
        w = x * 8 - i
        loc = {"vertices": [i, i + 1], "weights": [1.0 - w, w]}
        out = render(
            graph, [Event(0.0, "hit", "impact", {"impulse": 0.01, "location": loc})], 0.25, limiter=False
        ).audio[0]
        spectrum = np.abs(np.fft.rfft(out))
        bins = np.round(model.frequencies * out.size / 48000).astype(int)
        levels = 20 * np.log10(spectrum[bins] / spectrum.max() + 1e-12)
        print(f"{x:5.3f} " + "  ".join(f"{lv:7.1f} dB" for lv in levels))


if __name__ == "__main__":
    main()

"""Compose a patch in Python: a struck bar through a band-pass, with a noise 'breath'.

Run: python examples/compose_patch.py out.wav
"""

import sys

from jassy import Event, Graph, OfflineEngine
from patches.models import free_bar_model
from ugens import Biquad, Envelope, FractalNoise, ImpactForce, ModalBank, Multiply


def main(path: str) -> None:
    mallet = ImpactForce(name="mallet", duration=0.0006)
    bar = ModalBank(free_bar_model(n_modes=6), name="bar")(mallet)
    breath = Multiply(
        FractalNoise(beta=1.0, amp=0.05, seed=3), Envelope(name="env", attack=0.3, decay=1.0, sustain=0.0)
    )
    air = Biquad(breath, mode="bandpass", freq=880.0, q=8.0, name="air")
    mix = 12.0 * bar + air
    score = [Event(0.0, "env", "trigger"), Event(0.0, "air", "set", {"freq": 1760.0})]
    for i, place in enumerate(["x4", "x2", "x1", "x0"]):
        score.append(Event(0.4 * i, "mallet", "impact", {"impulse": 0.04, "location": place}))
    engine = OfflineEngine(Graph(mix, haptic=mallet), score, sample_rate=48000, block=64)
    summary = engine.render_to_file(path, duration=3.0)
    print(f"wrote {path}: peak {summary['peak']:.2f}")


if __name__ == "__main__":
    main(sys.argv[1] if len(sys.argv) > 1 else "compose.wav")

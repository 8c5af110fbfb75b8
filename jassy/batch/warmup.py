"""Warm up a batch worker: load numba's compiled kernels of the common ugens once.

The first render in a fresh process spends about 2 s loading numba's target registries
and the cached kernels. Importing this module does that work (it renders a few
milliseconds of an impact on a 3-mode bank), so the process pool's fork server imports it
and every worker forked from it starts warm.
"""

from __future__ import annotations

import contextlib


def warm_up() -> None:
    """Render 256 frames of ImpactForce -> ModalBank -> Gain + Mixer (kernels loaded from cache)."""
    from jassy.engines.offline import OfflineEngine
    from jassy.events import Event
    from jassy.graph import Graph
    from jassy.modal_model import ModalModel
    from jassy.registry import ugen_class

    model = ModalModel([440.0, 1000.0, 2500.0], [3.0, 5.0, 8.0], [[1.0, 0.5, 0.2]])
    hit = ugen_class("ImpactForce")(name="hit")
    bank = ugen_class("ModalBank")(model, name="bank")(hit)
    out = ugen_class("Gain")(bank, gain=0.5, name="out")
    mix = ugen_class("Mixer")(out, bank, name="mix")
    score = [Event(0.0, "hit", "impact", {"impulse": 0.01})]
    OfflineEngine(Graph(mix, haptic=hit), score, 48000, 64).render(256 / 48000)


with contextlib.suppress(Exception):  # an optimisation only: a cold worker renders correctly too
    warm_up()

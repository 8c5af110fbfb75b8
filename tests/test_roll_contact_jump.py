"""A rolling contact that jumps between track points: the plate's motion is carried.

The ``roll`` patch's ball (Roll, the rolling contact filter) and micro-impacts (RathRoll)
ride on the steel plate, which gives way under them (its driving-point modes at the
contact). When the contact jumps to the next track point the plate does not move: each
mode keeps its modal displacement and the contact sees it through the new point's mode
shapes. So the contact forces after a jump stay at the level of a steady roll, at either
point, over the same time, however often it jumps (the contact walking to and fro
between two points). (Keeping each mode's output at the contact instead hands the new
point a mode whose driving-point gain fell from g to g' with g / g' times its energy,
and the forces grow at every jump.)
"""

import numpy as np

from jassy import Event, render
from jassy.patchfile import load_patch

FS = 48000
SPEED = 0.2  # m/s: where the patch rolls back over t4 -> t3
JUMP = 1.0  # s: the first jump, then every STEP s
STEP = 0.05  # s
FRAME = 4800  # 100 ms RMS frames


def contact_forces(first, then):
    """The ball's and the micro-impacts' forces (N), contact at ``first``, from JUMP s
    jumping between ``then`` and ``first`` every STEP s."""
    patch = load_patch("roll")
    events = [Event(0.0, "ball", "set", {"force": 1.08, "speed": SPEED}, jump=True)]
    for node in ("ball", "hops"):
        events.append(Event(0.0, node, "set", {"location": first}, jump=True))
        for i in range(round(0.5 / STEP)):
            where = then if i % 2 == 0 else first
            events.append(Event(JUMP + i * STEP, node, "set", {"location": where}, jump=True))
    events.append(Event(0.0, "hops", "set", {"speed": SPEED}, jump=True))
    return render(patch.graph, events, JUMP + 0.5, FS, 256, limiter=False).haptic


def frames(x, start, stop):
    """100 ms RMS of x over [start, stop) s."""
    part = x[int(start * FS) : int(stop * FS)]
    return np.sqrt(np.mean(part.reshape(-1, FRAME) ** 2, axis=1))


def test_a_contact_jump_does_not_raise_the_forces():
    jumped = contact_forces("t4", "t3")
    at_t3 = contact_forces("t3", "t3")
    for layer, name in enumerate(("ball", "hops")):
        steady = max(
            frames(jumped[layer], JUMP - 0.5, JUMP).max(), frames(at_t3[layer], JUMP, JUMP + 0.5).max()
        )
        after = frames(jumped[layer], JUMP, JUMP + 0.5).max()
        assert steady > 0.0
        assert after < 1.25 * steady, (name, after, steady)

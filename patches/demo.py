"""Interactive probe demo: the pointer is a probe on a steel plate.

Click to tap, drag to scrape (or roll, in roll mode); sound and the haptic force channel
play live on one clock. The plate's sound texture map follows the probe along the
plate's track of gain locations (x across the window). :class:`Probe` turns pointer
input into jassy events; the window posts them to a :class:`jassy.live.LiveEngine`, and
:func:`render_script` renders a scripted probe path offline through the same Probe
(that is how the tests drive it). A drill mode needs the burr-drilling physics module,
which this build does not have yet, so it is not offered.
"""

from __future__ import annotations

import math
from collections.abc import Callable, Sequence
from dataclasses import dataclass

from jassy.errors import JassyError
from jassy.events import Event
from jassy.graph import Graph
from jassy.offline import OfflineEngine, Rendering

MODES = ("scrape", "roll")
PRESS_FORCE = 2.0  # N, normal force while the button is held
TAP_IMPULSE = 0.02  # N s, of the tap when the button goes down
MOVE_RAMP = 0.02  # s, parameters glide between pointer samples


def build_scene(mode: str = "scrape") -> Graph:
    """Tap + contact generator -> steel plate (ModalBank) -> out; haptic = contact force."""
    from patches.models_surface import steel_plate_model
    from ugens.impact import ImpactForce
    from ugens.mix import Gain, Mixer
    from ugens.modal import ModalBank
    from ugens.roll import Roll
    from ugens.scrape import Scrape

    if mode not in MODES:
        raise JassyError(f"--mode: expected one of {', '.join(MODES)}, got {mode!r}")
    tap = ImpactForce(name="tap", duration=0.0008)
    contact = (Scrape if mode == "scrape" else Roll)(name="contact", force=0.0, speed=0.0, seed=1)
    force = Mixer(tap, contact, name="force")
    plate = ModalBank(steel_plate_model(), name="plate")(force)
    return Graph(Gain(plate, gain=4.0, name="out"), haptic=force)


@dataclass
class Probe:
    """Pointer input -> events. Positions are fractions of the plate's track, 0..1;
    ``width`` (m) converts their rate of change to a sliding speed (m/s)."""

    send: Callable[[Event], None]
    width: float = 0.5
    points: int = 9
    live: bool = False
    _last: tuple[float, float] | None = None

    def _time(self, t: float) -> float:
        return 0.0 if self.live else t  # live events play as soon as possible

    def location(self, x: float) -> dict:
        """Barycentric location between the two track points around x."""
        s = min(max(x, 0.0), 1.0) * (self.points - 1)
        i = min(int(math.floor(s)), self.points - 2)
        w = s - i
        return {"vertices": [f"t{i}", f"t{i + 1}"], "weights": [1.0 - w, w]}

    def press(self, x: float, t: float) -> None:
        self._last = (x, t)
        self.send(Event(self._time(t), "plate", "set", {"location": self.location(x)}, jump=True))
        self.send(Event(self._time(t), "tap", "impact", {"impulse": TAP_IMPULSE}))
        self.send(Event(self._time(t), "contact", "set", {"force": PRESS_FORCE, "speed": 0.0}, jump=True))

    def move(self, x: float, t: float) -> None:
        if self._last is None:
            return
        x0, t0 = self._last
        if t <= t0:
            return
        speed = abs(x - x0) * self.width / (t - t0)
        self._last = (x, t)
        args = {"speed": min(speed, 5.0)}
        self.send(Event(self._time(t), "contact", "set", args, ramp=MOVE_RAMP))
        self.send(Event(self._time(t), "plate", "set", {"location": self.location(x)}, ramp=MOVE_RAMP))

    def release(self, t: float) -> None:
        self._last = None
        self.send(Event(self._time(t), "contact", "set", {"force": 0.0, "speed": 0.0}, ramp=MOVE_RAMP))


def render_script(
    path: Sequence[tuple[float, str, float]],
    duration: float,
    mode: str = "scrape",
    sample_rate: float = 48000,
    block: int = 64,
) -> Rendering:
    """Render a scripted probe path offline: (time s, "press" | "move" | "release", x)."""
    events: list[Event] = []
    probe = Probe(events.append)
    for t, kind, x in path:
        if kind == "press":
            probe.press(x, t)
        elif kind == "move":
            probe.move(x, t)
        elif kind == "release":
            probe.release(t)
        else:
            raise JassyError(f"probe path: unknown action {kind!r}; expected press, move or release")
    return OfflineEngine(build_scene(mode), events, sample_rate, block).render(duration)


def stroke(start: float = 0.2, end: float = 1.2, x0: float = 0.1, x1: float = 0.9, rate: float = 60.0):
    """A scripted press, straight drag at constant speed, and release (pointer rate Hz)."""
    steps = int((end - start) * rate)
    path = [(start, "press", x0)]
    path += [(start + k / rate, "move", x0 + (x1 - x0) * k / steps) for k in range(1, steps + 1)]
    path.append((end, "release", x1))
    return path


def run_window(mode: str = "scrape", **live_options) -> None:
    """Open the demo window (tkinter) and play live until it is closed."""
    try:
        import tkinter as tk
    except ImportError:
        raise JassyError(
            "the demo window needs tkinter (Debian/Ubuntu: apt-get install python3-tk)"
        ) from None
    from jassy.live import LiveEngine

    try:
        root = tk.Tk()
    except tk.TclError as exc:
        raise JassyError(f"cannot open a window ({exc}); use --script to run headless") from None
    engine = LiveEngine(build_scene(mode), [], **live_options)
    engine.start()
    probe = Probe(engine.post, live=True)
    width, height = 600, 300
    root.title(f"jassy demo: {mode} a steel plate (click to tap, drag to {mode})")
    canvas = tk.Canvas(root, width=width, height=height, background="#8a9199")
    canvas.pack()
    status = tk.Label(root, anchor="w")
    status.pack(fill="x")

    def position(event) -> float:
        return event.x / width

    canvas.bind("<ButtonPress-1>", lambda e: probe.press(position(e), e.time / 1000.0))
    canvas.bind("<B1-Motion>", lambda e: probe.move(position(e), e.time / 1000.0))
    canvas.bind("<ButtonRelease-1>", lambda e: probe.release(e.time / 1000.0))

    def refresh() -> None:
        status.config(text=engine.stats().summary())
        root.after(500, refresh)

    refresh()
    try:
        root.mainloop()
    finally:
        engine.stop()

"""Interactive probe demo: the pointer is a probe on a steel plate.

Click to tap, drag to scrape (or roll, in roll mode); sound and the haptic force channel
play live on one clock. The plate's sound texture map follows the probe along the
plate's track of gain locations (x across the window). :class:`Probe` turns pointer
input into jassy events; the window posts them to a :class:`jassy.engines.live.LiveEngine`, and
:func:`render_script` renders a scripted probe path offline through the same Probe
(that is how the tests drive it).

Drill mode (when ``physics.burr`` is installed, as here): holding the button pushes a
spinning burr down into a bone phantom at the pointer's x with a constant force; the
burr-bone simulation steps at 1 kHz (:class:`DrillProbe`) and its contact force and
removal rate drive the drilling sound, the force going to the haptic channel.
"""

from __future__ import annotations

import math
from collections.abc import Callable, Sequence
from dataclasses import dataclass

import numpy as np

from jassy.engines.offline import OfflineEngine, Rendering
from jassy.errors import JassyError
from jassy.events import Event
from jassy.graph import Graph

MODES = ("scrape", "roll", "drill", "poke")
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
    if mode == "drill":
        return build_drill_scene()
    if mode == "poke":
        return build_poke_scene()
    tap = ImpactForce(name="tap", duration=0.0008)
    contact = (Scrape if mode == "scrape" else Roll)(name="contact", force=0.0, speed=0.0, seed=1)
    force = Mixer(tap, contact, name="force")
    plate = ModalBank(steel_plate_model(), name="plate")(force)
    return Graph(Gain(plate, gain=4.0, name="out"), haptic=force)


def build_drill_scene() -> Graph:
    """DrillSource -> bone resonances, plus the handpiece whine; haptic = the burr force."""
    from patches.drill import bone_model
    from ugens.drill import DrillSource
    from ugens.mix import Gain, Mixer
    from ugens.modal import ModalBank

    drill = DrillSource(name="drill", rpm=0.0)
    bone = ModalBank(bone_model(), name="bone")(drill)
    out = Mixer(Gain(bone, gain=0.3), Gain(drill.tap("motor"), gain=1.5), name="out")
    return Graph(out, haptic=drill)


def build_poke_scene() -> Graph:
    """The soft ball's squish and press sounds (patches.poke); haptic = the normal force."""
    from patches.poke import ball_nodes
    from ugens.mix import Gain

    out, press = ball_nodes()
    return Graph(Gain(out, gain=0.5, name="out"), haptic=press)


class PokeProbe:
    """A probe sphere pressed into a soft rubber ball (patches.poke's ball: BEM Green's
    functions and capacitance-matrix contact, physics.deform), stepped at ``rate`` Hz.

    The pointer's x (0..1) is the probe's polar angle over the ball (-45..45 degrees);
    while pressed it sinks into the ball at ``speed`` m/s down to ``depth`` m, and rises
    when released. Each step sends the normal force and the sliding speed to the squish
    and the force to the press node (the haptic channel)."""

    def __init__(self, send: Callable[[Event], None], live: bool = False, rate: float = 1000.0,
                 depth: float = 0.008, speed: float = 0.05, gap: float = 0.004):  # fmt: skip
        from physics.deform.bem import SOFT_GEL_DENSITY
        from physics.deform.greens import reference_greens
        from physics.deform.haptic import PokeSim, soft_ball
        from physics.modal.materials import Material

        self.send, self.live, self.rate = send, live, rate
        self.radius, self.probe_radius = 0.05, 0.015
        V, F, fixed = soft_ball(self.radius, 3)
        self.sim = PokeSim(
            reference_greens(V, F, Material("soft ball", 2e5, 0.45, SOFT_GEL_DENSITY), fixed),
            self.probe_radius,
        )
        self.depth, self.speed, self.gap = depth, speed, gap
        self.x = 0.5
        self.indent = -gap
        self.pressed = False
        self.force = np.zeros(3)
        self.centre = self._centre()
        self._warm()

    def _warm(self) -> None:
        """Step the simulation once pressed full depth and once clear: the first contact
        loads the contact solver's kernels (seconds), which would freeze the first press."""
        indent = self.indent
        self.indent = self.depth
        self.sim.step(self._centre())
        self.indent = indent
        self.sim.step(self._centre())

    @property
    def touching(self) -> bool:
        return bool(np.any(self.force))

    def _centre(self) -> np.ndarray:
        angle = math.radians(90.0 * (self.x - 0.5))
        reach = self.radius + self.probe_radius - self.indent
        return reach * np.array([math.sin(angle), 0.0, math.cos(angle)])

    def press(self, x: float, t: float) -> None:
        self.x, self.pressed = x, True

    def move(self, x: float, t: float) -> None:
        self.x = x

    def release(self, t: float) -> None:
        self.pressed = False

    def step(self, t: float) -> None:
        """One haptic update at time t (s)."""
        dt = 1.0 / self.rate
        target = self.depth if self.pressed else -self.gap
        self.indent += min(max(target - self.indent, -self.speed * dt), self.speed * dt)
        centre = self._centre()
        sliding = float(np.linalg.norm(centre - self.centre)) / dt
        self.centre = centre
        self.force = self.sim.step(centre).force
        normal = float(np.linalg.norm(self.force))
        when = 0.0 if self.live else t
        rub = {"force": normal, "speed": sliding if normal else 0.0}
        self.send(Event(when, "squish", "set", rub, ramp=dt))
        self.send(Event(when, "press", "set", {"amp": normal}, ramp=dt))


class DrillProbe:
    """The burr-bone simulation under the pointer, stepped at ``rate`` Hz.

    While pressed, the burr sits at the pointer's x over the phantom and sinks with the
    force imbalance against a constant ``push`` (N); each step sends the contact's normal
    force, removal rate and the burr's speed to the DrillSource ``drill``.
    """

    def __init__(
        self,
        send: Callable[[Event], None],
        live: bool = False,
        n: int = 96,
        push: float = 2.0,
        rpm: float = 30000.0,
        rate: float = 1000.0,
    ):
        from physics.burr.loop import BurrSim, Descent
        from physics.burr.volume import phantom

        self.send, self.live, self.rate, self.rpm = send, live, rate, rpm
        self.volume = phantom(n)
        self.sim = BurrSim(self.volume)
        self.push = push
        self._descent = Descent
        self.controller = None
        self.depth = 0.0
        self.removed = 0.0
        self.x = 0.5
        self.force = 0.0
        self._warm()

    def _warm(self) -> None:
        """Step a copy of the simulation once with the burr a radius into the bone and once
        clear: the first contact loads the burr's kernels (3 s measured with numba's cache
        warm), which would freeze the first press."""
        import copy

        from physics.burr.loop import BurrSim

        scratch = BurrSim(copy.deepcopy(self.volume))
        centre, omega, velocity = self._descent(self._world(0.5), rpm=self.rpm)(0.0, None)
        for depth in (2.0 * self.sim.params.radius, 0.0):
            scratch.step(centre - [0.0, 0.0, depth], omega, velocity, 1.0 / self.rate)

    @property
    def touching(self) -> bool:
        return self.controller is not None

    def _world(self, x: float) -> np.ndarray:
        v = self.volume
        nx, ny, nz = v.density.shape
        centre = v.to_world([min(max(x, 0.05), 0.95) * (nx - 1), (ny - 1) / 2, nz - 1])
        centre[2] += self.sim.params.radius  # starts above the volume
        return centre

    def press(self, x: float, t: float) -> None:
        self.x = x
        self.controller = self._descent(self._world(x), push=self.push, rpm=self.rpm, v_max=0.05)
        self.send(Event(0.0 if self.live else t, "drill", "set", {"rpm": self.rpm}, ramp=0.05))

    def move(self, x: float, t: float) -> None:
        """Slide the burr sideways to the pointer's x while it drills."""
        self.x = x
        if self.controller is not None:
            self.controller.pos[0] = self._world(x)[0]

    def release(self, t: float) -> None:
        self.controller = None
        args = {"force": 0.0, "removal": 0.0, "rpm": 0.0}
        self.send(Event(0.0 if self.live else t, "drill", "set", args, ramp=0.1))

    def step(self, t: float) -> None:
        """One physics tick at time t (s): no-op while the button is up."""
        if self.controller is None:
            return
        centre, omega, velocity = self.controller(t, getattr(self, "_state", None))
        state = self.sim.step(centre, omega, velocity, 1.0 / self.rate)
        self._state = state
        self.removed += state.removed
        removal = state.removed * 1e9 / self.volume.rho_full * self.rate  # mm^3/s
        self.force = float(np.linalg.norm(state.elastic))
        args = {"force": self.force, "removal": removal}
        self.send(Event(0.0 if self.live else t, "drill", "set", args, ramp=1.0 / self.rate))


@dataclass
class Probe:
    """Pointer input -> events. Positions are fractions of the plate's track, 0..1;
    ``width`` (m) converts their rate of change to a sliding speed (m/s)."""

    send: Callable[[Event], None]
    width: float = 0.5
    points: int = 9
    live: bool = False
    x: float = 0.5  # where the probe is (0..1 along the track), pressed or not
    _last: tuple[float, float] | None = None

    @property
    def touching(self) -> bool:
        return self._last is not None

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
        self.x = x
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
        self.x = x
        args = {"speed": min(speed, 5.0)}
        self.send(Event(self._time(t), "contact", "set", args, ramp=MOVE_RAMP))
        self.send(Event(self._time(t), "plate", "set", {"location": self.location(x)}, ramp=MOVE_RAMP))

    def release(self, t: float) -> None:
        self._last = None
        self.send(Event(self._time(t), "contact", "set", {"force": 0.0, "speed": 0.0}, ramp=MOVE_RAMP))


def render_drill_script(
    path: Sequence[tuple[float, str, float]], duration: float, sample_rate: float = 48000, block: int = 64
) -> tuple[Rendering, DrillProbe]:
    """Drill mode, scripted: press/release actions of ``path``; the simulation steps at
    1 kHz between them. Returns the rendering and the probe (its simulation state)."""
    events: list[Event] = []
    probe = DrillProbe(events.append)
    actions = sorted(path)
    k = 0
    for i in range(int(duration * probe.rate)):
        t = i / probe.rate
        while k < len(actions) and actions[k][0] <= t:
            at, kind, x = actions[k]
            if kind == "press":
                probe.press(x, at)
            elif kind == "release":
                probe.release(at)
            elif kind != "move":
                raise JassyError(f"probe path: unknown action {kind!r}; expected press, move or release")
            k += 1
        probe.step(t)
    return OfflineEngine(build_drill_scene(), events, sample_rate, block).render(duration), probe


def render_script(
    path: Sequence[tuple[float, str, float]],
    duration: float,
    mode: str = "scrape",
    sample_rate: float = 48000,
    block: int = 64,
) -> Rendering:
    """Render a scripted probe path offline: (time s, "press" | "move" | "release", x)."""
    if mode == "drill":
        return render_drill_script(path, duration, sample_rate, block)[0]
    if mode == "poke":
        raise JassyError("--script: poke mode plays live only; its scripted gesture is 'jassy render poke'")
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


def start_live(mode: str, probe_udp: str | None = None, **live_options):
    """Start the live engine on ``mode``'s scene with its probe (and the drill's physics
    thread) and, with ``probe_udp`` = HOST:PORT, a UDP probe input driving the probe
    exactly as the pointer does. Returns (engine, probe, pose receiver or None)."""
    from jassy.engines.hapticframes import parse_address
    from jassy.engines.live import LiveEngine
    from jassy.engines.probeinput import PoseDriver, PoseReceiver

    engine = LiveEngine(build_scene(mode), [], monitor_seconds=0.25, mode="auto", **live_options)
    engine.start()
    physics = {"drill": DrillProbe, "poke": PokeProbe}.get(mode)
    probe = physics(engine.post, live=True) if physics else Probe(engine.post, live=True)
    if physics:
        _start_physics(probe)
    receiver = None
    if probe_udp:
        host, port = parse_address(probe_udp, "--probe-udp")
        receiver = PoseReceiver(PoseDriver(probe), host, port)
    return engine, probe, receiver


def stop_live(engine, probe, receiver) -> None:
    """Stop the input, the physics thread and the engine (fade, final frame, children)."""
    if receiver is not None:
        receiver.close()
    probe.running = False
    engine.stop()


def run_headless(mode: str = "scrape", probe_udp: str | None = None, **live_options) -> None:
    """The live scene without a window, driven by the UDP probe input, until stopped."""
    import time

    engine, probe, receiver = start_live(mode, probe_udp, **live_options)
    try:
        where = f"; probe input on {receiver.address}" if receiver else ""
        print(f"demo {mode} running headless{where}; Ctrl-C stops", flush=True)
        while True:
            time.sleep(0.5)
    finally:
        stop_live(engine, probe, receiver)


def run_window(mode: str = "scrape", probe_udp: str | None = None, **live_options) -> None:
    """Open the demo window (tkinter) and play live until it is closed or stopped."""
    try:
        import tkinter as tk
    except ImportError:
        raise JassyError(
            "the demo window needs tkinter (Debian/Ubuntu: apt-get install python3-tk)"
        ) from None
    from patches.demo_view import DemoView

    try:
        root = tk.Tk()
    except tk.TclError as exc:
        raise JassyError(f"cannot open a window ({exc}); use --script or --headless") from None
    engine, probe, receiver = start_live(mode, probe_udp, **live_options)
    stopped: list[BaseException] = []

    def report(exc_type, exc, tb):  # a signal's Stopped, raised inside a Tk callback
        if isinstance(exc, (KeyboardInterrupt, SystemExit)) or not isinstance(exc, Exception):
            stopped.append(exc)
            root.quit()
        else:
            raise exc

    root.report_callback_exception = report
    try:
        view = DemoView(root, mode, engine, probe)
        view.bind_pointer()
        print(
            f"demo {mode} window open" + (f"; probe input on {receiver.address}" if receiver else ""),
            flush=True,
        )
        root.mainloop()
    finally:
        stop_live(engine, probe, receiver)
        root.destroy()
    if stopped:
        raise stopped[0]


def _start_physics(probe) -> None:
    """Step the drill or poke simulation at its rate in a thread (the sound runs on the
    device clock; events go to it as they are computed)."""
    import threading
    import time

    probe.running = True
    probe.step(0.0)  # the first step loads the simulation's kernels (seconds): before any input

    def loop() -> None:
        start = time.monotonic() - 1.0 / probe.rate
        tick = 1
        while probe.running:
            probe.step(tick / probe.rate)
            tick += 1
            delay = start + tick / probe.rate - time.monotonic()
            if delay > 0:
                time.sleep(delay)

    threading.Thread(target=loop, name="drill-physics", daemon=True).start()

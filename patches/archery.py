"""Archery: a bow, its string and an arrow (physics.rod.contact_experiments.run_archery) rendered to sound.

The simulation gives the release time, the draw force, the brace tension, the arrow's speed along
its flight and the hit on the target (an Impact). The sound is the sum of
- the bow: the limbs' flexural ModalModel (physics.rod.modes, a limb clamped at the grip, heard at
  its tip) struck at release by an impulse of draw force x 1 ms;
- the string: a taut-string ModalModel, f_k = k c / 2 L with c = sqrt(T / rho_A) from the brace
  tension T, plucked at its middle by the same impulse (gains sin^2(k pi / 2) / k: odd harmonics);
- the flight: white noise band-passed at 2.5 kHz whose level follows (speed / peak speed)^2;
- the hit: the arrow-target Impact (its impulse) through a 3 ms force pulse on a straw-boss target
  (a few heavily damped modes, 120 Hz - 2.4 kHz).
Simplifications: the bow modes are those of one unloaded limb (the string's tension and the other
limb are not in the modal analysis); the release excitation is a fixed-length impulse.

``render_archery(out_wav, haptic_path=None, csv_path=None, **options)`` writes the sound (normalised
to a -6 dBFS peak), the string's force on the hand during draw and hold (1 kHz) and a CSV of the
arrow's flight.
"""

from __future__ import annotations

import math

import numpy as np

from jassy.engines.offline import OFFLINE_BLOCK
from jassy.errors import JassyError
from jassy.events import Event
from jassy.graph import Graph
from jassy.modal_model import ModalModel
from patches.scene_io import render_normalised, write_csv

PRE_ROLL = 0.2  # s of sound before the release
BOW_GAIN, STRING_GAIN, TARGET_GAIN = (
    2.0,
    6.0,
    0.5,
)  # mix levels (the bow's low modes would otherwise dominate the peak)


def string_model(length: float, tension: float, rho_a: float, n_modes: int = 16) -> ModalModel:
    """Taut string of ``length`` m under ``tension`` N with mass ``rho_a`` kg/m: f_k = k c / 2L,
    gains sin^2(k pi/2) / k (plucked at the middle), decays 4 + 1.5 k 1/s."""
    if not (length > 0 and tension > 0 and rho_a > 0):
        raise JassyError(
            f"length, tension, rho_a: expected positive numbers, got {length}, {tension}, {rho_a}"
        )
    k = np.arange(1, n_modes + 1)
    f1 = math.sqrt(tension / rho_a) / (2 * length)
    gains = (
        np.sin(k * np.pi / 2) ** 2 / k + 0.05 / k
    )  # + a little of the even modes (nock not exactly central)
    return ModalModel(f1 * k, 4.0 + 1.5 * k, gains[None, :], name="string")


def target_model() -> ModalModel:
    """A straw-boss target: 6 heavily damped modes (Q about 3) from 120 Hz to 2.4 kHz."""
    f = np.geomspace(120.0, 2400.0, 6)
    return ModalModel(f, np.pi * f / 3.0, (1.0 / np.sqrt(f / 120.0))[None, :], name="target")


def build_scene(result, bow: ModalModel, string: ModalModel, t0: float, end: float, seed: int = 0):
    """(Graph, score): release impulses on the bow and string banks, flight noise, target hit."""
    from ugens.filters import Biquad
    from ugens.impact import ImpactForce
    from ugens.mix import Gain, Mixer
    from ugens.modal import ModalBank
    from ugens.noise import WhiteNoise

    pluck = ImpactForce(name="pluck", duration=1e-3)
    hit = ImpactForce(name="hit", duration=3e-3)
    bow_out = ModalBank(bow, name="bow")(pluck)
    string_out = ModalBank(string, name="string")(pluck)
    target_out = ModalBank(target_model(), name="target")(hit)
    air = Gain(
        Biquad(WhiteNoise(name="noise", seed=seed), mode="bandpass", freq=2500.0, q=1.5, name="band"),
        gain=0.0,
        name="air",
    )
    out = Mixer(
        Gain(bow_out, gain=BOW_GAIN, name="bow_out"),
        Gain(string_out, gain=STRING_GAIN, name="string_out"),
        Gain(air, gain=0.05, name="air_out"),
        Gain(target_out, gain=TARGET_GAIN, name="target_out"),
        name="out",
    )
    draw = result.summary["draw_force_n"]
    score = [Event(result.release_time - t0, "pluck", "impact", {"impulse": draw * 1e-3})]
    path = result.arrow
    peak = max(float(np.max(path[:, 3])), 1e-9)
    stop = result.hit_time if result.hit_time is not None else path[-1, 0]
    flying = path[path[:, 0] <= stop]
    times = np.concatenate([flying[::4, 0], [stop + 1e-3]]) - t0
    levels = np.concatenate([(flying[::4, 3] / peak) ** 2, [0.0]])
    if not np.all(np.isfinite(levels)):
        raise JassyError("archery: non-finite arrow speed")
    score.append(Event(times[0], "air", "set", {"gain": float(levels[0])}, jump=True))
    score += [
        Event(
            float(times[i]), "air", "set", {"gain": float(levels[i + 1])}, ramp=float(times[i + 1] - times[i])
        )
        for i in range(len(times) - 1)
    ]
    for ev in result.impacts:
        if 5 in ev.bodies and 3 in ev.bodies:  # arrow (3) on the target plane (5)
            score.append(Event(ev.time - t0, "hit", "impact", {"impulse": ev.impulse}))
    return Graph(out), [e for e in score if 0.0 <= e.time < end]


def render_archery(
    out_wav,
    haptic_path=None,
    csv_path=None,
    tail: float = 1.5,
    sample_rate: int = 48000,
    block: int = OFFLINE_BLOCK,
    draw: float = 0.4,
    limb_ei: float = 30.0,
    target: float = 3.0,
    seed: int = 0,
    result=None,
    duration: float | None = None,
) -> dict:
    """Simulate the shot and render it: sound to ``out_wav`` (from 0.2 s before the release to ``tail``
    s after the hit), the string's force on the hand (x, y in N, 1 kHz: draw and hold) to
    ``haptic_path`` (via jassy.files.write_signal), and to ``csv_path`` a CSV time_s, x_m, y_m,
    speed_m_s of the arrow after the release. ``duration`` (s) overrides the sound length (from the
    pre-roll). ``result``: a run_archery result to render instead of simulating (then draw, limb_ei
    and target are ignored). Returns a summary dict."""
    import time

    from jassy.files import write_signal
    from physics.rod.contact_experiments import run_archery
    from physics.rod.modes import modal_model

    if not (isinstance(tail, (int, float)) and 0.1 <= tail <= 10):
        raise JassyError(f"tail: expected seconds in [0.1, 10], got {tail!r}")
    if duration is not None and not (isinstance(duration, (int, float)) and 0 < duration <= 60):
        raise JassyError(f"duration: expected seconds in (0, 60], got {duration!r}")
    t_start = time.perf_counter()
    res = result if result is not None else run_archery(draw, limb_ei, target)
    limb_len = res.limb.model.length
    bow = modal_model(res.limb, [limb_len], n_modes=6, loss=2e-3, name="bow")
    s = res.summary
    string = string_model(s["string_length_m"], s["brace_tension_n"], res.string.model.rho_A)
    t_phys = time.perf_counter() - t_start
    t0 = res.release_time - PRE_ROLL
    end_phys = res.hit_time if res.hit_time is not None else float(res.arrow[-1, 0])
    duration = end_phys - t0 + tail if duration is None else float(duration)
    graph, score = build_scene(res, bow, string, t0, duration, seed)
    t_render = time.perf_counter()
    audio, warnings = render_normalised(graph, score, duration, out_wav, sample_rate, block)
    render_seconds = time.perf_counter() - t_render
    peak = float(np.max(np.abs(audio))) if audio.size else 0.0
    if haptic_path:
        write_signal(haptic_path, res.hand[:, 1:].T.copy(), 1000.0, label="force_")
    if csv_path:
        write_csv(csv_path, res.arrow, "time_s,x_m,y_m,speed_m_s")
    return {
        **s,
        "bow_f1_hz": float(bow.frequencies[0]),
        "string_f1_hz": float(string.frequencies[0]),
        "frames": int(audio.shape[1]),
        "duration": duration,
        "peak": peak,
        "physics_seconds": t_phys,
        "render_seconds": render_seconds,
        "realtime_factor": duration / render_seconds,
        "warnings": warnings,
    }

"""Poking a soft ball: the BEM/capacitance-matrix haptic loop (physics.deform) driving sound.

A rubber-like ball (radius 5 cm, E = 200 kPa, nu = 0.45) rests on a rigid base (its bottom
cap fixed: the reference BVP of the Green's functions, cached on disk). A probe sphere
(radius 1.5 cm) follows the demo gesture of physics.deform.haptic.poke_path: a soft poke,
then a press that slides over the top and lifts off. The 1 kHz loop gives the force on the
probe; its ContactTrack drives

* a squish: a Scrape (fractal sliding noise, contact-patch low-pass) whose force follows
  the normal force and whose speed is the probe's speed relative to the surface while in
  contact (slip speed plus indentation speed);
* a press: the normal force itself (a Sine at 0 Hz whose amplitude follows the force)
  through a 40 Hz high-pass, i.e. roughly its derivative;

both exciting a heavily damped ModalModel of the soft ball.

``render_poke(out_wav, haptic_path=None, csv_path=None, duration=4.0, **options)`` writes
the sound, the haptic force frames and a CSV of time, probe centre, force and contacts.
"""

from __future__ import annotations

import math

import numpy as np

from jassy.engines.offline import OFFLINE_BLOCK
from jassy.errors import JassyError
from jassy.events import ContactTrack, track_events
from jassy.graph import Graph
from jassy.modal_model import ModalModel
from patches.scene_io import render_normalised, write_csv


def soft_model(n_modes: int = 16, seed: int = 3) -> ModalModel:
    """A soft rubber ball: n_modes modes log-spread over 90 Hz - 1.6 kHz (jittered), very
    damped (Q 2-5, decay d = pi f / Q), gains ~ 1/f."""
    rng = np.random.default_rng(seed)
    f = np.exp(np.linspace(np.log(90.0), np.log(1600.0), n_modes) + rng.uniform(-0.05, 0.05, n_modes))
    q = rng.uniform(2.0, 5.0, n_modes)
    a = (f / 90.0) ** -1.0 * rng.uniform(0.5, 1.0, n_modes) * 50.0
    return ModalModel(f, math.pi * f / q, a[None, :], name="soft_ball")


def ball_nodes(squish_gain: float = 1.0, press_gain: float = 1.0, seed: int = 0):
    """(output node, press node): Scrape ("squish", force N and speed m/s) + high-passed
    normal force ("press": a Sine at 0 Hz whose amplitude is the force, N) -> ModalBank
    ("ball"). The press node's output is the normal force itself (a haptic channel)."""
    from ugens.filters import Biquad
    from ugens.mix import Gain, Mixer
    from ugens.modal import ModalBank
    from ugens.oscillators import Sine
    from ugens.scrape import Scrape

    squish = Scrape(
        roughness=2e-5, patch=2e-4, f_ref=10.0, v_ref=0.05, stiffness=1e5, seed=seed, name="squish"
    )
    press = Sine(freq=0.0, amp=0.0, phase=math.pi / 2, name="press")
    thump = Biquad(press, mode="highpass", freq=40.0, q=0.7, name="thump")
    drive = Mixer(Gain(squish, gain=squish_gain, name="squish_gain"), Gain(thump, gain=press_gain,
                  name="press_gain"), name="drive")  # fmt: skip
    return ModalBank(soft_model(), name="ball")(drive), press


def build_scene(track: ContactTrack, rub_speed: np.ndarray, squish_gain: float = 1.0, press_gain: float = 1.0,
                seed: int = 0, control_step: int = 4):  # fmt: skip
    """(Graph, score): Scrape ("squish") + high-passed force ("press") -> ModalBank(soft ball),
    following ``track`` (normal force) and ``rub_speed`` (m/s per track sample), both taken
    every ``control_step``-th sample (4 ms at 1 kHz: the sound needs no finer control)."""
    out, _ = ball_nodes(squish_gain, press_gain, seed)
    k = slice(None, None, max(1, int(control_step)))
    rub = ContactTrack(
        track.bodies, track.times[k], track.normal_force[k], rub_speed[k], track.rolling_speed[k]
    )
    score = track_events(rub, {"normal_force": ("squish", "force"), "slip_speed": ("squish", "speed")})
    score += track_events(rub, {"normal_force": ("press", "amp")})
    return Graph(out), score


def run_experiment(duration: float = 4.0, radius: float = 0.05, probe_radius: float = 0.015,
                   depth: float = 0.008, subdivisions: int = 3, E: float = 2e5, nu: float = 0.45,
                   rate: float = 1000.0, mask_radius: float = 0.0, cache_dir=None):  # fmt: skip
    """Build (or load) the ball's Green's functions and run the demo gesture. Returns
    (PokeResult, GreensFunctions)."""
    from physics.deform.bem import SOFT_GEL_DENSITY
    from physics.deform.greens import reference_greens
    from physics.deform.haptic import PokeSim, poke_path, run_poke, soft_ball
    from physics.modal.materials import Material

    V, F, fixed = soft_ball(radius, subdivisions)
    greens = reference_greens(
        V, F, Material("soft ball", E, nu, SOFT_GEL_DENSITY), fixed, cache_dir=cache_dir
    )
    sim = PokeSim(greens, probe_radius, mask_radius)
    return run_poke(sim, poke_path(radius, probe_radius, depth), duration, rate), greens


def render_poke(out_wav, haptic_path=None, csv_path=None, duration: float = 4.0, sample_rate: int = 48000,
                block: int = OFFLINE_BLOCK, seed: int = 0, **options) -> dict:  # fmt: skip
    """Render the demo: sound to ``out_wav`` (WAV/FLAC, normalised to a -6 dBFS peak), the
    1 kHz force on the probe to ``haptic_path`` (.csv: frame, time_s, force_0..2 = x, y, z in
    N; .npz or .wav via jassy.files.write_signal), and to ``csv_path`` a CSV with columns
    time_s, probe_x/y/z_m, force_x/y/z_n, normal_force_n, slip_speed_m_s, contacts.
    ``options`` go to :func:`run_experiment`. Returns a summary dict."""
    import time

    from jassy.files import write_signal

    if not (isinstance(duration, (int, float)) and 0 < duration <= 60):
        raise JassyError(f"duration: expected seconds in (0, 60], got {duration!r}")
    t0 = time.perf_counter()
    res, greens = run_experiment(duration, **options)
    t_phys = time.perf_counter() - t0
    velocity = np.gradient(res.centres, res.times, axis=0)
    unit = res.forces / np.maximum(res.track.normal_force, 1e-300)[:, None]
    press_speed = np.abs(np.sum(velocity * unit, axis=1))
    rub = np.where(res.counts > 0, res.track.slip_speed + press_speed, 0.0)
    graph, score = build_scene(res.track, rub, seed=seed)
    audio, warnings = render_normalised(
        graph, score, duration, out_wav, sample_rate, block, radius=options.get("radius", 0.05)
    )
    peak = float(np.max(np.abs(audio))) if audio.size else 0.0
    if haptic_path:
        write_signal(haptic_path, res.forces.T.copy(), 1.0 / (res.times[1] - res.times[0]), label="force_")
    if csv_path:
        rows = np.column_stack([res.times, res.centres, res.forces, res.track.normal_force,
                                res.track.slip_speed, res.counts])  # fmt: skip
        header = ("time_s,probe_x_m,probe_y_m,probe_z_m,force_x_n,force_y_n,force_z_n,normal_force_n,"
                  "slip_speed_m_s,contacts")  # fmt: skip
        write_csv(csv_path, rows, header)
    return {
        "frames": audio.shape[1],
        "duration": duration,
        "peak": peak,
        "vertices": greens.n,
        "greens_seconds": greens.seconds,
        "greens_from_cache": greens.from_cache,
        "max_force_n": float(res.track.normal_force.max()),
        "max_contacts": int(res.counts.max()),
        "refactors": int(res.refactored.sum()),
        "haptic_steps": int(res.times.size),
        "haptic_median_us": float(np.median(res.step_seconds) * 1e6),
        "physics_seconds": t_phys,
        "render_seconds": time.perf_counter() - t0,
        "warnings": warnings,
    }

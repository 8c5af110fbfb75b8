"""Drilling: the burr-bone haptic simulation (physics.burr) driving a DrillSource into bone.

The experiment with which Agus et al. fit their burr parameters to measurements
("Physics-based burr haptic simulation: tuning and evaluation", HAPTICS 2004): a spinning burr
descends vertically at constant force into a phantom; the 1 kHz haptic loop gives the force on
the burr, the depth and the removed mass; its DrillTrack (normal force, removal rate, rotation
speed) drives a DrillSource whose force excites a
bone-like ModalModel (a few dozen heavily damped modes), mixed with the handpiece whine.

``render_drill(out_wav, haptic_path=None, csv_path=None, duration=6.0, **options)`` writes
the sound, the haptic force frames and a CSV of time, depth, force and removed mass.
"""

from __future__ import annotations

import math

import numpy as np

from jassy.engines.offline import OFFLINE_BLOCK
from jassy.errors import JassyError
from jassy.events import Event, track_events
from jassy.graph import Graph
from jassy.modal_model import ModalModel
from patches.scene_io import render_normalised, write_csv


def bone_model(n_modes: int = 36, seed: int = 1) -> ModalModel:
    """A bone-like resonator: n_modes modes log-spread over 600 Hz - 14 kHz (jittered),
    heavily damped (Q 8-25, decay d = pi f / Q), gains ~ f^-1/2 (displacement per N s,
    scaled so a 1 N s impulse peaks near 1)."""
    rng = np.random.default_rng(seed)
    f = np.exp(np.linspace(np.log(600.0), np.log(14000.0), n_modes) + rng.uniform(-0.04, 0.04, n_modes))
    q = rng.uniform(8.0, 25.0, n_modes)
    d = math.pi * f / q
    a = (f / 600.0) ** -0.5 * rng.uniform(0.5, 1.0, n_modes) * 2e2
    return ModalModel(f, d, a[None, :], name="bone")


def build_scene(track, rpm_node: str = "drill", bone_gain: float = 1.0, motor_gain: float = 1.0,
                smooth_ms: float = 10.0, seed: int = 0):  # fmt: skip
    """(Graph, score) of DrillSource -> ModalBank(bone) + motor whine, following ``track``
    (a physics.burr DrillTrack). The removal rate is averaged over ``smooth_ms`` (the
    roulette makes the per-step removal spiky)."""
    from physics.burr.loop import smooth_rate
    from ugens.drill import DrillSource
    from ugens.mix import Gain, Mixer
    from ugens.modal import ModalBank

    drill = DrillSource(name=rpm_node, seed=seed)
    bone = ModalBank(bone_model(), name="bone")(drill)
    out = Mixer(Gain(bone, gain=bone_gain, name="bone_out"), Gain(drill.tap("motor"), gain=motor_gain,
                name="motor_out"), name="out")  # fmt: skip
    dt = float(track.times[1] - track.times[0])
    removal = smooth_rate(np.asarray(track.removal_rate), max(1, int(round(smooth_ms * 1e-3 / dt))))
    smoothed = type(track)(track.bodies, track.times, track.normal_force, track.slip_speed,
                           track.rolling_speed, track.locations, removal_rate=removal,
                           rotation_speed=track.rotation_speed)  # fmt: skip
    score: list[Event] = track_events(
        smoothed,
        {
            "normal_force": (rpm_node, "force"),
            "removal_rate": (rpm_node, "removal"),
            "rotation_speed": (rpm_node, "rpm"),
        },
    )
    return Graph(out, haptic=drill), score


def run_experiment(duration: float = 6.0, push: float = 2.0, rpm: float = 30000.0, n: int = 128,
                   voxel: float = 1e-4, radius: float = 1.5e-3, rate: float = 1000.0, seed: int = 0,
                   method: str = "octree", leaf: int = 4, volume=None, start_gap: float = 2e-4,
                       **params):  # fmt: skip
    """Vertical descent at constant force ``push`` (N) into a phantom of n^3 voxels (or
    ``volume``), starting ``start_gap`` m above the bone surface at the volume's centre.
    Returns (LoopResult, surface height m, BurrSim)."""
    from physics.burr.loop import BurrParams, descent_experiment
    from physics.burr.volume import phantom

    vol = volume if volume is not None else phantom(n, voxel, seed=seed)
    p = BurrParams(radius=radius, method=method, leaf=leaf, **params)
    return descent_experiment(vol, duration, push, rpm, rate, seed, start_gap, p)


def render_drill(out_wav, haptic_path=None, csv_path=None, duration: float = 6.0, sample_rate: int = 48000,
                 block: int = OFFLINE_BLOCK, push: float = 2.0, rpm: float = 30000.0, n: int = 128,
                 seed: int = 0, **options) -> dict:  # fmt: skip
    """Render the reference experiment: sound to ``out_wav`` (WAV/FLAC, normalised to a
    -6 dBFS peak), the 1 kHz haptic force frames to ``haptic_path`` (.csv: frame, time_s,
    force_0, force_1, force_2 = x, y, z in N; .npz or .wav via jassy.files.write_signal at 1000 Hz),
    and to ``csv_path`` a CSV with columns time_s, depth_m (burr tip below the initial
    surface), force_n (vertical force of the bone on the burr), normal_force_n (|F_e|),
    removed_mass_kg (cumulative) and removal_rate_mm3_s. Returns a summary dict."""
    import time

    from jassy.files import write_signal

    if not (isinstance(duration, (int, float)) and 0 < duration <= 60):
        raise JassyError(f"duration: expected seconds in (0, 60], got {duration!r}")
    t0 = time.perf_counter()
    res, surface, sim = run_experiment(duration, push=push, rpm=rpm, n=n, seed=seed, **options)
    t_phys = time.perf_counter() - t0
    radius = sim.params.radius
    depth = surface - (res.centres[:, 2] - radius)
    graph, score = build_scene(res.track, seed=seed)
    audio, warnings = render_normalised(graph, score, duration, out_wav, sample_rate, block)
    peak = float(np.max(np.abs(audio))) if audio.size else 0.0
    if haptic_path:
        write_signal(haptic_path, res.forces.T.copy(), 1.0 / (res.times[1] - res.times[0]), label="force_")
    if csv_path:
        rows = np.column_stack(
            [res.times, depth, res.forces[:, 2], res.track.normal_force, res.removed, res.track.removal_rate]
        )
        write_csv(csv_path, rows, "time_s,depth_m,force_n,normal_force_n,removed_mass_kg,removal_rate_mm3_s")
    return {
        "frames": audio.shape[1],
        "duration": duration,
        "peak": peak,
        "final_depth_m": float(depth[-1]),
        "removed_mass_kg": float(res.removed[-1]),
        "haptic_steps": int(res.times.size),
        "haptic_median_us": float(np.median(res.step_seconds) * 1e6),
        "physics_seconds": t_phys,
        "render_seconds": time.perf_counter() - t0,
        "warnings": warnings,
    }

"""The virtual wok (van den Doel, Kry & Pai, "FoleyAutomatic", SIGGRAPH 2001).

A carbon-steel wok (a spherical cap of rim radius 0.18 m and radius of curvature 0.35 m,
a kinematic triangle mesh held by its handle) is shaken and tossed by a scripted hand: the
food (peas, tofu cubes, shrimp-like capsules and irregular convex bits) is dropped in, slides
and rolls while the wok is swirled, and flies and lands when it is tossed. Every impact
strikes the wok's modal model (wok_deep_model.toml: models_stochastic.wok_deep_model) where
the food landed and the food piece's own few damped modes; sliding and rolling contacts
drive Scrape and Roll generators; the contact force and torque of the food on the wok, about
the hand on the handle, is the haptic channel.
"""

from __future__ import annotations

import math
import time
from functools import partial
from pathlib import Path

import numpy as np
import trimesh

from jassy.engines.offline import OFFLINE_BLOCK
from jassy.errors import JassyError
from jassy.modal_model import ModalModel
from patches.rigid_sound import IMPACT_HEADER, Voice, contact_locator, impact_rows, scene_graph
from patches.scene_io import render_normalised, render_units, write_csv

WOK_RIM = 0.18  # m
WOK_CURVATURE = 0.35  # m
HANDLE = np.array([0.42, 0.0, 0.09])  # hand on the handle, wok frame (m)
TOSSES = (1.6, 3.2, 4.6)  # s


def wok_surface() -> trimesh.Trimesh:
    """The wok's inner surface (normals into the bowl), bottom at the origin, axis +z: the
    bottom cap of an icosphere (even triangles, edges about 1.4 cm)."""
    sphere = trimesh.creation.icosphere(subdivisions=5, radius=WOK_CURVATURE)
    rim_z = -math.sqrt(WOK_CURVATURE**2 - WOK_RIM**2)
    centre_z = sphere.vertices[sphere.faces, 2].mean(axis=1)  # not triangles_center: no cache hashing
    cap = sphere.submesh([np.flatnonzero(centre_z < rim_z)], append=True)
    cap.apply_translation([0.0, 0.0, WOK_CURVATURE])
    cap.invert()
    return cap


def _smoothstep(x):
    x = np.clip(x, 0.0, 1.0)
    return x * x * (3.0 - 2.0 * x)


def hand_path(t) -> tuple[np.ndarray, np.ndarray]:
    """Poses of the wok at times ``t`` (s, array (T,)): positions (T, 3) m and quaternions
    (T, 4). Held still, swirled, and tossed at TOSSES.

    A toss (0.35 s): the wok tilts back and is pushed forward and down, then jerks up and
    back (peak vertical acceleration about 2 g), throwing the food, and settles."""
    t = np.atleast_1d(np.asarray(t, dtype=float))
    pos = np.zeros((t.size, 3))
    tilt = np.zeros(t.size)
    swirl = _smoothstep((t - 0.8) / 0.3) * (1.0 - _smoothstep((t - 1.5) / 0.1))
    swirl += _smoothstep((t - 5.3) / 0.2)
    pos[:, 0] = 0.012 * swirl * np.cos(2 * np.pi * 2.2 * t)
    pos[:, 1] = 0.012 * swirl * np.sin(2 * np.pi * 2.2 * t)
    for t0 in TOSSES:
        u = (t - t0) / 0.35
        inside = (u >= 0.0) & (u <= 1.0)
        bump = np.where(inside, np.sin(np.pi * u) ** 2, 0.0)
        pos[:, 0] += 0.06 * np.sin(2 * np.pi * u) * bump
        pos[:, 2] += 0.05 * np.sin(2 * np.pi * u - 0.6) * bump
        tilt += 0.3 * np.sin(2 * np.pi * u + 0.4) * bump
    quat = np.zeros((t.size, 4))
    quat[:, 0] = np.cos(tilt / 2)
    quat[:, 2] = np.sin(tilt / 2)
    return pos, quat


def food_model(size: float, seed: int) -> ModalModel:
    """A soft food piece: 4 heavily damped modes (Q 3-6) around c / size, c = 40 m/s."""
    rng = np.random.default_rng(seed)
    f0 = 40.0 / size
    f = f0 * np.array([1.0, 1.7, 2.6, 3.9]) * rng.uniform(0.93, 1.07, 4)
    q = rng.uniform(3.0, 6.0, 4)
    gains = np.array([[1.0, 0.5, 0.3, 0.15]]) * 2e-3
    return ModalModel(f, math.pi * f / q, gains, name=f"food{seed}")


def build_world(n_food: int = 14, seed: int = 0, h: float = 1e-3):
    """The wok world: kinematic wok + n_food pieces placed above it."""
    from patches.models_stochastic import WOK_RADII
    from physics.rigid.shapes import Box, Capsule, Convex, Sphere, TriangleMesh
    from physics.rigid.world import MATERIALS, Body, Placement, StepParams, World

    if not 1 <= n_food <= 200:
        raise JassyError(f"n_food: expected 1..200 pieces, got {n_food!r}")
    rng = np.random.default_rng(seed)
    world = World(
        StepParams(h=h, integrator="semi-implicit", bounce_threshold=0.08, iterations=20, tolerance=1e-3)
    )
    steel = MATERIALS["steel"]
    food = MATERIALS["food"]
    r = WOK_RIM * np.asarray(WOK_RADII)
    points = np.c_[r * math.cos(0.3), r * math.sin(0.3), WOK_CURVATURE - np.sqrt(WOK_CURVATURE**2 - r**2)]
    world.add(
        Body(
            "wok",
            TriangleMesh(wok_surface()),
            steel,
            kind="kinematic",
            path=hand_path,
        )
    )
    wok_model = ModalModel.load(Path(__file__).with_name("wok_deep_model.toml"))
    voices = {
        0: Voice(
            wok_model,
            points,
            hit_duration=4e-4,
            scrape_roughness=1.5e-6,
            roll_roughness=6e-6,
            stiffness=400.0,
        )
    }
    for k in range(n_food):
        kind = k % 4
        if kind == 0:
            shape, size = Sphere(rng.uniform(0.006, 0.009)), 0.015
        elif kind == 1:
            side = rng.uniform(0.007, 0.01)
            shape, size = Box((side, side, side)), 2 * side
        elif kind == 2:
            shape, size = Capsule(0.005, rng.uniform(0.008, 0.012)), 0.03
        else:
            pts = rng.normal(size=(10, 3)) * np.array([0.01, 0.008, 0.006])
            shape, size = Convex(pts), 0.02
        angle = 2 * math.pi * k / n_food
        rad = 0.03 + 0.07 * rng.uniform()
        place = Placement(
            position=(rad * math.cos(angle), rad * math.sin(angle), 0.06 + 0.1 * rng.uniform()),
            quaternion=tuple(rng.normal(size=4)),
            angular_velocity=tuple(rng.normal(size=3) * 3.0),
        )
        idx = world.add(Body(f"food{k}", shape, food), place)
        voices[idx] = Voice(food_model(size, seed * 1000 + k), hit_duration=3e-3, level=1.0)
    return world, voices


def simulate_wok(duration: float = 6.0, n_food: int = 14, seed: int = 0, compile_units=None):
    """(world, voices, RunResult) of the wok scene; ``compile_units(world, voices)``: compile
    units for the step's helper on a cold kernel cache (physics.rigid.world.simulate)."""
    from physics.rigid.world import simulate

    world, voices = build_world(n_food, seed)
    units = compile_units(world, voices) if compile_units is not None else ()
    return world, voices, simulate(world, duration, sample_every=10, compile_units=units)


def render_wok(
    out_wav,
    haptic_path=None,
    csv_path=None,
    duration: float = 6.0,
    sample_rate: int = 48000,
    block: int = OFFLINE_BLOCK,
    n_food: int = 14,
    seed: int = 0,
) -> dict:
    """Render the wok: sound to ``out_wav`` (-6 dBFS peak), the force (N) and torque (N m) of
    the food on the wok about the hand to ``haptic_path`` (1 kHz frames: .csv/.npz/.wav via
    jassy.files.write_signal; columns force_x_n .. torque_z_nm), and a CSV of impacts
    (time_s, body_a, body_b, impulse_ns, speed_ms) to ``csv_path``. Returns a summary."""
    from jassy.files import write_signal
    from physics.rigid.events import contact_tracks, contact_wrench, impacts
    from physics.rigid.spatial import rotation_matrices

    if not (isinstance(duration, (int, float)) and 0 < duration <= 60):
        raise JassyError(f"duration: expected seconds in (0, 60], got {duration!r}")
    t0 = time.perf_counter()
    sound_units = partial(render_units, sample_rate=sample_rate, block=block)
    world, voices, result = simulate_wok(duration, n_food, seed, compile_units=sound_units)
    t_phys = time.perf_counter() - t0
    hits = impacts(result, locate=contact_locator(world, voices))
    tracks = contact_tracks(result)
    graph, score = scene_graph(world.bodies, hits, tracks, voices)
    audio, warnings = render_normalised(graph, score, duration, out_wav, sample_rate, block, radius=0.18)

    def hand(t):
        p, q = hand_path(t)
        return p + rotation_matrices(q) @ HANDLE

    times, force, torque = contact_wrench(result, world.index("wok"), hand)
    if haptic_path:
        names = ["force_x_n", "force_y_n", "force_z_n", "torque_x_nm", "torque_y_nm", "torque_z_nm"]
        write_signal(
            haptic_path, np.column_stack([force, torque]).T.copy(), 1.0 / world.params.h, label=names
        )
    if csv_path:
        write_csv(csv_path, impact_rows(hits), IMPACT_HEADER)
    return {
        "frames": audio.shape[1],
        "duration": duration,
        "impacts": len(hits),
        "tracks": len(tracks),
        "max_force_n": float(np.max(np.linalg.norm(force, axis=1))) if len(force) else 0.0,
        "physics_seconds": round(t_phys, 3),
        "render_seconds": round(time.perf_counter() - t0, 3),
        "stats": result.stats,
        "warnings": warnings,
    }

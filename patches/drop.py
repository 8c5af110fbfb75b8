"""Objects of different materials dropped on a wooden table: they bounce, slide and roll to rest.

A steel ball and a glass marble (bounce, then roll until rolling resistance stops them), a
wooden block and a ceramic tile (thrown sliding, stop by Coulomb friction), a rubber ball (many
bounces), a plastic die (an icosahedron: tumbles), and a ceramic cylinder (a capsule: rolls
sideways). The table top is a static box carrying the shipped wood-board modal model; each
object rings with the bending modes of a free bar of its size and material (physics.modal's
material table: Young's modulus, density, loss factor).
"""

from __future__ import annotations

import math
import time
from pathlib import Path
from typing import NamedTuple

import numpy as np
import trimesh

from jassy.engines.offline import OFFLINE_BLOCK
from jassy.errors import JassyError
from jassy.modal_model import ModalModel
from patches.rigid_sound import IMPACT_HEADER, Voice, contact_locator, impact_rows, scene_graph
from patches.scene_io import render_normalised, write_csv

TABLE_TOP = 0.0  # m


def bar_model(
    name: str, size: float, mass: float, material: str, overrides: dict, count: int = 5
) -> ModalModel | None:
    """Bending modes of a free-free bar of length ``size`` (m) and thickness size/3 in
    ``material`` (physics.modal.materials, with ``overrides``): f_n from Euler-Bernoulli,
    decay d0 + pi f loss (1/s), gains 2 / (m w_n) (driving-point displacement per N s at a
    free end); None when no mode lies below 18 kHz."""
    from physics.modal.analytic import free_free_beam_frequencies
    from physics.modal.materials import material as lookup

    mat = lookup(material, **overrides)
    f = free_free_beam_frequencies(size, size / 3, size / 3, mat.youngs, mat.density, count)
    f = f[f < 18000.0]
    if f.size == 0:
        return None  # too small and stiff to ring audibly: only what it strikes sounds
    decays = mat.d0 + math.pi * f * mat.loss
    gains = 2.0 / (mass * 2 * math.pi * f)
    return ModalModel(f, decays, gains[None, :], name=name)


class Throw(NamedTuple):
    """One thrown object: its rigid shape and material (physics.rigid's table), its modal
    material and overrides (physics.modal's table), bar length (m) for its modes, start
    position (m) and velocity (m/s), and its hit duration (s)."""

    name: str
    shape: object
    rigid: str
    modal: tuple[str, dict]
    size: float
    position: tuple[float, float, float]
    velocity: tuple[float, float, float]
    hit: float


def throws() -> list[Throw]:
    """The scene's seven objects with their throws."""
    from physics.rigid.shapes import Box, Capsule, Convex, Sphere

    die = Convex(trimesh.creation.icosahedron().vertices * 0.015)
    rubber = ("plastic", {"youngs": 5e7, "loss": 0.15})
    return [
        Throw(
            "steel_ball",
            Sphere(0.02),
            "steel",
            ("steel", {}),
            0.04,
            (-0.35, -0.2, 0.40),
            (0.45, 0.3, 0.0),
            2e-4,
        ),
        Throw(
            "glass_marble",
            Sphere(0.008),
            "glass",
            ("glass", {}),
            0.016,
            (-0.2, 0.25, 0.30),
            (0.5, -0.2, 0.0),
            1.5e-4,
        ),
        Throw(
            "wood_block",
            Box((0.04, 0.025, 0.015)),
            "wood",
            ("wood", {}),
            0.08,
            (0.1, -0.25, 0.15),
            (-0.9, 0.2, 0.0),
            6e-4,
        ),
        Throw(
            "ceramic_tile",
            Box((0.03, 0.03, 0.004)),
            "ceramic",
            ("ceramic", {}),
            0.06,
            (0.25, 0.2, 0.2),
            (-1.1, -0.3, 0.0),
            2e-4,
        ),
        Throw(
            "rubber_ball", Sphere(0.025), "rubber", rubber, 0.05, (0.35, -0.1, 0.55), (-0.2, 0.1, 0.0), 3e-3
        ),
        Throw(
            "plastic_die", die, "plastic", ("plastic", {}), 0.03, (-0.05, 0.0, 0.35), (0.3, 0.2, 0.0), 5e-4
        ),
        Throw(
            "ceramic_roller",
            Capsule(0.015, 0.03),
            "ceramic",
            ("ceramic", {}),
            0.09,
            (0.0, 0.3, 0.25),
            (0.1, -0.6, 0.0),
            2e-4,
        ),
    ]


def build_world(seed: int = 0, h: float = 1e-3):
    """(world, voices): the table and seven objects with their throws."""
    from physics.rigid.shapes import Box, mass_properties
    from physics.rigid.world import MATERIALS, Body, Material, Placement, StepParams, World

    rng = np.random.default_rng(seed)
    world = World(StepParams(h=h, integrator="semi-implicit", bounce_threshold=0.1, iterations=40))
    board = ModalModel.load(Path(__file__).with_name("wood_board_model.toml"))
    table_top = Material("varnished wood", 650.0, 0.45, 0.45, rolling=1e-3)  # rolling stops a ball in ~1 s
    world.add(
        Body("table", Box((0.6, 0.4, 0.02)), table_top, kind="static"),
        Placement(position=(0.0, 0.0, TABLE_TOP - 0.02)),
    )
    voices = {
        0: Voice(
            board, hit_duration=8e-4, scrape_roughness=3e-6, roll_roughness=1.5e-5, stiffness=500.0, level=1.0
        )
    }
    for throw in throws():
        mat = MATERIALS[throw.rigid]
        mass = mass_properties(throw.shape, mat.density).mass
        place = Placement(
            position=throw.position,
            quaternion=tuple(rng.normal(size=4)),
            velocity=throw.velocity,
            angular_velocity=tuple(rng.normal(size=3) * 4.0),
        )
        model = bar_model(throw.name, throw.size, mass, *throw.modal)
        idx = world.add(Body(throw.name, throw.shape, mat), place)
        if model is not None:
            voices[idx] = Voice(
                model,
                hit_duration=throw.hit,
                scrape_roughness=2e-6,
                roll_roughness=1e-5,
                stiffness=300.0,
                level=0.5,
            )
    return world, voices


def simulate_drop(duration: float = 5.0, seed: int = 0):
    """(world, voices, RunResult) of the drop scene."""
    from physics.rigid.world import simulate

    world, voices = build_world(seed)
    return world, voices, simulate(world, duration, sample_every=10)


def render_drop(
    out_wav,
    haptic_path=None,
    csv_path=None,
    duration: float = 5.0,
    sample_rate: int = 48000,
    block: int = OFFLINE_BLOCK,
    seed: int = 0,
) -> dict:
    """Render the drop scene to ``out_wav`` (-6 dBFS peak); ``haptic_path`` gets the contact force
    on the table (N, 1 kHz frames) and ``csv_path`` the impacts (time_s, body_a, body_b,
    impulse_ns, speed_ms). Returns a summary with each object's final speed."""
    from jassy.files import write_signal
    from physics.rigid.events import contact_tracks, contact_wrench, impacts

    if not (isinstance(duration, (int, float)) and 0 < duration <= 60):
        raise JassyError(f"duration: expected seconds in (0, 60], got {duration!r}")
    t0 = time.perf_counter()
    world, voices, result = simulate_drop(duration, seed)
    t_phys = time.perf_counter() - t0
    hits = impacts(result, locate=contact_locator(world, voices))
    tracks = contact_tracks(result)
    graph, score = scene_graph(world.bodies, hits, tracks, voices)
    audio, warnings = render_normalised(graph, score, duration, out_wav, sample_rate, block)
    if haptic_path:
        _, force, _ = contact_wrench(result, 0)
        write_signal(haptic_path, force.T.copy(), 1.0 / world.params.h, label="force_")
    if csv_path:
        write_csv(csv_path, impact_rows(hits), IMPACT_HEADER)
    speeds = np.linalg.norm(result.state.phi[:, 3:], axis=1)
    return {
        "frames": audio.shape[1],
        "duration": duration,
        "impacts": len(hits),
        "tracks": len(tracks),
        "final_speeds_ms": {
            b.name: round(float(s), 4)
            for b, s in zip(world.bodies, speeds, strict=True)
            if b.kind == "dynamic"
        },
        "physics_seconds": round(t_phys, 3),
        "render_seconds": round(time.perf_counter() - t0, 3),
        "warnings": warnings,
    }

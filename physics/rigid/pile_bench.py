"""jassy's pile against MuJoCo's: steps per CPU second and penetration, same scene and step.

Both engines start from the same bodies and poses (``bench.pile``, ``peers.mujoco_pile``),
settle for 1 s, then run ``seconds`` of steps from that settled state in interleaved rounds
(CPU time, the best round of each). Penetration is measured on the final poses of both by the
same geometry (:func:`pile_depths`), not by either engine's own contact depths.
"""

from __future__ import annotations

import copy
import math
import resource
import time

import numpy as np
from scipy.spatial import cKDTree

#: Shapes of the pile: even bodies spheres of this radius (m), odd ones cubes of this half-size.
SPHERE_RADIUS, BOX_HALF = 0.02, 0.018
_CORNERS = np.array([[sx, sy, sz] for sx in (-1, 1) for sy in (-1, 1) for sz in (-1, 1)], float) * BOX_HALF


def _rotations(quat: np.ndarray) -> np.ndarray:
    """(N, 3, 3) rotation matrices of unit quaternions (w, x, y, z)."""
    q = quat / np.linalg.norm(quat, axis=1, keepdims=True)
    w, x, y, z = q.T
    return np.stack(
        [
            np.stack([1 - 2 * (y * y + z * z), 2 * (x * y - w * z), 2 * (x * z + w * y)], -1),
            np.stack([2 * (x * y + w * z), 1 - 2 * (x * x + z * z), 2 * (y * z - w * x)], -1),
            np.stack([2 * (x * z - w * y), 2 * (y * z + w * x), 1 - 2 * (x * x + y * y)], -1),
        ],
        1,
    )


def _box_point_depth(centre, rot, points):
    """Depth (m) of each of ``points`` (M, 3) inside the cube at ``centre`` with rotation ``rot``
    (negative outside: minus the distance to the surface)."""
    local = (points - centre) @ rot
    outside = np.maximum(np.abs(local) - BOX_HALF, 0.0)
    inside = np.min(BOX_HALF - np.abs(local), axis=-1)
    return np.where(np.any(outside > 0, axis=-1), -np.linalg.norm(outside, axis=-1), inside)


def pile_depths(pos: np.ndarray, quat: np.ndarray, side: float) -> np.ndarray:
    """Penetration depth (m, 0 if none) of every touching pair and every body against the pen
    (floor z = 0, walls |x|, |y| = side) of a pile whose body i is a sphere for even i and a
    cube for odd i. Exact for spheres against anything and for cube corners against the pen;
    cube against cube counts corners inside the other cube (edge-edge overlap, and the overlap
    of two cubes face to face with aligned edges, are not seen)."""
    rot = _rotations(quat)
    sphere = np.arange(len(pos)) % 2 == 0
    corners = pos[:, None, :] + np.einsum("nij,kj->nki", rot, _CORNERS)
    depths = []
    for axis, sign in ((2, 1.0), (0, 1.0), (0, -1.0), (1, 1.0), (1, -1.0)):
        offset = 0.0 if axis == 2 else side
        centre_gap = sign * pos[:, axis] + offset
        corner_gap = np.min(sign * corners[:, :, axis], axis=1) + offset
        depths.append(np.where(sphere, SPHERE_RADIUS - centre_gap, -corner_gap))
    for a, b in cKDTree(pos).query_pairs(2 * math.sqrt(3) * BOX_HALF + 1e-3):
        if sphere[a] and sphere[b]:
            depths.append([2 * SPHERE_RADIUS - np.linalg.norm(pos[a] - pos[b])])
        elif sphere[a] or sphere[b]:
            s, c = (a, b) if sphere[a] else (b, a)
            depths.append(SPHERE_RADIUS + _box_point_depth(pos[c], rot[c], pos[s][None])[:1])
        else:
            depths.append(_box_point_depth(pos[a], rot[a], corners[b]))
            depths.append(_box_point_depth(pos[b], rot[b], corners[a]))
    return np.maximum(np.concatenate([np.ravel(d) for d in depths]), 0.0)


def _minor_faults() -> int:
    """Minor page faults of this process so far (a page of new memory given on first touch)."""
    return resource.getrusage(resource.RUSAGE_SELF).ru_minflt


def bench_piles(
    sizes=(100, 1000), seconds: float = 0.2, rounds: int = 3, progress=lambda m: None
) -> list[dict]:
    """Per pile size: steps per CPU second of jassy and MuJoCo (best of ``rounds`` interleaved
    rounds of ``seconds`` each from the same settled state), their ratio, and the largest and
    99th-percentile penetration after the rounds. Empty when MuJoCo is not installed. jassy
    runs as MuJoCo does, keeping no contact history (``keep_records=False``), and again
    keeping every contact record as a sound scene needs (``jassy_kept_steps_per_s``); the
    minor page faults per step of each run (new memory touched) are counted too."""
    from physics.rigid.bench import pile
    from physics.rigid.peers import mujoco_pile, mujoco_steps
    from physics.rigid.world import simulate

    rows = []
    for n in sizes:
        progress(f"pile of {n}: settling both engines for 1 s")
        reference = mujoco_pile(n)
        if reference is None:
            return []
        world, settled = pile(n)
        side = 0.05 * math.ceil(math.sqrt(n / 2.0)) + 0.05
        steps = int(round(seconds / world.params.h))
        ours, theirs, kept = [], [], []
        faults = {"jassy": [], "mujoco": [], "kept": []}
        for _ in range(rounds):
            f0, t0 = _minor_faults(), time.process_time()
            result = simulate(world, seconds, state=settled, sample_every=0, keep_records=False)
            ours.append(time.process_time() - t0)
            faults["jassy"].append(_minor_faults() - f0)
            model, data = reference[0], copy.copy(reference[1])
            f0, t0 = _minor_faults(), time.process_time()
            mujoco_steps((model, data), steps)
            theirs.append(time.process_time() - t0)
            faults["mujoco"].append(_minor_faults() - f0)
            f0, t0 = _minor_faults(), time.process_time()
            simulate(world, seconds, state=settled, sample_every=0)  # every contact record kept
            kept.append(time.process_time() - t0)
            faults["kept"].append(_minor_faults() - f0)
        depth_j = pile_depths(result.state.pos[-n:], result.state.quat[-n:], side)  # after the pen's planes
        depth_m = pile_depths(data.xpos[1:], data.xquat[1:], side)
        rows.append(
            {
                "bodies": n,
                "jassy_steps_per_s": steps / min(ours),
                "mujoco_steps_per_s": steps / min(theirs),
                "ratio": min(theirs) / min(ours),
                "jassy_kept_steps_per_s": steps / min(kept),
                "kept_ratio": min(theirs) / min(kept),
                **{f"{k}_faults_per_step": min(v) / steps for k, v in faults.items()},
                "jassy_contacts": result.stats["contacts"] / max(result.stats["solves"], 1),
                "mujoco_contacts": int(data.ncon),
                "jassy_sweeps": result.stats["sweeps"] / max(result.stats["solves"], 1),
                "jassy_depth_max": float(depth_j.max()),
                "mujoco_depth_max": float(depth_m.max()),
                "jassy_depth_p99": float(np.percentile(depth_j[depth_j > 0], 99))
                if np.any(depth_j > 0)
                else 0.0,
                "mujoco_depth_p99": float(np.percentile(depth_m[depth_m > 0], 99))
                if np.any(depth_m > 0)
                else 0.0,
            }
        )
    if len(rows) >= 2:
        a, b = rows[0], rows[-1]
        scale = math.log(b["bodies"] / a["bodies"])
        for key in ("jassy", "mujoco"):
            slope = math.log(a[f"{key}_steps_per_s"] / b[f"{key}_steps_per_s"]) / scale
            rows[-1][f"{key}_slope"] = slope
    return rows


def print_piles(rows: list[dict]) -> None:
    """The table of :func:`bench_piles` (or why it is empty)."""
    if not rows:
        print("pile vs MuJoCo: skipped (MuJoCo is not installed: pip install mujoco)")
        return
    print("pile vs MuJoCo (same scene and 1 ms step; CPU time, best of interleaved rounds)")
    print(
        f"{'bodies':>6s} {'jassy steps/s':>13s} {'MuJoCo steps/s':>14s} {'jassy/MuJoCo':>12s} "
        f"{'contacts j/M':>12s} {'sweeps':>6s} {'max depth j/M (mm)':>19s} {'p99 depth j/M (mm)':>19s}"
    )
    for r in rows:
        print(
            f"{r['bodies']:6d} {r['jassy_steps_per_s']:13.0f} {r['mujoco_steps_per_s']:14.0f} "
            f"{r['ratio']:11.2f}x {r['jassy_contacts']:6.0f}/{r['mujoco_contacts']:<5d} "
            f"{r['jassy_sweeps']:6.1f} "
            f"{1e3 * r['jassy_depth_max']:9.3f}/{1e3 * r['mujoco_depth_max']:<9.3f} "
            f"{1e3 * r['jassy_depth_p99']:9.3f}/{1e3 * r['mujoco_depth_p99']:<9.3f}"
        )
    for r in rows:
        print(
            f"{r['bodies']:6d} bodies, contact records kept: jassy {r['jassy_kept_steps_per_s']:.0f} steps/s "
            f"({r['kept_ratio']:.2f}x MuJoCo); minor page faults per step: jassy "
            f"{r['jassy_faults_per_step']:.1f}, records kept {r['kept_faults_per_step']:.1f}, "
            f"MuJoCo {r['mujoco_faults_per_step']:.1f}"
        )
    last = rows[-1]
    if "jassy_slope" in last:
        print(
            f"cost slope {rows[0]['bodies']}->{last['bodies']} bodies (log time per step / log bodies): "
            f"jassy {last['jassy_slope']:.2f}, MuJoCo {last['mujoco_slope']:.2f}"
        )

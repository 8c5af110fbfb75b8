"""The cataract-surgery experiment (Agus et al., VRIPHYS 2006, pp. 91-100): capsulorhexis of the
anterior capsule with forceps, then phacoemulsification of the lens along a cross-shaped
groove until it splits into quasi-rigid fragments that fall and collide in the capsule bag."""

from __future__ import annotations

import time

import numpy as np

from jassy.errors import JassyError
from physics.deform.fragments import FragmentParams, FragmentSim, lens_mesh
from physics.deform.membrane import disc_mesh, membrane_from_mesh
from physics.deform.shape_matching import Boundaries


def _groove_path(centre, half_length, depths, step, rng, tremor):
    """Raster of a cross-shaped groove: along y at x = 0, then along x at y = 0, passing
    back and forth at each depth from the top down (tool positions, m)."""
    line = np.arange(-half_length, half_length + step / 2, step)
    out = []
    for axis in (1, 0):
        for d, z in enumerate(depths):
            pts = np.zeros((line.size, 3))
            pts[:, axis] = line if d % 2 == 0 else line[::-1]
            pts[:, 2] = z
            out.append(pts)
    path = np.concatenate(out) + centre
    return path + tremor * rng.normal(size=path.shape)


def _anterior_capsule():
    """The anterior capsule: a 4.5 mm disc membrane 3 mm above the lens centre, rim (outer 72
    particles) anchored, the particles within 0.5 mm of the centre grasped (scripted).
    Returns (particle positions m, membrane, grasped particle indices)."""
    pts, tri = disc_mesh(4.5e-3, 12)
    pts[:, 2] += 3.0e-3
    rim = np.arange(len(pts) - 72, len(pts))
    grasp = np.flatnonzero(np.linalg.norm(pts[:, :2], axis=1) < 0.5e-3)
    mem = membrane_from_mesh(
        pts,
        tri,
        thickness=15e-6,
        density=1000.0,
        stiffness=0.01,
        damping=0.0,
        tear_strain=0.25,
        anchored=rim,
        scripted=grasp,
        viscosity=20.0,
    )
    return pts, mem, grasp


def _forceps(g0: np.ndarray, rhexis_time: float):
    """The forceps' script t -> grasped positions (m): from ``g0`` lift 1 mm over 0.2 s, then
    move out to a 2.5 mm radius over 0.1 s while circling once by ``rhexis_time`` s."""

    def forceps(t):
        lift = min(t / 0.2, 1.0) * 1e-3
        ang = max(t - 0.2, 0.0) * 2 * np.pi / max((rhexis_time - 0.2), 1e-9)
        r = 2.5e-3 * min(max(t - 0.2, 0.0) / 0.1, 1.0)
        return g0 + [r * np.cos(ang), r * np.sin(ang), lift]

    return forceps


def cataract_demo(
    steps: int = 2500,
    seed: int = 0,
    h: float = 1e-3,
    spacing: float = 0.6e-3,
    tool_radius: float = 0.7e-3,
    budget: int = 30,
    rhexis_steps: int = 400,
) -> dict:
    """Run the experiment for ``steps`` steps of h seconds (lens and membrane both stepped).

    Membrane: a 4.5 mm anterior-capsule disc, rim anchored, centre grasped by scripted
    forceps that lift 1 mm then circle (radius 2.5 mm) for ``rhexis_steps`` steps. Lens: a
    9 x 9 x 4 mm ellipsoid tet mesh (``spacing`` m) resting in a spherical bag (radius 6 mm);
    after the capsulorhexis the phaco tip (a sphere of ``tool_radius`` m, up to ``budget``
    tets per step, hand tremor 20 um from ``seed``) follows the cross-groove raster; the rest
    of the steps let the fragments fall and collide. Returns counts, the Impact and Tear
    events, the removed tets' indices into ``lens_mesh(spacing=spacing)``, the fragments' stable
    ids (as in the Impact events' bodies; -1 = the bag) and timings (wall-clock ms per call,
    this machine)."""
    if steps < 1 or rhexis_steps < 0:
        raise JassyError(
            f"steps, rhexis_steps: expected steps >= 1 and rhexis_steps >= 0, got {steps}, {rhexis_steps}"
        )
    rng = np.random.default_rng(seed)
    t_start = time.perf_counter()
    mesh = lens_mesh(spacing=spacing)
    sim = FragmentSim(mesh, FragmentParams(), Boundaries(bag_radius=6e-3))
    pts, mem, grasp = _anterior_capsule()
    mst = mem.initial_state()
    forceps = _forceps(pts[grasp], rhexis_steps * h)
    settle = 100
    path = None
    impacts, tears = [], []
    t_frag, t_erode, t_mem = [], [], []
    split_step = None
    for k in range(steps):
        if k < rhexis_steps:
            t0 = time.perf_counter()
            tears += mem.step(mst, h, forceps)
            t_mem.append(time.perf_counter() - t0)
        if k == settle:
            x = sim.state.body.x
            c = x[sim.matcher.order].mean(0)
            path = _groove_path(c, 5.0e-3, np.linspace(2.5e-3, -2.5e-3, 11), 0.5e-3, rng, 20e-6)
            path = np.repeat(path, 2, axis=0)
        erode_at = k - max(settle, rhexis_steps)
        if path is not None and 0 <= erode_at < len(path) and split_step is None:
            t0 = time.perf_counter()
            sim.erode(path[erode_at], tool_radius, budget)
            t_erode.append(time.perf_counter() - t0)
            if sim.n_fragments >= 4:
                split_step = k
        t0 = time.perf_counter()
        impacts += sim.step(h)
        t_frag.append(time.perf_counter() - t0)
    st = sim.state
    boundary_hits = sum(1 for i in impacts if i.bodies[1] < 0)

    def ms(v):
        return float(np.median(v) * 1e3) if v else 0.0

    return {
        "steps": steps,
        "lens_particles": int(mesh.points.shape[0]),
        "lens_tets": int(mesh.tets.shape[0]),
        "tets_removed": int((~st.alive).sum()),
        "removed_tets": np.flatnonzero(~st.alive).tolist(),
        "removed_by_external_faces": {str(i + 1): int(c) for i, c in enumerate(st.removed_by_kind)},
        "fragments": sim.n_fragments,
        "fragment_sizes": np.bincount(sim.matcher.body[sim.matcher.body >= 0]).tolist(),
        "fragment_ids": st.fragment_ids.tolist(),
        "split_time_s": None if split_step is None else split_step * h,
        "impacts": len(impacts),
        "impacts_boundary": boundary_hits,
        "impacts_fragment": len(impacts) - boundary_hits,
        "membrane_particles": int(len(pts)),
        "membrane_springs": int(mem.springs.shape[0]),
        "torn_springs": len(tears),
        "impact_events": impacts,
        "tear_events": tears,
        "fragment_step_ms": ms(t_frag),
        "erode_ms": ms(t_erode),
        "membrane_step_ms": ms(t_mem),
        "wall_s": time.perf_counter() - t_start,
    }

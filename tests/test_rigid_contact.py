"""Rigid contact against closed forms: bounces, sliding, rolling, penalty contact, events."""

import math

import numpy as np
import pytest
import trimesh

from jassy.errors import JassyError
from physics.rigid import codes
from physics.rigid import stepper as st
from physics.rigid.broad import new_sweep, sweep_pairs
from physics.rigid.events import contact_tracks, contact_wrench, haptic_frames, impacts
from physics.rigid.impulses import new_solver, new_warm_start
from physics.rigid.meshgrid import build_grid, grid_closest, grid_within
from physics.rigid.narrow import _mesh_closest, new_contacts, new_mesh_memory, segment_params
from physics.rigid.shapes import Box, Capsule, Convex, Plane, Sphere, TriangleMesh, mass_properties
from physics.rigid.world import Body, Material, Placement, StepParams, World, simulate

G = 9.81


def _ball_world(e, integrator="rk4", h=1e-3, height=1.0, radius=0.05, **params):
    w = World(StepParams(h=h, integrator=integrator, bounce_threshold=0.05, **params))
    w.add(Body("ground", Plane(), Material("g", 1000, e, 0.0), kind="static"))
    w.add(
        Body("ball", Sphere(radius), Material("b", 1000, e, 0.0)), Placement(position=(0, 0, height + radius))
    )
    return w


@pytest.mark.parametrize("e", [0.8, 0.5])
def test_bouncing_ball_impact_times_and_intervals(e):
    """RK4: impact times exact (within 1e-9 s) though they fall inside 1 ms steps; flight times
    shrink by e; the impulse is m (1 + e) v."""
    w = _ball_world(e)
    result = simulate(w, 3.0, sample_every=0)
    hits = impacts(result)
    v0 = math.sqrt(2 * G)
    n = min(len(hits), 6)
    expected = math.sqrt(2 / G) + np.r_[0, np.cumsum(2 * v0 * e ** np.arange(1, n) / G)]
    times = np.array([h.time for h in hits[:n]])
    assert np.max(np.abs(times - expected)) < 1e-9
    assert np.any(np.abs(times / 1e-3 - np.round(times / 1e-3)) > 0.05)  # not on the step grid
    intervals = np.diff(times)
    assert np.allclose(intervals[1:] / intervals[:-1], e, rtol=1e-6)
    mass = 1000 * 4 / 3 * math.pi * 0.05**3
    speeds = v0 * e ** np.arange(n)
    assert np.allclose([h.impulse for h in hits[:n]], mass * (1 + e) * speeds, rtol=1e-6)
    assert np.allclose([h.speed for h in hits[:n]], speeds, rtol=1e-6)


def test_bouncing_ball_default_integrator_follows_the_analytic_series():
    """Default (semi-implicit) integrator at 1 ms steps, e = 0.6: the flight is integrated in
    closed form, so the impact times t_k = t_1 + sum 2 v0 e^j / g and speeds v0 e^k match
    the analytic series to 1e-9 s and 1e-9 relative over six bounces (before: 1.1e-2 s and
    3.8 % off after five)."""
    e = 0.6
    result = simulate(_ball_world(e, integrator="semi-implicit"), 3.0, sample_every=0)
    hits = impacts(result)
    v0 = math.sqrt(2 * G)
    n = 6
    expected = math.sqrt(2 / G) + np.r_[0, np.cumsum(2 * v0 * e ** np.arange(1, n) / G)]
    times = np.array([h.time for h in hits[:n]])
    assert len(hits) >= n and np.max(np.abs(times - expected)) < 1e-9
    speeds = np.array([h.speed for h in hits[:n]])
    assert np.max(np.abs(speeds / (v0 * e ** np.arange(n)) - 1)) < 1e-9


def test_bouncing_ball_time_to_rest():
    """Zeno limit: rest at t1 + (v0/g) 2e/(1-e) after the first impact; bounces stop when the
    approach speed falls below the bounce threshold (a remainder below 2 v_thr / (g (1-e))).
    At rest: within 10 um of the floor and slower than 1 mm/s; the last landing, too slow for
    an impact, sinks into the floor by up to v_thr h and is pushed out at beta per step, a tail
    that then decays below 1e-6 m/s within 40 ms."""
    e = 0.5
    w = _ball_world(e, integrator="semi-implicit")
    result = simulate(w, 2.0)
    v0 = math.sqrt(2 * G)
    rest = math.sqrt(2 / G) + v0 / G * 2 * e / (1 - e)
    z, vz = result.pos[:, 1, 2], result.phi[:, 1, 5]
    resting = (np.abs(z - 0.05) < 1e-5) & (np.abs(vz) < 1e-3)
    first_rest = result.times[np.argmax(resting)]
    assert np.all(resting[result.times > first_rest])
    assert abs(first_rest - rest) < 2 * 0.05 / (G * (1 - e)) + 2e-3
    still = (np.abs(vz) < 1e-6) & (result.times > first_rest)
    assert still[-1] and result.times[np.argmax(still)] - first_rest < 0.04


@pytest.mark.parametrize("h", [1e-3, 5e-4])
def test_sliding_block_stops_at_coulomb_distance(h):
    v0, mu = 2.0, 0.5
    w = World(StepParams(h=h))
    w.add(Body("ground", Plane(), Material("g", 1000, 0, mu), kind="static"))
    w.add(
        Body("box", Box((0.1, 0.1, 0.05)), Material("b", 500, 0, mu)),
        Placement(position=(0, 0, 0.05), velocity=(v0, 0, 0)),
    )
    result = simulate(w, 0.6)
    x = result.pos[:, 1, 0]
    assert x[-1] == pytest.approx(v0**2 / (2 * mu * G), abs=v0 * h)
    stop = result.times[np.argmax(np.abs(result.phi[:, 1, 3]) < 1e-9)]
    assert stop == pytest.approx(v0 / (mu * G), abs=2 * h)
    assert np.max(np.abs(result.pos[:, 1, 2] - 0.05)) < 1e-5  # stays on the plane, no tipping
    tracks = contact_tracks(result)
    assert len(tracks) == 1
    track = tracks[0]
    mass = 500 * 0.2 * 0.2 * 0.1
    sliding = track.times < 0.35
    assert np.allclose(track.normal_force[sliding], mass * G, rtol=1e-6)
    slope = np.polyfit(track.times[sliding], track.slip_speed[sliding], 1)[0]
    assert slope == pytest.approx(-mu * G, rel=1e-3)


@pytest.mark.parametrize("mu, expected", [(0.5, 5 / 7), (0.0, 1.0)])
def test_sphere_on_incline(mu, expected):
    """Rolls without slipping at 5/7 g sin(theta) (mu > 2/7 tan theta); slides at g sin(theta)
    without friction."""
    theta = math.radians(30)
    n = (0.0, -math.sin(theta), math.cos(theta))
    w = World(StepParams(h=1e-3))
    w.add(Body("slope", Plane(n, 0.0), Material("g", 1000, 0, mu), kind="static"))
    w.add(Body("ball", Sphere(0.1), Material("b", 1000, 0, mu)), Placement(position=np.array(n) * 0.1))
    result = simulate(w, 1.0)
    s = np.linalg.norm(result.pos[:, 1] - result.pos[0, 1], axis=1)
    accel = 2 * np.polyfit(result.times, s, 2)[0]
    assert accel == pytest.approx(expected * G * math.sin(theta), rel=2e-3)
    if mu > 0:
        roll = contact_tracks(result)[0]
        assert np.max(roll.slip_speed) < 1e-6
        a = expected * G * math.sin(theta)  # rolling speed = centre speed (sampled at the step end)
        assert np.max(np.abs(roll.rolling_speed - a * roll.times)) < 1.01 * a * 1e-3


def _bounce_ode(k, c, m, v_in):
    """Independent reference: m x'' = -max(k x + c x', 0) from first touch to separation
    (scipy solve_ivp, tight tolerances); returns (rebound speed, contact time)."""
    from scipy.integrate import solve_ivp

    def rhs(t, y):
        return [y[1], -max(k * y[0] + c * y[1], 0.0) / m]

    def leave(t, y):
        return y[0] if t > 1e-6 else 1.0

    leave.terminal, leave.direction = True, -1
    sol = solve_ivp(rhs, (0, 1), [0.0, v_in], events=leave, rtol=1e-11, atol=1e-14, max_step=1e-5)
    return -sol.y_events[0][0][1], sol.t_events[0][0]


def test_linear_spring_damper_contact_matches_ode():
    """k = 1e4, c = 5, m = 0.1 (physics.md A4: unclamped e = 0.779467, t_c = 9.96578e-3 s).
    The force is clamped at zero (no pull before separation), so the reference is the
    clamped ODE, which separates slightly earlier and faster."""
    k, c, m = 1e4, 5.0, 0.1
    radius = 0.02
    density = m / (4 / 3 * math.pi * radius**3)
    w = World(StepParams(h=1e-5, contact="linear", stiffness=k, damping=c, gravity=(0, 0, 0), slop=0.0))
    w.add(Body("ground", Plane(), Material("g", 1000, 0, 0), kind="static"))
    w.add(
        Body("ball", Sphere(radius), Material("b", density, 0, 0)),
        Placement(position=(0, 0, radius + 1e-3), velocity=(0, 0, -1.0)),
    )
    result = simulate(w, 0.03)
    v_out, t_c = _bounce_ode(k, c, m, 1.0)
    assert 0.779467 < v_out < 0.80 and 9.5e-3 < t_c < 9.96578e-3
    rows = result.records
    t_contact = rows[-1, codes.REC_TIME] - rows[0, codes.REC_TIME] + 1e-5
    assert t_contact == pytest.approx(t_c, abs=3e-5)
    assert result.phi[-1, 1, 5] == pytest.approx(v_out, rel=2e-3)


@pytest.mark.parametrize("mass, exponent", [(0.1, 1.5), (0.4, 1.0)])
def test_hunt_crossley_restitution_and_zero_force_at_touch(mass, exponent):
    """e from v_out - v_in = (1/a) ln((1 + a v_out)/(1 + a v_in)), a = lambda/k, for any m, n."""
    from scipy.optimize import brentq

    k, lam, v_in = 1e5, 2e4, 1.0
    radius = 0.02
    density = mass / (4 / 3 * math.pi * radius**3)
    w = World(
        StepParams(
            h=2e-6,
            contact="hunt-crossley",
            stiffness=k,
            damping=lam,
            exponent=exponent,
            gravity=(0, 0, 0),
            slop=0.0,
        )
    )
    w.add(Body("ground", Plane(), Material("g", 1000, 0, 0), kind="static"))
    w.add(
        Body("ball", Sphere(radius), Material("b", density, 0, 0)),
        Placement(position=(0, 0, radius + 1e-5), velocity=(0, 0, -v_in)),
    )
    result = simulate(w, 0.02, sample_every=0)
    alpha = lam / k
    v_out = brentq(
        lambda v: (-v - v_in) - np.log((1 - alpha * v) / (1 + alpha * v_in)) / alpha, 1e-9, 1 / alpha - 1e-9
    )
    assert result.state.phi[1, 5] == pytest.approx(v_out, rel=2e-3)
    first = np.linalg.norm(result.records[0, codes.REC_IMPULSE : codes.REC_IMPULSE + 3]) / 2e-6
    assert first < 1e-3 * lam * v_in  # a linear damper would start at lambda-like c v_in


def _penalty_ball(h, height, velocity=(0, 0, 0), spin=(0, 0, 0), friction=0.0):
    """A 0.1 kg ball of radius 2 cm over a plane under the linear penalty model (k = 1e4 N/m,
    c = 5 N s/m), its lowest point ``height`` (m) above the plane."""
    radius, mass = 0.02, 0.1
    density = mass / (4 / 3 * math.pi * radius**3)
    params = StepParams(h=h, contact="linear", stiffness=1e4, damping=5.0, slop=0.0, bounce_threshold=0.05)
    w = World(params)
    w.add(Body("ground", Plane(), Material("g", 1000, 0, friction), kind="static"))
    place = Placement(position=(0, 0, radius + height), velocity=velocity, angular_velocity=spin)
    w.add(Body("ball", Sphere(radius), Material("b", density, 0, friction)), place)
    return w


def test_penalty_contact_gives_impacts_at_the_ballistic_times():
    """A ball dropped from rest H = 0.1 m above a plane, linear penalty contact, h = 0.1 ms:
    one impact per bounce (a bounce lasts many steps), the first at sqrt(2 H / g) and
    sqrt(2 g H) (seen at the first step start after it: within h, and g h faster); each later
    one a ballistic flight 2 v / g (v: its landing speed, take-off speed alike) after the
    last pushing step of the bounce before (within the step of take-off, of landing and the
    g h of the landing speed: 3 h)."""
    h, height = 1e-4, 0.1
    result = simulate(_penalty_ball(h, height), 0.6, sample_every=0)
    hits = impacts(result)
    assert len(hits) >= 3
    first = math.sqrt(2 * height / G)
    assert 0 < hits[0].time - first <= h * (1 + 1e-9)
    assert hits[0].speed == pytest.approx(math.sqrt(2 * G * height), abs=G * h)
    times = result.records[:, codes.REC_TIME]
    for before, after in zip(hits[:-1], hits[1:], strict=True):
        last_push = times[(times >= before.time) & (times < after.time)].max()
        assert after.time - last_push == pytest.approx(2 * after.speed / G, abs=3 * h)
        assert after.speed < before.speed  # the damper takes energy at each bounce


def test_penalty_contact_reports_the_rolling_speed():
    """A ball rolling without slipping at v = 0.5 m/s on a plane, linear penalty contact,
    resting at the static overlap x = m g / k: its contact point lies halfway through the
    overlap (lever arm r - x / 2), so it spins at v / (r - x / 2); its contact track's
    rolling speed (|w| times the lever arm) is v, and it does not slip."""
    v, radius, sink = 0.5, 0.02, 0.1 * G / 1e4
    spin = (0, v / (radius - sink / 2), 0)
    world = _penalty_ball(1e-4, -sink, velocity=(v, 0, 0), spin=spin, friction=0.5)
    track = contact_tracks(simulate(world, 0.1, sample_every=0))[0]
    assert np.median(track.rolling_speed) == pytest.approx(v, rel=1e-6)
    assert np.median(track.slip_speed) < 1e-9 * v


def test_box_resting_on_four_corners_carries_its_weight():
    w = World(StepParams(h=1e-3))
    w.add(Body("ground", Plane(), Material("g", 1000, 0, 0.5), kind="static"))
    w.add(Body("box", Box((0.1, 0.05, 0.02)), Material("b", 800, 0, 0.5)), Placement(position=(0, 0, 0.0205)))
    result = simulate(w, 0.5)
    times, force, _ = contact_wrench(result, 1)
    mass = 800 * 0.2 * 0.1 * 0.04
    assert np.allclose(force[times > 0.1, 2], mass * G, rtol=1e-6)
    assert np.max(np.abs(result.pos[:, 1, 2] - 0.02)) < 1e-3
    frames = haptic_frames(result, 1)
    assert len(frames) == 500 and np.allclose(frames[-1].force, [0, 0, mass * G], rtol=1e-6)
    # about a point moving along x at 0.1 m/s on the ground: the box is in equilibrium, so its
    # contact forces act as its weight below its centre, (0, 0, 0.02) - point, crossed with it
    times, _, torque = contact_wrench(result, 1, lambda t: np.c_[0.1 * t, 0 * t, 0 * t])
    late = times > 0.1
    assert np.allclose(torque[late, 1], 0.1 * times[late] * mass * G, rtol=1e-5)
    assert np.allclose(torque[late][:, [0, 2]], 0.0, atol=1e-6 * mass * G)


@pytest.mark.parametrize(
    "turn, shift",
    [(0.0, 0.0), (0.2, 0.0), (0.0, 0.003), (0.05, 0.001)],
    ids=["aligned", "turned", "shifted", "turned-and-shifted"],
)
def test_a_tower_of_cubes_stands(turn, shift):
    """Four equal 2 cm cubes stacked, each turned by ``turn`` (rad) about the vertical and
    shifted by ``shift`` (m) from the one below: aligned, their corners lie on the edges
    below; turned, every corner overhangs, and only edges cross faces. The tower must stand
    (static equilibrium: no level moves, the ground carries the whole weight)."""
    w = World(StepParams(h=1e-3))
    w.add(Body("ground", Plane(), Material("g", 1000, 0, 0.5), kind="static"))
    half = 0.01
    for level in range(4):
        angle = turn * level
        w.add(
            Body(f"cube{level}", Box((half, half, half)), Material("b", 800, 0, 0.5)),
            Placement(
                position=(shift * level, 0, (2 * level + 1) * half),
                quaternion=(math.cos(angle / 2), 0, 0, math.sin(angle / 2)),
            ),
        )
    result = simulate(w, 1.0, sample_every=100)
    assert np.max(np.abs(result.pos[:, 1:] - w.initial_state().pos[1:])) < 1e-5
    times, force, _ = contact_wrench(result, 0)
    weight = 4 * 800 * (2 * half) ** 3 * G
    assert np.allclose(force[times > 0.5, 2], -weight, rtol=1e-4)


def test_impact_location_on_a_mesh_is_the_hit_triangle():
    """A sphere dropped on a mesh floor whose model rows are its vertices strikes the triangle
    under it, with barycentric weights of the contact point."""
    floor = trimesh.creation.box(extents=(1.0, 1.0, 0.1))
    floor.apply_translation((0, 0, -0.05))
    w = World(StepParams(h=1e-3))
    from patches.rigid_sound import Voice, contact_locator

    w.add(Body("floor", TriangleMesh(floor), Material("g", 1000, 0.5, 0), kind="static"))
    w.add(Body("ball", Sphere(0.02), Material("b", 1000, 0.5, 0)), Placement(position=(0.13, -0.21, 0.3)))
    voices = {0: Voice(None, "vertices")}  # the floor's model rows are its vertices
    hit = impacts(simulate(w, 0.3, sample_every=0), locate=contact_locator(w, voices))[0]
    loc = hit.locations[0] if hit.bodies[0] == 0 else hit.locations[1]
    verts = np.asarray(floor.vertices)[list(loc.vertices)]
    point = np.asarray(loc.weights) @ verts
    assert sum(loc.weights) == pytest.approx(1.0)
    assert np.allclose(point, [0.13, -0.21, 0.0], atol=1e-6)


def test_second_mesh_carries_a_box_and_locates_its_contacts():
    """Two mesh floors side by side (their grids end to end in the model tables): a box resting
    on the second one stays up, and its contacts name the second mesh's triangles under it."""
    floors = [trimesh.creation.box(extents=(0.5, 0.5, 0.1)) for _ in range(2)]
    floors[0].apply_translation((-0.3, 0, -0.05))
    floors[1].apply_translation((0.3, 0, -0.05))
    w = World(StepParams(h=1e-3))
    for k, floor in enumerate(floors):
        w.add(Body(f"floor{k}", TriangleMesh(floor), Material("g", 1000, 0.5, 0.4), kind="static"))
    w.add(
        Body("box", Box((0.02, 0.02, 0.02)), Material("b", 500, 0.3, 0.4)), Placement(position=(0.3, 0, 0.05))
    )
    result = simulate(w, 0.5, sample_every=10)
    assert np.max(np.abs(result.pos[-20:, 2, 2] - 0.02)) < 1e-4
    rec = result.records[result.records[:, codes.REC_TIME] > 0.4]
    assert len(rec) and np.all(rec[:, codes.REC_B] == 1)
    tris = floors[1].triangles[rec[:, codes.REC_FEAT_B].astype(int)]
    points = np.einsum("ij,ijk->ik", rec[:, codes.REC_BARY : codes.REC_BARY + 3], tris)
    assert np.allclose(points[:, 2], 0.0, atol=1e-9)
    assert np.all(np.abs(points[:, :2] - [0.3, 0.0]).max(axis=1) < 0.021)


def test_grid_closest_point_matches_brute_force():
    """Against trimesh's vectorised point-triangle routine over every triangle."""
    mesh = trimesh.creation.icosphere(subdivisions=3, radius=0.3)
    grid = build_grid(np.asarray(mesh.vertices), np.asarray(mesh.faces))
    rng = np.random.default_rng(3)
    pts = rng.normal(size=(100, 3))
    pts *= ((0.3 + rng.uniform(-0.05, 0.05, 100)) / np.linalg.norm(pts, axis=1))[:, None]
    tris = np.asarray(mesh.triangles)
    for p in pts:
        cand = trimesh.triangles.closest_point(tris, np.tile(p, (len(tris), 1)))
        d = np.linalg.norm(cand - p, axis=1)
        q = cand[np.argmin(d)]
        tri, d2, u, v, w = grid_closest(*p, 0.2, grid.view())
        assert np.sqrt(d2) == pytest.approx(d.min(), abs=1e-9)
        assert np.allclose(np.array([u, v, w]) @ grid.triangles[tri], q, atol=1e-9)


def _bumpy_bowl():
    """A sphere of radius 0.3 m with its vertices moved in and out by up to 3 %: the nearest
    triangle of a point moving near it changes often, and not only to a neighbour."""
    mesh = trimesh.creation.icosphere(subdivisions=3, radius=0.3)
    scale = 1.0 + 0.03 * np.random.default_rng(8).uniform(-1.0, 1.0, len(mesh.vertices))
    return trimesh.Trimesh(mesh.vertices * scale[:, None], mesh.faces)


def _distances(tris, p):
    """Distance (m) from p to every triangle, by trimesh's vectorised routine."""
    return np.linalg.norm(trimesh.triangles.closest_point(tris, np.tile(p, (len(tris), 1))) - p, axis=1)


def test_grid_within_lists_every_triangle_within_the_radius_nearest_first():
    mesh = _bumpy_bowl()
    grid = build_grid(np.asarray(mesh.vertices), np.asarray(mesh.faces))
    view = grid.view()
    out, dist = np.full((2, 64), -1, np.int64), np.zeros((2, 64))
    rng = np.random.default_rng(9)
    pts = rng.normal(size=(40, 3))
    pts *= (rng.uniform(0.27, 0.33, 40) / np.linalg.norm(pts, axis=1))[:, None]
    for p in pts:
        d = _distances(grid.triangles, p)
        ds = np.sort(d)  # a radius between two distances, beyond ten triangles (ties: a shared vertex)
        count = 10 + np.flatnonzero(np.diff(ds[9:]) > 1e-6)[0]
        radius = ds[count - 1 : count + 1].mean()
        n = grid_within(*p, radius, view, out, dist, 1)
        assert n == count
        assert set(out[1, :n]) == set(np.flatnonzero(d < radius))
        assert np.allclose(dist[1, :n], d[out[1, :n]], atol=1e-12)
        assert np.all(np.diff(dist[1, :n]) >= 0.0)
        assert np.all(out[0] == -1)  # only the row asked for is written
        assert (
            grid_within(*p, radius, view, out[:, : n - 1], dist[:, : n - 1], 1) == -1
        )  # more than a row holds


def test_remembered_mesh_queries_equal_a_search_of_every_triangle():
    """A body point's memory of a mesh (bound on its distance where last searched; Verlet list of
    the triangles that can be nearest) gives what a search of every triangle gives, along a path
    of small steps (the list is reused) and jumps (it is rebuilt)."""
    w = World(StepParams(h=1e-3))
    w.add(Body("bowl", TriangleMesh(_bumpy_bowl()), Material("g", 1000, 0.5, 0), kind="static"))
    w.add(Body("ball", Sphere(0.01), Material("b", 1000, 0.5, 0)))
    geo = w.model().geometry
    m, k = geo.mesh_of[0], geo.point_start[1]
    tris = geo.tris[geo.tri_start[m] : geo.tri_start[m + 1]]
    near = new_mesh_memory(geo.point_start[-1])
    reach = 0.02
    rng = np.random.default_rng(10)
    p = np.array([0.0, 0.0, -0.28])
    reused = within = 0
    for step in range(600):
        p = p + (rng.normal(size=3) * (0.03 if step % 50 == 0 else 0.001))
        p *= (0.3 + 0.03 * math.sin(step / 30)) / np.linalg.norm(p)  # in and out of reach
        listed_before = near[4][k].copy()
        tri, d2, u, v, w_ = _mesh_closest(k, m, *p, reach, geo, near)
        d = _distances(tris, p)
        if d.min() < reach - 1e-9:
            within += 1
            assert tri >= 0 and math.sqrt(d2) == pytest.approx(d.min(), abs=1e-12)
            assert np.linalg.norm(np.array([u, v, w_]) @ tris[tri] - p) == pytest.approx(d.min(), abs=1e-12)
        elif d.min() > reach + 1e-9:
            assert tri == -1
        reused += listed_before[4] == m + 1 and np.array_equal(near[4][k], listed_before)
    assert 200 < within < 500 and reused > 200  # lists, searches and clearances were exercised


def test_each_island_of_a_solve_converges_on_its_own():
    """A column of four balls (many sweeps) and five lone boxes (few) resting on the ground,
    from a cold start: after one step every body is at rest, to the solver's tolerance.
    Contacts whose bodies have settled are skipped while the column is still sweeping;
    skipping too much (or too early) would leave a body moving."""
    h, r = 1e-3, 0.01
    w = World(StepParams(h=h, tolerance=1e-9, iterations=500))
    w.add(Body("ground", Plane(), Material("g", 1000, 0, 0.5), kind="static"))
    for level in range(4):
        w.add(
            Body(f"ball{level}", Sphere(r), Material("b", 800 + 400 * level, 0, 0.5)),
            Placement(position=(0, 0, (2 * level + 1) * r)),
        )
    for j in range(5):
        w.add(
            Body(f"box{j}", Box((r, r, r)), Material("b", 800 + 100 * j, 0, 0.5)),
            Placement(position=(0.1 + 0.05 * j, 0, r)),
        )
    result = simulate(w, h, sample_every=1)
    assert result.stats["sweeps"] > 20  # the column needs many
    assert np.max(np.abs(result.phi[-1, 1:])) < 1e-6 * G * h


def test_closest_segments_against_dense_sampling():
    rng = np.random.default_rng(4)
    s = np.linspace(0, 1, 801)
    for _ in range(20):
        p1, q1, p2, q2 = rng.normal(size=(4, 3))
        s1, s2 = segment_params(tuple(p1), tuple(q1), tuple(p2), tuple(q2))
        c1, c2 = p1 + s1 * (q1 - p1), p2 + s2 * (q2 - p2)
        a = p1 + s[:, None] * (q1 - p1)
        b = p2 + s[:, None] * (q2 - p2)
        brute = np.min(np.linalg.norm(a[:, None] - b[None], axis=2))
        assert np.linalg.norm(c1 - c2) <= brute + 1e-12
        assert np.linalg.norm(c1 - c2) >= brute - 1e-2


def test_sweep_and_prune_equals_all_pairs():
    """The broad phase against every pair tested by brute force, with a scratch reused across
    sweeps and a dense set that outgrows its pair buffer (the sweep counts them all; grown,
    it finds them)."""
    rng = np.random.default_rng(5)
    scratch = new_sweep(300)
    for size in (0.1, 0.6):
        lo = rng.uniform(0, 1, (300, 3))
        hi = lo + rng.uniform(0, size, (300, 3))
        movable = rng.uniform(size=300) < 0.8
        count = sweep_pairs(lo, hi, movable, scratch)
        if count > scratch.pairs.shape[0]:
            scratch = new_sweep(300, count)
            assert sweep_pairs(lo, hi, movable, scratch) == count
        got = [tuple(p) for p in scratch.pairs[:count]]
        overlap = np.all((lo[:, None] <= hi[None]) & (lo[None] <= hi[:, None]), axis=2)
        expected = {
            (i, j)
            for i in range(300)
            for j in range(i + 1, 300)
            if overlap[i, j] and (movable[i] or movable[j])
        }
        assert len(got) == len(set(got))
        assert set(got) == expected
    assert len(expected) > 8 * 300  # the dense set outgrew the first pair buffer


def test_mass_properties_against_trimesh():
    for shape, mesh in [
        (Box((0.1, 0.2, 0.3)), trimesh.creation.box(extents=(0.2, 0.4, 0.6))),
        (Sphere(0.1), trimesh.creation.icosphere(subdivisions=5, radius=0.1)),
        (Capsule(0.05, 0.1), trimesh.creation.capsule(height=0.2, radius=0.05, count=[64, 64])),
    ]:
        props = mass_properties(shape, 1000.0)
        ref = np.sort(np.linalg.eigvalsh(mesh.moment_inertia * 1000.0))
        assert props.mass == pytest.approx(1000.0 * mesh.volume, rel=2e-3)
        assert np.allclose(np.sort(props.inertia), ref, rtol=5e-3)
    hull = Convex(trimesh.creation.box(extents=(0.2, 0.4, 0.6)).vertices)
    assert np.allclose(
        np.sort(mass_properties(hull, 1000.0).inertia),
        np.sort(mass_properties(Box((0.1, 0.2, 0.3)), 1000.0).inertia),
    )


def test_bad_input_is_named():
    with pytest.raises(JassyError, match="restitution"):
        Material("x", 1000, 1.5, 0.3)
    with pytest.raises(JassyError, match="cannot be dynamic"):
        Body("p", Plane(), Material("x", 1000, 0.5, 0.3))
    with pytest.raises(JassyError, match="integrator"):
        StepParams(integrator="euler").options()
    with pytest.raises(JassyError, match="Sphere.radius"):
        Sphere(-1.0)
    with pytest.raises(JassyError, match="duration"):
        simulate(_ball_world(0.5), -1.0)


def test_kinematic_lift_carries_a_resting_ball_and_a_bad_path_is_named():
    """A kinematic slab rising at 0.2 m/s under a resting ball: the ball rides on it (speed
    0.2 m/s, centre one radius above the slab's top). A path that is not vectorised over
    times is refused with the body's name."""
    speed, r = 0.2, 0.05

    def lift(t):
        t = np.asarray(t, float)
        pos = np.zeros((t.size, 3))
        pos[:, 2] = speed * t
        quat = np.zeros((t.size, 4))
        quat[:, 0] = 1.0
        return pos, quat

    w = World(StepParams(h=1e-3, iterations=40))
    w.add(Body("lift", Box((0.5, 0.5, 0.05)), Material("m", 1000, 0.0, 0.5), kind="kinematic", path=lift))
    w.add(Body("ball", Sphere(r), Material("m", 1000, 0.0, 0.5)), Placement(position=(0, 0, 0.05 + r)))
    result = simulate(w, 0.5)
    assert result.state.phi[1, 5] == pytest.approx(speed, rel=1e-3)
    assert result.state.pos[1, 2] == pytest.approx(0.05 + r + speed * 0.5, abs=1e-4)

    bad = World(StepParams())
    bad.add(
        Body(
            "lift",
            Box((0.5, 0.5, 0.05)),
            Material("m", 1000, 0.0, 0.5),
            kind="kinematic",
            path=lambda t: (np.zeros(3), np.array([1.0, 0, 0, 0])),
        )
    )
    with pytest.raises(JassyError, match="'lift'.path"):
        simulate(bad, 0.01)


def test_a_ball_passing_behind_an_open_mesh_beyond_its_depth_is_not_caught():
    """A ball sliding fast 17 mm behind an open plate (r + depth = 15 mm) passes untouched,
    whatever the detection margin its speed gives (straight-line motion, no contact)."""
    plate = trimesh.Trimesh(
        np.array([[-1, -1, 0], [1, -1, 0], [1, 1, 0], [-1, 1, 0]], float), np.array([[0, 1, 2], [0, 2, 3]])
    )
    w = World(StepParams(h=1e-3, gravity=(0, 0, 0)))
    w.add(Body("plate", TriangleMesh(plate, depth=0.005), Material("m", 1000, 0.5, 0.3), kind="static"))
    place = Placement(position=(-0.5, 0, -0.017), velocity=(5.0, 0, 0))
    w.add(Body("ball", Sphere(0.01), Material("m", 1000, 0.5, 0.3)), place)
    result = simulate(w, 0.02)
    assert len(result.records) == 0
    assert np.allclose(result.state.pos[1], [-0.4, 0.0, -0.017], atol=1e-12)


def test_an_impact_late_in_a_step_does_not_launch_the_resting_body_it_hits():
    """A ball strikes a box resting on the ground (no gravity) at 0.999 of a step: the impact
    sub-step must not carry its impulse into the next step's warm start as a force. The ball
    rebounds at e v (the ground holds the box), and the box stays put."""
    e, v, h = 0.6, 3.0, 1e-3
    mat = Material("m", 7800, e, 0.3)
    w = World(StepParams(h=h, gravity=(0, 0, 0), iterations=5, tolerance=1e-3))
    w.add(Body("ground", Plane((0, 0, 1), 0.0), mat, kind="static"))
    w.add(Body("box", Box((0.05, 0.05, 0.05)), mat), Placement(position=(0, 0, 0.05)))
    w.add(
        Body("ball", Sphere(0.02), mat),
        Placement(position=(0.01, 0.02, 0.12 + v * 20.999 * h), velocity=(0, 0, -v)),
    )
    result = simulate(w, 0.06, sample_every=1)
    assert result.stats["impact_substeps"] >= 1
    assert result.state.phi[2, 3:] @ result.state.phi[2, 3:] == pytest.approx((e * v) ** 2, rel=0.03)
    assert np.max(np.abs(result.pos[:, 1, 2] - 0.05)) < 2e-4


def test_a_short_impact_sub_step_does_not_turn_a_penetration_into_a_launch():
    """A ball pressed 1 mm into the ground (no gravity) is pushed out at beta * depth / h, the
    outer step's recovery speed, also when another ball's impact at 0.999 of the step leaves a
    sub-step of h / 1000 (recovering the depth within that sub-step would launch it at 160 m/s)."""
    h, beta, depth, v = 1e-3, 0.2, 1e-3, 3.0
    mat = Material("m", 7800, 0.5, 0.3)
    w = World(StepParams(h=h, gravity=(0, 0, 0), beta=beta))
    w.add(Body("ground", Plane((0, 0, 1), 0.0), mat, kind="static"))
    w.add(Body("pressed", Sphere(0.02), mat), Placement(position=(0, 0, 0.02 - depth)))
    w.add(
        Body("striker", Sphere(0.02), mat),
        Placement(position=(1, 0, 0.02 + v * 0.999 * h), velocity=(0, 0, -v)),
    )
    result = simulate(w, 0.02, sample_every=1)
    assert result.stats["impact_substeps"] >= 1
    rise = result.phi[:, 1, 5]
    assert rise.max() == pytest.approx(beta * depth / h, rel=0.01)


def test_spin_bound_covers_a_tumbling_body_over_a_step():
    """The detection's speed bound for a free asymmetric body (bounding radius * |L| / I_min)
    covers how far its points move in a step, though |omega| itself changes within it."""
    from physics.rigid.integrate import semi_implicit_step
    from physics.rigid.spatial import rotation_matrices

    inertia = np.array([1.0, 4.0, 4.5]) * 1e-5
    radius, h = 0.04, 1e-3
    rng = np.random.default_rng(11)
    bound = np.array([radius])
    kind = np.array([codes.DYNAMIC])
    for _ in range(200):
        phi = np.r_[rng.normal(size=3) * 50.0, 0.0, 0.0, 0.0]
        q = rng.normal(size=4)
        q /= np.linalg.norm(q)
        _, q1, _ = semi_implicit_step(np.zeros(3), q, phi, inertia, 1.0, np.zeros(3), np.zeros(6), h)
        points = rng.normal(size=(50, 3))
        points *= radius / np.linalg.norm(points, axis=1, keepdims=True)
        moved = points @ (rotation_matrices(q1[None])[0] - rotation_matrices(q[None])[0]).T
        spin = np.zeros(1)
        st._speeds(
            kind,
            bound,
            inertia[None],
            phi[None],
            rotation_matrices(q[None]),
            np.zeros((1, 3)),
            np.zeros((1, 3)),
            np.zeros((1, 3)),
            spin,
        )
        assert np.max(np.linalg.norm(moved, axis=1)) <= h * spin[0] * (1 + 1e-9)


def _pair_gaps(world, state, margin=0.1):
    """Contacts (points, normals, gaps, pairs) of bodies 0 and 1 of ``world`` at ``state``."""
    from physics.rigid.narrow import narrow_entries, pair_contacts_of
    from physics.rigid.spatial import rotation_matrices

    geo = world.model().geometry
    buf = new_contacts(64, new_mesh_memory(geo.point_start[-1]))
    rot = rotation_matrices(state.quat)
    entries = narrow_entries(state.pos, rot, geo, buf)
    count = pair_contacts_of(0, 1, state.pos, rot, geo, margin, buf, 0, entries)
    return buf.points[:count], buf.normals[:count], buf.gaps[:count], buf.pairs[:count]


@pytest.mark.parametrize("gap", [0.01, 0.002, -0.001])
@pytest.mark.parametrize("twist", [0.0, 0.5])
def test_boxes_crossing_edge_to_edge_get_their_true_distance(gap, twist):
    """Two cubes (half side a) each standing on an edge, the upper one's lowest edge along x,
    the lower one's highest edge turned by ``twist`` from y about z: the edges cross, and the
    distance of the two is the height between them, z_top - 2 sqrt(2) a (closed form). The
    face axes alone see less (the old gap); the edge-edge axis finds it exactly, with one
    contact between the edges, normal vertical."""
    a = 0.05
    w = World(StepParams(h=1e-3))
    s = math.sin(math.pi / 8)
    c = math.cos(math.pi / 8)
    top = (c, s, 0.0, 0.0)  # 45 degrees about x: lowest edge along x
    qy = np.array([c, 0.0, s, 0.0])  # 45 degrees about y: highest edge along y
    qz = np.array([math.cos(twist / 2), 0.0, 0.0, math.sin(twist / 2)])
    w_, x_, y_, z_ = qz
    bottom = (
        w_ * qy[0] - z_ * qy[3],
        w_ * qy[1] - z_ * qy[2],
        w_ * qy[2] + z_ * qy[1],
        w_ * qy[3] + z_ * qy[0],
    )
    z_top = 2 * math.sqrt(2) * a + gap
    w.add(Body("upper", Box((a, a, a)), Material("b", 800, 0, 0.5)), Placement((0.01, -0.005, z_top), top))
    w.add(Body("lower", Box((a, a, a)), Material("b", 800, 0, 0.5)), Placement((0.0, 0.0, 0.0), bottom))
    points, normals, gaps, pairs = _pair_gaps(w, w.initial_state())
    assert len(gaps) == 1
    assert gaps[0] == pytest.approx(gap, abs=1e-12)
    sign = 1.0 if pairs[0, 0] == 0 else -1.0  # the normal points from b to a
    assert np.allclose(sign * normals[0], [0, 0, 1], atol=1e-12)
    # the contact lies midway between the crossing edges, above the lower box's centre line
    assert points[0, 2] == pytest.approx(math.sqrt(2) * a + gap / 2, abs=1e-12)
    assert abs(points[0, 0] * math.cos(twist) + points[0, 1] * math.sin(twist)) < 1e-12
    assert points[0, 1] == pytest.approx(-0.005, abs=1e-12)


def test_boxes_beyond_the_margin_edge_to_edge_have_no_contact():
    """The same crossing 5 cm apart: the face axes see a separation below the 4 cm margin,
    the edge axis the true 5 cm: no contact."""
    a = 0.05
    s, c = math.sin(math.pi / 8), math.cos(math.pi / 8)
    w = World(StepParams(h=1e-3))
    w.add(
        Body("upper", Box((a, a, a)), Material("b", 800, 0, 0.5)),
        Placement((0, 0, 2 * math.sqrt(2) * a + 0.05), (c, s, 0, 0)),
    )
    w.add(Body("lower", Box((a, a, a)), Material("b", 800, 0, 0.5)), Placement((0, 0, 0), (c, 0, s, 0)))
    assert len(_pair_gaps(w, w.initial_state(), margin=0.04)[2]) == 0


def _u_block(w, s, t, h, d):
    """A U-shaped block (closed, concave): outer width 2w (x), slot width 2s, base thickness t,
    height h (z from 0), depth 2d (y); and the three boxes (vertex sets) that make it up."""
    prof = np.array([(-w, 0), (w, 0), (w, t), (w, h), (s, h), (s, t), (-s, t), (-s, h), (-w, h), (-w, t)])
    cap = [(0, 1, 2), (0, 2, 5), (0, 5, 6), (0, 6, 9), (5, 2, 3), (5, 3, 4), (9, 6, 7), (9, 7, 8)]
    verts = np.r_[
        np.c_[prof[:, 0], np.full(10, -d), prof[:, 1]], np.c_[prof[:, 0], np.full(10, d), prof[:, 1]]
    ]
    faces = cap + [(c + 10, b + 10, a + 10) for a, b, c in cap]
    for k in range(10):
        j = (k + 1) % 10
        faces += [(k, j, j + 10), (k, j + 10, k + 10)]
    mesh = trimesh.Trimesh(verts, faces)
    mesh.fix_normals()

    def box(x0, x1, z0, z1):
        return np.array([(x, y, z) for x in (x0, x1) for y in (-d, d) for z in (z0, z1)])

    return mesh, (box(-w, w, 0, t), box(s, w, t, h), box(-w, -s, t, h))


def test_concave_body_rests_in_a_bowl_and_holds_a_ball_in_its_slot():
    """A U-shaped block (a compound of three convex pieces) dropped into an inverted square
    pyramid bowl z = k max(|x|, |y|) comes to rest on the two bottom edges at x = +-w, its
    bottom at z = k w (closed form), level; a ball dropped into its slot rests on the slot's
    floor, z = k w + t + r (its convex hull would hold the ball at the top, z = k w + h + r),
    and the bowl carries the weight of both."""
    from physics.rigid.shapes import Compound

    k, size = 0.5, 0.2
    rim = np.array([(-size, -size), (size, -size), (size, size), (-size, size)])
    verts = np.r_[[[0.0, 0.0, 0.0]], np.c_[rim, np.full(4, k * size)]]
    bowl = trimesh.Trimesh(verts, [(0, 1 + i, 1 + (i + 1) % 4) for i in range(4)], process=False)
    assert np.all(bowl.face_normals[:, 2] > 0)  # facing up, into the bowl
    w_, s_, t_, h_, d_ = 0.03, 0.015, 0.01, 0.04, 0.01
    mesh, pieces = _u_block(w_, s_, t_, h_, d_)
    r = 0.008
    world = World(StepParams(h=1e-3, bounce_threshold=0.05))
    world.add(Body("bowl", TriangleMesh(bowl), Material("g", 1000, 0.0, 0.5), kind="static"))
    u = Compound(mesh, pieces)
    world.add(Body("u", u, Material("wood", 600, 0.0, 0.5)), Placement(position=(0, 0, k * w_ + 1e-3)))
    world.add(
        Body("ball", Sphere(r), Material("steel", 7800, 0.0, 0.5)),
        Placement(position=(0, 0, k * w_ + t_ + r + 0.01)),
    )
    result = simulate(world, 0.6, sample_every=10)
    com = mass_properties(u, 600).com
    rest_u = k * w_ + com[2]
    assert np.max(np.abs(result.pos[-10:, 1] - [0, 0, rest_u])) < 2e-5
    assert np.max(np.abs(result.pos[-10:, 2] - [0, 0, k * w_ + t_ + r])) < 2e-5
    times, force, _ = contact_wrench(result, 0)
    weight = (mass_properties(u, 600).mass + 7800 * 4 / 3 * math.pi * r**3) * G
    assert np.mean(force[times > 0.4, 2]) == pytest.approx(-weight, rel=1e-3)


def test_convex_decomposition_covers_a_concave_mesh():
    """CoACD's pieces of the U-block: their hulls' volumes sum to the block's within 5 %, and
    no hull holds the middle of the slot (the block's convex hull would)."""
    pytest.importorskip("coacd", reason="convex decomposition needs the 'concave' extra (CoACD)")
    from physics.rigid.shapes import Compound

    mesh, _ = _u_block(0.03, 0.015, 0.01, 0.04, 0.01)
    u = Compound(mesh)
    assert sum(h.volume for h in u.hulls) == pytest.approx(mesh.volume, rel=0.05)
    slot = np.array([0.0, 0.0, 0.03])

    def inside(hull):  # behind every face plane of a convex hull
        return bool(np.all(np.einsum("ij,ij->i", hull.face_normals, slot - hull.triangles[:, 0]) < 0))

    assert inside(mesh.convex_hull)
    assert not any(inside(h) for h in u.hulls)


def test_concave_body_rests_on_another_crosswise():
    """Two U-blocks (compounds): the lower one on the floor, the upper one turned a quarter
    turn about z and dropped from 1 mm onto the lower one's prongs: it comes to rest with its
    bottom at the prongs' height h, level (compound against compound goes piece by piece)."""
    from physics.rigid.shapes import Compound

    w_, s_, t_, h_, d_ = 0.03, 0.015, 0.01, 0.04, 0.025
    mesh, pieces = _u_block(w_, s_, t_, h_, d_)
    world = World(StepParams(h=1e-3, bounce_threshold=0.05))
    world.add(Body("floor", Plane(), Material("g", 1000, 0.0, 0.5), kind="static"))
    u = Compound(mesh, pieces)
    world.add(Body("lower", u, Material("wood", 600, 0.0, 0.5)), Placement(position=(0, 0, 0)))
    quarter = (math.cos(math.pi / 4), 0.0, 0.0, math.sin(math.pi / 4))
    world.add(
        Body("upper", u, Material("wood", 600, 0.0, 0.5)),
        Placement(position=(0, 0, h_ + 1e-3), quaternion=quarter),
    )
    result = simulate(world, 0.4, sample_every=10)
    com = mass_properties(u, 600).com
    assert np.max(np.abs(result.pos[-10:, 1] - [0, 0, com[2]])) < 2e-5
    rest = np.array([-com[1], com[0], h_ + com[2]])  # the com turned a quarter about z
    assert np.max(np.abs(result.pos[-10:, 2] - rest)) < 2e-5


def _run_data(world, opt, rec, steps=1, warm_contacts=st.MAX_CONTACTS):
    """Data for ``steps`` steps of ``world`` from its initial state, as simulate builds it:
    no kinematic bodies, the record buffer ``rec``, fresh statistics, no pose samples, an empty
    warm start for ``warm_contacts`` contacts."""
    state = world.initial_state()
    return st.new_data(
        world.model(),
        opt,
        state.pos,
        state.quat,
        state.phi,
        np.zeros((steps + 1, 0, 3)),
        np.zeros((steps + 1, 0, 4)),
        rec,
        st.new_stats(),
        np.zeros((0, len(world.bodies), 13)),
        1,
        0,
        new_warm_start(warm_contacts),
    )


def _drop(places, tiny_scratch, steps=600):
    """Balls (r = 2 cm, e = 0.5) dropped from ``places`` ((x, z) of their centres, m) on a
    floor for ``steps`` steps of 1 ms: (final state arrays, records); with ``tiny_scratch`` the
    run starts with room for one pair and one contact, so the scratch grows as the balls land
    (stepper.run)."""
    w = World(StepParams(h=1e-3, bounce_threshold=0.05))
    w.add(Body("ground", Plane(), Material("g", 1000, 0.5, 0.3), kind="static"))
    for k, (x, z) in enumerate(places):
        w.add(Body(f"ball{k}", Sphere(0.02), Material("b", 1000, 0.5, 0.3)), Placement(position=(x, 0, z)))
    model, opt, n = w.model(), w.params.options(), len(w.bodies)
    data = _run_data(w, opt, np.empty((1 << 14, codes.REC_WIDTH)), steps)
    if tiny_scratch:
        data = data._replace(
            sweep=data.sweep._replace(pairs=np.empty((1, 2), np.int64)),
            near=st.new_pair_scratch(1),
            solver=new_solver(np.int64(1), n, st.MAX_CONTACTS),
        )
    data, done, nrec = st.run(model, opt, data, 0, steps, 0)
    assert done == steps
    return (data.pos, data.quat, data.phi), data.rec[:nrec]


def _fall_height(t, g=9.81, r=0.02):
    """Centre height (m) from which a ball of radius r at rest touches the floor after t s."""
    return r + 0.5 * g * t * t


_LANDING = _fall_height(0.1005)  # lands half way through step 100


@pytest.mark.parametrize(
    "places",
    [
        [(0.06 * k, 0.03 + 0.02 * k) for k in range(6)],  # landings in different steps
        [(0.0, _LANDING), (0.0, _LANDING + 0.04005)],  # a ball 50 um above: hit by the rebound
    ],
    ids=["staggered", "stacked"],
)
def test_a_step_stopped_for_more_scratch_resumes_where_it_stopped(monkeypatch, places):
    """A sweep or narrow phase that outgrows the scratch stops the step; grown, the run goes on
    from there: the same motion and records, bit for bit, as a run that had room from the
    start. Two balls falling together, 50 um apart, have one contact (the floor's) when the
    step starts; the lower one's rebound at its impact sub-step closes the gap within the step:
    a second contact, and a stop inside the step after that sub-step."""
    stops = []
    grown = st._grown

    def spy(d, opt, steps, nrec):
        stops.append((tuple(d.progress.need), float(d.progress.t_local[0]), int(d.progress.subs[0])))
        return grown(d, opt, steps, nrec)

    monkeypatch.setattr(st, "_grown", spy)
    state, records = _drop(places, False)
    assert not stops
    state_tiny, records_tiny = _drop(places, True)
    assert any(need[0] for need, _, _ in stops) and any(need[1] for need, _, _ in stops)
    if len(places) == 2:
        assert any(subs > 0 and t_local > 0.0 for _, t_local, subs in stops)
    assert len(records) > 100 * len(places)
    for a, b in zip(state + (records,), state_tiny + (records_tiny,), strict=True):
        assert np.array_equal(a, b)


def test_grown_scratch_makes_room_for_the_rest_of_the_step_or_raises():
    """A step resumed with more contacts than seen before gets a record buffer with room for
    its remaining solves at that count (the rows written kept); scratch that cannot grow past
    the contact buffer is an error, not an endless stop-and-resume."""
    w = World(StepParams(h=1e-3))
    w.add(Body("ground", Plane(), Material("g", 1000, 0.5, 0.3), kind="static"))
    w.add(Body("ball", Sphere(0.02), Material("b", 1000, 0.5, 0.3)), Placement(position=(0, 0, 0.05)))
    opt, n = w.params.options(), len(w.bodies)
    rec = np.arange(100.0 * codes.REC_WIDTH).reshape(100, codes.REC_WIDTH)
    data = _run_data(w, opt, rec)
    contacts = 2 * data.solver.idx.shape[0]
    data.progress.need[:] = (0, contacts)
    grown = st._grown(data, opt, 0, 90)
    assert grown.progress.most[0] == contacts
    assert grown.rec.shape[0] - 90 >= (opt.max_events + 2) * contacts
    assert np.array_equal(grown.rec[:90], rec[:90])
    full = grown.contacts.gaps.shape[0]
    grown = grown._replace(solver=new_solver(np.int64(full), n, st.MAX_CONTACTS))
    grown.progress.need[:] = (0, full + 1)
    with pytest.raises(RuntimeError, match="cannot grow"):
        st._grown(grown, opt, 0, 90)


def test_unknown_contact_model_code_is_an_error():
    """The stepper accepts the contact model codes of StepParams.contact only; any other code
    raises instead of running some model."""
    world = _ball_world(0.5)
    opt = world.params.options()._replace(contact=7)
    data = _run_data(world, opt, np.empty((4096, codes.REC_WIDTH)), warm_contacts=16)
    with pytest.raises(ValueError, match="unknown contact model"):
        st.run(world.model(), opt, data, 0, 1, 0)


def test_unknown_integrator_code_is_an_error():
    """Likewise the integrator codes of StepParams.integrator only (integrate.METHODS): any
    other code raises instead of running RK4's or the adaptive integrator's branch."""
    world = _ball_world(0.5)
    opt = world.params.options()._replace(integrator=7)
    data = _run_data(world, opt, np.empty((4096, codes.REC_WIDTH)), warm_contacts=16)
    with pytest.raises(ValueError, match="unknown integrator code 7"):
        st.run(world.model(), opt, data, 0, 1, 0)


def test_a_run_without_records_matches_the_run_that_keeps_them():
    """keep_records=False writes the records over one reused buffer (here more than once) and
    returns none: the motion and every count are those of the run that keeps them."""
    from physics.rigid.bench import pile

    world, state = pile(10)
    kept = simulate(world, 4.0, state=state, sample_every=0)
    lean = simulate(world, 4.0, state=state, sample_every=0, keep_records=False)
    assert len(kept.records) > 1 << 16  # more than the reused buffer holds
    assert lean.records.shape == (0, codes.REC_WIDTH)
    for name in ("pos", "quat", "phi"):
        assert np.array_equal(getattr(lean.state, name), getattr(kept.state, name))
    assert lean.stats == kept.stats

"""Frictional-contact experiments on rods (each returns a JSON-able dict; ``plot`` = optional PNG path).

* ``snap_fit(kind)``: an open elastic ring (C-shaped shell) pushed onto a rigid cylinder, then pulled
  off (Yoshida & Wada 2020 setting). Our two types (the talk's labels; their mapping to the paper's
  phases is unconfirmed): ring centre-line radius = cylinder radius (0.25 mm interference), opening
  100 deg ("I": the ring wraps 260 deg and must open to pass the equator) or 140 deg ("II": a
  shallower clip, 220 deg).
* ``shell_stack(gamma)``: semicircular shells (arches) dropped on each other onto the ground, with
  gravity number Gamma = rho_A g L^3 / EI (10: they keep their shape; 100: they sag and spread).
* ``archery()``: a bow (two limbs clamped at the grip, naturally curved), its string (a thin
  inextensible rod pinned to the limb tips, braced shorter than the tip distance), an arrow (a
  rigid body with a nock disk and a tip disk): bracing, draw by the hand, release, flight, hit.
* ``bicycle_on_rope()``: a bicycle (two rigid wheels pinned to a rigid frame + rider) ridden by a
  pedalling torque along a sagging rope pinned at both ends.

Simplifications: planar; the string is an inextensible rod (no string stretch); contacts are
inelastic (Moreau); the arrow is rigid and ballistic; rod self-contact is ignored.
"""

from __future__ import annotations

import math
from dataclasses import dataclass
from typing import NamedTuple

import numpy as np

from jassy.errors import JassyError
from physics.rod.mixed import MixedRod
from physics.rod.model import RodModel
from physics.rod.plotting import save_plot
from physics.rod.system import Anchor, Disk, Joint, Plane, RigidBody, RodSystem, contact_events


def _stats(infos) -> dict:
    res = [i.residual for i in infos if len(i.r)]
    its = [i.iterations for i in infos if len(i.r)]
    return {
        "steps": len(infos),
        "max_contacts": int(max((len(i.r) for i in infos), default=0)),
        "max_residual": float(max(res, default=0.0)),
        "mean_sweeps": float(np.mean(its)) if its else 0.0,
        "max_sweeps": int(max(its, default=0)),
        "steps_residual_over_1e-8": int(sum(r > 1e-8 for r in res)),
    }


def _tip(form, q) -> np.ndarray:
    a = form.arcs(q)
    p, _, _ = form.point_jacobian(q, len(a.x) - 1, float(a.l[-1]))
    return p


def snap_fit(
    kind: str = "I",
    n: int = 20,
    mu: float = 0.3,
    speed: float = 0.1,
    h: float = 2e-4,
    plot: str | None = None,
) -> dict:
    """Push an open ring (polymer strip: EI 1e-4 N m^2, rho_A 3e-3 kg/m, thickness 0.5 mm, centre-line
    radius = cylinder radius 10 mm, so it grips with 0.25 mm interference; opening 100 or 140 deg)
    centred above a rigid cylinder down at ``speed`` (m/s) by its crown until the crown is 0.2 mm
    from touching the cylinder (the driven crown cannot yield: it stops short), then pull
    it back up (velocity ramps of 20 ms at start and reversal). By symmetry only the right half is
    simulated (n elements): its crown end is driven (x = 0, tangent horizontal). Returns the push
    force (N, both halves, + = pushing down) against the crown displacement, the peak assembly and
    removal forces, the force and tip opening at the fit, and solver statistics."""
    if kind not in ("I", "II"):
        raise JassyError(f"kind: expected 'I' or 'II', got {kind!r}")
    rc = rr = 0.01
    opening = math.radians(100.0 if kind == "I" else 140.0)
    yc = rc + rr * math.cos(opening / 2) + 1e-3
    model = RodModel(
        n,
        (math.pi - opening / 2) * rr,
        1e-4,
        3e-3,
        radius=2.5e-4,
        rest_curvature=-1.0 / rr,
        gravity=0.0,
        start=(0.0, yc + rr, 0.0),
        start_bc="free",
        end_bc="free",
        damping=2e-7,
    )
    ring = MixedRod(model)
    sysm = RodSystem([ring], obstacles=[Disk((0.0, 0.0), rc)], mu=mu, margin=5e-4)
    state = sysm.initial_state()
    ramp = 0.02
    disp, force, infos = [], [], []
    for sign in (-1.0, 1.0):
        t = 0.0
        while (state.rods[0].q[1] > rc + model.radius + 2e-4) if sign < 0 else (state.rods[0].q[1] < yc + rr):
            t += h
            state, info = sysm.step(state, h, drives={0: (0.0, sign * speed * min(1.0, t / ramp), 0.0)})
            infos.append(info)
            disp.append(yc + rr - state.rods[0].q[1])
            force.append(2.0 * info.lam[-2] / h)
        if sign < 0:
            half = len(disp)
            tip_gap = 2.0 * _tip(ring, state.rods[0].q)[0]
    disp, force = np.array(disp), np.array(force)
    out = {
        "kind": kind,
        "ring_radius_m": rr,
        "cylinder_radius_m": rc,
        "opening_deg": math.degrees(opening),
        "mu": mu,
        "travel_m": float(yc + rr - rc - model.radius - 2e-4),
        "peak_assembly_force_n": float(np.max(force[:half])),
        "peak_removal_force_n": float(np.max(-force[half:])),
        "force_at_fit_n": float(force[half - 1]),
        "tip_opening_at_fit_m": float(tip_gap),
        "displacement_m": disp[::10].tolist(),
        "force_n": force[::10].tolist(),
        **_stats(infos),
    }
    if plot:
        _plot_xy(
            plot, disp * 1e3, force, "crown displacement (mm)", "push force (N)", f"snap-fit type {kind}"
        )
    return out


def _plot_xy(path, x, y, xl, yl, title):
    def draw(ax):
        ax.plot(x, y)
        ax.set(xlabel=xl, ylabel=yl, title=title)

    save_plot(path, draw, size=(5.0, 3.5), dpi=100)


def shell_stack(
    gamma: float = 10.0,
    shells: int = 4,
    n: int = 12,
    radius: float = 0.1,
    mu: float = 0.3,
    duration: float = 1.0,
    h: float = 1e-3,
    plot: str | None = None,
) -> dict:
    """Drop ``shells`` identical semicircular shells (arches of radius ``radius`` m, length pi R,
    rho_A 0.1 kg/m, thickness 4 mm, EI = rho_A g L^3 / gamma) stacked 1 mm apart onto a
    frictional ground (friction ``mu`` everywhere); simulate ``duration`` s. Returns each shell's
    final apex height over its rest height (1 = undeformed), foot spread over 2R, the stack height,
    contact and solver statistics."""
    if not (gamma > 0 and shells >= 1):
        raise JassyError(f"gamma, shells: expected gamma > 0 and shells >= 1, got {gamma!r}, {shells!r}")
    rho_a, thick = 0.1, 4e-3
    length = math.pi * radius
    ei = rho_a * 9.81 * length**3 / gamma
    d = math.sqrt((radius + thick + 1e-3) ** 2 - radius**2)
    rods = []
    for k in range(shells):
        model = RodModel(
            n,
            length,
            ei,
            rho_a,
            radius=thick / 2,
            rest_curvature=-1.0 / radius,
            start=(-radius, thick / 2 + 1e-3 + k * d, math.pi / 2),
            start_bc="free",
            end_bc="free",
            damping=1e-3 * ei,
        )
        rods.append(MixedRod(model))
    sysm = RodSystem(rods, obstacles=[Plane((0.0, 0.0), (0.0, 1.0))], mu=mu, margin=1e-3)
    state = sysm.initial_state()
    infos = [sysm.step(state, h)[1]]
    for _ in range(int(round(duration / h))):
        prev = state
        state, info = sysm.step(state, h)
        infos.append(info)
    apex, spread = [], []
    for f, st in zip(rods, state.rods, strict=True):
        a = f.arcs(st.q)
        mid, _, _ = (
            f.point_jacobian(st.q, n // 2, 0.0) if n % 2 == 0 else f.point_jacobian(st.q, n // 2, a.l[0] / 2)
        )
        feet = np.array([[a.x[0], a.y[0]], _tip(f, st.q)])
        apex.append(float((mid[1] - feet[:, 1].mean()) / radius))
        spread.append(float(abs(feet[1, 0] - feet[0, 0]) / (2 * radius)))
    top = max(float(np.max(f.arcs(st.q).y)) for f, st in zip(rods, state.rods, strict=True))
    out = {
        "gamma": gamma,
        "shells": shells,
        "EI_n_m2": ei,
        "apex_over_rest": apex,
        "foot_spread_over_2r": spread,
        "stack_height_m": top + thick / 2,
        "final_node_speed_m_s": _node_speed(rods, prev.rods, state.rods, h),
        **_stats(infos),
    }
    if plot:
        _plot_rods(plot, rods, state.rods, f"stack of shells, Gamma = {gamma:g}")
    return out


def _node_speed(forms, before, after, h) -> float:
    """Largest element-start speed (m/s) between two rod states h apart."""
    out = 0.0
    for f, a, b in zip(forms, before, after, strict=True):
        p, q = f.arcs(a.q), f.arcs(b.q)
        out = max(out, float(np.max(np.hypot(q.x - p.x, q.y - p.y)) / h))
    return out


def _plot_rods(path, forms, states, title, extra=None):
    from physics.rod import arc

    def draw(ax):
        for f, st in zip(forms, states, strict=True):
            a = f.arcs(st.q)
            s = np.linspace(0, 1, 9)[None, :] * a.l[:, None]
            p = arc.point(a.x[:, None], a.y[:, None], a.theta[:, None], a.kappa[:, None], s).ravel()
            ax.plot(p.real, p.imag, lw=2)
        if extra:
            extra(ax)
        ax.set_aspect("equal")
        ax.set_title(title)

    save_plot(path, draw, size=(6.0, 4.0), dpi=100)


def bicycle_on_rope(
    duration: float = 3.0,
    torque: float = 40.0,
    span: float = 4.0,
    slack: float = 0.04,
    n: int = 40,
    mu: float = 0.8,
    h: float = 2e-3,
    plot: str | None = None,
) -> dict:
    """A bicycle on a rope: rope (length span + slack m, EI 20 N m^2, rho_A 0.5 kg/m, radius 1 cm) pinned
    at (0, 0) and (span, 0), starting as a circular sag; wheels: rigid disks R 0.35 m, 2 kg, pinned
    1 m apart to a rigid frame + rider (70 kg, 11 kg m^2, centre 0.6 m above the hubs); the rear
    wheel is driven by a pedalling ``torque`` (N m), wheels on the rope with friction ``mu``; stops
    when the front wheel reaches the far anchor (crossed) or after ``duration`` s. Returns the
    bicycle's path (frame centre), peak speed, rope sag, contact slip and solver stats."""
    from scipy.optimize import brentq

    from physics.rod import arc

    if not (slack > 0 and span > 0 and duration > 0):
        raise JassyError("span, slack, duration: expected positive numbers")
    length = span + slack
    kappa = brentq(lambda k: length * np.sinc(k * length / 2 / np.pi) - span, 1e-9, 2 * np.pi / length - 1e-9)
    model = RodModel(
        n,
        length,
        20.0,
        0.5,
        radius=0.01,
        rest_curvature=0.0,
        start=(0.0, 0.0, -kappa * length / 2),
        start_bc="pinned",
        end_bc="pinned",
        end=(span, 0.0, kappa * length / 2),
        damping=0.5,
    )
    rope = MixedRod(model)
    rope_state = rope.initial_state(kappa=np.full(n, kappa))
    a = rope.arcs(rope_state.q)
    s = np.linspace(0, 1, 17)[None, :] * a.l[:, None]
    pts = arc.point(a.x[:, None], a.y[:, None], a.theta[:, None], a.kappa[:, None], s).ravel()
    R, lift = 0.35, 0.35 + 0.01 + 2e-3

    def centre(x):
        return np.array([x, np.interp(x, pts.real, pts.imag) + lift])

    rear = centre(0.6)
    front = centre(brentq(lambda x: np.linalg.norm(centre(x) - rear) - 1.0, 0.7, 2.5))
    phi = math.atan2(front[1] - rear[1], front[0] - rear[0])
    up = np.array([-math.sin(phi), math.cos(phi)])
    frame_c = 0.5 * (rear + front) + 0.6 * up
    wheel = RigidBody(2.0, 0.8 * 2.0 * R * R, ((0.0, 0.0, R),))
    frame = RigidBody(70.0, 11.0, disks=())
    joints = [
        Joint(Anchor(1), Anchor(3, offset=(-0.5, -0.6))),
        Joint(Anchor(2), Anchor(3, offset=(0.5, -0.6))),
    ]
    sysm = RodSystem([rope], [wheel, wheel, frame], [], joints, mu=mu, margin=5e-3)
    state = sysm.initial_state([rope_state], poses=[[*rear, 0.0], [*front, 0.0], [*frame_c, phi]])
    infos, path, speed = [], [], []
    for _ in range(int(round(duration / h))):
        state, info = sysm.step(state, h, forces={1: (0.0, 0.0, -torque)})
        infos.append(info)
        path.append(state.q[2, :2].copy())
        speed.append(float(np.hypot(*state.v[2, :2])))
        if state.q[1, 0] >= span - R - 0.2:  # front wheel at the far anchor: crossed
            break
    path = np.array(path)
    a = rope.arcs(state.rods[0].q)
    active = [(i.u[:, 1], i.r[:, 0]) for i in infos if len(i.r)]
    slip = max((float(np.max(np.abs(u[r > 0]), initial=0.0)) for u, r in active), default=0.0)
    impacts, _ = contact_events(infos)
    out = {
        "crossed": bool(state.q[1, 0] >= span - R - 0.2),
        "time_s": float(state.time),
        "torque_n_m": torque,
        "start_x_m": float(path[0, 0]),
        "end_x_m": float(path[-1, 0]),
        "min_frame_y_m": float(path[:, 1].min()),
        "peak_speed_m_s": float(max(speed)),
        "final_rope_sag_m": float(-np.min(a.y)),
        "max_contact_slip_m_s": slip,
        "impacts": len(impacts),
        "path_x_m": path[::25, 0].tolist(),
        "path_y_m": path[::25, 1].tolist(),
        **_stats(infos),
    }
    if plot:

        def bike(ax):
            for k in (0, 1):
                ax.add_patch(__import__("matplotlib.patches").patches.Circle(state.q[k, :2], R, fill=False))
            ax.plot(path[:, 0], path[:, 1], "k:", lw=1)

        _plot_rods(plot, [rope], state.rods, f"bicycle on a rope, t = {state.time:.2f} s", bike)
    return out


@dataclass(frozen=True)
class ArcheryResult:
    """Archery run: summary dict, the bow limb formulation and its braced state, the string's
    formulation, events (impacts, tracks), arrow path (time s, x, y, speed), the string's force on
    the hand during draw and hold (time s, fx, fy N; 1 kHz) and key times (s)."""

    summary: dict
    limb: object
    limb_state: object
    string: object
    impacts: list
    tracks: list
    arrow: np.ndarray
    hand: np.ndarray
    release_time: float
    hit_time: float | None


def archery(draw: float = 0.4, limb_ei: float = 30.0, target: float = 3.0, plot: str | None = None) -> dict:
    """Bow, string and arrow (see ``run_archery``): the JSON-able summary."""
    return run_archery(draw, limb_ei, target, plot).summary


_NOCK_RADIUS = 4e-3  # m, the arrow's nock disk
_BOW_IGNORES = [(0, 2), (1, 2), (0, 1)]  # limbs-string and limb-limb pairs do not collide
_PARKED = (0.0, 0.0, 0.0)  # a rigid body's drive velocity (vx, vy, omega) that holds it


class _Bow(NamedTuple):
    """The archery scene's parts: two limbs (rods 0, 1), the string (rod 2, ``nodes`` elements,
    ``length`` m), the arrow (body 3) and the hand (body 4), the string-to-tip joints and the
    target plane."""

    upper: MixedRod
    lower: MixedRod
    string: MixedRod
    nodes: int
    length: float
    arrow: RigidBody
    hand: RigidBody
    tips: list
    wall: Plane

    def system(self, joints: list) -> RodSystem:
        """The bow's rods and bodies held by ``joints`` (frictionless contact)."""
        rods = [self.upper, self.lower, self.string]
        return RodSystem(
            rods, [self.arrow, self.hand], [self.wall], joints, mu=0.0, margin=2e-3, ignore=_BOW_IGNORES
        )


def _build_bow(limb_ei: float, target: float) -> _Bow:
    """The bow of ``run_archery`` before bracing: limbs clamped at the grip, the string's upper
    end pinned to the upper tip and its lower end pulled toward the lower tip."""
    grip, lb, k0 = 0.08, 0.65, 0.4
    upper = MixedRod(
        RodModel(
            8,
            lb,
            limb_ei,
            0.15,
            radius=0.01,
            rest_curvature=k0,
            gravity=0.0,
            start=(0.0, grip, math.pi / 2),
            damping=2e-3 * limb_ei,
        )
    )
    lower = MixedRod(
        RodModel(
            8,
            lb,
            limb_ei,
            0.15,
            radius=0.01,
            rest_curvature=-k0,
            gravity=0.0,
            start=(0.0, -grip, -math.pi / 2),
            damping=2e-3 * limb_ei,
        )
    )
    tip = _tip(upper, upper.initial_state().q)
    ls = 0.97 * 2 * tip[1]
    ns = 16
    string = MixedRod(
        RodModel(
            ns,
            ls,
            1e-3,
            2e-3,
            radius=1.5e-3,
            gravity=0.0,
            start=(tip[0], tip[1], -math.pi / 2),
            start_bc="free",
            end_bc="free",
            damping=1e-4,
        )
    )
    arrow = RigidBody(0.025, 0.025 * 0.75**2 / 12, ((-0.375, 0.0, _NOCK_RADIUS), (0.375, 0.0, 3e-3)))
    hand = RigidBody(0.1, 1e-3, disks=(), gravity=0.0)
    tips = [
        Joint(Anchor(2, 0, 0.0), Anchor(0, 7, lb / 8)),
        Joint(Anchor(2, ns - 1, ls / ns), Anchor(1, 7, lb / 8), rate=0.02),
    ]
    wall = Plane((target, 0.0), (-1.0, 0.0))
    return _Bow(upper, lower, string, ns, ls, arrow, hand, tips, wall)


def _brace(bow: _Bow, h: float):
    """Bracing and settling (0.3 s at step ``h``) with the arrow and hand parked aside; then the
    arrow's nock is set on the string's middle and the hand on it. Returns (state, string
    tension N)."""
    brace = bow.system(bow.tips)
    state = brace.initial_state(poses=[[1.0, 5.0, 0.0], [0.0, 5.0, 0.0]])  # arrow and hand parked aside
    park = {3: _PARKED, 4: _PARKED}
    for _ in range(300):
        state, info = brace.step(state, h, drives=park)
    tension = float(np.hypot(*info.lam[-8:-6]) / h)  # lower tip joint impulse (rows before the 6 drive rows)
    p_mid, _, _ = bow.string.point_jacobian(state.rods[2].q, bow.nodes // 2, 0.0)
    nock = p_mid + np.array([bow.string.model.radius + _NOCK_RADIUS + 1e-4, 0.0])
    state.q[:] = [[nock[0] + 0.375, nock[1], 0.0], [*p_mid, 0.0]]
    return state, tension


def _draw(bow: _Bow, state, draw: float, h: float, infos: list):
    """Draw by the hand pinned to the string's middle, ``draw`` m at up to 1 m/s, then hold 0.1 s
    (steps' infos appended to ``infos``). Returns (state, draw lengths m, draw forces N, hand
    forces [t, fx, fy] per step, the held draw force N)."""
    draw_sys = bow.system([*bow.tips, Joint(Anchor(2, bow.nodes // 2, 0.0), Anchor(4))])
    draw_x, draw_f, hand_f = [], [], []
    t, x0 = 0.0, state.q[1, 0]
    while x0 - state.q[1, 0] < draw:
        t += h
        v = -min(1.0, t / 0.05, 0.05 + 10.0 * (draw - (x0 - state.q[1, 0])))
        state, info = draw_sys.step(state, h, drives={3: (v, 0.0, 0.0), 4: (v, 0.0, 0.0)})
        draw_x.append(x0 - state.q[1, 0])
        draw_f.append(info.lam[-3] / h)  # x impulse of the hand drive (its rows are last)
        infos.append(info)
        hand_f.append([state.time, info.lam[-3] / h, info.lam[-2] / h])
    for _ in range(100):
        state, info = draw_sys.step(state, h, drives={3: _PARKED, 4: _PARKED})
        infos.append(info)
        hand_f.append([state.time, info.lam[-3] / h, info.lam[-2] / h])
    return state, draw_x, draw_f, hand_f, float(info.lam[-3] / h)


def _release(bow: _Bow, state, infos: list):
    """Release (h = 0.1 ms for 40 ms, then 0.5 ms) until 0.25 s or 20 ms after the arrow hits
    the target (steps' infos appended to ``infos``). Returns (state, path rows [t, x, y, speed],
    the time the arrow left the string or None, the hit time or None)."""
    release = bow.system(bow.tips)
    t_rel = state.time
    path, hit, left = [], None, None
    while state.time < t_rel + 0.25 and (hit is None or state.time < hit + 0.02):
        h = 1e-4 if state.time < t_rel + 0.04 else 5e-4
        state, info = release.step(state, h, drives={4: _PARKED})
        infos.append(info)
        path.append([state.time, *state.q[0, :2], float(np.hypot(*state.v[0, :2]))])
        pairs = {tuple(sorted(map(int, b))) for b, r in zip(info.bodies, info.r, strict=True) if r[0] > 0}
        if left is None and state.time > t_rel + 1e-3 and (2, 3) not in pairs:
            left = state.time
        if hit is None and (3, 5) in pairs:
            hit = state.time
    return state, np.array(path), left, hit


def run_archery(draw: float = 0.4, limb_ei: float = 30.0, target: float = 3.0, plot: str | None = None):
    """A bow: two limbs (0.65 m, EI ``limb_ei`` N m^2, rho_A 0.15 kg/m, natural curvature 0.4 1/m
    toward the archer) clamped at a 16 cm grip; a string (thin inextensible rod: EI 1e-3 N m^2,
    rho_A 2e-3 kg/m, 3 % shorter than the tip distance) pinned to the tips; an arrow (rigid, 25 g,
    0.75 m, a nock disk and a tip disk). Phases: bracing (the string's lower end is pulled onto the
    lower tip, 2 % of the gap per step) and settling, 0.3 s; draw by a hand pinned to the string's
    middle, ``draw`` m at up to 1 m/s with the arrow driven along; hold 0.1 s; release (h = 0.1 ms
    for 40 ms, then 0.5 ms): the string pushes the nock (frictionless contact) until the arrow leaves;
    flight to a target plane at x = ``target`` m. Gravity acts on the arrow only."""
    if not (0.05 <= draw <= 0.6 and limb_ei > 0 and target > 1.0):
        raise JassyError(
            f"draw, limb_ei, target: expected 0.05..0.6 m, > 0, > 1 m; got {draw}, {limb_ei}, {target}"
        )
    bow = _build_bow(limb_ei, target)
    state, tension = _brace(bow, 1e-3)
    infos = []
    state, draw_x, draw_f, hand_f, draw_force = _draw(bow, state, draw, 1e-3, infos)
    t_rel = state.time
    state, path, left, hit = _release(bow, state, infos)
    impacts, tracks = contact_events(infos)
    speed_left = float(np.interp(left, path[:, 0], path[:, 3])) if left else 0.0
    stored = float(np.trapezoid(draw_f, draw_x))
    summary = {
        "brace_tension_n": tension,
        "string_length_m": float(bow.length),
        "draw_m": draw,
        "draw_force_n": draw_force,
        "stored_energy_j": stored,
        "arrow_speed_m_s": speed_left,
        "efficiency": 0.5 * bow.arrow.mass * speed_left**2 / stored if stored > 0 else 0.0,
        "power_stroke_ms": (left - t_rel) * 1e3 if left else None,
        "hit_time_s": hit - t_rel if hit else None,
        "impacts": len(impacts),
        **_stats(infos),
    }
    if plot:
        _plot_xy(
            plot, np.array(draw_x) * 100, np.array(draw_f), "draw (cm)", "draw force (N)", "bow draw curve"
        )
    return ArcheryResult(
        summary, bow.upper, state.rods[0], bow.string, impacts, tracks, path, np.array(hand_f), t_rel, hit
    )

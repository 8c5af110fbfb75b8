"""The rigid-world time step (numba): free motion, contacts, impact times inside the step.

The step works on three records, after MuJoCo's: the world's static :class:`Model` and step
:class:`Options` (physics.rigid.model) and the run's :class:`Data` (state, kinematic paths,
records, statistics and scratch); each stage is a function ``stage(m, opt, d, ...)``. One
outer step of h seconds (:func:`outer_step`) is:

1. kinematic_stage: kinematic bodies to their path's pose, with its velocity;
2. broad_stage: bounding boxes grown by how far each body can move, sweep and prune;
3. narrow_stage: contacts of the pairs within slop plus how far each pair can close in the
   step (narrow.pair_contacts_by_ref);
4. contact_stage: contacts touching (gap <= slop) resolved by the contact model, impulse
   (impulses.resolve: projected Gauss-Seidel with Newton restitution, Coulomb friction,
   rolling resistance, penetration recovery and a warm start) or a penalty force
   (physics.rigid.penalty); an unknown model code is an error (step_models);
5. advance_stage: every body moves freely to the end of the step (integrate.advance_body_into).
   With the default integrator a body in flight follows the exact ballistic path (so impact
   times and speeds of a bouncing body are those of the closed form); a body held by a resting
   contact of the solve (a recorded non-impact contact) drifts with its new velocity instead,
   the solve having folded the step's gravity increment into it, and so stays put at rest;
6. impact_stage: a pair that was apart at the start (slop < gap <= how far the two can close in
   the step, from their relative velocity and spins) and penetrates at the end, having closed
   faster than ``bounce_threshold`` on average, has hit inside the step: its time of impact is
   the root of its gap along the free motion (Illinois regula falsi to 1e-12 s), and the whole
   world moves to the earliest such time and goes back to 2. At most ``max_events`` such
   sub-steps per step; later impacts are resolved at the step end.

The contact model and the free motion's integrator are picked by the types of two arguments
of run_steps (:func:`step_models`, chosen from Options in Python; overloads resolved when
the stages are typed), not by branches inside them, so a run compiles only its own model and
integrator (the wok's first compile no longer builds the penalty models, RK4 and the
adaptive integrator).

The large stages (broad, narrow, contact, advance, impact) are called apart
(jassy.unlinked.call_apart), through entry points run_steps gets as its argument
``entries`` (:func:`step_entries`), not linked into it: numba links every kernel a kernel
calls into the caller's module and LLVM optimises and generates code for that whole tree
again at each level, so run_steps used to compile the whole step a second time (~10 s of
the wok's first compile, on one core, after everything below it). Each stage now compiles
once, and the stages and run_steps can compile side by side (physics.rigid.step_units). The
stages get Model and Data by reference (physics.rigid.record_ref: one pointer each, made
once per run_steps call) and read the fields they use into locals once per call, so a call
passes a few pointers and scalars, once per (sub-)step. The narrow phase itself
(narrow.pair_contacts, StepEntries.pair) is called apart per pair by the narrow and
impact stages, with the Geometry and the contact buffers by reference (pointers into m and
d, record_ref.field_ref), and its larger methods apart from it (narrow.NarrowEntries), so
each compiles once, not once more in each caller. Inside a
stage the smaller helpers are inlined (numba inline="always"), and so are the narrow
stage's pair loop, the impact-time search and its gap probe.

The whole step allocates nothing and run_steps and the stages are compiled without
reference counting (``_nrt=False``, passed on to every kernel they call that sets
no flag of its own): with it, every use of Model or Data counted a reference up and down for
each array they hold. Its scratch (contact solve, sweep, pair bounds, the gap probe's saved
poses) lives in Data; a sweep that finds more pairs, or a narrow phase more contacts, than
the scratch holds stops the run inside its step (Data.progress says where and how much is
needed), and :func:`run` grows the scratch and resumes the step there. Only the RK4 and
adaptive integrators allocate (integrate.advance_body_into keeps reference counting for
itself).

Each resolved contact appends a record row (columns ``codes.RECORD_FIELDS``): time, step,
bodies, world point, impulse on a (N s, world), approach speed, slip and rolling speed after
the solve, impact flag, features, barycentric weights on b, the contact point in each body's
frame, and the normal.
"""

from __future__ import annotations

import math
from typing import NamedTuple

import numba as nb
import numpy as np
from numba.extending import overload

from jassy import unlinked
from jassy.jit import _type_key, drop_stale_cache
from jassy.unlinked import Entry, call_apart, entries_of, entry, unset
from physics.rigid import (
    broad,
    codes,
    impulses,
    integrate,
    meshgrid,
    narrow,
    record_ref,
    shapes,
    spatial,
)
from physics.rigid import (
    penalty as penalty_model,
)
from physics.rigid.broad import Sweep, new_sweep, sweep_pairs
from physics.rigid.codes import (
    DYNAMIC,
    HUNT_CROSSLEY,
    IMPULSE,
    KINEMATIC,
    LINEAR,
    REC_A,
    REC_B,
    REC_IMPACT,
    REC_WIDTH,
)
from physics.rigid.impulses import SolverScratch, WarmStart, new_solver, resolve
from physics.rigid.integrate import SEMI_IMPLICIT, FreeBody, advance_body_into, semi_implicit_into
from physics.rigid.model import Model, Options
from physics.rigid.narrow import (
    Contacts,
    NarrowEntries,
    narrow_calls,
    new_contacts,
    new_mesh_memory,
)
from physics.rigid.penalty import penalty
from physics.rigid.record_ref import RefExample, deref, field_ref, ref
from physics.rigid.shapes import PLANE, SPHERE

#: numba's cache of this module holds copies of these modules' kernels and constants
#: (``unlinked``: the entry points' types checksums).
drop_stale_cache(
    __file__,
    [
        broad,
        codes,
        impulses,
        integrate,
        meshgrid,
        narrow,
        penalty_model,
        record_ref,
        shapes,
        spatial,
        unlinked,
    ],
)

MAX_CONTACTS = 1 << 16
PROBE_CONTACTS = 256  # contact rows of one pair's gap probe (impact times)


class RunStats(NamedTuple):
    """Counters of a run (each a (1,) int64 array, added to by the stages)."""

    impact_substeps: np.ndarray  # sub-steps taken at impacts inside a step
    late_impacts: np.ndarray  # steps whose impacts outnumbered max_events
    contacts: np.ndarray  # contacts solved
    solves: np.ndarray  # contact solves
    sweeps: np.ndarray  # PGS sweeps
    impact_checks: np.ndarray  # pairs checked for an impact inside the step


def new_stats() -> RunStats:
    return RunStats(*(np.zeros(1, np.int64) for _ in RunStats._fields))


class Data(NamedTuple):
    """A run's state, inputs, outputs and scratch (N bodies, K kinematic bodies)."""

    pos: np.ndarray  # (N, 3) centre-of-mass positions, m
    quat: np.ndarray  # (N, 4) unit quaternions of the principal frames
    phi: np.ndarray  # (N, 6) body-frame twists (rad/s, m/s)
    kin_pos: np.ndarray  # (S + 1, K, 3) kinematic bodies' positions at the run's steps, m
    kin_quat: np.ndarray  # (S + 1, K, 4) their quaternions
    rec: np.ndarray  # (R, codes.REC_WIDTH) contact records
    stats: RunStats
    traj: np.ndarray  # (T, N, 13) sampled poses and twists
    every: int  # sample after every ``every``-th step counted from step ``origin``
    origin: int
    warm: WarmStart  # the last solve's contact forces
    contacts: Contacts  # the step's contacts (MAX_CONTACTS rows)
    probe: Contacts  # one pair's contacts (PROBE_CONTACTS rows), for impact times
    kin_v: np.ndarray  # (N, 3) kinematic bodies' velocities over the step, m/s
    kin_w: np.ndarray  # (N, 3) their angular velocities, rad/s
    rot: np.ndarray  # (N, 3, 3) rotation matrices of quat
    new_pos: np.ndarray  # (N, 3) poses and twists after free motion
    new_quat: np.ndarray  # (N, 4)
    new_phi: np.ndarray  # (N, 6)
    new_rot: np.ndarray  # (N, 3, 3)
    moved_pos: np.ndarray  # (N, 3) poses of a pair moved to a trial time (impact times)
    moved_quat: np.ndarray  # (N, 4)
    moved_phi: np.ndarray  # (N, 6)
    resting: np.ndarray  # (N,) bool: held by a resting contact of the last solve
    vel: np.ndarray  # (N, 3) world velocity of each centre, m/s
    spin: np.ndarray  # (N,) bound on its points' speed about the centre, m/s
    motion: np.ndarray  # (N,) bound on how far any of its points moves in the step, m
    lo: np.ndarray  # (N, 3) bounding box grown by margin and motion, m
    hi: np.ndarray  # (N, 3)
    movable: np.ndarray  # (N,) bool: dynamic
    gravity: np.ndarray  # (3,) m/s^2
    gravity_norm: float  # |gravity|, m/s^2
    no_wrench: np.ndarray  # (6,) the free motion's body wrench: none
    solver: SolverScratch  # the contact solve's scratch (rows: contacts it can hold)
    sweep: Sweep  # the broad phase's scratch (rows: pairs it can hold)
    near: PairScratch  # per broad-phase pair (as many rows as sweep.pairs)
    keep: np.ndarray  # (2, 12) the poses (position, rotation) a gap probe moves and restores
    progress: Progress  # where a step stopped for more scratch, and the most contacts seen


class Progress(NamedTuple):
    """Where run_steps stopped inside an outer step for more scratch (run resumes it there),
    and the most contacts of a (sub-)step so far (each a small array, updated in place)."""

    t_local: np.ndarray  # (1,) time into the step, s
    subs: np.ndarray  # (1,) impact sub-steps taken in it
    need: np.ndarray  # (2,) pairs and contacts the scratch must hold (0, 0: it holds them)
    most: np.ndarray  # (1,) most contacts of a (sub-)step


def new_progress() -> Progress:
    return Progress(np.zeros(1), np.zeros(1, np.int64), np.zeros(2, np.int64), np.full(1, 64, np.int64))


def new_data(
    m: Model, opt: Options, pos, quat, phi, kin_pos, kin_quat, rec, stats, traj, every, origin, warm
):
    """Data of a run from the state arrays (updated in place), the kinematic bodies' path
    samples, the record buffer, statistics, sample buffer and warm start (kept by the caller
    across runs); fresh scratch, and a fresh memory of the body points near meshes."""
    n = pos.shape[0]
    near = new_mesh_memory(int(m.geometry.point_start[-1]))
    sweep = new_sweep(n)
    gravity = np.array([opt.gx, opt.gy, opt.gz])
    return Data(
        pos,
        quat,
        phi,
        kin_pos,
        kin_quat,
        rec,
        stats,
        traj,
        int(every),
        int(origin),
        warm,
        new_contacts(MAX_CONTACTS, near),
        new_contacts(PROBE_CONTACTS, near),
        np.zeros((n, 3)),
        np.zeros((n, 3)),
        np.empty((n, 3, 3)),
        np.empty_like(pos),
        np.empty_like(quat),
        np.empty_like(phi),
        np.empty((n, 3, 3)),
        np.empty_like(pos),
        np.empty_like(quat),
        np.empty_like(phi),
        np.zeros(n, np.bool_),
        np.zeros((n, 3)),
        np.zeros(n),
        np.zeros(n),
        np.empty((n, 3)),
        np.empty((n, 3)),
        np.zeros(n, np.bool_),
        gravity,
        float(np.sqrt(gravity[0] * gravity[0] + gravity[1] * gravity[1] + gravity[2] * gravity[2])),
        np.zeros(6),
        new_solver(np.int64(256), n, warm.keys.shape[0]),
        sweep,
        new_pair_scratch(sweep.pairs.shape[0]),
        np.empty((2, 12)),
        new_progress(),
    )


def _grown(d: Data, opt: Options, steps: int, nrec: int) -> Data:
    """d with scratch for the pairs and contacts d.progress.need asks for (twice as many, the
    contacts at most the contact buffer's rows) and a record buffer with room for the rest of
    the step at the most contacts seen (its first nrec rows kept), resuming at its step
    ``steps`` (the kinematic samples start there). Raises when the scratch cannot grow."""
    pairs, contacts = (int(x) for x in d.progress.need)
    sweep, near, solver, rec = d.sweep, d.near, d.solver, d.rec
    grew = False
    if pairs > min(sweep.pairs.shape[0], near.reach.shape[0]):
        sweep = sweep._replace(pairs=np.empty((2 * pairs, 2), np.int64))
        near = new_pair_scratch(2 * pairs)
        grew = True
    if contacts > solver.idx.shape[0]:
        rows = min(2 * contacts, d.contacts.gaps.shape[0])
        grew = grew or rows > solver.idx.shape[0]
        solver = new_solver(np.int64(rows), d.pos.shape[0], d.warm.keys.shape[0])
    if not grew:
        raise RuntimeError(
            f"run: a step needs scratch for {pairs} pairs, {contacts} contacts; it cannot grow"
        )
    d.progress.most[0] = max(d.progress.most[0], contacts)
    room = record_room(opt, d.progress.most[0])
    if rec.shape[0] - nrec < room:
        rec = grown_records(rec, nrec, nrec + room)
    d.progress.need[:] = 0
    return d._replace(
        kin_pos=d.kin_pos[steps:], kin_quat=d.kin_quat[steps:], rec=rec, sweep=sweep, near=near, solver=solver
    )


def grown_records(rec: np.ndarray, nrec: int, rows: int) -> np.ndarray:
    """A record buffer of at least ``rows`` rows and twice rec's, its first nrec rows rec's
    (the rest left unwritten: the stepper writes whole rows)."""
    grown = np.empty((max(2 * rec.shape[0], rows), REC_WIDTH))
    grown[:nrec] = rec[:nrec]
    return grown


@nb.njit(cache=True, _nrt=False)
def record_room(opt: Options, most) -> int:
    """Records an outer step may write at ``most`` contacts per (sub-)step: one per contact
    in each of its (max_events + 1) solves, with a margin."""
    max_events = opt.max_events if opt.contact == IMPULSE else 0
    return (max_events + 2) * most + 64


def carry_scratch(d: Data, previous: Data) -> Data:
    """d (a fresh run's Data) with the scratch previous grew and the most contacts it saw."""
    return d._replace(
        sweep=previous.sweep, near=previous.near, solver=previous.solver, progress=previous.progress
    )


def run(m: Model, opt: Options, d: Data, first: int, n_steps: int, nrec: int) -> tuple[Data, int, int]:
    """run_steps, growing d's scratch (and record buffer) whenever a step asks for more and
    resuming it: (d with the grown scratch and records, steps done, record count); fewer steps
    than n_steps when d.rec may not hold the next step's records (the caller grows it and calls
    again). The kinematic samples of the returned d start at the step it stopped in."""
    contact, motion = step_models(opt)
    entries = step_entries(m, opt, d)
    done = 0
    while True:
        steps, nrec = run_steps(m, opt, d, first + done, n_steps - done, nrec, contact, motion, entries)
        done += steps
        if not d.progress.need.any():
            return d, done, nrec
        d = _grown(d, opt, steps, nrec)


class SolveBodies(NamedTuple):
    """The Model arrays the contact solve reads (a call passes only these)."""

    kind: np.ndarray
    inv_mass: np.ndarray
    inv_inertia: np.ndarray
    restitution: np.ndarray
    friction: np.ndarray
    rolling: np.ndarray


class SolveData(NamedTuple):
    """The Data the contact solve reads and writes (a call passes only these)."""

    contacts: Contacts
    warm: WarmStart
    pos: np.ndarray
    rot: np.ndarray
    phi: np.ndarray
    kin_v: np.ndarray
    kin_w: np.ndarray
    rec: np.ndarray
    stats: RunStats


class PairScratch(NamedTuple):
    """Per broad-phase pair (grown with the pairs): how far its gap can shrink in the step (m),
    a lower bound of its gap (m), and whether it touches (gap <= slop)."""

    reach: np.ndarray
    gap: np.ndarray
    touching: np.ndarray


def new_pair_scratch(size: int) -> PairScratch:
    return PairScratch(np.empty(size), np.empty(size), np.empty(size, np.bool_))


@nb.njit(cache=True, _nrt=False)
def _rotations(quat, rot):
    """The rotation matrices of all the quaternions quat into rot (_rotation)."""
    for i in range(quat.shape[0]):
        _rotation(quat, i, rot)


@nb.njit(cache=True, inline="always")
def _rotation(quat, i, rot):
    """rot[i]: rotation matrix of the unit quaternion quat[i] (spatial.quat_to_mat, in place)."""
    w, x, y, z = quat[i, 0], quat[i, 1], quat[i, 2], quat[i, 3]
    rot[i, 0, 0], rot[i, 0, 1], rot[i, 0, 2] = (
        1 - 2 * (y * y + z * z),
        2 * (x * y - w * z),
        2 * (x * z + w * y),
    )
    rot[i, 1, 0], rot[i, 1, 1], rot[i, 1, 2] = (
        2 * (x * y + w * z),
        1 - 2 * (x * x + z * z),
        2 * (y * z - w * x),
    )
    rot[i, 2, 0], rot[i, 2, 1], rot[i, 2, 2] = (
        2 * (x * z - w * y),
        2 * (y * z + w * x),
        1 - 2 * (x * x + y * y),
    )


@nb.njit(cache=True, _nrt=False)
def _mark_resting(rec, first, last, kind, impulse, resting):
    """resting[i]: dynamic body i has a contact among the records first..last-1 (those of the
    solve just done): a non-impact one under the impulse model (``impulse``: the solve folded
    the step's gravity increment into its velocity), any under a penalty model (the symplectic
    update: positions move with the velocities after the forces)."""
    resting[:] = False
    for r in range(first, last):
        if rec[r, REC_IMPACT] == 0.0 or not impulse:
            for col in (REC_A, REC_B):
                i = int(rec[r, col])
                resting[i] = kind[i] == DYNAMIC


class FreeMotion(NamedTuple):
    """What the free motion of a body reads (from Model, Options and Data), gathered once per
    stage: a call of _move then passes these arrays, not every array of m and d."""

    kind: np.ndarray
    pos: np.ndarray
    quat: np.ndarray
    phi: np.ndarray
    inertia: np.ndarray
    mass: np.ndarray
    gravity: np.ndarray
    no_wrench: np.ndarray
    resting: np.ndarray
    kin_v: np.ndarray
    kin_w: np.ndarray
    method: int
    adaptive_tolerance: float


@nb.njit(cache=True, inline="always")
def _free_motion(m, opt, d):
    return FreeMotion(
        m.kind,
        d.pos,
        d.quat,
        d.phi,
        m.inertia,
        m.mass,
        d.gravity,
        d.no_wrench,
        d.resting,
        d.kin_v,
        d.kin_w,
        opt.integrator,
        opt.adaptive_tolerance,
    )


@nb.njit(cache=True, _nrt=False)
def _move(f, i, tau, out_p, out_q, out_phi):
    """Pose and twist of body i after tau seconds of free motion (``f``: FreeMotion, by the
    integrator f.method: RK4 or adaptive, AnyMotion; the semi-implicit one has
    _move_semi_implicit), into row i of out_p, out_q, out_phi."""
    if f.kind[i] == DYNAMIC:
        body = FreeBody(f.pos[i], f.quat[i], f.phi[i], f.inertia[i], f.mass[i], f.gravity, f.no_wrench)
        advance_body_into(body, tau, f.method, f.adaptive_tolerance, (out_p[i], out_q[i], out_phi[i]))
    else:
        _move_fixed(f, i, tau, out_p, out_q, out_phi)


@nb.njit(cache=True, _nrt=False)
def _move_semi_implicit(f, i, tau, out_p, out_q, out_phi):
    """_move with the semi-implicit integrator (f.method is SEMI_IMPLICIT): the other
    integrators are not compiled into the step."""
    if f.kind[i] == DYNAMIC:
        if tau > 0.0:
            body = FreeBody(f.pos[i], f.quat[i], f.phi[i], f.inertia[i], f.mass[i], f.gravity, f.no_wrench)
            semi_implicit_into(body, tau, (out_p[i], out_q[i], out_phi[i]), not f.resting[i])
        else:  # no time: the state as it is (integrate.advance_body)
            _copy_row(f.pos, i, out_p)
            _copy_row(f.quat, i, out_q)
            _copy_row(f.phi, i, out_phi)
    else:
        _move_fixed(f, i, tau, out_p, out_q, out_phi)


@nb.njit(cache=True, inline="always")
def _copy_row(src, i, dst):
    """dst[i] = src[i], element by element."""
    for x in range(src.shape[1]):
        dst[i, x] = src[i, x]


@nb.njit(cache=True, inline="always")
def _move_fixed(f, i, tau, out_p, out_q, out_phi):
    """_move of a static or kinematic body: its twist kept, a kinematic one moved by it."""
    kind, pos, quat, phi = f.kind, f.pos, f.quat, f.phi
    for x in range(6):
        out_phi[i, x] = phi[i, x]
    for x in range(3):
        out_p[i, x] = pos[i, x] + f.kin_v[i, x] * tau if kind[i] == KINEMATIC else pos[i, x]
    if kind[i] == KINEMATIC:
        _turn(i, tau, quat, f.kin_w, out_q)
    else:
        for x in range(4):
            out_q[i, x] = quat[i, x]


@nb.njit(cache=True, inline="always")
def _turn(i, tau, quat, kin_w, out_q):
    """out_q[i]: quat[i] turned by the angular velocity kin_w[i] (rad/s) for tau seconds,
    exp(tau w) q normalised (spatial.quat_exp, quat_mul in scalars)."""
    r0, r1, r2 = kin_w[i, 0] * tau, kin_w[i, 1] * tau, kin_w[i, 2] * tau
    angle = math.sqrt(r0**2 + r1**2 + r2**2)
    half = 0.5 * angle
    s = math.sin(half) / angle if angle > 1e-4 else 0.5 - angle * angle / 48.0
    a0, a1, a2, a3 = math.cos(half), s * r0, s * r1, s * r2
    b0, b1, b2, b3 = quat[i, 0], quat[i, 1], quat[i, 2], quat[i, 3]
    q0 = a0 * b0 - a1 * b1 - a2 * b2 - a3 * b3
    q1 = a0 * b1 + a1 * b0 + a2 * b3 - a3 * b2
    q2 = a0 * b2 - a1 * b3 + a2 * b0 + a3 * b1
    q3 = a0 * b3 + a1 * b2 - a2 * b1 + a3 * b0
    norm = math.sqrt(q0 * q0 + q1 * q1 + q2 * q2 + q3 * q3)
    out_q[i, 0], out_q[i, 1], out_q[i, 2], out_q[i, 3] = q0 / norm, q1 / norm, q2 / norm, q3 / norm


@nb.njit(cache=True, inline="always")
def _pair_gap(pair, gr, a, b, pos, rot, margin, probe, pr):
    """Smallest gap (m) of pair (a, b) at the poses pos, rot, at most margin (contacts in the
    buffers ``probe``, ``pr`` a reference to it; ``pair`` the narrow phase's entry point and
    ``gr`` a reference to the Geometry; ``pair`` the narrow phase's entry points, StepEntries.pair)."""
    count = call_apart(pair.contacts, (a, b, pos, rot, gr, margin, pr, np.int64(0), pair), nb.int64)
    best = margin
    for c in range(count):
        best = min(best, probe.gaps[c])
    return best


@nb.njit(cache=True, inline="always")
def _gap_at(m, opt, d, a, b, tau, margin, motion, narrow):
    """Smallest gap of pair (a, b) after tau seconds of free motion of both (moved in d's
    moved_* scratch; d.pos and d.rot are kept in d.keep and restored; ``narrow``: the tuple
    (pair, gr, pr) of _pair_gap's arguments)."""
    pair, gr, pr = narrow
    pos, rot, mp, mq, mf, keep = d.pos, d.rot, d.moved_pos, d.moved_quat, d.moved_phi, d.keep
    for side in range(2):
        i = a if side == 0 else b
        for x in range(3):
            keep[side, x] = pos[i, x]
            for y in range(3):
                keep[side, 3 + 3 * x + y] = rot[i, x, y]
    f = _free_motion(m, opt, d)
    for i in (a, b):
        move_body(motion, f, i, tau, mp, mq, mf)
    for i in (a, b):
        for x in range(3):
            pos[i, x] = mp[i, x]
        _rotation(mq, i, rot)
    gap = _pair_gap(pair, gr, a, b, pos, rot, margin, d.probe, pr)
    for side in range(2):
        i = a if side == 0 else b
        for x in range(3):
            pos[i, x] = keep[side, x]
            for y in range(3):
                rot[i, x, y] = keep[side, 3 + 3 * x + y]
    return gap


@nb.njit(cache=True, inline="always")
def _time_of_impact(m, opt, d, a, b, dt, gaps, margin, motion, narrow):
    """Root of the pair's gap on [0, dt] (``gaps`` = (g0, g1) at 0 and dt, g0 > 0 > g1),
    Illinois regula falsi (the bodies moved by ``motion``'s integrator, step_models; m and d by
    reference; ``narrow``: _gap_at's)."""
    lo, hi = 0.0, dt
    flo, fhi = gaps
    side = 0
    for _ in range(100):
        t = (lo * fhi - hi * flo) / (fhi - flo)
        if hi - lo < 1e-12:
            break
        f = _gap_at(m, opt, d, a, b, t, margin, motion, narrow)
        if f > 0.0:
            lo, flo = t, f
            if side == -1:
                fhi *= 0.5
            side = -1
        else:
            hi, fhi = t, f
            if side == 1:
                flo *= 0.5
            side = 1
        if abs(f) < 1e-13:
            return t
    return hi


@nb.njit(cache=True, _nrt=False)
def _motion(vel, spin, kind, g, dt, motion):
    """motion[i]: a bound (m) on how far any point of body i moves in dt seconds of free motion,
    from its centre's speed and spin bound (_speeds), plus g dt^2 if it falls."""
    for i in range(vel.shape[0]):
        speed = math.sqrt(vel[i, 0] ** 2 + vel[i, 1] ** 2 + vel[i, 2] ** 2)
        motion[i] = dt * (speed + spin[i]) + (g * dt * dt if kind[i] == DYNAMIC else 0.0)


@nb.njit(cache=True, _nrt=False)
def _speeds(kind, bound, inertia, phi, rot, kin_v, kin_w, vel, spin):
    """vel[i]: world velocity of body i's centre (m/s); spin[i]: a bound on its points' speed
    about the centre, bounding radius ``bound[i]`` * the largest |omega| of the step (m/s). A
    free body's |omega| can grow within a step (Euler's equations keep |L|, not |omega|):
    |L| / I_min bounds it."""
    for i in range(phi.shape[0]):
        if kind[i] == DYNAMIC:
            r = rot[i]
            for x in range(3):
                vel[i, x] = r[x, 0] * phi[i, 3] + r[x, 1] * phi[i, 4] + r[x, 2] * phi[i, 5]
            i0, i1, i2 = inertia[i, 0], inertia[i, 1], inertia[i, 2]
            momentum = math.sqrt((i0 * phi[i, 0]) ** 2 + (i1 * phi[i, 1]) ** 2 + (i2 * phi[i, 2]) ** 2)
            w = momentum / min(i0, i1, i2)
        elif kind[i] == KINEMATIC:
            for x in range(3):
                vel[i, x] = kin_v[i, x]
            w = math.sqrt(kin_w[i, 0] ** 2 + kin_w[i, 1] ** 2 + kin_w[i, 2] ** 2)
        else:
            for x in range(3):
                vel[i, x] = 0.0
            w = 0.0
        spin[i] = bound[i] * w if w > 0.0 else 0.0  # a plane's infinite bound only if it turns


@nb.njit(cache=True, _nrt=False)
def _gap_spin(spin, shape_type):
    """The part of each body's spin bound (_speeds) that can change a gap: none for a sphere
    (turning about its centre moves no point of it nearer to anything), all of it otherwise.
    In place."""
    for i in range(spin.shape[0]):
        if shape_type[i] == SPHERE:
            spin[i] = 0.0


@nb.njit(cache=True, _nrt=False)
def _pair_reach(pairs, vel, spin, kind, g, dt, out):
    """out[p]: a bound (m) on how much pair p's gap can shrink in dt seconds of free motion:
    dt (|v_a - v_b| + spin_a + spin_b), plus g dt^2 when only one of them falls (the larger of
    this and out[p])."""
    for p in range(pairs.shape[0]):
        a, b = pairs[p, 0], pairs[p, 1]
        dv = math.sqrt(
            (vel[a, 0] - vel[b, 0]) ** 2 + (vel[a, 1] - vel[b, 1]) ** 2 + (vel[a, 2] - vel[b, 2]) ** 2
        )
        reach = dt * (dv + spin[a] + spin[b])
        if (kind[a] == DYNAMIC) != (kind[b] == DYNAMIC):
            reach += g * dt * dt
        out[p] = max(out[p], reach)


@nb.njit(cache=True, inline="always")
def _boxes(m, d, margin):
    """d.lo, d.hi: bounding boxes grown by margin and d.motion; d.movable: the dynamic bodies."""
    geo = m.geometry
    shape_type, bound, kind, pos, motion, lo, hi, movable = (
        geo.shape_type,
        geo.bound,
        m.kind,
        d.pos,
        d.motion,
        d.lo,
        d.hi,
        d.movable,
    )
    for i in range(pos.shape[0]):
        movable[i] = kind[i] == DYNAMIC
        for x in range(3):
            if shape_type[i] == PLANE:
                lo[i, x] = -np.inf
                hi[i, x] = np.inf
            else:
                reach = bound[i] + margin + motion[i]
                lo[i, x] = pos[i, x] - reach
                hi[i, x] = pos[i, x] + reach


@nb.njit(cache=True, _nrt=False)
def _apart(a, b, pos, bound, margin):
    """Whether the bounding spheres of a and b are more than ``margin`` apart (cheap reject)."""
    reach = bound[a] + bound[b] + margin  # inf for a plane: never apart
    d0, d1, d2 = pos[a, 0] - pos[b, 0], pos[a, 1] - pos[b, 1], pos[a, 2] - pos[b, 2]
    return d0 * d0 + d1 * d1 + d2 * d2 > reach * reach


@nb.njit(cache=True, inline="always")
def _beyond_plane(a, b, pos, rot, geo, margin):
    """Whether body a lies wholly more than ``margin`` (m) beyond plane b: its centre's height
    over the plane less its bounding radius (every one of its contact points lies within that
    radius of its centre, narrow._against_plane), with a relative guard of 1e-9 against
    rounding. A plane pair that passes gives no contact, so the narrow phase is not called."""
    param, bound = geo.param, geo.bound
    nx = rot[b, 0, 0] * param[b, 0] + rot[b, 0, 1] * param[b, 1] + rot[b, 0, 2] * param[b, 2]
    ny = rot[b, 1, 0] * param[b, 0] + rot[b, 1, 1] * param[b, 1] + rot[b, 1, 2] * param[b, 2]
    nz = rot[b, 2, 0] * param[b, 0] + rot[b, 2, 1] * param[b, 1] + rot[b, 2, 2] * param[b, 2]
    height = nx * (pos[a, 0] - pos[b, 0]) + ny * (pos[a, 1] - pos[b, 1]) + nz * (pos[a, 2] - pos[b, 2])
    height -= param[b, 3]
    clear = height - bound[a]
    return clear > margin + 1e-9 * (1.0 + bound[a] + abs(height))


@nb.njit(cache=True, inline="always")
def _cannot_touch(a, b, pos, rot, geo, margin):
    """Cheap rejects before the narrow phase: bounding spheres apart, or a body wholly beyond
    a plane (both exact: such a pair has no contact within margin)."""
    btype = geo.shape_type
    if btype[b] == PLANE and btype[a] != PLANE:
        return _beyond_plane(a, b, pos, rot, geo, margin)
    if btype[a] == PLANE and btype[b] != PLANE:
        return _beyond_plane(b, a, pos, rot, geo, margin)
    return _apart(a, b, pos, geo.bound, margin)


@nb.njit(cache=True, inline="always")
def _detect(geo, slop, pos, rot, buf, pairs, near, pair, gr, br):
    """Contacts (into ``buf``, narrow.Contacts; returns their count) of all pairs within margin = slop +
    near.reach[p] (m, how far the pair can close in the step). near.gap[p]: a lower bound of
    pair p's gap (its smallest contact gap, polytope face planes standing in for the distance;
    ``margin`` when none is that close); near.touching[p]: it has a contact within slop. The
    solve skips contacts beyond slop. Each pair's contacts come from the narrow phase's entry
    points ``pair`` (StepEntries.pair), given references ``gr`` to geo and ``br`` to buf."""
    reach, gap, touching = near.reach, near.gap, near.touching
    count = np.int64(0)  # a literal 0 would compile the narrow phase a second time
    for p in range(pairs.shape[0]):
        a, b = pairs[p, 0], pairs[p, 1]
        margin = slop + reach[p]
        gap[p] = margin
        touching[p] = False
        if _cannot_touch(a, b, pos, rot, geo, margin):
            continue
        before = count
        count = call_apart(pair.contacts, (a, b, pos, rot, gr, margin, br, count, pair), nb.int64)
        for c in range(before, count):
            gap[p] = min(gap[p], buf.gaps[c])
        touching[p] = count > before and gap[p] <= slop
    return count


@nb.njit(cache=True, inline="always")
def kinematic_stage(m, opt, d, s):
    """Kinematic bodies to their path's pose at the run's step s, with the velocity and angular
    velocity (finite differences over the step) that take them to the next."""
    h, kin_pos, kin_quat = opt.h, d.kin_pos, d.kin_quat
    for j in range(m.kinematic.shape[0]):
        i = m.kinematic[j]
        for x in range(3):
            d.pos[i, x] = kin_pos[s, j, x]
            d.kin_v[i, x] = (kin_pos[s + 1, j, x] - kin_pos[s, j, x]) / h
        for x in range(4):
            d.quat[i, x] = kin_quat[s, j, x]
        _turn_rate(kin_quat, s, j, h, i, d.kin_w)


@nb.njit(cache=True, inline="always")
def _turn_rate(kin_quat, s, j, h, i, kin_w):
    """kin_w[i]: the angular velocity (rad/s) turning kinematic body j from its quaternion at
    step s to the next in h seconds, log(q1 conj(q0)) / h (spatial.quat_mul, quat_log in
    scalars)."""
    a0, a1, a2, a3 = (
        kin_quat[s + 1, j, 0],
        kin_quat[s + 1, j, 1],
        kin_quat[s + 1, j, 2],
        kin_quat[s + 1, j, 3],
    )
    b0, b1, b2, b3 = kin_quat[s, j, 0], -kin_quat[s, j, 1], -kin_quat[s, j, 2], -kin_quat[s, j, 3]
    w = a0 * b0 - a1 * b1 - a2 * b2 - a3 * b3
    v0 = a0 * b1 + a1 * b0 + a2 * b3 - a3 * b2
    v1 = a0 * b2 - a1 * b3 + a2 * b0 + a3 * b1
    v2 = a0 * b3 + a1 * b2 - a2 * b1 + a3 * b0
    if w < 0.0:
        w, v0, v1, v2 = -w, -v0, -v1, -v2
    n = math.sqrt(v0**2 + v1**2 + v2**2)
    if n < 1e-12:
        kin_w[i, 0], kin_w[i, 1], kin_w[i, 2] = (
            2.0 * v0 / max(w, 1e-300) / h,
            2.0 * v1 / max(w, 1e-300) / h,
            2.0 * v2 / max(w, 1e-300) / h,
        )
    else:
        scale = 2.0 * math.atan2(n, w) / n
        kin_w[i, 0], kin_w[i, 1], kin_w[i, 2] = scale * v0 / h, scale * v1 / h, scale * v2 / h


@nb.njit(cache=True, _nrt=False)
def broad_stage(m, opt, d, dt):
    """Rotations, speed bounds and the pairs of bodies that can come within slop in dt seconds
    of free motion (sweep and prune of bounding boxes grown by how far each can move) into
    d.sweep.pairs; d.spin keeps only what can change a gap (_gap_spin). Returns how many
    pairs there are (more than d.sweep.pairs holds: grow it and sweep again). Called apart
    (StepEntries.broad); m and d by reference."""
    _rotations(d.quat, d.rot)
    _speeds(m.kind, m.geometry.bound, m.inertia, d.phi, d.rot, d.kin_v, d.kin_w, d.vel, d.spin)
    _motion(d.vel, d.spin, m.kind, d.gravity_norm, dt, d.motion)
    _boxes(m, d, opt.slop)
    count = sweep_pairs(d.lo, d.hi, d.movable, d.sweep)
    _gap_spin(d.spin, m.geometry.shape_type)  # after the boxes, whose order on x sets the contacts' order
    return count


@nb.njit(cache=True, _nrt=False)
def narrow_stage(m, opt, d, n_pairs, dt, pair):
    """How far each of the broad phase's first ``n_pairs`` pairs (d.sweep.pairs) can close in
    dt (d.near.reach), then the contacts of the pairs that can come within slop (_detect);
    returns their count. Called apart (StepEntries.narrow: once per (sub-)step), the narrow
    phase through its entry points ``pair`` per pair; m and d by reference, their fields read
    once here."""
    pairs, near, geo, buf = d.sweep.pairs[:n_pairs], d.near, m.geometry, d.contacts
    reach = near.reach
    for p in range(pairs.shape[0]):
        reach[p] = 0.0
    _pair_reach(pairs, d.vel, d.spin, m.kind, d.gravity_norm, dt, reach)
    gr, br = field_ref(m, "geometry"), field_ref(d, "contacts")  # pointers into m and d
    return _detect(geo, opt.slop, d.pos, d.rot, buf, pairs, near, pair, gr, br)


@nb.njit(cache=True, _nrt=False)
def contact_stage(contact, m, opt, d, count, dt, time, step, nrec):
    """The contact model's response to the contacts d.contacts[:count] over dt (s), in the
    scratch d.solver (rows >= count), the model picked by the type of ``contact``
    (step_models). Returns the record count, -1 when d.rec is full. Called apart
    (StepEntries.response: once per (sub-)step, with the model linked in); m and d by
    reference."""
    d.stats.solves[0] += 1
    return contact_response(contact, m, opt, d, count, dt, time, step, nrec)


class ImpulseContacts(NamedTuple):
    """run_steps' ``contact`` for the impulse model (impulses.resolve); its type picks it."""

    code: int


class PenaltyContacts(NamedTuple):
    """run_steps' ``contact`` for a penalty model (physics.rigid.penalty: linear or
    Hunt-Crossley by Options.contact); its type picks it."""

    code: int


class SemiImplicitMotion(NamedTuple):
    """run_steps' ``motion`` for the semi-implicit integrator (_move_semi_implicit)."""

    code: int


class AnyMotion(NamedTuple):
    """run_steps' ``motion`` for any integrator, chosen at run time from Options (_move)."""

    code: int


#: Each contact model code's tag (Options.contact -> run_steps' ``contact`` type).
CONTACT_TAGS = {IMPULSE: ImpulseContacts, LINEAR: PenaltyContacts, HUNT_CROSSLEY: PenaltyContacts}


def step_models(opt: Options) -> tuple[ImpulseContacts | PenaltyContacts, SemiImplicitMotion | AnyMotion]:
    """run_steps' ``contact`` and ``motion`` arguments for ``opt``: numba compiles run_steps
    once per pair of their types, with only that contact model and integrator in it (the other
    overloads are never typed, so never compiled; named tuples of a module-level class keep
    numba's cache valid across processes, where a kernel passed as an argument would not). An
    unknown contact model or integrator code is an error."""
    contact_tag = CONTACT_TAGS.get(opt.contact)
    if contact_tag is None:
        raise ValueError(f"stepper.step_models: unknown contact model code {opt.contact!r}")
    if opt.integrator == SEMI_IMPLICIT:
        motion = SemiImplicitMotion(opt.integrator)
    elif opt.integrator in integrate.METHODS.values():
        motion = AnyMotion(opt.integrator)
    else:
        raise ValueError(
            f"stepper.step_models: unknown integrator code {opt.integrator!r}, "
            f"expected one of {sorted(integrate.METHODS.values())} (integrate.METHODS)"
        )
    contact = contact_tag(opt.contact)
    return contact, motion


class StepEntries(NamedTuple):
    """run_steps' argument ``entries``: the entry points (jassy.unlinked.Entry) of the stages
    it calls apart (step_calls), each compiled alone (not linked into run_steps)."""

    pair: NarrowEntries  # the narrow phase (called per pair by the narrow and impact stages)
    broad: Entry  # broad_stage
    narrow: Entry  # narrow_stage
    response: Entry  # contact_stage
    advance: Entry  # advance_stage
    impact: Entry  # impact_stage


def step_calls(m: Model, opt: Options, d: Data) -> dict:
    """The stages run_steps calls apart for a run of ``m``, ``opt``, ``d``: StepEntries'
    field -> (kernel, example arguments of the types run_steps passes); for ``pair`` the
    narrow phase's kernels, narrow.narrow_calls."""
    whole, dt = np.int64(0), 0.0
    contact, motion = step_models(opt)
    mr, dr, pair = RefExample(m), RefExample(d), unset(NarrowEntries)
    return {
        "pair": narrow_calls(d.pos, d.rot, m.geometry, d.contacts),
        "broad": (broad_stage, (mr, opt, dr, dt)),
        "narrow": (narrow_stage, (mr, opt, dr, whole, dt, pair)),
        "response": (contact_stage, (contact, mr, opt, dr, whole, dt, dt, whole, whole)),
        "advance": (advance_stage, (mr, opt, dr, dt, motion)),
        "impact": (impact_stage, (mr, opt, dr, whole, dt, motion, pair)),
    }


#: step_entries' answers by a cheap key of the run's types (numba's typing of Model and Data
#: for the five stages takes ~30 ms, run is called once per chunk of steps).
_ENTRIES: dict[tuple, StepEntries] = {}


def step_entries(m: Model, opt: Options, d: Data) -> StepEntries:
    """The entry points run_steps calls for this run, each stage compiled (or loaded from
    numba's cache) for its call's types the first time a run has these types."""
    contact, motion = step_models(opt)
    key = (type(contact), type(motion), _type_key((m, opt, d)))
    found = _ENTRIES.get(key)
    if found is None:
        calls = step_calls(m, opt, d)
        pair = entries_of(NarrowEntries, calls["pair"])
        stages = (entry(calls[name][0], *calls[name][1]) for name in StepEntries._fields[1:])
        found = StepEntries(pair, *stages)
        if key[2] is not None:  # None: a type the key cannot tell (not remembered)
            _ENTRIES[key] = found
    return found


def _impulse_response(contact, m, opt, d, count, dt, time, step, nrec):
    """contact_response of the impulse model (impulses.resolve)."""
    bodies = SolveBodies(m.kind, m.inv_mass, m.inv_inertia, m.restitution, m.friction, m.rolling)
    state = SolveData(d.contacts, d.warm, d.pos, d.rot, d.phi, d.kin_v, d.kin_w, d.rec, d.stats)
    return resolve(bodies, opt, state, d.solver, count, dt, time, step, nrec)


def _penalty_response(contact, m, opt, d, count, dt, time, step, nrec):
    """contact_response of a penalty model (physics.rigid.penalty)."""
    d.stats.contacts[0] += count
    return penalty(deref(m), opt, deref(d), d.solver, count, dt, time, step, nrec)


#: Each contact tag's response: the one table contact_response dispatches through, compiled
#: (by the argument's type, when run_steps is typed) and with numba's JIT off.
CONTACT_RESPONSES = {ImpulseContacts: _impulse_response, PenaltyContacts: _penalty_response}


def contact_response(contact, m, opt, d, count, dt, time, step, nrec):
    """The response of the model ``contact`` (step_models) to d.contacts[:count], looked up in
    CONTACT_RESPONSES. Compiled, the overload below picks it by the argument's type; this body
    runs only with numba's JIT off (NUMBA_DISABLE_JIT=1)."""
    return CONTACT_RESPONSES[type(contact)](contact, m, opt, d, count, dt, time, step, nrec)


@overload(contact_response, inline="always")
def _contact_response(contact, m, opt, d, count, dt, time, step, nrec):
    return CONTACT_RESPONSES.get(getattr(contact, "instance_class", None))


def _move_semi_implicit_body(motion, f, i, tau, out_p, out_q, out_phi):
    """move_body with the semi-implicit integrator."""
    _move_semi_implicit(f, i, tau, out_p, out_q, out_phi)


def _move_any_body(motion, f, i, tau, out_p, out_q, out_phi):
    """move_body with the integrator f.method (RK4 or adaptive)."""
    _move(f, i, tau, out_p, out_q, out_phi)


#: Each motion tag's free-motion step: the one table move_body dispatches through.
MOTIONS = {SemiImplicitMotion: _move_semi_implicit_body, AnyMotion: _move_any_body}


def move_body(motion, f, i, tau, out_p, out_q, out_phi):
    """Body i's free motion by the integrator of ``motion`` (step_models), looked up in
    MOTIONS. Compiled, the overload below picks it by the argument's type; this body runs
    only with numba's JIT off."""
    MOTIONS[type(motion)](motion, f, i, tau, out_p, out_q, out_phi)


@overload(move_body, inline="always")
def _move_body(motion, f, i, tau, out_p, out_q, out_phi):
    return MOTIONS.get(getattr(motion, "instance_class", None))


@nb.njit(cache=True, _nrt=False)
def advance_stage(m, opt, d, tau, motion):
    """Every body's pose and twist after tau seconds of free motion (by ``motion``'s
    integrator) into d.new_*; returns the number of bodies. Called apart
    (StepEntries.advance); m and d by reference."""
    f, new_pos, new_quat, new_phi = _free_motion(m, opt, d), d.new_pos, d.new_quat, d.new_phi
    for i in range(m.kind.shape[0]):
        move_body(motion, f, i, tau, new_pos, new_quat, new_phi)
    return m.kind.shape[0]


@nb.njit(cache=True, _nrt=False)
def impact_stage(m, opt, d, n_pairs, dt, motion, pair):
    """The earliest time of impact (s, within dt) of the broad phase's first ``n_pairs`` pairs
    (d.sweep.pairs) that were apart at the start of the (sub-)step and penetrate after it
    (d.new_*) having closed faster than the bounce threshold (module doc, step 6); dt when
    none. Called apart (StepEntries.impact: once per (sub-)step, with the impact-time search
    inlined), the narrow phase through its entry points ``pair``; m and d by reference, their
    fields read once here."""
    pairs, near = d.sweep.pairs[:n_pairs], d.near
    slop, bounce = opt.slop, opt.bounce_threshold
    # records read once, not per pair (taking one out of m or d in the loop costs a reference
    # count per array it holds)
    geo, pos, rot, new_pos, new_rot, probe, checks = (
        m.geometry,
        d.pos,
        d.rot,
        d.new_pos,
        d.new_rot,
        d.probe,
        d.stats.impact_checks,
    )
    reach, gap0, touching = near.reach, near.gap, near.touching
    gr, pr = field_ref(m, "geometry"), field_ref(d, "probe")  # for the narrow phase's entry point
    _rotations(d.new_quat, d.new_rot)
    _speeds(
        m.kind, m.geometry.bound, m.inertia, d.phi, d.rot, d.kin_v, d.kin_w, d.vel, d.spin
    )  # after the solve
    _gap_spin(d.spin, m.geometry.shape_type)
    _pair_reach(pairs, d.vel, d.spin, m.kind, d.gravity_norm, dt, reach)
    first_hit = dt
    for p in range(pairs.shape[0]):
        a, b = pairs[p, 0], pairs[p, 1]
        if touching[p] or gap0[p] - reach[p] >= -slop or reach[p] < bounce * dt:
            continue  # touching (the solve handles it), cannot close past -slop, or too slow
        if _cannot_touch(a, b, new_pos, new_rot, geo, slop):
            continue
        checks[0] += 1
        g1 = _pair_gap(pair, gr, a, b, new_pos, new_rot, slop, probe, pr)
        if g1 >= -slop:
            continue
        within = reach[p] + 4.0 * slop
        g0 = _pair_gap(pair, gr, a, b, pos, rot, within, probe, pr)
        if g0 <= slop or g0 - g1 < bounce * dt:
            continue  # touching already, or closing too slowly to bounce
        hit = _time_of_impact(m, opt, d, a, b, dt, (g0, g1), within, motion, (pair, gr, pr))
        first_hit = min(first_hit, hit)
    return first_hit


@nb.njit(cache=True, inline="always")
def _commit(d):
    """The state after the free motion (d.new_*) becomes the state."""
    _copy_rows(d.new_pos, d.pos)
    _copy_rows(d.new_quat, d.quat)
    _copy_rows(d.new_phi, d.phi)


@nb.njit(cache=True, inline="always")
def _copy_rows(src, dst, at=0):
    """dst[i, at:at + k] = src[i, :k] for every row i (element by element: no temporary)."""
    for i in range(src.shape[0]):
        for x in range(src.shape[1]):
            dst[i, at + x] = src[i, x]


@nb.njit(cache=True, inline="always")
def sample_stage(d, step):
    """After every d.every-th step counted from step d.origin, the poses and twists go to
    d.traj[k] (N, 13) if it has room."""
    done = step + 1 - d.origin
    if done % d.every == 0 and done // d.every - 1 < d.traj.shape[0]:
        k = done // d.every - 1
        row = d.traj[k]
        _copy_rows(d.pos, row, 0)
        _copy_rows(d.quat, row, 3)
        _copy_rows(d.phi, row, 7)


@nb.njit(cache=True, inline="always")
def outer_step(m, opt, d, step, nrec, contact, motion, entries):
    """One outer step of opt.h seconds at step number ``step`` (module doc): the stages, with
    impact sub-steps, from where d.progress says it stopped. Returns (record count, whether
    it stopped for more scratch: d.progress.need says how much)."""
    progress = d.progress
    h = opt.h
    max_events = opt.max_events if opt.contact == IMPULSE else 0
    t_local = progress.t_local[0]
    subs = progress.subs[0]
    while True:
        dt = h - t_local
        if dt <= 1e-15:
            break
        count = call_apart(entries.broad, (m, opt, d, dt), nb.int64)
        if count > d.sweep.pairs.shape[0] or count > d.near.reach.shape[0]:
            progress.need[0] = count
            return _stop(progress, t_local, subs, nrec)
        n_pairs = count
        count = call_apart(entries.narrow, (m, opt, d, n_pairs, dt, entries.pair), nb.int64)
        if count > d.solver.idx.shape[0]:
            progress.need[1] = count
            return _stop(progress, t_local, subs, nrec)
        progress.most[0] = max(progress.most[0], count)
        solved = nrec
        at = step * h + t_local
        nrec = call_apart(entries.response, (contact, m, opt, d, count, dt, at, step, nrec), nb.int64)
        if nrec < 0:
            raise RuntimeError("run_steps: contact record buffer overflow")
        _mark_resting(d.rec, solved, nrec, m.kind, opt.contact == IMPULSE, d.resting)
        call_apart(entries.advance, (m, opt, d, dt, motion), nb.int64)
        first_hit = dt
        if subs < max_events:
            impact_args = (m, opt, d, n_pairs, dt, motion, entries.pair)
            first_hit = call_apart(entries.impact, impact_args, nb.float64)
        if first_hit < dt:
            call_apart(entries.advance, (m, opt, d, first_hit, motion), nb.int64)
            _commit(d)
            t_local += first_hit
            subs += 1
            d.stats.impact_substeps[0] += 1
            continue
        _commit(d)
        if subs >= max_events and max_events > 0:
            d.stats.late_impacts[0] += 1
        break
    progress.t_local[0] = 0.0
    progress.subs[0] = 0
    return nrec, False


@nb.njit(cache=True, inline="always")
def _stop(progress, t_local, subs, nrec):
    """outer_step's return when it stops for more scratch at t_local after subs sub-steps."""
    progress.t_local[0] = t_local
    progress.subs[0] = subs
    return nrec, True


@nb.njit(cache=True, _nrt=False)
def run_steps(m, opt, d, first, n_steps, nrec, contact, motion, entries):
    """Advance n_steps outer steps from step ``first`` (time first * h); the kinematic bodies
    follow d.kin_pos/kin_quat[s] at step first + s. Returns (steps done, record count); stops
    before a step when d.rec may not hold its records (the caller grows it and calls again),
    and inside a step that needs more scratch (module doc; :func:`run` resumes it). The
    types of ``contact`` and ``motion`` pick the contact model and integrator (step_models).
    The stages take Model and Data by reference (record_ref: one pointer each)."""
    mr, dr = ref(m), ref(d)
    for s in range(n_steps):
        resuming = dr.progress.t_local[0] > 0.0 or dr.progress.subs[0] > 0
        if not resuming and dr.rec.shape[0] - nrec < record_room(opt, dr.progress.most[0]):
            return s, nrec
        if not resuming:
            kinematic_stage(mr, opt, dr, s)
        nrec, stopped = outer_step(mr, opt, dr, first + s, nrec, contact, motion, entries)
        if stopped:
            return s, nrec
        sample_stage(dr, first + s)
    return n_steps, nrec

"""Burr-bone contact: voxel-sphere overlap volumes, moments, penetration, forces, erosion.

Agus, Giachetti, Gobbetti, Zanetti, Zorcolo, "Real-time haptic and visual simulation of
bone dissection", IEEE VR 2002 / Presence 12(1) 2003.

All kernels work in grid units (lengths in voxels, volumes in voxel^3, density in counter
units 0..255); :mod:`physics.burr.loop` converts to SI. A voxel is taken as the sphere of
equal volume, radius ``R_VOXEL = (3 / (4 pi))^(1/3)`` voxels, centred on the voxel centre,
so a voxel fully inside the burr contributes exactly its volume (1 voxel^3).

* overlap of the burr (radius R) and a voxel sphere (radius r) at centre distance d
  (delta v(d), the exact sphere-sphere lens volume):
  pi (R + r - d)^2 (d^2 + 2 d r - 3 r^2 + 2 d R + 6 r R - 3 R^2) / (12 d);
* the disc of the two spheres' intersection circle (delta sigma(d), the voxel's
  share of the burr surface): pi (2 (R^2 + r^2) - d^2 - (r^2 - R^2)^2 / d^2) / 4, its plane
  at distance d / 2 + (R^2 - r^2) / (2 d) from the burr centre;
* m0 = sum rho_i dv_i, m1 = sum rho_i dv_i (x_i - x_c); n = -m1 / |m1|;
* h from m0 = pi rho0 R^3 (h/R)^2 (1 - h/(3R)), solved in closed form (trigonometric root).
"""

from __future__ import annotations

import math
from typing import NamedTuple

import numba as nb
import numpy as np

R_VOXEL = (3.0 / (4.0 * math.pi)) ** (1.0 / 3.0)
FASTMATH = {"reassoc", "contract", "nsz", "arcp"}

_GAMMA = np.uint64(0x9E3779B97F4A7C15)
_MIX1 = np.uint64(0xBF58476D1CE4E5B9)
_MIX2 = np.uint64(0x94D049BB133111EB)


@nb.njit(cache=True)
def uniform01(s):
    """splitmix64: advance state s, return (state, uniform draw in [0, 1))."""
    s += _GAMMA
    z = (s ^ (s >> np.uint64(30))) * _MIX1
    z = (z ^ (z >> np.uint64(27))) * _MIX2
    z ^= z >> np.uint64(31)
    return s, float(z >> np.uint64(11)) * 2.0**-53


@nb.njit(cache=True, fastmath=FASTMATH)
def lens_volume(d, R, r):
    """Overlap volume of spheres of radii R and r whose centres are d apart."""
    if d >= R + r:
        return 0.0
    if d <= abs(R - r):
        m = min(R, r)
        return 4.0 / 3.0 * math.pi * m * m * m
    s = R + r - d
    return (
        math.pi
        * s
        * s
        * (d * d + 2.0 * d * r - 3.0 * r * r + 2.0 * d * R + 6.0 * r * R - 3.0 * R * R)
        / (12.0 * d)
    )


@nb.njit(cache=True, fastmath=FASTMATH)
def disc_area(d, R, r):
    """Area of the disc bounded by the intersection circle of the two spheres (0 if none)."""
    if d >= R + r or d <= abs(R - r):
        return 0.0
    a2 = (2.0 * d * d * (R * R + r * r) - d**4 - (R * R - r * r) ** 2) / (4.0 * d * d)
    return math.pi * max(a2, 0.0)


@nb.njit(cache=True, fastmath=FASTMATH)
def lens_centroid(d, R, r):
    """Distance from the burr centre (radius R) of the centroid of its overlap with a sphere of
    radius r at distance d, along the line joining the centres (sum of two spherical caps)."""
    if d >= R + r or d <= 0.0:
        return 0.0
    if d <= r - R:  # burr inside the other sphere
        return 0.0
    if d <= R - r:  # other sphere inside the burr
        return d
    x0 = (d * d + R * R - r * r) / (2.0 * d)  # plane of the intersection circle
    h1 = R - x0  # cap of the burr beyond the plane
    h2 = r - (d - x0)  # cap of the other sphere on the burr side
    v1 = math.pi * h1 * h1 * (3.0 * R - h1) / 3.0
    v2 = math.pi * h2 * h2 * (3.0 * r - h2) / 3.0
    z1 = 3.0 * (2.0 * R - h1) ** 2 / (4.0 * (3.0 * R - h1))  # from the burr centre, outwards
    z2 = d - 3.0 * (2.0 * r - h2) ** 2 / (4.0 * (3.0 * r - h2))  # cap of the other, towards burr
    if v1 + v2 <= 0.0:
        return x0
    return (v1 * z1 + v2 * z2) / (v1 + v2)


class Ball(NamedTuple):
    """The burr's sphere in grid units: centre (cx, cy, cz) and radius R (voxels)."""

    cx: float
    cy: float
    cz: float
    R: float


class Box(NamedTuple):
    """A box of voxels [i0..i1] x [j0..j1] x [k0..k1] (inclusive grid indices)."""

    i0: int
    i1: int
    j0: int
    j1: int
    k0: int
    k1: int


@nb.njit(cache=True, fastmath=FASTMATH)
def voxel_moments(dens, ball, box):
    """(m0, m1x, m1y, m1z) of the voxels in the Box, each a sphere of radius R_VOXEL weighted
    by its lens overlap with the burr's Ball (grid units)."""
    cx, cy, cz, R = ball
    i0, i1, j0, j1, k0, k1 = box
    r = R_VOXEL
    reach2 = (R + r) * (R + r)
    inner2 = (R - r) * (R - r) if r < R else -1.0
    m0 = 0.0
    mx = 0.0
    my = 0.0
    mz = 0.0
    for i in range(i0, i1 + 1):
        dx = i - cx
        for j in range(j0, j1 + 1):
            dy = j - cy
            dxy = dx * dx + dy * dy
            if dxy >= reach2:
                continue
            for k in range(k0, k1 + 1):
                c = dens[i, j, k]
                if c == 0:
                    continue
                dz = k - cz
                d2 = dxy + dz * dz
                if d2 >= reach2:
                    continue
                w = float(c) if d2 <= inner2 else float(c) * lens_volume(math.sqrt(d2), R, r)
                m0 += w
                mx += w * dx
                my += w * dy
                mz += w * dz
    return m0, mx, my, mz


@nb.njit(cache=True, fastmath=FASTMATH)
def brute_moments(dens, cx, cy, cz, R, out):
    """Brute-force m0, m1 (out[0:4]) over every voxel of the burr's bounding box."""
    r = R_VOXEL
    nx, ny, nz = dens.shape
    reach = R + r
    i0 = max(0, int(math.ceil(cx - reach)))
    i1 = min(nx - 1, int(math.floor(cx + reach)))
    j0 = max(0, int(math.ceil(cy - reach)))
    j1 = min(ny - 1, int(math.floor(cy + reach)))
    k0 = max(0, int(math.ceil(cz - reach)))
    k1 = min(nz - 1, int(math.floor(cz + reach)))
    m0, mx, my, mz = voxel_moments(dens, Ball(cx, cy, cz, R), Box(i0, i1, j0, j1, k0, k1))
    out[0] = m0
    out[1] = mx
    out[2] = my
    out[3] = mz


def cap_volume(h: float, R: float) -> float:
    """Volume of a spherical cap of height h of a sphere of radius R."""
    return math.pi * R**3 * (h / R) ** 2 * (1.0 - h / (3.0 * R))


@nb.njit(cache=True)
def depth_from_m0(m0, rho0, R):
    """Penetration h in [0, 2R] with m0 = pi rho0 R^3 (h/R)^2 (1 - h/(3R)).

    With u = h/R and v = u - 1 the cubic is v^3 - 3v + 3q - 2 = 0, q = m0 / (pi rho0 R^3) in
    [0, 4/3]; the root in [-1, 1] is v = 2 cos(acos(1 - 3q/2)/3 - 2 pi/3).
    """
    q = m0 / (math.pi * rho0 * R * R * R)
    if q <= 0.0:
        return 0.0
    if q >= 4.0 / 3.0:
        return 2.0 * R
    phi = math.acos(min(1.0, max(-1.0, 1.0 - 1.5 * q)))
    u = 1.0 + 2.0 * math.cos(phi / 3.0 - 2.0 * math.pi / 3.0)
    return R * min(2.0, max(0.0, u))


@nb.njit(cache=True, fastmath=FASTMATH)
def cap_box(cx, cy, cz, R, nvec, cos_t, lo, hi, shape):
    """Grid box (inclusive) of the voxels that can touch the burr-surface cap {u . (-n) >= cos_t}.

    With nvec == 0 (normal undefined) the whole burr's bounding box.
    """
    reach = R + R_VOXEL + 1.0
    c = (cx, cy, cz)
    for a in range(3):
        e = -nvec[a]
        if nvec[0] == 0.0 and nvec[1] == 0.0 and nvec[2] == 0.0:
            top = 1.0
            bot = -1.0
        else:
            alpha = math.acos(min(1.0, max(-1.0, e)))
            theta = math.acos(min(1.0, max(-1.0, cos_t)))
            top = math.cos(max(0.0, alpha - theta))
            bot = -math.cos(max(0.0, math.pi - alpha - theta))
        lo[a] = max(0, int(math.floor(c[a] + min(bot * reach, bot * (R - R_VOXEL) - 1.0))))
        hi[a] = min(shape[a] - 1, int(math.ceil(c[a] + max(top * reach, top * (R - R_VOXEL) + 1.0))))


PI_R2 = math.pi * R_VOXEL * R_VOXEL


class BurrModel(NamedTuple):
    """The burr and erosion constants in grid units: radius (voxels), voxel edge (m),
    friction coefficient mu, kmass (counter units removed per joule)."""

    radius: float
    voxel: float
    mu: float
    kmass: float


class ContactOptions(NamedTuple):
    """One haptic step: burr centre (3,) (grid units), normal (3,) (zeros = undefined),
    Hertz contact radius a_hertz (voxels), load |F_e| (N), spin omega (3,) (rad/s), tool
    velocity (3,) (m/s), dt (s), erode (bool)."""

    centre: np.ndarray
    normal: np.ndarray
    a_hertz: float
    load: float
    omega: np.ndarray
    velocity: np.ndarray
    dt: float
    erode: bool


CONTACT_VOXEL = np.dtype(
    [("i", np.int64), ("j", np.int64), ("k", np.int64), ("dist2", np.float64), ("dist", np.float64),
     ("xi2", np.float64), ("share", np.float64), ("radius", np.float64), ("weight", np.float64)]
)  # fmt: skip
"""A gathered contact voxel: grid index (i, j, k), squared distance dist2 and distance dist
to the burr centre and squared distance xi2 to the axis along -n (voxel^2, voxel), surface
share (voxel^2), contact-point radius (voxels) and Hertz profile weight sqrt(1 - xi^2/a^2)."""


CONTACT_TALLY = np.dtype(
    [("force_x", np.float64), ("force_y", np.float64), ("force_z", np.float64), ("torque_x", np.float64),
     ("torque_y", np.float64), ("torque_z", np.float64), ("power", np.float64), ("expected", np.float64),
     ("removed", np.float64), ("voxels", np.float64), ("area", np.float64), ("lo_i", np.int64),
     ("lo_j", np.int64), ("lo_k", np.int64), ("hi_i", np.int64), ("hi_j", np.int64), ("hi_k", np.int64)]
)  # fmt: skip
"""What one surface pass adds up (SI): friction force (N) and torque (N m) about the burr
centre, frictional power (W), expected and actual counter decrements, contact voxels, sum
of their surface shares (m^2) and the grid box [lo, hi] (inclusive; empty: lo > hi) of
the voxels changed."""


class Bricks(NamedTuple):
    """The density's 2^shift-voxel bricks as an octree stores them: ``mom`` holds [m0, m1x,
    m1y, m1z] per brick (m1 about the brick centre) from offset ``start``, ``by`` x ``bz``
    bricks per i-slab and row. The surface pass subtracts each eroded voxel's decrement from
    its brick. shift < 0: no bricks."""

    mom: np.ndarray
    start: int
    shift: int
    by: int
    bz: int


NO_BRICKS = Bricks(np.zeros(4), 0, -1, 1, 1)


class ContactData(NamedTuple):
    """The eroding density (uint8 grid, modified in place), the roulette's splitmix64 state
    rng (1,) uint64, the scratch records of the gathered voxels (CONTACT_VOXEL; capacity:
    the voxels of the burr ball's box), the tally (one CONTACT_TALLY record) and the
    density's Bricks (NO_BRICKS without an octree)."""

    density: np.ndarray
    rng: np.ndarray
    voxels: np.ndarray
    tally: np.ndarray
    bricks: Bricks


@nb.njit(cache=True, fastmath=FASTMATH)
def _reset(d):
    """Zero the tally and empty the changed box."""
    t = d.tally[0]
    t.force_x = t.force_y = t.force_z = 0.0
    t.torque_x = t.torque_y = t.torque_z = 0.0
    t.power = t.expected = t.removed = t.voxels = t.area = 0.0
    t.lo_i, t.lo_j, t.lo_k = d.density.shape
    t.hi_i = t.hi_j = t.hi_k = -1


@nb.njit(cache=True, fastmath=FASTMATH)
def _share(d2, R):
    """(dsigma in voxel^2, radius of the contact point in voxels, distance d in voxels) of a
    voxel at distance^2 d2: the intersection disc for voxels straddling the burr surface; the
    voxel sphere's cross-section pi r^2 at the voxel's own position for voxels fully inside
    the burr."""
    r = R_VOXEL
    d = math.sqrt(d2)
    if r < R and d <= R - r:
        return PI_R2, d, d
    return disc_area(d, R, r), 0.5 * d + (R * R - r * r) / (2.0 * d), d


@nb.njit(cache=True, fastmath=FASTMATH)
def _gather(m, opt, d, defined, lo, hi):
    """Collect the occupied voxels in the burr ball (d < R + r) on the bone side (along -n)
    into the scratch, in grid order (i, then j, then k). Returns (count, max xi^2)."""
    dens, voxels = d.density, d.voxels
    cx, cy, cz = opt.centre[0], opt.centre[1], opt.centre[2]
    nvec = opt.normal
    R = m.radius
    r = R_VOXEL
    reach2 = (R + r) * (R + r)
    n = 0
    xmax = 0.0
    for i in range(lo[0], hi[0] + 1):
        dx = i - cx
        for j in range(lo[1], hi[1] + 1):
            dy = j - cy
            dxy = dx * dx + dy * dy
            if dxy >= reach2:
                continue
            half = math.sqrt(reach2 - dxy)
            k0 = max(lo[2], int(math.ceil(cz - half)))
            k1 = min(hi[2], int(math.floor(cz + half)))
            for k in range(k0, k1 + 1):
                if dens[i, j, k] == 0:
                    continue
                dz = k - cz
                d2 = dxy + dz * dz
                if d2 >= reach2:
                    continue
                xi2 = 0.0
                if defined:
                    along = -(dx * nvec[0] + dy * nvec[1] + dz * nvec[2])
                    if along <= 0.0:
                        continue
                    xi2 = d2 - along * along
                rec = voxels[n]
                rec.i = i
                rec.j = j
                rec.k = k
                rec.dist2 = d2
                rec.xi2 = xi2
                xmax = max(xmax, xi2)
                n += 1
    return n, xmax


@nb.njit(cache=True, fastmath=FASTMATH)
def _weights(d, defined, count, a2, R):
    """Hertz profile weight sqrt(1 - xi^2/a^2) of each gathered voxel (1 with no normal),
    a2 = a^2 > every xi^2; returns the sum of the shares times their weights."""
    voxels = d.voxels
    wsum = 0.0
    for n in range(count):
        rec = voxels[n]
        ds, rc, dist = _share(rec.dist2, R)
        rec.share = ds
        rec.radius = rc
        rec.dist = dist
        w = math.sqrt(1.0 - rec.xi2 / a2) if defined else 1.0
        rec.weight = w
        wsum += rec.share * w
    return wsum


@nb.njit(cache=True, fastmath=FASTMATH, inline="always")
def _grow_box(t, i, j, k):
    """Grow the tally's changed box to hold voxel (i, j, k)."""
    t.lo_i = min(t.lo_i, i)
    t.lo_j = min(t.lo_j, j)
    t.lo_k = min(t.lo_k, k)
    t.hi_i = max(t.hi_i, i)
    t.hi_j = max(t.hi_j, j)
    t.hi_k = max(t.hi_k, k)


@nb.njit(cache=True, fastmath=FASTMATH, inline="always")
def _erode_brick(bricks, i, j, k, dec):
    """Subtract a voxel's decrement from its brick's moments: m0 -= dec, m1 -= dec (x - c),
    c the brick centre (integer counts times half-integer offsets: exact in float64)."""
    mom, start, shift, by, bz = bricks
    if shift < 0:
        return
    s = 1 << shift
    half = 0.5 * (s - 1)
    bi = i >> shift
    bj = j >> shift
    bk = k >> shift
    q = start + ((bi * by + bj) * bz + bk) * 4
    mom[q] -= dec
    mom[q + 1] -= dec * (i - (bi * s + half))
    mom[q + 2] -= dec * (j - (bj * s + half))
    mom[q + 3] -= dec * (k - (bk * s + half))


@nb.njit(cache=True, fastmath=FASTMATH)
def _apply(m, opt, d, count, p_scale):
    """Friction, frictional power and (with opt.erode) erosion of each gathered voxel under
    the pressure p_scale * weight (Pa); eroded voxels leave their bricks too."""
    voxels, t = d.voxels, d.tally[0]
    cx, cy, cz = opt.centre[0], opt.centre[1], opt.centre[2]
    omega, vtool = opt.omega, opt.velocity
    voxel, mu = m.voxel, m.mu
    area_scale = voxel * voxel
    s_state = d.rng[0]
    for n in range(count):
        rec = voxels[n]
        ds = rec.share
        if ds <= 0.0:
            continue
        i = rec.i
        j = rec.j
        k = rec.k
        dist = rec.dist
        rp = rec.radius / dist * voxel if dist > 0.0 else 0.0
        px = (i - cx) * rp
        py = (j - cy) * rp
        pz = (k - cz) * rp
        vx = omega[1] * pz - omega[2] * py + vtool[0]
        vy = omega[2] * px - omega[0] * pz + vtool[1]
        vz = omega[0] * py - omega[1] * px + vtool[2]
        sp = math.sqrt(vx * vx + vy * vy + vz * vz)
        fn = p_scale * rec.weight * ds * area_scale  # N of normal load on this voxel
        if sp > 0.0:
            f = mu * fn / sp
            fx = -f * vx
            fy = -f * vy
            fz = -f * vz
            t.force_x += fx
            t.force_y += fy
            t.force_z += fz
            t.torque_x += py * fz - pz * fy
            t.torque_y += pz * fx - px * fz
            t.torque_z += px * fy - py * fx
        power = mu * fn * sp
        t.power += power
        t.voxels += 1.0
        t.area += ds * area_scale
        if opt.erode:
            dens = d.density
            c = dens[i, j, k]
            e = m.kmass * power * opt.dt
            t.expected += e
            dec = math.floor(e)
            s_state, u = uniform01(s_state)
            if u < e - dec:
                dec += 1.0
            if dec > c:
                dec = float(c)
            if dec > 0.0:
                dens[i, j, k] = np.uint8(int(c) - int(dec))
                _erode_brick(d.bricks, i, j, k, dec)
                t.removed += dec
                _grow_box(t, i, j, k)
    d.rng[0] = s_state


@nb.njit(cache=True, fastmath=FASTMATH)
def contact_pass(m, opt, d):
    """Hertz pressure, friction and erosion over the burr's contact voxels; fills d.tally
    and the changed box, and keeps d.bricks' moments equal to the eroded density's.

    Grid units in, SI out. Contact voxels: the occupied voxels in the burr ball on the bone
    side (along -n; all of them if the normal is zeros, i.e. undefined), each with a surface
    share dsigma: the intersection disc for voxels straddling the burr surface, and pi r^2
    for voxels already fully inside the burr (material the burr has sunk into, e.g. soft
    tissue, is cut too). The pressure P(xi) = P0 sqrt(1 - xi^2/a^2) (xi: distance from the
    axis through the burr centre along -n; uniform if n is undefined) is normalised so that
    sum P dsigma = load = |F_e| (N). The contact radius is a = max(a_hertz, xi_max + r),
    xi_max the widest contact voxel: on a flat surface this is the cap's chord, and it keeps
    an irregular (partly eroded) contact patch loaded. Each contact point p slides at
    v = omega x p + velocity, gets friction mu P dsigma against v and dissipates
    phi = mu P |v| dsigma (W); with ``erode`` its counter decreases by kmass * phi * dt, as
    an integer decrement by Russian roulette (floor, plus one with probability equal to the
    fractional part), never below 0.
    """
    lo = np.zeros(3, np.int64)
    hi = np.zeros(3, np.int64)
    nvec = opt.normal
    defined = not (nvec[0] == 0.0 and nvec[1] == 0.0 and nvec[2] == 0.0)
    _reset(d)
    c = opt.centre
    R = m.radius
    cap_box(c[0], c[1], c[2], R, nvec, -R_VOXEL / R, lo, hi, d.density.shape)  # bone-side hemisphere
    count, xi2max = _gather(m, opt, d, defined, lo, hi)
    a = max(opt.a_hertz, math.sqrt(xi2max) + R_VOXEL)
    wsum = _weights(d, defined, count, a * a, R)
    if wsum <= 0.0 or opt.load <= 0.0:
        return
    p_scale = opt.load / (wsum * m.voxel * m.voxel)  # Pa per unit weight
    _apply(m, opt, d, count, p_scale)

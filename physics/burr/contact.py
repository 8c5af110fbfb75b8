"""Burr-bone contact: voxel-sphere overlap volumes, moments, penetration, forces, erosion.

Agus, Giachetti, Gobbetti, Zanetti, Zorcolo, "Real-time haptic and visual simulation of
bone dissection", IEEE VR 2002 / Presence 12(1) 2003 (the seed 001's burr-bone model).

All kernels work in grid units (lengths in voxels, volumes in voxel^3, density in counter
units 0..255); :mod:`physics.burr.loop` converts to SI. A voxel is taken as the sphere of
equal volume, radius ``R_VOXEL = (3 / (4 pi))^(1/3)`` voxels, centred on the voxel centre,
so a voxel fully inside the burr contributes exactly its volume (1 voxel^3).

* overlap of the burr (radius R) and a voxel sphere (radius r) at centre distance d
  (the seed's delta v(d), exact sphere-sphere lens volume):
  pi (R + r - d)^2 (d^2 + 2 d r - 3 r^2 + 2 d R + 6 r R - 3 R^2) / (12 d);
* the disc of the two spheres' intersection circle (the seed's delta sigma(d), the voxel's
  share of the burr surface): pi (2 (R^2 + r^2) - d^2 - (r^2 - R^2)^2 / d^2) / 4, its plane
  at distance d / 2 + (R^2 - r^2) / (2 d) from the burr centre;
* m0 = sum rho_i dv_i, m1 = sum rho_i dv_i (x_i - x_c); n = -m1 / |m1|;
* h from m0 = pi rho0 R^3 (h/R)^2 (1 - h/(3R)), solved in closed form (trigonometric root).
"""

from __future__ import annotations

import math

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


@nb.njit(cache=True, fastmath=FASTMATH)
def voxel_moments(dens, cx, cy, cz, R, i0, i1, j0, j1, k0, k1):
    """(m0, m1x, m1y, m1z) of the voxels in the grid box [i0..i1] x [j0..j1] x [k0..k1],
    each a sphere of radius R_VOXEL weighted by its lens overlap with the burr (radius R,
    centre (cx, cy, cz), grid units)."""
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
    m0, mx, my, mz = voxel_moments(dens, cx, cy, cz, R, i0, i1, j0, j1, k0, k1)
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


@nb.njit(cache=True, fastmath=FASTMATH)
def _gather(dens, cx, cy, cz, R, nvec, defined, lo, hi, idx, geo):
    """Collect the occupied voxels in the burr ball (d < R + r) on the bone side (along -n):
    idx[m] = (i, j, k), geo[m] = (d^2, xi^2). Returns (count, max xi^2)."""
    r = R_VOXEL
    reach2 = (R + r) * (R + r)
    m = 0
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
                idx[m, 0] = i
                idx[m, 1] = j
                idx[m, 2] = k
                geo[m, 0] = d2
                geo[m, 1] = xi2
                xmax = max(xmax, xi2)
                m += 1
    return m, xmax


@nb.njit(cache=True, fastmath=FASTMATH)
def _share(d2, R):
    """(dsigma in voxel^2, radius of the contact point in voxels) of a voxel at distance^2 d2:
    the intersection disc for voxels straddling the burr surface; the voxel sphere's
    cross-section pi r^2 at the voxel's own position for voxels fully inside the burr."""
    r = R_VOXEL
    d = math.sqrt(d2)
    if r < R and d <= R - r:
        return PI_R2, d
    return disc_area(d, R, r), 0.5 * d + (R * R - r * r) / (2.0 * d)


@nb.njit(cache=True, fastmath=FASTMATH)
def _apply(dens, cx, cy, cz, R, defined, a2, count, idx, geo, p_scale, mu, omega, vtool, voxel, kmass, dt,
           erode, rng, box, out):  # fmt: skip
    area_scale = voxel * voxel
    s_state = rng[0]
    for m in range(count):
        d2 = geo[m, 0]
        xi2 = geo[m, 1]
        if defined and xi2 >= a2:
            continue
        ds, rc = geo[m, 2], geo[m, 3]  # surface share and contact radius, from surface_pass
        if ds <= 0.0:
            continue
        w = math.sqrt(1.0 - xi2 / a2) if defined else 1.0
        i = idx[m, 0]
        j = idx[m, 1]
        k = idx[m, 2]
        d = math.sqrt(d2)
        rp = rc / d * voxel if d > 0.0 else 0.0
        px = (i - cx) * rp
        py = (j - cy) * rp
        pz = (k - cz) * rp
        vx = omega[1] * pz - omega[2] * py + vtool[0]
        vy = omega[2] * px - omega[0] * pz + vtool[1]
        vz = omega[0] * py - omega[1] * px + vtool[2]
        sp = math.sqrt(vx * vx + vy * vy + vz * vz)
        fn = p_scale * w * ds * area_scale  # N of normal load on this voxel
        if sp > 0.0:
            f = mu * fn / sp
            fx = -f * vx
            fy = -f * vy
            fz = -f * vz
            out[0] += fx
            out[1] += fy
            out[2] += fz
            out[3] += py * fz - pz * fy
            out[4] += pz * fx - px * fz
            out[5] += px * fy - py * fx
        power = mu * fn * sp
        out[6] += power
        out[9] += 1.0
        out[10] += ds * area_scale
        if erode:
            c = dens[i, j, k]
            e = kmass * power * dt
            out[7] += e
            dec = math.floor(e)
            s_state, u = uniform01(s_state)
            if u < e - dec:
                dec += 1.0
            if dec > c:
                dec = float(c)
            if dec > 0.0:
                dens[i, j, k] = np.uint8(int(c) - int(dec))
                out[8] += dec
                box[0] = min(box[0], i)
                box[1] = min(box[1], j)
                box[2] = min(box[2], k)
                box[3] = max(box[3], i)
                box[4] = max(box[4], j)
                box[5] = max(box[5], k)
    rng[0] = s_state


@nb.njit(cache=True, fastmath=FASTMATH)
def surface_pass(
    dens,
    cx,
    cy,
    cz,
    R,
    nvec,
    a_hertz,
    load,
    mu,
    omega,
    vtool,
    voxel,
    kmass,
    dt,
    erode,
    rng,
    box,
    out,
    idx,
    geo,
):
    """Hertz pressure, friction and erosion over the burr's contact voxels.

    Grid units in, SI out. Contact voxels: the occupied voxels in the burr ball on the bone
    side (along -n; all of them if the normal nvec is zeros, i.e. undefined), each with a
    surface share dsigma: the seed's intersection disc for voxels straddling the burr surface,
    and pi r^2 for voxels already fully inside the burr (material the burr has sunk into,
    e.g. soft tissue, is cut too). The pressure P(xi) = P0 sqrt(1 - xi^2/a^2) (xi: distance
    from the axis through the burr centre along -n; uniform if n is undefined) is normalised
    so that sum P dsigma = load = |F_e| (N). The contact radius is a = max(a_hertz,
    xi_max + r), xi_max the widest contact voxel: on a flat surface this is the cap's chord,
    and it keeps an irregular (partly eroded) contact patch loaded. omega (rad/s, vector) and
    vtool (m/s): each contact point p slides at v = omega x p + vtool, gets friction
    mu P dsigma against v and dissipates phi = mu P |v| dsigma (W); with ``erode`` its
    counter decreases by kmass * phi * dt (kmass: counter units per joule), as an integer
    decrement by Russian roulette (floor, plus one with probability equal to the
    fractional part), never below 0.

    idx (int64, (N, 3)) and geo (float64, (N, 4): d^2, xi^2, dsigma, contact radius):
    scratch, N >= voxels in the ball's box.
    out: [Fx, Fy, Fz, Tx, Ty, Tz, power W, expected decrement (counts), actual decrement
    (counts), contact voxels, sum dsigma (m^2)]; box: the grid box of the changed voxels.
    """
    shape = dens.shape
    lo = np.zeros(3, np.int64)
    hi = np.zeros(3, np.int64)
    defined = not (nvec[0] == 0.0 and nvec[1] == 0.0 and nvec[2] == 0.0)
    for q in range(out.size):
        out[q] = 0.0
    box[0] = shape[0]
    box[1] = shape[1]
    box[2] = shape[2]
    box[3] = -1
    box[4] = -1
    box[5] = -1
    cap_box(cx, cy, cz, R, nvec, -R_VOXEL / R, lo, hi, shape)  # the bone-side hemisphere
    count, xi2max = _gather(dens, cx, cy, cz, R, nvec, defined, lo, hi, idx, geo)
    a = max(a_hertz, math.sqrt(xi2max) + R_VOXEL)
    a2 = a * a
    wsum = 0.0
    for m in range(count):
        if defined and geo[m, 1] >= a2:
            continue
        ds, rc = _share(geo[m, 0], R)
        geo[m, 2] = ds  # kept for _apply
        geo[m, 3] = rc
        wsum += ds * (math.sqrt(1.0 - geo[m, 1] / a2) if defined else 1.0)
    if wsum <= 0.0 or load <= 0.0:
        return
    p_scale = load / (wsum * voxel * voxel)  # Pa per unit weight
    _apply(dens, cx, cy, cz, R, defined, a2, count, idx, geo, p_scale, mu, omega, vtool, voxel, kmass, dt,
           erode, rng, box, out)  # fmt: skip

"""Builders of the plate and board models of the scrape and roll patches.

The shipped ``steel_plate_model.toml`` and ``wood_board_model.toml`` are the output of
:func:`steel_plate_model` and :func:`wood_board_model` (a test checks it); regenerate
them with ``python -m patches.models_surface``.

Both are simply supported rectangular Kirchhoff plates with analytic modes
(Leissa, "Vibration of Plates", NASA SP-160, 1969, ch. 4 and 11):

    f_mn = (pi / 2) sqrt((D1 (m/a)^4 + 2 H (m/a)^2 (n/b)^2 + D2 (n/b)^4) / (rho h)),
    phi_mn(x, y) = sin(m pi x / a) sin(n pi y / b),  modal mass M = rho h a b / 4,

with D_i = E_i h^3 / (12 (1 - nu^2)) and, for the orthotropic (wood) board, Huber's
H = sqrt(D1 D2); isotropic plates have D1 = D2 = H = D, i.e. the familiar
f_mn = (pi / 2) sqrt(D / (rho h)) ((m/a)^2 + (n/b)^2).

Gains: the velocity at a fixed pickup point q (a contact microphone) per N s of impulse
at contact point p, a[p, k] = phi_k(p) phi_k(q) / M (m/s per N s; ModalBank renders each
mode as sin instead of cos, same magnitude). Driving-point rows (what a closed-loop contact
such as HuntCrossleyImpact or Friction pushes against): the displacement at p itself per
N s at p, phi_k(p)^2 / (M w_k) (m per N s), the convention of every closed loop. Decay
d = d0 + pi f eta (1/s) for a loss factor eta (internal friction) plus a constant d0 (air
and supports).

Sound texture along a track: besides the named track points t0 .. t{n-1}, a track may carry
``between`` further points in each of its intervals (``t{i}_{j}``, the fraction j / (between
+ 1) of the way from t{i} to t{i+1}; stored after the named points, so t{i} stays row i).
ModalBank interpolates gains between neighbouring points linearly (a 1-D mesh's shape
functions: {vertices = ["t2_3", "t2_4"], weights = [0.5, 0.5]} is the midpoint). Along a
straight track a mode shape is a sum of two sinusoids whose wavenumbers are at most the
plate's bending wavenumber k = (omega^2 rho h / D)^(1/4); linear interpolation at a
midpoint then errs by at most 1 - cos(k s / 2) of the mode's peak gain (spacing s).

Anywhere on the plate: each model also carries its mode shapes (jassy.surface.PlateSurface:
the orders (m, n), phi_k(q) / M and 1 / (M w_k)), so a location ``{surface = [x/a, y/b]}``
gets exactly these gains and driving-point gains at any point, not only at the rows.
"""

from __future__ import annotations

from typing import NamedTuple

import numpy as np

from jassy.modal_model import ModalModel
from jassy.surface import PlateSurface, plate_shapes


class Plate(NamedTuple):
    """A simply supported rectangular plate, orthotropic along its sides (SI units)."""

    a: float  #: side along x (m)
    b: float  #: side along y (m)
    h: float  #: thickness (m)
    rho: float  #: density (kg/m^3)
    e1: float  #: Young's modulus along a (Pa)
    e2: float  #: Young's modulus along b (Pa)
    nu: float  #: Poisson's ratio
    eta: float  #: loss factor
    d0: float  #: constant decay (1/s): air and supports


def ss_plate_model(
    plate: Plate,
    track: tuple[tuple[float, float], tuple[float, float]] | None,
    pickup: tuple[float, float],
    n_points: int = 9,
    n_modes: int = 300,
    f_max: float = 20000.0,
    name: str = "plate",
    points: dict[str, tuple[float, float]] | None = None,
    between: int = 0,
    digits: int | None = None,
) -> ModalModel:
    """The lowest ``n_modes`` modes below ``f_max`` Hz of a simply supported ``plate``.

    Locations: ``n_points`` points t0 .. t{n-1} evenly spaced on the straight ``track``
    between two (x/a, y/b) points, with ``between`` more in each interval (module docstring),
    or the named (x/a, y/b) ``points``; pickup: (x/a, y/b) of the listening point. ``digits``:
    round gains to that many significant digits (smaller files for dense tracks).
    """
    a, b, h, rho, e1, e2, nu, eta, d0 = plate
    d1 = e1 * h**3 / (12 * (1 - nu**2))
    d2 = e2 * h**3 / (12 * (1 - nu**2))
    hub = np.sqrt(d1 * d2)
    orders = np.arange(1, 200)
    m, n = (g.reshape(-1) for g in np.meshgrid(orders, orders, indexing="ij"))
    km, kn = m / a, n / b
    freqs = np.pi / 2 * np.sqrt((d1 * km**4 + 2 * hub * km**2 * kn**2 + d2 * kn**4) / (rho * h))
    order = np.argsort(freqs, kind="stable")
    order = order[freqs[order] < f_max][:n_modes]
    m, n, freqs = m[order], n[order], freqs[order]
    mass = rho * h * a * b / 4

    if points is None:
        w, names = track_points(n_points, between)
        (u0, v0), (u1, v1) = track
        at = plate_shapes(m, n, u0 + w * (u1 - u0), v0 + w * (v1 - v0), pi_last=True)
    else:
        uv = np.array(list(points.values()), dtype=np.float64)
        at = plate_shapes(m, n, uv[:, 0], uv[:, 1], pi_last=True)
        names = tuple(points)
    listen = plate_shapes(m, n, pickup[0], pickup[1], pi_last=True)
    gains = at * listen / mass  # strike to pickup: signed
    # at the strike point itself, for contacts in a closed loop: a displacement receptance
    driving = at * at / (mass * 2 * np.pi * freqs)
    if digits is not None:
        gains, driving = (
            np.array([float(f"{x:.{digits}g}") for x in g.flat]).reshape(g.shape) for g in (gains, driving)
        )
    surface = PlateSurface((a, b), m, n, listen / mass, 1.0 / (mass * 2 * np.pi * freqs))
    return ModalModel(freqs, d0 + np.pi * freqs * eta, gains, names, name, driving=driving, surface=surface)


def track_points(n_points: int, between: int) -> tuple[np.ndarray, tuple[str, ...]]:
    """Fractions (0..1) along a track and names: t0 .. t{n-1} first, then ``between`` points
    t{i}_{j} in each interval i."""
    named = np.linspace(0.0, 1.0, n_points)
    step = 1.0 / ((n_points - 1) * (between + 1))
    inner = [(i, j) for i in range(n_points - 1) for j in range(1, between + 1)]
    w = np.concatenate([named, [named[i] + j * step for i, j in inner]])
    return w, tuple(f"t{i}" for i in range(n_points)) + tuple(f"t{i}_{j}" for i, j in inner)


def tin_sheet_model() -> ModalModel:
    """A 0.5 x 0.35 m panel of tinplate (steel, 0.8 mm), simply supported on its edges (nailed
    to a frame): all 1106 modes below 16 kHz (from 23 Hz), light damping (loss factor 1e-3 plus
    3 /s of radiation and fixing losses). Locations: a 4 x 3 grid ``x{i}y{j}`` at
    x/a = (i + 0.5)/4, y/b = (j + 0.5)/3, for impacts spread over the sheet (rain, hail)."""
    grid = {f"x{i}y{j}": ((i + 0.5) / 4, (j + 0.5) / 3) for i in range(4) for j in range(3)}
    return ss_plate_model(
        Plate(a=0.5, b=0.35, h=0.0008, rho=7850.0, e1=200e9, e2=200e9, nu=0.3, eta=1e-3, d0=3.0), track=None,
        pickup=(0.31, 0.43), n_modes=2000, f_max=16000.0, name="tin_sheet", points=grid,
    )  # fmt: skip


def steel_plate_model() -> ModalModel:
    """A 0.6 x 0.45 m steel plate, 2 mm thick: the 675 modes below 16 kHz (from 37 Hz), ringing
    for seconds. Track t0 .. t8 with 7 points between each pair (65 points, 7.5 mm apart: more
    than 4 per bending wavelength at 16 kHz, 35 mm); gains to 7 significant digits."""
    return ss_plate_model(
        Plate(a=0.6, b=0.45, h=0.002, rho=7850.0, e1=200e9, e2=200e9, nu=0.3, eta=2e-4, d0=1.5),
        track=((0.12, 0.3), (0.88, 0.62)),
        pickup=(0.37, 0.71),
        n_modes=1000,
        f_max=16000.0,
        name="steel_plate",
        between=7,
        digits=7,
    )


def wood_board_model() -> ModalModel:
    """A 0.8 x 0.3 m pine board, 18 mm thick (E along the grain 10 GPa, across 0.8 GPa):
    the 160 modes below 20 kHz (190 Hz up), loss factor 0.015 (short, dull decays). Track
    t0 .. t8 with 3 points between each pair (33 points, 20 mm apart: 4 per bending
    wavelength along the grain at 20 kHz, 90 mm); gains to 7 significant digits."""
    return ss_plate_model(
        Plate(a=0.8, b=0.3, h=0.018, rho=450.0, e1=10e9, e2=0.8e9, nu=0.3, eta=0.015, d0=8.0),
        track=((0.1, 0.5), (0.9, 0.4)),
        pickup=(0.33, 0.62),
        n_modes=200,
        name="wood_board",
        between=3,
        digits=7,
    )


def door_model() -> ModalModel:
    """A closed solid-pine door, 0.8 x 2.0 m, 40 mm thick (grain vertical: E 10 GPa along it,
    0.8 GPa across), its edges held by the frame (simply supported): the 399 modes below
    16 kHz (from 62 Hz), loss factor 0.02 (a knock is a short thud). Points: ``centre``,
    ``upper_panel`` and ``lower_panel`` (on the centre line at 3/4 and 1/4 of the height),
    ``latch_edge`` (beside the handle, 0.95 m up) and ``hinge_edge``; heard from 1 m in front."""
    points = {
        "centre": (0.5, 0.5),
        "upper_panel": (0.5, 0.75),
        "lower_panel": (0.5, 0.25),
        "latch_edge": (0.9, 0.475),
        "hinge_edge": (0.08, 0.5),
    }
    return ss_plate_model(
        Plate(a=0.8, b=2.0, h=0.04, rho=450.0, e1=0.8e9, e2=10e9, nu=0.3, eta=0.02, d0=6.0), track=None,
        pickup=(0.4, 0.6), n_modes=1000, f_max=16000.0, name="door", points=points,
    )  # fmt: skip


#: Shipped model files -> builders.
SHIPPED = {
    "steel_plate_model.toml": steel_plate_model,
    "wood_board_model.toml": wood_board_model,
    "tin_sheet_model.toml": tin_sheet_model,
    "door_model.toml": door_model,
}

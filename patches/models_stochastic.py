"""Modal models of the crumple and wok-sizzle patches (builders of the shipped *_model.toml).

Gains follow the project convention: a[p, k] is the displacement impulse response at the
contact point, x(t) = sum_k a_k e^{-d_k t} sin(2 pi f_k t) per 1 N s, i.e. for a mode of
shape Phi_k, modal mass M_k = rho h int Phi_k^2 dA and angular frequency w_k,
a_k = Phi_k(p)^2 / (M_k w_k) (m / (N s)).

* ``paper_sheet_model``: a thin sheet (paper) as a simply supported rectangular plate,
  f_mn = (pi / 2) sqrt(D / (rho h)) ((m / Lx)^2 + (n / Ly)^2), Phi = sin(m pi x / Lx)
  sin(n pi y / Ly), M = rho h Lx Ly / 4 (Leissa, "Vibration of Plates", NASA SP-160, 1969,
  section 4.1). A paper sheet has thousands of modes in the audio band (modal density
  (A / 2) sqrt(rho h / D) = 0.4 per Hz for A4), so a seeded random subset stands for them,
  each kept mode's gain scaled by sqrt(all / kept) to keep the expected power spectrum.
  Paper is light and lossy: decay d = d0 + pi f eta with a high loss factor.
* ``wok_model``: a wok as a shallow spherical shell of base radius a and radius of
  curvature Rc with a free rim, by Soedel's analogy between shallow spherical shells and
  flat plates (W. Soedel, "A natural frequency analogy between spherically curved panels
  and flat plates", J. Sound Vib. 29(4), 457-461, 1973; after Reissner's shallow-shell
  theory): w_shell^2 = w_plate^2 + E / (rho Rc^2), with the mode shapes of the plate. The
  plate is the free circular plate: W = J_n(lambda r / a) + C I_n(lambda r / a), lambda
  the roots of the free-edge conditions (zero bending moment and Kirchhoff shear at r = a;
  Leissa SP-160 section 2.1.3; lambda^2 = 5.358 for two nodal diameters, 9.003 for one
  nodal circle at nu = 0.3; a Ritz solution of the plate's energy functional in the tests
  agrees to 1e-9). Modes with n >= 1 nodal diameters are doublets (cos / sin n phi),
  split by 0.1-0.4 % (a real wok is not axisymmetric: handles, welds, hammering).
  The analogy is exact for shallow shells; a wok is deeper than that, so this is a
  plausible family (the membrane stiffening clusters the low plate modes just above the
  ring frequency sqrt(E / rho) / (2 pi Rc)), not a finite-element result.
"""

from __future__ import annotations

import numpy as np
from scipy.optimize import brentq
from scipy.special import ive, jv, jvp

from jassy.modal_model import ModalModel


def paper_sheet_model(
    lx: float = 0.297,
    ly: float = 0.210,
    thickness: float = 1.0e-4,
    youngs: float = 3.0e9,
    density: float = 700.0,
    poisson: float = 0.3,
    f_min: float = 150.0,
    f_max: float = 16000.0,
    n_modes: int = 240,
    loss: float = 0.05,
    air_decay: float = 40.0,
    seed: int = 11,
) -> ModalModel:
    """A4 paper (80 g/m^2-like) as a simply supported plate: ``n_modes`` random modes in
    [f_min, f_max] Hz, decay ``air_decay`` + pi f ``loss`` (1/s).

    Points: ``mean`` (the mean of Phi^2 over the sheet, 1/4: a micro-impact anywhere on
    the sheet), and ``p0`` .. ``p3`` at fixed positions.
    """
    rigidity = youngs * thickness**3 / (12.0 * (1.0 - poisson**2))
    mass_area = density * thickness
    c = 0.5 * np.pi * np.sqrt(rigidity / mass_area)
    m_max = int(np.sqrt(f_max / c) * lx) + 1
    n_max = int(np.sqrt(f_max / c) * ly) + 1
    m, n = np.meshgrid(np.arange(1, m_max + 1), np.arange(1, n_max + 1), indexing="ij")
    f = c * ((m / lx) ** 2 + (n / ly) ** 2)
    band = (f >= f_min) & (f <= f_max)
    m, n, f = m[band], n[band], f[band]
    rng = np.random.default_rng(seed)
    pick = np.sort(rng.choice(f.size, size=min(n_modes, f.size), replace=False))
    weight = np.sqrt(f.size / pick.size)
    m, n, f = m[pick], n[pick], f[pick]
    order = np.argsort(f, kind="stable")
    m, n, f = m[order], n[order], f[order]
    modal_mass = mass_area * lx * ly / 4.0
    omega = 2.0 * np.pi * f
    positions = [(0.31, 0.42), (0.55, 0.23), (0.12, 0.77), (0.71, 0.64)]  # fractions of (lx, ly)
    rows = [np.full(f.size, 0.25)]
    rows += [(np.sin(m * np.pi * x) * np.sin(n * np.pi * y)) ** 2 for x, y in positions]
    gains = weight * np.array(rows) / (modal_mass * omega)
    decays = air_decay + np.pi * f * loss
    return ModalModel(f, decays, gains, ("mean", "p0", "p1", "p2", "p3"), "paper_sheet")


def _free_plate_rows(n: int, lam: np.ndarray, nu: float):
    """Bending moment and Kirchhoff shear at the rim for J_n and (scaled) I_n, per lambda.

    W = A J_n(lam rho) + C I_n(lam rho), rho = r / a. With ' = d/drho at rho = 1:
    M ~ W'' + nu (W' - n^2 W), V ~ (lap W)' - (1 - nu) n^2 (W' - W), lap J = -lam^2 J,
    lap I = lam^2 I. I_n is scaled by e^-lam (ive) to keep the numbers finite.
    """
    j, jd = jv(n, lam), jvp(n, lam)
    jdd = -jd / lam - (1.0 - n * n / lam**2) * j
    i = ive(n, lam)
    idp = 0.5 * (ive(n - 1, lam) + ive(n + 1, lam))
    idd = -idp / lam + (1.0 + n * n / lam**2) * i
    mj = lam**2 * jdd + nu * (lam * jd - n * n * j)
    mi = lam**2 * idd + nu * (lam * idp - n * n * i)
    vj = -(lam**3) * jd - (1.0 - nu) * n * n * (lam * jd - j)
    vi = lam**3 * idp - (1.0 - nu) * n * n * (lam * idp - i)
    return mj, mi, vj, vi


def free_plate_roots(n: int, count: int, nu: float = 0.3, lam_max: float = 80.0) -> np.ndarray:
    """The first ``count`` nonzero frequency parameters lambda (= k a) of a free circular
    plate with n nodal diameters (w = lambda^2 / a^2 sqrt(D / (rho h)))."""

    def det(lam):
        mj, mi, vj, vi = _free_plate_rows(n, lam, nu)
        return mj * vi - mi * vj

    grid = np.linspace(0.5, lam_max, 8000)
    values = det(grid)
    roots = []
    for k in np.flatnonzero(np.sign(values[:-1]) != np.sign(values[1:])):
        roots.append(brentq(det, grid[k], grid[k + 1], xtol=1e-13))
        if len(roots) == count:
            break
    return np.asarray(roots)


def free_plate_shape(n: int, lam: float, rho: np.ndarray, nu: float = 0.3) -> np.ndarray:
    """Radial shape W(rho) of the free-plate mode (n, lam), up to scale."""
    mj, mi, _, _ = _free_plate_rows(n, lam, nu)
    c = -mj / mi  # coefficient of ive(n, lam rho): I_n(lam rho) = ive * e^{lam rho}
    return jv(n, lam * rho) + c * ive(n, lam * rho) * np.exp(lam * (rho - 1.0))


WOK_POINTS = ("rim", "wall", "bottom")
#: Radial positions (r / a) and azimuth (rad) of the named points of the wok.
WOK_RADII = (0.95, 0.6, 0.12)
WOK_AZIMUTH = 0.3


def wok_model(
    radius: float = 0.18,
    curvature: float = 0.6,
    thickness: float = 1.8e-3,
    youngs: float = 200e9,
    density: float = 7850.0,
    poisson: float = 0.3,
    f_max: float = 12000.0,
    max_diameters: int = 40,
    max_circles: int = 12,
    loss: float = 1.0e-3,
    base_decay: float = 2.0,
    seed: int = 5,
) -> ModalModel:
    """A carbon-steel wok (base radius ``radius`` m, radius of curvature ``curvature`` m)
    as a shallow spherical shell with a free rim (Soedel's analogy, see the module).

    Frequencies below ``f_max``; decay ``base_decay`` + pi f ``loss`` (1/s); points
    rim, wall and bottom (r / a = 0.95, 0.6, 0.12, at 0.3 rad from the doublet axes).
    """
    rigidity = youngs * thickness**3 / (12.0 * (1.0 - poisson**2))
    mass_area = density * thickness
    plate = np.sqrt(rigidity / mass_area) / (2.0 * np.pi * radius**2)  # f = lambda^2 * plate
    ring = np.sqrt(youngs / density) / (2.0 * np.pi * curvature)
    rho = np.linspace(0.0, 1.0, 4001)
    rng = np.random.default_rng(seed)
    freqs, shapes_at, masses = [], [], []
    for n in range(max_diameters + 1):
        lams = free_plate_roots(n, max_circles, poisson, lam_max=np.sqrt(f_max / plate) + 2.0)
        for lam in lams:
            f = np.hypot(lam**2 * plate, ring)
            if f > f_max:
                break
            w = free_plate_shape(n, lam, rho, poisson)
            at = free_plate_shape(n, lam, np.asarray(WOK_RADII), poisson)
            radial = np.trapezoid(w**2 * rho, rho)  # int W^2 rho drho
            if n == 0:
                freqs.append(f)
                shapes_at.append(at)
                masses.append(mass_area * radius**2 * 2.0 * np.pi * radial)
            else:
                split = rng.uniform(0.001, 0.004)
                for sign, ang in ((-1.0, np.cos(n * WOK_AZIMUTH)), (1.0, np.sin(n * WOK_AZIMUTH))):
                    freqs.append(f * (1.0 + sign * split / 2.0))
                    shapes_at.append(at * ang)
                    masses.append(mass_area * radius**2 * np.pi * radial)
    freqs = np.asarray(freqs)
    order = np.argsort(freqs, kind="stable")
    freqs = freqs[order]
    phi = np.asarray(shapes_at)[order].T  # (points, modes)
    masses = np.asarray(masses)[order]
    gains = phi**2 / (masses * 2.0 * np.pi * freqs)
    decays = base_decay + np.pi * freqs * loss
    return ModalModel(freqs, decays, gains, WOK_POINTS, "wok")


def wok_deep_model() -> ModalModel:
    """The tossing wok of the ``wok`` scene (patches/wok.py): rim radius 0.18 m, radius of
    curvature 0.35 m (5 cm deep; the shallow-shell analogy is stretched here)."""
    model = wok_model(radius=0.18, curvature=0.35)
    model.name = "wok_deep"
    return model


SHIPPED = {
    "paper_sheet_model.toml": paper_sheet_model,
    "wok_model.toml": wok_model,
    "wok_deep_model.toml": wok_deep_model,
}

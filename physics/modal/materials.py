"""Isotropic linear-elastic materials with a damping law for modal models.

Each material has Young's modulus E (Pa), Poisson's ratio nu, density rho (kg/m^3) and a
damping law giving the decay rate (1/s, amplitude envelope e^{-d t}) of a mode of frequency f:

    d(f) = d0 + pi * eta * f + 0.5 * beta * (2 pi f)^2

* ``eta`` is the loss factor (structural damping; van den Doel & Pai's internal friction
  tan(phi), FoleyAutomatic d = pi f tan(phi)); a mode of loss factor eta has Q = 1/eta.
* ``d0`` is a frequency-independent rate (air/support damping), equal to alpha/2 for mass-
  proportional Rayleigh damping C = alpha M.
* ``beta`` is stiffness-proportional Rayleigh damping C = beta K, which adds
  d = beta omega^2 / 2 (viscous losses growing fast with frequency).

So d0 and beta together are Rayleigh damping (zeta_k = alpha/(2 omega_k) + beta omega_k / 2,
d_k = zeta_k omega_k), and eta is the loss-factor law; the table uses d0 + eta.

Values are typical room-temperature figures: moduli and densities from handbooks (Ashby,
"Materials Selection in Mechanical Design"; CRC Handbook), loss factors from Cremer, Heckl &
Petersson, "Structure-Borne Sound", table of material loss factors (steel 1e-4..6e-4,
aluminium ~1e-4, glass 6e-4..2e-3, wood 8e-3..1e-2, plexiglass 2e-2..4e-2), and for bone
(cortical, wet) Lakes, "Viscoelastic properties of cortical bone". They are starting points to
tweak, not measurements of a particular object; wood is treated as isotropic (along-grain E
would be ~10-15 GPa, across ~1 GPa).
"""

from __future__ import annotations

import math
from dataclasses import dataclass, replace

import numpy as np

from jassy.errors import JassyError


@dataclass(frozen=True)
class Material:
    """Isotropic linear elastic material of every elastic model (modal FEM, BEM deformation):
    Young's modulus E = ``youngs`` (Pa), Poisson ratio nu = ``poisson``, density rho (kg/m^3)
    and damping d(f) = d0 + pi eta f + beta (2 pi f)^2 / 2 (1/s)."""

    name: str
    youngs: float
    poisson: float
    density: float
    loss: float = 0.0
    d0: float = 0.0
    beta: float = 0.0

    def __post_init__(self):
        checks = (
            ("youngs", self.youngs, self.youngs > 0, "> 0 Pa (Young's modulus E)"),
            ("poisson", self.poisson, -1.0 < self.poisson < 0.5, "in (-1, 0.5) (Poisson ratio nu)"),
            ("density", self.density, self.density > 0, "> 0 kg/m^3"),
            ("loss", self.loss, self.loss >= 0, ">= 0"),
            ("d0", self.d0, self.d0 >= 0, ">= 0 1/s"),
            ("beta", self.beta, self.beta >= 0, ">= 0 s"),
        )
        for key, value, ok, expected in checks:
            if not (math.isfinite(value) and ok):
                raise JassyError(f"material {self.name!r}: {key}: expected {expected}, got {value:g}")

    def decay(self, frequencies) -> np.ndarray:
        """Decay rates d(f) in 1/s for frequencies in Hz."""
        f = np.asarray(frequencies, dtype=np.float64)
        w = 2.0 * np.pi * f
        return self.d0 + np.pi * self.loss * f + 0.5 * self.beta * w * w

    @property
    def shear_modulus(self) -> float:
        return self.youngs / (2.0 * (1.0 + self.poisson))

    @property
    def lame(self) -> tuple[float, float]:
        """(lambda, mu) in Pa."""
        e, nu = self.youngs, self.poisson
        return e * nu / ((1 + nu) * (1 - 2 * nu)), e / (2 * (1 + nu))

    @property
    def shear_speed(self) -> float:
        """c_s = sqrt(mu / rho) in m/s."""
        return math.sqrt(self.shear_modulus / self.density)

    @property
    def bar_speed(self) -> float:
        """c = sqrt(E / rho) in m/s (longitudinal waves in a thin rod)."""
        return math.sqrt(self.youngs / self.density)

    def with_overrides(self, **values) -> Material:
        """A copy with the given fields replaced (None values are ignored)."""
        changes = {k: float(v) for k, v in values.items() if v is not None}
        return replace(self, **changes) if changes else self


#: The material table: E (Pa), nu, rho (kg/m^3), loss factor eta, d0 (1/s).
MATERIALS: dict[str, Material] = {
    m.name: m
    for m in (
        Material("steel", 200e9, 0.29, 7850.0, loss=2e-4, d0=0.5),
        Material("aluminium", 69e9, 0.33, 2700.0, loss=1e-4, d0=0.5),
        Material("bronze", 105e9, 0.34, 8700.0, loss=1.5e-4, d0=0.3),
        Material("glass", 70e9, 0.22, 2500.0, loss=1e-3, d0=1.0),
        Material("wood", 12e9, 0.3, 600.0, loss=1e-2, d0=2.0),
        Material("ceramic", 100e9, 0.22, 2400.0, loss=2e-3, d0=1.0),
        Material("plastic", 3e9, 0.36, 1180.0, loss=3e-2, d0=5.0),
        Material("bone", 17e9, 0.3, 1900.0, loss=2e-2, d0=5.0),
    )
}
MATERIALS["aluminum"] = MATERIALS["aluminium"]


def material(name: str, **overrides) -> Material:
    """A material from the table by name, with optional overrides (youngs, poisson, density,
    loss, d0, beta); raises JassyError naming the known materials."""
    key = name.strip().lower()
    if key not in MATERIALS:
        names = ", ".join(sorted(set(MATERIALS) - {"aluminum"}))
        raise JassyError(f"--material: unknown material {name!r}; expected one of {names}")
    return MATERIALS[key].with_overrides(**overrides)


#: What a model's gains measure at a vertex (``jassy modes --radiation``): the driving-point
#: displacement (n . phi)^2 / omega, or that times omega (velocity) or omega^2 (acceleration).
RADIATION = ("displacement", "velocity", "acceleration")

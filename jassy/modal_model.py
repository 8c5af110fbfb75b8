"""Modal models: frequencies (Hz), decay rates (1/s) and gains per surface location.

One impulse of unit strength at location p sounds as sum_k a[p, k] e^{-d_k t} sin(2 pi f_k t).
Gains between locations are interpolated barycentrically (the sound texture map): a
location is a vertex index, a point name, or up to three vertices with weights.

Files: TOML (``frequencies``, ``decays``, ``gains`` = list of rows, optional ``points``),
NPZ (same keys) and JASS ``.sy`` text files (read only). A model fitted to a recording may
carry an ``attack``: the strike's first milliseconds that no mode explains (contact, mallet,
unresolved high modes), samples at ``attack_rate`` Hz per unit impulse, played with each
strike (ugens.AttackSample).
"""

from __future__ import annotations

import math
import os
import tomllib
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import numpy as np

from jassy.errors import ModelError, PatchError


@dataclass(frozen=True)
class Location:
    """Up to three vertices (indices or point names) with barycentric weights."""

    vertices: tuple[int | str, ...]
    weights: tuple[float, ...]


def parse_location(value: Any, where: str) -> Location:
    """Parse a location from a patch value: int, point name, or {vertices, weights}."""
    if isinstance(value, Location):
        return value
    if isinstance(value, bool):
        raise PatchError(
            f"{where}: expected a vertex index, point name or {{vertices, weights}}, got {value!r}"
        )
    if isinstance(value, (int, np.integer)):
        if value < 0:
            raise PatchError(f"{where}: expected a vertex index >= 0, got {value}")
        return Location((int(value),), (1.0,))
    if isinstance(value, str):
        return Location((value,), (1.0,))
    if isinstance(value, dict) and set(value) == {"vertices", "weights"}:
        verts, weights = value["vertices"], value["weights"]
        ok = (
            isinstance(verts, (list, tuple))
            and isinstance(weights, (list, tuple))
            and 1 <= len(verts) <= 3
            and len(verts) == len(weights)
            and all(isinstance(v, (int, str)) and not isinstance(v, bool) for v in verts)
            and all(isinstance(w, (int, float)) and not isinstance(w, bool) for w in weights)
        )
        if not ok:
            raise PatchError(f"{where}: expected 1 to 3 vertices with as many weights, got {value!r}")
        w = np.asarray(weights, dtype=float)
        if np.any(w < 0) or not np.all(np.isfinite(w)) or abs(w.sum() - 1.0) > 1e-6:
            raise PatchError(
                f"{where}.weights: expected non-negative weights summing to 1, got {list(weights)}"
            )
        return Location(tuple(verts), tuple(float(x) for x in w))
    raise PatchError(f"{where}: expected a vertex index, point name or {{vertices, weights}}, got {value!r}")


@dataclass
class ModalModel:
    """Frequencies f[k] (Hz), decay rates d[k] (1/s), gains a[p, k] at P locations."""

    frequencies: np.ndarray
    decays: np.ndarray
    gains: np.ndarray
    points: tuple[str, ...] = ()
    name: str = ""
    source: str = field(default="", compare=False)
    attack: np.ndarray = field(default_factory=lambda: np.zeros(0), compare=False)
    attack_rate: float = 0.0

    def __post_init__(self):
        where = self.source or self.name or "model"
        try:
            self.frequencies = np.asarray(self.frequencies, dtype=np.float64).reshape(-1)
            self.decays = np.asarray(self.decays, dtype=np.float64).reshape(-1)
            gains = np.asarray(self.gains, dtype=np.float64)
        except (TypeError, ValueError) as exc:
            raise ModelError(
                f"{where}: frequencies, decays and gains must be numeric arrays ({exc})"
            ) from None
        if gains.ndim == 1:
            gains = gains[None, :]
        self.gains = gains
        self.points = tuple(self.points)
        self.attack = np.asarray(self.attack, dtype=np.float64).reshape(-1)
        self.attack_rate = float(self.attack_rate)
        self.validate()

    @property
    def n_modes(self) -> int:
        return self.frequencies.shape[0]

    @property
    def n_points(self) -> int:
        return self.gains.shape[0]

    def validate(self, sample_rate: float | None = None) -> None:
        """Raise ModelError unless 0 < f (< Nyquist if sample_rate given), d >= 0, all finite."""
        where = self.source or self.name or "model"
        k = self.n_modes
        if k == 0:
            raise ModelError(f"{where}: frequencies: expected at least one mode")
        if self.decays.shape != (k,):
            raise ModelError(
                f"{where}: decays: expected {k} values (one per mode), got {self.decays.shape[0]}"
            )
        if self.gains.ndim != 2 or self.gains.shape[1] != k:
            raise ModelError(
                f"{where}: gains: expected rows of {k} values (one per mode), got shape {self.gains.shape}"
            )
        for key, arr in (("frequencies", self.frequencies), ("decays", self.decays), ("gains", self.gains)):
            if not np.all(np.isfinite(arr)):
                raise ModelError(f"{where}: {key}: expected finite values, found NaN or Inf")
        if np.any(self.frequencies <= 0):
            i = int(np.argmax(self.frequencies <= 0))
            raise ModelError(f"{where}: frequencies[{i}]: expected > 0 Hz, got {self.frequencies[i]}")
        if np.any(self.decays < 0):
            i = int(np.argmax(self.decays < 0))
            raise ModelError(f"{where}: decays[{i}]: expected >= 0 1/s, got {self.decays[i]}")
        if sample_rate is not None and np.any(self.frequencies >= sample_rate / 2):
            i = int(np.argmax(self.frequencies >= sample_rate / 2))
            raise ModelError(
                f"{where}: frequencies[{i}] = {self.frequencies[i]:g} Hz: expected below Nyquist "
                f"({sample_rate / 2:g} Hz at {sample_rate:g} Hz); raise the sample rate or drop the mode "
                "(ModalModel.below)"
            )
        if self.attack.size and not (np.all(np.isfinite(self.attack)) and self.attack_rate > 0):
            raise ModelError(f"{where}: attack: expected finite samples and attack_rate > 0 Hz")
        if self.points and len(self.points) != self.n_points:
            raise ModelError(
                f"{where}: points: expected {self.n_points} names (one per gain row), got {len(self.points)}"
            )

    # --------------------------------------------------------------- locations
    def point_index(self, vertex: int | str, where: str) -> int:
        if isinstance(vertex, str):
            if vertex not in self.points:
                names = ", ".join(self.points) or "none (use vertex indices)"
                raise PatchError(f"{where}: unknown point {vertex!r}; the model's points are {names}")
            return self.points.index(vertex)
        if not 0 <= vertex < self.n_points:
            raise PatchError(
                f"{where}: vertex {vertex} out of range; the model has {self.n_points} location(s)"
            )
        return vertex

    def check_location(self, location: Location, where: str) -> None:
        for v in location.vertices:
            self.point_index(v, where)

    def gains_at(self, location: Location | int | str | None = None) -> np.ndarray:
        """Per-mode gains at a location (barycentric blend of its vertices' rows)."""
        if location is None:
            return self.gains[0].copy()
        loc = parse_location(location, "location")
        out = np.zeros(self.n_modes)
        for v, w in zip(loc.vertices, loc.weights, strict=True):
            out += w * self.gains[self.point_index(v, "location")]
        return out

    # ------------------------------------------------------------- derived models
    def below(self, f_max: float) -> ModalModel:
        """The modes with frequency below ``f_max`` Hz."""
        keep = self.frequencies < f_max
        return ModalModel(
            self.frequencies[keep], self.decays[keep], self.gains[:, keep], self.points, self.name
        )

    def truncated(self, n: int) -> ModalModel:
        """The first n modes."""
        return ModalModel(self.frequencies[:n], self.decays[:n], self.gains[:, :n], self.points, self.name)

    def impulse_response(self, duration: float, sample_rate: float, location=None) -> np.ndarray:
        """Closed form sum_k a_k e^{-d_k t} sin(2 pi f_k t) at t = (i + 1)/sample_rate.

        This is the continuous response sampled one sample after the impulse, which the
        impulse-invariant resonator reproduces exactly (reference for tests).
        """
        t = (np.arange(int(round(duration * sample_rate))) + 1) / sample_rate
        a = self.gains_at(location)
        out = np.zeros_like(t)
        for k in range(self.n_modes):
            out += a[k] * np.exp(-self.decays[k] * t) * np.sin(2 * np.pi * self.frequencies[k] * t)
        return out

    # --------------------------------------------------------------------- files
    @classmethod
    def load(cls, path: str | os.PathLike) -> ModalModel:
        """Read a model from .toml, .npz or JASS .sy (by extension)."""
        path = Path(path)
        ext = path.suffix.lower()
        if not path.is_file():
            raise ModelError(f"{path}: no such model file")
        try:
            if ext == ".toml":
                with open(path, "rb") as fh:
                    return cls.from_dict(tomllib.load(fh), str(path))
            if ext == ".npz":
                with np.load(path, allow_pickle=False) as data:
                    return cls.from_dict({k: data[k] for k in data.files}, str(path))
            if ext == ".sy":
                return cls.from_sy(path.read_text(), str(path))
        except tomllib.TOMLDecodeError as exc:
            raise ModelError(f"{path}: not valid TOML ({exc})") from None
        except (OSError, ValueError) as exc:
            raise ModelError(f"{path}: cannot read model ({exc})") from None
        raise ModelError(f"{path}: unknown model format {ext!r}; expected .toml, .npz or .sy")

    @classmethod
    def from_dict(cls, data: dict[str, Any], source: str = "model") -> ModalModel:
        """Build from a mapping with frequencies, decays, gains and optional points/name."""
        allowed = {"frequencies", "decays", "gains", "points", "name", "attack", "attack_rate"}
        for key in data:
            if key not in allowed:
                raise ModelError(f"{source}: unknown key {key!r}; expected {', '.join(sorted(allowed))}")
        for key in ("frequencies", "decays", "gains"):
            if key not in data:
                raise ModelError(f"{source}: missing key {key!r}")
        points = data.get("points", ())
        points = tuple(str(p) for p in np.asarray(points).reshape(-1)) if len(points) else ()
        name = str(np.asarray(data.get("name", "")))
        attack = np.asarray(data.get("attack", np.zeros(0)), dtype=np.float64)
        rate = float(np.asarray(data.get("attack_rate", 0.0)))
        return cls(data["frequencies"], data["decays"], data["gains"], points, name, source, attack, rate)

    @classmethod
    def from_sy(cls, text: str, source: str = "model.sy") -> ModalModel:
        """Parse a JASS .sy file: counts, three scales, frequencies, dampings, amplitudes.

        The scales are applied (f * fscale, d * dscale, a * ascale); all n_freq modes are
        kept (JASS's nactive_freq is a rendering choice, see ModalBank ``modes``).
        """
        lines = [ln.strip() for ln in text.splitlines()]
        lines = [ln for ln in lines if ln and not ln.startswith("<!")]
        values: list[str] = [ln for ln in lines if not ln.endswith(":") and ln.upper() != "END"]
        try:
            nf, np_ = int(values[1]), int(values[2])
            fscale, dscale, ascale = (float(v) for v in values[3:6])
            body = [float(v) for v in values[6:]]
        except (IndexError, ValueError):
            raise ModelError(f"{source}: not a JASS .sy file (expected counts, scales and numbers)") from None
        need = 2 * nf + nf * np_
        if len(body) != need:
            raise ModelError(
                f"{source}: expected {need} numbers for {nf} modes x {np_} points, got {len(body)}"
            )
        f = np.array(body[:nf]) * fscale
        d = np.array(body[nf : 2 * nf]) * dscale
        a = np.array(body[2 * nf :]).reshape(np_, nf) * ascale
        return cls(f, d, a, (), Path(source).stem, source)

    def save(self, path: str | os.PathLike) -> None:
        """Write .toml or .npz atomically."""
        from jassy.files import atomic_path

        path = Path(path)
        ext = path.suffix.lower()
        if ext not in (".toml", ".npz"):
            raise ModelError(f"{path}: expected a .toml or .npz file name")
        with atomic_path(path) as tmp:
            if ext == ".npz":
                with open(tmp, "wb") as fh:
                    np.savez(
                        fh,
                        frequencies=self.frequencies,
                        decays=self.decays,
                        gains=self.gains,
                        points=np.array(self.points, dtype=str),
                        name=np.array(self.name),
                        **(
                            {"attack": self.attack, "attack_rate": np.array(self.attack_rate)}
                            if self.attack.size
                            else {}
                        ),
                    )
            else:
                Path(tmp).write_text(self.to_toml())

    def to_toml(self) -> str:
        def arr(values: np.ndarray) -> str:
            return "[" + ", ".join(repr(float(v)) for v in values) + "]"

        lines = []
        if self.name:
            lines.append(f"name = {self.name!r}".replace("'", '"'))
        if self.points:
            lines.append("points = [" + ", ".join(f'"{p}"' for p in self.points) + "]")
        lines.append(f"frequencies = {arr(self.frequencies)}")
        lines.append(f"decays = {arr(self.decays)}")
        lines.append("gains = [")
        lines.extend(f"  {arr(row)}," for row in self.gains)
        lines.append("]")
        if self.attack.size:
            lines.append(f"attack_rate = {self.attack_rate!r}")
            lines.append(f"attack = {arr(self.attack)}")
        return "\n".join(lines) + "\n"


def t60_to_decay(t60: float) -> float:
    """Decay rate (1/s) of a mode that falls 60 dB in ``t60`` seconds: ln(1000)/t60."""
    return math.log(1000.0) / t60

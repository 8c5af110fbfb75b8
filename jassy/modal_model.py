"""Modal models: frequencies (Hz), decay rates (1/s) and gains per surface location.

One impulse of unit strength at location p sounds as sum_k a[p, k] e^{-d_k t} sin(2 pi f_k t).
Gains between locations are interpolated barycentrically (the sound texture map): a
location is a vertex index, a point name, or up to three vertices with weights. Points
named t0, t1, ... (and t{i}_{j} between them) form a track, whose locations are
interpolated with its linear shape functions (jassy.tracks).

Files: TOML (``frequencies``, ``decays``, ``gains`` = list of rows, optional ``points``,
``name``, ``reference_gain``, ``driving``, ``attack`` and ``attack_rate``), NPZ (same keys)
and JASS ``.sy`` text files (read only).

``attack``: the strike's broadband start that no mode explains (the contact, the mallet, the
unresolved high modes), as samples at ``attack_rate`` Hz of the response to a unit impulse
(the gains' units times N s): a fitted model keeps the first strike's residual (recording
minus modal resynthesis, a few ms) and plays it with every strike (StrikeAttack).
``reference_gain`` is the gain a ModalBank with ``level = "calibrated"`` applies (see
jassy.levels); without it the bank computes it from the model by the same rule.

``[surface]``: analytic mode shapes (jassy.surface, e.g. a simply supported plate's), which
give gains anywhere on the surface: a location ``{surface = [u, v]}`` (fractions of the
sides) besides the named points.

Signed gains. ``gains`` are strike-to-pickup gains phi_k(c) phi_k(p) / M_k (mass-normalised
mode shapes phi_k at the contact c and the pickup p), which have signs. A contact in a
closed loop (HuntCrossleyImpact, Friction) needs the driving-point gains phi_k(c)^2 / M_k
(>= 0) at the same locations: the optional ``driving`` rows. Without them the gains must
be >= 0 and serve as both (a pickup at the contact).
"""

from __future__ import annotations

import math
import os
from dataclasses import dataclass, field
from functools import cached_property
from pathlib import Path
from typing import Any

import numpy as np

from jassy.errors import ModelError, PatchError, suggest
from jassy.surface import PlateSurface, SurfacePoint, parse_surface_point, surface_from_dict
from jassy.tracks import Track, find_track, track_gains


@dataclass(frozen=True)
class Location:
    """Up to three vertices (indices or point names) with barycentric weights."""

    vertices: tuple[int | str, ...]
    weights: tuple[float, ...]


def parse_location(value: Any, where: str) -> Location | SurfacePoint:
    """Parse a location from a patch value: int, point name, {vertices, weights}, or
    {surface = [u, v]} (a point of a model's analytic surface, jassy.surface)."""
    if isinstance(value, (Location, SurfacePoint)):
        return value
    if isinstance(value, dict) and set(value) == {"surface"}:
        return parse_surface_point(value["surface"], where)
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
    raise PatchError(
        f"{where}: expected a vertex index, point name, {{vertices, weights}} or {{surface = [u, v]}}, "
        f"got {value!r}"
    )


@dataclass
class ModalModel:
    """Frequencies f[k] (Hz), decay rates d[k] (1/s), gains a[p, k] at P locations."""

    frequencies: np.ndarray
    decays: np.ndarray
    gains: np.ndarray
    points: tuple[str, ...] = ()
    name: str = ""
    source: str = field(default="", compare=False)
    reference_gain: float | None = None  # for level = "calibrated" (jassy.levels)
    driving: np.ndarray | None = field(default=None, compare=False)  # driving-point gains [p, k]
    attack: np.ndarray | None = field(default=None, compare=False)  # unit-impulse residual samples
    attack_rate: float | None = None  # Hz, the sample rate of ``attack``
    surface: PlateSurface | None = field(default=None, compare=False)  # gains anywhere (jassy.surface)

    def __post_init__(self):
        where = self.source or self.name or "model"
        try:
            self.frequencies = np.asarray(self.frequencies, dtype=np.float64).reshape(-1)
            self.decays = np.asarray(self.decays, dtype=np.float64).reshape(-1)
            gains = np.asarray(self.gains, dtype=np.float64)
        except (TypeError, ValueError, OverflowError) as exc:
            raise ModelError(
                f"{where}: frequencies, decays and gains must be numeric arrays ({exc})"
            ) from None
        if gains.ndim == 1:
            gains = gains[None, :]
        self.gains = gains
        if self.driving is not None:
            try:
                self.driving = np.asarray(self.driving, dtype=np.float64).reshape(gains.shape)
            except (TypeError, ValueError, OverflowError):
                raise ModelError(
                    f"{where}: driving: expected numeric rows shaped like gains {gains.shape}"
                ) from None
        if self.attack is not None:
            try:
                self.attack = np.asarray(self.attack, dtype=np.float64).reshape(-1)
            except (TypeError, ValueError, OverflowError):
                raise ModelError(f"{where}: attack: expected a list of numbers (samples)") from None
        self.points = tuple(self.points)
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
        if self.reference_gain is not None and not (
            isinstance(self.reference_gain, (int, float))
            and math.isfinite(self.reference_gain)
            and self.reference_gain > 0
        ):
            raise ModelError(f"{where}: reference_gain: expected a number > 0, got {self.reference_gain!r}")
        if self.driving is not None and (not np.all(np.isfinite(self.driving)) or np.any(self.driving < 0)):
            raise ModelError(f"{where}: driving: expected finite driving-point gains >= 0")
        if self.attack is not None:
            if not np.all(np.isfinite(self.attack)):
                raise ModelError(f"{where}: attack: expected finite samples, found NaN or Inf")
            rate = self.attack_rate
            if (
                isinstance(rate, bool)
                or not isinstance(rate, (int, float))
                or not (math.isfinite(rate) and rate > 0)
            ):
                raise ModelError(
                    f"{where}: attack_rate: expected the attack's sample rate > 0 Hz, got {rate!r}"
                )
        if self.surface is not None and self.surface.orders_x.shape != (k,):
            raise ModelError(f"{where}: surface: expected one mode shape per mode ({k})")
        if self.points and len(self.points) != self.n_points:
            raise ModelError(
                f"{where}: points: expected {self.n_points} names (one per gain row), got {len(self.points)}"
            )

    # --------------------------------------------------------------- locations
    def point_index(self, vertex: int | str, where: str) -> int:
        if isinstance(vertex, str):
            if vertex not in self.points:
                names = ", ".join(self.points) or "none (use vertex indices)"
                raise PatchError(
                    f"{where}: unknown point {vertex!r}; the model's points are {names}"
                    f"{suggest(vertex, self.points)}"
                )
            return self.points.index(vertex)
        if not 0 <= vertex < self.n_points:
            raise PatchError(
                f"{where}: vertex {vertex} out of range; the model has {self.n_points} location(s)"
            )
        return vertex

    def check_location(self, location: Location | SurfacePoint, where: str) -> None:
        if isinstance(location, SurfacePoint):
            if self.surface is None:
                raise PatchError(
                    f"{where}: model {self.name or self.source or '(unnamed)'} has no surface (analytic "
                    "mode shapes), so {surface = [u, v]} cannot be heard on it; use its points"
                    + (
                        f" ({', '.join(self.points[:6])}{', ...' if len(self.points) > 6 else ''})"
                        if self.points
                        else ""
                    )
                )
            return
        for v in location.vertices:
            self.point_index(v, where)

    def _surface_point(self, location: Any) -> SurfacePoint | None:
        """The location as a checked SurfacePoint, or None for a point or a blend of points."""
        if location is None:
            return None
        loc = parse_location(location, "location")
        if not isinstance(loc, SurfacePoint):
            return None
        self.check_location(loc, "location")
        return loc

    def gains_at(self, location: Location | SurfacePoint | int | str | None = None) -> np.ndarray:
        """Per-mode gains at a location (barycentric blend of its vertices' rows, or the
        analytic surface's mode shapes at a SurfacePoint)."""
        point = self._surface_point(location)
        if point is not None:
            return self.surface.gains(point)
        return self._blend(self.gains, location)

    @cached_property
    def track(self) -> Track | None:
        """The texture track of the points t0, t1, ... (jassy.tracks), or None."""
        return find_track(self.points)

    def _blend(self, rows: np.ndarray, location: Location | int | str | None) -> np.ndarray:
        if location is None:
            return rows[0].copy()
        loc = parse_location(location, "location")
        if self.track is not None:
            on_track = track_gains(self, rows, loc)
            if on_track is not None:
                return on_track
        out = np.zeros(self.n_modes)
        for v, w in zip(loc.vertices, loc.weights, strict=True):
            out += w * rows[self.point_index(v, "location")]
        return out

    def driving_at(self, location: Location | int | str | None = None) -> np.ndarray | None:
        """Driving-point gains at a location (blended as gains_at): the ``driving`` rows, or
        the gains themselves if they are all >= 0; None for signed gains without them."""
        point = self._surface_point(location)
        if point is not None:
            return self.surface.driving_gains(point)
        if self.driving is not None:
            return self._blend(self.driving, location)
        return self.gains_at(location) if not np.any(self.gains < 0) else None

    # ------------------------------------------------------------- derived models
    def _driving_columns(self, modes: Any) -> np.ndarray | None:
        return None if self.driving is None else self.driving[:, modes]

    def _surface_modes(self, modes: Any) -> PlateSurface | None:
        return None if self.surface is None else self.surface.modes(modes)

    def below(self, f_max: float) -> ModalModel:
        """The modes with frequency below ``f_max`` Hz."""
        keep = self.frequencies < f_max
        return ModalModel(
            self.frequencies[keep], self.decays[keep], self.gains[:, keep], self.points, self.name,
            reference_gain=self.reference_gain, driving=self._driving_columns(keep),
            attack=self.attack, attack_rate=self.attack_rate, surface=self._surface_modes(keep),
        )  # fmt: skip

    def truncated(self, n: int) -> ModalModel:
        """The first n modes."""
        return ModalModel(
            self.frequencies[:n], self.decays[:n], self.gains[:, :n], self.points, self.name,
            reference_gain=self.reference_gain, driving=self._driving_columns(slice(0, n)),
            attack=self.attack, attack_rate=self.attack_rate, surface=self._surface_modes(slice(0, n)),
        )  # fmt: skip

    def attack_at(self, rate: float) -> np.ndarray:
        """The stored attack resampled to ``rate`` Hz (polyphase, Kaiser window; the same
        samples when the rates agree); empty for a model without an attack."""
        if self.attack is None or self.attack.size == 0:
            return np.zeros(0)
        attack_rate = float(self.attack_rate or rate)
        if attack_rate == rate:
            return np.asarray(self.attack, dtype=np.float64)
        from fractions import Fraction

        from scipy.signal import resample_poly

        ratio = Fraction(rate / attack_rate).limit_denominator(1000)
        return resample_poly(self.attack, ratio.numerator, ratio.denominator)

    def impulse_response(self, duration: float, sample_rate: float, location=None) -> np.ndarray:
        """Closed form sum_k a_k e^{-d_k t} sin(2 pi f_k t) at t = i/sample_rate.

        The continuous response to a unit impulse at t = 0, which the impulse-invariant
        resonators of a ModalBank reproduce exactly from the sample after the impulse on
        (reference for tests).
        """
        t = np.arange(int(round(duration * sample_rate))) / sample_rate
        a = self.gains_at(location)
        out = np.zeros_like(t)
        for k in range(self.n_modes):
            out += a[k] * np.exp(-self.decays[k] * t) * np.sin(2 * np.pi * self.frequencies[k] * t)
        return out

    # --------------------------------------------------------------------- files
    @classmethod
    def load(cls, path: str | os.PathLike) -> ModalModel:
        """Read a model from .toml, .npz or JASS .sy (by extension)."""
        from jassy.errors import JassyError
        from jassy.inputs import decode, parse_toml, read_bytes

        if not isinstance(path, (str, os.PathLike)):
            raise ModelError(f"model file: expected a file name, got {path!r}")
        path = Path(path)
        ext = path.suffix.lower()
        if ext not in (".toml", ".npz", ".sy"):
            raise ModelError(f"{path}: unknown model format {ext!r}; expected .toml, .npz or .sy")
        try:
            data = read_bytes(path, "model file")
            if ext == ".npz":
                return cls.from_dict(read_npz(data, str(path)), str(path))
            text = decode(data, str(path))
            if ext == ".toml":
                return cls.from_dict(parse_toml(text, str(path)), str(path))
            return cls.from_sy(text, str(path))
        except ModelError:
            raise
        except JassyError as exc:
            raise ModelError(str(exc)) from None

    @classmethod
    def from_dict(cls, data: dict[str, Any], source: str = "model") -> ModalModel:
        """Build from a mapping with frequencies, decays, gains and optional points/name."""
        allowed = {"frequencies", "decays", "gains", "points", "name", "reference_gain", "driving", "attack",
                   "attack_rate", "surface", *NPZ_SURFACE}  # fmt: skip
        for key in data:
            if key not in allowed:
                raise ModelError(
                    f"{source}: unknown key {key!r}; expected {', '.join(sorted(allowed))}"
                    f"{suggest(key, allowed)}"
                )
        for key in ("frequencies", "decays", "gains"):
            if key not in data:
                raise ModelError(f"{source}: missing key {key!r}")
        points = data.get("points", ())
        if isinstance(points, np.ndarray):
            points = points.reshape(-1).tolist()
        if not isinstance(points, (list, tuple)) or not all(isinstance(p, str) for p in points):
            raise ModelError(f"{source}: points: expected a list of point names")
        name = data.get("name", "")
        if isinstance(name, np.ndarray) and name.ndim == 0:
            name = name.item()
        if not isinstance(name, str):
            raise ModelError(f"{source}: name: expected a string, got {name!r}")
        reference = data.get("reference_gain")
        if isinstance(reference, np.ndarray) and reference.ndim == 0:
            reference = reference.item()
        if reference is not None and (isinstance(reference, bool) or not isinstance(reference, (int, float))):
            raise ModelError(f"{source}: reference_gain: expected a number > 0, got {reference!r}")
        reference = None if reference is None else float(reference)
        driving = data.get("driving")
        attack, attack_rate = data.get("attack"), data.get("attack_rate")
        if isinstance(attack_rate, np.ndarray) and attack_rate.ndim == 0:
            attack_rate = attack_rate.item()
        if attack is not None and attack_rate is None:
            raise ModelError(f"{source}: attack: needs attack_rate (its sample rate in Hz)")
        surface = data.get("surface")
        if surface is None and any(key in data for key in NPZ_SURFACE):
            surface = {key: data.get(npz_key) for npz_key, key in NPZ_SURFACE.items()}
        n_modes = np.size(data["frequencies"])
        surface = None if surface is None else surface_from_dict(surface, n_modes, source)
        return cls(
            data["frequencies"],
            data["decays"],
            data["gains"],
            tuple(points),
            name,
            source,
            reference,
            driving,
            attack,
            attack_rate,
            surface,
        )

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
                    ref = self.reference_gain
                    extra = {} if ref is None else {"reference_gain": np.array(ref)}
                    if self.driving is not None:
                        extra["driving"] = self.driving
                    if self.attack is not None:
                        extra["attack"] = self.attack
                        extra["attack_rate"] = np.array(float(self.attack_rate))
                    if self.surface is not None:
                        table = self.surface.to_dict()
                        extra.update(
                            {npz: np.array(table[key]) for npz, key in NPZ_SURFACE.items() if key in table}
                        )
                    np.savez(
                        fh,
                        frequencies=self.frequencies,
                        decays=self.decays,
                        gains=self.gains,
                        points=np.array(self.points, dtype=str),
                        name=np.array(self.name),
                        **extra,
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
        if self.reference_gain is not None:
            lines.append(f"reference_gain = {float(self.reference_gain)!r}")
        lines.append(f"frequencies = {arr(self.frequencies)}")
        lines.append(f"decays = {arr(self.decays)}")
        lines.append("gains = [")
        lines.extend(f"  {arr(row)}," for row in self.gains)
        lines.append("]")
        if self.driving is not None:
            lines.append("driving = [")
            lines.extend(f"  {arr(row)}," for row in self.driving)
            lines.append("]")
        if self.attack is not None:
            lines.append(f"attack_rate = {float(self.attack_rate)!r}")
            lines.append(f"attack = {arr(self.attack)}")
        if self.surface is not None:  # a table: after every top-level key
            table = self.surface.to_dict()
            lines += ["", "[surface]", f'kind = "{table.pop("kind")}"']
            lines += [f"{key} = [{', '.join(repr(v) for v in values)}]" for key, values in table.items()]
        return "\n".join(lines) + "\n"


#: NPZ member names of a model's surface table (the TOML keeps it as a [surface] table).
NPZ_SURFACE = {
    f"surface_{key}": key for key in ("kind", "sides", "orders_x", "orders_y", "pickup", "driving")
}


def read_npz(data: bytes, where: str) -> dict[str, np.ndarray]:
    """The arrays of an .npz file's bytes, checked before anything is decompressed: a zip of
    .npy members of numeric or string dtype (no pickles) whose declared sizes fit in memory."""
    import io
    import zipfile

    from jassy.limits import check_memory

    try:
        archive = zipfile.ZipFile(io.BytesIO(data))
        total = 0
        for info in archive.infolist():
            if not info.filename.endswith(".npy"):
                raise ModelError(f"{where}: cannot read model ({info.filename}: not a .npy array)")
            with archive.open(info) as fh:
                major, _ = np.lib.format.read_magic(fh)
                read_header = (
                    np.lib.format.read_array_header_1_0 if major == 1 else np.lib.format.read_array_header_2_0
                )
                shape, _, dtype = read_header(fh)
            if dtype.hasobject or dtype.kind not in "biufcUS":
                raise ModelError(
                    f"{where}: cannot read model ({info.filename}: dtype {dtype}; expected numbers or "
                    "strings, objects and pickles are not loaded)"
                )
            total += math.prod(shape) * dtype.itemsize
        check_memory(total, where)
        with np.load(io.BytesIO(data), allow_pickle=False) as npz:
            return {k: npz[k] for k in npz.files}
    except (zipfile.BadZipFile, ValueError, EOFError, OSError, KeyError) as exc:
        raise ModelError(f"{where}: cannot read model (not a valid .npz file: {exc})") from None


def t60_to_decay(t60: float) -> float:
    """Decay rate (1/s) of a mode that falls 60 dB in ``t60`` seconds: ln(1000)/t60."""
    return math.log(1000.0) / t60

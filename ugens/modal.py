"""ModalBank: a bank of impulse-invariant two-pole resonators driven by a contact force.

Per mode k (JASS form), with R = exp(-d/fs), theta = 2 pi f/fs:

    y[n] = 2 R cos(theta) y[n-1] - R^2 y[n-2] + a R sin(theta) F[n-1] / fs

F is a force in N sampled at fs, so an impulse of J N s (any pulse with sum F / fs = J)
sounds as J a e^{-d t} sin(2 pi f t) whatever the sample rate; the discrete unit impulse
F = fs delta[n] (1 N s in one sample) gives exactly a R^n sin(n theta), i.e.
a e^{-d t} sin(2 pi f t) at t = n/fs: output sample n is the response at n/fs, so a
tap's sound does not lead its force. (JASS feeds F[n], which makes sample n the response
at (n+1)/fs, and omits the 1/fs, which makes its loudness depend on the sample rate.)

The bank's output is the convolution y(t) = int_0^inf h(s) F(t - s) ds with
h(s) = sum_k a_k e^{-d_k s} sin(2 pi f_k s), computed by the trapezoidal rule on the
sample grid (the resonators above; h(0) = 0) plus its Euler-Maclaurin end correction
(h'(0) / (12 fs^2)) F[n] = sum_k a_k 2 pi f_k / (12 fs^2) F[n] ("direct" gain D, one
multiply per sample, not per mode). For a smooth force the error is then O(fs^-4): a
1 ms raised-cosine tap on a 3 kHz mode is within 1e-4 of the exact convolution, where
the JASS form is 10 % off (tests/test_modal_bank.py). The correction also makes the
sound start on the force's first non-zero frame, as the exact response does.

Coefficients are designed in float64 and the state is float64: float32 state fails the
-60 dB accuracy bound for low, lightly damped modes (tests/test_modal_bank.py shows both).
With ``precision = "mixed"`` the modes whose float32 error bound allows it run in float32
in the delta form of ugens.modal_f32 (twice the SIMD lanes), the rest in float64.

Parameter changes ramp the coefficients (c1, c2, g, d) linearly, as SuperCollider's Ringz
does; along a ``freq_scale`` ramp it is therefore cos(theta), i.e. about f^2, that moves
linearly.

The kernel is vectorised across modes and unrolled four samples deep, so each mode's
state and coefficients are loaded once per four samples. Modes are stored sorted by
decay rate (slowest first); once the input is silent, modes whose state falls below
``floor`` are zeroed and the computed range shrinks to the last audible mode, so a
silent bank costs nothing ("silent modes skipped", also the subnormal guard).
"""

from __future__ import annotations

import math
from collections import deque
from typing import Any, NamedTuple

import numba as nb
import numpy as np

from jassy import anytime_rank, record_views
from jassy.anytime import a_weighting_power, fixed_entry
from jassy.anytime_rank import has_force
from jassy.errors import ModelError, PatchError
from jassy.jit import drop_stale_cache, specialise
from jassy.levels import reference_gain
from jassy.modal_model import Location, ModalModel, parse_location
from jassy.params import ParamSpec
from jassy.record_views import FIELD, float32_table, float_row, float_table, handle, int_row
from jassy.registry import register
from jassy.ugen import UGen
from ugens import cells, kernels, modal_budget, modal_f32, modal_meta, modal_retune
from ugens.cells import is_flush_frame, mode_rows, silent, two_pole, until_flush
from ugens.kernels import FASTMATH
from ugens.modal_budget import (
    FLAT_SPECTRUM_MODES,
    FLOOR,
    FLOOR2,
    GAIN_LEVEL,
    REMEMBERED,
    SIZE,
    TRANSFORMED,
    WEIGHT,
    BudgetTables,
    line_aligned_zeros,
)
from ugens.modal_f32 import (
    MIN_GAIN,
    TOLERANCE,
    WIDE_LANES,
    delta_coefficients,
    delta_rows,
    float32_error,
    flush_silent_delta,
    narrow_rows,
    order_by_form,
    resonate_narrow,
    unscaled_state,
)
from ugens.modal_meta import (
    ACTIVE,
    ALLOWED,
    DELTA_END,
    GATHERED,
    NARROW_ACTIVE,
    NARROW_ALL,
    RAMP_LEFT,
    BankMeta,
    CompactMeta,
    NarrowMeta,
)
from ugens.modal_retune import (
    COEF_C1,
    COEF_C2,
    COEF_DIRECT,
    COEF_GAIN,
    POLE_C1,
    POLE_C2,
    POLE_RATIO,
    POLE_SIN,
    TOP_BAND,
    TOP_BAND_COS,
    TOP_BAND_SIN,
    TopBand,
    pole_rows,
    resonator,
    retune_state,
    size_changes,
)

# its cache holds copies of their kernels and constants
drop_stale_cache(
    __file__, [anytime_rank, cells, kernels, modal_budget, modal_f32, modal_meta, modal_retune, record_views]
)

#: A design (c1, c2, g, d) is its poles (c1, c2, R sin theta, d / g) with the last two
#: rows scaled in place (ModalBank._design): the two layouts share their rows.
assert (POLE_C1, POLE_C2, POLE_SIN, POLE_RATIO) == (COEF_C1, COEF_C2, COEF_GAIN, COEF_DIRECT)

#: The band points of the ``"band"`` direct ratio as :func:`pole_rows` takes them.
TOP_BAND_ROWS = TopBand(TOP_BAND, TOP_BAND_COS, TOP_BAND_SIN)


class Ramp(NamedTuple):
    """A linear ramp of a bank's coefficients (c1, c2, g, d): (4, K) arrays of the current
    values, their per-sample increments and their final values."""

    coef: np.ndarray
    delta: np.ndarray
    target: np.ndarray


@nb.njit(fastmath=FASTMATH, cache=True)
def resonate(force, out, n, rows, active, last):
    """Run modes [0, active) of ``rows`` (ugens.cells.ModeRows) over force[:n] into out[:n] (overwrites out).

    last[0]: the force sample before force[0] (each resonator hears F[n-1]); left at
    force[n-1]. The direct term sum(d) F[n] is added once per sample; the sum is formed
    only if some F[n] is non-zero (a pass over the modes, per call: most blocks of an
    impact's ringing have no force)."""
    c1, c2, g, d, y1, y2 = rows
    direct = 0.0
    if has_force(force, 0, n):
        for k in range(active):
            direct += d[k]
    fp = last[0]
    i = 0
    while i + 4 <= n:
        f0 = force[i]
        f1 = force[i + 1]
        f2 = force[i + 2]
        f3 = force[i + 3]
        s0 = 0.0
        s1 = 0.0
        s2 = 0.0
        s3 = 0.0
        for k in range(active):
            p = c1[k]
            q = c2[k]
            gk = g[k]
            u1 = y1[k]
            u2 = y2[k]
            v0 = two_pole(p, q, u1, u2, gk * fp)
            v1 = two_pole(p, q, v0, u1, gk * f0)
            v2 = two_pole(p, q, v1, v0, gk * f1)
            v3 = two_pole(p, q, v2, v1, gk * f2)
            y2[k] = v2
            y1[k] = v3
            s0 += v0
            s1 += v1
            s2 += v2
            s3 += v3
        out[i] = s0 + direct * f0
        out[i + 1] = s1 + direct * f1
        out[i + 2] = s2 + direct * f2
        out[i + 3] = s3 + direct * f3
        fp = f3
        i += 4
    while i < n:
        f = force[i]
        s = 0.0
        for k in range(active):
            v = two_pole(c1[k], c2[k], y1[k], y2[k], g[k] * fp)
            y2[k] = y1[k]
            y1[k] = v
            s += v
        out[i] = s + direct * f
        fp = f
        i += 1
    last[0] = fp


@nb.njit(fastmath=FASTMATH, cache=True)
def resonate_ramp(force, out, n, ramp, y1, y2, remaining, active, last):
    """As :func:`resonate` over modes [0, active) while the coefficients ramp linearly.

    ramp: a Ramp of (c1, c2, g, d); y1, y2: the state rows. Each sample uses the current
    coefficients, then they step (as in params.ramp_fill), so they equal the ramp's target
    from its m-th sample on (``remaining`` = m). Returns the samples left.
    """
    K = active
    coef, delta, target = ramp
    c1, c2, g, d = coef[COEF_C1], coef[COEF_C2], coef[COEF_GAIN], coef[COEF_DIRECT]
    fp = last[0]
    for i in range(n):
        f = force[i]
        s = 0.0
        direct = 0.0
        for k in range(K):
            v = two_pole(c1[k], c2[k], y1[k], y2[k], g[k] * fp)
            y2[k] = y1[k]
            y1[k] = v
            s += v
            direct += d[k]
        out[i] = s + direct * f
        fp = f
        if remaining > 0:
            remaining -= 1
            if remaining == 0:
                for r in range(4):
                    for k in range(K):
                        coef[r, k] = target[r, k]
            else:
                for r in range(4):
                    for k in range(K):
                        coef[r, k] += delta[r, k]
    last[0] = fp
    return remaining


@nb.njit(cache=True)
def flush_silent(y1, y2, active, floor):
    """Zero modes below ``floor``; return the new active count (last audible mode + 1)."""
    last = 0
    for k in range(active):
        if silent(y1[k], y2[k], floor):
            y1[k] = 0.0
            y2[k] = 0.0
        else:
            last = k + 1
    return last


@nb.njit(fastmath=FASTMATH, cache=True)
def bank_step(force, out, start, n, bank, meta, floor, last):
    """One sub-block without ramps. bank rows: c1, c2, g, d, y1, y2; meta: a BankMeta (the
    active mode count and the most modes that may be active);
    last[0] = the force sample before force[0].

    The sub-block is cut at multiples of FLUSH_PERIOD on the clock. In each piece, any
    input activates every allowed mode (the inactive ones hold exact zeros, so when they
    start does not matter); at each multiple, modes whose state fell below ``floor`` are
    zeroed and the active count shrinks to the last audible mode (no mode is below a
    ``floor`` <= 0: the scan is skipped). The flush frames do not depend on the block size,
    so neither does the output."""
    i = 0
    while i < n:
        m = until_flush(start + i, n - i)
        f = force[i : i + m]
        o = out[i : i + m]
        if last[0] != 0.0 or has_force(f, 0, m):
            meta[ACTIVE] = meta[ALLOWED]
        active = meta[ACTIVE]
        if active == 0:
            for j in range(m):
                o[j] = 0.0
            last[0] = 0.0
        else:
            resonate(f, o, m, mode_rows(bank), active, last)
        i += m
        if active > 0 and floor > 0.0 and is_flush_frame(start + i):
            meta[ACTIVE] = flush_silent(bank[4], bank[5], active, floor)


class MixedRows(NamedTuple):
    """The arrays :func:`mixed_step` runs on: the float64 modes' bank rows (c1, c2, g, d,
    y1, y2; padded with silent modes to whole ugens.modal_f32.WIDE_LANES) and meta (a
    BankMeta), the float32 modes' delta-form rows (c0, b2, g, d) and state
    (y[n-2], Delta[n-1]) / g (ugens.modal_f32.narrow_rows) and their NarrowMeta
    (ugens.modal_meta)."""

    wide_bank: np.ndarray
    wide_meta: np.ndarray
    narrow_coef: np.ndarray
    narrow_state: np.ndarray
    narrow_meta: np.ndarray


@nb.njit(fastmath=FASTMATH, cache=True)
def mixed_step(force, out, start, n, rows, floor, last):
    """One sub-block of a bank split by precision (``rows``: MixedRows) into out[:n]: the
    float32 and the float64 modes in the same passes (ugens.modal_f32.resonate_narrow),
    with the silent-mode skipping and flush frames of :func:`bank_step` for each group;
    last[0] as in bank_step."""
    wide_bank, wide_meta, coef, state, narrow_meta = rows
    i = 0
    while i < n:
        m = until_flush(start + i, n - i)
        f = force[i : i + m]
        o = out[i : i + m]
        if last[0] != 0.0 or has_force(f, 0, m):
            wide_meta[ACTIVE] = wide_meta[ALLOWED]
            narrow_meta[NARROW_ACTIVE] = narrow_meta[NARROW_ALL]
        wide_active = wide_meta[ACTIVE]
        active = narrow_meta[NARROW_ACTIVE]
        if active == 0 and wide_active == 0:
            for j in range(m):
                o[j] = 0.0
            last[0] = 0.0
        else:
            narrow = delta_rows(coef, state)
            delta_end = narrow_meta[DELTA_END]
            if wide_meta[ALLOWED] > 0:
                resonate_narrow(f, o, m, narrow, active, mode_rows(wide_bank), wide_active, last, delta_end)
            else:
                resonate_narrow(f, o, m, narrow, active, None, 0, last, delta_end)
        i += m
        if is_flush_frame(start + i):
            if wide_active > 0 and floor > 0.0:
                wide_meta[ACTIVE] = flush_silent(wide_bank[4], wide_bank[5], wide_active, floor)
            if active > 0 and floor > 0.0:
                narrow_meta[NARROW_ACTIVE] = flush_silent_delta(
                    state[0], state[1], coef[COEF_GAIN], active, floor
                )


class BankArrays(NamedTuple):
    """The arrays :func:`bank_span` reads through its handle (jassy.record_views): a
    float64 bank's rows (c1, c2, g, d, y1, y2), its BankMeta and the force sample before
    the block."""

    bank: np.ndarray
    meta: np.ndarray
    last: np.ndarray


@nb.njit(fastmath=FASTMATH, cache=True)
def bank_span(force, out, start, n, a, floor):
    """:func:`bank_step` on the BankArrays of handle ``a``. numba unboxes every array
    argument at every call from Python, so ModalBank hands over one handle instead of
    three arrays."""
    bank_step(force, out, start, n, float_table(a, 0), int_row(a, FIELD), floor, float_row(a, 2 * FIELD))


#: Fields of a MixedRows (slots of FIELD in a handle).
MIXED_FIELDS = len(MixedRows._fields)


@nb.njit(inline="always", cache=True)
def mixed_rows_at(a, i):
    """The MixedRows whose fields start at slot ``i`` of handle ``a`` (jassy.record_views)."""
    return MixedRows(
        float_table(a, i), int_row(a, i + FIELD), float32_table(a, i + 2 * FIELD),
        float32_table(a, i + 3 * FIELD), int_row(a, i + 4 * FIELD),
    )  # fmt: skip


@nb.njit(fastmath=FASTMATH, cache=True)
def mixed_span(force, out, start, n, a, floor):
    """:func:`mixed_step` on handle ``a``: a MixedRows, then the force sample before the
    block (one array for Python to hand over instead of six)."""
    mixed_step(force, out, start, n, mixed_rows_at(a, 0), floor, float_row(a, MIXED_FIELDS * FIELD))


def mode_poles(frequencies, decays, sample_rate, fit="taylor") -> np.ndarray:
    """Rows (c1, c2, s, d / g) = (2 R cos theta, R^2, R sin theta, :func:`direct_ratio`) per
    mode, float64, R = exp(-d / fs), theta = 2 pi f / fs, compiled as ModalBank designs its
    modes (:func:`ugens.modal_retune.pole_rows`, which ModalBank calls with its scales).
    Modes at or above Nyquist get zero coefficients and gain (silent)."""
    freqs = np.ascontiguousarray(frequencies, dtype=np.float64)
    rows, sin2, inv = np.empty((4, freqs.size)), np.empty(freqs.size), np.empty(freqs.size)
    decays = np.ascontiguousarray(decays, dtype=np.float64)
    pole_rows(freqs, decays, 1.0, 1.0, float(sample_rate), fit == "band", TOP_BAND_ROWS, rows, sin2, inv)
    return rows


def design(frequencies, decays, sample_rate):
    """(c1, c2, s) = (2 R cos theta, R^2, R sin theta) per mode, float64: the resonator
    formula of :func:`ugens.modal_retune.resonator` evaluated by numpy, as the closed-loop
    ugens (Friction, RathRoll) and the benches design their modes (ModalBank runs the same
    formula compiled, :func:`mode_poles`; the two differ in the last bit of some modes).

    Modes at or above Nyquist get zero coefficients and gain (silent).
    """
    frequencies = np.asarray(frequencies, dtype=np.float64)
    c1, c2, s, _ = resonator(frequencies, np.asarray(decays, dtype=np.float64), sample_rate)
    sounding = frequencies < sample_rate / 2
    return np.where(sounding, c1, 0.0), np.where(sounding, c2, 0.0), np.where(sounding, s, 0.0)


def direct_ratio(frequencies, decays, sample_rate, fit="taylor"):
    """Per mode, the direct gain over the resonator's input gain, d / g (0 for silent modes).

    ``"taylor"``: the Euler-Maclaurin end correction theta / (12 R sin theta), which makes
    the bank's low-frequency response (and a smooth force's output) exact to O(fs^-4).

    ``"band"``: the constant that best matches, in relative least squares over TOP_BAND
    (fs/3 to fs/2), the discrete response d + g z^-1 / A(z) to the continuous one,
    H(s) = a w / ((s + d)^2 + w^2). Sampling the impulse response (impulse invariance) folds
    every mode's 1/f^2 tail about Nyquist: with the Taylor term a light mode reads
    1 / (4 sin^2(omega/2)) - 1/12 against 1 / omega^2 (times a w / fs^2), 4.3 dB too much
    at Nyquist, and a bank of many modes sums these tails coherently (Smith, Physical Audio
    Signal Processing, "Sampling the impulse response": the system should be low-passed
    before it is sampled). The fitted constant removes most of that excess while every
    mode keeps its sampled ringing (poles and g unchanged: output samples 1, 2, ... of an
    impulse are still a e^{-d t} sin(w t)); the price is a flat direct error at low
    frequencies of about 0.5 theta^2 / 12 of a mode's static response (0.03 % at 1 kHz,
    3 % at 8 kHz, at 48 kHz).
    """
    return mode_poles(frequencies, decays, sample_rate, fit)[POLE_RATIO]


class MixedSplit(NamedTuple):
    """A ModalBank's modes split by precision (``precision = "mixed"``): internal indices
    of the float64 modes (``wide``) and of the float32 modes (``narrow``), and their rows
    (MixedRows)."""

    wide: np.ndarray
    narrow: np.ndarray
    rows: MixedRows


def split_by_precision(bank: np.ndarray, sample_rate: float, tolerance: float = TOLERANCE) -> MixedSplit:
    """Split a float64 bank (rows c1, c2, g, d, y1, y2) into float64 modes and float32
    modes: float32 where :func:`ugens.modal_f32.float32_error` <= tolerance and |g| >=
    MIN_GAIN; those that miss it in the faster decay-factor form
    (:func:`ugens.modal_f32.decay_factor_error`) first, in chunks of the delta form
    (:func:`ugens.modal_f32.order_by_form`), the rest in the decay-factor form; the float64
    rows padded to whole WIDE_LANES (for resonate_narrow's vectors)."""
    c1, c2, g, d, y1, y2 = bank
    fits = (float32_error(c1, c2, sample_rate) <= tolerance) & (np.abs(g) >= MIN_GAIN)
    wide, narrow = np.flatnonzero(~fits), np.flatnonzero(fits)
    order, delta_end = order_by_form(c1[narrow], c2[narrow], sample_rate, tolerance)
    narrow = narrow[order]
    c0, b2 = delta_coefficients(c1[narrow], c2[narrow])
    coef, state = narrow_rows(c0, b2, g[narrow], d[narrow], y1[narrow], y2[narrow], delta_end)
    nw, nn = wide.size, narrow.size
    wide_bank = line_aligned_zeros((6, -(-nw // WIDE_LANES) * WIDE_LANES))  # silent padding modes
    wide_bank[:, :nw] = bank[:, wide]
    rows = MixedRows(
        wide_bank,
        np.array(BankMeta(nw, 0, nw), dtype=np.int64),
        coef,
        state,
        np.array(NarrowMeta(nn, nn, delta_end), dtype=np.int64),
    )
    return MixedSplit(wide, narrow, rows)


#: The ``level`` of a ugen whose own modal resonator is heard (Friction, HuntCrossleyImpact).
HEARD_LEVEL = ParamSpec(
    "str",
    "raw",
    choices=("raw", "calibrated"),
    fixed=True,
    doc="'raw': the heard output in the model's gain units (m for finite-element models); "
    "'calibrated': times the model's reference gain, the scale of a calibrated ModalBank "
    "(a 1e-3 N s, 1 ms strike at the loudest point peaks at -18 dBFS; jassy.levels)",
)


class ModelParams:
    """Validation of a ``model`` param (a ModalModel) and a ``location`` param (checked
    against the model), for ugens that own a modal resonator. With ``driving_point``,
    the model must give driving-point gains (ModalModel.driving_at: its ``driving`` rows,
    or gains that are all >= 0)."""

    driving_point = False

    def level_gain(self) -> float:
        """The factor of the heard output: the model's reference gain when the ``level``
        param is 'calibrated', else 1."""
        if self.values.get("level") != "calibrated":
            return 1.0
        return reference_gain(self.model, self.sample_rate)

    def __init__(self, *sources: UGen, name: str | None = None, where: str | None = None, **params: Any):
        """The model may also be given as the first positional argument."""
        if sources and isinstance(sources[0], ModalModel):
            params.setdefault("model", sources[0])
            sources = sources[1:]
        super().__init__(*sources, name=name, where=where, **params)

    @property
    def model(self) -> ModalModel:
        return self.values["model"]

    def validate_model(self) -> None:
        """At render start: the model against the sample rate, as a patch error."""
        try:
            self.model.validate(self.sample_rate)
        except ModelError as exc:
            raise PatchError(f"nodes.{self.name}.model: {exc}") from None

    def check_value(self, spec: ParamSpec, value: Any, where: str) -> Any:
        if spec.kind == "model":
            if not isinstance(value, ModalModel):
                raise PatchError(f"{where}: expected a ModalModel, got {value!r}")
            return value
        if spec.kind == "location":
            loc = parse_location(value, where)
            model = self.values.get("model")
            if model is not None:
                model.check_location(loc, where)
                if self.driving_point and model.driving_at(loc) is None:
                    k = int(np.argmin(model.gains.min(axis=0)))  # the most negative gain's mode
                    raise PatchError(
                        f"{where}: model {model.name or model.source or '(unnamed)'} has signed gains "
                        f"(mode {k}: {model.gains[:, k].min():g}) and no driving-point gains; a contact "
                        "needs the model's `driving` rows (phi(c)^2 / M >= 0) or gains >= 0"
                    )
            return loc
        return super().check_value(spec, value, where)


@register
class ModalBank(ModelParams, UGen):
    """Modal resonator bank (JASS ModalObjectWithOneContact) driven by a force input.

    Output for a unit impulse of force at location p: sum_k a[p,k] e^{-d_k t} sin(2 pi f_k t).

    Optional input ``size``: a fragment size s in (0, 1] held per event (e.g. the ``size``
    output of Crumple), SDT's resonator fragment size (``SDTResonator_setFragmentSize``):
    the modal masses scale by s at unchanged stiffness, so frequencies and decay rates
    scale by 1/sqrt(s) and the displacement per unit impulse, a / (m w), by 1/sqrt(s). The
    bank retunes at the frame where s changes, keeping each ringing mode's amplitude and
    phase (its energy, as SDT); s <= 0 (no event yet) means s = 1.

    Input: force in N. Output: the model's gain units times N s (m for the finite-element
    models, whose gains are m per N s) with ``level = "raw"``; full scale (1 = 0 dBFS) with
    ``level = "calibrated"``, where the default impact peaks at -18 dBFS (jassy.levels).
    """

    type_name = "ModalBank"
    _held = False  #: while set, set_param only stores values: more keys of one change follow
    inputs = ("input", "size")
    optional_inputs = ("size",)
    accepts_location = True
    inline_events = True
    supports_budget = True
    param_specs = {
        "model": ParamSpec("model", required=True, fixed=True, doc="the ModalModel (name in a patch)"),
        "location": ParamSpec("location", 0, doc="contact location: vertex, point name or barycentric"),
        "freq_scale": ParamSpec(
            "float", 1.0, low=0.0, low_open=True, high=1e3, smooth=True, doc="multiplies every frequency"
        ),
        "decay_scale": ParamSpec(
            "float", 1.0, low=0.0, high=1e6, smooth=True, doc="multiplies every decay rate"
        ),
        "gain": ParamSpec("float", 1.0, smooth=True, doc="multiplies every input gain"),
        "level": ParamSpec(
            "str",
            "raw",
            choices=("raw", "calibrated"),
            fixed=True,
            doc="'raw': the model's gains as they are; 'calibrated': times the model's reference gain, "
            "so the default impact (1e-3 N s, 1 ms) peaks at -18 dBFS at its loudest point (jassy.levels)",
        ),
        "floor": ParamSpec(
            "float",
            1e-10,
            low=0.0,
            high=1e-3,
            fixed=True,
            doc="state magnitude below which a silent mode is zeroed and skipped",
        ),
        "direct": ParamSpec(
            "str",
            "taylor",
            choices=("taylor", "band"),
            fixed=True,
            doc="direct (same-sample) gain per mode: 'taylor' is exact at low frequencies (smooth forces); "
            "'band' matches each mode's continuous response over fs/3-fs/2, removing most of the 1/f^2 tails "
            "that impulse invariance folds about Nyquist (sharp forces, many modes); see direct_ratio",
        ),
        "precision": ParamSpec(
            "str",
            "float64",
            choices=("float64", "mixed"),
            fixed=True,
            doc="'float64': every mode in float64; 'mixed': float32 (delta form) for the modes whose "
            "error bound stays 10 dB inside -60 dB of their peak, float64 for the rest (very high Q)",
        ),
    }

    def _design_basis(self) -> tuple[tuple, tuple]:
        """What the design caches depend on besides the event-driven parameters: the model
        and its arrays (compared by identity; a model's arrays are not changed in place),
        and the sample rate, direct-gain form and level (compared by value)."""
        model, v = self.model, self.values
        objects = (model, model.frequencies, model.decays, model.gains, model.driving, model.surface)
        return objects, (self.sample_rate, v["direct"], v["level"])

    def _design_unchanged(self, basis: tuple[tuple, tuple]) -> bool:
        """Whether ``basis`` is the one the design caches were made (and the model validated) for."""
        kept = getattr(self, "_kept_basis", None)
        return (
            kept is not None
            and all(a is b for a, b in zip(kept[0], basis[0], strict=True))
            and kept[1] == basis[1]
        )

    def _prepare(self) -> None:
        self._size_input = self.sources.get("size")
        self._size = 1.0  # the fragment size of the current design
        model = self.model
        basis = self._design_basis()
        if not self._design_unchanged(basis):
            # A new model or rate: validate and start the design caches afresh (a render of
            # the same graph again keeps them, and its designs are the same numbers).
            self.validate_model()
            self._level_gain = self.level_gain()
            self.order = np.argsort(model.decays, kind="stable")
            self._poles = None  # (parameters, (c1, c2, R sin theta), ...) of the last design
            self._gain_rows = {None: None}  # (location, gain) -> design, for the poles at key None
            self._location_rows = {}  # location -> the model's gains there, internal order
            self._mode_rows = model.frequencies[self.order], model.decays[self.order]  # Hz, 1/s
            self._kept_basis = basis
        self._tuning = np.full((6, model.n_modes), np.nan)  # the last retune's new tuning (retune_state)
        k = model.n_modes
        self.bank = line_aligned_zeros((6, k))  # c1, c2, g, d (current coefficients), y1, y2 (state)
        self.coef, self.y = self.bank[:4], self.bank[4:]
        self.delta = np.zeros((4, k))
        self.target = np.zeros((4, k))
        self.last = np.zeros(1)  # the force sample before the next sub-block
        self.meta = np.zeros(len(BankMeta._fields), dtype=np.int64)  # a BankMeta
        self.coef[:] = self._design()
        self.target[:] = self.coef
        self._floor = float(self.values["floor"])
        self._input = self.sources["input"]
        self._ramping = False
        self._mixed = self.values["precision"] == "mixed"
        self._split: MixedSplit | None = None  # while set, it holds the state, not self.bank
        self._split_handle: np.ndarray | None = None  # the split's rows and self.last (mixed_span)
        self._bank_handle = handle(BankArrays(self.bank, self.meta, self.last))
        self._bank_call = self._mixed_call = None  # entry points, found on first use (_call)
        self._steady = None  # (_steady, _steady_rows): process's fast path (_span)
        self._steady_rows: np.ndarray | None = None
        self.budgeted = False
        self._change_watch: dict | None = None  # told of queued changes (anytime_watch)
        self._tables: BudgetTables | None = None  # a budget's tables, which hold the rows (anytime_attach)
        self._heard = None  # the force over the last budget period (a ring of the tables)
        self._compact_meta = np.zeros(len(CompactMeta._fields), dtype=np.int64)  # a CompactMeta
        self._refresh_design_cache()

    def _call(self, kernel, rows: np.ndarray):
        """The entry point of :func:`bank_span` or :func:`mixed_span` for this bank's
        argument types: looked up when first used, not at prepare (a graph that runs as a
        program renders its banks without them, and a cold process would compile them)."""
        return specialise(kernel, self.out, self.out, 0, 0, rows, self._floor)

    def _pole_design(self) -> tuple[np.ndarray, np.ndarray]:
        """(c1, c2, R sin theta, d / g (:func:`direct_ratio`)) and 1 / (R^2 sin^2 theta)
        (0 for silent modes) per mode in internal order, for the current freq_scale and
        decay_scale; kept between calls, so a location or gain change (every impact of a
        rigid scene) only recomputes gains."""
        v = self.values
        key = (v["freq_scale"], v["decay_scale"], self._size)
        if self._poles is None or self._poles[0] != key:
            retune = 1.0 / np.sqrt(self._size)
            freqs, decays = self._mode_rows
            k = freqs.size
            poles, sin2, inv = np.empty((4, k)), np.empty(k), np.empty(k)
            band = v["direct"] == "band"
            f_scale, d_scale, rate = (
                v["freq_scale"] * retune,
                v["decay_scale"] * retune,
                float(self.sample_rate),
            )
            pole_rows(freqs, decays, f_scale, d_scale, rate, band, TOP_BAND_ROWS, poles, sin2, inv)
            self._poles = (key, poles, sin2, inv)
        return self._poles[1], self._poles[3]

    def _design(self) -> np.ndarray:
        """Target (c1, c2, g, d) from the current parameter values, in internal mode order:
        d = g theta / (12 R sin theta) = a gain 2 pi f / (12 fs^2), the direct gain. Kept
        per (location, gain) for the current poles: the array is shared, never changed."""
        poles, _ = self._pole_design()
        v = self.values
        key = (v["location"], v["gain"])
        out = self._gain_rows.get(key) if self._gain_rows[None] is poles else None
        if out is None:
            if self._gain_rows[None] is not poles or len(self._gain_rows) > 256:
                self._gain_rows = {None: poles}  # new poles, or many locations: start afresh
            scale = v["gain"] * self._level_gain / (self.sample_rate * math.sqrt(self._size))
            out = poles.copy()  # c1, c2 as they are, R sin theta scaled to g, then d
            gains = out[COEF_GAIN]  # R sin theta times scale times the location's gains
            np.multiply(gains, scale, out=gains)
            np.multiply(gains, self.anytime_gains(v["location"]), out=gains)
            np.multiply(gains, poles[POLE_RATIO], out=out[COEF_DIRECT])
            self._gain_rows[key] = out  # read only: every user copies it or reads it
        return out

    def anytime_gains(self, location: Any) -> np.ndarray:
        """The model's gains at ``location`` in internal mode order (also the mode budget's
        impact gains), kept per location (a
        retune at every crumple event redesigns the gains, not the location)."""
        row = self._location_rows.get(location)
        if row is None:
            if len(self._location_rows) > 256:
                self._location_rows.clear()
            row = self._location_rows[location] = self.model.gains_at(location)[self.order]
        return row

    def _settle(self) -> None:
        """Move the state of a budget's compact bank or of a precision split back into
        ``self.bank`` (float64), before anything reads or changes the bank's coefficients
        or state (which ends process's fast path until the next plain span)."""
        split = self._split
        self._forget_split()
        if self._compact_meta[GATHERED]:
            self._anytime_entry("settle")(self._tables_handle, self._slot)
        if split is None:
            return
        self.y[:, split.wide] = split.rows.wide_bank[4:, : split.wide.size]
        self.y[:, split.narrow] = unscaled_state(split.rows.narrow_state, self.bank[2, split.narrow])
        self.meta[ACTIVE] = self.meta[ALLOWED]

    def _forget_split(self) -> None:
        """Drop what is derived from the bank's current layout: the precision split, its
        record handle and process's fast path (rebuilt on the next plain span)."""
        self._split = None
        self._split_handle = None
        self._steady = None

    def _reset(self) -> None:
        self._forget_split()
        self._compact_meta[GATHERED] = 0
        if self._tables is not None:
            self._kept_mask[:] = True
            self._faded[:] = False
        self._pending = deque()  # (frame, key, value, jump, ramp) of set_param_at
        if self._size != 1.0:
            self._size = 1.0
            self._refresh_design_cache()
            self.target[:] = self._fresh
        self.y[:] = 0.0
        self.last[0] = 0.0
        self.coef[:] = self.target
        self.meta[:] = BankMeta(0, 0, self.model.n_modes)
        self._ramping = False
        if self._heard is not None:
            self._heard[:] = 0.0
            self._tables.values[REMEMBERED, self._slot] = 0.0

    def _refresh_design_cache(self) -> None:
        """Keep the design for the current parameters (``fresh``; for an anytime budget
        also in its tables, with the per-mode rows that depend on the poles)."""
        self._fresh = self._design()
        if self._tables is not None:
            self._design_to_tables()
            self._refresh_forcing()

    def _design_to_tables(self) -> None:
        """Copy the current design into the budget's tables: the fresh rows, and the gain
        times the level gain and the fragment size (an impact elsewhere is ranked by them)."""
        self._fresh_rows[:] = self._fresh
        values, slot = self._tables.values, self._slot
        values[GAIN_LEVEL, slot], values[SIZE, slot] = self.values["gain"] * self._level_gain, self._size

    def _refresh_forcing(self) -> None:
        """Per mode (internal order), in the budget's rows: sin^2 theta, 1 / (R^2 sin^2
        theta), the energy decay over a period R^(2 period), the share of the period a free
        decay fills (FILL, ugens.modal_budget), the build-up under a steady
        force over the budget's horizon tau, (1 - e^{-2 d tau}) / (2 d) in s (the
        amplitude^2 a stationary force of power spectral density S gives it is unit2 S
        times this), and the DFT bin of its frequency in a budget period."""
        v = self.values
        key = (float(v["freq_scale"]), float(v["decay_scale"]), float(self._size))
        if key == self._forcing_key:  # a location or gain change: nothing to redo
            return
        self._forcing_key = key
        _, _, sin2, inv = self._poles
        model, rate, horizon = self.model, float(self.sample_rate), float(self._horizon)
        modal_budget.forcing_rows(
            self._mode_rows_view, self._psd_bins, sin2, inv, self._fresh[COEF_C2], model.frequencies,
            model.decays, self.order, key, (self._heard.size, rate, horizon),
        )  # fmt: skip
        self._tables.values[REMEMBERED, self._slot] = 0.0  # (the SPECTRUM row: a PSD of other modes)

    def _param_changed(self, key: str, value: Any, jump: bool) -> None:
        if self._held:  # more keys of the same change follow (:meth:`_set_together`)
            return
        if self._tables is not None and self._jumps_gains_only(jump):
            self._jump_in_place()
            return
        self._settle()
        before = self._poles
        self._refresh_design_cache()
        if self._tables is not None:  # modes a budget silenced follow ramps virtually:
            out = ~self._kept_mask
            self.coef[:, out] = self.target[:, out] - self.meta[RAMP_LEFT] * self.delta[:, out]
        self.target[:] = self._fresh
        ramp = self.ramp_samples()
        if jump or ramp < 1:
            if before is not None and before[0] != self._poles[0] and self.y.any():
                self._jump_poles(before[1])
            else:
                self.coef[:] = self.target
            self.meta[RAMP_LEFT] = 0
        else:
            self.delta[:] = (self.target - self.coef) / ramp
            self.meta[RAMP_LEFT] = ramp
        self._ramping = self.meta[RAMP_LEFT] > 0

    def _jumps_gains_only(self, jump: bool) -> bool:
        """Whether a change jumps to a design with the current poles (a new location or
        gain at each impact of a rigid scene): then a budgeted bank's coefficients jump to
        the fresh design in its tables and its compact bank's kept columns in place
        (ugens.modal_budget.jump_to_fresh), which is what writing the compact bank back,
        jumping and gathering it again gives."""
        v = self.values
        key = (v["freq_scale"], v["decay_scale"], self._size)
        return self._poles is not None and self._poles[0] == key and (jump or self.ramp_samples() < 1)

    def _jump_poles(self, old_poles: np.ndarray) -> None:
        """A jump of freq_scale or decay_scale: each ringing mode keeps its amplitude and
        phase (:func:`retune_state`, as a fragment-size retune). Reading the state (y1, y2)
        with the new pole instead scales a mode's amplitude by about sin theta_old /
        sin theta_new, a rate-dependent error: a mode jumped to near Nyquist came out up to
        15 dB louder at 48 kHz than at 192 kHz. The retune's kink correction is left out (a
        program applies events between sub-blocks, with no frame to add it to)."""
        y1, y2 = self.y
        rate = float(self.sample_rate)
        fp = float(self.last[0])
        retune_state(self.coef, self._fresh, old_poles, self._poles[1], y1, y2, fp, rate, self._tuning)
        self.target[:] = self.coef

    def set_param_at(self, frame: int, key: str, value: Any, jump: bool, ramp: float | None) -> None:
        """Queue a parameter change for ``frame``: :meth:`process` applies it there (a location
        jump at each impact of a rigid scene need not split the graph's sub-block)."""
        self._pending.append((frame, key, value, jump, ramp))
        if self._change_watch is not None:
            self._change_watch[id(self)] = self

    def process(self, start: int, n: int, offset: int = 0) -> None:
        """Frames [start, start + n) from the inputs' samples [offset, offset + n) of this
        sub-block into out[offset : offset + n] (an anytime budget renders a sub-block in
        pieces split where it decides)."""
        steady = self._steady
        if steady is not None and not offset and not self._pending:
            steady(self._input.out, self.out, start, n, self._steady_rows, self._floor)
            return
        inp, out = self._input.out, self.out
        if offset:
            inp, out = inp[offset:], out[offset:]
        sizes = self._size_changes(n, offset) if self._size_input is not None else ()
        if not self._pending and not len(sizes):
            self._span(inp, out, start, n)
            return
        pending, done, k = self._pending, 0, 0
        kinks = []  # (frame offset, end correction) of the retunes
        while True:
            at_event = pending[0][0] - start if pending and pending[0][0] < start + n else n
            at_size = sizes[k] if k < len(sizes) else n
            at = min(at_event, at_size)
            if at >= n:
                break
            if at > done:
                self._span(inp[done:], out[done:], start + done, at - done)
                done = at
            if at_size <= at_event:
                kinks.append((at_size, self._retune(float(self._size_input.out[offset + at_size]))))
                k += 1
            else:
                self._apply_queued()
        if done < n:
            self._span(inp[done:], out[done:], start + done, n - done)
        for at, correction in kinks:
            out[at] += correction

    def _set_together(self, changes: list[tuple[str, Any]], jump: bool, ramp: float | None) -> None:
        """Parameter changes for one frame (the keys of one ``set`` event) with one redesign:
        each value is checked and set in turn, the bank reacts once, to the last. A jump (or
        a change without a ramp) of freq_scale or decay_scale retunes the ringing modes with
        the gains of the moment, so such changes apply key by key, as the compiled program
        applies them (and so do changes of ``smooth``, which times the ramps of the keys after it)."""
        self._event_ramp = ramp
        try:
            steps = self.ramp_samples()
        finally:
            self._event_ramp = None
        keys = {key for key, _ in changes}
        if "smooth" in keys or ((jump or steps < 1) and keys & {"freq_scale", "decay_scale"}):
            for key, value in changes:
                self.set_param(key, value, jump=jump, ramp=ramp)
            return
        self._held = True
        try:
            for key, value in changes[:-1]:
                self.set_param(key, value, jump=jump, ramp=ramp)
        finally:
            self._held = False
        self.set_param(*changes[-1], jump=jump, ramp=ramp)

    def _size_changes(self, n: int, offset: int = 0) -> np.ndarray:
        """Offsets from ``offset`` in this block where the size input differs from the size
        before it."""
        return size_changes(self._size_input.out[offset:], n, self._size)

    def _retune(self, size: float) -> float:
        """Retune to fragment size ``size`` from the next frame n0 on, keeping every
        ringing mode's amplitude and phase: frame n0 still rings at the old tuning (it
        hears the force sample before it with the old gain), and y = A R^k sin(k theta +
        phi) continues from the same (A, phi) at n0 with the new R and theta.

        Returns the end correction for frame n0. The retune bends each mode's waveform
        there (its slope jumps, its value does not); sampled as it is, that kink folds its
        1/f^2 spectrum about Nyquist as a sampled impulse response does (see
        :func:`direct_ratio`), a broadband error that dense events (crumpling) repeat
        hundreds of times a second. The correction is the direct gain's counterpart for a
        kink: per unit slope jump (per sample), the bank's direct gain per unit initial
        slope of a mode, K / theta with K = (d / g) R sin theta (1/12 for ``"taylor"``),
        for the sine part of the jump (A cos phi, initial slope theta) and the cosine
        part (A sin phi, initial slope -delta, delta = -ln R). A mode moved to or above
        Nyquist rings out at its old pole, damped to -60 dB within LEAVING_FADE s (cutting
        it would be a step)."""
        if size == self._size:
            return 0.0
        self._settle()
        old_poles = self._pole_design()[0]
        self._size = size
        self._refresh_design_cache()
        self.meta[RAMP_LEFT] = 0
        self._ramping = False
        y1, y2 = self.y
        fp, rate = float(self.last[0]), float(self.sample_rate)
        new_poles, tuning = self._poles[1], self._tuning
        correction = retune_state(self.coef, self._fresh, old_poles, new_poles, y1, y2, fp, rate, tuning)
        self.target[:] = self.coef
        return correction

    def _span(self, inp: np.ndarray, out: np.ndarray, start: int, n: int) -> None:
        """Frames start .. start + n - 1 from force ``inp[:n]`` into ``out[:n]``."""
        if self.budgeted:
            self._span_kept(inp, out, start, n)
        elif self._mixed and not self._ramping:
            self._span_mixed(inp, out, start, n)
        elif self._ramping:
            self._settle()
            y, meta = self.y, self.meta
            meta[ACTIVE] = meta[ALLOWED]
            ramp = Ramp(self.coef, self.delta, self.target)
            meta[RAMP_LEFT] = resonate_ramp(
                inp, out, n, ramp, y[0], y[1], meta[RAMP_LEFT], meta[ACTIVE], self.last
            )
            self._ramping = meta[RAMP_LEFT] > 0
        else:
            self._settle()
            if self._bank_handle is None:  # (a budget's attach moved the rows: made again on use)
                self._bank_handle = handle(BankArrays(self.bank, self.meta, self.last))
            call = self._bank_call
            if call is None:
                call = self._bank_call = self._call(bank_span, self._bank_handle)
            call(inp, out, start, n, self._bank_handle, self._floor)
            self._hold_steady(call, self._bank_handle)

    def _hold_steady(self, call, rows: np.ndarray) -> None:
        """Let :meth:`process` call ``call`` on ``rows`` directly (no parameter change, ramp,
        budget or size input in between) until :meth:`_settle` ends it: spans of 64 frames
        at 64 modes cost ~1 us, a third of it the Python around the kernel."""
        if self._size_input is None:
            self._steady, self._steady_rows = call, rows

    def _span_kept(self, inp: np.ndarray, out: np.ndarray, start: int, n: int) -> None:
        """As :meth:`_span` for a budgeted bank: only the kept modes, in the budget's compact
        bank (ugens.modal_kept); the force goes to the budget period's ring (continuous
        excitation), its coefficients ramping while the bank's meta says so."""
        self._anytime_entry("span")(self._tables_handle, self._slot, inp, out, start, n)

    def _span_mixed(self, inp: np.ndarray, out: np.ndarray, start: int, n: int) -> None:
        """As :meth:`_span` with the modes split by precision: float64 modes write out,
        float32 modes add to it."""
        if self._split is None:
            self._split = split_by_precision(self.bank, self.sample_rate)
            self._split_handle = handle(self._split.rows, (self.last,))
        call = self._mixed_call
        if call is None:
            call = self._mixed_call = self._call(mixed_span, self._split_handle)
        call(inp, out, start, n, self._split_handle, self._floor)
        self._hold_steady(call, self._split_handle)

    def _apply_queued(self) -> None:
        """Apply the first queued parameter change (:meth:`set_param_at`) and those queued
        for the same frame with the same jump and ramp, together."""
        pending = self._pending
        frame, key, value, jump, ramp = pending.popleft()
        changes = [(key, value)]
        while pending and pending[0][0] == frame and pending[0][3:] == (jump, ramp):
            changes.append(pending.popleft()[1:3])
        self._set_together(changes, jump, ramp)

    # ------------------------------------------------------------ anytime synthesis
    def anytime_compiled(self) -> bool:
        """Whether the budget's compiled render (ugens.modal_kept.render_kept, which also
        runs coefficient ramps) can render the bank's spans throughout a render: no size
        input (queued parameter changes the budget applies between spans,
        :meth:`anytime_apply`; a budgeted bank's ramp is read from its meta's RAMP_LEFT)."""
        return self._size_input is None

    def anytime_changes(self, end: int) -> list[int] | tuple:
        """The frames before ``end`` of the parameter changes queued (:meth:`set_param_at`)."""
        if not self._pending:
            return ()
        return [change[0] for change in self._pending if change[0] < end]

    def anytime_watch(self, watch: dict) -> None:
        """From now on enter this bank in ``watch`` (by id) whenever a parameter change is
        queued (:meth:`set_param_at`; now too if one is): the budget that renders the bank
        asks only the banks entered there for their changes (asking each of the wok
        scene's 15 banks at every sub-block cost ~6 us)."""
        self._change_watch = watch
        if self._pending:
            watch[id(self)] = self

    def anytime_apply(self, frame: int) -> None:
        """Apply the parameter changes queued for frames up to ``frame``: the budget has
        rendered the bank up to there (as :meth:`process` does between its spans)."""
        pending = self._pending
        while pending and pending[0][0] <= frame:
            if not self._jump_location(pending):
                self._apply_queued()

    def _jump_location(self, pending: deque) -> bool:
        """Apply the first queued change if it is a location alone (a parsed Location, no
        other key at its frame) to which the bank jumps with its current poles: a rigid
        scene's before each impact. Then only the design, the budget's tables and the
        kept modes' jump in place change (:meth:`_jump_in_place`), and the
        value was checked when its event was (jassy.scheduler.prepare_score): the
        re-check and the dispatch of :meth:`_set_together` and :meth:`set_param`, about
        half of such a change's ~17 us, are left out. Returns whether it applied it."""
        frame, key, value, jump, ramp = pending[0]
        if self._tables is None or key != "location" or type(value) is not Location:
            return False
        if len(pending) > 1 and pending[1][0] == frame and pending[1][3:] == (jump, ramp):
            return False  # (keys changed together: _apply_queued)
        if jump:
            gains_only = self._jumps_gains_only(jump)
        else:  # (whether it ramps depends on the event's own ramp)
            self._event_ramp = ramp
            try:
                gains_only = self._jumps_gains_only(jump)
            finally:
                self._event_ramp = None
        if not gains_only:
            return False
        pending.popleft()
        self.values["location"] = value
        self._jump_in_place()
        return True

    def _jump_in_place(self) -> None:
        """A budgeted bank's jump to the fresh design with its current poles
        (:meth:`_jumps_gains_only`): the design, the budget's tables and the kept modes in
        place (ugens.modal_budget.jump_to_fresh); no ramp left. (The poles are the same, so
        :meth:`_refresh_forcing` finds its per-mode rows current and returns.)"""
        self._refresh_design_cache()
        self._anytime_entry("jump")(self._tables_handle, self._slot)
        self.meta[RAMP_LEFT] = 0
        self._ramping = False

    def anytime_attach(
        self, tables: BudgetTables, slot: int, horizon: float, weighting: str, tables_handle=None
    ) -> None:
        """Start a budgeted render: the bank's rows move into column ``slot`` of the
        budget's ``tables`` (ugens.modal_budget; decisions every period, the ring's
        length); a continuous force is judged by the amplitude it builds in ``horizon``
        seconds; modes are weighted by ``weighting`` ("flat" or "A", see jassy.anytime).
        ``tables_handle``: the tables' handle (jassy.record_views) if the budget made it.
        The tables are fresh (ugens.modal_budget.allocate_tables: zeros, every mode kept)."""
        self._settle()
        k, first, bank_at, coef_at, _ = tables.layout[:, slot].tolist()
        self._tables, self._slot = tables, slot
        bank = tables.bank[bank_at : bank_at + 6 * k].reshape(6, k)
        bank[:] = self.bank
        target = tables.target[coef_at : coef_at + 4 * k].reshape(4, k)
        target[:] = self.target
        delta = tables.delta[coef_at : coef_at + 4 * k].reshape(4, k)
        delta[:] = self.delta
        self.bank, self.target, self.delta = bank, target, delta
        self.coef, self.y = bank[:4], bank[4:]
        self._fresh_rows = tables.fresh[coef_at : coef_at + 4 * k].reshape(4, k)
        self._design_to_tables()
        tables.meta[slot] = self.meta
        self.meta = tables.meta[slot]
        self.meta[ALLOWED] = k
        tables.last[slot] = self.last[0]
        self.last = tables.last[slot : slot + 1]
        self._bank_handle = None  # (a budgeted render does not use it: made again on use)
        values = tables.values
        values[FLOOR, slot], values[FLOOR2, slot] = self._floor, self._floor * self._floor
        values[TRANSFORMED, slot] = k > FLAT_SPECTRUM_MODES
        self._compact_meta = tables.compact_meta[slot]
        cut = slice(first, first + k)
        self._kept_mask, self._faded = tables.kept[cut], tables.faded[cut]
        self._mode_rows_view = tables.rows[:, cut]
        if weighting == "A":
            self._mode_rows_view[WEIGHT] = a_weighting_power(self.model.frequencies[self.order])
        else:
            self._mode_rows_view[WEIGHT] = 1.0
        self._heard = tables.rings[slot]
        self._psd_bins = tables.bins[cut]
        self._horizon = horizon
        self._forcing_key = None
        self._tables_handle = handle(tables) if tables_handle is None else tables_handle
        self._anytime_entries = {}
        self._refresh_forcing()

    def _anytime_entry(self, name: str):
        """A budgeted bank's compiled entry point ``name``: "settle" (its compact bank's
        state back into its rows), "jump" (its coefficients to the fresh design in place)
        or "span" (its kept modes over a span, for a bank rendering through its own
        ``process``), found on first use: most banks of a budget use none of them (their
        argument types are fixed: jassy.anytime.fixed_entry)."""
        entry = self._anytime_entries.get(name)
        if entry is None:
            from ugens import modal_kept  # (not at the top: it imports this module)

            at, slot = self._tables_handle, self._slot
            kernel, example = {
                "settle": (modal_kept.settle_at, (at, slot)),
                "jump": (modal_budget.jump_at, (at, slot)),
                "span": (modal_kept.kept_span, (at, slot, self.out, self.out, 0, 0)),
            }[name]
            entry = self._anytime_entries[name] = fixed_entry(kernel, *example)
        return entry

    def active_modes(self) -> int:
        """The modes the bank computes now (its kernels' active count)."""
        return int(self.meta[ACTIVE])

    def state_arrays(self) -> dict[str, np.ndarray]:
        self._settle()
        return {
            "bank": self.bank,
            "delta": self.delta,
            "target": self.target,
            "meta": self.meta,
            "last": self.last,
        }

    def _state_restored(self) -> None:
        self._forget_split()
        self._ramping = self.meta[RAMP_LEFT] > 0

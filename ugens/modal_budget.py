"""Compiled parts of anytime synthesis for ModalBank: the tables every budgeted bank keeps
its rows in, and one decision over all of them (importance, ranking, kept sets).

A budgeted bank keeps its modes in their internal order and computes only the kept ones:
their rows are gathered into a compact bank (the same row layout, so the same kernels run
on it, at a cost proportional to the kept modes) and scattered back when the kept set or
the coefficients change. Modes outside the kept set hold zero state. The kept set is the
mask ``BudgetTables.kept`` alone; its size is the bank's ``meta[ALLOWED]`` (the most modes that
may be active), the compact bank's width that size rounded up to whole vectors.

Every budgeted bank's rows live in shared flat stores (:class:`BudgetTables`; bank b's
(rows, modes) block at its offsets, so each bank still sees C-contiguous arrays), and a
decision is one compiled call over all banks (:func:`decide`) instead of several per bank.

Importance of mode k for the coming budget period (see jassy.anytime):

    I_k = w_k (max(F_k A_k^2, u_k S(f_k) G_k) + F_k (u_k sum_j J_j^2 + E_k))

A_k^2 = (y1^2 - c1 y1 y2 + c2 y2^2) / sin^2 theta: the squared amplitude of the
decaying sine through the last two state samples; F_k = (1 - R^(2 P)) / (P (1 - R^2)) the
share of the period's P samples a free decay from amplitude A fills at A^2 (its energy
over the period is F P A^2: a mode gone in a few ms weighs by the little it sounds, not
by its amplitude now; 1 for a mode that does not decay, as a steady force's build-up
counts); u_k = (g fs)^2 / (R^2 sin^2 theta) the
squared amplitude per unit impulse (N s) at the bank's current location; S the force's
power spectral density at the mode's frequency (N^2/Hz); G_k = (1 - e^{-2 d tau}) / (2 d)
the build-up of a steady force over the horizon tau (s); J_j the impulses scheduled at the
current location and E_k the squared amplitudes of impacts scheduled elsewhere.
"""

from __future__ import annotations

from typing import NamedTuple

import numba as nb
import numpy as np

from jassy import anytime_rank, record_views
from jassy.anytime_rank import centred_power, rank_modes
from jassy.jit import address, drop_stale_cache, void_pointer
from jassy.packed_arrays import BOOL, FLOAT, INT, packed_zeros
from jassy.record_views import FIELD, bool_row, float_row, float_table, int_row, int_table
from ugens import cells, modal_block, modal_meta, modal_retune, real_fft
from ugens.cells import mode_rows
from ugens.modal_block import BLOCK_TABLE
from ugens.modal_meta import ACTIVE, ALLOWED, GATHERED, RAMP_LEFT, WIDTH
from ugens.modal_retune import COEF_GAIN
from ugens.real_fft import real_spectrum, twiddles

drop_stale_cache(
    __file__, [anytime_rank, cells, modal_block, modal_meta, modal_retune, real_fft, record_views]
)  # its cache holds copies of their kernels

#: Rows of a compact bank: c1, c2, g, d, y1, y2 (BANK_ROWS as ModalBank.bank,
#: ugens.cells.ModeRows), then the ramp's per-sample increments (from row RAMP_DELTA) and
#: targets (from row RAMP_TARGET) of the COEF_ROWS coefficients c1, c2, g, d.
BANK_ROWS, COEF_ROWS = 6, 4
RAMP_DELTA, RAMP_TARGET = BANK_ROWS, BANK_ROWS + COEF_ROWS
COMPACT_ROWS = BANK_ROWS + 2 * COEF_ROWS

#: The compact bank of the kept modes is padded to a multiple of this many modes: the mode
#: loop then runs in whole SIMD vectors (30 modes cost 1.5x 32 without it).
KEPT_LANES = 8

#: Per-mode rows of :attr:`BudgetTables.rows` (one column per mode of every bank): sin^2
#: theta; 1 / (R^2 sin^2 theta); the build-up G under a steady force (s); the energy decay
#: over one period, R^(2 period); the importance weight; the force's PSD at the mode's
#: frequency (N^2/Hz, banks that hear a force through a transform); squared amplitudes of
#: the impacts scheduled elsewhere on the bank, this period and the next; the share of the
#: period a free decay fills, (1 - R^(2 period)) / (period (1 - R^2)).
SIN2, INV, GROWTH, DECAY, WEIGHT, SPECTRUM, ELSEWHERE_NOW, ELSEWHERE_NEXT, FILL = range(9)
MODE_ROWS = 9

#: Per-bank integer fields of :attr:`BudgetTables.layout`: mode count; its first column
#: in the per-mode rows; offsets of its (6, modes) bank rows, of its (4, modes) target,
#: delta and fresh rows, and of its compact bank in their stores.
MODES, FIRST, BANK_AT, COEF_AT, COMPACT_AT = range(5)

#: Per-bank fields of :attr:`BudgetTables.values`: sum of squared impulses (N^2 s^2) at the
#: current location this period and the next; 1.0 if impacts elsewhere fill the
#: ELSEWHERE_NOW / ELSEWHERE_NEXT rows; 1.0 if SPECTRUM holds the force's PSD (else the
#: force's power counts flat over frequency); the state magnitude below which a mode is
#: silent (ModalBank's ``floor``), and its square; the bank's gain times its level gain
#: and its fragment size (an impact's amplitude per mode elsewhere is its location's
#: gain times impulse times the first, over the root of the second); 1.0 once SPECTRUM
#: holds a smoothed PSD to blend the next with; 1.0 if the bank judges a force by its
#: periodogram (more modes than FLAT_SPECTRUM_MODES); the frame of its last periodogram;
#: the power of the force it heard over the last period at the last decision (N^2, its
#: ring's centred mean square: the flat PSD's and jassy.anytime_rank.note_decided's).
(
    KICK_NOW, KICK_NEXT, HAS_ELSEWHERE_NOW, HAS_ELSEWHERE_NEXT, SPECTRAL, FLOOR, FLOOR2, GAIN_LEVEL, SIZE,
    REMEMBERED, TRANSFORMED, PSD_FRAME, RING_POWER,
) = range(13)  # fmt: skip
BANK_VALUES = 13

#: A bank that keeps hearing a force ranks by its remembered (smoothed) PSD at a decision
#: at most this many budget periods after its last periodogram, so that decisions every
#: period (impacts coming) transform at every fourth one: the transform is most of a
#: decision's cost (~20 of ~40 us on the wok's 241 modes). Against one period (every
#: other decision): the wok's compiled steps ~0.2 ms (of ~4) faster, its 25 % error
#: -17.11 -> -17.15 dB, scrape's -17.23 -> -17.06 dB. (Scaling the remembered PSD to the
#: force's power now was tried: the wok's bursty contacts then lost 0.4-0.7 dB.)
PSD_REUSE_PERIODS = 3

#: Banks of at most this many modes judge a continuous force by its power alone (spread
#: flat over frequency), without a transform.
FLAT_SPECTRUM_MODES = 8

#: Weights that smooth a force's periodogram over neighbouring bins.
PSD_SMOOTHING = np.array([1.0, 2.0, 3.0, 2.0, 1.0]) / 9.0

#: The share of the previous smoothed periodogram kept at each decision.
PSD_MEMORY = 0.75

#: Rows of :attr:`BudgetTables.spectra` (one budget period wide, the same for every
#: budget of that period and only read): the Hann window and the transform's cos and sin
#: table (ugens.real_fft.twiddles).
WINDOW, COS, SIN = range(3)
SPECTRA_ROWS = 3

#: Rows of a periodogram's scratch (:func:`periodogram` allocates it): the period's force
#: centred and windowed, the transform's scratch (real, imaginary) and the spectrum (real,
#: imaginary).
WINDOWED, PACKED_RE, PACKED_IM, SPECTRUM_RE, SPECTRUM_IM = range(5)
SCRATCH_ROWS = 5


class BudgetTables(NamedTuple):
    """The rows of every bank a mode budget shares, in flat stores (ModalBank's arrays are
    C-contiguous views of them) and per-mode / per-bank tables."""

    layout: np.ndarray  # int64 (5, banks): MODES .. COMPACT_AT
    bank: np.ndarray  # float64: per bank (6, modes) c1, c2, g, d, y1, y2 (ModalBank.bank)
    target: np.ndarray  # float64: per bank (4, modes), the coefficients' ramp targets
    delta: np.ndarray  # float64: per bank (4, modes), their per-sample ramp increments
    fresh: np.ndarray  # float64: per bank (4, modes), the design for the current parameters
    compact: np.ndarray  # float64: per bank (COMPACT_ROWS, width): the kept modes' rows
    meta: np.ndarray  # int64 (banks, 3): ModalBank.meta [active, ramp samples left, kept]
    compact_meta: np.ndarray  # int64 (banks, 3): [active, gathered (1) or stale (0), width]
    rows: np.ndarray  # float64 (MODE_ROWS, modes)
    kept: np.ndarray  # bool (modes,): computed (the kept set, fading modes included)
    faded: np.ndarray  # bool (modes,): fading out in this period
    rings: np.ndarray  # float64 (banks, period): the force over the last period, frame t at t mod period
    last: np.ndarray  # float64 (banks,): ModalBank.last, the force sample before the next frame
    values: np.ndarray  # float64 (BANK_VALUES, banks)
    bins: np.ndarray  # int64 (modes,): the periodogram's bin at each mode's frequency
    spectra: np.ndarray  # float64 (SPECTRA_ROWS, period): a periodogram's window and twiddles (shared)
    blocks: (
        np.ndarray
    )  # float64 (banks, BLOCK_TABLE): block tables of banks of few kept modes (ugens.modal_block)


@nb.njit(cache=True)
def tables_at(a, i):
    """The :class:`BudgetTables` whose fields start at slot ``i`` of handle ``a``
    (jassy.record_views)."""
    return BudgetTables(
        int_table(a, i), float_row(a, i + FIELD), float_row(a, i + 2 * FIELD), float_row(a, i + 3 * FIELD),
        float_row(a, i + 4 * FIELD), float_row(a, i + 5 * FIELD), int_table(a, i + 6 * FIELD),
        int_table(a, i + 7 * FIELD), float_table(a, i + 8 * FIELD), bool_row(a, i + 9 * FIELD),
        bool_row(a, i + 10 * FIELD), float_table(a, i + 11 * FIELD), float_row(a, i + 12 * FIELD),
        float_table(a, i + 13 * FIELD), int_row(a, i + 14 * FIELD), float_table(a, i + 15 * FIELD),
        float_table(a, i + 16 * FIELD),
    )  # fmt: skip


#: Fields of a :class:`BudgetTables` (slots of FIELD in a handle), and the place of the
#: one not in a budget's buffer (:func:`allocate_tables`).
TABLE_FIELDS = len(BudgetTables._fields)
SPECTRA_FIELD = BudgetTables._fields.index("spectra")


def aligned(size: int) -> int:
    """``size`` rounded up to whole 64-byte cache lines of float64."""
    return -(-size // 8) * 8


def line_aligned_zeros(shape: tuple[int, ...]) -> np.ndarray:
    """A C-contiguous float64 array of zeros starting on a 64-byte cache-line boundary.

    The mode loop's vector loads then never straddle cache lines: a bank 16 bytes off the
    boundary ran the 1000-mode bell about 13 % slower (``jassy bench modal``)."""
    return packed_zeros([(shape, FLOAT)]).arrays[0]


def budget_tables(mode_counts: list[int], period: int) -> BudgetTables:
    """Empty tables for banks of ``mode_counts`` modes and a budget ``period`` (frames, a
    power of two)."""
    return allocate_tables(mode_counts, period).tables


class Allocated(NamedTuple):
    """:class:`BudgetTables` and their handle slots (jassy.record_views: three per field),
    and the arrays of the ``more`` fields of :func:`allocate_tables` and their slots."""

    tables: BudgetTables
    table_slots: tuple
    arrays: list[np.ndarray]
    slots: list[tuple[int, int, int]]


def allocate_tables(mode_counts: list[int], period: int, more=()) -> Allocated:
    """Empty :class:`BudgetTables` for banks of ``mode_counts`` modes and a budget
    ``period`` (frames, a power of two), and their handle slots: the fields are views of one
    zeroed buffer (jassy.packed_arrays; each starts on a 64-byte cache line), the window
    and twiddles shared (:func:`spectra_rows`); ``more`` fields ((shape, dtype) pairs) in
    the same buffer."""
    count = len(mode_counts)
    first = bank_at = coef_at = compact_at = 0
    places = []
    for k in mode_counts:
        places.append((k, first, bank_at, coef_at, compact_at))
        first += k
        bank_at += aligned(BANK_ROWS * k)
        coef_at += aligned(COEF_ROWS * k)
        compact_at += COMPACT_ROWS * aligned(k + KEPT_LANES)
    f, i, b = FLOAT, INT, BOOL
    owned = (  # (shape, dtype) of the fields in the buffer, in BudgetTables' order (spectra: shared)
        ((5, count), i), ((bank_at,), f), ((coef_at,), f), ((coef_at,), f), ((coef_at,), f),
        ((compact_at,), f), ((count, 3), i), ((count, 3), i), ((MODE_ROWS, first), f), ((first,), b),
        ((first,), b), ((count, period), f), ((count,), f), ((BANK_VALUES, count), f), ((first,), i),
        ((count, BLOCK_TABLE), f),
    )  # fmt: skip
    arrays, slots = packed_zeros((*owned, *more))
    n, at = len(owned), SPECTRA_FIELD
    tables = BudgetTables(*arrays[:at], spectra_rows(period), *arrays[at:n])
    table_slots = (*slots[:at], _SPECTRA_SLOTS[period], *slots[at:n])
    tables.layout.T[:] = places  # the layout
    tables.kept[:] = True  # every mode kept
    return Allocated(tables, table_slots, arrays[n:], slots[n:])


#: :func:`spectra_rows` by period, computed once per process and shared by every budget,
#: their handle slots (jassy.record_views; the address of a read-only array is found by a
#: slow path, ~25 us at a render's start) and the window's energy (the sum of its squares)
#: by period
_SPECTRA: dict[int, np.ndarray] = {}
_SPECTRA_SLOTS: dict[int, tuple[int, int, int]] = {}
_WINDOW_ENERGY: dict[int, float] = {}


def spectra_rows(period: int) -> np.ndarray:
    """:attr:`BudgetTables.spectra` for a ``period`` (a power of two): the Hann window and
    the transform's tables, computed for the first budget of that period (they cost
    ~0.1-0.3 ms) and shared by all (compiled code only reads them; a periodogram's
    scratch is its own)."""
    spectra = _SPECTRA.get(period)
    if spectra is None:
        spectra = _SPECTRA[period] = np.zeros((SPECTRA_ROWS, period))
        spectra[WINDOW] = np.hanning(period)
        spectra[[COS, SIN], : period // 2 + 1] = twiddles(period)
        _WINDOW_ENERGY[period] = float(np.sum(spectra[WINDOW] ** 2))
        _SPECTRA_SLOTS[period] = (address(spectra), *spectra.shape)
        spectra.flags.writeable = False  # (shared: a write would change every budget's)
    return spectra


def window_power(period: int, sample_rate: float) -> float:
    """The periodogram's scale for a budget ``period``: the sample rate (Hz) times the
    energy of :func:`spectra_rows`' window (a PSD in N^2/Hz; :attr:`Rates.window_power`)."""
    if period not in _WINDOW_ENERGY:
        spectra_rows(period)
    return sample_rate * _WINDOW_ENERGY[period]


@nb.njit(inline="always", cache=True)
def rows_in(store, at, rows, columns):
    """store[at : at + rows * columns] (float64, C-contiguous, that long) as a C-contiguous
    (rows, columns) view, made from its address: numba's reshape calls a C helper, ~17 ns
    (three to five of them were a third of a small bank's importance and kept-set
    change). For compiled callers only, as jassy.record_views' fields: the view neither
    keeps ``store`` alive nor checks its length (the tables' layout gives every bank
    room for its rows and a compact bank of all its modes)."""
    return nb.carray(void_pointer(store[at:].ctypes.data), (rows, columns), np.float64)


@nb.njit(cache=True)
def bank_rows(t, b):
    """Bank b's (BANK_ROWS, modes) rows c1, c2, g, d, y1, y2 in the tables ``t`` (a view
    for compiled callers: :func:`rows_in`)."""
    return rows_in(t.bank, t.layout[BANK_AT, b], BANK_ROWS, t.layout[MODES, b])


@nb.njit(cache=True)
def coef_rows(store, t, b):
    """Bank b's (COEF_ROWS, modes) rows c1, c2, g, d in ``store`` (the tables' target,
    delta or fresh; a view for compiled callers: :func:`rows_in`)."""
    return rows_in(store, t.layout[COEF_AT, b], COEF_ROWS, t.layout[MODES, b])


@nb.njit(inline="always", cache=True)
def squared_amplitude(c1, c2, y1, y2):
    """A^2 sin^2 theta of the decaying sine through a mode's last two state samples y1,
    y2 (c1 = 2 R cos theta, c2 = R^2): y1^2 - c1 y1 y2 + c2 y2^2."""
    return y1 * y1 - c1 * y1 * y2 + c2 * y2 * y2


@nb.njit(cache=True)
def gather_kept(bank, delta, target, kept, compact):
    """Copy the rows of the modes ``kept`` (a mask) into the first columns of ``compact``
    (bank rows 0-5, delta rows 6-9, target rows 10-13); its further columns become
    silent modes."""
    compact[:, :] = 0.0
    j = 0
    for k in range(kept.size):
        if kept[k]:
            for r in range(BANK_ROWS):
                compact[r, j] = bank[r, k]
            for r in range(COEF_ROWS):
                compact[RAMP_DELTA + r, j] = delta[r, k]
                compact[RAMP_TARGET + r, j] = target[r, k]
            j += 1


@nb.njit(cache=True)
def compact_bank(t, b):
    """Bank b's compact bank, gathered from its rows first if stale (its width: the kept
    modes rounded up to whole vectors of KEPT_LANES; a view for compiled callers:
    :func:`rows_in`)."""
    meta = t.compact_meta[b]
    at = t.layout[COMPACT_AT, b]
    if meta[GATHERED]:
        width = meta[WIDTH]
        return rows_in(t.compact, at, COMPACT_ROWS, width)
    k, o = t.layout[MODES, b], t.layout[FIRST, b]
    width = (t.meta[b, ALLOWED] + KEPT_LANES - 1) // KEPT_LANES * KEPT_LANES
    compact = rows_in(t.compact, at, COMPACT_ROWS, width)
    gather_kept(
        bank_rows(t, b), coef_rows(t.delta, t, b), coef_rows(t.target, t, b), t.kept[o : o + k], compact
    )
    meta[ACTIVE] = t.meta[b, ACTIVE]
    meta[GATHERED] = 1
    meta[WIDTH] = width
    return compact


@nb.njit(cache=True)
def scatter_kept(compact, kept, bank):
    """Write the coefficients and state of the compact bank back to the modes ``kept``."""
    j = 0
    for k in range(kept.size):
        if kept[k]:
            for r in range(BANK_ROWS):
                bank[r, k] = compact[r, j]
            j += 1


@nb.njit(cache=True)
def settle_compact(t, b):
    """If bank b's compact bank holds its kept modes' state, write it back to the bank's
    rows; the compact bank is then stale (gathered again by :func:`compact_bank`)."""
    meta = t.compact_meta[b]
    if meta[GATHERED]:
        k, o = t.layout[MODES, b], t.layout[FIRST, b]
        scatter_kept(compact_bank(t, b), t.kept[o : o + k], bank_rows(t, b))
        meta[GATHERED] = 0


@nb.njit(cache=True)
def jump_to_fresh(t, b):
    """Bank b's coefficients jump to its fresh design (a new location or gain: the poles
    and every mode's state stay): its rows' current coefficients and ramp targets become
    the fresh ones, and so do the kept modes' columns of its compact bank if gathered, so
    the compact bank keeps its state in place (no write-back, no gather again)."""
    k, o = t.layout[MODES, b], t.layout[FIRST, b]
    bank, target, fresh = bank_rows(t, b), coef_rows(t.target, t, b), coef_rows(t.fresh, t, b)
    for r in range(COEF_ROWS):
        for i in range(k):
            bank[r, i] = fresh[r, i]
            target[r, i] = fresh[r, i]
    if t.compact_meta[b, GATHERED]:
        compact = compact_bank(t, b)  # (gathered: its view)
        kept, j = t.kept[o : o + k], 0
        for i in range(k):
            if kept[i]:
                for r in range(COEF_ROWS):
                    compact[r, j] = fresh[r, i]
                    compact[RAMP_TARGET + r, j] = fresh[r, i]
                j += 1


@nb.njit(cache=True)
def jump_at(a, b):
    """:func:`jump_to_fresh` of bank b on the tables of handle ``a`` (jassy.record_views)."""
    jump_to_fresh(tables_at(a, 0), b)


@nb.njit(fastmath=True, cache=True, inline="always")
def centred_times(force, mean, window, out):
    """out = (force - mean) * window, element by element (the same length; slices that start
    at their first element: the loop vectorises, where offset indices kept it scalar)."""
    for i in range(force.size):
        out[i] = (force[i] - mean) * window[i]


@nb.njit(fastmath=True, cache=True)
def centred_windowed(force, window, out, oldest):
    """out = (force - its mean) * window, the window starting at sample ``oldest`` of the
    ring ``force`` (its earliest frame) and wrapping around: a period's force ready for
    its periodogram (a steady load makes no sound; the transform's magnitudes do not
    depend on where the ring starts, the window's taper does)."""
    n = force.size
    mean = 0.0
    for i in range(n):
        mean += force[i]
    mean /= n
    centred_times(force[oldest:], mean, window[: n - oldest], out[oldest:])
    centred_times(force[:oldest], mean, window[n - oldest :], out[:oldest])


@nb.njit(cache=True)
def forcing_rows(rows, bins, sin2, inv, c2, frequencies, decays, order, scales, timing):
    """A bank's per-mode rows of a budget in one pass (``timing`` = (period in frames,
    sample_rate in Hz, horizon in s); ``rows``: its columns of :attr:`BudgetTables.rows`,
    ``bins`` of :attr:`BudgetTables.bins`), from its
    poles' sin^2 theta and 1 / (R^2 sin^2 theta), its design's c2 = R^2 (internal order)
    and its model's frequencies (Hz) and decay rates (1/s), ``order`` the model's mode at
    each internal position: SIN2, INV, the energy decay over a period c2^period =
    R^(2 period), the share of the period a free decay fills (FILL: 1 - R^(2 period) over
    period (1 - R^2)), the build-up under a steady force over the horizon tau (s),
    (1 - e^{-2 d tau}) / (2 d) (tau as d -> 0), and the periodogram's bin of each
    frequency (at most period / 2); frequencies and decays scaled by ``scales``
    (freq_scale, decay_scale, fragment size s: both also by 1 / sqrt(s))."""
    period, sample_rate, horizon = timing
    retune = 1.0 / np.sqrt(scales[2])
    freq_scale, decay_scale = scales[0] * retune, scales[1] * retune
    half = period // 2
    for i in range(bins.size):
        j = order[i]
        rows[SIN2, i], rows[INV, i] = sin2[i], inv[i]
        rows[DECAY, i] = c2[i] ** float(period)
        rows[FILL, i] = (1.0 - rows[DECAY, i]) / (period * (1.0 - c2[i])) if c2[i] < 1.0 else 1.0
        bins[i] = int(min(np.rint(frequencies[j] * freq_scale * period / sample_rate), half))
        decay = decays[j] * decay_scale
        two_d_tau = 2.0 * decay * horizon
        rows[GROWTH, i] = -np.expm1(-two_d_tau) / max(2.0 * decay, 1e-300) if two_d_tau > 1e-9 else horizon


@nb.njit(cache=True)
def psd_at_bins(re, im, bins, taps, scale, memory, remembered, psd):
    """Per mode, the periodogram |re + i im|^2 / ``scale`` (N^2/Hz) smoothed over the bins
    ``bins[m] - len(taps) // 2 ...`` with weights ``taps`` (bins past either end count as
    zero), into ``psd``; ``remembered``: blended as memory * psd + (1 - memory) * new (a
    periodogram of noise scatters by its own size: it is the trend that ranks)."""
    edge, size = taps.size // 2, re.size
    for m in range(bins.size):
        total = 0.0
        for t in range(taps.size):
            b = bins[m] + t - edge
            if 0 <= b < size:
                total += (re[b] * re[b] + im[b] * im[b]) * taps[t]
        value = total / scale
        psd[m] = memory * psd[m] + (1.0 - memory) * value if remembered else value


class Decision(NamedTuple):
    """What a decision needs besides the tables: per bank, whether it is woken by a force
    nobody scheduled (``onset``, whose input samples [begin, end) at ``inputs[b]``
    (addresses of float64 arrays) are judged) or heard a force lately; the budget's scores
    (3, modes) and the keep / fade / next-period masks of
    :func:`jassy.anytime_rank.rank_modes`."""

    onset: np.ndarray
    heard: np.ndarray
    inputs: np.ndarray
    scores: np.ndarray
    keep: np.ndarray
    fade: np.ndarray
    later: np.ndarray


class Rates(NamedTuple):
    """Scalars of a decision: sample rate (Hz), the modes the budget may compute, the bonus
    of a kept mode against churn, the amplitude factor per sample of a fading mode, the
    input samples [begin, end) an onset is judged by, the periodogram's scale (the
    sample rate times the window's energy: a PSD in N^2/Hz) and the decision's frame."""

    sample_rate: float
    limit: int
    bonus: float
    shrink: float
    begin: int
    end: int
    window_power: float
    frame: int


@nb.njit(cache=True)
def decision_at(a, i):
    """The :class:`Decision` whose fields start at slot ``i`` of handle ``a``
    (jassy.record_views)."""
    return Decision(
        bool_row(a, i), bool_row(a, i + FIELD), int_row(a, i + 2 * FIELD), float_table(a, i + 3 * FIELD),
        bool_row(a, i + 4 * FIELD), bool_row(a, i + 5 * FIELD), bool_row(a, i + 6 * FIELD),
    )  # fmt: skip


@nb.njit(cache=True)
def periodogram(t, b, window_power, frame):
    """The power spectral density (N^2/Hz) of bank b's force over the period before
    ``frame`` (its ring; centred, Hann-windowed from its earliest frame) at each of its
    modes' bins (:attr:`BudgetTables.bins`), smoothed over PSD_SMOOTHING and blended with
    the last one by PSD_MEMORY, into its SPECTRUM row (ugens.real_fft: no Python between
    the force and the row)."""
    s, x = t.spectra, np.empty((SCRATCH_ROWS, t.spectra.shape[1]))
    half = s.shape[1] // 2
    centred_windowed(t.rings[b], s[WINDOW], x[WINDOWED], frame % s.shape[1])
    re, im = x[SPECTRUM_RE, : half + 1], x[SPECTRUM_IM, : half + 1]
    real_spectrum(x[WINDOWED], s[COS], s[SIN], x[PACKED_RE, :half], x[PACKED_IM, :half], re, im)
    o, k = t.layout[FIRST, b], t.layout[MODES, b]
    remembered = t.values[REMEMBERED, b] > 0.0
    psd_at_bins(
        re,
        im,
        t.bins[o : o + k],
        PSD_SMOOTHING,
        window_power,
        PSD_MEMORY,
        remembered,
        t.rows[SPECTRUM, o : o + k],
    )
    t.values[REMEMBERED, b] = 1.0


@nb.njit(cache=True)
def load_impacts(t, kicks, count, at, period):
    """The impacts scheduled from frame ``at`` to the end of its period and in the next
    period (``period`` frames; rows of the first ``count`` of ``kicks``,
    jassy.anytime_rank.Kicks, in frame order) into the tables: per bank struck, the sum of
    squared impulses at its current location (KICK_NOW / KICK_NEXT) and, for impacts at
    other locations, the squared amplitude per mode, (gain at the location * GAIN_LEVEL *
    impulse)^2 / SIZE, summed in the ELSEWHERE_NOW / ELSEWHERE_NEXT rows (HAS_ELSEWHERE_*
    set). A decision between period starts (a force woke a bank) so still counts the rest
    of its period's impacts. Returns whether some bank is struck."""
    values, rows = t.values, t.rows
    for field in range(KICK_NOW, HAS_ELSEWHERE_NEXT + 1):
        values[field, :] = 0.0
    kicked = False
    next_period = at - at % period + period
    j = np.searchsorted(kicks.frames[:count], at)
    while j < count and kicks.frames[j] < next_period + period:
        b = kicks.slots[j]
        if b >= 0 and kicks.positive[j]:
            kicked = True
            later = 1 if kicks.frames[j] >= next_period else 0
            impulse = kicks.impulses[j]
            if kicks.located[j] < 0:
                values[KICK_NOW + later, b] += impulse * impulse
            else:
                o, k = t.layout[FIRST, b], t.layout[MODES, b]
                row = rows[ELSEWHERE_NOW + later, o : o + k]
                if values[HAS_ELSEWHERE_NOW + later, b] == 0.0:
                    row[:] = 0.0
                    values[HAS_ELSEWHERE_NOW + later, b] = 1.0
                scale, size = values[GAIN_LEVEL, b] * impulse, values[SIZE, b]
                gains = kicks.gains[kicks.located[j] : kicks.located[j] + k]
                for i in range(k):
                    a = gains[i] * scale
                    row[i] += a * a / size
        j += 1
    return kicked


@nb.njit(fastmath=True, cache=True)
def bank_importance(t, d, b, flat_psd, sample_rate, bonus):
    """Importance of bank b's modes for this period (scores[0]) and the next (scores[1],
    the amplitude decayed by a period), and whether each sounds now (scores[2]: 1.0 or
    0.0), into ``d.scores``; kept modes not fading get ``bonus`` (no churn at the margin).
    ``flat_psd``: the force's PSD spread flat over frequency unless SPECTRAL. One pass
    over the modes, the kept set's choices as selects (a branch on it mispredicts as it
    varies from decision to decision)."""
    k, o = t.layout[MODES, b], t.layout[FIRST, b]
    rows, scores, kept, faded = t.rows, d.scores, t.kept, t.faded
    floor2 = t.values[FLOOR2, b]
    gathered = t.compact_meta[b, GATHERED] > 0  # the state in the compact bank, kept modes in order
    if gathered and t.compact_meta[b, WIDTH] == 0:  # none kept (the bank's rows then: none read)
        gathered = False
    state = mode_rows(compact_bank(t, b) if gathered else bank_rows(t, b))  # (modes not kept: zero)
    last, j = state.c1.size - 1, 0
    spectral = t.values[SPECTRAL, b] > 0.0
    has_now, has_next = t.values[HAS_ELSEWHERE_NOW, b] > 0.0, t.values[HAS_ELSEWHERE_NEXT, b] > 0.0
    kick_now, kick_next = t.values[KICK_NOW, b], t.values[KICK_NEXT, b]
    left = float(t.meta[b, RAMP_LEFT])
    target, delta = coef_rows(t.target, t, b)[COEF_GAIN], coef_rows(t.delta, t, b)[COEF_GAIN]
    for i in range(k):
        m = o + i
        at = min(j, last) if gathered else i
        a = squared_amplitude(state.c1[at], state.c2[at], state.y1[at], state.y2[at]) / rows[SIN2, m]
        a = max(a, 0.0) if kept[m] else 0.0
        j += kept[m]
        scores[2, m] = 1.0 if a > floor2 else 0.0
        g = (target[i] - left * delta[i]) * sample_rate
        unit2 = g * g * rows[INV, m]
        s = rows[SPECTRUM, m] if spectral else flat_psd
        forced = unit2 * s * rows[GROWTH, m]
        fill = rows[FILL, m]
        struck_now = unit2 * kick_now + (rows[ELSEWHERE_NOW, m] if has_now else 0.0)
        struck_next = unit2 * kick_next + (rows[ELSEWHERE_NEXT, m] if has_next else 0.0)
        now = max(a * fill, forced) + struck_now * fill
        later = max(a * rows[DECAY, m] * fill, forced) + struck_next * fill
        now *= bonus if kept[m] and not faded[m] else 1.0
        w = rows[WEIGHT, m]
        scores[0, m] = w * now
        scores[1, m] = w * later


@nb.njit(cache=True)
def apply_kept(t, b, keep, fade, ramp_left, shrink):
    """Make ``keep`` | ``fade`` bank b's computed set; return its size, or -1 if nothing
    changes (same set, no fades then or now). Its compact bank, if gathered, is written
    back first and becomes stale.

    Modes back from a fade take their fresh design (their ramp is lost); entering modes
    take the coefficients their ramp has reached (target - left * delta); fading modes
    decay by ``shrink`` per sample (amplitude) and hear nothing; silenced modes hold zero
    state (their coefficients keep following ramps virtually)."""
    k, o = t.layout[MODES, b], t.layout[FIRST, b]
    kept, faded = t.kept, t.faded
    same = True
    for m in range(o, o + k):
        if fade[m] or faded[m] or keep[m] != kept[m]:
            same = False
            break
    if same:
        return -1
    bank = bank_rows(t, b)
    rows = mode_rows(bank)
    target, delta, fresh = coef_rows(t.target, t, b), coef_rows(t.delta, t, b), coef_rows(t.fresh, t, b)
    settle_compact(t, b)
    count = 0
    for i in range(k):  # (branches only on what is rare: one on the kept set mispredicts)
        m = o + i
        if faded[m]:
            for r in range(COEF_ROWS):
                target[r, i] = fresh[r, i]
                delta[r, i] = 0.0
        if keep[m] and (not kept[m] or faded[m]):
            for r in range(COEF_ROWS):
                bank[r, i] = target[r, i] - ramp_left * delta[r, i]
        if fade[m] and not keep[m]:  # R -> R shrink: c1 = 2 R cos theta, c2 = R^2; no input
            rows.c1[i] *= shrink
            rows.c2[i] *= shrink * shrink
            rows.g[i] = 0.0
            rows.d[i] = 0.0
            for r in range(COEF_ROWS):
                target[r, i] = bank[r, i]
                delta[r, i] = 0.0
        computed = keep[m] or fade[m]
        rows.y1[i] = rows.y1[i] if computed else 0.0  # (silenced: zero state)
        rows.y2[i] = rows.y2[i] if computed else 0.0
        faded[m] = fade[m]
        kept[m] = computed
        count += computed
    t.compact_meta[b, GATHERED] = 0
    return count


@nb.njit(cache=True)
def decide(t, d, rates):
    """One decision over every bank of the tables ``t``: importance of every mode, the
    ranking (jassy.anytime_rank.rank_modes) and each bank's new kept set. A bank judging
    its force by a transform (TRANSFORMED) that heard one lately, and was not woken now,
    takes its :func:`periodogram` first (SPECTRAL; its remembered PSD if its last was
    taken up to PSD_REUSE_PERIODS periods before). A
    quiet bank's
    scores (nothing rings, no impact comes, no force heard) are zero; a woken bank judges
    the force in its input samples [begin, end), another bank that heard a force lately
    judges the last period's (its ring; its power kept in RING_POWER), both spread flat
    over frequency unless SPECTRAL.
    Returns (whether some mode fades, modes computed)."""
    count = t.layout.shape[1]
    scores = d.scores
    for b in range(count):
        if t.values[TRANSFORMED, b] > 0.0:
            spectral = d.heard[b] and not d.onset[b]
            if spectral:
                since = rates.frame - t.values[PSD_FRAME, b]
                if t.values[REMEMBERED, b] == 0.0 or since > PSD_REUSE_PERIODS * t.rings.shape[1]:
                    periodogram(t, b, rates.window_power, rates.frame)
                    t.values[PSD_FRAME, b] = rates.frame
            t.values[SPECTRAL, b] = 1.0 if spectral else 0.0
    for b in range(count):
        kicked = False
        for field in range(KICK_NOW, HAS_ELSEWHERE_NEXT + 1):
            kicked |= t.values[field, b] > 0.0
        if not (kicked or d.onset[b] or d.heard[b] or t.meta[b, ACTIVE]):
            o, k = t.layout[FIRST, b], t.layout[MODES, b]
            for r in range(3):
                for m in range(o, o + k):
                    scores[r, m] = 0.0
            continue
        flat_psd = 0.0
        if d.onset[b]:
            size = rates.end - rates.begin
            x = nb.carray(void_pointer(d.inputs[b] + 8 * rates.begin), (size,), np.float64)
            flat_psd = centred_power(x) / rates.sample_rate
        elif d.heard[b]:
            t.values[RING_POWER, b] = centred_power(t.rings[b])
            if t.values[SPECTRAL, b] == 0.0:
                flat_psd = t.values[RING_POWER, b] / rates.sample_rate
        bank_importance(t, d, b, flat_psd, rates.sample_rate, rates.bonus)
    fading = rank_modes(scores, rates.limit, d.keep, d.fade, d.later)
    total = 0
    for b in range(count):
        left = float(t.meta[b, RAMP_LEFT])
        kept = apply_kept(t, b, d.keep, d.fade, left, rates.shrink)
        if kept >= 0:
            t.meta[b, ACTIVE] = kept
            t.meta[b, ALLOWED] = kept
        total += t.meta[b, ALLOWED]
    return fading, total

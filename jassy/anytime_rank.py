"""Ranking of a mode budget, compiled: the modes to compute and to fade out per period,
and which banks hear a force."""

from __future__ import annotations

from typing import NamedTuple

import numba as nb
import numpy as np

from jassy import record_views
from jassy.jit import drop_stale_cache, void_pointer
from jassy.record_views import FIELD, bool_row, float_row, int_row

drop_stale_cache(__file__, [record_views])  # the cache holds copies of its views


#: Bits of a float64 score a selection pass sorts by (256 bins), the first pass's lowest
#: bit (a non-negative float64's bits, bit 63 its zero sign, order as its value).
DIGIT_BITS, TOP_SHIFT = 8, 55


@nb.njit(cache=True)
def kth_smallest(a, k, bins):
    """(the k-th smallest (from 0; 0 <= k < a.size) of the non-negative values a, how many
    are larger), a reordered in place (no NaN), by radix selection on their bits,
    DIGIT_BITS at a time from the top: per pass a histogram (``bins``: int64 scratch of
    2^DIGIT_BITS), the bin holding the k-th (sought from the nearer end of the bins
    used), the values in it kept. The value np.partition(a, k)[k] gives, with few
    branches that depend on the values: on the wok's 297 scores, varying from call to
    call as the decisions' do, a ``rank_modes`` took 5.6 us with Wirth's selection
    (mispredicted branches; 1.8 us on the same scores again and again)."""
    bits = a.view(np.int64)
    count, shift, mask, larger = a.size, TOP_SHIFT, (1 << DIGIT_BITS) - 1, 0
    while count > 1:
        bins[:] = 0
        low, high = mask, 0
        for i in range(count):
            digit = (bits[i] >> shift) & mask
            bins[digit] += 1
            low, high = min(low, digit), max(high, digit)
        if 2 * k < count:
            digit, below = low, 0
            while below + bins[digit] <= k:
                below += bins[digit]
                digit += 1
        else:
            digit, above = high, 0
            while count - above - bins[digit] > k:
                above += bins[digit]
                digit -= 1
            below = count - above - bins[digit]
        larger += count - below - bins[digit]
        kept = 0
        for i in range(count):  # the bin's values to the front, without a branch
            value = bits[i]
            bits[kept] = value
            kept += ((value >> shift) & mask) == digit
        count, k = kept, k - below
        if shift == 0:  # every bit sorted: the values left are equal
            break
        shift = max(shift - DIGIT_BITS, 0)
    return a[k], larger  # (the values left equal it)


@nb.njit(cache=True)
def threshold_of(score, limit, ranked, bins):
    """(threshold, ties): the ``limit`` highest positive scores (ties broken by index) are
    those above the threshold and the first ``ties`` equal to it; all positive ones when
    at most ``limit`` are (threshold 0), none for ``limit`` <= 0. ``ranked`` (float64,
    score.size) and ``bins`` (:func:`kth_smallest`) are scratch."""
    n = score.size
    if limit <= 0:
        return np.inf, 0
    positive = 0
    unordered = False  # a NaN score
    for k in range(n):
        s = score[k]
        unordered |= s != s
        ranked[positive] = s
        positive += s > 0.0
    if positive <= limit:
        return 0.0, 0
    if not unordered:  # the (positive - limit)-th smallest of the positive scores
        threshold, above = kth_smallest(ranked[:positive], positive - limit, bins)
        return threshold, limit - above
    threshold = np.partition(score, n - limit)[n - limit]  # (the same value without a NaN)
    above = 0
    for k in range(n):
        above += score[k] > threshold
    return threshold, limit - above


@nb.njit(cache=True)
def mark_top(score, threshold, ties, top):
    """top[k] = whether ``score[k]`` is among the highest by :func:`threshold_of`'s threshold
    and ``ties``: above it, or one of the first ``ties`` equal to it (by index). The
    comparison runs over every score with no branch (it vectorises), the ties are found
    after it (one loop carrying the ties left from score to score cost ~0.3 us more over
    the wok's 297 scores)."""
    for k in range(score.size):
        top[k] = score[k] > threshold
    k = 0
    while ties > 0 and k < score.size:
        if score[k] == threshold:
            top[k] = True
            ties -= 1
        k += 1


@nb.njit(cache=True)
def top_mask(score, limit, keep, ranked, bins):
    """keep[k] = True for the ``limit`` highest positive scores (ties broken by index);
    none for ``limit`` <= 0. ``ranked`` and ``bins``: :func:`threshold_of`'s scratch."""
    threshold, ties = threshold_of(score, limit, ranked, bins)
    mark_top(score, threshold, ties, keep)


@nb.njit(cache=True)
def rank_modes(scores, limit, keep, fade, later_top):
    """The modes to compute for this period (``keep``: the ``limit`` highest positive
    scores[0], :func:`top_mask`) and, among them, those to fade out (``fade``: kept now,
    not among the top of the next period, scores[1] (``later_top``), and sounding,
    scores[2] > 0). Returns whether some mode fades."""
    n = scores.shape[1]
    ranked, bins = np.empty(n), np.empty(1 << DIGIT_BITS, np.int64)
    top_mask(scores[0], limit, keep, ranked, bins)
    top_mask(scores[1], limit, later_top, ranked, bins)
    any_fade = False
    for k in range(n):
        f = keep[k] and not later_top[k] and scores[2, k] > 0.0
        fade[k] = f
        keep[k] = keep[k] and not f
        any_fade |= f
    return any_fade


class Kicks(NamedTuple):
    """The impacts of the score a budget renders, in frame order: the frame each applies
    at, the slot of the bank it strikes (-1: none of the budget's), whether its impulse
    is positive (the bank then expects it), the impulse (N s), and where the struck
    bank's gains at its location start in ``gains`` (-1: the bank's current location);
    ``gains``: those rows, each the model's gain per mode at a location, in the bank's
    mode order."""

    frames: np.ndarray  # int64
    slots: np.ndarray  # int64
    positive: np.ndarray  # bool
    impulses: np.ndarray  # float64
    located: np.ndarray  # int64
    gains: np.ndarray  # float64


@nb.njit(cache=True)
def kicks_at(a, i):
    """The :class:`Kicks` whose fields start at slot ``i`` of handle ``a``
    (jassy.record_views)."""
    return Kicks(
        int_row(a, i), int_row(a, i + FIELD), bool_row(a, i + 2 * FIELD), float_row(a, i + 3 * FIELD),
        int_row(a, i + 4 * FIELD), float_row(a, i + 5 * FIELD),
    )  # fmt: skip


#: Fields of a budget's step state (int64): a mode fades out in this period (the last
#: decision said so); some bank expects an impact in this period; the budget decides at
#: every period (it adapts its size to a CPU budget); the step takes its decisions itself
#: (no Python needed: no bank renders through Python, no bank is fed by another, no CPU
#: budget); the step renders the banks; decisions taken; the most modes a decision kept;
#: periods left undecided since the last decision (:func:`steady_forces`).
STEP_SLOTS = FADING, ANY_EXPECTED, EVERY_PERIOD, INLINE, RENDERS, DECISIONS, PEAK, UNDECIDED = tuple(range(8))
STEP_STATE = len(STEP_SLOTS)

#: A period whose only news is that banks went on hearing forces is left undecided while
#: no such force's power rose above this factor times its power at the last decision...
STEADY_POWER = 2.0
#: ... for at most this many periods in a row.
STEADY_PERIODS = 4


#: The force scan's sum reduction vectorises only reassociated; no other fast-math flag (a
#: NaN must still count as a force).
SCAN_FASTMATH = {"reassoc"}

#: Samples the force scan sums before it tests the sum.
SCAN_BLOCK = 64


@nb.njit(fastmath=SCAN_FASTMATH, cache=True, inline="always")
def has_force(force, begin, end):
    """Whether force[begin:end] has a non-zero (or NaN) sample. Tested SCAN_BLOCK samples
    at a time by the sum of their magnitudes, which is non-zero exactly then (a sum of
    non-negative numbers does not cancel; NaN and inf propagate; -0.0 counts as zero, as
    in ``!= 0.0``) and vectorises: a silent block, the common case while a bank rings,
    costs 0.08 ns per sample against 0.5 with a branch per sample or per eight. (Its
    callers compile it with their own fast-math flags: they must include reassoc.)"""
    i = begin
    while i + SCAN_BLOCK <= end:
        block = force[i : i + SCAN_BLOCK]  # (indices from 0: no wraparound test per sample)
        magnitude = 0.0
        for j in range(SCAN_BLOCK):
            magnitude += abs(block[j])
        if magnitude != 0.0:
            return True
        i += SCAN_BLOCK
    while i < end:
        if force[i] != 0.0:
            return True
        i += 1
    return False


class Hearing(NamedTuple):
    """What a budget knows of each bank's force: its input (float64 arrays of ``size`` at
    ``inputs``, kept alive by their nodes), whether its input is rendered after the
    budget's step (``unseen``: a bank fed by a bank; its force counts as heard), an impact
    expected in this period, a force heard in this and in the last period, a force in the
    current stretch, a force nobody scheduled waking it (``onset``), a force since it was
    last rendered, and whether its
    force is the score's impacts alone (``struck_only``: an ImpactForce's; ranked from the
    score, it never counts as heard nor wakes the bank: its input is not scanned, so its
    ``forced``, ``unrendered`` and ``onset`` stay False, unless it is also ``unseen``, a
    bank upstream of it through another source, when it counts as forced)."""

    inputs: np.ndarray
    size: int
    unseen: np.ndarray
    expected: np.ndarray
    heard_now: np.ndarray
    heard_before: np.ndarray
    forced: np.ndarray
    onset: np.ndarray
    unrendered: np.ndarray
    struck_only: np.ndarray
    decided_power: np.ndarray


@nb.njit(fastmath=SCAN_FASTMATH, cache=True)
def scan_forces(h, begin, end, rotate):
    """Which banks hear a force in samples [begin, end) of their inputs into ``h.forced``;
    banks ``unseen`` count as forced. First the stretch scanned before is folded into
    ``heard_now`` and ``unrendered``. ``rotate`` (a period starts): the last period's
    ``heard_now`` becomes ``heard_before``. ``onset``: forced banks that expected no
    impact and heard nothing in this or the last period. A bank ``struck_only`` neither
    hears nor is woken, so it is not scanned (the wok scene's ImpactForce inputs were 40 %
    of the samples scanned; ugens.modal_kept.render_kept looks for such a bank's force
    itself where it has modes kept and nothing sounding). Returns (any heard_before, any
    onset). A bank that heard a force in this period already is not scanned."""
    any_before = False
    any_onset = False
    heard_now, heard_before, forced = h.heard_now, h.heard_before, h.forced
    for b in range(h.inputs.size):
        heard_now[b] |= forced[b] and not h.struck_only[b]
        h.unrendered[b] |= forced[b]
        if rotate:
            heard_before[b] = heard_now[b]
            heard_now[b] = False
        any_before |= heard_before[b]
        loud = h.unseen[b]
        if not loud and not heard_now[b] and not h.struck_only[b]:
            loud = has_force(nb.carray(void_pointer(h.inputs[b]), (h.size,), np.float64), begin, end)
        forced[b] = loud
        quiet = h.expected[b] or heard_now[b] or heard_before[b] or h.unseen[b] or h.struck_only[b]
        h.onset[b] = loud and not quiet
        any_onset |= h.onset[b]
    return any_before, any_onset


@nb.njit(cache=True)
def hearing_at(a, i):
    """The :class:`Hearing` whose fields start at slot ``i`` of handle ``a``
    (jassy.record_views)."""
    return Hearing(
        int_row(a, i), a[i + FIELD], bool_row(a, i + 2 * FIELD), bool_row(a, i + 3 * FIELD),
        bool_row(a, i + 4 * FIELD), bool_row(a, i + 5 * FIELD), bool_row(a, i + 6 * FIELD),
        bool_row(a, i + 7 * FIELD), bool_row(a, i + 8 * FIELD), bool_row(a, i + 9 * FIELD),
        float_row(a, i + 10 * FIELD),
    )  # fmt: skip


@nb.njit(fastmath=True, cache=True)
def centred_power(force):
    """Mean square of ``force`` about its mean (a steady load makes no sound), N^2, in one
    pass: from the sums of its samples' differences from the first sample and of their
    squares, S1 and S2, as (S2 - S1^2 / n) / n, which is exactly 0 when every sample
    equals the first (a steady force leaves every mode of a 100 % budget as the full
    banks'); the shift keeps a large steady load from swamping the sums. (fastmath lets
    the sums run in SIMD lanes: a strict left-to-right sum cost about 5 us per
    2048-sample period; two passes, the mean's then the squares', ~0.16 us against
    ~0.10 us.) 0 for no sample."""
    n = force.size
    if n == 0:
        return 0.0
    first = force[0]
    total, squares = 0.0, 0.0
    for i in range(n):
        f = force[i] - first
        total += f
        squares += f * f
    return max(squares - total * total / n, 0.0) / n


@nb.njit(cache=True)
def note_decided(h, powers, heard, state):
    """A decision was taken: remember the power of each bank's force over the last period
    (``powers``, N^2, as the decision measured it: ugens.modal_budget's RING_POWER; zero
    for a bank that heard none, ``heard``)."""
    for b in range(heard.size):
        h.decided_power[b] = powers[b] if heard[b] else 0.0
    state[UNDECIDED] = 0


@nb.njit(cache=True)
def steady_forces(h, rings, ramp_left, state):
    """At a period's start where the only news is forces heard in the last period (no
    impact coming, no mode fading, no bank woken): whether the decision may be left out.
    It may while no bank that heard a force heard more than STEADY_POWER times its power
    at the last decision (its ring ``rings[b]`` holds the last period, the banks rendered
    up to here; a weaker force raises no mode above those kept), no such bank's
    coefficients ramp (``ramp_left[b]`` > 0: its gains move, a contact sliding over the
    surface) and fewer than STEADY_PERIODS periods went undecided (on the wok scene, a
    decision over its 15 banks with the periodogram of its 241-mode wok costs ~40 us)."""
    if state[UNDECIDED] + 1 >= STEADY_PERIODS:
        return False
    for b in range(h.heard_before.size):
        if h.heard_before[b]:
            if ramp_left[b] > 0:
                return False
            if centred_power(rings[b]) > STEADY_POWER * h.decided_power[b]:
                return False
    state[UNDECIDED] += 1
    return True

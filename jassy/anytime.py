"""Anytime synthesis: one mode budget shared by every ModalBank of a graph.

At multiples of ``period`` frames on the clock (the banks' sub-blocks are split there when
a decision is taken, so the result does not depend on the block size) the budget ranks
all modes of all banks by

    I_k = w(f_k) * (max(F_k A_k^2, a_k^2 S_b(f_k) (1 - e^{-2 d_k tau}) / (2 d_k)) + F_k (a_k J_b)^2)

(ugens.modal_budget gives it in full) where A_k is the mode's current amplitude (from its
two state samples), F_k the share of the period its free decay fills (so that ringing and
impacts count by their energy over the period), a_k its amplitude
per unit impulse at the point struck, (a_k J_b)^2 summed over the impacts scheduled
upstream of bank b in this period, S_b the power spectral density (N^2/Hz, Hann-windowed periodogram, mean
removed) of the force the bank heard in the last period, and w = 1 (the budget minimises
the output's error energy) or, with ``weighting = "A"``, the A-weighting power gain (IEC
61672) as a loudness proxy. The last term is the squared amplitude a stationary
force of that spectrum builds in a mode over the horizon tau, so continuous contacts
(scraping, rolling, friction) compete with impacts and ringing modes on one scale. The
top ``max_modes`` modes are computed for the next period; the rest are silenced and cost
nothing: each bank runs its kept modes gathered into a compact bank, so its cost is
proportional to them. Every bank keeps its rows in the budget's shared tables
(ugens.modal_budget.BudgetTables), and a decision is one compiled call over all of them
(impacts, periodograms, importance, ranking, kept sets), taken inside the compiled step
that renders the banks unless a bank needs Python (see :meth:`ModeBudget.step`).

A decision is taken only where something may change the ranking: an impact scheduled in
this or the next period, a force heard in the last period, or a mode fading out. Between
them the kept set only loses modes (ringing modes decay, silent ones are skipped), which
the banks do by themselves. A budget that covers every mode never decides: the render is
the full synthesis. Whether a bank hears a force is read from its input before the banks
run (one compiled pass over every bank's input; a bank driven by an ImpactForce hears
none: its force is the score's impacts, ranked from the score, so no periodogram of its
pulses and no decision for them after their period). When no bank hears another bank the
budget renders the banks itself: a sub-block is split only at the frames where it
decides, so a budgeted bank is called no more often than a full one between decisions.

Leaving without clicks: the scheduler knows the score, so the budget also ranks the modes
for the *following* period (amplitudes decayed by one period, impacts scheduled then). A
kept mode that will be displaced then is faded out during this period (its decay raised
to fall 60 dB in one period) while still counting against the budget, so the mode that
displaces it enters, from silence, exactly when its impact starts. Only a displacement
that could not be foreseen (a force that is not a scheduled event) cuts a sounding mode
at once. With ``cpu_fraction`` the budget adapts ``max_modes`` each period so that
rendering takes that fraction of real time (non-deterministic by nature).
"""

from __future__ import annotations

import math
import operator
import time
from dataclasses import dataclass, field
from typing import Any, NamedTuple

import numpy as np

from jassy.anytime_chain import credit_fed_banks, feeding_banks, heard_banks, weigh_feeders
from jassy.anytime_rank import DECISIONS, EVERY_PERIOD, INLINE, PEAK, RENDERS, STEP_STATE, Hearing, Kicks
from jassy.errors import PatchError
from jassy.jit import address, specialise
from jassy.packed_arrays import BOOL, FLOAT, INT, Packed, handle_of, packed_zeros
from jassy.record_views import FIELD

#: The importance of a mode already computed is multiplied by this, so modes near the
#: margin do not swap at every decision (each swap regathers a bank and cuts a mode).
KEPT_BONUS = 1.25


def a_weighting_power(f: np.ndarray) -> np.ndarray:
    """Squared A-weighting gain at frequencies f (Hz), normalised to 1 at 1 kHz."""
    f2 = np.asarray(f, dtype=np.float64) ** 2
    ra = (12194.0**2 * f2**2) / (
        (f2 + 20.6**2) * np.sqrt((f2 + 107.7**2) * (f2 + 737.9**2)) * (f2 + 12194.0**2)
    )
    return (ra / 0.7943282347242815) ** 2  # R_A(1 kHz) = 10^(-2/20)


#: Rows of ModeBudget's flags (one column per bank): the Hearing's (jassy.anytime_rank) from
#: ``unseen`` to ``struck_only``, then the banks the step leaves to Python and the Decision's
#: ``heard`` (ugens.modal_budget).
FLAG_ROWS = (
    "unseen",
    "expected",
    "heard_now",
    "heard_before",
    "forced",
    "onset",
    "unrendered",
    "struck_only",
    "by_python",
    "heard",
)
UNSEEN, ONSET, STRUCK_ONLY, BY_PYTHON, HEARD = (
    FLAG_ROWS.index(n) for n in ("unseen", "onset", "struck_only", "by_python", "heard")
)


class StepRecords(NamedTuple):
    """The compiled step's records besides the tables and the impacts
    (:meth:`ModeBudget._records`): the flags (FLAG_ROWS, banks), the Decision's masks
    (3, modes), the banks' input and output addresses (2, banks), their output samples
    known zero, the step state (jassy.anytime_rank's step fields), the forces' power at
    the last decision and the Decision's scores (3, modes); each field an array, its
    (shape, dtype) (:func:`record_fields`) or its handle slots (jassy.packed_arrays)."""

    flags: Any
    masks: Any
    addresses: Any
    zeros: Any
    state: Any
    power: Any
    scores: Any


def record_fields(count: int, total: int) -> StepRecords:
    """(shape, dtype) of the step's records for ``count`` banks of ``total`` modes."""
    return StepRecords(
        flags=((len(FLAG_ROWS), count), BOOL),
        masks=((3, total), BOOL),
        addresses=((2, count), INT),
        zeros=((count,), INT),
        state=((STEP_STATE,), INT),
        power=((count,), FLOAT),
        scores=((3, total), FLOAT),
    )


def kick_fields(rows: int, gains: int) -> tuple:
    """(shape, dtype) of a Kicks table (jassy.anytime_rank) of ``rows`` impacts and
    ``gains`` gains."""
    column = (rows,)
    fields = ((column, INT), (column, INT), (column, BOOL), (column, FLOAT), (column, INT))
    return (*fields, ((max(gains, 1),), FLOAT))


#: Compiled entry points of the budget's kernels, by kernel (:func:`fixed_entry`).
_ENTRIES: dict = {}


def fixed_entry(kernel, *example_args):
    """jassy.jit.specialise for a kernel whose callers always pass arguments of the types
    of ``example_args`` (the budget's: handles, C-contiguous float64 arrays, Python ints,
    records of Python scalars): found once per process and kept by kernel, as numba's
    dispatcher keeps its compiled code (re-deriving the types at every render's set-up
    cost ~5 us per entry point)."""
    entry = _ENTRIES.get(kernel)
    if entry is None:
        entry = _ENTRIES[kernel] = specialise(kernel, *example_args)
    return entry


@dataclass
class ModeBudget:
    """A budget of modes computed per period across all ModalBanks of a graph.

    max_modes: modes computed at most (leaving modes included); cpu_fraction: adapt
    max_modes so rendering takes this fraction of real time; period: frames between
    decisions; horizon: seconds over which a continuous force's build-up is judged;
    weighting: "flat" (rank by output energy) or "A" (by A-weighted energy, a loudness proxy).
    """

    max_modes: int | None = None
    cpu_fraction: float | None = None
    period: int = 2048
    horizon: float = 0.1
    weighting: str = "flat"
    #: modes computed times frames, summed over the banks the budget renders
    mode_samples: int = field(default=0, init=False)
    #: the compiled step's state (jassy.anytime_rank's step fields), made at attach
    _state: np.ndarray | None = field(default=None, init=False, repr=False, compare=False)
    #: the banks' flags (FLAG_ROWS x banks), made at attach
    _flags: np.ndarray | None = field(default=None, init=False, repr=False, compare=False)

    @property
    def decisions(self) -> int:
        """Decisions taken in the current render."""
        return 0 if self._state is None else int(self._state[DECISIONS])

    @property
    def peak_modes(self) -> int:
        """The most modes kept at once in the current render."""
        return 0 if self._state is None else int(self._state[PEAK])

    def __post_init__(self):
        if self.max_modes is None and self.cpu_fraction is None:
            raise PatchError("mode budget: give max_modes, cpu_fraction or both")
        if self.max_modes is not None and (not isinstance(self.max_modes, int) or self.max_modes < 1):
            raise PatchError(f"mode_budget: expected an integer >= 1, got {self.max_modes!r}")
        if self.cpu_fraction is not None and not 0 < self.cpu_fraction <= 10:
            raise PatchError(
                f"cpu_budget: expected a fraction of real time in (0, 10], got {self.cpu_fraction!r}"
            )
        try:
            self.period = operator.index(self.period)  # an int or numpy integer, as an int
        except TypeError:
            raise PatchError(
                f"ModeBudget period: expected a power of two >= 8 frames, got {self.period!r}"
            ) from None
        if self.period < 8 or self.period & (self.period - 1):
            raise PatchError(f"ModeBudget period: expected a power of two >= 8 frames, got {self.period!r}")
        if self.weighting not in ("flat", "A"):
            raise PatchError(f"budget weighting: expected 'flat' or 'A', got {self.weighting!r}")
        if not 0 < self.horizon <= 60:
            raise PatchError(f"budget horizon: expected seconds in (0, 60], got {self.horizon!r}")

    def decides(self, total_modes: int) -> bool:
        """Whether the budget decides anything on banks of ``total_modes`` modes (one that
        holds every mode never does: the render is the full synthesis)."""
        return self.cpu_fraction is not None or (self.max_modes or total_modes) < total_modes

    def attach(self, banks: list, sample_rate: float, listed, renders: bool = False, audio=None) -> None:
        """Start a render: ``banks`` expose the anytime_* methods of ugens.modal.ModalBank;
        ``listed()`` gives the score's impacts (jassy.scheduler.ListedImpacts: columns of
        frame, ugen struck, impulse, location) in frame order, the same object until the
        score changes. ``renders``:
        :meth:`step` also renders the banks (their inputs are rendered before it), splitting
        their sub-block only at the frames where it decides; otherwise the scheduler cuts
        sub-blocks at every period and the force of a bank fed by a bank (its input is
        rendered after the step) counts as heard in every period.
        ``audio``: the graph's audio outputs (a bank heard only through another bank is
        ranked by what reaches them; None: every bank is heard)."""
        self._audio = audio
        self.banks = banks
        self.sample_rate = sample_rate
        self.listed = listed
        total = sum(b.model.n_modes for b in banks)
        self.limit = min(self.max_modes or total, total)
        self.mode_samples = 0
        self._clock = None
        self.active = self.decides(total)
        self.renders = renders and self.active
        for bank in banks:
            bank.budgeted = self.active
        self._one_call = False
        self._same_score = True  # (the listing loaded at attach; Scheduler.insert says when not)
        if self.active:
            self._attach_tables(banks, total, renders)
        else:  # (no step: only its state, which counts no decisions)
            self._state = np.zeros(STEP_STATE, dtype=np.int64)
        self._state[EVERY_PERIOD] = self.cpu_fraction is not None
        self._state[RENDERS] = self.renders
        self._processes = [bank.process for bank in banks]

    def _records(self, banks: list, total: int, renders: bool, packed: Packed) -> None:
        """The compiled step's records besides the tables and the impacts (``packed``: the
        arrays of :func:`record_fields`, jassy.packed_arrays), and their slots of the step
        handle: the Hearing's
        flags and the by-Python and Decision's heard masks (rows of ``_flags``, FLAG_ROWS;
        ``renders``: the banks are rendered before the budget's step decides), the banks'
        input and output addresses, their output samples known zero (render_kept), the
        step state (FADING .. UNDECIDED, jassy.anytime_rank), the forces' power at the
        last decision, the Decision's masks and scores. Python makes the views of the
        Hearing and the Decision only when asked (:attr:`hearing`, :attr:`decision`): the
        step reads them by address."""
        count, rows = len(banks), len(FLAG_ROWS)
        records, slots = StepRecords(*packed.arrays), StepRecords(*packed.slots)
        self._flags, self._masks, self._addresses = records.flags, records.masks, records.addresses
        self._zeros, self._state, self._power, self._scores = records[3:]
        heard_inputs = [bank.sources["input"].out for bank in banks]  # the addresses stay valid
        self._addresses[0] = [address(x) for x in heard_inputs]
        self._addresses[1] = [address(bank.out) for bank in banks]  # alive with them
        self._flags[UNSEEN] = False  # (the step runs after every input but a bank's: jassy.graph)
        self._flags[UNSEEN, [fed.slot for fed in self._fed]] = True
        self._flags[STRUCK_ONLY] = [bank.sources["input"].score_impacts_only for bank in banks]
        self._size = min(x.size for x in heard_inputs)
        flag = [(slots.flags[0] + r * count, count, 1) for r in range(rows)]
        at = slots.addresses[0]
        inputs, outputs = (at, count, 1), (at + self._addresses.itemsize * count, count, 1)
        mask = [(slots.masks[0] + r * total, total, 1) for r in range(3)]
        hearing = (inputs, (self._size, 0, 0), *flag[: STRUCK_ONLY + 1], slots.power)
        self._before_kicks = (*hearing, outputs, flag[BY_PYTHON], slots.zeros)
        decision = (flag[ONSET], flag[HEARD], inputs, slots.scores, *mask)
        self._after_kicks = (slots.state, *decision)

    @property
    def hearing(self) -> Hearing:
        """The Hearing the compiled step reads (jassy.anytime_rank), as views."""
        f = self._flags
        return Hearing(self._addresses[0], self._size, *f[: STRUCK_ONLY + 1], self._power)

    @property
    def decision(self):
        """The Decision the compiled step reads (ugens.modal_budget), as views."""
        from ugens.modal_budget import Decision  # (not at the top: the ugens import jassy)

        return Decision(
            self._flags[ONSET], self._flags[HEARD], self._addresses[0], self._scores, *self._masks
        )

    def _attach_tables(self, banks: list, total: int, renders: bool) -> None:
        """Move every bank's rows into shared tables and prepare the compiled decision: the
        tables, the step's records and the score's impacts carved from one buffer."""
        from ugens import modal_budget as mb  # (not at the top: the ugens import jassy)
        from ugens import modal_kept as mk

        counts, records = [b.model.n_modes for b in banks], record_fields(len(banks), total)

        def carve(kicks: tuple) -> Packed:  # the impacts' fields, with the tables and records
            allocated = mb.allocate_tables(counts, self.period, (*records, *kicks))
            self._tables, self._table_slots = allocated.tables, allocated.table_slots
            n = len(records)
            self._records(banks, total, renders, Packed(allocated.arrays[:n], allocated.slots[:n]))
            return Packed(allocated.arrays[n:], allocated.slots[n:])

        self._slots = {id(bank): slot for slot, bank in enumerate(banks)}
        #: banks fed by banks, credited with their feeders' impacts (this period, the next)
        self._fed = [] if self.renders else feeding_banks(banks)  # (a bank fed by one: not renders)
        self._loaded = None  # the listing in the Kicks table
        self._handle_size = mk.DECISION_AT + len(mb.Decision._fields) * FIELD  # (the step handle's: checked)
        self._load_kicks(self.listed(), carve)  # the score's impacts, before the first sub-block
        tables, fields = self._tables, len(self._table_slots)
        self._tables_handle = self._step_handle[: fields * FIELD]  # (the banks' and the step's)
        for slot, bank in enumerate(banks):
            bank.anytime_attach(tables, slot, self.horizon, self.weighting, self._tables_handle)
        if self._fed:
            weigh_feeders(tables, self._fed, heard_banks(banks, self._audio or banks), self.sample_rate)
            self._chain_fields = (
                (mb.KICK_NOW, mb.HAS_ELSEWHERE_NOW, mb.ELSEWHERE_NOW),
                (mb.KICK_NEXT, mb.HAS_ELSEWHERE_NEXT, mb.ELSEWHERE_NEXT),
            )
        shrink = math.exp(-math.log(1000.0) / self.period)  # a fading mode: -60 dB over one period
        scale = mb.window_power(self.period, self.sample_rate)
        self._rates = mb.Rates(float(self.sample_rate), int(self.limit), KEPT_BONUS, shrink, 0, 0, scale, 0)
        #: the banks the compiled render cannot render (a size input), marked in by_python
        self._slow = [i for i, bank in enumerate(banks) if not bank.anytime_compiled()]
        self._watched = {}  # id -> the compiled banks with a parameter change queued
        for i, bank in enumerate(banks):
            if i in self._slow:
                self._flags[BY_PYTHON, i] = True
            else:
                bank.anytime_watch(self._watched)
        #: the compiled step renders every bank and takes every decision itself (INLINE)
        self._inline = not ((self.renders and self._slow) or self._fed or self.cpu_fraction is not None)
        self._state[INLINE] = self._inline
        #: every sub-block without a queued change or a new score is one compiled call
        self._one_call = self._inline and self.renders
        self._advance = fixed_entry(mk.advance_at, self._step_handle, 0, 0, 0, 0, 0, 0, self._rates)
        self._impacts = fixed_entry(mk.impacts_at, self._step_handle, 0, 0, 0)
        self._decide_all = fixed_entry(mk.decide_at, self._step_handle, self._rates)

    @staticmethod
    def _empty_kicks(packed: Packed) -> tuple[Kicks, list]:
        """The Kicks table of ``packed`` (the arrays of :func:`kick_fields`), none located,
        and its handle slots (jassy.record_views)."""
        kicks = Kicks(*packed.arrays)
        kicks.located[:] = -1  # none located
        return kicks, packed.slots

    def _steps_handle(self, kicks: list) -> None:
        """The handle (jassy.record_views) of what the compiled step reads: the tables, the
        Hearing, the banks' outputs, the by-Python mask, the output samples known zero, the
        impacts (``kicks``: the Kicks table's slots), the step state and the Decision
        (ugens.modal_kept.DECISION_AT)."""
        parts = (*self._table_slots, *self._before_kicks, *kicks, *self._after_kicks)
        self._step_handle = handle_of(parts)  # handle(tables, hearing, ..., decision), one array
        assert self._step_handle.size == self._handle_size, "step handle layout"

    def step(self, start: int, n: int) -> None:
        """Graph step for frames [start, start + n), after every node the banks hear:
        decide at multiples of ``period`` where the ranking may change, and at once where
        a bank that heard nothing for a period starts to hear a force nobody scheduled (a
        contact starting), so that its modes sound from the contact's first sample. The
        bookkeeping, the decisions and (when the budget renders the banks) the renders
        between them run in one compiled call (ugens.modal_kept.advance_at): a sub-block
        is split only where a decision changes the kept sets, or where a bank has a
        parameter change queued (applied there between two compiled calls). It returns
        to Python to decide only when a bank renders through its own ``process`` (a size
        input: rendered over the same spans), a bank is fed by another (credited in
        Python, jassy.anytime_chain) or a CPU budget adapts."""
        if self._one_call and self._same_score and not self._watched:
            rows, handle = self._loaded_rows, self._step_handle  # (the common case, in fewest steps)
            self.mode_samples += self._advance(
                handle, rows, self.period, start, n, start, start, self._rates
            )[2]
            return
        if not self.active:
            return
        period, end = self.period, start + n
        listed = self.listed()
        count = self._loaded_rows if listed is self._loaded else self._load_kicks(listed)
        self._same_score = True
        changes = self._queued_changes(start, end) if self.renders else None
        at, rendered, addresses = start, start, self._step_handle
        slow = self._slow if self.renders else []
        limits = [*sorted(changes), end] if changes else (end,)
        for limit in limits:  # render up to each frame a bank's parameters change
            while True:
                was = rendered
                at, rendered, work, deciding = self._advance(
                    addresses, count, period, start, limit - start, at, rendered, self._rates
                )
                self.mode_samples += work
                for i in slow:
                    if rendered > was:
                        self._processes[i](was, rendered - was, was - start)
                        self.mode_samples += (rendered - was) * self.banks[i].active_modes()
                if not deciding:
                    break
                stop = min(limit, (at // period + 1) * period)
                if at % period == 0 and self.cpu_fraction is not None:
                    self._adapt()
                self._decide(at, count, at - start, stop - at)
                at = stop
            for bank in changes.get(limit, ()) if changes else ():
                bank.anytime_apply(limit)
                if not bank.anytime_changes(math.inf):  # (the next sub-block: one call again)
                    self._watched.pop(id(bank), None)

    def score_changed(self, frame: int, now: int) -> None:
        """The score changed during the render (jassy.scheduler.Scheduler.insert) by an event
        applied at ``frame``, the render at frame ``now``: the next step lists its impacts
        again. An event in the period already started (its impacts were expected at its
        start) ends ``struck_only`` for the render: the bank it strikes must be woken by
        the force it hears, as every bank is; one in a later period is foreseen there. (A
        pulse of the score already credited at the period's start that runs on past the
        insert then wakes its bank as an onset.)"""
        self._same_score = False
        if self._flags is not None and frame < (now // self.period + 1) * self.period:
            self._flags[STRUCK_ONLY] = False

    def _queued_changes(self, start: int, end: int) -> dict[int, list] | None:
        """Frame -> the banks rendered by the compiled step that have a parameter change
        queued there, for the frames before ``end`` (those before ``start`` at ``start``),
        in the banks' order; None for none. Only the banks that queued a change are asked
        (ModalBank.anytime_watch); those with none left are let go (:meth:`step` also lets
        go those it applied the last change of)."""
        watch = self._watched
        if not watch:
            return None
        banks = list(watch.values()) if len(watch) == 1 else sorted(watch.values(), key=self._slot_of)
        changes = None  # (no dictionary for the sub-blocks without a change, most of them)
        for bank in banks:
            frames = bank.anytime_changes(end)
            if not frames:
                if not bank.anytime_changes(math.inf):
                    del watch[id(bank)]
                continue
            if changes is None:
                changes = {}
            for frame in frames:
                changes.setdefault(max(frame, start), []).append(bank)
        return changes

    def _slot_of(self, bank) -> int:
        return self._slots[id(bank)]

    def _load_kicks(self, listed, carve=packed_zeros) -> int:
        """The score's impacts (``listed``: jassy.scheduler.ListedImpacts, columns of one
        row per bank struck in frame order) into the compiled step's table (slot -1 for a
        bank not the budget's), with the struck bank's gains at each location named;
        returns the rows. Loaded when the render starts (:meth:`attach`), again only when
        the score changes (a new listing). Column by column: ~0.2 ms for the wok scene's
        1030 impacts. ``carve``: makes the table's arrays of their fields (jassy.packed_arrays)."""
        if listed is self._loaded:
            return self._loaded_rows
        slot_of, count = self._slots, len(listed.frames)
        slots = [slot_of.get(id(node), -1) for node in listed.nodes]
        at, located, gains, size = [-1] * count, {}, [], 0
        named = [i for i, where in enumerate(listed.locations) if where is not None and slots[i] >= 0]
        for i in named:  # the struck bank's gains at each location named
            key = (slots[i], listed.locations[i])
            offset = located.get(key)
            if offset is None:
                row = self.banks[key[0]].anytime_gains(key[1])
                offset = located[key] = size
                gains.append(row)
                size += row.size
            at[i] = offset
        table, kicks = self._empty_kicks(carve(kick_fields(max(count, 1), size)))
        self._kick_table = table
        if count:
            table.frames[:count] = listed.frames
            table.slots[:count] = slots
            table.impulses[:count] = listed.impulses
            np.greater(table.impulses, 0.0, out=table.positive)
            table.located[:count] = at
        if gains:
            np.concatenate(gains, out=table.gains)
        self._steps_handle(kicks)
        self._loaded, self._loaded_rows = listed, count
        return count

    def _decide(self, at: int, count: int, offset: int, n: int) -> None:
        """Rank every mode at frame ``at`` and apply the kept sets (in Python's hands: the
        step does this itself unless a bank needs Python); onsets are judged by the
        sub-block's input samples [offset, offset + n)."""
        kicked = self._impacts(self._step_handle, count, at, self.period)
        if self._fed and kicked:
            for fields in self._chain_fields:
                credit_fed_banks(self._tables, self._fed, fields, self.sample_rate)
        rates = self._rates
        if rates.limit != self.limit or rates.begin != offset or rates.end != offset + n or rates.frame != at:
            rates = self._rates = rates._replace(
                limit=int(self.limit), begin=offset, end=offset + n, frame=at
            )
        self._decide_all(self._step_handle, rates)

    def _adapt(self) -> None:
        now = time.perf_counter()
        if self._clock is not None:
            allowed = self.cpu_fraction * self.period / self.sample_rate
            used = max(now - self._clock, 1e-9)
            ceiling = self.max_modes or sum(b.model.n_modes for b in self.banks)
            self.limit = int(np.clip(self.limit * min(max(allowed / used, 0.5), 1.25), 16, ceiling))
        self._clock = now

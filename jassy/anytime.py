"""Anytime synthesis: one mode budget shared by every ModalBank of a graph.

At multiples of ``period`` frames on the clock (the banks' sub-blocks are split there when
a decision is taken, so the result does not depend on the block size) the budget ranks
all modes of all banks by

    I_k = w(f_k) * (A_k^2 + (a_k J_b)^2 + a_k^2 S_b(f_k) (1 - e^{-2 d_k tau}) / (2 d_k))

where A_k is the mode's current amplitude (from its two state samples), a_k its amplitude
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
(importance, ranking, kept sets); Python adds per decision only the impacts scheduled
and, for a bank of many modes that heard a force, a periodogram (numpy FFT).

A decision is taken only where something may change the ranking: an impact scheduled in
this or the next period, a force heard in the last period, or a mode fading out. Between
them the kept set only loses modes (ringing modes decay, silent ones are skipped), which
the banks do by themselves. A budget that covers every mode never decides: the render is
the full synthesis. Whether a bank hears a force is read from its input before the banks
run (one compiled pass over every bank's input), and when no bank hears another bank the
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

import bisect
import math
import time
from dataclasses import dataclass, field

import numpy as np

from jassy.anytime_chain import credit_fed_banks, feeding_banks, heard_banks, weigh_feeders
from jassy.anytime_rank import ANY_EXPECTED, EVERY_PERIOD, FADING, Hearing, Kicks, scan_forces
from jassy.errors import PatchError
from jassy.jit import specialise
from jassy.record_views import handle

#: the impacts (impulse N s, location) on a bank no impact strikes
NO_KICK: list[tuple[float, object]] = []

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
    peak_modes: int = field(default=0, init=False)
    decisions: int = field(default=0, init=False)
    #: modes computed times frames, summed over the banks the budget renders
    mode_samples: int = field(default=0, init=False)

    def __post_init__(self):
        if self.max_modes is None and self.cpu_fraction is None:
            raise PatchError("mode budget: give max_modes, cpu_fraction or both")
        if self.max_modes is not None and (not isinstance(self.max_modes, int) or self.max_modes < 1):
            raise PatchError(f"mode_budget: expected an integer >= 1, got {self.max_modes!r}")
        if self.cpu_fraction is not None and not 0 < self.cpu_fraction <= 10:
            raise PatchError(
                f"cpu_budget: expected a fraction of real time in (0, 10], got {self.cpu_fraction!r}"
            )
        if not isinstance(self.period, int) or self.period < 8:
            raise PatchError(f"budget period: expected an integer >= 8 frames, got {self.period!r}")
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
        ``listed()`` gives (frames, impacts) of the score's impacts (frame, nodes, impulse,
        location) in frame order, the same objects until the score changes. ``renders``:
        :meth:`step` also renders the banks (their inputs are rendered before it), splitting
        their sub-block only at the frames where it decides; otherwise the scheduler cuts
        sub-blocks at every period and a bank's force counts as heard in every period (it
        may be rendered after the step).
        ``audio``: the graph's audio outputs (a bank heard only through another bank is
        ranked by what reaches them; None: every bank is heard)."""
        self._audio = audio
        self.banks = banks
        self.sample_rate = sample_rate
        self.listed = listed
        total = sum(b.model.n_modes for b in banks)
        self.limit = min(self.max_modes or total, total)
        self.peak_modes = 0
        self.decisions = 0
        self.mode_samples = 0
        self._clock = None
        self._fading = False
        self.active = self.decides(total)
        self.renders = renders and self.active
        count = len(banks)
        inputs = [bank.sources["input"].out for bank in banks]  # the addresses stay valid
        flags = (np.zeros(count, dtype=bool) for _ in range(6))
        self._hearing = h = Hearing(
            np.array([x.ctypes.data for x in inputs], dtype=np.intp), min(x.size for x in inputs),
            np.array([not renders for _ in banks], dtype=bool), *flags,
        )  # fmt: skip
        self._state = np.zeros(3, dtype=np.int64)  # FADING, ANY_EXPECTED, EVERY_PERIOD (jassy.anytime_rank)
        self._state[EVERY_PERIOD] = self.cpu_fraction is not None
        self._scan = specialise(scan_forces, h, 0, 0, True)
        for bank in banks:
            bank.budgeted = self.active
        if self.active:
            self._attach_tables(banks, total)
        self._processes = [bank.process for bank in banks]
        self._kicks, self._now, self._kicked = NO_KICK, {}, False

    def _attach_tables(self, banks: list, total: int) -> None:
        """Move every bank's rows into shared tables and prepare the compiled decision."""
        from ugens import modal_budget as mb  # (not at the top: the ugens import jassy)

        self._tables = tables = mb.budget_tables([b.model.n_modes for b in banks], self.period)
        for slot, bank in enumerate(banks):
            bank.anytime_attach(tables, slot, self.horizon, self.weighting)
        #: the scores (now, next period, sounding) and the masks to keep, fade, and keep next
        masks = (np.zeros(total, dtype=bool) for _ in range(3))
        h = self._hearing
        self._decision = mb.Decision(h.onset, np.zeros(len(banks), dtype=bool), h.inputs,
                                  np.zeros((3, total)), *masks)  # fmt: skip
        self._rows = {}  # id(bank): (slot, its ELSEWHERE_NOW row, its ELSEWHERE_NEXT row)
        for slot, (bank, k, first) in enumerate(zip(banks, *tables.layout[:2], strict=True)):
            cut = slice(first, first + k)
            self._rows[id(bank)] = (
                slot,
                tables.rows[mb.ELSEWHERE_NOW, cut],
                tables.rows[mb.ELSEWHERE_NEXT, cut],
            )
        #: the fields of tables.values that impacts set (this period, then the next), and SPECTRAL
        self._kick_fields = ((mb.KICK_NOW, mb.HAS_ELSEWHERE_NOW), (mb.KICK_NEXT, mb.HAS_ELSEWHERE_NEXT))
        self._spectral_field = mb.SPECTRAL
        #: banks fed by banks, credited with their feeders' impacts (this period, the next)
        self._fed = feeding_banks(banks)
        if self._fed:
            weigh_feeders(tables, self._fed, heard_banks(banks, self._audio or banks), self.sample_rate)
        self._chain_fields = (
            (mb.KICK_NOW, mb.HAS_ELSEWHERE_NOW, mb.ELSEWHERE_NOW),
            (mb.KICK_NEXT, mb.HAS_ELSEWHERE_NEXT, mb.ELSEWHERE_NEXT),
        )
        self._spectral = [(slot, bank) for slot, bank in enumerate(banks) if bank.anytime_spectral]
        shrink = math.exp(-math.log(1000.0) / self.period)  # a fading mode: -60 dB over one period
        self._rates = mb.Rates(float(self.sample_rate), int(self.limit), KEPT_BONUS, shrink, 0, 0)
        self._decide_handle = handle(tables, self._decision)
        self._decide_all = specialise(mb.decide_at, self._decide_handle, self._rates)
        from ugens import modal_kept as mk

        self._outputs = np.array([bank.out.ctypes.data for bank in banks], dtype=np.intp)  # alive with them
        self._by_python = np.zeros(len(banks), dtype=bool)
        #: the banks' anytime_compiled, the flags last written to by_python, those banks
        self._compiled = [bank.anytime_compiled for bank in banks]
        self._flags, self._slow = [False] * len(banks), []
        self._slots = {id(bank): slot for slot, bank in enumerate(banks)}
        self._kick_table = Kicks(
            np.zeros(16, dtype=np.int64), np.zeros(16, dtype=np.int64), np.zeros(16, dtype=bool)
        )
        self._step_handle = None  # (_load_kicks)
        self._loaded, self._loaded_rows = None, 0  # the listing in the Kicks table, its rows
        self._advance = specialise(mk.advance_at, self._steps_handle(), 0, 0, 0, 0, 0, 0)

    def _steps_handle(self) -> np.ndarray:
        """The handle (jassy.record_views) of what the compiled step reads: the tables, the
        Hearing, the banks' outputs, the by-Python mask, the impacts and the step state."""
        self._step_handle = handle(
            self._tables, self._hearing, (self._outputs, self._by_python), self._kick_table, (self._state,)
        )
        return self._step_handle

    def upcoming(self, start: int, end: int) -> list[tuple[int, list, float, object]]:
        """The impacts (frame, nodes, impulse, location) of the score in frames [start, end)."""
        frames, impacts = self.listed()
        return impacts[bisect.bisect_left(frames, start) : bisect.bisect_left(frames, end)]

    def _predicted(self, kicks: list, start: int, end: int) -> dict[int, list[tuple[float, object]]]:
        """Per bank, the (impulse N s, location or None: the bank's own) of every impact of
        ``kicks`` (frame, nodes, impulse, location) in frames [start, end)."""
        predicted: dict[int, list[tuple[float, object]]] = {}
        for frame, node_banks, impulse, location in kicks:
            if start <= frame < end and impulse > 0.0:
                for bank in node_banks:
                    predicted.setdefault(id(bank), []).append((impulse, location))
        return predicted

    def step(self, start: int, n: int) -> None:
        """Graph step for frames [start, start + n), after every node the banks hear:
        decide at multiples of ``period`` where the ranking may change, and at once where
        a bank that heard nothing for a period starts to hear a force nobody scheduled (a
        contact starting), so that its modes sound from the contact's first sample. When
        the budget renders the banks, it runs them up to each decision and after the last
        one: a sub-block is split only where a decision changes the kept sets."""
        if not self.active:
            return
        if self.renders:
            self._rendering_step(start, n)
            return
        end, period, at = start + n, self.period, start
        while at < end:
            stop = min(end, (at // period + 1) * period)
            onset = self._due(at, stop - at, at - start)
            if onset is not None:
                self._decide(at, onset, at - start, stop - at)
            at = stop

    def _rendering_step(self, start: int, n: int) -> None:
        """:meth:`step` when the budget renders the banks: the bookkeeping and the renders
        between decisions run in one compiled call (ugens.modal_kept.advance_at), which
        returns to Python only where the budget decides. Banks with a parameter change,
        ramp or size input pending render through their own ``process`` over the same
        spans."""
        period, end = self.period, start + n
        count = self._load_kicks(self.listed())
        slow = self._python_banks()
        state, at, rendered, addresses = self._state, start, start, self._step_handle
        while True:
            state[FADING] = self._fading
            was = rendered
            at, rendered, work, deciding = self._advance(addresses, count, period, start, n, at, rendered)
            self.mode_samples += work
            for i in slow:
                if rendered > was:
                    self._processes[i](was, rendered - was, was - start)
                    self.mode_samples += (rendered - was) * int(self.banks[i].meta[0])
            if not deciding:
                return
            stop = min(end, (at // period + 1) * period)
            if at % period == 0:
                self._kicks = self.upcoming(at, at + 2 * period)
                self._now = self._predicted(self._kicks, at, at + period) if self._kicks else {}
                if self.cpu_fraction is not None:
                    self._adapt()
            else:
                self._kicks, self._now = NO_KICK, {}
            self._decide(at, self._hearing.onset, at - start, stop - at)
            at = stop

    def _python_banks(self) -> list[int]:
        """The banks the compiled render cannot render now (a parameter change, ramp or size
        input pending), marked in ``by_python``."""
        flags = [not compiled() for compiled in self._compiled]
        if flags != self._flags:
            self._by_python[:] = self._flags = flags
            self._slow = [i for i, python in enumerate(flags) if python]
        return self._slow

    def _load_kicks(self, listed: tuple) -> int:
        """The score's impacts (``listed``: frames, impacts (frame, nodes, impulse, location))
        into the compiled step's table, one row per bank struck (one row with slot -1 for
        an impact on none of the budget's banks), in frame order; returns the rows. Loaded
        once per render, again only when the score changes (a new listing)."""
        if listed is self._loaded:
            return self._loaded_rows
        kicks, slots = listed[1], self._slots
        rows = [
            (frame, slots.get(id(node), -1), impulse > 0.0)
            for frame, nodes, impulse, _ in kicks
            for node in nodes or (None,)
        ]
        count, table = len(rows), self._kick_table
        if count > table.frames.size:
            size = 2 * count
            table = self._kick_table = Kicks(
                np.zeros(size, dtype=np.int64), np.zeros(size, dtype=np.int64), np.zeros(size, dtype=bool)
            )
            self._steps_handle()
        if count:
            table.frames[:count], table.slots[:count], table.positive[:count] = zip(*rows, strict=True)
        self._loaded, self._loaded_rows = listed, count
        return count

    def _due(self, at: int, n: int, offset: int) -> np.ndarray | None:
        """Bookkeeping at frame ``at`` (a period's start or a sub-block's) for the next ``n``
        frames (inputs at ``offset`` of the sub-block); the banks woken by a force nobody
        scheduled (a mask) if the budget decides at ``at``, else None."""
        rotate = at % self.period == 0
        if rotate:
            kicks = self._kicks = self.upcoming(at, at + 2 * self.period)
            now = self._now = self._predicted(kicks, at, at + self.period) if kicks else {}
            expected = self._hearing.expected
            if self._state[ANY_EXPECTED]:
                expected[:] = False
            self._state[ANY_EXPECTED] = bool(now)
            if now:
                for i, bank in enumerate(self.banks):
                    expected[i] = id(bank) in now
        else:
            self._kicks, self._now = NO_KICK, {}
        heard, woken = self._scan(self._hearing, offset, offset + n, rotate)
        driven = rotate and (self._fading or bool(self._kicks) or heard)
        if rotate and self.cpu_fraction is not None:
            driven = True
            self._adapt()
        return self._hearing.onset if driven or woken else None

    def _decide(self, at: int, onset: np.ndarray, offset: int, n: int) -> None:
        """Rank every mode at frame ``at`` and apply the kept sets; ``onset``: the banks
        woken by the force in the sub-block's frames [offset, offset + n)."""
        kicks, now, period = self._kicks, self._now, self.period
        later = self._predicted(kicks, at + period, at + 2 * period) if kicks else {}
        d, values = self._decision, self._tables.values
        np.logical_or(
            self._hearing.heard_now, self._hearing.heard_before, out=d.heard
        )  # before the stretch from ``at``
        if self._kicked:
            for fields in self._kick_fields:
                values[fields, :] = 0.0
        self._kicked = bool(now or later)
        for column, (predicted, (kick, elsewhere)) in enumerate(
            zip((now, later), self._kick_fields, strict=True)
        ):
            for key, impacts in predicted.items():
                slot, *rows = self._rows[key]
                values[kick, slot], values[elsewhere, slot] = self.banks[slot].anytime_kicks(
                    impacts, rows[column]
                )
        if self._fed and self._kicked:
            for fields in self._chain_fields:
                credit_fed_banks(self._tables, self._fed, fields, self.sample_rate)
        for slot, bank in self._spectral:
            heard = d.heard[slot] and not onset[slot]
            values[self._spectral_field, slot] = heard and bank.anytime_spectrum()
        rates = self._rates
        if rates.limit != self.limit or rates.begin != offset or rates.end != offset + n:
            rates = self._rates = rates._replace(limit=int(self.limit), begin=offset, end=offset + n)
        self._fading, total = self._decide_all(self._decide_handle, rates)
        self.peak_modes = max(self.peak_modes, total)
        self.decisions += 1

    def _adapt(self) -> None:
        now = time.perf_counter()
        if self._clock is not None:
            allowed = self.cpu_fraction * self.period / self.sample_rate
            used = max(now - self._clock, 1e-9)
            ceiling = self.max_modes or sum(b.model.n_modes for b in self.banks)
            self.limit = int(np.clip(self.limit * min(max(allowed / used, 0.5), 1.25), 16, ceiling))
        self._clock = now

"""Per-sample cells shared by block and loop kernels (Faust's and STK's small parts).

Each cell is a numba function inlined into its caller (``inline="always"``), so it takes the
caller's fastmath flags and compiles to the same instructions as the code it replaced.

* :func:`raised_cosine`: the 1 - cos contact pulse of JASS's BangForce (van den Doel & Pai,
  "JASS: a Java audio synthesis system for programmers", ICAD 2001);
* :func:`pulse_sum`: its sampled sum, which scales a pulse to an exact impulse;
* :func:`with_room`: a table that doubles its rows when full; :func:`pulse_amplitude`,
  :func:`append_pulse`, :func:`append_pulses`: pulses added to a (t0, T, A) pulse table
  (ImpactForce, ImpactTrain, Crumple, Break, Bounce);
* :func:`decay_sums`, :func:`add_onset`, :func:`drop_row`: exponential pulses r^x and x r^x
  (x samples after their onsets) kept as two running sums and a queue of pending onsets
  (the blast waves of Explosion, the firings of Engine);
* :func:`two_pole`: one sample of a mode's impulse-invariant two-pole recursion (ModalBank,
  Friction), and :class:`ModeRows` (:func:`mode_rows`): a float64 bank's rows by name;
  :func:`state_step`: a mode's (displacement, velocity) pair through its 2x2 transition
  over a step (HuntCrossleyImpact, the heard output of closed loops);
  :func:`silent`: the test by which silent modes are zeroed, at the flush frames
  (FLUSH_PERIOD; :func:`until_flush`, :func:`is_flush_frame`);
* :func:`store`: a kernel's named state record written back to the float64 array that holds
  it (its fields in order; the record's reader is the inverse); :func:`slot`: where one
  field of such a record sits in its array.
"""

from __future__ import annotations

import math
from typing import NamedTuple

import numba as nb
import numpy as np

#: Shortest contact pulse in samples: a pulse must be sampled at least once.
MIN_PULSE_SAMPLES = 2.0


@nb.njit(inline="always", cache=True)
def raised_cosine(x, T):
    """1 - cos(2 pi x / T): the unit pulse at x samples after its onset, T samples long."""
    return 1.0 - math.cos(2.0 * math.pi * x / T)


@nb.njit(cache=True)
def pulse_sum(t0, T):
    """Sum of (1 - cos(2 pi (n - t0)/T)) over integers t0 < n < t0 + T."""
    s = 0.0
    n = math.floor(t0) + 1
    while n < t0 + T:
        s += raised_cosine(n - t0, T)
        n += 1
    return s


@nb.njit(cache=True)
def with_room(table, rows):
    """``table``, or a zero-padded copy with its row count doubled until ``rows`` rows fit."""
    size = max(table.shape[0], 1)
    if rows <= table.shape[0]:
        return table
    while size < rows:
        size *= 2
    grown = np.zeros((size, table.shape[1]))
    for i in range(table.shape[0]):  # element-wise: a slice copy compiles numba's shape-error text
        for j in range(table.shape[1]):
            grown[i, j] = table[i, j]
    return grown


@nb.njit(cache=True)
def pulse_amplitude(impulse, fs, t0, T):
    """The amplitude A of a 1 - cos pulse of ``impulse`` N s starting at fractional sample t0,
    T samples long, whose samples sum to exactly impulse * fs (:func:`pulse_sum`)."""
    return impulse * fs / pulse_sum(t0, T)


class Pulse(NamedTuple):
    """A row of a pulse table: the 1 - cos pulse A (1 - cos(2 pi (t - t0) / T)), t0 < t < t0 + T
    (t in samples)."""

    t0: float  #: start (fractional sample)
    length: float  #: T (samples)
    amplitude: float  #: A


#: Columns of a pulse table (rows, PULSE_COLUMNS), one Pulse per row.
PULSE_T0, PULSE_LENGTH, PULSE_AMPLITUDE = range(len(Pulse._fields))
PULSE_COLUMNS = len(Pulse._fields)


@nb.njit(cache=True)
def append_pulse(pulses, count, t0, T, amplitude):
    """Row ``count`` of a (t0, T, A) pulse table set to (t0, T, amplitude); returns the table
    (a larger copy if it was full)."""
    pulses = with_room(pulses, count + 1)
    pulses[count, PULSE_T0] = t0
    pulses[count, PULSE_LENGTH] = T
    pulses[count, PULSE_AMPLITUDE] = amplitude
    return pulses


@nb.njit(cache=True)
def append_pulses(pulses, count, starts, lengths, impulses, fs):
    """Pulses of ``impulses`` N s at fractional samples ``starts``, ``lengths`` samples long,
    appended to a (t0, T, A) pulse table grown once (:func:`pulse_amplitude`)."""
    pulses = with_room(pulses, count + starts.shape[0])
    for k in range(starts.shape[0]):
        amplitude = pulse_amplitude(impulses[k], fs, starts[k], lengths[k])
        pulses = append_pulse(pulses, count + k, starts[k], lengths[k], amplitude)
    return pulses


@nb.njit(inline="always", cache=True)
def decay_sums(s1, s2, r):
    """One sample later: s1 = sum A r^x -> r s1, s2 = sum x A r^x -> r (s2 + s1)."""
    return r * s1, r * (s2 + s1)


@nb.njit(inline="always", cache=True)
def add_onset(s1, s2, amp, x, log_r):
    """The sums with a pulse of amplitude ``amp`` that started ``x`` samples ago (log_r = ln r)."""
    e = amp * math.exp(x * log_r)
    return s1 + e, s2 + x * e


class Onset(NamedTuple):
    """A row of an onset queue: a pulse waiting for its onset (:func:`add_onset`)."""

    at: float  #: onset (fractional sample)
    amplitude: float  #: the pulse's amplitude


#: Columns of an onset queue (rows, ONSET_COLUMNS), one Onset per row.
ONSET_AT, ONSET_AMPLITUDE = range(len(Onset._fields))
ONSET_COLUMNS = len(Onset._fields)


@nb.njit(inline="always", cache=True)
def drop_row(queue, k, count):
    """Remove row k of the first ``count`` rows of an onset queue (the last row takes its
    place); returns the new count."""
    count -= 1
    queue[k, ONSET_AT] = queue[count, ONSET_AT]
    queue[k, ONSET_AMPLITUDE] = queue[count, ONSET_AMPLITUDE]
    return count


@nb.njit(inline="always", cache=True)
def two_pole(c1, c2, y1, y2, x):
    """y[n] = c1 y[n-1] - c2 y[n-2] + x: a mode with c1 = 2 R cos(theta), c2 = R^2 driven by
    its scaled input x (ModalBank's recursion, module docstring of ugens.modal)."""
    return c1 * y1 - c2 * y2 + x


class ModeRows(NamedTuple):
    """A float64 bank's rows as ugens.modal.resonate reads them, one entry per mode: the
    coefficients c1 = 2 R cos theta, c2 = R^2 of :func:`two_pole`, input gain g = a R sin
    theta / fs (per N) and direct gain d (module docstring of ugens.modal), and the state
    y1 = y[n-1], y2 = y[n-2]."""

    c1: np.ndarray
    c2: np.ndarray
    g: np.ndarray
    d: np.ndarray
    y1: np.ndarray
    y2: np.ndarray


@nb.njit(inline="always", cache=True)
def mode_rows(bank):
    """The ModeRows of a (6, K) bank array, whose rows are the record's fields in order."""
    return ModeRows(bank[0], bank[1], bank[2], bank[3], bank[4], bank[5])


@nb.njit(inline="always", cache=True)
def state_step(a11, a12, a21, a22, q, p):
    """A mode's displacement q and velocity p one step on through its transition matrix
    [[a11, a12], [a21, a22]] (without the force's share)."""
    return a11 * q + a12 * p, a21 * q + a22 * p


@nb.njit(inline="always", cache=True)
def silent(a, b, floor):
    """Whether a mode whose two states (in one unit) are a and b is below ``floor`` (it is
    then zeroed and no longer computed)."""
    return abs(a) < floor and abs(b) < floor


#: Silent modes are looked for at every multiple of this many frames on the clock (ModalBank
#: and its variants, HuntCrossleyImpact): the flush frames, hence the output, do not depend
#: on the block size.
FLUSH_PERIOD = 1024


@nb.njit(inline="always", cache=True)
def until_flush(frame, left):
    """Frames from ``frame`` up to the next flush frame (a multiple of FLUSH_PERIOD), at most
    ``left``: the piece of a block a kernel runs before it next looks for silent modes."""
    return min(left, (frame // FLUSH_PERIOD + 1) * FLUSH_PERIOD - frame)


@nb.njit(inline="always", cache=True)
def is_flush_frame(frame):
    """Whether silent modes are looked for at ``frame`` (a multiple of FLUSH_PERIOD)."""
    return frame % FLUSH_PERIOD == 0


@nb.njit(inline="always", cache=True)
def store(array, record):
    """Write the fields of ``record`` (a NamedTuple of floats) to array[0], array[1], ..."""
    for k in range(len(record)):
        array[k] = record[k]


def slot(record_type: type, field: str) -> int:
    """Index of ``field`` of a NamedTuple record type in the float64 array that holds the record
    (for a host-side write of one setting)."""
    return record_type._fields.index(field)

"""The integer ``meta`` records of a ModalBank's kernels, stored in int64 arrays.

A bank's meta (:class:`BankMeta`) says how many modes its kernels compute; an anytime
budget's compact bank of the kept modes has its own (:class:`CompactMeta`), which
:func:`ugens.modal.bank_step` reads as a bank's (the active count and its cap sit in the
same slots). The float32 modes of a mixed-precision bank have their own too
(:class:`NarrowMeta`), read only by :func:`ugens.modal.mixed_step`, not by bank_step: its
``delta_end`` sits in the slot of BankMeta's ``allowed`` and is no cap.
Kernels index the arrays by the slot constants below (cells.slot), which compile to the
same loads as the numbers they replace.
"""

from __future__ import annotations

from typing import NamedTuple

from ugens.cells import slot


class BankMeta(NamedTuple):
    """A bank's int64 ``meta`` array, fields in this order."""

    active: int  #: modes computed, [0, active): the last audible mode + 1
    ramp_left: int  #: samples left of a coefficient ramp (0: none)
    allowed: int  #: the most modes that may be active: all, or an anytime budget's share


class CompactMeta(NamedTuple):
    """The int64 meta of an anytime budget's compact bank of the kept modes, fields in this order."""

    active: int  #: modes computed in the compact bank
    gathered: int  #: 1 while the compact bank holds the kept modes' state, 0 when stale
    width: int  #: the compact bank's modes (the kept ones padded to whole SIMD vectors)


class NarrowMeta(NamedTuple):
    """The int64 meta of a bank's float32 modes (ugens.modal.mixed_step), fields in this order."""

    active: int  #: float32 modes computed, [0, active): the last audible one + 1
    all: int  #: float32 modes in the rows (all become active when force arrives)
    #: modes [0, delta_end) in the delta form (coefficient row 1 holds b2), the rest R^2 - c0;
    #: the explicit-vector kernel (ugens.modal_f32.resonate_chunks) runs only whole chunks of
    #: 32 modes in one form, so other values take the general loop
    delta_end: int


ACTIVE, RAMP_LEFT, ALLOWED = (slot(BankMeta, key) for key in BankMeta._fields)
GATHERED, WIDTH = (slot(CompactMeta, key) for key in ("gathered", "width"))
NARROW_ACTIVE, NARROW_ALL, DELTA_END = (slot(NarrowMeta, key) for key in NarrowMeta._fields)
assert (slot(CompactMeta, "active"), WIDTH) == (ACTIVE, ALLOWED)  # bank_step reads either

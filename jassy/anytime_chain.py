"""Impacts on a bank that feeds another bank: what the fed bank's modes will hear.

An impact is credited to the banks whose force input it drives (jassy.graph's
``struck_targets``); a bank fed by a struck bank hears that bank's ringing output instead.
Its modes would score nothing until the budget has heard that output for a period, so a
tight budget would start them late (their response from the onset lost) or never. Here the
struck bank's modes, of squared amplitude P_j after the impacts, frequency w_j (rad/s) and
decay rate d_j (1/s), give its output's spectrum (the Laplace transform of decaying
sinusoids, A w_j / ((d_j + i w)^2 + w_j^2)); a fed mode k, of squared amplitude U_k^2 per
unit impulse (N s), rings after that input with about U_k^2 |X(w_k)|^2, summed over the
struck modes incoherently (their phases are not tracked). Exact for an undamped fed mode.
Over a budget period each pair's energy lasts as long as the slower of the two modes rings
(:func:`lasting`), as the ranking weighs a mode's own ringing by its decay. The same
transfer weighs a feeding bank's modes by the energy they give the fed bank's (what of
them is heard, when only the fed bank reaches an output).
"""

from __future__ import annotations

from typing import NamedTuple

import numpy as np


class FedBank(NamedTuple):
    """A budgeted bank fed by other budgeted banks, through no other bank."""

    slot: int  #: its index among the budget's banks
    feeders: tuple[int, ...]  #: the feeding banks' indices
    transfers: tuple[np.ndarray, ...]  #: per feeder, |X(w_k)|^2 per unit P_j: (fed modes, feeder modes)


def _first_banks_upstream(nodes, slots: dict[int, int]) -> list[int]:
    """Slots of the banks (``slots``: id(bank) -> slot) reached from ``nodes`` going upstream
    through their sources without passing another bank (the nodes themselves included)."""
    found, stack, seen = [], list(nodes), set()
    while stack:
        node = stack.pop()
        if id(node) in seen:
            continue
        seen.add(id(node))
        if id(node) in slots:
            found.append(slots[id(node)])
        else:
            stack.extend(node.sources.values())
    return found


def feeding_banks(banks: list) -> list[FedBank]:
    """The banks of ``banks`` (in the graph's order) fed by others of them, with the squared
    spectral transfer from each feeder's modes to theirs."""
    slots = {id(bank): i for i, bank in enumerate(banks)}
    fed = []
    for slot, bank in enumerate(banks):
        feeders = _first_banks_upstream(bank.sources.values(), slots)
        if feeders:
            w = 2 * np.pi * bank.model.frequencies
            transfers = tuple(_transfer(w, banks[a].model) for a in sorted(feeders))
            fed.append(FedBank(slot, tuple(sorted(feeders)), transfers))
    return fed


def _transfer(w: np.ndarray, model) -> np.ndarray:
    """|w_j / ((d_j + i w_k)^2 + w_j^2)|^2 (s^2) for fed frequencies w_k (rad/s) and the
    feeding ``model``'s modes j."""
    wj = 2 * np.pi * model.frequencies
    dj = np.maximum(model.decays, 1e-6)
    s = dj[None, :] + 1j * w[:, None]
    return np.abs(wj[None, :] / (s * s + wj[None, :] ** 2)) ** 2


def bank_row(tables, row: int, b: int) -> np.ndarray:
    """Bank b's columns of the per-mode row ``row`` of ``tables.rows`` (a view)."""
    from ugens.modal_budget import FIRST, MODES

    first = tables.layout[FIRST, b]
    return tables.rows[row, first : first + tables.layout[MODES, b]]


def lasting(transfer: np.ndarray, fed_fill: np.ndarray, feeder_fill: np.ndarray) -> np.ndarray:
    """``transfer`` (fed modes, feeder modes) times, per pair, the share of a budget period
    the longer-lived of the two fills (ugens.modal_budget's FILL): a fed mode driven by a
    ringing feeder mode rings as long as the slower of them, so the energy a pair carries
    over the period scales with that one's fill, not the fed mode's nor the feeder's."""
    return transfer * np.maximum(fed_fill[:, None], feeder_fill[None, :])


def unit_power(tables, b: int, sample_rate: float) -> np.ndarray:
    """Bank b's squared mode amplitudes per unit impulse (N s) at its gains' ramp targets."""
    from ugens.modal_budget import COEF_AT, INV, MODES
    from ugens.modal_retune import COEF_GAIN

    k = tables.layout[MODES, b]
    gains = tables.layout[COEF_AT, b] + COEF_GAIN * k  # row g of the ramp targets
    g = tables.target[gains : gains + k] * sample_rate
    return g * g * bank_row(tables, INV, b)


def credit_fed_banks(tables, fed: list[FedBank], fields: tuple[int, int, int], sample_rate: float) -> None:
    """Add to each fed bank's impacts-elsewhere row what its feeders' impacts give it.
    ``fields``: the tables' value field of squared impulses at the bank's location, the
    value field flagging the row and the row (this period's or the next). Fed banks come
    after their feeders (graph order), so a chain of banks passes the credit on."""
    from ugens.modal_budget import FILL

    kick, has_row, row = fields
    values = tables.values

    def struck(b: int) -> np.ndarray | None:
        """Bank b's squared mode amplitudes after the impacts, None if it is not struck."""
        if values[kick, b] <= 0.0 and values[has_row, b] <= 0.0:
            return None
        power = unit_power(tables, b, sample_rate) * values[kick, b]
        if values[has_row, b] > 0.0:
            power += bank_row(tables, row, b)
        return power

    for slot, feeders, transfers in fed:
        heard, fill = None, bank_row(tables, FILL, slot)
        for a, transfer in zip(feeders, transfers, strict=True):
            power = struck(a)
            if power is not None:
                energy = lasting(transfer, fill, bank_row(tables, FILL, a)) @ power
                heard = energy if heard is None else heard + energy
        if heard is None:
            continue
        target = bank_row(tables, row, slot)
        if values[has_row, slot] <= 0.0:
            target[:] = 0.0
            values[has_row, slot] = 1.0
        target += unit_power(tables, slot, sample_rate) * heard / fill  # (the ranking multiplies by fill)


def heard_banks(banks: list, audio: list) -> np.ndarray:
    """Whether each bank of ``banks`` reaches an ``audio`` output through no other bank."""
    slots = {id(bank): i for i, bank in enumerate(banks)}
    heard = np.zeros(len(banks), dtype=bool)
    heard[_first_banks_upstream(audio, slots)] = True
    return heard


def weigh_feeders(tables, fed: list[FedBank], heard: np.ndarray, sample_rate: float) -> None:
    """Set each feeding bank's WEIGHT row to what its modes reach the outputs with: its own
    weight if the bank is heard directly (``heard``), plus, per fed bank, the energy its
    modes ring with per unit energy of the feeder's mode (U_k^2 |X(w_k)|^2 / P_j, weighted
    by the fed modes' own weights). A bank that only feeds another is then ranked by what is heard of it."""
    from ugens.modal_budget import FILL, WEIGHT

    feeds: dict[int, list[tuple[int, np.ndarray]]] = {}
    for slot, feeders, transfers in fed:
        for a, transfer in zip(feeders, transfers, strict=True):
            feeds.setdefault(a, []).append((slot, transfer))
    for a in sorted(feeds, reverse=True):  # fed banks come later: their weights are final
        w, fill = bank_row(tables, WEIGHT, a), bank_row(tables, FILL, a)
        reach = sum(
            (unit_power(tables, c, sample_rate) * bank_row(tables, WEIGHT, c))
            @ lasting(transfer, bank_row(tables, FILL, c), fill)
            for c, transfer in feeds[a]
        )
        w[:] = w * heard[a] + reach / fill  # (the ranking multiplies the feeder's score by its fill)

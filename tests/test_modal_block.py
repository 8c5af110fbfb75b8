"""The block update of small kept banks (ugens.modal_block) against the two-pole recursion
run sample by sample (a plain loop here, and ugens.modal_kept.kept_step without blocks)."""

import numpy as np

from ugens.cells import ModeRows
from ugens.modal_block import BLOCK_TABLE, block_resonate, fill_table
from ugens.modal_budget import BANK_ROWS, COMPACT_ROWS, line_aligned_zeros
from ugens.modal_kept import kept_step

RATE = 48000.0


def compact_bank(rng, live=4):
    """A compact bank of 8 columns, ``live`` modes of 50 Hz - 19 kHz decaying 5-60 /s."""
    bank = line_aligned_zeros((COMPACT_ROWS, 8))
    radius = np.exp(-rng.uniform(5, 60, live) / RATE)
    theta = 2 * np.pi * rng.uniform(50, 19000, live) / RATE
    bank[0, :live], bank[1, :live] = 2 * radius * np.cos(theta), radius**2
    bank[2, :live] = rng.uniform(0.1, 1.0, live) * 1e-3
    bank[3, :live] = rng.uniform(0.0, 1.0, live) * 1e-4
    return bank


def two_pole_loop(force, bank, before):
    """y_k[n] = c1 y_k[n-1] - c2 y_k[n-2] + g_k F[n-1], out[n] = sum_k y_k[n] + sum_k d_k F[n]."""
    c1, c2, g, d, y1, y2 = (list(map(float, row)) for row in bank[:BANK_ROWS])
    out, fp = [], before
    for f in force:
        total = 0.0
        for k in range(len(c1)):
            v = c1[k] * y1[k] - c2[k] * y2[k] + g[k] * fp
            y1[k], y2[k] = v, y1[k]
            total += v
        out.append(total + sum(d) * f)
        fp = f
    return np.array(out), np.array([y1, y2])


def test_block_update_matches_the_recursion_sample_by_sample():
    rng = np.random.default_rng(7)
    for n in (8, 13, 203, 645):  # whole passes, and remainders of 5, 3 and 5 samples
        bank = compact_bank(rng)
        bank[4:6, :4] = rng.normal(size=(2, 4)) * 1e-3  # ringing before the force
        force = rng.normal(size=n)
        want, state = two_pole_loop(force, bank, 0.25)
        table = line_aligned_zeros((BLOCK_TABLE,))
        fill_table(table, *bank[:4])
        out, last = np.zeros(n), np.array([0.25])
        block_resonate(force, out, n, ModeRows(*bank[:BANK_ROWS]), table, last)
        scale = np.max(np.abs(want))
        assert np.max(np.abs(out - want)) < 1e-12 * scale, n
        assert np.allclose(bank[4:6], state, rtol=0, atol=1e-12 * np.max(np.abs(state)))
        assert last[0] == force[-1]


def test_kept_step_with_blocks_matches_it_without_through_forces_flushes_and_a_jump():
    rng = np.random.default_rng(11)
    frames = 7000
    force = np.zeros(frames)
    force[100:900] = rng.normal(size=800)
    force[2000:2003] = 1.0  # an impact, then free ringing and flushes
    force[3000:4500] = rng.normal(size=1500)
    force[5000:6500] = rng.normal(size=1500)
    plain = compact_bank(rng, live=3)
    blocked = plain.copy()
    metas = [np.array([0, 1, 8]), np.array([0, 1, 8])]
    lasts = [np.zeros(1), np.zeros(1)]
    outs = [np.zeros(frames), np.zeros(frames)]
    table = line_aligned_zeros((BLOCK_TABLE,))
    at = 0
    for size in (37, 1000, 5, 2048, 13, 1897, 60, 1500, 440):
        if at >= 4800:  # a location jump: the gains change, the poles stay
            new_gains = rng.uniform(0.1, 1.0, 3) * 1e-3
            plain[2, :3] = blocked[2, :3] = new_gains
        size = min(size, frames - at)
        for bank, meta, last, out, blocks in zip(
            (plain, blocked), metas, lasts, outs, (None, table), strict=True
        ):
            rows, span = bank[:BANK_ROWS], out[at : at + size]
            if blocks is None:
                kept_step(force[at : at + size], span, at, size, rows, meta, 1e-10, last, np.zeros(0))
            else:
                kept_step(force[at : at + size], span, at, size, rows, meta, 1e-10, last, np.zeros(0), blocks)
        at += size
    assert at == frames
    assert np.max(np.abs(outs[0])) > 0
    assert np.max(np.abs(outs[1] - outs[0])) < 1e-12 * np.max(np.abs(outs[0]))
    assert metas[0][0] == metas[1][0]
    late = slice(5000, frames)  # after the jump: fails if the table kept the old gains
    assert np.max(np.abs(outs[1][late] - outs[0][late])) < 1e-12 * np.max(np.abs(outs[0][late]))


def test_a_bank_dropping_to_four_kept_modes_renders_by_blocks_as_without():
    """A budgeted bank keeping more than four modes, then (a louder bank struck, its modes
    faded out first) four or fewer: once its fades are over the compiled render takes the
    block path (ugens.modal_kept.render_bank), which renders columns 0-3 of the compact
    bank only. Its columns 4-7 are then silent (exact zeros), and from that state
    kept_step with blocks equals it without, over a force, within 1e-12 of the peak."""
    from jassy import Event, Graph, ModalModel, render
    from jassy.anytime import ModeBudget
    from ugens import ImpactForce, Mixer, ModalBank
    from ugens.modal_budget import COMPACT_AT, FIRST, MODES
    from ugens.modal_meta import ALLOWED, GATHERED, RAMP_LEFT, WIDTH

    quiet = ModalModel(np.linspace(300.0, 2700.0, 10), np.full(10, 2.0), np.ones((1, 10)))
    loud = ModalModel(np.linspace(3100.0, 4700.0, 5), np.full(5, 1.0), np.full((1, 5), 30.0))
    bank = ModalBank(quiet, name="quiet")(ImpactForce(name="hq"))
    mix = Mixer(bank, ModalBank(loud, name="loud")(ImpactForce(name="hl")))
    score = [Event(0.0, "hq", "impact", {"impulse": 1.0}), Event(0.3, "hl", "impact", {"impulse": 1.0})]
    budget = ModeBudget(max_modes=8, period=512)
    seen = {"more": False, "fading": False, "blocks": None}
    step = budget.step

    def watched(start, n):  # after each sub-block: the quiet bank's kept set and compact bank
        step(start, n)
        t, b = budget._tables, budget._slots[id(bank)]
        first, modes = t.layout[FIRST, b], t.layout[MODES, b]
        allowed, meta = t.meta[b, ALLOWED], t.compact_meta[b]
        seen["more"] |= allowed > 4
        seen["fading"] |= seen["more"] and bool(t.faded[first : first + modes].any())
        by_blocks = allowed <= 4 and t.meta[b, RAMP_LEFT] == 0 and meta[WIDTH] == 8 and meta[GATHERED]
        if seen["fading"] and by_blocks and seen["blocks"] is None:
            at = t.layout[COMPACT_AT, b]
            compact = t.compact[at : at + COMPACT_ROWS * 8].reshape((COMPACT_ROWS, 8))
            seen["blocks"] = (compact.copy(), meta.copy(), t.last[b], int(allowed), t.blocks[b].copy())

    budget.step = watched
    render(Graph(mix, budget=budget), score, 0.6, int(RATE), 64, limiter=False)
    assert seen["more"] and seen["fading"] and seen["blocks"] is not None
    compact, meta, before, allowed, made = seen["blocks"]
    assert 0 < allowed <= 4 and np.any(compact[4, :allowed] != 0)  # kept modes ringing
    assert not np.any(compact[:, 4:])  # what the block path leaves out is silent
    assert np.array_equal(made.reshape(-1, 8)[-2, :4], compact[0, :4])  # the render's table: c1
    rng = np.random.default_rng(3)
    force = rng.normal(size=1024) * 1e-2
    outs = []
    for blocks in (None, line_aligned_zeros((BLOCK_TABLE,))):
        rows, state, last, out = compact[:BANK_ROWS].copy(), meta.copy(), np.array([before]), np.zeros(1024)
        extra = () if blocks is None else (blocks,)
        kept_step(force, out, 0, 1024, rows, state, 1e-10, last, np.zeros(0), *extra)
        outs.append(out)
    assert np.max(np.abs(outs[0])) > 0
    assert np.max(np.abs(outs[1] - outs[0])) < 1e-12 * np.max(np.abs(outs[0]))


def test_free_ringing_by_blocks_follows_the_decaying_sinusoids():
    """With no force a bank of 1-4 modes rendered by blocks (its free ringing too) rings as
    sum_k A_k R_k^n sin(n theta_k + phi_k) over spans of awkward lengths (flush frames
    at 1024 and 2048 inside), its modes past ``live`` silent, its state the recursion's."""
    rng = np.random.default_rng(13)
    n = np.arange(3001)[:, None]
    for live in (1, 2, 4):
        bank = compact_bank(rng, live)
        amp, phi = rng.uniform(0.5, 2.0, live), rng.uniform(0, 6, live)
        radius = np.sqrt(bank[1, :live])
        theta = np.arccos(bank[0, :live] / (2 * radius))
        bank[4, :live] = amp / radius * np.sin(phi - theta)  # y[-1]
        bank[5, :live] = amp / radius**2 * np.sin(phi - 2 * theta)  # y[-2]
        expected = np.sum(amp * radius**n * np.sin(n * theta + phi), axis=1)
        out, at, meta, last = np.zeros(3001), 0, np.array([live, 1, 8]), np.zeros(1)
        table = line_aligned_zeros((BLOCK_TABLE,))
        for size in (5, 8, 1000, 13, 1975):
            kept_step(
                np.zeros(size),
                out[at : at + size],
                at,
                size,
                bank[:BANK_ROWS],
                meta,
                1e-12,
                last,
                np.zeros(0),
                table,
            )
            at += size
        assert np.max(np.abs(out - expected)) < 1e-9 * np.max(np.abs(expected)), live
        assert meta[0] == live and last[0] == 0.0 and not np.any(bank[4:6, live:])

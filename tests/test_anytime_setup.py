"""A mode budget's set-up (ModeBudget.attach): the per-mode rows it computes in one
compiled pass against numpy's formulas, and the periodogram's shared window and twiddles."""

import os
import subprocess
import sys

import numpy as np
import pytest

from jassy.anytime import ModeBudget
from jassy.engines.offline import OfflineEngine
from jassy.patchfile import load_patch
from ugens import modal_budget as mb

PERIOD, FS, HORIZON = 2048, 48000.0, 0.1


def numpy_forcing(sin2, inv, c2, frequencies, decays, order, scales, period, rate, horizon):
    """The rows of ugens.modal_budget.forcing_rows with numpy, as the budget used to
    compute them: (sin2, inv, decay, growth, bins, fill); fill, the share of a period a
    free decay fills, as the sum of its energy's geometric series term by term."""
    retune = 1.0 / np.sqrt(scales[2])
    f = frequencies[order] * (scales[0] * retune)
    d = decays[order] * (scales[1] * retune)
    bins = np.minimum(np.rint(f * period / rate), period // 2)
    two_d_tau = 2.0 * d * horizon
    growth = np.where(two_d_tau > 1e-9, -np.expm1(-two_d_tau) / np.maximum(2.0 * d, 1e-300), horizon)
    fill = np.sum(c2[:, None] ** np.arange(period), axis=1) / period
    return sin2, inv, c2**period, growth, bins, fill


def test_forcing_rows_match_numpy_on_random_modes():
    """Random poles and modes in a shuffled order, retuned (freq_scale, decay_scale and a
    fragment size), some undamped (growth = the horizon) and some past the top bin: the
    compiled pass writes the bank's columns only, equal to numpy's within 1 ulp, bins
    exactly."""
    rng = np.random.default_rng(5)
    k, other = 37, 5
    sin2, inv, c2 = rng.uniform(0.01, 1, k), rng.uniform(1, 100, k), rng.uniform(0.99, 1, k)
    frequencies, decays = rng.uniform(20, 30000, k), rng.uniform(0, 40, k)
    decays[:4], frequencies[4:6] = 0.0, 40000.0
    order = rng.permutation(k)
    scales = (1.3, 0.7, 2.5)
    rows = np.full((mb.MODE_ROWS, other + k), -1.0)
    bins = np.full(other + k, -1, dtype=np.int64)
    mb.forcing_rows(
        rows[:, other:],
        bins[other:],
        sin2,
        inv,
        c2,
        frequencies,
        decays,
        order,
        scales,
        (PERIOD, FS, HORIZON),
    )
    expected = numpy_forcing(sin2, inv, c2, frequencies, decays, order, scales, PERIOD, FS, HORIZON)
    for row, want in zip((mb.SIN2, mb.INV, mb.DECAY, mb.GROWTH), expected[:4], strict=True):
        assert np.allclose(rows[row, other:], want, rtol=4e-16, atol=0)
    assert np.array_equal(bins[other:], expected[4])
    assert np.allclose(rows[mb.FILL, other:], expected[5], rtol=1e-10, atol=0)
    assert np.any(expected[4] == PERIOD // 2) and np.any(expected[3] == HORIZON)
    assert np.all(rows[:, :other] == -1.0) and np.all(bins[:other] == -1)
    written = (mb.SIN2, mb.INV, mb.DECAY, mb.GROWTH, mb.FILL)
    untouched = [r for r in range(mb.MODE_ROWS) if r not in written]
    assert np.all(rows[untouched] == -1.0)


def test_a_budgeted_banks_rows_after_attach_match_numpy():
    """The bell's bank attached to a budget (tables filled by ModeBudget.attach): its
    per-mode rows equal numpy's formulas from its model and design."""
    patch = load_patch("bell")
    bank = patch.graph.nodes["bell"]
    patch.graph.budget = ModeBudget(max_modes=30)
    OfflineEngine(patch.graph, patch.score, FS, 4096, limiter=False, program=False)
    tables = patch.graph.budget._tables
    _, _, sin2, inv = bank._poles
    scales = (1.0, 1.0, 1.0)
    model = bank.model
    expected = numpy_forcing(
        sin2, inv, bank._fresh[1], model.frequencies, model.decays, bank.order, scales, PERIOD, FS, HORIZON
    )
    for row, want in zip((mb.SIN2, mb.INV, mb.DECAY, mb.GROWTH), expected[:4], strict=True):
        assert np.allclose(tables.rows[row], want, rtol=4e-16, atol=0)
    assert np.array_equal(tables.bins, expected[4])
    assert np.allclose(tables.rows[mb.FILL], expected[5], rtol=1e-10, atol=0)


def test_budgets_share_the_window_and_twiddles_and_no_render_writes_them():
    """Two budgets of the same period read one array of the Hann window and the
    transform's twiddles (cos, sin of 2 pi j / period); after a scrape render (which
    takes periodograms, their scratch their own) it still holds exactly those."""
    patch = load_patch("scrape")
    patch.graph.budget = ModeBudget(max_modes=200)
    engine = OfflineEngine(patch.graph, patch.score, FS, 4096, limiter=False, program=False)
    engine.render(1.0)
    spectra = patch.graph.budget._tables.spectra
    assert spectra is mb.budget_tables([3], PERIOD).spectra
    j = np.arange(PERIOD // 2 + 1)
    assert np.array_equal(spectra[mb.WINDOW], np.hanning(PERIOD))
    assert np.allclose(spectra[mb.COS, : j.size], np.cos(2 * np.pi * j / PERIOD), atol=1e-15)
    assert np.allclose(spectra[mb.SIN, : j.size], np.sin(2 * np.pi * j / PERIOD), atol=1e-15)
    assert mb.window_power(PERIOD, FS) == FS * np.sum(np.hanning(PERIOD) ** 2)
    with pytest.raises(ValueError, match="read-only"):  # shared by every budget: never written
        spectra[mb.WINDOW, 0] = 1.0


def test_packed_zeros_carves_zeroed_line_aligned_arrays_at_their_slots():
    """Each array of jassy.packed_arrays.packed_zeros is zeroed, C-contiguous, of its
    shape and dtype, starts on a 64-byte line after the one before it (none overlap) and
    its slot holds its address and extents; an empty field still takes a line."""
    from jassy.jit import address
    from jassy.packed_arrays import BOOL, FLOAT, INT, LINE, packed_zeros

    fields = [((3, 5), FLOAT), ((0,), INT), ((7,), BOOL), ((2, 9), INT), ((1,), FLOAT)]
    arrays, slots = packed_zeros(fields)
    starts = [address(a) if a.size else slot[0] for a, slot in zip(arrays, slots, strict=True)]
    assert all(s % LINE == 0 for s in starts)
    sizes = [max(a.nbytes, 1) for a in arrays]
    assert all(b - a >= -(-n // LINE) * LINE for a, b, n in zip(starts, starts[1:], sizes, strict=False))
    for (shape, dtype), a, slot, start in zip(fields, arrays, slots, starts, strict=True):
        assert a.shape == shape and a.dtype == dtype and a.flags.c_contiguous and not a.any()
        assert slot == (start, shape[0], shape[1] if len(shape) > 1 else 1)


def test_the_step_handle_carved_from_buffers_lists_every_record_as_handle_does():
    """ModeBudget.attach carves the tables, the Hearing, the Decision, the step state and
    the impacts out of a few buffers and writes their handle from offsets: it equals the
    handle jassy.record_views.handle makes by asking numpy for each array's address, on
    the bell (one bank) and three bells of different sizes struck in turn."""
    from jassy import Event, Graph
    from jassy.anytime import BY_PYTHON
    from jassy.record_views import handle
    from patches.models import bell_model
    from ugens import ImpactForce, Mixer, ModalBank

    hits = [ImpactForce(name=f"h{b}", duration=0.0005) for b in range(3)]
    banks = [ModalBank(bell_model(40 + 30 * b, seed=b), name=f"b{b}")(hit) for b, hit in enumerate(hits)]
    struck = [Event(0.1 * i, f"h{i % 3}", "impact", {"impulse": 0.3}) for i in range(7)]
    bell = load_patch("bell")
    for graph, score in ((bell.graph, bell.score), (Graph(Mixer(*banks), haptic=hits), struck)):
        graph.budget = ModeBudget(max_modes=30)
        OfflineEngine(graph, score, FS, 4096, limiter=False, program=False)
        budget = graph.budget
        outputs = (budget._addresses[1], budget._flags[BY_PYTHON], budget._zeros)
        records = (budget._tables, budget.hearing, outputs)
        rest = (budget._kick_table, (budget._state,), budget.decision)
        assert np.array_equal(budget._step_handle, handle(*records, *rest))


def test_an_impact_inserted_during_a_budgeted_render_is_ranked_as_one_scored():
    """The budget's one-call sub-blocks take the impacts loaded at attach until the
    scheduler says the score changed (Scheduler.insert): a bell struck once more at 1.3 s
    by an event inserted after 0.5 s of rendering sounds as the same bell with that
    impact in its score from the start (the budget foresees it either way), and unlike
    the bell without it."""
    from jassy import Event
    from jassy.scheduler import validate_event

    extra = Event(1.3, "clapper", "impact", {"impulse": 0.7, "location": "waist"})

    def render(score, insert_at=None):
        patch = load_patch("bell")
        patch.graph.budget = ModeBudget(max_modes=30)
        engine = OfflineEngine(patch.graph, score(patch), FS, 4096, limiter=False, program=False)
        if insert_at is None:
            return engine.render(2.0).audio
        first = engine.render(insert_at).audio
        engine.scheduler.insert(validate_event(patch.graph, extra, "test"))
        return np.concatenate((first, engine.render(2.0 - insert_at).audio), axis=1)

    scored = render(
        lambda p: sorted([*p.score, validate_event(p.graph, extra, "test")], key=lambda e: e.time)
    )
    inserted = render(lambda p: p.score, insert_at=4096 * 6 / FS)
    plain = render(lambda p: p.score)
    assert np.array_equal(inserted, scored)
    assert not np.allclose(plain, scored)


def test_a_set_inserted_without_a_location_keeps_the_listed_impacts():
    """Scheduler.insert lists the score's impacts again only for an impact-like event or
    a set naming a location: a gain set inserted live on the bell's output keeps the
    listing (the same object, the budget not told the score changed) and sounds as the
    same set scored from the start; a location set inserted after it relists."""
    from jassy import Event
    from jassy.scheduler import validate_event

    gain = Event(1.0, "out", "set", {"gain": 0.5})
    moved = Event(1.5, "bell", "set", {"location": "lip"})

    def engine(score):
        patch = load_patch("bell")
        patch.graph.budget = ModeBudget(max_modes=30)
        return patch, OfflineEngine(patch.graph, score(patch), FS, 4096, limiter=False, program=False)

    patch, live = engine(lambda p: p.score)
    told = []
    patch.graph.budget.score_changed = lambda frame, now: told.append(True)
    first = live.render(4096 * 6 / FS).audio
    listed = live.scheduler.listed_impacts()
    live.scheduler.insert(validate_event(patch.graph, gain, "test"))
    audio = np.concatenate((first, live.render(1.0).audio), axis=1)
    assert live.scheduler.listed_impacts() is listed and not told
    patch, scored = engine(
        lambda p: sorted([*p.score, validate_event(p.graph, gain, "test")], key=lambda e: e.time)
    )
    assert np.array_equal(audio, scored.render(audio.shape[1] / FS).audio)
    live.scheduler.insert(validate_event(live.graph, moved, "test"))
    assert live.scheduler.listed_impacts() is not listed and told


NODE_PATH_WITHOUT_LIMITER = """
from jassy.engines import coldstart
from jassy.engines.offline import OfflineEngine
from jassy.patchfile import load_patch

before = coldstart.kernels_cached()
patch = load_patch("bell")
OfflineEngine(patch.graph, patch.score, 48000.0, 256, limiter=False, program=False).render(0.1)
coldstart._cache_found = False  # (asked again, not remembered)
print(before, coldstart.kernels_cached())
"""


@pytest.mark.timeout(300)
def test_a_render_without_the_limiter_fills_what_the_cold_start_check_looks_for(tmp_path):
    """On an empty numba cache the engine's cold-start check
    (jassy.engines.coldstart.kernels_cached) finds nothing compiled; after one node-by-node
    render without the limiter (as the anytime bench's) it finds the cache filled, so later
    engine starts run no cold-start compile units and fork no helper."""
    env = dict(os.environ, NUMBA_CACHE_DIR=str(tmp_path))
    out = subprocess.run(
        [sys.executable, "-c", NODE_PATH_WITHOUT_LIMITER],
        env=env,
        capture_output=True,
        text=True,
        timeout=280,
    )
    assert out.returncode == 0, out.stderr[-2000:]
    assert out.stdout.split() == ["False", "True"]

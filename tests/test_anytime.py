"""Anytime synthesis: error falls with the budget, the budget holds, modes leave smoothly."""

import numpy as np
import pytest
from helpers import max_abs_diff

from jassy import Event, Graph, ModalModel, PatchError, render
from jassy.anytime import ModeBudget, a_weighting_power
from jassy.apps.cli import main
from jassy.engines.offline import OfflineEngine
from jassy.patchfile import load_patch
from patches.models import bell_model
from patches.models_surface import steel_plate_model
from ugens import ImpactForce, Mixer, ModalBank
from ugens.scrape import Scrape

FS = 48000


def scene(budget, seconds=2.0, seed=0):
    """Six bells of 150 modes struck 30 times at random."""
    rng = np.random.default_rng(seed)
    banks, hits = [], []
    for b in range(6):
        hit = ImpactForce(name=f"h{b}", duration=0.0005)
        banks.append(ModalBank(bell_model(150, prime=150 + 60 * b, seed=b), name=f"b{b}")(hit))
        hits.append(hit)
    score = [
        Event(float(t), f"h{int(b)}", "impact", {"impulse": float(j)})
        for t, b, j in zip(
            rng.uniform(0, seconds, 30), rng.integers(0, 6, 30), rng.uniform(0.05, 0.5, 30), strict=True
        )
    ]
    return Graph(Mixer(*banks), haptic=hits, budget=budget), score


def test_error_against_full_synthesis_falls_as_the_budget_grows():
    graph, score = scene(None)
    full = render(graph, score, 2.0, FS, 64, limiter=False).audio[0]
    errors = []
    for n in (20, 90, 225, 450, 900):
        graph, score = scene(ModeBudget(max_modes=n))
        y = render(graph, score, 2.0, FS, 64, limiter=False).audio[0]
        errors.append(np.sqrt(np.mean((y - full) ** 2) / np.mean(full**2)))
    assert all(a > b for a, b in zip(errors, errors[1:], strict=False)), errors
    assert errors[-1] < 1e-9  # everything fits: exact
    assert errors[2] < 0.3  # a quarter of the modes already gets within -10 dB


def test_budget_is_never_exceeded():
    budget = ModeBudget(max_modes=100)
    graph, score = scene(budget)
    banks = [graph.nodes[f"b{b}"] for b in range(6)]
    worst = [0]

    def audit(start, n):
        worst[0] = max(worst[0], sum(int(b.meta[0]) for b in banks))

    graph.prepare(FS, 64)
    original = Graph.prepare

    def prepare_with_audit(self, sample_rate, block):
        original(self, sample_rate, block)
        self.steps.append(audit)

    Graph.prepare = prepare_with_audit
    try:
        render(graph, score, 2.0, FS, 64, limiter=False)
    finally:
        Graph.prepare = original
    assert 90 <= worst[0] <= 100
    # decisions only where impacts come (at most the periods before and of each strike)
    assert budget.peak_modes <= 100 and 0 < budget.decisions <= 2 * 30


def test_budgeted_render_is_block_size_invariant():
    outs = []
    for block in (1, 64, 1000):
        graph, score = scene(ModeBudget(max_modes=120), seconds=0.6)
        outs.append(render(graph, score, 0.6, FS, block, limiter=False).audio)
    assert max_abs_diff(outs[0], outs[1]) < 1e-6 and max_abs_diff(outs[0], outs[2]) < 1e-6


def test_a_displaced_mode_fades_out_before_the_new_one_enters():
    """Budget 1: a ringing 220 Hz mode must give way to a 1 kHz strike at 0.5 s."""
    low = ModalModel([220.0], [0.5], [[1.0]])
    high = ModalModel([1000.0], [3.0], [[1.0]])
    ha, hb = ImpactForce(name="ha"), ImpactForce(name="hb")
    mix = Mixer(ModalBank(low, name="a")(ha), ModalBank(high, name="b")(hb))
    score = [Event(0.0, "ha", "impact", {"impulse": 0.5}), Event(0.5, "hb", "impact", {"impulse": 1.0})]
    budget = ModeBudget(max_modes=1, period=512)
    y = render(Graph(mix, budget=budget), score, 1.0, FS, 64, limiter=False).audio[0]
    hb2 = ImpactForce(name="hb")
    b_only = render(Graph(ModalBank(high)(hb2)), score[1:], 1.0, FS, 64, limiter=False).audio[0]
    strike = int(0.5 * FS)
    fade_start = (strike // 512 - 1) * 512  # the decision one period before the strike's own
    # before the fade: the low mode rings untouched; during it: a smooth exponential decay
    ring = y[:fade_start]
    np.testing.assert_allclose(  # (the kept bank's kernels round otherwise: ugens.modal_block,
        ring,  # whose free ringing drifts ~1e-11 of the peak in 0.5 s at 220 Hz, ring's ~1e-13)
        render(Graph(ModalBank(low)(ImpactForce(name="ha"))), score[:1], 1.0, FS, 64, limiter=False).audio[0][
            :fade_start
        ],
        rtol=0,
        atol=1e-10 * np.max(np.abs(ring)),
    )
    assert np.max(np.abs(np.diff(y[fade_start - 200 : strike]))) <= np.max(np.abs(np.diff(ring))) * 1.001
    before = np.abs(y[fade_start - 220 : fade_start]).max()  # one 220 Hz cycle before the fade
    assert np.abs(y[fade_start + 462 : fade_start + 512]).max() < 2e-3 * before  # -54 dB within the period
    assert np.max(np.abs(y[strike - 64 : strike])) < 2e-3 * np.max(np.abs(ring))
    # the 1 kHz strike is rendered in full from its first sample
    np.testing.assert_allclose(y[strike:], b_only[strike:], atol=1e-9)
    assert budget.peak_modes == 1


def test_a_weighting_is_normalised_and_shaped():
    w = a_weighting_power(np.array([1000.0, 100.0, 20.0, 4000.0]))
    assert w[0] == pytest.approx(1.0, rel=1e-3)
    assert 10 * np.log10(w[1]) == pytest.approx(-19.1, abs=0.2)  # IEC 61672 table values
    assert 10 * np.log10(w[2]) == pytest.approx(-50.5, abs=0.3)
    assert 10 * np.log10(w[3]) == pytest.approx(1.0, abs=0.2)


def test_budget_options_are_validated_and_reach_the_cli(tmp_path, capsys):
    with pytest.raises(PatchError, match="mode_budget: expected an integer >= 1"):
        ModeBudget(max_modes=0)
    for period in (3000, 4, 2048.0):
        with pytest.raises(
            PatchError, match=rf"ModeBudget period: expected a power of two >= 8 frames, got {period}"
        ):
            ModeBudget(max_modes=10, period=period)
    assert ModeBudget(max_modes=10, period=np.int64(1024)).period == 1024
    assert (
        main(
            [
                "render",
                "bell",
                "-o",
                str(tmp_path / "b.wav"),
                "--duration",
                "0.5",
                "--mode-budget",
                "10",
                "-q",
            ]
        )
        == 0
    )


def test_cpu_budget_adapts_the_mode_count():
    """A CPU budget impossible to meet starts from every mode and shrinks to the floor of
    16 modes; from then on the banks compute at most those plus the modes still fading
    out of the last decision."""
    budget = ModeBudget(cpu_fraction=1e-4)
    graph, score = scene(budget, seconds=1.0)
    banks, step, adapted = [graph.nodes[f"b{b}"] for b in range(6)], budget.step, []

    def watched_step(start, n):
        step(start, n)
        if budget.limit == 16:
            fading = int(budget.decision.fade.sum())
            adapted.append((sum(bank.active_modes() for bank in banks), fading))

    budget.step = watched_step
    render(graph, score, 1.0, FS, 64, limiter=False)
    assert budget.limit == 16 and budget.peak_modes > 16 * 4  # it started far above the floor
    assert len(adapted) > 0.5 * FS / 64  # the floor is reached within the first half second
    assert all(computed <= 16 + fading for computed, fading in adapted), max(adapted)
    assert max(fading for _, fading in adapted) > 0  # modes do fade out there


def error_db(y, reference):
    """Energy of the difference over the energy of the reference, dB."""
    return 10 * np.log10(max(np.sum((y - reference) ** 2) / np.sum(reference**2), 1e-300))


def render_patch(name, seconds, fraction, block=4096):
    patch = load_patch(name)
    total = sum(node.model.n_modes for node in patch.graph.order if node.supports_budget)
    if fraction is not None:
        patch.graph.budget = ModeBudget(max_modes=int(round(fraction * total)))
    engine = OfflineEngine(patch.graph, patch.score, FS, block, limiter=False, program=False)
    return engine.render(seconds).audio[0], patch.graph.budget


@pytest.mark.timeout(300)
@pytest.mark.parametrize(("name", "seconds"), [("scrape", 7.0), ("bell", 6.0)])
def test_a_quarter_of_the_modes_is_within_15_db_and_all_of_them_exact(name, seconds):
    """Scraping (a continuous contact moving over the plate) and a bell struck at four
    places: a quarter of the modes renders within -15 dB of the full synthesis, all of
    them reproduce it (the budget then never decides)."""
    full, _ = render_patch(name, seconds, None)
    quarter, budget = render_patch(name, seconds, 0.25)
    assert budget.decisions > 0
    assert error_db(quarter, full) <= -15.0
    everything, budget = render_patch(name, seconds, 1.0)
    assert budget.decisions == 0 and error_db(everything, full) < -200.0


def test_modes_rank_by_their_energy_over_the_period_not_their_amplitude_now():
    """Two banks struck at once, one mode each: a 220 Hz mode ringing for seconds and a
    2.2 kHz one gone in a few ms (600 1/s), which the ranking once put first by its
    squared amplitude per unit impulse. Over a period an ideal impulse leaves the slow one
    ~45x the fast one's energy (the default pulse excites 2.2 kHz less still): with one
    mode allowed the budget keeps the slow one, so the render is the slow mode's."""

    def graph(budget):
        slow = ModalBank(ModalModel([220.0], [3.0], [[1.0]]), name="slow")(ImpactForce(name="hit_slow"))
        fast = ModalBank(ModalModel([2200.0], [600.0], [[1.0]]), name="fast")(ImpactForce(name="hit_fast"))
        return Graph(Mixer(slow, fast), budget=budget)

    score = [Event(0.1, f"hit_{name}", "impact", {"impulse": 0.1}) for name in ("slow", "fast")]
    full = render(graph(None), score, 0.5, FS, 64, limiter=False).audio[0]
    slow_alone = render(graph(None), score[:1], 0.5, FS, 64, limiter=False).audio[0]
    kept = render(graph(ModeBudget(max_modes=1)), score, 0.5, FS, 64, limiter=False).audio[0]
    assert error_db(kept, slow_alone) < -200.0
    assert error_db(kept, full) < -30.0  # (keeping the fast mode: about 0 dB)


@pytest.mark.parametrize("fed_bank", [False, True])
def test_an_impact_after_a_mid_period_onset_still_counts_at_that_decision(fed_bank):
    """A scrape starts mid-period on a silent plate (an onset: the budget decides there)
    and a silent bell is struck later in that period: the decision counts the rest of the
    period's impacts, so the bell keeps modes for its impact and sounds as in the full
    synthesis (it scored zero, stayed silent and never scored again). Also where the banks
    render themselves after the budget's step (``fed_bank``: a bank hears a bank)."""
    period = 2048

    def graph(budget):
        stylus = Scrape(name="stylus", roughness=4e-6, stiffness=1e5, seed=3, force=0.0, speed=0.0)
        plate = ModalBank(steel_plate_model(), name="plate", location="t2", gain=30.0)(stylus)
        bell = ModalBank(bell_model(150, prime=300, seed=4), name="bell")(ImpactForce(name="hit"))
        heard = [plate, bell]
        if fed_bank:
            feeder = ModalBank(bell_model(20, prime=500, seed=1), name="feeder")(ImpactForce(name="tap"))
            heard += [feeder, ModalBank(bell_model(10, prime=700, seed=2), name="fed")(feeder)]
        return Graph(Mixer(*heard), budget=budget), bell

    onset, strike = 10 * period + 300, 10 * period + 1500
    score = [
        Event(onset / FS, "stylus", "set", {"force": 1.0, "speed": 0.5}, jump=True),
        Event(strike / FS, "hit", "impact", {"impulse": 0.5}),
    ]
    bells = []
    for budget in (None, ModeBudget(max_modes=250, period=period)):
        g, bell = graph(budget)
        engine = OfflineEngine(g, score, FS, 512, limiter=False, program=False)
        assert g.budget_renders is (budget is not None and not fed_bank)
        out = []
        for _ in range(0, 12 * period, 512):
            engine.render(512 / FS)
            out.append(bell.out[:512].copy())
        bells.append(np.concatenate(out)[strike:])
    full, budgeted = bells
    assert np.sum(full**2) > 1.0
    assert error_db(budgeted, full) < -20.0


def test_a_feeder_heard_through_a_slow_bank_ranks_by_how_long_that_bank_rings():
    """A fast-decaying exciter (40 modes, ~100 1/s) heard only through a slow bell it
    feeds, beside a bell struck on its own: the exciter's modes carry what the fed bell
    rings with over the period, which lasts as long as the bell's modes (the slower of
    each pair), not the exciter's few ms. Ranked by the exciter's own decay they lost
    their place and the fed bell went silent (-3.2 dB at 100 of 200 modes; -8.2 dB now)."""
    rng = np.random.default_rng(0)
    frequencies, decays = np.sort(rng.uniform(150, 4000, 40)), 100.0 * rng.uniform(0.7, 1.4, 40)
    gains = rng.uniform(0.3, 1, (1, 40))
    times, impulses = rng.uniform(0, 1.5, 24), rng.uniform(0.05, 0.5, 24)

    def graph(budget):
        exciter = ModalBank(ModalModel(frequencies, decays, gains), name="exciter")(ImpactForce(name="ha"))
        fed = ModalBank(bell_model(60, prime=250, seed=1), name="fed", gain=300.0)(exciter)
        other = ModalBank(bell_model(100, prime=450, seed=2), name="other")(ImpactForce(name="hc"))
        return Graph(Mixer(fed, other), budget=budget)

    score = [
        Event(float(t), name, "impact", {"impulse": float(j)})
        for t, name, j in zip(times, ["ha", "hc"] * 12, impulses, strict=True)
    ]
    full = render(graph(None), score, 1.5, FS, 256, limiter=False).audio[0]
    half = render(graph(ModeBudget(max_modes=100)), score, 1.5, FS, 256, limiter=False).audio[0]
    assert error_db(half, full) < -6.0


def test_a_contact_nobody_scheduled_sounds_from_its_first_sample():
    """A scrape starts on a silent plate mid-period, with no impact in the score: the
    budget decides in that very sub-block, so the budgeted output starts with the full one
    and follows it closely."""

    def graph(budget):
        stylus = Scrape(name="stylus", roughness=4e-6, stiffness=1e5, seed=3, force=0.0, speed=0.0)
        plate = ModalBank(steel_plate_model(), name="plate", location="t2", gain=30.0)(stylus)
        bell = ModalBank(bell_model(150), name="bell")(ImpactForce(name="hit"))
        return Graph(Mixer(plate, bell), budget=budget)

    score = [
        Event(0.0, "hit", "impact", {"impulse": 0.3}),
        Event(0.3, "stylus", "set", {"force": 1.0, "speed": 0.5}, jump=True),
    ]
    start = int(0.3 * FS)
    assert start % 2048 != 0  # mid-period
    full = render(graph(None), score, 0.6, FS, 64, limiter=False).audio[0]
    budget = ModeBudget(max_modes=200)
    y = render(graph(budget), score, 0.6, FS, 64, limiter=False).audio[0]
    assert error_db(y[start : start + 480], full[start : start + 480]) < -10.0  # its first 10 ms
    assert error_db(y[start : start + 4800], full[start : start + 4800]) < -10.0  # and 0.1 s


def test_ranking_keeps_exactly_the_highest_positive_scores():
    """The compiled ranking against a sort: the ``limit`` highest positive scores (ties at
    the threshold filled up to the limit), all positive ones when fewer."""
    from jassy.anytime_rank import DIGIT_BITS, top_mask

    rng = np.random.default_rng(1)
    for size, limit in ((835, 209), (40, 7), (12, 30)):
        score = np.where(rng.random(size) < 0.3, 0.0, rng.random(size))
        score[:5] = score[5]  # ties
        keep = np.zeros(size, dtype=bool)
        top_mask(score, limit, keep, np.empty(score.size), np.empty(1 << DIGIT_BITS, np.int64))
        positive = np.sort(score[score > 0])[::-1]
        assert keep.sum() == min(limit, positive.size)
        assert np.all(score[keep] > 0)
        if positive.size > limit:
            assert score[keep].min() == positive[limit - 1]
            assert score[~keep].max() <= positive[limit - 1]


def test_rank_modes_fades_the_kept_modes_not_on_top_later():
    """rank_modes against numpy masks: later_top the ``limit`` highest positive scores[1]
    (lexsort: ties by index), fade those of scores[0]'s top not among them and sounding
    (scores[2] > 0), keep the rest of scores[0]'s top."""
    from jassy.anytime_rank import rank_modes

    rng = np.random.default_rng(6)
    for size, limit in ((297, 74), (40, 7), (12, 30)):
        scores = np.where(rng.random((3, size)) < 0.3, 0.0, rng.exponential(size=(3, size)) ** 4)
        scores[:2, :6] = scores[:2, 6:7]  # ties
        masks = [np.zeros(size, dtype=bool) for _ in range(3)]
        any_fade = rank_modes(scores, limit, *masks)
        keep, fade, later = masks
        top = []
        for row in scores[:2]:
            order = np.lexsort((np.arange(size), -row))  # highest first, ties by index
            mask = np.zeros(size, dtype=bool)
            mask[order[:limit]] = True
            top.append(mask & (row > 0))
        np.testing.assert_array_equal(later, top[1])
        np.testing.assert_array_equal(fade, top[0] & ~top[1] & (scores[2] > 0))
        np.testing.assert_array_equal(keep, top[0] & ~fade)
        assert any_fade == fade.any()


@pytest.mark.timeout(120)
def test_selection_gives_numpys_partition_value():
    """kth_smallest (the ranking's threshold, a radix selection, and the count above it)
    against np.partition:
    sizes 1-300, ties, zeros, values spread over 80 decades and values a last bit apart,
    k from the first to the last; top_mask with a NaN score takes np.partition's
    threshold, and with a limit of 0 keeps nothing (it used to select one past the end)."""
    from jassy.anytime_rank import DIGIT_BITS, kth_smallest, top_mask

    rng = np.random.default_rng(5)
    bins = np.zeros(1 << DIGIT_BITS, np.int64)
    for size in (1, 2, 3, 7, 64, 297):
        values = np.round(rng.exponential(size=size) ** 3, 1)  # many ties, zeros
        spread = np.exp(rng.normal(0.0, 30.0, size))  # 1e-40 .. 1e40, subnormal-free
        spread[1 : size // 3] = np.nextafter(spread[0], np.inf)  # values a last bit apart
        for k in [*range(0, size, max(1, size // 17)), size - 1]:
            for a in (values, spread):
                value = np.partition(a, k)[k]
                assert kth_smallest(a.copy(), k, bins) == (value, np.sum(a > value))
    for unordered in (False, True):
        score = rng.random(40)
        score[3] = np.nan if unordered else score[3]
        keep = np.ones(40, dtype=bool)
        top_mask(score, 0, keep, np.empty(score.size), np.empty(1 << DIGIT_BITS, np.int64))
        assert not keep.any()
    score = rng.random(50)
    score[7] = np.nan
    keep = np.zeros(50, dtype=bool)
    top_mask(score, 10, keep, np.empty(score.size), np.empty(1 << DIGIT_BITS, np.int64))
    threshold = np.partition(score, 40)[40]  # (numpy sorts NaN last: 9 numbers above it, then it)
    np.testing.assert_array_equal(keep, score >= threshold)


def test_a_budgeted_bank_is_split_only_where_the_budget_decides(monkeypatch):
    """Six bells struck 30 times, blocks of 4096 and decisions every 2048 frames, one bell
    rendered through its own ``process`` (over the spans the budget renders): a sub-block
    is split only where the budget decides inside it (the scheduler does not cut
    sub-blocks at every period), and the output equals a render whose sub-blocks are all
    cut at every period (block 2048) within rounding."""
    graph, score = scene(ModeBudget(max_modes=120), seconds=2.0)
    budget, slow, spans, steps = graph.budget, graph.nodes["b0"], [], []
    monkeypatch.setattr(slow, "anytime_compiled", lambda: False)
    process, step = slow.process, budget.step

    def counted_process(start, n, offset):
        spans.append(start)
        process(start, n, offset)

    def counted_step(start, n):
        spans_before, decisions_before = len(spans), budget.decisions
        step(start, n)
        inner_periods = len(range((start // 2048 + 1) * 2048, start + n, 2048))
        steps.append((len(spans) - spans_before, budget.decisions - decisions_before, inner_periods))

    monkeypatch.setattr(slow, "process", counted_process)
    budget.step = counted_step
    y = render(graph, score, 2.0, FS, 4096, limiter=False).audio
    assert budget.decisions > 0 and len(steps) == 24 and len(spans) >= len(steps)
    assert all(pieces <= 1 + decisions for pieces, decisions, _ in steps)
    # a split at every period would break that: some sub-block holds a period start but no decision
    assert any(inner > decisions for _, decisions, inner in steps)
    graph, score = scene(ModeBudget(max_modes=120), seconds=2.0)
    cut = render(graph, score, 2.0, FS, 2048, limiter=False).audio
    assert max_abs_diff(y, cut) < 1e-6


def changing_scene(budget):
    """:func:`scene` over one second with parameter changes: a frequency ramp, a jump of
    the gain, a move of the contact (where the next impacts strike) and a decay ramp
    queued exactly at a period start (frame 20480)."""
    graph, score = scene(budget, seconds=1.0)
    score += [
        Event(0.2, "b1", "set", {"freq_scale": 1.05}, ramp=0.1),
        Event(0.35, "b2", "set", {"gain": 0.5}, jump=True),
        Event(0.3, "b3", "set", {"location": 3}),
        Event(20480 / FS, "b4", "set", {"decay_scale": 2.0}, ramp=0.05),
    ]
    return graph, sorted(score, key=lambda event: event.time)


def test_the_compiled_render_of_all_banks_matches_each_bank_rendering_itself(monkeypatch):
    """The budget renders its banks in one compiled call over its tables (a bank's queued
    parameter changes applied between two calls, its ramps by
    ugens.modal_kept.ramp_kept); with every bank sent through its own ``process`` instead
    (as banks with a size input are) the output is the same: six bells struck 30 times,
    a quarter of their modes, their parameters ramping, jumping and the contact moving.
    A change queued exactly at a period start is applied before that period's decision
    in the compiled path and after it through ``process``: the decision sees the old or
    the new coefficients, both within rounding of each other here."""
    for changing in (False, True):
        make = changing_scene if changing else lambda budget: scene(budget, seconds=1.0)
        graph, score = make(ModeBudget(max_modes=225))
        compiled = render(graph, score, 1.0, FS, 4096, limiter=False).audio
        assert graph.budget.decisions > 0 and graph.budget.mode_samples > 0
        with monkeypatch.context() as patched:
            patched.setattr(ModalBank, "anytime_compiled", lambda self: False)
            graph, score = make(ModeBudget(max_modes=225))
            by_python = render(graph, score, 1.0, FS, 4096, limiter=False).audio
        assert np.max(np.abs(compiled)) > 1e-3
        assert max_abs_diff(compiled, by_python) < 1e-12 * np.max(np.abs(compiled)), changing


def test_a_location_jump_keeps_the_compact_bank_in_place(monkeypatch):
    """A budgeted bank's location jump (the poles stay) sets its coefficients, and its
    compact bank's kept columns, to the new design in place (modal_budget.jump_to_fresh):
    the same output, bit for bit, as writing the compact bank back, jumping and
    gathering it again; six bells at a quarter of their modes, 40 jumps between struck
    locations, some while the banks ring."""
    rng = np.random.default_rng(3)
    jumps = [
        Event(float(t), f"b{int(b)}", "set", {"location": int(loc)}, jump=True)
        for t, b, loc in zip(
            rng.uniform(0, 1.0, 40), rng.integers(0, 6, 40), rng.integers(0, 4, 40), strict=True
        )
    ]
    taken = []
    in_place = ModalBank._jumps_gains_only

    def counted(self, jump):
        taken.append(in_place(self, jump))
        return taken[-1]

    def run(jumping):
        graph, score = scene(ModeBudget(max_modes=225), seconds=1.0)
        score = sorted(score + (jumps if jumping else []), key=lambda event: event.time)
        return render(graph, score, 1.0, FS, 4096, limiter=False).audio

    monkeypatch.setattr(ModalBank, "_jumps_gains_only", counted)
    fast = run(True)
    assert sum(taken) == len(jumps)
    monkeypatch.setattr(ModalBank, "_jumps_gains_only", lambda self, jump: False)
    settled = run(True)
    assert np.array_equal(fast, settled)
    assert max_abs_diff(fast, run(False)) > 1e-3 * np.max(np.abs(fast))  # the jumps are heard


def chained_bells(budget):
    """Bell ``b`` (100 modes) hears bell ``a`` (150 modes), which a hammer strikes 4 times;
    only ``b`` is heard."""
    hit = ImpactForce(name="h", duration=0.0005)
    a = ModalBank(bell_model(150, prime=150, seed=0), name="a")(hit)
    b = ModalBank(bell_model(100, prime=210, seed=1), name="b")(a)
    score = [Event(0.05 + 0.3 * i, "h", "impact", {"impulse": 0.5}) for i in range(4)]
    return Graph(b, budget=budget), score


def test_an_impact_is_credited_to_the_bank_it_drives_and_passed_on_through_a_chain():
    from jassy.scheduler import Scheduler

    graph, score = chained_bells(ModeBudget(max_modes=60))
    graph.prepare(FS, 256)
    impacts = Scheduler(graph, score, FS, 256).upcoming_impulses(0, FS)
    assert [[bank.name for bank in banks] for _, banks, _, _ in impacts] == [["a"]] * 4
    full = render(*chained_bells(None), 1.5, FS, 256, limiter=False).audio[0]
    y = render(*chained_bells(ModeBudget(max_modes=60)), 1.5, FS, 256, limiter=False).audio[0]
    # a quarter of the modes (the struck bell ranked by what reaches the heard one) is
    # within -15 dB; crediting ``b`` with the hammer's impacts gave -2.7 dB
    assert 10 * np.log10(np.sum((y - full) ** 2) / np.sum(full**2)) < -15


def test_the_compiled_real_fft_matches_numpy():
    """Every power-of-two length 4 .. 8192: an odd and an even count of radix-2 stages
    after the first two, the vector butterflies at their narrowest blocks (4 points); the
    scratch and outputs of their exact sizes, followed by NaN guards that are neither read
    (the result would be NaN) nor written. Other lengths and short arrays are refused."""
    from ugens.real_fft import real_spectrum, twiddles

    guard = 16
    for n in 2 ** np.arange(2, 14):
        x = np.random.default_rng(n).normal(size=n) + 0.1
        cos, sin = twiddles(n)
        buffers = [np.full(size + guard, np.nan) for size in (n // 2, n // 2, n // 2 + 1, n // 2 + 1)]
        zr, zi, re, im = (b[: b.size - guard] for b in buffers)
        real_spectrum(x, cos, sin, zr, zi, re, im)
        expected = np.fft.rfft(x)
        assert np.max(np.abs(re + 1j * im - expected)) < 1e-13 * np.max(np.abs(expected))
        assert all(np.isnan(b[b.size - guard :]).all() for b in buffers)
    for n in (2, 6, 12):
        cos, sin = twiddles(n)
        with pytest.raises(ValueError, match="power of two"):
            real_spectrum(np.ones(n), cos, sin, np.zeros(n), np.zeros(n), np.zeros(n), np.zeros(n))
    cos, sin = twiddles(16)
    with pytest.raises(ValueError, match="scratch of n/2"):
        real_spectrum(np.ones(16), cos, sin, np.zeros(7), np.zeros(8), np.zeros(9), np.zeros(9))


def test_the_compiled_periodogram_at_the_modes_bins_matches_numpy():
    from ugens import modal_budget as mb
    from ugens.real_fft import real_spectrum, twiddles

    rng = np.random.default_rng(3)
    period, k = 2048, 97
    force, window = rng.normal(size=period) + 0.3, np.hanning(period)
    bins = np.sort(rng.integers(0, period // 2 + 1, k))
    bins[0], bins[-1] = 0, period // 2  # taps past either end count as zero
    spectrum = np.fft.rfft((force - force.mean()) * window)
    padded = np.pad(np.abs(spectrum) ** 2, 2)
    expected = padded[bins[:, None] + np.arange(5)] @ mb.PSD_SMOOTHING / 7.0
    windowed, psd = np.zeros(period), np.full(k, 2.0)
    mb.centred_windowed(force, window, windowed, 300)  # a ring whose earliest frame is at 300
    assert max_abs_diff(np.roll(windowed, -300), (np.roll(force, -300) - force.mean()) * window) < 1e-12
    mb.centred_windowed(force, window, windowed, 0)
    assert max_abs_diff(windowed, (force - force.mean()) * window) < 1e-12
    re, im, half = np.zeros(period // 2 + 1), np.zeros(period // 2 + 1), np.zeros(period // 2)
    real_spectrum(windowed, *twiddles(period), half, half.copy(), re, im)
    mb.psd_at_bins(re, im, bins, mb.PSD_SMOOTHING, 7.0, 0.75, True, psd)  # remembered
    assert np.allclose(psd, 0.75 * 2.0 + 0.25 * expected, rtol=1e-9)
    mb.psd_at_bins(re, im, bins, mb.PSD_SMOOTHING, 7.0, 0.75, False, psd)
    assert np.allclose(psd, expected, rtol=1e-9)


def test_impacts_load_as_numpy_sums():
    """ugens.modal_budget.load_impacts against sums in numpy: per bank, the squared
    impulses at its current location from the decision to its period's end and in the
    next period, and the squared amplitudes per mode of impacts elsewhere; impacts before
    the decision, two periods on, with impulse <= 0 or on none of the banks (slot -1)
    count nowhere. At a period's start and between two (a force woke a bank)."""
    from jassy.anytime_rank import Kicks
    from ugens import modal_budget as mb

    period, at, counts = 16, 32, [5, 7]
    t = mb.budget_tables(counts, period)
    t.values[mb.GAIN_LEVEL] = (2.0, 3.0)
    t.values[mb.SIZE] = (4.0, 9.0)
    gains = np.random.default_rng(2).normal(size=14)  # bank 1 at two locations: rows at 0 and 7
    rows = [  # frame, slot, impulse, where its gains start (-1: current location)
        (at - 1, 0, 9.0, -1), (at, 0, 0.5, -1), (at + 3, 0, 0.25, -1), (at + 4, 0, -0.5, -1),
        (at + 5, 1, 0.0, 0), (at + 6, -1, 2.0, -1), (at + 7, 1, 0.3, 0), (at + 8, 1, 0.2, 7),
        (at + 10, 0, 0.125, -1), (at + 12, 1, 0.7, 0), (at + period, 0, 0.75, -1),
        (at + period + 1, 1, 0.4, 7), (at + period + 2, 1, 0.6, -1), (at + 2 * period, 0, 5.0, -1),
        (at + 2 * period, 1, 5.0, 0),
    ]  # fmt: skip
    frames, slots, impulses, located = (np.array(column) for column in zip(*rows, strict=True))
    kicks = Kicks(frames, slots, impulses > 0, impulses.astype(float), located, gains)
    for decision in (at, at + period // 2):
        t.values[mb.KICK_NOW] = 7.0  # stale values of an earlier decision are cleared
        t.rows[mb.ELSEWHERE_NOW] = 7.0
        assert mb.load_impacts(t, kicks, len(rows), decision, period)
        bounds = (decision, at + period, at + 2 * period)
        window = [(frames >= bounds[p]) & (frames < bounds[p + 1]) & (impulses > 0) for p in (0, 1)]
        for b, k in enumerate(counts):
            o = sum(counts[:b])
            for later in (0, 1):
                here = window[later] & (slots == b) & (located < 0)
                assert t.values[mb.KICK_NOW + later, b] == pytest.approx(np.sum(impulses[here] ** 2), abs=0)
                elsewhere = np.flatnonzero(window[later] & (slots == b) & (located >= 0))
                assert t.values[mb.HAS_ELSEWHERE_NOW + later, b] == float(elsewhere.size > 0)
                if elsewhere.size:
                    amplitude = (
                        gains[located[elsewhere, None] + np.arange(k)]
                        * impulses[elsewhere, None]
                        * t.values[mb.GAIN_LEVEL, b]
                    )
                    expected = np.sum(amplitude**2, axis=0) / t.values[mb.SIZE, b]
                    assert np.allclose(t.rows[mb.ELSEWHERE_NOW + later, o : o + k], expected, rtol=1e-14)
    assert t.values[mb.KICK_NOW, 0] == 0.125**2  # (the middle's: at + 10 only)


def test_the_periodogram_of_a_banks_ring_in_budget_tables_matches_numpy():
    """ugens.modal_budget.periodogram on real tables (two banks, the second's columns
    after the first's) against numpy.fft.rfft of the ring in time order (its earliest
    frame the decision's modulo the period), centred and Hann-windowed, smoothed over the
    neighbouring bins; the second transform is blended with the first."""
    from ugens import modal_budget as mb

    period, counts, window_power = 256, [11, 23], 3.5
    t = mb.budget_tables(counts, period)
    rng = np.random.default_rng(4)
    t.bins[:] = rng.integers(0, period // 2 + 1, sum(counts))
    t.bins[11], t.bins[-1] = 0, period // 2  # taps past either end count as zero

    def expected_psd(ring, bins):
        spectrum = np.fft.rfft((ring - ring.mean()) * np.hanning(period))
        padded = np.pad(np.abs(spectrum) ** 2, 2)
        return padded[bins[:, None] + np.arange(5)] @ mb.PSD_SMOOTHING / window_power

    bins, first = t.bins[11:], []
    for memory, frame in ((False, 3 * period), (True, 5 * period + 40)):  # the second mid-period
        t.rings[1] = rng.normal(size=period) + 0.2
        mb.periodogram(t, 1, window_power, frame)
        psd = expected_psd(np.roll(t.rings[1], -(frame % period)), bins)  # in time order
        if memory:
            psd = mb.PSD_MEMORY * first[0] + (1 - mb.PSD_MEMORY) * psd
        first.append(psd)
        assert np.allclose(t.rows[mb.SPECTRUM, 11:], psd, rtol=1e-10)
        assert t.values[mb.REMEMBERED, 1] == 1.0
    assert np.all(t.rows[mb.SPECTRUM, :11] == 0.0)  # the first bank's row is untouched


def test_a_remembered_psd_stands_for_psd_reuse_periods():
    """ugens.modal_budget.decide on tables whose second bank hears a new force at each
    decision, one budget period apart (six decisions), then two apart (three): its
    periodogram (the PSD numpy gives for that ring, blended with the one remembered) is
    taken at the first decision and then at the first more than PSD_REUSE_PERIODS (3)
    periods after the last one taken; the decisions between rank by the remembered PSD
    unchanged."""
    from ugens import modal_budget as mb

    period, counts, window_power = 256, [11, 23], 3.5
    t = mb.budget_tables(counts, period)
    t.values[mb.TRANSFORMED, 1] = 1.0
    t.meta[:, 2] = counts  # every mode allowed
    t.rows[mb.SIN2] = 0.5
    rng = np.random.default_rng(5)
    t.bins[:] = rng.integers(2, period // 2 - 2, sum(counts))
    masks = (np.zeros(sum(counts), dtype=bool) for _ in range(3))
    d = mb.Decision(np.zeros(2, dtype=bool), np.array([False, True]), np.zeros(2, dtype=np.intp),
                    np.zeros((3, sum(counts))), *masks)  # fmt: skip
    assert mb.PSD_REUSE_PERIODS == 3
    remembered, transforms = None, []
    for k, frame in enumerate([*range(0, 6 * period, period), *range(7 * period, 13 * period, 2 * period)]):
        t.rings[1] = rng.normal(size=period) * (k + 1)
        spectrum = np.fft.rfft((t.rings[1] - t.rings[1].mean()) * np.hanning(period))
        padded = np.pad(np.abs(spectrum) ** 2, 2)
        fresh = padded[t.bins[11:, None] + np.arange(5)] @ mb.PSD_SMOOTHING / window_power
        before = t.rows[mb.SPECTRUM, 11:].copy()
        mb.decide(t, d, mb.Rates(float(FS), 20, 1.25, 0.99, 0, 0, window_power, frame))
        transformed = not np.array_equal(before, t.rows[mb.SPECTRUM, 11:])
        transforms.append(transformed)
        if transformed:
            remembered = (
                fresh if remembered is None else mb.PSD_MEMORY * remembered + (1 - mb.PSD_MEMORY) * fresh
            )
        assert np.allclose(t.rows[mb.SPECTRUM, 11:], remembered, rtol=1e-10), k
        assert t.values[mb.SPECTRAL, 1] == 1.0
    assert transforms == [True, False, False, False, True, False, False, True, False]


def rubbed_bell(budget):
    """A bell of 150 modes rubbed by white noise (a steady contact force)."""
    from ugens.noise import WhiteNoise

    noise = WhiteNoise(name="rub", amp=1.0, seed=2)
    return Graph(ModalBank(bell_model(150), name="bell", gain=0.01)(noise), budget=budget)


def test_a_steady_force_is_not_decided_every_period():
    """A bell rubbed by steady noise over 24 budget periods: periods whose only news is the
    force heard again are left undecided (jassy.anytime_rank.steady_forces), at least
    every STEADY_PERIODS-th and whenever the force's power rises past STEADY_POWER; the
    error stays within 1 dB of deciding every period (a slow gain ramp keeps the
    budget deciding: its gains move). A force whose power rises fourfold every period
    is decided every period."""
    from jassy.anytime_rank import STEADY_PERIODS, STEADY_POWER

    periods = 24
    seconds = periods * 2048 / FS
    creeping = [Event(0.0, "bell", "set", {"gain": 0.0100001}, ramp=seconds)]
    rising = [Event(k * 2048 / FS, "rub", "set", {"amp": 2.0**k}, jump=True) for k in range(periods)]
    assert STEADY_POWER < 4.0
    results = {}
    for name, score in (("steady", []), ("creeping", creeping), ("rising", rising)):
        full = render(rubbed_bell(None), score, seconds, FS, 4096, limiter=False).audio[0]
        budget = ModeBudget(max_modes=40)
        y = render(rubbed_bell(budget), score, seconds, FS, 4096, limiter=False).audio[0]
        results[name] = budget.decisions, error_db(y, full)
    assert results["creeping"][0] == periods and results["rising"][0] == periods
    # at least one period in STEADY_PERIODS decided, at least a quarter of them left undecided
    assert periods // STEADY_PERIODS <= results["steady"][0] <= 3 * periods // 4, results
    assert abs(results["steady"][1] - results["creeping"][1]) < 1.0


def test_centred_power_is_numpys_variance_and_zero_for_a_steady_force():
    """centred_power (one pass, shifted by the first sample) against numpy's variance on
    noise, noise on a large steady load, a steady force with one spike (first, last or
    inside) and a slow ramp; exactly 0 for a steady force of any value (a 100 % budget
    stays the full banks' bits) and for no sample."""
    from jassy.anytime_rank import centred_power

    rng = np.random.default_rng(3)
    noise = rng.normal(size=2048)
    spiky = []
    for at in (0, 1000, 2047):
        ring = np.full(2048, 3.7)
        ring[at] = -50.0
        spiky.append(ring)
    for ring in (noise, 1e6 + 1e-3 * noise, 1e-9 * noise, *spiky, np.linspace(-2.0, 5.0, 2048), noise[:7]):
        assert centred_power(ring) == pytest.approx(np.var(ring), rel=1e-9)
    for value in (0.0, 1.0, -3.3, 1e300, 5e-324):
        assert centred_power(np.full(2048, value)) == 0.0
    assert centred_power(np.empty(0)) == 0.0


def test_steady_forces_skips_only_weaker_or_slightly_stronger_forces():
    """The policy alone on two banks' rings: a period is left undecided while each heard
    force's power is at most STEADY_POWER times its power at the last decision (a weaker
    one too), no heard bank ramps, and fewer than STEADY_PERIODS periods in a row."""
    from jassy.anytime_rank import (
        STEADY_PERIODS,
        STEADY_POWER,
        STEP_STATE,
        UNDECIDED,
        Hearing,
        centred_power,
        note_decided,
        steady_forces,
    )

    rng = np.random.default_rng(1)
    rings = rng.normal(size=(2, 2048))
    flags = [np.zeros(2, dtype=bool) for _ in range(8)]
    h = Hearing(np.zeros(2, dtype=np.intp), 2048, *flags, np.zeros(2))
    state, ramp_left = np.zeros(STEP_STATE, dtype=np.int64), np.zeros(2, dtype=np.int64)
    h.heard_before[:] = True
    powers = np.array([centred_power(ring) for ring in rings])  # (the decision's RING_POWER)
    note_decided(h, powers, np.array([True, False]), state)
    power = np.mean((rings[0] - rings[0].mean()) ** 2)
    assert h.decided_power[0] == pytest.approx(power, rel=1e-12) and h.decided_power[1] == 0.0
    assert not steady_forces(h, rings, ramp_left, state)  # bank 1: heard now, not at the decision
    note_decided(h, powers, np.array([True, True]), state)
    for scale, steady in (
        (0.1, True),
        (0.99 * np.sqrt(STEADY_POWER), True),
        (1.01 * np.sqrt(STEADY_POWER), False),
    ):
        state[UNDECIDED] = 0
        assert steady_forces(h, rings * np.array([[scale], [1.0]]), ramp_left, state) == steady, scale
    state[UNDECIDED] = 0
    assert [steady_forces(h, rings, ramp_left, state) for _ in range(STEADY_PERIODS)] == [True] * (
        STEADY_PERIODS - 1
    ) + [False]
    state[UNDECIDED], ramp_left[1] = 0, 5
    assert not steady_forces(h, rings, ramp_left, state)
    h.heard_before[1] = False  # a ramping bank that heard nothing does not count
    assert steady_forces(h, rings, ramp_left, state)


def test_the_force_scan_leaves_a_struck_only_bank_unscanned():
    """jassy.anytime_rank.scan_forces on two banks hearing the same pulse: the one
    ``struck_only`` is neither forced, nor heard, nor woken (its force is found where it
    renders, ugens.modal_kept.render_kept); the other is forced in the stretch with the
    pulse, wakes (no impact expected) and hears it once the next stretch is scanned."""
    from jassy.anytime_rank import Hearing, scan_forces

    force = np.zeros(2048)
    force[700] = 0.5
    flags = [np.zeros(2, dtype=bool) for _ in range(8)]
    h = Hearing(np.array([force.ctypes.data] * 2, dtype=np.intp), force.size, *flags, np.zeros(2))
    h.struck_only[0] = True
    assert scan_forces(h, 0, 512, True) == (False, False)
    assert not h.forced.any()
    assert scan_forces(h, 512, 1024, False) == (False, True)
    assert list(h.forced) == [False, True] and list(h.onset) == [False, True]
    scan_forces(h, 1024, 2048, False)
    assert list(h.heard_now) == [False, True] and list(h.unrendered) == [False, True]
    assert not h.forced.any()  # (bank 1 heard this period already: not scanned again)


def test_a_struck_only_bank_silent_with_modes_kept_sounds_from_its_impacts_first_sample(monkeypatch):
    """A bank driven by an ImpactForce alone, its modes kept for two impacts of one period,
    gone silent after the first (they decay in ms) when a sub-block starts, struck again
    within that sub-block: its force is found by the render itself
    (jassy.anytime_rank.scan_forces leaves it unscanned), so the second impact sounds from
    its first sample, and as it does rendering through its own process."""
    period, block, again = 2048, 512, (1700, 5800, 9900)  # each within a period, a block in
    model = ModalModel(np.linspace(400.0, 4000.0, 12), np.full(12, 3000.0), np.ones((1, 12)))

    def scene(budget):
        hit = ImpactForce(name="hit", duration=0.0003)
        frames = sorted([*again, *(f - 1600 for f in again)])  # the first of each pair
        score = [Event(f / FS, "hit", "impact", {"impulse": 0.3}) for f in frames]
        return Graph(ModalBank(model, name="b")(hit), budget=budget), score

    def budget():
        return ModeBudget(max_modes=6, period=period)

    full = render(*scene(None), 0.25, FS, block, limiter=False).audio[0]
    budgeted = render(*scene(budget()), 0.25, FS, block, limiter=False).audio[0]
    with monkeypatch.context() as patched:
        patched.setattr(ModalBank, "anytime_compiled", lambda self: False)
        own = render(*scene(budget()), 0.25, FS, block, limiter=False).audio[0]
    for start in again:  # silent before, sounding at once, about as loud as the full's
        before, here = slice(start - 200, start), slice(start, start + 48)
        assert (
            not np.any(budgeted[before])
            and np.flatnonzero(budgeted[start:])[0] == np.flatnonzero(full[start:])[0]
        )
        assert np.sum(budgeted[here] ** 2) > 0.1 * np.sum(full[here] ** 2)  # (6 of its 12 modes)
    assert np.max(np.abs(budgeted - own)) <= 1e-10 * np.max(np.abs(own))


def test_a_sub_block_in_one_compiled_call_gives_the_stepwise_renders_bits(monkeypatch):
    """ModeBudget.step renders a sub-block without a queued change in one call of the
    compiled step when the step takes every decision itself; the general loop around
    the same call (split at each queued change, ready to decide in Python) gives the
    same bits, decisions and mode-samples: six bells struck 30 times, their parameters
    ramping, jumping and the contact moving."""
    graph, score = changing_scene(ModeBudget(max_modes=225))
    fast = render(graph, score, 1.0, FS, 4096, limiter=False).audio
    budget = graph.budget
    counts = budget.decisions, budget.peak_modes, budget.mode_samples
    attach = ModeBudget.attach

    def stepwise(self, *args, **options):
        attach(self, *args, **options)
        self._inline = False  # (the compiled step still decides: its INLINE flag is set)

    monkeypatch.setattr(ModeBudget, "attach", stepwise)
    graph, score = changing_scene(ModeBudget(max_modes=225))
    slow = render(graph, score, 1.0, FS, 4096, limiter=False).audio
    budget = graph.budget
    assert counts[0] > 0 and counts == (budget.decisions, budget.peak_modes, budget.mode_samples)
    assert np.max(np.abs(fast)) > 1e-3 and np.array_equal(fast, slow)


class StickyWatch(dict):
    """A watch of banks with a queued change that never lets a bank go."""

    def __delitem__(self, key):
        pass

    def pop(self, key, default=None):
        return self.get(key, default)


def watch_for_good(monkeypatch, every_bank: bool = False) -> None:
    """ModeBudget.attach patched so that the budget's watch never lets a bank go
    (:class:`StickyWatch`); with ``every_bank`` every bank is watched from the start, so
    each is asked for its changes at every sub-block."""
    attach = ModeBudget.attach

    def sticky(self, *args, **options):
        attach(self, *args, **options)
        self._watched = StickyWatch(self._watched)
        for bank in self.banks:
            bank.anytime_watch(self._watched)
            if every_bank:
                self._watched[id(bank)] = bank

    monkeypatch.setattr(ModeBudget, "attach", sticky)


def test_a_bank_leaves_the_watch_with_its_last_queued_change(monkeypatch):
    """Once a bank's last queued change is applied, ModeBudget.step lets it go, so the
    sub-block after the change is one compiled call again instead of a search of the
    watched banks' changes that finds none: six bells struck 30 times, their parameters
    ramping, jumping and the contact moving, give the same bits, decisions and
    mode-samples as a render whose banks stay watched for good (every sub-block after the
    first change through the general path), and no search meets a watch whose banks have
    nothing queued."""
    searched, idle = [0], [0]
    queued = ModeBudget._queued_changes

    def counted(self, start, end):
        searched[0] += 1
        idle[0] += all(not bank.anytime_changes(np.inf) for bank in self._watched.values())
        return queued(self, start, end)

    monkeypatch.setattr(ModeBudget, "_queued_changes", counted)
    graph, score = changing_scene(ModeBudget(max_modes=225))
    letting_go = render(graph, score, 1.0, FS, 4096, limiter=False).audio
    budget = graph.budget
    counts, searches = (budget.decisions, budget.peak_modes, budget.mode_samples), searched[0]
    assert idle[0] == 0 and searches > 0
    watch_for_good(monkeypatch)
    searched[0] = idle[0] = 0
    graph, score = changing_scene(ModeBudget(max_modes=225))
    holding = render(graph, score, 1.0, FS, 4096, limiter=False).audio
    budget = graph.budget
    assert counts[0] > 0 and counts == (budget.decisions, budget.peak_modes, budget.mode_samples)
    assert np.max(np.abs(letting_go)) > 1e-3 and np.array_equal(letting_go, holding)
    assert idle[0] > 0 and searched[0] > searches


def bells_and_a_sine(budget):
    """Three bells of 80 modes struck in turn, each jumping to a new location between
    strikes, and a silent Sine whose frequency is set at the frame of each jump: a set
    the compiled step does not apply ends the engine's sub-block at the jump's frame."""
    from ugens.oscillators import Sine

    hits = [ImpactForce(name=f"h{b}", duration=0.0005) for b in range(3)]
    banks = [
        ModalBank(bell_model(80, prime=100 + 40 * b, seed=b), name=f"b{b}")(h) for b, h in enumerate(hits)
    ]
    score = [Event(0.05 + 0.2 * i, f"h{i % 3}", "impact", {"impulse": 0.3}) for i in range(8)]
    for i in range(8):
        t = 0.1 + 0.2 * i
        score.append(Event(t, f"b{i % 3}", "set", {"location": (i * 7) % 4}, jump=True))
        score.append(Event(t, "osc", "set", {"freq": 300.0 + 10 * i}, jump=True))
        score.append(Event(t + 1e-3, f"h{i % 3}", "impact", {"impulse": 0.2}))
    graph = Graph([Mixer(*banks, name="mix"), Sine(name="osc", amp=0.0)], haptic=hits, budget=budget)
    return graph, sorted(score, key=lambda event: event.time)


def test_a_watched_bank_whose_change_is_at_the_sub_blocks_end_stays_watched(monkeypatch):
    """A bank's location jump shares its frame with a set of another node, so the engine's
    sub-block ends at the jump and the bank's change is queued at (not before) its end:
    ModeBudget._queued_changes keeps the bank watched for the next sub-block, which
    applies the jump at its first frame. The render equals, bit for bit, one that asks
    every bank for its changes at every sub-block (a watch that never lets go)."""
    kept = [0]
    queued = ModeBudget._queued_changes

    def counted(self, start, end):
        kept[0] += sum(
            not bank.anytime_changes(end) and bool(bank.anytime_changes(np.inf))
            for bank in self._watched.values()
        )
        return queued(self, start, end)

    monkeypatch.setattr(ModeBudget, "_queued_changes", counted)
    graph, score = bells_and_a_sine(ModeBudget(max_modes=60))
    watched = render(graph, score, 2.0, FS, 4096, limiter=False).audio
    assert kept[0] >= 8  # (every jump met the branch that keeps its bank)
    watch_for_good(monkeypatch, every_bank=True)
    graph, score = bells_and_a_sine(ModeBudget(max_modes=60))
    everyone = render(graph, score, 2.0, FS, 4096, limiter=False).audio
    assert np.max(np.abs(watched)) > 1e-3 and np.array_equal(watched, everyone)


def short_rings(budget, seconds=2.0):
    """Four bells of 150 modes ringing 30 times shorter than :func:`scene`'s (each falls
    silent within ~0.3 s), each struck three times at random."""
    rng = np.random.default_rng(7)
    banks, hits = [], []
    for b in range(4):
        hit = ImpactForce(name=f"h{b}", duration=0.0005)
        bell = bell_model(150, prime=150 + 60 * b, seed=b)
        banks.append(ModalBank(bell, name=f"b{b}", decay_scale=30.0)(hit))
        hits.append(hit)
    score = [
        Event(float(t), f"h{b}", "impact", {"impulse": 0.3})
        for b in range(4)
        for t in np.sort(rng.uniform(0, seconds - 0.3, 3))
    ]
    return Graph(Mixer(*banks), haptic=hits, budget=budget), sorted(score, key=lambda event: event.time)


def test_a_silent_bank_writes_zeros_only_where_its_output_may_hold_other_samples(monkeypatch):
    """The compiled render writes a silent bank's zeros only past the samples its output
    buffer is known to hold zeros in (ModeBudget's count per bank, ugens.modal_kept.render_kept):
    four bells struck three times each, falling silent between strikes, at a quarter of
    their modes, give the same bits, decisions and mode-samples as the render that
    forgets the count before every step (every silent span written), and whole silent
    sub-blocks are skipped."""
    graph, score = short_rings(ModeBudget(max_modes=150))
    skipping = render(graph, score, 2.0, FS, 4096, limiter=False).audio
    counts = graph.budget.decisions, graph.budget.mode_samples
    step, known = ModeBudget.step, []

    def forgetting(self, start, n):
        known.append(int(self._zeros.max()))
        self._zeros[:] = 0
        step(self, start, n)

    monkeypatch.setattr(ModeBudget, "step", forgetting)
    graph, score = short_rings(ModeBudget(max_modes=150))
    writing = render(graph, score, 2.0, FS, 4096, limiter=False).audio
    assert counts[0] > 0 and counts == (graph.budget.decisions, graph.budget.mode_samples)
    assert np.max(np.abs(skipping)) > 1e-3 and np.array_equal(skipping, writing)
    assert max(known) == 4096  # some bank was silent through a whole sub-block (the next is skipped)


def test_a_location_jump_in_the_short_path_changes_what_the_general_path_changes(monkeypatch):
    """A budgeted bank applies a queued jump of its location alone without re-checking the
    value and dispatching through ``set_param`` (ModalBank._jump_location): six bells at a
    quarter of their modes with 40 location jumps, some of them sharing a frame with a
    gain jump (the general path, keys together) or ramping (not in place), give the same
    bits, decisions, locations and designs as every change through the general path."""
    rng = np.random.default_rng(5)
    times, banks, spots = rng.uniform(0, 1.0, 40), rng.integers(0, 6, 40), rng.integers(0, 4, 40)
    changes = []
    for i, (t, b, loc) in enumerate(zip(times, banks, spots, strict=True)):
        if i % 10 == 3:  # a location that ramps: not a jump in place
            changes.append(Event(float(t), f"b{b}", "set", {"location": int(loc)}, ramp=0.01))
        elif i % 10 == 7:  # a location and a gain at one frame: applied together
            changes.append(Event(float(t), f"b{b}", "set", {"location": int(loc), "gain": 0.8}, jump=True))
        else:
            changes.append(Event(float(t), f"b{b}", "set", {"location": int(loc)}, jump=True))
    short = ModalBank._jump_location
    taken = []

    def counted(self, pending):
        taken.append(short(self, pending))
        return taken[-1]

    def run():
        graph, score = scene(ModeBudget(max_modes=225), seconds=1.0)
        score = sorted(score + changes, key=lambda event: event.time)
        audio = render(graph, score, 1.0, FS, 4096, limiter=False).audio
        banks = [node for node in graph.order if node.supports_budget]
        return audio, graph.budget.decisions, [(b.values["location"], b._fresh.copy()) for b in banks]

    monkeypatch.setattr(ModalBank, "_jump_location", counted)
    fast, decisions, states = run()
    assert 20 <= sum(taken) < len(taken)  # most jumps took the short path, not all
    monkeypatch.setattr(ModalBank, "_jump_location", lambda self, pending: False)
    general, general_decisions, general_states = run()
    assert np.max(np.abs(fast)) > 1e-3 and np.array_equal(fast, general) and decisions == general_decisions
    for (location, design), (other, other_design) in zip(states, general_states, strict=True):
        assert location == other and np.array_equal(design, other_design)


def struck_bell(budget, through_gain: bool):
    """A bell of 150 modes struck four times by an ImpactForce, directly or through a Gain
    (whose output the budget cannot tell from a continuous force)."""
    from ugens.mix import Gain

    hit = ImpactForce(name="hit", duration=0.001)
    force = Gain(hit, name="via", gain=1.0) if through_gain else hit
    score = [Event(t, "hit", "impact", {"impulse": 0.3}) for t in (0.05, 0.4, 0.75, 1.1)]
    return Graph(ModalBank(bell_model(150), name="bell")(force), budget=budget), score


def test_a_bank_struck_only_by_the_scores_impacts_never_hears_them_as_a_force():
    """An ImpactForce's output is the score's impacts, which the budget ranks from the
    score: the bank it drives is ``struck_only`` (no periodogram of its pulses, no
    decision for having heard them), the same pulses through a Gain are judged as a
    heard force; both render within -15 dB of the full synthesis."""
    from ugens import modal_budget as mb

    decisions, errors = {}, {}
    for through_gain in (False, True):
        graph, score = struck_bell(None, through_gain)
        full = render(graph, score, 1.5, FS, 4096, limiter=False).audio[0]
        budget = ModeBudget(max_modes=40)
        graph, score = struck_bell(budget, through_gain)
        y = render(graph, score, 1.5, FS, 4096, limiter=False).audio[0]
        assert list(budget.hearing.struck_only) == [not through_gain]
        assert budget._tables.values[mb.REMEMBERED, 0] == float(through_gain)  # a periodogram taken
        decisions[through_gain], errors[through_gain] = budget.decisions, error_db(y, full)
    assert decisions[False] < decisions[True], decisions
    assert max(errors.values()) <= -15.0, errors


@pytest.mark.parametrize("fed_bank", [False, True])
def test_an_impact_inserted_live_into_a_started_period_sounds_on_a_struck_only_bank(fed_bank):
    """Scheduler.insert (the live engine's path) strikes a bank that nothing else strikes in
    the middle of a budget period: no period's start listed it, so the bank must be woken
    by what it hears; its budgeted output then carries the full synthesis's energy. Also
    where a third bank hears the first (``fed_bank``: the banks then render themselves
    after the budget's step, and only the fed bank's force is unseen when it decides)."""
    block, insert_at = 512, 4608  # period 2048: inserted mid-period

    def run(budget):
        ha, hb = ImpactForce(name="ha", duration=0.0005), ImpactForce(name="hb", duration=0.0005)
        a = ModalBank(bell_model(150, prime=150, seed=0), name="a")(ha)
        b = ModalBank(bell_model(150, prime=210, seed=1), name="b")(hb)
        score = [Event(t, "ha", "impact", {"impulse": 0.3}) for t in np.arange(0.0, 1.0, 0.05)]
        heard = [a, b, ModalBank(bell_model(20, prime=20, seed=2), name="c")(a)] if fed_bank else [a, b]
        graph = Graph(Mixer(*heard), budget=budget)
        engine = OfflineEngine(graph, score, FS, block, limiter=False, program=False)
        assert graph.budget_renders is (budget is not None and not fed_bank)
        buffer, bank_b = np.zeros((1, block)), []
        for frame in range(0, FS, block):
            if frame == insert_at:
                engine.scheduler.insert(Event(frame / FS, "hb", "impact", {"impulse": 0.5}))
            engine.produce(buffer, block)
            bank_b.append(b.out[:block].copy())
        return np.concatenate(bank_b)

    full, budgeted = run(None), run(ModeBudget(max_modes=60))
    assert np.sum(full[insert_at:] ** 2) > 1.0
    assert error_db(budgeted[insert_at:], full[insert_at:]) <= -10.0


def test_a_bank_with_no_mode_kept_outputs_zeros_and_hears_its_whole_force():
    """A bank driven by a quiet white noise beside a loud struck bank, at a budget of 8 of
    their 160 modes: whenever it keeps no mode (and does not ramp) its output over the
    sub-block is zero and its ring of the period's force holds the period of its input
    that ends the sub-block (frame t at t % period), as the compiled render leaves them
    (ugens.modal_kept.none_kept, without a pass per flush period)."""
    from ugens.modal_meta import ALLOWED, RAMP_LEFT
    from ugens.noise import WhiteNoise

    period = 512
    quiet = ModalBank(
        ModalModel(np.linspace(300.0, 2700.0, 10), np.full(10, 2.0), np.ones((1, 10))), name="q"
    )
    loud = ModalBank(bell_model(150), name="loud")(ImpactForce(name="hl"))
    mix = Mixer(quiet(WhiteNoise(amp=1e-4, name="noise")), loud)
    score = [Event(t, "hl", "impact", {"impulse": 1.0}) for t in (0.0, 0.2, 0.4)]
    budget = ModeBudget(max_modes=8, period=period)
    step, checked = budget.step, []

    def watched(start, n):
        step(start, n)
        t, b = budget._tables, budget._slots[id(quiet)]
        if t.meta[b, ALLOWED] == 0 and t.meta[b, RAMP_LEFT] == 0 and n >= period:
            heard = quiet.sources["input"].out[n - period : n]
            assert not np.any(quiet.out[:n])
            assert np.array_equal(t.rings[b][np.arange(start + n - period, start + n) % period], heard)
            checked.append(start)

    budget.step = watched
    render(Graph(mix, budget=budget), score, 0.6, FS, 4096, limiter=False)
    assert len(checked) >= 2


def switching_scene(seed, period, fraction):
    """Five small banks (1-6 modes), the even ones driven by noise switched between off,
    faint and loud, the odd ones struck three times: banks go silent, keep no mode, keep
    some and lose them again, and forces rise and fall between decisions."""
    from ugens.noise import WhiteNoise

    rng = np.random.default_rng(seed)
    banks, score, total = [], [], 0
    for i in range(5):
        k = int(rng.choice([1, 2, 3, 4, 6]))
        total += k
        model = ModalModel(
            np.sort(rng.uniform(20, 2000, k)), rng.uniform(0.0, 5.0, k), rng.uniform(0.1, 1, (2, k))
        )
        if i % 2 == 0:
            source = WhiteNoise(amp=0.0, name=f"n{i}")
            for t in np.sort(rng.uniform(0, 1.5, 6)):
                amp = float(rng.choice([0.0, 1e-4, 1e-2]))
                score.append(Event(float(t), f"n{i}", "set", {"amp": amp}, jump=True))
        else:
            source = ImpactForce(name=f"h{i}")
            for t in rng.uniform(0, 1.5, 3):
                score.append(Event(float(t), f"h{i}", "impact", {"impulse": float(rng.uniform(0.01, 1.0))}))
        banks.append(ModalBank(model, name=f"b{i}")(source))
    budget = ModeBudget(max_modes=max(1, int(fraction * total)), period=period)
    return Graph(Mixer(*banks), budget=budget), sorted(score, key=lambda e: e.time)


@pytest.mark.parametrize("seed", range(4))
def test_banks_hearing_forces_that_rise_and_fall_render_as_through_their_own_process(seed, monkeypatch):
    """The compiled render of all banks against each bank rendering itself through its own
    process (as banks with a size input do), on banks whose noise forces switch on and off:
    the same decisions, so the same output within rounding. (A bank rendered after the
    step once left its ring of the period's force behind the step's check for a steadily
    heard force, which then skipped decisions the compiled render took: up to 1e-5 of the
    peak apart.)"""
    for period, block, fraction in ((512, 4096, 0.2), (512, 100, 0.3), (2048, 777, 0.15), (1024, 8192, 0.4)):
        compiled = render(*switching_scene(seed, period, fraction), 1.5, FS, block, limiter=False).audio[0]
        with monkeypatch.context() as patched:
            patched.setattr(ModalBank, "anytime_compiled", lambda self: False)
            own = render(*switching_scene(seed, period, fraction), 1.5, FS, block, limiter=False).audio[0]
        peak = np.max(np.abs(own))
        assert peak > 0.0
        assert np.max(np.abs(compiled - own)) <= 1e-10 * peak, (period, block)

"""Study designs: the TOML file, conditions and factors, blocks, counterbalancing,
practice, and the seeded trial schedule.

A design file (see ``examples/*study*.toml``)::

    [study]
    name = "toj-force"
    stimulus = "wall_tap"         # patch name or .toml path (relative to the design file)
    task = "toj"                  # toj (which came first: a/h), sj (simultaneous: s/n),
                                  # 2afc / 3afc (which interval was asynchronous: 1/2/3)
    function = "gaussian"         # model: toj gaussian|logistic, sj gaussian|difference
    trial_duration = 0.5          # s rendered and presented per stimulus
    interval_gap = 0.4            # s between the intervals of a 2AFC/3AFC trial
    sample_rate = 48000
    block = 64                    # frames per engine block
    seed = 2001                   # randomisation seed (mixed with participant and session)
    instructions = "..."          # shown once at the start
    breaks_every = 40             # trials between breaks inside a block (0 = none)
    pause = 0.6                   # s between a response and the next stimulus (live only)
    onset_threshold = 1e-6        # onset = first sample above this fraction of the peak
    conditions = "conds.csv"      # optional conditions file (CSV, or TOML [[condition]])

    [factors]                     # optional, crossed with each other and the file's rows
    force_level = [0.5, 2.0]      # scales every impact impulse of the stimulus score
    leading = ["audio", "haptic"] # offsets become magnitudes; this sets the sign

    [materials.wood]              # a condition's `material` names one of these
    set = ["out.gain=120.0"]      # patch overrides node.param=value
    stimulus = "other.toml"       # optional other patch

    [blocks]
    by = "force_level"            # each level of this factor is a block ("" = one block)
    order = "latin_square"        # fixed | random | latin_square (by participant number)
    repeat = 1                    # the block sequence this many times
    instructions = { "0.5" = "Light taps.", "2.0" = "Hard taps." }  # by block level

    [practice]                    # optional, first, with feedback, not analysed
    trials = 6
    offsets_ms = [-150.0, 150.0]
    feedback = true
    instructions = "A few practice taps first."

    [method]
    kind = "constant"             # constant | staircase | quest | quest_plus
    offsets_ms = [-80.0, -40.0, 0.0, 40.0, 80.0]   # negative = audio first
    repetitions = 10              # per offset and condition

    # staircase: rule (1down1up|2down1up|3down1up), tracks (audio_first, haptic_first),
    #   start_ms, steps_ms, min_ms, max_ms, reversals, max_trials
    # quest: guess_ms, prior_sd_ms, sigma_ms (TOJ) or slope (m-AFC), lapse, max_trials,
    #   stop_sd_ms, min_trials (TOJ: two tracks at 25 % and 75 %)
    # quest_plus: offsets_ms (the stimulus domain), max_trials, stop_param, stop_sd,
    #   min_trials, choose_from

    [observer]                    # the simulated observer (--responses simulated)
    pss_ms = 0.0
    sigma_ms = 20.0
    window_ms = 150.0             # sj difference model
    threshold_ms = 30.0           # 2afc / 3afc
    slope = 2.0
    lapse = 0.02
    [[observer.when]]             # parameter changes in matching conditions
    force_level = 2.0
    pss_ms = -10.0

Condition columns with a meaning: ``stimulus``, ``force_level``, ``material``,
``leading``; columns named ``node.param`` are patch overrides; any other column is a
label. Every error names the file and key (``DesignError``: one line, exit code 2).
"""

from __future__ import annotations

import csv
import hashlib
import itertools
import json
import math
import re
import zlib
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any, NamedTuple

import numpy as np

from jassy.errors import JassyError, suggest
from jassy.study.methods import ConstantTrack, QuestPlusTrack, QuestTrack, Staircase, quest_plus_grid
from jassy.study.models import FUNCTIONS, TASKS, Model, make_model


class DesignError(JassyError):
    """A study design file is invalid; the message names the file and key."""


ANSWERS = {
    "toj": ("audio", "haptic"),
    "sj": ("simultaneous", "successive"),
    "2afc": ("1", "2"),
    "3afc": ("1", "2", "3"),
}
QUESTION_ALIASES = {"which_first": "toj", "simultaneous": "sj"}
RULES = {"1down1up": 1, "2down1up": 2, "3down1up": 3}
TRACKS = {"audio_first": -1.0, "haptic_first": 1.0}
LEADING = {"audio": -1.0, "haptic": 1.0}
PARTICIPANT = re.compile(r"^[A-Za-z0-9][A-Za-z0-9_-]{0,63}$")

STUDY_KEYS = {
    "name",
    "description",
    "stimulus",
    "task",
    "question",
    "function",
    "trial_duration",
    "interval_gap",
    "sample_rate",
    "block",
    "seed",
    "instructions",
    "breaks_every",
    "pause",
    "onset_threshold",
    "conditions",
}
METHOD_KEYS = {
    "constant": {"kind", "offsets_ms", "repetitions"},
    "staircase": {
        "kind",
        "rule",
        "tracks",
        "start_ms",
        "steps_ms",
        "min_ms",
        "max_ms",
        "reversals",
        "max_trials",
    },
    "quest": {
        "kind",
        "guess_ms",
        "prior_sd_ms",
        "sigma_ms",
        "slope",
        "lapse",
        "max_trials",
        "stop_sd_ms",
        "min_trials",
    },
    "quest_plus": {"kind", "offsets_ms", "max_trials", "stop_param", "stop_sd", "min_trials", "choose_from"},
}
OBSERVER_KEYS = {"pss_ms", "sigma_ms", "window_ms", "threshold_ms", "slope", "lapse", "function", "when"}
BLOCK_KEYS = {"by", "order", "repeat", "instructions"}
PRACTICE_KEYS = {"trials", "offsets_ms", "feedback", "instructions"}


def check_participant(participant: str, where: str = "participant") -> str:
    """A participant id safe in file names: letters, digits, '-' and '_' (no path parts)."""
    if not isinstance(participant, str) or not PARTICIPANT.match(participant):
        raise JassyError(
            f"{where}: expected 1-64 letters, digits, '-' or '_' "
            f"(no path separators or '..'), got {participant!r}"
        )
    return participant


@dataclass
class ObserverSpec:
    """A simulated observer: model parameters (ms) and lapse rate, and per-condition changes."""

    pss_ms: float = 0.0
    sigma_ms: float = 20.0
    window_ms: float = 150.0
    threshold_ms: float = 30.0
    slope: float = 2.0
    lapse: float = 0.02
    function: str = ""
    when: list[dict[str, Any]] = field(default_factory=list)

    def theta(self, model: Model, condition: dict[str, Any] | None = None) -> dict[str, float]:
        """The model parameters in ``condition`` (the matching ``when`` entries applied)."""
        values = {
            k: getattr(self, k) for k in ("pss_ms", "sigma_ms", "window_ms", "threshold_ms", "slope", "lapse")
        }
        for rule in self.when:
            if all(condition and _same(condition.get(k), v) for k, v in rule.items() if k not in values):
                values.update({k: v for k, v in rule.items() if k in values})
        names = {"pss": "pss_ms", "sigma": "sigma_ms", "window": "window_ms", "threshold": "threshold_ms"}
        return {p.name: float(values[names.get(p.name, p.name)]) for p in model.params}


def _same(a: Any, b: Any) -> bool:
    if isinstance(a, (int, float)) and isinstance(b, (int, float)):
        return float(a) == float(b)
    return str(a) == str(b)


class Condition(NamedTuple):
    """One cell of the design: its factor values and what they mean for the stimulus."""

    index: int
    factors: dict[str, Any]
    stimulus: str
    overrides: tuple[str, ...]
    force_level: float
    sign: float | None  # leading modality: -1 audio first, +1 haptic first, None = offsets signed

    @property
    def label(self) -> str:
        return " ".join(f"{k}={v}" for k, v in self.factors.items()) or "all"


class TrialSpec(NamedTuple):
    """One trial: index, offset (ms), track, condition, block, practice, m-AFC interval."""

    index: int
    offset_ms: float
    track: str
    condition: int
    block: int
    block_name: str
    practice: bool
    interval: int  # 1-based interval holding the asynchrony (m-AFC), 0 otherwise


class Block(NamedTuple):
    name: str
    conditions: tuple[int, ...]
    instructions: str
    practice: bool


@dataclass
class Design:
    """A validated study design."""

    name: str
    stimulus: str
    task: str = "toj"
    function: str = "gaussian"
    trial_duration: float = 0.5
    interval_gap: float = 0.4
    sample_rate: int = 48000
    block: int = 64
    seed: int = 0
    instructions: str = ""
    breaks_every: int = 0
    pause: float = 0.6
    onset_threshold: float = 1e-6
    method: dict[str, Any] = field(
        default_factory=lambda: {"kind": "constant", "offsets_ms": [0.0], "repetitions": 1}
    )
    observer: ObserverSpec = field(default_factory=ObserverSpec)
    conditions: list[Condition] = field(default_factory=list)
    blocks: dict[str, Any] = field(default_factory=dict)
    practice: dict[str, Any] = field(default_factory=dict)
    description: str = ""
    source: str = ""
    raw: dict[str, Any] = field(default_factory=dict)

    @property
    def model(self) -> Model:
        return make_model(self.task, self.function)

    @property
    def answers(self) -> tuple[str, ...]:
        return ANSWERS[self.task]

    @property
    def factor_names(self) -> list[str]:
        names: list[str] = []
        for c in self.conditions:
            names += [k for k in c.factors if k not in names]
        return names

    def sha256(self) -> str:
        """Digest of the design's content (not its path): a results file belongs to one design."""
        return hashlib.sha256(json.dumps(self.raw, sort_keys=True, default=str).encode()).hexdigest()

    def participant_seed(self, participant: str, session: str = "1") -> np.random.SeedSequence:
        """The randomisation seed of one session: the design seed mixed with the ids."""
        return np.random.SeedSequence(
            [int(self.seed), zlib.crc32(participant.encode()), zlib.crc32(session.encode())]
        )

    def positive(self, trial: TrialSpec, answer: str) -> bool:
        """Whether ``answer`` is the model's positive answer (haptic first / simultaneous /
        the right interval)."""
        if self.task == "toj":
            return answer == "haptic"
        if self.task == "sj":
            return answer == "simultaneous"
        return answer == str(trial.interval)

    def correct(self, trial: TrialSpec, offset_ms: float, answer: str) -> bool | None:
        """Whether ``answer`` is right for the presented offset (None: no right answer)."""
        if self.task in ("2afc", "3afc"):
            return answer == str(trial.interval)
        if offset_ms == 0:
            return (answer == "simultaneous") if self.task == "sj" else None
        if self.task == "toj":
            return answer == ("audio" if offset_ms < 0 else "haptic")
        return answer == "successive"

    # ------------------------------------------------------------------ blocks
    def block_order(
        self, participant_number: int | None, rng: np.random.Generator | None = None
    ) -> list[Block]:
        """Practice (if any), then the blocks in the order for this participant."""
        by = self.blocks.get("by", "")
        if by:
            levels: list[Any] = []
            for c in self.conditions:
                if not any(_same(c.factors[by], v) for v in levels):
                    levels.append(c.factors[by])
            groups = [
                (str(v), tuple(c.index for c in self.conditions if _same(c.factors[by], v))) for v in levels
            ]
        else:
            groups = [("all", tuple(c.index for c in self.conditions))]
        order = self.blocks.get("order", "fixed")
        k = len(groups)
        if order == "latin_square" and k > 1:
            if participant_number is None:
                raise JassyError(
                    f"{self.source}: blocks.order = 'latin_square' needs a participant number "
                    "(--participant-number, or digits at the end of the participant id)"
                )
            rows = balanced_latin_square(k)
            sequence = rows[(participant_number - 1) % len(rows)]
        elif order == "random" and rng is not None:
            sequence = [int(i) for i in rng.permutation(k)]
        else:
            sequence = list(range(k))
        texts = self.blocks.get("instructions", {})
        out = []
        if self.practice.get("trials"):
            out.append(Block("practice", (0,), self.practice.get("instructions", ""), True))
        for _ in range(self.blocks.get("repeat", 1)):
            out += [Block(groups[i][0], groups[i][1], texts.get(groups[i][0], ""), False) for i in sequence]
        return out

    def schedule(
        self, participant: str, session: str = "1", participant_number: int | None = None
    ) -> Schedule:
        """The seeded trial schedule of one session (random order is redrawn per block)."""
        rng = np.random.default_rng(self.participant_seed(participant, session))
        return Schedule(self, self.block_order(participant_number, rng), rng)

    def tracks(self, condition: Condition, rng: np.random.Generator) -> list:
        """The method's tracks for one condition (see jassy.study.methods)."""
        m, model = self.method, self.model
        prefix = f"c{condition.index}"
        kind = m["kind"]

        def signed(values):
            return [abs(v) * condition.sign for v in values] if condition.sign is not None else list(values)

        if kind == "constant":
            return [ConstantTrack(prefix, signed(m["offsets_ms"]), m["repetitions"], rng)]
        if kind == "staircase":
            names = (
                ["audio_first" if condition.sign < 0 else "haptic_first"]
                if condition.sign is not None
                else m["tracks"]
            )
            return [
                Staircase(
                    f"{prefix}:{t}",
                    TRACKS[t],
                    m["rule"],
                    m["start_ms"],
                    m["steps_ms"],
                    m["min_ms"],
                    m["max_ms"],
                    m["reversals"],
                    m["max_trials"],
                )
                for t in names
            ]
        if kind == "quest":
            common = dict(
                prior_sd_ms=m["prior_sd_ms"],
                sigma_ms=m["sigma_ms"],
                slope=m["slope"],
                lapse=m["lapse"],
                max_trials=m["max_trials"],
                stop_sd_ms=m["stop_sd_ms"],
                min_trials=m["min_trials"],
            )
            if self.task == "toj":
                return [
                    QuestTrack(
                        f"{prefix}:q{int(t * 100)}", model, t, m["guess_ms"] + z * m["sigma_ms"], **common
                    )
                    for t, z in ((0.25, -0.6745), (0.75, 0.6745))
                ]
            target = 1.0 / model.alternatives + 0.5 * (1 - 1.0 / model.alternatives) * (1 - m["lapse"])
            return [
                QuestTrack(f"{prefix}:q", model, target, m["guess_ms"], sign=condition.sign or 1.0, **common)
            ]
        offsets = np.asarray(signed(m["offsets_ms"]))
        return [
            QuestPlusTrack(
                prefix,
                model,
                offsets,
                quest_plus_grid(model, offsets),
                m["max_trials"],
                rng,
                m["stop_param"],
                m["stop_sd"],
                m["min_trials"],
                m["choose_from"],
            )
        ]


def balanced_latin_square(k: int) -> list[list[int]]:
    """Williams' balanced Latin square: every block precedes every other equally often
    (Williams 1949, Aust. J. Sci. Res. A 2: 149). k rows for even k, 2k for odd k."""
    first, lo, hi = [0], 1, k - 1
    for j in range(1, k):
        if j % 2:
            first.append(lo)
            lo += 1
        else:
            first.append(hi)
            hi -= 1
    rows = [[(v + r) % k for v in first] for r in range(k)]
    return rows + [row[::-1] for row in rows] if k % 2 else rows


class Schedule:
    """Yields trials block by block; inside a block each trial comes from one of the
    block's live tracks, drawn with probability proportional to its remaining trials
    (constant stimuli: a uniform random order) or uniformly (adaptive tracks)."""

    def __init__(self, design: Design, blocks: list[Block], rng: np.random.Generator):
        self.design, self.blocks, self.rng = design, blocks, rng
        self.block_index = -1
        self.count = 0
        self.live: list[tuple[int, Any]] = []
        self.all_tracks: dict[str, Any] = {}
        self.planned_total = self._planned()

    def _planned(self) -> int | None:
        d = self.design
        if d.method["kind"] != "constant":
            return None
        per = len(d.method["offsets_ms"]) * d.method["repetitions"]
        return sum(
            d.practice.get("trials", 0) if b.practice else per * len(b.conditions) for b in self.blocks
        )

    @property
    def planned(self) -> int | None:
        return self.planned_total

    def _enter(self, index: int) -> None:
        self.block_index = index
        block = self.blocks[index]
        d = self.design
        if block.practice:
            offsets = d.practice.get("offsets_ms") or d.method.get("offsets_ms") or [0.0]
            reps = math.ceil(d.practice["trials"] / len(offsets))
            track = ConstantTrack("practice", offsets, reps, self.rng)
            track.offsets = track.offsets[: d.practice["trials"]]
            self.live = [(d.conditions[0].index, track)]
        else:
            self.live = []
            for c in block.conditions:
                for t in d.tracks(d.conditions[c], self.rng):
                    name = f"b{index}:{t.name}"
                    t.name = name
                    self.all_tracks[name] = t
                    self.live.append((c, t))

    def next(self) -> TrialSpec | None:
        if self.block_index < 0:
            self._enter(0)
        while True:
            live = [(c, t) for c, t in self.live if t.next_offset() is not None]
            if live:
                break
            if self.block_index + 1 >= len(self.blocks):
                return None
            self._enter(self.block_index + 1)
        weights = np.array([t.remaining if t.remaining is not None else 1 for _, t in live], dtype=float)
        c, track = live[int(self.rng.choice(len(live), p=weights / weights.sum()))]
        m = self.design.model.alternatives
        interval = int(self.rng.integers(1, m + 1)) if self.design.task in ("2afc", "3afc") else 0
        block = self.blocks[self.block_index]
        spec = TrialSpec(
            self.count,
            track.next_offset(),
            track.name,
            c,
            self.block_index,
            block.name,
            block.practice,
            interval,
        )
        self.count += 1
        return spec

    def update(self, trial: TrialSpec, positive: bool, correct: bool | None) -> None:
        for _, t in self.live:
            if t.name == trial.track:
                t.update(trial.offset_ms, positive, correct)
                return

    def summary(self) -> dict[str, Any]:
        return {name: t.summary() for name, t in self.all_tracks.items()}


# --------------------------------------------------------------------------- loading
def _number(value: Any, key: str, where: str, low: float, high: float, integer: bool = False) -> Any:
    ok = isinstance(value, int) if integer else isinstance(value, (int, float))
    if isinstance(value, bool) or not ok or not math.isfinite(value) or not (low <= value <= high):
        kind = "an integer" if integer else "a number"
        raise DesignError(f"{where}: {key}: expected {kind} in [{low:g}, {high:g}], got {value!r}")
    return int(value) if integer else float(value)


def _unknown(table: dict, allowed: set[str], where: str) -> None:
    for key in table:
        if key not in allowed:
            raise DesignError(
                f"{where}: unknown key {key!r}; expected one of {', '.join(sorted(allowed))}"
                f"{suggest(key, allowed)}"
            )


def _table(data: dict, key: str, where: str) -> dict:
    value = data.get(key, {})
    if not isinstance(value, dict):
        raise DesignError(f"{where}: {key}: expected a table")
    return value


def _stimulus_path(spec: str, base: Path | None) -> str:
    """A patch path relative to the design file, or a built-in patch name."""
    path = Path(spec)
    if base is not None and (path.suffix == ".toml" or "/" in spec) and not path.is_absolute():
        return str((base / path).resolve())
    return spec


def _named(value: Any, choices) -> bool:
    """Whether ``value`` is one of the names ``choices`` (a TOML value of any type: a list
    or table is no name, and cannot be looked up in a dict)."""
    return isinstance(value, str) and value in choices


def _string(table: dict, key: str, where: str, default: str = "") -> str:
    value = table.get(key, default)
    if not isinstance(value, str):
        raise DesignError(f"{where}: {key}: expected a string, got {value!r}")
    return value


def parse_design(data: dict[str, Any], where: str = "design", base: Path | None = None) -> Design:
    """Validate a design mapping (the parsed TOML)."""
    _unknown(data, {"study", "method", "observer", "factors", "materials", "blocks", "practice"}, where)
    study = data.get("study")
    if not isinstance(study, dict):
        raise DesignError(f"{where}: missing [study] table")
    w = f"{where}: study"
    _unknown(study, STUDY_KEYS, w)
    if not isinstance(study.get("stimulus"), str) or not study["stimulus"]:
        raise DesignError(f"{w}: stimulus: expected a patch name or .toml path")
    question = study.get("question", "which_first")
    task = study.get("task", QUESTION_ALIASES[question] if _named(question, QUESTION_ALIASES) else question)
    if not _named(task, TASKS):
        raise DesignError(
            f"{w}: task: expected one of {', '.join(TASKS)}, got {task!r}{suggest(task, TASKS)}"
        )
    function = _string(study, "function", w, FUNCTIONS[task][0])
    if function not in FUNCTIONS[task]:
        raise DesignError(
            f"{w}: function: expected one of {', '.join(FUNCTIONS[task])} for {task}, got {function!r}"
            f"{suggest(function, FUNCTIONS[task])}"
        )
    design = Design(
        name=_string(study, "name", w, Path(where).stem),
        stimulus=_stimulus_path(study["stimulus"], base),
        task=task,
        function=function,
        trial_duration=_number(study.get("trial_duration", 0.5), "trial_duration", w, 0.01, 60.0),
        interval_gap=_number(study.get("interval_gap", 0.4), "interval_gap", w, 0.0, 60.0),
        sample_rate=_number(study.get("sample_rate", 48000), "sample_rate", w, 1000, 768000, integer=True),
        block=_number(study.get("block", 64), "block", w, 1, 65536, integer=True),
        seed=_number(study.get("seed", 0), "seed", w, 0, 2**63 - 1, integer=True),
        instructions=_string(study, "instructions", w),
        breaks_every=_number(study.get("breaks_every", 0), "breaks_every", w, 0, 100000, integer=True),
        pause=_number(study.get("pause", 0.6), "pause", w, 0.0, 60.0),
        onset_threshold=_number(study.get("onset_threshold", 1e-6), "onset_threshold", w, 1e-12, 0.5),
        description=_string(study, "description", w),
        source=where,
        raw=data,
    )
    design.method = _parse_method(data.get("method"), f"{where}: method", task)
    design.conditions = _parse_conditions(data, study, where, base, design.stimulus)
    if design.method["kind"] == "quest" and task == "sj":
        raise DesignError(
            f"{where}: method: kind: 'quest' needs a monotonic task (toj, 2afc, 3afc); "
            "use 'quest_plus' for sj"
        )
    design.blocks = _parse_blocks(_table(data, "blocks", where), f"{where}: blocks", design.conditions)
    design.practice = _parse_practice(_table(data, "practice", where), f"{where}: practice")
    design.observer = parse_observer(
        _table(data, "observer", where), f"{where}: observer", design.factor_names
    )
    return design


def _offsets(value: Any, key: str, where: str) -> list[float]:
    if not isinstance(value, list) or not value:
        raise DesignError(f"{where}: {key}: expected a non-empty list of numbers (ms)")
    return [_number(v, key, where, -10000.0, 10000.0) for v in value]


def _parse_method(method: Any, where: str, task: str) -> dict[str, Any]:
    if not isinstance(method, dict):
        raise DesignError(
            f"{where}: missing [method] table (kind = 'constant', 'staircase', 'quest' or 'quest_plus')"
        )
    kind = method.get("kind", "constant")
    if not _named(kind, METHOD_KEYS):
        raise DesignError(
            f"{where}: kind: expected one of {', '.join(METHOD_KEYS)}, got {kind!r}"
            f"{suggest(kind, METHOD_KEYS)}"
        )
    _unknown(method, METHOD_KEYS[kind], where)
    out: dict[str, Any] = {"kind": kind}
    if kind in ("constant", "quest_plus"):
        if "offsets_ms" not in method:
            raise DesignError(f"{where}: offsets_ms: missing (list of audio-haptic offsets in ms)")
        out["offsets_ms"] = _offsets(method["offsets_ms"], "offsets_ms", where)
    if kind == "constant":
        out["repetitions"] = _number(
            method.get("repetitions", 10), "repetitions", where, 1, 100000, integer=True
        )
    elif kind == "staircase":
        rule = method.get("rule", "2down1up")
        if not _named(rule, RULES):
            raise DesignError(
                f"{where}: rule: expected one of {', '.join(RULES)}, got {rule!r}{suggest(rule, RULES)}"
            )
        tracks = method.get("tracks", ["audio_first", "haptic_first"])
        if not isinstance(tracks, list) or not tracks or any(not _named(t, TRACKS) for t in tracks):
            raise DesignError(f"{where}: tracks: expected a list of {', '.join(TRACKS)}, got {tracks!r}")
        if len(set(tracks)) != len(tracks):
            raise DesignError(f"{where}: tracks: each track at most once")
        steps = method.get("steps_ms", [4.0])
        if not isinstance(steps, list) or not steps:
            raise DesignError(f"{where}: steps_ms: expected a non-empty list of step sizes (ms)")
        out.update(
            rule=rule,
            tracks=tracks,
            steps_ms=[_number(s, "steps_ms", where, 1e-6, 10000.0) for s in steps],
            min_ms=_number(method.get("min_ms", 0.0), "min_ms", where, 0.0, 10000.0),
            max_ms=_number(method.get("max_ms", 200.0), "max_ms", where, 1e-6, 10000.0),
            reversals=_number(method.get("reversals", 10), "reversals", where, 1, 10000, integer=True),
            max_trials=_number(method.get("max_trials", 60), "max_trials", where, 1, 100000, integer=True),
        )
        out["start_ms"] = _number(
            method.get("start_ms", 40.0), "start_ms", where, out["min_ms"], out["max_ms"]
        )
    elif kind == "quest":
        out.update(
            guess_ms=_number(
                method.get("guess_ms", 0.0 if task == "toj" else 40.0), "guess_ms", where, -10000.0, 10000.0
            ),
            prior_sd_ms=_number(method.get("prior_sd_ms", 60.0), "prior_sd_ms", where, 1e-3, 10000.0),
            sigma_ms=_number(method.get("sigma_ms", 30.0), "sigma_ms", where, 1e-3, 10000.0),
            slope=_number(method.get("slope", 2.0), "slope", where, 0.1, 50.0),
            lapse=_number(method.get("lapse", 0.02), "lapse", where, 0.0, 0.1),
            max_trials=_number(method.get("max_trials", 40), "max_trials", where, 1, 100000, integer=True),
            stop_sd_ms=_number(method.get("stop_sd_ms", 0.0), "stop_sd_ms", where, 0.0, 10000.0),
            min_trials=_number(method.get("min_trials", 0), "min_trials", where, 0, 100000, integer=True),
        )
        if task in ("2afc", "3afc") and out["guess_ms"] <= 0:
            raise DesignError(f"{where}: guess_ms: expected a positive threshold guess (ms) for {task}")
    else:
        names = make_model(task).names
        stop = _string(method, "stop_param", where)
        if stop and stop not in names:
            raise DesignError(
                f"{where}: stop_param: expected one of {', '.join(names)}, got {stop!r}{suggest(stop, names)}"
            )
        out.update(
            max_trials=_number(method.get("max_trials", 100), "max_trials", where, 1, 100000, integer=True),
            stop_param=stop,
            stop_sd=_number(method.get("stop_sd", 0.0), "stop_sd", where, 0.0, 10000.0),
            min_trials=_number(method.get("min_trials", 0), "min_trials", where, 0, 100000, integer=True),
            choose_from=_number(method.get("choose_from", 1), "choose_from", where, 1, 1000, integer=True),
        )
    return out


def _read_conditions_file(path: Path, where: str) -> list[dict[str, Any]]:
    """Rows of a conditions file: CSV with a header, or TOML with [[condition]] tables."""
    if not path.is_file():
        raise DesignError(f"{where}: conditions: no such file {path}")
    if path.suffix == ".toml":
        from jassy.inputs import load_toml

        try:
            rows = load_toml(path, "conditions file").get("condition")
        except JassyError as exc:
            raise DesignError(str(exc)) from None
        if not isinstance(rows, list) or not rows or not all(isinstance(r, dict) for r in rows):
            raise DesignError(f"{path}: condition: expected [[condition]] tables")
        for i, row in enumerate(rows):
            for key, value in row.items():
                if isinstance(value, (list, dict)):
                    raise DesignError(
                        f"{path}: condition[{i}].{key}: expected a string or a number, got {value!r}"
                    )
        return rows
    if path.suffix != ".csv":
        raise DesignError(f"{where}: conditions: expected a .csv or .toml file, got {path.name}")
    with open(path, newline="") as fh:
        rows = list(csv.DictReader(fh))
    if not rows:
        raise DesignError(f"{path}: expected a header line and at least one condition row")
    out = []
    for row in rows:
        if None in row or any(v is None for v in row.values()):
            raise DesignError(f"{path}: row {len(out) + 2}: expected {len(rows[0])} columns")
        out.append({k.strip(): _cell(v.strip()) for k, v in row.items()})
    return out


def _cell(text: str) -> Any:
    try:
        return float(text) if any(c in text for c in ".eE") else int(text)
    except ValueError:
        return text


def _parse_conditions(data, study, where, base, stimulus) -> list[Condition]:
    rows: list[dict[str, Any]] = [{}]
    source = where
    if "conditions" in study:
        spec = _string(study, "conditions", f"{where}: study")
        path = Path(spec) if Path(spec).is_absolute() or base is None else base / spec
        rows = _read_conditions_file(path, f"{where}: study")
        source = str(path)
    factors = _table(data, "factors", where)
    for key, levels in factors.items():
        if not isinstance(levels, list) or not levels:
            raise DesignError(f"{where}: factors: {key}: expected a non-empty list of levels")
        for level in levels:
            if isinstance(level, (list, dict)):
                raise DesignError(
                    f"{where}: factors: {key}: expected levels that are strings or numbers, got {level!r}"
                )
        if any(key in r for r in rows):
            raise DesignError(f"{where}: factors: {key}: also a column of the conditions file")
    crossed = [
        dict(r, **dict(zip(factors, combo, strict=True)))
        for r in rows
        for combo in itertools.product(*factors.values())
    ]
    materials = _table(data, "materials", where)
    out = []
    for i, row in enumerate(crossed):
        w = f"{source}: condition {i + 1}"
        stim = stimulus
        overrides: list[str] = []
        if "stimulus" in row:
            stim = _stimulus_path(str(row["stimulus"]), base)
        if "material" in row:
            name = str(row["material"])
            mat = materials.get(name)
            if not isinstance(mat, dict):
                raise DesignError(
                    f"{w}: material: expected one of the [materials] tables "
                    f"({', '.join(materials) or 'none defined'}), got {name!r}"
                )
            _unknown(mat, {"stimulus", "set"}, f"{where}: materials.{name}")
            if "stimulus" in mat:
                stim = _stimulus_path(_string(mat, "stimulus", f"{where}: materials.{name}"), base)
            sets = mat.get("set", [])
            if not isinstance(sets, list) or not all(
                isinstance(s, str) and "=" in s and "." in s.split("=")[0] for s in sets
            ):
                raise DesignError(
                    f"{where}: materials.{name}: set: expected a list of 'node.param=value' strings"
                )
            overrides += sets
        overrides += [f"{k}={v}" for k, v in row.items() if "." in k]
        force = row.get("force_level", 1.0)
        force = _number(force, "force_level", w, 1e-6, 1000.0)
        sign = None
        if "leading" in row:
            if not _named(row["leading"], LEADING):
                raise DesignError(f"{w}: leading: expected 'audio' or 'haptic', got {row['leading']!r}")
            sign = LEADING[row["leading"]]
        labels = {k: v for k, v in row.items() if "." not in k}
        out.append(Condition(i, labels, stim, tuple(overrides), force, sign))
    return out


def _parse_blocks(table: dict, where: str, conditions: list[Condition]) -> dict[str, Any]:
    _unknown(table, BLOCK_KEYS, where)
    by = _string(table, "by", where)
    if by and any(by not in c.factors for c in conditions):
        names = sorted({k for c in conditions for k in c.factors})
        raise DesignError(
            f"{where}: by: expected a factor ({', '.join(names) or 'none defined'}), got {by!r}"
        )
    order = _string(table, "order", where, "fixed")
    if order not in ("fixed", "random", "latin_square"):
        raise DesignError(f"{where}: order: expected fixed, random or latin_square, got {order!r}")
    texts = _table(table, "instructions", where)
    if not all(isinstance(v, str) for v in texts.values()):
        raise DesignError(f'{where}: instructions: expected block level = "text" strings')
    return {
        "by": by,
        "order": order,
        "repeat": _number(table.get("repeat", 1), "repeat", where, 1, 100, integer=True),
        "instructions": {str(k): v for k, v in texts.items()},
    }


def _parse_practice(table: dict, where: str) -> dict[str, Any]:
    if not table:
        return {}
    _unknown(table, PRACTICE_KEYS, where)
    feedback = table.get("feedback", True)
    if not isinstance(feedback, bool):
        raise DesignError(f"{where}: feedback: expected true or false")
    out = {
        "trials": _number(table.get("trials", 6), "trials", where, 0, 1000, integer=True),
        "feedback": feedback,
        "instructions": _string(table, "instructions", where),
    }
    if "offsets_ms" in table:
        out["offsets_ms"] = _offsets(table["offsets_ms"], "offsets_ms", where)
    return out


def parse_observer(table: Any, where: str = "observer", factors: list[str] | None = None) -> ObserverSpec:
    if not isinstance(table, dict):
        raise DesignError(f"{where}: expected a table")
    _unknown(table, OBSERVER_KEYS, where)
    function = _string(table, "function", where)
    spec = ObserverSpec(
        pss_ms=_number(table.get("pss_ms", 0.0), "pss_ms", where, -10000.0, 10000.0),
        sigma_ms=_number(table.get("sigma_ms", 20.0), "sigma_ms", where, 1e-6, 10000.0),
        window_ms=_number(table.get("window_ms", 150.0), "window_ms", where, 1e-6, 10000.0),
        threshold_ms=_number(table.get("threshold_ms", 30.0), "threshold_ms", where, 1e-6, 10000.0),
        slope=_number(table.get("slope", 2.0), "slope", where, 0.05, 100.0),
        lapse=_number(table.get("lapse", 0.02), "lapse", where, 0.0, 1.0),
        function=function,
    )
    when = table.get("when", [])
    if not isinstance(when, list) or not all(isinstance(r, dict) for r in when):
        raise DesignError(f"{where}: when: expected [[observer.when]] tables")
    params = OBSERVER_KEYS - {"function", "when"}
    for i, rule in enumerate(when):
        for key, value in rule.items():
            if key in params:
                _number(value, key, f"{where}: when[{i}]", -10000.0, 10000.0)
            elif factors is not None and key not in factors:
                raise DesignError(
                    f"{where}: when[{i}]: {key}: expected a factor "
                    f"({', '.join(factors) or 'none'}) or an observer parameter"
                )
    spec.when = when
    return spec


def load_design(path: str | Path) -> Design:
    """Read and validate a design TOML file (DesignError with file and key on bad input)."""
    p = Path(path)
    if not p.is_file():
        raise DesignError(f"{path}: no such design file")
    from jassy.inputs import load_toml

    try:
        data = load_toml(p, "design file")
    except JassyError as exc:
        raise DesignError(str(exc)) from None
    return parse_design(data, str(path), p.resolve().parent)

"""Study designs: the TOML file, the seeded trial list and adaptive staircases.

A design file (see ``examples/pilot_study.toml``)::

    [study]
    name = "pilot-2ms"
    stimulus = "wall_tap"         # patch name or .toml path (relative to the design file)
    trial_duration = 0.5          # s rendered and presented per trial (score events after it are dropped)
    sample_rate = 48000           # Hz
    block = 64                    # frames per block (offline and live)
    seed = 2001                   # randomisation seed (mixed with the participant id)
    question = "which_first"      # "which_first" (a = audio first, h = haptic first)
                                  # or "simultaneous" (s = simultaneous, n = not)
    instructions = "..."
    breaks_every = 40             # trials between breaks (0 = none)
    pause = 0.6                   # s between a response and the next stimulus (live only)
    onset_threshold = 1e-6        # onset = first sample above this fraction of the channel's peak

    [method]                      # constant stimuli
    kind = "constant"
    offsets_ms = [-2.0, 2.0]      # audio minus haptic onset: negative = audio first
    repetitions = 20              # of every offset, in seeded random order

    [method]                      # or interleaved staircases on the offset magnitude
    kind = "staircase"
    rule = "2down1up"             # "1down1up", "2down1up" or "3down1up"
    tracks = ["audio_first", "haptic_first"]
    start_ms = 40.0
    steps_ms = [8.0, 4.0, 2.0]    # step size; the next one after each reversal (the last is kept)
    min_ms = 0.5
    max_ms = 200.0
    reversals = 10                # a track ends after this many reversals ...
    max_trials = 60               # ... or this many trials

    [observer]                    # the simulated observer (--responses simulated)
    pss_ms = 0.0                  # point of subjective simultaneity, ms
    sigma_ms = 20.0               # spread of the psychometric function, ms
    lapse = 0.02                  # probability of a random answer
    function = "gaussian"         # or "logistic"

"Correct" for a staircase: the response names the modality that really came first
(which_first), or says "not simultaneous" (simultaneous).
"""

from __future__ import annotations

import hashlib
import json
import math
import zlib
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import numpy as np

from jassy.errors import JassyError


class DesignError(JassyError):
    """A study design file is invalid; the message names the file and key."""


QUESTIONS = {
    "which_first": ("audio", "haptic"),
    "simultaneous": ("simultaneous", "successive"),
}
RULES = {"1down1up": 1, "2down1up": 2, "3down1up": 3}
TRACKS = {"audio_first": -1.0, "haptic_first": 1.0}
FUNCTIONS = ("gaussian", "logistic")

STUDY_KEYS = {
    "name",
    "description",
    "stimulus",
    "trial_duration",
    "sample_rate",
    "block",
    "seed",
    "question",
    "instructions",
    "breaks_every",
    "pause",
    "onset_threshold",
}
CONSTANT_KEYS = {"kind", "offsets_ms", "repetitions"}
STAIRCASE_KEYS = {
    "kind",
    "rule",
    "tracks",
    "start_ms",
    "steps_ms",
    "min_ms",
    "max_ms",
    "reversals",
    "max_trials",
}
OBSERVER_KEYS = {"pss_ms", "sigma_ms", "lapse", "function"}


@dataclass
class ObserverSpec:
    """Parameters of a simulated observer (psychometric function plus lapses)."""

    pss_ms: float = 0.0
    sigma_ms: float = 20.0
    lapse: float = 0.02
    function: str = "gaussian"


@dataclass
class Design:
    """A validated study design."""

    name: str
    stimulus: str
    trial_duration: float = 0.5
    sample_rate: int = 48000
    block: int = 64
    seed: int = 0
    question: str = "which_first"
    instructions: str = ""
    breaks_every: int = 0
    pause: float = 0.6
    onset_threshold: float = 1e-6
    method: dict[str, Any] = field(default_factory=lambda: {"kind": "constant", "offsets_ms": [0.0]})
    observer: ObserverSpec = field(default_factory=ObserverSpec)
    description: str = ""
    source: str = ""
    raw: dict[str, Any] = field(default_factory=dict)

    @property
    def answers(self) -> tuple[str, str]:
        return QUESTIONS[self.question]

    def sha256(self) -> str:
        """Digest of the design's content (not its path): a results file belongs to one design."""
        return hashlib.sha256(json.dumps(self.raw, sort_keys=True, default=str).encode()).hexdigest()

    def participant_seed(self, participant: str) -> np.random.SeedSequence:
        """The randomisation seed of one participant: the design seed mixed with the id."""
        return np.random.SeedSequence([int(self.seed), zlib.crc32(participant.encode())])

    def schedule(self, participant: str) -> Schedule:
        """A fresh trial schedule for ``participant`` (seeded: always the same sequence)."""
        rng = np.random.default_rng(self.participant_seed(participant))
        if self.method["kind"] == "constant":
            return ConstantSchedule(self.method["offsets_ms"], self.method["repetitions"], rng)
        m = self.method
        return StaircaseSchedule(
            [
                Staircase(
                    t,
                    TRACKS[t],
                    m["rule"],
                    m["start_ms"],
                    m["steps_ms"],
                    m["min_ms"],
                    m["max_ms"],
                    m["reversals"],
                    m["max_trials"],
                )
                for t in m["tracks"]
            ],
            rng,
        )

    def correct(self, offset_ms: float, response: str) -> bool | None:
        """Whether ``response`` is right for a physical offset (None if no right answer)."""
        if self.question == "which_first":
            if offset_ms == 0:
                return None
            return response == ("audio" if offset_ms < 0 else "haptic")
        return None if offset_ms == 0 else response == "successive"


# --------------------------------------------------------------------------- schedules
@dataclass
class TrialSpec:
    """One trial to run: its index (0-based), staircase track ('' if none) and offset."""

    index: int
    offset_ms: float
    track: str = ""


class Schedule:
    """Yields trials one at a time; ``update`` feeds back a response (adaptive methods)."""

    def next(self) -> TrialSpec | None:
        raise NotImplementedError

    def update(self, trial: TrialSpec, correct: bool | None) -> None:
        pass

    @property
    def planned(self) -> int | None:
        """Total number of trials if known in advance."""
        return None

    def summary(self) -> dict[str, Any]:
        return {}


class ConstantSchedule(Schedule):
    """Method of constant stimuli: every offset ``repetitions`` times, in seeded random order."""

    def __init__(self, offsets_ms: list[float], repetitions: int, rng: np.random.Generator):
        trials = np.repeat(np.asarray(offsets_ms, dtype=float), repetitions)
        self.offsets = trials[rng.permutation(trials.size)]
        self.position = 0

    @property
    def planned(self) -> int:
        return int(self.offsets.size)

    def next(self) -> TrialSpec | None:
        if self.position >= self.offsets.size:
            return None
        spec = TrialSpec(self.position, float(self.offsets[self.position]))
        self.position += 1
        return spec


class Staircase:
    """An n-down/1-up staircase on the offset magnitude (ms) with a sign per track.

    After ``n_down`` consecutive correct responses the magnitude decreases by the current
    step, after each error it increases (clamped to [min_ms, max_ms]). A change of
    direction is a reversal; the step then moves to the next entry of ``steps_ms``. The
    n-down/1-up rule converges to the magnitude judged correctly with probability
    0.5 ** (1 / n_down) (1-up/1-down: 50 %, 2-down/1-up: 70.7 %, 3-down/1-up: 79.4 %).
    """

    def __init__(
        self,
        name: str,
        sign: float,
        rule: str,
        start_ms: float,
        steps_ms: list[float],
        min_ms: float,
        max_ms: float,
        reversals: int,
        max_trials: int,
    ):
        self.name, self.sign = name, sign
        self.n_down = RULES[rule]
        self.magnitude = float(start_ms)
        self.steps = [float(s) for s in steps_ms]
        self.min_ms, self.max_ms = float(min_ms), float(max_ms)
        self.max_reversals, self.max_trials = int(reversals), int(max_trials)
        self.step_index = 0
        self.run = 0
        self.direction = 0
        self.reversal_values: list[float] = []
        self.trials = 0

    @property
    def done(self) -> bool:
        return len(self.reversal_values) >= self.max_reversals or self.trials >= self.max_trials

    @property
    def offset_ms(self) -> float:
        return self.sign * self.magnitude

    def update(self, correct: bool) -> None:
        self.trials += 1
        move = 0
        if correct:
            self.run += 1
            if self.run >= self.n_down:
                self.run = 0
                move = -1
        else:
            self.run = 0
            move = 1
        if move == 0:
            return
        if self.direction != 0 and move != self.direction:
            self.reversal_values.append(self.magnitude)
            self.step_index = min(self.step_index + 1, len(self.steps) - 1)
        self.direction = move
        step = self.steps[self.step_index]
        self.magnitude = min(max(self.magnitude + move * step, self.min_ms), self.max_ms)

    def threshold(self) -> float | None:
        """Mean magnitude at the reversals after the first two (None if too few)."""
        values = self.reversal_values[2:] if len(self.reversal_values) > 2 else []
        return float(np.mean(values)) if values else None


class StaircaseSchedule(Schedule):
    """Interleaved staircases: each trial comes from a track drawn at random among those
    not yet finished (seeded), so the participant cannot follow a track."""

    def __init__(self, tracks: list[Staircase], rng: np.random.Generator):
        self.tracks = tracks
        self.rng = rng
        self.count = 0

    def next(self) -> TrialSpec | None:
        live = [t for t in self.tracks if not t.done]
        if not live:
            return None
        track = live[int(self.rng.integers(len(live)))]
        spec = TrialSpec(self.count, track.offset_ms, track.name)
        self.count += 1
        return spec

    def update(self, trial: TrialSpec, correct: bool | None) -> None:
        for t in self.tracks:
            if t.name == trial.track:
                t.update(bool(correct))

    def summary(self) -> dict[str, Any]:
        return {
            t.name: {
                "trials": t.trials,
                "reversals": t.reversal_values,
                "threshold_ms": t.threshold(),
                "rule": f"{t.n_down}down1up",
            }
            for t in self.tracks
        }


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
            raise DesignError(f"{where}: unknown key {key!r}; expected one of {', '.join(sorted(allowed))}")


def _stimulus_path(spec: str, base: Path | None) -> str:
    """A patch path relative to the design file, or a built-in patch name."""
    path = Path(spec)
    if base is not None and (path.suffix == ".toml" or "/" in spec) and not path.is_absolute():
        return str((base / path).resolve())
    return spec


def parse_design(data: dict[str, Any], where: str = "design", base: Path | None = None) -> Design:
    """Validate a design mapping (the parsed TOML)."""
    _unknown(data, {"study", "method", "observer"}, where)
    study = data.get("study")
    if not isinstance(study, dict):
        raise DesignError(f"{where}: missing [study] table")
    _unknown(study, STUDY_KEYS, f"{where}: study")
    w = f"{where}: study"
    if not isinstance(study.get("stimulus"), str) or not study["stimulus"]:
        raise DesignError(f"{w}: stimulus: expected a patch name or .toml path")
    question = study.get("question", "which_first")
    if question not in QUESTIONS:
        raise DesignError(f"{w}: question: expected one of {', '.join(QUESTIONS)}, got {question!r}")
    for key in ("name", "description", "instructions"):
        if key in study and not isinstance(study[key], str):
            raise DesignError(f"{w}: {key}: expected a string")
    design = Design(
        name=study.get("name", Path(where).stem),
        stimulus=_stimulus_path(study["stimulus"], base),
        trial_duration=_number(study.get("trial_duration", 0.5), "trial_duration", w, 0.01, 60.0),
        sample_rate=_number(study.get("sample_rate", 48000), "sample_rate", w, 1000, 768000, integer=True),
        block=_number(study.get("block", 64), "block", w, 1, 65536, integer=True),
        seed=_number(study.get("seed", 0), "seed", w, 0, 2**63 - 1, integer=True),
        question=question,
        instructions=study.get("instructions", ""),
        breaks_every=_number(study.get("breaks_every", 0), "breaks_every", w, 0, 100000, integer=True),
        pause=_number(study.get("pause", 0.6), "pause", w, 0.0, 60.0),
        onset_threshold=_number(study.get("onset_threshold", 1e-6), "onset_threshold", w, 1e-12, 0.5),
        description=study.get("description", ""),
        source=where,
        raw=data,
    )
    design.method = _parse_method(data.get("method"), f"{where}: method")
    design.observer = parse_observer(data.get("observer", {}), f"{where}: observer")
    return design


def _offsets(value: Any, key: str, where: str) -> list[float]:
    if not isinstance(value, list) or not value:
        raise DesignError(f"{where}: {key}: expected a non-empty list of numbers (ms)")
    return [_number(v, key, where, -10000.0, 10000.0) for v in value]


def _parse_method(method: Any, where: str) -> dict[str, Any]:
    if not isinstance(method, dict):
        raise DesignError(f"{where}: missing [method] table (kind = 'constant' or 'staircase')")
    kind = method.get("kind", "constant")
    if kind == "constant":
        _unknown(method, CONSTANT_KEYS, where)
        if "offsets_ms" not in method:
            raise DesignError(f"{where}: offsets_ms: missing (list of audio-haptic offsets in ms)")
        return {
            "kind": "constant",
            "offsets_ms": _offsets(method["offsets_ms"], "offsets_ms", where),
            "repetitions": _number(
                method.get("repetitions", 10), "repetitions", where, 1, 100000, integer=True
            ),
        }
    if kind == "staircase":
        _unknown(method, STAIRCASE_KEYS, where)
        rule = method.get("rule", "2down1up")
        if rule not in RULES:
            raise DesignError(f"{where}: rule: expected one of {', '.join(RULES)}, got {rule!r}")
        tracks = method.get("tracks", ["audio_first", "haptic_first"])
        if not isinstance(tracks, list) or not tracks or any(t not in TRACKS for t in tracks):
            raise DesignError(f"{where}: tracks: expected a list of {', '.join(TRACKS)}, got {tracks!r}")
        if len(set(tracks)) != len(tracks):
            raise DesignError(f"{where}: tracks: each track at most once")
        steps = method.get("steps_ms", [4.0])
        if not isinstance(steps, list) or not steps:
            raise DesignError(f"{where}: steps_ms: expected a non-empty list of step sizes (ms)")
        out = {
            "kind": "staircase",
            "rule": rule,
            "tracks": tracks,
            "steps_ms": [_number(s, "steps_ms", where, 1e-6, 10000.0) for s in steps],
            "min_ms": _number(method.get("min_ms", 0.0), "min_ms", where, 0.0, 10000.0),
            "max_ms": _number(method.get("max_ms", 200.0), "max_ms", where, 1e-6, 10000.0),
            "reversals": _number(method.get("reversals", 10), "reversals", where, 1, 10000, integer=True),
            "max_trials": _number(method.get("max_trials", 60), "max_trials", where, 1, 100000, integer=True),
        }
        out["start_ms"] = _number(
            method.get("start_ms", 40.0), "start_ms", where, out["min_ms"], out["max_ms"]
        )
        return out
    raise DesignError(f"{where}: kind: expected 'constant' or 'staircase', got {kind!r}")


def parse_observer(table: Any, where: str = "observer") -> ObserverSpec:
    if not isinstance(table, dict):
        raise DesignError(f"{where}: expected a table")
    _unknown(table, OBSERVER_KEYS, where)
    function = table.get("function", "gaussian")
    if function not in FUNCTIONS:
        raise DesignError(f"{where}: function: expected one of {', '.join(FUNCTIONS)}, got {function!r}")
    return ObserverSpec(
        pss_ms=_number(table.get("pss_ms", 0.0), "pss_ms", where, -10000.0, 10000.0),
        sigma_ms=_number(table.get("sigma_ms", 20.0), "sigma_ms", where, 1e-6, 10000.0),
        lapse=_number(table.get("lapse", 0.02), "lapse", where, 0.0, 1.0),
        function=function,
    )


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

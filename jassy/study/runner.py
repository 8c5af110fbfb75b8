"""Running a study: render each trial exactly, present it, log it, resume after a stop.

Every trial's stimulus is rendered by the offline engine with the offset applied exactly
in samples on the one clock (``offsets_ms={"audio": offset}``: a negative offset delays
the haptic channels, a positive one the audio). The offset actually presented is then
*measured*, independently of the requested value, by onset detection on the buffers:
the onset of a kind (audio or haptic) is the first sample whose magnitude exceeds
``onset_threshold`` times that kind's peak (the stimulus starts from digital silence), and
the measured offset is audio onset minus haptic onset, in samples. With ``present="live"``
the trial is also played on the device by a :class:`jassy.engines.live.LiveEngine` and the
offset is measured on the monitor copy of what the device received.

Results: ``RESULTS.csv`` gets one row per trial, appended, flushed and fsync'ed as soon
as the response is in, so an interrupted session loses nothing; the JSON header goes to
the sidecar ``RESULTS.json`` (design, participant, software versions, presentation
device, latency, underruns, one entry per session), replaced atomically. Running the same
design with the same results file again resumes: the completed rows are read back (a
partly written last line is dropped), the seeded schedule is replayed through them (for a
staircase, with the recorded responses) and the session continues with the next trial.
"""

from __future__ import annotations

import csv
import io
import json
import os
import platform
import re
import time
from dataclasses import dataclass, field, replace
from datetime import UTC, datetime
from pathlib import Path
from typing import Any, NamedTuple

import numpy as np

from jassy.errors import JassyError
from jassy.study.design import Condition, Design, Schedule, TrialSpec, check_participant
from jassy.study.observer import Response, TrialInfo

CORE_COLUMNS = [
    "trial",
    "participant",
    "session",
    "block",
    "block_name",
    "practice",
    "condition",
]
TRIAL_COLUMNS = [
    "track",
    "requested_ms",
    "requested_samples",
    "measured_samples",
    "measured_ms",
    "audio_onset",
    "haptic_onset",
    "interval",
    "response",
    "positive",
    "correct",
    "response_time_s",
    "latency_s",
    "underruns",
    "timestamp",
]


def columns(design: Design) -> list[str]:
    """The results CSV columns: ids, the design's factors, then the trial's data."""
    return CORE_COLUMNS + design.factor_names + TRIAL_COLUMNS


FORMAT = "jassy-study-results/2"


class ResultsError(JassyError):
    """A results file cannot be used (another design, damaged, ...)."""


# --------------------------------------------------------------------------- stimulus
def offset_samples(offset_ms: float, sample_rate: float) -> int:
    """The offset in whole samples, rounded as the engine's channel delays round it."""
    n = int(round(abs(offset_ms) * sample_rate / 1000.0))
    return -n if offset_ms < 0 else n


def onset(x: np.ndarray, threshold: float) -> int:
    """First frame where any row of x (channels, frames) exceeds ``threshold`` x its peak."""
    x = np.atleast_2d(np.abs(x))
    peak = float(np.max(x)) if x.size else 0.0
    if not peak > 0:
        raise JassyError("no stimulus: a channel is silent, its onset cannot be measured")
    return int(np.flatnonzero(np.any(x > threshold * peak, axis=0))[0])


def measure_offset(audio: np.ndarray, haptic: np.ndarray, threshold: float = 1e-6) -> tuple[int, int, int]:
    """(audio onset, haptic onset, audio minus haptic in samples) of rendered/heard buffers."""
    a, h = onset(audio, threshold), onset(haptic, threshold)
    return a, h, a - h


def _measure(audio: np.ndarray, haptic: np.ndarray, design: Design, offset_ms: float) -> tuple[int, int, int]:
    try:
        return measure_offset(audio, haptic, design.onset_threshold)
    except JassyError as exc:
        raise JassyError(
            f"{design.source}: trial with offset {offset_ms:g} ms: {exc} (is trial_duration = "
            f"{design.trial_duration:g} s long enough for the stimulus plus the offset?)"
        ) from None


def load_stimulus(design: Design, condition: Condition | None = None):
    """The condition's patch (overrides applied, impact impulses scaled by its force
    level) with its score cut to the trial (events before trial_duration)."""
    from jassy.patchfile import load_patch

    condition = condition or design.conditions[0]
    patch = load_patch(condition.stimulus, list(condition.overrides))
    if not patch.graph.audio or not patch.graph.haptic:
        raise JassyError(f"{design.source}: stimulus {condition.stimulus!r} needs audio and haptic outputs")
    score = [ev for ev in patch.score if ev.time < design.trial_duration]
    if condition.force_level != 1.0:
        score = [
            replace(ev, args={**ev.args, "impulse": ev.args["impulse"] * condition.force_level})
            if ev.action == "impact" and "impulse" in ev.args
            else ev
            for ev in score
        ]
    if not score:
        raise JassyError(
            f"{design.source}: stimulus {condition.stimulus!r} has no event before trial_duration"
        )
    patch.score = score
    return patch


def render_trial(
    design: Design, offset_ms: float, condition: Condition | None = None, block: int | None = None
):
    """Render one trial's stimulus with the audio-haptic offset (ms; negative = audio first)."""
    from jassy.engines.offline import OfflineEngine

    patch = load_stimulus(design, condition)
    engine = OfflineEngine(
        patch.graph,
        patch.score,
        design.sample_rate,
        block or design.block,
        offsets_ms={"audio": float(offset_ms), "haptic": 0.0},
    )
    return engine.render(design.trial_duration)


# --------------------------------------------------------------------------- presenters
class Presented(NamedTuple):
    """What was presented: onsets (frames) and offset in samples, underruns during it."""

    audio_onset: int
    haptic_onset: int
    measured_samples: int
    underruns: int = 0
    latency_s: float | None = None  # device output latency measured for this presentation


class OfflinePresenter:
    """``present="none"``: render only (simulated observers, tests). Renders are cached per
    offset in samples (rendering is deterministic, so a cached buffer is the same one)."""

    mode = "none"

    def __init__(self, design: Design):
        self.design = design
        self._cache: dict[tuple[int, int], Presented] = {}

    def info(self) -> dict[str, Any]:
        return {"mode": self.mode, "device": None, "latency_s": None}

    def present(self, offset_ms: float, condition: Condition, interval: int = 0) -> Presented:
        """Render the trial (for m-AFC the interval with the asynchrony; the others are
        the same stimulus without it) and measure its offset."""
        key = (condition.index, offset_samples(offset_ms, self.design.sample_rate))
        if key not in self._cache:
            r = render_trial(self.design, offset_ms, condition)
            self._cache[key] = Presented(*_measure(r.audio, r.haptic, self.design, offset_ms))
        p = self._cache[key]
        return Presented(p.audio_onset, p.haptic_onset, p.measured_samples)

    def close(self) -> dict[str, Any]:
        return {}


class LivePresenter:
    """``present="live"``: play each trial on the device through a LiveEngine (audio and
    haptic channels in one stream) and measure the offset on what the device received.

    A presentation with an underrun (silence inserted by the device callback) may have
    moved what was heard, so it is played again, up to ``max_presentations`` times in all;
    the row logs the underruns of the presentation the observer answered, the sidecar the
    total and the number of repeats."""

    mode = "live"

    def __init__(
        self,
        design: Design,
        device: str | int | None = None,
        ring_blocks: float = 2.5,
        max_presentations: int = 3,
    ):
        if max_presentations < 1:
            raise JassyError(f"max_presentations: expected at least 1, got {max_presentations}")
        self.design, self.device, self.ring_blocks = design, device, ring_blocks
        self.max_presentations = max_presentations
        self.latency: float | None = None
        self.callbacks = 0
        self.underruns = 0
        self.repeats = 0

    def info(self) -> dict[str, Any]:
        return {
            "mode": self.mode,
            "device": self.device,
            "latency_s": self.latency,
            "ring_blocks": self.ring_blocks,
            "max_presentations": self.max_presentations,
        }

    def present(self, offset_ms: float, condition: Condition, interval: int = 0) -> Presented:
        """Play the trial (m-AFC: its intervals in turn, ``interval_gap`` apart, the
        asynchrony in ``interval``); replay it if the device reported an underrun."""
        shown = self._trial(offset_ms, condition, interval)
        for _ in range(self.max_presentations - 1):
            if shown.underruns == 0:
                break
            self.repeats += 1
            shown = self._trial(offset_ms, condition, interval)
        return shown

    def _trial(self, offset_ms: float, condition: Condition, interval: int) -> Presented:
        if not interval:
            return self._play(offset_ms, condition)
        underruns, target = 0, None
        for i in range(1, self.design.model.alternatives + 1):
            if i > 1:
                time.sleep(self.design.interval_gap)
            shown = self._play(offset_ms if i == interval else 0.0, condition)
            underruns += shown.underruns
            target = shown if i == interval else target
        return target._replace(underruns=underruns)

    def _play(self, offset_ms: float, condition: Condition) -> Presented:
        from jassy.engines.live import LiveEngine

        d = self.design
        patch = load_stimulus(d, condition)
        engine = LiveEngine(
            patch.graph,
            patch.score,
            d.sample_rate,
            d.block,
            self.ring_blocks,
            self.device,
            offsets_ms={"audio": float(offset_ms), "haptic": 0.0},
            monitor_seconds=d.trial_duration + 1.0,
            mode="ring",  # offsets need the ring: every trial, 0 ms too, on one path and latency
        )
        engine.start()
        try:
            latency = engine.stats().latency
            time.sleep(d.trial_duration + latency + 2 * d.block / d.sample_rate)
        finally:  # also on a signal: forces fade out, the stream stops, no child outlives us
            stats = engine.stop()
        self.latency = stats.latency
        self.callbacks += stats.callbacks
        self.underruns += stats.underrun_callbacks
        heard, _ = engine.monitor()
        n_audio = len(patch.graph.audio)
        a, h, m = _measure(heard[:n_audio], heard[n_audio:], d, offset_ms)
        return Presented(a, h, m, stats.underrun_callbacks, stats.latency)

    def close(self) -> dict[str, Any]:
        return {
            "callbacks": self.callbacks,
            "underrun_callbacks": self.underruns,
            "repeated_presentations": self.repeats,
            "latency_s": self.latency,
        }


# --------------------------------------------------------------------------- results
def sidecar_path(results: str | os.PathLike) -> Path:
    return Path(results).with_suffix(".json")


def _write_json_atomic(path: Path, data: dict) -> None:
    tmp = path.with_name(f".{path.name}.tmp")
    with open(tmp, "w") as f:
        json.dump(data, f, indent=2, default=str)
        f.write("\n")
        f.flush()
        os.fsync(f.fileno())
    os.replace(tmp, path)


def software_versions() -> dict[str, str]:
    import numba
    import scipy

    import jassy

    return {
        "jassy": jassy.__version__,
        "python": platform.python_version(),
        "numpy": np.__version__,
        "scipy": scipy.__version__,
        "numba": numba.__version__,
        "platform": platform.platform(),
    }


def read_rows(path: str | os.PathLike, repair: bool = False) -> list[dict[str, str]]:
    """Rows of a results CSV. A last line without its newline (a write cut short) is
    ignored, and removed from the file if ``repair``."""
    from jassy.inputs import decode, read_bytes

    p = Path(path)
    try:
        data = read_bytes(p, "results file")
        decode(data, str(p))  # all of it is UTF-8, so is any prefix cut at a newline
    except JassyError as exc:
        raise ResultsError(str(exc)) from None
    if data and not data.endswith(b"\n"):
        cut = data.rfind(b"\n") + 1
        data = data[:cut]
        if repair:
            with open(p, "r+b") as f:
                f.truncate(cut)
                f.flush()
                os.fsync(f.fileno())
    reader = csv.DictReader(io.StringIO(data.decode()))
    names = reader.fieldnames or []
    if data and (names[: len(CORE_COLUMNS)] != CORE_COLUMNS or names[-len(TRIAL_COLUMNS) :] != TRIAL_COLUMNS):
        raise ResultsError(f"{path}: not a jassy study results file (columns {names})")
    return list(reader)


def read_header(path: str | os.PathLike) -> dict[str, Any]:
    side = sidecar_path(path)
    if not side.is_file():
        return {}
    try:
        return json.loads(side.read_bytes().decode("utf-8"))
    except (json.JSONDecodeError, UnicodeDecodeError, RecursionError) as exc:
        raise ResultsError(f"{side}: damaged JSON header: {exc}") from None


def date_string(now: datetime | None = None) -> str:
    """PsychoPy's date format for data file names: 2026-11-26_23h14.05.123."""
    now = now or datetime.now()
    return now.strftime("%Y-%m-%d_%Hh%M.%S.") + f"{now.microsecond // 1000:03d}"


def safe_name(text: str) -> str:
    """``text`` with every character other than letters, digits, '-' and '_' made '-'."""
    return re.sub(r"[^A-Za-z0-9_-]", "-", text) or "study"


def results_name(design: Design, participant: str, session: str, folder: str | os.PathLike = "data") -> Path:
    """PsychoPy-style dated results path: FOLDER/PARTICIPANT_STUDY_sSESSION_DATE.csv."""
    check_participant(participant)
    return Path(folder) / f"{participant}_{safe_name(design.name)}_s{session}_{date_string()}.csv"


def find_unfinished(
    design: Design, participant: str, session: str, folder: str | os.PathLike = "data"
) -> Path | None:
    """The newest results file of this design, participant and session whose last session
    did not complete (to resume), or None."""
    check_participant(participant)
    found = []
    for path in Path(folder).glob(f"{participant}_{safe_name(design.name)}_s{session}_*.csv"):
        header = read_header(path)
        sessions = header.get("sessions") or [{}]
        if header.get("design_sha256") == design.sha256() and not sessions[-1].get("completed"):
            found.append(path)
    return max(found, key=lambda p: p.name) if found else None


def summary_path(results: str | os.PathLike) -> Path:
    p = Path(results)
    return p.with_name(f"{p.stem}_summary.csv")


def write_summary(results: Path, design: Design, rows: list[dict[str, str]]) -> Path:
    """The wide summary beside the trial CSV: one row per condition (practice excluded),
    the trials and proportion of positive answers at each offset as columns."""
    rows = [r for r in rows if r["practice"] == "0"]
    key = "measured_ms"
    offsets = sorted({round(float(r[key]), 6) for r in rows})
    positive = {"toj": "haptic_first", "sj": "simultaneous"}.get(design.task, "correct")
    head = ["condition", *design.factor_names, "trials"]
    head += [f"n@{x:g}" for x in offsets] + [f"p_{positive}@{x:g}" for x in offsets]
    lines = []
    for c in design.conditions:
        mine = [r for r in rows if r["condition"] == str(c.index)]
        if not mine:
            continue
        line = [c.index, *(c.factors.get(f, "") for f in design.factor_names), len(mine)]
        counts = [[r for r in mine if round(float(r[key]), 6) == x] for x in offsets]
        line += [len(g) for g in counts]
        line += [f"{sum(r['positive'] == '1' for r in g) / len(g):.4f}" if g else "" for g in counts]
        lines.append(line)
    buf = io.StringIO()
    writer = csv.writer(buf, lineterminator="\n")
    writer.writerow(head)
    writer.writerows(lines)
    out = summary_path(results)
    write_text_atomic(out, buf.getvalue())
    return out


def write_text_atomic(path: Path, text: str) -> None:
    tmp = path.with_name(f".{path.name}.tmp")
    with open(tmp, "w") as f:
        f.write(text)
        f.flush()
        os.fsync(f.fileno())
    os.replace(tmp, path)


@dataclass
class SessionResult:
    """Summary of a run: rows written now, rows in the file, whether it completed."""

    path: Path
    completed: bool
    new_trials: int
    total_trials: int
    resumed_from: int
    tracks: dict[str, Any] = field(default_factory=dict)


class Session:
    """One participant's session of a design into one results file (resumable)."""

    def __init__(
        self,
        design: Design,
        results: str | os.PathLike,
        participant: str,
        responder,
        presenter,
        session: str = "1",
        participant_number: int | None = None,
    ):
        check_participant(participant)
        check_participant(session, "session")
        self.design, self.results = design, Path(results)
        if self.results.suffix != ".csv":
            raise JassyError(f"{results}: results file name must end in .csv")
        self.participant, self.session = participant, session
        if participant_number is None:
            digits = re.search(r"(\d+)$", participant)
            participant_number = int(digits.group(1)) if digits else None
        self.participant_number = participant_number
        self.responder, self.presenter = responder, presenter
        self.columns = columns(design)

    # ------------------------------------------------------------ resume
    def _replay(self, schedule: Schedule, rows: list[dict[str, str]]) -> None:
        """Advance the seeded schedule through the completed rows (checking they match)."""
        for i, row in enumerate(rows):
            spec = schedule.next()
            if spec is None:
                raise ResultsError(f"{self.results}: has more trials than the design ({len(rows)})")
            try:
                ok = int(row["trial"]) == i and abs(float(row["requested_ms"]) - spec.offset_ms) < 1e-9
            except (KeyError, ValueError):
                ok = False
            if not ok or row["track"] != spec.track or row["participant"] != self.participant:
                raise ResultsError(
                    f"{self.results}: row {i + 1} does not match the seeded trial list of this design and "
                    f"participant (expected trial {i}, offset {spec.offset_ms:g} ms); "
                    "use another results file"
                )
            correct = None if row["correct"] == "" else row["correct"] == "1"
            schedule.update(spec, row["positive"] == "1", correct)

    def _open(self) -> tuple[list[dict[str, str]], dict[str, Any]]:
        header = read_header(self.results)
        if self.results.exists():
            if header.get("format") != FORMAT:
                raise ResultsError(
                    f"{self.results}: exists but {sidecar_path(self.results)} is missing or foreign"
                )
            if header.get("design_sha256") != self.design.sha256():
                raise ResultsError(f"{self.results}: written for another design (or an edited one)")
            if header.get("participant") != self.participant or header.get("session") != self.session:
                raise ResultsError(
                    f"{self.results}: belongs to participant {header.get('participant')!r} session "
                    f"{header.get('session')!r}, not {self.participant!r} session {self.session!r}"
                )
            rows = read_rows(self.results, repair=True)
        else:
            self.results.parent.mkdir(parents=True, exist_ok=True)
            header = {
                "format": FORMAT,
                "columns": self.columns,
                "participant": self.participant,
                "session": self.session,
                "participant_number": self.participant_number,
                "task": self.design.task,
                "function": self.design.function,
                "conditions": [c.factors for c in self.design.conditions],
                "design_file": self.design.source,
                "design_sha256": self.design.sha256(),
                "design": self.design.raw,
                "seed": self.design.seed,
                "sample_rate": self.design.sample_rate,
                "block": self.design.block,
                "sessions": [],
            }
            rows = []
            with open(self.results, "w", newline="") as f:
                f.write(",".join(self.columns) + "\n")
                f.flush()
                os.fsync(f.fileno())
        return rows, header

    def _row(
        self, spec: TrialSpec, shown: Presented, measured_ms: float, response: Response, positive, correct
    ) -> str:
        d = self.design
        condition = d.conditions[spec.condition]
        values = [
            spec.index,
            self.participant,
            self.session,
            spec.block,
            spec.block_name,
            int(spec.practice),
            spec.condition,
            *(condition.factors.get(f, "") for f in d.factor_names),
            spec.track,
            repr(float(spec.offset_ms)),
            offset_samples(spec.offset_ms, d.sample_rate),
            shown.measured_samples,
            repr(measured_ms),
            shown.audio_onset,
            shown.haptic_onset,
            spec.interval,
            response.answer,
            int(positive),
            "" if correct is None else int(correct),
            f"{response.time:.4f}",
            "" if shown.latency_s is None else f"{shown.latency_s:.6f}",
            shown.underruns,
            datetime.now(UTC).isoformat(timespec="milliseconds"),
        ]
        buf = io.StringIO()
        csv.writer(buf, lineterminator="\n").writerow(values)
        return buf.getvalue()

    # ------------------------------------------------------------ run
    def run(self, max_trials: int | None = None) -> SessionResult:
        """Run (or resume) until the schedule ends, the responder quits or ``max_trials``
        trials were run in this call."""
        d = self.design
        rows, header = self._open()
        schedule = d.schedule(self.participant, self.session, self.participant_number)
        self._replay(schedule, rows)
        session = {
            "started": datetime.now(UTC).isoformat(),
            "resumed_from": len(rows),
            "software": software_versions(),
            "presentation": self.presenter.info(),
            "block_order": [b.name for b in schedule.blocks],
            "live_trials": [],
        }
        header["sessions"].append(session)
        side = sidecar_path(self.results)
        _write_json_atomic(side, header)
        done, new, completed, underruns = len(rows), 0, False, 0
        block = int(rows[-1]["block"]) if rows else None  # resuming inside a block: no new message
        in_block = 0
        self.responder.begin(d)
        try:
            with open(self.results, "a", newline="") as out:
                while True:
                    if max_trials is not None and new >= max_trials:
                        break
                    spec = schedule.next()
                    if spec is None:
                        completed = True
                        break
                    if spec.block != block:  # a new block: its instructions (if any) first
                        in_block, block = 0, spec.block
                        current = schedule.blocks[spec.block]
                        title = "Practice" if current.practice else f"Block {current.name}"
                        shown_text = current.instructions.strip()
                        if (shown_text or len(schedule.blocks) > 1) and not self.responder.rest(
                            f"{title}. {shown_text}".strip()
                        ):
                            break
                    elif (
                        d.breaks_every
                        and in_block
                        and in_block % d.breaks_every == 0
                        and not self.responder.rest(f"Break: {done} trials done.")
                    ):
                        break
                    condition = d.conditions[spec.condition]
                    shown = self.presenter.present(spec.offset_ms, condition, spec.interval)
                    measured_ms = shown.measured_samples * 1000.0 / d.sample_rate
                    info = TrialInfo(
                        spec.index, schedule.planned, measured_ms, d.task, condition.factors, spec.interval
                    )
                    response: Response = self.responder.respond(info)
                    if response.answer is None:
                        break
                    if response.answer not in d.answers:
                        raise JassyError(
                            f"response {response.answer!r}: expected one of {', '.join(d.answers)}"
                        )
                    positive = d.positive(spec, response.answer)
                    correct = d.correct(spec, measured_ms, response.answer)
                    schedule.update(spec, positive, correct)
                    underruns += shown.underruns
                    out.write(self._row(spec, shown, measured_ms, response, positive, correct))
                    out.flush()  # one line per write, then to disk
                    os.fsync(out.fileno())
                    if shown.latency_s is not None:
                        session["live_trials"].append([spec.index, shown.latency_s, shown.underruns])
                    if spec.practice and d.practice.get("feedback") and correct is not None:
                        self.responder.feedback("Correct." if correct else "Wrong.")
                    done += 1
                    new += 1
                    in_block += 1
                    if self.presenter.mode == "live" and d.pause:
                        time.sleep(d.pause)
        finally:
            session.update(
                ended=datetime.now(UTC).isoformat(),
                trials=new,
                completed=completed,
                underruns=underruns,
                presentation=self.presenter.info(),
                device_stats=self.presenter.close(),
                tracks=schedule.summary(),
            )
            _write_json_atomic(side, header)
            write_summary(self.results, d, read_rows(self.results))
        self.responder.end(
            "Thank you: the session is complete." if completed else "Session stopped; it can be resumed."
        )
        return SessionResult(self.results, completed, new, done, len(rows), schedule.summary())


def run_study(
    design: Design,
    results: str | os.PathLike,
    participant: str = "P01",
    responder=None,
    present: str = "none",
    device: str | int | None = None,
    max_trials: int | None = None,
    observer_seed: int | None = None,
    session: str = "1",
    participant_number: int | None = None,
) -> SessionResult:
    """Run ``design`` for one participant (default responder: the design's simulated
    observer, seeded from the design seed and participant unless ``observer_seed``)."""
    from jassy.study.observer import SimulatedObserver

    check_participant(participant)
    if responder is None:
        seed = (
            observer_seed
            if observer_seed is not None
            else design.participant_seed(participant, session).spawn(1)[0]
        )
        responder = SimulatedObserver(design.observer, seed, design.function)
    if present == "none":
        presenter = OfflinePresenter(design)
    elif present == "live":
        presenter = LivePresenter(design, device)
    else:
        raise JassyError(f"--present: expected none or live, got {present!r}")
    return Session(design, results, participant, responder, presenter, session, participant_number).run(
        max_trials
    )


__all__ = [
    "LivePresenter",
    "OfflinePresenter",
    "Presented",
    "Session",
    "SessionResult",
    "columns",
    "find_unfinished",
    "measure_offset",
    "onset",
    "read_header",
    "read_rows",
    "render_trial",
    "results_name",
    "run_study",
]

"""Running a study: render each trial exactly, present it, log it, resume after a stop.

Every trial's stimulus is rendered by the offline engine with the offset applied exactly
in samples on the one clock (``offsets_ms={"audio": offset}``: a negative offset delays
the haptic channels, a positive one the audio). The offset actually presented is then
*measured*, independently of the requested value, by onset detection on the buffers:
the onset of a kind (audio or haptic) is the first sample whose magnitude exceeds
``onset_threshold`` times that kind's peak (the stimulus starts from digital silence), and
the measured offset is audio onset minus haptic onset, in samples. With ``present="live"``
the trial is also played on the device by a :class:`jassy.live.LiveEngine` and the
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
import time
from dataclasses import dataclass, field
from datetime import UTC, datetime
from pathlib import Path
from typing import Any

import numpy as np

from jassy.errors import JassyError
from jassy.study.design import Design, Schedule
from jassy.study.observer import Response, TrialInfo

COLUMNS = [
    "trial",
    "participant",
    "track",
    "requested_ms",
    "requested_samples",
    "measured_samples",
    "measured_ms",
    "audio_onset",
    "haptic_onset",
    "response",
    "response_time_s",
    "correct",
    "underruns",
    "timestamp",
]
FORMAT = "jassy-study-results/1"


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


def load_stimulus(design: Design):
    """The design's patch with its score cut to the trial (events before trial_duration)."""
    from jassy.patchfile import load_patch

    patch = load_patch(design.stimulus)
    if not patch.graph.audio or not patch.graph.haptic:
        raise JassyError(f"{design.source}: stimulus {design.stimulus!r} needs audio and haptic outputs")
    patch.score = [ev for ev in patch.score if ev.time < design.trial_duration]
    if not patch.score:
        raise JassyError(f"{design.source}: stimulus {design.stimulus!r} has no event before trial_duration")
    return patch


def render_trial(design: Design, offset_ms: float, block: int | None = None):
    """Render one trial's stimulus with the audio-haptic offset (ms; negative = audio first)."""
    from jassy.offline import OfflineEngine

    patch = load_stimulus(design)
    engine = OfflineEngine(
        patch.graph,
        patch.score,
        design.sample_rate,
        block or design.block,
        offsets_ms={"audio": float(offset_ms), "haptic": 0.0},
    )
    return engine.render(design.trial_duration)


# --------------------------------------------------------------------------- presenters
@dataclass
class Presented:
    """What was presented: onsets (frames) and offset in samples, underruns during it."""

    audio_onset: int
    haptic_onset: int
    measured_samples: int
    underruns: int = 0


class OfflinePresenter:
    """``present="none"``: render only (simulated observers, tests). Renders are cached per
    offset in samples (rendering is deterministic, so a cached buffer is the same one)."""

    mode = "none"

    def __init__(self, design: Design):
        self.design = design
        self._cache: dict[int, Presented] = {}

    def info(self) -> dict[str, Any]:
        return {"mode": self.mode, "device": None, "latency_s": None}

    def present(self, offset_ms: float) -> Presented:
        key = offset_samples(offset_ms, self.design.sample_rate)
        if key not in self._cache:
            r = render_trial(self.design, offset_ms)
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

    def present(self, offset_ms: float) -> Presented:
        shown = self._play(offset_ms)
        for _ in range(self.max_presentations - 1):
            if shown.underruns == 0:
                break
            self.repeats += 1
            shown = self._play(offset_ms)
        return shown

    def _play(self, offset_ms: float) -> Presented:
        from jassy.live import LiveEngine

        d = self.design
        patch = load_stimulus(d)
        engine = LiveEngine(
            patch.graph,
            patch.score,
            d.sample_rate,
            d.block,
            self.ring_blocks,
            self.device,
            offsets_ms={"audio": float(offset_ms), "haptic": 0.0},
            monitor_seconds=d.trial_duration + 1.0,
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
        return Presented(a, h, m, stats.underrun_callbacks)

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
    p = Path(path)
    data = p.read_bytes()
    if data and not data.endswith(b"\n"):
        cut = data.rfind(b"\n") + 1
        data = data[:cut]
        if repair:
            with open(p, "r+b") as f:
                f.truncate(cut)
                f.flush()
                os.fsync(f.fileno())
    reader = csv.DictReader(io.StringIO(data.decode()))
    if data and reader.fieldnames != COLUMNS:
        raise ResultsError(f"{path}: not a jassy study results file (columns {reader.fieldnames})")
    return list(reader)


def read_header(path: str | os.PathLike) -> dict[str, Any]:
    side = sidecar_path(path)
    if not side.is_file():
        return {}
    try:
        return json.loads(side.read_text())
    except json.JSONDecodeError as exc:
        raise ResultsError(f"{side}: damaged JSON header: {exc}") from None


@dataclass
class SessionResult:
    """Summary of a run: rows written now, rows in the file, whether it completed."""

    path: Path
    completed: bool
    new_trials: int
    total_trials: int
    resumed_from: int
    staircases: dict[str, Any] = field(default_factory=dict)


class Session:
    """One participant's run of a design into one results file (resumable)."""

    def __init__(self, design: Design, results: str | os.PathLike, participant: str, responder, presenter):
        if not participant or any(c in participant for c in ',\n\r"'):
            raise JassyError(
                f"participant: expected a non-empty id without commas or quotes, got {participant!r}"
            )
        self.design, self.results = design, Path(results)
        if self.results.suffix != ".csv":
            raise JassyError(f"{results}: results file name must end in .csv")
        self.participant = participant
        self.responder, self.presenter = responder, presenter

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
            schedule.update(spec, self.design.correct(float(row["measured_ms"]), row["response"]))

    def _open(self) -> tuple[list[dict[str, str]], dict[str, Any]]:
        header = read_header(self.results)
        if self.results.exists():
            if header.get("format") != FORMAT:
                raise ResultsError(
                    f"{self.results}: exists but {sidecar_path(self.results)} is missing or foreign"
                )
            if header.get("design_sha256") != self.design.sha256():
                raise ResultsError(f"{self.results}: written for another design (or an edited one)")
            if header.get("participant") != self.participant:
                raise ResultsError(
                    f"{self.results}: belongs to participant {header.get('participant')!r}, "
                    f"not {self.participant!r}"
                )
            rows = read_rows(self.results, repair=True)
        else:
            self.results.parent.mkdir(parents=True, exist_ok=True)
            header = {
                "format": FORMAT,
                "columns": COLUMNS,
                "participant": self.participant,
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
                f.write(",".join(COLUMNS) + "\n")
                f.flush()
                os.fsync(f.fileno())
        return rows, header

    # ------------------------------------------------------------ run
    def run(self, max_trials: int | None = None) -> SessionResult:
        """Run (or resume) until the schedule ends, the responder quits or ``max_trials``
        trials were run in this call."""
        d = self.design
        rows, header = self._open()
        schedule = d.schedule(self.participant)
        self._replay(schedule, rows)
        session = {
            "started": datetime.now(UTC).isoformat(),
            "resumed_from": len(rows),
            "software": software_versions(),
            "presentation": self.presenter.info(),
        }
        header["sessions"].append(session)
        side = sidecar_path(self.results)
        _write_json_atomic(side, header)
        done = len(rows)
        new = 0
        completed = False
        underruns = 0
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
                    rest = d.breaks_every and new and done % d.breaks_every == 0
                    if rest and not self.responder.rest(f"Break: {done} trials done."):
                        break
                    shown = self.presenter.present(spec.offset_ms)
                    measured_ms = shown.measured_samples * 1000.0 / d.sample_rate
                    info = TrialInfo(spec.index, schedule.planned, measured_ms, d.question)
                    response: Response = self.responder.respond(info)
                    if response.answer is None:
                        break
                    if response.answer not in d.answers:
                        raise JassyError(
                            f"response {response.answer!r}: expected one of {', '.join(d.answers)}"
                        )
                    correct = d.correct(measured_ms, response.answer)
                    schedule.update(spec, correct)
                    underruns += shown.underruns
                    row = [
                        spec.index,
                        self.participant,
                        spec.track,
                        repr(float(spec.offset_ms)),
                        offset_samples(spec.offset_ms, d.sample_rate),
                        shown.measured_samples,
                        repr(measured_ms),
                        shown.audio_onset,
                        shown.haptic_onset,
                        response.answer,
                        f"{response.time:.4f}",
                        "" if correct is None else int(correct),
                        shown.underruns,
                        datetime.now(UTC).isoformat(timespec="milliseconds"),
                    ]
                    out.write(",".join(str(v) for v in row) + "\n")  # one write, then to disk
                    out.flush()
                    os.fsync(out.fileno())
                    done += 1
                    new += 1
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
                staircases=schedule.summary(),
            )
            _write_json_atomic(side, header)
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
) -> SessionResult:
    """Run ``design`` for one participant (default responder: the design's simulated
    observer, seeded from the design seed and participant unless ``observer_seed``)."""
    from jassy.study.observer import SimulatedObserver

    if responder is None:
        seed = (
            observer_seed if observer_seed is not None else design.participant_seed(participant).spawn(1)[0]
        )
        responder = SimulatedObserver(design.observer, seed)
    if present == "none":
        presenter = OfflinePresenter(design)
    elif present == "live":
        presenter = LivePresenter(design, device)
    else:
        raise JassyError(f"--present: expected none or live, got {present!r}")
    return Session(design, results, participant, responder, presenter).run(max_trials)


__all__ = [
    "COLUMNS",
    "LivePresenter",
    "OfflinePresenter",
    "Presented",
    "Session",
    "SessionResult",
    "measure_offset",
    "onset",
    "read_header",
    "read_rows",
    "render_trial",
    "run_study",
]

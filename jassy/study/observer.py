"""Response sources: a simulated observer, the terminal keyboard, a window, any callable.

A responder has ``begin(design)`` (instructions), ``respond(trial) -> Response``,
``rest(message) -> bool`` (a break; False = stop the session) and ``end(message)``.
``respond`` is called right after the stimulus ended; the response time is measured from
that moment. A response of ``None`` stops the session (it can be resumed later).
"""

from __future__ import annotations

import math
import sys
import time
from collections.abc import Callable
from dataclasses import dataclass
from typing import Any

import numpy as np
from scipy.special import ndtr

from jassy.errors import JassyError
from jassy.study.design import QUESTIONS, Design, ObserverSpec

KEYS = {
    "which_first": {"a": "audio", "h": "haptic"},
    "simultaneous": {"s": "simultaneous", "n": "successive"},
}
PROMPTS = {
    "which_first": "Which came first?  [a] audio (sound)   [h] haptic (touch)   [q] quit",
    "simultaneous": "Were they simultaneous?  [s] simultaneous   [n] not simultaneous   [q] quit",
}


@dataclass
class Response:
    """An answer ('audio'/'haptic' or 'simultaneous'/'successive'; None = quit) and its
    time in seconds from the end of the stimulus."""

    answer: str | None
    time: float


@dataclass
class TrialInfo:
    """What a responder may know about the trial it answers."""

    index: int
    planned: int | None
    offset_ms: float  # the offset presented (measured), for simulated observers only
    question: str


def cdf(x: np.ndarray | float, function: str = "gaussian") -> np.ndarray | float:
    """Standard cumulative Gaussian or logistic (scale so that sigma is the scale parameter)."""
    if function == "gaussian":
        return ndtr(x)
    return 1.0 / (1.0 + np.exp(-np.asarray(x, dtype=float)))


def p_positive(
    x: np.ndarray | float, mu: float, sigma: float, lapse: float, question: str, function: str = "gaussian"
) -> np.ndarray | float:
    """Probability of the "positive" answer at offset x (ms; audio minus haptic).

    which_first: P("haptic first") = lapse/2 + (1 - lapse) F((x - mu) / sigma);
    simultaneous: P("simultaneous") = lapse/2 + (1 - lapse) exp(-(x - mu)^2 / (2 sigma^2)).
    A lapse is a random answer (either alternative with probability 1/2).
    """
    z = (np.asarray(x, dtype=float) - mu) / sigma
    core = cdf(z, function) if question == "which_first" else np.exp(-0.5 * z * z)
    return 0.5 * lapse + (1.0 - lapse) * core


POSITIVE = {"which_first": "haptic", "simultaneous": "simultaneous"}


class SimulatedObserver:
    """A model observer: answers from a psychometric function of the presented offset with
    a point of subjective simultaneity ``pss_ms``, spread ``sigma_ms`` and lapse rate
    (see :func:`p_positive`); seeded. Response times are drawn from a log-normal
    distribution (median 0.5 s) but not waited for."""

    def __init__(self, spec: ObserverSpec | None = None, seed: int | np.random.SeedSequence = 0, **kw: Any):
        spec = spec or ObserverSpec()
        for key, value in kw.items():
            setattr(spec, key, value)
        self.spec = spec
        self.rng = np.random.default_rng(seed)

    def begin(self, design: Design) -> None:
        self.question = design.question

    def respond(self, trial: TrialInfo) -> Response:
        s = self.spec
        p = float(p_positive(trial.offset_ms, s.pss_ms, s.sigma_ms, s.lapse, trial.question, s.function))
        positive = self.rng.random() < p
        answers = QUESTIONS[trial.question]
        answer = (
            POSITIVE[trial.question]
            if positive
            else next(a for a in answers if a != POSITIVE[trial.question])
        )
        return Response(answer, float(math.exp(self.rng.normal(math.log(0.5), 0.3))))

    def rest(self, message: str) -> bool:
        return True

    def end(self, message: str) -> None:
        pass


class CallableResponder:
    """Wraps ``fn(trial: TrialInfo) -> answer | (answer, seconds) | None``."""

    def __init__(self, fn: Callable[[TrialInfo], Any]):
        self.fn = fn

    def begin(self, design: Design) -> None:
        pass

    def respond(self, trial: TrialInfo) -> Response:
        t0 = time.monotonic()
        out = self.fn(trial)
        if isinstance(out, tuple):
            return Response(out[0], float(out[1]))
        return Response(out, time.monotonic() - t0)

    def rest(self, message: str) -> bool:
        return True

    def end(self, message: str) -> None:
        pass


class KeyboardResponder:
    """Single key presses in the terminal (no Enter needed where stdin is a terminal).

    Keys typed during the stimulus are discarded; the response time runs from the end of
    the stimulus to the key press.
    """

    def __init__(self, stream_in=None, stream_out=None):
        self.stdin = stream_in or sys.stdin
        self.stdout = stream_out or sys.stdout

    def _print(self, text: str) -> None:
        print(text, file=self.stdout, flush=True)

    def _tty(self) -> bool:
        try:
            return self.stdin.isatty()
        except (AttributeError, ValueError):
            return False

    def _read_key(self, allowed: str) -> str:
        if not self._tty():
            while True:
                line = self.stdin.readline()
                if not line:
                    return "q"
                key = line.strip()[:1].lower() or ("\n" if "\n" in allowed else "")
                if key and key in allowed:
                    return key
        import termios
        import tty

        fd = self.stdin.fileno()
        old = termios.tcgetattr(fd)
        try:
            tty.setcbreak(fd)
            termios.tcflush(fd, termios.TCIFLUSH)  # keys pressed during the stimulus
            while True:
                key = self.stdin.read(1).lower()
                if not key:  # end of input
                    return "q"
                if key in allowed:
                    return key
        finally:
            termios.tcsetattr(fd, termios.TCSADRAIN, old)

    def begin(self, design: Design) -> None:
        self.question = design.question
        if design.instructions:
            self._print(design.instructions.strip())
        self._print("Press any key to start.")
        self._read_key("abcdefghijklmnopqrstuvwxyz \n")

    def respond(self, trial: TrialInfo) -> Response:
        keys = KEYS[trial.question]
        counter = f"[{trial.index + 1}/{trial.planned}] " if trial.planned else f"[{trial.index + 1}] "
        self._print(counter + PROMPTS[trial.question])
        t0 = time.monotonic()
        key = self._read_key("".join(keys) + "q")
        rt = time.monotonic() - t0
        return Response(None if key == "q" else keys[key], rt)

    def rest(self, message: str) -> bool:
        self._print(f"{message}  Press c to continue, q to stop (the session can be resumed).")
        return self._read_key("cq") == "c"

    def end(self, message: str) -> None:
        self._print(message)


class WindowResponder:
    """A small tkinter window with two answer buttons (and keys a/h or s/n)."""

    def __init__(self):
        try:
            import tkinter as tk
        except ImportError as exc:  # pragma: no cover - depends on the Python build
            raise JassyError(f"--responses window needs tkinter: {exc}") from None
        self.tk = tk
        try:
            self.root = tk.Tk()
        except tk.TclError as exc:
            raise JassyError(f"--responses window: cannot open a window ({exc})") from None
        self.root.title("jassy study")
        self.label = tk.Label(self.root, text="", font=("TkDefaultFont", 14), wraplength=520, justify="left")
        self.label.pack(padx=20, pady=15)
        self.frame = tk.Frame(self.root)
        self.frame.pack(pady=10)
        self.var = tk.StringVar(self.root, "")
        self.root.protocol("WM_DELETE_WINDOW", lambda: self.var.set("quit"))

    def _buttons(self, choices: list[tuple[str, str, str]]) -> None:
        for w in self.frame.winfo_children():
            w.destroy()
        self.root.unbind("<Key>")
        for label, value, _key in choices:
            b = self.tk.Button(self.frame, text=label, width=16, command=lambda v=value: self.var.set(v))
            b.pack(side="left", padx=8)
        keymap = {key: value for _, value, key in choices}
        self.root.bind("<Key>", lambda e: keymap.get(e.char.lower()) and self.var.set(keymap[e.char.lower()]))

    def _wait(self) -> str:
        self.var.set("")
        self.root.wait_variable(self.var)
        return self.var.get()

    def begin(self, design: Design) -> None:
        self.label.config(text=(design.instructions.strip() or design.name) + "\n\nClick Start when ready.")
        self._buttons([("Start", "go", "\r")])
        if self._wait() == "quit":
            raise KeyboardInterrupt

    def respond(self, trial: TrialInfo) -> Response:
        keys = KEYS[trial.question]
        names = {
            "audio": "Sound first",
            "haptic": "Touch first",
            "simultaneous": "Simultaneous",
            "successive": "Not simultaneous",
        }
        self.label.config(text=PROMPTS[trial.question].split("[")[0].strip())
        self._buttons([(f"{names[v]} ({k})", v, k) for k, v in keys.items()])
        self.root.update()
        t0 = time.monotonic()
        answer = self._wait()
        rt = time.monotonic() - t0
        self.label.config(text="")
        self._buttons([])
        self.root.update()
        return Response(None if answer == "quit" else answer, rt)

    def rest(self, message: str) -> bool:
        self.label.config(text=message)
        self._buttons([("Continue", "go", "c"), ("Stop", "quit", "q")])
        return self._wait() != "quit"

    def end(self, message: str) -> None:
        self.label.config(text=message)
        self._buttons([])
        self.root.update()
        self.root.after(1500, self.root.destroy)
        self.root.mainloop()

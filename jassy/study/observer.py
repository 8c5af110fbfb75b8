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
from dataclasses import dataclass, field
from typing import Any

import numpy as np

from jassy.errors import JassyError
from jassy.study.design import ANSWERS, Design, ObserverSpec
from jassy.study.models import make_model

KEYS = {
    "toj": {"a": "audio", "h": "haptic"},
    "sj": {"s": "simultaneous", "n": "successive"},
    "2afc": {"1": "1", "2": "2"},
    "3afc": {"1": "1", "2": "2", "3": "3"},
}
PROMPTS = {
    "toj": "Which came first?  [a] audio (sound)   [h] haptic (touch)   [q] quit",
    "sj": "Were they simultaneous?  [s] simultaneous   [n] not simultaneous   [q] quit",
    "2afc": "Which interval was out of sync?  [1] first   [2] second   [q] quit",
    "3afc": "Which interval was out of sync?  [1] first   [2] second   [3] third   [q] quit",
}


@dataclass
class Response:
    """An answer (see jassy.study.design.ANSWERS; None = quit) and its time in seconds
    from the end of the stimulus."""

    answer: str | None
    time: float


@dataclass
class TrialInfo:
    """What a responder may know about the trial it answers."""

    index: int
    planned: int | None
    offset_ms: float  # the offset presented (measured), for simulated observers only
    task: str
    condition: dict[str, Any] = field(default_factory=dict)
    interval: int = 0  # m-AFC: the interval holding the asynchrony (simulated observers only)


class SimulatedObserver:
    """A model observer: answers drawn from the task's psychometric model
    (jassy.study.models) at the presented offset, with the parameters of ``spec`` in the
    trial's condition; seeded. Response times are drawn from a log-normal distribution
    (median 0.5 s) but not waited for."""

    def __init__(
        self, spec: ObserverSpec | None = None, seed: int | np.random.SeedSequence = 0, function: str = ""
    ):
        self.spec = spec or ObserverSpec()
        self.function = self.spec.function or function
        self.rng = np.random.default_rng(seed)

    def begin(self, design: Design) -> None:
        self.function = self.spec.function or design.function

    def respond(self, trial: TrialInfo) -> Response:
        model = make_model(trial.task, self.function or None)
        theta = self.spec.theta(model, trial.condition)
        positive = bool(self.rng.random() < float(model.prob(trial.offset_ms, **theta)))
        if trial.task in ("2afc", "3afc"):
            others = [i for i in range(1, model.alternatives + 1) if i != trial.interval]
            answer = str(trial.interval if positive else others[int(self.rng.integers(len(others)))])
        else:
            answer = ANSWERS[trial.task][1 if positive == (trial.task == "toj") else 0]
        return Response(answer, float(math.exp(self.rng.normal(math.log(0.5), 0.3))))

    def rest(self, message: str) -> bool:
        return True

    def feedback(self, message: str) -> None:
        pass

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

    def feedback(self, message: str) -> None:
        pass

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
        self.task = design.task
        if design.instructions:
            self._print(design.instructions.strip())
        self._print("Press any key to start.")
        self._read_key("abcdefghijklmnopqrstuvwxyz \n")

    def respond(self, trial: TrialInfo) -> Response:
        keys = KEYS[trial.task]
        counter = f"[{trial.index + 1}/{trial.planned}] " if trial.planned else f"[{trial.index + 1}] "
        self._print(counter + PROMPTS[trial.task])
        t0 = time.monotonic()
        key = self._read_key("".join(keys) + "q")
        rt = time.monotonic() - t0
        return Response(None if key == "q" else keys[key], rt)

    def feedback(self, message: str) -> None:
        self._print(message)

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
        keys = KEYS[trial.task]
        names = {
            "audio": "Sound first",
            "haptic": "Touch first",
            "simultaneous": "Simultaneous",
            "successive": "Not simultaneous",
            "1": "First",
            "2": "Second",
            "3": "Third",
        }
        self.label.config(text=PROMPTS[trial.task].split("[")[0].strip())
        self._buttons([(f"{names[v]} ({k})", v, k) for k, v in keys.items()])
        self.root.update()
        t0 = time.monotonic()
        answer = self._wait()
        rt = time.monotonic() - t0
        self.label.config(text="")
        self._buttons([])
        self.root.update()
        return Response(None if answer == "quit" else answer, rt)

    def feedback(self, message: str) -> None:
        self.label.config(text=message)
        self.root.update()
        self.root.after(700)

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

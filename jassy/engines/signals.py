"""Clean ends of live commands on SIGINT, SIGTERM and SIGHUP.

Inside :func:`stop_on_signals` the first of these signals raises :class:`Stopped` in the
main thread, so ``finally`` blocks run (the live engine fades forces to zero, sends its
final haptic frame, stops the stream and ends its child processes); the command then
exits with 128 + the signal number (130, 143, 129), the shell convention. Signals that
arrive while that cleanup runs are ignored: a second Ctrl-C cannot cut the fade short.
"""

from __future__ import annotations

import contextlib
import signal
from collections.abc import Iterator

#: The signals that end a live command in order.
ENDING_SIGNALS = (signal.SIGINT, signal.SIGTERM, signal.SIGHUP)


class Stopped(BaseException):
    """A live command was asked to stop by ``signum``; it exits with 128 + signum."""

    def __init__(self, signum: int):
        super().__init__(signal.Signals(signum).name)
        self.signum = signum

    @property
    def exit_code(self) -> int:
        return 128 + self.signum


@contextlib.contextmanager
def stop_on_signals() -> Iterator[None]:
    """Turn the first ending signal into :class:`Stopped`; ignore the ones after it."""
    received: list[int] = []

    def handler(signum, frame):
        if received:
            return
        received.append(signum)
        raise Stopped(signum)

    previous = {sig: signal.signal(sig, handler) for sig in ENDING_SIGNALS}
    try:
        yield
    finally:
        for sig, old in previous.items():
            signal.signal(sig, old)

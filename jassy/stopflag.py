"""A process-wide "stop requested" flag, set by the CLI's SIGTERM/SIGHUP handler.

The handler also raises KeyboardInterrupt, but Python runs a signal handler at the next
bytecode boundary, which can fall inside a finaliser (``__del__``, a weakref callback), where
an exception is printed and dropped. Long loops therefore also check the flag between chunks,
so a stop cannot be lost.
"""

from __future__ import annotations

import threading

requested = threading.Event()


def check() -> None:
    """Raise KeyboardInterrupt if a stop was requested."""
    if requested.is_set():
        raise KeyboardInterrupt

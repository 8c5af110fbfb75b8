"""The underrun floor of a JACK server: what a client that renders nothing gets.

A device callback that only writes silence cannot be late through its own work, so the
output underflows PortAudio flags for it are the host's: the server's cycle or the
client's thread woke too late (on a virtual machine, a virtual CPU that was not
running). ``jassy bench live --floor`` runs it for as long as the real run, on a server
of the same period, with the same busy Python main thread, and reads jackd's own
messages to split the late cycles by cause (:func:`jassy.engines.jackserver.server_xruns`).
"""

from __future__ import annotations

import os
import time
from collections.abc import Callable

import numba as nb
import numpy as np
from numba import types

from jassy.engines.callback import OUTPUT_UNDERFLOW

CALLBACKS, FLAGGED = range(2)


@nb.cfunc(
    types.int32(types.voidptr, types.voidptr, types.uint64, types.voidptr, types.uint64, types.voidptr),
    cache=True,
)
def silent_callback(inp, out, frames, time_info, status, user):
    """PortAudio callback: write ``frames`` frames of silence on 2 channels and count the
    callbacks and those flagged with an output underflow."""
    counts = nb.carray(user, (2,), np.int64)
    o = nb.carray(out, (frames * 2,), np.float32)
    for i in range(frames * 2):
        o[i] = 0.0
    counts[CALLBACKS] += 1
    if status & OUTPUT_UNDERFLOW:
        counts[FLAGGED] += 1
    return 0


def floor_run(seconds: float, sample_rate: int, block: int, busy: Callable[[float], object]) -> dict:
    """Play silence for ``seconds`` on a fresh JACK dummy server of ``block`` frames while
    ``busy(seconds)`` runs on this thread; the callbacks, those flagged late, and jackd's
    late cycles by cause (driver: its own timer; client: a client still busy)."""
    from jassy.engines import portaudio
    from jassy.engines.jackserver import dummy_jack, server_xruns

    counts = np.zeros(2, dtype=np.int64)
    with dummy_jack(f"jassy-floor-{os.getpid()}", sample_rate, block, channels=2) as server:
        stream = portaudio.OutputStream(
            portaudio.default_output_device(),
            2,
            sample_rate,
            block,
            silent_callback.address,
            counts.ctypes.data,
        )
        stream.start()
        before = server_xruns(server.log)
        t0 = time.monotonic()
        busy(seconds)
        elapsed = time.monotonic() - t0
        after = server_xruns(server.log)
        stream.close()
        portaudio.release()
    return {
        "floor_seconds": elapsed,
        "floor_callbacks": int(counts[CALLBACKS]),
        "floor_underruns": int(counts[FLAGGED]),
        "floor_driver_xruns": after.driver - before.driver,
        "floor_client_xruns": after.client - before.client,
    }

"""Keep the memory a real-time callback touches resident.

A page fault in the device callback costs a trip into the kernel, and a fault on a fresh
page may wait for the process's memory map lock while another thread of the process
allocates: a priority inversion in the middle of a buffer. Before the stream starts, the
arrays the callback reads and writes are locked in RAM with ``mlock`` (allowed for root,
CAP_IPC_LOCK or within RLIMIT_MEMLOCK) or, where that is refused, at least faulted in
for writing so the callback never meets a fresh zero page.
"""

from __future__ import annotations

import ctypes
import ctypes.util
from collections.abc import Iterable

import numpy as np

PAGE = 4096


def _libc():
    return ctypes.CDLL(ctypes.util.find_library("c") or "libc.so.6", use_errno=True)


def resident(arrays: Iterable[np.ndarray | memoryview]) -> tuple[int, int]:
    """Lock each array's pages in RAM, or fault them in for writing where mlock is
    refused. Returns (bytes locked, bytes only faulted in)."""
    libc = _libc()
    libc.mlock.argtypes = [ctypes.c_void_p, ctypes.c_size_t]
    locked = touched = 0
    for array in arrays:
        array = np.asarray(array)
        if array.size == 0 or not array.flags.c_contiguous:
            continue
        flat = array.reshape(-1).view(np.uint8)
        if libc.mlock(flat.ctypes.data, flat.size) == 0:
            locked += flat.size
            continue
        flat[::PAGE] |= 0  # a write to every page: each is now private and mapped
        if flat.size % PAGE:
            flat[-1] |= 0
        touched += flat.size
    return locked, touched

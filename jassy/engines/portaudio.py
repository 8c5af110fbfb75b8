"""A small, stable ctypes binding to the PortAudio C library (libportaudio2).

Only what jassy needs: opening an output stream whose callback is a C function pointer
(a numba ``@cfunc``), so the audio thread never enters Python; this binding is the path
that opens every live stream. Devices are listed and chosen by name through sounddevice
(:mod:`jassy.engines.devices`), on the same library, so the indices agree. It relies on
PortAudio's public, versioned C API only. Loading fails with a clear :class:`LiveError`
where the library is missing.
"""

from __future__ import annotations

import contextlib
import ctypes
import ctypes.util
import os
import time

from jassy.errors import JassyError

PA_FLOAT32 = 0x00000001
PA_CLIP_OFF = 0x00000001
PA_NO_DEVICE = -1


class LiveError(JassyError):
    """Live audio is unavailable or a stream could not be opened."""


class DeviceInfo(ctypes.Structure):
    _fields_ = [
        ("struct_version", ctypes.c_int),
        ("name", ctypes.c_char_p),
        ("host_api", ctypes.c_int),
        ("max_input_channels", ctypes.c_int),
        ("max_output_channels", ctypes.c_int),
        ("default_low_input_latency", ctypes.c_double),
        ("default_low_output_latency", ctypes.c_double),
        ("default_high_input_latency", ctypes.c_double),
        ("default_high_output_latency", ctypes.c_double),
        ("default_sample_rate", ctypes.c_double),
    ]


class StreamParameters(ctypes.Structure):
    _fields_ = [
        ("device", ctypes.c_int),
        ("channel_count", ctypes.c_int),
        ("sample_format", ctypes.c_ulong),
        ("suggested_latency", ctypes.c_double),
        ("host_api_specific_stream_info", ctypes.c_void_p),
    ]


class StreamInfo(ctypes.Structure):
    _fields_ = [
        ("struct_version", ctypes.c_int),
        ("input_latency", ctypes.c_double),
        ("output_latency", ctypes.c_double),
        ("sample_rate", ctypes.c_double),
    ]


@contextlib.contextmanager
def _quiet_stderr():
    """Silence the C library's stderr chatter (ALSA probing) during initialisation."""
    try:
        saved = os.dup(2)
    except OSError:
        yield
        return
    devnull = os.open(os.devnull, os.O_WRONLY)
    try:
        os.dup2(devnull, 2)
        yield
    finally:
        os.dup2(saved, 2)
        os.close(saved)
        os.close(devnull)


_LIB = None


def loaded() -> bool:
    """True once this process has initialised PortAudio."""
    return _LIB is not None


def library() -> ctypes.CDLL:
    """The initialised PortAudio library (loaded once)."""
    global _LIB
    if _LIB is not None:
        return _LIB
    name = ctypes.util.find_library("portaudio") or "libportaudio.so.2"
    try:
        lib = ctypes.CDLL(name)
    except OSError:
        raise LiveError(
            "live audio needs the PortAudio library (Debian/Ubuntu: apt-get install libportaudio2); "
            "offline rendering works without it"
        ) from None
    lib.Pa_GetErrorText.restype = ctypes.c_char_p
    lib.Pa_GetDeviceInfo.restype = ctypes.POINTER(DeviceInfo)
    lib.Pa_GetStreamInfo.restype = ctypes.POINTER(StreamInfo)
    lib.Pa_GetStreamInfo.argtypes = [ctypes.c_void_p]
    lib.Pa_GetStreamTime.restype = ctypes.c_double
    lib.Pa_GetStreamTime.argtypes = [ctypes.c_void_p]
    lib.Pa_OpenStream.argtypes = [
        ctypes.POINTER(ctypes.c_void_p),
        ctypes.POINTER(StreamParameters),
        ctypes.POINTER(StreamParameters),
        ctypes.c_double,
        ctypes.c_ulong,
        ctypes.c_ulong,
        ctypes.c_void_p,
        ctypes.c_void_p,
    ]
    for fn in ("Pa_StartStream", "Pa_StopStream", "Pa_AbortStream", "Pa_CloseStream", "Pa_IsStreamActive"):
        getattr(lib, fn).argtypes = [ctypes.c_void_p]
    with _quiet_stderr():
        check(lib, lib.Pa_Initialize(), "initialise PortAudio")
    _LIB = lib
    return lib


def release() -> None:
    """Terminate PortAudio in this process (closes its JACK client, if any); the next
    use initialises it again, e.g. against another JACK server."""
    global _LIB
    if _LIB is not None:
        _LIB.Pa_Terminate()
        _LIB = None


def check(lib: ctypes.CDLL, code: int, what: str) -> int:
    if code < 0:
        raise LiveError(f"cannot {what}: {lib.Pa_GetErrorText(code).decode(errors='replace')}")
    return code


def default_output_device() -> int:
    """PortAudio's default output device index (device listing and lookup by name:
    :mod:`jassy.engines.devices`, through sounddevice)."""
    lib = library()
    index = lib.Pa_GetDefaultOutputDevice()
    for _ in range(NO_DEVICE_TRIES):
        if index != PA_NO_DEVICE or lib.Pa_GetDeviceCount() > 0:
            break
        # no device at all (so no stream open here): a sound server that refused the
        # connection as PortAudio started (seen with JACK on a loaded machine); start again
        release()
        time.sleep(NO_DEVICE_PAUSE)
        lib = library()
        index = lib.Pa_GetDefaultOutputDevice()
    if index == PA_NO_DEVICE:
        raise LiveError("no default output device (see 'jassy devices')")
    return index


#: Restarts of PortAudio, NO_DEVICE_PAUSE s apart, while it finds no device at all.
NO_DEVICE_TRIES, NO_DEVICE_PAUSE = 10, 0.2


class OutputStream:
    """A float32 interleaved output stream driven by a C callback (its address)."""

    def __init__(
        self,
        device: int,
        channels: int,
        sample_rate: float,
        frames_per_buffer: int,
        callback_address: int,
        user_data: int,
        latency: float | None = None,
    ):
        lib = library()
        info = lib.Pa_GetDeviceInfo(device).contents
        if channels > info.max_output_channels:
            have = info.max_output_channels
            raise LiveError(f"device {info.name.decode()!r} has {have} output channels, {channels} needed")
        params = StreamParameters(
            device,
            channels,
            PA_FLOAT32,
            info.default_low_output_latency if latency is None else latency,
            None,
        )
        self._lib = lib
        self._stream = ctypes.c_void_p()
        check(
            lib,
            lib.Pa_OpenStream(
                ctypes.byref(self._stream),
                None,
                ctypes.byref(params),
                float(sample_rate),
                frames_per_buffer,
                PA_CLIP_OFF,
                ctypes.c_void_p(callback_address),
                ctypes.c_void_p(user_data),
            ),
            "open the output stream",
        )

    @property
    def output_latency(self) -> float:
        """Device output latency reported by PortAudio (s)."""
        return float(self._lib.Pa_GetStreamInfo(self._stream).contents.output_latency)

    def clock_offset(self, tries: int = 5) -> float:
        """Local monotonic time minus the stream clock (s), the clock of the callback's
        ``outputBufferDacTime``: from the tightest of a few paired readings."""
        import time

        best = (float("inf"), 0.0)
        for _ in range(tries):
            before = time.monotonic()
            stream_time = self._lib.Pa_GetStreamTime(self._stream)
            after = time.monotonic()
            best = min(best, (after - before, (before + after) / 2 - stream_time))
        return best[1]

    def start(self) -> None:
        check(self._lib, self._lib.Pa_StartStream(self._stream), "start the stream")

    def close(self) -> None:
        """Stop at once (pending buffers are dropped, not played) and close."""
        if self._stream:
            self._lib.Pa_AbortStream(self._stream)
            self._lib.Pa_CloseStream(self._stream)
            self._stream = ctypes.c_void_p()

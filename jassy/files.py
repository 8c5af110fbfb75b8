"""Atomic output files: write to a hidden temporary beside the target, then rename.

A failure or Ctrl-C (KeyboardInterrupt) removes the temporary, so nothing ever appears
under the requested name unless the whole file was written and flushed. A temporary
names the process that writes it (``.NAME.pPID.XXXX.partial``); one left by a process
that no longer runs (killed with SIGKILL, or a power cut) is removed by the next write
into the same folder. A full disk or any other write error is a RenderError naming the
file, and the old file, if any, stays as it was.
"""

from __future__ import annotations

import contextlib
import errno
import io
import os
import re
import struct
import tempfile
import zipfile
from collections.abc import Iterator
from pathlib import Path

import numpy as np

from jassy.errors import RenderError, suggest

AUDIO_FORMATS = {".wav": "WAV", ".flac": "FLAC"}
AUDIO_SUBTYPES = {"float32": "FLOAT", "pcm16": "PCM_16", "pcm24": "PCM_24"}


def _umask() -> int:
    mask = os.umask(0)
    os.umask(mask)
    return mask


#: A temporary written by :func:`atomic_path`: ``.NAME.pPID.RANDOM.partial`` (older
#: versions wrote ``.NAME.RANDOM.partial``, without the process id).
_PARTIAL = re.compile(r"^\..+?(?:\.p(\d+))?\.[A-Za-z0-9_]+\.partial$")


def _running(pid: int) -> bool:
    try:
        os.kill(pid, 0)
    except ProcessLookupError:
        return False
    except (PermissionError, OverflowError):
        return pid < 2**22  # a process of another user holds it (or a nonsense number)
    return True


def remove_stale_partials(directory: str | os.PathLike) -> list[str]:
    """Delete temporaries of :func:`atomic_path` in ``directory`` whose writer no longer
    runs (or, without a process id in the name, that are older than an hour); return their names."""
    import time

    removed = []
    try:
        entries = list(os.scandir(directory))
    except OSError:
        return removed
    for entry in entries:
        match = _PARTIAL.match(entry.name)
        if not match or not entry.is_file(follow_symlinks=False):
            continue
        pid = match.group(1)
        try:
            stale = not _running(int(pid)) if pid else time.time() - entry.stat().st_mtime > 3600
            if stale:
                os.unlink(entry.path)
                removed.append(entry.name)
        except OSError:
            continue
    return removed


def check_output(path: str | os.PathLike, option: str, extensions: tuple[str, ...] = ()) -> Path:
    """Fail before any work unless ``path`` can be written: a file name (not a directory)
    with one of ``extensions``, in an existing folder this process may write to."""
    text = os.fspath(path)
    if not isinstance(text, str) or not text.strip() or "\0" in text:
        raise RenderError(f"{option}: expected a file name, got {text!r}")
    p = Path(text)
    if text.endswith(os.sep) or p.is_dir():
        raise RenderError(f"{option}: {p} is a directory; expected a file name")
    if extensions and p.suffix.lower() not in extensions:
        raise RenderError(f"{option}: {p}: expected a {' or '.join(extensions)} file name")
    folder = p.parent if str(p.parent) else Path(".")
    if not folder.is_dir():
        raise RenderError(f"{option}: {p}: the folder {folder} does not exist")
    if not os.access(folder, os.W_OK | os.X_OK):
        raise RenderError(f"{option}: {p}: the folder {folder} is not writable")
    if p.exists() and not p.is_file():
        raise RenderError(f"{option}: {p} exists and is not a regular file")
    return p


def check_distinct(outputs: dict[str, str | os.PathLike | None]) -> None:
    """Refuse two options naming the same output file (one would overwrite the other)."""
    seen: dict[str, str] = {}
    for option, path in outputs.items():
        if path is None:
            continue
        key = os.path.realpath(os.fspath(path))
        if key in seen:
            raise RenderError(f"{option}: {path} is also the {seen[key]} output; name different files")
        seen[key] = option


@contextlib.contextmanager
def atomic_path(path: str | os.PathLike) -> Iterator[str]:
    """Yield a temporary path; on success rename it to ``path``, else delete it."""
    path = Path(path)
    directory = path.parent if str(path.parent) else Path(".")
    if not directory.is_dir():
        raise RenderError(f"{path}: directory {directory} does not exist")
    if path.is_dir():
        raise RenderError(f"{path}: is a directory; expected a file name")
    remove_stale_partials(directory)
    try:
        fd, tmp = tempfile.mkstemp(prefix=f".{path.name}.p{os.getpid()}.", suffix=".partial", dir=directory)
    except OSError as exc:
        raise RenderError(f"{path}: cannot create a file there ({exc.strerror})") from None
    os.close(fd)
    try:
        try:
            yield tmp
            with open(tmp, "rb+") as fh:
                os.fsync(fh.fileno())
            os.chmod(tmp, 0o666 & ~_umask())
            os.replace(tmp, path)
        except OSError as exc:
            raise RenderError(f"{path}: cannot write ({_reason(exc)})") from None
    except BaseException:
        with contextlib.suppress(OSError):
            os.unlink(tmp)
        raise


def _reason(exc: BaseException) -> str:
    """A short reason for a failed write (a full disk is named as such)."""
    if isinstance(exc, OSError) and exc.errno == errno.ENOSPC:
        return "no space left on the device"
    if isinstance(exc, OSError) and exc.strerror:
        return exc.strerror
    text = str(exc).strip().splitlines()
    return text[-1] if text else type(exc).__name__


#: Largest magnitude of a float32 sample; larger finite values would be stored as Inf.
FLOAT32_MAX = float(np.finfo(np.float32).max)


def clip_to_float32(data: np.ndarray, path: str | os.PathLike) -> tuple[np.ndarray, str | None]:
    """``data`` with values beyond the float32 range clipped to it, and a warning if any were."""
    over = np.abs(data) > FLOAT32_MAX
    if not np.any(over):
        return data, None
    peak = float(np.max(np.abs(data)))
    return np.clip(data, -FLOAT32_MAX, FLOAT32_MAX), (
        f"{path}: {int(over.sum())} sample(s) up to {peak:.3g} beyond the float32 range clipped to "
        f"+-{FLOAT32_MAX:.3g} (set a clamp, e.g. --max-force)"
    )


def _peak_time_offset(fh) -> int | None:
    """Offset of the time stamp in a WAV file's PEAK chunk (libsndfile writes the time of
    writing there for float data), or None."""
    fh.seek(0)
    head = fh.read(12)
    if len(head) < 12 or head[:4] != b"RIFF" or head[8:12] != b"WAVE":
        return None
    pos = 12
    while True:
        fh.seek(pos)
        header = fh.read(8)
        if len(header) < 8:
            return None
        chunk, size = header[:4], struct.unpack("<I", header[4:])[0]
        if chunk == b"PEAK" and size >= 8:
            return pos + 12
        if chunk == b"data":
            return None
        pos += 8 + size + (size & 1)


def deterministic_wav(data: bytes) -> bytes:
    """WAV bytes with the PEAK chunk's time stamp zeroed: the same signal, the same bytes."""
    offset = _peak_time_offset(io.BytesIO(data))
    if offset is None:
        return data
    return data[:offset] + b"\0\0\0\0" + data[offset + 4 :]


def deterministic_npz(data: bytes) -> bytes:
    """An .npz (zip) with its members' time stamps set to 1980-01-01."""
    src = zipfile.ZipFile(io.BytesIO(data))
    out = io.BytesIO()
    with zipfile.ZipFile(out, "w") as dst:
        for info in src.infolist():
            fixed = zipfile.ZipInfo(info.filename, date_time=(1980, 1, 1, 0, 0, 0))
            fixed.compress_type, fixed.external_attr = info.compress_type, info.external_attr
            dst.writestr(fixed, src.read(info))
    return out.getvalue()


def deterministic_bytes(data: bytes) -> bytes:
    """File bytes without the time of writing (WAV PEAK time stamps, NPZ member dates)."""
    if data[:4] == b"PK\x03\x04":
        return deterministic_npz(data)
    return deterministic_wav(data)


def audio_format(path: str | os.PathLike, sample_format: str = "float32") -> tuple[str, str]:
    """(soundfile format, subtype) for an output path and sample format name."""
    ext = Path(path).suffix.lower()
    if ext not in AUDIO_FORMATS:
        raise RenderError(f"{path}: expected a .wav or .flac file name")
    if sample_format not in AUDIO_SUBTYPES:
        raise RenderError(
            f"--format: expected one of {', '.join(AUDIO_SUBTYPES)}, got {sample_format!r}"
            f"{suggest(sample_format, AUDIO_SUBTYPES)}"
        )
    fmt, subtype = AUDIO_FORMATS[ext], AUDIO_SUBTYPES[sample_format]
    if fmt == "FLAC" and subtype == "FLOAT":
        raise RenderError(f"{path}: FLAC stores integers; use --format pcm16 or pcm24")
    return fmt, subtype


class AtomicAudioWriter:
    """Stream frames into a WAV/FLAC file that appears only when complete.

    Use as a context manager; ``write(block)`` takes (channels, frames) float arrays,
    which must be finite and within [-1, 1] (the engine's limiter guarantees both).
    """

    def __init__(
        self, path: str | os.PathLike, sample_rate: int, channels: int, sample_format: str = "float32"
    ):
        import soundfile

        self.path = Path(path)
        self.format, self.subtype = audio_format(path, sample_format)
        self._ctx = atomic_path(self.path)
        self._tmp = self._ctx.__enter__()
        try:
            self._file = soundfile.SoundFile(
                self._tmp, "w", int(sample_rate), channels, self.subtype, format=self.format
            )
        except BaseException:
            self._ctx.__exit__(*__import__("sys").exc_info())
            raise

    def write(self, block: np.ndarray) -> None:
        if not np.all(np.isfinite(block)):
            raise RenderError(f"{self.path}: refusing to write non-finite samples")
        try:
            self._file.write(np.ascontiguousarray(block.T, dtype=np.float32))
        except (RuntimeError, OSError) as exc:  # soundfile.LibsndfileError is a RuntimeError
            raise RenderError(f"{self.path}: cannot write ({_reason(exc)})") from None

    def __enter__(self) -> AtomicAudioWriter:
        return self

    def __exit__(self, exc_type, exc, tb) -> bool:
        try:
            self._file.close()
        except (RuntimeError, OSError) as error:
            failure = RenderError(f"{self.path}: cannot write ({_reason(error)})")
            self._ctx.__exit__(RenderError, failure, None)
            if exc_type is None:
                raise failure from None
            return False
        if exc_type is None and self.format == "WAV":
            with open(self._tmp, "r+b") as fh:  # the same render gives the same bytes
                offset = _peak_time_offset(fh)
                if offset is not None:
                    fh.seek(offset)
                    fh.write(b"\0\0\0\0")
        return bool(self._ctx.__exit__(exc_type, exc, tb))


def write_signal(
    path: str | os.PathLike, data: np.ndarray, sample_rate: float, label: str | list[str] = "force"
) -> str | None:
    """Write a (channels, frames) signal atomically as .wav (float32), .npz or .csv.

    NPZ holds ``data``, ``sample_rate`` and ``frames`` (sample index of each column);
    CSV has columns frame, time_s and one per channel, named ``label`` + index, or by the
    list of names ``label``. Values beyond the float32 range of a .wav are clipped to it;
    the warning saying so is returned (else None).
    """
    path = Path(path)
    if not np.all(np.isfinite(data)):
        raise RenderError(f"{path}: refusing to write non-finite samples")
    ext = path.suffix.lower()
    warning = None
    if ext == ".wav":
        data, warning = clip_to_float32(data, path)
    frames = np.arange(data.shape[1])
    with atomic_path(path) as tmp:
        if ext == ".wav":
            import soundfile

            buffer = io.BytesIO()
            soundfile.write(buffer, data.T.astype(np.float32), int(sample_rate), "FLOAT", format="WAV")
            Path(tmp).write_bytes(deterministic_wav(buffer.getvalue()))
        elif ext == ".npz":
            buffer = io.BytesIO()
            np.savez(buffer, data=data, sample_rate=np.float64(sample_rate), frames=frames)
            Path(tmp).write_bytes(deterministic_npz(buffer.getvalue()))
        elif ext == ".csv":
            cols = [frames, frames / sample_rate, *data]
            names = [f"{label}{c}" for c in range(data.shape[0])] if isinstance(label, str) else list(label)
            if len(names) != data.shape[0]:
                raise RenderError(f"{path}: {len(names)} column names for {data.shape[0]} channels")
            header = ",".join(["frame", "time_s", *names])
            row = ",".join(["%d", "%.9f"] + ["%.9g"] * data.shape[0]) + "\n"
            values = [v for line in zip(*(c.tolist() for c in cols), strict=True) for v in line]
            # one % over all rows: what np.savetxt writes, without its per-row Python loop
            Path(tmp).write_text(header + "\n" + (row * len(frames)) % tuple(values))
        else:
            raise RenderError(f"{path}: expected a .wav, .npz or .csv file name")
    return warning

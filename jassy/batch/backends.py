"""Rendering batch variants on workers: the task, the worker function and the backends.

A :class:`Task` is self-contained: the patch data with the variant's overrides applied and
the bytes of its model files, so a worker needs jassy installed but no access to the
grid's files; it returns the rendered file's bytes and the client writes them. Workers
render with :meth:`jassy.engines.offline.OfflineEngine.render_to_file`, exactly like
``jassy render``, so a variant's file does not depend on which worker rendered it
(jassy.files fixes the time stamps libsndfile and numpy would write into the files).

Backends, all with the same results:

* ``serial``: in this process.
* ``pool``: local worker processes (``multiprocessing``, forked from a fork server that
  has jassy imported); a worker that dies is replaced and its chunk is rendered again.
* ``dask``: a Dask ``distributed`` cluster, a LocalCluster started here or an existing one
  (``tcp://HOST:PORT``); Dask reschedules the tasks of a worker that dies.

Variants are submitted in chunks (several variants per task) to cut the per-task
overhead; a chunk whose worker keeps dying is split so only the culprit variant fails.
"""

from __future__ import annotations

import atexit
import contextlib
import logging
import os
import shutil
import socket
import tempfile
import threading
import time
import tomllib
import warnings
from collections.abc import Callable, Iterable
from dataclasses import dataclass
from pathlib import Path
from typing import Any

from jassy.batch.grid import RenderOptions, Variant, apply_overrides, sha256_bytes
from jassy.errors import JassyError, PatchError, RenderError

DEFAULT_RATE = 48000
#: Attempts of a chunk whose worker died before it is split (or a single variant fails).
MAX_ATTEMPTS = 3

Result = dict[str, Any]
RenderFn = Callable[["Task"], Result]


@dataclass(frozen=True)
class Task:
    """Everything a worker needs to render one variant."""

    index: int
    id: str
    patch: str
    source: str
    data: dict
    blobs: dict[str, bytes]
    render: RenderOptions


class BlobReader:
    """Model file bytes, read once per file (the same bytes object is shared by all tasks)."""

    def __init__(self):
        self.cache: dict[Path, bytes] = {}

    def __call__(self, path: Path, digest: str) -> bytes:
        key = path.resolve()
        if key not in self.cache:
            data = key.read_bytes()
            if sha256_bytes(data) != digest:
                raise RenderError(f"{path}: model file changed while the batch was being planned")
            self.cache[key] = data
        return self.cache[key]


def make_task(variant: Variant, grid_dir: Path, blobs: BlobReader) -> Task:
    """The task of one variant: overrides applied, model files carried as bytes."""
    data = apply_overrides(variant.patch.data, variant.overrides, grid_dir)
    carried = {}
    for name, path in variant.model_files.items():
        digest = variant.model_digests[name]
        blob = f"{digest[:32]}{path.suffix.lower()}"
        data["models"][name] = {"file": blob}
        carried[blob] = blobs(path, digest)
    return Task(
        variant.index, variant.id, variant.patch.name, variant.patch.source, data, carried, variant.render
    )


# ------------------------------------------------------------------------------ worker

_BLOB_DIR: Path | None = None
_BLOB_LOCK = threading.Lock()


def _blob_dir() -> Path:
    global _BLOB_DIR
    with _BLOB_LOCK:
        if _BLOB_DIR is None:
            path = tempfile.mkdtemp(prefix="jassy-batch-models-")
            atexit.register(shutil.rmtree, path, True)
            _BLOB_DIR = Path(path)
    return _BLOB_DIR


def _materialize(blobs: dict[str, bytes]) -> Path:
    """Write model blobs (named by content hash) into this process's cache directory."""
    directory = _blob_dir()
    for name, data in blobs.items():
        path = directory / name
        if not path.exists():
            tmp = directory / f".{name}.{os.getpid()}.{threading.get_ident()}"
            tmp.write_bytes(data)
            os.replace(tmp, path)
    return directory


_PARSED: dict[str, dict] = {}


def _inline_toml_models(task: Task) -> dict:
    """The task's patch data with its TOML model files inlined, parsed once per process.

    A patch loads ``file = "x.toml"`` models with ``ModalModel.from_dict`` of the parsed file,
    exactly as an inline model table; parsing a large model file for every variant would
    cost more than rendering a short one.
    """
    models = task.data.get("models")
    if not isinstance(models, dict):
        return task.data
    inlined = dict(models)
    for name, entry in models.items():
        blob = entry.get("file") if isinstance(entry, dict) else None
        if isinstance(blob, str) and blob.endswith(".toml") and blob in task.blobs:
            if blob not in _PARSED:
                _PARSED[blob] = tomllib.loads(task.blobs[blob].decode("utf-8"))
            inlined[name] = _PARSED[blob]
    return {**task.data, "models": inlined}


def worker_name() -> str:
    return f"{socket.gethostname()}:{os.getpid()}"


def render_task(task: Task) -> Result:
    """Render one variant. Never raises for a bad variant: returns status "error" and the message.

    Result keys: index, id, status, error, audio (file bytes), haptic (bytes or None),
    frames, duration, sample_rate, peak, haptic_peak, warnings, render_s, worker.
    """
    from jassy.engines.offline import OfflineEngine
    from jassy.patchfile import build_patch

    t0 = time.perf_counter()
    result: Result = {"index": task.index, "id": task.id, "worker": worker_name()}
    try:
        base = _materialize(task.blobs)
        patch = build_patch(_inline_toml_models(task), task.source, base)
        opts = task.render
        rate = opts.sample_rate or patch.sample_rate or DEFAULT_RATE
        duration = opts.duration or patch.duration
        if duration is None:
            raise PatchError(f"{task.source}: the patch sets no duration; give render.duration in the grid")
        if opts.haptic and not patch.graph.haptic:
            raise PatchError(f"{task.source}: render.haptic: the patch has no haptic output")
        with tempfile.TemporaryDirectory(prefix="jassy-batch-") as tmp:
            audio_path = Path(tmp) / f"audio.{opts.container}"
            haptic_path = Path(tmp) / f"force.{opts.haptic}" if opts.haptic else None
            engine = OfflineEngine(patch.graph, patch.score, rate, opts.block)
            summary = engine.render_to_file(audio_path, duration, opts.format, haptic_path)
            audio = audio_path.read_bytes()  # jassy.files writes deterministic bytes
            haptic = haptic_path.read_bytes() if haptic_path else None
        result.update(
            status="ok",
            error="",
            audio=audio,
            haptic=haptic,
            frames=summary["frames"],
            duration=summary["duration"],
            sample_rate=rate,
            peak=summary["peak"],
            haptic_peak=summary["haptic_peak"],
            warnings=summary["warnings"],
        )
    except JassyError as exc:
        result.update(status="error", error=str(exc))
    except Exception as exc:  # a bug or a resource problem: recorded, the batch goes on
        result.update(status="error", error=f"{type(exc).__name__}: {exc}")
    result["render_s"] = time.perf_counter() - t0
    return result


def error_result(task: Task, message: str) -> Result:
    return {"index": task.index, "id": task.id, "status": "error", "error": message, "worker": ""}


def render_chunk(render: RenderFn, tasks: list[Task]) -> list[Result]:
    """Render the tasks of one chunk in order; an exception fails its variant only."""
    out = []
    for task in tasks:
        try:
            out.append(render(task))
        except Exception as exc:
            out.append(error_result(task, f"{type(exc).__name__}: {exc}"))
    return out


def chunked(tasks: list[Task], size: int) -> list[list[Task]]:
    return [tasks[i : i + size] for i in range(0, len(tasks), size)]


# ----------------------------------------------------------------------------- backends


def run_serial(chunks: Iterable[list[Task]], render: RenderFn, on_result: Callable[[Result], None]) -> None:
    for chunk in chunks:
        for task in chunk:
            on_result(render_chunk(render, [task])[0])


def _pool_worker(render: RenderFn, conn) -> None:  # pragma: no cover (runs in a child process)
    with contextlib.suppress(KeyboardInterrupt, EOFError, BrokenPipeError):
        conn.send(("ready", None, None))
        while True:
            item = conn.recv()
            if item is None:
                return
            key, chunk = item
            conn.send(("started", key, None))
            conn.send(("done", key, render_chunk(render, chunk)))


class _Slot:
    """One worker process of the pool, its pipe and the chunk it runs."""

    def __init__(self, ctx, render):
        self.conn, child = ctx.Pipe()
        self.process = ctx.Process(target=_pool_worker, args=(render, child), daemon=True)
        self.process.start()
        child.close()
        self.ready = self.started = False
        self.key: int | None = None


#: Imported once by the fork server, so pool workers start warm (numba's kernels loaded).
PRELOAD = ["jassy.batch.backends", "jassy.patchfile", "jassy.batch.warmup"]


def _pool_context(multiprocessing):
    """A fork server that has jassy imported (fast, clean starts); spawn where there is none."""
    try:
        ctx = multiprocessing.get_context("forkserver")
    except ValueError:  # pragma: no cover (Windows)
        return multiprocessing.get_context("spawn")
    ctx.set_forkserver_preload(PRELOAD)
    return ctx


def run_pool(
    chunks: list[list[Task]],
    render: RenderFn,
    on_result: Callable[[Result], None],
    workers: int,
) -> None:
    """Render chunks on ``workers`` local processes; a dead worker is replaced and its chunk rerun.

    Each worker has its own pipe and runs one chunk at a time, so the chunk of a worker that
    dies is known exactly; it is charged an attempt only if the worker had started it.
    """
    import multiprocessing
    from multiprocessing.connection import wait

    ctx = _pool_context(multiprocessing)
    pending = [(chunk, 0) for chunk in chunks]
    running: dict[int, tuple[list[Task], int]] = {}
    next_key = 0
    slots = [_Slot(ctx, render) for _ in range(max(1, min(workers, len(chunks))))]
    ever_ready, early_deaths = False, 0

    def receive(slot: _Slot) -> bool:
        """Handle one message from ``slot``; False when its pipe is closed."""
        nonlocal ever_ready
        try:
            kind, key, rows = slot.conn.recv()
        except (EOFError, OSError):
            return False
        if kind == "ready":
            slot.ready = ever_ready = True
        elif kind == "started":
            slot.started = True
        elif kind == "done" and key in running:
            running.pop(key)
            slot.key, slot.started = None, False
            for row in rows:
                on_result(row)
        return True

    try:
        while pending or running:
            for slot in slots:
                if slot.ready and slot.key is None and pending:
                    chunk, attempts = pending.pop(0)
                    slot.key, next_key = next_key, next_key + 1
                    running[slot.key] = (chunk, attempts)
                    slot.conn.send((slot.key, chunk))
            ready = wait([s.conn for s in slots] + [s.process.sentinel for s in slots], timeout=1.0)
            for i, slot in enumerate(slots):
                alive = True
                if slot.conn in ready:
                    alive = receive(slot)
                if alive and slot.process.sentinel not in ready:
                    continue
                while alive and slot.conn.poll():  # what the worker sent before it died
                    alive = receive(slot)
                slot.process.join(timeout=1.0)
                code = slot.process.exitcode
                if not slot.ready:
                    early_deaths += 1
                    if early_deaths >= 3 and not ever_ready:
                        raise RenderError(
                            f"batch worker processes exit as they start (exit code {code}); a script that "
                            "calls run_batch must do so under if __name__ == '__main__'"
                        )
                if slot.key is not None and slot.key in running:
                    chunk, attempts = running.pop(slot.key)
                    if slot.started:
                        _retry(
                            chunk, attempts + 1, pending, on_result, f"worker process died (exit code {code})"
                        )
                    else:
                        pending.insert(0, (chunk, attempts))
                slot.conn.close()
                slots[i] = _Slot(ctx, render)
    finally:
        for slot in slots:
            with contextlib.suppress(OSError, ValueError):
                slot.conn.send(None)
        deadline = time.monotonic() + (5.0 if not running else 0.0)
        for slot in slots:
            slot.process.join(timeout=max(0.0, deadline - time.monotonic()))
            if slot.process.is_alive():
                slot.process.terminate()
                slot.process.join(timeout=2.0)
            slot.conn.close()


def _retry(chunk: list[Task], attempts: int, pending: list, on_result: Callable[[Result], None], why: str):
    """Requeue a chunk whose worker died; split it after MAX_ATTEMPTS; fail a lone variant then."""
    if attempts < MAX_ATTEMPTS:
        pending.append((chunk, attempts))
    elif len(chunk) > 1:
        pending.extend(([task], 0) for task in chunk)
    else:
        on_result(error_result(chunk[0], f"{why} {attempts} times while rendering this variant"))


def local_cluster(workers: int):
    """A Dask LocalCluster of ``workers`` single-threaded worker processes, started warm.

    The worker processes are forked from the fork server of the process pool (which has
    jassy imported and its kernels loaded, see :data:`PRELOAD`) instead of spawned
    fresh, so each starts in a fraction of a second rather than paying the warm-up.
    """
    import multiprocessing

    import dask
    from distributed import LocalCluster

    method = "spawn"
    with contextlib.suppress(ValueError):
        _pool_context(multiprocessing)
        method = "forkserver"
    try:
        with (
            dask.config.set({"distributed.worker.multiprocessing-method": method}),
            warnings.catch_warnings(),  # "port 8787 is in use": another HTTP port is picked
        ):
            warnings.filterwarnings("ignore", message="Port .* is already in use", category=UserWarning)
            return LocalCluster(
                n_workers=workers,
                threads_per_worker=1,
                processes=True,
                dashboard_address=None,
                silence_logs=logging.ERROR,
            )
    except RuntimeError as exc:
        raise RenderError(
            f"dask: cannot start a LocalCluster ({exc}); a script that calls run_batch must do so "
            "under if __name__ == '__main__'"
        ) from None


def connect_dask(scheduler: str | None, workers: int):
    """A Dask client: to ``scheduler`` (tcp://HOST:PORT) or to a new LocalCluster of ``workers``.

    Returns (client, cluster or None, description). Raises ImportError without distributed.
    """
    from distributed import Client

    if scheduler:
        try:
            client = Client(scheduler, timeout="10s", set_as_default=False)
        except (OSError, TimeoutError) as exc:
            raise JassyError(f"--scheduler {scheduler}: cannot connect ({exc})") from None
        return client, None, f"dask cluster {scheduler} ({dask_threads(client)} worker threads)"
    cluster = local_cluster(workers)
    try:
        client = Client(cluster, set_as_default=False)
    except BaseException:
        cluster.close()
        raise
    return client, cluster, f"dask LocalCluster ({workers} workers)"


def dask_threads(client) -> int:
    return max(1, sum(w.get("nthreads", 1) for w in client.scheduler_info()["workers"].values()))


def run_dask(
    client,
    chunks: list[list[Task]],
    render: RenderFn,
    on_result: Callable[[Result], None],
) -> None:
    """Render chunks on a Dask cluster; chunks lost with a worker are rescheduled by Dask."""
    from concurrent.futures import CancelledError

    from distributed import as_completed

    owner: dict[str, tuple[list[Task], int]] = {}
    futures = as_completed(loop=client.loop)

    def submit(chunk: list[Task], attempts: int) -> None:
        fut = client.submit(render_chunk, render, chunk, pure=False, retries=0)
        owner[fut.key] = (chunk, attempts)
        futures.add(fut)

    for chunk in chunks:
        submit(chunk, 0)
    try:
        for fut in futures:
            chunk, attempts = owner.pop(fut.key)
            try:
                rows = fut.result()
            except CancelledError:
                raise RenderError("dask: a task was cancelled (did the cluster shut down?)") from None
            except Exception as exc:  # KilledWorker (Dask already retried) or a lost connection
                if not client.status == "running":
                    raise RenderError(f"dask: lost the cluster ({exc})") from None
                if len(chunk) > 1:
                    for task in chunk:
                        submit([task], attempts + 1)
                else:
                    on_result(error_result(chunk[0], f"worker died while rendering this variant ({exc})"))
                continue
            finally:
                fut.release()
            for row in rows:
                on_result(row)
    finally:
        with contextlib.suppress(Exception):
            client.cancel(list(futures.futures))

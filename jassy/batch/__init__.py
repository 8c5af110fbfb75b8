"""``jassy batch``: render a grid or random sweep of patch variants, on all cores or a Dask cluster.

::

    jassy batch GRID.toml -o OUTDIR                          # all local cores (Dask LocalCluster)
    jassy batch GRID.toml -o OUTDIR --scheduler tcp://host:8786   # an existing Dask cluster
    jassy batch GRID.toml -o OUTDIR --scheduler pool         # local processes, no Dask

One file per variant (``<patch>-<id12>.wav``, the id a hash of patch content, overrides
and render options) plus ``manifest.csv`` (and ``manifest.parquet`` if asked for): the
variant's parameters, output file, duration, peak, SHA-256 of the file, and the error if
it failed. Outputs and the manifest are written atomically and the manifest is kept up to
date while the batch runs, so a rerun skips every variant whose file is there with the
recorded hash, and renders only the rest (failed variants are tried again). The grid
format is described in :mod:`jassy.batch.grid`; the backends in :mod:`jassy.batch.backends`.
"""

from __future__ import annotations

import argparse
import contextlib
import math
import os
import sys
import tempfile
import time
from collections.abc import Callable
from dataclasses import dataclass, field
from pathlib import Path

from jassy.batch.backends import (
    BlobReader,
    RenderFn,
    Result,
    chunked,
    connect_dask,
    dask_threads,
    make_task,
    render_task,
    run_dask,
    run_pool,
    run_serial,
)
from jassy.batch.grid import Grid, load_grid, sha256_bytes, sha256_file
from jassy.batch.manifest import (
    Journal,
    Row,
    columns,
    have_pyarrow,
    peak_dbfs,
    read_rows,
    text,
    write_csv,
    write_parquet,
)
from jassy.errors import JassyError, RenderError
from jassy.files import atomic_path

#: Seconds between rewrites of the manifest while a batch runs (the journal has every row at once).
FLUSH_SECONDS = 2.0
MAX_CHUNK = 16
SCHEDULERS = ("local", "pool", "serial")
LOCK = ".jassy-batch.lock"


@dataclass
class BatchResult:
    """What a batch did: counts, where the manifest is, the first errors."""

    grid: Grid
    outdir: Path
    manifest: Path
    backend: str
    total: int = 0
    skipped: int = 0
    rendered: int = 0
    failed: int = 0
    elapsed: float = 0.0
    errors: list[tuple[str, str, str]] = field(default_factory=list)  # (variant, patch, error)
    parquet: Path | None = None

    @property
    def rate(self) -> float:
        """Variants rendered (or failed) per minute of wall time."""
        done = self.rendered + self.failed
        return 60.0 * done / self.elapsed if self.elapsed > 0 else 0.0


def have_dask() -> bool:
    """True if Dask's distributed scheduler can be imported (the ``dist`` extra)."""
    try:
        import distributed  # noqa: F401
    except ImportError:
        return False
    return True


def local_cores() -> int:
    try:
        return len(os.sched_getaffinity(0))
    except AttributeError:  # pragma: no cover (not Linux)
        return os.cpu_count() or 1


def _choose_backend(scheduler: str | None, workers: int, client) -> str:
    if client is not None:
        return "dask"
    if scheduler is None:
        scheduler = "local" if workers > 1 else "serial"
    if "://" in scheduler:
        if not have_dask():
            raise JassyError(
                f"--scheduler {scheduler}: a Dask cluster needs Dask (pip install 'jassy[dist]')"
            )
        return "dask-remote"
    if scheduler not in SCHEDULERS:
        raise JassyError(
            f"--scheduler: expected tcp://HOST:PORT of a Dask scheduler or one of {', '.join(SCHEDULERS)}, "
            f"got {scheduler!r}"
        )
    if scheduler == "local":
        return "dask" if have_dask() else "pool"
    return scheduler


class _Lock:
    """An exclusive lock on OUTDIR, so two batches never write the same manifest."""

    def __init__(self, outdir: Path):
        try:
            import fcntl
        except ImportError:  # pragma: no cover (Windows: no lock)
            self._fh = None
            return
        self._fh = open(outdir / LOCK, "a")  # noqa: SIM115 (closed in release())
        try:
            fcntl.flock(self._fh, fcntl.LOCK_EX | fcntl.LOCK_NB)
        except OSError:
            self._fh.close()
            raise JassyError(f"{outdir}: another jassy batch is writing to this directory") from None

    def release(self) -> None:
        if self._fh is not None:
            self._fh.close()


def _is_done(row: Row | None, outdir: Path, verify: bool) -> bool:
    """A variant is done when the manifest says ok and its file(s) exist with the recorded hash."""
    if row is None or row.get("status") != "ok" or not row.get("output") or not row.get("sha256"):
        return False
    files = [(row["output"], row["sha256"])]
    if row.get("haptic_output"):
        files.append((row["haptic_output"], row.get("haptic_sha256", "")))
    for name, digest in files:
        path = outdir / name
        if not path.is_file():
            return False
        if verify and sha256_file(path) != digest:
            return False
    return True


class _Recorder:
    """Receives results from workers: writes files, keeps rows, the journal and the manifest."""

    def __init__(self, grid: Grid, outdir: Path, rows: dict[str, Row], cols: list[str], bar, journal):
        self.grid, self.outdir, self.rows, self.cols = grid, outdir, rows, cols
        self.by_id = {v.id: v for v in grid.variants}
        self.bar, self.journal = bar, journal
        self.rendered = self.failed = 0
        self.errors: list[tuple[str, str, str]] = []
        self.seen: set[str] = set()
        self.last_flush = time.monotonic()

    def __call__(self, result: Result) -> None:
        variant = self.by_id[result["id"]]
        if variant.id in self.seen:  # a chunk rendered twice (its worker died after sending)
            return
        self.seen.add(variant.id)
        row = dict(self.rows[variant.id])
        row.update(status=result["status"], error=result.get("error", ""), worker=result.get("worker", ""))
        if result["status"] == "ok":
            try:
                row["sha256"] = self._write(variant.filename, result["audio"])
                row["output"] = variant.filename
                if variant.haptic_filename and result.get("haptic") is not None:
                    row["haptic_sha256"] = self._write(variant.haptic_filename, result["haptic"])
                    row["haptic_output"] = variant.haptic_filename
            except (OSError, JassyError) as exc:
                row.update(status="error", error=f"cannot write the output: {exc}")
        if row["status"] == "ok":
            row.update(
                duration=text(result["duration"]),
                sample_rate=text(result["sample_rate"]),
                frames=text(result["frames"]),
                peak=text(result["peak"]),
                peak_dbfs=peak_dbfs(result["peak"]),
                warnings="; ".join(result.get("warnings", [])),
            )
            self.rendered += 1
        else:
            for key in ("output", "sha256", "haptic_output", "haptic_sha256", "peak", "peak_dbfs", "frames"):
                row[key] = ""
            self.failed += 1
            if len(self.errors) < 20:
                self.errors.append((variant.id, variant.patch.name, row["error"]))
        if "render_s" in result:
            row["render_s"] = f"{result['render_s']:.4f}"
        self.rows[variant.id] = row
        self.journal.append(row)
        if self.bar is not None:
            self.bar.update(1)
            if self.failed:
                self.bar.set_postfix(failed=self.failed, refresh=False)
        if time.monotonic() - self.last_flush > FLUSH_SECONDS:
            self.flush()

    def _write(self, name: str, data: bytes) -> str:
        with atomic_path(self.outdir / name) as tmp, open(tmp, "wb") as fh:
            fh.write(data)
        return sha256_bytes(data)

    def ordered(self) -> list[Row]:
        return [self.rows[v.id] for v in self.grid.variants]

    def flush(self) -> None:
        write_csv(self.outdir, self.ordered(), self.cols)
        self.journal.clear()
        self.last_flush = time.monotonic()


def run_batch(
    grid: str | os.PathLike | Grid,
    outdir: str | os.PathLike,
    *,
    scheduler: str | None = None,
    workers: int | None = None,
    chunk: int | None = None,
    force: bool = False,
    verify: bool = True,
    parquet: bool | None = None,
    progress: bool = False,
    render: RenderFn = render_task,
    client=None,
    log: Callable[[str], None] | None = None,
) -> BatchResult:
    """Render every variant of ``grid`` not yet done in ``outdir``; write files and the manifest.

    scheduler: None or "local" (a Dask LocalCluster of ``workers`` processes, or a process
    pool without Dask; serial if ``workers`` is 1), "pool", "serial", or the address of a
    Dask scheduler (tcp://HOST:PORT). ``client``: an existing ``distributed.Client`` to use.
    ``render``: the per-variant function run on workers (for tests; must be importable there).
    """
    grid = grid if isinstance(grid, Grid) else load_grid(grid)
    outdir = Path(outdir)
    workers = local_cores() if workers is None else workers
    most = max(64, 8 * local_cores())  # local processes: more only thrash the machine
    if isinstance(workers, bool) or not isinstance(workers, int) or not 1 <= workers <= most:
        raise JassyError(f"--workers: expected an integer in [1, {most}], got {workers!r}")
    if chunk is not None and (isinstance(chunk, bool) or not isinstance(chunk, int) or chunk < 1):
        raise JassyError(f"--chunk: expected an integer >= 1, got {chunk!r}")
    backend = _choose_backend(scheduler, workers, client)
    want_parquet = grid.manifest == "parquet" if parquet is None else parquet
    if want_parquet and not have_pyarrow():
        raise JassyError("a Parquet manifest needs pyarrow (pip install pyarrow); the CSV manifest does not")
    try:
        outdir.mkdir(parents=True, exist_ok=True)
    except OSError as exc:
        raise RenderError(f"{outdir}: cannot create the output directory ({exc.strerror})") from None
    haptic = any(v.render.haptic for v in grid.variants)
    cols = columns(grid.columns, haptic)

    t0 = time.perf_counter()
    lock = _Lock(outdir)
    try:
        old = {} if force else read_rows(outdir)
        rows: dict[str, Row] = {}
        todo = []
        for v in grid.variants:
            row = {"index": str(v.index), "variant": v.id, "patch": v.patch.name}
            row.update({c: text(v.labels.get(c)) for c in grid.columns})
            prev = old.get(v.id)
            if _is_done(prev, outdir, verify):
                rows[v.id] = {**prev, **row}
            else:
                rows[v.id] = {**row, "status": "pending"}
                todo.append(v)
        result = BatchResult(grid, outdir, outdir / "manifest.csv", backend, total=len(grid.variants))
        result.skipped = len(grid.variants) - len(todo)
        if not todo:
            result.backend = "nothing to render"
        journal = Journal(outdir)
        bar = None
        if progress and todo:
            from tqdm import tqdm

            bar = tqdm(total=len(todo), unit="variant", desc=grid.name, delay=0.5, file=sys.stderr)
        recorder = _Recorder(grid, outdir, rows, cols, bar, journal)
        completed = False
        try:
            recorder.flush()
            if todo:
                result.backend = _execute(
                    grid, todo, backend, scheduler, workers, chunk, render, recorder, client
                )
            completed = True
        finally:
            if bar is not None:
                bar.close()
            recorder.flush()
            journal.close(remove=True)
            if want_parquet:
                result.parquet = write_parquet(outdir, recorder.ordered(), cols)
            result.rendered, result.failed, result.errors = (
                recorder.rendered,
                recorder.failed,
                recorder.errors,
            )
            result.elapsed = time.perf_counter() - t0
            if not completed and log is not None:
                done = recorder.rendered + recorder.failed
                log(f"stopped early: {done} variants rendered and recorded in {result.manifest}")
    finally:
        lock.release()
    return result


def _execute(grid, todo, backend, scheduler, workers, chunk, render, recorder, client) -> str:
    blobs = BlobReader()
    tasks = [make_task(v, grid.path.parent, blobs) for v in todo]
    if backend == "serial":
        run_serial([tasks], render, recorder)
        return "serial (this process)"
    if backend == "pool":
        size = chunk or _chunk_size(len(tasks), workers)
        run_pool(chunked(tasks, size), render, recorder, workers)
        return f"process pool ({workers} workers)"
    cluster = None
    description = "dask (given client)"
    if client is None:
        client, cluster, description = connect_dask(scheduler if backend == "dask-remote" else None, workers)
    try:
        size = chunk or _chunk_size(len(tasks), dask_threads(client))
        run_dask(client, chunked(tasks, size), render, recorder)
    finally:
        if cluster is not None:
            with contextlib.suppress(Exception):
                client.close()
            with contextlib.suppress(Exception):
                cluster.close()
        elif backend == "dask-remote":
            with contextlib.suppress(Exception):
                client.close()
    return description


def _chunk_size(n_tasks: int, workers: int) -> int:
    """About four chunks per worker (balance), at most MAX_CHUNK variants each (progress, retries)."""
    return max(1, min(MAX_CHUNK, math.ceil(n_tasks / (4 * max(1, workers)))))


# ---------------------------------------------------------------------------------- CLI


def _cmd_batch(args: argparse.Namespace) -> int:
    grid = load_grid(args.grid)
    if args.dry_run:
        _print_plan(grid)
        return 0
    say = (lambda msg: print(f"jassy: {msg}", file=sys.stderr)) if not args.quiet else None
    result = run_batch(
        grid,
        args.output,
        scheduler=args.scheduler,
        workers=args.workers,
        chunk=args.chunk,
        force=args.force,
        verify=not args.no_verify,
        parquet=True if args.parquet else None,
        progress=not args.quiet,
        log=say,
    )
    if not args.quiet:
        done = result.rendered + result.failed
        print(
            f"batch {grid.name}: {result.total} variants: {result.skipped} already done, "
            f"{result.rendered} rendered, {result.failed} failed, in {result.elapsed:.1f} s"
            + (f" ({result.rate:.0f} variants/min) on {result.backend}" if done else "")
            + f"; manifest {result.manifest}"
        )
    if result.failed:
        for variant, patch, error in result.errors[:3]:
            print(f"jassy: variant {variant[:12]} ({patch}) failed: {error}", file=sys.stderr)
        more = f" (first {min(3, len(result.errors))} above)" if result.failed > 1 else ""
        print(f"jassy: {result.failed} variant(s) failed{more}; see {result.manifest}", file=sys.stderr)
        return 1
    return 0


def _print_plan(grid: Grid) -> None:
    counts: dict[str, int] = {}
    for v in grid.variants:
        counts[v.patch.name] = counts.get(v.patch.name, 0) + 1
    dup = f" ({grid.duplicates} duplicates merged)" if grid.duplicates else ""
    print(
        f"grid {grid.name}: {len(grid.variants)} variants{dup}: "
        + ", ".join(f"{k} x{n}" for k, n in counts.items())
    )
    print("columns: " + (", ".join(grid.columns) or "-"))
    for v in grid.variants[:5]:
        params = ", ".join(f"{k}={text(x)}" for k, x in v.labels.items())
        print(f"  {v.filename}: {params or '(the patch as it is)'}")
    if len(grid.variants) > 5:
        print(f"  ... {len(grid.variants) - 5} more")


#: The grid file format, as ``jassy batch --help`` shows it (docs/formats.md has more).
GRID_HELP = """\
grid file (TOML):
  [batch]          name, description, manifest = "csv" | "parquet"
  [render]         duration (s), sample_rate (Hz), block, format ("float32" | "pcm16" | "pcm24"),
                   container ("wav" | "flac"), haptic ("wav" | "npz" | "csv": also the force track)
  patch = "bar"    patch name(s) or file(s) to sweep
  [set]            fixed overrides: "node.param" = value
  [grid]           "key" = [values, ...]: the full product of all lists; or a factor of named
                   levels: [grid.material] metal = { "bar.decay_scale" = 1.0, ... }
  [random]         n = draws per grid point, seed, "key" = { uniform = [lo, hi] } |
                   { loguniform = [lo, hi] } | { choice = [...] } | { randint = [lo, hi] }
  [[sweep]]        several sweeps instead, each with patch, set, grid, random, render
  [patches.NAME]   an inline patch (the layout of a patch file)
keys: node.param, score[i].time | .jump | .ramp, score[i].ACTION.ARG (e.g.
  score[0].impact.impulse), models.NAME.file, render.duration | .sample_rate | .block | .format
outputs: OUTDIR/<patch>-<id12>.wav (id: SHA-256 of patch, overrides, options) and
  OUTDIR/manifest.csv, one row per variant (parameters, output, status, error, peak, sha256, ...)
example:
  patch = "bar"
  [render]
  duration = 1.0
  [grid]
  "score[0].impact.impulse" = [0.001, 0.01]
  "bar.freq_scale" = [0.5, 1.0, 2.0]
"""


def add_command(subparsers) -> argparse.ArgumentParser:
    """Add ``jassy batch`` to the CLI's subparsers."""
    p = subparsers.add_parser(
        "batch",
        help="render a grid or random sweep of patch variants: one file each plus a manifest",
        description="Render every variant of a grid file into OUTDIR, on all local cores with Dask "
        "(or a process pool without it) or on a Dask cluster. Reruns skip finished variants.",
        epilog=GRID_HELP,
        formatter_class=argparse.RawDescriptionHelpFormatter,
    )
    p.add_argument("grid", help="grid file (.toml): patches, [grid] / [random] sweeps, [render] options")
    p.add_argument("-o", "--output", required=True, metavar="OUTDIR", help="directory for files and manifest")
    p.add_argument(
        "--scheduler",
        metavar="ADDRESS",
        help="tcp://HOST:PORT of a running Dask scheduler; or 'local' (default: a Dask LocalCluster "
        "on all cores, a process pool without Dask), 'pool' or 'serial'",
    )
    p.add_argument("--workers", type=int, help="local worker processes (default: all cores)")
    p.add_argument(
        "--chunk", type=int, help=f"variants per task (default: ~4 tasks per worker, <= {MAX_CHUNK})"
    )
    p.add_argument("--force", action="store_true", help="render every variant again, even those done")
    p.add_argument(
        "--no-verify", action="store_true", help="skip done variants without re-hashing their files"
    )
    p.add_argument("--parquet", action="store_true", help="also write manifest.parquet (needs pyarrow)")
    p.add_argument("--dry-run", action="store_true", help="show the variants; render nothing")
    p.add_argument("-q", "--quiet", action="store_true", help="no progress bar or summary line")
    p.set_defaults(func=_cmd_batch)
    return p


# -------------------------------------------------------------------------------- bench

BENCH_GRID = """
patch = "bell"

[batch]
name = "bench"

[render]
duration = {duration}
format = "pcm16"

[grid]
"score[0].impact.location" = ["soundbow", "lip", "waist", "shoulder"]
"score[0].impact.impulse" = [0.3, 0.6]
"bell.decay_scale" = {decays}
"""


def bench_batch(
    workers: int = 2, duration: float = 3.0, decays: tuple = (1.0, 2.0, 3.0, 4.0), repeats: int = 3
) -> dict:
    """Variants per minute: serial in this process vs ``workers`` Dask workers (or a pool without Dask).

    The grid: the bell patch (120 modes), 4 locations x 2 impulses x len(decays) decay
    scales, ``duration`` s each, 16-bit WAV. Serial runs after one warm-up variant (JIT,
    caches). The cluster is timed cold (its start and the first batch: worker start-up and
    warm-up included), then warm (further batches on the same workers). Warm figures are the
    best of ``repeats`` runs, each into a fresh directory. The outputs of all runs must be
    identical, and are compared.
    """
    with tempfile.TemporaryDirectory(prefix="jassy-bench-batch-") as tmp:
        root = Path(tmp)
        grid_path = root / "bench.toml"
        grid_path.write_text(BENCH_GRID.format(duration=duration, decays=list(decays)))
        grid = load_grid(grid_path)
        n = len(grid.variants)
        render_task(make_task(grid.variants[0], root, BlobReader()))  # warm-up: JIT and caches
        runs: list[BatchResult] = []

        def timed(name: str, **kwargs) -> float:
            t0 = time.perf_counter()
            runs.append(run_batch(grid, root / name, workers=workers, **kwargs))
            return time.perf_counter() - t0

        t_serial = min(timed(f"serial{i}", scheduler="serial") for i in range(repeats))
        if have_dask():
            t0 = time.perf_counter()
            client, cluster, description = connect_dask(None, workers)
            try:
                timed("cold", client=client)
                t_cold = time.perf_counter() - t0
                t_warm = min(timed(f"warm{i}", client=client) for i in range(repeats))
            finally:
                client.close()
                cluster.close()
        else:
            description = f"process pool ({workers} workers)"
            t_cold = timed("cold", scheduler="pool")
            t_warm = None
        digests = [[row["sha256"] for row in read_rows(r.outdir).values()] for r in runs]
        identical = all(d == digests[0] for d in digests) and len(digests[0]) == n
        failed = sum(r.failed for r in runs)
    return {
        "variants": n,
        "audio_seconds": duration,
        "workers": workers,
        "backend": description,
        "cores": local_cores(),
        "serial_s": t_serial,
        "serial_per_min": 60 * n / t_serial,
        "parallel_cold_s": t_cold,
        "parallel_cold_per_min": 60 * n / t_cold,
        "parallel_warm_s": t_warm,
        "parallel_warm_per_min": 60 * n / t_warm if t_warm else None,
        "speedup_warm": t_serial / t_warm if t_warm else None,
        "speedup_cold": t_serial / t_cold,
        "identical": identical,
        "failed": failed,
        "repeats": repeats,
    }


def print_bench(result: dict) -> None:
    r = result
    print(
        f"batch: {r['variants']} variants of the bell patch ({r['audio_seconds']:g} s each, 16-bit WAV), "
        f"{r['cores']} cores; serial and warm: best of {r['repeats']}"
    )
    print(f"{'run':<34} {'wall s':>8} {'variants/min':>13} {'speedup':>8}")
    label = "serial (this process, warmed up)"
    print(f"{label:<34} {r['serial_s']:>8.2f} {r['serial_per_min']:>13.0f} {1:>7.2f}x")
    label = f"{r['workers']} workers, cold (incl. start)"
    cold = r["parallel_cold_per_min"]
    print(f"{label:<34} {r['parallel_cold_s']:>8.2f} {cold:>13.0f} {r['speedup_cold']:>7.2f}x")
    if r["parallel_warm_s"]:
        label = f"{r['workers']} workers, warm"
        print(
            f"{label:<34} {r['parallel_warm_s']:>8.2f} {r['parallel_warm_per_min']:>13.0f} "
            f"{r['speedup_warm']:>7.2f}x"
        )
    same = "identical" if r["identical"] else "DIFFERENT"
    print(f"backend: {r['backend']}; outputs of all runs {same}; failed variants: {r['failed']}")

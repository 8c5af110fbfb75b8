"""The manifest of a batch: one row per variant, written atomically as CSV (and Parquet).

Columns: index, variant (the SHA-256 identity), patch, one column per swept key (and per
named factor), then output (file name, relative to the manifest), status (ok, error or
pending), error, duration (s), sample_rate (Hz), frames, peak (linear), peak_dbfs,
sha256 (of the output file), warnings, render_s (wall time), worker (host:pid) and, when
the haptic track is written, haptic_output and haptic_sha256.

While a batch runs, each finished variant is also appended to a journal
(``.manifest.journal``, one JSON row per line, flushed at once) so an interrupted run
loses nothing; the next run merges it into the manifest.
"""

from __future__ import annotations

import contextlib
import csv
import json
import math
import os
from pathlib import Path
from typing import Any

from jassy.batch.grid import HAPTIC, HEAD, TAIL, canonical
from jassy.errors import JassyError
from jassy.files import atomic_path

MANIFEST = "manifest.csv"
PARQUET = "manifest.parquet"
JOURNAL = ".manifest.journal"

INT_COLUMNS = {"index", "frames"}
FLOAT_COLUMNS = {"duration", "sample_rate", "peak", "peak_dbfs", "render_s"}

Row = dict[str, str]


def columns(params: list[str], haptic: bool) -> list[str]:
    """All columns: the fixed ones around the parameters (a factor never takes a fixed name)."""
    return HEAD + params + TAIL + (HAPTIC if haptic else [])


def text(value: Any) -> str:
    """A parameter value as manifest text: strings as they are, numbers by repr, tables as JSON."""
    if value is None:
        return ""
    if isinstance(value, str):
        return value
    if isinstance(value, bool):
        return "true" if value else "false"
    if isinstance(value, (int, float)):
        return repr(value)
    return canonical(value)


def peak_dbfs(peak: float) -> str:
    """Peak level in dBFS; empty for silence (no -inf in a manifest: CSV and Parquet hold
    only finite numbers)."""
    return f"{20 * math.log10(peak):.2f}" if peak > 0 else ""


def read_rows(outdir: Path) -> dict[str, Row]:
    """Rows of an existing manifest and journal, by variant id (journal rows win)."""
    rows: dict[str, Row] = {}
    path = outdir / MANIFEST
    if path.is_file():
        try:
            with open(path, newline="", encoding="utf-8") as fh:
                for row in csv.DictReader(fh):
                    if row.get("variant"):
                        rows[row["variant"]] = {k: v or "" for k, v in row.items() if k is not None}
        except (OSError, csv.Error, UnicodeDecodeError) as exc:
            raise JassyError(f"{path}: cannot read the manifest of the previous run ({exc})") from None
    journal = outdir / JOURNAL
    if journal.is_file():
        with open(journal, encoding="utf-8", errors="replace") as fh:
            for line in fh:
                try:
                    row = json.loads(line)
                except json.JSONDecodeError:
                    continue  # a line cut by a crash
                if isinstance(row, dict) and row.get("variant"):
                    rows[row["variant"]] = {str(k): str(v) for k, v in row.items()}
    return rows


def write_csv(outdir: Path, rows: list[Row], cols: list[str]) -> Path:
    path = outdir / MANIFEST
    with atomic_path(path) as tmp, open(tmp, "w", newline="", encoding="utf-8") as fh:
        writer = csv.DictWriter(fh, fieldnames=cols, extrasaction="ignore", lineterminator="\n")
        writer.writeheader()
        for row in rows:
            writer.writerow({c: row.get(c, "") for c in cols})
    return path


def have_pyarrow() -> bool:
    try:
        import pyarrow  # noqa: F401
        import pyarrow.parquet  # noqa: F401
    except ImportError:
        return False
    return True


def _number(value: str, kind: type) -> Any:
    if value == "":
        return None
    try:
        number = kind(value)
    except ValueError:
        return None
    return number if kind is not float or math.isfinite(number) else None


def write_parquet(outdir: Path, rows: list[Row], cols: list[str]) -> Path:
    """The manifest as Parquet: numeric columns typed, parameters numeric where all values are."""
    import pyarrow as pa
    import pyarrow.parquet as pq

    data: dict[str, list] = {}
    for col in cols:
        values = [row.get(col, "") for row in rows]
        if col in INT_COLUMNS:
            data[col] = pa.array([_number(v, int) for v in values], pa.int64())
        elif col in FLOAT_COLUMNS:
            data[col] = pa.array([_number(v, float) for v in values], pa.float64())
        else:
            present = [v for v in values if v != ""]
            numeric = [_number(v, float) for v in present]
            if col not in HEAD + TAIL + HAPTIC and present and all(n is not None for n in numeric):
                data[col] = pa.array([_number(v, float) for v in values], pa.float64())
            else:
                data[col] = pa.array(values, pa.string())
    path = outdir / PARQUET
    with atomic_path(path) as tmp:
        pq.write_table(pa.table(data), tmp)
    return path


class Journal:
    """Append-only log of finished rows; each line is flushed when written."""

    def __init__(self, outdir: Path):
        self.path = outdir / JOURNAL
        self._fh = open(self.path, "a", encoding="utf-8")  # noqa: SIM115 (closed in close())

    def append(self, row: Row) -> None:
        self._fh.write(json.dumps(row, separators=(",", ":")) + "\n")
        self._fh.flush()

    def clear(self) -> None:
        """Called after the rows were written to the manifest."""
        self._fh.truncate(0)
        self._fh.seek(0)

    def close(self, remove: bool) -> None:
        self._fh.close()
        if remove:
            with contextlib.suppress(OSError):
                os.unlink(self.path)

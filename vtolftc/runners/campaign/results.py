"""Campaign results in Parquet: appended as scenarios finish, safe against crashes.

Layout of an output folder::

    campaign.json              # the spec's name, sha256, scenario count (checked by --resume)
    spec.toml                  # a copy of the spec
    parts/part-NNNNNN.parquet  # rows as they finished, one small file per batch
    results.parquet            # all rows sorted by scenario index (written at the end)

Each part is written to a temporary name, flushed to disk and renamed (atomic on POSIX), so a
crash, SIGKILL, SIGTERM or Ctrl-C at any moment leaves only complete parts: what was written
is never lost, and at most the rows of the unwritten batch are flown again by ``--resume``.
:func:`read_results` merges the parts (and ``results.parquet``), keeps one row per scenario
and sorts by index; :func:`write_final` writes ``results.parquet`` the same way (atomically).

Columns (one row per scenario) are :data:`SCHEMA`: the scenario's axes, ``outcome`` /
``survived`` (:mod:`vtolftc.runners.campaign.outcome`), ``recoverable`` / ``recovery_margin`` (the
physical oracle, :mod:`vtolftc.runners.campaign.oracle`; a NaN margin: not judged), crash time,
final errors, RMSEs over the window from the injection, largest attitude excursion and
altitude loss, transition time, share of control steps whose allocation fell short of the
commanded moments, and wall times.
NaN marks a value that does not exist (no crash, no transition).
"""

from __future__ import annotations

import time
from collections.abc import Iterable
from pathlib import Path
from typing import Any

import pyarrow as pa
import pyarrow.parquet as pq

from vtolftc.base.jsonio import atomic_write

__all__ = ["SCHEMA", "TIMING_COLUMNS", "PartWriter", "read_results", "write_final"]

SCHEMA = pa.schema([
    ("index", pa.int64()),
    ("scenario_id", pa.string()),
    ("controller", pa.string()),
    ("family", pa.string()),
    ("faults", pa.string()),
    ("phase", pa.string()),
    ("fault_time_s", pa.float64()),
    ("wind", pa.string()),
    ("perturbation", pa.string()),
    ("seed", pa.int64()),
    ("duration_s", pa.float64()),
    ("outcome", pa.string()),
    ("survived", pa.bool_()),
    ("recoverable", pa.bool_()),       # the physical oracle's verdict (campaign/oracle.py)
    ("recovery_margin", pa.float64()),  # rad/s^2; < 0: the trim's deficit, NaN: not judged
    ("crashed", pa.bool_()),
    ("crash_time_s", pa.float64()),
    ("final_altitude_error_m", pa.float64()),
    ("final_roll_deg", pa.float64()),
    ("final_pitch_deg", pa.float64()),
    ("final_airspeed_m_s", pa.float64()),
    ("rmse_altitude_m", pa.float64()),
    ("rmse_roll_deg", pa.float64()),
    ("rmse_pitch_deg", pa.float64()),
    ("rmse_yaw_deg", pa.float64()),
    ("max_attitude_excursion_deg", pa.float64()),
    ("max_altitude_lost_m", pa.float64()),
    ("transition_complete_s", pa.float64()),
    ("transition_duration_s", pa.float64()),
    ("quad_chute", pa.bool_()),
    ("saturated_share", pa.float64()),
    ("allocation_fallbacks", pa.int64()),
    ("error", pa.string()),
    ("fly_command", pa.string()),
    ("sim_time_s", pa.float64()),
    ("run_wall_time_s", pa.float64()),   # the flight loop alone
    ("wall_time_s", pa.float64()),       # the whole task (airframe, gains, set-up, flight)
])
TIMING_COLUMNS = ("run_wall_time_s", "wall_time_s")
_NAN_DEFAULT = {"float": float("nan"), "int": 0, "bool": False, "str": ""}


def _table(rows: Iterable[dict[str, Any]]) -> pa.Table:
    cols: dict[str, list[Any]] = {f.name: [] for f in SCHEMA}
    for r in rows:
        for f in SCHEMA:
            v = r.get(f.name)
            if v is None:
                t = f.type
                v = (_NAN_DEFAULT["float"] if pa.types.is_floating(t) else
                     _NAN_DEFAULT["int"] if pa.types.is_integer(t) else
                     _NAN_DEFAULT["bool"] if pa.types.is_boolean(t) else _NAN_DEFAULT["str"])
            cols[f.name].append(v)
    return pa.table(cols, schema=SCHEMA)


def _atomic_write(table: pa.Table, path: Path) -> None:
    atomic_write(path, lambda fh: pq.write_table(table, fh))


class PartWriter:
    """Buffers rows and writes them as a new part every ``batch`` rows or ``interval_s``
    seconds (whichever first), and on :meth:`flush` / :meth:`close`."""

    def __init__(self, out_dir: str | Path, batch: int = 8, interval_s: float = 10.0) -> None:
        self.dir = Path(out_dir) / "parts"
        self.dir.mkdir(parents=True, exist_ok=True)
        self.batch = max(1, int(batch))
        self.interval_s = float(interval_s)
        self._rows: list[dict[str, Any]] = []
        self._last = time.monotonic()
        existing = [int(p.stem.split("-")[1]) for p in self.dir.glob("part-*.parquet")]
        self._seq = max(existing, default=-1) + 1
        self.written = 0

    def add(self, row: dict[str, Any]) -> None:
        """Buffer one result row; write a part once ``batch`` rows or ``interval_s`` have passed."""
        self._rows.append(row)
        if (len(self._rows) >= self.batch
                or time.monotonic() - self._last >= self.interval_s):
            self.flush()

    def flush(self) -> None:
        """Write the buffered rows as the next Parquet part (atomic rename); nothing if empty."""
        if not self._rows:
            return
        _atomic_write(_table(self._rows), self.dir / f"part-{self._seq:06d}.parquet")
        self._seq += 1
        self.written += len(self._rows)
        self._rows = []
        self._last = time.monotonic()

    close = flush


def read_results(path: str | Path) -> pa.Table:
    """All rows of a campaign: an output folder (its parts and ``results.parquet``) or one
    Parquet file; one row per scenario id, sorted by index. Missing folder: an empty table."""
    p = Path(path)
    if p.is_file():
        files = [p]
    else:
        files = sorted((p / "parts").glob("part-*.parquet"))
        if (p / "results.parquet").is_file():
            files.insert(0, p / "results.parquet")
    tables = [pq.read_table(f, schema=SCHEMA) for f in files]
    if not tables:
        return SCHEMA.empty_table()
    t = pa.concat_tables(tables)
    # one row per scenario (the first written), sorted by index
    ids = t.column("scenario_id").to_pylist()
    seen: set[str] = set()
    keep = []
    for i, sid in enumerate(ids):
        if sid not in seen:
            seen.add(sid)
            keep.append(i)
    t = t.take(pa.array(keep, pa.int64()))
    return t.sort_by([("index", "ascending")])


def write_final(out_dir: str | Path) -> pa.Table:
    """Merge everything into ``results.parquet`` (atomically) and return it."""
    t = read_results(out_dir)
    _atomic_write(t, Path(out_dir) / "results.parquet")
    return t

"""The vehicle process's run folder: the truth of every control step and the event log.

``vehicle_truth.csv``: simulated time, NED position and velocity, roll/pitch/yaw, body rates,
airspeed, then per actuator its position, effectiveness and command; one row per control step.
A step is snapshotted (a few array copies) on the lockstep's critical path, formatted off it
(:meth:`TruthLog.format_pending`, while the autopilot computes) and written at the next flush,
every ``flush_rows`` steps (125 = 0.5 s of simulated time) and at close, so a SIGKILL loses less
than 0.5 s. ``vehicle_events.jsonl``: one JSON object per event, flushed.
"""

from __future__ import annotations

import json
from pathlib import Path
from typing import Any, TextIO

import numpy as np

from vtolftc.base.rotation import quat_to_euler
from vtolftc.firmware_sim.vehicle.dynamics import N_RIGID

__all__ = ["TruthLog"]


class TruthLog:
    """Writes ``vehicle_truth.csv`` and ``vehicle_events.jsonl`` in ``out_dir`` (created).

    Parameters
    ----------
    out_dir : pathlib.Path
        The vehicle's run folder.
    actuator_names : sequence of str
        Actuator names in command order (the per-actuator column names).
    flush_rows : int
        Steps between two flushes of the truth file.
    """

    def __init__(self, out_dir: Path, actuator_names: tuple[str, ...] | list[str],
                 flush_rows: int = 125) -> None:
        out_dir.mkdir(parents=True, exist_ok=True)
        self.flush_rows = flush_rows
        self._rows: list[tuple[int, np.ndarray, float, np.ndarray, np.ndarray]] = []
        self._lines: list[str] = []
        self._row_fmt: str | None = None
        self._truth: TextIO | None = (out_dir / "vehicle_truth.csv").open("w")
        cols = ["time_s", "pn_m", "pe_m", "pd_m", "vn_m_s", "ve_m_s", "vd_m_s", "roll_rad",
                "pitch_rad", "yaw_rad", "p_rad_s", "q_rad_s", "r_rad_s", "airspeed_m_s"]
        for kind in ("pos", "eff", "cmd"):
            cols += [f"{kind}_{a}" for a in actuator_names]
        self._truth.write(",".join(cols) + "\n")
        self._events: TextIO | None = (out_dir / "vehicle_events.jsonl").open("w")

    def record(self, time_usec: int, x: np.ndarray, airspeed_m_s: float, eff: np.ndarray,
               commands: np.ndarray, flush: bool = True) -> None:
        """Snapshot one step: state vector ``x``, airspeed [m/s], effectiveness and commands
        (copied; formatted by :meth:`format_pending` or at the next flush)."""
        if self._truth is None:
            return
        self._rows.append((time_usec, x.copy(), airspeed_m_s, eff.copy(), commands.copy()))
        if flush and self.pending >= self.flush_rows:
            self.flush()

    @property
    def pending(self) -> int:
        """Steps not yet written (snapshotted or formatted)."""
        return len(self._rows) + len(self._lines)

    def format_pending(self) -> None:
        """Format the snapshots into CSV rows (``%.9g``, as ``np.savetxt`` writes them), kept
        until the next flush: the vehicle process calls this after each send, while the
        autopilot computes, so that a flush is only a write."""
        if not self._rows:
            return
        fmt = self._row_fmt
        for t, x, air, eff, cmd in self._rows:
            row = np.concatenate(([t * 1e-6], x[0:6], quat_to_euler(x[6:10]), x[10:13], [air],
                                  x[N_RIGID:], eff, cmd))
            if fmt is None:
                fmt = self._row_fmt = ",".join(["%.9g"] * row.size) + "\n"
            self._lines.append(fmt % tuple(row.tolist()))
        self._rows.clear()

    def between_steps(self) -> None:
        """The work of the wait for the autopilot's answer: format what is pending, and write
        it once ``flush_rows`` steps are pending."""
        self.format_pending()
        if self.pending >= self.flush_rows:
            self.flush()

    def flush(self) -> None:
        """Write the rows (formatting what is not yet) and flush the file."""
        if self._truth is not None and self.pending:
            self.format_pending()
            self._truth.write("".join(self._lines))
            self._truth.flush()
            self._lines.clear()

    def event(self, time_s: float, event: str, text: str, **extra: Any) -> None:
        """Append one event (simulated time [s], kind, text, extra fields) and flush."""
        if self._events is not None:
            rec = {"time_s": time_s, "event": event, "text": text, **extra}
            self._events.write(json.dumps(rec) + "\n")
            self._events.flush()

    def close(self) -> None:
        """Flush and close both files. Idempotent."""
        self.flush()
        for f in (self._truth, self._events):
            if f is not None:
                f.close()
        self._truth = self._events = None

"""The vehicle process's run folder: the truth of every control step and the event log.

``vehicle_truth.csv``: simulated time, NED position and velocity, roll/pitch/yaw, body rates,
airspeed, then per actuator its position, effectiveness and command; one row per control step.
A step is snapshotted (a few array copies) on the lockstep's critical path and formatted at the
next flush, every ``flush_rows`` steps (125 = 0.5 s of simulated time) and at close, so a
SIGKILL loses less than 0.5 s. ``vehicle_events.jsonl``: one JSON object per event, flushed.
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
        (copied; formatted at the next flush)."""
        if self._truth is None:
            return
        self._rows.append((time_usec, x.copy(), airspeed_m_s, eff.copy(), commands.copy()))
        if flush and len(self._rows) >= self.flush_rows:
            self.flush()

    @property
    def pending(self) -> int:
        """Snapshots not yet written."""
        return len(self._rows)

    def flush(self) -> None:
        """Write the snapshots as CSV rows (``%.9g``, as ``np.savetxt`` writes them) and flush
        the file."""
        if self._truth is not None and self._rows:
            rows = [np.concatenate(([t * 1e-6], x[0:6], quat_to_euler(x[6:10]), x[10:13],
                                    [air], x[N_RIGID:], eff, cmd))
                    for t, x, air, eff, cmd in self._rows]
            block = np.vstack(rows)
            # np.savetxt's very text (each row "%.9g,%.9g,...\n"), in one formatting call
            # for the whole block instead of one per row
            row_fmt = ",".join(["%.9g"] * block.shape[1]) + "\n"
            self._truth.write((row_fmt * block.shape[0]) % tuple(block.ravel().tolist()))
            self._truth.flush()
            self._rows.clear()

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

"""Wall and thread-CPU time of the named parts of a loop's step (the SITL processes' profile).

A lockstep process spends each step in parts one after the other (wait for the peer and read,
compute, send, bookkeeping). :class:`StepParts` sums, per part, the wall time (``perf_counter``)
and the calling thread's CPU time (``thread_time``) between consecutive :meth:`StepParts.lap`
calls. Wall minus CPU is the time the thread did not run in that part: blocked waiting, or
preempted by another process (on loopback UDP the receiver's wake-up runs in the sender).

Per-step trace (opt-in, :meth:`StepParts.enable_trace`): the means hide the slow tail, so for
up to ``rows`` steps one row per :meth:`StepParts.end_step` keeps each part's wall time, CPU
time and the ``perf_counter`` at its end (CLOCK_MONOTONIC on Linux: the same clock in every
process, so two processes' rows line up on one time axis), the step's key (simulated time) and
the calling thread's cumulative context switches and page faults (``getrusage``
``RUSAGE_THREAD``: an involuntary switch is a preemption, a voluntary one a sleep, such as a
wait for the GIL or the link). :meth:`StepParts.trace` returns the columns as arrays.
"""

from __future__ import annotations

import resource
import time
from pathlib import Path

import numpy as np

__all__ = ["StepParts"]


def check_trace_steps(n: int) -> str | None:
    """The error text for an invalid ``--trace-steps`` value (a negative one), or None."""
    if n >= 0:
        return None
    return f"--trace-steps {n}: expected N >= 0 steps (0 = off)"


class StepParts:
    """Per-part sums of wall and thread-CPU time [s] between laps.

    Parameters
    ----------
    names : sequence of str
        The parts, in the order the summaries list them.

    Examples
    --------
    >>> p = StepParts(("work", "rest"))
    >>> _ = p.start()
    >>> _ = sum(range(10000)); t = p.lap("work")
    >>> p.wall["work"] >= p.cpu["work"] > 0.0 and p.wall["rest"] == 0.0
    True
    """

    def __init__(self, names: tuple[str, ...] | list[str]) -> None:
        self.wall = dict.fromkeys(names, 0.0)
        """Wall time summed per part [s]."""
        self.cpu = dict.fromkeys(names, 0.0)
        """The lapping thread's CPU time summed per part [s]."""
        self._t = 0.0
        self._c = 0.0
        self.names = tuple(names)
        """The parts, in order."""
        self._index = {n: i for i, n in enumerate(self.names)}
        self._rows: list[tuple[float, ...]] = []
        self._max_rows = 0
        self._cur: list[float] | None = None

    def start(self) -> tuple[float, float]:
        """Start the next part now (no time is booked). Returns (``perf_counter()``,
        ``thread_time()``) [s]."""
        self._t, self._c = time.perf_counter(), time.thread_time()
        return self._t, self._c

    def lap(self, name: str) -> tuple[float, float]:
        """Book the time since the last :meth:`start` / :meth:`lap` to ``name`` and start the
        next part. Returns (``perf_counter()``, ``thread_time()``) [s]."""
        t, c = time.perf_counter(), time.thread_time()
        self.wall[name] += t - self._t
        self.cpu[name] += c - self._c
        cur = self._cur
        if cur is not None:  # tracing: this step's wall, CPU and end time of the part
            i = self._index[name]
            k = len(self.names)
            cur[i] += t - self._t
            cur[k + i] += c - self._c
            cur[2 * k + i] = t
        self._t, self._c = t, c
        return t, c

    def enable_trace(self, rows: int) -> None:
        """Keep one row per step for the next ``rows`` steps (0: off)."""
        self._max_rows = max(0, int(rows))
        k = len(self.names)
        self._cur = [0.0] * (2 * k) + [float("nan")] * k if self._max_rows else None

    def end_step(self, name: str, key: float) -> tuple[float, float]:
        """:meth:`lap` ``name``, the step's last part, and close the step's trace row
        (``key``: the step's simulated time [us]; no row when not tracing or the trace is
        full). Returns what :meth:`lap` returns."""
        out = self.lap(name)
        cur = self._cur
        if cur is None:
            return out
        ru = resource.getrusage(resource.RUSAGE_THREAD)
        self._rows.append((*cur, key, ru.ru_nivcsw, ru.ru_nvcsw, ru.ru_minflt, ru.ru_majflt))
        if len(self._rows) >= self._max_rows:
            self._cur = None
        else:
            k = len(self.names)
            cur[:2 * k] = [0.0] * (2 * k)
            cur[2 * k:] = [float("nan")] * k
        return out

    def trace(self) -> dict[str, np.ndarray]:
        """The trace's columns, one value per traced step: ``wall_<part>``, ``cpu_<part>``
        [s], ``end_<part>`` (``perf_counter`` at the part's last lap in the step, NaN if
        none) [s], ``key`` (simulated time [us]) and the thread's cumulative ``nivcsw``,
        ``nvcsw``, ``minflt``, ``majflt``."""
        cols = ([f"{w}_{n}" for w in ("wall", "cpu", "end") for n in self.names]
                + ["key", "nivcsw", "nvcsw", "minflt", "majflt"])
        a = np.array(self._rows, dtype=np.float64).reshape(len(self._rows), len(cols))
        return {c: a[:, j] for j, c in enumerate(cols)}

    def save_trace(self, path: Path) -> None:
        """Write :meth:`trace` to ``path`` (``.npz``) if anything was traced."""
        if self._rows:
            np.savez(path, **self.trace())

    def summary(self, steps: int) -> dict[str, dict[str, float]]:
        """``part_mean_us`` (wall) and ``part_cpu_mean_us`` (thread CPU): means per step [us]."""
        n = max(1, steps)
        return {"part_mean_us": {k: 1e6 * x / n for k, x in self.wall.items()},
                "part_cpu_mean_us": {k: 1e6 * x / n for k, x in self.cpu.items()}}

"""Wall and thread-CPU time of the named parts of a loop's step (the SITL processes' profile).

A lockstep process spends each step in parts one after the other (wait for the peer and read,
compute, send, bookkeeping). :class:`StepParts` sums, per part, the wall time (``perf_counter``)
and the calling thread's CPU time (``thread_time``) between consecutive :meth:`StepParts.lap`
calls. Wall minus CPU is the time the thread did not run in that part: blocked waiting, or
preempted by another process (on loopback UDP the receiver's wake-up runs in the sender).
"""

from __future__ import annotations

import time

__all__ = ["StepParts"]


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
        self._t, self._c = t, c
        return t, c

    def summary(self, steps: int) -> dict[str, dict[str, float]]:
        """``part_mean_us`` (wall) and ``part_cpu_mean_us`` (thread CPU): means per step [us]."""
        n = max(1, steps)
        return {"part_mean_us": {k: 1e6 * x / n for k, x in self.wall.items()},
                "part_cpu_mean_us": {k: 1e6 * x / n for k, x in self.cpu.items()}}

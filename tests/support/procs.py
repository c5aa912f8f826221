"""The processes tests start: their live process trees, read through psutil (one home for
every test that needs the live descendants of a process it started), and how the real-time
SITL tests ask for scheduling priority."""

from __future__ import annotations

import psutil

__all__ = ["RT_PRIORITY", "descendants"]

RT_PRIORITY = ["--rt-priority", "10"]
"""Extra arguments of both SITL processes in the real-time tests: SCHED_FIFO where permitted
(root, as CI; :mod:`vtolftc.runners.processes.priority`). Beside CPU burners on 2 cores an
ordinary process was runnable yet given no CPU for 0.66-1.41 s, longer than the 0.5 s HIL-loss
and output-watchdog tolerances those tests fly with."""


def descendants(pid: int) -> set[int]:
    """Every live descendant of ``pid`` (children, their children, ...); empty when ``pid``
    is gone."""
    try:
        return {c.pid for c in psutil.Process(pid).children(recursive=True)}
    except psutil.NoSuchProcess:
        return set()

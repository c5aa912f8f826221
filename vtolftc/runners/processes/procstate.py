"""What a process's threads are doing, read from ``/proc`` (Linux; elsewhere nothing).

Used where a process does not end or does not progress and the reason must be written down:
:meth:`vtolftc.runners.sitl.SitlRun.stop` for a process still alive after SIGTERM's grace (a
process in uninterruptible sleep, state D, e.g. an ``fsync`` waiting for a loaded disk, ends
only once that I/O completes, even after SIGKILL), and the tests' stall probe.
"""

from __future__ import annotations

import os
from pathlib import Path

__all__ = ["describe_threads", "proc_threads"]

_HZ = os.sysconf("SC_CLK_TCK") if hasattr(os, "sysconf") else 100


def proc_threads(pid: int) -> list[tuple[int, str, str, float, str]]:
    """(tid, name, state, CPU time user+system in s, kernel wait channel) of every thread of
    ``pid`` (empty list when it is gone or there is no ``/proc``)."""
    out = []
    base = Path(f"/proc/{pid}/task")
    try:
        tids = sorted(int(t.name) for t in base.iterdir())
    except OSError:
        return out
    for tid in tids:
        try:
            stat = (base / str(tid) / "stat").read_text()
            name = (base / str(tid) / "comm").read_text().strip()
            try:
                wchan = (base / str(tid) / "wchan").read_text().strip()
            except OSError:
                wchan = "?"
        except OSError:
            continue
        f = stat[stat.rindex(")") + 2:].split()
        out.append((tid, name, f[0], (int(f[11]) + int(f[12])) / _HZ, wchan or "0"))
    return out


def describe_threads(pid: int) -> str:
    """One line per thread of ``pid``: tid, name, state, CPU seconds, wait channel and, for a
    thread in uninterruptible sleep (D) where readable (root), its kernel stack's function
    names; "gone" when the process has no ``/proc`` entry."""
    lines = []
    for tid, name, state, cpu, wchan in proc_threads(pid):
        line = f"{tid} {name} {state} cpu {cpu:.2f} s wchan {wchan}"
        if state == "D":
            try:
                stack = Path(f"/proc/{pid}/task/{tid}/stack").read_text().split()
                line += " stack " + " < ".join(w.split("+")[0] for w in stack
                                               if "+" in w)
            except OSError:
                pass
        lines.append(line)
    return "\n".join(lines) if lines else "gone"

"""What a process's threads are doing, read from ``/proc`` (Linux; elsewhere nothing).

Used where a process does not end or does not progress and the reason must be written down:
:meth:`vtolftc.runners.sitl.SitlRun.stop` for a process still alive after SIGTERM's grace (a
process in uninterruptible sleep, state D, e.g. an ``fsync`` waiting for a loaded disk, ends
only once that I/O completes, even after SIGKILL), and the tests' stall probe. The SITL
programs also dump every thread's Python stack to their stderr (their log) on
:data:`DUMP_SIGNAL` (:func:`enable_stack_dump`), which ``SitlRun.stop`` sends first.
"""

from __future__ import annotations

import faulthandler
import os
import signal
import sys
import time
from pathlib import Path

__all__ = ["DUMP_SIGNAL", "describe_threads", "enable_stack_dump", "proc_threads"]

DUMP_SIGNAL = signal.SIGUSR1
"""The signal on which a program that called :func:`enable_stack_dump` writes every thread's
Python stack to its stderr."""


def enable_stack_dump() -> None:
    """Write every thread's Python stack to stderr on :data:`DUMP_SIGNAL` (``faulthandler``:
    from a C signal handler, so also while the interpreter is busy or shutting down)."""
    faulthandler.register(DUMP_SIGNAL, file=sys.stderr, all_threads=True)

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


def describe_threads(pid: int, sample_s: float = 0.0) -> str:
    """One line per thread of ``pid``: tid, name, state, CPU seconds, wait channel and, for a
    thread in uninterruptible sleep (D) or running (R) where readable (root), its kernel
    stack's function names; "gone" when the process has no ``/proc`` entry. With
    ``sample_s`` > 0 the threads are read twice that many wall seconds apart and each line also
    gives the CPU time used in between (a thread in R that used none was runnable but given
    no CPU)."""
    first = {}
    if sample_s > 0:
        first = {t[0]: t[3] for t in proc_threads(pid)}
        time.sleep(sample_s)
    lines = []
    for tid, name, state, cpu, wchan in proc_threads(pid):
        line = f"{tid} {name} {state} cpu {cpu:.2f} s wchan {wchan}"
        if tid in first:
            line += f" (+{cpu - first[tid]:.2f} s in {sample_s:g} s)"
        if state in ("D", "R"):
            try:
                stack = Path(f"/proc/{pid}/task/{tid}/stack").read_text().split()
                names = " < ".join(w.split("+")[0] for w in stack if "+" in w)
                if names:  # empty for a thread running in user space
                    line += " stack " + names
            except OSError:
                pass
        lines.append(line)
    return "\n".join(lines) if lines else "gone"

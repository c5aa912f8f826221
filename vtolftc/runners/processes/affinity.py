"""CPU pinning of the SITL process programs (``--cpu N``).

In lockstep each process sleeps while the other computes; on waking it finds its core's caches
(L1/L2, TLB, branch predictors) filled by whatever ran there meanwhile, often the other
process, and its step costs 2-3x its warm CPU (``benchmarks/bench_sitl.py``). ``--cpu N``
(opt-in, default off) keeps a whole process on core ``N`` once it is ready: every thread it
has then, and so every thread those start later (a new thread inherits its creator's
affinity), may run on ``N`` only. With the autopilot on one core and the vehicle on another,
each comes back to the caches it left, provided nothing else wants those cores: on a loaded
machine a pinned process cannot move to an idle core and waits instead (session 10 measured
0.5-0.6x against 0.8-0.9x under a load of 20), so this is for an idle machine.

Set once the process is compiled and ready, as ``--rt-priority``
(:mod:`vtolftc.runners.processes.priority`): the two processes' numba compilers at start keep
using both cores. A CPU outside the set this process may use is a usage error (one line, exit
status 2); a refusal by the system (a cgroup's cpuset changed meanwhile) is one line and the
process runs unpinned.
"""

from __future__ import annotations

import argparse
import contextlib
import os
from typing import TextIO

__all__ = ["CPU_OFF", "add_cpu_argument", "apply_cpu", "check_cpu"]

CPU_OFF = -1
"""``--cpu`` default: not pinned."""


def add_cpu_argument(ap: argparse.ArgumentParser) -> None:
    """Add ``--cpu N`` (int, default -1 = not pinned) to a process's parser."""
    ap.add_argument("--cpu", type=int, default=CPU_OFF, metavar="N",
                    help="once ready, run every thread of this process on CPU N only (warm "
                         "caches between lockstep steps; for an idle machine, one core per "
                         "process); default -1 = not pinned")


def check_cpu(n: int) -> str | None:
    """The error text for an invalid ``--cpu`` value, or None if ``n`` is valid (-1, or a CPU
    this process may run on: ``os.sched_getaffinity(0)``)."""
    if n == CPU_OFF:
        return None
    allowed = sorted(os.sched_getaffinity(0))
    if n in allowed:
        return None
    return f"--cpu {n}: expected -1 (off) or a CPU this process may use: {allowed}"


def apply_cpu(n: int, who: str, log: TextIO) -> bool:
    """Pin every thread of this process (and so the threads they start afterwards) to CPU
    ``n``.

    Parameters
    ----------
    n : int
        CPU number (validated by :func:`check_cpu`); -1 does nothing.
    who : str
        The program's name for the log line ("vehicle", "autopilot").
    log : TextIO
        Where the one-line outcome is written.

    Returns
    -------
    bool
        True if every thread was pinned; False if ``n`` is -1 or the system refused (logged;
        the process then runs on its previous CPU set).
    """
    if n == CPU_OFF:
        return False
    try:
        tids = sorted(int(t) for t in os.listdir("/proc/self/task"))
    except OSError:  # no /proc: the calling thread only
        tids = [0]
    before = os.sched_getaffinity(0)
    try:
        for tid in tids:
            with contextlib.suppress(ProcessLookupError):  # a thread that has just ended
                os.sched_setaffinity(tid, {n})
    except OSError as exc:  # EINVAL: no longer in the cpuset; EPERM
        for tid in tids:  # all or nothing: no thread left pinned
            with contextlib.suppress(OSError):
                os.sched_setaffinity(tid, before)
        print(f"{who}: --cpu {n} not applied ({exc.strerror or exc}): not pinned", file=log,
              flush=True)
        return False
    print(f"{who}: pinned to CPU {n} ({len(tids)} threads)", file=log, flush=True)
    return True

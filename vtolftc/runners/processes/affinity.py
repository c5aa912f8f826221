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

``--zenoh-cpu M`` (with ``--cpu N``; zenoh links only) puts zenoh's runtime threads
(:data:`vtolftc.runners.processes.priority.ZENOH_THREAD_RE`) on CPU ``M`` instead, the peer
process's CPU in the SITL runner (``SitlConfig.zenoh_peer_cpu``). In lockstep the thread that
reads a sample from the socket wakes when the peer has just published it, i.e. while the peer
waits for the answer: on the peer's core it runs at once (a local wake-up inside the peer's
send, as loopback UDP's receiver wake-up, and with ``--rt-priority`` one above the peer's
spinning control thread), hands the sample to the channel the control thread polls across the
cores and sleeps; the control thread keeps its core and its caches. On its own process's core
it had to preempt that control thread, whose next step then ran on caches the reader had used.
"""

from __future__ import annotations

import argparse
import contextlib
import os
from typing import TextIO

from vtolftc.runners.processes.priority import ZENOH_THREAD_RE, thread_name

__all__ = ["CPU_OFF", "add_cpu_argument", "apply_cpu", "check_cpu", "thread_cpus"]

CPU_OFF = -1
"""``--cpu`` default: not pinned."""


def add_cpu_argument(ap: argparse.ArgumentParser) -> None:
    """Add ``--cpu N`` (int, default -1 = not pinned) to a process's parser."""
    ap.add_argument("--cpu", type=int, default=CPU_OFF, metavar="N",
                    help="once ready, run every thread of this process on CPU N only (warm "
                         "caches between lockstep steps; for an idle machine, one core per "
                         "process); default -1 = not pinned")
    ap.add_argument("--zenoh-cpu", type=int, default=CPU_OFF, metavar="M",
                    help="with --cpu: zenoh's runtime threads on CPU M instead (the peer "
                         "process's CPU: its socket reader then wakes where the sample was "
                         "sent); default -1 = with the process's --cpu")


def check_cpu(n: int, flag: str = "--cpu") -> str | None:
    """The error text for an invalid ``--cpu`` (or ``flag``) value, or None if ``n`` is valid
    (-1, or a CPU this process may run on: ``os.sched_getaffinity(0)``)."""
    if n == CPU_OFF:
        return None
    allowed = sorted(os.sched_getaffinity(0))
    if n in allowed:
        return None
    return f"{flag} {n}: expected -1 (off) or a CPU this process may use: {allowed}"


def apply_cpu(n: int, who: str, log: TextIO, zenoh_cpu: int = CPU_OFF) -> bool:
    """Pin every thread of this process (and so the threads they start afterwards) to CPU
    ``n``, zenoh's runtime threads to ``zenoh_cpu`` if given.

    Parameters
    ----------
    n : int
        CPU number (validated by :func:`check_cpu`); -1 does nothing.
    who : str
        The program's name for the log line ("vehicle", "autopilot").
    log : TextIO
        Where the one-line outcome is written.
    zenoh_cpu : int
        CPU of zenoh's runtime threads (validated by :func:`check_cpu`); -1: ``n``.

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
    cpus = thread_cpus(n, zenoh_cpu, {tid: thread_name(tid) for tid in tids})
    try:
        for tid, cpu in cpus.items():
            with contextlib.suppress(ProcessLookupError):  # a thread that has just ended
                os.sched_setaffinity(tid, {cpu})
    except OSError as exc:  # EINVAL: no longer in the cpuset; EPERM
        for tid in tids:  # all or nothing: no thread left pinned
            with contextlib.suppress(OSError):
                os.sched_setaffinity(tid, before)
        print(f"{who}: --cpu {n} not applied ({exc.strerror or exc}): not pinned", file=log,
              flush=True)
        return False
    moved = sum(cpu != n for cpu in cpus.values())
    print(f"{who}: pinned to CPU {n} ({len(tids)} threads)"
          + (f", zenoh's {moved} runtime threads to CPU {zenoh_cpu}" if moved else ""),
          file=log, flush=True)
    return True


def thread_cpus(n: int, zenoh_cpu: int, names: dict[int, str]) -> dict[int, int]:
    """The CPU of each thread for ``--cpu n --zenoh-cpu zenoh_cpu``: ``zenoh_cpu`` for zenoh's
    runtime threads (:data:`ZENOH_THREAD_RE`) when it is not -1, ``n`` for every other.

    Parameters
    ----------
    n : int
        The process's CPU.
    zenoh_cpu : int
        zenoh's runtime threads' CPU, -1 = ``n``.
    names : dict[int, str]
        Thread id -> thread name (``comm``; "" when unknown).

    Returns
    -------
    dict[int, int]
        Thread id -> CPU.
    """
    z = n if zenoh_cpu == CPU_OFF else zenoh_cpu
    return {tid: z if ZENOH_THREAD_RE.match(name) else n for tid, name in names.items()}

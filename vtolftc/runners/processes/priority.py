"""Real-time scheduling priority for the SITL process programs (``--rt-priority N``).

On a loaded machine an ordinary (``SCHED_OTHER``) process can be runnable yet get no CPU for
a second or more: measured beside CPU burners on 2 cores (``tests/test_coldstart.py``), the
vehicle's loop stalled 0.66-1.41 s with its thread in state R and CPU pressure at 96-98 %, and
its 0.5 s output watchdog cut the rotors. PX4 on POSIX runs its modules as ``SCHED_FIFO``
threads for this reason; ``--rt-priority N`` (1-99, opt-in, default off) does the same for a
whole process once it is ready: every thread it has then, and so every thread those start
later, runs ``SCHED_FIFO`` at priority N. Not before: numba compiling for seconds in a
``SCHED_FIFO`` thread is never preempted by a thread of equal priority, and the autopilot's
ground-station worker, which must answer TEMPORARILY_REJECTED while the autopilot boots,
waited 4.8 s for a CPU (both cores held by the two processes' compilers) when the priority was
set at start. The kernel's real-time throttling (``/proc/sys/kernel/sched_rt_runtime_us``,
0.95 s per 1 s by default) still leaves ordinary processes some CPU if a real-time thread
never sleeps.

zenoh's runtime threads (tokio workers named ``rx-N``, ``tx-N``, ``app-N``, ``acc-N``, ``net-N``:
the HIL link's socket reads and, in the universal transport, its writes) run one priority above
the rest (N + 1, at most the system's maximum): in lockstep a spinning ``SCHED_FIFO`` control
thread (``--spin-us``) on the core of its process (``--cpu``) would otherwise keep the thread
that reads the peer's sample off that core until the spin ends, and zenoh's hop would cost the
whole spin (session 16 measured 3.3x instead of 8.0x with spin + pin + rt over zenoh). One above,
the reader preempts the spinner as soon as the socket is readable, hands the sample to the
channel the spinner polls and sleeps again. A UDP process has no such threads: nothing changes.

It needs ``CAP_SYS_NICE`` (root, or ``setcap``/``RLIMIT_RTPRIO``); without it the process says
so in one line and runs at its ordinary priority.
"""

from __future__ import annotations

import argparse
import contextlib
import os
import re
from typing import TextIO

__all__ = ["ZENOH_THREAD_RE", "add_rt_priority_argument", "apply_rt_priority",
           "check_rt_priority", "thread_name", "thread_priorities"]

ZENOH_THREAD_RE = re.compile(r"^(rx|tx|app|acc|net)-[0-9]+$")
"""Names (``/proc/<pid>/task/<tid>/comm``) of zenoh's tokio runtime threads (zenoh-runtime:
``ZRuntime`` RX, TX, Application, Acceptor, Net); rerun's tokio threads are
``tokio-rt-worker``, Python's take the program's name."""


def add_rt_priority_argument(ap: argparse.ArgumentParser) -> None:
    """Add ``--rt-priority N`` (int, default 0 = ordinary scheduling) to a process's parser."""
    ap.add_argument("--rt-priority", type=int, default=0, metavar="N",
                    help="run as SCHED_FIFO at priority N (1-99; needs CAP_SYS_NICE, as "
                         "PX4's POSIX threads): a loaded machine cannot starve the real-time "
                         "loop; default 0 = ordinary scheduling")


def check_rt_priority(n: int) -> str | None:
    """The error text for an invalid ``--rt-priority`` value, or None if ``n`` is valid
    (0, or a ``SCHED_FIFO`` priority of this system, 1-99 on Linux)."""
    lo, hi = os.sched_get_priority_min(os.SCHED_FIFO), os.sched_get_priority_max(os.SCHED_FIFO)
    if n == 0 or lo <= n <= hi:
        return None
    return f"--rt-priority {n}: expected 0 (off) or a SCHED_FIFO priority in [{lo}, {hi}]"


def apply_rt_priority(n: int, who: str, log: TextIO) -> bool:
    """Switch every thread of this process (and so the threads they start afterwards) to
    ``SCHED_FIFO`` at priority ``n``.

    Parameters
    ----------
    n : int
        Priority (validated by :func:`check_rt_priority`); 0 does nothing.
    who : str
        The program's name for the log line ("vehicle", "autopilot").
    log : TextIO
        Where the one-line outcome is written.

    Returns
    -------
    bool
        True if the policy was set; False if ``n`` is 0 or the system refused (logged).
    """
    if n == 0:
        return False
    try:
        tids = sorted(int(t) for t in os.listdir("/proc/self/task"))
    except OSError:  # no /proc: the calling thread only
        tids = [0]
    prios = thread_priorities(n, {tid: thread_name(tid) for tid in tids})
    try:
        for tid, prio in prios.items():
            with contextlib.suppress(ProcessLookupError):  # a thread that has just ended
                os.sched_setscheduler(tid, os.SCHED_FIFO, os.sched_param(prio))
    except OSError as exc:  # EPERM without CAP_SYS_NICE
        print(f"{who}: --rt-priority {n} not applied ({exc.strerror or exc}): ordinary "
              "scheduling", file=log, flush=True)
        return False
    above = [tid for tid, prio in prios.items() if prio != n]
    print(f"{who}: SCHED_FIFO priority {n} ({len(tids)} threads)"
          + (f", zenoh's {len(above)} runtime threads at {prios[above[0]]}" if above else ""),
          file=log, flush=True)
    return True


def thread_priorities(n: int, names: dict[int, str]) -> dict[int, int]:
    """The ``SCHED_FIFO`` priority of each thread for ``--rt-priority n``: ``n``, and ``n + 1``
    (at most the system's maximum) for zenoh's runtime threads (:data:`ZENOH_THREAD_RE`).

    Parameters
    ----------
    n : int
        The process's priority (1-99 on Linux).
    names : dict[int, str]
        Thread id -> thread name (``comm``; "" when unknown).

    Returns
    -------
    dict[int, int]
        Thread id -> priority.
    """
    top = min(n + 1, os.sched_get_priority_max(os.SCHED_FIFO))
    return {tid: top if ZENOH_THREAD_RE.match(name) else n for tid, name in names.items()}


def thread_name(tid: int) -> str:
    """A thread's name (``comm``) of this process, "" if unknown (gone, or no ``/proc``)."""
    try:
        with open(f"/proc/self/task/{tid}/comm", encoding="utf-8", errors="replace") as f:
            return f.read().strip()
    except OSError:
        return ""

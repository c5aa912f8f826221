"""Dask clusters on this machine whose workers start warm for a campaign.

:func:`local_tcp_cluster` starts a ``dask scheduler`` and a ``dask worker`` as processes on
127.0.0.1, their workers warmed by the preload :data:`PRELOAD`
(:mod:`vtolftc.runners.campaign.dask_preload`), to try a deployment on one machine (the
benchmarks and tests); :func:`warm_local_cluster` is a ``LocalCluster`` whose workers fork
from a forkserver that has imported the flight code. Importing this module does not import
the flight code.
"""

from __future__ import annotations

import contextlib
import json
import signal
import subprocess
import sys
import tempfile
import time
from collections.abc import Iterator
from pathlib import Path
from typing import Any

__all__ = ["PRELOAD", "local_tcp_cluster", "warm_local_cluster"]

PRELOAD = "vtolftc.runners.campaign.dask_preload"
"""The worker preload that imports and warms the flight code before a worker registers
(``dask worker ... --preload vtolftc.runners.campaign.dask_preload``)."""


@contextlib.contextmanager
def local_tcp_cluster(n_workers: int, *, preload: bool = True, idle_timeout_s: float = 600.0,
                      start_timeout_s: float = 300.0) -> Iterator[str]:
    """A Dask cluster of separate processes on 127.0.0.1: ``dask scheduler`` and ``dask
    worker --nworkers n_workers --nthreads 1`` (with ``preload``, ``--preload``
    :data:`PRELOAD`), as a deployment starts them. Yields the scheduler's address once it is
    up (the workers may still be starting: ``Client.wait_for_workers``); on exit stops both
    (SIGTERM, then SIGKILL after 60 s). They end by themselves if this process dies: the
    scheduler after ``idle_timeout_s`` without a task, the workers 60 s after it."""
    cmd = [sys.executable, "-m", "dask"]
    with tempfile.TemporaryDirectory(prefix="vtolftc-dask-") as d:
        sfile = Path(d) / "scheduler.json"
        procs = [subprocess.Popen(
            [*cmd, "scheduler", "--host", "127.0.0.1", "--port", "0", "--no-dashboard",
             "--scheduler-file", str(sfile), "--idle-timeout", f"{idle_timeout_s:g}s"],
            stdout=subprocess.DEVNULL, stderr=subprocess.DEVNULL, cwd=d)]
        try:
            deadline = time.monotonic() + start_timeout_s
            while not sfile.is_file():
                if time.monotonic() > deadline or procs[0].poll() is not None:
                    raise RuntimeError("dask scheduler did not start")
                time.sleep(0.05)
            procs.append(subprocess.Popen(
                [*cmd, "worker", "--scheduler-file", str(sfile), "--nworkers", str(n_workers),
                 "--nthreads", "1", "--no-dashboard", "--host", "127.0.0.1",
                 "--death-timeout", "60", "--local-directory", d,
                 *(["--preload", PRELOAD] if preload else [])],
                stdout=subprocess.DEVNULL, stderr=subprocess.DEVNULL, cwd=d))
            yield json.loads(sfile.read_text())["address"]
        finally:
            for p in reversed(procs):
                p.send_signal(signal.SIGTERM)
                try:
                    p.wait(timeout=60)
                except subprocess.TimeoutExpired:
                    p.kill()
                    p.wait(timeout=30)


@contextlib.contextmanager
def warm_local_cluster(n_workers: int, **kwargs: Any) -> Iterator[Any]:
    """A :class:`distributed.LocalCluster` of ``n_workers`` processes (one thread each,
    127.0.0.1, no dashboard; ``kwargs`` override) whose workers start warm.

    Its workers are forked from a forkserver that has imported ``distributed`` and the
    flight code (:data:`PRELOAD`) once, instead of each starting a fresh interpreter and
    importing them (Dask's ``distributed.worker.multiprocessing-method`` = ``forkserver``
    while the cluster lives, so a worker its nanny restarts forks too); then each runs the
    preload's warm-up before it registers. A fork from the forkserver is safe whatever
    threads this process runs (the client's event loop): the forkserver is a process of its
    own, single-threaded. Where there is no forkserver (Windows), the workers are spawned
    and the preload imports the flight code in each. The forkserver is this process's one
    (:mod:`multiprocessing`'s): one already running keeps the modules it started with.
    """
    import multiprocessing

    import dask
    from distributed import LocalCluster
    from distributed.utils import get_mp_context

    opts: dict[str, Any] = {"n_workers": n_workers, "threads_per_worker": 1,
                            "processes": True, "host": "127.0.0.1",
                            "dashboard_address": None, "preload": [PRELOAD]}
    opts.update(kwargs)
    method = "forkserver" if "forkserver" in multiprocessing.get_all_start_methods() else None
    with dask.config.set({"distributed.worker.multiprocessing-method": method or "spawn"}):
        if method:
            ctx = get_mp_context()  # sets Dask's own forkserver preload, once per process
            ctx.set_forkserver_preload(["distributed", PRELOAD])
        with LocalCluster(**opts) as cluster:
            yield cluster

"""The Dask side of a campaign: the client, the workers' plugins, the task size.

:func:`connect` opens a client to a scheduler (``tcp://HOST:PORT``; an unreachable one is a
:class:`ConnectionError` with one line). :func:`prepare_workers` registers the campaign's
worker plugins (:mod:`vtolftc.runners.campaign.dask_plugin`): every worker, and every worker
that joins later, warms itself for the campaign's (airframe, gains, controller) in its task
thread without blocking anyone, and pauses its statistical profiler and its event-loop
ticks (and its nanny's). ``vtolftc campaign``
calls it before it computes the recoverability oracle, so a fresh cluster's workers import
the flight code and load their kernels meanwhile, as the local pool's workers inherit them
from the campaign process. :func:`vtolftc.runners.campaign.execute.run_dask` submits the
scenarios in batches of :func:`dask_batch_size`. :func:`cluster_pids` and
:func:`cluster_holdings` say which processes make up a cluster and what Dask holds in them
(the memory runs of ``benchmarks/bench_campaign_memory.py`` and the tests).
:func:`local_tcp_cluster` starts a ``dask scheduler`` and a ``dask worker`` as processes on
127.0.0.1, their workers warmed by the preload :mod:`vtolftc.runners.campaign.dask_preload`
(to try a deployment on one machine; the benchmarks and tests); :func:`warm_local_cluster`
is a ``LocalCluster`` whose workers fork from a forkserver that has imported the flight
code. This module never imports the flight code.
"""

from __future__ import annotations

import contextlib
import json
import math
import signal
import subprocess
import sys
import tempfile
import time
from collections.abc import Callable, Iterator, Sequence
from pathlib import Path
from typing import Any

__all__ = [
    "PRELOAD",
    "TASKS_PER_WORKER",
    "TASK_SIM_S",
    "cluster_holdings",
    "cluster_pids",
    "connect",
    "dask_batch_size",
    "local_tcp_cluster",
    "prepare_workers",
    "release_workers",
    "warm_local_cluster",
]

TASK_SIM_S = 60.0
"""Simulated seconds a Dask task flies at least when the campaign is long enough (s): a
60 s flight is 1-3 s of a worker, against a few ms of dispatch per task (the result to the
scheduler, the next task back), so the per-task overhead stays well under 2 %."""
PRELOAD = "vtolftc.runners.campaign.dask_preload"
"""The worker preload that imports and warms the flight code before a worker registers
(``dask worker ... --preload vtolftc.runners.campaign.dask_preload``)."""
TASKS_PER_WORKER = 8
"""Tasks per worker at least (when there are scenarios enough): the last ones balance the
workers' ends."""


def dask_batch_size(n_scenarios: int, n_workers: int, duration_s: float = TASK_SIM_S) -> int:
    """Scenarios per Dask task for ``n_scenarios`` flights of ``duration_s`` simulated seconds
    on ``n_workers``: enough for :data:`TASK_SIM_S` of simulated flight per task, but no more
    than leaves :data:`TASKS_PER_WORKER` tasks per worker; at least 1."""
    want = math.ceil(TASK_SIM_S / max(float(duration_s), 1e-3) - 1e-9)
    most = n_scenarios // (TASKS_PER_WORKER * max(1, n_workers))
    return max(1, min(want, most))


def connect(address: str) -> Any:
    """A :class:`distributed.Client` of the scheduler at ``address`` (30 s to connect)."""
    from distributed import Client

    try:
        return Client(address, timeout="30s", set_as_default=False)
    except (OSError, TimeoutError, ValueError) as exc:
        raise ConnectionError(f"--scheduler {address}: cannot reach a Dask scheduler "
                              f"({exc})") from None


def prepare_workers(client: Any, warm: Callable[[list[tuple[Any, ...]]], Any],
                    keys: Sequence[tuple[str | None, str | None, str]]) -> None:
    """Register the campaign's worker plugins on ``client``'s cluster: each worker (and each
    one joining later) pauses its profiler and ticks (and its nanny's ticks) and runs
    ``warm(keys)`` in its task thread.
    Returns at once (the warm-up runs on the workers); a worker already warm for these keys
    costs nothing more (see :func:`vtolftc.runners.campaign.execute.prepare_dask`)."""
    from vtolftc.runners.campaign.dask_plugin import (
        NANNY_PLUGIN_NAME,
        PLUGIN_NAME,
        WARM_PLUGIN_NAME,
        PauseProfiler,
        QuietNanny,
        WarmWorker,
    )

    client.register_plugin(PauseProfiler(), name=PLUGIN_NAME)
    client.register_plugin(QuietNanny(), name=NANNY_PLUGIN_NAME)
    client.register_plugin(WarmWorker(warm, keys), name=WARM_PLUGIN_NAME)


def release_workers(client: Any) -> None:
    """Unregister :func:`prepare_workers`' plugins (the workers' profiler back on; what they
    loaded stays for the next campaign)."""
    from vtolftc.runners.campaign.dask_plugin import (
        NANNY_PLUGIN_NAME,
        PLUGIN_NAME,
        WARM_PLUGIN_NAME,
    )

    try:  # only those registered (the scheduler logs a missing one as an error)
        workers, nannies = client.run_on_scheduler(_plugin_names)
    except Exception:
        return
    for name in (WARM_PLUGIN_NAME, PLUGIN_NAME):
        if name in workers:
            with contextlib.suppress(Exception):
                client.unregister_worker_plugin(name)
    if NANNY_PLUGIN_NAME in nannies:
        with contextlib.suppress(Exception):
            client.unregister_worker_plugin(NANNY_PLUGIN_NAME, nanny=True)


def _plugin_names(dask_scheduler: Any) -> tuple[list[str], list[str]]:
    """The worker and nanny plugins the scheduler holds (run on the scheduler)."""
    return list(dask_scheduler.worker_plugins), list(dask_scheduler.nanny_plugins)


def cluster_pids(client: Any) -> dict[int, str]:
    """The processes of ``client``'s cluster: ``{pid: role}``, the role ``"scheduler"``,
    ``"nanny"`` or ``"worker"`` (joined by ``+`` where they share a process, as a
    ``LocalCluster``'s scheduler and nannies share the process that started it, or the
    nannies of one ``dask worker --nworkers N``)."""
    import os

    roles: dict[int, set[str]] = {}
    roles.setdefault(int(client.run_on_scheduler(os.getpid)), set()).add("scheduler")
    for role, nanny in (("worker", False), ("nanny", True)):
        with contextlib.suppress(Exception):  # a cluster without nannies
            for pid in client.run(os.getpid, nanny=nanny, on_error="ignore").values():
                roles.setdefault(int(pid), set()).add(role)
    return {pid: "+".join(sorted(r)) for pid, r in roles.items()}


def _worker_holdings(dask_worker: Any) -> dict[str, int]:
    """What a worker holds for its tasks (run on the worker)."""
    st = dask_worker.state
    return {"data": len(dask_worker.data), "tasks": len(st.tasks), "log": len(st.log),
            "stimulus_log": len(st.stimulus_log)}


def _scheduler_holdings(dask_scheduler: Any) -> dict[str, int]:
    """What the scheduler holds for the tasks (run on the scheduler)."""
    s = dask_scheduler
    return {"tasks": len(s.tasks), "task_groups": len(s.task_groups),
            "task_prefixes": len(s.task_prefixes), "transition_log": len(s.transition_log),
            "computations": len(s.computations)}


def cluster_holdings(client: Any) -> dict[str, dict[str, int]]:
    """Dask's own bookkeeping of the campaign's tasks: per worker address, the results it
    keeps (``data``), the tasks it knows and its state machine's logs; under
    ``"scheduler"``, its tasks, task groups and prefixes, transition log and computations.
    After a campaign whose futures were all released, ``data`` and ``tasks`` are 0
    everywhere; the logs are bounded by ``distributed.admin.low-level-log-length``."""
    out: dict[str, dict[str, int]] = dict(client.run(_worker_holdings))
    out["scheduler"] = client.run_on_scheduler(_scheduler_holdings)
    return out


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

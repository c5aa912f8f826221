"""The Dask side of a campaign: the client, the workers' plugins, the task size.

:func:`connect` opens a client to a scheduler (``tcp://HOST:PORT``; an unreachable one is a
:class:`ConnectionError` with one line). :func:`prepare_workers` registers the campaign's
worker plugins (:mod:`vtolftc.runners.campaign.dask_plugin`): every worker, and every worker
that joins later, warms itself for the campaign's (airframe, gains, controller) in its task
thread without blocking anyone, and pauses its statistical profiler, its event-loop ticks
and its system monitor (and its nanny's, and the scheduler's). ``vtolftc campaign`` calls
it before it computes the recoverability oracle, so a fresh cluster's workers import
the flight code and load their kernels meanwhile, as the local pool's workers inherit them
from the campaign process. :func:`vtolftc.runners.campaign.execute.run_dask` submits the
scenarios in batches of :func:`dask_batch_size`. :func:`cluster_pids` and
:func:`cluster_holdings` say which processes make up a cluster and what Dask holds in them
(the memory runs of ``benchmarks/bench_campaign_memory.py`` and the tests).
Clusters on this machine whose workers start warm:
:mod:`vtolftc.runners.campaign.dask_clusters`. This module never imports the flight code.
"""

from __future__ import annotations

import contextlib
import math
from collections.abc import Callable, Sequence
from typing import Any

__all__ = [
    "TASKS_PER_WORKER",
    "TASK_SIM_S",
    "cluster_holdings",
    "cluster_pids",
    "connect",
    "dask_batch_size",
    "prepare_workers",
    "release_workers",
]

TASK_SIM_S = 60.0
"""Simulated seconds a Dask task flies at least when the campaign is long enough (s): a
60 s flight is 1-3 s of a worker, against a few ms of dispatch per task (the result to the
scheduler, the next task back), so the per-task overhead stays well under 2 %."""
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
        SCHEDULER_PLUGIN_NAME,
        WARM_PLUGIN_NAME,
        PauseProfiler,
        QuietNanny,
        QuietScheduler,
        WarmWorker,
    )

    client.register_plugin(PauseProfiler(), name=PLUGIN_NAME)
    client.register_plugin(QuietNanny(), name=NANNY_PLUGIN_NAME)
    client.register_plugin(WarmWorker(warm, keys), name=WARM_PLUGIN_NAME)
    with contextlib.suppress(Exception):  # a scheduler without this package: not quieted
        client.register_plugin(QuietScheduler(client.id), name=SCHEDULER_PLUGIN_NAME)


def release_workers(client: Any) -> None:
    """Unregister :func:`prepare_workers`' plugins (the workers' profiler and the
    scheduler's tick back on; what the workers loaded stays for the next campaign)."""
    from vtolftc.runners.campaign.dask_plugin import (
        NANNY_PLUGIN_NAME,
        PLUGIN_NAME,
        WARM_PLUGIN_NAME,
        quiet_scheduler_off,
    )

    try:  # only those registered (the scheduler logs a missing one as an error)
        workers, nannies = client.run_on_scheduler(_plugin_names)
    except Exception:
        return
    with contextlib.suppress(Exception):
        client.run_on_scheduler(quiet_scheduler_off)
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


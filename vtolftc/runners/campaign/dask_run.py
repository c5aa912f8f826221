"""Campaign scenarios as tasks on a Dask distributed cluster.

:func:`connect` opens a client to a scheduler (``tcp://HOST:PORT``; an unreachable one is a
:class:`ConnectionError` with one line). :func:`prepare_workers` registers the campaign's
worker plugins (:mod:`vtolftc.runners.campaign.dask_plugin`): every worker, and every worker
that joins later, warms itself for the campaign's (airframe, gains, controller) in its task
thread without blocking anyone, and pauses its statistical profiler. ``vtolftc campaign``
calls it before it computes the recoverability oracle, so a fresh cluster's workers import
the flight code and load their kernels meanwhile, as the local pool's workers inherit them
from the campaign process. :func:`run_dask` submits the scenarios in batches
(:func:`dask_batch_size`) of :func:`~vtolftc.runners.campaign.execute.fly_batch` and yields
their rows as tasks finish; each finished task is released at once, so neither the workers
nor the client hold the results of a long campaign.
"""

from __future__ import annotations

import contextlib
import math
from collections.abc import Iterator, Sequence
from typing import Any

from vtolftc.runners.campaign.scenarios import CampaignScenario

__all__ = [
    "TASKS_PER_WORKER",
    "TASK_SIM_S",
    "connect",
    "dask_batch_size",
    "prepare_workers",
    "release_workers",
    "run_dask",
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


def prepare_workers(client: Any, scenarios: Sequence[CampaignScenario]) -> None:
    """Register the campaign's worker plugins on ``client``'s cluster: each worker (and each
    one joining later) pauses its profiler and warms for ``scenarios`` in its task thread.
    Returns at once (the warm-up runs on the workers); a worker already warm for these
    scenarios costs nothing more."""
    from vtolftc.runners.campaign.dask_plugin import (
        PLUGIN_NAME,
        WARM_PLUGIN_NAME,
        PauseProfiler,
        WarmWorker,
    )
    from vtolftc.runners.campaign.execute import warm_keys

    client.register_plugin(PauseProfiler(), name=PLUGIN_NAME)
    client.register_plugin(WarmWorker(warm_keys(scenarios)), name=WARM_PLUGIN_NAME)


def release_workers(client: Any) -> None:
    """Unregister :func:`prepare_workers`' plugins (the workers' profiler back on; what they
    loaded stays for the next campaign)."""
    from vtolftc.runners.campaign.dask_plugin import PLUGIN_NAME, WARM_PLUGIN_NAME

    for name in (WARM_PLUGIN_NAME, PLUGIN_NAME):
        with contextlib.suppress(Exception):
            client.unregister_worker_plugin(name)


def run_dask(scenarios: Sequence[CampaignScenario], scheduler: Any, *,
             tag: str = "campaign", batch: int | None = None) -> Iterator[dict[str, Any]]:
    """Rows of ``scenarios`` flown as tasks on a Dask cluster, as they finish.

    Parameters
    ----------
    scenarios
        The scenarios to fly.
    scheduler
        The scheduler's address (``tcp://HOST:PORT``: a client is opened and closed here) or
        a :class:`distributed.Client` (kept open; typically one :func:`prepare_workers` was
        called on earlier, which this call repeats at no cost).
    tag
        Part of the task keys (``vtolftc-TAG-...``).
    batch
        Scenarios per task (default :func:`dask_batch_size` of the cluster's workers).

    Each worker needs this package (same version) installed; see ``docs/campaigns/README.md``.
    A task flies its batch with :func:`~vtolftc.runners.campaign.execute.fly_batch`; its
    future is released as soon as its rows are here. The plugins are unregistered at the
    end. Closing the generator cancels what is not done.
    """
    from distributed import as_completed

    from vtolftc.runners.campaign.execute import fly_batch

    own = isinstance(scheduler, str)
    client = connect(scheduler) if own else scheduler
    pending: set[Any] = set()
    try:
        prepare_workers(client, scenarios)
        if batch is None:
            dur = max((sc.duration_s for sc in scenarios), default=TASK_SIM_S)
            batch = dask_batch_size(len(scenarios), len(client.scheduler_info()["workers"]),
                                    dur)
        size = max(1, int(batch))
        chunks = [list(scenarios[i:i + size]) for i in range(0, len(scenarios), size)]
        futures = client.map(fly_batch, chunks,
                             key=[f"vtolftc-{tag}-{c[0].scenario_id}-{len(c)}" for c in chunks],
                             pure=False, retries=1)
        pending = set(futures)
        done = as_completed(futures, loop=client.loop)
        del futures
        for fut in done:
            rows = fut.result()
            pending.discard(fut)
            fut.release()
            del fut
            yield from rows
    finally:
        if pending:
            client.cancel(list(pending))
        release_workers(client)
        if own:
            client.close()

"""The Dask worker plugins of a campaign: workers warmed once, their profiler paused meanwhile.

:class:`WarmWorker` prepares each worker for the campaign's flights as soon as it is
registered (and on every worker that joins later): it runs
:func:`vtolftc.runners.campaign.execute.warm_up_keys` (imports of the flight code, the
airframe, the gain files and the numba kernels of a short flight per controller) in the
worker's task thread, without blocking the worker's event loop or the client. The tasks the
worker receives meanwhile queue behind it on the same thread (one thread per worker), so a
fresh worker warms while the campaign's parent computes the recoverability oracle rather
than inside the first flights, and a long-lived worker, already warm, returns at once.

A Dask worker samples the stack of its task threads every 10 ms
(``distributed.worker.profile``) on its event loop, which takes the GIL from the flight
running in the task thread each time, and every worker, nanny and scheduler checks its
event loop's health every 20 ms (``distributed.admin.tick``, which only logs) and samples
the machine every 0.5 s for the dashboard (``distributed.admin.system-monitor``). A
campaign's tasks are flights whose profile and graphs nobody reads, and on a machine whose
cores all fly each wake-up is CPU a flight loses, so while a campaign runs
:class:`PauseProfiler` stops the profiling, tick and system-monitor callbacks of each worker
(its memory check every :data:`MEMORY_CHECK_MS`), :class:`QuietNanny` the ticks and system
monitor of each nanny and :class:`QuietScheduler` those of the scheduler
(:func:`vtolftc.runners.campaign.execute.run_dask` registers them for the campaign and
unregisters them at the end, which starts them again; the scheduler's start again by
themselves if the campaign's client disconnects without it). Imported only with Dask;
importing this module does not import the flight code (a worker unpickles the plugin on its
event loop).
"""

from __future__ import annotations

import asyncio
from collections.abc import Callable, Sequence
from typing import Any

from distributed.diagnostics.plugin import NannyPlugin, SchedulerPlugin, WorkerPlugin

__all__ = ["MEMORY_CHECK_MS", "NANNY_PLUGIN_NAME", "PLUGIN_NAME", "SCHEDULER_PLUGIN_NAME",
           "WARM_PLUGIN_NAME", "PauseProfiler", "QuietNanny", "QuietScheduler", "WarmWorker",
           "quiet_scheduler_off"]

PLUGIN_NAME = "vtolftc-campaign-pause-profiler"
NANNY_PLUGIN_NAME = "vtolftc-campaign-quiet-nanny"
SCHEDULER_PLUGIN_NAME = "vtolftc-campaign-quiet-scheduler"
WARM_PLUGIN_NAME = "vtolftc-campaign-warm"
_CALLBACKS = ("profile", "profile-cycle", "tick", "ticks", "monitor")
_NANNY_CALLBACKS = ("tick", "ticks", "monitor")
_SCHEDULER_CALLBACKS = ("tick", "ticks", "monitor")
MEMORY_CHECK_MS = 1000.0
"""Period of a worker's and a nanny's memory check while a campaign runs (ms; Dask's default
is 100): a campaign's worker grows by MB over hundreds of flights."""
NANNY_MEMORY_CHECK_MS = MEMORY_CHECK_MS
"""The nanny's (the same; the name of round 10)."""


_STATE = "_vtolftc_campaign_paused"
"""Attribute of a paused Dask server holding what to restore: kept on the server rather than
on the plugin, since a nanny given a plugin of the same name again does not tear the old
one down first (the second instance would find nothing running and restore nothing)."""


def _pause(server: Any, keys: Sequence[str], memory_ms: float | None = None) -> None:
    """Stop the running periodic callbacks ``keys`` of a Dask server and, with
    ``memory_ms``, slow its memory monitor to that period; once (a second call is a no-op)."""
    if getattr(server, _STATE, None) is not None:
        return
    pcs = server.periodic_callbacks
    stopped = [k for k in keys if k in pcs and pcs[k].is_running()]
    for k in stopped:
        pcs[k].stop()
    old_ms = None
    if memory_ms is not None and "memory_monitor" in pcs:
        old_ms = pcs["memory_monitor"].callback_time
        pcs["memory_monitor"].callback_time = max(old_ms, memory_ms)
    setattr(server, _STATE, (stopped, old_ms))


def _resume(server: Any) -> None:
    """Undo :func:`_pause`."""
    state = getattr(server, _STATE, None)
    if state is None:
        return
    stopped, old_ms = state
    pcs = server.periodic_callbacks
    for k in stopped:
        if k in pcs:
            pcs[k].start()
    if old_ms is not None and "memory_monitor" in pcs:
        pcs["memory_monitor"].callback_time = old_ms
    setattr(server, _STATE, None)


class PauseProfiler(WorkerPlugin):
    """Quiet a worker while a campaign runs: its profiling callbacks (every 10 ms), its
    event-loop tick (every 20 ms; it only logs) and its system monitor (every 0.5 s; the
    dashboard's graphs and the memory the scheduler displays) stop on setup, its memory
    check (spilling and pausing near the memory limit) runs every :data:`MEMORY_CHECK_MS`
    instead of 100 ms; teardown undoes it."""

    name = PLUGIN_NAME

    def setup(self, worker: Any) -> None:
        """Stop the running profiling, tick and monitor callbacks of ``worker``, slow its
        memory check."""
        _pause(worker, _CALLBACKS, MEMORY_CHECK_MS)

    def teardown(self, worker: Any) -> None:
        """Start again what :meth:`setup` stopped."""
        _resume(worker)


class QuietNanny(NannyPlugin):
    """Quiet a nanny while a campaign runs: on a machine whose cores all fly, its wake-ups
    are CPU the flights lose. Its event-loop tick (every 20 ms; it only logs) and system
    monitor (every 0.5 s; the dashboard's graphs) stop; its memory monitor, which restarts a
    worker near its memory limit, keeps running but every :data:`MEMORY_CHECK_MS`
    instead of 100 ms (a campaign's worker grows by MB over hundreds of flights)."""

    name = NANNY_PLUGIN_NAME

    def setup(self, nanny: Any) -> None:
        """Stop the tick and system monitor callbacks of ``nanny``, slow its memory check."""
        _pause(nanny, _NANNY_CALLBACKS, MEMORY_CHECK_MS)

    def teardown(self, nanny: Any) -> None:
        """Undo :meth:`setup`."""
        _resume(nanny)


class QuietScheduler(SchedulerPlugin):
    """Quiet the scheduler while the campaign of client ``client_id`` runs: its event-loop
    tick (every 20 ms; it only logs) and its system monitor (every 0.5 s; the dashboard's
    graphs) stop when the plugin is registered (:meth:`start`). They start again with
    :func:`quiet_scheduler_off` (what :func:`vtolftc.runners.campaign.dask_run.release_workers`
    runs at the campaign's end) or, should the campaign die without it, when that client
    leaves the scheduler (:meth:`remove_client`). The scheduler must be able to import this
    module (this package installed beside it); otherwise the campaign runs without it.
    Idempotent: registered again while it is (``vtolftc campaign`` prepares the workers,
    then :func:`~vtolftc.runners.campaign.execute.run_dask` does), it stays as it is."""

    name = SCHEDULER_PLUGIN_NAME
    idempotent = True

    def __init__(self, client_id: str) -> None:
        self.client_id = client_id

    def start(self, scheduler: Any) -> None:
        """Stop the running tick and monitor callbacks of ``scheduler``."""
        _pause(scheduler, _SCHEDULER_CALLBACKS)

    def remove_client(self, scheduler: Any, client: str) -> None:
        """Start them again, and unregister this plugin, when the campaign's client
        leaves."""
        if client == self.client_id:
            _resume(scheduler)
            if scheduler.plugins.get(SCHEDULER_PLUGIN_NAME) is self:
                del scheduler.plugins[SCHEDULER_PLUGIN_NAME]


def quiet_scheduler_off(dask_scheduler: Any) -> bool:
    """Undo :class:`QuietScheduler` and unregister it (run on the scheduler, e.g. by
    ``client.run_on_scheduler``); True if it was registered."""
    _resume(dask_scheduler)
    return dask_scheduler.plugins.pop(SCHEDULER_PLUGIN_NAME, None) is not None


class WarmWorker(WorkerPlugin):
    """Warm a worker for the flights of ``keys`` (airframe path, gains folder, controller;
    None: the shipped ones) in its task thread: ``warm(keys)`` there (pickled by reference:
    :func:`vtolftc.runners.campaign.execute.warm_up_keys`, which warms each key once per
    process).

    :meth:`setup` only hands the warm-up to the worker's default executor and returns (the
    worker's event loop and the client's ``register_plugin`` do not wait for it);
    :attr:`pending` is that future on the worker, for tests and diagnostics.
    """

    name = WARM_PLUGIN_NAME

    def __init__(self, warm: Callable[[list[tuple[Any, ...]]], Any],
                 keys: Sequence[tuple[str | None, str | None, str]]) -> None:
        self.warm = warm
        self.keys = [tuple(k) for k in keys]
        self.pending: Any = None

    def setup(self, worker: Any) -> None:
        """Queue the warm-up on ``worker``'s task thread (the executor its tasks run on)."""
        executor = worker.executors.get("default")
        loop = asyncio.get_running_loop()
        self.pending = loop.run_in_executor(executor, self.warm, self.keys)

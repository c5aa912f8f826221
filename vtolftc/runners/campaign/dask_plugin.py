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
running in the task thread each time, and every worker and nanny checks its event loop's
health every 20 ms (``distributed.admin.tick``, which only logs). A campaign's tasks are
flights whose profile nobody reads, so :class:`PauseProfiler` stops the profiling and tick
callbacks of each worker and :class:`QuietNanny` the ticks of each nanny while they are
registered (:func:`vtolftc.runners.campaign.execute.run_dask` registers them for the
campaign and unregisters them at the end, which starts the profiler again). Imported only
with Dask; importing this module does not import the flight code (a worker unpickles the
plugin on its event loop).
"""

from __future__ import annotations

import asyncio
from collections.abc import Callable, Sequence
from typing import Any

from distributed.diagnostics.plugin import NannyPlugin, WorkerPlugin

__all__ = ["NANNY_PLUGIN_NAME", "PLUGIN_NAME", "WARM_PLUGIN_NAME", "PauseProfiler", "QuietNanny",
           "WarmWorker"]

PLUGIN_NAME = "vtolftc-campaign-pause-profiler"
NANNY_PLUGIN_NAME = "vtolftc-campaign-quiet-nanny"
WARM_PLUGIN_NAME = "vtolftc-campaign-warm"
_CALLBACKS = ("profile", "profile-cycle", "tick", "ticks")
_NANNY_CALLBACKS = ("tick", "ticks", "monitor")
NANNY_MEMORY_CHECK_MS = 1000.0
"""Period of a nanny's memory check while a campaign runs (ms; Dask's default is 100)."""


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
    """Stop the worker's profiling callbacks and its event-loop tick (a health check every
    20 ms that only logs) on setup, start them again on teardown."""

    name = PLUGIN_NAME

    def setup(self, worker: Any) -> None:
        """Stop the running profiling and tick callbacks of ``worker``."""
        _pause(worker, _CALLBACKS)

    def teardown(self, worker: Any) -> None:
        """Start again what :meth:`setup` stopped."""
        _resume(worker)


class QuietNanny(NannyPlugin):
    """Quiet a nanny while a campaign runs: on a machine whose cores all fly, its wake-ups
    are CPU the flights lose. Its event-loop tick (every 20 ms; it only logs) and system
    monitor (every 0.5 s; the dashboard's graphs) stop; its memory monitor, which restarts a
    worker near its memory limit, keeps running but every :data:`NANNY_MEMORY_CHECK_MS`
    instead of 100 ms (a campaign's worker grows by MB over hundreds of flights)."""

    name = NANNY_PLUGIN_NAME

    def setup(self, nanny: Any) -> None:
        """Stop the tick and system monitor callbacks of ``nanny``, slow its memory check."""
        _pause(nanny, _NANNY_CALLBACKS, NANNY_MEMORY_CHECK_MS)

    def teardown(self, nanny: Any) -> None:
        """Undo :meth:`setup`."""
        _resume(nanny)


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

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
running in the task thread each time. A campaign's tasks are flights whose profile nobody
reads, so :class:`PauseProfiler` stops the two profiling callbacks of each worker while it
is registered (:func:`vtolftc.runners.campaign.execute.run_dask` registers both plugins for the
campaign and unregisters them at the end, which starts the profiler again). Imported only
with Dask; importing this module does not import the flight code (a worker unpickles the
plugin on its event loop).
"""

from __future__ import annotations

import asyncio
from collections.abc import Callable, Sequence
from typing import Any

from distributed.diagnostics.plugin import WorkerPlugin

__all__ = ["PLUGIN_NAME", "WARM_PLUGIN_NAME", "PauseProfiler", "WarmWorker"]

PLUGIN_NAME = "vtolftc-campaign-pause-profiler"
WARM_PLUGIN_NAME = "vtolftc-campaign-warm"
_CALLBACKS = ("profile", "profile-cycle")


class PauseProfiler(WorkerPlugin):
    """Stop the worker's profiling callbacks on setup, start the ones it stopped on teardown."""

    name = PLUGIN_NAME

    def __init__(self) -> None:
        self.stopped: list[str] = []

    def setup(self, worker: Any) -> None:
        """Stop the running profiling callbacks of ``worker``."""
        for key in _CALLBACKS:
            pc = worker.periodic_callbacks.get(key)
            if pc is not None and pc.is_running():
                pc.stop()
                self.stopped.append(key)

    def teardown(self, worker: Any) -> None:
        """Start again what :meth:`setup` stopped."""
        for key in self.stopped:
            pc = worker.periodic_callbacks.get(key)
            if pc is not None:
                pc.start()
        self.stopped = []


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

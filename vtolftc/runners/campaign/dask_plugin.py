"""The Dask worker plugin of a campaign: the workers' statistical profiler paused meanwhile.

A Dask worker samples the stack of its task threads every 10 ms
(``distributed.worker.profile``) on its event loop, which takes the GIL from the flight
running in the task thread each time. A campaign's tasks are flights whose profile nobody
reads, so :class:`PauseProfiler` stops the two profiling callbacks of each worker while it
is registered (:func:`vtolftc.runners.campaign.execute.run_dask` registers it for the
campaign and unregisters it at the end, which starts them again). Imported only with Dask.
"""

from __future__ import annotations

from typing import Any

from distributed.diagnostics.plugin import WorkerPlugin

__all__ = ["PLUGIN_NAME", "PauseProfiler"]

PLUGIN_NAME = "vtolftc-campaign-pause-profiler"
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

"""A Dask worker preload: the worker imports the flight code and warms it before it registers.

Pass it to the workers of a cluster that will fly campaigns::

    dask worker tcp://HOST:8786 --nthreads 1 --preload vtolftc.runners.campaign.dask_preload

(or ``LocalCluster(..., preload=[dask_clusters.PRELOAD])``, or ``distributed.worker.preload`` in
Dask's configuration). Dask imports this module when it builds the worker, which imports the
flight code (:mod:`vtolftc.runners.scenario`, numba, scipy); then :func:`dask_setup`, still
before the worker registers with its scheduler, flies the short warm-up flight of
:func:`vtolftc.runners.campaign.execute.warm_up_keys` for each shipped controller on the
shipped airframe and gains, in the worker's task thread (gain files, numba kernels from the
cache). A campaign's first task then finds the worker warm, and the campaign's own warm-up
plugin (:class:`vtolftc.runners.campaign.dask_plugin.WarmWorker`) returns at once for these
keys (a campaign with another airframe or gains folder warms those itself). Without the
preload a fresh worker pays this inside the campaign.
"""

from __future__ import annotations

import asyncio
import time
from typing import Any

import vtolftc.runners.campaign.execute as _execute
import vtolftc.runners.scenario  # noqa: F401  (the flight code, imported with the worker)
from vtolftc.runners.campaign.spec import CONTROLLERS

__all__ = ["dask_setup", "preload_keys"]


def preload_keys() -> list[tuple[str | None, str | None, str]]:
    """The warm-up keys of the preload: (shipped airframe, shipped gains, controller) for
    each shipped controller (see :func:`vtolftc.runners.campaign.execute.warm_keys`)."""
    return [(None, None, c) for c in CONTROLLERS]


async def dask_setup(worker: Any) -> None:
    """Warm ``worker`` for the flights of :func:`preload_keys` before it registers (Dask
    calls this once per worker; the warm-up runs in the worker's task thread). The wall
    time it took is ``worker.vtolftc_preload_s`` (s)."""
    executor = worker.executors.get("default")
    t0 = time.perf_counter()
    await asyncio.get_running_loop().run_in_executor(executor, _execute.warm_up_keys,
                                                     preload_keys())
    worker.vtolftc_preload_s = time.perf_counter() - t0

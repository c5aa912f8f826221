"""Flying campaign scenarios: one scenario in-process, many on a local pool or a Dask cluster.

:func:`fly_scenario` is the unit of work: it flies one
:class:`~vtolftc.runners.campaign.scenarios.CampaignScenario` with the in-process runner
(:func:`vtolftc.runners.scenario.run_scenario`, deterministic) and returns its result row (see
:mod:`vtolftc.runners.campaign.results`). Everything in the row except the wall times depends only
on
the scenario, so the same spec gives the same rows on one core, on a process pool or on any
Dask worker with the same package installed.

:func:`run_local` runs scenarios on a :class:`multiprocessing.pool.Pool` (workers ignore
Ctrl-C; the parent stops them); :func:`run_dask` submits them as tasks to a Dask distributed
scheduler (``tcp://HOST:PORT``). Both yield rows as scenarios finish, in completion order.

What scenarios share is made once per process, never per scenario: the airframe
(:func:`cached_airframe`), the timeline without its faults (:func:`base_scenario`) and the
compiled kernels. The local pool forks its workers from this process after
:func:`warm_up` has flown a short flight of each controller here (imports, gain files and the
numba kernels then come with the fork instead of costing each worker its own start). A process
running threads of its own (a Dask client, a progress monitor), which a fork could catch
holding a lock, starts them from a forkserver that has imported the flight code instead. A
worker is replaced by a fresh one every :data:`WORKER_SCENARIOS` scenarios (forked by the
pool's own thread, as multiprocessing's ``maxtasksperchild`` always does), which bounds its
memory. A Dask worker keeps the same per-process caches from one task to the next; its scenarios
go to it in batches (:func:`fly_batch`), each finished task is released at once, so neither
the workers nor the client hold the results of a long campaign; :func:`prepare_dask` warms
fresh workers in their task threads without blocking (see
:mod:`vtolftc.runners.campaign.dask_run`).
"""

from __future__ import annotations

import contextlib
import math
import multiprocessing
import os
import signal
import sys
import threading
import time
import traceback
from collections.abc import Iterator, Sequence
from typing import Any

from vtolftc.runners.campaign.outcome import outcome
from vtolftc.runners.campaign.scenarios import CampaignScenario

__all__ = [
    "WORKER_SCENARIOS",
    "base_scenario",
    "cached_airframe",
    "dask_batch_size",
    "fly_batch",
    "fly_scenario",
    "pool_context",
    "prepare_dask",
    "run_dask",
    "run_local",
    "vehicle_options",
    "warm_keys",
    "warm_up",
    "warm_up_keys",
]

_AIRFRAMES: dict[str | None, Any] = {}
_BASE_SCENARIOS: dict[tuple[float, str | None], Any] = {}
_WARM: set[tuple[str | None, str | None, str]] = set()
WORKER_SCENARIOS = 100
"""Scenarios a local pool worker flies before a fresh one replaces it (a fork of the warmed
campaign process: a few ms): its memory is then bounded whatever the campaign's length (a
fresh worker's allocators grow over its first few hundred flights before they settle)."""
WARM_UP_FLIGHT_S = 2.0
"""Simulated length of :func:`warm_up`'s flight per controller (s): arming and the start of
the take-off; kernels of later phases are loaded from numba's cache by the first flight."""


def cached_airframe(path: str | None) -> Any:
    """The airframe (loaded once per process and path)."""
    af = _AIRFRAMES.get(path)
    if af is None:
        from vtolftc.airframe.loader import load_airframe

        af = _AIRFRAMES[path] = load_airframe(path)
    return af


def base_scenario(duration_s: float, airframe_path: str | None = None) -> Any:
    """The campaign's timeline (:func:`vtolftc.runners.scenario.paper_scenario` of case 0,
    ``duration_s`` s) without extra faults, built once per process and duration (it reads
    the fault-case file)."""
    key = (float(duration_s), airframe_path)
    base = _BASE_SCENARIOS.get(key)
    if base is None:
        from vtolftc.runners.scenario import paper_scenario

        base = _BASE_SCENARIOS[key] = paper_scenario(0, float(duration_s),
                                                     airframe=cached_airframe(airframe_path))
    return base


def _campaign_scenario(sc: CampaignScenario, faults: Sequence[Any]) -> Any:
    """``paper_scenario(0, sc.duration_s, extra_faults=faults, window_start_s=...)`` from the
    cached :func:`base_scenario`: the same actions in the same (stable) order."""
    import dataclasses

    from vtolftc.runners.scenario import Action

    base = base_scenario(sc.duration_s, sc.airframe_path)
    actions = list(base.actions)
    actions += [Action(f.start_s, "fault", f"fault {f.describe()}", fault=f) for f in faults]
    actions.sort(key=lambda a: a.t_s)
    return dataclasses.replace(base, actions=tuple(actions), window_start_s=sc.window_start_s)


def vehicle_options(steady_ned_m_s: Sequence[float] = (0.0, 0.0, 0.0),
                    gusts: Sequence[tuple[float, float, Sequence[float]]] = (),
                    mass_scale: float = 1.0,
                    inertia_scale: Sequence[float] = (1.0, 1.0, 1.0),
                    cg_offset_m: Sequence[float] = (0.0, 0.0, 0.0),
                    noise_level: str = "none", seed: int = 0) -> dict[str, Any]:
    """The ``vehicle_options`` of :func:`vtolftc.runners.scenario.run_scenario` for a wind (steady
    NED
    m/s, gusts as (start s, duration s, amplitude NED m/s)), an airframe perturbation and a
    state-noise level (``none`` | ``typical``) with its seed. Shared by the campaign and
    ``vtolftc fly``, so both fly the very same vehicle."""
    from vtolftc.firmware_sim.vehicle.model import Perturbation
    from vtolftc.firmware_sim.vehicle.sensors import StateNoise
    from vtolftc.firmware_sim.vehicle.wind import Gust, WindField

    opts: dict[str, Any] = {}
    steady = tuple(float(v) for v in steady_ned_m_s)
    if steady != (0.0, 0.0, 0.0) or gusts:
        opts["wind"] = WindField(steady, tuple(Gust(float(s), float(d), tuple(a))
                                               for s, d, a in gusts))
    pert = Perturbation(float(mass_scale), tuple(float(v) for v in inertia_scale),
                        tuple(float(v) for v in cg_offset_m))
    if not pert.is_identity:
        opts["perturbation"] = pert
    if noise_level == "typical":
        opts["state_noise"] = StateNoise.typical()
        opts["seed"] = int(seed)
    elif noise_level != "none":
        raise ValueError(f"noise level {noise_level!r}: expected none or typical")
    return opts


def _none_nan(v: Any) -> float:
    return math.nan if v is None else float(v)


def fly_scenario(sc: CampaignScenario) -> dict[str, Any]:
    """Fly one scenario and return its result row (never raises on a failing flight: an
    exception inside the simulation is the outcome ``error`` with its message)."""
    from vtolftc.firmware_sim.vehicle.faults import Fault
    from vtolftc.runners.scenario import run_scenario

    t0 = time.perf_counter()
    row: dict[str, Any] = {
        "index": sc.index, "scenario_id": sc.scenario_id, "controller": sc.controller,
        "family": sc.family, "faults": sc.faults_label, "phase": sc.phase,
        "fault_time_s": sc.fault_time_s, "wind": sc.wind.name,
        "perturbation": sc.perturbation.name, "seed": sc.seed,
        "duration_s": sc.duration_s, "fly_command": sc.fly_command(),
    }
    try:
        af = cached_airframe(sc.airframe_path)
        faults = [Fault(a, kind, loss, sc.fault_time_s) for a, kind, loss in sc.fault_set.faults]
        scen = _campaign_scenario(sc, faults)
        p = sc.perturbation
        opts = vehicle_options(sc.wind.steady_ned_m_s, sc.gusts(), p.mass_scale,
                               p.inertia_scale, p.cg_offset_m, sc.noise_level, sc.seed)
        res = run_scenario(scen, sc.controller, airframe=af, gains_dir=sc.gains_dir,
                           vehicle_options=opts)
    except Exception as exc:  # a failing simulation is a result, not a lost campaign
        row.update(outcome="error", survived=False, crashed=True,
                   error=f"{type(exc).__name__}: {exc} "
                         f"({traceback.extract_tb(exc.__traceback__)[-1].name})",
                   sim_time_s=math.nan, run_wall_time_s=math.nan,
                   wall_time_s=time.perf_counter() - t0)
        return row
    _WARM.add((sc.airframe_path, sc.gains_dir, sc.controller))
    m = res.metrics
    counts = res.allocation.get("counts", {})
    row.update(
        outcome=outcome(m), survived=outcome(m) == "survived", crashed=bool(m["crashed"]),
        crash_time_s=_none_nan(m["crash_time_s"]),
        final_altitude_error_m=float(m["final_altitude_error_m"]),
        final_roll_deg=float(m["final_roll_deg"]), final_pitch_deg=float(m["final_pitch_deg"]),
        final_airspeed_m_s=float(m["final_airspeed_m_s"]),
        rmse_altitude_m=float(m["rmse_altitude_m"]), rmse_roll_deg=float(m["rmse_roll_deg"]),
        rmse_pitch_deg=float(m["rmse_pitch_deg"]), rmse_yaw_deg=float(m["rmse_yaw_deg"]),
        max_attitude_excursion_deg=float(m["max_attitude_excursion_deg"]),
        max_altitude_lost_m=float(m["max_altitude_lost_m"]),
        transition_complete_s=_none_nan(m["transition_complete_s"]),
        transition_duration_s=_none_nan(m["transition_duration_s"]),
        quad_chute=bool(m["quad_chute"]),
        saturated_share=float(m["allocation_saturated_share"]),
        allocation_fallbacks=int(counts.get("fallback", 0) + counts.get("invalid_input", 0)),
        error="", sim_time_s=float(res.sim_time_s), run_wall_time_s=float(res.wall_time_s),
        wall_time_s=time.perf_counter() - t0)
    return row


def fly_batch(scenarios: Sequence[CampaignScenario]) -> list[dict[str, Any]]:
    """The rows of ``scenarios`` flown one after the other in this process (a Dask task)."""
    return [fly_scenario(sc) for sc in scenarios]


def warm_keys(scenarios: Sequence[CampaignScenario]) -> list[tuple[str | None, str | None, str]]:
    """The distinct (airframe path, gains folder, controller) of ``scenarios``, in order."""
    return list(dict.fromkeys((sc.airframe_path, sc.gains_dir, sc.controller)
                              for sc in scenarios))


def warm_up_keys(keys: Sequence[tuple[str | None, str | None, str]]) -> float:
    """Prepare this process for the flights of ``keys`` (see :func:`warm_keys`): load their
    airframes and fly a :data:`WARM_UP_FLIGHT_S` flight of each, which imports the flight
    code, reads the gain files and compiles (or loads from numba's cache) the kernels of the
    first control steps. Each key once per process; a failing one is left to the scenarios
    (their rows say ``error``). Returns the wall time spent (s)."""
    t0 = time.perf_counter()
    for key in keys:
        key = (key[0], key[1], key[2])
        if key in _WARM:
            continue
        _WARM.add(key)
        try:
            from vtolftc.runners.scenario import run_scenario

            run_scenario(base_scenario(WARM_UP_FLIGHT_S, key[0]), key[2],
                         airframe=cached_airframe(key[0]), gains_dir=key[1])
        except Exception:  # each scenario reports its own error in its row
            continue
    return time.perf_counter() - t0


def warm_up(scenarios: Sequence[CampaignScenario]) -> float:
    """:func:`warm_up_keys` of the (airframe, gains, controller) of ``scenarios``; returns
    the wall time spent (s)."""
    return warm_up_keys(warm_keys(scenarios))


# --------------------------------------------------------------------------------------------
# Local process pool
# --------------------------------------------------------------------------------------------

def _watch_parent(parent: int) -> None:
    """Exit when the process that started this worker is gone (e.g. SIGKILLed): a pool
    worker never outlives its campaign."""
    while os.getppid() == parent:
        time.sleep(0.5)
    os._exit(1)


def _worker_init(airframe_path: str | None) -> None:
    # a forked worker inherits the parent's unwritten stdout buffer and would write it again
    # at its exit: its own output (diagnostics only) goes to stderr, and that copy never
    sys.stdout = sys.stderr
    signal.signal(signal.SIGINT, signal.SIG_IGN)   # the parent handles Ctrl-C
    signal.signal(signal.SIGTERM, signal.SIG_DFL)
    threading.Thread(target=_watch_parent, args=(os.getppid(),), daemon=True).start()
    cached_airframe(airframe_path)


def pool_context() -> Any:
    """The multiprocessing context of the local pool: ``fork`` (the workers inherit this
    process's imports, caches and compiled kernels) when this process runs no other thread,
    since only then is a fork safe; otherwise a ``forkserver`` that imports the flight code
    once for all workers (``spawn`` where neither exists)."""
    methods = multiprocessing.get_all_start_methods()
    if "fork" in methods and threading.active_count() == 1:
        return multiprocessing.get_context("fork")
    if "forkserver" in methods:
        ctx = multiprocessing.get_context("forkserver")
        ctx.set_forkserver_preload([__name__, "vtolftc.runners.scenario"])
        return ctx
    return multiprocessing.get_context("spawn")


def run_local(scenarios: Sequence[CampaignScenario], jobs: int | None = None, *,
              worker_scenarios: int | None = None) -> Iterator[dict[str, Any]]:
    """Rows of ``scenarios`` flown on ``jobs`` local processes (default: all cores), as they
    finish. ``jobs == 1`` flies them in this process. A worker flies ``worker_scenarios``
    (default :data:`WORKER_SCENARIOS`; five times that from a forkserver, where a new worker
    loads its kernels again) and is then replaced by a fresh one, so no worker's memory grows
    with the campaign's length. Closing the generator (or an exception in the consumer, e.g.
    KeyboardInterrupt) terminates the workers."""
    n = jobs or os.cpu_count() or 1
    af_path = scenarios[0].airframe_path if scenarios else None
    if n <= 1:
        for sc in scenarios:
            yield fly_scenario(sc)
        return
    ctx = pool_context()
    fork = ctx.get_start_method() == "fork"
    if fork:
        warm_up(scenarios)
        for stream in (sys.stdout, sys.stderr):  # nothing buffered here is written twice
            with contextlib.suppress(Exception):
                stream.flush()
    per_worker = worker_scenarios or (WORKER_SCENARIOS if fork else 5 * WORKER_SCENARIOS)
    pool = ctx.Pool(n, initializer=_worker_init, initargs=(af_path,),
                    maxtasksperchild=max(1, int(per_worker)))
    try:
        yield from pool.imap_unordered(fly_scenario, scenarios, chunksize=1)
        pool.close()
    finally:
        pool.terminate()
        pool.join()


# --------------------------------------------------------------------------------------------
# Dask distributed (the client, plugins and task size: vtolftc.runners.campaign.dask_run)
# --------------------------------------------------------------------------------------------

def dask_batch_size(n_scenarios: int, n_workers: int, duration_s: float = 60.0) -> int:
    """See :func:`vtolftc.runners.campaign.dask_run.dask_batch_size`."""
    from vtolftc.runners.campaign.dask_run import dask_batch_size as size

    return size(n_scenarios, n_workers, duration_s)


def prepare_dask(client: Any, scenarios: Sequence[CampaignScenario]) -> None:
    """Register the campaign's worker plugins on ``client``'s cluster for ``scenarios``
    (:func:`vtolftc.runners.campaign.dask_run.prepare_workers`: each worker warms with
    :func:`warm_up_keys` in its task thread, its profiler paused); returns at once."""
    from vtolftc.runners.campaign.dask_run import prepare_workers

    prepare_workers(client, warm_up_keys, warm_keys(scenarios))


def run_dask(scenarios: Sequence[CampaignScenario], scheduler: Any, *,
             tag: str = "campaign", batch: int | None = None) -> Iterator[dict[str, Any]]:
    """Rows of ``scenarios`` flown as tasks on a Dask cluster, as they finish.

    Parameters
    ----------
    scenarios
        The scenarios to fly.
    scheduler
        The scheduler's address (``tcp://HOST:PORT``: a client is opened and closed here) or
        a :class:`distributed.Client` (kept open; typically one :func:`prepare_dask` was
        called on earlier, which this call repeats at no cost).
    tag
        Part of the task keys (``vtolftc-TAG-...``).
    batch
        Scenarios per task (default
        :func:`~vtolftc.runners.campaign.dask_run.dask_batch_size` of the cluster's workers).

    Each worker needs this package (same version) installed; see ``docs/campaigns/README.md``.
    A task flies its batch with :func:`fly_batch`; its future is released as soon as its
    rows are here. The worker plugins (:func:`prepare_dask`) are unregistered at the end.
    Closing the generator cancels what is not done.
    """
    from distributed import as_completed

    from vtolftc.runners.campaign.dask_run import connect, release_workers

    own = isinstance(scheduler, str)
    client = connect(scheduler) if own else scheduler
    pending: set[Any] = set()
    try:
        prepare_dask(client, scenarios)
        if batch is None:
            dur = max((sc.duration_s for sc in scenarios), default=60.0)
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

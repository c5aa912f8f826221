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
"""

from __future__ import annotations

import math
import multiprocessing
import os
import signal
import threading
import time
import traceback
from collections.abc import Iterator, Sequence
from typing import Any

from vtolftc.runners.campaign.outcome import outcome
from vtolftc.runners.campaign.scenarios import CampaignScenario

__all__ = ["fly_scenario", "run_dask", "run_local", "vehicle_options"]

_AIRFRAMES: dict[str | None, Any] = {}


def cached_airframe(path: str | None) -> Any:
    """The airframe (loaded once per process and path)."""
    af = _AIRFRAMES.get(path)
    if af is None:
        from vtolftc.airframe.loader import load_airframe

        af = _AIRFRAMES[path] = load_airframe(path)
    return af


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
    from vtolftc.runners.scenario import paper_scenario, run_scenario

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
        scen = paper_scenario(0, sc.duration_s, airframe=af, extra_faults=faults,
                              window_start_s=sc.window_start_s)
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
    signal.signal(signal.SIGINT, signal.SIG_IGN)   # the parent handles Ctrl-C
    signal.signal(signal.SIGTERM, signal.SIG_DFL)
    threading.Thread(target=_watch_parent, args=(os.getppid(),), daemon=True).start()
    cached_airframe(airframe_path)


def run_local(scenarios: Sequence[CampaignScenario], jobs: int | None = None,
              ) -> Iterator[dict[str, Any]]:
    """Rows of ``scenarios`` flown on ``jobs`` local processes (default: all cores), as they
    finish. ``jobs == 1`` flies them in this process. Closing the generator (or an exception
    in the consumer, e.g. KeyboardInterrupt) terminates the workers."""
    n = jobs or os.cpu_count() or 1
    af_path = scenarios[0].airframe_path if scenarios else None
    if n <= 1:
        for sc in scenarios:
            yield fly_scenario(sc)
        return
    ctx = multiprocessing.get_context("forkserver" if os.name == "posix" else "spawn")
    pool = ctx.Pool(n, initializer=_worker_init, initargs=(af_path,))
    try:
        yield from pool.imap_unordered(fly_scenario, scenarios, chunksize=1)
        pool.close()
    finally:
        pool.terminate()
        pool.join()


# --------------------------------------------------------------------------------------------
# Dask distributed
# --------------------------------------------------------------------------------------------

def run_dask(scenarios: Sequence[CampaignScenario], address: str, *,
             tag: str = "campaign") -> Iterator[dict[str, Any]]:
    """Rows of ``scenarios`` flown as tasks on the Dask scheduler at ``address``, as they
    finish. Each worker needs this package (same version) installed; see
    ``docs/campaigns/README.md``. Closing the generator cancels what is not done."""
    from distributed import Client, as_completed

    try:
        client = Client(address, timeout="30s", set_as_default=False)
    except (OSError, TimeoutError) as exc:
        raise ConnectionError(f"--scheduler {address}: cannot reach a Dask scheduler "
                              f"({exc})") from None
    futures = []
    try:
        futures = client.map(fly_scenario, list(scenarios),
                             key=[f"vtolftc-{tag}-{sc.scenario_id}" for sc in scenarios],
                             pure=False, retries=1)
        for fut in as_completed(futures, loop=client.loop):
            yield fut.result()
    finally:
        if futures:
            client.cancel(futures)
        client.close()

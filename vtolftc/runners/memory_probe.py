"""Resident memory of the two SITL processes against simulated time (issue 24).

:func:`fly_sampled` flies a :class:`~vtolftc.runners.sitl.SitlConfig` (the paper's scenario of
its case) and samples the resident set size (``VmRSS`` of ``/proc/PID/status``, Linux) of the
autopilot and vehicle processes it started, by pid, each sample paired with the simulated time
the ground station sees. Memory grows per row logged, and rows are logged per *simulated*
second, so the slope against simulated time is what a long flight grows by. Used by
``benchmarks/bench_memory.py`` (>= 10 simulated minutes) and ``tests/test_memory_sitl.py``
(a shorter flight in CI).
"""

from __future__ import annotations

import threading
from typing import Any

import numpy as np

from vtolftc.runners.campaign.memwatch import rss_bytes
from vtolftc.runners.scenario import paper_scenario
from vtolftc.runners.sitl import SitlConfig, SitlRun

__all__ = ["fly_sampled", "slope_mb_per_h"]


def fly_sampled(cfg: SitlConfig, every_sim_s: float = 1.0,
                poll_wall_s: float = 0.02) -> tuple[np.ndarray, Any]:
    """Fly ``cfg`` sampling both processes' RSS every ``every_sim_s`` of *simulated* time.

    The ground station's simulated time is polled every ``poll_wall_s`` wall seconds and a
    sample is taken once it has advanced by ``every_sim_s`` since the last one, so how many
    samples a flight yields depends on the simulated time flown, not on how fast this
    machine runs the lockstep (as long as one poll period is shorter than ``every_sim_s``
    of simulated time: below 50x real time with the defaults).

    Parameters
    ----------
    cfg : SitlConfig
        The flight (its case's paper scenario, ``cfg.duration_s`` of simulated time).
    every_sim_s : float
        Sampling period [simulated s], > 0.
    poll_wall_s : float
        Polling period [wall s], > 0.

    Returns
    -------
    samples : ndarray, shape (N, 3)
        Simulated time [s], autopilot RSS [KB], vehicle RSS [KB]; simulated time strictly
        increasing, consecutive samples >= ``every_sim_s`` apart, below ``cfg.duration_s``.
    result : ScenarioResult
        The flight's result (``sim_time_s``, ``real_time_factor``, metrics).
    """
    if not (every_sim_s > 0 and poll_wall_s > 0):
        raise ValueError(f"every_sim_s {every_sim_s} and poll_wall_s {poll_wall_s} must be > 0")
    samples: list[tuple[float, float, float]] = []
    out: dict[str, Any] = {}
    with SitlRun(cfg) as run:
        run.start()
        pids = {name: p.pid for name, p in run.procs.items()}
        if set(pids) != {"autopilot", "vehicle"}:
            raise RuntimeError(f"expected the autopilot and vehicle processes, got {sorted(pids)}")

        def fly() -> None:
            try:
                out["res"] = run.fly(paper_scenario(cfg.case, cfg.duration_s))
            except BaseException as exc:  # handed to the calling thread
                out["exc"] = exc

        th = threading.Thread(target=fly, daemon=True)
        th.start()
        assert run.gs is not None
        while th.is_alive():
            t_sim = run.gs.snapshot().sim_time_s
            if t_sim < cfg.duration_s and (not samples
                                           or t_sim >= samples[-1][0] + every_sim_s):
                ap, veh = rss_bytes(pids["autopilot"]), rss_bytes(pids["vehicle"])
                if ap is not None and veh is not None:
                    samples.append((t_sim, ap / 1024.0, veh / 1024.0))
            th.join(timeout=poll_wall_s)
    if "exc" in out:
        raise out["exc"]
    return np.array(samples), out["res"]


def slope_mb_per_h(t_s: np.ndarray, rss_kb: np.ndarray, from_s: float | None = None) -> float:
    """Least-squares slope of ``rss_kb`` [KB] against ``t_s`` [simulated s], as MB per
    simulated hour, over ``t_s >= from_s`` (default: the second half of the time span)."""
    if from_s is None:
        from_s = t_s[0] + 0.5 * (t_s[-1] - t_s[0])
    keep = t_s >= from_s
    return float(np.polyfit(t_s[keep], rss_kb[keep], 1)[0]) * 3600.0 / 1024.0

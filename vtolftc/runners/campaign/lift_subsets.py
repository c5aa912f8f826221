"""k lift rotors off at one moment of the flight: which subsets the oracle calls recoverable,
and which of them a controller survives.

:func:`recoverable_subsets` judges every k-subset of the airframe's lift rotors switched off at
``fault_time_s`` with the physical recoverability oracle (:mod:`vtolftc.runners.campaign.oracle`,
one nominal reference flight, calm air); :func:`fly_subsets` flies the paper's timeline
(:func:`vtolftc.runners.scenario.paper_scenario`, case 0) with those rotors off from
``fault_time_s`` and judges each flight by the campaign's outcome
(:mod:`vtolftc.runners.campaign.outcome`), on ``jobs`` processes. Used by the degraded-lift
transition test and ``benchmarks/lift_subsets.py``.
"""

from __future__ import annotations

import itertools
import multiprocessing
from collections.abc import Sequence
from typing import Any

__all__ = ["fly_subset", "fly_subsets", "lift_subsets", "recoverable_subsets"]


def lift_subsets(k: int, airframe_path: str | None = None) -> list[tuple[str, ...]]:
    """Every k-subset of the airframe's lift rotors, as actuator names (``rotor_1a`` ...)."""
    from vtolftc.runners.campaign.execute import cached_airframe

    af = cached_airframe(airframe_path)
    names = [n for n in af.actuator_names[: len(af.lift_rotors)]]
    return [tuple(c) for c in itertools.combinations(names, k)]


def recoverable_subsets(subsets: Sequence[tuple[str, ...]], fault_time_s: float,
                        airframe_path: str | None = None) -> dict[tuple[str, ...], float]:
    """The oracle's recovery margin [rad/s^2] of each subset switched off at ``fault_time_s``
    [s] of the nominal reference flight; recoverable where it is in the answer and >= the
    oracle's threshold (only those are returned)."""
    from vtolftc.runners.campaign.execute import cached_airframe
    from vtolftc.runners.campaign.oracle import judge, reference_conditions

    af = cached_airframe(airframe_path)
    pc = reference_conditions([fault_time_s], airframe_path)[fault_time_s]
    cache: dict[Any, Any] = {}
    out: dict[tuple[str, ...], float] = {}
    for s in subsets:
        r = judge(af, [(a, "off", 1.0) for a in s], pc, model_cache=cache)
        if r.recoverable:
            out[tuple(s)] = float(r.margin)
    return out


def fly_subset(args: tuple[tuple[str, ...], float, float, str, str | None]
               ) -> dict[str, Any]:
    """Fly one subset: ``(rotors, fault_time_s, duration_s, controller, airframe_path)``;
    returns the outcome and a few metrics of the flight."""
    from vtolftc.firmware_sim.vehicle.faults import Fault
    from vtolftc.runners.campaign.execute import cached_airframe
    from vtolftc.runners.campaign.outcome import outcome
    from vtolftc.runners.scenario import paper_scenario, run_scenario

    rotors, t_fault, duration, controller, path = args
    af = cached_airframe(path)
    faults = [Fault(a, "off", 1.0, t_fault) for a in rotors]
    res = run_scenario(paper_scenario(0, duration, airframe=af, extra_faults=faults),
                       controller, airframe=af)
    m = res.metrics
    return {"rotors": tuple(rotors), "outcome": outcome(m),
            "crashed": bool(m["crashed"]),
            "max_altitude_lost_m": float(m["max_altitude_lost_m"]),
            "final_altitude_error_m": float(m["final_altitude_error_m"]),
            "transition_complete_s": m["transition_complete_s"],
            "quad_chute": bool(m["quad_chute"])}


def fly_subsets(subsets: Sequence[tuple[str, ...]], fault_time_s: float, duration_s: float,
                controller: str = "gs-shif", jobs: int = 1,
                airframe_path: str | None = None) -> list[dict[str, Any]]:
    """Fly every subset (see :func:`fly_subset`) on ``jobs`` processes, in subset order."""
    work = [(tuple(s), float(fault_time_s), float(duration_s), controller, airframe_path)
            for s in subsets]
    if jobs <= 1 or len(work) <= 1:
        return [fly_subset(w) for w in work]
    with multiprocessing.get_context("spawn").Pool(min(jobs, len(work))) as pool:
        return pool.map(fly_subset, work, chunksize=1)

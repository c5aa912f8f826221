"""Every campaign scenario judged by the physical recoverability oracle.

For each scenario the columns ``recoverable`` and ``recovery_margin`` (rad/s^2) say whether
the actuators left after its faults can hold the trim at its flight condition, and by how
much (:mod:`vtolftc.firmware_sim.vehicle.recoverability` defines both). The verdict belongs
to the scenario's fault set and condition, never to a controller: the controllers of one
condition share it, and survival is reported against it (survived / recoverable).

The flight condition of a phase (its injection time) is read from one **reference flight**:
the campaign's timeline (:func:`vtolftc.runners.scenario.paper_scenario`, no fault, calm air, the
airframe file as it is) flown once with GS-SHIF, up to the last injection time. At each
injection time it gives the speed over the ground along the heading, the pitch and the
actuator positions (where a stuck actuator stays), and the autopilot's mode: in the
multicopter modes (on the ground, takeoff, hover, back transition, land) the flight software
keeps the pushers off, so the oracle holds them there too. The scenario's airframe
perturbation and its wind then enter the oracle, as the wind relative to the vehicle's
steady motion: in the multicopter modes the autopilot holds the position, so the whole
steady wind and, as a second condition, the steady wind plus each gust's peak (amplitude);
in forward flight (transition, fixed-wing) the vehicle drifts with the air mass (its
airspeed is the reference flight's, its ground track is not held), so only each gust's peak.
The smallest margin counts. In a transition the forward force is free: the transition is an
acceleration (the reference flight's pushers are well above what holds the airspeed), and a
deceleration is a return to hover, which the hover phase judges. One reference flight per
campaign (a few seconds) and one or two LPs per distinct (fault set, phase, wind,
perturbation), cached: 444 distinct ones in about 15 s.
"""

from __future__ import annotations

import math
from collections.abc import Iterable, Sequence
from dataclasses import dataclass
from typing import Any

import numpy as np

from vtolftc.runners.campaign.scenarios import CampaignScenario

__all__ = ["PhaseCondition", "judge", "oracle_columns", "reference_conditions"]

_MULTICOPTER_MODES = ("IDLE", "TAKEOFF", "HOVER", "BACK_TRANSITION", "LAND")
_TRANSITION_MODES = ("FRONT_TRANSITION", "BACK_TRANSITION")


@dataclass(frozen=True)
class PhaseCondition:
    """The reference flight at one injection time: the oracle's condition and the mode."""

    time_s: float
    mode: str                      # the autopilot's FlightMode name
    speed_m_s: float               # over the ground along the heading (calm: the airspeed)
    pitch_rad: float
    yaw_rad: float                 # the heading (the oracle's condition flies along it)
    actuator_positions: tuple[float, ...]

    def wind_in_heading_frame(self, wind_ned_m_s: Sequence[float]) -> tuple[float, float, float]:
        """A NED wind (m/s) in the frame of a vehicle heading north, as the oracle flies."""
        c, s = math.cos(self.yaw_rad), math.sin(self.yaw_rad)
        n, e, d = (float(v) for v in wind_ned_m_s)
        return (c * n + s * e, -s * n + c * e, d)

    @property
    def multicopter(self) -> bool:
        """True in the modes where the flight software keeps the pushers off."""
        return self.mode in _MULTICOPTER_MODES


class _Recorder:
    """A run observer keeping the vehicle truth at the first sample at or after each time."""

    def __init__(self, times_s: Iterable[float]) -> None:
        self.todo = sorted({float(t) for t in times_s})
        self.found: dict[float, PhaseCondition] = {}

    def on_start(self, info: dict[str, Any]) -> None:
        """Nothing to do at the start."""

    def on_sample(self, sample: Any) -> None:
        """Record the truth when an injection time is reached."""
        t = sample.time_usec * 1e-6
        while self.todo and t >= self.todo[0] - 1e-9 and sample.truth is not None:
            tr = sample.truth
            _, pitch, yaw = (float(v) for v in tr.euler_rad)
            v = np.asarray(tr.vel_ned_m_s, dtype=float)
            speed = float(v[0] * math.cos(yaw) + v[1] * math.sin(yaw))
            self.found[self.todo.pop(0)] = PhaseCondition(
                t, sample.status.mode.name, speed, pitch, yaw,
                tuple(float(x) for x in tr.actuator_positions))

    def on_event(self, time_usec: int, kind: str, text: str) -> None:
        """Events are not needed."""

    def on_finish(self, metrics: dict[str, Any]) -> None:
        """Nothing to close."""


def reference_conditions(times_s: Sequence[float], airframe_path: str | None = None,
                         gains_dir: str | None = None) -> dict[float, PhaseCondition]:
    """The reference flight's condition at each of ``times_s`` (s, simulated); a time the
    flight did not reach (it crashed) is missing from the answer."""
    from vtolftc.airframe.loader import load_airframe
    from vtolftc.runners.scenario import paper_scenario, run_scenario

    af = load_airframe(airframe_path)
    rec = _Recorder(times_s)
    if not rec.todo:
        return {}
    duration = max(rec.todo) + 0.05
    run_scenario(paper_scenario(0, duration, airframe=af), "gs-shif", airframe=af,
                 gains_dir=gains_dir, observers=[rec])
    return rec.found


def _key(sc: CampaignScenario) -> tuple[Any, ...]:
    p = sc.perturbation
    return (sc.fault_set.faults, sc.fault_time_s, sc.wind.steady_ned_m_s,
            tuple(g.amplitude_ned_m_s for g in sc.wind.gusts), p.mass_scale,
            tuple(p.inertia_scale), tuple(p.cg_offset_m))


def oracle_columns(scenarios: Sequence[CampaignScenario],
                   conditions: dict[float, PhaseCondition] | None = None,
                   ) -> dict[str, dict[str, Any]]:
    """``{scenario_id: {"recoverable": bool, "recovery_margin": float}}`` for every scenario
    (margin NaN and not recoverable where the reference flight did not reach the phase).
    ``conditions`` defaults to :func:`reference_conditions` of the scenarios' phase times."""
    from vtolftc.airframe.loader import load_airframe
    from vtolftc.firmware_sim.vehicle.model import Perturbation
    if not scenarios:
        return {}
    first = scenarios[0]
    if conditions is None:
        conditions = reference_conditions({sc.fault_time_s for sc in scenarios},
                                          first.airframe_path, first.gains_dir)
    af = load_airframe(first.airframe_path)
    cache: dict[tuple[Any, ...], dict[str, Any]] = {}
    models: dict[tuple[Any, ...], Any] = {}
    out: dict[str, dict[str, Any]] = {}
    for sc in scenarios:
        k = _key(sc)
        if k not in cache:
            pc = conditions.get(sc.fault_time_s)
            if pc is None:
                cache[k] = {"recoverable": False, "recovery_margin": math.nan}
            else:
                p = sc.perturbation
                pert = (None if p.nominal else
                        Perturbation(p.mass_scale, p.inertia_scale, p.cg_offset_m))
                r = judge(af, sc.fault_set.faults, pc, sc.wind.steady_ned_m_s,
                          [g.amplitude_ned_m_s for g in sc.wind.gusts], pert, models)
                cache[k] = {"recoverable": bool(r.recoverable),
                            "recovery_margin": float(r.margin)}
        out[sc.scenario_id] = cache[k]
    return out


def judge(af: Any, faults: Iterable[Any], pc: PhaseCondition,
          steady_ned_m_s: Sequence[float] = (0.0, 0.0, 0.0),
          gust_amplitudes_ned_m_s: Iterable[Sequence[float]] = (),
          perturbation: Any = None, model_cache: dict[Any, Any] | None = None) -> Any:
    """The oracle's answer (:class:`~vtolftc.firmware_sim.vehicle.recoverability.
    Recoverability`) for ``faults`` at the reference flight's condition ``pc`` in a wind
    (NED, m/s), by the rules of the module docstring: the pushers held in the multicopter
    modes, the steady wind felt only while the position is held, and in a transition the
    forward force free (the transition is an acceleration; a deceleration is a return to
    hover, judged at the hover phase)."""
    from vtolftc.firmware_sim.vehicle.recoverability import DEMAND, FlightCondition, assess

    pushers = [n for n in af.actuator_names if n.startswith("pusher_")]
    steady = (pc.wind_in_heading_frame(steady_ned_m_s) if pc.multicopter
              else (0.0, 0.0, 0.0))
    cond = FlightCondition(pc.mode.lower(), pc.speed_m_s, pc.pitch_rad, steady,
                           pc.actuator_positions)
    demand = DEMAND if pc.mode not in _TRANSITION_MODES else tuple(
        a for a in DEMAND if a != "Fx")
    return assess(af, faults, cond,
                  gust_peaks_ned_m_s=[pc.wind_in_heading_frame(g)
                                      for g in gust_amplitudes_ned_m_s],
                  perturbation=perturbation, hold=pushers if pc.multicopter else (),
                  demand=demand, model_cache=model_cache)

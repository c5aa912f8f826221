"""Flight metrics of a run, as the paper's table 4 and a few more.

Computed only from what every runner has: each sample's :class:`NavState` (what the autopilot
flew on) and :class:`AutopilotStatus` (its references and mode). An in-process run and a SITL
run fed with the same samples therefore give identical metrics.

Over the transition window ``t >= window_start_s`` (default 20 s, when the transition is
commanded):

- ``rmse_altitude_m``: RMSE of ``altitude_ref - altitude`` (altitude above home = -NED z);
- ``rmse_roll_deg``, ``rmse_pitch_deg``, ``rmse_yaw_deg``: RMSE of the attitude tracking error
  ``reference - measured`` (ZYX Euler; yaw error wrapped to (-180, 180] deg);
- ``max_abs_{roll,pitch,yaw}_error_deg``: largest absolute tracking error;

and over the whole run:

- ``transition_start_s``: first sample in FRONT_TRANSITION; ``transition_complete_s``: first
  sample in FIXED_WING (sim seconds, None if never); ``transition_duration_s``;
- ``quad_chute``: a front transition that ended back in HOVER;
- ``final_altitude_m``, ``final_altitude_error_m`` (last sample), ``final_airspeed_m_s``,
  ``final_{roll,pitch,yaw}_deg`` (mean over the last second);
- ``crashed``: non-finite state, ground contact in the air (altitude below 0.5 m above the
  altitude at the first armed sample, in a flying mode, after having been above 2 m), or an
  attitude beyond 60 deg of roll or pitch.
"""

from __future__ import annotations

import math
from collections.abc import Iterable
from typing import Any

from firmware_sim.autopilot.autopilot import quat_to_euler
from firmware_sim.autopilot.interface import FlightMode
from vtolftc.telemetry import TelemetrySample

__all__ = ["CRASH_ATTITUDE_DEG", "MetricsAccumulator", "compute_metrics", "is_crash"]

CRASH_ATTITUDE_DEG = 60.0
_FLYING = {FlightMode.HOVER, FlightMode.FRONT_TRANSITION, FlightMode.FIXED_WING,
           FlightMode.BACK_TRANSITION}


def _wrap_deg(x: float) -> float:
    return -((-x + 180.0) % 360.0 - 180.0)


def is_crash(altitude_above_ground_m: float, roll_rad: float, pitch_rad: float,
             flying: bool, was_high: bool) -> bool:
    """The crash criterion of the module docstring for one sample."""
    if not all(math.isfinite(v) for v in (altitude_above_ground_m, roll_rad, pitch_rad)):
        return True
    lim = math.radians(CRASH_ATTITUDE_DEG)
    if abs(roll_rad) > lim or abs(pitch_rad) > lim:
        return True
    return flying and was_high and altitude_above_ground_m < 0.5


class MetricsAccumulator:
    """Streaming metrics: ``add(sample)`` per control step, ``result()`` at any time."""

    def __init__(self, window_start_s: float = 20.0) -> None:
        self.window_start_s = float(window_start_s)
        self.n = 0
        self.n_win = 0
        self._se = [0.0, 0.0, 0.0, 0.0]          # altitude, roll, pitch, yaw squared errors
        self._max = [0.0, 0.0, 0.0]
        self.transition_start_s: float | None = None
        self.transition_complete_s: float | None = None
        self.quad_chute = False
        self.crashed = False
        self.crash_time_s: float | None = None
        self._ground: float | None = None
        self._was_high = False
        self._prev_mode: FlightMode | None = None
        self._last: dict[str, float] = {}
        self._tail: list[tuple[float, float, float, float]] = []
        self.t_last = 0.0

    def add(self, s: TelemetrySample) -> None:
        t = s.time_usec * 1e-6
        self.t_last = t
        nav, st = s.nav, s.status
        roll, pitch, yaw = quat_to_euler(nav.q_wxyz)
        h = -float(nav.pos_ned_m[2])
        mode = FlightMode(st.mode)
        if self._ground is None and st.armed:
            self._ground = h
        ground = self._ground if self._ground is not None else h
        if h - ground > 2.0:
            self._was_high = True
        if not self.crashed and is_crash(h - ground, roll, pitch, mode in _FLYING,
                                         self._was_high):
            self.crashed = True
            self.crash_time_s = t
        if mode == FlightMode.FRONT_TRANSITION and self.transition_start_s is None:
            self.transition_start_s = t
        if mode == FlightMode.FIXED_WING and self.transition_complete_s is None:
            self.transition_complete_s = t
        if self._prev_mode == FlightMode.FRONT_TRANSITION and mode == FlightMode.HOVER:
            self.quad_chute = True
        self._prev_mode = mode
        self.n += 1
        ref = st.attitude_ref_rad
        e_h = float(st.altitude_ref_m) - h
        e = (math.degrees(float(ref[0]) - roll), math.degrees(float(ref[1]) - pitch),
             _wrap_deg(math.degrees(float(ref[2]) - yaw)))
        if t >= self.window_start_s:
            self.n_win += 1
            self._se[0] += e_h * e_h
            for k in range(3):
                self._se[k + 1] += e[k] * e[k]
                self._max[k] = max(self._max[k], abs(e[k]))
        self._last = {"altitude": h, "altitude_error": e_h, "airspeed": float(nav.airspeed_m_s)}
        self._tail.append((t, math.degrees(roll), math.degrees(pitch), math.degrees(yaw)))
        if len(self._tail) > 4096 or (self._tail and t - self._tail[0][0] > 1.0 + 1e-9):
            while self._tail and t - self._tail[0][0] > 1.0 + 1e-9:
                self._tail.pop(0)

    def result(self) -> dict[str, Any]:
        n = max(self.n_win, 1)
        rm = [math.sqrt(x / n) if self.n_win else math.nan for x in self._se]
        tail = self._tail or [(0.0, math.nan, math.nan, math.nan)]
        dur = (self.transition_complete_s - self.transition_start_s
               if self.transition_complete_s is not None and self.transition_start_s is not None
               else None)
        return {
            "window_start_s": self.window_start_s,
            "samples": self.n,
            "samples_in_window": self.n_win,
            "duration_s": self.t_last,
            "rmse_altitude_m": rm[0],
            "rmse_roll_deg": rm[1],
            "rmse_pitch_deg": rm[2],
            "rmse_yaw_deg": rm[3],
            "max_abs_roll_error_deg": self._max[0],
            "max_abs_pitch_error_deg": self._max[1],
            "max_abs_yaw_error_deg": self._max[2],
            "transition_start_s": self.transition_start_s,
            "transition_complete_s": self.transition_complete_s,
            "transition_duration_s": dur,
            "quad_chute": self.quad_chute,
            "final_altitude_m": self._last.get("altitude", math.nan),
            "final_altitude_error_m": self._last.get("altitude_error", math.nan),
            "final_airspeed_m_s": self._last.get("airspeed", math.nan),
            "final_roll_deg": sum(r[1] for r in tail) / len(tail),
            "final_pitch_deg": sum(r[2] for r in tail) / len(tail),
            "final_yaw_deg": sum(r[3] for r in tail) / len(tail),
            "crashed": self.crashed,
            "crash_time_s": self.crash_time_s,
        }


def compute_metrics(samples: Iterable[TelemetrySample], window_start_s: float = 20.0,
                    ) -> dict[str, Any]:
    """Metrics of a sequence of samples (see the module docstring)."""
    acc = MetricsAccumulator(window_start_s)
    for s in samples:
        acc.add(s)
    return acc.result()

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
- ``max_attitude_excursion_deg``: largest ``max(|roll|, |pitch|)`` (away from level);
- ``max_altitude_lost_m``: largest ``altitude_ref - altitude`` (0 if never below);

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
from collections import deque
from collections.abc import Iterable, Sequence
from typing import Any

import numpy as np
from numpy.typing import NDArray

from vtolftc.protocols.hil import NavState
from vtolftc.rotation import quat_to_euler
from vtolftc.telemetry.autopilot_status import FlightMode
from vtolftc.telemetry.samples import TelemetrySample

__all__ = ["CRASH_ATTITUDE_DEG", "MetricsAccumulator", "compute_metrics", "is_crash"]

CRASH_ATTITUDE_DEG = 60.0
_CRASH_ATTITUDE_RAD = math.radians(CRASH_ATTITUDE_DEG)
_M_FIXED_WING = FlightMode.FIXED_WING
_M_FRONT_TRANSITION = FlightMode.FRONT_TRANSITION
_M_HOVER = FlightMode.HOVER
_RAD_TO_DEG = math.degrees(1.0)  # what math.degrees multiplies by (CPython)
_FLYING = {FlightMode.HOVER, FlightMode.FRONT_TRANSITION, FlightMode.FIXED_WING,
           FlightMode.BACK_TRANSITION}


def _wrap_deg(x: float) -> float:
    return -((-x + 180.0) % 360.0 - 180.0)


def is_crash(altitude_above_ground_m: float, roll_rad: float, pitch_rad: float,
             flying: bool, was_high: bool) -> bool:
    """The crash criterion of the module docstring for one sample."""
    return _is_crash(altitude_above_ground_m, roll_rad, pitch_rad, flying, was_high)


def _is_crash(h: float, roll: float, pitch: float, flying: bool, was_high: bool) -> bool:
    isf = math.isfinite
    if not (isf(h) and isf(roll) and isf(pitch)):
        return True
    if abs(roll) > _CRASH_ATTITUDE_RAD or abs(pitch) > _CRASH_ATTITUDE_RAD:
        return True
    return flying and was_high and h < 0.5


class MetricsAccumulator:
    """Streaming metrics: ``add(sample)`` per control step, ``result()`` at any time.

    ``add`` is O(1) and allocation-light (a few microseconds): it runs every control step of
    every run, in-process and in SITL.
    """

    def __init__(self, window_start_s: float = 20.0) -> None:
        self.window_start_s = float(window_start_s)
        self.n = 0
        self.n_win = 0
        self._se = [0.0, 0.0, 0.0, 0.0]          # altitude, roll, pitch, yaw squared errors
        self._max = [0.0, 0.0, 0.0]
        self._max_tilt = 0.0
        self._max_lost = 0.0
        self.transition_start_s: float | None = None
        self.transition_complete_s: float | None = None
        self.quad_chute = False
        self.crashed = False
        self.crash_time_s: float | None = None
        self._ground: float | None = None
        self._was_high = False
        self._prev_mode: FlightMode | None = None
        self._last: tuple[float, float, float] | None = None  # altitude, its error, airspeed
        self._tail: deque[tuple[float, float, float, float]] = deque()
        self.t_last = 0.0

    def add(self, s: TelemetrySample) -> None:
        """Add one control step: errors, peaks, transition and crash detection."""
        st = s.status
        self.add_step(s.time_usec, s.nav, st.mode, st.armed, st.attitude_ref_rad,
                      st.altitude_ref_m)

    def add_step(self, time_usec: int, nav: NavState, mode: FlightMode | int, armed: bool,
                 attitude_ref_rad: NDArray[np.float64] | Sequence[float],
                 altitude_ref_m: float,
                 euler_rad: tuple[float, float, float] | None = None) -> None:
        """:meth:`add` from the sample's parts (the in-process runner's path: no
        :class:`AutopilotStatus` built when nobody else reads it).

        Parameters
        ----------
        time_usec : int
            Sample time [us].
        nav : NavState
            What the autopilot flew on.
        mode, armed, attitude_ref_rad, altitude_ref_m
            The :class:`AutopilotStatus` fields of the same names (roll, pitch, yaw
            references [rad]; altitude reference above home [m]); read, never kept.
        euler_rad : tuple, optional
            ``quat_to_euler(nav.q_wxyz)`` when the caller has it already [rad].
        """
        t = time_usec * 1e-6
        self.t_last = t
        roll, pitch, yaw = quat_to_euler(nav.q_wxyz) if euler_rad is None else euler_rad
        pos = nav.pos_ned_m
        h = -(pos.tolist()[2] if type(pos) is np.ndarray and pos.shape == (3,)
              else float(pos[2]))
        if type(mode) is not FlightMode:
            mode = FlightMode(mode)
        if self._ground is None and armed:
            self._ground = h
        ground = self._ground if self._ground is not None else h
        if h - ground > 2.0:
            self._was_high = True
        if not self.crashed and _is_crash(h - ground, roll, pitch, mode in _FLYING,
                                          self._was_high):
            self.crashed = True
            self.crash_time_s = t
        if mode is _M_FRONT_TRANSITION:
            if self.transition_start_s is None:
                self.transition_start_s = t
        elif mode is _M_FIXED_WING:
            if self.transition_complete_s is None:
                self.transition_complete_s = t
        elif mode is _M_HOVER and self._prev_mode is _M_FRONT_TRANSITION:
            self.quad_chute = True
        self._prev_mode = mode
        self.n += 1
        ref = attitude_ref_rad
        r0, r1, r2 = ref.tolist() if type(ref) is np.ndarray and ref.shape == (3,) else (
            float(ref[0]), float(ref[1]), float(ref[2]))
        e_h = float(altitude_ref_m) - h
        if t >= self.window_start_s:
            e0 = (r0 - roll) * _RAD_TO_DEG
            e1 = (r1 - pitch) * _RAD_TO_DEG
            e2 = _wrap_deg((r2 - yaw) * _RAD_TO_DEG)
            self.n_win += 1
            se, mx = self._se, self._max
            se[0] += e_h * e_h
            se[1] += e0 * e0
            se[2] += e1 * e1
            se[3] += e2 * e2
            a = abs(e0)
            if a > mx[0]:
                mx[0] = a
            a = abs(e1)
            if a > mx[1]:
                mx[1] = a
            a = abs(e2)
            if a > mx[2]:
                mx[2] = a
            a = abs(roll) if abs(roll) > abs(pitch) else abs(pitch)
            if a > self._max_tilt:
                self._max_tilt = a
            if e_h > self._max_lost:
                self._max_lost = e_h
        self._last = (h, e_h, float(nav.airspeed_m_s))
        tail = self._tail
        tail.append((t, roll * _RAD_TO_DEG, pitch * _RAD_TO_DEG, yaw * _RAD_TO_DEG))
        while t - tail[0][0] > 1.0 + 1e-9:
            tail.popleft()

    def result(self) -> dict[str, Any]:
        """Metrics so far: RMSE and peak errors, transition timing, crash and quad-chute flags."""
        n = max(self.n_win, 1)
        rm = [math.sqrt(x / n) if self.n_win else math.nan for x in self._se]
        tail = list(self._tail) or [(0.0, math.nan, math.nan, math.nan)]
        dur = (self.transition_complete_s - self.transition_start_s
               if self.transition_complete_s is not None and self.transition_start_s is not None
               else None)
        last = self._last if self._last is not None else (math.nan, math.nan, math.nan)
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
            "max_attitude_excursion_deg": self._max_tilt * _RAD_TO_DEG,
            "max_altitude_lost_m": self._max_lost,
            "transition_start_s": self.transition_start_s,
            "transition_complete_s": self.transition_complete_s,
            "transition_duration_s": dur,
            "quad_chute": self.quad_chute,
            "final_altitude_m": last[0],
            "final_altitude_error_m": last[1],
            "final_airspeed_m_s": last[2],
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

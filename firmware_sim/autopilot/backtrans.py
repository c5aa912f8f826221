"""Back-transition planning: where to start braking so the aircraft stops at its point.

PX4's idea (``VT_B_DEC_MSS``): the back transition of a VTOL landing starts at the distance
the aircraft needs to stop from its present speed at the deceleration it achieves, so the
multicopter arrives over the land point instead of beyond it. Here the stop has two parts
(what DS-1 does: the back transition glides, pusher off, wings level, until the airspeed falls
to ``VT_B_TRANS_ARSP`` or ``VT_B_TRANS_DUR`` runs out; then the multicopter position loop
brakes the rest):

- the back transition, in the air mass: the airspeed ``Va`` falls at ``a_t`` per second to
  ``Va1 = max(VT_B_TRANS_ARSP, Va - a_t VT_B_TRANS_DUR)`` in ``T = (Va - Va1) / a_t``, over
  the air distance ``(Va^2 - Va1^2) / (2 a)`` (``a = VT_B_DEC_MSS``: the deceleration per
  distance; drag falls with the airspeed, so ``a_t`` < ``a``: DS-1 glides from 18 m/s for the
  whole 20 s, 250 m, ending near 9 m/s); the wind along the track ``W`` (ground speed less
  airspeed) adds ``W T`` over the ground, and the multicopter takes over at ``v1 = Va1 + W``;
- the multicopter's stop from ``v1``, as the navigator flies it: braking at its largest
  deceleration ``a_mc = g tan(MPC_TILTMAX_AIR)`` down to the cruise speed ``v_c =
  min(v1, MPC_XY_CRUISE)``, then the approach that never goes faster than it can stop at
  half of that: ``(v1^2 - v_c^2) / (2 a_mc) + v_c^2 / a_mc``.

Starting too early costs a short multicopter leg forward; too late, a leg back.

``a`` and ``a_t`` start at ``VT_B_DEC_MSS``; every back transition flown is measured
(:meth:`BackTransitionPlanner.finish`: its air distance and duration from the airspeeds and
the ground track) and the estimates move towards the measured values (``VT_B_DEC_ADAPT``: 0
keeps the parameter, 1 takes the last measurement), so the next back transition starts where
this aircraft, with its faults, needs it.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

__all__ = ["BackTransitionPlanner", "BrakeMeasurement", "braking_distance", "mc_stop_distance"]


def mc_stop_distance(v1_m_s: float, mc_decel_m_s2: float, mc_cruise_m_s: float) -> float:
    """Ground distance [m] the multicopter needs to stop from ``v1_m_s`` (see the module
    docstring; ``mc_decel_m_s2`` its largest deceleration, ``mc_cruise_m_s`` its approach
    speed)."""
    v1 = max(0.0, float(v1_m_s))
    a_mc = max(float(mc_decel_m_s2), 1e-3)
    vc = min(v1, max(float(mc_cruise_m_s), 0.0))
    return (v1 * v1 - vc * vc) / (2.0 * a_mc) + vc * vc / a_mc


def braking_distance(airspeed_m_s: float, wind_along_m_s: float, decel_m_s2: float,
                     decel_time_m_s2: float, v_end_m_s: float, duration_s: float,
                     mc_decel_m_s2: float, mc_cruise_m_s: float) -> float:
    """Ground distance [m] before the point where the back transition must start.

    Parameters
    ----------
    airspeed_m_s
        airspeed when it starts, m/s.
    wind_along_m_s
        wind along the track towards the point (ground speed less airspeed; positive: tail).
    decel_m_s2
        deceleration per distance in the air, ``(Va^2 - Va1^2) / (2 d_air)``, m/s^2.
    decel_time_m_s2
        deceleration per time, ``(Va - Va1) / T``, m/s^2.
    v_end_m_s
        the airspeed that ends the back transition (``VT_B_TRANS_ARSP``), m/s.
    duration_s
        its timeout (``VT_B_TRANS_DUR``), s.
    mc_decel_m_s2, mc_cruise_m_s
        the multicopter's largest deceleration (m/s^2) and approach speed (m/s).

    Returns
    -------
    float
        metres; 0 when the aircraft is not moving towards the point.
    """
    va = max(0.0, float(airspeed_m_s))
    w = float(wind_along_m_s)
    if va + w <= 0.0:
        return 0.0
    a = max(float(decel_m_s2), 1e-3)
    a_t = max(float(decel_time_m_s2), 1e-3)
    va1 = min(va, max(float(v_end_m_s), va - a_t * float(duration_s)))
    t = (va - va1) / a_t
    d_bt = (va * va - va1 * va1) / (2.0 * a) + w * t
    return max(0.0, d_bt + mc_stop_distance(va1 + w, mc_decel_m_s2, mc_cruise_m_s))


@dataclass
class BrakeMeasurement:
    """One back transition as flown (along its initial ground track)."""

    airspeed0_m_s: float
    airspeed1_m_s: float
    v0_m_s: float
    """ground speed when it began, m/s"""
    v1_m_s: float
    """ground speed along the same direction when it ended, m/s"""
    distance_m: float
    """ground distance covered along that direction, m"""
    wind_m_s: float
    """wind along the track when it began (ground speed less airspeed), m/s"""
    duration_s: float

    @property
    def air_distance_m(self) -> float:
        """Distance flown through the air, m (ground distance less the wind's drift)."""
        return self.distance_m - self.wind_m_s * self.duration_s

    @property
    def decel_m_s2(self) -> float:
        """Deceleration per air distance ``(Va0^2 - Va1^2) / (2 d_air)``, m/s^2 (NaN when it
        did not slow down over a positive distance)."""
        d = self.air_distance_m
        if d <= 1.0 or self.airspeed1_m_s >= self.airspeed0_m_s:
            return math.nan
        return (self.airspeed0_m_s ** 2 - self.airspeed1_m_s ** 2) / (2.0 * d)

    @property
    def decel_time_m_s2(self) -> float:
        """Deceleration per time ``(Va0 - Va1) / T``, m/s^2 (NaN as above)."""
        if self.duration_s <= 0.1 or self.airspeed1_m_s >= self.airspeed0_m_s:
            return math.nan
        return (self.airspeed0_m_s - self.airspeed1_m_s) / self.duration_s


class BackTransitionPlanner:
    """Braking distance from the expected deceleration, adapted by what is measured.

    Parameters
    ----------
    decel_m_s2
        the expected deceleration ``VT_B_DEC_MSS`` before any measurement, m/s^2.
    v_end_m_s
        the airspeed ending a back transition (``VT_B_TRANS_ARSP``), m/s.
    duration_s
        the back-transition timeout (``VT_B_TRANS_DUR``), s.
    """

    def __init__(self, decel_m_s2: float, v_end_m_s: float, duration_s: float = math.inf
                 ) -> None:
        self.param_decel = float(decel_m_s2)
        self.param_v_end = float(v_end_m_s)
        self.param_duration = float(duration_s)
        self.decel_est: float = math.nan
        """measured deceleration per air distance (NaN before the first), m/s^2"""
        self.decel_time_est: float = math.nan
        """measured deceleration per time (NaN before the first), m/s^2"""
        self.measurements: list[BrakeMeasurement] = []
        self._start: tuple[int, float, float, float, float, float, float, float] | None = None

    def set_params(self, decel_m_s2: float, v_end_m_s: float,
                   duration_s: float = math.inf) -> None:
        """The parameters as set now (``VT_B_DEC_MSS``, ``VT_B_TRANS_ARSP``,
        ``VT_B_TRANS_DUR``)."""
        self.param_decel = float(decel_m_s2)
        self.param_v_end = float(v_end_m_s)
        self.param_duration = float(duration_s)

    @property
    def decel(self) -> float:
        """The deceleration per air distance planned with, m/s^2."""
        return self.decel_est if math.isfinite(self.decel_est) else self.param_decel

    @property
    def decel_time(self) -> float:
        """The deceleration per time planned with, m/s^2."""
        return self.decel_time_est if math.isfinite(self.decel_time_est) else self.param_decel

    def distance(self, v_ground_along_m_s: float, airspeed_m_s: float,
                 mc_decel_m_s2: float, mc_cruise_m_s: float) -> float:
        """Where to start: metres before the point (see :func:`braking_distance`).

        ``v_ground_along_m_s``: ground speed towards the point; ``airspeed_m_s``: the
        airspeed now (their difference is the wind along the track).
        """
        va = airspeed_m_s if math.isfinite(airspeed_m_s) else v_ground_along_m_s
        return braking_distance(va, v_ground_along_m_s - va, self.decel, self.decel_time,
                                self.param_v_end, self.param_duration, mc_decel_m_s2,
                                mc_cruise_m_s)

    # -- measuring ------------------------------------------------------------------------
    def start(self, t_usec: int, pos_ne: tuple[float, float], vel_ne: tuple[float, float],
              airspeed_m_s: float) -> None:
        """A back transition begins (position m, ground velocity m/s, NED; airspeed m/s)."""
        v = math.hypot(*vel_ne)
        if v < 1.0 or not math.isfinite(airspeed_m_s):
            self._start = None
            return
        self._start = (int(t_usec), pos_ne[0], pos_ne[1], vel_ne[0] / v, vel_ne[1] / v, v,
                       float(airspeed_m_s), v - float(airspeed_m_s))

    def finish(self, t_usec: int, pos_ne: tuple[float, float], vel_ne: tuple[float, float],
               airspeed_m_s: float, adapt: float) -> BrakeMeasurement | None:
        """The back transition ended: measure it and move the estimates by ``adapt``
        (0..1) towards the measurement. Returns the measurement (None without a start)."""
        s = self._start
        self._start = None
        if s is None or not math.isfinite(airspeed_m_s):
            return None
        t0, n0, e0, un, ue, v0, va0, wind = s
        d = (pos_ne[0] - n0) * un + (pos_ne[1] - e0) * ue
        v1 = vel_ne[0] * un + vel_ne[1] * ue
        meas = BrakeMeasurement(va0, float(airspeed_m_s), v0, v1, d, wind,
                                (t_usec - t0) * 1e-6)
        self.measurements.append(meas)
        k = min(max(float(adapt), 0.0), 1.0)
        a, a_t = meas.decel_m_s2, meas.decel_time_m_s2
        if k > 0.0 and math.isfinite(a) and math.isfinite(a_t):
            self.decel_est = self.decel + k * (a - self.decel)
            self.decel_time_est = self.decel_time + k * (a_t - self.decel_time)
        return meas

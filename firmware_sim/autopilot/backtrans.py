"""Back-transition planning: where to start braking so the aircraft stops at its point.

PX4's idea (``VT_B_DEC_MSS``): the back transition of a VTOL landing starts at the distance
the aircraft needs to stop from its present *ground* speed at the deceleration it achieves,
so the multicopter arrives over the land point instead of beyond it. Here the stop has two
parts (what DS-1 does: the back transition glides, pusher off, wings level, until the
airspeed falls to ``VT_B_TRANS_ARSP`` or ``VT_B_TRANS_DUR`` runs out; then the multicopter
position loop brakes the rest):

- the back transition, at a constant ground deceleration ``a`` from the ground speed
  ``v0`` along the track to ``v1``: ``(v0^2 - v1^2) / (2 a)``, where ``v1`` is the end
  airspeed plus the wind along the track, or ``v0 - a VT_B_TRANS_DUR`` when the timeout
  ends it first (DS-1 glides from 18 m/s for the whole 20 s and ends near 9 m/s);
- the multicopter's stop from ``v1``: braking at most ``g tan(MPC_TILTMAX_AIR)``, then its
  position loop's first-order approach (speed ``MPC_XY_P`` times the distance left):
  ``v1^2 / (2 g tan(MPC_TILTMAX_AIR)) + v1 / MPC_XY_P`` (an upper bound: the two overlap).

Starting too early costs a short multicopter leg forward; too late, a return leg: where the
model is uncertain it errs early.

Ground speeds (not airspeeds) make the distance right in wind: a tailwind lengthens it, a
headwind shortens it. ``a`` starts at ``VT_B_DEC_MSS``; every back transition flown is
measured (:meth:`BackTransitionPlanner.finish`: ground deceleration along its track and the
ground speed it ended at) and the estimates move to the measured values (``VT_B_DEC_ADAPT``:
0 keeps the parameter, 1 takes the last measurement), so the next back transition starts
where this aircraft, with its faults, in this wind, needs it.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

__all__ = ["BackTransitionPlanner", "BrakeMeasurement", "braking_distance"]


def braking_distance(v0_m_s: float, decel_m_s2: float, v1_m_s: float,
                     kp_xy_per_s: float, mc_decel_m_s2: float) -> float:
    """Ground distance [m] to stop from ``v0_m_s`` (ground speed along the track, m/s).

    Parameters
    ----------
    v0_m_s
        ground speed towards the point when the back transition starts, m/s (<= 0: 0 m).
    decel_m_s2
        ground deceleration during the back transition, m/s^2 (> 0).
    v1_m_s
        ground speed at which the back transition ends (the multicopter then stops), m/s.
    kp_xy_per_s
        the multicopter position gain ``MPC_XY_P``, 1/s.
    mc_decel_m_s2
        the multicopter's largest deceleration (``g tan(MPC_TILTMAX_AIR)``), m/s^2.

    Returns
    -------
    float
        the distance before the point where the back transition must start, m.
    """
    v0 = max(0.0, float(v0_m_s))
    v1 = min(max(0.0, float(v1_m_s)), v0)
    a = max(float(decel_m_s2), 1e-3)
    a_mc = max(float(mc_decel_m_s2), 1e-3)
    return ((v0 * v0 - v1 * v1) / (2.0 * a) + v1 * v1 / (2.0 * a_mc)
            + v1 / max(float(kp_xy_per_s), 1e-3))


@dataclass
class BrakeMeasurement:
    """One back transition as flown (ground frame, along its start velocity)."""

    v0_m_s: float
    """ground speed when it began, m/s"""
    v1_m_s: float
    """ground speed along the same direction when it ended, m/s"""
    distance_m: float
    """ground distance covered along that direction, m"""
    duration_s: float

    @property
    def decel_m_s2(self) -> float:
        """Mean ground deceleration over the distance, ``(v0^2 - v1^2) / (2 d)``, m/s^2
        (NaN when it did not slow down over a positive distance)."""
        if self.distance_m <= 1.0 or self.v1_m_s >= self.v0_m_s:
            return math.nan
        return (self.v0_m_s ** 2 - self.v1_m_s ** 2) / (2.0 * self.distance_m)


class BackTransitionPlanner:
    """Braking distance from the expected deceleration, adapted by what is measured.

    Parameters
    ----------
    decel_m_s2
        the expected deceleration ``VT_B_DEC_MSS`` before any measurement, m/s^2.
    v_end_m_s
        the expected ground speed at the end of a back transition without wind (about
        ``VT_B_TRANS_ARSP``), m/s.
    """

    def __init__(self, decel_m_s2: float, v_end_m_s: float, duration_s: float = math.inf
                 ) -> None:
        self.param_decel = float(decel_m_s2)
        self.param_v_end = float(v_end_m_s)
        self.param_duration = float(duration_s)
        self.decel_est: float = math.nan
        """measured ground deceleration (NaN before the first back transition), m/s^2"""
        self.v_end_est: float = math.nan
        """measured end-of-back-transition ground speed less the tailwind then, m/s"""
        self.measurements: list[BrakeMeasurement] = []
        self._start: tuple[int, float, float, float, float, float] | None = None

    def set_params(self, decel_m_s2: float, v_end_m_s: float,
                   duration_s: float = math.inf) -> None:
        """The parameters as set now (``VT_B_DEC_MSS``, ``VT_B_TRANS_ARSP``,
        ``VT_B_TRANS_DUR``)."""
        self.param_decel = float(decel_m_s2)
        self.param_v_end = float(v_end_m_s)
        self.param_duration = float(duration_s)

    @property
    def decel(self) -> float:
        """The deceleration planned with, m/s^2."""
        return self.decel_est if math.isfinite(self.decel_est) else self.param_decel

    def v_end(self, wind_along_m_s: float) -> float:
        """The ground speed expected at the end of the back transition, m/s (the airspeed it
        ends at plus the wind along the track)."""
        v = self.v_end_est if math.isfinite(self.v_end_est) else self.param_v_end
        return max(0.0, v + wind_along_m_s)

    def distance(self, v_ground_along_m_s: float, airspeed_m_s: float,
                 kp_xy_per_s: float, mc_decel_m_s2: float) -> float:
        """Where to start: metres before the point (see :func:`braking_distance`).

        ``v_ground_along_m_s``: ground speed towards the point; ``airspeed_m_s``: the
        airspeed now (their difference is the wind along the track).
        """
        wind = v_ground_along_m_s - airspeed_m_s if math.isfinite(airspeed_m_s) else 0.0
        a = self.decel
        v1 = max(self.v_end(wind), v_ground_along_m_s - a * self.param_duration)
        return braking_distance(v_ground_along_m_s, a, v1, kp_xy_per_s, mc_decel_m_s2)

    # -- measuring ------------------------------------------------------------------------
    def start(self, t_usec: int, pos_ne: tuple[float, float], vel_ne: tuple[float, float],
              airspeed_m_s: float) -> None:
        """A back transition begins (position m, ground velocity m/s, NED)."""
        v = math.hypot(*vel_ne)
        if v < 1.0:
            self._start = None
            return
        self._start = (int(t_usec), pos_ne[0], pos_ne[1], vel_ne[0] / v, vel_ne[1] / v,
                       v - airspeed_m_s if math.isfinite(airspeed_m_s) else 0.0)
        self._v0 = v

    def finish(self, t_usec: int, pos_ne: tuple[float, float], vel_ne: tuple[float, float],
               adapt: float) -> BrakeMeasurement | None:
        """The back transition ended: measure it and move the estimates by ``adapt``
        (0..1) towards the measurement. Returns the measurement (None without a start)."""
        s = self._start
        self._start = None
        if s is None:
            return None
        t0, n0, e0, un, ue, wind = s
        d = (pos_ne[0] - n0) * un + (pos_ne[1] - e0) * ue
        v1 = vel_ne[0] * un + vel_ne[1] * ue
        meas = BrakeMeasurement(self._v0, v1, d, (t_usec - t0) * 1e-6)
        self.measurements.append(meas)
        k = min(max(float(adapt), 0.0), 1.0)
        a = meas.decel_m_s2
        if k > 0.0 and math.isfinite(a):
            prev = self.decel
            self.decel_est = prev + k * (a - prev)
            if meas.duration_s < 0.98 * self.param_duration:  # ended by its airspeed
                prev_v = self.v_end_est if math.isfinite(self.v_end_est) else self.param_v_end
                self.v_end_est = prev_v + k * (max(0.0, v1 - wind) - prev_v)
        return meas

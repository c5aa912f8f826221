"""The autopilot's state intake: what one control step knows of the vehicle.

Reads a :class:`~vtolftc.firmware_sim.autopilot.interface.NavState` (NED position and
velocity, scalar-first attitude quaternion, FRD body rates, airspeed), rejects unusable data
and keeps the derived values the stages read: ZYX Euler angles, altitude and climb rate (up
positive), airspeed (0 when not finite) and the ground altitude.
"""

from __future__ import annotations

import math

import numpy as np
from numpy.typing import NDArray

from vtolftc.firmware_sim.autopilot.interface import NavState

__all__ = ["StateEstimate", "body_velocity", "body_velocity_f"]


def body_velocity(q: NDArray[np.float64], v: NDArray[np.float64]) -> tuple[float, float, float]:
    """NED vector ``v`` in body FRD axes (R^T v) for the scalar-first quaternion ``q``."""
    return body_velocity_f(float(q[0]), float(q[1]), float(q[2]), float(q[3]),
                           float(v[0]), float(v[1]), float(v[2]))


def body_velocity_f(w: float, x: float, y: float, z: float, vn: float, ve: float,
                    vd: float) -> tuple[float, float, float]:
    """:func:`body_velocity` on plain floats (quaternion w, x, y, z; NED vector)."""
    r00 = 1 - 2 * (y * y + z * z)
    r01 = 2 * (x * y - w * z)
    r02 = 2 * (x * z + w * y)
    r10 = 2 * (x * y + w * z)
    r11 = 1 - 2 * (x * x + z * z)
    r12 = 2 * (y * z - w * x)
    r20 = 2 * (x * z - w * y)
    r21 = 2 * (y * z + w * x)
    r22 = 1 - 2 * (x * x + y * y)
    return (r00 * vn + r10 * ve + r20 * vd, r01 * vn + r11 * ve + r21 * vd,
            r02 * vn + r12 * ve + r22 * vd)


class StateEstimate:
    """The vehicle state of the last usable navigation data (see the module docstring).

    Attributes
    ----------
    have_nav : bool
        usable navigation data came at least once (arming needs it).
    last_nav : NavState or None
        the last usable navigation data.
    time_usec : int
        its simulated time [us].
    att : ndarray, shape (3,)
        roll, pitch, yaw [rad] (ZYX Euler angles of the NED-to-FRD rotation).
    euler : tuple of float
        the same angles as a tuple (what :meth:`update` returned last).
    ql : list of float
        attitude quaternion w, x, y, z.
    vel : list of float
        velocity NED [m/s].
    alt : float
        altitude above the NED origin [m, up].
    v_up : float
        climb rate [m/s, up].
    airspeed : float
        airspeed [m/s] (0 when the measurement is not finite).
    ground_alt : float
        altitude of the ground [m, up]: the first usable altitude, then the one at arming.
    """

    __slots__ = ("airspeed", "alt", "att", "euler", "ground_alt", "have_nav", "last_nav",
                 "ql", "time_usec", "v_up", "vel")

    def __init__(self) -> None:
        self.have_nav = False
        self.last_nav: NavState | None = None
        self.time_usec = 0
        self.att = np.zeros(3)
        self.euler = (0.0, 0.0, 0.0)
        self.ql = [1.0, 0.0, 0.0, 0.0]
        self.vel = [0.0, 0.0, 0.0]
        self.alt = 0.0
        self.v_up = 0.0
        self.airspeed = 0.0
        self.ground_alt = math.nan

    def update(self, nav: NavState) -> tuple[float, float, float] | None:
        """Take ``nav`` in; returns its roll, pitch, yaw [rad], or None (nothing changed)
        when any of its position, velocity, attitude or rates is not finite."""
        pos = nav.pos_ned_m.tolist()
        vel = nav.vel_ned_m_s.tolist()
        ql = nav.q_wxyz.tolist()
        isf = math.isfinite
        if not (isf(pos[0]) and isf(pos[1]) and isf(pos[2]) and isf(vel[0]) and isf(vel[1])
                and isf(vel[2]) and isf(ql[0]) and isf(ql[1]) and isf(ql[2]) and isf(ql[3])):
            return None
        p_, q_, r_ = nav.omega_body_rad_s.tolist()
        if not (isf(p_) and isf(q_) and isf(r_)):
            return None
        self.have_nav = True
        self.last_nav = nav
        self.time_usec = int(nav.time_usec)
        # quat_to_euler(ql), inlined: the same expressions in the same order (its clip
        # max(-1, min(1, s)) written as comparisons: equal for the finite s it gets here)
        w, x, y, z = ql
        roll = math.atan2(2.0 * (w * x + y * z), 1.0 - 2.0 * (x * x + y * y))
        s_ = 2.0 * (w * y - z * x)
        s_ = s_ if s_ < 1.0 else 1.0
        pitch = math.asin(s_ if s_ > -1.0 else -1.0)
        yaw = math.atan2(2.0 * (w * z + x * y), 1.0 - 2.0 * (y * y + z * z))
        att = self.att
        att[0], att[1], att[2] = roll, pitch, yaw
        self.ql = ql
        self.vel = vel
        h = -pos[2]
        self.v_up = -vel[2]
        V = float(nav.airspeed_m_s)
        if not math.isfinite(V):
            V = 0.0
        self.airspeed = V
        self.alt = h
        if not math.isfinite(self.ground_alt):
            self.ground_alt = h
        self.euler = euler = (roll, pitch, yaw)
        return euler

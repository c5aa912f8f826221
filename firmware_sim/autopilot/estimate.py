"""The autopilot's state intake: what one control step knows of the vehicle.

Reads a :class:`~vtolftc.firmware_sim.autopilot.interface.NavState` (NED position and
velocity, scalar-first attitude quaternion, FRD body rates, airspeed), rejects unusable data
and keeps the derived values the stages read: ZYX Euler angles, altitude and climb rate (up
positive), airspeed (0 when not finite) and the ground altitude.
"""

from __future__ import annotations

import math

import numba
import numpy as np
from numpy.typing import NDArray

from vtolftc.firmware_sim.autopilot.interface import NavState

__all__ = ["StateEstimate", "body_velocity", "body_velocity_f", "estimate_step"]


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


#: Layout of :class:`StateEstimate`'s workspace (``StateEstimate.ws``), float64:
#: roll, pitch, yaw [rad], body-axis velocity x (forward) and z (down) [m/s], altitude [m, up],
#: climb rate [m/s, up].
W_ROLL, W_PITCH, W_YAW, W_UB, W_WB, W_ALT, W_VUP = range(7)
W_SIZE = 7


@numba.njit(cache=True)
def estimate_step(q, omega, pos, vel, ws):  # pragma: no cover - compiled
    """The numerical part of :meth:`StateEstimate.update`: False (``ws`` untouched) when any
    of ``pos``, ``vel``, ``q`` or ``omega`` is not finite, else True with ``ws`` written (the
    ``W_*`` layout): the ZYX Euler angles of ``q`` (``quat_to_euler``'s expressions, its clip
    as comparisons), the NED velocity in body axes x and z (:func:`body_velocity_f`'s
    expressions), the altitude ``-pos[2]`` and the climb rate ``-vel[2]``."""
    if not (math.isfinite(pos[0]) and math.isfinite(pos[1]) and math.isfinite(pos[2])
            and math.isfinite(vel[0]) and math.isfinite(vel[1]) and math.isfinite(vel[2])
            and math.isfinite(q[0]) and math.isfinite(q[1]) and math.isfinite(q[2])
            and math.isfinite(q[3]) and math.isfinite(omega[0])
            and math.isfinite(omega[1]) and math.isfinite(omega[2])):
        return False
    w = q[0]
    x = q[1]
    y = q[2]
    z = q[3]
    ws[0] = math.atan2(2.0 * (w * x + y * z), 1.0 - 2.0 * (x * x + y * y))
    s_ = 2.0 * (w * y - z * x)
    s_ = s_ if s_ < 1.0 else 1.0
    ws[1] = math.asin(s_ if s_ > -1.0 else -1.0)
    ws[2] = math.atan2(2.0 * (w * z + x * y), 1.0 - 2.0 * (y * y + z * z))
    vn = vel[0]
    ve = vel[1]
    vd = vel[2]
    ws[3] = ((1 - 2 * (y * y + z * z)) * vn + 2 * (x * y + w * z) * ve
             + 2 * (x * z - w * y) * vd)
    ws[4] = (2 * (x * z + w * y) * vn + 2 * (y * z - w * x) * ve
             + (1 - 2 * (x * x + y * y)) * vd)
    ws[5] = -pos[2]
    ws[6] = -vel[2]
    return True


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
    ws : ndarray, shape (W_SIZE,)
        the workspace :func:`estimate_step` writes (the ``W_*`` layout).
    att : ndarray, shape (3,)
        roll, pitch, yaw [rad] (ZYX Euler angles of the NED-to-FRD rotation): a view of
        ``ws[0:3]`` (relinked on copy and unpickle).
    euler : tuple of float
        the same angles as a tuple (what :meth:`update` returned last).
    ub, wb : float
        velocity in body axes x (forward) and z (down) [m/s].
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
                 "time_usec", "ub", "v_up", "wb", "ws")

    def __init__(self) -> None:
        self.have_nav = False
        self.last_nav: NavState | None = None
        self.time_usec = 0
        self.ws = np.zeros(W_SIZE)
        self.att = self.ws[W_ROLL:W_YAW + 1]
        self.euler = (0.0, 0.0, 0.0)
        self.ub = 0.0
        self.wb = 0.0
        self.alt = 0.0
        self.v_up = 0.0
        self.airspeed = 0.0
        self.ground_alt = math.nan

    def __getstate__(self) -> dict:
        return {k: getattr(self, k) for k in self.__slots__ if k != "att"}

    def __setstate__(self, state: dict) -> None:
        for k, v in state.items():
            setattr(self, k, v)
        self.att = self.ws[W_ROLL:W_YAW + 1]

    def update(self, nav: NavState) -> tuple[float, float, float] | None:
        """Take ``nav`` in; returns its roll, pitch, yaw [rad], or None (nothing changed)
        when any of its position, velocity, attitude or rates is not finite."""
        if not estimate_step(nav.q_wxyz, nav.omega_body_rad_s, nav.pos_ned_m,
                             nav.vel_ned_m_s, self.ws):
            return None
        self.have_nav = True
        self.last_nav = nav
        self.time_usec = int(nav.time_usec)
        roll, pitch, yaw, self.ub, self.wb, h, self.v_up = self.ws.tolist()
        V = float(nav.airspeed_m_s)
        if not math.isfinite(V):
            V = 0.0
        self.airspeed = V
        self.alt = h
        if not math.isfinite(self.ground_alt):
            self.ground_alt = h
        self.euler = euler = (roll, pitch, yaw)
        return euler

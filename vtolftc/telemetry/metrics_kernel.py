"""The per-sample arithmetic of :class:`~vtolftc.telemetry.metrics.MetricsAccumulator`, compiled.

One call of :func:`metrics_step` per control step updates the accumulator's running sums,
peaks, flags and its one-second tail in two flat float64 arrays (no Python object per step).
It does the operations of the Python reference :func:`metrics_step_py` in the same order
(``fastmath`` off), so both give the same bits; ``tests/test_metrics_kernel.py`` checks that
on random samples. Roll, pitch and yaw come in already computed (``quat_to_euler`` stays in
Python, or the autopilot's own angles are reused): the kernel never calls a libm function
whose result could differ from CPython's.

State layout (indices into ``s``, all float64; flags are 0.0 / 1.0, counts exact below 2**53):
see the ``S_*`` constants. The tail is a ring buffer ``tail`` of shape (capacity, 4) holding
``(t [s], roll [deg], pitch [deg], yaw [deg])`` of the samples of the last second, oldest at
``s[S_HEAD]``, ``s[S_LEN]`` of them.
"""

from __future__ import annotations

import math

import numba
import numpy as np
from numpy.typing import NDArray

__all__ = ["N_STATE", "metrics_step", "metrics_step_py", "new_state"]

S_N, S_N_WIN = 0, 1
S_SE = 2                 # 2..5: altitude, roll, pitch, yaw squared errors (m², deg²)
S_MAX = 6                # 6..8: peak |roll|, |pitch|, |yaw| errors [deg]
S_MAX_TILT, S_MAX_LOST = 9, 10
S_HAS_GROUND, S_GROUND, S_WAS_HIGH = 11, 12, 13
S_CRASHED, S_CRASH_T = 14, 15
S_HAS_TS, S_TS, S_HAS_TC, S_TC = 16, 17, 18, 19
S_QUAD_CHUTE, S_PREV_MODE = 20, 21
S_HAS_LAST, S_LAST_H, S_LAST_EH, S_LAST_AIR = 22, 23, 24, 25
S_T_LAST, S_WINDOW, S_HEAD, S_LEN = 26, 27, 28, 29
N_STATE = 30

CRASH_ATTITUDE_RAD = math.radians(60.0)
_RAD_TO_DEG = math.degrees(1.0)  # what math.degrees multiplies by (CPython)
_TAIL_S = 1.0 + 1e-9
# FlightMode values (vtolftc.telemetry.autopilot_status): HOVER 2, FRONT_TRANSITION 3,
# FIXED_WING 4, BACK_TRANSITION 5 fly; -1: no previous mode
_HOVER, _FRONT, _FW, _BACK = 2, 3, 4, 5


def new_state(window_start_s: float) -> NDArray[np.float64]:
    """A fresh accumulator state (no sample yet) with the window starting at
    ``window_start_s`` [s]."""
    s = np.zeros(N_STATE)
    s[S_PREV_MODE] = -1.0
    s[S_GROUND] = s[S_CRASH_T] = s[S_TS] = s[S_TC] = math.nan
    s[S_WINDOW] = window_start_s
    return s


def metrics_step_py(s: NDArray[np.float64], tail: NDArray[np.float64], time_usec: int,
                    pos_ned_m: NDArray[np.float64], roll: float, pitch: float, yaw: float,
                    mode: int, armed: bool, ref: NDArray[np.float64], alt_ref: float,
                    airspeed: float) -> int:
    """Add one sample to the state ``s`` and ``tail`` (the Python reference of
    :func:`metrics_step`, same arguments and result).

    Parameters
    ----------
    s, tail : numpy.ndarray
        The state (``N_STATE``,) and the tail ring (capacity, 4), updated in place.
    time_usec : int
        Sample time [us].
    pos_ned_m : numpy.ndarray
        Position NED (3,) [m] (altitude = -z).
    roll, pitch, yaw : float
        Attitude of the sample (ZYX Euler) [rad].
    mode : int
        ``FlightMode`` value.
    armed : bool
        Armed flag.
    ref : numpy.ndarray
        Attitude reference (3,) [rad].
    alt_ref : float
        Altitude reference above home [m].
    airspeed : float
        Airspeed [m/s].

    Returns
    -------
    int
        1: added. 2: added, and the flight has crashed (``s[S_CRASHED]`` set, now or
        before). 0: the tail ring is full; nothing was changed (grow it and call again).
    """
    cap = tail.shape[0]
    n_tail = int(s[S_LEN])
    if n_tail >= cap:
        return 0
    t = time_usec * 1e-6
    s[S_T_LAST] = t
    h = -pos_ned_m[2]
    if s[S_HAS_GROUND] == 0.0 and armed:
        s[S_HAS_GROUND] = 1.0
        s[S_GROUND] = h
    ground = s[S_GROUND] if s[S_HAS_GROUND] != 0.0 else h
    if h - ground > 2.0:
        s[S_WAS_HIGH] = 1.0
    if s[S_CRASHED] == 0.0:
        hg = h - ground
        flying = _HOVER <= mode <= _BACK  # the four flying modes are 2..5
        if (not (math.isfinite(hg) and math.isfinite(roll) and math.isfinite(pitch))
                or abs(roll) > CRASH_ATTITUDE_RAD or abs(pitch) > CRASH_ATTITUDE_RAD):
            crash = True
        else:
            crash = flying and s[S_WAS_HIGH] != 0.0 and hg < 0.5
        if crash:
            s[S_CRASHED] = 1.0
            s[S_CRASH_T] = t
    if mode == _FRONT:
        if s[S_HAS_TS] == 0.0:
            s[S_HAS_TS] = 1.0
            s[S_TS] = t
    elif mode == _FW:
        if s[S_HAS_TC] == 0.0:
            s[S_HAS_TC] = 1.0
            s[S_TC] = t
    elif mode == _HOVER and s[S_PREV_MODE] == _FRONT:
        s[S_QUAD_CHUTE] = 1.0
    s[S_PREV_MODE] = mode
    s[S_N] += 1.0
    e_h = alt_ref - h
    if t >= s[S_WINDOW]:
        e0 = (ref[0] - roll) * _RAD_TO_DEG
        e1 = (ref[1] - pitch) * _RAD_TO_DEG
        e2 = -((-((ref[2] - yaw) * _RAD_TO_DEG) + 180.0) % 360.0 - 180.0)
        s[S_N_WIN] += 1.0
        s[S_SE] += e_h * e_h
        s[S_SE + 1] += e0 * e0
        s[S_SE + 2] += e1 * e1
        s[S_SE + 3] += e2 * e2
        a = abs(e0)
        if a > s[S_MAX]:
            s[S_MAX] = a
        a = abs(e1)
        if a > s[S_MAX + 1]:
            s[S_MAX + 1] = a
        a = abs(e2)
        if a > s[S_MAX + 2]:
            s[S_MAX + 2] = a
        a = abs(roll) if abs(roll) > abs(pitch) else abs(pitch)
        if a > s[S_MAX_TILT]:
            s[S_MAX_TILT] = a
        if e_h > s[S_MAX_LOST]:
            s[S_MAX_LOST] = e_h
    s[S_HAS_LAST] = 1.0
    s[S_LAST_H] = h
    s[S_LAST_EH] = e_h
    s[S_LAST_AIR] = airspeed
    head = int(s[S_HEAD])
    j = (head + n_tail) % cap
    tail[j, 0] = t
    tail[j, 1] = roll * _RAD_TO_DEG
    tail[j, 2] = pitch * _RAD_TO_DEG
    tail[j, 3] = yaw * _RAD_TO_DEG
    n_tail += 1
    while t - tail[head, 0] > _TAIL_S:
        head = (head + 1) % cap
        n_tail -= 1
    s[S_HEAD] = head
    s[S_LEN] = n_tail
    return 2 if s[S_CRASHED] != 0.0 else 1


#: the one signature, compiled (or loaded from numba's cache) at import: a SITL autopilot
#: never compiles it in flight, whatever array layout its samples carry
_SIGNATURE = "int64(float64[:], float64[:, :], int64, float64[:], float64, float64, float64, " \
    "int64, boolean, float64[:], float64, float64)"
metrics_step = numba.njit(_SIGNATURE, cache=True)(metrics_step_py)
""":func:`metrics_step_py` compiled by numba (``fastmath`` off: the same operations in the
same order, hence the same bits; Python's float ``%`` and numba's agree, sign included)."""

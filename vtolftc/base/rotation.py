"""Attitude kinematics: quaternions, ZYX Euler angles and rotation matrices, in one place.

Conventions (the project's): quaternions are scalar-first ``(w, x, y, z)`` and rotate body FRD
vectors into the NED world frame; Euler angles are ZYX (yaw, then pitch, then roll) in radians;
``R = dcm(q)`` maps body to NED (``v_ned = R @ v_body``). These are the plain-Python helpers
used outside compiled loops; the vehicle's numba integrator keeps its own inlined copy of
:func:`dcm` (``vtolftc.firmware_sim.vehicle.dynamics.quat_to_dcm``), tested against this one.
"""

from __future__ import annotations

import math
from collections.abc import Sequence

import numpy as np
from numpy.typing import NDArray

__all__ = ["ATTITUDE_AXES", "dcm", "euler_to_quat", "quat_mul", "quat_to_euler"]

#: The attitude axes in the order of :func:`quat_to_euler`'s angles (body FRD: roll about x,
#: pitch about y, yaw about z); every per-axis table of the project (gains, designs, plots)
#: uses this order.
ATTITUDE_AXES: tuple[str, str, str] = ("roll", "pitch", "yaw")


def quat_to_euler(q: Sequence[float] | NDArray[np.float64]) -> tuple[float, float, float]:
    """ZYX Euler angles of a unit quaternion.

    Parameters
    ----------
    q : array_like, shape (4,)
        Quaternion ``(w, x, y, z)``, body FRD -> NED.

    Returns
    -------
    roll, pitch, yaw : float
        [rad]; pitch is clipped to [-pi/2, pi/2] at the gimbal-lock singularity.
    """
    if type(q) is np.ndarray and q.shape == (4,):
        w, x, y, z = q.tolist()
    else:
        w, x, y, z = float(q[0]), float(q[1]), float(q[2]), float(q[3])
    roll = math.atan2(2.0 * (w * x + y * z), 1.0 - 2.0 * (x * x + y * y))
    pitch = math.asin(max(-1.0, min(1.0, 2.0 * (w * y - z * x))))
    yaw = math.atan2(2.0 * (w * z + x * y), 1.0 - 2.0 * (y * y + z * z))
    return roll, pitch, yaw


def euler_to_quat(roll: float, pitch: float, yaw: float) -> NDArray[np.float64]:
    """Quaternion of ZYX Euler angles.

    Parameters
    ----------
    roll, pitch, yaw : float
        [rad].

    Returns
    -------
    ndarray, shape (4,)
        ``(w, x, y, z)``, body FRD -> NED, unit norm.
    """
    cr, sr = math.cos(roll / 2), math.sin(roll / 2)
    cp, sp = math.cos(pitch / 2), math.sin(pitch / 2)
    cy, sy = math.cos(yaw / 2), math.sin(yaw / 2)
    return np.array([
        cr * cp * cy + sr * sp * sy,
        sr * cp * cy - cr * sp * sy,
        cr * sp * cy + sr * cp * sy,
        cr * cp * sy - sr * sp * cy,
    ])


def quat_mul(a: Sequence[float] | NDArray[np.float64],
             b: Sequence[float] | NDArray[np.float64]) -> NDArray[np.float64]:
    """Hamilton product ``a * b`` (apply ``b`` first, then ``a``), both ``(w, x, y, z)``.

    Parameters
    ----------
    a, b : array_like, shape (4,)
        Quaternions, scalar first.

    Returns
    -------
    ndarray, shape (4,)
        The product, scalar first.
    """
    w1, x1, y1, z1 = a
    w2, x2, y2, z2 = b
    return np.array([
        w1 * w2 - x1 * x2 - y1 * y2 - z1 * z2,
        w1 * x2 + x1 * w2 + y1 * z2 - z1 * y2,
        w1 * y2 - x1 * z2 + y1 * w2 + z1 * x2,
        w1 * z2 + x1 * y2 - y1 * x2 + z1 * w2,
    ])


def dcm(q: Sequence[float] | NDArray[np.float64]) -> NDArray[np.float64]:
    """Rotation matrix of a unit quaternion.

    Parameters
    ----------
    q : array_like, shape (4,)
        ``(w, x, y, z)``, body FRD -> NED.

    Returns
    -------
    ndarray, shape (3, 3)
        ``R`` with ``v_ned = R @ v_body``.
    """
    w, x, y, z = (float(v) for v in q)
    return np.array([
        [1 - 2 * (y * y + z * z), 2 * (x * y - w * z), 2 * (x * z + w * y)],
        [2 * (x * y + w * z), 1 - 2 * (x * x + z * z), 2 * (y * z - w * x)],
        [2 * (x * z - w * y), 2 * (y * z + w * x), 1 - 2 * (x * x + y * y)],
    ])

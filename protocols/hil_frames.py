"""The HIL step's numbers decoded straight from checked frame bytes (no message objects).

The SITL link checks a datagram's framing, CRC and signature in one compiled call
(:class:`~vtolftc.protocols.fastparse.FastParser`); the HIL_SENSOR, HIL_STATE_QUATERNION and
HIL_ACTUATOR_CONTROLS frames of every lockstep step can then be handed over as
:class:`~vtolftc.protocols.fastparse.RawFrame` (``FastParser.defer``) and decoded here into
what the two processes consume:

- :class:`HilStateFrameDecoder`: a HIL_STATE_QUATERNION frame -> the autopilot's
  :class:`~vtolftc.protocols.hil.NavState`, in one compiled call, bit for bit the
  :class:`~vtolftc.protocols.hil.HilStateDecoder` of the message the generated parser makes
  (same float32 -> float64 conversions, same scaling, same operations in the same order);
- :func:`frame_time_usec`: the leading ``uint64 time_usec`` of a HIL frame;
- :func:`actuator_controls`: HIL_ACTUATOR_CONTROLS' ``controls`` as float64 values.

The payload offsets are those of the dialect's wire layout (fields sorted by size, MAVLink 2
zero-tail truncation undone by reading missing bytes as 0); the constructors check them
against the generated classes' ``struct`` formats, so a dialect change fails loudly instead of
decoding wrong. Little-endian hosts only (as the wire): the kernels reinterpret the payload
bytes in place.
"""

from __future__ import annotations

import math
from typing import Any

import numba
import numpy as np
from numpy.typing import NDArray

from vtolftc.protocols.hil import EARTH_RADIUS_M, HIL_OUTPUTS, HilStateDecoder, NavState
from vtolftc.protocols.mavlink import dialect

__all__ = ["HilStateFrameDecoder", "actuator_controls", "frame_time_usec"]

_STATE_FORMAT = "<Q4ffffiiihhhHHhhh"
"""HIL_STATE_QUATERNION's wire layout the kernel reads (time, q[4], p, q, r, lat, lon, alt,
vx, vy, vz, ind_airspeed, true_airspeed, xacc, yacc, zacc)."""
_STATE_SIZE = 64
_CONTROLS_FORMAT = "<QQ16fB"
"""HIL_ACTUATOR_CONTROLS' wire layout (time_usec, flags, controls[16], mode)."""
_CONTROLS_SIZE = 81
_DEG_TO_RAD = math.radians(1.0)  # CPython's math.radians: x * (pi / 180)


def _check_layout(name: str, fmt: str) -> None:
    cls = getattr(dialect(), f"MAVLink_{name}_message")
    if cls.unpacker.format != fmt:
        raise RuntimeError(f"{cls.msgname}: wire layout {cls.unpacker.format!r}, the fast "
                           f"decoder reads {fmt!r}")


def frame_time_usec(raw: Any) -> int:
    """The leading ``uint64 time_usec`` [us] of a HIL frame (HIL_SENSOR,
    HIL_STATE_QUATERNION, HIL_ACTUATOR_CONTROLS), from a :class:`RawFrame`."""
    start = raw.payload_start
    return int.from_bytes(raw.data[start:start + min(raw.mlen, 8)], "little")


class HilStateFrameDecoder:
    """:class:`~vtolftc.protocols.hil.HilStateDecoder` of a HIL_STATE_QUATERNION frame's
    bytes, in one compiled call.

    Parameters
    ----------
    home_lat_deg, home_lon_deg, home_alt_m : float
        Home (the projection's origin): latitude and longitude [deg], altitude AMSL [m].
    """

    __slots__ = ("_alt0", "_cos", "_lat0", "_lon0", "_u64")

    def __init__(self, home_lat_deg: float, home_lon_deg: float, home_alt_m: float) -> None:
        _check_layout("hil_state_quaternion", _STATE_FORMAT)
        ref = HilStateDecoder(home_lat_deg, home_lon_deg, home_alt_m)
        self._lat0, self._lon0, self._alt0 = home_lat_deg, home_lon_deg, home_alt_m
        self._cos = ref._cos  # the same double as the reference decoder's projection
        self._u64 = np.zeros(2, dtype=np.uint64)

    def __call__(self, raw: Any) -> NavState | None:
        """The :class:`NavState` of a HIL_STATE_QUATERNION :class:`RawFrame`, or None when
        its attitude is not a rotation quaternion (zero or not finite: the caller decodes the
        message with :class:`HilStateDecoder`, which raises its error)."""
        a = np.empty(13)
        u = self._u64
        if _state_kernel(raw.data, raw.payload_start, raw.mlen, self._lat0, self._lon0,
                         self._alt0, self._cos, a, u) < 0:
            return None
        time_usec, air = u.tolist()
        return NavState(time_usec, a[0:4], a[4:7], a[7:10], a[10:13], air * 0.01)


@numba.njit(cache=True)
def _payload(data, start, mlen, size):  # pragma: no cover - compiled
    """The payload ``data[start:start + mlen]`` zero-padded to ``size`` bytes (uint8)."""
    p = np.zeros(size, dtype=np.uint8)
    for i in range(min(mlen, size)):
        p[i] = data[start + i]
    return p


@numba.njit(cache=True)
def _state_kernel(data, start, mlen, lat0, lon0, alt0, cos_lat0, a,
                  u64):  # pragma: no cover - compiled
    """Decode a HIL_STATE_QUATERNION payload as ``HilStateDecoder.__call__`` does.

    Writes the normalised quaternion, rates, position NED [m] and velocity NED [m/s] into
    ``a`` (13,), ``time_usec`` and ``ind_airspeed`` [cm/s] into ``u64`` (2,); returns 0, or -1
    (``a`` then meaningless) when the attitude is not a rotation quaternion.
    """
    p = _payload(data, start, mlen, _STATE_SIZE)
    f = p[8:36].view(np.float32)
    i32 = p[36:48].view(np.int32)
    i16 = p[48:54].view(np.int16)
    u64[0] = p[0:8].view(np.uint64)[0]
    u64[1] = p[54:56].view(np.uint16)[0]
    qw, qx, qy, qz = np.float64(f[0]), np.float64(f[1]), np.float64(f[2]), np.float64(f[3])
    n = math.sqrt(qw * qw + qx * qx + qy * qy + qz * qz)
    if not (n > 0.0 and math.isfinite(n)):
        return -1
    a[0] = qw / n
    a[1] = qx / n
    a[2] = qy / n
    a[3] = qz / n
    a[4] = np.float64(f[4])
    a[5] = np.float64(f[5])
    a[6] = np.float64(f[6])
    a[7] = ((np.float64(i32[0]) * 1e-7 - lat0) * _DEG_TO_RAD) * EARTH_RADIUS_M
    a[8] = ((np.float64(i32[1]) * 1e-7 - lon0) * _DEG_TO_RAD) * EARTH_RADIUS_M * cos_lat0
    a[9] = alt0 - np.float64(i32[2]) * 1e-3
    a[10] = np.float64(i16[0]) * 0.01
    a[11] = np.float64(i16[1]) * 0.01
    a[12] = np.float64(i16[2]) * 0.01
    return 0


def actuator_controls(raw: Any, n: int) -> tuple[int, int, bool, NDArray[np.float64]]:
    """HIL_ACTUATOR_CONTROLS of a :class:`RawFrame` in one compiled call.

    Parameters
    ----------
    raw : RawFrame
        A HIL_ACTUATOR_CONTROLS frame.
    n : int
        How many of the 16 ``controls`` to return (``0 <= n <= 16``).

    Returns
    -------
    time_usec : int
        The step answered [us].
    mode : int
        The MAV_MODE_FLAG bits.
    finite : bool
        All ``n`` controls are finite.
    controls : numpy.ndarray
        ``controls[:n]`` as float64 (each the float32 the wire carries: the values of the
        message's ``controls[:n]``).
    """
    if not 0 <= n <= HIL_OUTPUTS:
        raise ValueError(f"{n} controls: HIL_ACTUATOR_CONTROLS carries {HIL_OUTPUTS}")
    out = np.empty(n)
    u = np.empty(2, dtype=np.uint64)
    finite = _controls_kernel(raw.data, raw.payload_start, raw.mlen, out, u)
    return int(u[0]), int(u[1]), finite, out


@numba.njit(cache=True)
def _controls_kernel(data, start, mlen, out, u64):  # pragma: no cover - compiled
    """``controls[:out.size]`` into ``out``, ``time_usec`` and ``mode`` into ``u64``;
    returns whether every control written is finite."""
    p = _payload(data, start, mlen, _CONTROLS_SIZE)
    f = p[16:80].view(np.float32)
    u64[0] = p[0:8].view(np.uint64)[0]
    u64[1] = p[80]
    finite = True
    for i in range(out.size):
        out[i] = np.float64(f[i])
        finite = finite and math.isfinite(out[i])
    return finite


_check_layout("hil_actuator_controls", _CONTROLS_FORMAT)

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
- :func:`actuator_controls`: HIL_ACTUATOR_CONTROLS' ``controls`` as float64 values;
- :class:`HilFramePackers`: the vehicle's HIL_SENSOR from a sensor sample's arrays and its
  HIL_STATE_QUATERNION from the rigid-body state, each frame (the state's encoding included)
  in one compiled call into the :class:`~vtolftc.protocols.fastpack.FramePacker`'s buffer: the
  bytes of ``FramePacker.pack`` of the same values (signing, sequence numbers too).

The payload offsets are those of the dialect's wire layout (fields sorted by size, MAVLink 2
zero-tail truncation undone by reading missing bytes as 0); the constructors check them
against the generated classes' ``struct`` formats, so a dialect change fails loudly instead of
decoding wrong. Little-endian hosts only (as the wire): the kernels reinterpret the payload
bytes in place.
"""

from __future__ import annotations

import functools
import math
from typing import Any

import numba
import numpy as np
from numpy.typing import NDArray

from vtolftc.base.geodesy import FlatEarth
from vtolftc.protocols.fastpack import FramePacker, frame_kernel
from vtolftc.protocols.fastparse import RawFrame
from vtolftc.protocols.hil import (
    EARTH_RADIUS_M,
    HIL_OUTPUTS,
    NavState,
    encode_state_kernel,
)
from vtolftc.protocols.mavlink import dialect

__all__ = ["HilFramePackers", "HilStateFrameDecoder", "actuator_controls", "frame_time_usec",
           "warm_up"]

_STATE_FORMAT = "<Q4ffffiiihhhHHhhh"
"""HIL_STATE_QUATERNION's wire layout the kernel reads (time, q[4], p, q, r, lat, lon, alt,
vx, vy, vz, ind_airspeed, true_airspeed, xacc, yacc, zacc)."""
_STATE_SIZE = 64
_SENSOR_FORMAT = "<QfffffffffffffIB"
"""HIL_SENSOR's wire layout (time, 13 floats from xacc to temperature, fields_updated, id)."""
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
        self._lat0, self._lon0, self._alt0 = home_lat_deg, home_lon_deg, home_alt_m
        # the same double as HilStateDecoder's projection
        self._cos = FlatEarth(home_lat_deg, home_lon_deg).cos_lat0
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


_INT64_MAX = 2**63 - 1


class HilFramePackers:
    """HIL_SENSOR and HIL_STATE_QUATERNION frames of the vehicle, each in one compiled call.

    Parameters
    ----------
    codec : Any
        The link's generated ``MAVLink`` object (ids, sequence, signing).
    home_lat_deg, home_lon_deg, home_alt_m : float
        Home (the projection's origin of :func:`~vtolftc.protocols.hil.encode_hil_state`).

    Each method returns the frame, or None for what the compiled path leaves to the general
    one (a float ``struct`` refuses, a state the codec refuses, a time past 2**63 us): the
    caller then packs with :attr:`sensor` / :attr:`state` ``.pack`` and the
    :class:`~vtolftc.protocols.hil.HilStateEncoder`, which give the same bytes or raise.
    """

    __slots__ = ("_home", "_out", "sensor", "state")

    def __init__(self, codec: Any, home_lat_deg: float, home_lon_deg: float,
                 home_alt_m: float) -> None:
        _check_layout("hil_sensor", _SENSOR_FORMAT)
        _check_layout("hil_state_quaternion", _STATE_FORMAT)
        mod = dialect()
        self.sensor = FramePacker(codec, mod.MAVLink_hil_sensor_message)
        self.state = FramePacker(codec, mod.MAVLink_hil_state_quaternion_message)
        # the same doubles as HilStateEncoder's projection
        r_cos = EARTH_RADIUS_M * FlatEarth(home_lat_deg, home_lon_deg).cos_lat0
        self._home = (home_lat_deg, home_lon_deg, home_alt_m, r_cos)
        self._out = np.empty(14)

    def sensor_frame(self, time_usec: int, accel: NDArray[np.float64],
                     gyro: NDArray[np.float64], mag: NDArray[np.float64], abs_pressure: float,
                     diff_pressure: float, pressure_alt: float, temperature: float,
                     fields_updated: int, sensor_id: int) -> bytes | None:
        """HIL_SENSOR: ``time_usec`` [us], accelerometer [m/s^2], gyro [rad/s], magnetometer
        [gauss] (3 float64 each, FRD), pressures [hPa], pressure altitude [m], temperature
        [degC], ``fields_updated`` bits, sensor id: ``sensor.pack`` of the same values."""
        if not 0 <= time_usec <= _INT64_MAX or not 0 <= fields_updated < 2**32 \
                or not 0 <= sensor_id < 256:
            return None
        return self.sensor.pack_compiled(
            _sensor_kernel, time_usec, accel, gyro, mag, float(abs_pressure),
            float(diff_pressure), float(pressure_alt), float(temperature), fields_updated,
            sensor_id)

    def state_frame(self, time_usec: int, state: NDArray[np.float64],
                    airspeed_m_s: float) -> bytes | None:
        """HIL_STATE_QUATERNION of a rigid-body state (13+ float64: position NED [m],
        velocity NED [m/s], quaternion w x y z body FRD -> NED, body rates [rad/s]) and
        airspeed [m/s]: ``state.pack`` of ``HilStateEncoder``'s fields."""
        if not 0 <= time_usec <= _INT64_MAX or type(state) is not np.ndarray \
                or state.dtype != np.float64 or state.ndim != 1 or state.shape[0] < 13:
            return None
        lat0, lon0, alt0, r_cos = self._home
        return self.state.pack_compiled(_state_pack_kernel, time_usec, state,
                                        float(airspeed_m_s), lat0, lon0, alt0, r_cos,
                                        self._out)


@numba.njit(cache=True)
def _put(buf, pos, value, nbytes):  # pragma: no cover - compiled
    """``nbytes`` little-endian bytes of the int64 ``value`` (two's complement) at ``pos``."""
    for k in range(nbytes):
        buf[pos + k] = (value >> (8 * k)) & 0xFF


@numba.njit(cache=True)
def _put_f32(buf, pos, x, scratch):  # pragma: no cover - compiled
    """``x`` as ``struct``'s ``f`` packs it; False (nothing that counts) if ``struct``
    raises: a finite value that overflows float32."""
    y = np.float32(x)
    if math.isinf(y) and not math.isinf(x):
        return False
    scratch[0] = y
    _put(buf, pos, np.int64(scratch.view(np.uint32)[0]), 4)
    return True


@numba.njit(cache=True)
def _sensor_kernel(buf, size, seq, sys_id, comp_id, msg_id, crc_extra, signed, link_id, ts,
                   t, accel, gyro, mag, abs_p, diff_p, alt, temp, fields,
                   sensor_id):  # pragma: no cover - compiled
    """HIL_SENSOR's payload (``<QfffffffffffffIB``) at ``buf[10:]``, then the frame."""
    scratch = np.empty(1, dtype=np.float32)
    _put(buf, 10, t, 8)
    vals = (accel[0], accel[1], accel[2], gyro[0], gyro[1], gyro[2], mag[0], mag[1], mag[2],
            abs_p, diff_p, alt, temp)
    pos = 18
    for x in vals:
        if not _put_f32(buf, pos, x, scratch):
            return -1
        pos += 4
    _put(buf, 70, fields, 4)
    buf[74] = sensor_id
    return frame_kernel(buf, size, seq, sys_id, comp_id, msg_id, crc_extra, signed, link_id,
                         ts)


@numba.njit(cache=True)
def _state_pack_kernel(buf, size, seq, sys_id, comp_id, msg_id, crc_extra, signed, link_id,
                       ts, t, state, airspeed, lat0, lon0, alt0, r_cos,
                       out):  # pragma: no cover - compiled
    """HIL_STATE_QUATERNION's payload (``<Q4ffffiiihhhHHhhh``) of ``encode_hil_state``'s
    fields (:func:`~vtolftc.protocols.hil.encode_state_kernel`, the same bits) at ``buf[10:]``,
    then the frame; -1 for what the codec refuses."""
    if not encode_state_kernel(state, airspeed, lat0, lon0, alt0, r_cos, out):
        return -1
    scratch = np.empty(1, dtype=np.float32)
    _put(buf, 10, t, 8)
    for i in range(7):  # already float32 values: no overflow
        _put_f32(buf, 18 + 4 * i, out[i], scratch)
    for i in range(3):  # lat, lon [degE7], alt [mm]: int32
        _put(buf, 46 + 4 * i, np.int64(out[7 + i]), 4)
    for i in range(3):  # vx, vy, vz [cm/s]: int16
        _put(buf, 58 + 2 * i, np.int64(out[10 + i]), 2)
    air = np.int64(out[13])
    _put(buf, 64, air, 2)  # ind_airspeed, true_airspeed [cm/s]: uint16
    _put(buf, 66, air, 2)
    _put(buf, 68, 0, 6)  # xacc, yacc, zacc: 0
    return frame_kernel(buf, size, seq, sys_id, comp_id, msg_id, crc_extra, signed, link_id,
                         ts)


@functools.cache
def warm_up() -> None:
    """Compile (or load from numba's cache) every kernel of this module for the argument
    types of a flight, once per process: called when the autopilot's bridge and the
    vehicle's encoder are made, so that a fresh cache compiles nothing after the autopilot
    says STANDBY (``tests/test_coldstart.py``)."""
    from vtolftc.protocols.fastparse import FastParser
    from vtolftc.protocols.mavlink import make_codec

    codec = make_codec(1, 1)
    packers = HilFramePackers(codec, 47.0, 8.0, 500.0)
    z = np.zeros(3)
    x = np.zeros(13)
    x[6] = 1.0
    data = packers.sensor_frame(4000, z, z, z, 1013.25, 0.0, 0.0, 15.0, 0x1FFF, 0)
    data = (data or b"") + (packers.state_frame(4000, x, 0.0) or b"")
    data += codec.hil_actuator_controls_encode(4000, [0.0] * HIL_OUTPUTS, 0, 0).pack(codec)
    mod = dialect()
    parser = FastParser(make_codec(2, 2), mod)
    parser.defer = frozenset((mod.MAVLink_hil_state_quaternion_message.id,
                              mod.MAVLink_hil_actuator_controls_message.id))
    frames = parser.parse(data) or []
    for raw in frames:
        if type(raw) is not RawFrame:
            continue
        if raw.msg_id == mod.MAVLink_hil_state_quaternion_message.id:
            HilStateFrameDecoder(47.0, 8.0, 500.0)(raw)
        else:
            actuator_controls(raw, 1)


_check_layout("hil_actuator_controls", _CONTROLS_FORMAT)

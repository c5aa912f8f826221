"""The HIL wire forms shared by the simulated vehicle and the autopilot.

- :class:`NavState`: the navigation solution the autopilot flies on (attitude, rates, position,
  velocity, airspeed), and :class:`HilState`, HIL_STATE_QUATERNION's fields in the wire's own
  types; :func:`encode_hil_state` / :func:`decode_hil_state` convert between them with a
  flat-earth projection about home. The vehicle encodes its state with them; the autopilot
  decodes what it receives; the in-process runner passes the vehicle state through the *same*
  pair, so an in-process run and a lockstep SITL run see bit-identical inputs.
- :func:`wire_commands`: the airframe's normalised actuator commands (any number up to
  :data:`HIL_OUTPUTS`) rounded to float32 exactly as HIL_ACTUATOR_CONTROLS carries them.

HIL mapping (as PX4's actuator functions: motors first, then servos): slot ``i`` of
HIL_ACTUATOR_CONTROLS' 16 carries actuator ``i`` of the airframe's order (lift rotors,
pushers, surfaces); unused slots are 0. An airframe with more than 16 actuators cannot be
carried and is refused by the airframe loader.

Frames and units: NED world frame with its origin at home (metres), FRD body frame,
quaternion scalar-first rotating body vectors into NED, SI units, radians. This module knows
no flight logic and no physics.
"""

from __future__ import annotations

import math
import struct
from collections.abc import Sequence
from dataclasses import dataclass
from typing import Any

import numba
import numpy as np
from numpy.typing import NDArray

from vtolftc.base.geodesy import EARTH_RADIUS_M, FlatEarth

__all__ = [
    "EARTH_RADIUS_M",
    "HIL_OUTPUTS",
    "HilRoundTrip",
    "HilState",
    "HilStateDecoder",
    "HilStateEncoder",
    "NavState",
    "decode_hil_state",
    "encode_hil_state",
    "nav_of_round_trip",
    "wire_commands",
    "wire_round",
]

HIL_OUTPUTS = 16
"""Outputs of HIL_ACTUATOR_CONTROLS: the most actuators an airframe can have."""

"""Radius of the flat-earth projection about home [m] (WGS-84 equatorial radius)."""


@dataclass(slots=True)
class NavState:
    """The autopilot's view of the vehicle at ``time_usec`` (simulated microseconds).

    ``q_wxyz``: attitude quaternion (body FRD -> NED, scalar first); ``omega_body_rad_s``:
    body rates p, q, r (rad/s); ``pos_ned_m``: position relative to home (m);
    ``vel_ned_m_s``: ground velocity in NED (m/s); ``airspeed_m_s``: indicated airspeed.
    """

    time_usec: int
    q_wxyz: NDArray[np.float64]
    omega_body_rad_s: NDArray[np.float64]
    pos_ned_m: NDArray[np.float64]
    vel_ned_m_s: NDArray[np.float64]
    airspeed_m_s: float


@dataclass(slots=True)
class HilState:
    """HIL_STATE_QUATERNION's fields, in the wire's own types and units."""

    time_usec: int
    attitude_quaternion: tuple[float, float, float, float]  # float32, w x y z
    rollspeed: float                                         # float32, rad/s
    pitchspeed: float
    yawspeed: float
    lat: int                                                 # degE7
    lon: int                                                 # degE7
    alt: int                                                 # mm above MSL
    vx: int                                                  # cm/s north (int16)
    vy: int                                                  # cm/s east
    vz: int                                                  # cm/s down
    ind_airspeed: int                                        # cm/s (uint16)
    true_airspeed: int                                       # cm/s (uint16)
    xacc: int = 0                                            # mG (int16)
    yacc: int = 0
    zacc: int = 0


_F32X7 = struct.Struct("<7f")


def _clip_int(x: float, lo: int, hi: int) -> int:
    return int(min(max(round(x), lo), hi))


def encode_hil_state(nav: NavState, home_lat_deg: float, home_lon_deg: float,
                     home_alt_m: float) -> HilState:
    """Encode ``nav`` as HIL_STATE_QUATERNION fields (flat-earth projection about home).

    Floats are rounded to float32 exactly as the wire does (``struct`` packing, as pymavlink),
    integers rounded to nearest (ties to even, as ``round``) and clipped to their field's
    range. The in-process runner and the SITL processes both use this pair, so they see the
    same bits.
    """
    pn, pe, pd = nav.pos_ned_m.tolist()
    lat, lon = FlatEarth(home_lat_deg, home_lon_deg).to_global(pn, pe)
    qw, qx, qy, qz, p, q, r = _F32X7.unpack(
        _F32X7.pack(*nav.q_wxyz.tolist(), *nav.omega_body_rad_s.tolist()))
    vn, ve, vd = nav.vel_ned_m_s.tolist()
    air = _clip_int(100.0 * nav.airspeed_m_s, 0, 65535)
    return HilState(
        time_usec=int(nav.time_usec),
        attitude_quaternion=(qw, qx, qy, qz),
        rollspeed=p, pitchspeed=q, yawspeed=r,
        lat=_clip_int(lat * 1e7, -2**31, 2**31 - 1),
        lon=_clip_int(lon * 1e7, -2**31, 2**31 - 1),
        alt=_clip_int(1000.0 * (home_alt_m - pd), -2**31, 2**31 - 1),
        vx=_clip_int(100.0 * vn, -32768, 32767),
        vy=_clip_int(100.0 * ve, -32768, 32767),
        vz=_clip_int(100.0 * vd, -32768, 32767),
        ind_airspeed=air, true_airspeed=air,
    )


def decode_hil_state(h: HilState, home_lat_deg: float, home_lon_deg: float,
                     home_alt_m: float) -> NavState:
    """Inverse of :func:`encode_hil_state` (up to the wire's resolution: about 1 cm, 1 cm/s)."""
    pn, pe = FlatEarth(home_lat_deg, home_lon_deg).to_local(h.lat * 1e-7, h.lon * 1e-7)
    pd = home_alt_m - h.alt * 1e-3
    qw, qx, qy, qz = h.attitude_quaternion
    n = math.sqrt(qw * qw + qx * qx + qy * qy + qz * qz)
    if not (n > 0.0 and math.isfinite(n)):
        raise ValueError(f"HIL_STATE_QUATERNION attitude {h.attitude_quaternion}: "
                         "not a rotation quaternion")
    return NavState(
        time_usec=int(h.time_usec),
        q_wxyz=np.array((qw / n, qx / n, qy / n, qz / n)),
        omega_body_rad_s=np.array((h.rollspeed, h.pitchspeed, h.yawspeed)),
        pos_ned_m=np.array((pn, pe, pd)),
        vel_ned_m_s=np.array((h.vx * 0.01, h.vy * 0.01, h.vz * 0.01)),
        airspeed_m_s=h.ind_airspeed * 0.01,
    )


class HilStateDecoder:
    """:func:`decode_hil_state` of a received HIL_STATE_QUATERNION message, bit for bit,
    without the intermediate :class:`HilState` and the per-call projection.

    The SITL autopilot decodes one message per control step; this reads the message's fields
    directly, keeps the projection about home, and returns a :class:`NavState` whose four
    arrays are float64 views of one 13-entry array, the very layout the in-process runner's
    :class:`HilRoundTrip` hands the autopilot (so both feed its compiled kernels the same
    argument types). ``tests/test_interface.py`` checks it against :func:`decode_hil_state`.

    Parameters
    ----------
    home_lat_deg, home_lon_deg, home_alt_m : float
        Home (the projection's origin): latitude and longitude [deg], altitude AMSL [m].
    """

    __slots__ = ("_alt0", "_cos", "_lat0", "_lon0")

    def __init__(self, home_lat_deg: float, home_lon_deg: float, home_alt_m: float) -> None:
        self._lat0 = home_lat_deg
        self._lon0 = home_lon_deg
        self._alt0 = home_alt_m
        # FlatEarth.to_local's east: radians(.) * EARTH_RADIUS_M * cos_lat0, left to right
        self._cos = FlatEarth(home_lat_deg, home_lon_deg).cos_lat0

    def __call__(self, msg: Any) -> NavState:
        """The :class:`NavState` of ``msg`` (a HIL_STATE_QUATERNION message or anything with
        its fields: ``time_usec``, ``attitude_quaternion`` (w, x, y, z), ``rollspeed``,
        ``pitchspeed``, ``yawspeed`` [rad/s], ``lat``, ``lon`` [degE7], ``alt`` [mm],
        ``vx``, ``vy``, ``vz`` [cm/s], ``ind_airspeed`` [cm/s]).

        Raises
        ------
        ValueError
            The attitude is not a rotation quaternion (zero or not finite).
        """
        qw, qx, qy, qz = (float(x) for x in msg.attitude_quaternion)
        n = math.sqrt(qw * qw + qx * qx + qy * qy + qz * qz)
        if not (n > 0.0 and math.isfinite(n)):
            raise ValueError(f"HIL_STATE_QUATERNION attitude {(qw, qx, qy, qz)}: "
                             "not a rotation quaternion")
        a = np.array((
            qw / n, qx / n, qy / n, qz / n,
            float(msg.rollspeed), float(msg.pitchspeed), float(msg.yawspeed),
            math.radians(int(msg.lat) * 1e-7 - self._lat0) * EARTH_RADIUS_M,
            math.radians(int(msg.lon) * 1e-7 - self._lon0) * EARTH_RADIUS_M * self._cos,
            self._alt0 - int(msg.alt) * 1e-3,
            int(msg.vx) * 0.01, int(msg.vy) * 0.01, int(msg.vz) * 0.01))
        return NavState(int(msg.time_usec), a[0:4], a[4:7], a[7:10], a[10:13],
                        int(msg.ind_airspeed) * 0.01)


class HilRoundTrip:
    """``decode_hil_state(encode_hil_state(nav, *home), *home)`` in one call, bit for bit.

    The in-process runner passes the vehicle state through the wire codec every control step
    so that it flies on exactly the bits a SITL autopilot receives; this does the same
    arithmetic, in the same order, without building the intermediate :class:`HilState` (about
    a fifth of the codec pair's time). ``tests/test_interface.py`` checks it against the pair.

    Parameters
    ----------
    home_lat_deg, home_lon_deg, home_alt_m : float
        Home (the projection's origin): latitude and longitude [deg], altitude AMSL [m].
    """

    __slots__ = ("_alt0", "_cos", "_lat0", "_lon0", "_r_cos", "kernel_home")

    def __init__(self, home_lat_deg: float, home_lon_deg: float, home_alt_m: float) -> None:
        self._lat0 = home_lat_deg
        self._lon0 = home_lon_deg
        self._alt0 = home_alt_m
        # the same doubles as geodesy.FlatEarth (the codec pair's projection), fused here
        self._cos = FlatEarth(home_lat_deg, home_lon_deg).cos_lat0
        self._r_cos = EARTH_RADIUS_M * self._cos
        #: :func:`round_trip_kernel`'s ``lat0, lon0, alt0, r_cos, cos_lat0`` as one array
        #: (for a caller that fuses the kernel into its own compiled call): the same doubles
        self.kernel_home = np.array([self._lat0, self._lon0, self._alt0, self._r_cos,
                                     self._cos])

    def __call__(self, time_usec: int, state: NDArray[np.float64],
                 airspeed_m_s: float) -> NavState:
        """The :class:`NavState` the autopilot decodes from the HIL_STATE_QUATERNION of a
        rigid-body state.

        Parameters
        ----------
        time_usec : int
            Simulated time [us].
        state : numpy.ndarray
            At least 13 entries: position NED [m], velocity NED [m/s], quaternion
            ``(w, x, y, z)`` body FRD -> NED, body rates [rad/s] (the vehicle's state order).
        airspeed_m_s : float
            Airspeed [m/s].

        Returns
        -------
        NavState
            Equal, bit for bit, to ``decode_hil_state(encode_hil_state(NavState(time_usec,
            state[6:10], state[10:13], state[0:3], state[3:6], airspeed_m_s), *home), *home)``
            (its four arrays are views of one 13-entry array).
        """
        if type(state) is np.ndarray and state.dtype == _F64 and state.ndim == 1 \
                and state.shape[0] >= 13:
            a = np.empty(13)
            air = round_trip_kernel(state, float(airspeed_m_s), self._lat0, self._lon0,
                                     self._alt0, self._r_cos, self._cos, a)
            if air >= 0:  # else a value the codec refuses: the Python path raises its error
                return nav_of_round_trip(time_usec, a, air)
        return self._python(time_usec, state, airspeed_m_s)

    def _python(self, time_usec: int, state: NDArray[np.float64],
                airspeed_m_s: float) -> NavState:
        """:meth:`__call__` in Python (the kernel's reference; raises on what the codec
        refuses)."""
        pn, pe, pd, vn, ve, vd, q0, q1, q2, q3, w0, w1, w2 = state[:13].tolist()
        lat0, lon0, alt0 = self._lat0, self._lon0, self._alt0
        # encode (as encode_hil_state)
        lat = lat0 + math.degrees(pn / EARTH_RADIUS_M)
        lon = lon0 + math.degrees(pe / self._r_cos)
        qw, qx, qy, qz, p, q, r = _F32X7.unpack(_F32X7.pack(q0, q1, q2, q3, w0, w1, w2))
        ilat = round(lat * 1e7)
        ilat = -2**31 if ilat < -2**31 else 2**31 - 1 if ilat > 2**31 - 1 else ilat
        ilon = round(lon * 1e7)
        ilon = -2**31 if ilon < -2**31 else 2**31 - 1 if ilon > 2**31 - 1 else ilon
        ialt = round(1000.0 * (alt0 - pd))
        ialt = -2**31 if ialt < -2**31 else 2**31 - 1 if ialt > 2**31 - 1 else ialt
        ivx = round(100.0 * vn)
        ivx = -32768 if ivx < -32768 else 32767 if ivx > 32767 else ivx
        ivy = round(100.0 * ve)
        ivy = -32768 if ivy < -32768 else 32767 if ivy > 32767 else ivy
        ivz = round(100.0 * vd)
        ivz = -32768 if ivz < -32768 else 32767 if ivz > 32767 else ivz
        air = round(100.0 * airspeed_m_s)
        air = 0 if air < 0 else 65535 if air > 65535 else air
        # decode (as decode_hil_state)
        n = math.sqrt(qw * qw + qx * qx + qy * qy + qz * qz)
        if not (n > 0.0 and math.isfinite(n)):
            raise ValueError(f"HIL_STATE_QUATERNION attitude {(qw, qx, qy, qz)}: "
                             "not a rotation quaternion")
        a = np.array((
            qw / n, qx / n, qy / n, qz / n, p, q, r,
            math.radians(ilat * 1e-7 - lat0) * EARTH_RADIUS_M,
            math.radians(ilon * 1e-7 - lon0) * EARTH_RADIUS_M * self._cos,
            alt0 - ialt * 1e-3,
            ivx * 0.01, ivy * 0.01, ivz * 0.01))
        return NavState(int(time_usec), a[0:4], a[4:7], a[7:10], a[10:13], air * 0.01)


def nav_of_round_trip(time_usec: int, a: NDArray[np.float64], air_cm_s: float) -> NavState:
    """The :class:`NavState` of a round trip's decoded array ``a`` (at least 13 entries:
    quaternion, body rates [rad/s], position NED [m], velocity NED [m/s]; its four arrays are
    views of ``a``) and airspeed ``air_cm_s`` [cm/s] at ``time_usec`` [us]."""
    return NavState(int(time_usec), a[0:4], a[4:7], a[7:10], a[10:13], air_cm_s * 0.01)


_F64 = np.dtype(np.float64)
_RAD_TO_DEG = math.degrees(1.0)  # CPython's math.degrees: x * (180 / pi)
_DEG_TO_RAD = math.radians(1.0)  # math.radians: x * (pi / 180)
_F32_MAX = float(np.finfo(np.float32).max)


@numba.njit(cache=True)
def _round_half_even(x):  # pragma: no cover - compiled
    """Python's ``round(x)`` of a finite float, as a float (ties to even; + 0.0: an int
    has no negative zero)."""
    return np.rint(x) + 0.0


@numba.njit(cache=True)
def _clip(x, lo, hi):  # pragma: no cover - compiled
    return lo if x < lo else hi if x > hi else x


@numba.njit(cache=True)
def round_trip_kernel(state, airspeed, lat0, lon0, alt0, r_cos, cos_lat0,
                       a):  # pragma: no cover - compiled
    """:meth:`HilRoundTrip._python` compiled (the same operations in the same order).

    Writes the decoded quaternion, rates, position and velocity into ``a`` (13,); returns the
    airspeed in cm/s, or -1 (``a`` then meaningless) when a value is one the codec refuses
    (non-finite before rounding, a float32 overflow, a zero quaternion).
    """
    f32 = np.empty(7)
    for i in range(7):
        x = state[6 + i]
        if math.isfinite(x) and abs(x) > _F32_MAX:
            y = np.float32(x)
            if math.isinf(y):
                return -1
        f32[i] = np.float64(np.float32(x))
    lat = lat0 + (state[0] / EARTH_RADIUS_M) * _RAD_TO_DEG
    lon = lon0 + (state[1] / r_cos) * _RAD_TO_DEG
    v = (lat * 1e7, lon * 1e7, 1000.0 * (alt0 - state[2]), 100.0 * state[3],
         100.0 * state[4], 100.0 * state[5], 100.0 * airspeed)
    for x in v:
        if not math.isfinite(x):
            return -1
    ilat = _clip(_round_half_even(v[0]), -2147483648.0, 2147483647.0)
    ilon = _clip(_round_half_even(v[1]), -2147483648.0, 2147483647.0)
    ialt = _clip(_round_half_even(v[2]), -2147483648.0, 2147483647.0)
    ivx = _clip(_round_half_even(v[3]), -32768.0, 32767.0)
    ivy = _clip(_round_half_even(v[4]), -32768.0, 32767.0)
    ivz = _clip(_round_half_even(v[5]), -32768.0, 32767.0)
    air = _clip(_round_half_even(v[6]), 0.0, 65535.0)
    qw, qx, qy, qz = f32[0], f32[1], f32[2], f32[3]
    n = math.sqrt(qw * qw + qx * qx + qy * qy + qz * qz)
    if not (n > 0.0 and math.isfinite(n)):
        return -1
    a[0] = qw / n
    a[1] = qx / n
    a[2] = qy / n
    a[3] = qz / n
    a[4] = f32[4]
    a[5] = f32[5]
    a[6] = f32[6]
    a[7] = ((ilat * 1e-7 - lat0) * _DEG_TO_RAD) * EARTH_RADIUS_M
    a[8] = ((ilon * 1e-7 - lon0) * _DEG_TO_RAD) * EARTH_RADIUS_M * cos_lat0
    a[9] = alt0 - ialt * 1e-3
    a[10] = ivx * 0.01
    a[11] = ivy * 0.01
    a[12] = ivz * 0.01
    return int(air)


class HilStateEncoder:
    """:func:`encode_hil_state` of a rigid-body state, bit for bit, in one compiled call.

    The SITL vehicle encodes its state every control step on the lockstep's critical path;
    this does :func:`encode_hil_state`'s arithmetic (the encode half of
    :class:`HilRoundTrip`'s kernel, the same operations in the same order) with the projection
    about home kept, and falls back to :func:`encode_hil_state` itself for what the wire
    refuses (non-finite values, a float32 overflow), which then raises its own error.
    ``tests/test_interface.py`` checks it against :func:`encode_hil_state`.

    Parameters
    ----------
    home_lat_deg, home_lon_deg, home_alt_m : float
        Home (the projection's origin): latitude and longitude [deg], altitude AMSL [m].
    """

    __slots__ = ("_alt0", "_lat0", "_lon0", "_out", "_r_cos")

    def __init__(self, home_lat_deg: float, home_lon_deg: float, home_alt_m: float) -> None:
        self._lat0 = home_lat_deg
        self._lon0 = home_lon_deg
        self._alt0 = home_alt_m
        self._r_cos = EARTH_RADIUS_M * FlatEarth(home_lat_deg, home_lon_deg).cos_lat0
        self._out = np.empty(14)

    def __call__(self, time_usec: int, state: NDArray[np.float64],
                 airspeed_m_s: float) -> HilState:
        """The HIL_STATE_QUATERNION fields of a rigid-body state.

        Parameters
        ----------
        time_usec : int
            Simulated time [us].
        state : numpy.ndarray
            At least 13 float64 entries: position NED [m], velocity NED [m/s], quaternion
            ``(w, x, y, z)`` body FRD -> NED, body rates [rad/s] (the vehicle's state order).
        airspeed_m_s : float
            Airspeed [m/s] (both airspeed fields).

        Returns
        -------
        HilState
            Equal to ``encode_hil_state(NavState(time_usec, state[6:10], state[10:13],
            state[0:3], state[3:6], airspeed_m_s), *home)``.
        """
        o = self._out
        if type(state) is np.ndarray and state.dtype == _F64 and state.ndim == 1 \
                and state.shape[0] >= 13 and encode_state_kernel(
                    state, float(airspeed_m_s), self._lat0, self._lon0, self._alt0,
                    self._r_cos, o):
            (qw, qx, qy, qz, p, q, r, lat, lon, alt, vx, vy, vz, air) = o.tolist()
            air_i = int(air)
            return HilState(int(time_usec), (qw, qx, qy, qz), p, q, r, int(lat), int(lon),
                            int(alt), int(vx), int(vy), int(vz), air_i, air_i)
        return encode_hil_state(NavState(time_usec, state[6:10], state[10:13], state[0:3],
                                         state[3:6], airspeed_m_s),
                                self._lat0, self._lon0, self._alt0)


@numba.njit(cache=True)
def encode_state_kernel(state, airspeed, lat0, lon0, alt0, r_cos, out):  # pragma: no cover
    """:func:`encode_hil_state` compiled (as :func:`round_trip_kernel`'s encode half).

    Writes the float32-rounded quaternion and rates, then the rounded and clipped lat, lon
    [degE7], alt [mm], vx, vy, vz [cm/s] and airspeed [cm/s] into ``out`` (14,); returns
    False (``out`` then meaningless) for what the codec refuses.
    """
    for i in range(7):
        x = state[6 + i]
        if not math.isfinite(x):
            return False
        y = np.float32(x)
        if math.isinf(y):
            return False
        out[i] = np.float64(y)
    lat = lat0 + (state[0] / EARTH_RADIUS_M) * _RAD_TO_DEG
    lon = lon0 + (state[1] / r_cos) * _RAD_TO_DEG
    v = (lat * 1e7, lon * 1e7, 1000.0 * (alt0 - state[2]), 100.0 * state[3],
         100.0 * state[4], 100.0 * state[5], 100.0 * airspeed)
    for x in v:
        if not math.isfinite(x):
            return False
    out[7] = _clip(_round_half_even(v[0]), -2147483648.0, 2147483647.0)
    out[8] = _clip(_round_half_even(v[1]), -2147483648.0, 2147483647.0)
    out[9] = _clip(_round_half_even(v[2]), -2147483648.0, 2147483647.0)
    out[10] = _clip(_round_half_even(v[3]), -32768.0, 32767.0)
    out[11] = _clip(_round_half_even(v[4]), -32768.0, 32767.0)
    out[12] = _clip(_round_half_even(v[5]), -32768.0, 32767.0)
    out[13] = _clip(_round_half_even(v[6]), 0.0, 65535.0)
    return True


def wire_commands(u: Sequence[float] | NDArray[np.float64]) -> NDArray[np.float64]:
    """Commands as HIL_ACTUATOR_CONTROLS carries them: float32 in slots ``0..n-1``.

    Parameters
    ----------
    u : array_like
        The ``n <= 16`` normalised actuator commands in the airframe's order.

    Returns
    -------
    numpy.ndarray
        ``n`` float64 values, each exactly the float32 the wire carries.

    Raises
    ------
    ValueError
        More than :data:`HIL_OUTPUTS` commands, or not a flat vector.
    """
    arr = np.asarray(u, dtype=np.float64)
    if arr.ndim != 1 or arr.size > HIL_OUTPUTS:
        raise ValueError(f"commands of shape {arr.shape}: HIL_ACTUATOR_CONTROLS carries at "
                         f"most {HIL_OUTPUTS} actuators")
    return arr.astype(np.float32).astype(np.float64)


@numba.njit(cache=True)
def wire_round(u):  # pragma: no cover - compiled
    """:func:`wire_commands` inside a compiled caller (the in-process vehicle's control
    step): a new float64 array of ``u``'s values each rounded to the float32 the wire
    carries (the same IEEE round-to-nearest-even cast as numpy's ``astype``, so the same
    bits, ``tests/test_inproc_fastpaths.py``). No shape check: the caller's ``u`` is the
    airframe's ``n <= HIL_OUTPUTS`` commands."""
    out = np.empty(u.size)
    for i in range(u.size):
        out[i] = np.float64(np.float32(u[i]))
    return out

"""The autopilot's boundary: what it is given, what it answers, and the commands it takes.

Everything that crosses between the autopilot and the rest of the system is defined here, so
that the in-process runner, the MAVLink autopilot process, the ground station and the
dashboard agree without importing each other:

- :class:`NavState`: the navigation solution the autopilot flies on (attitude, rates,
  position, velocity, airspeed). The autopilot has no estimator: in SITL it is decoded from
  the vehicle's HIL_STATE_QUATERNION; in-process it is built from the vehicle state and passed
  through the *same* wire encoding (:func:`encode_hil_state` / :func:`decode_hil_state`), so
  an in-process run and a lockstep SITL run see bit-identical inputs.
- the autopilot's output: 15 normalised actuator commands in the airframe's actuator order
  (rotors and pushers 0..1 of maximum thrust, surfaces -1..1 of full deflection), rounded to
  float32 exactly as HIL_ACTUATOR_CONTROLS carries them (:func:`wire_commands`).
- :class:`CommandResult` (MAV_RESULT values), :class:`FlightMode`, :class:`VtolState`
  (MAV_VTOL_STATE), :class:`LandedState` (MAV_LANDED_STATE).
- :class:`ParameterStore`: named INT32 / REAL32 parameters with bounds, the store the PARAM
  protocol serves (``SYS_FAILURE_EN`` lives here).
- :class:`AutopilotAPI`: the protocol an autopilot implements.

Frames and units: NED world frame with its origin at home (metres), FRD body frame,
quaternion scalar-first rotating body vectors into NED, SI units, radians.
"""

from __future__ import annotations

import enum
import math
import struct
from collections.abc import Iterator, Sequence
from dataclasses import dataclass, field
from typing import Protocol, runtime_checkable

import numpy as np
from numpy.typing import NDArray

__all__ = [
    "EARTH_RADIUS_M",
    "N_ACTUATORS",
    "AutopilotAPI",
    "AutopilotStatus",
    "CommandResult",
    "FlightMode",
    "HilState",
    "LandedState",
    "NavState",
    "ParamError",
    "ParamType",
    "Parameter",
    "ParameterStore",
    "VtolState",
    "decode_hil_state",
    "encode_hil_state",
    "wire_commands",
]

N_ACTUATORS = 15
EARTH_RADIUS_M = 6_378_137.0


class CommandResult(enum.IntEnum):
    """MAV_RESULT values, the answer to every command."""

    ACCEPTED = 0
    TEMPORARILY_REJECTED = 1
    DENIED = 2
    UNSUPPORTED = 3
    FAILED = 4
    IN_PROGRESS = 5


class FlightMode(enum.IntEnum):
    """Flight modes of the autopilot's state machine."""

    IDLE = 0              # on the ground (armed or not), rotors at idle or off
    TAKEOFF = 1           # multicopter climb to the takeoff altitude
    HOVER = 2             # multicopter position and altitude hold
    FRONT_TRANSITION = 3  # pusher ramps up, lift rotors hold altitude, wing takes over
    FIXED_WING = 4        # wing-borne cruise, altitude hold by pitch
    BACK_TRANSITION = 5   # pusher off, decelerate, lift rotors take over again
    LAND = 6              # multicopter descent to touchdown, then IDLE


class VtolState(enum.IntEnum):
    """MAV_VTOL_STATE."""

    UNDEFINED = 0
    TRANSITION_TO_FW = 1
    TRANSITION_TO_MC = 2
    MC = 3
    FW = 4


class LandedState(enum.IntEnum):
    """MAV_LANDED_STATE."""

    UNDEFINED = 0
    ON_GROUND = 1
    IN_AIR = 2
    TAKEOFF = 3
    LANDING = 4


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
    range. The in-process runner (``vtolftc.scenario``) uses a compiled fusion of this and
    :func:`decode_hil_state` that must return the very same bits: change both together.
    """
    pn, pe, pd = nav.pos_ned_m.tolist()
    lat = home_lat_deg + math.degrees(pn / EARTH_RADIUS_M)
    lon = home_lon_deg + math.degrees(
        pe / (EARTH_RADIUS_M * math.cos(math.radians(home_lat_deg))))
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
    pn = math.radians(h.lat * 1e-7 - home_lat_deg) * EARTH_RADIUS_M
    pe = (math.radians(h.lon * 1e-7 - home_lon_deg) * EARTH_RADIUS_M
          * math.cos(math.radians(home_lat_deg)))
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


def wire_commands(u: Sequence[float] | NDArray[np.float64]) -> NDArray[np.float64]:
    """Commands as HIL_ACTUATOR_CONTROLS carries them: float32, 16 slots (ours are 0..14)."""
    arr = np.asarray(u, dtype=np.float64)
    if arr.shape == (N_ACTUATORS,):  # the usual case: same float32 rounding, 1 us less
        return arr.astype(np.float32).astype(np.float64)
    out = np.zeros(16, dtype=np.float32)
    out[: arr.size] = arr
    return out[:N_ACTUATORS].astype(np.float64)


@dataclass(slots=True)
class AutopilotStatus:
    """A snapshot of the autopilot for telemetry, logs and ground stations."""

    time_usec: int
    mode: FlightMode
    armed: bool
    vtol_state: VtolState
    landed_state: LandedState
    attitude_ref_rad: NDArray[np.float64]       # roll, pitch, yaw references
    attitude_rad: NDArray[np.float64]           # roll, pitch, yaw measured
    altitude_ref_m: float                       # above home
    airspeed_m_s: float
    virtual_command: NDArray[np.float64]        # [Fz (N, NED down), Fx (N, forward), L, M, N (N m)]
    actuator_commands: NDArray[np.float64]      # 15 normalised commands
    allocation_status: str
    controller: str                             # "gs-shif", "shif" or "lqr"
    message: str = ""                           # last event worth a STATUSTEXT
    px4_custom_mode: int = -1                   # PX4 HEARTBEAT custom mode, -1: from ``mode``


class ParamType(enum.IntEnum):
    """MAV_PARAM_TYPE values used here."""

    INT32 = 6
    REAL32 = 9


class ParamError(ValueError):
    """Unknown parameter name, wrong type or value out of range."""


@dataclass
class Parameter:
    """One named parameter (name at most 16 characters, as the PARAM protocol allows)."""

    name: str
    value: float
    type: ParamType
    default: float
    minimum: float = -math.inf
    maximum: float = math.inf
    description: str = ""


@dataclass
class ParameterStore:
    """Named parameters in a fixed order (index = registration order)."""

    _params: dict[str, Parameter] = field(default_factory=dict)

    def register(self, name: str, default: float, type: ParamType = ParamType.REAL32,
                 minimum: float = -math.inf, maximum: float = math.inf,
                 description: str = "") -> None:
        if not 0 < len(name) <= 16 or not name.isascii():
            raise ParamError(f"parameter name {name!r}: expected 1-16 ASCII characters")
        if name in self._params:
            raise ParamError(f"parameter {name} registered twice")
        self._params[name] = Parameter(name, float(default), ParamType(type), float(default),
                                       minimum, maximum, description)

    def __contains__(self, name: object) -> bool:
        return name in self._params

    def __iter__(self) -> Iterator[Parameter]:
        return iter(self._params.values())

    def __len__(self) -> int:
        return len(self._params)

    def index(self, name: str) -> int:
        return list(self._params).index(self._lookup(name).name)

    def by_index(self, i: int) -> Parameter:
        if not 0 <= i < len(self._params):
            raise ParamError(f"parameter index {i}: expected 0..{len(self._params) - 1}")
        return list(self._params.values())[i]

    def _lookup(self, name: str) -> Parameter:
        try:
            return self._params[name]
        except KeyError:
            raise ParamError(f"unknown parameter {name!r}") from None

    def get(self, name: str) -> float:
        return self._lookup(name).value

    def set(self, name: str, value: float) -> Parameter:
        """Set ``name`` to ``value`` (checked against type and bounds); returns the parameter."""
        p = self._lookup(name)
        v = float(value)
        if not math.isfinite(v):
            raise ParamError(f"{name} = {value!r}: expected a finite number")
        if p.type == ParamType.INT32 and v != int(v):
            raise ParamError(f"{name} = {value!r}: expected an integer")
        if not p.minimum <= v <= p.maximum:
            raise ParamError(f"{name} = {value!r}: expected {p.minimum:g} .. {p.maximum:g}")
        p.value = v
        return p


@runtime_checkable
class AutopilotAPI(Protocol):
    """What an autopilot offers to the runners and to its MAVLink endpoint.

    ``step`` is called once per control period (250 Hz) with the latest navigation state and
    returns the 15 normalised actuator commands (before :func:`wire_commands`). ``command``
    takes a MAVLink COMMAND_LONG's id and its seven params (NaN = default) for the flight
    commands (COMPONENT_ARM_DISARM 400, NAV_TAKEOFF 22, DO_SET_MODE 176, DO_VTOL_TRANSITION
    3000, NAV_LAND 21) and answers with a :class:`CommandResult`; any other id gets
    ``UNSUPPORTED``. Fault injection is not the autopilot's business: the MAVLink endpoint
    checks ``SYS_FAILURE_EN`` in :attr:`params` and forwards it to the vehicle.
    """

    params: ParameterStore

    def step(self, nav: NavState) -> NDArray[np.float64]: ...

    def command(self, command_id: int, params: Sequence[float]) -> CommandResult: ...

    def status(self) -> AutopilotStatus: ...

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
from collections.abc import Iterator, Mapping, Sequence
from dataclasses import dataclass, field
from types import MappingProxyType
from typing import Protocol, runtime_checkable

import numpy as np
from numpy.typing import NDArray

# The boundary types live at the lowest layer that needs them, and are re-exported here so the
# autopilot's whole boundary reads from one place (everything above imports them from here):
# NavState and the HIL wire forms in protocols (the HIL codec decodes into NavState); the
# autopilot's status and mode enums in telemetry.autopilot_status (a TelemetrySample carries
# an AutopilotStatus; the metrics and the recorder read FlightMode; nothing in protocols does).
from vtolftc.protocols.hil import (
    EARTH_RADIUS_M,
    HIL_OUTPUTS,
    HilState,
    NavState,
    decode_hil_state,
    encode_hil_state,
    wire_commands,
)
from vtolftc.telemetry.autopilot_status import AutopilotStatus, FlightMode, LandedState, VtolState

__all__ = [
    "EARTH_RADIUS_M",
    "HIL_OUTPUTS",
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



class CommandResult(enum.IntEnum):
    """MAV_RESULT values, the answer to every command."""

    ACCEPTED = 0
    TEMPORARILY_REJECTED = 1
    DENIED = 2
    UNSUPPORTED = 3
    FAILED = 4
    IN_PROGRESS = 5


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
        """Add a parameter with its default value, MAVLink type, range and description.

        Raises
        ------
        ParamError
            the name is not 1-16 ASCII characters, or it is already registered.
        """
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
        """Position of parameter ``name`` in registration order (PARAM_VALUE's index)."""
        return list(self._params).index(self._lookup(name).name)

    def by_index(self, i: int) -> Parameter:
        """The parameter at registration position ``i`` (ParamError when out of range)."""
        if not 0 <= i < len(self._params):
            raise ParamError(f"parameter index {i}: expected 0..{len(self._params) - 1}")
        return list(self._params.values())[i]

    def _lookup(self, name: str) -> Parameter:
        try:
            return self._params[name]
        except KeyError:
            raise ParamError(f"unknown parameter {name!r}") from None

    def get(self, name: str) -> float:
        """Current value of parameter ``name`` (ParamError if unknown)."""
        return self._lookup(name).value

    def view(self) -> Mapping[str, Parameter]:
        """A live, read-only mapping name -> :class:`Parameter` (the hot paths read
        ``view[name].value`` without a call per read; later registrations and sets show)."""
        return MappingProxyType(self._params)

    def set_default(self, name: str, value: float) -> Parameter:
        """Make ``value`` both the default and the current value of ``name`` (an airframe's
        own default, like a PX4 airframe file's ``param set-default``); checked like
        :meth:`set`."""
        p = self.set(name, value)
        p.default = p.value
        return p

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

    def step(self, nav: NavState) -> NDArray[np.float64]:
        """One control step: the 15 normalised actuator commands for navigation state ``nav``."""

    def command(self, command_id: int, params: Sequence[float]) -> CommandResult:
        """Execute flight command ``command_id`` with its seven params (NaN = default)."""

    def status(self) -> AutopilotStatus:
        """Snapshot for telemetry: mode, arming, VTOL and landed state, references, commands."""

"""The autopilot's reported status: its flight modes and the snapshot it gives every step.

:class:`FlightMode` (the mode machine's states), :class:`VtolState` (MAV_VTOL_STATE),
:class:`LandedState` (MAV_LANDED_STATE) and :class:`AutopilotStatus` belong to the autopilot,
whose interface (:mod:`vtolftc.firmware_sim.autopilot.interface`) is where everything above
this layer imports them from. They are defined here, in the telemetry layer, because that is
the lowest layer that needs them: a :class:`~vtolftc.telemetry.samples.TelemetrySample`
carries an :class:`AutopilotStatus`, and the metrics and the rerun recorder read the
:class:`FlightMode`, while telemetry may not import the autopilot (layer 3). Nothing in the
protocols layer below needs them (the wire carries PX4's custom modes, :mod:`.protocols.px4`).
"""

from __future__ import annotations

import enum
from dataclasses import dataclass

import numpy as np
from numpy.typing import NDArray

__all__ = ["AutopilotStatus", "FlightMode", "LandedState", "VtolState"]


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

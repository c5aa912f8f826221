"""What a run reports while it flies: one sample per control step, events, and observers.

The runners (in-process and SITL) produce :class:`TelemetrySample` records and events and hand
them to every :class:`RunObserver` (the run-folder writer, the rerun recorder, live views).
A sample joins what the autopilot knew and decided (``nav``, ``status``) with what only the
simulated vehicle knows (``truth``): the truth part is for logs and plots and never reaches the
controller (passive FTC). In SITL the autopilot process has no truth; ``truth`` is then None
in its samples and the vehicle process reports it on its own.
"""

from __future__ import annotations

import enum
from dataclasses import dataclass
from typing import Any, Protocol, runtime_checkable

import numpy as np
from numpy.typing import NDArray

from vtolftc.protocols.hil import NavState

__all__ = [
    "AutopilotStatus",
    "FlightMode",
    "LandedState",
    "RunObserver",
    "TelemetrySample",
    "VehicleTruth",
    "VtolState",
]


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


@dataclass(slots=True)
class VehicleTruth:
    """Simulator-side state at a sample (SI units, NED / FRD, radians)."""

    pos_ned_m: NDArray[np.float64]
    vel_ned_m_s: NDArray[np.float64]
    q_wxyz: NDArray[np.float64]
    euler_rad: NDArray[np.float64]                 # roll, pitch, yaw
    omega_body_rad_s: NDArray[np.float64]
    airspeed_m_s: float
    actuator_positions: NDArray[np.float64]        # 15 normalised positions after actuator dynamics
    effectiveness: NDArray[np.float64]             # 15 factors in [0, 1] (1 = healthy)


@dataclass(slots=True)
class TelemetrySample:
    """One control step: the autopilot's inputs and outputs, and the vehicle truth if known."""

    time_usec: int
    nav: NavState
    status: AutopilotStatus
    truth: VehicleTruth | None = None


@runtime_checkable
class RunObserver(Protocol):
    """Receives a run as it happens. Every method must be cheap (it runs in the flight loop)
    and must not raise; ``on_finish`` is called exactly once, also when the run is
    interrupted (then ``metrics`` holds what was computed so far and ``"interrupted": True``)."""

    def on_start(self, info: dict[str, Any]) -> None:
        """``info``: airframe name and sha256, actuator names, controller, case, run folder."""

    def on_sample(self, sample: TelemetrySample) -> None:
        """One control step's navigation state, autopilot status and commands."""

    def on_event(self, time_usec: int, kind: str, text: str) -> None:
        """``kind``: "mode", "command", "fault", "ack", "warning"; ``text`` human-readable."""

    def on_finish(self, metrics: dict[str, Any]) -> None:
        """End of run with the final ``metrics``; close files here."""

"""What a run reports while it flies: one sample per control step, events, and observers.

The runners (in-process and SITL) produce :class:`TelemetrySample` records and events and hand
them to every :class:`RunObserver` (the run-folder writer, the rerun recorder, live views).
A sample joins what the autopilot knew and decided (``nav``, ``status``) with what only the
simulated vehicle knows (``truth``): the truth part is for logs and plots and never reaches the
controller (passive FTC). In SITL the autopilot process has no truth; ``truth`` is then None
in its samples and the vehicle process reports it on its own. The autopilot's part, its
status and modes, is defined in :mod:`vtolftc.telemetry.autopilot_status`.
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import Any, Protocol, runtime_checkable

import numpy as np
from numpy.typing import NDArray

from vtolftc.protocols.hil import NavState
from vtolftc.telemetry.autopilot_status import AutopilotStatus

__all__ = [
    "RunObserver",
    "TelemetrySample",
    "VehicleTruth",
]


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

"""The autopilot's attitude stage: the scheduled attitude controller of one control step.

The controller (``gs-shif``, ``shif`` or ``lqr``, :mod:`.attitude`) gives the body moments
``[L, M, N]`` [N m] for the attitude reference; its gains are scheduled on the measured
airspeed through a first-order low-pass of time constant ``FTC_SCHED_TAU`` (0.5 s; the modes,
the allocation and the outer loops use the raw value). On the ground before takeoff the
controller is held reset (no integrator wind-up against the ground).
"""

from __future__ import annotations

import math
from typing import Any

import numpy as np
from numpy.typing import NDArray

from vtolftc.firmware_sim.autopilot.attitude import AttitudeController
from vtolftc.firmware_sim.autopilot.estimate import StateEstimate
from vtolftc.firmware_sim.autopilot.interface import FlightMode

__all__ = ["AttitudeStage"]

_M_TAKEOFF = FlightMode.TAKEOFF


class AttitudeStage:
    """Scheduled attitude control (see the module docstring).

    Parameters
    ----------
    controller
        the attitude controller.
    pp
        the autopilot's parameters by name (``Parameter`` objects, read every step).
    estimate
        the state intake (ground altitude).
    dt
        control period [s].
    """

    def __init__(self, controller: AttitudeController, pp: dict[str, Any],
                 estimate: StateEstimate, dt: float) -> None:
        self.controller = controller
        self._p = pp
        self.est = estimate
        self.dt = dt
        #: the airspeed the gains are scheduled with [m/s] (FTC_SCHED_TAU low-pass)
        self.v_sched = math.nan

    def update(self, mode: FlightMode, h: float, V: float, ref: NDArray[np.float64],
               att: NDArray[np.float64], rates: NDArray[np.float64], sat_hi: list[bool],
               sat_lo: list[bool]) -> NDArray[np.float64]:
        """The body torque commands [N m] (FRD) for the reference ``ref`` (roll, pitch, yaw
        [rad]): ``att`` roll/pitch/yaw [rad], ``rates`` body rates [rad/s], ``V`` airspeed
        [m/s], ``h`` altitude [m]; ``sat_hi``/``sat_lo`` the moment axes the last allocation
        fell short of upwards/downwards (anti-windup)."""
        if mode == _M_TAKEOFF and h - self.est.ground_alt < 0.5:  # still on the ground
            self.controller.reset()
        # gains scheduled on a low-passed airspeed: the measurement's noise would otherwise
        # move the gains between neighbouring design points from step to step (in hover
        # between 0 and 1 m/s, whose pitch gains differ by 3x), a randomly time-varying
        # controller that the design never analysed
        tc = self._p["FTC_SCHED_TAU"].value
        vs = self.v_sched
        if tc > 0.0 and math.isfinite(vs):
            vs += min(1.0, self.dt / tc) * (V - vs)
        else:
            vs = V
        self.v_sched = vs
        return self.controller.update(ref, att, rates, vs, sat_hi, sat_lo)

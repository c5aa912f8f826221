"""The autopilot's attitude stage: the scheduled attitude controller of one control step.

The controller (``gs-shif``, ``shif`` or ``lqr``, :mod:`.attitude`) gives the body moments
``[L, M, N]`` [N m] for the attitude reference; its gains are scheduled on the measured
airspeed through a first-order low-pass of time constant ``FTC_SCHED_TAU`` (0.5 s; the modes,
the allocation and the outer loops use the raw value). On the ground before takeoff the
controller is held reset (no integrator wind-up against the ground).

With a :class:`~.attitude.ScheduledPPIDController` (``gs-shif``, ``shif``) the stage calls the
compiled step itself (:func:`.control_kernels.scheduled_ppid3_step_packed`: what ``update``
calls, :func:`.control_kernels.scheduled_ppid3_step`, on views of the schedule's packed
tables and the controller's workspace, the saturation flags as the output stage's mask; no
conversion, no copy), so the same bits; compiled without ``fastmath``. In a flight the
autopilot does not call :meth:`AttitudeStage.update`: it takes that step's arguments from
:meth:`AttitudeStage.kernel_step_args` (the stage's work before the controller done) and
hands them to the output stage, whose allocation runs the step first in the same compiled
call (``ActiveSetAllocator.allocate_tracked(..., ppid=...)``).
"""

from __future__ import annotations

import math
from typing import Any

import numpy as np
from numpy.typing import NDArray

from vtolftc.firmware_sim.autopilot.attitude import AttitudeController, ScheduledPPIDController
from vtolftc.firmware_sim.autopilot.control_kernels import scheduled_ppid3_step_packed
from vtolftc.firmware_sim.autopilot.estimate import StateEstimate
from vtolftc.firmware_sim.autopilot.interface import FlightMode

__all__ = ["AttitudeStage"]

_M_TAKEOFF = FlightMode.TAKEOFF
_F64 = np.dtype(np.float64)


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
               sat_lo: list[bool], sat_mask: int | None = None) -> NDArray[np.float64]:
        """The body torque commands [N m] (FRD) for the reference ``ref`` (roll, pitch, yaw
        [rad]): ``att`` roll/pitch/yaw [rad], ``rates`` body rates [rad/s], ``V`` airspeed
        [m/s], ``h`` altitude [m]; ``sat_hi``/``sat_lo`` the moment axes the last allocation
        fell short of upwards/downwards (anti-windup), ``sat_mask`` the same flags as the
        output stage's mask (bits 0-2 ``sat_hi``, 3-5 ``sat_lo``) when the caller has it.
        The result may be the controller's own output array (read it before the next step,
        do not keep it)."""
        if sat_mask is None:
            sat_mask = ((1 if sat_hi[0] else 0) | (2 if sat_hi[1] else 0)
                        | (4 if sat_hi[2] else 0) | (8 if sat_lo[0] else 0)
                        | (16 if sat_lo[1] else 0) | (32 if sat_lo[2] else 0))
        args = self.kernel_step_args(mode, h, V, ref, att, rates, sat_mask)
        if args is not None:
            # ctrl.update(ref, att, rates, vs, sat_hi, sat_lo) without its argument
            # conversions (``ref`` and ``att`` are the autopilot's own float64 arrays): the
            # same compiled step on the same arrays, hence the same bits, on the schedule's
            # tables and the controller's arrays as two packed arrays. The result is the
            # controller's output array (the output stage copies it into the virtual command
            # at once), not a copy
            scheduled_ppid3_step_packed(*args)
            return self.controller.kernel_arrays[3]
        return self.controller_update(ref, att, rates, sat_hi, sat_lo)

    def kernel_step_args(self, mode: FlightMode, h: float, V: float, ref: NDArray[np.float64],
                         att: NDArray[np.float64], rates: NDArray[np.float64],
                         sat_mask: int) -> tuple[Any, ...] | None:
        """:meth:`update`'s work before the controller, and the compiled step's arguments
        for a caller that runs that step itself (the output stage, fused with the
        allocation: ``allocate_tracked(..., ppid=...)``).

        Resets the controller while on the ground before takeoff and low-passes the
        airspeed the gains are scheduled with (``v_sched``). When the controller is stepped
        directly (a :class:`~.attitude.ScheduledPPIDController` whose ``update`` is not
        replaced on the instance, e.g. by a test's spy; float64 ``rates``) returns the
        arguments ``(tab, vs, ref, att, rates, ws, sat_mask)`` of
        :func:`.control_kernels.scheduled_ppid3_step_packed` (the moments [N m] land in
        ``ws[W_OUT:W_SIZE]``, the controller's output array); else None, and the caller
        calls :meth:`controller_update`. Arguments as :meth:`update`'s.
        """
        ctrl = self.controller
        if mode == _M_TAKEOFF and h - self.est.ground_alt < 0.5:  # still on the ground
            ctrl.reset()
        # gains scheduled on a low-passed airspeed: the measurement's noise would otherwise
        # move the gains between neighbouring design points from step to step (in hover
        # between 0 and 1 m/s, whose pitch gains differ by 3x), a randomly time-varying
        # controller that the design never analysed
        tc = self._p["FTC_SCHED_TAU"].value
        vs = self.v_sched
        if tc > 0.0 and math.isfinite(vs):
            r = self.dt / tc
            vs += (r if r < 1.0 else 1.0) * (V - vs)  # min(1.0, r), without the call
        else:
            vs = V
        self.v_sched = vs
        if type(ctrl) is ScheduledPPIDController and "update" not in ctrl.__dict__ \
                and type(rates) is np.ndarray and rates.dtype is _F64:
            return ctrl.schedule.kernel_packed, vs, ref, att, rates, ctrl.kernel_ws, sat_mask
        return None

    def controller_update(self, ref: NDArray[np.float64], att: NDArray[np.float64],
                          rates: NDArray[np.float64], sat_hi: list[bool],
                          sat_lo: list[bool]) -> NDArray[np.float64]:
        """The controller's own ``update`` at the scheduled airspeed ``v_sched``, after
        :meth:`kernel_step_args` answered None; arguments as :meth:`update`'s."""
        return self.controller.update(ref, att, rates, self.v_sched, sat_hi, sat_lo)

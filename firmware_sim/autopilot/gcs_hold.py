"""Simulation hold of the ground-station endpoint (lockstep only, a vtol-ftc extension for
exactly timed scripted runs).

The INT32 parameter ``SIM_HOLD_MS`` (-1 = off) makes the autopilot wait before the control
step at simulated time >= SIM_HOLD_MS ms (:meth:`SimulationHold.hold_usec`, asked by the
control thread); while held, the endpoint sends NAMED_VALUE_INT ``SIM_HOLD`` (value = the hold
time in ms) at once and then at 1 Hz of wall-clock time (:meth:`SimulationHold.due`, asked by
the worker), and keeps serving commands and parameters until SIM_HOLD_MS is moved past the
current time (or set to -1).
"""

from __future__ import annotations

from typing import Any

from vtolftc.firmware_sim.autopilot.interface import ParamType

__all__ = ["SIM_HOLD_PARAM", "SimulationHold"]

SIM_HOLD_PARAM = "SIM_HOLD_MS"


class SimulationHold:
    """``SIM_HOLD_MS`` (registered in ``params`` if absent, set to ``hold_ms``) and the
    announcement of a hold (module docstring). Without ``lockstep`` there is never a hold."""

    def __init__(self, params: Any, *, lockstep: bool, hold_ms: int = -1) -> None:
        self.params = params
        self.lockstep = lockstep
        if SIM_HOLD_PARAM not in params:
            params.register(SIM_HOLD_PARAM, -1, ParamType.INT32, -1, 2**31 - 1,
                            "lockstep only: hold the simulation before the control step at "
                            "this simulated time in ms (-1 = off)")
        params.set(SIM_HOLD_PARAM, int(hold_ms))
        self.notice_ms: int | None = None
        """Control thread: the simulated time [ms] held at now, None while running."""
        self._sent_ms: int | None = None
        self._next_wall = 0.0

    def hold_usec(self) -> int | None:
        """Simulated time [us] at which to hold, None if no hold (or not lockstep)."""
        if not self.lockstep:
            return None
        v = int(self.params.get(SIM_HOLD_PARAM))
        return None if v < 0 else v * 1000

    def announce(self, time_usec: int) -> bool:
        """Control thread: held at ``time_usec``; True if that is news for the worker."""
        ms = time_usec // 1000
        if self.notice_ms == ms:
            return False
        self.notice_ms = ms
        return True

    def stepped(self) -> None:
        """Worker: simulated time advanced (a new hold is announced at once)."""
        self._sent_ms = None

    def due(self, now: float) -> int | None:
        """Worker, at monotonic time ``now`` [s]: the hold time [ms] to announce now, if any."""
        ms = self.notice_ms
        if ms is None or (self._sent_ms == ms and now < self._next_wall):
            return None
        self._sent_ms = ms
        self._next_wall = now + 1.0
        return ms

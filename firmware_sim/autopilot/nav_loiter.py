"""The navigator's hold: AUTO.LOITER and DO_REPOSITION (PX4's ``Loiter`` navigator mode).

Hold where it is when the mode is selected (PX4 reports Hold on the ground too): in
multicopter the autopilot's position hold over that point, in fixed-wing a circle of
``NAV_LOITER_RAD`` about it (clockwise). DO_REPOSITION (192) moves the point (latitude and
longitude in param5/6, NaN: here; altitude AMSL in param7, NaN: keep; ground speed param1) and
holds there, flown at that speed in multicopter.
"""

from __future__ import annotations

import math

from vtolftc.firmware_sim.autopilot.interface import CommandResult, FlightMode, NavState
from vtolftc.firmware_sim.autopilot.nav_base import NavigatorMode, NavMode

__all__ = ["Loiter"]


class Loiter(NavigatorMode):
    """Hold and reposition (see the module docstring)."""

    def enter_hold(self, why: str = "") -> None:
        """AUTO.LOITER about the present position (``why``, if any, told to the ground)."""
        nv = self.navigator
        nv.leave_auto(NavMode.LOITER)
        nav = nv.last_nav
        if nav is not None:
            nv.loiter_center = (float(nav.pos_ned_m[0]), float(nav.pos_ned_m[1]))
            nv.hold_at(nv.loiter_center, lock=False)
        if why:
            nv.say(why)

    def reposition(self, p: list[float]) -> CommandResult:
        """DO_REPOSITION: go to lat/lon (param5/6 deg, NaN = here) at altitude param7 (AMSL,
        NaN = keep) and hold there (loiter in fixed-wing)."""
        nv = self.navigator
        ap = nv.ap
        m = ap.modes
        if not m.armed or m.mode in (FlightMode.IDLE, FlightMode.TAKEOFF, FlightMode.LAND):
            return CommandResult.DENIED
        nav = nv.last_nav
        if nav is None or nv.home is None:
            return CommandResult.TEMPORARILY_REJECTED
        n, e = float(nav.pos_ned_m[0]), float(nav.pos_ned_m[1])
        if math.isfinite(p[4]) and math.isfinite(p[5]):
            if not (-90 <= p[4] <= 90 and -180 <= p[5] <= 180):
                return CommandResult.DENIED
            n, e = nv.to_local(p[4], p[5])
        nv.leave_auto(NavMode.LOITER)
        nv.loiter_center = (n, e)
        nv.hold_at((n, e))
        if math.isfinite(p[6]):
            nv.set_alt_ref(p[6] - nv.home_alt)
        if math.isfinite(p[0]) and p[0] > 0:
            nv.mc_speed = p[0]
        return CommandResult.ACCEPTED

    def circle(self, nav: NavState) -> None:
        """Fixed-wing: circle ``NAV_LOITER_RAD`` clockwise about the loiter point (the present
        position when there is none yet)."""
        nv = self.navigator
        if nv.loiter_center is None:
            nv.loiter_center = (float(nav.pos_ned_m[0]), float(nav.pos_ned_m[1]))
        nv.fw_target = ("loiter", nv.loiter_center, nv.param["NAV_LOITER_RAD"].value, 1)

    def on_active(self, nav: NavState, yaw: float) -> None:
        """Fixed-wing: the circle; multicopter after a reposition: the carrot to the point at
        its speed (otherwise the autopilot's position hold holds it)."""
        nv = self.navigator
        mode = nv.ap.modes.mode
        if mode == FlightMode.FIXED_WING:
            self.circle(nav)
        elif mode == FlightMode.HOVER and nv.loiter_center is not None \
                and math.isfinite(nv.mc_speed):
            nv.mc_goto(nv.loiter_center, nav)

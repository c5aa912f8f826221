"""The navigator's return to launch (PX4's ``RTL`` navigator mode).

AUTO.RTL (DO_SET_MODE), the command NAV_RETURN_TO_LAUNCH (20), the mission item of the same
number and the failsafes: climb to ``RTL_RETURN_ALT`` above home if lower, return to the
nearest of home and the rally points, in fixed-wing with the VTOL landing above
(:class:`~vtolftc.firmware_sim.autopilot.nav_land.Land`: back transition at the braking
distance); in multicopter at the cruise speed. A running mission is paused.
"""

from __future__ import annotations

import math

from vtolftc.firmware_sim.autopilot.interface import CommandResult, FlightMode, NavState
from vtolftc.firmware_sim.autopilot.mission import NAV_VTOL_LAND, RALLY
from vtolftc.firmware_sim.autopilot.nav_base import (
    MS_ACTIVE,
    MS_PAUSED,
    Goal,
    NavigatorBase,
    NavigatorMode,
    NavMode,
)
from vtolftc.firmware_sim.autopilot.nav_land import Land

__all__ = ["Rtl"]


class Rtl(NavigatorMode):
    """Return to launch (see the module docstring).

    Parameters
    ----------
    navigator
        the navigator's state.
    land
        the landing that ends the return.
    """

    def __init__(self, navigator: NavigatorBase, land: Land) -> None:
        super().__init__(navigator)
        self.land = land
        self.item_goal: Goal | None = None
        """the landing of a NAV_RETURN_TO_LAUNCH mission item being flown"""

    def start(self, why: str) -> CommandResult:
        """Return to launch (``why`` is the reason told to the ground station).

        Flies to the nearest of home and the rally points at ``RTL_RETURN_ALT`` or higher and
        lands there; a running mission is paused. DENIED when disarmed, IDLE or without a home.
        """
        nv = self.navigator
        m = nv.ap.modes
        if not m.armed or m.mode == FlightMode.IDLE or nv.home is None:
            return CommandResult.DENIED
        if nv.nav_mode == NavMode.MISSION and nv.mission_state == MS_ACTIVE:
            nv.mission_state = MS_PAUSED
        nv.nav_mode = NavMode.RTL
        n, e = self.destination()
        rtl_alt = nv.param["RTL_RETURN_ALT"].value
        nv.goal = Goal(NAV_VTOL_LAND, -1, n, e, max(rtl_alt, nv.altitude_m))
        nv.phase = ""
        nv.say(f"{why}: returning to ({n:.0f}, {e:.0f}) m at {nv.goal.alt:.0f} m")
        return CommandResult.ACCEPTED

    def destination(self) -> tuple[float, float]:
        """The nearest of home and the rally points (local north, east m)."""
        nv = self.navigator
        nav = nv.last_nav
        here = (0.0, 0.0) if nav is None else (float(nav.pos_ned_m[0]), float(nav.pos_ned_m[1]))
        best, dbest = (0.0, 0.0), math.hypot(*here)
        for it in nv.store.plans[RALLY]:
            n, e = nv.to_local(it.lat_deg, it.lon_deg)
            d = math.hypot(n - here[0], e - here[1])
            if d < dbest:
                best, dbest = (n, e), d
        return best

    def on_active(self, nav: NavState, yaw: float) -> None:
        """Fly the return's landing goal; done (no goal) once landed."""
        nv = self.navigator
        if nv.goal is None:
            return
        pos = (float(nav.pos_ned_m[0]), float(nav.pos_ned_m[1]))
        h = -float(nav.pos_ned_m[2])
        if self.land.fly(nv.goal, nav, yaw, pos, h):
            nv.goal = None

    def fly_item(self, nav: NavState, yaw: float, pos: tuple[float, float], h: float) -> bool:
        """The mission item NAV_RETURN_TO_LAUNCH: the same return, from the item's first step
        (position ``pos``, north/east m, height ``h``, m above home); True once landed."""
        nv = self.navigator
        if nv.phase == "" or self.item_goal is None:
            n, e = self.destination()
            self.item_goal = Goal(NAV_VTOL_LAND, -1, n, e,
                                  max(nv.param["RTL_RETURN_ALT"].value, h))
            nv.set_phase("rtl")
        return self.land.fly(self.item_goal, nav, yaw, pos, h)

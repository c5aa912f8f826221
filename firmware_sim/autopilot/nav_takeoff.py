"""The navigator's takeoff: multicopter climb, heading alignment and the front transition.

PX4's ``Takeoff`` navigator mode and the takeoff part of its ``MissionBlock``: AUTO.TAKEOFF
itself is flown by the autopilot's mode machine (:mod:`.modes`), the navigator only reports
it; a mission's NAV_TAKEOFF (22) climbs to the item's altitude (``MIS_TAKEOFF_ALT`` when it
has none), NAV_VTOL_TAKEOFF (84) then turns towards its target and transitions, and
DO_VTOL_TRANSITION (3000) to fixed-wing turns towards the next positioned item first (PX4's
mission "align" work item: a 30 deg/s heading slew, the transition once within
``MIS_YAW_ERR``). The item is reached when the aircraft is wing-borne.
"""

from __future__ import annotations

import math

from vtolftc.firmware_sim.autopilot.guidance import wrap_pi
from vtolftc.firmware_sim.autopilot.interface import CommandResult, FlightMode, NavState
from vtolftc.firmware_sim.autopilot.mission import NAV_TAKEOFF
from vtolftc.firmware_sim.autopilot.nav_base import Goal, NavigatorMode

__all__ = ["Takeoff"]

_YAW_SLEW = math.radians(30.0)  # rad/s, heading slew in multicopter before a transition
_ALIGN_MIN_DIST_M = 50.0        # a target nearer than this sets no heading


class Takeoff(NavigatorMode):
    """Takeoff and front transition (see the module docstring)."""

    def start(self, alt: float) -> bool:
        """Arm-state takeoff of the mode machine to ``alt`` [m above home]; True if taken."""
        nv = self.navigator
        nv.set_takeoff_alt(alt)
        res = nv.ap.modes.takeoff()
        nv.drain_events()
        return res == CommandResult.ACCEPTED

    def fly_item(self, g: Goal, nav: NavState, yaw: float, pos: tuple[float, float],
                 h: float) -> bool:
        """NAV_TAKEOFF / NAV_VTOL_TAKEOFF goal ``g`` at position ``pos`` (north, east m) and
        height ``h`` (m above home); True once reached."""
        nv = self.navigator
        ap = nv.ap
        mode = ap.modes.mode
        alt = g.alt if math.isfinite(g.alt) else nv.param["MIS_TAKEOFF_ALT"].value
        if nv.phase == "":
            if mode == FlightMode.IDLE:
                if not self.start(alt):
                    return False
                nv.set_phase("climb")
                return False
            if mode == FlightMode.FIXED_WING:
                return True
            nv.set_alt_ref(alt)
            nv.set_phase("climb")
        if nv.phase == "climb":
            if mode == FlightMode.TAKEOFF:
                return False
            nv.set_alt_ref(alt)
            if abs(h - alt) > nv.param["NAV_MC_ALT_RAD"].value:
                return False
            if g.command == NAV_TAKEOFF:
                return True
            nv.set_phase("align")
        target = (g.north, g.east) if g.has_position and math.hypot(
            g.north - pos[0], g.east - pos[1]) > _ALIGN_MIN_DIST_M else None
        return self.front_transition(nav, yaw, target)

    def fly_transition_item(self, nav: NavState, yaw: float, pos: tuple[float, float],
                            nxt: Goal | None) -> bool:
        """DO_VTOL_TRANSITION to fixed-wing, aligned with ``nxt`` (the next positioned goal,
        None for none); True once wing-borne."""
        nv = self.navigator
        target = (nxt.north, nxt.east) if nxt is not None and math.hypot(
            nxt.north - pos[0], nxt.east - pos[1]) > _ALIGN_MIN_DIST_M else None
        if nv.phase == "":
            nv.set_phase("align")
        return self.front_transition(nav, yaw, target)

    def front_transition(self, nav: NavState, yaw: float,
                         target: tuple[float, float] | None) -> bool:
        """Phase "align": slew the heading towards ``target`` (north, east m; None: keep),
        then command the front transition; True once in fixed-wing."""
        nv = self.navigator
        ap = nv.ap
        m = ap.modes
        pos = (float(nav.pos_ned_m[0]), float(nav.pos_ned_m[1]))
        if m.mode == FlightMode.FIXED_WING:
            nv.seg_a = pos
            nv.prev_wp = None
            return True
        if nv.phase == "align":
            if m.mode != FlightMode.HOVER:
                return False
            if target is not None:
                want = math.atan2(target[1] - pos[1], target[0] - pos[0])
                err = wrap_pi(want - nv.yaw_hold)
                step = _YAW_SLEW * ap.dt
                nv.yaw_hold = wrap_pi(nv.yaw_hold + min(max(err, -step), step))
                if abs(wrap_pi(want - yaw)) > math.radians(nv.param["MIS_YAW_ERR"].value):
                    return False
            nv.set_phase("transition")
            m.transition(True)
            nv.drain_events()
        return False

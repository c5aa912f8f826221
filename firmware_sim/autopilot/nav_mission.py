"""The navigator's AUTO.MISSION: sequencing the uploaded mission and flying its items.

PX4's ``Mission`` navigator mode with its ``MissionBlock`` (how an item is flown and when it
is reached). The current item becomes a :class:`~.nav_base.Goal`; on the ground the mission
takes off first (``MIS_TAKEOFF_ALT``); each item reached is reported (MISSION_ITEM_REACHED)
and the next one becomes current; DO_JUMP repeats; after the last item the mission is
complete and the aircraft holds (a loiter circle in fixed-wing).

Items flown here: NAV_WAYPOINT (16): fixed-wing L1 segment from the previous waypoint,
reached within ``max(param2 or NAV_ACC_RAD, L1 distance)`` as PX4's fixed-wing acceptance
(at the braking distance when the next item is DO_VTOL_TRANSITION to multicopter, which then
holds over the waypoint); multicopter: within param2 or ``NAV_ACC_RAD`` horizontally and
``NAV_MC_ALT_RAD`` vertically, then param1 seconds of hold; NAV_LOITER_TIME (19) /
NAV_LOITER_UNLIM (17): circle of param3 (0: ``NAV_LOITER_RAD``, sign = direction: positive
clockwise) in fixed-wing, position hold in multicopter, the time counted from reaching the
circle; NAV_DELAY (93); DO_CHANGE_SPEED (178); DO_JUMP (177, param1 target, param2 repeats);
DO_LAND_START (189, a marker). Takeoff and front transitions are flown by
:mod:`.nav_takeoff`, landings and back transitions by :mod:`.nav_land`, NAV_RETURN_TO_LAUNCH
(20) by :mod:`.nav_rtl`.
"""

from __future__ import annotations

import math

from vtolftc.firmware_sim.autopilot.guidance import cross_track
from vtolftc.firmware_sim.autopilot.interface import CommandResult, FlightMode, NavState
from vtolftc.firmware_sim.autopilot.mission import (
    DO_CHANGE_SPEED,
    DO_JUMP,
    DO_LAND_START,
    DO_VTOL_TRANSITION,
    NAV_DELAY,
    NAV_LAND,
    NAV_LOITER_TIME,
    NAV_LOITER_UNLIM,
    NAV_RETURN_TO_LAUNCH,
    NAV_TAKEOFF,
    NAV_VTOL_LAND,
    NAV_VTOL_TAKEOFF,
    NAV_WAYPOINT,
    RALLY,
)
from vtolftc.firmware_sim.autopilot.nav_base import (
    MS_ACTIVE,
    MS_COMPLETE,
    MS_NOT_STARTED,
    Goal,
    NavigatorBase,
    NavigatorMode,
    NavMode,
)
from vtolftc.firmware_sim.autopilot.nav_land import Land
from vtolftc.firmware_sim.autopilot.nav_loiter import Loiter
from vtolftc.firmware_sim.autopilot.nav_rtl import Rtl
from vtolftc.firmware_sim.autopilot.nav_takeoff import Takeoff

__all__ = ["Mission"]


class Mission(NavigatorMode):
    """AUTO.MISSION (see the module docstring).

    Parameters
    ----------
    navigator
        the navigator's state (the mission store, the goal, the mission state).
    takeoff, land, rtl, loiter
        the modes whose flying the mission's items reuse.
    """

    def __init__(self, navigator: NavigatorBase, takeoff: Takeoff, land: Land, rtl: Rtl,
                 loiter: Loiter) -> None:
        super().__init__(navigator)
        self.takeoff = takeoff
        self.land = land
        self.rtl = rtl
        self.loiter = loiter
        self._jump_counts: dict[int, int] = {}

    # ------------------------------------------------------------------ plan and commands
    def on_plan_change(self, plan: int) -> None:
        """A plan was replaced or cleared: a new mission starts afresh."""
        nv = self.navigator
        if plan == RALLY or plan != 0:
            return
        nv.mission_state = MS_NOT_STARTED
        self._jump_counts.clear()
        if nv.nav_mode == NavMode.MISSION:
            nv.goal = None  # restart from the (new) current item

    def on_set_current(self, seq: int) -> None:
        """The current item was set (MISSION_SET_CURRENT): fly from there."""
        nv = self.navigator
        if nv.mission_state == MS_COMPLETE:
            nv.mission_state = MS_NOT_STARTED
        if nv.nav_mode == NavMode.MISSION:
            nv.goal = None

    def start(self) -> CommandResult:
        """Fly the uploaded mission from its current item (from the start once completed).

        DENIED without a mission, TEMPORARILY_REJECTED before the home is known.
        """
        nv = self.navigator
        if not nv.store.mission:
            nv.say("mission rejected: no mission uploaded")
            return CommandResult.DENIED
        if nv.home is None:
            return CommandResult.TEMPORARILY_REJECTED
        if nv.mission_state == MS_COMPLETE:
            nv.store.current = 0
            self._jump_counts.clear()
        nv.nav_mode = NavMode.MISSION
        nv.goal = None
        return CommandResult.ACCEPTED

    def start_at(self, p: list[float]) -> CommandResult:
        """MISSION_START (300): from item param1 (NaN or negative: 0)."""
        nv = self.navigator
        if not nv.store.mission:
            return CommandResult.DENIED
        first = int(p[0]) if math.isfinite(p[0]) and p[0] >= 0 else 0
        if first >= len(nv.store.mission):
            return CommandResult.DENIED
        nv.store.set_current(first)
        nv.mission_state = MS_NOT_STARTED
        return self.start()

    def set_current(self, p: list[float]) -> CommandResult:
        """DO_SET_MISSION_CURRENT (224): item param1."""
        seq = int(p[0]) if math.isfinite(p[0]) else -1
        if not self.navigator.store.set_current(seq):
            return CommandResult.DENIED
        return CommandResult.ACCEPTED

    # ------------------------------------------------------------------ sequencing
    def on_active(self, nav: NavState, yaw: float) -> None:
        """One step of the mission: take the current item, fly it, go on when reached."""
        nv = self.navigator
        items = nv.store.mission
        if not items or nv.mission_state == MS_COMPLETE:
            if nv.ap.modes.mode == FlightMode.FIXED_WING:
                self.loiter.circle(nav)  # hold after the mission
            return
        if nv.goal is None:
            seq = nv.store.current
            if seq >= len(items):
                self.complete()
                return
            nv.goal = nv.goal_of(items[seq])
            nv.phase = ""
            if nv.mission_state != MS_ACTIVE:
                nv.mission_state = MS_ACTIVE
                nv.say(f"mission started at item {seq}")
        g = nv.goal
        if nv.ap.modes.mode == FlightMode.IDLE and g.command not in (NAV_TAKEOFF,
                                                                     NAV_VTOL_TAKEOFF):
            if nv.phase != "auto_takeoff":  # on the ground: take off first (PX4)
                nv.phase = "auto_takeoff"
                self.takeoff.start(nv.param["MIS_TAKEOFF_ALT"].value)
            return
        if nv.phase == "auto_takeoff":
            if nv.ap.modes.mode == FlightMode.TAKEOFF:
                return
            nv.phase = ""
        if self.fly(g, nav, yaw):
            self.item_reached(g)

    def item_reached(self, g: Goal) -> None:
        """Report goal ``g`` reached and make the next item current (DO_JUMP: its target)."""
        nv = self.navigator
        items = nv.store.mission
        seq = g.seq
        nv.reached.append(seq)
        nv.reached_log.append((nv.time_usec, seq))
        if g.command in (NAV_WAYPOINT, NAV_LOITER_TIME) and g.has_position:
            nv.prev_wp = (g.north, g.east)
        nxt = seq + 1
        if g.command == DO_JUMP:
            target, repeats = int(g.params[0]), int(g.params[1])
            done = self._jump_counts.get(seq, 0)
            if repeats < 0 or done < repeats:
                self._jump_counts[seq] = done + 1
                nxt = target
        nv.goal = None
        nv.phase = ""
        if nxt >= len(items):
            self.complete()
        else:
            nv.store.current = nxt

    def complete(self) -> None:
        """The mission is complete (the aircraft holds)."""
        nv = self.navigator
        nv.mission_state = MS_COMPLETE
        nv.goal = None
        nv.say("mission complete")

    def back_transition_next(self, seq: int) -> bool:
        """True when mission item ``seq + 1`` is DO_VTOL_TRANSITION to multicopter."""
        nv = self.navigator
        items = nv.store.mission
        if nv.nav_mode != NavMode.MISSION or not 0 <= seq + 1 < len(items):
            return False
        nxt = items[seq + 1]
        return nxt.command == DO_VTOL_TRANSITION and nxt.param1 == 3.0

    def next_nav_goal(self, seq: int) -> Goal | None:
        """The first item after ``seq`` with a horizontal position, as a goal (None: none)."""
        nv = self.navigator
        for it in nv.store.mission[seq + 1:]:
            g = nv.goal_of(it)
            if g.has_position:
                return g
        return None

    # ------------------------------------------------------------------ flying one item
    def fly(self, g: Goal, nav: NavState, yaw: float) -> bool:
        """Advance goal ``g``; True once it is reached."""
        nv = self.navigator
        pos = (float(nav.pos_ned_m[0]), float(nav.pos_ned_m[1]))
        h = -float(nav.pos_ned_m[2])
        cmd = g.command
        if cmd in (NAV_TAKEOFF, NAV_VTOL_TAKEOFF):
            return self.takeoff.fly_item(g, nav, yaw, pos, h)
        if cmd == DO_VTOL_TRANSITION:
            if g.params[0] == 4.0:
                return self.takeoff.fly_transition_item(nav, yaw, pos,
                                                        self.next_nav_goal(g.seq))
            return self.land.fly_back_transition_item()
        if cmd == DO_CHANGE_SPEED:
            nv.change_speed([g.params[0], g.params[1], g.params[2], g.params[3],
                             math.nan, math.nan, math.nan])
            return True
        if cmd in (DO_JUMP, DO_LAND_START):
            return True
        if cmd == NAV_DELAY:
            if nv.phase == "":
                nv.set_phase("wait")
            return nv.phase_s() >= max(0.0, g.params[0] if math.isfinite(g.params[0])
                                       else 0.0)
        if cmd == NAV_RETURN_TO_LAUNCH:
            return self.rtl.fly_item(nav, yaw, pos, h)
        if cmd in (NAV_LAND, NAV_VTOL_LAND):
            return self.land.fly(g, nav, yaw, pos, h)
        if cmd in (NAV_WAYPOINT, NAV_LOITER_TIME, NAV_LOITER_UNLIM):
            return self.fly_position(g, nav, pos, h)
        return True  # validated plans hold nothing else

    def fly_position(self, g: Goal, nav: NavState, pos: tuple[float, float],
                     h: float) -> bool:
        """NAV_WAYPOINT, NAV_LOITER_TIME, NAV_LOITER_UNLIM from position ``pos`` (north, east
        m) at height ``h`` (m above home); True once reached."""
        nv = self.navigator
        ap = nv.ap
        mode = ap.modes.mode
        tgt = (g.north, g.east) if g.has_position else pos
        if not g.has_position and nv.phase == "":
            g.north, g.east = pos
        if math.isfinite(g.alt):
            nv.set_alt_ref(g.alt)
        d = math.hypot(tgt[0] - pos[0], tgt[1] - pos[1])
        loiter = g.command in (NAV_LOITER_TIME, NAV_LOITER_UNLIM)
        if nv.phase == "":
            nv.set_phase("go")
            a = nv.prev_wp if nv.prev_wp is not None else pos
            if mode != FlightMode.FIXED_WING:
                a = pos
            nv.seg_a = a
            nv.loiter_since = None
        if mode == FlightMode.FIXED_WING:
            if not loiter:
                return self._fw_waypoint(g, nav, pos, h, tgt, d)
            radius = g.params[2] if math.isfinite(g.params[2]) and g.params[2] != 0 \
                else nv.param["NAV_LOITER_RAD"].value
            direction = -1 if radius < 0 else 1
            radius = abs(radius)
            nv.fw_target = ("loiter", tgt, radius, direction)
            on_circle = abs(d - radius) < max(0.25 * radius, 10.0)
            if nv.loiter_since is None and on_circle:
                nv.loiter_since = nv.time_usec
        elif mode in (FlightMode.HOVER, FlightMode.TAKEOFF):
            nv.mc_goto(tgt, nav)
            acc = g.params[1] if (not loiter and math.isfinite(g.params[1])
                                  and g.params[1] > 0) else nv.param["NAV_ACC_RAD"].value
            arrived = d <= acc and (not math.isfinite(g.alt)
                                    or abs(h - g.alt) < nv.param["NAV_MC_ALT_RAD"].value)
            if arrived and nv.loiter_since is None:
                nv.loiter_since = nv.time_usec
            if not loiter:
                hold = g.params[0] if math.isfinite(g.params[0]) and g.params[0] > 0 else 0.0
                return nv.loiter_since is not None and (
                    nv.time_usec - nv.loiter_since) * 1e-6 >= hold
        else:
            return False
        if g.command == NAV_LOITER_TIME and nv.loiter_since is not None:
            t_need = g.params[0] if math.isfinite(g.params[0]) else 0.0
            return (nv.time_usec - nv.loiter_since) * 1e-6 >= t_need
        return False

    def _fw_waypoint(self, g: Goal, nav: NavState, pos: tuple[float, float], h: float,
                     tgt: tuple[float, float], d: float) -> bool:
        """Fixed-wing NAV_WAYPOINT: the L1 segment to ``tgt`` at distance ``d`` [m]; True
        once within the acceptance radius (or past the waypoint) at its altitude."""
        nv = self.navigator
        nv.fw_target = ("segment", nv.seg_a, tgt)
        acc = g.params[1] if math.isfinite(g.params[1]) and g.params[1] > 0 \
            else nv.param["NAV_ACC_RAD"].value
        acc = max(acc, nv.l1.l1_distance)
        if self.back_transition_next(g.seq):
            # the next item brakes to a multicopter: reached where the back
            # transition must start to stop over this waypoint
            acc = self.land.brake_distance(tgt, nav)
        alt_ok = (not math.isfinite(g.alt)
                  or abs(h - g.alt) < nv.param["NAV_FW_ALT_RAD"].value)
        _, along = cross_track(nv.seg_a, tgt, pos)
        seg_len = math.hypot(tgt[0] - nv.seg_a[0], tgt[1] - nv.seg_a[1])
        reached = bool((d <= acc or along >= seg_len) and alt_ok)
        if reached and self.back_transition_next(g.seq):
            nv.bt_hold = tgt
        return reached

"""The navigator: AUTO.MISSION, RTL, takeoff, land, hold/loiter and reposition on top of the
flight modes.

PX4's split: the navigator decides *where* to go (mission items, return, loiter), the
position controllers and the VTOL mode machine (:mod:`.modes`) decide *how*; the attitude
control underneath stays the scheduled FTC of :mod:`.attitude`, untouched. One
:class:`Navigator` per :class:`~vtolftc.firmware_sim.autopilot.autopilot.Autopilot`; the
autopilot calls :meth:`Navigator.update` once per control step (after its mode machine) and
reads the references it leaves:

- multicopter (TAKEOFF, HOVER, LAND): the position-hold target ``setpoints.hold_ne`` (moved as
  a carrot at the cruise speed ``MPC_XY_CRUISE``, or a DO_CHANGE_SPEED ground speed) and
  the altitude reference; the heading is slewed (30 deg/s) to face the next waypoint before a
  front transition, as PX4's mission "align" work item does;
- fixed-wing: :meth:`Navigator.fw_lateral` gives the roll reference of PX4's L1 guidance
  (:mod:`.guidance`: segments between waypoints, loiter circles) and a yaw reference that
  turns at the coordinated rate ``g tan(phi) / V`` and is pulled onto the ground course
  (zero sideslip without wind); :meth:`Navigator.airspeed_setpoint` the airspeed
  (``FW_AIRSPD_TRIM`` or DO_CHANGE_SPEED).

As in PX4 the navigator is split into its modes, one module each, over the shared state of
:mod:`.nav_base` (:class:`~.nav_base.NavigatorBase`, :class:`~.nav_base.Goal`, the NAV
parameters); :class:`Navigator` owns that state, keeps one object per mode and, every step,
lets the mode of its navigation state fly:

- :mod:`.nav_mission`: AUTO.MISSION, the mission's sequencing and its items (waypoints,
  loiters, delays, speed changes, jumps);
- :mod:`.nav_takeoff`: NAV_TAKEOFF, NAV_VTOL_TAKEOFF and DO_VTOL_TRANSITION to fixed-wing
  (climb, align, front transition);
- :mod:`.nav_land`: NAV_LAND, NAV_VTOL_LAND and DO_VTOL_TRANSITION to multicopter (approach,
  back transition at the braking distance of :mod:`.backtrans`, multicopter to the point,
  descent, touchdown);
- :mod:`.nav_rtl`: AUTO.RTL (mode, command 20, item 20, failsafes): climb to
  ``RTL_RETURN_ALT`` above home if lower, return to the nearest of home and the rally points,
  land there;
- :mod:`.nav_loiter`: AUTO.LOITER (hold) and DO_REPOSITION.

Reported PX4 mode (:meth:`Navigator.custom_mode`): AUTO.MISSION and AUTO.RTL while those run
(also on the ground with a mission selected), AUTO.TAKEOFF / AUTO.LAND for the commanded
takeoff and landing, AUTO.LOITER for hold (on the ground too, as PX4 reports Hold; in
fixed-wing that is a loiter circle about the point where it began), POSCTL / ALTCTL when
selected, and POSCTL for fixed-wing flight after a transition commanded outside a mission
(the autopilot then holds course and altitude, PX4's position mode behaviour, not a loiter).
"""

from __future__ import annotations

import math
from collections.abc import Callable
from typing import Any

from vtolftc.firmware_sim.autopilot.guidance import cross_track, roll_for_lateral_accel, wrap_pi
from vtolftc.firmware_sim.autopilot.interface import CommandResult, FlightMode, NavState
from vtolftc.firmware_sim.autopilot.mission import (
    NAV_LAND,
    NAV_RETURN_TO_LAUNCH,
    NAV_VTOL_LAND,
)
from vtolftc.firmware_sim.autopilot.nav_base import (
    MS_ACTIVE,
    MS_COMPLETE,
    MS_PAUSED,
    NAV_PARAMS,
    Goal,
    NavigatorBase,
    NavigatorMode,
    NavMode,
)
from vtolftc.firmware_sim.autopilot.nav_land import Land
from vtolftc.firmware_sim.autopilot.nav_loiter import Loiter
from vtolftc.firmware_sim.autopilot.nav_mission import Mission
from vtolftc.firmware_sim.autopilot.nav_rtl import Rtl
from vtolftc.firmware_sim.autopilot.nav_takeoff import Takeoff
from vtolftc.protocols.generated import constants as mav

__all__ = ["MS_COMPLETE", "NAV_PARAMS", "Goal", "NavMode", "Navigator"]

CMD_NAV_RETURN_TO_LAUNCH = mav.MAV_CMD_NAV_RETURN_TO_LAUNCH
CMD_DO_CHANGE_SPEED = mav.MAV_CMD_DO_CHANGE_SPEED
CMD_DO_REPOSITION = mav.MAV_CMD_DO_REPOSITION
CMD_DO_SET_MISSION_CURRENT = mav.MAV_CMD_DO_SET_MISSION_CURRENT
CMD_MISSION_START = mav.MAV_CMD_MISSION_START


class Navigator(NavigatorBase):
    """Mission, RTL, takeoff, land and loiter (see the module docstring).

    Parameters
    ----------
    ap
        the :class:`~vtolftc.firmware_sim.autopilot.autopilot.Autopilot` it steers (its
        mode machine, references and parameters; not imported here: no import cycle).
    on_text
        ``f(text)`` for events worth a STATUSTEXT.
    """

    def __init__(self, ap: Any, on_text: Callable[[str], None] | None = None) -> None:
        super().__init__(ap)
        self.on_text = on_text or (lambda text: None)
        self.takeoff = Takeoff(self)
        self.land = Land(self)
        self.loiter = Loiter(self)
        self.rtl = Rtl(self, self.land)
        self.mission = Mission(self, self.takeoff, self.land, self.rtl, self.loiter)
        self._modes: dict[tuple[int, int], NavigatorMode] = {
            NavMode.MISSION: self.mission, NavMode.RTL: self.rtl, NavMode.LOITER: self.loiter,
            NavMode.TAKEOFF: self.takeoff, NavMode.LAND: self.land}
        """the navigator mode flown in each reported PX4 mode (none in ALTCTL / POSCTL)"""
        self._yaw_ref = 0.0
        self._yaw_ref_valid = False
        self._last_mode = FlightMode.IDLE
        self.lateral_accel = 0.0
        """the L1 lateral acceleration of the last fixed-wing step (m/s^2)"""
        self.cross_track_m = math.nan
        """distance from the L1 line or circle at the last fixed-wing step (m)"""

    def on_plan_change(self, plan: int) -> None:
        """``MissionStore`` callback (see :meth:`.nav_mission.Mission.on_plan_change`)."""
        self.mission.on_plan_change(plan)

    def on_set_current(self, seq: int) -> None:
        """``MissionStore`` callback (see :meth:`.nav_mission.Mission.on_set_current`)."""
        self.mission.on_set_current(seq)

    # ------------------------------------------------------------------ reporting
    def custom_mode(self, mode: FlightMode) -> int:
        """PX4 HEARTBEAT custom mode for the flight mode now (see the module docstring)."""
        main, sub = self.px4_mode(mode)
        return (main << 16) | (sub << 24)

    def px4_mode(self, mode: FlightMode) -> tuple[int, int]:
        """PX4 (main, sub) mode reported for flight mode ``mode`` and the navigator's state."""
        if self.nav_mode in (NavMode.MISSION, NavMode.RTL):
            return self.nav_mode
        if mode == FlightMode.TAKEOFF:
            return NavMode.TAKEOFF
        if mode == FlightMode.LAND:
            return NavMode.LAND
        if mode == FlightMode.IDLE:
            return NavMode.LOITER
        return self.nav_mode

    def mission_status(self) -> tuple[int, int]:
        """(MISSION_STATE, MISSION_MODE) for MISSION_CURRENT."""
        in_mission = 1 if self.nav_mode == NavMode.MISSION else 2 if self.mission_state in (
            MS_ACTIVE, MS_PAUSED) else 0
        return self.mission_state, in_mission

    # ------------------------------------------------------------------ commands
    def command(self, cid: int, p: list[float]) -> CommandResult | None:
        """Commands the navigator owns (None: not one of them). ``p``: seven params, NaN =
        default, positions in degrees and altitudes AMSL (the endpoint converts COMMAND_INT
        and relative frames)."""
        if cid == mav.MAV_CMD_DO_SET_MODE:
            return self._set_mode(p)
        if cid == CMD_NAV_RETURN_TO_LAUNCH:
            return self.start_rtl("RTL commanded")
        if cid == CMD_MISSION_START:
            return self.mission.start_at(p)
        if cid == CMD_DO_SET_MISSION_CURRENT:
            return self.mission.set_current(p)
        if cid == CMD_DO_CHANGE_SPEED:
            return self.change_speed(p)
        if cid == CMD_DO_REPOSITION:
            return self.loiter.reposition(p)
        if cid in (mav.MAV_CMD_NAV_LAND, mav.MAV_CMD_NAV_TAKEOFF, mav.MAV_CMD_DO_VTOL_TRANSITION):
            # land, takeoff, transition: the autopilot flies them
            if cid == mav.MAV_CMD_NAV_TAKEOFF:
                self.leave_auto(NavMode.TAKEOFF)
            elif cid == mav.MAV_CMD_NAV_LAND:
                self.leave_auto(NavMode.LAND)
            elif cid == mav.MAV_CMD_DO_VTOL_TRANSITION and self.nav_mode in (
                    NavMode.MISSION, NavMode.RTL, NavMode.LOITER, NavMode.TAKEOFF):
                # a transition outside the navigator's plan: course and altitude hold
                self.leave_auto(NavMode.POSCTL)
            return None
        return None

    def _set_mode(self, p: list[float]) -> CommandResult | None:
        """DO_SET_MODE with PX4 custom modes (param2 main, param3 sub); None: the autopilot
        completes it (its hold, takeoff or landing)."""
        if not (math.isfinite(p[0]) and int(p[0]) & 1 and math.isfinite(p[1])):
            return CommandResult.DENIED
        main = int(p[1])
        sub = int(p[2]) if math.isfinite(p[2]) else 0
        if main == 4 and sub == 4:
            return self.start_mission()
        if main == 4 and sub == 5:
            return self.start_rtl("RTL commanded")
        if main == 4 and sub == 3:
            self.loiter.enter_hold()
            return None  # the autopilot's hold (ends a takeoff or landing)
        if main in (2, 3):
            self.leave_auto(NavMode.ALTCTL if main == 2 else NavMode.POSCTL)
            return None  # the autopilot's own hold handling
        if main == 4 and sub in (2, 6):
            self.leave_auto(NavMode.TAKEOFF if sub == 2 else NavMode.LAND)
            return None
        return CommandResult.DENIED

    def start_mission(self) -> CommandResult:
        """AUTO.MISSION from the current item (see :meth:`.nav_mission.Mission.start`)."""
        return self.mission.start()

    def start_rtl(self, why: str) -> CommandResult:
        """AUTO.RTL, ``why`` told to the ground station (see :meth:`.nav_rtl.Rtl.start`)."""
        return self.rtl.start(why)

    # ------------------------------------------------------------------ the step
    def update(self, nav: NavState, yaw: float) -> None:
        """Once per control step, after the mode machine: the mode of the navigation state
        flies (``nav`` the navigation solution, ``yaw`` the measured heading [rad])."""
        m = self.ap.modes
        mode = m.mode
        self.time_usec = int(nav.time_usec)
        if mode != self._last_mode:
            self.land.measure_back_transition(self._last_mode, mode, nav)
            self._on_mode_change(self._last_mode, mode, yaw)
            self._last_mode = mode
        self.fw_target = None
        g = self.goal
        if (mode == FlightMode.IDLE and self.nav_mode == NavMode.MISSION and g is not None
                and g.command in (NAV_LAND, NAV_VTOL_LAND, NAV_RETURN_TO_LAUNCH)
                and self.phase in ("descend", "reposition", "back_transition")):
            self.mission.item_reached(g)  # touchdown: the autopilot has disarmed
        if not m.armed:
            return
        active = self._modes.get(self.nav_mode)
        if active is not None:
            active.on_active(nav, yaw)

    def _on_mode_change(self, old: FlightMode, new: FlightMode, yaw: float) -> None:
        if new == FlightMode.FIXED_WING:
            self._yaw_ref = yaw
            self._yaw_ref_valid = True
        if new == FlightMode.HOVER and old == FlightMode.TAKEOFF \
                and self.nav_mode == NavMode.TAKEOFF:
            self.nav_mode = NavMode.LOITER
            self.loiter_center = None
        if new == FlightMode.IDLE:
            if self.nav_mode == NavMode.RTL:
                self.say("RTL complete: landed")
            if self.nav_mode != NavMode.MISSION:
                self.nav_mode = NavMode.LOITER
                self.goal = None
            self.airspeed_sp = math.nan
            self.mc_speed = math.nan
        if (old == FlightMode.FRONT_TRANSITION and new == FlightMode.HOVER
                and self.nav_mode in (NavMode.MISSION, NavMode.RTL)):
            # quad-chute: PX4 stops the mission and holds (the failsafe may then return)
            self.say("quad-chute during the transition: mission paused, holding")
            self.loiter.enter_hold()

    # ------------------------------------------------------------------ fixed-wing references
    def airspeed_setpoint(self) -> float:
        """Fixed-wing airspeed setpoint [m/s] (DO_CHANGE_SPEED, else ``FW_AIRSPD_TRIM``)."""
        if math.isfinite(self.airspeed_sp):
            return self.airspeed_sp
        return self.param["FW_AIRSPD_TRIM"].value

    def fw_lateral(self, nav: NavState, roll: float, yaw: float,
                   airspeed: float) -> tuple[float, float] | None:
        """(roll, yaw) references [rad] in fixed-wing, None when the navigator does not steer
        (course and altitude hold of the autopilot)."""
        fw = self.fw_target
        if fw is None:
            self._yaw_ref_valid = False
            self.cross_track_m = math.nan
            return None
        pp = self.param
        self.l1.period = pp["FW_L1_PERIOD"].value
        self.l1.damping = pp["FW_L1_DAMPING"].value
        pos = (float(nav.pos_ned_m[0]), float(nav.pos_ned_m[1]))
        vel = (float(nav.vel_ned_m_s[0]), float(nav.vel_ned_m_s[1]))
        if fw[0] == "segment":
            a_lat = self.l1.segment(fw[1], fw[2], pos, vel)
            self.cross_track_m, _ = cross_track(fw[1], fw[2], pos)
        else:
            a_lat = self.l1.loiter(fw[1], fw[2], fw[3], pos, vel)
            self.cross_track_m = math.hypot(pos[0] - fw[1][0], pos[1] - fw[1][1]) - fw[2]
        self.lateral_accel = a_lat
        g = self.ap.airframe.gravity_m_s2
        roll_ref = roll_for_lateral_accel(a_lat, g, math.radians(pp["FW_R_LIM"].value))
        if not self._yaw_ref_valid:
            self._yaw_ref = yaw
            self._yaw_ref_valid = True
        v = max(airspeed, 5.0)
        course = math.atan2(vel[1], vel[0]) if math.hypot(*vel) > 3.0 else yaw
        r_turn = g * math.tan(roll) / v
        dt = self.ap.dt
        self._yaw_ref = wrap_pi(self._yaw_ref + (r_turn + 0.5 * wrap_pi(course - self._yaw_ref))
                                * dt)
        # yaw reference kept near the measured heading (the rudder coordinates, it does not
        # steer): at most 15 deg ahead
        lim = math.radians(15.0)
        self._yaw_ref = wrap_pi(yaw + min(max(wrap_pi(self._yaw_ref - yaw), -lim), lim))
        self.yaw_hold = self._yaw_ref
        return roll_ref, self._yaw_ref

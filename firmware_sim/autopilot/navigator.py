"""The navigator: AUTO.MISSION, RTL, hold/loiter and reposition on top of the flight modes.

PX4's split: the navigator decides *where* to go (mission items, return, loiter), the
position controllers and the VTOL mode machine (:mod:`.modes`) decide *how*; the attitude
control underneath stays the scheduled FTC of :mod:`.attitude`, untouched. One
:class:`Navigator` per :class:`~vtolftc.firmware_sim.autopilot.autopilot.Autopilot`; the
autopilot calls :meth:`Navigator.update` once per control step (after its mode machine) and
reads the references it leaves:

- multicopter (TAKEOFF, HOVER, LAND): the position-hold target ``Autopilot._hold_ne`` (moved
  as a carrot at the cruise speed ``MPC_XY_CRUISE``, or a DO_CHANGE_SPEED ground speed) and
  the altitude reference; the heading is slewed (30 deg/s) to face the next waypoint before a
  front transition, as PX4's mission "align" work item does;
- fixed-wing: :meth:`fw_lateral` gives the roll reference of PX4's L1 guidance
  (:mod:`.guidance`: segments between waypoints, loiter circles) and a yaw reference that
  turns at the coordinated rate ``g tan(phi) / V`` and is pulled onto the ground course
  (zero sideslip without wind); :meth:`airspeed_setpoint` the airspeed (``FW_AIRSPD_TRIM``
  or DO_CHANGE_SPEED).

Mission items flown (MAV_CMD): NAV_TAKEOFF (22) and NAV_VTOL_TAKEOFF (84): multicopter climb
to the item's altitude (AMSL, or relative in the relative frames), VTOL takeoff then aligns
with its target (or the next waypoint) and transitions; DO_VTOL_TRANSITION (3000, param1 4
to fixed-wing, 3 to multicopter; reached when the transition is complete); NAV_WAYPOINT
(16): fixed-wing L1 segment from the previous waypoint, reached within ``max(param2 or
NAV_ACC_RAD, L1 distance)`` as PX4's fixed-wing acceptance (at the braking distance when the
next item is DO_VTOL_TRANSITION to multicopter, which then holds over the waypoint);
multicopter: within param2 or ``NAV_ACC_RAD`` horizontally and ``NAV_MC_ALT_RAD``
vertically, then param1 seconds of hold; NAV_LOITER_TIME (19) / NAV_LOITER_UNLIM (17):
circle of param3 (0: ``NAV_LOITER_RAD``, sign = direction: positive clockwise) in
fixed-wing, position hold in multicopter, the time counted from reaching the circle;
NAV_DELAY (93); DO_CHANGE_SPEED (178, param2 m/s, -1 no change); DO_JUMP (177, param1
target, param2 repeats); DO_LAND_START (189, a marker); NAV_RETURN_TO_LAUNCH (20); NAV_LAND
(21) and NAV_VTOL_LAND (85): in fixed-wing an approach on the line to the land point, the
back transition started at the braking distance before it (:mod:`.backtrans`: from the
ground speed towards the point, the deceleration expected, ``VT_B_DEC_MSS``, then measured
in flight, and the multicopter's stop), then multicopter to the point (no faster than it can
stop), descent (``MPC_LAND_SPEED``), touchdown detection and disarm (the autopilot's).
Latitude and longitude 0 of a land item: land where it is.

RTL (mode AUTO.RTL, command NAV_RETURN_TO_LAUNCH 20, item 20, or a failsafe): climb to
``RTL_RETURN_ALT`` above home if lower, return to the nearest of home and the rally points,
in fixed-wing with the VTOL landing above; in multicopter at the cruise speed.

Reported PX4 mode (:meth:`custom_mode`): AUTO.MISSION and AUTO.RTL while those run (also on
the ground with a mission selected), AUTO.TAKEOFF / AUTO.LAND for the commanded takeoff and
landing, AUTO.LOITER for hold (on the ground too, as PX4 reports Hold; in fixed-wing that is
a loiter circle about the point where it began), POSCTL / ALTCTL when selected, and POSCTL
for fixed-wing flight after a transition commanded outside a mission (the autopilot then
holds course and altitude, PX4's position mode behaviour, not a loiter).
"""

from __future__ import annotations

import math
from collections.abc import Callable
from dataclasses import dataclass
from typing import Any

from vtolftc.firmware_sim.autopilot.backtrans import BackTransitionPlanner
from vtolftc.firmware_sim.autopilot.guidance import L1Guidance, roll_for_lateral_accel, wrap_pi
from vtolftc.firmware_sim.autopilot.interface import (
    CommandResult,
    FlightMode,
    NavState,
    ParamType,
)
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
    MissionItem,
    MissionStore,
)
from vtolftc.geodesy import FlatEarth
from vtolftc.protocols.generated import constants as mav

__all__ = ["NAV_PARAMS", "Goal", "NavMode", "Navigator"]

CMD_NAV_RETURN_TO_LAUNCH = mav.MAV_CMD_NAV_RETURN_TO_LAUNCH
CMD_DO_CHANGE_SPEED = mav.MAV_CMD_DO_CHANGE_SPEED
CMD_DO_REPOSITION = mav.MAV_CMD_DO_REPOSITION
CMD_DO_SET_MISSION_CURRENT = mav.MAV_CMD_DO_SET_MISSION_CURRENT
CMD_MISSION_START = mav.MAV_CMD_MISSION_START


class NavMode:
    """PX4 (main, sub) custom modes the navigator reports."""

    ALTCTL = (2, 0)
    POSCTL = (3, 0)
    TAKEOFF = (4, 2)
    LOITER = (4, 3)
    MISSION = (4, 4)
    RTL = (4, 5)
    LAND = (4, 6)


# MISSION_STATE / MISSION_MODE of MISSION_CURRENT
MS_NOT_STARTED, MS_ACTIVE = mav.MISSION_STATE_NOT_STARTED, mav.MISSION_STATE_ACTIVE
MS_PAUSED, MS_COMPLETE = mav.MISSION_STATE_PAUSED, mav.MISSION_STATE_COMPLETE

NAV_PARAMS: tuple[tuple[str, float, ParamType, float, float, str], ...] = (
    ("NAV_ACC_RAD", 2.0, ParamType.REAL32, 0.05, 200.0,
     "multicopter waypoint acceptance radius, m"),
    ("NAV_MC_ALT_RAD", 0.8, ParamType.REAL32, 0.05, 200.0,
     "multicopter waypoint altitude acceptance, m"),
    ("NAV_FW_ALT_RAD", 10.0, ParamType.REAL32, 0.05, 200.0,
     "fixed-wing waypoint altitude acceptance, m"),
    ("NAV_LOITER_RAD", 80.0, ParamType.REAL32, 25.0, 1000.0, "fixed-wing loiter radius, m"),
    ("FW_L1_PERIOD", 20.0, ParamType.REAL32, 7.0, 50.0, "L1 guidance period, s"),
    ("FW_L1_DAMPING", 0.75, ParamType.REAL32, 0.6, 0.9, "L1 guidance damping"),
    ("FW_R_LIM", 30.0, ParamType.REAL32, 20.0, 50.0, "fixed-wing max roll reference, deg"),
    ("FW_AIRSPD_MIN", 14.0, ParamType.REAL32, 10.0, 40.0, "fixed-wing min airspeed, m/s"),
    ("FW_AIRSPD_MAX", 22.0, ParamType.REAL32, 10.0, 40.0, "fixed-wing max airspeed, m/s"),
    ("MPC_XY_CRUISE", 5.0, ParamType.REAL32, 0.5, 20.0, "multicopter mission speed, m/s"),
    ("RTL_RETURN_ALT", 30.0, ParamType.REAL32, 5.0, 500.0, "RTL return altitude above home, m"),
    ("VT_B_DEC_MSS", 0.5, ParamType.REAL32, 0.1, 10.0,
     "expected back-transition deceleration per distance flown (where it starts), m/s^2"),
    ("VT_B_DEC_ADAPT", 0.5, ParamType.REAL32, 0.0, 1.0,
     "weight of each measured back transition in the deceleration estimate (0: parameter)"),
    ("MIS_YAW_ERR", 5.0, ParamType.REAL32, 1.0, 90.0,
     "heading error accepted before a mission front transition, deg"),
)

_YAW_SLEW = math.radians(30.0)  # rad/s, heading slew in multicopter before a transition
_ALIGN_MIN_DIST_M = 50.0


@dataclass
class Goal:
    """One thing to fly: a mission item's command with its position in the local frame."""

    command: int
    seq: int = -1                   # mission item, -1 for RTL/hold goals
    north: float = math.nan         # m from home
    east: float = math.nan
    alt: float = math.nan           # m above home (NaN: keep)
    params: tuple[float, float, float, float] = (math.nan, math.nan, math.nan, math.nan)

    @property
    def has_position(self) -> bool:
        """True when the goal has a horizontal position (north and east finite)."""
        return math.isfinite(self.north) and math.isfinite(self.east)


class Navigator:
    """Mission, RTL, loiter and reposition (see the module docstring).

    Parameters
    ----------
    ap
        the :class:`~vtolftc.firmware_sim.autopilot.autopilot.Autopilot` it steers (its
        mode machine, references and parameters; not imported here: no import cycle).
    on_text
        ``f(text)`` for events worth a STATUSTEXT.
    """

    def __init__(self, ap: Any, on_text: Callable[[str], None] | None = None) -> None:
        self.ap = ap
        self.on_text = on_text or (lambda text: None)
        for name, default, typ, lo, hi, desc in NAV_PARAMS:
            if name not in ap.params:
                ap.params.register(name, default, typ, lo, hi, desc)
        self._p = ap.params._params
        self.store = MissionStore(on_change=self._on_plan_change,
                                  on_set_current=self._on_set_current)
        self.home: tuple[float, float, float] | None = None
        self.nav_mode: tuple[int, int] = NavMode.LOITER
        self.l1 = L1Guidance()
        self.reached: list[int] = []
        """Mission items reached and not yet reported (MISSION_ITEM_REACHED); drained by the
        MAVLink endpoint."""
        self.reached_log: list[tuple[int, int]] = []
        """Every mission item reached as (time_usec, seq)."""
        self.mission_state = MS_NOT_STARTED
        self.goal: Goal | None = None
        self.phase = ""
        self._phase_usec = 0
        self._t = 0
        self._prev_wp: tuple[float, float] | None = None
        self._seg_a: tuple[float, float] = (0.0, 0.0)
        self._fw: tuple | None = None
        self._airspeed_sp = math.nan
        self._mc_speed = math.nan
        self._yaw_ref = 0.0
        self._yaw_ref_valid = False
        self._loiter_center: tuple[float, float] | None = None
        self._loiter_since: int | None = None
        self._jump_counts: dict[int, int] = {}
        self._last_mode = FlightMode.IDLE
        self.lateral_accel = 0.0
        self.cross_track_m = math.nan
        self.backtrans = BackTransitionPlanner(self._p["VT_B_DEC_MSS"].value,
                                               self._p["VT_B_TRANS_ARSP"].value
                                               if "VT_B_TRANS_ARSP" in ap.params else 5.0)
        """where back transitions start (braking distance) and what they achieved"""
        self._bt_hold: tuple[float, float] | None = None

    # ------------------------------------------------------------------ geometry
    def set_home(self, lat_deg: float, lon_deg: float, alt_m: float) -> None:
        """Geodetic origin of the local NED frame (the vehicle's home)."""
        self.home = (float(lat_deg), float(lon_deg), float(alt_m))

    @property
    def home_alt(self) -> float:
        """Home altitude AMSL (m); 0 before the home is set."""
        return self.home[2] if self.home is not None else 0.0

    def to_local(self, lat_deg: float, lon_deg: float) -> tuple[float, float]:
        """(north, east) [m] of a latitude/longitude (the flat-earth projection about home of
        :func:`vtolftc.firmware_sim.autopilot.interface.encode_hil_state`)."""
        if self.home is None:
            raise ValueError("no home position yet")
        return FlatEarth(self.home[0], self.home[1]).to_local(lat_deg, lon_deg)

    def to_global(self, north: float, east: float) -> tuple[float, float]:
        """Inverse of :meth:`to_local` (degrees)."""
        lat0, lon0, _ = self.home if self.home is not None else (0.0, 0.0, 0.0)
        return FlatEarth(lat0, lon0).to_global(north, east)

    def goal_of(self, item: MissionItem) -> Goal:
        """Goal of ``item``: north, east from home (m, local NED) and height above home (m)."""
        g = Goal(item.command, item.seq,
                 params=(item.param1, item.param2, item.param3, item.param4))
        positional = item.command in (NAV_WAYPOINT, NAV_LOITER_TIME, NAV_LOITER_UNLIM,
                                      NAV_TAKEOFF, NAV_VTOL_TAKEOFF, NAV_LAND, NAV_VTOL_LAND)
        if positional and self.home is not None:
            if not (item.x == 0 and item.y == 0):
                g.north, g.east = self.to_local(item.lat_deg, item.lon_deg)
            g.alt = item.altitude_amsl(self.home_alt) - self.home_alt
        return g

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

    def _say(self, text: str) -> None:
        self.ap._note(text)

    # ------------------------------------------------------------------ plan changes
    def _on_plan_change(self, plan: int) -> None:
        if plan == RALLY or plan != 0:
            return
        self.mission_state = MS_NOT_STARTED
        self._jump_counts.clear()
        if self.nav_mode == NavMode.MISSION:
            self.goal = None  # restart from the (new) current item

    def _on_set_current(self, seq: int) -> None:
        if self.mission_state == MS_COMPLETE:
            self.mission_state = MS_NOT_STARTED
        if self.nav_mode == NavMode.MISSION:
            self.goal = None

    # ------------------------------------------------------------------ commands
    def command(self, cid: int, p: list[float]) -> CommandResult | None:
        """Commands the navigator owns (None: not one of them). ``p``: seven params, NaN =
        default, positions in degrees and altitudes AMSL (the endpoint converts COMMAND_INT
        and relative frames)."""
        if cid == mav.MAV_CMD_DO_SET_MODE:
            if not (math.isfinite(p[0]) and int(p[0]) & 1 and math.isfinite(p[1])):
                return CommandResult.DENIED
            main = int(p[1])
            sub = int(p[2]) if math.isfinite(p[2]) else 0
            if main == 4 and sub == 4:
                return self.start_mission()
            if main == 4 and sub == 5:
                return self.start_rtl("RTL commanded")
            if main == 4 and sub == 3:
                self._enter_hold()
                return None  # the autopilot's hold (ends a takeoff or landing)
            if main in (2, 3):
                self._leave_auto(NavMode.ALTCTL if main == 2 else NavMode.POSCTL)
                return None  # the autopilot's own hold handling
            if main == 4 and sub in (2, 6):
                self._leave_auto(NavMode.TAKEOFF if sub == 2 else NavMode.LAND)
                return None
            return CommandResult.DENIED
        if cid == CMD_NAV_RETURN_TO_LAUNCH:
            return self.start_rtl("RTL commanded")
        if cid == CMD_MISSION_START:
            if not self.store.mission:
                return CommandResult.DENIED
            first = int(p[0]) if math.isfinite(p[0]) and p[0] >= 0 else 0
            if first >= len(self.store.mission):
                return CommandResult.DENIED
            self.store.set_current(first)
            self.mission_state = MS_NOT_STARTED
            return self.start_mission()
        if cid == CMD_DO_SET_MISSION_CURRENT:
            seq = int(p[0]) if math.isfinite(p[0]) else -1
            if not self.store.set_current(seq):
                return CommandResult.DENIED
            return CommandResult.ACCEPTED
        if cid == CMD_DO_CHANGE_SPEED:
            return self._change_speed(p)
        if cid == CMD_DO_REPOSITION:
            return self._reposition(p)
        if cid in (mav.MAV_CMD_NAV_LAND, mav.MAV_CMD_NAV_TAKEOFF, mav.MAV_CMD_DO_VTOL_TRANSITION):
            # land, takeoff, transition: the autopilot flies them
            if cid == mav.MAV_CMD_NAV_TAKEOFF:
                self._leave_auto(NavMode.TAKEOFF)
            elif cid == mav.MAV_CMD_NAV_LAND:
                self._leave_auto(NavMode.LAND)
            elif cid == mav.MAV_CMD_DO_VTOL_TRANSITION and self.nav_mode in (
                    NavMode.MISSION, NavMode.RTL, NavMode.LOITER, NavMode.TAKEOFF):
                # a transition outside the navigator's plan: course and altitude hold
                self._leave_auto(NavMode.POSCTL)
            return None
        return None

    def _leave_auto(self, mode: tuple[int, int]) -> None:
        if self.nav_mode == NavMode.MISSION and self.mission_state == MS_ACTIVE:
            self.mission_state = MS_PAUSED
        self.nav_mode = mode
        self.goal = None
        self._fw = None
        self.phase = ""
        self._bt_hold = None

    def _enter_hold(self, why: str = "") -> None:
        self._leave_auto(NavMode.LOITER)
        nav = self.ap._last_nav
        if nav is not None:
            self._loiter_center = (float(nav.pos_ned_m[0]), float(nav.pos_ned_m[1]))
            self.ap._hold_ne[:] = self._loiter_center
        if why:
            self._say(why)

    def _change_speed(self, p: list[float]) -> CommandResult:
        speed = p[1]
        if not math.isfinite(speed) or speed == -1.0:
            return CommandResult.ACCEPTED
        if speed <= 0:
            return CommandResult.DENIED
        if self.ap.modes.mode in (FlightMode.FIXED_WING, FlightMode.FRONT_TRANSITION) or (
                math.isfinite(p[0]) and int(p[0]) in (0, 3)):
            lo, hi = self._p["FW_AIRSPD_MIN"].value, self._p["FW_AIRSPD_MAX"].value
            self._airspeed_sp = min(max(speed, lo), hi)
        else:
            self._mc_speed = min(speed, self._p["MPC_XY_VEL_MAX"].value)
        return CommandResult.ACCEPTED

    def _reposition(self, p: list[float]) -> CommandResult:
        """DO_REPOSITION: go to lat/lon (param5/6 deg, NaN = here) at altitude param7 (AMSL,
        NaN = keep) and hold there (loiter in fixed-wing)."""
        m = self.ap.modes
        if not m.armed or m.mode in (FlightMode.IDLE, FlightMode.TAKEOFF, FlightMode.LAND):
            return CommandResult.DENIED
        nav = self.ap._last_nav
        if nav is None or self.home is None:
            return CommandResult.TEMPORARILY_REJECTED
        n, e = float(nav.pos_ned_m[0]), float(nav.pos_ned_m[1])
        if math.isfinite(p[4]) and math.isfinite(p[5]):
            if not (-90 <= p[4] <= 90 and -180 <= p[5] <= 180):
                return CommandResult.DENIED
            n, e = self.to_local(p[4], p[5])
        self._leave_auto(NavMode.LOITER)
        self._loiter_center = (n, e)
        self.ap._hold_ne[:] = (n, e)
        self.ap._hold_locked = True
        if math.isfinite(p[6]):
            self.ap._alt_ref = p[6] - self.home_alt
        if math.isfinite(p[0]) and p[0] > 0:
            self._mc_speed = p[0]
        return CommandResult.ACCEPTED

    def start_mission(self) -> CommandResult:
        """Fly the uploaded mission from its current item (from the start once completed).

        DENIED without a mission, TEMPORARILY_REJECTED before the home is known.
        """
        if not self.store.mission:
            self._say("mission rejected: no mission uploaded")
            return CommandResult.DENIED
        if self.home is None:
            return CommandResult.TEMPORARILY_REJECTED
        if self.mission_state == MS_COMPLETE:
            self.store.current = 0
            self._jump_counts.clear()
        self.nav_mode = NavMode.MISSION
        self.goal = None
        return CommandResult.ACCEPTED

    def start_rtl(self, why: str) -> CommandResult:
        """Return to launch (``why`` is the reason told to the ground station).

        Flies to the nearest of home and the rally points at ``RTL_RETURN_ALT`` or higher and
        lands there; a running mission is paused. DENIED when disarmed, IDLE or without a home.
        """
        m = self.ap.modes
        if not m.armed or m.mode == FlightMode.IDLE or self.home is None:
            return CommandResult.DENIED
        if self.nav_mode == NavMode.MISSION and self.mission_state == MS_ACTIVE:
            self.mission_state = MS_PAUSED
        self.nav_mode = NavMode.RTL
        n, e = self._rtl_destination()
        rtl_alt = self._p["RTL_RETURN_ALT"].value
        self.goal = Goal(NAV_VTOL_LAND, -1, n, e, max(rtl_alt, self.ap._alt))
        self.phase = ""
        self._say(f"{why}: returning to ({n:.0f}, {e:.0f}) m at {self.goal.alt:.0f} m")
        return CommandResult.ACCEPTED

    def _rtl_destination(self) -> tuple[float, float]:
        """The nearest of home and the rally points (local north, east)."""
        nav = self.ap._last_nav
        here = (0.0, 0.0) if nav is None else (float(nav.pos_ned_m[0]), float(nav.pos_ned_m[1]))
        best, dbest = (0.0, 0.0), math.hypot(*here)
        for it in self.store.plans[RALLY]:
            n, e = self.to_local(it.lat_deg, it.lon_deg)
            d = math.hypot(n - here[0], e - here[1])
            if d < dbest:
                best, dbest = (n, e), d
        return best

    # ------------------------------------------------------------------ the step
    def update(self, nav: NavState, yaw: float) -> None:
        """Once per control step, after the mode machine (see the module docstring)."""
        ap = self.ap
        m = ap.modes
        mode = m.mode
        self._t = int(nav.time_usec)
        if mode != self._last_mode:
            self._measure_back_transition(self._last_mode, mode, nav)
            self._on_mode_change(self._last_mode, mode, yaw)
            self._last_mode = mode
        self._fw = None
        g = self.goal
        if (mode == FlightMode.IDLE and self.nav_mode == NavMode.MISSION and g is not None
                and g.command in (NAV_LAND, NAV_VTOL_LAND, NAV_RETURN_TO_LAUNCH)
                and self.phase in ("descend", "reposition", "back_transition")):
            self._item_reached(g)  # touchdown: the autopilot has disarmed
        if not m.armed:
            return
        if self.nav_mode == NavMode.MISSION:
            self._run_mission(nav, yaw)
        elif self.nav_mode == NavMode.RTL and self.goal is not None:
            if self._fly(self.goal, nav, yaw):
                self.goal = None
        elif self.nav_mode == NavMode.LOITER and mode == FlightMode.FIXED_WING:
            if self._loiter_center is None:
                self._loiter_center = (float(nav.pos_ned_m[0]), float(nav.pos_ned_m[1]))
            self._fw = ("loiter", self._loiter_center, self._p["NAV_LOITER_RAD"].value, 1)
        elif self.nav_mode == NavMode.LOITER and mode == FlightMode.HOVER \
                and self._loiter_center is not None and math.isfinite(self._mc_speed):
            self._mc_goto(self._loiter_center, nav)

    def _measure_back_transition(self, old: FlightMode, new: FlightMode,
                                 nav: NavState) -> None:
        """Start and end of every back transition: the planner measures what it achieved."""
        bt = self.backtrans
        pos = (float(nav.pos_ned_m[0]), float(nav.pos_ned_m[1]))
        vel = (float(nav.vel_ned_m_s[0]), float(nav.vel_ned_m_s[1]))
        if new == FlightMode.BACK_TRANSITION:
            bt.set_params(self._p["VT_B_DEC_MSS"].value, self._p["VT_B_TRANS_ARSP"].value,
                      self._p["VT_B_TRANS_DUR"].value)
            bt.start(self._t, pos, vel, float(nav.airspeed_m_s))
        elif old == FlightMode.BACK_TRANSITION:
            meas = bt.finish(self._t, pos, vel, float(nav.airspeed_m_s),
                             self._p["VT_B_DEC_ADAPT"].value)
            if meas is not None and math.isfinite(meas.decel_m_s2):
                self._say(f"back transition: airspeed {meas.airspeed0_m_s:.1f} -> "
                          f"{meas.airspeed1_m_s:.1f} m/s in {meas.duration_s:.1f} s over "
                          f"{meas.distance_m:.0f} m ({meas.decel_m_s2:.2f} m/s^2); planning "
                          f"with {bt.decel:.2f} m/s^2")

    def _brake_distance(self, tgt: tuple[float, float], nav: NavState) -> float:
        """Metres before ``tgt`` where a back transition must start to stop over it (ground
        speed towards it, the planner's deceleration, see :mod:`.backtrans`)."""
        pos = (float(nav.pos_ned_m[0]), float(nav.pos_ned_m[1]))
        dn, de = tgt[0] - pos[0], tgt[1] - pos[1]
        d = math.hypot(dn, de)
        if d < 1e-6:
            return 0.0
        v_along = (float(nav.vel_ned_m_s[0]) * dn + float(nav.vel_ned_m_s[1]) * de) / d
        bt = self.backtrans
        bt.set_params(self._p["VT_B_DEC_MSS"].value, self._p["VT_B_TRANS_ARSP"].value,
                      self._p["VT_B_TRANS_DUR"].value)
        a_mc = self.ap.airframe.gravity_m_s2 * math.tan(math.radians(
            self._p["MPC_TILTMAX_AIR"].value))
        v_mc = self._mc_speed if math.isfinite(self._mc_speed) else self._p["MPC_XY_CRUISE"].value
        return bt.distance(v_along, float(self.ap._airspeed), a_mc, v_mc)

    def _on_mode_change(self, old: FlightMode, new: FlightMode, yaw: float) -> None:
        if new == FlightMode.FIXED_WING:
            self._yaw_ref = yaw
            self._yaw_ref_valid = True
        if new == FlightMode.HOVER and old == FlightMode.TAKEOFF \
                and self.nav_mode == NavMode.TAKEOFF:
            self.nav_mode = NavMode.LOITER
            self._loiter_center = None
        if new == FlightMode.IDLE:
            if self.nav_mode == NavMode.RTL:
                self._say("RTL complete: landed")
            if self.nav_mode != NavMode.MISSION:
                self.nav_mode = NavMode.LOITER
                self.goal = None
            self._airspeed_sp = math.nan
            self._mc_speed = math.nan
        if (old == FlightMode.FRONT_TRANSITION and new == FlightMode.HOVER
                and self.nav_mode in (NavMode.MISSION, NavMode.RTL)):
            # quad-chute: PX4 stops the mission and holds (the failsafe may then return)
            self._say("quad-chute during the transition: mission paused, holding")
            self._enter_hold()

    # ------------------------------------------------------------------ mission sequencing
    def _run_mission(self, nav: NavState, yaw: float) -> None:
        items = self.store.mission
        if not items or self.mission_state == MS_COMPLETE:
            self._hold_after_mission(nav)
            return
        if self.goal is None:
            seq = self.store.current
            if seq >= len(items):
                self._complete()
                return
            self.goal = self.goal_of(items[seq])
            self.phase = ""
            if self.mission_state != MS_ACTIVE:
                self.mission_state = MS_ACTIVE
                self._say(f"mission started at item {seq}")
        g = self.goal
        if self.ap.modes.mode == FlightMode.IDLE and g.command not in (NAV_TAKEOFF,
                                                                       NAV_VTOL_TAKEOFF):
            if self.phase != "auto_takeoff":  # on the ground: take off first (PX4)
                self.phase = "auto_takeoff"
                self._takeoff(self._p["MIS_TAKEOFF_ALT"].value, nav)
            return
        if self.phase == "auto_takeoff":
            if self.ap.modes.mode == FlightMode.TAKEOFF:
                return
            self.phase = ""
        done = self._fly(g, nav, yaw)
        if done:
            self._item_reached(g)

    def _item_reached(self, g: Goal) -> None:
        items = self.store.mission
        seq = g.seq
        self.reached.append(seq)
        self.reached_log.append((self._t, seq))
        if g.command in (NAV_WAYPOINT, NAV_LOITER_TIME) and g.has_position:
            self._prev_wp = (g.north, g.east)
        nxt = seq + 1
        if g.command == DO_JUMP:
            target, repeats = int(g.params[0]), int(g.params[1])
            done = self._jump_counts.get(seq, 0)
            if repeats < 0 or done < repeats:
                self._jump_counts[seq] = done + 1
                nxt = target
        self.goal = None
        self.phase = ""
        if nxt >= len(items):
            self._complete()
        else:
            self.store.current = nxt

    def _complete(self) -> None:
        self.mission_state = MS_COMPLETE
        self.goal = None
        self._say("mission complete")

    def _hold_after_mission(self, nav: NavState) -> None:
        if self.ap.modes.mode == FlightMode.FIXED_WING:
            if self._loiter_center is None:
                self._loiter_center = (float(nav.pos_ned_m[0]), float(nav.pos_ned_m[1]))
            self._fw = ("loiter", self._loiter_center, self._p["NAV_LOITER_RAD"].value, 1)

    def _back_transition_next(self, seq: int) -> bool:
        """True when mission item ``seq + 1`` is DO_VTOL_TRANSITION to multicopter."""
        items = self.store.mission
        if self.nav_mode != NavMode.MISSION or not 0 <= seq + 1 < len(items):
            return False
        nxt = items[seq + 1]
        return nxt.command == DO_VTOL_TRANSITION and nxt.param1 == 3.0

    def _next_nav_goal(self, seq: int) -> Goal | None:
        for it in self.store.mission[seq + 1:]:
            g = self.goal_of(it)
            if g.has_position:
                return g
        return None

    # ------------------------------------------------------------------ flying one goal
    def _set_phase(self, phase: str) -> None:
        self.phase = phase
        self._phase_usec = self._t

    def _phase_s(self) -> float:
        return (self._t - self._phase_usec) * 1e-6

    def _takeoff(self, alt: float, nav: NavState) -> bool:
        ap = self.ap
        ap._takeoff_alt = alt
        ap._alt_ref = alt
        res = ap.modes.takeoff()
        ap._drain_events()
        return res == CommandResult.ACCEPTED

    def _fly(self, g: Goal, nav: NavState, yaw: float) -> bool:
        """Advance goal ``g``; True once it is reached."""
        ap = self.ap
        m = ap.modes
        mode = m.mode
        pos = (float(nav.pos_ned_m[0]), float(nav.pos_ned_m[1]))
        h = -float(nav.pos_ned_m[2])
        cmd = g.command
        pp = self._p
        if cmd in (NAV_TAKEOFF, NAV_VTOL_TAKEOFF):
            alt = g.alt if math.isfinite(g.alt) else pp["MIS_TAKEOFF_ALT"].value
            if self.phase == "":
                if mode == FlightMode.IDLE:
                    if not self._takeoff(alt, nav):
                        return False
                    self._set_phase("climb")
                    return False
                if mode == FlightMode.FIXED_WING:
                    return True
                ap._alt_ref = alt
                self._set_phase("climb")
            if self.phase == "climb":
                if mode == FlightMode.TAKEOFF:
                    return False
                ap._alt_ref = alt
                if abs(h - alt) > pp["NAV_MC_ALT_RAD"].value:
                    return False
                if cmd == NAV_TAKEOFF:
                    return True
                self._set_phase("align")
            target = (g.north, g.east) if g.has_position and math.hypot(
                g.north - pos[0], g.east - pos[1]) > _ALIGN_MIN_DIST_M else None
            return self._front_transition(g, nav, yaw, target)
        if cmd == DO_VTOL_TRANSITION:
            if g.params[0] == 4.0:
                nxt = self._next_nav_goal(g.seq)
                target = (nxt.north, nxt.east) if nxt is not None and math.hypot(
                    nxt.north - pos[0], nxt.east - pos[1]) > _ALIGN_MIN_DIST_M else None
                if self.phase == "":
                    self._set_phase("align")
                return self._front_transition(g, nav, yaw, target)
            if mode in (FlightMode.HOVER, FlightMode.LAND, FlightMode.IDLE):
                if self._bt_hold is not None and mode == FlightMode.HOVER:
                    # braked for the waypoint before: hold over it (PX4 keeps the
                    # waypoint as the multicopter's position setpoint)
                    ap._hold_ne[0], ap._hold_ne[1] = self._bt_hold
                    ap._hold_locked = True
                self._bt_hold = None
                return True
            if mode in (FlightMode.FIXED_WING, FlightMode.FRONT_TRANSITION):
                m.transition(False)
                ap._drain_events()
            return False
        if cmd == DO_CHANGE_SPEED:
            self._change_speed([g.params[0], g.params[1], g.params[2], g.params[3],
                                math.nan, math.nan, math.nan])
            return True
        if cmd in (DO_JUMP, DO_LAND_START):
            return True
        if cmd == NAV_DELAY:
            if self.phase == "":
                self._set_phase("wait")
            return self._phase_s() >= max(0.0, g.params[0] if math.isfinite(g.params[0])
                                          else 0.0)
        if cmd == NAV_RETURN_TO_LAUNCH:
            if self.phase == "":
                n, e = self._rtl_destination()
                self._rtl_goal = Goal(NAV_VTOL_LAND, -1, n, e,
                                      max(pp["RTL_RETURN_ALT"].value, h))
                self._set_phase("rtl")
            return self._fly_land(self._rtl_goal, nav, yaw, pos, h)
        if cmd in (NAV_LAND, NAV_VTOL_LAND):
            return self._fly_land(g, nav, yaw, pos, h)
        if cmd in (NAV_WAYPOINT, NAV_LOITER_TIME, NAV_LOITER_UNLIM):
            return self._fly_position(g, nav, pos, h)
        return True  # validated plans hold nothing else

    def _front_transition(self, g: Goal, nav: NavState, yaw: float,
                          target: tuple[float, float] | None) -> bool:
        ap = self.ap
        m = ap.modes
        pos = (float(nav.pos_ned_m[0]), float(nav.pos_ned_m[1]))
        if m.mode == FlightMode.FIXED_WING:
            self._seg_a = pos
            self._prev_wp = None
            return True
        if self.phase == "align":
            if m.mode != FlightMode.HOVER:
                return False
            if target is not None:
                want = math.atan2(target[1] - pos[1], target[0] - pos[0])
                err = wrap_pi(want - ap._yaw_hold)
                step = _YAW_SLEW * ap.dt
                ap._yaw_hold = wrap_pi(ap._yaw_hold + min(max(err, -step), step))
                if abs(wrap_pi(want - yaw)) > math.radians(self._p["MIS_YAW_ERR"].value):
                    return False
            self._set_phase("transition")
            m.transition(True)
            ap._drain_events()
        return False

    def _fly_position(self, g: Goal, nav: NavState, pos: tuple[float, float],
                      h: float) -> bool:
        ap = self.ap
        mode = ap.modes.mode
        pp = self._p
        tgt = (g.north, g.east) if g.has_position else pos
        if not g.has_position and self.phase == "":
            g.north, g.east = pos
        if math.isfinite(g.alt):
            ap._alt_ref = g.alt
        d = math.hypot(tgt[0] - pos[0], tgt[1] - pos[1])
        loiter = g.command in (NAV_LOITER_TIME, NAV_LOITER_UNLIM)
        if self.phase == "":
            self._set_phase("go")
            a = self._prev_wp if self._prev_wp is not None else pos
            if mode != FlightMode.FIXED_WING:
                a = pos
            self._seg_a = a
            self._loiter_since = None
        if mode == FlightMode.FIXED_WING:
            if loiter:
                radius = g.params[2] if math.isfinite(g.params[2]) and g.params[2] != 0 \
                    else pp["NAV_LOITER_RAD"].value
                direction = -1 if radius < 0 else 1
                radius = abs(radius)
                self._fw = ("loiter", tgt, radius, direction)
                on_circle = abs(d - radius) < max(0.25 * radius, 10.0)
                if self._loiter_since is None and on_circle:
                    self._loiter_since = self._t
            else:
                self._fw = ("segment", self._seg_a, tgt)
                acc = g.params[1] if math.isfinite(g.params[1]) and g.params[1] > 0 \
                    else pp["NAV_ACC_RAD"].value
                acc = max(acc, self.l1.l1_distance)
                if self._back_transition_next(g.seq):
                    # the next item brakes to a multicopter: reached where the back
                    # transition must start to stop over this waypoint
                    acc = self._brake_distance(tgt, nav)
                alt_ok = (not math.isfinite(g.alt)
                          or abs(h - g.alt) < pp["NAV_FW_ALT_RAD"].value)
                _, along = _along(self._seg_a, tgt, pos)
                seg_len = math.hypot(tgt[0] - self._seg_a[0], tgt[1] - self._seg_a[1])
                reached = bool((d <= acc or along >= seg_len) and alt_ok)
                if reached and self._back_transition_next(g.seq):
                    self._bt_hold = tgt
                return reached
        elif mode in (FlightMode.HOVER, FlightMode.TAKEOFF):
            self._mc_goto(tgt, nav)
            acc = g.params[1] if (not loiter and math.isfinite(g.params[1])
                                  and g.params[1] > 0) else pp["NAV_ACC_RAD"].value
            arrived = d <= acc and (not math.isfinite(g.alt)
                                    or abs(h - g.alt) < pp["NAV_MC_ALT_RAD"].value)
            if arrived and self._loiter_since is None:
                self._loiter_since = self._t
            if not loiter:
                hold = g.params[0] if math.isfinite(g.params[0]) and g.params[0] > 0 else 0.0
                return self._loiter_since is not None and (
                    self._t - self._loiter_since) * 1e-6 >= hold
        else:
            return False
        if g.command == NAV_LOITER_TIME and self._loiter_since is not None:
            t_need = g.params[0] if math.isfinite(g.params[0]) else 0.0
            return (self._t - self._loiter_since) * 1e-6 >= t_need
        return False

    def _mc_goto(self, tgt: tuple[float, float], nav: NavState) -> None:
        """Multicopter: move the position-hold target as a carrot towards ``tgt``."""
        ap = self.ap
        pos = (float(nav.pos_ned_m[0]), float(nav.pos_ned_m[1]))
        dx, dy = tgt[0] - pos[0], tgt[1] - pos[1]
        d = math.hypot(dx, dy)
        v = self._mc_speed if math.isfinite(self._mc_speed) else self._p["MPC_XY_CRUISE"].value
        # no faster than it can stop at half its largest deceleration (tilt-limited): the
        # position loop alone (speed MPC_XY_P d) asks for more near the target and overshoots
        a_stop = 0.5 * ap.airframe.gravity_m_s2 * math.tan(math.radians(
            self._p["MPC_TILTMAX_AIR"].value))
        v = min(v, math.sqrt(2.0 * a_stop * d))
        lead = v / max(self._p["MPC_XY_P"].value, 1e-3)
        if d > lead:
            ap._hold_ne[0] = pos[0] + dx / d * lead
            ap._hold_ne[1] = pos[1] + dy / d * lead
        else:
            ap._hold_ne[0], ap._hold_ne[1] = tgt
        ap._hold_locked = True

    def _fly_land(self, g: Goal, nav: NavState, yaw: float, pos: tuple[float, float],
                  h: float) -> bool:
        """Fixed-wing approach, back transition at the braking distance, multicopter to the
        land point, descent, touchdown (the autopilot disarms)."""
        ap = self.ap
        m = ap.modes
        mode = m.mode
        pp = self._p
        if not g.has_position:
            g.north, g.east = pos
        tgt = (g.north, g.east)
        d = math.hypot(tgt[0] - pos[0], tgt[1] - pos[1])
        if self.phase in ("", "rtl"):
            self._set_phase("approach")
            self._seg_a = self._prev_wp if (self._prev_wp is not None
                                            and mode == FlightMode.FIXED_WING) else pos
        if mode == FlightMode.IDLE:
            return self.phase in ("descend", "reposition")
        if self.phase == "approach":
            if math.isfinite(g.alt) and g.seq < 0:
                # RTL: the return altitude; a land item's altitude is the ground's: the
                # approach and back transition stay at the current altitude (PX4)
                ap._alt_ref = g.alt
            if mode == FlightMode.FIXED_WING:
                self._fw = ("segment", self._seg_a, tgt)
                if d <= self._brake_distance(tgt, nav):
                    m.transition(False)
                    ap._drain_events()
                    self._set_phase("back_transition")
                return False
            if mode == FlightMode.FRONT_TRANSITION:
                m.transition(False)
                ap._drain_events()
                self._set_phase("back_transition")
                return False
            if mode == FlightMode.BACK_TRANSITION:
                self._set_phase("back_transition")
                return False
            self._set_phase("reposition")
        if self.phase == "back_transition":
            if mode in (FlightMode.HOVER, FlightMode.LAND):
                self._set_phase("reposition")
            else:
                return False
        if self.phase == "reposition":
            if mode == FlightMode.LAND:
                self._set_phase("descend")
                return False
            if mode != FlightMode.HOVER:
                return False
            if math.isfinite(g.alt) and g.seq < 0:
                ap._alt_ref = g.alt
            self._mc_goto(tgt, nav)
            v = math.hypot(float(nav.vel_ned_m_s[0]), float(nav.vel_ned_m_s[1]))
            if d < max(1.0, 0.5 * pp["NAV_ACC_RAD"].value) and v < 0.5:
                m.land()
                ap._drain_events()
                self._set_phase("descend")
            return False
        if self.phase == "descend":
            ap._hold_ne[0], ap._hold_ne[1] = tgt
            ap._hold_locked = True
            return False
        return False

    # ------------------------------------------------------------------ fixed-wing references
    def airspeed_setpoint(self) -> float:
        """Fixed-wing airspeed setpoint [m/s] (DO_CHANGE_SPEED, else ``FW_AIRSPD_TRIM``)."""
        if math.isfinite(self._airspeed_sp):
            return self._airspeed_sp
        return self._p["FW_AIRSPD_TRIM"].value

    def fw_lateral(self, nav: NavState, roll: float, yaw: float,
                   airspeed: float) -> tuple[float, float] | None:
        """(roll, yaw) references [rad] in fixed-wing, None when the navigator does not steer
        (course and altitude hold of the autopilot)."""
        fw = self._fw
        if fw is None:
            self._yaw_ref_valid = False
            self.cross_track_m = math.nan
            return None
        pp = self._p
        self.l1.period = pp["FW_L1_PERIOD"].value
        self.l1.damping = pp["FW_L1_DAMPING"].value
        pos = (float(nav.pos_ned_m[0]), float(nav.pos_ned_m[1]))
        vel = (float(nav.vel_ned_m_s[0]), float(nav.vel_ned_m_s[1]))
        if fw[0] == "segment":
            a_lat = self.l1.segment(fw[1], fw[2], pos, vel)
            self.cross_track_m, _ = _along(fw[1], fw[2], pos)
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
        self.ap._yaw_hold = self._yaw_ref
        return roll_ref, self._yaw_ref


def _along(a: tuple[float, float], b: tuple[float, float],
           p: tuple[float, float]) -> tuple[float, float]:
    from vtolftc.firmware_sim.autopilot.guidance import cross_track

    return cross_track(a, b, p)

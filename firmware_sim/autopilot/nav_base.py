"""What the navigator's modes share: the navigator's state, its goals and its parameters.

PX4's navigator is one ``Navigator`` owning the vehicle's navigation state and a set of
``NavigatorMode`` objects (mission, RTL, takeoff, land, loiter) that it activates by the
vehicle's navigation state. Here :class:`NavigatorBase` is that state (home, the goal being
flown and its phase, the fixed-wing target, the multicopter carrot, the parameters) with the
few actions every mode needs (projection about home, the multicopter carrot, leaving an
automatic mode); :class:`NavigatorMode` is the base of the modes in ``nav_*.py``, and
:class:`~vtolftc.firmware_sim.autopilot.navigator.Navigator` adds the modes and dispatches.

Units and frames: positions north, east [m] from home (local NED), altitudes [m] above home,
times in microseconds of simulated time, angles in radians.
"""

from __future__ import annotations

import math
from dataclasses import dataclass
from typing import Any

from vtolftc.base.geodesy import FlatEarth
from vtolftc.firmware_sim.autopilot.backtrans import BackTransitionPlanner
from vtolftc.firmware_sim.autopilot.guidance import L1Guidance
from vtolftc.firmware_sim.autopilot.interface import (
    CommandResult,
    FlightMode,
    NavState,
    Parameter,
    ParamType,
)
from vtolftc.firmware_sim.autopilot.mission import (
    NAV_LAND,
    NAV_LOITER_TIME,
    NAV_LOITER_UNLIM,
    NAV_TAKEOFF,
    NAV_VTOL_LAND,
    NAV_VTOL_TAKEOFF,
    NAV_WAYPOINT,
    MissionItem,
    MissionStore,
)
from vtolftc.protocols.generated import constants as mav

__all__ = ["MS_ACTIVE", "MS_COMPLETE", "MS_NOT_STARTED", "MS_PAUSED", "NAV_PARAMS", "Goal",
           "NavMode", "NavigatorBase", "NavigatorMode"]


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
    ("FW_AIRSPD_MIN", 14.0, ParamType.REAL32, 0.5, 60.0, "fixed-wing min airspeed, m/s"),
    ("FW_AIRSPD_MAX", 22.0, ParamType.REAL32, 0.5, 60.0, "fixed-wing max airspeed, m/s"),
    ("MPC_XY_CRUISE", 5.0, ParamType.REAL32, 0.5, 20.0, "multicopter mission speed, m/s"),
    ("RTL_RETURN_ALT", 30.0, ParamType.REAL32, 5.0, 500.0, "RTL return altitude above home, m"),
    ("VT_B_DEC_MSS", 0.5, ParamType.REAL32, 0.1, 10.0,
     "expected back-transition deceleration per distance flown (where it starts), m/s^2"),
    ("VT_B_DEC_ADAPT", 0.5, ParamType.REAL32, 0.0, 1.0,
     "weight of each measured back transition in the deceleration estimate (0: parameter)"),
    ("MIS_YAW_ERR", 5.0, ParamType.REAL32, 1.0, 90.0,
     "heading error accepted before a mission front transition, deg"),
)

_POSITIONAL = (NAV_WAYPOINT, NAV_LOITER_TIME, NAV_LOITER_UNLIM, NAV_TAKEOFF, NAV_VTOL_TAKEOFF,
               NAV_LAND, NAV_VTOL_LAND)


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


def horizontal(nav: NavState) -> tuple[tuple[float, float], float]:
    """((north, east) [m], height above home [m]) of the navigation solution ``nav``."""
    return (float(nav.pos_ned_m[0]), float(nav.pos_ned_m[1])), -float(nav.pos_ned_m[2])


class NavigatorBase:
    """The navigator's state and the actions its modes share (see the module docstring).

    Parameters
    ----------
    ap
        the :class:`~vtolftc.firmware_sim.autopilot.autopilot.Autopilot` it steers (its
        mode machine, references and parameters; not imported here: no import cycle). The
        :data:`NAV_PARAMS` it lacks are registered in its parameter store.

    Attributes
    ----------
    param : dict[str, Parameter]
        the autopilot's parameters by name (read each step: a PARAM_SET acts at once).
    goal : Goal or None
        what is being flown (a mission item, the RTL landing), None for none.
    phase : str
        the goal's phase ("", "climb", "align", "transition", "go", "approach",
        "back_transition", "reposition", "descend", "wait", "rtl", "auto_takeoff").
    fw_target : tuple or None
        the fixed-wing lateral target of this step: ``("segment", a, b)`` (L1 line from a to
        b, local north/east m) or ``("loiter", centre, radius_m, direction)``; None: the
        autopilot's course and altitude hold.
    """

    def __init__(self, ap: Any) -> None:
        self.ap = ap
        for name, default, typ, lo, hi, desc in NAV_PARAMS:
            if name not in ap.params:
                ap.params.register(name, default, typ, lo, hi, desc)
        self.param: dict[str, Parameter] = ap.params.view()  # live: later PARAM_SETs act
        self.store = MissionStore(on_change=self.on_plan_change,
                                  on_set_current=self.on_set_current)
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
        self.phase_usec = 0
        self.time_usec = 0
        """simulated time of the step being flown (µs)"""
        self.prev_wp: tuple[float, float] | None = None
        """the last fixed-wing waypoint reached (start of the next L1 segment)"""
        self.seg_a: tuple[float, float] = (0.0, 0.0)
        self.fw_target: tuple | None = None
        self.airspeed_sp = math.nan
        """fixed-wing airspeed of DO_CHANGE_SPEED (m/s; NaN: FW_AIRSPD_TRIM)"""
        self.mc_speed = math.nan
        """multicopter speed of DO_CHANGE_SPEED or DO_REPOSITION (m/s; NaN: MPC_XY_CRUISE)"""
        self.loiter_center: tuple[float, float] | None = None
        self.loiter_since: int | None = None
        """time (µs) the loiter point or circle was reached, None before"""
        self.backtrans = BackTransitionPlanner(self.param["VT_B_DEC_MSS"].value,
                                               self.param["VT_B_TRANS_ARSP"].value
                                               if "VT_B_TRANS_ARSP" in ap.params else 5.0)
        """where back transitions start (braking distance) and what they achieved"""
        self.bt_hold: tuple[float, float] | None = None
        """the waypoint a back transition brakes for (held over once in multicopter)"""

    def on_plan_change(self, plan: int) -> None:
        """``MissionStore`` callback: a plan was replaced or cleared (the mission's)."""

    def on_set_current(self, seq: int) -> None:
        """``MissionStore`` callback: the current mission item was set to ``seq``."""

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
        if item.command in _POSITIONAL and self.home is not None:
            if not (item.x == 0 and item.y == 0):
                g.north, g.east = self.to_local(item.lat_deg, item.lon_deg)
            g.alt = item.altitude_amsl(self.home_alt) - self.home_alt
        return g

    # ------------------------------------------------------------------ the autopilot steered
    # The one place the navigator reads and sets the autopilot's own state (its references,
    # measurements and event queue): the modes use these.
    @property
    def last_nav(self) -> NavState | None:
        """The autopilot's latest navigation solution (None before the first)."""
        return self.ap.estimate.last_nav

    @property
    def altitude_m(self) -> float:
        """The autopilot's measured height above home [m]."""
        return self.ap.estimate.alt

    @property
    def airspeed_m_s(self) -> float:
        """The autopilot's measured airspeed [m/s]."""
        return self.ap.estimate.airspeed

    @property
    def yaw_hold(self) -> float:
        """The autopilot's heading reference in multicopter and fixed-wing hold [rad]."""
        return self.ap.setpoints.yaw_hold

    @yaw_hold.setter
    def yaw_hold(self, yaw: float) -> None:
        self.ap.setpoints.yaw_hold = yaw

    def set_alt_ref(self, alt: float) -> None:
        """The autopilot's altitude reference [m above home]."""
        self.ap.setpoints.alt_ref = alt

    def set_takeoff_alt(self, alt: float) -> None:
        """The altitude [m above home] the mode machine's next takeoff climbs to (and the
        altitude reference)."""
        self.ap.setpoints.takeoff_alt = alt
        self.ap.setpoints.alt_ref = alt

    def drain_events(self) -> None:
        """Let the autopilot log and act on the mode machine's events now (after a command
        to it: takeoff, transition, land)."""
        self.ap.commander.drain_events()

    def say(self, text: str) -> None:
        """An event worth a STATUSTEXT (the autopilot's event log)."""
        self.ap.commander.note(text)

    # ------------------------------------------------------------------ shared actions

    def set_phase(self, phase: str) -> None:
        """Enter ``phase`` of the goal now (its clock restarts)."""
        self.phase = phase
        self.phase_usec = self.time_usec

    def phase_s(self) -> float:
        """Seconds spent in the current phase."""
        return (self.time_usec - self.phase_usec) * 1e-6

    def leave_auto(self, mode: tuple[int, int]) -> None:
        """Report PX4 mode ``mode`` and fly no goal (a running mission is paused)."""
        if self.nav_mode == NavMode.MISSION and self.mission_state == MS_ACTIVE:
            self.mission_state = MS_PAUSED
        self.nav_mode = mode
        self.goal = None
        self.fw_target = None
        self.phase = ""
        self.bt_hold = None

    def change_speed(self, p: list[float]) -> CommandResult:
        """DO_CHANGE_SPEED (command or item): param1 speed type, param2 speed [m/s] (-1 or
        NaN: no change); fixed-wing airspeed clamped to FW_AIRSPD_MIN..MAX, multicopter speed
        to MPC_XY_VEL_MAX."""
        speed = p[1]
        if not math.isfinite(speed) or speed == -1.0:
            return CommandResult.ACCEPTED
        if speed <= 0:
            return CommandResult.DENIED
        if self.ap.modes.mode in (FlightMode.FIXED_WING, FlightMode.FRONT_TRANSITION) or (
                math.isfinite(p[0]) and int(p[0]) in (0, 3)):
            lo, hi = self.param["FW_AIRSPD_MIN"].value, self.param["FW_AIRSPD_MAX"].value
            self.airspeed_sp = min(max(speed, lo), hi)
        else:
            self.mc_speed = min(speed, self.param["MPC_XY_VEL_MAX"].value)
        return CommandResult.ACCEPTED

    def mc_goto(self, tgt: tuple[float, float], nav: NavState) -> None:
        """Multicopter: move the position-hold target as a carrot towards ``tgt`` (north,
        east m), leading by speed / ``MPC_XY_P``."""
        ap = self.ap
        pos = (float(nav.pos_ned_m[0]), float(nav.pos_ned_m[1]))
        dx, dy = tgt[0] - pos[0], tgt[1] - pos[1]
        d = math.hypot(dx, dy)
        v = self.mc_speed if math.isfinite(self.mc_speed) else self.param["MPC_XY_CRUISE"].value
        # no faster than it can stop at half its largest deceleration (tilt-limited): the
        # position loop alone (speed MPC_XY_P d) asks for more near the target and overshoots
        a_stop = 0.5 * ap.airframe.gravity_m_s2 * math.tan(math.radians(
            self.param["MPC_TILTMAX_AIR"].value))
        v = min(v, math.sqrt(2.0 * a_stop * d))
        lead = v / max(self.param["MPC_XY_P"].value, 1e-3)
        if d > lead:
            ap.setpoints.hold_ne[0] = pos[0] + dx / d * lead
            ap.setpoints.hold_ne[1] = pos[1] + dy / d * lead
        else:
            ap.setpoints.hold_ne[0], ap.setpoints.hold_ne[1] = tgt
        ap.setpoints.hold_locked = True

    def hold_at(self, tgt: tuple[float, float], lock: bool = True) -> None:
        """Multicopter: hold position over ``tgt`` (north, east m) from now; ``lock`` False
        leaves the autopilot free to re-centre the hold when it stops (AUTO.LOITER)."""
        self.ap.setpoints.hold_ne[0], self.ap.setpoints.hold_ne[1] = tgt
        if lock:
            self.ap.setpoints.hold_locked = True


class NavigatorMode:
    """One mode of the navigator (PX4's ``NavigatorMode``).

    The navigator calls :meth:`on_active` at every control step (armed) while the mode is
    its navigation state; a mode that can be refused is entered by its own ``start``. All
    state shared between modes lives in the :class:`NavigatorBase` given, a mode keeps only
    its own.
    """

    def __init__(self, navigator: NavigatorBase) -> None:
        self.navigator = navigator

    def on_active(self, nav: NavState, yaw: float) -> None:
        """One control step in the mode: ``nav`` the navigation solution, ``yaw`` [rad]
        (nothing by default: the autopilot's mode machine flies it)."""

"""The autopilot's mode and command logic (PX4's commander, in small).

MAVLink commands (arm, takeoff, transitions, land, set mode; the navigator's own commands go
to it first), the mode machine's automatic transitions each step (with landing detection in
LAND), what entering a mode sets (position hold, altitude reference, loop resets), the
auto-disarm on the ground, the low-battery failsafe and the event log (mode changes, arming,
quad-chute, degraded lift ... as ``(time_usec, text)``). The transition timeout's quad-chute
is held off while the degraded-lift guidance judges hover not recoverable
(:mod:`.degraded_lift`).
"""

from __future__ import annotations

import math
from collections.abc import Callable, Sequence
from typing import Any

from vtolftc.base.rotation import quat_to_euler
from vtolftc.firmware_sim.autopilot.arming import ArmingMonitor
from vtolftc.firmware_sim.autopilot.estimate import StateEstimate
from vtolftc.firmware_sim.autopilot.interface import (
    CommandResult,
    FlightMode,
    NavState,
    ParameterStore,
)
from vtolftc.firmware_sim.autopilot.modes import AUTO_EXIT_MODES, ModeMachine
from vtolftc.firmware_sim.autopilot.navigator import MS_COMPLETE, NavMode
from vtolftc.firmware_sim.autopilot.outer_loops import OuterLoops
from vtolftc.firmware_sim.autopilot.setpoints import Setpoints
from vtolftc.protocols.generated import constants as mav

__all__ = [
    "CMD_COMPONENT_ARM_DISARM",
    "CMD_DO_SET_MODE",
    "CMD_DO_VTOL_TRANSITION",
    "CMD_NAV_LAND",
    "CMD_NAV_TAKEOFF",
    "FORCE_DISARM_MAGIC",
    "TAKEOFF_MIN_HEIGHT_M",
    "Commander",
]

CMD_NAV_LAND = mav.MAV_CMD_NAV_LAND
CMD_NAV_TAKEOFF = mav.MAV_CMD_NAV_TAKEOFF
CMD_DO_SET_MODE = mav.MAV_CMD_DO_SET_MODE
CMD_COMPONENT_ARM_DISARM = mav.MAV_CMD_COMPONENT_ARM_DISARM
CMD_DO_VTOL_TRANSITION = mav.MAV_CMD_DO_VTOL_TRANSITION
FORCE_DISARM_MAGIC = 21196  # PX4's force-disarm magic in param2 (not a MAVLink enum)
MAV_VTOL_STATE_MC = mav.MAV_VTOL_STATE_MC
MAV_VTOL_STATE_FW = mav.MAV_VTOL_STATE_FW
#: NAV_TAKEOFF's param7 giving less than this height above home [m] (below home, e.g. a
#: relative altitude sent where PX4 reads AMSL, as MAVProxy's ``takeoff 30`` does) means
#: the default takeoff altitude ``MIS_TAKEOFF_ALT`` (PX4 raises it to that minimum clearance).
TAKEOFF_MIN_HEIGHT_M = 1.0

_M_LAND = FlightMode.LAND
_M_IDLE = FlightMode.IDLE


class Commander:
    """Commands, mode logic and events (see the module docstring).

    Parameters
    ----------
    modes
        the mode machine.
    params
        the parameter store.
    pp
        its parameters by name (``Parameter`` objects, read every step).
    setpoints
        the shared references (hold position, altitude reference, heading).
    estimate
        the state intake (time, navigation data, ground altitude).
    outer
        the outer loops (their part of a mode entry).
    reset_loops
        resets the attitude controller, the altitude hold and the anti-windup flags.
    dt
        control period [s].

    The ``navigator`` and ``arming`` attributes are set by the autopilot once they exist.
    """

    def __init__(self, modes: ModeMachine, params: ParameterStore, pp: dict[str, Any],
                 setpoints: Setpoints, estimate: StateEstimate, outer: OuterLoops,
                 reset_loops: Callable[[], None], dt: float) -> None:
        self.modes = modes
        self.params = params
        self._p = pp
        self.sp = setpoints
        self.est = estimate
        self.outer = outer
        self.reset_loops = reset_loops
        self.dt = dt
        self.navigator: Any = None
        self.arming: ArmingMonitor | None = None
        self.event_log: list[tuple[int, str]] = []
        self.message = ""
        self.last_mode = modes.mode
        self._landed_timer = 0.0
        self._dl_noted = False  # the degraded-lift guidance's engagement was logged

    # ---- commands ------------------------------------------------------------------------
    def command(self, command_id: int, params: Sequence[float]) -> CommandResult:
        """Handle a MAVLink COMMAND_LONG (id and its seven params, NaN = default).

        COMPONENT_ARM_DISARM 400: param1 1 arm (on the ground, once navigation data came),
        0 disarm (on the ground; in the air only with param2 = 21196). NAV_TAKEOFF 22: param7
        the takeoff altitude AMSL as in PX4 (needs the home position, ``Autopilot.set_home``); NaN,
        or less than :data:`TAKEOFF_MIN_HEIGHT_M` above home: ``MIS_TAKEOFF_ALT`` above home
        (STATUSTEXT "Using minimum takeoff altitude", as PX4); more than 500 m above home:
        DENIED; armed and on the ground only. On the ground the vehicle disarms by itself
        (:mod:`.arming`: ``COM_DISARM_PRFLT`` after arming, ``COM_DISARM_LAND`` after
        landing). DO_VTOL_TRANSITION
        3000: param1 4 = to fixed-wing, 3 = to multicopter (in the air). NAV_LAND 21 (from
        fixed-wing: back transition first).
        DO_SET_MODE 176 with PX4 custom modes (param1 custom flag, param2 main, param3 sub):
        POSCTL/ALTCTL/AUTO.LOITER hold, AUTO.TAKEOFF, AUTO.LAND, AUTO.MISSION, AUTO.RTL.
        The navigator's commands (:meth:`.navigator.Navigator.command`): NAV_RETURN_TO_LAUNCH
        20, DO_CHANGE_SPEED 178, DO_REPOSITION 192, DO_SET_MISSION_CURRENT 224,
        MISSION_START 300. Not allowed now: DENIED; unknown id: UNSUPPORTED.
        """
        p = [float("nan")] * 7
        for i, x in enumerate(list(params)[:7]):
            try:
                p[i] = float(x)
            except (TypeError, ValueError):
                return CommandResult.DENIED
        m = self.modes
        cid = int(command_id)
        nav_res = self.navigator.command(cid, p)
        if nav_res is not None:
            return self._after(nav_res)
        if cid == CMD_COMPONENT_ARM_DISARM:
            if p[0] == 1.0:
                if not self.est.have_nav:
                    self.note("arming denied: no navigation data yet")
                    return CommandResult.DENIED
                res = m.arm()
                if res == CommandResult.ACCEPTED and m.mode == FlightMode.IDLE:
                    self._on_arm()
                return self._after(res)
            if p[0] == 0.0:
                return self._after(m.disarm(force=p[1] == FORCE_DISARM_MAGIC))
            return CommandResult.DENIED
        if cid == CMD_NAV_TAKEOFF:
            return self._takeoff(p[6])
        if cid == CMD_DO_VTOL_TRANSITION:
            if p[0] == MAV_VTOL_STATE_FW:
                return self._after(m.transition(True))
            if p[0] == MAV_VTOL_STATE_MC:
                return self._after(m.transition(False))
            return CommandResult.DENIED
        if cid == CMD_NAV_LAND:
            return self._after(m.land())
        if cid == CMD_DO_SET_MODE:
            return self._after(self._set_mode(p))
        return CommandResult.UNSUPPORTED

    def _takeoff(self, alt_amsl: float) -> CommandResult:
        """NAV_TAKEOFF to ``alt_amsl`` (param7, m AMSL; NaN: the default altitude)."""
        m = self.modes
        default = self.params.get("MIS_TAKEOFF_ALT")
        raised = ""
        if math.isfinite(alt_amsl):
            if self.navigator.home is None:
                self.note("takeoff denied: no home position yet (param7 is AMSL)")
                return CommandResult.TEMPORARILY_REJECTED
            alt = alt_amsl - self.navigator.home_alt
            if alt < TAKEOFF_MIN_HEIGHT_M:  # below home (a relative altitude?): PX4's way
                raised = (f"Using minimum takeoff altitude: {default:.2f} m (param7 "
                          f"{alt_amsl:g} m AMSL is {alt:.1f} m above home)")
                alt = default
        else:
            alt = default
            raised = f"Using minimum takeoff altitude: {default:.2f} m"
        if alt > 500.0:
            self.note(f"takeoff denied: {alt:.1f} m above home (param7 is AMSL, home "
                      f"{self.navigator.home_alt:.1f} m)")
            return CommandResult.DENIED
        res = m.takeoff()
        if res == CommandResult.ACCEPTED:
            self.sp.takeoff_alt = alt
            self.sp.alt_ref = alt
            if raised:
                self.drain_events()
                self.note(raised)
        return self._after(res)

    def _set_mode(self, p: list[float]) -> CommandResult:
        """DO_SET_MODE with PX4's custom modes: POSCTL/ALTCTL/AUTO.LOITER = hold the current
        flight (hover, or cruise in fixed-wing), AUTO.TAKEOFF, AUTO.LAND."""
        if not (math.isfinite(p[0]) and int(p[0]) & 1 and math.isfinite(p[1])):
            return CommandResult.DENIED
        main = int(p[1])
        sub = int(p[2]) if math.isfinite(p[2]) else 0
        m = self.modes
        if main in (2, 3) or (main == 4 and sub == 3):
            if m.mode in (FlightMode.TAKEOFF, FlightMode.LAND):
                m.set_mode(FlightMode.HOVER, "hold commanded")
            return CommandResult.ACCEPTED
        if main == 4 and sub == 2:
            return m.takeoff() if m.mode == FlightMode.IDLE else CommandResult.DENIED
        if main == 4 and sub == 6:
            return m.land()
        return CommandResult.DENIED

    def _after(self, res: CommandResult) -> CommandResult:
        m = self.modes
        self.arming.track(self.est.time_usec, m.armed, m.mode)
        self.drain_events()
        return res

    def _on_arm(self) -> None:
        nav = self.est.last_nav
        if nav is not None:
            self.est.ground_alt = -float(nav.pos_ned_m[2])
            self.sp.hold_ne[:] = nav.pos_ned_m[:2]
            self.sp.yaw_hold = quat_to_euler(nav.q_wxyz)[2]
        self.reset_loops()

    def battery_failsafe(self, action: str, text: str) -> None:
        """The low-battery failsafe's action (``"rtl"``, ``"land"`` or a warning only)."""
        self.note(text)
        if action == "rtl" and self.navigator.start_rtl(text) == CommandResult.ACCEPTED:
            return
        if action in ("rtl", "land") and self.modes.mode != FlightMode.IDLE:
            self.navigator.leave_auto((4, 6))
            self.modes.land()
            self.drain_events()

    # ---- mode logic of a step --------------------------------------------------------------
    def update_mode(self, nav: NavState, h: float, v_up: float, V: float, pitch: float,
                    yaw: float) -> FlightMode:
        """The step's mode logic: landing detection (in LAND), the mode machine, mode entry,
        the queued events, the navigator and the auto-disarm; returns the mode.

        ``h`` altitude [m] (up), ``v_up`` climb rate [m/s], ``V`` airspeed [m/s], ``pitch``
        and ``yaw`` [rad].
        """
        pp = self._p
        m = self.modes
        landed = False
        if m.mode == _M_LAND:
            if h - self.est.ground_alt < 0.3 and abs(v_up) < 0.25:
                self._landed_timer += self.dt
            else:
                self._landed_timer = 0.0
            landed = self._landed_timer > 1.0
        if m.mode in AUTO_EXIT_MODES:
            dl = self.outer.degraded
            m.update(self.est.time_usec, altitude_m=h, takeoff_alt_m=self.sp.takeoff_alt,
                     airspeed_m_s=V, arsp_trans=pp["VT_ARSP_TRANS"].value,
                     # (hover_recoverable() is True while not active: no call then)
                     trans_timeout_s=(pp["VT_TRANS_TMOUT"].value
                                      if not dl.active or dl.hover_recoverable() else math.inf),
                     b_trans_arsp=pp["VT_B_TRANS_ARSP"].value,
                     b_trans_dur_s=pp["VT_B_TRANS_DUR"].value, landed=landed)
        else:  # no automatic change in this mode: its parameters and arguments unread
            m.advance(self.est.time_usec)
        mode = m.mode
        if mode != self.last_mode:
            self._enter_mode(mode, self.last_mode, nav, pitch)
            self.last_mode = mode
        if self.outer.degraded.active is not self._dl_noted:
            self._dl_noted = self.outer.degraded.active
            if self._dl_noted:
                self.note(f"degraded lift: lift rotors short and sinking at {-v_up:.1f} m/s "
                          f"in the transition, pitching up (airspeed {V:.1f} m/s)")
        if m.events:  # drain_events() has nothing to do otherwise
            self.drain_events()
        self.navigator.update(nav, yaw)
        ar = self.arming
        # in flight (armed before and now, out of IDLE) the auto-disarm's check changes
        # nothing and says "stay armed" (ArmingMonitor.airborne): no call then
        if (m.armed or ar.armed) and not (m.armed and ar.armed and ar.airborne
                                          and m.mode != _M_IDLE):
            self._auto_disarm()
        return mode

    def _enter_mode(self, mode: FlightMode, old: FlightMode, nav: NavState,
                    pitch: float) -> None:
        sp = self.sp
        if mode == FlightMode.TAKEOFF:
            sp.hold_ne[:] = nav.pos_ned_m[:2]
            sp.hold_locked = True
        elif mode == FlightMode.HOVER:
            if old in (FlightMode.FRONT_TRANSITION, FlightMode.BACK_TRANSITION,
                       FlightMode.FIXED_WING):
                sp.hold_locked = False  # brake first, then hold where stopped
            if old == FlightMode.TAKEOFF:
                sp.alt_ref = sp.takeoff_alt
        elif mode == FlightMode.LAND:
            sp.alt_ref = -float(nav.pos_ned_m[2])
        self.outer.enter_mode(mode, pitch)
        if mode == FlightMode.IDLE:
            self.reset_loops()

    def _auto_disarm(self) -> None:
        """PX4's auto-disarm on the ground (:mod:`.arming`), once per step."""
        m = self.modes
        nv = self.navigator
        t = self.est.time_usec
        why = self.arming.check(t, m.armed, m.mode,
                                nv.nav_mode == NavMode.MISSION and nv.mission_state != MS_COMPLETE)
        if why and m.disarm(force=False) == CommandResult.ACCEPTED:
            self.arming.track(t, m.armed, m.mode)
            self.note(why)

    # ---- events ----------------------------------------------------------------------------
    def note(self, text: str) -> None:
        """Log ``text`` as an event at the current time (and make it the status message)."""
        self.modes.events.append((self.est.time_usec, text))
        self.drain_events()

    def drain_events(self) -> None:
        """Move the mode machine's queued events into the event log."""
        if self.modes.events:
            self.message = self.modes.events[-1][1]
            self.event_log.extend(self.modes.events)
            self.modes.events.clear()

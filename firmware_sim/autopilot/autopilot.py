"""The autopilot: modes, altitude/position/airspeed loops, attitude control, QP allocation.

:class:`Autopilot` implements :class:`~vtolftc.firmware_sim.autopilot.interface.AutopilotAPI`. Each
``step(nav)`` (250 Hz):

1. the mode machine (:mod:`.modes`) takes its automatic transitions;
2. the outer loops give the references of the mode: attitude (roll, pitch, yaw), vertical
   force ``Fz`` (body z, N; from the constant-gain altitude hold of :mod:`.altitude` plus a
   nominal-aerodynamics feed-forward of the wing's lift) and forward force ``Fx`` (pusher ramp
   in the transition, airspeed hold in fixed-wing);
3. the attitude controller (``gs-shif``, ``shif`` or ``lqr``, :mod:`.attitude`) gives the
   moments ``[L, M, N]`` (N m), its gains scheduled on the measured airspeed through a
   first-order low-pass of time constant ``FTC_SCHED_TAU`` (0.5 s; the modes, the
   allocation and the outer loops use the raw value);
4. ``ActiveSetAllocator`` maps ``v = [Fz, Fx, L, M, N]`` onto all 15 actuators at once with
   the nominal ``B(V)`` at the measured airspeed (:mod:`.effectiveness`), actuator position
   limits, rate limits as per-step bounds and a warm-started active-set solve (the paper's
   redundancy management; ``B`` is evaluated on a 0.1 m/s airspeed grid). In fixed-wing the
   lift rotors' upper bound is ramped to 0 over ``VT_TRANS_P2_DUR`` after the transition (they
   stop carrying the weight); after the ramp the ``Fz`` row is dropped and the lift rotors
   become a moment reserve: a second allocator with the actuator weights
   :data:`FW_ROTOR_RESERVE_WEIGHT` (lift rotors 30 times costlier than the surfaces in the
   secondary objective) keeps them at 0 while the surfaces can deliver the moments and uses
   them only for what the surfaces cannot (e.g. a dead elevator, once the pitch command
   exceeds what the nominal elevator could give). Still passive: both allocators use the
   nominal ``B``. In hover the surfaces stay in the problem (their columns vanish with the
   airspeed). The pushers are off (upper bound 0) in
   the multicopter modes and the back transition.

Anti-windup: where the allocation could not achieve a moment (achieved short of the command by
more than a small tolerance), the controller's integrator on that axis is frozen in that
direction at the next step.

Attitude references: hover/takeoff/land: position hold through small tilt references (at most
``MPC_TILTMAX_AIR``), heading held; front transition: roll 0, pitch 0, heading held (the
paper); fixed-wing: roll 0, heading held, pitch from the altitude hold; back transition:
roll 0, pitch 0.

Passive FTC: the autopilot sees only :class:`NavState` and the airframe file (nominal model);
it never imports the vehicle and never reads fault state.
"""

from __future__ import annotations

import math
from collections.abc import Sequence
from pathlib import Path

import numpy as np
from numpy.typing import NDArray

from vtolftc.airframe.loader import Airframe, load_airframe
from vtolftc.firmware_sim.autopilot.allocation import ActiveSetAllocator, AllocationStatus
from vtolftc.firmware_sim.autopilot.altitude import FixedWingAltitudeHold, MulticopterAltitudeHold
from vtolftc.firmware_sim.autopilot.arming import ARMING_PARAMS, ArmingMonitor
from vtolftc.firmware_sim.autopilot.attitude import AttitudeController, make_controller
from vtolftc.firmware_sim.autopilot.battery import BatteryMonitor
from vtolftc.firmware_sim.autopilot.effectiveness import EffectivenessModel
from vtolftc.firmware_sim.autopilot.interface import (
    HIL_OUTPUTS,
    AutopilotStatus,
    CommandResult,
    FlightMode,
    NavState,
    ParameterStore,
    ParamType,
)
from vtolftc.firmware_sim.autopilot.modes import ModeMachine, landed_state, vtol_state
from vtolftc.firmware_sim.autopilot.navigator import MS_COMPLETE, Navigator, NavMode
from vtolftc.protocols.generated import constants as mav
from vtolftc.rotation import quat_to_euler

__all__ = [
    "CMD_COMPONENT_ARM_DISARM",
    "CMD_DO_SET_MODE",
    "CMD_DO_VTOL_TRANSITION",
    "CMD_NAV_LAND",
    "CMD_NAV_TAKEOFF",
    "FORCE_DISARM_MAGIC",
    "Autopilot",
    "default_parameters",
    "quat_to_euler",
]

CMD_NAV_LAND = mav.MAV_CMD_NAV_LAND
CMD_NAV_TAKEOFF = mav.MAV_CMD_NAV_TAKEOFF
CMD_DO_SET_MODE = mav.MAV_CMD_DO_SET_MODE
CMD_COMPONENT_ARM_DISARM = mav.MAV_CMD_COMPONENT_ARM_DISARM
CMD_DO_VTOL_TRANSITION = mav.MAV_CMD_DO_VTOL_TRANSITION
FORCE_DISARM_MAGIC = 21196  # PX4's force-disarm magic in param2 (not a MAVLink enum)
MAV_VTOL_STATE_MC = mav.MAV_VTOL_STATE_MC
MAV_VTOL_STATE_FW = mav.MAV_VTOL_STATE_FW
ARMED_IDLE_THROTTLE = 0.05
#: NAV_TAKEOFF's param7 giving less than this height above home [m] (below home, e.g. a
#: relative altitude sent where PX4 reads AMSL, as MAVProxy's ``takeoff 30`` does) means
#: the default takeoff altitude ``MIS_TAKEOFF_ALT`` (PX4 raises it to that minimum clearance).
TAKEOFF_MIN_HEIGHT_M = 1.0

#: ``AutopilotStatus.allocation_status`` text of each allocation status.
_STATUS_NAMES: dict[AllocationStatus, str] = {st: st.name.lower() for st in AllocationStatus}

#: FlightMode members as module constants (an Enum class attribute costs ~75 ns in 3.11).
_M_BACK_TRANSITION = FlightMode.BACK_TRANSITION
_M_FIXED_WING = FlightMode.FIXED_WING
_M_FRONT_TRANSITION = FlightMode.FRONT_TRANSITION
_M_IDLE = FlightMode.IDLE
_M_LAND = FlightMode.LAND
_M_TAKEOFF = FlightMode.TAKEOFF

#: MAV_VTOL_STATE and MAV_LANDED_STATE of each mode (``status()`` runs every step).
_VTOL_STATE_OF = {m: vtol_state(m) for m in FlightMode}
_LANDED_STATE_OF = {m: landed_state(m) for m in FlightMode}

#: Virtual-axis weights of the QP: [Fz (N), Fx (N), L, M, N (N m)]; moments first.
ALLOCATION_WEIGHTS = np.array([1.0, 0.5, 10.0, 10.0, 5.0])
#: Weight of the lift rotors in the fixed-wing allocator's secondary objective (surfaces and
#: pushers 1): the rotors are a reserve the QP reaches for only when the surfaces cannot
#: deliver (the primary, tracking, objective is ~1e5 times heavier per N m).
FW_ROTOR_RESERVE_WEIGHT = 30.0


def _body_velocity(q: NDArray[np.float64], v: NDArray[np.float64]) -> tuple[float, float, float]:
    """NED vector ``v`` in body FRD axes (R^T v) for the quaternion ``q``."""
    return _body_velocity_f(float(q[0]), float(q[1]), float(q[2]), float(q[3]),
                            float(v[0]), float(v[1]), float(v[2]))


def _body_velocity_f(w: float, x: float, y: float, z: float, vn: float, ve: float,
                     vd: float) -> tuple[float, float, float]:
    """:func:`_body_velocity` on plain floats (quaternion w, x, y, z; NED vector)."""
    r00 = 1 - 2 * (y * y + z * z)
    r01 = 2 * (x * y - w * z)
    r02 = 2 * (x * z + w * y)
    r10 = 2 * (x * y + w * z)
    r11 = 1 - 2 * (x * x + z * z)
    r12 = 2 * (y * z - w * x)
    r20 = 2 * (x * z - w * y)
    r21 = 2 * (y * z + w * x)
    r22 = 1 - 2 * (x * x + y * y)
    return (r00 * vn + r10 * ve + r20 * vd, r01 * vn + r11 * ve + r21 * vd,
            r02 * vn + r12 * ve + r22 * vd)


_PARAMS: tuple[tuple[str, float, ParamType, float, float, str], ...] = (
    ("SYS_FAILURE_EN", 0, ParamType.INT32, 0, 1,
     "enable fault injection commands (read by the MAVLink endpoint only)"),
    ("MIS_TAKEOFF_ALT", 30.0, ParamType.REAL32, 1.0, 500.0, "default takeoff altitude, m"),
    ("VT_ARSP_TRANS", 13.0, ParamType.REAL32, 5.0, 40.0,
     "airspeed completing the front transition, m/s"),
    ("VT_TRANS_TMOUT", 15.0, ParamType.REAL32, 1.0, 120.0,
     "front transition timeout (quad-chute back to hover), s"),
    ("VT_F_TRANS_THR", 0.7, ParamType.REAL32, 0.0, 1.0,
     "pusher thrust fraction during the front transition"),
    ("VT_PSHER_SLEW", 0.33, ParamType.REAL32, 0.01, 10.0,
     "pusher ramp rate in the front transition, 1/s"),
    ("VT_TRANS_P2_DUR", 2.0, ParamType.REAL32, 0.0, 20.0,
     "lift-rotor ramp-down after the front transition, s"),
    ("VT_B_TRANS_DUR", 20.0, ParamType.REAL32, 1.0, 120.0, "back transition timeout, s"),
    ("VT_B_TRANS_ARSP", 5.0, ParamType.REAL32, 0.0, 20.0,
     "airspeed completing the back transition, m/s"),
    ("FW_AIRSPD_TRIM", 18.0, ParamType.REAL32, 10.0, 40.0, "fixed-wing cruise airspeed, m/s"),
    ("FTC_SCHED_TAU", 0.5, ParamType.REAL32, 0.0, 5.0,
     "low-pass time constant of the airspeed that schedules the attitude gains, s (0: none)"),
    ("FW_AIRSPD_P", 0.6, ParamType.REAL32, 0.0, 10.0,
     "airspeed hold: forward acceleration per airspeed error, 1/s"),
    ("FW_AIRSPD_I", 0.1, ParamType.REAL32, 0.0, 10.0, "airspeed hold integral gain, 1/s^2"),
    ("FW_ALT_P", 0.25, ParamType.REAL32, 0.0, 5.0, "fixed-wing climb rate per altitude error, 1/s"),
    ("FW_VZ_P", 0.03, ParamType.REAL32, 0.0, 1.0, "pitch per climb-rate error, rad s/m"),
    ("FW_VZ_I", 0.01, ParamType.REAL32, 0.0, 1.0, "pitch integral per climb-rate error, rad/m"),
    ("FW_CLMB_MAX", 3.0, ParamType.REAL32, 0.1, 10.0, "fixed-wing max climb rate, m/s"),
    ("FW_SINK_MAX", 3.0, ParamType.REAL32, 0.1, 10.0, "fixed-wing max sink rate, m/s"),
    ("FW_P_LIM_MAX", 20.0, ParamType.REAL32, 0.0, 45.0, "fixed-wing max pitch reference, deg"),
    ("FW_P_LIM_MIN", -15.0, ParamType.REAL32, -45.0, 0.0, "fixed-wing min pitch reference, deg"),
    ("MPC_Z_P", 1.0, ParamType.REAL32, 0.0, 10.0, "climb rate per altitude error, 1/s"),
    ("MPC_Z_VEL_P_ACC", 4.0, ParamType.REAL32, 0.0, 30.0,
     "vertical acceleration per climb-rate error, 1/s"),
    ("MPC_Z_VEL_I_ACC", 2.0, ParamType.REAL32, 0.0, 30.0, "climb-rate integral gain, 1/s^2"),
    ("MPC_Z_VEL_MAX_UP", 3.0, ParamType.REAL32, 0.1, 10.0, "max climb rate, m/s"),
    ("MPC_Z_VEL_MAX_DN", 1.5, ParamType.REAL32, 0.1, 10.0, "max descent rate, m/s"),
    ("MPC_TKO_SPEED", 2.5, ParamType.REAL32, 0.1, 10.0, "takeoff climb rate, m/s"),
    ("MPC_LAND_SPEED", 0.7, ParamType.REAL32, 0.1, 5.0, "landing descent rate, m/s"),
    ("MPC_XY_P", 0.95, ParamType.REAL32, 0.0, 5.0, "horizontal speed per position error, 1/s"),
    ("MPC_XY_VEL_P_ACC", 1.8, ParamType.REAL32, 0.0, 10.0,
     "horizontal acceleration per speed error, 1/s"),
    ("MPC_XY_VEL_MAX", 5.0, ParamType.REAL32, 0.1, 20.0, "max horizontal speed in hover, m/s"),
    ("MPC_TILTMAX_AIR", 10.0, ParamType.REAL32, 0.0, 45.0,
     "max tilt reference of the position hold, deg"),
)


def default_parameters() -> ParameterStore:
    """A fresh parameter store with every autopilot parameter at its default."""
    ps = ParameterStore()
    for name, default, typ, lo, hi, desc in (*_PARAMS, *ARMING_PARAMS):
        ps.register(name, default, typ, lo, hi, desc)
    return ps


class Autopilot:
    """The flight software (see the module docstring).

    Parameters
    ----------
    airframe
        the airframe (nominal model for allocation); default the shipped DS-1.
    controller
        ``"gs-shif"``, ``"shif"`` or ``"lqr"``.
    gains_dir
        directory holding the gain files (default ``firmware_sim/autopilot/gains``).
    dt_s
        control period [s] (default 0.004, 250 Hz).
    """

    def __init__(self, airframe: Airframe | None = None, controller: str = "gs-shif",
                 gains_dir: str | Path | None = None, dt_s: float = 0.004) -> None:
        self.airframe = airframe if airframe is not None else load_airframe()
        af = self.airframe
        if af.n_actuators > HIL_OUTPUTS:
            raise ValueError(f"airframe {af.name}: {af.n_actuators} actuators, HIL carries "
                             f"at most {HIL_OUTPUTS}")
        self.dt = float(dt_s)
        self.controller_name = controller
        self.attitude: AttitudeController = make_controller(
            controller, gains_dir, self.dt, airframe_name=af.name, airframe_sha256=af.sha256)
        self.params = default_parameters()
        # fast read access to the parameter values (read every step, so changes act at once)
        _store = self.params._params
        self._param = lambda name: _store[name].value
        # the Parameter objects themselves (mutated in place by ParameterStore.set), read as
        # ``self._p[name].value`` on the hot path without a call per read
        self._p = dict(_store)
        self.effectiveness = EffectivenessModel(af)
        self.n_rotors = len(af.lift_rotors)
        self.i_push = [af.actuator_index(r_name) for r_name in
                       (f"pusher_{p.name}" for p in af.pushers)]
        self.n_u = af.n_actuators
        u_min = np.zeros(self.n_u)
        u_max = np.ones(self.n_u)
        n_rot_all = len(af.rotors)
        u_min[n_rot_all:] = -1.0
        rate = np.empty(self.n_u)
        for i, r in enumerate(af.rotors):
            rate[i] = r.rate_limit_per_s
        rate[n_rot_all:] = af.surfaces.rate_limit_rad_s / af.surfaces.max_deflection_rad
        self.u_min, self.u_max = u_min, u_max
        self.hover_throttle = af.weight_N / sum(r.max_thrust_N for r in af.lift_rotors)
        self.u_pref_mc = np.zeros(self.n_u)
        self.u_pref_mc[: self.n_rotors] = self.hover_throttle
        self.u_pref_fw = np.zeros(self.n_u)
        self._hi = self.u_max.copy()  # per-step upper limits handed to the allocator
        self._hi_key = (math.nan, math.nan)  # (rotor, pusher) upper limits held in _hi
        self._pushers_nominal = [(r.max_thrust_N, r.zero_thrust_axial_speed_m_s)
                                 for r in af.pushers]
        # The compiled active-set solver, warm-started from the previous command: on all QPs
        # of paper case 1 as accurate as OSQP + polish against an independent BVLS solution
        # (3.7e-5 vs 3.9e-5 in a normalised command) at a fifth of the cost (median 14 us vs
        # 64 us, benchmarks/bench_allocation.py). No wall-clock limit: a run is deterministic
        # whatever the machine's load. QPAllocator (OSQP) stays available with the same API.
        self.allocator = ActiveSetAllocator(5, u_min, u_max, w_v=ALLOCATION_WEIGHTS,
                                            u_pref=self.u_pref_mc, rate_limit=rate, dt=self.dt)
        w_fw = np.ones(self.n_u)
        w_fw[: self.n_rotors] = FW_ROTOR_RESERVE_WEIGHT
        self.allocator_fw = ActiveSetAllocator(5, u_min, u_max, w_v=ALLOCATION_WEIGHTS,
                                               w_u=w_fw, u_pref=self.u_pref_fw,
                                               rate_limit=rate, dt=self.dt)
        self.allocator_fw.stats = self.allocator.stats  # one statistics record for both
        self._fw_reserve = False  # allocator_fw active (fixed-wing after the rotor ramp)
        self.mc_alt = MulticopterAltitudeHold(self.dt)
        self.fw_alt = FixedWingAltitudeHold(self.dt)
        self.modes = ModeMachine()
        self._event_log: list[tuple[int, str]] = []
        self._B = np.zeros((5, self.n_u))
        self._B_grid_key: int | None = None  # matrix_on_grid key of _B_grid
        self._B_grid: NDArray[np.float64] | None = None
        self._wing: tuple = (None,)  # (airframe, rho, wing constants) of _aero_estimate
        self._B_of: NDArray[np.float64] | None = None  # the grid B that _B (Fz row 0) is of
        self._u = np.zeros(self.n_u)
        self._v = np.zeros(5)
        self._ref = np.zeros(3)
        self._att = np.zeros(3)
        # per moment axis: the last allocation fell short upwards / downwards (plain lists of
        # bool: read by the attitude controller's anti-windup every step)
        self._sat_hi = [False, False, False]
        self._sat_lo = [False, False, False]
        # control steps whose allocation fell short of a commanded moment (any axis)
        self.saturated_steps = 0
        self._time_usec = 0
        self._airspeed = 0.0
        # the airspeed the attitude gains are scheduled with (FTC_SCHED_TAU low-pass)
        self._v_sched = math.nan
        self._alt_ref = 0.0
        self._alt = 0.0
        self._ground_alt = math.nan
        self._hold_ne = np.zeros(2)
        self._hold_locked = False
        self._yaw_hold = 0.0
        self._takeoff_alt = 30.0
        self._pusher_ramp = 0.0
        self._fw_entry_usec = 0
        self._airspeed_int = 0.0
        self._landed_timer = 0.0
        self._last_mode = self.modes.mode
        self._message = ""
        self._alloc_status = "idle"
        self._have_nav = False
        self._last_nav: NavState | None = None
        self.navigator = Navigator(self)
        """Missions, RTL, loiter, reposition (:mod:`.navigator`)."""
        self.battery = BatteryMonitor(self.params, self._battery_failsafe)
        """Battery estimate and the low-battery failsafe (:mod:`.battery`)."""
        self.arming = ArmingMonitor(self.params)
        """Auto-disarm on the ground (COM_DISARM_PRFLT, COM_DISARM_LAND) and the flight
        record of FLIGHT_INFORMATION (:mod:`.arming`)."""

    def battery_update(self, time_usec: int, voltage_v: float, current_a: float) -> None:
        """A power-module reading (pack voltage [V], current [A]) from the vehicle."""
        self.battery.update(time_usec, voltage_v, current_a)

    def _battery_failsafe(self, action: str, text: str) -> None:
        self._note(text)
        if action == "rtl" and self.navigator.start_rtl(text) == CommandResult.ACCEPTED:
            return
        if action in ("rtl", "land") and self.modes.mode != FlightMode.IDLE:
            self.navigator._leave_auto((4, 6))
            self.modes.land()
            self._drain_events()

    def set_home(self, lat_deg: float, lon_deg: float, alt_m: float) -> None:
        """Geodetic origin of the NED frame (needed for missions and AMSL altitudes)."""
        self.navigator.set_home(lat_deg, lon_deg, alt_m)

    # ------------------------------------------------------------------------------------
    # Commands
    # ------------------------------------------------------------------------------------
    def command(self, command_id: int, params: Sequence[float]) -> CommandResult:
        """Handle a MAVLink COMMAND_LONG (id and its seven params, NaN = default).

        COMPONENT_ARM_DISARM 400: param1 1 arm (on the ground, once navigation data came),
        0 disarm (on the ground; in the air only with param2 = 21196). NAV_TAKEOFF 22: param7
        the takeoff altitude AMSL as in PX4 (needs the home position, :meth:`set_home`); NaN,
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
                if not self._have_nav:
                    self._note("arming denied: no navigation data yet")
                    return CommandResult.DENIED
                res = m.arm()
                if res == CommandResult.ACCEPTED and m.mode == FlightMode.IDLE:
                    self._on_arm()
                return self._after(res)
            if p[0] == 0.0:
                return self._after(m.disarm(force=p[1] == FORCE_DISARM_MAGIC))
            return CommandResult.DENIED
        if cid == CMD_NAV_TAKEOFF:
            default = self.params.get("MIS_TAKEOFF_ALT")
            raised = ""
            if math.isfinite(p[6]):
                if self.navigator.home is None:
                    self._note("takeoff denied: no home position yet (param7 is AMSL)")
                    return CommandResult.TEMPORARILY_REJECTED
                alt = p[6] - self.navigator.home_alt
                if alt < TAKEOFF_MIN_HEIGHT_M:  # below home (a relative altitude?): PX4's way
                    raised = (f"Using minimum takeoff altitude: {default:.2f} m (param7 "
                              f"{p[6]:g} m AMSL is {alt:.1f} m above home)")
                    alt = default
            else:
                alt = default
                raised = f"Using minimum takeoff altitude: {default:.2f} m"
            if alt > 500.0:
                self._note(f"takeoff denied: {alt:.1f} m above home (param7 is AMSL, home "
                           f"{self.navigator.home_alt:.1f} m)")
                return CommandResult.DENIED
            res = m.takeoff()
            if res == CommandResult.ACCEPTED:
                self._takeoff_alt = alt
                self._alt_ref = alt
                if raised:
                    self._drain_events()
                    self._note(raised)
            return self._after(res)
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
        self.arming.track(self._time_usec, m.armed, m.mode)
        self._drain_events()
        return res

    def _auto_disarm(self) -> None:
        """PX4's auto-disarm on the ground (:mod:`.arming`), once per step."""
        m = self.modes
        nv = self.navigator
        why = self.arming.check(self._time_usec, m.armed, m.mode,
                                nv.nav_mode == NavMode.MISSION and nv.mission_state != MS_COMPLETE)
        if why and m.disarm(force=False) == CommandResult.ACCEPTED:
            self.arming.track(self._time_usec, m.armed, m.mode)
            self._note(why)

    def _note(self, text: str) -> None:
        self.modes.events.append((self._time_usec, text))
        self._drain_events()

    def _drain_events(self) -> None:
        if self.modes.events:
            self._message = self.modes.events[-1][1]
            self.event_log.extend(self.modes.events)
            self.modes.events.clear()

    @property
    def event_log(self) -> list[tuple[int, str]]:
        """Every event so far as (time_usec, text) (mode changes, arming, quad-chute ...)."""
        return self._event_log

    def _on_arm(self) -> None:
        nav = self._last_nav
        if nav is not None:
            self._ground_alt = -float(nav.pos_ned_m[2])
            self._hold_ne[:] = nav.pos_ned_m[:2]
            self._yaw_hold = quat_to_euler(nav.q_wxyz)[2]
        self._reset_loops()

    def _reset_loops(self) -> None:
        self.attitude.reset()
        self.mc_alt.reset()
        self._sat_hi = [False, False, False]
        self._sat_lo = [False, False, False]

    # ------------------------------------------------------------------------------------
    # Control step
    # ------------------------------------------------------------------------------------
    def step(self, nav: NavState) -> NDArray[np.float64]:
        """One control step on ``nav``; returns the 15 normalised actuator commands.

        The stages, in order: read the navigation data (hold the previous command when it is
        unusable), the mode logic (:meth:`_update_mode`), the outer loops writing the force
        commands (:meth:`_outer_mc` or :meth:`_outer_fw`), the attitude control
        (:meth:`_attitude_control`) and the allocation to the actuators (:meth:`_allocate`).
        """
        # ---- read navigation ------------------------------------------------------------
        pos = nav.pos_ned_m.tolist()
        vel = nav.vel_ned_m_s.tolist()
        q = nav.q_wxyz
        ql = q.tolist()
        isf = math.isfinite
        if not (isf(pos[0]) and isf(pos[1]) and isf(pos[2]) and isf(vel[0]) and isf(vel[1])
                and isf(vel[2]) and isf(ql[0]) and isf(ql[1]) and isf(ql[2]) and isf(ql[3])
                and all(map(isf, nav.omega_body_rad_s.tolist()))):
            # unusable navigation data: hold the previous command (never output NaN)
            self._alloc_status = "invalid navigation data"
            return self._u.copy()
        self._have_nav = True
        self._last_nav = nav
        self._time_usec = int(nav.time_usec)
        roll, pitch, yaw = quat_to_euler(ql)
        w_, x_, y_, z_ = ql
        att = self._att
        att[0], att[1], att[2] = roll, pitch, yaw
        rates = nav.omega_body_rad_s
        h = -pos[2]
        v_up = -vel[2]
        V = float(nav.airspeed_m_s)
        if not math.isfinite(V):
            V = 0.0
        self._airspeed = V
        self._alt = h
        m = self.modes
        if not math.isfinite(self._ground_alt):
            self._ground_alt = h

        mode = self._update_mode(nav, h, v_up, V, pitch, yaw)
        if not m.armed or mode == _M_IDLE:
            return self._idle_output()

        # ---- outer loops: references and forces ----------------------------------------
        ref = self._ref
        ref[2] = self._yaw_hold
        cos_tilt = max(0.5, math.cos(roll) * math.cos(pitch))
        # _body_velocity_f(*ql, *vel)[0] and [2], inlined (same expressions, same bits)
        vn_, ve_, vd_ = vel
        ub = ((1 - 2 * (y_ * y_ + z_ * z_)) * vn_ + 2 * (x_ * y_ + w_ * z_) * ve_
              + 2 * (x_ * z_ - w_ * y_) * vd_)
        wb = (2 * (x_ * z_ + w_ * y_) * vn_ + 2 * (y_ * z_ - w_ * x_) * ve_
              + (1 - 2 * (x_ * x_ + y_ * y_)) * vd_)
        alpha = math.atan2(wb, ub) if ub > 1.0 else 0.0
        lift, drag = self._aero_estimate(V, alpha)
        fz_aero = -lift * math.cos(alpha) - drag * math.sin(alpha)  # body z, N

        if mode is not _M_FIXED_WING:  # TAKEOFF, HOVER, LAND, FRONT/BACK_TRANSITION
            reserve = False
            rotor_hi = 1.0
            pusher_hi = self._outer_mc(mode, nav, yaw, h, v_up, V, cos_tilt, fz_aero)
            u_pref = self.u_pref_mc
        else:  # FIXED_WING
            t_fw = (self._time_usec - self._fw_entry_usec) * 1e-6
            ramp = self._p["VT_TRANS_P2_DUR"].value
            rotor_hi = max(0.0, 1.0 - t_fw / ramp) if ramp > 0 else 0.0
            reserve = False
            if rotor_hi <= 0.0:
                rotor_hi = 1.0   # the reserve: weighted, not bounded (allocator_fw)
                reserve = True
            pusher_hi = 1.0
            self._outer_fw(nav, roll, pitch, yaw, h, v_up, V, cos_tilt, alpha, lift, drag,
                           fz_aero, reserve)
            u_pref = self.u_pref_fw

        tau = self._attitude_control(mode, h, V, att, rates)
        return self._allocate(V, tau, reserve, rotor_hi, pusher_hi, u_pref)

    def _update_mode(self, nav: NavState, h: float, v_up: float, V: float, pitch: float,
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
            if h - self._ground_alt < 0.3 and abs(v_up) < 0.25:
                self._landed_timer += self.dt
            else:
                self._landed_timer = 0.0
            landed = self._landed_timer > 1.0
        m.update(self._time_usec, altitude_m=h, takeoff_alt_m=self._takeoff_alt,
                 airspeed_m_s=V, arsp_trans=pp["VT_ARSP_TRANS"].value,
                 trans_timeout_s=pp["VT_TRANS_TMOUT"].value,
                 b_trans_arsp=pp["VT_B_TRANS_ARSP"].value,
                 b_trans_dur_s=pp["VT_B_TRANS_DUR"].value, landed=landed)
        mode = m.mode
        if mode != self._last_mode:
            self._enter_mode(mode, self._last_mode, nav, pitch)
            self._last_mode = mode
        self._drain_events()
        self.navigator.update(nav, yaw)
        if m.armed or self.arming.armed:
            self._auto_disarm()
        return mode

    def _idle_output(self) -> NDArray[np.float64]:
        """Disarmed or IDLE: rotors off (idle throttle when armed), loops and allocator reset;
        returns a copy of the commands."""
        u = self._u
        u[:] = 0.0
        if self.modes.armed:
            u[: self.n_rotors] = ARMED_IDLE_THROTTLE
        self._v[:] = 0.0
        self._ref[:] = (0.0, 0.0, self._yaw_hold)
        self._alloc_status = "idle"
        self.allocator.reset(u)
        self._fw_reserve = False
        self._reset_loops()
        return u.copy()

    def _outer_mc(self, mode: FlightMode, nav: NavState, yaw: float, h: float, v_up: float,
                  V: float, cos_tilt: float, fz_aero: float) -> float:
        """Outer loops in the multicopter modes (TAKEOFF, HOVER, LAND, transitions).

        Writes the roll/pitch references into ``self._ref`` [rad] and the body z and x force
        commands [N] into ``self._v[0]`` and ``self._v[1]``; returns the pushers' upper
        bound (1 in the front transition, else 0).
        """
        pp = self._p
        ref = self._ref
        override = None
        vmax_up = pp["MPC_Z_VEL_MAX_UP"].value
        if mode == _M_TAKEOFF:
            vmax_up = min(vmax_up, pp["MPC_TKO_SPEED"].value)
        if mode == _M_LAND:
            override = -pp["MPC_LAND_SPEED"].value
            self._alt_ref = h
        a_up = self.mc_alt.update(self._alt_ref, h, v_up, kp_z=pp["MPC_Z_P"].value,
                                  kp_vz=pp["MPC_Z_VEL_P_ACC"].value,
                                  ki_vz=pp["MPC_Z_VEL_I_ACC"].value,
                                  v_max_up=vmax_up, v_max_dn=pp["MPC_Z_VEL_MAX_DN"].value,
                                  v_up_override=override)
        self._v[0] = (-self.airframe.mass_kg * (self.airframe.gravity_m_s2 + a_up) / cos_tilt
                      - fz_aero)
        fx_cmd = 0.0
        pusher_hi = 1.0
        if mode == _M_FRONT_TRANSITION:
            ref[0] = 0.0
            ref[1] = 0.0
            self._pusher_ramp = min(1.0, self._pusher_ramp
                                    + pp["VT_PSHER_SLEW"].value * self.dt)
            fx_cmd = pp["VT_F_TRANS_THR"].value * self._pusher_ramp * self._pusher_max_force(V)
        elif mode == _M_BACK_TRANSITION:
            ref[0] = 0.0
            ref[1] = 0.0
            pusher_hi = 0.0
        else:
            ref[0], ref[1] = self._position_hold(nav, yaw)
            pusher_hi = 0.0
        self._v[1] = fx_cmd
        return pusher_hi

    def _outer_fw(self, nav: NavState, roll: float, pitch: float, yaw: float, h: float,
                  v_up: float, V: float, cos_tilt: float, alpha: float, lift: float,
                  drag: float, fz_aero: float, reserve: bool) -> None:
        """Outer loops in FIXED_WING: lateral guidance, altitude (TECS-like pitch) and
        airspeed loops.

        Writes the roll/pitch/yaw references into ``self._ref`` [rad] and the body z and x
        force commands [N] into ``self._v[0]`` and ``self._v[1]`` (no z command in the
        reserve, where the lift rotors are only weighted).
        """
        pp = self._p
        ref = self._ref
        mass = self.airframe.mass_kg
        g = self.airframe.gravity_m_s2
        lim = math.radians
        lateral = self.navigator.fw_lateral(nav, roll, yaw, V)
        if lateral is None:
            ref[0] = 0.0
        else:
            ref[0], ref[2] = lateral
        ref[1] = self.fw_alt.update(self._alt_ref, h, v_up, kp_alt=pp["FW_ALT_P"].value,
                                    kp_vz=pp["FW_VZ_P"].value, ki_vz=pp["FW_VZ_I"].value,
                                    climb_max=pp["FW_CLMB_MAX"].value,
                                    sink_max=pp["FW_SINK_MAX"].value,
                                    pitch_min=lim(pp["FW_P_LIM_MIN"].value),
                                    pitch_max=lim(pp["FW_P_LIM_MAX"].value))
        fx_max = self._pusher_max_force(V)
        e_v = self.navigator.airspeed_setpoint() - V
        a_x = pp["FW_AIRSPD_P"].value * e_v + self._airspeed_int
        fx_cmd = drag * math.cos(alpha) - lift * math.sin(alpha) + mass * (
            a_x + g * math.sin(pitch))
        if not ((fx_cmd >= fx_max and e_v > 0) or (fx_cmd <= 0.0 and e_v < 0)):
            self._airspeed_int = min(max(self._airspeed_int
                                         + pp["FW_AIRSPD_I"].value * e_v * self.dt, -3.0), 3.0)
        self._v[1] = min(max(fx_cmd, 0.0), fx_max)
        if not reserve:
            a_up = self.mc_alt.update(self._alt_ref, h, v_up, kp_z=pp["MPC_Z_P"].value,
                                      kp_vz=pp["MPC_Z_VEL_P_ACC"].value,
                                      ki_vz=pp["MPC_Z_VEL_I_ACC"].value,
                                      v_max_up=pp["MPC_Z_VEL_MAX_UP"].value,
                                      v_max_dn=pp["MPC_Z_VEL_MAX_DN"].value)
            self._v[0] = -mass * (g + a_up) / cos_tilt - fz_aero
        else:
            self._v[0] = 0.0

    def _attitude_control(self, mode: FlightMode, h: float, V: float, att: NDArray[np.float64],
                          rates: NDArray[np.float64]) -> NDArray[np.float64]:
        """Attitude control on the scheduling airspeed: the body torque commands [N m]
        (FRD) for the references in ``self._ref`` (``att`` roll/pitch/yaw [rad], ``rates``
        body rates [rad/s], ``V`` airspeed [m/s], ``h`` altitude [m])."""
        if mode == _M_TAKEOFF and h - self._ground_alt < 0.5:  # still on the ground
            self.attitude.reset()
        # gains scheduled on a low-passed airspeed: the measurement's noise would otherwise
        # move the gains between neighbouring design points from step to step (in hover
        # between 0 and 1 m/s, whose pitch gains differ by 3x), a randomly time-varying
        # controller that the design never analysed
        tc = self._p["FTC_SCHED_TAU"].value
        vs = self._v_sched
        if tc > 0.0 and math.isfinite(vs):
            vs += min(1.0, self.dt / tc) * (V - vs)
        else:
            vs = V
        self._v_sched = vs
        return self.attitude.update(self._ref, att, rates, vs, self._sat_hi, self._sat_lo)

    def _allocate(self, V: float, tau: NDArray[np.float64], reserve: bool, rotor_hi: float,
                  pusher_hi: float, u_pref: NDArray[np.float64]) -> NDArray[np.float64]:
        """Allocate the virtual command (``self._v[0:2]`` forces [N], ``tau`` torques [N m])
        to the actuators at airspeed ``V`` [m/s]; returns a copy of the commands."""
        # B(V) on a 0.1 m/s airspeed grid: the allocator rebuilds its Hessian only when B changes
        # (every ~12 steps in the transition instead of every step); the dynamic pressure
        # differs from the exact one by < 1 % above 10 m/s, far below the faults' 20-50 %.
        k_grid = round(V / 0.1) if V > 0.0 else 0  # matrix_on_grid's key (V is finite here)
        if k_grid != self._B_grid_key:
            self._B_grid = self.effectiveness.matrix_on_grid(V, 0.1)
            self._B_grid_key = k_grid
        B = self._B_grid
        if reserve:  # no z force command: the lift rotors' row is zeroed
            if B is not self._B_of:  # the grid's B is cached and read-only: copy on change
                np.copyto(self._B, B)
                self._B[0, :] = 0.0
                self._B_of = B
            B = self._B
        u = self._u
        v = self._v
        v[2:] = tau
        hi = self._hi
        if rotor_hi != self._hi_key[0] or pusher_hi != self._hi_key[1]:  # rarely changes
            hi[: self.n_rotors] = rotor_hi
            for i in self.i_push:
                hi[i] = pusher_hi
            self._hi_key = (rotor_hi, pusher_hi)
        if reserve != self._fw_reserve:  # hand over, warm-started at the current command
            (self.allocator_fw if reserve else self.allocator).reset(u)
            self._fw_reserve = reserve
        alloc = self.allocator_fw if reserve else self.allocator
        res = alloc.allocate(v, B, u_max=hi, u_pref=u_pref)
        self._alloc_status = _STATUS_NAMES[res.status]
        self._track_saturation(v, res.v_achieved)
        u[:] = res.u
        return u.copy()

    # ------------------------------------------------------------------------------------
    def _enter_mode(self, mode: FlightMode, old: FlightMode, nav: NavState,
                    pitch: float) -> None:
        h = -float(nav.pos_ned_m[2])
        if mode == FlightMode.TAKEOFF:
            self._hold_ne[:] = nav.pos_ned_m[:2]
            self._hold_locked = True
        elif mode == FlightMode.HOVER:
            if old in (FlightMode.FRONT_TRANSITION, FlightMode.BACK_TRANSITION,
                       FlightMode.FIXED_WING):
                self._hold_locked = False  # brake first, then hold where stopped
            if old == FlightMode.TAKEOFF:
                self._alt_ref = self._takeoff_alt
        elif mode == FlightMode.FRONT_TRANSITION:
            self._pusher_ramp = 0.0
        elif mode == FlightMode.FIXED_WING:
            self._fw_entry_usec = self._time_usec
            self.fw_alt.reset(pitch)
            self._airspeed_int = 0.0
        elif mode == FlightMode.BACK_TRANSITION:
            self.mc_alt.reset(self.mc_alt.integral)
        elif mode == FlightMode.LAND:
            self._alt_ref = h
        if mode == FlightMode.IDLE:
            self._reset_loops()

    def _aero_estimate(self, V: float, alpha: float) -> tuple[float, float]:
        """Nominal wing lift and drag [N] at airspeed V and angle of attack alpha (from the
        airframe file, linear lift clipped at CL_max)."""
        if V < 1.0:
            return 0.0, 0.0
        wing = self._wing
        if wing[0] is not self.airframe:
            w = self.airframe.wing
            wing = self._wing = (self.airframe, self.effectiveness._rho, w.area_m2, w.CL0,
                                 w.CL_alpha, w.CL_max, w.CD0, w.induced_drag_factor)
        _, rho, area, cl0, cl_alpha, cl_max, cd0, k_i = wing
        # effectiveness.dynamic_pressure(V) * area, inlined (V >= 1 here)
        qS = 0.5 * rho * V * V * area
        cl = min(max(cl0 + cl_alpha * alpha, -cl_max), cl_max)
        cd = cd0 + k_i * cl * cl
        return qS * cl, qS * cd

    def _pusher_max_force(self, V: float) -> float:
        """Nominal total pusher thrust at full command and airspeed V [N]."""
        tot = 0.0
        for tmax, v0 in self._pushers_nominal:
            tot += tmax * min(1.25, max(0.0, 1.0 - V / v0))
        return tot

    def _position_hold(self, nav: NavState, yaw: float) -> tuple[float, float]:
        """Roll and pitch references [rad] holding the horizontal position (brake first)."""
        pp = self._p
        vn, ve = float(nav.vel_ned_m_s[0]), float(nav.vel_ned_m_s[1])
        if not self._hold_locked:
            if math.hypot(vn, ve) < 0.5:
                self._hold_ne[:] = nav.pos_ned_m[:2]
                self._hold_locked = True
            vrn, vre = 0.0, 0.0
        else:
            kp = pp["MPC_XY_P"].value
            vrn = kp * (self._hold_ne[0] - float(nav.pos_ned_m[0]))
            vre = kp * (self._hold_ne[1] - float(nav.pos_ned_m[1]))
            vmax = pp["MPC_XY_VEL_MAX"].value
            s = math.hypot(vrn, vre)
            if s > vmax:
                vrn, vre = vrn * vmax / s, vre * vmax / s
        kv = pp["MPC_XY_VEL_P_ACC"].value
        an, ae = kv * (vrn - vn), kv * (vre - ve)
        g = self.airframe.gravity_m_s2
        a_fwd = math.cos(yaw) * an + math.sin(yaw) * ae
        a_right = -math.sin(yaw) * an + math.cos(yaw) * ae
        tmax = math.radians(pp["MPC_TILTMAX_AIR"].value)
        pitch_ref = min(max(-math.atan2(a_fwd, g), -tmax), tmax)
        roll_ref = min(max(math.atan2(a_right, g), -tmax), tmax)
        return roll_ref, pitch_ref

    def _track_saturation(self, v: NDArray[np.float64], achieved: NDArray[np.float64]) -> None:
        """Which moment axes the allocation could not achieve, and in which direction."""
        _, _, w0, w1, w2 = v.tolist()
        _, _, g0, g1, g2 = achieved.tolist()
        tol = 0.02 + 0.02 * abs(w0)
        h0 = w0 > g0 + tol
        l0 = w0 < g0 - tol
        tol = 0.02 + 0.02 * abs(w1)
        h1 = w1 > g1 + tol
        l1 = w1 < g1 - tol
        tol = 0.02 + 0.02 * abs(w2)
        h2 = w2 > g2 + tol
        l2 = w2 < g2 - tol
        self._sat_hi = [h0, h1, h2]
        self._sat_lo = [l0, l1, l2]
        if h0 or l0 or h1 or l1 or h2 or l2:
            self.saturated_steps += 1

    # ------------------------------------------------------------------------------------
    def status(self) -> AutopilotStatus:
        """Snapshot for telemetry, logs and ground stations."""
        mode = self.modes.mode
        # positional, in AutopilotStatus's field order (time_usec, mode, armed, vtol_state,
        # landed_state, attitude_ref_rad, attitude_rad, altitude_ref_m, airspeed_m_s,
        # virtual_command, actuator_commands, allocation_status, controller, message)
        return AutopilotStatus(
            self._time_usec, mode, self.modes.armed, _VTOL_STATE_OF[mode],
            _LANDED_STATE_OF[mode], self._ref.copy(), self._att.copy(), float(self._alt_ref),
            float(self._airspeed), self._v.copy(), self._u.copy(), self._alloc_status,
            self.controller_name, self._message, self.navigator.custom_mode(mode))

    def metrics_inputs(self, nav: NavState) -> tuple[FlightMode, bool, NDArray[np.float64],
                                                     float, tuple[float, float, float] | None]:
        """What the flight metrics read of :meth:`status`, without building it.

        Returns ``(mode, armed, attitude_ref_rad, altitude_ref_m, euler_rad)``: the status
        fields of those names (``attitude_ref_rad`` is the autopilot's own array: read it, do
        not keep it) and, when the last step flew on ``nav`` itself, the ZYX Euler angles
        [rad] it computed from ``nav.q_wxyz`` (else None). The in-process runner's path when
        no observer wants the full status.
        """
        m = self.modes
        euler = tuple(self._att.tolist()) if nav is self._last_nav else None
        return m.mode, m.armed, self._ref, float(self._alt_ref), euler

    @property
    def allocation_stats(self) -> dict[str, object]:
        """The allocator's running statistics (counts per status, iterations, timing)."""
        return self.allocator.stats.as_dict()

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
4. ``ActiveSetAllocator`` maps ``v = [Fz, Fx, L, M, N]`` onto all the airframe's actuators at
   once with the nominal ``B(V)`` at the measured airspeed (:mod:`.effectiveness`), actuator
   position limits, rate limits as per-step bounds and a warm-started active-set solve (the paper's
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
paper; pitch up when the lift rotors cannot hold the altitude, :mod:`.degraded_lift`);
fixed-wing: roll 0, heading held, pitch from the altitude hold; back transition:
roll 0, pitch 0.

The collaborators, one job each: :mod:`.estimate` (state intake), :mod:`.commander` (commands,
mode logic, events), :mod:`.outer_loops`, :mod:`.attitude_stage`, :mod:`.output` (allocation),
sharing the references of :mod:`.setpoints`; :class:`Autopilot` composes them.

Passive FTC: the autopilot sees only :class:`NavState` and the airframe file (nominal model);
it never imports the vehicle and never reads fault state.
"""

from __future__ import annotations

from collections.abc import Sequence
from pathlib import Path

import numpy as np
from numpy.typing import NDArray

from vtolftc.airframe.loader import Airframe, load_airframe
from vtolftc.base.rotation import quat_to_euler
from vtolftc.firmware_sim.autopilot.arming import ArmingMonitor
from vtolftc.firmware_sim.autopilot.attitude import make_controller
from vtolftc.firmware_sim.autopilot.attitude_stage import AttitudeStage
from vtolftc.firmware_sim.autopilot.battery import BatteryMonitor
from vtolftc.firmware_sim.autopilot.commander import (
    CMD_COMPONENT_ARM_DISARM,
    CMD_DO_SET_MODE,
    CMD_DO_VTOL_TRANSITION,
    CMD_NAV_LAND,
    CMD_NAV_TAKEOFF,
    FORCE_DISARM_MAGIC,
    MAV_VTOL_STATE_FW,
    MAV_VTOL_STATE_MC,
    TAKEOFF_MIN_HEIGHT_M,
    Commander,
)
from vtolftc.firmware_sim.autopilot.delegation import Delegated
from vtolftc.firmware_sim.autopilot.effectiveness import EffectivenessModel
from vtolftc.firmware_sim.autopilot.estimate import StateEstimate
from vtolftc.firmware_sim.autopilot.interface import (
    HIL_OUTPUTS,
    AutopilotStatus,
    CommandResult,
    FlightMode,
    NavState,
)
from vtolftc.firmware_sim.autopilot.modes import ModeMachine, landed_state, vtol_state
from vtolftc.firmware_sim.autopilot.navigator import Navigator
from vtolftc.firmware_sim.autopilot.outer_loops import OuterLoops
from vtolftc.firmware_sim.autopilot.output import (
    ALLOCATION_WEIGHTS,
    ARMED_IDLE_THROTTLE,
    FW_ROTOR_RESERVE_WEIGHT,
    OutputStage,
)
from vtolftc.firmware_sim.autopilot.parameters import airframe_airspeed_defaults, default_parameters
from vtolftc.firmware_sim.autopilot.setpoints import Setpoints

__all__ = [
    "ALLOCATION_WEIGHTS",
    "ARMED_IDLE_THROTTLE",
    "CMD_COMPONENT_ARM_DISARM",
    "CMD_DO_SET_MODE",
    "CMD_DO_VTOL_TRANSITION",
    "CMD_NAV_LAND",
    "CMD_NAV_TAKEOFF",
    "FORCE_DISARM_MAGIC",
    "FW_ROTOR_RESERVE_WEIGHT",
    "MAV_VTOL_STATE_FW",
    "MAV_VTOL_STATE_MC",
    "TAKEOFF_MIN_HEIGHT_M",
    "Autopilot",
    "default_parameters",
    "quat_to_euler",
]

#: FlightMode members as module constants (an Enum class attribute costs ~75 ns in 3.11).
_M_FIXED_WING = FlightMode.FIXED_WING
_M_IDLE = FlightMode.IDLE

#: MAV_VTOL_STATE and MAV_LANDED_STATE of each mode (``status()`` runs every step).
_VTOL_STATE_OF = {m: vtol_state(m) for m in FlightMode}
_LANDED_STATE_OF = {m: landed_state(m) for m in FlightMode}


class Autopilot:
    """The flight software (see the module docstring): a composition of its stages.

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

    # the stages' state under the names the autopilot has always offered
    attitude = Delegated("attitude_stage", "controller")
    allocator = Delegated("output", "allocator")
    allocator_fw = Delegated("output", "allocator_fw")
    saturated_steps = Delegated("output", "saturated_steps")
    n_rotors = Delegated("output", "n_rotors")
    i_push = Delegated("output", "i_push")
    n_u = Delegated("output", "n_u")
    u_min = Delegated("output", "u_min")
    u_max = Delegated("output", "u_max")
    hover_throttle = Delegated("output", "hover_throttle")
    u_pref_mc = Delegated("output", "u_pref_mc")
    u_pref_fw = Delegated("output", "u_pref_fw")
    mc_alt = Delegated("outer", "mc_alt")
    fw_alt = Delegated("outer", "fw_alt")
    event_log = Delegated("commander", "event_log")

    def __init__(self, airframe: Airframe | None = None, controller: str = "gs-shif",
                 gains_dir: str | Path | None = None, dt_s: float = 0.004) -> None:
        self.airframe = airframe if airframe is not None else load_airframe()
        af = self.airframe
        if af.n_actuators > HIL_OUTPUTS:
            raise ValueError(f"airframe {af.name}: {af.n_actuators} actuators, HIL carries "
                             f"at most {HIL_OUTPUTS}")
        self.dt = float(dt_s)
        self.controller_name = controller
        controller_obj = make_controller(
            controller, gains_dir, self.dt, airframe_name=af.name, airframe_sha256=af.sha256)
        self.params = default_parameters()
        # the Parameter objects themselves (mutated in place by ParameterStore.set), read as
        # ``pp[name].value`` on the hot path without a call per read
        pp = dict(self.params.view())
        self.effectiveness = EffectivenessModel(af)
        self.setpoints = Setpoints()
        """References shared by the stages (:mod:`.setpoints`)."""
        self.estimate = StateEstimate()
        """State intake from the navigation data (:mod:`.estimate`)."""
        self.output = OutputStage(af, self.effectiveness, self.setpoints, self.dt)
        """Allocation to the actuators (:mod:`.output`)."""
        self.outer = OuterLoops(af, self.effectiveness, pp, self.setpoints, self.estimate,
                                self.dt)
        """Outer loops: attitude references and forces (:mod:`.outer_loops`)."""
        self.attitude_stage = AttitudeStage(controller_obj, pp, self.estimate, self.dt)
        """Scheduled attitude control (:mod:`.attitude_stage`)."""
        self.modes = ModeMachine()
        self.commander = Commander(self.modes, self.params, pp, self.setpoints, self.estimate,
                                   self.outer, self._reset_loops, self.dt)
        """Commands, mode logic and events (:mod:`.commander`)."""
        self.navigator = Navigator(self)
        """Missions, RTL, loiter, reposition (:mod:`.navigator`)."""
        self.battery = BatteryMonitor(self.params, self.commander.battery_failsafe)
        """Battery estimate and the low-battery failsafe (:mod:`.battery`)."""
        self.arming = ArmingMonitor(self.params)
        """Auto-disarm on the ground (COM_DISARM_PRFLT, COM_DISARM_LAND) and the flight
        record of FLIGHT_INFORMATION (:mod:`.arming`)."""
        self.outer.navigator = self.commander.navigator = self.navigator
        self.outer.output = self.output
        self.commander.arming = self.arming
        for name, value in airframe_airspeed_defaults(af).items():  # the airframe's own
            self.params.set_default(name, value)

    def battery_update(self, time_usec: int, voltage_v: float, current_a: float) -> None:
        """A power-module reading (pack voltage [V], current [A]) from the vehicle."""
        self.battery.update(time_usec, voltage_v, current_a)

    def set_home(self, lat_deg: float, lon_deg: float, alt_m: float) -> None:
        """Geodetic origin of the NED frame (needed for missions and AMSL altitudes)."""
        self.navigator.set_home(lat_deg, lon_deg, alt_m)

    def command(self, command_id: int, params: Sequence[float]) -> CommandResult:
        """Handle a MAVLink COMMAND_LONG (id and its seven params, NaN = default); see
        :meth:`.commander.Commander.command` for the commands and their answers."""
        return self.commander.command(command_id, params)

    def _reset_loops(self) -> None:
        self.attitude_stage.controller.reset()
        self.outer.mc_alt.reset()
        self.output.clear_saturation()

    # ------------------------------------------------------------------------------------
    # Control step
    # ------------------------------------------------------------------------------------
    def step(self, nav: NavState) -> NDArray[np.float64]:
        """One control step on ``nav``; returns the 15 normalised actuator commands.

        The stages, in order: read the navigation data (:mod:`.estimate`; hold the previous
        command when it is unusable), the mode logic (:mod:`.commander`), the outer loops
        writing the references and force commands (:mod:`.outer_loops`), the attitude
        control (:mod:`.attitude_stage`) and the allocation to the actuators
        (:mod:`.output`).
        """
        est = self.estimate
        out = self.output
        euler = est.update(nav)
        if euler is None:
            # unusable navigation data: hold the previous command (never output NaN)
            out.status_text = "invalid navigation data"
            return out.u.copy()
        roll, pitch, yaw = euler
        h = est.alt
        v_up = est.v_up
        V = est.airspeed
        mode = self.commander.update_mode(nav, h, v_up, V, pitch, yaw)
        if not self.modes.armed or mode == _M_IDLE:
            out.idle(self.modes.armed)
            sp = self.setpoints
            sp.ref[:] = (0.0, 0.0, sp.yaw_hold)
            self._reset_loops()
            return out.u.copy()
        reserve, rotor_hi, pusher_hi = self.outer.update(mode, nav, roll, pitch, yaw, h, v_up,
                                                         V)
        u_pref = out.u_pref_fw if mode is _M_FIXED_WING else out.u_pref_mc
        stage = self.attitude_stage
        ref = self.setpoints.ref
        rates = nav.omega_body_rad_s
        # the scheduled P-PID step fused into the allocation's compiled call, when the
        # controller is stepped directly; else the controller's update, then the allocation
        ppid = stage.kernel_step_args(mode, h, V, ref, est.att, rates, out.sat_mask)
        if ppid is not None:
            return out.allocate(V, None, reserve, rotor_hi, pusher_hi, u_pref, ppid)
        tau = stage.controller_update(ref, est.att, rates, out.sat_hi, out.sat_lo)
        return out.allocate(V, tau, reserve, rotor_hi, pusher_hi, u_pref)

    # ------------------------------------------------------------------------------------
    def status(self) -> AutopilotStatus:
        """Snapshot for telemetry, logs and ground stations."""
        mode = self.modes.mode
        est = self.estimate
        sp = self.setpoints
        out = self.output
        # positional, in AutopilotStatus's field order (time_usec, mode, armed, vtol_state,
        # landed_state, attitude_ref_rad, attitude_rad, altitude_ref_m, airspeed_m_s,
        # virtual_command, actuator_commands, allocation_status, controller, message)
        return AutopilotStatus(
            est.time_usec, mode, self.modes.armed, _VTOL_STATE_OF[mode],
            _LANDED_STATE_OF[mode], sp.ref.copy(), est.att.copy(), float(sp.alt_ref),
            float(est.airspeed), sp.v.copy(), out.u.copy(), out.status_text,
            self.controller_name, self.commander.message, self.navigator.custom_mode(mode))

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
        est = self.estimate
        euler = est.euler if nav is est.last_nav else None
        return m.mode, m.armed, self.setpoints.ref, float(self.setpoints.alt_ref), euler

    @property
    def allocation_stats(self) -> dict[str, object]:
        """The allocator's running statistics (counts per status, iterations, timing)."""
        return self.output.allocator.stats.as_dict()

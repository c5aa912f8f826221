"""The autopilot's outer loops: attitude references and force commands of the flight mode.

Multicopter modes (TAKEOFF, HOVER, LAND, front and back transition): the constant-gain
altitude hold of :mod:`.altitude` gives the body z force ``Fz`` [N] (with a nominal-aerodynamics
feed-forward of the wing's lift); hover, takeoff and land hold the horizontal position through
small tilt references (at most ``MPC_TILTMAX_AIR``); the front transition flies roll 0,
pitch 0 and ramps the pushers (``Fx``) at ``VT_PSHER_SLEW`` up to ``VT_F_TRANS_THR``, unless
the lift rotors saturate while the vehicle sinks: then the degraded-lift guidance
(:mod:`.degraded_lift`) pitches up within a stall margin and asks the pushers for more; the
back transition flies roll 0, pitch 0 with the pushers off.

Fixed-wing: lateral guidance of the navigator (roll, heading), a TECS-like pitch from the
altitude hold and an airspeed hold on the pushers; the lift rotors' upper bound ramps to 0
over ``VT_TRANS_P2_DUR``, after which they become a weighted reserve (no ``Fz`` command).
"""

from __future__ import annotations

import math
from typing import Any

import numpy as np
from numpy.typing import NDArray

from vtolftc.airframe.loader import Airframe
from vtolftc.firmware_sim.autopilot.altitude import FixedWingAltitudeHold, MulticopterAltitudeHold
from vtolftc.firmware_sim.autopilot.degraded_lift import DegradedLift
from vtolftc.firmware_sim.autopilot.effectiveness import EffectivenessModel
from vtolftc.firmware_sim.autopilot.estimate import StateEstimate
from vtolftc.firmware_sim.autopilot.interface import FlightMode, NavState
from vtolftc.firmware_sim.autopilot.outer_kernels import (
    aero_lift_drag,
    fw_longitudinal_step,
    mc_hold_step,
    mc_transition_step,
    mc_z_force_step,
    outer_aero_step,
    pusher_force,
)
from vtolftc.firmware_sim.autopilot.setpoints import Setpoints

__all__ = ["OuterLoops"]

#: FlightMode members as module constants (an Enum class attribute costs ~75 ns in 3.11).
_M_BACK_TRANSITION = FlightMode.BACK_TRANSITION
_M_FIXED_WING = FlightMode.FIXED_WING
_M_FRONT_TRANSITION = FlightMode.FRONT_TRANSITION
_M_LAND = FlightMode.LAND
_M_TAKEOFF = FlightMode.TAKEOFF


class OuterLoops:
    """References and forces of the flight mode (see the module docstring).

    Parameters
    ----------
    airframe
        the airframe (mass, gravity, wing, pushers: nominal values).
    effectiveness
        the nominal effectiveness model (air density).
    pp
        the autopilot's parameters by name (``Parameter`` objects, read every step).
    setpoints
        the shared references (read and written).
    estimate
        the state intake (time of the step).
    dt
        control period [s].
    """

    def __init__(self, airframe: Airframe, effectiveness: EffectivenessModel,
                 pp: dict[str, Any], setpoints: Setpoints, estimate: StateEstimate,
                 dt: float) -> None:
        self.airframe = airframe
        self.effectiveness = effectiveness
        self._p = pp
        self.sp = setpoints
        self.est = estimate
        self.dt = dt
        self.mc_alt = MulticopterAltitudeHold(self.dt)
        self.fw_alt = FixedWingAltitudeHold(self.dt)
        self.navigator: Any = None  # set by the autopilot once its navigator exists
        self.output: Any = None  # the output stage (last allocation's Fz), set by the autopilot
        self.degraded = DegradedLift(airframe, pp, dt)
        """Degraded-lift guidance of the front transition (:mod:`.degraded_lift`)."""
        self._wing_of: Any = None  # the airframe the wing constants belong to
        self._wing = np.zeros(7)  # its wing constants (_wing_constants)
        self._aero = np.zeros(5)  # outer_aero_step's output
        # each pusher's static thrust [N] and zero-thrust axial speed [m/s] (pusher_force)
        self._pushers = np.array([x for r in airframe.pushers
                                  for x in (r.max_thrust_N, r.zero_thrust_axial_speed_m_s)],
                                 dtype=np.float64)
        # the kernels' constants (the airframe and the loops are fixed at construction): mass
        # [kg], gravity [m/s^2], period [s], the fixed-wing and multicopter altitude holds'
        # periods [s], the latter's a_up_max, a_dn_max, i_limit [m/s^2]
        ma = self.mc_alt
        self._consts = np.array([airframe.mass_kg, airframe.gravity_m_s2, dt, self.fw_alt.dt,
                                 ma.dt, ma.a_up_max, ma.a_dn_max, ma.i_limit])
        self.pusher_ramp = 0.0
        self.fw_entry_usec = 0
        self.airspeed_int = 0.0

    def enter_mode(self, mode: FlightMode, pitch: float) -> None:
        """The loops' part of entering ``mode`` (``pitch`` the current pitch [rad])."""
        if mode == FlightMode.FRONT_TRANSITION:
            self.pusher_ramp = 0.0
            self.degraded.reset()
        elif mode == FlightMode.FIXED_WING:
            self.fw_entry_usec = self.est.time_usec
            self.fw_alt.reset(pitch)
            self.airspeed_int = 0.0
        elif mode == FlightMode.BACK_TRANSITION:
            self.mc_alt.reset(self.mc_alt.integral)

    def update(self, mode: FlightMode, nav: NavState, roll: float, pitch: float, yaw: float,
               h: float, v_up: float, V: float) -> tuple[bool, float, float]:
        """One step of the outer loops in an armed flight ``mode``.

        Writes the attitude reference (``setpoints.ref``, rad) and the force commands
        (``setpoints.v[0:2]``, N). ``roll``, ``pitch``, ``yaw`` [rad], ``h`` altitude [m],
        ``v_up`` climb rate [m/s], ``V`` airspeed [m/s]. Returns ``(reserve, rotor_hi,
        pusher_hi)``: the lift rotors are a weighted reserve (fixed-wing after the ramp), and
        the upper bounds of the lift rotors and of the pushers (normalised).
        """
        sp = self.sp
        sp.ref[2] = sp.yaw_hold
        est = self.est
        dl = self.degraded
        # degraded lift: trust no wing lift beyond the stall margin (a sinking vehicle's wing
        # is past the stall, where the nominal model's clipped CL is far too high)
        lim = dl.alpha_limit() if dl.active and mode is _M_FRONT_TRANSITION else math.inf
        aero = self._aero
        # cos_tilt = max(0.5, cos(roll) cos(pitch)), alpha = atan2(wb, ub) (0 unless ub > 1),
        # the nominal lift and drag at min(alpha, lim) and their body z force [N]: compiled
        wing = self._wing if self._wing_of is self.airframe else self._wing_constants()
        outer_aero_step(roll, pitch, est.ub, est.wb, V, lim, wing, aero)
        cos_tilt, alpha, lift, drag, fz_aero = aero.tolist()

        if mode is not _M_FIXED_WING:  # TAKEOFF, HOVER, LAND, FRONT/BACK_TRANSITION
            pusher_hi = self._outer_mc(mode, nav, yaw, h, v_up, V, cos_tilt, fz_aero)
            if mode is _M_FRONT_TRANSITION:
                self._degraded_lift(h, v_up, V, pitch, alpha, cos_tilt, lift, drag)
            return False, 1.0, pusher_hi
        t_fw = (est.time_usec - self.fw_entry_usec) * 1e-6
        ramp = self._p["VT_TRANS_P2_DUR"].value
        rotor_hi = max(0.0, 1.0 - t_fw / ramp) if ramp > 0 else 0.0
        reserve = False
        if rotor_hi <= 0.0:
            rotor_hi = 1.0   # the reserve: weighted, not bounded (allocator_fw)
            reserve = True
        self._outer_fw(nav, roll, pitch, yaw, h, v_up, V, cos_tilt, alpha, lift, drag,
                       fz_aero, reserve)
        return reserve, rotor_hi, 1.0

    def _outer_mc(self, mode: FlightMode, nav: NavState, yaw: float, h: float, v_up: float,
                  V: float, cos_tilt: float, fz_aero: float) -> float:
        """Outer loops in the multicopter modes (TAKEOFF, HOVER, LAND, transitions).

        Writes the roll/pitch references into ``setpoints.ref`` [rad] and the body z and x
        force commands [N] into ``setpoints.v[0]`` and ``setpoints.v[1]``; returns the
        pushers' upper bound (1 in the front transition, else 0).
        """
        pp = self._p
        sp = self.sp
        ref = sp.ref
        override = None
        vmax_up = pp["MPC_Z_VEL_MAX_UP"].value
        if mode == _M_TAKEOFF:
            tko = pp["MPC_TKO_SPEED"].value
            vmax_up = tko if tko < vmax_up else vmax_up  # min(vmax_up, tko)
        if mode == _M_LAND:
            override = -pp["MPC_LAND_SPEED"].value
            sp.alt_ref = h
        if mode is not _M_FRONT_TRANSITION and mode is not _M_BACK_TRANSITION:
            # TAKEOFF, HOVER, LAND: the altitude hold, the z force, the position hold (its
            # hypot CPython's) and no pusher force in one compiled call, the same bits
            ma = self.mc_alt
            sp.hold_locked, ma.integral, ma.v_up_ref = mc_hold_step(
                nav.pos_ned_m, nav.vel_ned_m_s, sp.hold_ne, ref, sp.v, self._consts,
                sp.hold_locked, ma.integral, sp.alt_ref, h, v_up, pp["MPC_Z_P"].value,
                pp["MPC_Z_VEL_P_ACC"].value, pp["MPC_Z_VEL_I_ACC"].value, vmax_up,
                pp["MPC_Z_VEL_MAX_DN"].value, 0.0 if override is None else override,
                override is not None, cos_tilt, fz_aero, pp["MPC_XY_P"].value,
                pp["MPC_XY_VEL_MAX"].value, pp["MPC_XY_VEL_P_ACC"].value, yaw,
                pp["MPC_TILTMAX_AIR"].value)
            return 0.0
        # FRONT_TRANSITION, BACK_TRANSITION: the altitude hold, the z force, roll and pitch 0
        # and the pushers' ramp (front) or none (back) in one compiled call, the same bits
        ma = self.mc_alt
        front = mode is _M_FRONT_TRANSITION
        ma.integral, ma.v_up_ref, self.pusher_ramp = mc_transition_step(
            sp.v, ref, self._consts, self._pushers, ma.integral, sp.alt_ref, h, v_up,
            pp["MPC_Z_P"].value, pp["MPC_Z_VEL_P_ACC"].value, pp["MPC_Z_VEL_I_ACC"].value,
            vmax_up, pp["MPC_Z_VEL_MAX_DN"].value, cos_tilt, fz_aero, front, self.pusher_ramp,
            pp["VT_PSHER_SLEW"].value, pp["VT_F_TRANS_THR"].value, V)
        return 1.0 if front else 0.0

    def _degraded_lift(self, h: float, v_up: float, V: float, pitch: float, alpha: float,
                       cos_tilt: float, lift: float, drag: float) -> None:
        """The degraded-lift guidance's part of a front-transition step: when engaged
        (:mod:`.degraded_lift`), its pitch reference [rad] and ``FTC_DL_PSH`` of the pushers'
        thrust [N] replace the transition's pitch 0 and pusher ramp."""
        out = self.output
        if out is None:
            return
        wing_up = lift * math.cos(pitch - alpha) - drag * math.sin(pitch - alpha)
        if self.degraded.update(v_up, V, pitch, alpha, cos_tilt, out.fz_cmd, out.fz_achieved,
                                wing_up, self.sp.alt_ref - h,
                                self.sp.v[1] * math.sin(pitch)):
            self.sp.ref[1] = self.degraded.pitch_ref
            # the rotors' share of the z force, corrected by their measured effectiveness
            self.sp.v[0] /= max(self.degraded.rotor_effectiveness, 0.3)
            self.sp.v[1] = max(self.sp.v[1],
                               self._p["FTC_DL_PSH"].value * self.pusher_max_force(V))

    def _outer_fw(self, nav: NavState, roll: float, pitch: float, yaw: float, h: float,
                  v_up: float, V: float, cos_tilt: float, alpha: float, lift: float,
                  drag: float, fz_aero: float, reserve: bool) -> None:
        """Outer loops in FIXED_WING: lateral guidance, altitude (TECS-like pitch) and
        airspeed loops.

        Writes the roll/pitch/yaw references into ``setpoints.ref`` [rad] and the body z and
        x force commands [N] into ``setpoints.v[0]`` and ``setpoints.v[1]`` (no z command in
        the reserve, where the lift rotors are only weighted).
        """
        pp = self._p
        sp = self.sp
        ref = sp.ref
        lateral = self.navigator.fw_lateral(nav, roll, yaw, V)
        if lateral is None:
            ref[0] = 0.0
        else:
            ref[0], ref[2] = lateral
        # fw_alt.update, pusher_max_force and the airspeed hold: one compiled call
        fa = self.fw_alt
        c = self._consts
        ref[1], fa.integral, fa.v_up_ref, self.airspeed_int, sp.v[1] = fw_longitudinal_step(
            self._pushers, c, sp.alt_ref, h, v_up, V, pitch, alpha, lift, drag, fa.integral,
            pp["FW_ALT_P"].value, pp["FW_VZ_P"].value, pp["FW_VZ_I"].value,
            pp["FW_CLMB_MAX"].value, pp["FW_SINK_MAX"].value, pp["FW_P_LIM_MIN"].value,
            pp["FW_P_LIM_MAX"].value, self.navigator.airspeed_setpoint(),
            pp["FW_AIRSPD_P"].value, pp["FW_AIRSPD_I"].value, self.airspeed_int)
        if not reserve:  # the lift rotors' altitude hold and z force, compiled
            ma = self.mc_alt
            ma.integral, ma.v_up_ref = mc_z_force_step(
                sp.v, c, ma.integral, sp.alt_ref, h, v_up, pp["MPC_Z_P"].value,
                pp["MPC_Z_VEL_P_ACC"].value, pp["MPC_Z_VEL_I_ACC"].value,
                pp["MPC_Z_VEL_MAX_UP"].value, pp["MPC_Z_VEL_MAX_DN"].value, 0.0, False,
                cos_tilt, fz_aero)
        else:
            sp.v[0] = 0.0

    def _wing_constants(self) -> NDArray[np.float64]:
        """The nominal wing constants of :func:`.outer_kernels.aero_lift_drag` (air density,
        area, CL0, CL_alpha, CL_max, CD0, induced drag factor), rebuilt when the airframe
        object changes."""
        if self._wing_of is not self.airframe:
            w = self.airframe.wing
            self._wing = np.array([self.effectiveness._rho, w.area_m2, w.CL0, w.CL_alpha,
                                   w.CL_max, w.CD0, w.induced_drag_factor])
            self._wing_of = self.airframe
        return self._wing

    def aero_estimate(self, V: float, alpha: float) -> tuple[float, float]:
        """Nominal wing lift and drag [N] at airspeed V [m/s] and angle of attack alpha [rad]
        (from the airframe file, linear lift clipped at CL_max)."""
        return aero_lift_drag(self._wing_constants(), V, alpha)

    def pusher_max_force(self, V: float) -> float:
        """Nominal total pusher thrust at full command and airspeed V [m/s], in N."""
        return pusher_force(self._pushers, V)

"""Degraded-lift guidance of the front transition: when the lift rotors cannot hold the
altitude, ask the wing (passive FTC).

In the front transition the paper flies pitch 0 and the lift rotors carry what the wing does
not. When the rotors have lost lift (a fault the autopilot never learns of), the altitude hold
asks for more body z force than the allocation can give and the vehicle sinks; tight tracking
of pitch 0 then keeps the wing at its zero-pitch lift while the vehicle falls. This monitor
decides from what the autopilot measures only (climb rate, airspeed, angle of attack from the
velocity in body axes, the allocation's commanded and achieved body z force):

- **engage** (latched until the next front transition) when, for ``FTC_DL_TRIG_T`` seconds,
  the lift rotors saturate (the allocation's achieved body z force, nominal model, short of
  the command by more than ``FTC_DL_SAT`` of it) while the climb rate is below
  ``-FTC_DL_SINK`` [m/s], or the vehicle sinks faster than the altitude hold ever commands
  (``MPC_Z_VEL_MAX_DN + FTC_DL_SINK``): lift lost that the nominal model does not see;
- **pitch up**: the pitch reference slews at ``FTC_DL_P_RATE`` [deg/s] towards
  ``FTC_DL_P_MAX`` [deg] scaled by the altitude error (full at ``FTC_DL_ALT_BND`` [m] below
  the reference, 0 at it: no climb overshoot into fixed-wing); from ``FTC_DL_VS_RAT`` times
  the airframe's stall speed on, at most the pitch that puts the measured angle of attack at
  the wing's stall angle ``(CL_max - CL0) / CL_alpha`` less the margin ``FTC_DL_AOA_MRG``
  [deg]; the outer loops' wing-lift feed-forward then also trusts no angle of attack beyond
  that limit (a sinking vehicle's wing is past the stall, where the nominal clipped CL is far
  too high);
- **pushers** at ``FTC_DL_PSH`` of their thrust (instead of ``VT_F_TRANS_THR``);
- **rotor demand** divided by the rotors' measured effectiveness (at least 0.3): their
  measured lift (vertical force from the low-passed climb acceleration, less the nominal wing
  lift) over what the allocation believed it achieved;
- **no quad-chute while hover is not recoverable**: the transition timeout's return to hover
  is held off for ``FTC_DL_EST_T`` seconds after engaging (the effectiveness is being
  measured; low-pass 0.5 s), then unless the least measured effectiveness (the pushers'
  upward thrust taken out) times the rotors' nominal
  total thrust is at least ``FTC_DL_HOV_TW`` times the weight.

With the monitor never engaged (``FTC_DL_EN`` 0, or a nominal transition) the outer loops fly
exactly as before.
"""

from __future__ import annotations

import math
from typing import Any

from vtolftc.airframe.loader import Airframe

__all__ = ["DEGRADED_LIFT_PARAMS", "DegradedLift"]

#: (name, default, min, max, description) of the degraded-lift parameters (REAL32).
DEGRADED_LIFT_PARAMS: tuple[tuple[str, float, float, float, str], ...] = (
    ("FTC_DL_EN", 1.0, 0.0, 1.0,
     "degraded-lift transition guidance: 1 enabled, 0 off (pitch 0 as the paper)"),
    ("FTC_DL_SAT", 0.03, 0.0, 1.0,
     "lift saturation: achieved body z force short of the command by this fraction"),
    ("FTC_DL_SINK", 0.8, 0.0, 10.0, "sink rate engaging the degraded-lift guidance, m/s"),
    ("FTC_DL_TRIG_T", 0.2, 0.0, 5.0,
     "saturation and sink held this long engage the degraded-lift guidance, s"),
    ("FTC_DL_P_MAX", 15.0, 0.0, 30.0, "max pitch reference of the degraded-lift guidance, deg"),
    ("FTC_DL_P_RATE", 15.0, 0.1, 90.0, "pitch reference slew rate when degraded, deg/s"),
    ("FTC_DL_AOA_MRG", 2.0, 0.0, 15.0,
     "stall margin: angle of attack kept this far below the stall angle, deg"),
    ("FTC_DL_ALT_BND", 3.0, 0.0, 50.0,
     "altitude error below the reference giving the full pitch up (less: scaled), m"),
    ("FTC_DL_VS_RAT", 0.9, 0.0, 2.0,
     "airspeed over the stall speed from which the stall margin limits the pitch up"),
    ("FTC_DL_PSH", 1.0, 0.0, 1.0, "pusher thrust fraction when degraded"),
    ("FTC_DL_EST_T", 2.0, 0.0, 30.0,
     "time engaged before the measured rotor effectiveness may allow the quad-chute, s"),
    ("FTC_DL_HOV_TW", 1.8, 1.0, 3.0,
     "rotor thrust over weight needed to count hover as recoverable (quad-chute allowed)"),
)


class DegradedLift:
    """The degraded-lift monitor and its references (see the module docstring).

    Parameters
    ----------
    airframe
        the nominal airframe file (mass, wing, lift rotors' thrust).
    pp
        the autopilot's parameters by name (``Parameter`` objects, read every step).
    dt
        control period [s].

    Attributes
    ----------
    active : bool
        the guidance is engaged (latched until :meth:`reset`).
    pitch_ref : float
        its pitch reference [rad] (0 until engaged).
    rotor_effectiveness : float
        measured lift of the rotors over the nominal-model lift the allocation achieved
        (1 until measured; low-passed, 0.5 s).
    rotor_effectiveness_min : float
        its least value since engaged (a lost rotor does not come back): what judges hover.
    """

    def __init__(self, airframe: Airframe, pp: dict[str, Any], dt: float) -> None:
        w = airframe.wing
        self._p = pp
        self.dt = float(dt)
        self.mass = airframe.mass_kg
        self.g = airframe.gravity_m_s2
        self.alpha_stall = (w.CL_max - w.CL0) / w.CL_alpha
        self.v_stall = airframe.stall_speed_m_s()
        self.rotor_thrust_N = sum(r.max_thrust_N for r in airframe.lift_rotors)
        self.reset()

    def reset(self) -> None:
        """Disengage (entering the front transition)."""
        self.active = False
        self.pitch_ref = 0.0
        self.rotor_effectiveness = 1.0
        self.rotor_effectiveness_min = 1.0
        self._trig_s = 0.0
        self._active_s = 0.0
        self._v_up_prev = math.nan
        self._a_up = 0.0

    def update(self, v_up: float, V: float, pitch: float, alpha: float, cos_tilt: float,
               fz_cmd: float, fz_achieved: float, wing_up_N: float,
               alt_err: float = math.inf, pusher_up_N: float = 0.0) -> bool:
        """One step in the front transition; returns :attr:`active`.

        ``v_up`` climb rate [m/s], ``V`` airspeed [m/s], ``pitch`` and ``alpha`` (measured
        angle of attack) [rad], ``cos_tilt`` cos(roll) cos(pitch), ``fz_cmd`` and
        ``fz_achieved`` the last allocation's commanded and achieved body z force [N]
        (negative up, nominal model), ``wing_up_N`` the nominal wing force upwards [N],
        ``alt_err`` the altitude reference less the altitude [m], ``pusher_up_N`` the
        pushers' commanded thrust's upward component [N].
        """
        pp = self._p
        dt = self.dt
        # climb acceleration, low-passed derivative of the climb rate (tau 0.5 s)
        if self._v_up_prev == self._v_up_prev:
            a = (v_up - self._v_up_prev) / dt
            self._a_up += (a - self._a_up) * min(1.0, dt / 0.5)
        self._v_up_prev = v_up
        if not pp["FTC_DL_EN"].value:
            return False
        short = fz_achieved - fz_cmd  # > 0: less upward force than commanded
        saturated = fz_cmd < 0.0 and short > pp["FTC_DL_SAT"].value * -fz_cmd
        sink = pp["FTC_DL_SINK"].value
        if not self.active:
            # saturated and sinking, or sinking faster than the altitude hold ever commands
            if (saturated and v_up < -sink) or v_up < -(pp["MPC_Z_VEL_MAX_DN"].value + sink):
                self._trig_s += dt
                if self._trig_s >= pp["FTC_DL_TRIG_T"].value:
                    self.active = True
            else:
                self._trig_s = 0.0
            if not self.active:
                return False
        self._active_s += dt
        # rotor effectiveness: measured rotor lift over the lift the allocation believed
        rotor_meas = self.mass * (self.g + self._a_up) - wing_up_N - pusher_up_N
        rotor_model = -fz_achieved * cos_tilt
        if rotor_model > 1.0:
            eff = min(max(rotor_meas / rotor_model, 0.0), 1.5)
            self.rotor_effectiveness += (eff - self.rotor_effectiveness) * min(1.0, dt / 0.5)
            self.rotor_effectiveness_min = min(self.rotor_effectiveness_min,
                                               self.rotor_effectiveness)
        # pitch target: FTC_DL_P_MAX, scaled down as the altitude error closes (0 at the
        # reference: no climb overshoot); from FTC_DL_VS_RAT x stall speed on, at most the
        # pitch that puts the measured angle of attack at the stall margin
        band = pp["FTC_DL_ALT_BND"].value
        scale = min(max(alt_err / band, 0.0), 1.0) if band > 0.0 else 1.0
        target = math.radians(pp["FTC_DL_P_MAX"].value) * scale
        v_margin = pp["FTC_DL_VS_RAT"].value * self.v_stall
        if v_margin <= V:
            gamma = pitch - alpha  # flight-path angle [rad]
            target = min(max(gamma + self.alpha_limit(), 0.0), target)
        step = math.radians(pp["FTC_DL_P_RATE"].value) * dt
        self.pitch_ref += min(max(target - self.pitch_ref, -step), step)
        return True

    def alpha_limit(self) -> float:
        """The angle of attack the guidance flies at most [rad]: the nominal wing's stall
        angle less ``FTC_DL_AOA_MRG``."""
        return self.alpha_stall - math.radians(self._p["FTC_DL_AOA_MRG"].value)

    def hover_recoverable(self) -> bool:
        """Hover judged recoverable from the measured rotor effectiveness (always True while
        not engaged; False for the first ``FTC_DL_EST_T`` seconds engaged, while the
        effectiveness is being measured)."""
        if not self.active:
            return True
        if self._active_s < self._p["FTC_DL_EST_T"].value:
            return False
        return (self.rotor_effectiveness_min * self.rotor_thrust_N
                >= self._p["FTC_DL_HOV_TW"].value * self.mass * self.g)

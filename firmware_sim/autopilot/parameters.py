"""The autopilot's own parameters (PX4 names where PX4 has them) and their defaults.

The navigator, the battery and the arming monitors register theirs on the same store.
"""

from __future__ import annotations

from vtolftc.airframe.loader import (
    SPEED_GRID_M_S,
    Airframe,
    current_airspeeds,
    round_up_speed,
)
from vtolftc.firmware_sim.autopilot.arming import ARMING_PARAMS
from vtolftc.firmware_sim.autopilot.degraded_lift import DEGRADED_LIFT_PARAMS
from vtolftc.firmware_sim.autopilot.interface import ParameterStore, ParamType

__all__ = ["AUTOPILOT_PARAMS", "airframe_airspeed_defaults", "default_parameters"]

#: (name, default, type, min, max, description) of every autopilot parameter.
AUTOPILOT_PARAMS: tuple[tuple[str, float, ParamType, float, float, str], ...] = (
    ("SYS_FAILURE_EN", 0, ParamType.INT32, 0, 1,
     "enable fault injection commands (read by the MAVLink endpoint only)"),
    ("MIS_TAKEOFF_ALT", 30.0, ParamType.REAL32, 1.0, 500.0, "default takeoff altitude, m"),
    ("VT_ARSP_TRANS", 13.0, ParamType.REAL32, 0.5, 60.0,
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
    ("FW_AIRSPD_TRIM", 18.0, ParamType.REAL32, 0.5, 60.0, "fixed-wing cruise airspeed, m/s"),
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
    for name, default, typ, lo, hi, desc in (*AUTOPILOT_PARAMS, *ARMING_PARAMS):
        ps.register(name, default, typ, lo, hi, desc)
    for name, default, lo, hi, desc in DEGRADED_LIFT_PARAMS:
        ps.register(name, default, ParamType.REAL32, lo, hi, desc)
    return ps


FW_AIRSPD_MIN_OVER_STALL = 1.1
"""``FW_AIRSPD_MIN`` over the stall speed [-] (PX4's guidance: 10-20 % above the stall)."""
FW_AIRSPD_MAX_OVER_CRUISE = 1.2
"""``FW_AIRSPD_MAX`` over the cruise speed [-]."""


def airframe_airspeed_defaults(af: Airframe) -> dict[str, float]:
    """The airspeed parameters of ``af`` [m/s], from its :attr:`Airframe.airspeeds` (declared
    in its file or derived from its wing by the loader's one rule), as a PX4 airframe file
    sets them: ``VT_ARSP_TRANS`` = transition end, ``FW_AIRSPD_TRIM`` = cruise,
    ``FW_AIRSPD_MIN`` = 1.1 stall rounded to the nearest point of the loader's 0.5 m/s grid
    and ``FW_AIRSPD_MAX`` = 1.2 cruise rounded up to it. DS-1: 13, 18, 14 and 22 m/s.

    Examples
    --------
    >>> from vtolftc.airframe.loader import load_airframe
    >>> airframe_airspeed_defaults(load_airframe())
    {'VT_ARSP_TRANS': 13.0, 'FW_AIRSPD_TRIM': 18.0, 'FW_AIRSPD_MIN': 14.0, 'FW_AIRSPD_MAX': 22.0}
    """
    sp = current_airspeeds(af)
    return {"VT_ARSP_TRANS": sp.transition_end_m_s, "FW_AIRSPD_TRIM": sp.cruise_m_s,
            "FW_AIRSPD_MIN": SPEED_GRID_M_S * round(FW_AIRSPD_MIN_OVER_STALL * sp.stall_m_s
                                                    / SPEED_GRID_M_S),
            "FW_AIRSPD_MAX": round_up_speed(FW_AIRSPD_MAX_OVER_CRUISE * sp.cruise_m_s)}

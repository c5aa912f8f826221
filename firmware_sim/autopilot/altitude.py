"""Altitude hold with constant gains (the paper: the altitude loop is not scheduled).

Two laws, both on the altitude above home ``h = -pos_ned_z`` [m] and the climb rate
``v_up = -vel_ned_z`` [m/s]:

- :class:`MulticopterAltitudeHold` (takeoff, hover, transition, landing): a cascaded P / PI
  like PX4's MPC_Z loop::

      v_up_ref = clip(MPC_Z_P (h_ref - h), -MPC_Z_VEL_MAX_DN, MPC_Z_VEL_MAX_UP)
      a_up     = MPC_Z_VEL_P_ACC (v_up_ref - v_up) + MPC_Z_VEL_I_ACC int(v_up_ref - v_up) dt

  returns the upward acceleration command [m/s^2] (clipped to ``[-a_dn_max, a_up_max]``); the
  integral is clamped (anti-windup) and frozen while the output saturates in its direction.
  The caller turns it into a vertical force (``-m (g + a_up)`` along NED down).
- :class:`FixedWingAltitudeHold` (wing-borne): altitude by pitch::

      v_up_ref  = clip(FW_ALT_P (h_ref - h), -FW_SINK_MAX, FW_CLMB_MAX)
      theta_ref = FW_VZ_P (v_up_ref - v_up) + FW_VZ_I int(v_up_ref - v_up) dt

  clipped to ``[FW_P_LIM_MIN, FW_P_LIM_MAX]`` [rad]; the integral carries the trim pitch (it is
  initialised with the pitch at engagement, so the handover is bumpless) and converges to it.
"""

from __future__ import annotations

import math

import numba

__all__ = ["FixedWingAltitudeHold", "MulticopterAltitudeHold", "fw_altitude_law",
           "mc_altitude_law"]


@numba.njit(cache=True)
def mc_altitude_law(integral, dt, a_up_max, a_dn_max, i_limit, h_ref, h, v_up, kp_z, kp_vz,
                    ki_vz, v_max_up, v_max_dn, override, use_override):  # pragma: no cover
    """One step of the multicopter altitude law (:class:`MulticopterAltitudeHold`: its
    integral [m/s^2], period [s] and limits, then its ``update``'s arguments;
    ``use_override`` says whether ``override`` is given); returns ``(a_up, integral,
    v_up_ref)`` [m/s^2, m/s^2, m/s]. Compiled without ``fastmath`` (the same bits as the
    expressions in Python; min / max as comparisons with the builtins' rule)."""
    if not use_override:
        x = kp_z * (h_ref - h)
        lo = -v_max_dn
        x = lo if lo > x else x
        v_ref = v_max_up if v_max_up < x else x
    else:
        v_ref = override
    e = v_ref - v_up
    p = kp_vz * e
    dI = ki_vz * e * dt
    u = p + integral + dI
    a_dn = -a_dn_max
    if (u > a_up_max and dI > 0.0) or (u < a_dn and dI < 0.0):
        dI = 0.0
    x = integral + dI
    lo = -i_limit
    x = lo if lo > x else x
    integral = x = i_limit if i_limit < x else x
    x = p + x
    x = a_dn if a_dn > x else x
    return (a_up_max if a_up_max < x else x), integral, v_ref


@numba.njit(cache=True)
def fw_altitude_law(integral, dt, h_ref, h, v_up, kp_alt, kp_vz, ki_vz, climb_max, sink_max,
                    pitch_min, pitch_max):  # pragma: no cover - compiled
    """One step of the fixed-wing altitude law (:class:`FixedWingAltitudeHold`, whose
    arguments these are, the integral [rad] and the period ``dt`` [s] first); returns
    ``(pitch_ref, integral, v_up_ref)`` [rad, rad, m/s]. Compiled without ``fastmath``: the
    same bits as the expressions in Python; min / max written as comparisons with the
    builtins' rule (the later argument only when strictly greater / less)."""
    x = kp_alt * (h_ref - h)
    lo = -sink_max
    x = lo if lo > x else x
    v_ref = climb_max if climb_max < x else x
    e = v_ref - v_up
    p = kp_vz * e
    dI = ki_vz * e * dt
    u = p + integral + dI
    if (u > pitch_max and dI > 0.0) or (u < pitch_min and dI < 0.0):
        dI = 0.0
    x = integral + dI
    x = pitch_min if pitch_min > x else x
    integral = x = pitch_max if pitch_max < x else x
    x = p + x
    x = pitch_min if pitch_min > x else x
    return (pitch_max if pitch_max < x else x), integral, v_ref


class MulticopterAltitudeHold:
    """Constant-gain altitude / climb-rate loop giving an upward acceleration command.

    Parameters
    ----------
    dt
        control period [s].
    a_up_max, a_dn_max
        limits of the acceleration command [m/s^2] (both > 0).
    i_limit
        limit of the integral term [m/s^2].
    """

    def __init__(self, dt: float, a_up_max: float = 5.0, a_dn_max: float = 4.0,
                 i_limit: float = 4.0) -> None:
        self.dt = float(dt)
        self.a_up_max = float(a_up_max)
        self.a_dn_max = float(a_dn_max)
        self.i_limit = float(i_limit)
        self.integral = 0.0
        self.v_up_ref = 0.0

    def reset(self, integral: float = 0.0) -> None:
        """Set the integral term (m/s^2), e.g. to the hover feed-forward for a bumpless start."""
        self.integral = float(integral)

    def update(self, h_ref: float, h: float, v_up: float, *, kp_z: float, kp_vz: float,
               ki_vz: float, v_max_up: float, v_max_dn: float,
               v_up_override: float | None = None) -> float:
        """One step; returns the upward acceleration command [m/s^2].

        ``v_up_override`` replaces the altitude P loop by a climb-rate reference (landing).
        """
        use = v_up_override is not None
        out, self.integral, self.v_up_ref = mc_altitude_law(
            self.integral, self.dt, self.a_up_max, self.a_dn_max, self.i_limit, h_ref, h, v_up,
            kp_z, kp_vz, ki_vz, v_max_up, v_max_dn, float(v_up_override) if use else 0.0, use)
        return out


class FixedWingAltitudeHold:
    """Constant-gain altitude loop giving a pitch reference [rad] (see the module docstring)."""

    def __init__(self, dt: float) -> None:
        self.dt = float(dt)
        self.integral = 0.0
        self.v_up_ref = 0.0

    def reset(self, pitch_rad: float = 0.0) -> None:
        """Engage with the integral at ``pitch_rad`` (bumpless from the current pitch)."""
        self.integral = float(pitch_rad) if math.isfinite(pitch_rad) else 0.0

    def update(self, h_ref: float, h: float, v_up: float, *, kp_alt: float, kp_vz: float,
               ki_vz: float, climb_max: float, sink_max: float, pitch_min: float,
               pitch_max: float) -> float:
        """Pitch reference (rad) from the altitude error, through a climb-rate loop.

        Parameters
        ----------
        h_ref, h : float
            altitude reference and altitude (m).
        v_up : float
            climb rate (m/s, up positive).
        kp_alt : float
            altitude gain (1/s); the climb-rate reference is clipped to
    ``[-sink_max, climb_max]`` (m/s).
        kp_vz, ki_vz : float
            proportional (rad s/m) and integral (rad/m) climb-rate gains.
        pitch_min, pitch_max : float
            output limits (rad); the integrator stops at them (anti-windup).

        Returns
        -------
        float
            pitch reference (rad).
        """
        out, self.integral, self.v_up_ref = fw_altitude_law(
            self.integral, self.dt, h_ref, h, v_up, kp_alt, kp_vz, ki_vz, climb_max, sink_max,
            pitch_min, pitch_max)
        return out

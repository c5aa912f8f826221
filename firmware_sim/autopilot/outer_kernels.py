"""Compiled pieces of the outer loops (:mod:`.outer_loops`), bit for bit their Python.

- :func:`hypot2`: CPython 3.11's ``math.hypot`` of two floats (``Modules/mathmodule.c``,
  ``math_hypot`` with ``vector_norm``: exact scaling by a power of two, Dekker's exact
  squares, compensated sums and one differential correction of the square root). numba's own
  ``math.hypot`` calls the C library's, which differs from CPython's in ~0.6 % of random pairs;
  this port gives CPython's bits (``tests/test_inproc_fastpaths.py`` compares them on 10^6
  pairs over many magnitudes and on zeros, subnormals, huge values, infinities and NaN).
- :func:`outer_aero_step` (with :func:`aero_lift_drag`): the tilt factor, angle of attack,
  nominal wing lift and drag and their body z force of every armed step of
  :meth:`.outer_loops.OuterLoops.update`, into a small output array.
- :func:`fw_longitudinal_step` (with :func:`pusher_force` and
  :func:`.altitude.fw_altitude_law`): the fixed-wing altitude and airspeed loops.
- :func:`mc_hold_step`: TAKEOFF, HOVER and LAND's altitude law, z force and position hold;
  :func:`mc_transition_step`: the front and back transitions' altitude law, z force and
  pusher ramp; :func:`mc_z_force_step`: the altitude law and z force of both (and of
  FIXED_WING while the lift rotors ramp down).
- :func:`position_hold_step`: the multicopter position hold of
  :meth:`.outer_loops.OuterLoops._position_hold` (brake, lock, then a P position / P velocity
  cascade to tilt references), the same expressions in the same order.

Written without ``fastmath`` (no reassociation, no contraction): IEEE double precision as
CPython evaluates the same expressions.
"""

from __future__ import annotations

import math

import numba

from vtolftc.firmware_sim.autopilot.altitude import fw_altitude_law, mc_altitude_law

__all__ = ["aero_lift_drag", "fw_longitudinal_step", "hypot2", "mc_hold_step",
           "mc_transition_step", "mc_z_force_step", "outer_aero_step", "position_hold_step",
           "pusher_force"]

_VELTKAMP = 134217729.0  # 2**27 + 1


@numba.njit(cache=True)
def _split(x: float) -> tuple[float, float]:  # pragma: no cover - compiled
    """Dekker's split of ``x`` into two halves of 26 bits (hi + lo == x exactly)."""
    t = x * _VELTKAMP
    hi = t - (t - x)
    return hi, x - hi


@numba.njit(cache=True)
def _mul(x: float, y: float) -> tuple[float, float]:  # pragma: no cover - compiled
    """Dekker's exact product: ``x * y == z + zz``."""
    xh, xl = _split(x)
    yh, yl = _split(y)
    p = xh * yh
    q = xh * yl + xl * yh
    z = p + q
    zz = p - z + q + xl * yl
    return z, zz


@numba.njit(cache=True)
def _norm2(a: float, b: float, mx: float) -> float:  # pragma: no cover - compiled
    """``vector_norm`` of (a, b) >= 0, finite, ``mx = max(a, b) > 0``, normal range."""
    _, max_e = math.frexp(mx)
    scale = math.ldexp(1.0, -max_e)
    csum = 1.0
    frac1 = 0.0
    frac2 = 0.0
    x = a * scale
    hi, lo = _mul(x, x)
    s = csum + hi
    frac2 += (csum - s) + hi
    csum = s
    frac1 += lo
    x = b * scale
    hi, lo = _mul(x, x)
    s = csum + hi
    frac2 += (csum - s) + hi
    csum = s
    frac1 += lo
    h = math.sqrt(csum - 1.0 + (frac1 + frac2))
    hi, lo = _mul(-h, h)
    s = csum + hi
    frac2 += (csum - s) + hi
    csum = s
    frac1 += lo
    x = csum - 1.0 + (frac1 + frac2)
    h += x / (2.0 * h)
    return h / scale


@numba.njit(cache=True)
def hypot2(x: float, y: float) -> float:  # pragma: no cover - compiled
    """``math.hypot(x, y)`` of CPython 3.11, bit for bit (see the module docstring)."""
    a = abs(x)
    b = abs(y)
    if math.isinf(a) or math.isinf(b):
        return math.inf
    if math.isnan(a) or math.isnan(b):
        return math.nan
    mx = b if b > a else a
    if mx == 0.0:
        return mx
    _, max_e = math.frexp(mx)
    if max_e < -1023:
        # ldexp(1.0, -max_e) would overflow: 3.11 divides by the maximum instead (a plain
        # compensated sum of the squared ratios; 3.12 changed this branch)
        csum = 1.0
        frac = 0.0
        x = a / mx
        x = x * x
        old = csum
        csum += x
        frac += (old - csum) + x
        x = b / mx
        x = x * x
        old = csum
        csum += x
        frac += (old - csum) + x
        return mx * math.sqrt(csum - 1.0 + frac)
    return _norm2(a, b, mx)


@numba.njit(cache=True)
def position_hold_step(pos, vel, hold_ne, ref, locked, kp, vmax, kv, g, yaw,
                       tilt_max_deg):  # pragma: no cover - compiled
    """One step of the multicopter position hold; writes ``ref[0]`` (roll) and ``ref[1]``
    (pitch) [rad] and returns whether the hold is locked afterwards.

    Parameters
    ----------
    pos, vel : ndarray
        NED position [m] and velocity [m/s] (the first two entries are read).
    hold_ne : ndarray, shape (2,)
        the held north/east position [m]; set to ``pos[:2]`` when the hold locks.
    ref : ndarray, shape (3,)
        the attitude reference [rad]; entries 0 and 1 written.
    locked : bool
        the hold is locked (else it brakes, and locks below 0.5 m/s).
    kp, vmax, kv : float
        ``MPC_XY_P`` [1/s], ``MPC_XY_VEL_MAX`` [m/s], ``MPC_XY_VEL_P_ACC`` [1/s].
    g : float
        gravity [m/s^2].
    yaw : float
        heading [rad].
    tilt_max_deg : float
        ``MPC_TILTMAX_AIR`` [deg].
    """
    vn = vel[0]
    ve = vel[1]
    if not locked:
        if hypot2(vn, ve) < 0.5:
            hold_ne[0] = pos[0]
            hold_ne[1] = pos[1]
            locked = True
        vrn = 0.0
        vre = 0.0
    else:
        vrn = kp * (hold_ne[0] - pos[0])
        vre = kp * (hold_ne[1] - pos[1])
        s = hypot2(vrn, vre)
        if s > vmax:
            vrn, vre = vrn * vmax / s, vre * vmax / s
    an = kv * (vrn - vn)
    ae = kv * (vre - ve)
    a_fwd = math.cos(yaw) * an + math.sin(yaw) * ae
    a_right = -math.sin(yaw) * an + math.cos(yaw) * ae
    tmax = tilt_max_deg * (math.pi / 180.0)  # math.radians
    lo = -tmax
    x = -math.atan2(a_fwd, g)
    x = lo if lo > x else x
    ref[1] = tmax if tmax < x else x  # min(max(x, -tmax), tmax)
    x = math.atan2(a_right, g)
    x = lo if lo > x else x
    ref[0] = tmax if tmax < x else x
    return locked


@numba.njit(cache=True)
def aero_lift_drag(wing, V, alpha):  # pragma: no cover - compiled
    """Nominal wing lift and drag [N] at airspeed ``V`` [m/s] and angle of attack ``alpha``
    [rad]: linear lift clipped at ``CL_max``, parabolic drag; 0 below 1 m/s. ``wing``: air
    density [kg/m^3], area [m^2], ``CL0``, ``CL_alpha`` [1/rad], ``CL_max``, ``CD0``, induced
    drag factor (the airframe's nominal values)."""
    if V < 1.0:
        return 0.0, 0.0
    qS = 0.5 * wing[0] * V * V * wing[1]
    cl = wing[2] + wing[3] * alpha
    cl_max = wing[4]
    lo = -cl_max
    cl = lo if lo > cl else cl
    cl = cl_max if cl_max < cl else cl  # min(max(cl, -cl_max), cl_max)
    cd = wing[5] + wing[6] * cl * cl
    return qS * cl, qS * cd


@numba.njit(cache=True)
def outer_aero_step(roll, pitch, ub, wb, V, alpha_limit, wing, out):  # pragma: no cover
    """The outer loops' per-step aerodynamics (:meth:`.outer_loops.OuterLoops.update`).

    Writes ``out``: the tilt factor ``max(0.5, cos(roll) cos(pitch))``, the angle of attack
    ``atan2(wb, ub)`` [rad] (0 unless ``ub`` > 1 m/s), the nominal lift and drag [N] at
    ``min(alpha, alpha_limit)`` (``alpha_limit`` +inf but in a degraded-lift front
    transition) and their body z force ``-lift cos(alpha) - drag sin(alpha)`` [N].
    ``roll``, ``pitch`` [rad]; ``ub``, ``wb`` body-axis velocity x and z [m/s]; ``V``
    airspeed [m/s]; ``wing`` as :func:`aero_lift_drag`.
    """
    c = math.cos(roll) * math.cos(pitch)
    out[0] = c if c > 0.5 else 0.5  # max(0.5, c)
    alpha = math.atan2(wb, ub) if ub > 1.0 else 0.0
    a = alpha_limit if alpha_limit < alpha else alpha  # min(alpha, alpha_limit)
    lift, drag = aero_lift_drag(wing, V, a)
    out[1] = alpha
    out[2] = lift
    out[3] = drag
    out[4] = -lift * math.cos(alpha) - drag * math.sin(alpha)


@numba.njit(cache=True)
def pusher_force(pushers, V):  # pragma: no cover - compiled
    """Nominal total pusher thrust [N] at full command and airspeed ``V`` [m/s]; ``pushers``
    holds each pusher's static thrust [N] and zero-thrust axial speed [m/s] in turn."""
    tot = 0.0
    for i in range(0, pushers.size, 2):
        x = 1.0 - V / pushers[i + 1]
        x = x if x > 0.0 else 0.0  # max(0.0, x)
        tot += pushers[i] * (x if x < 1.25 else 1.25)  # min(1.25, x)
    return tot


@numba.njit(cache=True)
def fw_longitudinal_step(pushers, c, h_ref, h, v_up, V, pitch, alpha, lift, drag, fw_integral,
                         kp_alt, kp_vz, ki_vz, climb_max, sink_max, pitch_min_deg,
                         pitch_max_deg, v_sp, kp_v, ki_v, airspeed_int):  # pragma: no cover
    """The fixed-wing altitude (pitch) and airspeed (pusher force) loops of one step
    (:meth:`.outer_loops.OuterLoops._outer_fw`).

    ``pushers`` as :func:`pusher_force`; ``c``: mass [kg], gravity [m/s^2], the outer loops'
    period and the altitude hold's [s]. ``h_ref``, ``h`` [m], ``v_up`` [m/s], ``V`` airspeed
    [m/s], ``pitch``, ``alpha`` [rad], nominal ``lift``, ``drag`` [N]; the altitude law's
    integral [rad] and gains (``FW_ALT_P``, ``FW_VZ_P``, ``FW_VZ_I``, ``FW_CLMB_MAX``,
    ``FW_SINK_MAX``, ``FW_P_LIM_MIN`` / ``MAX`` [deg]); the airspeed setpoint [m/s], the
    airspeed hold's gains (``FW_AIRSPD_P``, ``FW_AIRSPD_I``) and integral [m/s^2].

    Returns ``(pitch_ref, fw_integral, v_up_ref, airspeed_int, fx)``: the pitch reference
    [rad], the altitude law's new integral and climb-rate reference, the airspeed hold's new
    integral and the pushers' force command [N] (``min(max(fx_cmd, 0), fx_max)``).
    """
    mass = c[0]
    g = c[1]
    pitch_ref, fw_integral, v_ref = fw_altitude_law(
        fw_integral, c[3], h_ref, h, v_up, kp_alt, kp_vz, ki_vz, climb_max, sink_max,
        pitch_min_deg * (math.pi / 180.0), pitch_max_deg * (math.pi / 180.0))
    fx_max = pusher_force(pushers, V)
    e_v = v_sp - V
    a_x = kp_v * e_v + airspeed_int
    fx_cmd = drag * math.cos(alpha) - lift * math.sin(alpha) + mass * (
        a_x + g * math.sin(pitch))
    if not ((fx_cmd >= fx_max and e_v > 0) or (fx_cmd <= 0.0 and e_v < 0)):
        x = airspeed_int + ki_v * e_v * c[2]
        x = -3.0 if x < -3.0 else x
        airspeed_int = 3.0 if x > 3.0 else x  # min(max(x, -3.0), 3.0)
    x = 0.0 if fx_cmd < 0.0 else fx_cmd
    return pitch_ref, fw_integral, v_ref, airspeed_int, (fx_max if fx_max < x else x)


@numba.njit(cache=True)
def mc_z_force_step(v, c, integral, h_ref, h, v_up, kp_z, kp_vz, ki_vz, v_max_up, v_max_dn,
                    override, use_override, cos_tilt, fz_aero):  # pragma: no cover - compiled
    """The multicopter altitude law (:func:`.altitude.mc_altitude_law` with the hold's
    constants from ``c``, see :func:`mc_hold_step`) and the body z force it asks of the lift
    rotors, ``v[0] = -m (g + a_up) / cos_tilt - fz_aero`` [N]; returns ``(integral,
    v_up_ref)``."""
    a_up, integral, v_ref = mc_altitude_law(integral, c[4], c[5], c[6], c[7], h_ref, h, v_up,
                                            kp_z, kp_vz, ki_vz, v_max_up, v_max_dn, override,
                                            use_override)
    v[0] = -c[0] * (c[1] + a_up) / cos_tilt - fz_aero
    return integral, v_ref


@numba.njit(cache=True)
def mc_transition_step(v, ref, c, pushers, integral, h_ref, h, v_up, kp_z, kp_vz, ki_vz,
                       v_max_up, v_max_dn, cos_tilt, fz_aero, front, ramp, slew, thr,
                       V):  # pragma: no cover - compiled
    """The outer loops of FRONT_TRANSITION (``front``) and BACK_TRANSITION in one call
    (:meth:`.outer_loops.OuterLoops._outer_mc`): the altitude law and z force
    (:func:`mc_z_force_step`, no climb-rate override), roll and pitch references 0
    (``ref[0:2]``) and the pushers' force ``v[1]`` [N]: in the front transition
    ``thr * ramp * pusher_force(pushers, V)`` with the ramp advanced by ``slew`` [1/s] over
    one period (``c[2]``) up to 1 (``VT_PSHER_SLEW``, ``VT_F_TRANS_THR``), else 0. Returns
    ``(integral, v_up_ref, ramp)``."""
    integral, v_ref = mc_z_force_step(v, c, integral, h_ref, h, v_up, kp_z, kp_vz, ki_vz,
                                      v_max_up, v_max_dn, 0.0, False, cos_tilt, fz_aero)
    ref[0] = 0.0
    ref[1] = 0.0
    fx = 0.0
    if front:
        r = ramp + slew * c[2]
        ramp = r if r < 1.0 else 1.0  # min(1.0, r)
        fx = thr * ramp * pusher_force(pushers, V)
    v[1] = fx
    return integral, v_ref, ramp


@numba.njit(cache=True)
def mc_hold_step(pos, vel, hold_ne, ref, v, c, locked, integral, h_ref, h, v_up, kp_z, kp_vz,
                 ki_vz, v_max_up, v_max_dn, override, use_override, cos_tilt, fz_aero, kp_xy,
                 vmax_xy, kv_xy, yaw, tilt_max_deg):  # pragma: no cover - compiled
    """The multicopter outer loops of TAKEOFF, HOVER and LAND in one call
    (:meth:`.outer_loops.OuterLoops._outer_mc`): the altitude law
    (:func:`.altitude.mc_altitude_law`) and the body z force ``v[0] = -m (g + a_up) /
    cos_tilt - fz_aero`` [N], the position hold (:func:`position_hold_step`, writing
    ``ref[0:2]`` and ``hold_ne``) and no pusher force (``v[1] = 0``).

    ``c``: mass [kg], gravity [m/s^2], the loops' period, the fixed-wing altitude hold's
    period, the multicopter altitude hold's period [s] and its ``a_up_max``, ``a_dn_max``,
    ``i_limit`` [m/s^2]. The altitude law's integral and arguments and the position hold's
    (``MPC_XY_P``, ``MPC_XY_VEL_MAX``, ``MPC_XY_VEL_P_ACC``, ``yaw``, ``MPC_TILTMAX_AIR``) as
    in those functions. Returns ``(locked, integral, v_up_ref)``.
    """
    integral, v_ref = mc_z_force_step(v, c, integral, h_ref, h, v_up, kp_z, kp_vz, ki_vz,
                                      v_max_up, v_max_dn, override, use_override, cos_tilt,
                                      fz_aero)
    locked = position_hold_step(pos, vel, hold_ne, ref, locked, kp_xy, vmax_xy, kv_xy, c[1],
                                yaw, tilt_max_deg)
    v[1] = 0.0
    return locked, integral, v_ref

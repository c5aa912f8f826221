"""Nonlinear 6-DOF equations of motion of a dual-system VTOL, compiled with numba.

State vector ``x`` (float64, length ``13 + n_actuators``):

====== ============================================================================
index  meaning
====== ============================================================================
0:3    position of the CG in NED (m), origin on the ground (z = 0), z positive down
3:6    velocity of the CG in NED (m/s)
6:10   attitude quaternion body FRD -> NED, scalar first (w, x, y, z)
10:13  angular velocity in body FRD (rad/s): p, q, r
13:    actuator positions, normalised: rotors and pushers 0..1 of max thrust, surfaces
       -1..1 of max deflection (positive: trailing edge down for ailerons and elevator,
       trailing edge left for rudders)
====== ============================================================================

Forces: gravity; each rotor's thrust along its axis at its position, falling linearly with
axial inflow, and its reaction torque; wing/tail aerodynamics (lift with a rounded stall peak
blended into flat-plate post-stall, parabolic drag, side force, the airspeed-dependent
derivatives C_lp, C_mq, C_malpha, C_nr, C_nbeta interpolated from tables, control-surface
moments scaling with dynamic pressure); landing-gear spring-dampers against flat ground.

Sideways flow. The wing and the horizontal tail see only the air velocity in the body x-z
(chordwise) plane, the component normal to the span, as Gazebo's LiftDrag plugin (PX4 SITL)
does with its ``velInLDPlane``: their terms use ``qbar_xz = 0.5 rho (u^2 + w^2)`` and the rate
factor ``0.25 rho V_xz S`` with ``V_xz = sqrt(u^2 + w^2)`` (u, w: body FRD air velocity, m/s),
with ``alpha = atan2(w, u)`` as before. These are lift and drag (CL(alpha), CL_de, CL_q, CD),
the pitching moment (Cm0, C_malpha, Cm_de, C_mq), the aileron terms (CY_da, Cl_da, Cn_da: the
ailerons are part of the wing) and the rate terms that come from the wing's lift across the
span (C_lp, Cl_r, Cn_p). Flow along the span (v alone) then makes no wing lift, drag or pitch
moment, and a deflected aileron no force; without this a hover in a crosswind had
``alpha = atan2(0, 0) = 0`` (CL0 at the full sideways dynamic pressure) at level attitude and
+-90 deg (flat plate) at any roll. The fuselage and fin terms keep the full dynamic pressure
``0.5 rho Va^2`` and ``0.25 rho Va S`` (Va the whole air speed), because sideways flow is what
drives them: side force CY_beta, dihedral Cl_beta and weathercock C_nbeta (with beta =
asin(v / Va)), the rudder (CY_dr, Cl_dr, Cn_dr; its chordwise plane x-y contains the sideways
flow) and the fin's rate terms (CY_p, CY_r, C_nr). The airspeed tables are read at Va. With
v = 0 every term is what it was.
Actuators: first-order lag with rate and position limits. Faults enter through ``eff``
(effectiveness multiplier per actuator, applied to the physical output) and ``stuck`` (the
actuator position freezes). Integration: classical RK4 at a fixed step, the quaternion
renormalised after each step.

Everything here takes flat arrays (see :func:`pack`) so that one compiled step costs a few
microseconds; the Python-level API is :class:`vtolftc.firmware_sim.vehicle.model.Vehicle`.
"""

from __future__ import annotations

import math
from typing import NamedTuple

import numpy as np
from numba import njit

from vtolftc.airframe.loader import Airframe
from vtolftc.base.nrt import borrowed, keep_alive

N_RIGID = 13

# Physics switches (bit mask) for verification runs; the default is everything on.
GRAVITY = 1
AERODYNAMICS = 2
GROUND = 4
PROPULSION = 8
ALL_PHYSICS = GRAVITY | AERODYNAMICS | GROUND | PROPULSION

# An actuator position (normalised) smaller in magnitude than this is set to exactly zero at
# the end of each integration step. A first-order lag commanded to zero decays geometrically
# and, in float64, ends on a subnormal number that rounding holds there forever (an idle lift
# rotor in cruise: x = 1.2e-322 about 35 s after the transition); arithmetic on subnormals
# takes the CPU's microcode path, which made the physics step 2.7x slower after a minute of
# cruise (case 1: 12 -> 32 us per control step). 1e-200 is far below anything that can reach
# a force or moment (thrust = tmax * x: 1e-198 N against sums of order 1 N, below their last
# bit) and far above the subnormal range (products of it with the airframe's coefficients
# stay normal), so the flights' commands and rigid-body states are bit for bit what they were.
ACT_ZERO = 1e-200

# Indices into the packed scalar-parameter vector P.
(P_MASS, P_G, P_RHO, P_S, P_B, P_C, P_CL0, P_CLA, P_CLMAX, P_STALL_RND, P_STALL_M, P_CLQ,
 P_CLDE, P_CD0, P_K, P_CYB, P_CYP, P_CYR, P_CYDA, P_CYDR, P_CLB, P_CLR, P_CLDA, P_CLDR,
 P_CM0, P_CMDE, P_CNP, P_CNDA, P_CNDR, P_ALIN, P_ASAT, P_DEFL, P_GK, P_GC, P_GF,
 P_GMU, P_ARM_X, P_ARM_Y, P_ARM_Z, P_NAIL, P_NRUD) = range(41)
N_PARAMS = 41
# P_NAIL, P_NRUD: number of ailerons and of rudders (1 or 2; surfaces in the order ailerons,
# elevator, rudders). One surface gives the whole aircraft derivative, each of two half.
# P_ARM_*: position of the aerodynamic reference point relative to the CG, body FRD (m). Zero
# for the airframe as designed (the coefficients are about the CG); a perturbed CG (see
# :func:`perturb`) moves it, and the aerodynamic force then also acts through this arm.

# Derivative table rows.
T_CLP, T_CMQ, T_CMA, T_CNR, T_CNB = range(5)


class Packed(NamedTuple):
    """An airframe as the flat arrays the compiled kernels take."""

    P: np.ndarray            # (N_PARAMS,) scalar parameters
    J: np.ndarray            # (3, 3) inertia, body FRD, kg m^2
    Jinv: np.ndarray         # (3, 3)
    rotor_pos: np.ndarray    # (n_rotors, 3) m
    rotor_axis: np.ndarray   # (n_rotors, 3) thrust direction
    rotor_torque: np.ndarray  # (n_rotors, 3) reaction torque per newton of thrust, m
    rotor_tmax: np.ndarray   # (n_rotors,) N
    rotor_inv_v0: np.ndarray  # (n_rotors,) 1 / zero-thrust axial speed, s/m
    act_tau: np.ndarray      # (n_act,) s
    act_rate: np.ndarray     # (n_act,) normalised units per s
    act_min: np.ndarray      # (n_act,)
    act_max: np.ndarray      # (n_act,)
    tab_v: np.ndarray        # (n_tab,) m/s
    tab: np.ndarray          # (5, n_tab)
    gear: np.ndarray         # (n_gear, 3) m


def pack(af: Airframe) -> Packed:
    """Flatten an :class:`Airframe` for the compiled kernels."""
    w = af.wing
    P = np.zeros(N_PARAMS)
    P[P_MASS] = af.mass_kg
    P[P_G] = af.gravity_m_s2
    P[P_RHO] = af.air_density_kg_m3
    P[P_S], P[P_B], P[P_C] = w.area_m2, w.span_m, w.chord_m
    P[P_CL0], P[P_CLA], P[P_CLMAX] = w.CL0, w.CL_alpha, w.CL_max
    P[P_STALL_RND], P[P_STALL_M] = w.stall_rounding_rad, w.post_stall_blend_per_rad
    P[P_CLQ], P[P_CLDE], P[P_CD0], P[P_K] = w.CL_q, w.CL_de, w.CD0, w.induced_drag_factor
    P[P_CYB], P[P_CYP], P[P_CYR], P[P_CYDA], P[P_CYDR] = w.CY_beta, w.CY_p, w.CY_r, w.CY_da, w.CY_dr
    P[P_CLB], P[P_CLR], P[P_CLDA], P[P_CLDR] = w.Cl_beta, w.Cl_r, w.Cl_da, w.Cl_dr
    P[P_CM0], P[P_CMDE] = w.Cm0, w.Cm_de
    P[P_CNP], P[P_CNDA], P[P_CNDR] = w.Cn_p, w.Cn_da, w.Cn_dr
    P[P_ALIN], P[P_ASAT] = w.moment_angle_linear_rad, w.moment_angle_saturation_rad
    P[P_DEFL] = af.surfaces.max_deflection_rad
    P[P_NAIL] = sum(n.startswith("aileron") for n in af.surfaces.names)
    P[P_NRUD] = sum(n.startswith("rudder") for n in af.surfaces.names)
    g = af.landing_gear
    P[P_GK], P[P_GC], P[P_GF], P[P_GMU] = (
        g.stiffness_N_m, g.damping_N_s_m, g.friction_N_s_m, g.friction_coefficient)

    rotors = af.rotors
    n_act = af.n_actuators
    act_tau = np.empty(n_act)
    act_rate = np.empty(n_act)
    act_min = np.empty(n_act)
    act_max = np.empty(n_act)
    for i, r in enumerate(rotors):
        act_tau[i], act_rate[i], act_min[i], act_max[i] = (
            r.time_constant_s, r.rate_limit_per_s, 0.0, 1.0)
    s = af.surfaces
    for i in range(len(rotors), n_act):
        act_tau[i] = s.time_constant_s
        act_rate[i] = s.rate_limit_rad_s / s.max_deflection_rad
        act_min[i], act_max[i] = -1.0, 1.0
    d = af.derivatives
    return Packed(
        P=P,
        J=np.array(af.inertia_kg_m2, dtype=float),
        Jinv=np.linalg.inv(af.inertia_kg_m2),
        rotor_pos=np.array([r.position_m for r in rotors]),
        rotor_axis=np.array([r.thrust_axis for r in rotors]),
        rotor_torque=np.array([-r.torque_to_thrust_m * r.spin_axis for r in rotors]),
        rotor_tmax=np.array([r.max_thrust_N for r in rotors]),
        rotor_inv_v0=np.array([1.0 / r.zero_thrust_axial_speed_m_s for r in rotors]),
        act_tau=act_tau, act_rate=act_rate, act_min=act_min, act_max=act_max,
        tab_v=np.array(d.airspeed_m_s, dtype=float),
        tab=np.array([d.C_lp, d.C_mq, d.C_malpha, d.C_nr, d.C_nbeta], dtype=float),
        gear=np.array(af.landing_gear.points_m, dtype=float),
    )


def perturb(pk: Packed, mass_scale: float = 1.0,
            inertia_scale: tuple[float, float, float] = (1.0, 1.0, 1.0),
            cg_offset_m: tuple[float, float, float] = (0.0, 0.0, 0.0)) -> Packed:
    """A copy of ``pk`` describing the physical vehicle off its design values.

    ``mass_scale`` multiplies the mass; ``inertia_scale`` multiplies the rows and columns of
    the inertia tensor (``J' = S J S`` with ``S = diag(sqrt(s))``, so the diagonal scales by
    ``s`` and the products of inertia consistently); ``cg_offset_m`` moves the CG by ``d``
    (body FRD, m) from the design point: every rotor and landing-gear point moves by ``-d``
    relative to the CG and the aerodynamic force acts at ``-d`` (``P_ARM_*``). The state's
    position then tracks the perturbed CG. The identity perturbation returns equal arrays.
    """
    s = np.asarray(inertia_scale, dtype=float)
    d = np.asarray(cg_offset_m, dtype=float)
    if not (math.isfinite(mass_scale) and mass_scale > 0.0):
        raise ValueError(f"mass_scale = {mass_scale!r}: expected a positive factor")
    if s.shape != (3,) or not np.all(np.isfinite(s)) or not np.all(s > 0.0):
        raise ValueError(f"inertia_scale = {inertia_scale!r}: expected three positive factors")
    if d.shape != (3,) or not np.all(np.isfinite(d)):
        raise ValueError(f"cg_offset_m = {cg_offset_m!r}: expected three finite numbers (m)")
    P = pk.P.copy()
    P[P_MASS] = pk.P[P_MASS] * mass_scale
    P[P_ARM_X], P[P_ARM_Y], P[P_ARM_Z] = -d
    root = np.sqrt(s)
    J = pk.J * np.outer(root, root) if np.any(s != 1.0) else pk.J.copy()
    return pk._replace(
        P=P, J=J, Jinv=np.linalg.inv(J) if np.any(s != 1.0) else pk.Jinv.copy(),
        rotor_pos=pk.rotor_pos - d, gear=pk.gear - d)


# --------------------------------------------------------------------------------------------
# Small compiled helpers
# --------------------------------------------------------------------------------------------


@njit(cache=True, fastmath=False)
def quat_to_dcm_entries(q0: float, q1: float, q2: float,
                        q3: float) -> tuple[float, float, float, float, float, float, float,
                                            float, float]:
    """Rotation matrix body -> NED of a unit quaternion (w, x, y, z) as its nine entries
    ``(R00, R01, R02, R10, R11, R12, R20, R21, R22)`` (row-major): no array to allocate."""
    return (1.0 - 2.0 * (q2 * q2 + q3 * q3), 2.0 * (q1 * q2 - q0 * q3),
            2.0 * (q1 * q3 + q0 * q2), 2.0 * (q1 * q2 + q0 * q3),
            1.0 - 2.0 * (q1 * q1 + q3 * q3), 2.0 * (q2 * q3 - q0 * q1),
            2.0 * (q1 * q3 - q0 * q2), 2.0 * (q2 * q3 + q0 * q1),
            1.0 - 2.0 * (q1 * q1 + q2 * q2))


@njit(cache=True, fastmath=False)
def quat_to_dcm(q0: float, q1: float, q2: float, q3: float, R: np.ndarray) -> None:
    """Rotation matrix body -> NED of a unit quaternion (w, x, y, z), written into R."""
    (R[0, 0], R[0, 1], R[0, 2], R[1, 0], R[1, 1], R[1, 2], R[2, 0], R[2, 1],
     R[2, 2]) = quat_to_dcm_entries(q0, q1, q2, q3)


@njit(cache=True)
def table_interp(v: float, tab_v: np.ndarray, row: np.ndarray) -> float:
    """Linear interpolation in a table over airspeed, clamped outside."""
    n = tab_v.shape[0]
    if v <= tab_v[0]:
        return row[0]
    if v >= tab_v[n - 1]:
        return row[n - 1]
    i = 1
    while tab_v[i] < v:
        i += 1
    f = (v - tab_v[i - 1]) / (tab_v[i] - tab_v[i - 1])
    return row[i - 1] + f * (row[i] - row[i - 1])


@njit(cache=True)
def table_bracket(v: float, tab_v: np.ndarray) -> tuple[int, float]:
    """Where :func:`table_interp` reads ``v`` in ``tab_v``: ``(i, f)`` with ``i`` = 0 below
    the table (the first entry), ``-1`` above it (the last), else the interval's upper index
    and ``f`` its fraction, computed as :func:`table_interp` does (so that
    :func:`table_at` gives its bits for every row of one table: one search, one division)."""
    n = tab_v.shape[0]
    if v <= tab_v[0]:
        return 0, 0.0
    if v >= tab_v[n - 1]:
        return -1, 0.0
    i = 1
    while tab_v[i] < v:
        i += 1
    return i, (v - tab_v[i - 1]) / (tab_v[i] - tab_v[i - 1])


@njit(cache=True)
def table_at(i: int, f: float, row: np.ndarray) -> float:
    """:func:`table_interp` of one row at :func:`table_bracket`'s ``(i, f)``."""
    if i == 0:
        return row[0]
    if i < 0:
        return row[row.shape[0] - 1]
    return row[i - 1] + f * (row[i] - row[i - 1])


@njit(cache=True)
def saturate_angle(a: float, a_lin: float, a_sat: float) -> float:
    """Identity for |a| <= a_lin, then a smooth (C1) approach to +-a_sat."""
    m = abs(a)
    if m <= a_lin:
        return a
    w = a_sat - a_lin
    return math.copysign(a_lin + w * math.tanh((m - a_lin) / w), a)


# inlined: its sin / cos of alpha are then the caller's (one sincos a call, the same values)
@njit(cache=True, inline="always")
def lift_drag_coefficients(alpha: float, P: np.ndarray) -> tuple[float, float]:
    """CL(alpha), CD(alpha) of the wing (no control or rate terms).

    Attached flow: CL0 + CL_alpha*alpha up to a rounded peak of exactly CL_max, falling
    beyond; blended with a sigmoid into a flat plate (2 sin^2 a cos a) past the stall.
    """
    cl0 = P[P_CL0]
    cla = P[P_CLA]
    clmax = P[P_CLMAX]
    d = P[P_STALL_RND]
    a_pk = (clmax - cl0) / cla + 0.5 * d
    if alpha <= a_pk - d:
        cl_att = cl0 + cla * alpha
    elif alpha <= a_pk + d:
        cl_att = clmax - cla * (alpha - a_pk) ** 2 / (2.0 * d)
    else:
        cl_att = clmax - 0.5 * cla * d - cla * (alpha - a_pk - d)
    a0 = a_pk + 4.0 * d  # far enough past the peak that CL_max is reached to 1e-4
    M = P[P_STALL_M]
    e1 = math.exp(min(-M * (alpha - a0), 600.0))
    e2 = math.exp(min(M * (alpha + a0), 600.0))
    sigma = (1.0 + e1 + e2) / ((1.0 + e1) * (1.0 + e2))
    sa = math.sin(alpha)
    ca = math.cos(alpha)
    cl_fp = 2.0 * math.copysign(1.0, alpha) * sa * sa * ca
    cl = (1.0 - sigma) * cl_att + sigma * cl_fp
    cd = P[P_CD0] + (1.0 - sigma) * P[P_K] * cl_att * cl_att + sigma * 2.0 * sa * sa
    return cl, cd


# --------------------------------------------------------------------------------------------
# Equations of motion
# --------------------------------------------------------------------------------------------


@njit(cache=True)
def actuator_rates(x, u, stuck, atau, arate, amin, amax, dx):  # pragma: no cover - compiled
    """The actuator rows of :func:`derivatives` (``dx[N_RIGID:]``): first-order actuators
    with rate and position limits; stuck ones hold their position. The only rows that
    depend on the commands ``u``."""
    for i in range(atau.shape[0]):
        k = N_RIGID + i
        if stuck[i]:
            dx[k] = 0.0
        else:
            target = min(amax[i], max(amin[i], u[i]))
            rate = (target - x[k]) / atau[i]
            dx[k] = min(arate[i], max(-arate[i], rate))


# _nrt=False: no reference counting of the 22 arrays at each of the 16 calls per control step
# (the function allocates nothing; see vtolftc.base.nrt); the same arithmetic
@njit(cache=True, _nrt=False)
def derivatives(x, u, eff, stuck, P, J, Jinv, rpos, raxis, rtorque, rtmax, rinv_v0,
                atau, arate, amin, amax, tab_v, tab, gear, wind, flags, dx, fm):
    """Time derivative of the state ``x`` under actuator commands ``u``, written into ``dx``.

    ``fm`` receives the body-frame non-gravitational force (0:3, N) and moment (3:6, N m),
    plus airspeed (6), alpha (7) and beta (8): what the sensors and tests need.
    """
    nr = rtmax.shape[0]
    q0, q1, q2, q3 = x[6], x[7], x[8], x[9]
    p, q, r = x[10], x[11], x[12]
    # the rotation's entries as scalars (no 3x3 array allocated 17 times per control step)
    R00, R01, R02, R10, R11, R12, R20, R21, R22 = quat_to_dcm_entries(q0, q1, q2, q3)

    # Air-relative velocity in body axes.
    vr0 = x[3] - wind[0]
    vr1 = x[4] - wind[1]
    vr2 = x[5] - wind[2]
    ub = R00 * vr0 + R10 * vr1 + R20 * vr2
    vb = R01 * vr0 + R11 * vr1 + R21 * vr2
    wb = R02 * vr0 + R12 * vr1 + R22 * vr2
    Va = math.sqrt(ub * ub + vb * vb + wb * wb)

    Fx = 0.0
    Fy = 0.0
    Fz = 0.0
    Mx = 0.0
    My = 0.0
    Mz = 0.0
    alpha = 0.0
    beta = 0.0
    if Va > 1e-6:
        alpha = math.atan2(wb, ub)
        sb = vb / Va
        beta = math.asin(min(1.0, max(-1.0, sb)))

    # Propulsion: lift rotors and pushers.
    if flags & PROPULSION:
        for i in range(nr):
            xa = x[N_RIGID + i]
            er = eff[i] * rtmax[i]
            if xa == 0.0 and math.isfinite(er):
                # a rotor at exactly zero (idle lift rotors in cruise, pushers in hover):
                # T = er * xa * fade is +-0 (fade is in [0, 1.25]), so is every term it
                # adds below, and adding +-0 to a sum that started at +0.0 (so is never
                # -0.0: in round-to-nearest a sum is -0.0 only if both terms are) changes
                # no bit of it, NaN and inf included
                continue
            ax0 = raxis[i, 0]
            ax1 = raxis[i, 1]
            ax2 = raxis[i, 2]
            v_axial = ub * ax0 + vb * ax1 + wb * ax2
            fade = 1.0 - v_axial * rinv_v0[i]
            fade = min(1.25, max(0.0, fade))
            T = er * xa * fade  # eff[i] * rtmax[i] * x[N_RIGID + i] * fade, left to right
            fx = T * ax0
            fy = T * ax1
            fz = T * ax2
            Fx += fx
            Fy += fy
            Fz += fz
            rx = rpos[i, 0]
            ry = rpos[i, 1]
            rz = rpos[i, 2]
            Mx += ry * fz - rz * fy + T * rtorque[i, 0]
            My += rz * fx - rx * fz + T * rtorque[i, 1]
            Mz += rx * fy - ry * fx + T * rtorque[i, 2]

    # Aerodynamics.
    if flags & AERODYNAMICS and Va > 1e-6:
        rho = P[P_RHO]
        S = P[P_S]
        b = P[P_B]
        c = P[P_C]
        # Whole flow (fuselage, fin, rudder) and chordwise x-z flow (wing, tailplane, ailerons):
        # see the module docstring, "Sideways flow".
        qbar = 0.5 * rho * Va * Va
        k_rate = 0.25 * rho * Va * S  # multiplies C_xp * (b or c)^2 * rate
        v_xz2 = ub * ub + wb * wb
        qbar_xz = 0.5 * rho * v_xz2
        k_xz = 0.25 * rho * math.sqrt(v_xz2) * S
        defl = P[P_DEFL]
        s0 = nr
        d_al = eff[s0] * x[N_RIGID + s0] * defl
        if P[P_NAIL] == 2.0:
            d_ar = eff[s0 + 1] * x[N_RIGID + s0 + 1] * defl
            d_a = 0.5 * (d_al - d_ar)
            s0 += 2
        else:  # one aileron: positive = trailing edge down on the left (rolls right)
            d_a = d_al
            s0 += 1
        d_e = eff[s0] * x[N_RIGID + s0] * defl
        d_rl = eff[s0 + 1] * x[N_RIGID + s0 + 1] * defl
        if P[P_NRUD] == 2.0:
            d_rr = eff[s0 + 2] * x[N_RIGID + s0 + 2] * defl
            d_r = 0.5 * (d_rl + d_rr)
        else:
            d_r = d_rl

        cl, cd = lift_drag_coefficients(alpha, P)
        lift = qbar_xz * S * (cl + P[P_CLDE] * d_e) + k_xz * c * c * P[P_CLQ] * q
        drag = qbar_xz * S * cd
        side = (qbar * S * (P[P_CYB] * beta + P[P_CYDR] * d_r) + qbar_xz * S * P[P_CYDA] * d_a
                + k_rate * b * (P[P_CYP] * p + P[P_CYR] * r))
        sa = math.sin(alpha)
        ca = math.cos(alpha)
        fax = -drag * ca + lift * sa
        faz = -drag * sa - lift * ca
        Fx += fax
        Fy += side
        Fz += faz
        ax_ = P[P_ARM_X]
        ay_ = P[P_ARM_Y]
        az_ = P[P_ARM_Z]
        if ax_ != 0.0 or ay_ != 0.0 or az_ != 0.0:
            # aerodynamic force through the reference point, off the (perturbed) CG
            Mx += ay_ * faz - az_ * side
            My += az_ * fax - ax_ * faz
            Mz += ax_ * side - ay_ * fax

        am = saturate_angle(alpha, P[P_ALIN], P[P_ASAT])
        bm = saturate_angle(beta, P[P_ALIN], P[P_ASAT])
        # table_interp(Va, tab_v, row) of the five rows, the search and fraction done once
        ti, tf = table_bracket(Va, tab_v)
        clp = table_at(ti, tf, tab[T_CLP])
        cmq = table_at(ti, tf, tab[T_CMQ])
        cma = table_at(ti, tf, tab[T_CMA])
        cnr = table_at(ti, tf, tab[T_CNR])
        cnb = table_at(ti, tf, tab[T_CNB])
        Mx += (qbar * S * b * (P[P_CLB] * bm + P[P_CLDR] * d_r) + qbar_xz * S * b * P[P_CLDA] * d_a
               + k_xz * b * b * (clp * p + P[P_CLR] * r))
        My += (qbar_xz * S * c * (P[P_CM0] + cma * am + P[P_CMDE] * d_e)
               + k_xz * c * c * cmq * q)
        Mz += (qbar * S * b * (cnb * bm + P[P_CNDR] * d_r) + qbar_xz * S * b * P[P_CNDA] * d_a
               + k_xz * b * b * P[P_CNP] * p + k_rate * b * b * cnr * r)

    # Landing gear against flat ground at NED z = 0.
    if flags & GROUND:
        for i in range(gear.shape[0]):
            gx = gear[i, 0]
            gy = gear[i, 1]
            gz = gear[i, 2]
            pz = x[2] + R20 * gx + R21 * gy + R22 * gz
            if pz > 0.0:
                # Velocity of the contact point in NED: v + R (omega x r).
                cx = q * gz - r * gy
                cy = r * gx - p * gz
                cz = p * gy - q * gx
                pv0 = x[3] + R00 * cx + R01 * cy + R02 * cz
                pv1 = x[4] + R10 * cx + R11 * cy + R12 * cz
                pv2 = x[5] + R20 * cx + R21 * cy + R22 * cz
                normal = P[P_GK] * pz + P[P_GC] * pv2
                if normal < 0.0:
                    normal = 0.0
                fn0 = -P[P_GF] * pv0
                fn1 = -P[P_GF] * pv1
                fh = math.sqrt(fn0 * fn0 + fn1 * fn1)
                fmax = P[P_GMU] * normal
                if fh > fmax and fh > 0.0:
                    fn0 *= fmax / fh
                    fn1 *= fmax / fh
                fn2 = -normal
                # To body axes.
                fbx = R00 * fn0 + R10 * fn1 + R20 * fn2
                fby = R01 * fn0 + R11 * fn1 + R21 * fn2
                fbz = R02 * fn0 + R12 * fn1 + R22 * fn2
                Fx += fbx
                Fy += fby
                Fz += fbz
                Mx += gy * fbz - gz * fby
                My += gz * fbx - gx * fbz
                Mz += gx * fby - gy * fbx

    m = P[P_MASS]
    gdown = P[P_G] if flags & GRAVITY else 0.0
    dx[0] = x[3]
    dx[1] = x[4]
    dx[2] = x[5]
    dx[3] = (R00 * Fx + R01 * Fy + R02 * Fz) / m
    dx[4] = (R10 * Fx + R11 * Fy + R12 * Fz) / m
    dx[5] = (R20 * Fx + R21 * Fy + R22 * Fz) / m + gdown
    dx[6] = 0.5 * (-q1 * p - q2 * q - q3 * r)
    dx[7] = 0.5 * (q0 * p + q2 * r - q3 * q)
    dx[8] = 0.5 * (q0 * q - q1 * r + q3 * p)
    dx[9] = 0.5 * (q0 * r + q1 * q - q2 * p)
    # Euler's equation: J w' = M - w x (J w).
    h0 = J[0, 0] * p + J[0, 1] * q + J[0, 2] * r
    h1 = J[1, 0] * p + J[1, 1] * q + J[1, 2] * r
    h2 = J[2, 0] * p + J[2, 1] * q + J[2, 2] * r
    t0 = Mx - (q * h2 - r * h1)
    t1 = My - (r * h0 - p * h2)
    t2 = Mz - (p * h1 - q * h0)
    dx[10] = Jinv[0, 0] * t0 + Jinv[0, 1] * t1 + Jinv[0, 2] * t2
    dx[11] = Jinv[1, 0] * t0 + Jinv[1, 1] * t1 + Jinv[1, 2] * t2
    dx[12] = Jinv[2, 0] * t0 + Jinv[2, 1] * t1 + Jinv[2, 2] * t2

    actuator_rates(x, u, stuck, atau, arate, amin, amax, dx)

    fm[0] = Fx
    fm[1] = Fy
    fm[2] = Fz
    fm[3] = Mx
    fm[4] = My
    fm[5] = Mz
    fm[6] = Va
    fm[7] = alpha
    fm[8] = beta


def memo_size(nx: int, na: int) -> int:
    """Length of :func:`step_n_memo`'s memo array for ``nx`` states and ``na`` actuators."""
    return 2 + 2 * nx + na + 3



@njit(cache=True)
def _memo_valid(memo, x, eff, wind, flags):  # pragma: no cover - compiled
    """True when ``memo`` holds the rigid-body rows of ``derivatives`` at exactly (bit for
    bit) this ``x``, ``eff``, ``wind`` and ``flags`` (what those rows depend on besides the
    airframe)."""
    if memo[0] != 1.0 or memo[1] != flags:
        return False
    nx = x.shape[0]
    na = eff.shape[0]
    mb = memo.view(np.int64)
    xb = x.view(np.int64)
    for i in range(nx):
        if mb[2 + i] != xb[i]:
            return False
    o = 2 + 2 * nx
    eb = eff.view(np.int64)
    for i in range(na):
        if mb[o + i] != eb[i]:
            return False
    wb = wind.view(np.int64)
    for i in range(3):  # noqa: SIM110 (a loop, not a generator, in compiled code)
        if mb[o + na + i] != wb[i]:
            return False
    return True


@njit(cache=True)
def _memo_store(memo, x, dx, eff, wind, flags):  # pragma: no cover - compiled
    """Keep ``x``, its derivative's rigid-body rows ``dx[:N_RIGID]``, ``eff``, ``wind`` and
    ``flags`` in ``memo`` (layout: valid, flags, x (nx), dx rows (nx), eff (na), wind (3))."""
    nx = x.shape[0]
    na = eff.shape[0]
    memo[1] = flags
    for i in range(nx):
        memo[2 + i] = x[i]
    for i in range(N_RIGID):
        memo[2 + nx + i] = dx[i]
    o = 2 + 2 * nx
    for i in range(na):
        memo[o + i] = eff[i]
    for i in range(3):
        memo[o + na + i] = wind[i]
    memo[0] = 1.0


@njit(cache=True)
def step_n_memo(x, u, eff, stuck, n, dt, P, J, Jinv, rpos, raxis, rtorque, rtmax, rinv_v0,
                atau, arate, amin, amax, tab_v, tab, gear, wind, flags, fm, memo):
    """Advance ``x`` in place by ``n`` RK4 steps of ``dt`` seconds with commands ``u`` held.

    ``memo`` (length :func:`memo_size`, or empty: none) carries the last call's final
    evaluation of :func:`derivatives` (the one that leaves ``fm`` describing the final
    state) to the next call: its rigid-body rows do not depend on the commands, so when
    ``x``, ``eff``, ``wind`` and ``flags`` are bit for bit those of that evaluation (and the
    airframe the same: the caller's to guarantee, e.g. by clearing ``memo[0]`` when it
    changes) the first stage of the next step takes them and computes only the actuator
    rows (:func:`actuator_rates`) for the new commands: one evaluation of 4n + 1 fewer,
    the same numbers (the same bits).
    """
    nx = x.shape[0]
    ws = np.empty(5 * nx)  # the RK4 stages' work arrays; alive to the end (keep_alive)
    k1 = borrowed(ws[0:nx])
    k2 = borrowed(ws[nx:2 * nx])
    k3 = borrowed(ws[2 * nx:3 * nx])
    k4 = borrowed(ws[3 * nx:4 * nx])
    xt = borrowed(ws[4 * nx:])
    na = atau.shape[0]
    use_memo = memo.shape[0] > 0
    # the arrays derivatives() takes, as views without reference counting (base.nrt)
    x = borrowed(x)
    u = borrowed(u)
    eff = borrowed(eff)
    stuck = borrowed(stuck)
    P = borrowed(P)
    J = borrowed(J)
    Jinv = borrowed(Jinv)
    rpos = borrowed(rpos)
    raxis = borrowed(raxis)
    rtorque = borrowed(rtorque)
    rtmax = borrowed(rtmax)
    rinv_v0 = borrowed(rinv_v0)
    atau = borrowed(atau)
    arate = borrowed(arate)
    amin = borrowed(amin)
    amax = borrowed(amax)
    tab_v = borrowed(tab_v)
    tab = borrowed(tab)
    gear = borrowed(gear)
    wind = borrowed(wind)
    fm = borrowed(fm)
    for j in range(n):
        if j == 0 and use_memo and _memo_valid(memo, x, eff, wind, flags):
            for i in range(N_RIGID):
                k1[i] = memo[2 + nx + i]
            actuator_rates(x, u, stuck, atau, arate, amin, amax, k1)
        else:
            derivatives(x, u, eff, stuck, P, J, Jinv, rpos, raxis, rtorque, rtmax, rinv_v0,
                        atau, arate, amin, amax, tab_v, tab, gear, wind, flags, k1, fm)
        for i in range(nx):
            xt[i] = x[i] + 0.5 * dt * k1[i]
        derivatives(xt, u, eff, stuck, P, J, Jinv, rpos, raxis, rtorque, rtmax, rinv_v0,
                    atau, arate, amin, amax, tab_v, tab, gear, wind, flags, k2, fm)
        for i in range(nx):
            xt[i] = x[i] + 0.5 * dt * k2[i]
        derivatives(xt, u, eff, stuck, P, J, Jinv, rpos, raxis, rtorque, rtmax, rinv_v0,
                    atau, arate, amin, amax, tab_v, tab, gear, wind, flags, k3, fm)
        for i in range(nx):
            xt[i] = x[i] + dt * k3[i]
        derivatives(xt, u, eff, stuck, P, J, Jinv, rpos, raxis, rtorque, rtmax, rinv_v0,
                    atau, arate, amin, amax, tab_v, tab, gear, wind, flags, k4, fm)
        for i in range(nx):
            x[i] += dt / 6.0 * (k1[i] + 2.0 * k2[i] + 2.0 * k3[i] + k4[i])
        nq = math.sqrt(x[6] * x[6] + x[7] * x[7] + x[8] * x[8] + x[9] * x[9])
        for i in range(6, 10):
            x[i] /= nq
        for i in range(na):
            k = N_RIGID + i
            xa = min(amax[i], max(amin[i], x[k]))
            # an actuator that has decayed to within ACT_ZERO of zero is at zero: else an
            # idle lift rotor's lag ends on a subnormal number (~1e-322) that rounding never
            # moves, and every product with it runs on the CPU's slow path from then on
            x[k] = xa if abs(xa) >= ACT_ZERO else 0.0
    # Leave fm describing the final state.
    derivatives(x, u, eff, stuck, P, J, Jinv, rpos, raxis, rtorque, rtmax, rinv_v0,
                atau, arate, amin, amax, tab_v, tab, gear, wind, flags, k1, fm)
    if use_memo:
        _memo_store(memo, x, k1, eff, wind, flags)
    keep_alive(ws)  # the borrowed k1..xt point into ws: numba frees it after its last use


@njit(cache=True)
def step_n(x, u, eff, stuck, n, dt, P, J, Jinv, rpos, raxis, rtorque, rtmax, rinv_v0,
           atau, arate, amin, amax, tab_v, tab, gear, wind, flags, fm):
    """Advance ``x`` in place by ``n`` RK4 steps of ``dt`` seconds with commands ``u`` held
    (:func:`step_n_memo` without a memo)."""
    step_n_memo(x, u, eff, stuck, n, dt, P, J, Jinv, rpos, raxis, rtorque, rtmax, rinv_v0,
                atau, arate, amin, amax, tab_v, tab, gear, wind, flags, fm, np.empty(0))


def flatten_packed(pk: Packed) -> tuple[np.ndarray, np.ndarray]:
    """The 15 arrays of ``pk`` in one read-only float buffer, for :func:`step_n_flat`.

    Returns
    -------
    tuple
        ``(buf, layout)``: ``buf`` the arrays' values one after the other (C order);
        ``layout`` (15, 3) int64 rows ``(offset, rows, columns)`` in ``Packed``'s field order
        (a vector has one column). A copy: ``pk`` is treated as immutable (as everywhere).
    """
    parts = [np.ascontiguousarray(a, dtype=np.float64) for a in pk]
    layout = np.zeros((len(parts), 3), dtype=np.int64)
    off = 0
    for k, a in enumerate(parts):
        layout[k] = (off, a.shape[0], a.shape[1] if a.ndim == 2 else 1)
        off += a.size
    buf = np.concatenate([a.ravel() for a in parts]) if off else np.zeros(0)
    buf.setflags(write=False)
    layout.setflags(write=False)
    return buf, layout


@njit(cache=True)
def _vec(buf, layout, k):  # pragma: no cover - compiled
    o = layout[k, 0]
    return buf[o:o + layout[k, 1]]


@njit(cache=True)
def _mat(buf, layout, k):  # pragma: no cover - compiled
    o = layout[k, 0]
    r = layout[k, 1]
    c = layout[k, 2]
    return buf[o:o + r * c].reshape((r, c))


@njit(cache=True)
def step_n_flat_memo(x, u, eff, stuck, n, dt, buf, layout, wind, flags, fm,
                     memo):  # pragma: no cover - compiled
    """:func:`step_n_memo` on the airframe as :func:`flatten_packed`'s ``(buf, layout)``: the
    same arithmetic (the same bits), with 12 arguments to pass from Python instead of 25
    (each array argument costs a fraction of a microsecond per call)."""
    step_n_memo(x, u, eff, stuck, n, dt, _vec(buf, layout, 0), _mat(buf, layout, 1),
                _mat(buf, layout, 2), _mat(buf, layout, 3), _mat(buf, layout, 4),
                _mat(buf, layout, 5), _vec(buf, layout, 6), _vec(buf, layout, 7),
                _vec(buf, layout, 8), _vec(buf, layout, 9), _vec(buf, layout, 10),
                _vec(buf, layout, 11), _vec(buf, layout, 12), _mat(buf, layout, 13),
                _mat(buf, layout, 14), wind, flags, fm, memo)


@njit(cache=True)
def step_n_flat(x, u, eff, stuck, n, dt, buf, layout, wind, flags, fm):  # pragma: no cover
    """:func:`step_n_flat_memo` without a memo (:func:`step_n` on the flat airframe)."""
    step_n_flat_memo(x, u, eff, stuck, n, dt, buf, layout, wind, flags, fm, np.empty(0))


# --------------------------------------------------------------------------------------------
# Attitude helpers (plain Python, used outside the hot loop)
# --------------------------------------------------------------------------------------------



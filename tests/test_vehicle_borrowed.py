"""The vehicle's RK4 kernel and derivative (session 18) against main's, bit for bit.

``dynamics.step_n_memo`` passes :func:`~vtolftc.firmware_sim.vehicle.dynamics.derivatives`
views of its arrays that hold no reference (``base.nrt.borrowed``), its stage arrays in one
allocation; ``derivatives`` counts no references (``_nrt=False``), skips a rotor at exactly
zero and has ``lift_drag_coefficients`` inlined. ``_derivatives_main``,
``_lift_drag_main`` and ``_step_n_memo_main`` below are main's code (d5536a1) word for word;
both fly random and adversarial states (ground contact, stall and post-stall, wind, lost and
stuck actuators, rotors at +-0, perturbed airframes, every physics switch, memo hits and
misses, 1-4 steps a call) and must agree to the last bit in the state, ``fm`` and the memo.
"""

from __future__ import annotations

import math

import numpy as np
import pytest
from numba import njit

from vtolftc.base.nrt import borrowed
from vtolftc.firmware_sim.vehicle import dynamics as dyn
from vtolftc.firmware_sim.vehicle.dynamics import (  # main's derivative reads these
    ACT_ZERO,
    N_RIGID,
    P_ALIN,
    P_ARM_X,
    P_ARM_Y,
    P_ARM_Z,
    P_ASAT,
    P_B,
    P_C,
    P_CD0,
    P_CL0,
    P_CLA,
    P_CLB,
    P_CLDA,
    P_CLDE,
    P_CLDR,
    P_CLMAX,
    P_CLQ,
    P_CLR,
    P_CM0,
    P_CMDE,
    P_CNDA,
    P_CNDR,
    P_CNP,
    P_CYB,
    P_CYDA,
    P_CYDR,
    P_CYP,
    P_CYR,
    P_DEFL,
    P_G,
    P_GC,
    P_GF,
    P_GK,
    P_GMU,
    P_K,
    P_MASS,
    P_NAIL,
    P_NRUD,
    P_RHO,
    P_S,
    P_STALL_M,
    P_STALL_RND,
    T_CLP,
    T_CMA,
    T_CMQ,
    T_CNB,
    T_CNR,
    _memo_store,
    _memo_valid,
    actuator_rates,
)


@njit(cache=False)
def _lift_drag_main(alpha, P):  # pragma: no cover - compiled
    """main's ``lift_drag_coefficients`` (d5536a1), unchanged."""
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


@njit(cache=False)
def _derivatives_main(x, u, eff, stuck, P, J, Jinv, rpos, raxis, rtorque, rtmax, rinv_v0,
                      atau, arate, amin, amax, tab_v, tab, gear, wind, flags, dx,
                      fm):  # pragma: no cover - compiled
    """main's ``derivatives`` (d5536a1), unchanged: the reference."""
    nr = rtmax.shape[0]
    q0, q1, q2, q3 = x[6], x[7], x[8], x[9]
    p, q, r = x[10], x[11], x[12]
    # the rotation's entries as scalars (no 3x3 array allocated 17 times per control step)
    R00, R01, R02, R10, R11, R12, R20, R21, R22 = dyn.quat_to_dcm_entries(q0, q1, q2, q3)

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
    if flags & dyn.PROPULSION:
        for i in range(nr):
            ax0 = raxis[i, 0]
            ax1 = raxis[i, 1]
            ax2 = raxis[i, 2]
            v_axial = ub * ax0 + vb * ax1 + wb * ax2
            fade = 1.0 - v_axial * rinv_v0[i]
            fade = min(1.25, max(0.0, fade))
            T = eff[i] * rtmax[i] * x[N_RIGID + i] * fade
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
    if flags & dyn.AERODYNAMICS and Va > 1e-6:
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

        cl, cd = _lift_drag_main(alpha, P)
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

        am = dyn.saturate_angle(alpha, P[P_ALIN], P[P_ASAT])
        bm = dyn.saturate_angle(beta, P[P_ALIN], P[P_ASAT])
        clp = dyn.table_interp(Va, tab_v, tab[T_CLP])
        cmq = dyn.table_interp(Va, tab_v, tab[T_CMQ])
        cma = dyn.table_interp(Va, tab_v, tab[T_CMA])
        cnr = dyn.table_interp(Va, tab_v, tab[T_CNR])
        cnb = dyn.table_interp(Va, tab_v, tab[T_CNB])
        Mx += (qbar * S * b * (P[P_CLB] * bm + P[P_CLDR] * d_r) + qbar_xz * S * b * P[P_CLDA] * d_a
               + k_xz * b * b * (clp * p + P[P_CLR] * r))
        My += (qbar_xz * S * c * (P[P_CM0] + cma * am + P[P_CMDE] * d_e)
               + k_xz * c * c * cmq * q)
        Mz += (qbar * S * b * (cnb * bm + P[P_CNDR] * d_r) + qbar_xz * S * b * P[P_CNDA] * d_a
               + k_xz * b * b * P[P_CNP] * p + k_rate * b * b * cnr * r)

    # Landing gear against flat ground at NED z = 0.
    if flags & dyn.GROUND:
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
    gdown = P[P_G] if flags & dyn.GRAVITY else 0.0
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


@njit(cache=False)
def _step_n_memo_main(x, u, eff, stuck, n, dt, P, J, Jinv, rpos, raxis, rtorque, rtmax,
                      rinv_v0, atau, arate, amin, amax, tab_v, tab, gear, wind, flags, fm,
                      memo):  # pragma: no cover - compiled
    """main's ``step_n_memo`` (d5536a1), unchanged: the reference."""
    nx = x.shape[0]
    k1 = np.empty(nx)
    k2 = np.empty(nx)
    k3 = np.empty(nx)
    k4 = np.empty(nx)
    xt = np.empty(nx)
    na = atau.shape[0]
    use_memo = memo.shape[0] > 0
    for j in range(n):
        if j == 0 and use_memo and _memo_valid(memo, x, eff, wind, flags):
            for i in range(N_RIGID):
                k1[i] = memo[2 + nx + i]
            actuator_rates(x, u, stuck, atau, arate, amin, amax, k1)
        else:
            _derivatives_main(x, u, eff, stuck, P, J, Jinv, rpos, raxis, rtorque, rtmax, rinv_v0,
                        atau, arate, amin, amax, tab_v, tab, gear, wind, flags, k1, fm)
        for i in range(nx):
            xt[i] = x[i] + 0.5 * dt * k1[i]
        _derivatives_main(xt, u, eff, stuck, P, J, Jinv, rpos, raxis, rtorque, rtmax, rinv_v0,
                    atau, arate, amin, amax, tab_v, tab, gear, wind, flags, k2, fm)
        for i in range(nx):
            xt[i] = x[i] + 0.5 * dt * k2[i]
        _derivatives_main(xt, u, eff, stuck, P, J, Jinv, rpos, raxis, rtorque, rtmax, rinv_v0,
                    atau, arate, amin, amax, tab_v, tab, gear, wind, flags, k3, fm)
        for i in range(nx):
            xt[i] = x[i] + dt * k3[i]
        _derivatives_main(xt, u, eff, stuck, P, J, Jinv, rpos, raxis, rtorque, rtmax, rinv_v0,
                    atau, arate, amin, amax, tab_v, tab, gear, wind, flags, k4, fm)
        for i in range(nx):
            x[i] += dt / 6.0 * (k1[i] + 2.0 * k2[i] + 2.0 * k3[i] + k4[i])
        nq = math.sqrt(x[6] * x[6] + x[7] * x[7] + x[8] * x[8] + x[9] * x[9])
        for i in range(6, 10):
            x[i] /= nq
        for i in range(na):
            k = N_RIGID + i
            xa = min(amax[i], max(amin[i], x[k]))
            x[k] = xa if abs(xa) >= ACT_ZERO else 0.0
    _derivatives_main(x, u, eff, stuck, P, J, Jinv, rpos, raxis, rtorque, rtmax, rinv_v0,
                atau, arate, amin, amax, tab_v, tab, gear, wind, flags, k1, fm)
    if use_memo:
        _memo_store(memo, x, k1, eff, wind, flags)


def _bits(a: np.ndarray) -> bytes:
    return np.ascontiguousarray(a).tobytes()


def _random_state(rng: np.random.Generator, kind: int, na: int) -> np.ndarray:
    """A state of one of six kinds: cruise, hover, ground contact, stall / post-stall,
    tumbling, and actuators near ACT_ZERO (subnormal and tiny positions)."""
    x = np.zeros(N_RIGID + na)
    q = rng.normal(0.0, 1.0, 4)
    if kind in (0, 1, 2, 5):
        q = 0.1 * q + np.array([1.0, 0.0, 0.0, 0.0])
    x[6:10] = q / np.linalg.norm(q)
    x[0:3] = rng.normal(0.0, 20.0, 3)
    x[2] = -abs(rng.normal(60.0, 20.0))
    x[10:13] = rng.normal(0.0, 0.3 if kind != 4 else 4.0, 3)
    x[N_RIGID:N_RIGID + 10] = rng.uniform(0.0, 1.0, 10)
    x[N_RIGID + 10:] = rng.uniform(-1.0, 1.0, na - 10)
    if kind == 0:  # cruise
        x[3:6] = (rng.normal(17.0, 3.0), rng.normal(0.0, 2.0), rng.normal(0.0, 1.0))
    elif kind == 1:  # hover, slow
        x[3:6] = rng.normal(0.0, 0.5, 3)
    elif kind == 2:  # ground contact: the gear below z = 0, moving
        x[2] = rng.uniform(-0.3, 0.3)
        x[3:6] = rng.normal(0.0, 1.5, 3)
    elif kind == 3:  # stall and post-stall: steep descent at speed, any alpha
        x[3:6] = (rng.normal(8.0, 4.0), rng.normal(0.0, 4.0), rng.normal(6.0, 6.0))
    elif kind == 4:  # tumbling, fast
        x[3:6] = rng.normal(0.0, 15.0, 3)
    else:  # actuators at and around ACT_ZERO, a subnormal one, exact zeros
        x[3:6] = rng.normal(12.0, 5.0, 3)
        x[N_RIGID + rng.integers(0, na, 4)] = (5e-324, 2e-200, -3e-201, 0.0)
    return x


def test_borrowed_step_n_memo_equals_mains_kernel_bit_for_bit(ds1):
    """1,200 calls of both kernels from equal copies of random and adversarial states and
    settings: state, ``fm`` and memo equal to the last bit after every call, the memo hit
    on most of the calls that continue a flight and missed on the rest."""
    rng = np.random.default_rng(18)
    na = ds1.n_actuators
    nominal = dyn.pack(ds1)
    airframes = [nominal, dyn.perturb(nominal, 1.15, (0.8, 1.3, 1.1), (0.02, -0.01, 0.03)),
                 dyn.perturb(nominal, 0.9, (1.2, 1.0, 0.9), (-0.03, 0.0, 0.0))]
    flags_all = (dyn.ALL_PHYSICS, dyn.ALL_PHYSICS & ~dyn.AERODYNAMICS,
                 dyn.ALL_PHYSICS & ~dyn.GROUND, dyn.GRAVITY | dyn.GROUND)
    u_min = np.r_[np.zeros(10), -np.ones(na - 10)]
    hits = misses = 0
    contacts = stalls = 0
    x_a = x_b = None
    memo_a = np.zeros(dyn.memo_size(N_RIGID + na, na))
    memo_b = memo_a.copy()
    for k in range(1200):
        fresh = k % 6 == 0
        if fresh:  # a new state and settings; else the flight goes on from the last call
            kind = (k // 6) % 6
            x_a = _random_state(rng, kind, na)
            x_b = x_a.copy()
            pk = airframes[(k // 6) % 3]
            flags = flags_all[(k // 12) % 4] if (k // 6) % 5 else dyn.ALL_PHYSICS
            eff = np.ones(na)
            stuck = np.zeros(na, dtype=np.bool_)
            if kind in (2, 4, 5):  # lost, weak and stuck actuators
                eff[rng.integers(0, na, 2)] = (0.0, rng.uniform(0.1, 0.9))
                stuck[rng.integers(0, na)] = True
            wind = rng.normal(0.0, 4.0, 3) if k % 4 else np.zeros(3)
            memo_a[0] = memo_b[0] = 0.0  # another airframe or state: no memo
        u = rng.uniform(u_min - 0.2, 1.2).astype(np.float32).astype(np.float64)
        n = int(rng.integers(1, 5))
        fm_a = np.zeros(9)
        fm_b = np.zeros(9)
        before = bool(_memo_valid(memo_a, x_a, eff, wind, flags))
        hits += before
        misses += not before
        for f, x, fm, memo in ((dyn.step_n_memo, x_a, fm_a, memo_a),
                               (_step_n_memo_main, x_b, fm_b, memo_b)):
            f(x, u, eff, stuck, n, 1e-3, pk.P, pk.J, pk.Jinv, pk.rotor_pos, pk.rotor_axis,
              pk.rotor_torque, pk.rotor_tmax, pk.rotor_inv_v0, pk.act_tau, pk.act_rate,
              pk.act_min, pk.act_max, pk.tab_v, pk.tab, pk.gear, wind, flags, fm, memo)
        assert _bits(x_a) == _bits(x_b), k
        assert _bits(fm_a) == _bits(fm_b), k
        assert _bits(memo_a) == _bits(memo_b), k
        contacts += bool(x_a[2] > -0.6 and flags & dyn.GROUND)
        stalls += bool(abs(fm_a[7]) > 0.3)
    assert hits > 600 and misses >= 200, (hits, misses)
    assert contacts > 50 and stalls > 50, (contacts, stalls)


def test_borrowed_step_n_memo_without_memo_and_flat_equals_mains(ds1):
    """``step_n`` (an empty memo) and ``step_n_flat_memo`` (the flattened airframe, whose
    views are ``_vec`` / ``_mat`` temporaries of the caller) against the reference."""
    rng = np.random.default_rng(3)
    na = ds1.n_actuators
    pk = dyn.perturb(dyn.pack(ds1), 1.05, (1.0, 1.1, 1.0), (0.01, 0.0, -0.02))
    buf, lay = dyn.flatten_packed(pk)
    u_min = np.r_[np.zeros(10), -np.ones(na - 10)]
    eff = np.ones(na)
    eff[2] = 0.4
    stuck = np.zeros(na, dtype=np.bool_)
    stuck[12] = True
    wind = np.array([3.0, -2.0, 0.4])
    x0 = _random_state(rng, 0, na)
    xs = [x0.copy() for _ in range(3)]
    fms = [np.zeros(9) for _ in range(3)]
    memo_flat = np.zeros(dyn.memo_size(N_RIGID + na, na))
    memo_ref = memo_flat.copy()
    for k in range(300):
        u = rng.uniform(u_min, 1.0)
        dyn.step_n(xs[0], u, eff, stuck, 4, 1e-3, pk.P, pk.J, pk.Jinv, pk.rotor_pos,
                   pk.rotor_axis, pk.rotor_torque, pk.rotor_tmax, pk.rotor_inv_v0,
                   pk.act_tau, pk.act_rate, pk.act_min, pk.act_max, pk.tab_v, pk.tab,
                   pk.gear, wind, dyn.ALL_PHYSICS, fms[0])
        dyn.step_n_flat_memo(xs[1], u, eff, stuck, 4, 1e-3, buf, lay, wind,
                             dyn.ALL_PHYSICS, fms[1], memo_flat)
        _step_n_memo_main(xs[2], u, eff, stuck, 4, 1e-3, pk.P, pk.J, pk.Jinv, pk.rotor_pos,
                          pk.rotor_axis, pk.rotor_torque, pk.rotor_tmax, pk.rotor_inv_v0,
                          pk.act_tau, pk.act_rate, pk.act_min, pk.act_max, pk.tab_v, pk.tab,
                          pk.gear, wind, dyn.ALL_PHYSICS, fms[2], memo_ref)
        for i in (0, 1):
            assert _bits(xs[i]) == _bits(xs[2]), (k, i)
            assert _bits(fms[i]) == _bits(fms[2]), (k, i)
        assert _bits(memo_flat) == _bits(memo_ref), k


@njit(cache=False)
def _borrow_probe(a):  # pragma: no cover - compiled
    b = borrowed(a)
    b[1] = 7.0  # writes through to a
    return b.shape[0], b.strides[0], b[0] + b[2]


@pytest.mark.parametrize("step", [1, 3])
def test_borrowed_is_a_view_of_the_same_memory(step):
    """``borrowed`` keeps the data pointer, shape and strides (a strided view too)."""
    base = np.arange(12.0)
    a = base[::step]
    n, stride, s = _borrow_probe(a)
    assert (n, stride, s) == (a.shape[0], a.strides[0], a[0] + a[2])
    assert a[1] == 7.0


def test_derivatives_equal_mains_bit_for_bit_on_adversarial_states(ds1):
    """``derivatives`` against main's on 6,000 states: the six kinds of
    ``_random_state``, rotors at +0.0 and -0.0 (skipped) among running ones, all rotors at
    zero, lost rotors (eff 0) at zero and running, a NaN or infinite effectiveness, NaN and
    huge velocities, every physics switch, perturbed airframes, wind; ``dx`` and ``fm``
    equal to the last bit (NaN payloads and signed zeros included)."""
    rng = np.random.default_rng(24)
    na = ds1.n_actuators
    nominal = dyn.pack(ds1)
    airframes = [nominal, dyn.perturb(nominal, 1.2, (0.7, 1.4, 1.0), (0.03, 0.02, -0.04))]
    flags_all = (dyn.ALL_PHYSICS, dyn.PROPULSION, dyn.PROPULSION | dyn.GRAVITY,
                 dyn.ALL_PHYSICS & ~dyn.AERODYNAMICS, dyn.ALL_PHYSICS & ~dyn.GROUND)
    zeros_seen = 0
    for k in range(6000):
        pk = airframes[k % 2]
        x = _random_state(rng, k % 6, na)
        case = (k // 6) % 8
        if case == 1:  # some rotors at exactly +0 or -0
            idx = rng.choice(10, size=int(rng.integers(1, 10)), replace=False)
            x[N_RIGID + idx] = rng.choice([0.0, -0.0], size=idx.size)
        elif case == 2:  # every rotor idle
            x[N_RIGID:N_RIGID + 10] = 0.0
        elif case == 3:  # cruise-like: lift rotors at zero, pushers running
            x[N_RIGID:N_RIGID + 8] = 0.0
        eff = np.ones(na)
        if case == 4:
            eff[rng.integers(0, 10, 2)] = 0.0
            x[N_RIGID + rng.integers(0, 10)] = 0.0
        elif case == 5:
            eff[rng.integers(0, 10)] = rng.choice([np.nan, np.inf])
            x[N_RIGID + rng.integers(0, 10, 2)] = 0.0
        elif case == 6:
            x[3 + rng.integers(0, 3)] = rng.choice([np.nan, 1e200, -np.inf])
            x[N_RIGID + rng.integers(0, 10)] = 0.0
        stuck = rng.uniform(size=na) < 0.1
        wind = rng.normal(0.0, 3.0, 3) if k % 3 else np.zeros(3)
        u = rng.uniform(-1.2, 1.2, na)
        flags = flags_all[k % 5]
        zeros_seen += int(np.sum(x[N_RIGID:N_RIGID + 10] == 0.0))
        out = []
        for f in (dyn.derivatives, _derivatives_main):
            dx = np.full(x.size, 7.0)
            fm = np.full(9, 7.0)
            f(x, u, eff, stuck, pk.P, pk.J, pk.Jinv, pk.rotor_pos, pk.rotor_axis,
              pk.rotor_torque, pk.rotor_tmax, pk.rotor_inv_v0, pk.act_tau, pk.act_rate,
              pk.act_min, pk.act_max, pk.tab_v, pk.tab, pk.gear, wind, flags, dx, fm)
            out.append((_bits(dx), _bits(fm)))
        assert out[0] == out[1], (k, case)
    assert zeros_seen > 10_000


@pytest.mark.parametrize("alpha", [-3.0, -0.9, -0.2, 0.0, -0.0, 0.1, 0.2, 0.25, 0.4, 1.3, 3.1])
def test_lift_drag_coefficients_equal_mains(ds1, alpha):
    """The inlined ``lift_drag_coefficients`` (called from Python) is main's, attached flow,
    the rounded peak, post-stall and reversed flow, to the last bit."""
    P = dyn.pack(ds1).P
    for a in (alpha, np.nextafter(alpha, 1.0), alpha * (1 + 1e-9)):
        got = dyn.lift_drag_coefficients(a, P)
        ref = _lift_drag_main(a, P)
        assert np.array(got).tobytes() == np.array(ref).tobytes(), a


def test_table_bracket_and_at_equal_table_interp(ds1):
    """One search for the five derivative tables (``table_bracket`` + ``table_at``) against
    ``table_interp`` per row: random airspeeds inside and outside the table, every grid
    point and its neighbours, -0.0, inf, -inf, NaN; a random table too."""
    pk = dyn.pack(ds1)
    rng = np.random.default_rng(7)
    tables = [(pk.tab_v, pk.tab),
              (np.sort(rng.uniform(0.0, 30.0, 9)), rng.normal(0.0, 2.0, (5, 9)))]
    for tab_v, tab in tables:
        vs = [*rng.uniform(-5.0, 40.0, 3000), 0.0, -0.0, np.inf, -np.inf, np.nan]
        for g in tab_v:
            vs += [g, np.nextafter(g, -np.inf), np.nextafter(g, np.inf)]
        for v in vs:
            i, f = dyn.table_bracket(v, tab_v)
            for row in tab:
                got = dyn.table_at(i, f, row)
                ref = dyn.table_interp(v, tab_v, row)
                assert np.float64(got).tobytes() == np.float64(ref).tobytes(), (v, i, f)

"""The RK4 kernel on borrowed (reference-count free) arrays against the kernel it replaced.

``dynamics.step_n_memo`` passes :func:`~vtolftc.firmware_sim.vehicle.dynamics.derivatives`
views of its arrays that hold no reference (``base.nrt.borrowed``), its stage arrays in one
allocation: the same evaluations in the same order, so the same bits. ``_step_n_memo_main``
below is main's kernel (d5536a1) word for word, five allocations and counted references; both
fly random and adversarial states (ground contact, stall and post-stall, wind, lost and stuck
actuators, perturbed airframes, every physics switch, memo hits and misses, 1-4 steps a call)
and must agree to the last bit in the state, ``fm`` and the memo.
"""

from __future__ import annotations

import math

import numpy as np
import pytest
from numba import njit

from vtolftc.base.nrt import borrowed
from vtolftc.firmware_sim.vehicle import dynamics as dyn
from vtolftc.firmware_sim.vehicle.dynamics import (
    ACT_ZERO,
    N_RIGID,
    _memo_store,
    _memo_valid,
    actuator_rates,
    derivatives,
)


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
            x[k] = xa if abs(xa) >= ACT_ZERO else 0.0
    derivatives(x, u, eff, stuck, P, J, Jinv, rpos, raxis, rtorque, rtmax, rinv_v0,
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

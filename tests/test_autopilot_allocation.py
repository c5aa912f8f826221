"""The autopilot's allocation set-up (QPAllocator on the nominal B(V) of DS-1): exact when
feasible, limits never violated, graceful when infeasible, no worse than the PX4-style
pseudo-inverse, and the fixed-wing exclusion of the lift rotors."""

from __future__ import annotations

import numpy as np
import pytest

from vtolftc.firmware_sim.autopilot.allocation import AllocationStatus, PseudoInverseAllocator
from vtolftc.firmware_sim.autopilot.autopilot import ALLOCATION_WEIGHTS
from vtolftc.firmware_sim.autopilot.effectiveness import EffectivenessModel


@pytest.fixture
def alloc(ds1):
    from vtolftc.firmware_sim.autopilot.allocation import QPAllocator

    u_min = np.r_[np.zeros(10), -np.ones(5)]
    u_max = np.ones(15)
    pref = np.r_[np.full(8, ds1.weight_N / 280.0), np.zeros(7)]
    return QPAllocator(5, u_min, u_max, w_v=ALLOCATION_WEIGHTS, u_pref=pref,
                       settings={"time_limit": 1e10}), u_min, u_max, pref


@pytest.mark.parametrize("V", [0.0, 7.0, 13.0, 18.0])
def test_exact_when_feasible(ds1, alloc, V):
    qp, u_min, u_max, _ = alloc
    B = EffectivenessModel(ds1).matrix(V)
    rng = np.random.default_rng(int(V))
    for _ in range(20):
        u_true = rng.uniform(u_min + 0.2, u_max - 0.2)
        u_true[8:10] = rng.uniform(0.2, 0.8, 2)
        v = B @ u_true
        res = qp.allocate(v, B)
        assert res.status == AllocationStatus.SOLVED
        scale = np.maximum(np.abs(v), 1.0)
        assert np.all(np.abs(res.residual) / scale < 1e-3), res.residual
        assert np.all(res.u >= u_min) and np.all(res.u <= u_max)


def test_graceful_and_prioritised_when_infeasible(ds1, alloc):
    qp, u_min, u_max, pref = alloc
    B = EffectivenessModel(ds1).matrix(10.0)
    pinv = PseudoInverseAllocator(u_min, u_max, u_trim=pref)
    W = ALLOCATION_WEIGHTS
    rng = np.random.default_rng(3)
    for _ in range(30):
        v = np.array([-120.0, 20.0, 0.0, 0.0, 0.0]) + rng.normal(0, 1, 5) * [
            150.0, 30.0, 80.0, 80.0, 20.0]
        qp.reset()
        res = qp.allocate(v, B)
        assert res.status in (AllocationStatus.SOLVED, AllocationStatus.SOLVED_INACCURATE)
        assert np.all(np.isfinite(res.u))
        assert np.all(res.u >= u_min - 1e-12) and np.all(res.u <= u_max + 1e-12)
        e_qp = np.linalg.norm(W * (B @ res.u - v))
        e_pi = np.linalg.norm(W * (B @ pinv.compute(v, B) - v))
        assert e_qp <= e_pi * (1.0 + 1e-6) + 1e-9
    # a roll moment beyond reach is tracked as far as possible, with the rotors saturating
    v = np.array([-122.6, 0.0, 400.0, 0.0, 0.0])
    qp.reset()
    res = qp.allocate(v, B)
    assert 0.0 < res.v_achieved[2] < 400.0
    assert np.any(res.u[:8] == 1.0) and np.any(res.u[:8] == 0.0)


def test_fixed_wing_excludes_the_lift_rotors(ds1, alloc):
    qp, _, u_max, _ = alloc
    B = EffectivenessModel(ds1).matrix(18.0)
    B[0, :] = 0.0                       # the autopilot drops the Fz row in fixed-wing
    hi = u_max.copy()
    hi[:8] = 0.0
    v = np.array([0.0, 15.0, 2.0, -4.0, 0.5])
    res = qp.allocate(v, B, u_max=hi, u_pref=np.zeros(15))
    assert np.all(res.u[:8] == 0.0)
    np.testing.assert_allclose(res.v_achieved[1:], v[1:], atol=1e-3)


def test_compiled_step_bounds_match_the_reference_functions():
    from vtolftc.firmware_sim.autopilot.allocation import (
        QPAllocator,
        _step_bounds,
        rate_limited_bounds,
    )

    rng = np.random.default_rng(7)
    n = 15
    dmin, dmax = np.r_[np.zeros(10), -np.ones(5)], np.ones(n)
    for _ in range(500):
        umin = dmin + rng.uniform(0, 0.5, n) * (rng.random(n) < 0.3)
        umax = dmax - rng.uniform(0, 1.5, n) * (rng.random(n) < 0.3)
        umin[rng.random(n) < 0.1] = np.nan
        umax[rng.random(n) < 0.1] = np.inf
        prev = rng.uniform(-1.5, 1.5, n)
        if rng.random() < 0.1:
            prev[3] = np.nan
        rate = rng.uniform(1, 20, n)
        rate[rng.random(n) < 0.2] = np.inf
        pmin = QPAllocator._sane_limit(umin, dmin, "u_min")
        pmax = np.maximum(QPAllocator._sane_limit(umax, dmax, "u_max"), pmin)
        ok = bool(np.all(np.isfinite(prev)))
        lo_ref, hi_ref = rate_limited_bounds(pmin, pmax, prev if ok else None, rate, 0.004)
        lo, hi = np.empty(n), np.empty(n)
        assert _step_bounds(dmin, dmax, umin, umax, prev, True, rate, True, 0.004,
                            lo, hi) == int(ok)
        np.testing.assert_array_equal(lo, lo_ref)
        np.testing.assert_array_equal(hi, hi_ref)

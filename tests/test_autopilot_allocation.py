"""The autopilot's allocation set-up (each QP allocator on the nominal B(V) of DS-1): exact when
feasible, limits never violated, graceful when infeasible, no worse than the PX4-style
pseudo-inverse, and the fixed-wing exclusion of the lift rotors."""

from __future__ import annotations

import numpy as np
import pytest

from vtolftc.firmware_sim.autopilot.allocation import AllocationStatus, PseudoInverseAllocator
from vtolftc.firmware_sim.autopilot.autopilot import ALLOCATION_WEIGHTS
from vtolftc.firmware_sim.autopilot.effectiveness import EffectivenessModel


@pytest.fixture(params=["osqp", "active_set"])
def alloc(ds1, request):
    from vtolftc.firmware_sim.autopilot.allocation import ActiveSetAllocator, QPAllocator

    u_min = np.r_[np.zeros(10), -np.ones(5)]
    u_max = np.ones(15)
    pref = np.r_[np.full(8, ds1.weight_N / 280.0), np.zeros(7)]
    cls = QPAllocator if request.param == "osqp" else ActiveSetAllocator
    return cls(5, u_min, u_max, w_v=ALLOCATION_WEIGHTS, u_pref=pref), u_min, u_max, pref


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


def _reference_bounds(dmin, dmax, umin, umax, prev, rate, dt):
    """Plain-numpy statement of the per-step bounds (the oracle of ``step_bounds``): position
    limits (non-finite -> construction ones, upper raised to lower), intersected with
    ``prev ± rate dt`` when ``prev`` is finite, position limits winning where that is empty."""
    pmin = np.where(np.isfinite(umin), umin, dmin)
    pmax = np.maximum(np.where(np.isfinite(umax), umax, dmax), pmin)
    if not np.all(np.isfinite(prev)):
        return pmin, pmax
    lo = np.maximum(pmin, prev - rate * dt)
    hi = np.minimum(pmax, prev + rate * dt)
    bad = lo > hi
    fix = np.clip(prev, pmin, pmax)
    return np.where(bad, fix, lo), np.where(bad, fix, hi)


def test_compiled_step_bounds_match_the_reference_functions():
    from vtolftc.firmware_sim.autopilot.allocation import step_bounds

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
        ok = bool(np.all(np.isfinite(prev)))
        lo_ref, hi_ref = _reference_bounds(dmin, dmax, umin, umax, prev, rate, 0.004)
        lo, hi = np.empty(n), np.empty(n)
        assert step_bounds(dmin, dmax, umin, umax, prev, True, rate, True, 0.004,
                           lo, hi) == int(ok)
        np.testing.assert_array_equal(lo, lo_ref)
        np.testing.assert_array_equal(hi, hi_ref)

"""The per-step fast paths of the autopilot (issue 24) against the Python they replace, equal
to the last bit on random inputs: a changed operation order or a dropped branch fails here
before it changes a flight (``benchmarks/command_digest.py`` checks three whole flights)."""

from __future__ import annotations

import copy

import numpy as np

from vtolftc.firmware_sim.autopilot.allocation import ActiveSetAllocator, AllocationStatus
from vtolftc.firmware_sim.autopilot.autopilot import Autopilot
from vtolftc.firmware_sim.autopilot.effectiveness import EffectivenessModel


def _bits(a: np.ndarray) -> bytes:
    return np.ascontiguousarray(a, dtype=np.float64).tobytes()


def test_allocate_trusted_equals_allocate_bit_for_bit(ds1):
    """The same sequence of problems (airspeed grid points, reserve rows, rate and position
    limits, infeasible commands, a non-finite command) through ``allocate`` and
    ``allocate_trusted`` of two identical allocators: same ``u``, ``B u``, status, warm start
    and statistics, step after step."""
    ap = Autopilot(ds1)
    ref: ActiveSetAllocator = ap.output.allocator
    fast: ActiveSetAllocator = Autopilot(ds1).output.allocator  # (a deep copy's workspace
    # views would be copies of their own: the kernel writes the bounds into the workspace)
    eff = EffectivenessModel(ds1)
    rng = np.random.default_rng(24)
    n_u = ref.n_u
    statuses = set()
    for k in range(400):
        V = float(rng.choice([0.0, 3.0, 7.3, 12.0, 17.9]))
        B = eff.matrix_on_grid(V, 0.1)
        if k % 7 == 3:  # the output stage's reserve matrix: a writable copy, Fz row zeroed
            B = B.copy()
            B[0, :] = 0.0
        v = np.array([-ds1.weight_N, 5.0, 0.0, 0.0, 0.0]) + rng.normal(0, 1, 5) * [
            60.0, 20.0, 15.0, 15.0, 5.0] * (4.0 if k % 11 == 5 else 1.0)
        if k == 200:
            v[3] = np.nan  # INVALID_INPUT: previous command held
        hi = np.ones(n_u)
        hi[: ap.n_rotors] = float(rng.choice([1.0, 0.6, 0.0]))
        pref = ap.u_pref_mc if k % 2 else ap.u_pref_fw
        res = ref.allocate(v, B, u_max=hi, u_pref=pref)
        u, va, st = fast.allocate_trusted(v, B, hi, pref)
        statuses.add(st)
        assert st == res.status, k
        assert _bits(u) == _bits(res.u), k
        assert _bits(va) == _bits(res.v_achieved), k
        assert _bits(fast._u_last) == _bits(ref._u_last), k
        assert _bits(fast._ws) == _bits(ref._ws), k
    assert AllocationStatus.INVALID_INPUT in statuses and AllocationStatus.SOLVED in statuses
    a, b = ref.stats.as_dict(), fast.stats.as_dict()
    for d in (a, b):
        d.pop("max_wall_time_s"), d.pop("mean_wall_time_s")
    assert a == b


def test_output_stage_saturation_flags_equal_the_reference(ds1):
    """``OutputStage.allocate``'s inlined saturation tracking gives what
    ``_track_saturation(v, B u)`` gives (flags, the Fz pair, the count of saturated steps)
    on commands inside and far outside what the actuators can do."""
    ap = Autopilot(ds1)
    out = ap.output
    ref = copy.deepcopy(out)
    rng = np.random.default_rng(7)
    for k in range(300):
        V = float(rng.uniform(0.0, 20.0))
        tau = rng.normal(0, 1, 3) * [20.0, 20.0, 8.0] * (5.0 if k % 5 == 0 else 1.0)
        out.sp.v[0] = -ds1.weight_N * float(rng.uniform(0.5, 1.6))
        out.sp.v[1] = float(rng.uniform(0.0, 30.0))
        reserve = k % 9 == 4
        u = out.allocate(V, tau, reserve, 1.0, 1.0, ap.u_pref_mc)
        B = out._B if reserve else out._B_grid
        ref._track_saturation(out.sp.v, B @ u)
        assert (out.sat_hi, out.sat_lo) == (ref.sat_hi, ref.sat_lo), k
        assert (out.fz_cmd, out.fz_achieved) == (ref.fz_cmd, ref.fz_achieved), k
        assert out.saturated_steps == ref.saturated_steps, k
    assert 0 < out.saturated_steps < 300


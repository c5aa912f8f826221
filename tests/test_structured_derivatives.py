"""The structured tuner's lazily built per-parameter derivatives (``structured._Evaluator``)
are the batched stacks' and the one-point-at-a-time loop's, bit for bit."""

from __future__ import annotations

import numpy as np

from vtolftc.airframe.loader import load_airframe
from vtolftc.synthesis.robust import RobustMethod, robust_points
from vtolftc.synthesis.structured import _Evaluator
from vtolftc.synthesis.surfaces import surface_grid, surface_problem


def _small_grid():  # type: ignore[no-untyped-def]
    by_v = {p.airspeed_m_s: p for p in robust_points(load_airframe())}
    return surface_grid([by_v[4.0], by_v[10.0]], 2)     # 4, 7, 10 m/s


def test_lazy_derivative_lists_are_the_stacks_and_the_loop_bit_for_bit() -> None:
    af = load_airframe()
    sp = surface_problem(RobustMethod(), af, "pitch", _small_grid(), 1)
    theta = sp.problem.initial * np.linspace(0.9, 1.1, sp.problem.initial.size)
    ev = _Evaluator(sp.problem)
    stacks = ev.derivative_stacks(theta)
    assert stacks is not None
    lists = ev.derivatives(theta)          # built from the cached stacks
    loop = _Evaluator(sp.problem)._derivatives_loop(theta)
    assert len(lists) == len(loop) == len(stacks) == len(sp.problem.channels)
    for st, per_k, ref in zip(stacks, lists, loop, strict=True):
        assert len(per_k) == len(ref) == ev.p
        for k in range(ev.p):
            for m in range(4):
                np.testing.assert_array_equal(per_k[k][m], st[m][k])
                np.testing.assert_array_equal(per_k[k][m], ref[k][m])
    # the other order (lists first) gives the same stacks
    ev2 = _Evaluator(sp.problem)
    ev2.derivatives(theta)
    for a, b in zip(ev2.derivative_stacks(theta) or [], stacks, strict=True):
        for x, y in zip(a, b, strict=True):
            np.testing.assert_array_equal(x, y)

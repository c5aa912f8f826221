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
    # the differences in theta (the chain rule through the gains is
    # tests/test_surface_chain_rule.py's; the lazy lists of its stacks are checked below)
    ev.chain_rule = False
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
    ev2.chain_rule = False
    ev2.derivatives(theta)
    for a, b in zip(ev2.derivative_stacks(theta) or [], stacks, strict=True):
        for x, y in zip(a, b, strict=True):
            np.testing.assert_array_equal(x, y)
    # with the chain rule (the default for a degree >= 1 surface) the lists are its stacks
    ev3 = _Evaluator(sp.problem)
    assert ev3.chain_rule
    chained, lists3 = ev3.derivative_stacks(theta), ev3.derivatives(theta)
    assert chained is not None
    for st, per_k in zip(chained, lists3, strict=True):
        for k in range(ev3.p):
            for m in range(4):
                np.testing.assert_array_equal(per_k[k][m], st[m][k])


def test_abscissa_values_alone_are_the_eigenpairs_bit_for_bit() -> None:
    """The constraint values (no eigenvectors) equal the real part of the rightmost eigenpair's
    eigenvalue: on random matrices and on the surface problem's channels, either order."""
    from vtolftc.synthesis.structured import _rightmost_eig, _rightmost_real

    rng = np.random.default_rng(5)
    for t in range(600):
        n = int(rng.integers(1, 16))
        A = rng.standard_normal((n, n)) * 10.0 ** rng.uniform(-3, 3, (n, n))
        if t % 3 == 0:
            A = A + A.T
        if t % 5 == 0:
            A = np.triu(A)
        assert _rightmost_real(A) == _rightmost_eig(A)[0].real
    af = load_airframe()
    sp = surface_problem(RobustMethod(), af, "roll", _small_grid(), 2)
    base = sp.problem.initial
    for scale in (0.7, 1.0, 1.3):
        theta = base * np.linspace(scale, 1.0 / scale, base.size)
        ev = _Evaluator(sp.problem)
        alone, g0 = ev.abscissa_and_grad(theta, grad=False)     # values only, first
        full, g = ev.abscissa_and_grad(theta)                   # then with the gradient
        again, _ = _Evaluator(sp.problem).abscissa_and_grad(theta)
        assert g0 is None and g is not None
        assert alone.tobytes() == full.tobytes() == again.tobytes()
        assert ev.abscissa_and_grad(theta, grad=False)[0].tobytes() == full.tobytes()

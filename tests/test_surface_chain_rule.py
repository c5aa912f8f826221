"""The surface tuner's derivatives by the chain rule (issue 23's performance item): the
derivatives in each grid point's five gains times d gains / d theta
(:meth:`vtolftc.synthesis.surfaces.SurfaceRealizer.gain_derivatives`) against the central
differences in the coefficients they replace, at random and adversarial coefficients
(gains clipped at some grid points, coefficients exactly on a gain bound)."""

from __future__ import annotations

import numpy as np
import pytest

from vtolftc.airframe.loader import load_airframe
from vtolftc.synthesis.robust import RobustMethod, robust_points
from vtolftc.synthesis.structured import TuningProblem, _Evaluator
from vtolftc.synthesis.surfaces import SurfaceProblem, surface_grid, surface_problem


def _problem(axis: str, degree: int = 2) -> SurfaceProblem:
    af = load_airframe()
    by_v = {p.airspeed_m_s: p for p in robust_points(af)}
    grid = surface_grid([by_v[0.0], by_v[4.0], by_v[10.0]], 2)     # 0, 2, 4, 7, 10 m/s
    return surface_problem(RobustMethod(), af, axis, grid, degree)


def _thetas(sp: SurfaceProblem, seed: int) -> list[np.ndarray]:
    """Random coefficients, coefficients whose gains leave the bounds at some grid points
    (clipped there) and constant surfaces exactly on a bound."""
    pb = sp.problem
    rng = np.random.default_rng(seed)
    lo, hi, x0 = pb.lower, pb.upper, pb.initial
    span = np.where(np.isfinite(hi - lo), hi - lo, 10 * pb.scales)
    out = [x0] + [np.clip(x0 + s * span * rng.standard_normal(x0.size), lo, hi)
                  for s in (0.02, 0.2)]
    n = sp.basis.size
    steep = x0.copy()
    for j in range(len(sp.lower)):   # a steep linear term: clipped at one end of the grid
        if np.isfinite(sp.upper[j]):
            steep[j * n] = sp.upper[j] * (0.9 if j % 2 else 0.999)
            steep[j * n + 1] = 0.5 * (sp.upper[j] - sp.lower[j]) * (1 if j % 2 else -1)
    out.append(steep)
    for bound in (sp.lower, sp.upper):    # on the bound at every grid point
        th = x0.copy()
        th[1::n] = 0.0
        if n > 2:
            th[2::n] = 0.0
        k = int(np.argmax(np.isfinite(bound) & (bound > 0)))
        th[k * n] = bound[k]
        out.append(th)
    return out


@pytest.mark.parametrize("axis", ["roll", "pitch", "yaw"])
def test_chain_rule_derivatives_are_the_coefficient_differences(axis: str) -> None:
    sp = _problem(axis)
    pb = sp.problem
    for theta in _thetas(sp, {"roll": 1, "pitch": 2, "yaw": 3}[axis]):
        chain, ref = _Evaluator(pb), _Evaluator(pb)
        assert chain.chain_rule
        ref.chain_rule = False
        got, want = chain.derivative_stacks(theta), ref.derivative_stacks(theta)
        assert got is not None and want is not None
        for a, b in zip(got, want, strict=True):
            for x, y in zip(a, b, strict=True):
                assert x.shape == y.shape
                # central differences of two step sizes: O(h^2) apart, h ~ 1e-6
                np.testing.assert_allclose(x, y, rtol=0, atol=1e-6 * max(np.abs(y).max(), 1))
        W = [np.array([0.0, 0.3, 3.0, 30.0])] * len(pb.channels)
        s1, g1 = chain.sigma_and_grad(theta, W, True)
        s0, g0 = ref.sigma_and_grad(theta, W, True)
        assert s1.tobytes() == s0.tobytes()
        assert g1 is not None and g0 is not None and g1.shape == g0.shape
        np.testing.assert_allclose(g1, g0, rtol=0, atol=1e-6 * np.abs(g0).max())
        v1, a1 = chain.abscissa_and_grad(theta)
        v0, a0 = ref.abscissa_and_grad(theta)
        assert v1.tobytes() == v0.tobytes()
        assert a1 is not None and a0 is not None
        np.testing.assert_allclose(a1, a0, rtol=0, atol=1e-6 * np.abs(a0).max())


def test_gain_jacobian_zero_where_clipped_half_on_a_bound() -> None:
    sp = _problem("pitch")
    pb = sp.problem
    assert pb.realizer is not None
    n = sp.basis.size
    Phi = sp.basis.evaluate([p.airspeed_m_s for p in sp.grid])
    for theta in _thetas(sp, 4):
        ch = pb.realizer.gain_derivatives(theta, pb.scales)
        assert ch is not None
        raw = theta.reshape(-1, n) @ Phi.T                    # (5, n_grid)
        for i, (_, J) in enumerate(ch):
            g = sp.point_of_channel[i]
            for j in range(J.shape[0]):
                r, lo, hi = raw[j, g], sp.lower[j], sp.upper[j]
                slope = 1.0 if lo < r < hi else (0.5 if r in (lo, hi) else 0.0)
                want = np.zeros(theta.size)
                want[j * n:(j + 1) * n] = slope * Phi[g]
                assert J[j].tobytes() == want.tobytes()


def test_chain_rule_only_where_it_saves_realisations() -> None:
    """SHIF (degree 0: as many gains as coefficients) keeps the differences in theta, and so
    do problems without a surface realizer."""
    sp0, sp2 = _problem("roll", 0), _problem("roll", 1)
    assert not _Evaluator(sp0.problem).chain_rule
    assert _Evaluator(sp2.problem).chain_rule
    pb = sp2.problem
    plain = TuningProblem(pb.parameters, pb.channels, pb.channel_names, pb.stability_margin)
    assert not _Evaluator(plain).chain_rule


def test_inner_ftol_reaches_the_step_subproblem_and_is_checked(monkeypatch) -> None:  # type: ignore[no-untyped-def]
    """``tune(inner_ftol=...)`` is the SLSQP tolerance of each step (the surface tune's
    looser one visits fewer points); the default is the point designs' 1e-10."""
    from vtolftc.synthesis import structured

    seen: list[float] = []
    real = structured.minimize

    def spy(*a, **k):  # type: ignore[no-untyped-def]
        if k.get("method") == "SLSQP":
            seen.append(k["options"]["ftol"])
        return real(*a, **k)

    monkeypatch.setattr(structured, "minimize", spy)
    pb = _problem("yaw", 1).problem
    f_init = pb.objective(pb.initial)
    assert np.isfinite(f_init)
    for tol in (structured.INNER_FTOL, 1e-8, 1e-3):
        seen.clear()
        kw = {} if tol == structured.INNER_FTOL else {"inner_ftol": tol}
        res = structured.tune(pb, max_iter=2, **kw)
        assert seen and res.starts[0].iterations >= 1
        # relative to the objective at each step: between the final and the initial value
        assert all(res.value * (1 - 1e-12) <= f / tol <= f_init * (1 + 1e-12) for f in seen)
    assert structured.INNER_FTOL == 1e-10
    for bad in (0.0, -1e-8, float("nan"), float("inf")):
        with pytest.raises(ValueError, match="inner_ftol"):
            structured.tune(pb, max_iter=1, inner_ftol=bad)


def test_chain_rule_off_is_the_coefficient_differences_bit_for_bit() -> None:
    """``surface_problem(chain_rule=False)`` (the yaw surface tune's setting) gives the tuner
    the central differences in the coefficients, bit for bit those of a problem without
    the chain rule; True (the default) gives the chain rule."""
    af = load_airframe()
    by_v = {p.airspeed_m_s: p for p in robust_points(af)}
    grid = surface_grid([by_v[0.0], by_v[4.0], by_v[10.0]], 2)
    off = surface_problem(RobustMethod(), af, "yaw", grid, 2, chain_rule=False)
    on = surface_problem(RobustMethod(), af, "yaw", grid, 2)
    ev_off, ev_on, ref = _Evaluator(off.problem), _Evaluator(on.problem), _Evaluator(on.problem)
    ref.chain_rule = False
    assert not ev_off.chain_rule and ev_on.chain_rule
    for theta in _thetas(on, 7)[:3]:
        got, want = ev_off.derivative_stacks(theta), ref.derivative_stacks(theta)
        assert got is not None and want is not None
        for g, w in zip(got, want, strict=True):
            for x, y in zip(g, w, strict=True):
                assert x.tobytes() == y.tobytes()
        chained = ev_on.derivative_stacks(theta)
        assert chained is not None
        assert any(x.tobytes() != y.tobytes()
                   for g, w in zip(chained, want, strict=True) for x, y in zip(g, w, strict=True))


@pytest.mark.parametrize("axis", ["roll", "yaw"])
def test_design_surfaces_tunes_each_axis_with_its_settings(monkeypatch, axis: str) -> None:  # type: ignore[no-untyped-def]
    """The surface (second) tune gets ``SURFACE_TUNE[axis]``: roll the fast tune (chain
    rule, 1e-8), yaw the precise one (central differences, 1e-10); SHIF keeps the tuner's
    defaults; an explicit ``settings`` wins."""
    from vtolftc.synthesis import structured
    from vtolftc.synthesis import surfaces as surf

    seen: list[tuple[bool, float]] = []
    real = surf.tune

    def spy(problem, **kw):  # type: ignore[no-untyped-def]
        seen.append((_Evaluator(problem).chain_rule,
                     kw.get("inner_ftol", structured.INNER_FTOL)))
        return real(problem, **{**kw, "max_iter": 1})

    monkeypatch.setattr(surf, "tune", spy)
    af = load_airframe()
    by_v = {p.airspeed_m_s: p for p in robust_points(af)}
    grid = surface_grid([by_v[4.0], by_v[10.0]], 1)
    want = {"roll": (True, 1e-8), "yaw": (False, 1e-10)}[axis]
    assert (surf.SURFACE_TUNE[axis].chain_rule, surf.SURFACE_TUNE[axis].inner_ftol) == want
    d = surf.design_surfaces(RobustMethod(), af, axis, grid, 1, n_starts=0, max_iter=1)
    assert seen == [(False, structured.INNER_FTOL), want]
    assert d.surface_objective <= d.constant_objective
    seen.clear()
    surf.design_surfaces(RobustMethod(), af, axis, grid, 1, n_starts=0, max_iter=1,
                         settings=surf.SurfaceTune(1e-3, not want[0]))
    assert seen[1] == (not want[0], 1e-3)

"""Gain surfaces (``synthesis/surfaces.py``): the basis against numpy's Legendre polynomials,
a degree-0 surface is exactly a constant, the surface design is never worse than the constant
design on its objective (DS-1), and the export is a schedule the autopilot reads."""

from __future__ import annotations

import dataclasses
from pathlib import Path

import numpy as np
import pytest
from numpy.polynomial import legendre

from vtolftc.airframe.loader import load_airframe
from vtolftc.firmware_sim.autopilot.attitude import make_controller
from vtolftc.firmware_sim.autopilot.schedule import GainSchedule
from vtolftc.synthesis import surfaces as surf
from vtolftc.synthesis.loops import PARAM_NAMES
from vtolftc.synthesis.robust import RobustMethod, robust_points
from vtolftc.synthesis.surfaces import (
    GainSurface,
    SurfaceBasis,
    SurfaceChannel,
    design_surfaces,
    legendre_basis,
    schedule_from_surfaces,
    surface_grid,
    surface_problem,
    write_surface_gains,
)
from vtolftc.synthesis.uncertainty import DesignPoint

GAINS = {"kp_angle": 2.3, "kp_rate": 0.71, "ki_rate": 0.137, "kd_rate": 0.0123,
         "tf_rate_s": 0.021}


@pytest.mark.parametrize("degree", [0, 1, 2, 3, 6])
def test_basis_matches_numpy_legendre(degree: int) -> None:
    s = np.linspace(-1.0, 1.0, 37)
    want = legendre.legvander(s, degree)
    got = legendre_basis(s, degree)
    np.testing.assert_allclose(got, want, rtol=0, atol=1e-13)
    # and each column is the Legendre series with one unit coefficient
    for j in range(degree + 1):
        e = np.zeros(degree + 1)
        e[j] = 1.0
        np.testing.assert_allclose(got[:, j], legendre.legval(s, e), atol=1e-13)


def test_normalised_airspeed_maps_the_range_and_clamps() -> None:
    b = SurfaceBasis(2, 3.0, 13.0)
    assert b.normalise([3.0, 8.0, 13.0]).tolist() == [-1.0, 0.0, 1.0]
    assert b.normalise([0.0, 20.0]).tolist() == [-1.0, 1.0]
    with pytest.raises(ValueError):
        SurfaceBasis(-1, 0.0, 1.0)
    with pytest.raises(ValueError):
        SurfaceBasis(1, 5.0, 5.0)


def test_a_degree_0_surface_is_exactly_a_constant() -> None:
    b = SurfaceBasis(0, 0.0, 18.0)
    sf = GainSurface.constant(b, GAINS)
    for v in (0.0, 0.3, 7.7, 18.0, 40.0):
        assert sf.gains_at(v) == GAINS
    # embedded in a higher degree: the same gains, bit for bit
    hi = sf.embed(4)
    assert hi.basis.degree == 4
    assert (hi.coefficients[:, 1:] == 0).all()
    for v in np.linspace(0.0, 18.0, 11):
        assert hi.gains_at(float(v)) == GAINS
    with pytest.raises(ValueError):
        hi.embed(2)


def test_surface_gains_are_the_series_and_clipped() -> None:
    b = SurfaceBasis(2, 0.0, 10.0)
    c = np.array([[1.0, 0.5, 0.25], [0.5, 0, 0], [0.1, 0, 0], [0.01, 0, 0], [0.02, 0, 0]])
    sf = GainSurface(b, c, lower=np.zeros(5), upper=np.full(5, 1.6))
    v = np.array([0.0, 2.5, 5.0, 7.5, 10.0])
    want = legendre.legval(2 * v / 10 - 1, c[0])
    got = sf.gain_matrix(v)[:, 0]
    np.testing.assert_allclose(got, np.clip(want, 0.0, 1.6), atol=1e-14)
    assert got[-1] == 1.6 and want[-1] > 1.6   # clipped at the top


def test_surface_grid_is_dense_and_contains_the_design_points() -> None:
    af = load_airframe()
    pts = robust_points(af)
    grid = surface_grid(pts, 2)
    assert len(grid) == 2 * len(pts) - 1
    vs = [p.airspeed_m_s for p in grid]
    assert vs == sorted(vs)
    assert set(p.airspeed_m_s for p in pts) <= set(vs)
    for p in grid:
        assert p.v_min_m_s <= p.airspeed_m_s <= p.v_max_m_s
        assert p.number > surf.GRID_NUMBER_OFFSET


def _small_grid() -> tuple[DesignPoint, ...]:
    pts = robust_points(load_airframe())
    by_v = {p.airspeed_m_s: p for p in pts}
    return surface_grid([by_v[4.0], by_v[10.0]], 2)     # 4, 7, 10 m/s


def test_surface_channel_with_a_constant_is_the_point_channel() -> None:
    af = load_airframe()
    m = RobustMethod()
    grid = _small_grid()
    sp = surface_problem(m, af, "roll", grid, 0)
    theta = sp.problem.initial * np.array([1.1, 0.9, 1.05, 0.8, 1.2])   # within the bounds
    assert (theta >= sp.lower).all() and (theta <= sp.upper).all()
    # the degree-0 surface problem is the point design's problem over the grid
    for ch, i in zip(sp.problem.channels, sp.point_of_channel, strict=True):
        assert isinstance(ch, SurfaceChannel)
        A1, B1, C1, D1 = ch(theta)
        A2, B2, C2, D2 = ch.inner(theta)
        assert (A1 == A2).all() and (B1 == B2).all() and (C1 == C2).all() and (D1 == D2).all()
        assert 0 <= i < len(grid)
    whole = m.setup(af, "roll", [m.weights(af, "roll", p) for p in grid]).problem
    assert sp.problem.objective(theta) == pytest.approx(whole.objective(theta), rel=1e-12)
    # batch realisation agrees with the one at a time (degree 2, random coefficients)
    sp2 = surface_problem(m, af, "roll", grid, 2)
    rng = np.random.default_rng(1)
    th = sp2.problem.initial + 0.01 * rng.standard_normal((3, sp2.problem.initial.size))
    ch = sp2.problem.channels[0]
    batch = ch.realize_batch(th)
    for k in range(3):
        for X, Y in zip(batch, ch(th[k]), strict=True):
            np.testing.assert_array_equal(X[k], Y)


def test_surface_design_is_never_worse_than_the_constant_design_ds1() -> None:
    af = load_airframe()
    d = design_surfaces(RobustMethod(), af, "roll", _small_grid(), 1, n_starts=0,
                        max_iter=4)
    assert np.isfinite(d.constant_objective)
    assert d.surface_objective <= d.constant_objective
    # the objective is what the reported surfaces give, evaluated afresh
    sp = surface_problem(RobustMethod(), af, "roll", d.grid, 1)
    theta = d.surface.coefficients.reshape(-1)
    assert sp.problem.objective(theta) == pytest.approx(d.surface_objective, rel=1e-9)
    start = d.constant.embed(1).coefficients.reshape(-1)
    assert sp.problem.objective(start) == pytest.approx(d.constant_objective, rel=1e-9)
    assert max(d.surface_grid_norms) == pytest.approx(d.surface_objective, rel=1e-12)


def test_a_worse_optimiser_result_keeps_the_constant_start(monkeypatch: pytest.MonkeyPatch,
                                                           ) -> None:
    """The final check: if the surface tune returns a worse point, the SHIF start is kept."""
    af = load_airframe()
    real_tune = surf.tune
    calls: list[int] = []

    def bad_tune(problem, **kw):  # type: ignore[no-untyped-def]
        res = real_tune(problem, **kw)
        calls.append(1)
        if len(calls) == 2:  # the surface tune: return a much worse point (stable gains)
            th = problem.initial.copy()
            th[0] = problem.parameters[0].lower
            return dataclasses.replace(res, theta=th)
        return res

    monkeypatch.setattr(surf, "tune", bad_tune)
    d = design_surfaces(RobustMethod(), af, "roll", _small_grid(), 1, n_starts=0,
                        max_iter=2)
    assert len(calls) == 2
    assert d.kept_start
    assert d.surface_objective == d.constant_objective
    for v in (4.0, 7.0, 10.0):
        assert d.surface.gains_at(v) == d.constant.gains_at(v)


def test_export_is_a_schedule_the_autopilot_reads() -> None:
    af = load_airframe()
    b = SurfaceBasis(2, 0.0, 18.0)
    c = np.array([[2.0, 0.4, -0.1], [0.5, 0.1, 0.0], [0.1, 0.0, 0.02], [0.01, 0, 0],
                  [0.02, 0, 0]])
    sfs = {ax: GainSurface(b, c * (1 + i), np.zeros(5), np.full(5, np.inf))
           for i, ax in enumerate(("roll", "pitch", "yaw"))}
    bps = [0.0, 4.5, 9.0, 13.5, 18.0]
    doc = schedule_from_surfaces(af, sfs, bps)
    gs = GainSchedule.from_dict(doc)
    assert gs.breakpoints_m_s == tuple(bps)
    assert gs.airframe_sha256 == af.sha256.lower()
    for v in bps:
        got = gs.gains_at(v)
        for ax, sf in sfs.items():
            want = sf.gains_at(v)
            for k in PARAM_NAMES:
                assert getattr(got[ax], k) == pytest.approx(want[k], rel=1e-5)


def test_written_gains_directory_is_what_the_autopilot_flies(tmp_path: Path) -> None:
    af = load_airframe()
    d = design_surfaces(RobustMethod(), af, "roll", _small_grid(), 1, n_starts=0,
                        max_iter=1)
    files = write_surface_gains(af, {ax: d for ax in ("roll", "pitch", "yaw")}, tmp_path)
    assert set(files) == {"gs-shif", "shif", "surfaces"}
    for name, sf in (("gs-shif", d.surface), ("shif", d.constant)):
        ctl = make_controller(name, tmp_path, airframe_name=af.name,
                              airframe_sha256=af.sha256)
        gs = GainSchedule.load(files[name])
        assert gs.breakpoints_m_s == tuple(p.airspeed_m_s for p in d.grid)
        assert ctl.name == name
        for v in gs.breakpoints_m_s:
            want = sf.gains_at(v)
            got = gs.gains_at(v)["roll"]
            for k in PARAM_NAMES:
                assert getattr(got, k) == pytest.approx(want[k], rel=1e-5)

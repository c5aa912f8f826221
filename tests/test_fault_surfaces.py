"""Gain surfaces designed on the predicted fault response (``synthesis/fault_surfaces.py``):
on the design objective J the surface design (GS-SHIF) is never worse than the constant
design (SHIF), which is never worse than the reference it starts from; J is what the reported
surfaces give, evaluated afresh; a worse optimiser result keeps the start."""

from __future__ import annotations

import numpy as np
import pytest

from vtolftc.airframe.loader import load_airframe
from vtolftc.synthesis import fault_surfaces as fs
from vtolftc.synthesis.fault_objective import PAPER_CASES
from vtolftc.synthesis.fault_surfaces import (
    FaultObjective,
    channel_kind,
    design_fault_surfaces,
)
from vtolftc.synthesis.robust import RobustMethod, robust_points
from vtolftc.synthesis.surfaces import GainSurface, SurfaceBasis, surface_grid, surface_problem

#: DS-1's shipped robust SHIF, roll (firmware_sim/autopilot/gains/shif.json).
REF = {"kp_angle": 2.60602, "kp_rate": 25.6777, "ki_rate": 120.103, "kd_rate": 0.813077,
       "tf_rate_s": 0.0625796}
CASES = [PAPER_CASES["1"], PAPER_CASES["2"]]


def _objective(af, grid, degree, slack):  # type: ignore[no-untyped-def]
    """J on the degree-``degree`` problem with the caps made from the reference."""
    basis = SurfaceBasis(0, grid[0].airspeed_m_s, grid[-1].airspeed_m_s)
    sp0 = surface_problem(RobustMethod(), af, "roll", grid, 0,
                          start=GainSurface.constant(basis, REF))
    caps = fs._caps(sp0, sp0.problem.channel_norms(sp0.problem.initial), slack)
    sp = surface_problem(RobustMethod(), af, "roll", grid, degree)
    return FaultObjective(sp, af, "roll", caps, CASES)


def test_channel_kinds() -> None:
    assert channel_kind("roll point 3 delay @ 7 m/s") == "delay"
    assert channel_kind("roll point 101 eq8 @ 0 m/s") == "eq8"
    assert channel_kind("roll point 1 disturbance @ 1.5 m/s") == "disturbance"


def test_surface_never_worse_than_constant_never_worse_than_reference_ds1() -> None:
    af = load_airframe()
    grid = surface_grid(robust_points(af), 1)
    d = design_fault_surfaces(RobustMethod(), af, "roll", grid, 1, max_evals=25,
                              reference=REF)
    f1 = _objective(af, grid, 1, d.slack)
    J_const = f1(d.constant.embed(1).coefficients.reshape(-1))
    J_surf = f1(d.surface.coefficients.reshape(-1))
    f0 = _objective(af, grid, 0, d.slack)
    J_ref = f0(np.array([REF[k] for k in ("kp_angle", "kp_rate", "ki_rate", "kd_rate",
                                           "tf_rate_s")]))
    assert np.isfinite(J_ref)
    assert J_const == pytest.approx(d.constant_J, rel=1e-9)
    assert J_surf == pytest.approx(d.surface_J, rel=1e-9)
    assert J_surf <= J_const <= J_ref
    # the optimiser made progress from the reference (a tuner that stalls fails here)
    assert J_const < J_ref


def test_a_worse_optimiser_result_keeps_the_constant_start(monkeypatch: pytest.MonkeyPatch,
                                                           ) -> None:
    af = load_airframe()
    grid = surface_grid(robust_points(af), 1)
    real = fs._minimise
    calls: list[int] = []

    def bad(f, theta0, max_evals):  # type: ignore[no-untyped-def]
        th, J, n = real(f, theta0, max_evals)
        calls.append(1)
        if len(calls) == 2:          # the surface stage: claim a much worse point
            th = theta0.copy()
            th[0] = f.sp.problem.lower[0]
            return th, f(th), n
        return th, J, n

    monkeypatch.setattr(fs, "_minimise", bad)
    d = design_fault_surfaces(RobustMethod(), af, "roll", grid, 1, max_evals=5,
                              reference=REF)
    assert len(calls) == 2
    assert d.kept_start
    assert d.surface_J == d.constant_J
    for v in (4.0, 7.0, 10.0):
        assert d.surface.gains_at(v) == pytest.approx(d.constant.gains_at(v), rel=1e-12)


def test_constant_starts_shif_is_the_lowest_J_of_all_starts(monkeypatch: pytest.MonkeyPatch,
                                                            ) -> None:
    """Every start of the SHIF stage is minimised (here: a minimiser that returns its start)
    and SHIF is the one of lowest J, whatever the order of the starts."""
    af = load_airframe()
    grid = surface_grid(robust_points(af), 1)
    f0 = _objective(af, grid, 0, 0.05)
    names = ("kp_angle", "kp_rate", "ki_rate", "kd_rate", "tf_rate_s")
    better = {**REF, "ki_rate": 1.1 * REF["ki_rate"]}
    worse = {**REF, "ki_rate": 0.9 * REF["ki_rate"]}
    J = {k: f0(np.array([g[n] for n in names]))
         for k, g in (("ref", REF), ("better", better), ("worse", worse))}
    assert J["better"] < J["ref"] < J["worse"]        # the premise of the test
    starts: list[np.ndarray] = []

    def stay(f, theta0, max_evals):  # type: ignore[no-untyped-def]
        starts.append(np.array(theta0))
        return theta0, f(theta0), 1

    monkeypatch.setattr(fs, "_minimise", stay)
    for extra, want in (([worse, better], better), ([worse], REF), ([better, worse], better)):
        starts.clear()
        d = design_fault_surfaces(RobustMethod(), af, "roll", grid, 1, max_evals=5,
                                  reference=REF, constant_starts=extra)
        assert len(starts) == 2 + len(extra)          # reference, extra starts, surface
        assert d.constant.gains_at(5.0) == pytest.approx(want, rel=1e-12)
        assert d.surface_J <= d.constant_J

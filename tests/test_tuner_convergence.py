"""The structured H-infinity tuner on COMPleib static-output-feedback problems (issue 23):
iteration limits that follow convergence, plant-scaled random starts that stabilise, and no
regression against the values before the fix (``tests/support/compleib.py``)."""

from __future__ import annotations

import math

import numpy as np
import pytest
from support.compleib import BEFORE_ISSUE_23, ISSUE_23_TARGETS, compleib, slycot_norm

from vtolftc.synthesis import nsbfgs, structured
from vtolftc.synthesis.blocks import StaticGain, lft_problem
from vtolftc.synthesis.hinfnorm import hinf_norm
from vtolftc.synthesis.lft import lft
from vtolftc.synthesis.structured import ITER_CAP, tune


def _sof(name: str):
    P = compleib(name)
    nu, ny = P.B2.shape[1], P.C2.shape[0]
    return P, lft_problem(P, StaticGain("K", nu, ny, plant=P)), (nu, ny)


def test_default_runs_each_start_to_convergence_and_an_int_is_a_hard_cap() -> None:
    _, pb, _ = _sof("AC4")
    res = tune(pb, n_starts=2, seed=1)
    for s in res.starts:
        assert s.status.startswith("converged"), s.status
        assert 0 < s.iterations < ITER_CAP
    capped = tune(pb, n_starts=2, seed=1, max_iter=2)
    assert all(s.iterations <= 2 for s in capped.starts)
    assert any(s.status == "max_iter reached" for s in capped.starts)
    with pytest.raises(ValueError, match="max_iter"):
        tune(pb, max_iter=0)


def test_a_start_without_progress_stops(monkeypatch: pytest.MonkeyPatch) -> None:
    """The progress test: a window of 2 iterations in which the objective must fall by 90 %
    stops every start early (AC4 needs ~10 iterations to converge otherwise)."""
    _, pb, _ = _sof("AC4")
    normal = tune(pb, n_starts=1, seed=1)
    monkeypatch.setattr(structured, "PROGRESS_WINDOW", 2)
    monkeypatch.setattr(structured, "PROGRESS_TOL", 0.9)
    res = tune(pb, n_starts=1, seed=1)
    for s, n in zip(res.starts, normal.starts, strict=True):
        assert s.status.startswith("converged (no progress"), s.status
        assert 2 <= s.iterations < n.iterations
    # the rule is off under an explicit cap: the same starts run on
    capped = tune(pb, n_starts=1, seed=1, max_iter=50)
    assert all(s.iterations > 2 for s in capped.starts)


@pytest.mark.parametrize("name", ["AC15", "BDT1", "HE1"])
def test_random_starts_with_a_far_too_large_scale_are_scaled_back_to_stability(
        name: str) -> None:
    """AC10's failure (issue 23: random gains spread 1.46e4, four of five starts never
    stabilise) reproduced with a gain scale 1e4 x the plant's: the random starts are pulled
    back towards their anchor until they are no less stable than it: K = 0 where it
    stabilises (AC15, BDT1), the stabilising gain of the spectral-abscissa phase where it does
    not (HE1 is open-loop unstable); all of them then stabilise (the slow test below)."""
    P = compleib(name)
    nu, ny = P.B2.shape[1], P.C2.shape[0]
    pb = lft_problem(P, StaticGain("K", nu, ny, scale=1e4 * P.gain_scale()))
    a0 = float(np.max(np.linalg.eigvals(P.A).real))
    anchor = structured.start_anchor(pb)
    assert anchor.stabilised == (a0 >= 0)
    assert anchor.abscissa < 0
    if not anchor.stabilised:
        np.testing.assert_array_equal(anchor.theta, pb.initial)
    jobs = structured.start_jobs(pb, n_starts=4, seed=0)
    rng_starts = [structured._sample_start(pb, np.random.default_rng(c), 1.0)
                  + (anchor.theta - pb.initial) for c in np.random.SeedSequence(0).spawn(4)]
    shrunk = 0
    for (_, _, th, _), raw in zip(jobs[1:], rng_starts, strict=True):
        a = float(np.max(np.linalg.eigvals(lft(P, th.reshape(nu, ny))[0]).real))
        assert a < 0  # every random start stabilises
        np.testing.assert_allclose(th - anchor.theta, 0, atol=np.max(np.abs(raw - anchor.theta)))
        if not np.allclose(th, raw, rtol=1e-12, atol=0):  # along the ray from the anchor
            ratio = (th - anchor.theta) / (raw - anchor.theta)
            np.testing.assert_allclose(ratio, ratio[0], rtol=1e-9)
            assert 0 < ratio[0] < 1
            shrunk += 1
    assert shrunk >= 1  # the raw draws were indeed too large


def test_ac10_random_starts_are_centred_on_a_stabilising_gain() -> None:
    """COMPleib AC10 (55 states, open-loop unstable, plant gain scales 1.46e4 and 7.8e-4):
    the random starts of the plant-scaled StaticGain all stabilise (before issue 23's fix
    four of five did not), and they differ from each other and from the anchor."""
    P, pb, (nu, ny) = _sof("AC10")
    anchor = structured.start_anchor(pb)
    assert anchor.stabilised and anchor.abscissa < 0
    jobs = structured.start_jobs(pb, n_starts=4, seed=0)
    thetas = [job[2] for job in jobs[1:]]
    for th in thetas:
        assert float(np.max(np.linalg.eigvals(lft(P, th.reshape(nu, ny))[0]).real)) < 0
        assert not np.allclose(th, anchor.theta)
    assert len({th.tobytes() for th in thetas}) == 4


@pytest.mark.slow
@pytest.mark.parametrize("name", ["AC15", "BDT1", "HE1"])
def test_every_start_stabilises_with_a_far_too_large_scale(name: str) -> None:
    P = compleib(name)
    nu, ny = P.B2.shape[1], P.C2.shape[0]
    pb = lft_problem(P, StaticGain("K", nu, ny, scale=1e4 * P.gain_scale()))
    res = tune(pb, n_starts=4, seed=0, max_iter=1)
    assert all(math.isfinite(s.value) for s in res.starts)


def test_plant_scaled_static_gain_keeps_the_unit_step() -> None:
    """The plant scale sets the random starts and the bounds, the step unit stays 1 (on HE3
    plant-scaled steps stall at 0.94, unit steps reach 0.82; ``bench_compleib.py``)."""
    P = compleib("HE3")
    prm = StaticGain("K", 4, 6, plant=P).parameters()
    np.testing.assert_allclose([p.sample_sd for p in prm], P.gain_scale().ravel())
    assert all(p.scale == 1.0 for p in prm)
    explicit = StaticGain("K", 4, 6, plant=P, scale=2.0).parameters()
    assert all(p.scale == 2.0 and p.sample_sd == 2.0 for p in explicit)


_QUICK = ["AC2", "AC4", "AC6", "AC7", "AC8", "AC15", "HE1"]


@pytest.mark.slow
@pytest.mark.parametrize("name", _QUICK)
def test_compleib_no_worse_than_before_and_the_norm_is_slycots(name: str) -> None:
    P, pb, (nu, ny) = _sof(name)
    res = tune(pb, n_starts=4, seed=0, polish=True)
    assert res.stable
    assert sum(math.isfinite(s.value) for s in res.starts) >= 4
    assert res.value <= BEFORE_ISSUE_23[name] * (1 + 1e-4)
    cl = lft(P, res.theta.reshape(nu, ny))
    assert res.value == pytest.approx(hinf_norm(cl, method="hamiltonian").value, rel=1e-6)
    assert res.value == pytest.approx(slycot_norm(cl), rel=1e-6)  # raw SLICOT AB13DD


@pytest.mark.slow
def test_every_ac10_start_stabilises() -> None:
    """Issue 23's AC10 must-show, its stabilisation part: all 5 starts (K = 0 through the
    spectral-abscissa phase, 4 random ones centred on its gain) reach a stabilising gain, each
    norm checked by raw SLICOT AB13DD. (Pulled back towards K = 0 instead, two of the four
    random starts collapsed onto K = 0's own run.) The norm target 13.45 is not reached yet
    (``bench_compleib.py AC10``)."""
    P, pb, (nu, ny) = _sof("AC10")
    res = tune(pb, n_starts=4, seed=0, max_iter=1)
    for s in res.starts:
        assert math.isfinite(s.value), s.status
        assert s.value == pytest.approx(slycot_norm(lft(P, s.theta.reshape(nu, ny))), rel=1e-6)


def test_polish_restarts_from_the_best_point_only_when_asked() -> None:
    """The polish stage (issue 23 item 6) is opt-in: by default ``tune`` gives the unpolished
    numbers bit for bit (the DS-1 design, ``start_jobs``/``collect_starts``); asked for, it
    restarts from the best point and lowers the objective (HE1 after 2 iterations: 0.1879
    without, 0.1595 with the polish)."""
    _, pb, _ = _sof("HE1")
    plain = tune(pb, n_starts=1, seed=1, max_iter=2, polish=False)
    default = tune(pb, n_starts=1, seed=1, max_iter=2)
    assert default.value == plain.value
    np.testing.assert_array_equal(default.theta, plain.theta)
    assert [s.status for s in default.starts] == [s.status for s in plain.starts]
    polished = tune(pb, n_starts=1, seed=1, max_iter=2, polish=True)
    assert polished.value < plain.value * (1 - 1e-3)
    assert sum("polished from" in s.status for s in polished.starts) == 1
    assert polished.value == pytest.approx(pb.objective(polished.theta), rel=1e-12)


def test_the_polish_restart_takes_the_other_step_unit() -> None:
    """Plant-scaled gains step in unit 1; the polish restart steps in the plant's gain scale
    (and back, for parameters whose unit already was their sample scale)."""
    P, pb, _ = _sof("HE3")
    alt = structured._alt_units(pb)
    assert alt is not None
    np.testing.assert_allclose(alt.scales, P.gain_scale().ravel())
    np.testing.assert_array_equal(structured._alt_units(alt).scales, pb.scales)
    plain = lft_problem(P, StaticGain("K", 4, 6))  # no plant scale: nothing to swap
    assert structured._alt_units(plain) is None


AC10_STALL = [0.1662832056960073, 1.5086920007036473e-05, 0.16698755757043476,
              8.726871482036256e-05]
"""Where AC10's start 0 (K = 0 through the spectral-abscissa phase) stops without the polish:
14.55400 after 32 iterations, "no progress" (``tune(n_starts=4, seed=0, polish=False)``; the
best of the five starts before the polish, 14.554)."""


def _converging() -> structured._Options:
    return structured._Options(ITER_CAP, 1e-7, 40, 1.0, 1000, to_convergence=True)


@pytest.mark.slow
def test_ac10_polish_reaches_the_published_value_from_where_the_starts_stall() -> None:
    """Issue 23's AC10 must-show, its norm part (13.45, the published structured H-infinity
    value): the polish from the stalled best start reaches it (13.2365, the norm checked by
    raw SLICOT AB13DD); without the polish (``_polish`` returning the record as it is) the
    value stays the stalled 14.554 and the test fails. The point's own units (``_units_at``)
    get there in about 40 iterations; without them the other two restarts also reach 13.2365
    but in 189 (measured). The full five-start tune of AC10 is in
    ``benchmarks/bench_compleib.py AC10`` only (minutes)."""
    P, pb, (nu, ny) = _sof("AC10")
    th = np.array(AC10_STALL)
    f0 = pb.objective(th)
    assert f0 == pytest.approx(14.554, abs=1e-3)
    rec = structured.StartRecord(0, th, th, f0, [f0], 32, "converged (no progress)")
    out = structured._polish(pb, rec, _converging())
    assert out.value <= 13.45
    assert out.value == pytest.approx(slycot_norm(lft(P, out.theta.reshape(nu, ny))), rel=1e-6)
    assert out.status.startswith("converged (no progress); polished from 14.554 to")


def test_nonsmooth_bfgs_steps_off_a_kink_by_gradient_sampling(
        monkeypatch: pytest.MonkeyPatch) -> None:
    """f = 10 |x1| + x2^2 from (0, 1): the gradient there, (10, 2), points uphill along
    -g (f(-10 t, 1 - 2 t) = 1 + 96 t + 4 t^2), so the weak Wolfe line search fails at once (as
    it does on HE3's trust-region stall); the gradient-sampling step (least-norm convex
    combination of nearby gradients, about (0, 2)) goes on to the minimiser. Without it
    (``SAMPLE_RADII`` empty) the run stops at f = 1 and this test fails."""

    def fg(x: np.ndarray) -> tuple[float, np.ndarray]:
        return 10 * abs(x[0]) + x[1] ** 2, np.array([10.0 if x[0] >= 0 else -10.0, 2 * x[1]])

    r = nsbfgs.nonsmooth_bfgs(fg, np.array([0.0, 1.0]), max_iter=200, window=20,
                              rel_tol=1e-9)
    assert r.value < 1e-6, (r.value, r.status)
    assert r.history[0] == 1.0
    assert all(b < a for a, b in zip(r.history, r.history[1:], strict=False))
    monkeypatch.setattr(nsbfgs, "SAMPLE_RADII", ())
    stuck = nsbfgs.nonsmooth_bfgs(fg, np.array([0.0, 1.0]), max_iter=200, window=20,
                                  rel_tol=1e-9)
    assert stuck.value == 1.0 and stuck.iterations == 0
    assert stuck.status.startswith("stationary")


def test_nonsmooth_bfgs_needs_a_finite_start() -> None:
    with pytest.raises(ValueError, match="finite objective"):
        nsbfgs.nonsmooth_bfgs(lambda x: (math.inf, None), np.zeros(2), max_iter=5,
                              window=2, rel_tol=0.0)


@pytest.mark.slow
def test_he3_bfgs_from_the_start_reaches_the_issue_target() -> None:
    """Issue 23's HE3 must-show (<= 0.8157, the best earlier result): nonsmooth BFGS from K = 0
    (stabilised by the spectral-abscissa phase, as start 0 is) reaches it, the norm checked by
    raw SLICOT AB13DD and the closed loop stable. The trust-region solver from the same point
    stops at 0.82254 (84 iterations, "small decrease"; the old polish from there 0.817), with
    a closed-loop pole pair held on its abscissa constraint, so without the BFGS stage the
    value stays above the target (``bench_compleib.py`` docstring). From exactly K = 0 the
    path is the CPU's rounding's to decide (0.80696 on one machine, 0.85458 against the
    stability boundary on another): the jittered starts of ``_bfgs_from`` (0.80695, 0.80415
    there) make the target independent of it."""
    P, pb, (nu, ny) = _sof("HE3")
    out = structured._bfgs_from(pb, pb.initial, _converging())
    assert out is not None
    th, f = out[0], out[1]
    assert f <= ISSUE_23_TARGETS["HE3"], (f, out[3], out[4])
    cl = lft(P, th.reshape(nu, ny))
    assert f == pytest.approx(slycot_norm(cl), rel=1e-6)
    assert float(np.max(np.linalg.eigvals(cl[0]).real)) < 0


def test_bfgs_from_runs_the_start_and_its_jittered_copies_and_keeps_the_best(
        monkeypatch: pytest.MonkeyPatch) -> None:
    """``_bfgs_from`` runs BFGS from the start and from BFGS_JITTER_SEEDS copies moved by
    BFGS_JITTER of the scales (seeded: the same copies every run), keeps the lowest and counts
    the iterations of all."""
    _, pb, _ = _sof("HE1")
    seen: list[np.ndarray] = []
    values = iter([3.0, 1.0, 2.0])

    def fake_stage(ev, th, opts):  # type: ignore[no-untyped-def]
        seen.append(np.array(th))
        f = next(values)
        return th, f, [f], 10, f"stand-in {f}"

    monkeypatch.setattr(structured, "_bfgs_stage", fake_stage)
    th0 = tune(pb, n_starts=1, seed=1, max_iter=2, polish=False).theta
    out = structured._bfgs_from(pb, th0, _converging())
    assert out is not None
    assert len(seen) == 1 + len(structured.BFGS_JITTER_SEEDS) == 3
    np.testing.assert_array_equal(seen[0], np.clip(th0, pb.lower, pb.upper))
    for k, s in enumerate(structured.BFGS_JITTER_SEEDS, start=1):
        d = (seen[k] - th0) / pb.scales
        assert 0 < np.max(np.abs(d)) <= structured.BFGS_JITTER
        u = np.random.default_rng(s).uniform(-1.0, 1.0, th0.size)
        np.testing.assert_allclose(d, structured.BFGS_JITTER * u, rtol=1e-9, atol=1e-15)
    assert out[1] == 1.0 and out[4] == "stand-in 1.0" and out[3] == 30
    np.testing.assert_array_equal(out[0], seen[1])


def test_polish_runs_bfgs_from_the_best_starts_own_start(
        monkeypatch: pytest.MonkeyPatch) -> None:
    """The polish's first stage is BFGS from the best start's start point (``theta0``), not
    only from where it stopped; its point is kept when better (here: a stand-in that returns
    a point of lower objective is taken, then the rounds restart from it)."""
    _, pb, _ = _sof("HE1")
    seen: list[np.ndarray] = []
    better = tune(pb, n_starts=1, seed=1, polish=False).theta

    def fake_bfgs_from(problem, theta0, opts):  # type: ignore[no-untyped-def]
        seen.append(np.array(theta0))
        return better, pb.objective(better), [pb.objective(better)], 7, "stand-in"

    monkeypatch.setattr(structured, "_bfgs_from", fake_bfgs_from)
    rec = tune(pb, max_iter=1).starts[0]  # K = 0 (unstable), one iteration after phase 1
    assert math.isfinite(rec.value) and rec.value > pb.objective(better)
    out = structured._polish(pb, rec, structured._Options(2, 1e-7, 40, 1.0, 1000))
    assert len(seen) == 1
    np.testing.assert_array_equal(seen[0], rec.theta0)
    assert out.value <= pb.objective(better)
    assert out.iterations >= rec.iterations + 7

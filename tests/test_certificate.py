"""The real-parametric certificate (synthesis/certificate.py) against independent answers:
the airframe's models, the robust design plant, python-control's closed loop, a family whose
real mu is known in closed form (Routh), and the dense grid of closed-loop poles."""

from __future__ import annotations

import json
import math
from pathlib import Path

import numpy as np
import pytest

from vtolftc.airframe.loader import load_airframe
from vtolftc.synthesis import certificate as C  # noqa: N812
from vtolftc.synthesis.hinfnorm import frequency_response
from vtolftc.synthesis.loops import closed_loop
from vtolftc.synthesis.models import attitude_model, axis_coefficients
from vtolftc.synthesis.robust import ROBUST_DESIGN_POINTS, design_plant
from vtolftc.synthesis.uncertainty import DesignPoint

GAINS = Path(__file__).resolve().parents[1] / "firmware_sim" / "autopilot" / "gains"


@pytest.fixture(scope="module")
def af():
    return load_airframe()


@pytest.fixture(scope="module")
def robust_gs():
    return json.loads((GAINS / "gs-shif.json").read_text())


@pytest.fixture(scope="module")
def paper_gs():
    return json.loads((GAINS / "paper" / "gs-shif.json").read_text())


def test_pieces_split_at_table_breakpoints(af):
    p = DesignPoint(2, 1.0, 0.8, 2.5)
    assert C.airspeed_pieces(af, p) == [(0.8, 1.0), (1.0, 2.0), (2.0, 2.5)]
    assert C.airspeed_pieces(af, DesignPoint(7, 18.0, 13.0, 20.0)) == [(13.0, 18.0),
                                                                     (18.0, 20.0)]
    with pytest.raises(ValueError, match="straddles"):
        C.family(af, "roll", 0.8, 2.5)


@pytest.mark.parametrize("axis", ["roll", "pitch", "yaw"])
def test_family_coefficients_equal_the_model(af, axis):
    rng = np.random.default_rng(1)
    for p in ROBUST_DESIGN_POINTS:
        for lo, hi in C.airspeed_pieces(af, p):
            fam = C.family(af, axis, lo, hi)
            assert fam.n_v == (2 if axis == "roll" else 3) or hi > 18.0
            for dV in rng.uniform(-1, 1, 3):
                c = axis_coefficients(af, axis, float(fam.airspeed(dV)))
                D, K, _ = fam.coefficients(dV, 0.0)
                assert float(D) == pytest.approx(c.damping, rel=1e-12, abs=1e-12)
                assert float(K) == pytest.approx(c.stiffness, rel=1e-12, abs=1e-12)


@pytest.mark.parametrize("plant", ["lagged", "paper"])
@pytest.mark.parametrize("axis", ["roll", "pitch", "yaw"])
def test_lft_equals_the_model_in_frequency(af, axis, plant):
    """The LFT with the real blocks closed is the plant of (V, gamma), by frequency
    response, at random members of several pieces."""
    rng = np.random.default_rng(2)
    w = np.logspace(-2, 2, 25)
    for lo, hi in [(0.0, 0.8), (2.5, 4.0), (7.0, 8.5), (13.0, 18.0)]:
        fam = C.family(af, axis, lo, hi, plant=plant)
        for dV, dg in rng.uniform(-1, 1, (3, 2)):
            V, g = float(fam.airspeed(dV)), float(fam.gamma(dg))
            ref = design_plant(af, axis, V, g) if plant == "lagged" else attitude_model(
                af, axis, V, g)
            F = frequency_response(C.upper_lft_plant(fam, dV, dg), w)
            Fr = frequency_response(ref, w)
            np.testing.assert_allclose(F, Fr, rtol=1e-9, atol=1e-12)


def test_closed_loops_agree(af, robust_gs):
    """M(s) with Delta closed, the directly assembled true closed loop and python-control's
    (loops.closed_loop) have the same poles."""
    rng = np.random.default_rng(3)
    for axis in ("roll", "pitch", "yaw"):
        th = C.gains_at(robust_gs, axis, 2)
        for plant in ("lagged", "paper"):
            fam = C.family(af, axis, 2.5, 4.0, plant=plant)
            A, B, Cm, D = C.closed_loop_lft(fam, th)
            for dV, dg in rng.uniform(-1.0, 1.0, (3, 2)):
                V, g = float(fam.airspeed(dV)), float(fam.gamma(dg))
                G = design_plant(af, axis, V, g) if plant == "lagged" else attitude_model(
                    af, axis, V, g)
                ref = np.sort_complex(closed_loop(G, th).poles)
                Dl = np.diag([dV] * fam.n_v + [dg])
                Ap = A + B @ Dl @ np.linalg.solve(np.eye(fam.n_v + 1) - D @ Dl, Cm)
                At = C.true_closed_loop_matrices(fam.inertia, *fam.coefficients(dV, dg),
                                                 fam.tau_s, th)[0]
                for X in (Ap, At):
                    np.testing.assert_allclose(np.sort_complex(np.linalg.eigvals(X)), ref,
                                               rtol=1e-8, atol=1e-9)


def _hand_family(b0: float, rg: float) -> C.ParametricFamily:
    """J s^2 (s - 0) rate loop: plant b / (J s), no airspeed dependence, no lag."""
    return C.ParametricFamily("roll", 1.0, np.zeros(1), np.zeros(1), 0.0, 0.0, 1.0 - b0, rg,
                              None)


def test_closed_form_real_mu_brackets():
    """Plant b/(s^2) (angle), u = (kp + ki/s) e: J s^3 + b kp s^2 + b (kp kpa + ki) s +
    b ki kpa (kd = 0). Routh: unstable below b_crit = J ki kpa / (kp (kp kpa + ki)) = 0.8
    (J = kp = kpa = 1, ki = 4) at w = sqrt(a1 / a3) = 2 rad/s, and at b = 0 (w = 0).
    With b = 1.2 - 0.6 dg: mu = 0.6 / (1.2 - 0.8) = 1.5 at 2 rad/s (mu(0) = 0.5): a spike
    in frequency (one real parameter), found through the vertex crossings."""
    fam = _hand_family(1.2, 0.6)
    th = {"kp_angle": 1.0, "kp_rate": 1.0, "ki_rate": 4.0, "kd_rate": 0.0, "tf_rate_s": 0.05}
    sw = C.mu_real_sweep(fam, th)
    assert sw.peak_lower <= 1.5 * (1 + 1e-6)
    assert sw.peak_upper >= 1.5 * (1 - 1e-6)
    assert sw.peak_upper == pytest.approx(1.5, rel=2e-3)
    assert sw.peak_lower == pytest.approx(1.5, rel=2e-3)
    assert sw.peak_upper_frequency_rad_s == pytest.approx(2.0, rel=1e-3)
    i0 = int(np.nonzero(sw.omegas == 0.0)[0][0])
    assert sw.upper[i0] >= 0.5 * (1 - 1e-6)
    _, khi = C.grid_margin(fam, th)
    assert 1.0 / khi == pytest.approx(1.5, rel=1e-3)
    M0 = frequency_response(C.closed_loop_lft(fam, th), np.array([0.0]))[0]
    assert C.zero_frequency_margin(M0, fam) == pytest.approx(2.0, abs=0.05)


def test_two_parameter_lower_repeated_real_closed_form():
    """diag(dV I_2, dg) with M = blockdiag(A, 0): mu = largest |real eigenvalue| of A."""
    A = np.array([[0.3, 2.0], [-0.1, 0.5]], complex)   # eigenvalues 0.4 +- 0.436j: none real
    B = np.array([[1.0, 0.5], [0.0, -0.8]], complex)   # real eigenvalues 1 and -0.8
    for X, mu in ((A, 0.0), (B, 1.0)):
        M = np.zeros((3, 3), complex)
        M[:2, :2] = X
        assert C.two_parameter_lower(M, 2) == pytest.approx(mu, abs=1e-9)


@pytest.mark.parametrize("axis,i", [("roll", 0), ("pitch", 0), ("yaw", 0), ("yaw", 6)])
def test_bounds_and_grid_on_robust_design(af, robust_gs, axis, i):
    """upper >= lower, and upper >= 1 / k_hi of the grid (a grid member unstable at scale
    k proves mu >= 1/k): would fail if the upper bound missed the peak."""
    p = C.design_points(robust_gs)[i]
    c = C.certify_point(af, axis, p, C.gains_at(robust_gs, axis, i), "lagged")
    assert c.mu_upper >= c.mu_lower
    for q in c.pieces:
        assert q.mu_upper >= q.mu_lower
        assert q.mu_upper >= q.grid_mu * (1 - 1e-3)
        assert q.mu_upper_at_zero >= (1.0 / q.zero_frequency_k) * (1 - 1e-6)
    assert c.grid.stable == (c.grid.unstable_members == 0)
    if not c.grid.stable:
        assert c.mu_upper >= 1.0 and not c.certified


def test_unstable_grid_member_is_never_certified(af, paper_gs):
    """Paper design, yaw point 1, on its own plant: the grid finds unstable members of the
    box; the mixed-mu upper bound is >= 1 and the certificate says so."""
    p = C.design_points(paper_gs)[0]
    c = C.certify_point(af, "yaw", p, C.gains_at(paper_gs, "yaw", 0), "paper")
    assert not c.grid.stable and c.grid.max_real_pole > 0
    assert c.mu_upper >= 1.0 and c.mu_lower >= 1.0
    assert not c.certified and c.verdict.startswith("not certified")


def test_scaled_box_beyond_the_grid_margin_is_not_certified(af, robust_gs):
    """Scale a certified piece's box to 1.05 x its grid margin: the grid (true-model
    continuation) has an unstable member at scale 1, so the upper bound must be >= 1."""
    th = C.gains_at(robust_gs, "roll", 0)
    fam = C.family(af, "roll", 0.0, 0.8)
    klo, khi = C.grid_margin(fam, th)
    assert 1.0 < khi < C.K_MAX
    big = fam.scaled(1.05 * khi)
    assert C._max_re_scaled(big, th, 1.0, 41) >= 0.0
    assert C.mu_real_sweep(big, th).peak_upper >= 1.0
    small = fam.scaled(0.95 * klo)
    assert C.mu_real_sweep(small, th).peak_upper < 1.0


def test_box_with_reversed_effectiveness_is_not_certified(af, robust_gs):
    """gamma up to 1.1 (effectiveness reversed): unstable members, upper bound >= 1."""
    p = C.design_points(robust_gs)[3]
    c = C.certify_point(af, "pitch", p, C.gains_at(robust_gs, "pitch", 3), "lagged",
                        gamma_range=(0.0, 1.1), grid_n=21)
    assert not c.grid.stable
    assert c.mu_upper >= 1.0 and not c.certified
    assert math.isfinite(c.mu_upper)


@pytest.mark.slow
def test_every_robust_shif_axis_point(af):
    """The constant robust SHIF gains at all 21 axis-points: upper >= lower >= 0, upper >=
    the grid's 1/k on every piece, and a grid with an unstable member is never certified
    (yaw 1-3 are: the loop is conditionally stable and loses stability at hover below
    about 0.66 of its yaw effectiveness)."""
    doc = json.loads((GAINS / "shif.json").read_text())
    recs = C.certify_schedule(af, doc, "lagged", grid_n=21)
    assert len(recs) == 21
    for r in recs:
        assert r["mu_upper"] >= r["mu_lower"] >= 0.0
        for q in r["pieces"]:
            assert q["mu_upper"] >= (q["grid_mu"] or 0.0) * (1 - 1e-3)
        if not r["grid_stable"]:
            assert r["mu_upper"] >= 1.0 and not r["certified"]
    assert {(r["axis"], r["point"]) for r in recs if not r["certified"]} == {
        ("yaw", 1), ("yaw", 2), ("yaw", 3)}


@pytest.mark.parametrize("n_v", [0, 2, 3])
def test_zero_frequency_margin_equals_the_brute_force_grid(n_v):
    """det(I - M(0) Delta) from two determinants per dV (affine in dg) against one
    determinant per grid point, on random real M and the same grid."""
    rng = np.random.default_rng(40 + n_v)
    fam = C.ParametricFamily("pitch", 1.0, np.ones(n_v + 1), np.zeros(1), 5.0, 1.0, 0.3,
                             0.3, None)
    assert fam.n_v == n_v
    d = np.linspace(-C.K_MAX, C.K_MAX, 41)
    for scale in (0.05, 0.3, 1.0):
        M = scale * rng.normal(size=(n_v + 1, n_v + 1))
        bad = [max(abs(v), abs(g)) for v in d for g in d
               if np.linalg.det(np.eye(n_v + 1) - M @ np.diag([v] * n_v + [g])) <= 0.0]
        ref = min(bad) if bad else math.inf
        assert C.zero_frequency_margin(M, fam, n=41) == ref

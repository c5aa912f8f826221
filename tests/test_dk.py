"""D-K iteration with the fixed P-PID structure (``synthesis/dk.py``).

How each test can fail: the fit tests fail if the least squares does not recover a rational
scaling it can represent; the direction test fails if the channel applies D^-1 N D (its
norm is then 8.03, not 1); the mu tests compare with the independent bound of
``synthesis/mu.py`` and fail if the D step's values differ from it or if the iteration
returns gains with a larger (or not smaller) peak mu than the start.
"""

from __future__ import annotations

import control as ct
import numpy as np
import pytest

from vtolftc.synthesis.dk import (
    RationalScaling,
    ScaledChannel,
    cascade_rp,
    dk_iterate,
    fit_scaling,
    optimal_scalings,
    scaled_system,
)
from vtolftc.synthesis.hinfnorm import frequency_response, hinf_norm
from vtolftc.synthesis.loops import ControlWeight, SensitivityWeight
from vtolftc.synthesis.mu import mu_bounds, mu_sweep
from vtolftc.synthesis.robustness import RP_BLOCKS, square_rp
from vtolftc.synthesis.structured import Parameter


def _static(M: np.ndarray) -> tuple[np.ndarray, ...]:
    p, m = M.shape
    return np.zeros((0, 0)), np.zeros((0, m)), np.zeros((p, 0)), np.asarray(M, float)


def test_fit_reproduces_a_first_order_scaling() -> None:
    w = np.logspace(-3, 3, 121)
    true = RationalScaling(3.0, (0.5,), (20.0,))
    D = fit_scaling(w, np.abs(true.response(w)), order=1)
    assert D.gain == pytest.approx(3.0, rel=1e-4)
    assert D.zeros_rad_s[0] == pytest.approx(0.5, rel=1e-4)
    assert D.poles_rad_s[0] == pytest.approx(20.0, rel=1e-4)


def test_fit_reproduces_a_second_order_scaling() -> None:
    w = np.logspace(-3, 3, 121)
    true = RationalScaling(0.2, (0.05, 30.0), (1.0, 2.0))
    d = np.abs(true.response(w))
    D = fit_scaling(w, d, order=2)
    err = np.max(np.abs(np.log(np.abs(D.response(w))) - np.log(d)))
    assert err < 1e-4
    assert sorted(D.zeros_rad_s) == pytest.approx([0.05, 30.0], rel=1e-3)
    assert sorted(D.poles_rad_s) == pytest.approx([1.0, 2.0], rel=1e-3)


def test_scaling_ss_matches_response_and_inverse() -> None:
    D = RationalScaling(2.0, (0.3, 4.0), (1.5, 40.0))
    w = np.logspace(-2, 3, 30)
    r = frequency_response(D.ss(), w)[:, 0, 0]
    ri = frequency_response(D.ss(inverse=True), w)[:, 0, 0]
    assert np.allclose(r, D.response(w), rtol=1e-10)
    assert np.allclose(r * ri, 1.0, rtol=1e-10)


def test_scaling_is_applied_as_d_n_dinv() -> None:
    # mu of N is 1 with d = 1/4: diag(d, 1) N diag(1/d, 1) = [[.5, .5], [.5, .5]]; applied
    # backwards (D^-1 N D) the same d gives [[.5, 8], [1/32, .5]], norm 8.03
    N = np.array([[0.5, 2.0], [0.125, 0.5]])
    d, mu, free = optimal_scalings(N[None].astype(complex))
    assert d[0] == pytest.approx(0.25, rel=1e-5)
    assert mu[0] == pytest.approx(1.0, rel=1e-6)
    assert not free[0]
    ch = ScaledChannel(lambda th: _static(N), RationalScaling(float(d[0])))
    assert hinf_norm(ch(np.zeros(1))).value == pytest.approx(1.0, rel=1e-6)
    # dynamic D on a dynamic N: the scaled response is D(jw) N12 and N21 / D(jw)
    D = RationalScaling(2.0, (0.5,), (5.0,))
    Nd = (np.array([[-1.0]]), np.array([[1.0, 0.0]]), np.array([[1.0], [0.0]]),
          np.array([[0.0, 1.0], [1.0, 0.0]]))
    w = np.array([0.1, 1.0, 10.0])
    F = frequency_response(scaled_system(Nd, D), w)
    Dw = D.response(w)
    assert np.allclose(F[:, 0, 1], Dw * 1.0)
    assert np.allclose(F[:, 1, 0], 1.0 / Dw)


def test_optimal_scalings_agree_with_mu_bounds() -> None:
    rng = np.random.default_rng(3)
    F = rng.normal(size=(6, 3, 2)) + 1j * rng.normal(size=(6, 3, 2))
    _, mu, _ = optimal_scalings(F)
    for i in range(F.shape[0]):
        b = mu_bounds(square_rp(F[i:i + 1])[0], RP_BLOCKS)
        assert mu[i] == pytest.approx(b.upper, rel=1e-4)
        assert mu[i] >= b.lower * (1 - 1e-6)


def _textbook() -> tuple[object, list[Parameter], np.ndarray]:
    """A rate-and-angle cascade on an inertia J = 0.1 kg m^2 behind a 50 ms actuator lag,
    a 30 % input uncertainty rising to 200 % above 20 rad/s, Ws with M = 1.5 and
    omega_b = 2 rad/s, Wr eq. 6."""
    J, tau = 0.1, 0.05
    G = ct.ss(ct.tf([1.0], [tau, 1.0])) * ct.ss([[0.0, 0.0], [1.0, 0.0]], [[1.0 / J], [0.0]],
                                                 np.eye(2), np.zeros((2, 1)))
    Wt = ct.tf([2.0 / 20.0, 0.3], [1.0 / 20.0 / 6.0, 1.0])
    rp = cascade_rp(ct.ss(G), SensitivityWeight(1.5, 2.0), Wt, ControlWeight(0.5, 2.0, 5.0))
    params = [Parameter("kp_angle", 2.0, 0.1, 10.0, scale=1.0),
              Parameter("kp_rate", 0.3, 0.01, 3.0, scale=J),
              Parameter("ki_rate", 0.3, 0.001, 10.0, scale=J),
              Parameter("kd_rate", 0.005, 0.0, 0.05, scale=0.01 * J),
              Parameter("tf_rate_s", 0.02, 0.01, 0.5, scale=0.02)]
    return rp, params, np.array([p.initial for p in params])


def _mu_peak(rp: object, theta: np.ndarray, w: np.ndarray) -> float:
    F = frequency_response(rp(theta), w)                   # type: ignore[operator]
    return mu_sweep(square_rp(F), RP_BLOCKS, w, n_starts=0).peak_upper


@pytest.mark.slow
def test_dk_does_not_increase_peak_mu_textbook() -> None:
    rp, params, th0 = _textbook()
    w = np.logspace(-3, 3, 61)
    res = dk_iterate(rp, params, th0, order=1, max_iter=3, omegas=w, tune_iter=20)
    before, after = _mu_peak(rp, th0, w), _mu_peak(rp, res.theta, w)
    assert res.steps[0].mu_peak == pytest.approx(before, rel=1e-4)
    assert res.mu_peak == pytest.approx(after, rel=1e-4)
    assert after <= before * (1 + 1e-9)
    assert after < 0.97 * before          # the iteration does something


def test_dk_rejects_unstable_start_and_bad_settings() -> None:
    rp, params, th0 = _textbook()
    with pytest.raises(ValueError, match="max_iter"):
        dk_iterate(rp, params, th0, max_iter=0)
    with pytest.raises(ValueError, match="order"):
        fit_scaling([1.0, 2.0], [1.0, 1.0], order=3)
    with pytest.raises(ValueError, match="> 0"):
        RationalScaling(1.0, (-1.0,), (1.0,))


def test_synth_dk_rejects_bad_input(tmp_path, capsys) -> None:  # type: ignore[no-untyped-def]
    from vtolftc.cli.main import run

    for argv, word in ((["--dk", "0"], "--dk 0"), (["--dk", "21"], "--dk 21"),
                       (["--method", "paper", "--dk", "2"], "--method robust only"),
                       (["--method", "surface", "--dk", "2"], "--method robust only")):
        assert run(["synth", *argv, "--out", str(tmp_path)]) == 2
        err = capsys.readouterr().err
        assert word in err
        assert len(err.strip().splitlines()) == 1 and "Traceback" not in err


@pytest.mark.slow
def test_dk_on_ds1_axis_point_keeps_requirements(tmp_path) -> None:  # type: ignore[no-untyped-def]
    """One D-K iteration at DS-1 roll point 3 from the shipped robust gains: mu_RP falls,
    the delay margin stays >= 50 ms and the rotor-out channel is no worse; the gains file
    written holds the new gains at that point only."""
    import json
    from pathlib import Path

    from vtolftc.airframe.loader import load_airframe
    from vtolftc.synthesis.dk_robust import DKSettings, dk_schedule
    from vtolftc.synthesis.dk_run import write_dk_outputs
    from vtolftc.synthesis.loops import PARAM_NAMES
    from vtolftc.synthesis.robust import robust_points

    af = load_airframe()
    shipped = Path(__file__).resolve().parents[1] / "firmware_sim/autopilot/gains"
    doc = json.loads((shipped / "gs-shif.json").read_text())
    pts = robust_points(af)
    gains = {ax: [{k: doc["axes"][ax][k][i] for k in PARAM_NAMES} for i in range(len(pts))]
             for ax in ("roll", "pitch", "yaw")}
    st = DKSettings(max_iter=1)
    (r,) = dk_schedule(af, pts, gains, only=lambda ax, p: (ax, p.number) == ("roll", 3),
                       settings=st)
    assert r.after["mu_rp"] < 0.95 * r.before["mu_rp"]
    assert r.after["delay_margin_s"] >= 0.050
    assert r.after["Wd*Sd"] <= r.before["Wd*Sd"] * (1 + 1e-6)
    files = write_dk_outputs(af, pts, gains, [r], st, tmp_path, shipped)
    out = json.loads(files["gs-shif"].read_text())
    assert out["axes"]["roll"]["kp_angle"][2] == pytest.approx(r.gains_after["kp_angle"],
                                                               rel=1e-5)
    assert out["axes"]["roll"]["kp_angle"][2] != doc["axes"]["roll"]["kp_angle"][2]
    for ax in ("pitch", "yaw"):
        assert out["axes"][ax]["kp_rate"] == doc["axes"][ax]["kp_rate"]
    assert (tmp_path / "shif.json").is_file() and (tmp_path / "DK.md").is_file()


@pytest.mark.slow
def test_synth_dk_writes_the_dk_folder(tmp_path, capsys) -> None:  # type: ignore[no-untyped-def]
    """The ``--dk`` stage of ``vtolftc synth`` on a one-point robust result (point 5, the
    shipped gains): DIR/dk holds the gains, dk.json and DK.md, and the table is printed."""
    import argparse
    import json
    from pathlib import Path
    from types import SimpleNamespace

    from vtolftc.airframe.loader import load_airframe
    from vtolftc.cli.cmd_synth import _cmd_dk
    from vtolftc.synthesis.loops import PARAM_NAMES
    from vtolftc.synthesis.robust import robust_points

    af = load_airframe()
    shipped = Path(__file__).resolve().parents[1] / "firmware_sim/autopilot/gains"
    doc = json.loads((shipped / "gs-shif.json").read_text())
    pt = robust_points(af)[4]
    gs = {ax: [SimpleNamespace(gains={k: doc["axes"][ax][k][4] for k in PARAM_NAMES})]
          for ax in ("roll", "pitch", "yaw")}
    res = SimpleNamespace(points=(pt,), gs=gs)
    args = argparse.Namespace(dk=1, out=tmp_path, jobs=1, quiet=True)
    assert _cmd_dk(args, af, res) == 0
    out = capsys.readouterr().out
    assert "| pitch | 5 | 10 |" in out
    d = json.loads((tmp_path / "dk" / "dk.json").read_text())
    assert [(p["axis"], p["point"]) for p in d["points"]] == [("roll", 5), ("pitch", 5),
                                                              ("yaw", 5)]
    g = json.loads((tmp_path / "dk" / "gs-shif.json").read_text())
    assert g["airspeed_breakpoints_m_s"] == [10.0]
    assert (tmp_path / "dk" / "DK.md").is_file()

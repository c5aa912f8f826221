"""Tests of the discrete cascaded P-PID (``vtolftc.firmware_sim.autopilot.pid``) against the
continuous transfer function K_rate(s) = kp + ki/s + kd s/(tf s + 1) (scipy.signal)."""

from __future__ import annotations

import math

import numpy as np
import pytest
import scipy.signal as sg

from vtolftc.firmware_sim.autopilot.pid import CascadedPPID, PPIDGains, wrap_angle

DT = 1.0 / 250.0
G = PPIDGains(kp_angle=4.0, kp_rate=0.8, ki_rate=0.5, kd_rate=0.05, tf_rate_s=0.05)


def run_rate(c: CascadedPPID, e: np.ndarray) -> np.ndarray:
    return np.array([c.update_rate(ei, 0.0) for ei in e])


def continuous_response(g: PPIDGains, t_end: float, u_of_t, fine: int = 40):
    """Continuous K_rate(s) response sampled at the controller instants (lsim on a fine grid)."""
    num, den = g.rate_tf()
    t = np.arange(0.0, t_end, DT / fine)
    _, y, _ = sg.lsim((num, den), u_of_t(t), t)
    return y[::fine]


def test_rate_tf_coefficients():
    num, den = G.rate_tf()
    kp, ki, kd, tf = 0.8, 0.5, 0.05, 0.05
    np.testing.assert_allclose(num, [kp * tf + kd, kp + ki * tf, ki])
    np.testing.assert_allclose(den, [tf, 1.0, 0.0])
    # value at s = j w equals kp + ki/s + kd s/(tf s + 1)
    s = 3.0j
    np.testing.assert_allclose(
        np.polyval(num, s) / np.polyval(den, s), kp + ki / s + kd * s / (tf * s + 1)
    )
    cc = CascadedPPID(G).continuous_coefficients()
    assert cc.kp_angle == 4.0 and cc.tf_rate_s == 0.05
    np.testing.assert_allclose(cc.rate_num, num)


def test_tustin_is_the_bilinear_image_of_the_continuous_controller():
    c = CascadedPPID(G, DT)
    num, den = c.discrete_rate_tf()
    nd, dd, _ = sg.cont2discrete(G.rate_tf(), DT, method="bilinear")
    np.testing.assert_allclose(num, np.ravel(nd), rtol=1e-12)
    np.testing.assert_allclose(den, np.ravel(dd), rtol=1e-12)


@pytest.mark.parametrize("method", ["tustin", "backward_euler"])
def test_implementation_equals_its_discrete_transfer_function(method):
    rng = np.random.default_rng(0)
    e = rng.standard_normal(500)
    c = CascadedPPID(G, DT, method=method)
    y = run_rate(c, e)
    num, den = c.discrete_rate_tf()
    _, yd = sg.dlsim((num, den, DT), e)
    np.testing.assert_allclose(y, np.ravel(yd), atol=1e-10)


@pytest.mark.parametrize("method, tol", [("tustin", 0.01), ("backward_euler", 0.03)])
def test_step_response_matches_continuous(method, tol):
    T = 2.0
    y_c = continuous_response(G, T, lambda t: np.ones_like(t))
    y_d = run_rate(CascadedPPID(G, DT, method=method), np.ones(y_c.size))
    scale = np.max(np.abs(y_c))  # kp + kd/tf = 1.8 at t = 0
    # the first sample carries the derivative kick (sampled vs continuous): compare after it,
    # and the P + I part exactly everywhere after one filter time constant
    err = np.abs(y_d - y_c)
    assert np.max(err[1:]) / scale < 3 * tol
    k = int(5 * G.tf_rate_s / DT)
    assert np.max(err[k:]) / scale < tol
    np.testing.assert_allclose(y_d[-1], 0.8 + 0.5 * (y_c.size - 1) * DT + 0.0, rtol=0.01)


@pytest.mark.parametrize("method, tol", [("tustin", 0.005), ("backward_euler", 0.02)])
def test_ramp_response_matches_continuous(method, tol):
    T = 2.0
    y_c = continuous_response(G, T, lambda t: t)
    e = np.arange(y_c.size) * DT
    y_d = run_rate(CascadedPPID(G, DT, method=method), e)
    assert np.max(np.abs(y_d - y_c)) / np.max(np.abs(y_c)) < tol


def test_cascade_outer_loop_feeds_inner_loop():
    c = CascadedPPID(G, DT)
    ref = CascadedPPID(G, DT)
    for _ in range(50):
        u = c.update(angle_ref=0.1, angle=0.02, rate=0.3)
        u_ref = ref.update_rate(4.0 * (0.1 - 0.02), 0.3)
        assert u == pytest.approx(u_ref)
    assert c.rate_ref == pytest.approx(4.0 * 0.08)


def test_rate_reference_limit_and_feed_forward():
    c = CascadedPPID(G, DT, rate_limit=0.5)
    assert c.rate_reference(1.0, 0.0) == pytest.approx(0.5)
    assert c.rate_reference(-1.0, 0.0) == pytest.approx(-0.5)
    assert c.rate_reference(0.0, 0.0, rate_ff=0.2) == pytest.approx(0.2)


def test_yaw_error_is_wrapped():
    c = CascadedPPID(G, DT, wrap=True)
    r = c.rate_reference(math.radians(179.0), math.radians(-179.0))
    assert r == pytest.approx(4.0 * math.radians(-2.0))
    c2 = CascadedPPID(G, DT, wrap=False)
    assert c2.rate_reference(math.radians(179.0), math.radians(-179.0)) == pytest.approx(
        4.0 * math.radians(358.0)
    )
    assert wrap_angle(math.pi) == pytest.approx(math.pi)
    assert wrap_angle(-math.pi) == pytest.approx(math.pi)  # (-pi, pi]
    assert wrap_angle(3 * math.pi) == pytest.approx(math.pi)
    assert wrap_angle(-0.5) == pytest.approx(-0.5)
    assert wrap_angle(2 * math.pi + 0.25) == pytest.approx(0.25)


def test_anti_windup_integrator_does_not_grow_while_saturated_and_recovers():
    g = PPIDGains(kp_angle=1.0, kp_rate=0.2, ki_rate=2.0, kd_rate=0.0, tf_rate_s=0.02)
    c = CascadedPPID(g, DT, output_limit=1.0)
    integrals, outputs = [], []
    for _ in range(int(2.0 / DT)):  # 2 s of a large positive rate error
        outputs.append(c.update_rate(1.0, 0.0))
        integrals.append(c.integral)
    assert max(outputs) <= 1.0
    assert c.saturated and c.output == pytest.approx(1.0)
    k_sat = next(i for i, u in enumerate(outputs) if u >= 1.0 - 1e-12)
    # after saturation the integral stays (at most) where it was: no wind-up
    assert max(integrals[k_sat:]) <= integrals[k_sat] + 1e-12
    assert integrals[-1] <= 1.0 - 0.2 + 1e-9
    # error reverses: the output leaves the limit at once (naive integrator: ~1.5 s later)
    recover = []
    for _ in range(25):
        recover.append(c.update_rate(-0.5, 0.0))
    assert recover[0] < 1.0
    assert recover[12] < recover[0]


def test_anti_windup_negative_side_and_asymmetric_limits():
    g = PPIDGains(1.0, 0.1, 5.0, 0.0, 0.02)
    c = CascadedPPID(g, DT, output_limit=(-0.5, 2.0))
    for _ in range(500):
        u = c.update_rate(-3.0, 0.0)
    assert u == pytest.approx(-0.5)
    assert c.integral == pytest.approx(-0.5 + 0.3)  # kp*e = -0.3 already
    assert c.update_rate(0.5, 0.0) > -0.5


def test_derivative_filter_behaviour():
    g = PPIDGains(0.0, 0.0, 0.0, 0.1, 0.02)
    for method in ("tustin", "backward_euler"):
        c = CascadedPPID(g, DT, method=method)
        # ramp of slope 2 rad/s²: D -> kd * 2
        y = run_rate(c, 2.0 * np.arange(200) * DT)
        assert y[-1] == pytest.approx(0.2, rel=1e-6)
        # step: decays geometrically with the filter pole, no sign alternation
        c.reset()
        y = run_rate(c, np.ones(60))
        assert np.all(y > 0) and np.all(np.diff(y) < 0)
        ratio = y[10] / y[9]
        pole = (2 * 0.02 - DT) / (2 * 0.02 + DT) if method == "tustin" else 0.02 / (0.02 + DT)
        assert ratio == pytest.approx(pole, rel=1e-9)
        assert ratio == pytest.approx(math.exp(-DT / 0.02), abs=0.02)  # continuous pole
    # tf < dt/2 with Tustin: backward-Euler coefficients (no ringing at Nyquist)
    c = CascadedPPID(PPIDGains(0.0, 0.0, 0.0, 0.1, 0.0005), DT)
    y = run_rate(c, np.ones(10))
    assert np.all(y >= 0) and np.all(np.diff(y) <= 0)
    # tf = 0: pure backward difference
    c = CascadedPPID(PPIDGains(0.0, 0.0, 0.0, 0.1, 0.0), DT)
    y = run_rate(c, np.arange(5) * DT)
    np.testing.assert_allclose(y[1:], 0.1)


def test_gain_changes_are_bumpless():
    c = CascadedPPID(G, DT)
    for _ in range(100):
        c.update_rate(0.2, 0.0)
    i_before, d_before = c.integral, c.derivative
    g2 = PPIDGains(4.0, 0.8, 5.0, 0.5, 0.05)  # ki and kd x10
    u = c.update_rate(0.2, 0.0, gains=g2)
    assert c.integral == pytest.approx(i_before + 5.0 * DT * 0.2)  # only the new increment
    assert c.derivative == pytest.approx(d_before * (2 * 0.05 - DT) / (2 * 0.05 + DT))
    assert u == pytest.approx(0.8 * 0.2 + c.integral + c.derivative)


def test_reset_and_bumpless_start():
    c = CascadedPPID(G, DT)
    c.update_rate(1.0, 0.0)
    c.reset(integral=0.3, rate_error=1.0)
    assert c.integral == 0.3
    u = c.update_rate(1.0, 0.0)  # no derivative kick: previous error was already 1
    assert u == pytest.approx(0.8 + 0.3 + 0.5 * DT)


def test_validation():
    with pytest.raises(ValueError, match="dt"):
        CascadedPPID(G, 0.0)
    with pytest.raises(ValueError, match="method"):
        CascadedPPID(G, DT, method="zoh")  # type: ignore[arg-type]
    with pytest.raises(ValueError, match="output_limit"):
        CascadedPPID(G, DT, output_limit=(1.0, -1.0))

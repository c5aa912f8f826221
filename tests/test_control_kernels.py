"""The compiled control laws (``control_kernels``) against independent answers: steps worked
out by hand, a textbook discrete PID written out here, and scipy's bilinear transform."""

from __future__ import annotations

import math

import numpy as np
import pytest
import scipy.signal as sg

from vtolftc.firmware_sim.autopilot import control_kernels as ck


def axis(dt: float = 0.01, *, wrap: bool = False, rate_limit: float = math.nan,
         tustin: bool = True, u_min: float = -math.inf, u_max: float = math.inf
         ) -> tuple[np.ndarray, np.ndarray]:
    """State and constants of one axis at rest (row 0)."""
    S = np.zeros((1, ck.N_STATE))
    S[0, ck.S_TF] = math.nan
    C = np.zeros((1, ck.N_CONST))
    C[0, ck.C_WRAP] = 1.0 if wrap else 0.0
    C[0, ck.C_RATE_LIMIT] = rate_limit
    C[0, ck.C_DT] = dt
    C[0, ck.C_TUSTIN] = 1.0 if tustin else 0.0
    C[0, ck.C_U_MIN], C[0, ck.C_U_MAX] = u_min, u_max
    return S, C


# kp_angle 2 /s, kp_rate 0.5, ki_rate 4, kd_rate 0.1, tf 0.02 s
G = np.array([2.0, 0.5, 4.0, 0.1, 0.02])


def test_ppid_two_steps_worked_by_hand():
    """dt = 0.01 s, angle error 0.2 rad, rate 0.05 rad/s: rate reference 0.4, e = 0.35.
    Tustin filter: a = (0.04 - 0.01)/(0.04 + 0.01) = 0.6, b = 2/0.05 = 40.
    Step 1: D = 40 * 0.1 * 0.35 = 1.4, I = 0.5 * 4 * 0.01 * 0.35 = 0.007, P = 0.175,
    u = 1.582. Step 2 (same input): D = 0.6 * 1.4 = 0.84, I = 0.007 + 0.014 = 0.021,
    u = 0.175 + 0.021 + 0.84 = 1.036."""
    S, C = axis()
    u1 = ck.ppid_step(G, S, C, 0, 0.3, 0.1, 0.05, 0.0, False, False)
    assert u1 == pytest.approx(1.582, rel=1e-12)
    assert S[0, ck.S_RATE_REF] == pytest.approx(0.4, rel=1e-12)
    assert S[0, ck.S_INTEGRAL] == pytest.approx(0.007, rel=1e-12)
    assert S[0, ck.S_DERIVATIVE] == pytest.approx(1.4, rel=1e-12)
    assert (S[0, ck.S_A], S[0, ck.S_B]) == pytest.approx((0.6, 40.0), rel=1e-12)
    u2 = ck.ppid_step(G, S, C, 0, 0.3, 0.1, 0.05, 0.0, False, False)
    assert u2 == pytest.approx(1.036, rel=1e-12)
    assert S[0, ck.S_INTEGRAL] == pytest.approx(0.021, rel=1e-12)


def test_ppid_feed_forward_rate_limit_and_yaw_wrap_by_hand():
    S, C = axis(rate_limit=0.5)
    ck.ppid_step(G, S, C, 0, 0.1, 0.0, 0.0, 0.1, False, False)   # 2 * 0.1 + 0.1
    assert S[0, ck.S_RATE_REF] == pytest.approx(0.3, rel=1e-12)
    ck.ppid_step(G, S, C, 0, 1.0, 0.0, 0.0, 0.0, False, False)   # 2.0, limited
    assert S[0, ck.S_RATE_REF] == 0.5
    S, C = axis(wrap=True)
    ck.ppid_step(G, S, C, 0, math.pi - 0.05, -math.pi + 0.05, 0.0, 0.0, False, False)
    assert S[0, ck.S_RATE_REF] == pytest.approx(2.0 * -0.1, rel=1e-9)  # error -0.1, not 2pi-0.1
    assert ck.wrap_angle(-math.pi) == pytest.approx(math.pi)           # (-pi, pi]
    assert ck.wrap_angle(2.0 * math.pi + 0.25) == pytest.approx(0.25)


def textbook_backward_euler_pid(e: np.ndarray, kp: float, ki: float, kd: float, tf: float,
                                dt: float) -> np.ndarray:
    """u_k = kp e_k + ki dt sum_{j<=k} e_j + D_k, D_k = (tf D_{k-1} + kd (e_k - e_{k-1}))/(tf + dt)
    (Astrom & Murray, Feedback Systems, sec. 10.5, backward differences; e_{-1} = 0)."""
    out, acc, d, prev = [], 0.0, 0.0, 0.0
    for ek in e:
        acc += ek
        d = (tf * d + kd * (ek - prev)) / (tf + dt)
        out.append(kp * ek + ki * dt * acc + d)
        prev = ek
    return np.array(out)


def rate_loop(e: np.ndarray, S: np.ndarray, C: np.ndarray, g: np.ndarray = G) -> np.ndarray:
    return np.array([ck.ppid_rate_step(g, S, C, 0, float(x), 0.0) for x in e])


def test_backward_euler_kernel_is_the_textbook_discrete_pid():
    e = np.random.default_rng(1).standard_normal(400)
    S, C = axis(tustin=False)
    want = textbook_backward_euler_pid(e, 0.5, 4.0, 0.1, 0.02, 0.01)
    np.testing.assert_allclose(rate_loop(e, S, C), want, rtol=1e-10, atol=1e-12)


def test_tustin_kernel_is_scipys_bilinear_image_of_the_continuous_pid():
    kp, ki, kd, tf = 0.5, 4.0, 0.1, 0.02
    num = [kp * tf + kd, kp + ki * tf, ki]    # kp + ki/s + kd s/(tf s + 1)
    den = [tf, 1.0, 0.0]
    nd, dd, _ = sg.cont2discrete((num, den), 0.01, method="bilinear")
    e = np.random.default_rng(2).standard_normal(400)
    want = sg.lfilter(np.ravel(nd), np.ravel(dd), e)
    S, C = axis()
    np.testing.assert_allclose(rate_loop(e, S, C), want, rtol=1e-9, atol=1e-10)


def test_tustin_falls_back_to_backward_euler_filter_below_half_a_sample():
    assert ck.filter_coefficients(0.004, 0.01, True) == pytest.approx((0.004 / 0.014,
                                                                       1.0 / 0.014))
    assert ck.filter_coefficients(0.02, 0.01, True) == pytest.approx((0.6, 40.0))
    assert ck.filter_coefficients(0.02, 0.01, False) == pytest.approx((2.0 / 3.0, 1.0 / 0.03))


def test_output_limit_and_conditional_integration_by_hand():
    """P alone (kp 1) with a unit error at limit 0.5: the output is 0.5, saturated, and the
    integral (ki 10, backward Euler, dt 0.01: 0.1 per step) never grows, since the output is
    already beyond the limit; with the error reversed it integrates at once."""
    g = np.array([0.0, 1.0, 10.0, 0.0, 0.0])
    S, C = axis(tustin=False, u_min=-0.5, u_max=0.5)
    for _ in range(5):
        u = ck.ppid_rate_step(g, S, C, 0, 1.0, 0.0)
    assert u == 0.5 and S[0, ck.S_SATURATED] == 1.0 and S[0, ck.S_INTEGRAL] == 0.0
    assert S[0, ck.S_OUTPUT_UNSAT] == 1.0
    u = ck.ppid_rate_step(g, S, C, 0, -0.1, 0.0)
    assert S[0, ck.S_INTEGRAL] == pytest.approx(-0.01)
    assert u == pytest.approx(-0.11)
    # an increment that would overshoot the limit is cut so the output just reaches it
    S, C = axis(tustin=False, u_min=-0.5, u_max=0.5)
    u = ck.ppid_rate_step(np.array([0.0, 0.45, 10.0, 0.0, 0.0]), S, C, 0, 1.0, 0.0)
    assert u == pytest.approx(0.5) and S[0, ck.S_INTEGRAL] == pytest.approx(0.05)


def test_allocation_saturation_flags_freeze_the_integral_and_take_it_out_of_the_output():
    S, C = axis(tustin=False)
    g = np.array([1.0, 0.0, 10.0, 0.0, 0.0])   # pure integral of the rate error
    u = ck.ppid_step(g, S, C, 0, 0.1, 0.0, 0.0, 0.0, True, False)  # would add +0.01
    assert u == 0.0 and S[0, ck.S_INTEGRAL] == 0.0
    u = ck.ppid_step(g, S, C, 0, 0.1, 0.0, 0.0, 0.0, False, True)  # the other side: passes
    assert u == pytest.approx(0.01) and S[0, ck.S_INTEGRAL] == pytest.approx(0.01)


def test_three_axis_call_is_the_axis_step_per_row():
    rng = np.random.default_rng(3)
    Gs = np.abs(rng.normal(size=(3, 5))) + 0.01
    S3 = np.zeros((3, ck.N_STATE))
    S3[:, ck.S_TF] = math.nan
    C3 = np.vstack([axis(0.004, wrap=(k == 2), rate_limit=1.0)[1] for k in range(3)])
    rows = [axis(0.004, wrap=(k == 2), rate_limit=1.0) for k in range(3)]
    out = np.zeros(3)
    for _ in range(50):
        ref, att, rates = rng.normal(size=3), rng.normal(size=3), rng.normal(size=3)
        flags = rng.random(6) < 0.3
        ck.ppid3_step(ref, att, rates, Gs, S3, C3, *map(bool, flags), out)
        for k in range(3):
            S, C = rows[k]
            want = ck.ppid_step(Gs[k], S, C, 0, ref[k], att[k], rates[k], 0.0,
                                bool(flags[k]), bool(flags[3 + k]))
            assert out[k] == want
            assert S3[k].tobytes() == S[0].tobytes()


def test_lqr_step_by_hand():
    """k_int 2, k_angle 3, k_rate 0.5, dt 0.01; error 0.1 rad, rate 0.2 rad/s: the integral
    term grows by 2 * 0.1 * 0.01 = 0.002 and tau = 0.3 - 0.1 + 0.002 = 0.202 N m; yaw's
    error pi - 0.05 - (-pi + 0.05) wraps to -0.1; a saturated side freezes the integral."""
    K = np.array([[2.0, 3.0, 0.5]] * 3)
    it, out = np.zeros(3), np.zeros(3)
    ref = np.array([0.1, 0.1, math.pi - 0.05])
    att = np.array([0.0, 0.0, -math.pi + 0.05])
    ck.lqr3_step(ref, att, np.full(3, 0.2), K, 0.01, it, False, True, False,
                 False, False, False, out)
    assert out[0] == pytest.approx(0.202, rel=1e-12)
    assert it[1] == 0.0 and out[1] == pytest.approx(0.2, rel=1e-12)
    assert it[2] == pytest.approx(-0.002, rel=1e-9)
    assert out[2] == pytest.approx(-0.3 - 0.1 - 0.002, rel=1e-9)

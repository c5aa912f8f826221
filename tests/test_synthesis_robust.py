"""The robust design's pieces (synthesis/robust.py, the centred cover, the disturbance row of
the cascade channel) against independent answers: brute-force grids, python-control's disk
margins and high-order Pade closed loops, hand calculations from the airframe file."""

from __future__ import annotations

import math

import control as ct
import numpy as np
import pytest

from vtolftc.synthesis.hinfnorm import frequency_response
from vtolftc.synthesis.loops import CascadeChannel, closed_loop
from vtolftc.synthesis.robust import (
    ROBUST_DESIGN_POINTS,
    LoopDelays,
    delay_weight,
    design_plant,
    disturbance_peak,
    loop_frequency_response,
    loop_margins,
    robust_parameters,
    robust_weights,
    rotor_out_moment,
    sensitivity_rule,
    stable_with_delay,
    trim_rotor_thrusts,
)
from vtolftc.synthesis.uncertainty import DesignPoint, centred_nominal, relative_error

GAINS = {"kp_angle": 4.0, "kp_rate": 12.0, "ki_rate": 6.0, "kd_rate": 0.5, "tf_rate_s": 0.04}


def test_delay_weight_covers_every_delay_up_to_the_margin():
    tau = 0.05
    A, B, C, D = delay_weight(tau)
    w = np.logspace(-2, 4, 3000)
    W = np.abs(frequency_response((A, B, C, D), w)[:, 0, 0])
    for t in np.linspace(0.0, tau, 26):     # brute force over the delays
        assert np.all(np.abs(np.exp(-1j * w * t) - 1.0) - 1e-12 <= W)
    assert W[-1] < 2.6                       # and not wildly above the bound (2)


def test_trim_thrusts_and_rotor_out_moment_by_hand(ds1):
    T = trim_rotor_thrusts(ds1, 0.0)
    assert T.sum() == pytest.approx(ds1.weight_N)
    x = np.array([r.position_m[0] for r in ds1.lift_rotors])
    y = np.array([r.position_m[1] for r in ds1.lift_rotors])
    assert x @ T == pytest.approx(0.0, abs=1e-9) and y @ T == pytest.approx(0.0, abs=1e-9)
    # front rotors (x = 0.65) carry less than rear ones (x = -0.60): T_f/T_r = 0.60/0.65
    assert T[0] / T[1] == pytest.approx(0.60 / 0.65, rel=1e-9)
    T_rear = ds1.weight_N / 4 * 0.65 / 1.25
    assert rotor_out_moment(ds1, "roll", 0.0) == pytest.approx(1.05 * T_rear, rel=1e-9)
    assert rotor_out_moment(ds1, "pitch", 0.0) == pytest.approx(0.60 * T_rear, rel=1e-9)
    # the wing unloads the rotors: at 13 m/s qbar S CL0 = 58 N of the 122.6 N weight
    qs = 0.5 * ds1.air_density_kg_m3 * 13.0**2 * ds1.wing.area_m2 * ds1.wing.CL0
    assert trim_rotor_thrusts(ds1, 13.0).sum() == pytest.approx(ds1.weight_N - qs)
    assert rotor_out_moment(ds1, "roll", 20.0) == 0.0


def test_centred_nominal_of_a_pure_gamma_set_is_gamma_0_3(ds1):
    pt = DesignPoint(9, 7.0, 7.0, 7.0)       # one airspeed: the set is gamma in [0, 0.6]
    V, g = centred_nominal(ds1, "roll", pt)
    assert V == 7.0 and g == pytest.approx(0.3)
    om = np.logspace(-2, 2, 50)
    rel = relative_error(ds1, "roll", pt, om, nominal=(V, g))
    assert rel.bound.max() == pytest.approx(0.3 / 0.7, rel=1e-9)    # instead of 0.6
    assert relative_error(ds1, "roll", pt, om).bound.max() == pytest.approx(0.6, rel=1e-9)


def test_centred_cover_is_smaller_than_the_paper_cover_at_pitch_3(ds1):
    w = robust_weights(ds1, "pitch", ROBUST_DESIGN_POINTS[2])
    assert w.Wt.gain < 0.95                  # the paper's corner nominal gives 2.03
    assert w.d_max_N_m > 0 and w.Wd > 0


def test_disturbance_row_equals_series_assembly(ds1):
    G = design_plant(ds1, "roll", 4.0, 0.2)
    Wd = (np.array([[-0.005]]), np.array([[1.0]]), np.array([[40.0]]), np.array([[80.0]]))
    ch = CascadeChannel(G, Wd=Wd)
    th = np.array(list(GAINS.values()))
    w = np.logspace(-3, 3, 40)
    np.testing.assert_allclose(frequency_response(ch(th), w),
                               frequency_response(ch.reference(th), w), rtol=1e-9, atol=1e-12)
    # e/d by python-control: -G_angle / (1 + L_u)
    cl = closed_loop(G, th)
    ed = frequency_response(cl.S_ud(), w)[:, 0, 0]
    L = loop_frequency_response(G, GAINS, w)
    Ga = frequency_response(G, w)[:, 1, 0]
    np.testing.assert_allclose(ed, -Ga / (1 + L), rtol=1e-8)
    # a channel with Wd only is the weighted e/d
    Wr = frequency_response(Wd, w)[:, 0, 0]
    np.testing.assert_allclose(frequency_response(ch(th), w)[:, 0, 0], Wr * ed, rtol=1e-8)


def test_delay_margin_is_where_the_pade_closed_loop_loses_stability(ds1):
    G = design_plant(ds1, "pitch", 4.0, 0.0)
    m = loop_margins(G, GAINS)
    assert 0.01 < m.delay_margin_s < 1.0
    assert stable_with_delay(G, GAINS, 0.95 * m.delay_margin_s, order=10)
    assert not stable_with_delay(G, GAINS, 1.05 * m.delay_margin_s, order=10)


def test_disk_margin_matches_python_control(ds1):
    G = design_plant(ds1, "roll", 10.0, 0.3)
    m = loop_margins(G, GAINS)
    w = np.logspace(-3, 4, 6000)
    g = GAINS
    # python-control's disk margin of the same loop, built as an LTI object
    K = ct.tf([g["kp_rate"] * g["tf_rate_s"] + g["kd_rate"], g["kp_rate"]
               + g["ki_rate"] * g["tf_rate_s"], g["ki_rate"]], [g["tf_rate_s"], 1.0, 0.0])
    Gs = ct.ss(G)
    L = K * (g["kp_angle"] * Gs[1, 0] + Gs[0, 0])
    dm = ct.disk_margins(L, w, skew=0.0)
    assert m.disk_alpha == pytest.approx(float(np.min(dm[0])), rel=1e-4)


def test_disturbance_peak_is_the_step_response_peak(ds1):
    G = design_plant(ds1, "roll", 0.0, 0.3)
    cl = closed_loop(G, GAINS)
    sys = ct.ss(cl.A, cl.B[:, [1]], cl.C[[3], :], 0)
    t = np.linspace(0, 10, 20001)
    y = ct.forced_response(sys, t, 16.0 * np.ones_like(t)).outputs
    assert disturbance_peak(G, GAINS, 16.0) == pytest.approx(float(np.max(np.abs(y))),
                                                             rel=2e-3)


def test_sensitivity_rule_and_bounds(ds1):
    pt = ROBUST_DESIGN_POINTS[0]
    Ws, r = sensitivity_rule(ds1, "roll", pt, 88.9, 16.7)
    assert r["omega_act_rad_s"] == pytest.approx(20.0)
    assert Ws.omega_b_rad_s == pytest.approx(min(20.0 / 8, r["omega_u_rad_s"] / 2))
    # 20 % overshoot: zeta 0.456; its unity loop has |S| peak ~1.5
    assert 1.3 < Ws.M < 1.7
    params, why = robust_parameters(ds1, "roll", 88.9)
    assert {p.name for p in params} == set(GAINS)
    for p in params:
        assert p.lower <= p.initial <= p.upper
    assert why["k_hf"]["k_hf_max"] > 0


def test_design_plant_delay_and_lag(ds1):
    G = design_plant(ds1, "yaw", 7.0, 0.1, LoopDelays(0.004, 0.002, 0.05))
    w = np.logspace(-2, 1, 30)
    tau = 0.05 + 0.008
    F = frequency_response(G, w)
    G0 = frequency_response(ct.ss(*_base(ds1, "yaw", 7.0, 0.1)), w)
    np.testing.assert_allclose(F, G0 / (1 + 1j * w * tau)[:, None, None], rtol=1e-8)


def _base(af, axis, V, g):
    from vtolftc.synthesis.models import attitude_model

    G = attitude_model(af, axis, V, g)
    return G.A, G.B, G.C, G.D


@pytest.mark.parametrize("axis", ["roll", "pitch"])
def test_robust_point_design_meets_its_margins(ds1, axis):
    from vtolftc.synthesis.robust import robust_design_point

    d = robust_design_point(ds1, axis, ROBUST_DESIGN_POINTS[3], n_starts=0)
    assert d.stable
    w = d.weights[0]
    m = loop_margins(w.plant(ds1), d.gains)
    assert m.delay_margin_s >= 0.05
    assert stable_with_delay(w.plant(ds1), d.gains, 0.05)
    assert math.degrees(disturbance_peak(w.plant(ds1), d.gains, w.d_max_N_m)) <= 15.0

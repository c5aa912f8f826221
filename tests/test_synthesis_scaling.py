"""The synthesis scaled from the airframe's physics (synthesis/scaling.py, design.py, robust.py):
every scale gives DS-1 today's numbers to the last bit and follows its formula for another
aircraft; the one design loop is the same with and without workers; airframes other than
DS-1 (tests/data: DS-1 scaled up, a 4-lift-rotor quadplane) go through the synthesis, and an
airframe with no authority on an axis is refused in one line."""

from __future__ import annotations

import dataclasses
import json
import math
from concurrent.futures import ThreadPoolExecutor
from pathlib import Path

import numpy as np
import pytest

from vtolftc.airframe.loader import Airframe, AirframeError, load_airframe
from vtolftc.synthesis.design import (
    OMEGA_A_RAD_S,
    R_MAX_RAD,
    TABLE2,
    PaperMethod,
    control_weight_bandwidth,
    moment_authority,
    paper_points,
    parameters,
    table2_scaled,
    weights_for,
)
from vtolftc.synthesis.design_loop import run_design_loop
from vtolftc.synthesis.models import AXES
from vtolftc.synthesis.robust import (
    RobustSpec,
    high_frequency_gain_bound,
    moment_authority_robust,
    robust_parameters,
    robust_points,
    robust_weights,
)
from vtolftc.synthesis.scaling import (
    actuator_bandwidth,
    authority_bandwidth,
    scaled_design_points,
    transition_speeds,
)
from vtolftc.synthesis.uncertainty import PAPER_DESIGN_POINTS, DesignPoint

DATA = Path(__file__).resolve().parent / "data"
SCALED_UP = DATA / "ds1_scaled_up.toml"
QUADPLANE = DATA / "quadplane_4.toml"


def _with_actuator_tau(af: Airframe, tau: float) -> Airframe:
    rotors = tuple(dataclasses.replace(r, time_constant_s=tau) for r in af.lift_rotors)
    return dataclasses.replace(af, lift_rotors=rotors,
                               surfaces=dataclasses.replace(af.surfaces, time_constant_s=tau))


def _with_inertia_times(af: Airframe, k: float) -> Airframe:
    return dataclasses.replace(af, inertia_kg_m2=af.inertia_kg_m2 * k)


def _bounds(params):
    return {p.name: (p.lower, p.upper) for p in params}


def _starts(params):
    return {p.name: p.initial for p in params}


# ------------------------------------------------------------------------------------------
# design airspeeds
# ------------------------------------------------------------------------------------------


def test_design_points_of_ds1_are_table1_and_the_18_m_s_cruise_point(ds1):
    sp = transition_speeds(ds1)
    assert (sp.transition_end_m_s, sp.cruise_m_s) == (13.0, 18.0)
    assert paper_points(ds1) == PAPER_DESIGN_POINTS
    assert robust_points(ds1) == (*PAPER_DESIGN_POINTS, DesignPoint(7, 18.0, 13.0, 20.0))


def test_design_points_follow_the_stall_speed_and_declared_speeds(ds1):
    heavy = dataclasses.replace(ds1, mass_kg=4.0 * ds1.mass_kg)   # stall speed x 2
    vs = heavy.stall_speed_m_s()
    assert vs == pytest.approx(2.0 * ds1.stall_speed_m_s())
    sp = transition_speeds(heavy)
    assert sp.transition_end_m_s == math.ceil(vs / 0.5) * 0.5 == 25.5
    assert sp.cruise_m_s == math.ceil(1.4 * vs / 0.5) * 0.5 == 36.0
    pts = scaled_design_points(heavy, cruise=True)
    for p, q in zip(pts[:6], PAPER_DESIGN_POINTS, strict=True):
        for a, b in ((p.airspeed_m_s, q.airspeed_m_s), (p.v_min_m_s, q.v_min_m_s),
                     (p.v_max_m_s, q.v_max_m_s)):
            assert a == pytest.approx(b * 25.5 / 13.0, rel=1e-12)
    assert pts[5].v_max_m_s == 25.5 and pts[6] == DesignPoint(7, 36.0, 25.5, 40.2)
    declared = transition_speeds(ds1, transition_end_m_s=15.0, cruise_m_s=22.0)
    assert (declared.transition_end_m_s, declared.cruise_m_s) == (15.0, 22.0)
    with pytest.raises(AirframeError, match="transition end 10 m/s: expected at least"):
        transition_speeds(ds1, transition_end_m_s=10.0)
    with pytest.raises(AirframeError, match="cruise 13 m/s: expected above"):
        transition_speeds(ds1, cruise_m_s=13.0)


# ------------------------------------------------------------------------------------------
# bandwidths
# ------------------------------------------------------------------------------------------


def test_actuator_and_authority_bandwidths_follow_their_formulas(ds1):
    assert actuator_bandwidth(ds1) == 20.0
    assert actuator_bandwidth(_with_actuator_tau(ds1, 0.1)) == pytest.approx(10.0)
    w = authority_bandwidth(80.0, 1.6, R_MAX_RAD)
    assert w == pytest.approx(math.sqrt(80.0 / (1.6 * R_MAX_RAD)))
    assert authority_bandwidth(80.0, 3.2, R_MAX_RAD) == pytest.approx(w / math.sqrt(2.0))
    assert authority_bandwidth(160.0, 1.6, R_MAX_RAD) == pytest.approx(w * math.sqrt(2.0))


# ------------------------------------------------------------------------------------------
# paper method: table 2 and its bounds
# ------------------------------------------------------------------------------------------


def test_table2_is_kept_for_ds1_and_scaled_by_authority_bandwidth(ds1):
    for ax in AXES:
        for p in PAPER_DESIGN_POINTS:
            assert table2_scaled(ds1, ax, p) == TABLE2[ax][p.number - 1]   # bit for bit
            w = weights_for(ds1, ax, p)
            assert (w.Ws.M, w.Ws.omega_b_rad_s) == TABLE2[ax][p.number - 1]
    assert control_weight_bandwidth(ds1) == OMEGA_A_RAD_S
    heavy = _with_inertia_times(ds1, 2.0)          # same authority, twice the inertia
    for ax in AXES:
        for p in PAPER_DESIGN_POINTS:
            M, wb = table2_scaled(heavy, ax, p)
            M0, wb0 = TABLE2[ax][p.number - 1]
            assert M == M0
            assert wb == pytest.approx(wb0 / math.sqrt(2.0), rel=1e-12)
    slow = _with_actuator_tau(ds1, 0.1)
    assert control_weight_bandwidth(slow) == pytest.approx(OMEGA_A_RAD_S / 2.0)
    assert weights_for(slow, "roll", PAPER_DESIGN_POINTS[0]).Wr.omega_a_rad_s == \
        pytest.approx(2.5)


def _old_paper_parameters(J: float, u_max: float):
    """The paper method's bounds and start as they were written for DS-1 (literal numbers)."""
    wr = min(6.0, math.sqrt(4.0 * u_max / (R_MAX_RAD * J)))
    kp = J * wr
    return ({"kp_angle": (0.3, 8.0), "kp_rate": (0.5 * J, 40.0 * J),
             "ki_rate": (2.0 * J, 40.0 * J), "kd_rate": (0.0, 2.0 * J),
             "tf_rate_s": (0.01, 1.0)},
            {"kp_angle": wr / 4.0, "kp_rate": kp, "ki_rate": max(kp * wr / 5.0, 2.0 * J),
             "kd_rate": 0.05 * J, "tf_rate_s": 0.02})


def test_paper_bounds_and_starts_of_ds1_are_todays_numbers(ds1):
    for ax in AXES:
        J = float(np.diag(ds1.inertia_kg_m2)[AXES.index(ax)])
        for p in PAPER_DESIGN_POINTS:
            u = moment_authority(ds1, ax, p.airspeed_m_s)
            prm = parameters(ds1, ax, u)
            bounds, starts = _old_paper_parameters(J, u)
            assert _bounds(prm) == bounds
            assert _starts(prm) == starts


def test_paper_bounds_follow_actuator_bandwidth_and_inertia(ds1):
    u = moment_authority(ds1, "roll", 0.0)
    b0 = _bounds(parameters(ds1, "roll", u))
    b = _bounds(parameters(_with_actuator_tau(ds1, 0.1), "roll", u))   # omega_act / 2
    assert b["kp_angle"] == pytest.approx((0.15, 4.0))
    assert b["kp_rate"] == pytest.approx((b0["kp_rate"][0] / 2, b0["kp_rate"][1] / 2))
    assert b["ki_rate"] == pytest.approx((b0["ki_rate"][0] / 4, b0["ki_rate"][1] / 4))
    assert b["tf_rate_s"] == pytest.approx((0.01, 2.0))
    b2 = _bounds(parameters(_with_inertia_times(ds1, 2.0), "roll", u))
    for k in ("kp_rate", "ki_rate", "kd_rate"):
        assert b2[k] == pytest.approx((2 * b0[k][0], 2 * b0[k][1]))


# ------------------------------------------------------------------------------------------
# robust method: bounds and starts
# ------------------------------------------------------------------------------------------


def _old_robust_parameters(af: Airframe, J: float, u_max: float):
    """The robust method's bounds and start as they were written for DS-1 (literal numbers:
    0.3, 6 rad/s, 0.2 J, 0.1 J, 2 J, 0.05 J, [0.01, 1] s, 0.02 s)."""
    w_act = 20.0
    hf = high_frequency_gain_bound(af, u_max, RobustSpec())
    tf_min = max(0.01, 2.5 * 0.004)
    kp_hi = min(J * w_act, hf["k_hf_max"])
    kd_hi = min(2.0 * J, hf["k_hf_max"] * tf_min)
    ki_hi = J * w_act**2 / 4.0
    wr = min(6.0, math.sqrt(4.0 * u_max / (R_MAX_RAD * J)), kp_hi / J)
    kp0 = min(J * wr, kp_hi)
    return ({"kp_angle": (0.3, w_act / 2.0), "kp_rate": (0.2 * J, kp_hi),
             "ki_rate": (0.1 * J, ki_hi), "kd_rate": (0.0, kd_hi), "tf_rate_s": (tf_min, 1.0)},
            {"kp_angle": min(wr / 4.0, w_act / 2.0), "kp_rate": kp0,
             "ki_rate": min(max(kp0 * wr / 5.0, 0.1 * J), ki_hi),
             "kd_rate": min(0.05 * J, kd_hi), "tf_rate_s": max(0.02, tf_min)})


def test_robust_bounds_and_starts_of_ds1_are_todays_numbers(ds1):
    for ax in AXES:
        J = float(np.diag(ds1.inertia_kg_m2)[AXES.index(ax)])
        us = [moment_authority_robust(ds1, ax, p.airspeed_m_s) for p in robust_points(ds1)]
        for u in [*us, min(us)]:                  # every GS-SHIF point and the SHIF tune
            prm, why = robust_parameters(ds1, ax, u)
            bounds, starts = _old_robust_parameters(ds1, J, u)
            assert _bounds(prm) == bounds
            assert _starts(prm) == starts
            assert why["kp_angle"]["lower"] == 0.3


def test_robust_bounds_follow_inertia_and_actuator_bandwidth(ds1):
    u = moment_authority_robust(ds1, "roll", 0.0)
    b0 = _bounds(robust_parameters(ds1, "roll", u)[0])
    b2 = _bounds(robust_parameters(_with_inertia_times(ds1, 2.0), "roll", u)[0])
    assert b2["kp_rate"][0] == pytest.approx(2 * b0["kp_rate"][0])      # J omega_act / 100
    assert b2["ki_rate"] == pytest.approx((2 * b0["ki_rate"][0], 2 * b0["ki_rate"][1]))
    slow = _with_actuator_tau(ds1, 0.1)
    b = _bounds(robust_parameters(slow, "roll", u)[0])
    assert b["kp_angle"] == pytest.approx((0.15, 5.0))                  # omega_act/66, /2
    assert b["ki_rate"] == pytest.approx((b0["ki_rate"][0] / 4, b0["ki_rate"][1] / 4))
    assert b["tf_rate_s"] == pytest.approx((0.01, 2.0))                 # 2.5 T, 20 tau


def test_robust_outer_loop_bound_relaxes_to_a_slow_rate_loop(ds1):
    """Issue 22's traceback: the scaled-up DS-1's yaw at hover allows a rate crossover of
    only ~1.2 rad/s (gyro noise against its small yaw authority): the start kp_angle
    (a quarter of it) was below the fixed 0.3 bound. The bound now relaxes to the start."""
    af = load_airframe(SCALED_UP)
    u = moment_authority_robust(af, "yaw", 0.0)
    prm, why = robust_parameters(af, "yaw", u)
    kpa = prm[0]
    assert kpa.name == "kp_angle" and kpa.initial < 0.3
    assert kpa.lower == kpa.initial
    assert why["kp_angle"]["lower_from"] == "a quarter of the start's rate crossover"
    for p in prm:
        assert p.lower <= p.initial <= p.upper
    # the rate crossover is bounded by gyro noise, linear in u_max: half the authority,
    # half the bound
    prm_half, _ = robust_parameters(af, "yaw", u / 2.0)
    assert prm_half[0].lower == pytest.approx(kpa.lower / 2.0, rel=1e-12)


# ------------------------------------------------------------------------------------------
# refusals
# ------------------------------------------------------------------------------------------


def _no_yaw(ds1: Airframe) -> Airframe:
    rotors = tuple(dataclasses.replace(r, torque_to_thrust_m=0.0) for r in ds1.lift_rotors)
    return dataclasses.replace(ds1, lift_rotors=rotors,
                               wing=dataclasses.replace(ds1.wing, Cn_dr=0.0))


def test_no_authority_on_an_axis_is_an_airframe_error(ds1):
    af = _no_yaw(ds1)
    for make in (lambda: robust_weights(af, "yaw", robust_points(af)[0]),
                 lambda: weights_for(af, "yaw", paper_points(af)[0])):
        with pytest.raises(AirframeError, match=r"ds1.toml \(DS-1\): no yaw moment authority "
                                                r"at 0 m/s"):
            make()
    robust_weights(af, "roll", robust_points(af)[0])        # the other axes still design


def test_cli_synth_refuses_no_authority_in_one_line(tmp_path, capsys):
    from vtolftc.cli import run

    text = Path(load_airframe().source).read_text()
    text = text.replace("torque_to_thrust_m = 0.016", "torque_to_thrust_m = 0.0")
    text = text.replace("Cn_dr = -0.069", "Cn_dr = 0.0")
    f = tmp_path / "noyaw.toml"
    f.write_text(text)
    code = run(["synth", "--airframe", str(f), "--out", str(tmp_path / "out"), "--jobs", "1",
                "--quiet", "--no-mu", "--no-report", "--starts", "0"])
    err = capsys.readouterr().err.strip().splitlines()
    assert code == 2
    # the loader refuses it before the synthesis does (its flyability check, issue 22):
    # one line naming the field and the reason
    assert len(err) == 1 and "noyaw.toml" in err[0] and "no yaw authority" in err[0], err
    assert "Traceback" not in err[0]


# ------------------------------------------------------------------------------------------
# one design loop
# ------------------------------------------------------------------------------------------


def test_the_design_loop_is_the_same_with_and_without_workers(ds1):
    """Both methods run design_loop.run_design_loop; its executor path (weights once, SHIF
    starts cut into jobs, recombined in start order) gives the sequential result bit for
    bit (here the paper method, one point, one random start, few iterations)."""
    pts = (PAPER_DESIGN_POINTS[3],)
    kw = {"shif_points": pts, "n_starts": 1, "seed": 3, "max_iter": 4}
    gs_a, sh_a = run_design_loop(PaperMethod(), ds1, pts, **kw)
    with ThreadPoolExecutor(2) as ex:
        gs_b, sh_b = run_design_loop(PaperMethod(), ds1, pts, executor=ex, **kw)
    for ax in AXES:
        assert gs_a[ax][0].gains == gs_b[ax][0].gains
        assert sh_a[ax].gains == sh_b[ax].gains
        assert gs_a[ax][0].label == "point 4" and sh_a[ax].label == "all points"


# ------------------------------------------------------------------------------------------
# other airframes through the synthesis
# ------------------------------------------------------------------------------------------


@pytest.mark.slow
@pytest.mark.parametrize("method", ["robust", "paper"])
@pytest.mark.parametrize("path", [SCALED_UP, QUADPLANE], ids=["scaled-up", "quadplane-4"])
def test_synthesis_finishes_for_other_airframes(path, method, tmp_path):
    """`vtolftc synth`'s pipeline on DS-1 scaled up (16 kg, 3.2 m span, 42 N rotors,
    inertia x1.3) and on a 4-lift-rotor quadplane variant, at two of their design points
    (hover and the last: transition end for paper, cruise for robust; SHIF over both), no
    random start, no mu: gain files written, every closed loop stable (40-115 s each with
    three points on a loaded 2-core machine, hence two)."""
    from vtolftc.synthesis.pipeline import run_synthesis

    af = load_airframe(path)
    pts = robust_points(af) if method == "robust" else paper_points(af)
    sel = (pts[0], pts[-1])
    res = run_synthesis(af, tmp_path, n_starts=0, jobs=2, mu=False, report=False,
                        method=method, points=sel)
    doc = json.loads((tmp_path / "gs-shif.json").read_text())
    assert doc["airframe"]["sha256"] == af.sha256
    assert (tmp_path / "shif.json").is_file() and (tmp_path / "lqr.json").is_file()
    for ax in AXES:
        assert [d.stable for d in res.gs[ax]] == [True] * 2, ax
        assert res.shif[ax].stable, ax

"""Attitude controllers: LQR gain reader and law, scheduled P-PID, anti-windup, selection."""

from __future__ import annotations

import copy
import json
import math

import numpy as np
import pytest

from vtolftc.firmware_sim.autopilot.attitude import (
    ControllerError,
    LQRAttitudeController,
    ScheduledPPIDController,
    make_controller,
)
from vtolftc.firmware_sim.autopilot.lqr import LQRGains, LQRGainsError
from vtolftc.firmware_sim.autopilot.pid import CascadedPPID
from vtolftc.firmware_sim.autopilot.schedule import GainSchedule

SHA = "ab" * 32
NO = np.zeros(3, dtype=bool)


def lqr_dict(bp=(0.0, 10.0)):
    n = len(bp)
    return {
        "format": "vtolftc-lqr-gains/1", "controller": "lqr",
        "airframe": {"name": "DS-1", "sha256": SHA},
        "airspeed_breakpoints_m_s": list(bp),
        "axes": {ax: {"k_int": [1.0 * (i + 1) for i in range(n)],
                      "k_angle": [10.0 * (i + 1) for i in range(n)],
                      "k_rate": [3.0 * (i + 1) for i in range(n)]}
                 for ax in ("roll", "pitch", "yaw")},
        "Q": [[1, 0], [0, 1]],
    }


def sched_dict(bp=(0.0, 10.0)):
    n = len(bp)
    return {
        "format": "vtolftc-gain-schedule/1", "controller": "gs-shif",
        "airframe": {"name": "DS-1", "sha256": SHA},
        "airspeed_breakpoints_m_s": list(bp),
        "axes": {ax: {"kp_angle": [4.0 + i for i in range(n)],
                      "kp_rate": [10.0 + 2 * i for i in range(n)],
                      "ki_rate": [5.0] * n, "kd_rate": [0.1] * n, "tf_rate_s": [0.02] * n}
                 for ax in ("roll", "pitch", "yaw")},
    }


def test_lqr_reader_interpolates_and_keeps_metadata():
    g = LQRGains.from_dict(lqr_dict())
    assert g.metadata["Q"] == [[1, 0], [0, 1]]
    assert g.gains_at(0.0)["roll"].k_angle == 10.0
    assert g.gains_at(5.0)["pitch"].k_angle == pytest.approx(15.0)
    assert g.gains_at(50.0)["yaw"].k_rate == 6.0          # clamped
    assert g.gains_at(float("nan"))["yaw"].k_int == 1.0   # first breakpoint


@pytest.mark.parametrize("mutate, match", [
    (lambda d: d.update(format="vtolftc-lqr-gains/2"), "format"),
    (lambda d: d["airframe"].update(sha256="xyz"), "airframe.sha256"),
    (lambda d: d.update(airspeed_breakpoints_m_s=[0.0, 0.0]), r"airspeed_breakpoints_m_s\[1\]"),
    (lambda d: d["axes"].pop("yaw"), "axes.yaw"),
    (lambda d: d["axes"]["roll"].update(k_rate=[1.0]), "axes.roll.k_rate"),
    (lambda d: d["axes"]["pitch"].update(k_int=[1.0, -2.0]), r"axes.pitch.k_int\[1\]"),
    (lambda d: d["axes"]["pitch"].update(k_int=[1.0, float("nan")]), r"axes.pitch.k_int\[1\]"),
    (lambda d: d["axes"]["roll"].update(kp=[1.0, 1.0]), "axes.roll.kp"),
])
def test_lqr_reader_rejects_bad_files(mutate, match):
    d = copy.deepcopy(lqr_dict())
    mutate(d)
    with pytest.raises(LQRGainsError, match=match):
        LQRGains.from_dict(d)


def test_lqr_load_names_the_file(tmp_path):
    p = tmp_path / "lqr.json"
    p.write_text("{not json")
    with pytest.raises(LQRGainsError, match=r"lqr\.json"):
        LQRGains.load(p)


def test_lqr_law_and_yaw_wrap():
    c = LQRAttitudeController(LQRGains.from_dict(lqr_dict((0.0,))), dt=0.004)
    ref = np.array([0.1, -0.2, math.pi - 0.05])
    att = np.array([0.0, 0.0, -math.pi + 0.05])       # yaw error wraps to -0.1 rad
    rates = np.array([0.5, -0.5, 0.2])
    tau = c.update(ref, att, rates, 0.0, NO, NO)
    e = np.array([0.1, -0.2, -0.1])
    expected = 1.0 * e * 0.004 + 10.0 * e - 3.0 * rates
    np.testing.assert_allclose(tau, expected, atol=1e-12)


def test_lqr_anti_windup_freezes_integral_in_saturated_direction():
    c = LQRAttitudeController(LQRGains.from_dict(lqr_dict((0.0,))), dt=0.004)
    ref = np.array([0.1, 0.1, 0.1])
    sat_hi = np.array([True, False, False])
    for _ in range(100):
        c.update(ref, np.zeros(3), np.zeros(3), 0.0, sat_hi, NO)
    assert c.integral_term[0] == 0.0
    assert c.integral_term[1] == pytest.approx(100 * 1.0 * 0.1 * 0.004)
    # a saturation the other way does not stop integration towards the limit's inside
    c.update(ref, np.zeros(3), np.zeros(3), 0.0, NO, np.array([True, False, False]))
    assert c.integral_term[0] > 0.0


def test_lqr_compiled_step_equals_the_law_bit_for_bit():
    """The compiled three-axis LQR step equals the law written out here per axis in Python
    floats (tau = k_int int(e) + k_angle e - k_rate rate, yaw error wrapped, the integral
    frozen towards a saturated side), bit for bit, over a random flight through a scheduled
    gain file with saturation flags."""
    gains = LQRGains.from_dict(lqr_dict((0.0, 10.0, 20.0)))
    c = LQRAttitudeController(gains, dt=0.004)
    it = [0.0, 0.0, 0.0]
    rng = np.random.default_rng(6)
    for i in range(2000):
        ref = rng.normal(scale=(0.3, 0.3, 3.0))
        att = rng.normal(scale=(0.3, 0.3, 3.0))
        rates = rng.normal(scale=3.0, size=3)
        V = round(float(rng.uniform(-1.0, 25.0)), 2)
        hi, lo = list(rng.random(3) < 0.2), list(rng.random(3) < 0.2)
        if i % 700 == 0:
            c.reset()
            it = [0.0, 0.0, 0.0]
        tau = c.update(ref, att, rates, V, hi, lo)
        g = gains.gains_at(V)
        for k, ax in enumerate(("roll", "pitch", "yaw")):
            e = float(ref[k]) - float(att[k])
            if ax == "yaw":
                e = math.remainder(e, 2.0 * math.pi)
            dI = g[ax].k_int * e * 0.004
            if not ((dI > 0.0 and hi[k]) or (dI < 0.0 and lo[k])):
                it[k] += dI
            want = g[ax].k_angle * e - g[ax].k_rate * float(rates[k]) + it[k]
            assert tau[k] == pytest.approx(want, rel=1e-12, abs=1e-12)
        np.testing.assert_allclose(c.integral_term, it, rtol=1e-12, atol=1e-12)


def test_scheduled_ppid_uses_the_gains_at_the_airspeed():
    sched = GainSchedule.from_dict(sched_dict())
    c = ScheduledPPIDController(sched, dt=0.004)
    ref, att, rates = np.array([0.05, 0.02, 0.01]), np.zeros(3), np.array([0.1, 0.0, -0.1])
    tau = c.update(ref, att, rates, 5.0, NO, NO)
    g = sched.gains_at(5.0)
    for k, ax in enumerate(("roll", "pitch", "yaw")):
        ref_pid = CascadedPPID(g[ax], 0.004, wrap=(ax == "yaw"),
                               rate_limit=(2.0, 2.0, 1.0)[k])
        assert tau[k] == pytest.approx(ref_pid.update(ref[k], att[k], rates[k]))


def _pid_state(pid: CascadedPPID) -> tuple:
    return (pid.integral, pid.derivative, pid.previous_rate_error, pid.rate_ref, pid.output,
            pid.output_unsat, pid.saturated, pid.gains)


def test_scheduled_ppid_is_its_axis_loops_with_the_allocation_flags():
    """The controller's one compiled call for three axes equals one ``CascadedPPID`` per axis
    (gains from the schedule at the airspeed, yaw wrapped, per-axis rate limits, the
    allocation's saturation flags), to the last bit of every output and every state the axis
    views show; resets, a deep copy and writes to the views' attributes (state and
    constants) act on the state the compiled step uses."""
    sched = GainSchedule.from_dict(sched_dict((0.0, 10.0, 20.0)))
    c = ScheduledPPIDController(sched, dt=0.004)
    ref_pids = [CascadedPPID(p.gains, p.dt, wrap=p.wrap, rate_limit=p.rate_limit,
                             output_limit=1e6) for p in c.pids]
    rng = np.random.default_rng(5)
    for i in range(3000):
        ref = rng.normal(scale=(0.3, 0.3, 3.0))
        att = rng.normal(scale=(0.3, 0.3, 3.0))
        rates = rng.normal(scale=3.0, size=3)
        V = round(float(rng.uniform(-1.0, 25.0)), 2)
        hi, lo = list(rng.random(3) < 0.2), list(rng.random(3) < 0.2)
        if i % 500 == 0:
            c.reset()
            for p in ref_pids:
                p.reset()
        if i == 1200:  # the views' attributes are the compiled step's state
            c.pids[0].integral = ref_pids[0].integral = 0.25
        if i == 1700:
            c = copy.deepcopy(c)
        if i == 2200:  # and so are its constants
            c.pids[2].rate_limit = ref_pids[2].rate_limit = 0.5
            c.pids[1].u_min, c.pids[1].u_max = ref_pids[1].u_min, ref_pids[1].u_max = -0.2, 0.3
            c.pids[0].method = ref_pids[0].method = "backward_euler"
        tau = c.update(ref, att, rates, V, hi, lo)
        g = sched.gains_at(V)
        for k, ax in enumerate(("roll", "pitch", "yaw")):
            pid = ref_pids[k]
            o = pid.update(float(ref[k]), float(att[k]), float(rates[k]), g[ax],
                           sat_hi=hi[k], sat_lo=lo[k])
            assert np.float64(tau[k]).tobytes() == np.float64(o).tobytes()
            assert _pid_state(c.pids[k]) == _pid_state(pid)
            assert type(c.pids[k].saturated) is bool


def test_scheduled_ppid_anti_windup():
    sched = GainSchedule.from_dict(sched_dict((0.0,)))
    c = ScheduledPPIDController(sched, dt=0.004)
    sat_lo = np.array([False, True, False])
    for _ in range(50):
        c.update(np.array([0.0, -0.2, 0.0]), np.zeros(3), np.zeros(3), 0.0, NO, sat_lo)
    assert c.pids[1].integral == 0.0      # would have gone negative
    c.reset()
    for _ in range(50):
        c.update(np.array([0.0, -0.2, 0.0]), np.zeros(3), np.zeros(3), 0.0, NO, NO)
    assert c.pids[1].integral < 0.0


def test_make_controller_selects_by_name_and_checks_files(tmp_path, ds1):
    for name, d in (("gs-shif", sched_dict()), ("shif", sched_dict((0.0,))),
                    ("lqr", lqr_dict())):
        d = copy.deepcopy(d)
        d["airframe"]["sha256"] = ds1.sha256
        (tmp_path / f"{name}.json").write_text(json.dumps(d))
    assert isinstance(make_controller("gs-shif", tmp_path), ScheduledPPIDController)
    assert isinstance(make_controller("shif", tmp_path, airframe_sha256=ds1.sha256),
                      ScheduledPPIDController)
    c = make_controller("lqr", tmp_path, airframe_name="DS-1", airframe_sha256=ds1.sha256)
    assert isinstance(c, LQRAttitudeController) and len(c.gains_sha256) == 64
    with pytest.raises(ControllerError, match="unknown controller 'pid'"):
        make_controller("pid", tmp_path)
    with pytest.raises(ControllerError, match=r"airframe\.sha256"):
        make_controller("lqr", tmp_path, airframe_sha256="cd" * 32)
    with pytest.raises(ControllerError, match="not found"):
        make_controller("lqr", tmp_path / "nowhere")


@pytest.mark.parametrize("bp", [(0.0,), (0.0, 10.0), (0.0, 1.0, 4.5, 13.0, 18.0)])
def test_scheduled_gains_kernel_is_gains_at_bit_for_bit(bp):
    """The compiled interpolation gives the very bits of ``GainSchedule.gains_at`` at and
    between the breakpoints, below and above them, and for NaN and infinities."""
    from vtolftc.firmware_sim.autopilot import control_kernels as ck
    from vtolftc.firmware_sim.autopilot.pid import gains_row

    d = sched_dict(bp)
    d["axes"]["pitch"]["kd_rate"] = [0.1 + 0.037 * i for i in range(len(bp))]
    s = GainSchedule.from_dict(d)
    rng = np.random.default_rng(3)
    speeds = [*bp, -1.0, 0.0, 25.0, math.nan, math.inf, -math.inf, 1e-300, 17.99999999,
              *rng.uniform(-1.0, 20.0, 500).tolist(),
              *np.round(rng.uniform(0.0, 20.0, 500), 2).tolist()]
    out = np.zeros((3, 5))
    for V in speeds:
        ck.scheduled_gains(*s.kernel_tables, V, out)
        g = s.gains_at(V)
        want = np.array([gains_row(g[ax]) for ax in ("roll", "pitch", "yaw")])
        assert out.tobytes() == want.tobytes(), V


def test_scheduled_axes_gains_are_the_last_step_s():
    """A scheduled controller's axes show the gains of the airspeed of its last step, and a
    write to an axis' gains is the compiled step's."""
    sched = GainSchedule.from_dict(sched_dict((0.0, 10.0)))
    c = ScheduledPPIDController(sched, dt=0.004)
    assert c.pids[1].gains == sched.gains_at(0.0)["pitch"]
    c.update(np.zeros(3), np.zeros(3), np.zeros(3), 4.0, NO, NO)
    assert [p.gains for p in c.pids] == [sched.gains_at(4.0)[ax]
                                         for ax in ("roll", "pitch", "yaw")]
    c.pids[0].gains = sched.gains_at(7.0)["roll"]
    assert c.pids[0].gains == sched.gains_at(7.0)["roll"]

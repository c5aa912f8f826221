"""Flight metrics from synthetic samples with known errors."""

from __future__ import annotations

import math

import numpy as np
import pytest

from vtolftc.firmware_sim.autopilot.interface import (
    AutopilotStatus,
    FlightMode,
    LandedState,
    NavState,
    VtolState,
)
from vtolftc.telemetry import TelemetrySample
from vtolftc.telemetry.metrics import MetricsAccumulator, compute_metrics


def quat(roll, pitch, yaw):
    cr, sr = math.cos(roll / 2), math.sin(roll / 2)
    cp, sp = math.cos(pitch / 2), math.sin(pitch / 2)
    cy, sy = math.cos(yaw / 2), math.sin(yaw / 2)
    return np.array([cr * cp * cy + sr * sp * sy, sr * cp * cy - cr * sp * sy,
                     cr * sp * cy + sr * cp * sy, cr * cp * sy - sr * sp * cy])


def sample(t, alt, att_deg, ref_deg, mode, alt_ref=30.0, armed=True):
    att = np.radians(att_deg)
    nav = NavState(round(t * 1e6), quat(*att), np.zeros(3), np.array([0.0, 0.0, -alt]),
                   np.zeros(3), 10.0)
    st = AutopilotStatus(round(t * 1e6), mode, armed, VtolState.MC, LandedState.IN_AIR,
                         np.radians(ref_deg), att, alt_ref, 10.0, np.zeros(5), np.zeros(15),
                         "solved", "gs-shif")
    return TelemetrySample(nav.time_usec, nav, st)


def test_rmse_over_the_window_and_transition_times():
    samples = [sample(0.0, 0.3, (0, 0, 0), (0, 0, 0), FlightMode.IDLE, alt_ref=0.0)]
    # before the window: large errors that must not count
    samples += [sample(10.0 + 0.1 * k, 25.0, (9, 9, 9), (0, 0, 0), FlightMode.HOVER)
                for k in range(10)]
    # window: alternating errors of known RMSE
    modes = [FlightMode.FRONT_TRANSITION] * 4 + [FlightMode.FIXED_WING] * 4
    for k, mode in enumerate(modes):
        s = 1.0 if k % 2 else -1.0
        samples.append(sample(20.0 + k, 30.0 + 0.5 * s, (2 * s, 1.0, 179.0),
                              (0.0, 0.0, -179.0), mode))
    m = compute_metrics(samples, window_start_s=20.0)
    assert m["samples_in_window"] == 8
    assert m["rmse_altitude_m"] == pytest.approx(0.5)
    assert m["rmse_roll_deg"] == pytest.approx(2.0, abs=1e-9)
    assert m["rmse_pitch_deg"] == pytest.approx(1.0, abs=1e-9)
    assert m["rmse_yaw_deg"] == pytest.approx(2.0, abs=1e-6)        # wrapped: 2 deg, not 358
    assert m["max_abs_yaw_error_deg"] == pytest.approx(2.0, abs=1e-6)
    assert m["transition_start_s"] == 20.0 and m["transition_complete_s"] == 24.0
    assert m["transition_duration_s"] == 4.0
    assert not m["crashed"] and not m["quad_chute"]
    assert m["final_altitude_m"] == pytest.approx(30.5)


def test_crash_and_quad_chute_detection():
    acc = MetricsAccumulator()
    acc.add(sample(0.0, 0.3, (0, 0, 0), (0, 0, 0), FlightMode.IDLE))
    acc.add(sample(5.0, 10.0, (0, 0, 0), (0, 0, 0), FlightMode.HOVER))
    acc.add(sample(6.0, 10.0, (0, 0, 0), (0, 0, 0), FlightMode.FRONT_TRANSITION))
    acc.add(sample(7.0, 10.0, (0, 0, 0), (0, 0, 0), FlightMode.HOVER))
    assert acc.result()["quad_chute"] and not acc.result()["crashed"]
    acc.add(sample(8.0, 0.5, (0, 0, 0), (0, 0, 0), FlightMode.HOVER))   # hit the ground
    r = acc.result()
    assert r["crashed"] and r["crash_time_s"] == 8.0
    acc2 = MetricsAccumulator()
    acc2.add(sample(1.0, 5.0, (70, 0, 0), (0, 0, 0), FlightMode.TAKEOFF))  # rolled over
    assert acc2.result()["crashed"]
    acc3 = MetricsAccumulator()   # on the ground, disarmed, level: no crash
    for k in range(5):
        acc3.add(sample(k, 0.3, (0, 0, 0), (0, 0, 0), FlightMode.IDLE, armed=False))
    assert not acc3.result()["crashed"] and math.isnan(acc3.result()["rmse_roll_deg"])

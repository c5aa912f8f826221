"""The ULog of ``vtolftc fly`` as Flight Review reads it: every topic its plots and map need,
with PX4's field names, the logger's rates and sensible values, read by pyulog (an independent
reader) with Flight Review's own message filter and pyulog's PX4 helpers."""

from __future__ import annotations

import importlib.metadata as md
import math

import numpy as np
import pytest
from pyulog import ULog
from pyulog.px4 import PX4ULog

from vtolftc.firmware_sim.vehicle.sensors import Home

# the topics the issue lists (Flight Review's map, rate plots, sensors, VTOL state, CPU)
LISTED = ("vehicle_global_position", "vehicle_gps_position", "vehicle_angular_velocity",
          "vehicle_rates_setpoint", "sensor_combined", "vehicle_air_data",
          "position_setpoint_triplet", "vtol_vehicle_status", "cpuload")
# Flight Review's load_ulog_file() message filter (app/plot_app/helper.py), the part we log
# (battery_status only with a battery model: SITL)
REVIEW_FILTER = ["sensor_combined", "cpuload", "vehicle_gps_position",
                 "vehicle_local_position", "vehicle_global_position", "actuator_outputs",
                 "vehicle_angular_velocity", "vehicle_attitude", "vehicle_attitude_setpoint",
                 "vehicle_rates_setpoint", "position_setpoint_triplet", "vehicle_status",
                 "airspeed", "vehicle_air_data"]
DURATION_S = 32.0      # takeoff, hover, front transition (complete near 27.8 s), fixed wing


@pytest.fixture(scope="module")
def flight_ulg(tmp_path_factory):
    """``vtolftc fly --case 1`` in-process: its ``flight.ulg``."""
    from vtolftc.cli.main import run

    out = tmp_path_factory.mktemp("fly") / "run"
    assert run(["fly", "--case", "1", "--duration", str(DURATION_S), "--out", str(out),
                "--no-plots"]) == 0
    return out / "flight.ulg"


@pytest.fixture(scope="module")
def flight(flight_ulg):
    """The ULog, every topic, with pyulog's PX4 roll/pitch/yaw fields added."""
    log = ULog(str(flight_ulg))
    PX4ULog(log).add_roll_pitch_yaw()
    return log


def test_flight_review_filter_loads_every_plotted_topic(flight_ulg):
    log = ULog(str(flight_ulg), REVIEW_FILTER, disable_str_exceptions=True)
    names = {d.name for d in log.data_list}
    assert set(REVIEW_FILTER) <= names, set(REVIEW_FILTER) - names
    assert all(len(d.data["timestamp"]) > 0 for d in log.data_list)


def _d(log: ULog, name: str) -> dict[str, np.ndarray]:
    return log.get_dataset(name).data


def test_every_listed_topic_at_the_loggers_rate(flight):
    names = {d.name for d in flight.data_list}
    assert set(LISTED) <= names, set(LISTED) - names
    rates = {"vehicle_angular_velocity": 50, "vehicle_rates_setpoint": 50,
             "sensor_combined": 50, "vehicle_gps_position": 10, "vehicle_global_position": 5,
             "vehicle_air_data": 5, "position_setpoint_triplet": 5, "cpuload": 2}
    for name, hz in rates.items():
        t = _d(flight, name)["timestamp"] * 1e-6
        assert len(t) == pytest.approx(hz * DURATION_S, abs=2), name
        assert np.all(np.diff(t) > 0), name
    vtol = _d(flight, "vtol_vehicle_status")
    assert len(vtol["timestamp"]) >= 5 * DURATION_S - 2


def test_info_flight_review_shows(flight):
    info = flight.msg_info_dict
    assert info["sys_name"] == "vtol-ftc" and info["ver_hw"] == "SITL"
    assert len(info["ver_sw"]) >= 8 and info["time_ref_utc"] == 0
    assert info["sys_os_name"] and info["sys_uuid"]
    assert flight.get_version_info_str() == "v" + md.version("vtol-ftc")


def test_gps_and_global_position_near_home_and_on_the_local_position(flight):
    home = Home()
    gps, glob = _d(flight, "vehicle_gps_position"), _d(flight, "vehicle_global_position")
    lpos = _d(flight, "vehicle_local_position")
    assert set(gps["fix_type"]) == {3} and np.all(gps["satellites_used"] >= 6)
    lat, lon = gps["lat"] * 1e-7, gps["lon"] * 1e-7
    # every fix within 2 km of home; the flight goes north in fixed wing
    k_lat = math.radians(1.0) * 6_371_000.0
    assert np.all(np.abs(lat - home.lat_deg) * k_lat < 2000.0)
    assert np.all(np.abs(lon - home.lon_deg) * k_lat * math.cos(math.radians(home.lat_deg))
                  < 2000.0)
    assert (lat[-1] - home.lat_deg) * k_lat > 50.0
    # GPS and fused altitude AMSL = home + height of the local position at the same time
    for t, alt in ((gps["timestamp"], gps["alt"] * 1e-3), (glob["timestamp"], glob["alt"])):
        z = np.interp(t, lpos["timestamp"], lpos["z"])
        assert np.max(np.abs(alt - (home.alt_m - z))) < 0.2
    assert np.max(np.abs(glob["lat"] - np.interp(glob["timestamp"], gps["timestamp"], lat))) \
        < 1e-5
    assert np.max(-lpos["z"]) == pytest.approx(30.0, abs=2.0)
    speed = np.hypot(glob["vel_n"], glob["vel_e"])
    assert speed[-1] > 12.0 and np.all(gps["time_utc_usec"] > 1.6e15)


def test_angular_velocity_matches_the_attitude_quaternions(flight):
    """Body rates from successive vehicle_attitude quaternions (an independent derivation)
    against vehicle_angular_velocity, and sensor_combined's gyro equal to it."""
    att, w = _d(flight, "vehicle_attitude"), _d(flight, "vehicle_angular_velocity")
    assert np.array_equal(att["timestamp"], w["timestamp"])
    q = np.column_stack([att[f"q[{i}]"] for i in range(4)])
    dt = np.diff(att["timestamp"]) * 1e-6
    # dq = conj(q_k) * q_k+1 (body frame); omega ~ 2 vec(dq) / dt
    w0, x0, y0, z0 = q[:-1].T
    w1, x1, y1, z1 = q[1:].T
    dx = w0 * x1 - x0 * w1 - y0 * z1 + z0 * y1
    dy = w0 * y1 + x0 * z1 - y0 * w1 - z0 * x1
    dz = w0 * z1 - x0 * y1 + y0 * x1 - z0 * w1
    est = 2.0 * np.column_stack((dx, dy, dz)) / dt[:, None]
    logged = np.column_stack([w[f"xyz[{i}]"] for i in range(3)])
    mid = 0.5 * (logged[:-1] + logged[1:])
    for ax in range(3):
        err = np.sqrt(np.mean((est[:, ax] - mid[:, ax]) ** 2))
        sig = np.sqrt(np.mean(mid[:, ax] ** 2))
        assert err < 0.15 * sig + 0.003, (ax, err, sig)
    sc = _d(flight, "sensor_combined")
    for i in range(3):
        assert np.array_equal(sc[f"gyro_rad[{i}]"], w[f"xyz[{i}]"])


def test_accelerometer_and_baro(flight):
    sc, air = _d(flight, "sensor_combined"), _d(flight, "vehicle_air_data")
    lpos = _d(flight, "vehicle_local_position")
    acc = np.column_stack([sc[f"accelerometer_m_s2[{i}]"] for i in range(3)])
    on_ground = sc["timestamp"] < 0.9e6
    assert np.allclose(acc[on_ground][1:], [0.0, 0.0, -9.80665], atol=0.05)
    hover = (sc["timestamp"] > 15e6) & (sc["timestamp"] < 19.5e6)   # steady at 30 m
    assert np.mean(acc[hover, 2]) == pytest.approx(-9.81, abs=0.3)
    assert np.all(np.linalg.norm(acc, axis=1) < 30.0)
    # ISA: about 11.8 Pa per metre near sea level, baro altitude on the local height
    h = -np.interp(air["timestamp"], lpos["timestamp"], lpos["z"])
    slope = -np.polyfit(h, air["baro_pressure_pa"], 1)[0]
    assert slope == pytest.approx(11.8, abs=0.4)
    assert np.max(np.abs(air["baro_alt_meter"] - (Home().alt_m + h))) < 0.2
    assert np.all((air["rho"] > 1.1) & (air["rho"] < 1.3))


def test_rate_setpoints_and_position_setpoints(flight):
    rs = _d(flight, "vehicle_rates_setpoint")
    for ax, lim in (("roll", 2.0), ("pitch", 2.0), ("yaw", 1.0)):
        v = rs[ax]
        assert np.all(np.isfinite(v)) and np.max(np.abs(v)) <= lim + 1e-6
    assert np.max(np.abs(rs["pitch"])) > 0.01
    # the outer P loops: rate setpoint = kp_angle (scheduled, > 0) x attitude error, with
    # the error from pyulog's Euler angles of q_d and q (an independent path)
    att, attsp = _d(flight, "vehicle_attitude"), _d(flight, "vehicle_attitude_setpoint")
    assert np.array_equal(rs["timestamp"], att["timestamp"])
    for ax in ("roll", "pitch", "yaw"):
        err = (attsp[f"{ax}_d"] - att[ax] + np.pi) % (2 * np.pi) - np.pi
        assert np.corrcoef(rs[ax], err)[0, 1] > 0.75, ax
        assert np.polyfit(err, rs[ax], 1)[0] > 0.5, ax
    sp = _d(flight, "position_setpoint_triplet")
    airborne = sp["timestamp"] > 15e6
    assert np.all(sp["current.valid"][airborne] == 1)
    assert np.allclose(sp["current.alt"][airborne], Home().alt_m + 30.0, atol=0.5)
    assert not np.any(sp["previous.valid"]) and not np.any(sp["next.valid"])
    assert np.allclose(attsp["pitch_d"], attsp["pitch_body"], atol=1e-5)


def test_vtol_state_and_cpuload(flight):
    states = _d(flight, "vtol_vehicle_status")["vehicle_vtol_state"]
    changes = [int(s) for k, s in enumerate(states) if k == 0 or s != states[k - 1]]
    assert changes == [3, 1, 4], changes        # MC, transition to FW, FW
    cpu = _d(flight, "cpuload")
    assert np.all((cpu["load"] >= 0.0) & (cpu["load"] <= 1.0)) and np.max(cpu["load"]) > 0
    assert np.all((cpu["ram_usage"] > 0.0) & (cpu["ram_usage"] < 1.0))

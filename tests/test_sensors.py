"""Sensor outputs: consistent with the true state, in MAVLink HIL units, seeded noise."""

from __future__ import annotations

import numpy as np
import pytest

from vtolftc.base.rotation import euler_to_quat
from vtolftc.firmware_sim.vehicle.model import Vehicle
from vtolftc.firmware_sim.vehicle.sensors import (
    Home,
    SensorNoise,
    altitude_from_pressure_m,
    pressure_at_altitude_hpa,
)


def test_isa_pressure_known_values():
    assert pressure_at_altitude_hpa(0.0) == pytest.approx(1013.25)
    assert pressure_at_altitude_hpa(1000.0) == pytest.approx(898.75, abs=0.05)  # ISA table
    assert altitude_from_pressure_m(pressure_at_altitude_hpa(437.0)) == pytest.approx(437.0)


def test_exact_readings_in_hover(ds1, hover_trim):
    v = Vehicle(ds1, state=hover_trim.state, home=Home(alt_m=100.0))
    s = v.sensors()
    assert np.allclose(s.accel_m_s2, [0, 0, -ds1.gravity_m_s2], atol=1e-9)
    assert np.allclose(s.gyro_rad_s, 0.0)
    assert np.allclose(s.mag_gauss, Home().mag_ned_gauss)  # level, heading north
    assert s.pressure_alt_m == pytest.approx(130.0, abs=1e-6)
    assert s.gps_alt_m == pytest.approx(130.0)
    assert s.gps_lat_deg == pytest.approx(Home().lat_deg)
    assert s.diff_pressure_hpa == 0.0 and s.airspeed_m_s == 0.0


def test_heading_east_rotates_the_magnetometer(ds1, hover_trim):
    x = hover_trim.state.copy()
    x[6:10] = euler_to_quat(0.0, 0.0, np.pi / 2)
    s = Vehicle(ds1, state=x).sensors()
    mn, me, md = Home().mag_ned_gauss
    assert np.allclose(s.mag_gauss, [me, -mn, md], atol=1e-12)


def test_airspeed_and_gps_in_cruise(ds1, cruise_trim):
    v = Vehicle(ds1, state=cruise_trim.state)
    v.step(cruise_trim.commands, 1000)
    s = v.sensors()
    assert s.airspeed_m_s == pytest.approx(18.0, abs=1e-3)
    assert s.gps_vel_ned_m_s[0] == pytest.approx(18.0, abs=1e-3)
    north = (s.gps_lat_deg - Home().lat_deg) * np.pi / 180 * 6_378_137.0
    assert north == pytest.approx(18.0, abs=0.01)


def test_noise_is_seeded_and_has_the_requested_spread(ds1, hover_trim):
    def readings(seed):
        v = Vehicle(ds1, state=hover_trim.state, noise=SensorNoise.typical(), seed=seed)
        return np.array([v.sensors().gyro_rad_s for _ in range(4000)])

    a, b, c = readings(1), readings(1), readings(2)
    assert np.array_equal(a, b)
    assert not np.array_equal(a, c)
    assert np.std(a) == pytest.approx(SensorNoise.typical().gyro_rad_s, rel=0.05)


def test_noise_free_sample_has_the_bits_of_adding_zero_arrays() -> None:
    """Without noise, every field is the truth plus a zero, bit for bit (-0.0 becomes +0.0,
    as adding an array of zeros does), and the projection follows a changed home."""
    from vtolftc.base.geodesy import FlatEarth
    from vtolftc.firmware_sim.vehicle.sensors import Home, SensorModel

    m = SensorModel()
    sf = np.array([-0.0, 1.5, -9.81])
    om = np.array([0.1, -0.0, 0.0])
    vel = np.array([-0.0, 2.0, -1.0])
    pos = np.array([12.0, -0.0, -30.0])
    s = m.sample(4000, pos, vel, np.eye(3), om, sf, 17.0)
    z = np.zeros(3)
    assert s.accel_m_s2.tobytes() == (sf + z).tobytes()
    assert s.gyro_rad_s.tobytes() == (om + z).tobytes()
    assert s.gps_vel_ned_m_s.tobytes() == (vel + z).tobytes()
    assert s.mag_gauss.tobytes() == (np.eye(3).T @ np.array(m.home.mag_ned_gauss) + z).tobytes()
    h = m.home
    assert (s.gps_lat_deg, s.gps_lon_deg) == FlatEarth(h.lat_deg, h.lon_deg).to_global(12.0, 0.0)
    m.home = Home(lat_deg=10.0, lon_deg=20.0, alt_m=h.alt_m)
    s2 = m.sample(4000, pos, vel, np.eye(3), om, sf, 17.0)
    assert (s2.gps_lat_deg, s2.gps_lon_deg) == FlatEarth(10.0, 20.0).to_global(12.0, 0.0)

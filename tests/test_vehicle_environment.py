"""The physical vehicle off its airframe file (mass, inertia, CG), wind gusts, state noise."""

from __future__ import annotations

import math

import numpy as np
import pytest

from vtolftc.airframe.loader import load_airframe
from vtolftc.base.rotation import euler_to_quat
from vtolftc.firmware_sim.vehicle import dynamics as dyn
from vtolftc.firmware_sim.vehicle.model import Perturbation, Vehicle
from vtolftc.firmware_sim.vehicle.sensors import StateEstimateNoise, StateNoise
from vtolftc.firmware_sim.vehicle.wind import Gust, WindField


@pytest.fixture(scope="module")
def af():
    return load_airframe()


def _flying_state(v: Vehicle, speed: float = 12.0) -> np.ndarray:
    x = v.state
    x[2] = -30.0
    x[3] = speed
    x[6:10] = euler_to_quat(0.05, 0.08, 0.3)
    x[10:13] = (0.1, -0.2, 0.05)
    x[dyn.N_RIGID:] = np.linspace(0.2, 0.6, v.n_actuators)
    return x


def _cross(a, b):
    return np.cross(np.asarray(a), np.asarray(b))


@pytest.mark.parametrize("physics", [dyn.PROPULSION, dyn.AERODYNAMICS,
                                     dyn.PROPULSION | dyn.AERODYNAMICS])
def test_cg_offset_moves_every_moment_arm(af, physics):
    """M about the moved CG = M about the design CG - d x F (forces unchanged)."""
    d = np.array([0.03, -0.02, 0.01])
    nom = Vehicle(af, physics=physics)
    per = Vehicle(af, physics=physics, perturbation=Perturbation(cg_offset_m=tuple(d)))
    x = _flying_state(nom)
    u = np.linspace(0.1, 0.9, af.n_actuators)
    _, fm0 = nom.derivatives(x, u)
    _, fm1 = per.derivatives(x, u)
    np.testing.assert_allclose(fm1[0:3], fm0[0:3], rtol=0, atol=1e-12)
    np.testing.assert_allclose(fm1[3:6], fm0[3:6] - _cross(d, fm0[0:3]), rtol=1e-12,
                               atol=1e-9)


def test_mass_and_inertia_scale_the_accelerations(af):
    s_m, s_j = 1.2, np.array([1.3, 0.8, 1.1])
    nom = Vehicle(af, physics=dyn.PROPULSION | dyn.GRAVITY)
    per = Vehicle(af, physics=dyn.PROPULSION | dyn.GRAVITY,
                  perturbation=Perturbation(s_m, tuple(s_j)))
    x = _flying_state(nom)
    x[10:13] = 0.0  # no gyroscopic term: J w' = M exactly
    u = np.linspace(0.1, 0.9, af.n_actuators)
    dx0, fm0 = nom.derivatives(x, u)
    dx1, _ = per.derivatives(x, u)
    g = np.array([0.0, 0.0, af.gravity_m_s2])
    np.testing.assert_allclose(dx1[3:6] - g, (dx0[3:6] - g) / s_m, rtol=1e-12)
    # J' = S J S with S = diag(sqrt(s)): w' = J'^-1 M, solved independently
    root = np.sqrt(s_j)
    J1 = np.diag(root) @ np.asarray(af.inertia_kg_m2) @ np.diag(root)
    np.testing.assert_allclose(np.diag(J1), s_j * np.diag(af.inertia_kg_m2), rtol=1e-12)
    np.testing.assert_allclose(dx1[10:13], np.linalg.solve(J1, fm0[3:6]), rtol=1e-10)
    assert per.mass_kg == pytest.approx(s_m * af.mass_kg, rel=1e-15)


def test_identity_perturbation_changes_nothing(af):
    a = Vehicle(af)
    b = Vehicle(af, perturbation=Perturbation())
    u = np.full(af.n_actuators, 0.55)
    for _ in range(50):
        a.step(u, 4)
        b.step(u, 4)
    assert np.array_equal(a.x, b.x)


def test_gust_shape_and_vehicle_wind(af):
    g = Gust(10.0, 2.0, (0.0, 4.0, -2.0))
    assert g.factor(9.99) == 0.0 and g.factor(12.0) == 0.0
    assert g.factor(11.0) == pytest.approx(1.0)
    assert g.factor(10.5) == pytest.approx(0.5)
    wf = WindField((1.0, 0.0, 0.0), (g,))
    out = np.empty(3)
    wf.at(11.0, out)
    np.testing.assert_allclose(out, [1.0, 4.0, -2.0])
    v = Vehicle(af, wind=wf)
    np.testing.assert_allclose(v.wind, [1.0, 0.0, 0.0])
    v.step(np.zeros(af.n_actuators), 11_000)  # 11 s at 1 kHz, on the ground
    np.testing.assert_allclose(v.wind, [1.0, 4.0, -2.0], atol=1e-12)


def test_steady_wind_field_equals_the_constant_wind(af):
    a = Vehicle(af, wind_ned_m_s=(2.0, -1.0, 0.0))
    b = Vehicle(af, wind=WindField((2.0, -1.0, 0.0)))
    x = _flying_state(a)
    a.set_state(x)
    b.set_state(x)
    u = np.full(af.n_actuators, 0.5)
    for _ in range(20):
        a.step(u, 4)
        b.step(u, 4)
    assert np.array_equal(a.x, b.x)


def test_state_noise_statistics_and_seed(af):
    v = Vehicle(af)
    x = _flying_state(v)
    noise = StateNoise(attitude_rad=0.01, rate_rad_s=0.02, position_m=0.5, velocity_m_s=0.1,
                       airspeed_m_s=0.3)
    gen = StateEstimateNoise(noise, seed=3)
    draws = [gen.apply(x, 12.0) for _ in range(4000)]
    xs = np.array([d[0] for d in draws])
    np.testing.assert_allclose(np.std(xs[:, 0:3] - x[0:3], axis=0), 0.5, rtol=0.06)
    np.testing.assert_allclose(np.std(xs[:, 3:6] - x[3:6], axis=0), 0.1, rtol=0.06)
    np.testing.assert_allclose(np.std(xs[:, 10:13] - x[10:13], axis=0), 0.02, rtol=0.06)
    np.testing.assert_allclose(np.linalg.norm(xs[:, 6:10], axis=1), 1.0, atol=1e-12)
    # rotation angle between truth and estimate: |dtheta| of a 3-D normal with sigma 0.01
    dots = np.clip(np.abs(xs[:, 6:10] @ x[6:10]), 0, 1)
    ang = 2 * np.arccos(dots)
    assert math.sqrt(np.mean(ang**2)) == pytest.approx(0.01 * math.sqrt(3), rel=0.06)
    again = StateEstimateNoise(noise, seed=3).apply(x, 12.0)
    assert np.array_equal(again[0], draws[0][0]) and again[1] == draws[0][1]
    other = StateEstimateNoise(noise, seed=4).apply(x, 12.0)
    assert not np.array_equal(other[0], draws[0][0])
    # without noise the vehicle reports its truth (no copy, no draw)
    est, air = v.estimated_state()
    assert est is v.x and air == float(v.fm[6])

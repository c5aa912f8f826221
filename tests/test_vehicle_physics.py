"""The nonlinear 6-DOF vehicle against closed forms, conservation laws and independent solvers."""

from __future__ import annotations

import math

import numpy as np
import pytest
from scipy.integrate import solve_ivp

from vtolftc.base.rotation import dcm, euler_to_quat
from vtolftc.firmware_sim.vehicle import dynamics as dyn
from vtolftc.firmware_sim.vehicle.model import Vehicle


def _state(ds1, pos=(0, 0, -100), vel=(0, 0, 0), euler=(0, 0, 0), omega=(0, 0, 0)):
    x = np.zeros(dyn.N_RIGID + ds1.n_actuators)
    x[0:3], x[3:6], x[10:13] = pos, vel, omega
    x[6:10] = euler_to_quat(*euler)
    return x


def test_free_fall_is_exact(ds1):
    v = Vehicle(ds1, state=_state(ds1, vel=(1.0, -2.0, 0.5), euler=(0.3, -0.2, 1.0)),
                physics=dyn.GRAVITY)
    v.step(np.zeros(ds1.n_actuators), 2000)
    t = 2.0
    g = ds1.gravity_m_s2
    assert v.time_usec == 2_000_000
    assert np.allclose(v.position_ned_m, [2.0, -4.0, -100 + 0.5 * t + 0.5 * g * t * t],
                       atol=1e-9)
    assert np.allclose(v.velocity_ned_m_s, [1.0, -2.0, 0.5 + g * t], atol=1e-9)
    # A free-falling accelerometer reads zero specific force.
    assert np.allclose(v.sensors().accel_m_s2, 0.0, atol=1e-12)


def test_torque_free_rotation_conserves_energy_and_momentum(ds1):
    # Spin mostly about x, the intermediate axis (Jy < Jx < Jz): it tumbles (Dzhanibekov),
    # a hard case for the integrator.
    w0 = np.array([2.0, 0.05, 0.1])
    v = Vehicle(ds1, state=_state(ds1, omega=w0), physics=0)
    J = ds1.inertia_kg_m2

    def invariants():
        w = v.omega_body_rad_s
        R = dcm(v.quaternion)
        return 0.5 * w @ J @ w, R @ (J @ w)

    e0, h0 = invariants()
    ws = []
    for _ in range(100):
        v.step(np.zeros(ds1.n_actuators), 100)
        ws.append(v.omega_body_rad_s)
    e1, h1 = invariants()
    assert abs(e1 - e0) / e0 < 1e-8
    assert np.linalg.norm(h1 - h0) / np.linalg.norm(h0) < 1e-8
    assert min(w[0] for w in ws) < -1.0, "the intermediate-axis spin should flip"

    # Independent solution of Euler's equations with scipy (tight tolerances).
    def euler_eq(_t, w):
        return np.linalg.solve(J, -np.cross(w, J @ w))

    sol = solve_ivp(euler_eq, (0, 10.0), w0, rtol=1e-11, atol=1e-12, t_eval=[10.0])
    assert np.allclose(v.omega_body_rad_s, sol.y[:, -1], atol=1e-6)


def test_hover_trim_holds_still_for_10_s(ds1, hover_trim):
    v = Vehicle(ds1, state=hover_trim.state)
    v.step(hover_trim.commands, 10_000)
    assert np.max(np.abs(v.position_ned_m - hover_trim.state[0:3])) < 1e-6
    assert np.max(np.abs(v.velocity_ned_m_s)) < 1e-6
    assert np.max(np.abs(v.euler_rad)) < 1e-7
    assert np.max(np.abs(v.omega_body_rad_s)) < 1e-7


@pytest.mark.parametrize("airspeed", [13.0, 18.0])
def test_level_flight_trim_holds_altitude_and_airspeed(ds1, airspeed):
    from vtolftc.firmware_sim.vehicle.trim import trim_level_flight

    tp = trim_level_flight(ds1, airspeed, altitude_m=30.0)
    assert tp.mode == "wing" and np.all(tp.lift_rotor_fractions == 0.0)
    v = Vehicle(ds1, state=tp.state)
    v.step(tp.commands, 10_000)
    assert abs(v.altitude_m - 30.0) < 1e-3
    assert abs(v.airspeed_m_s - airspeed) < 1e-3
    assert abs(v.euler_rad[1] - tp.pitch_rad) < 1e-5
    assert abs(v.position_ned_m[0] - 10 * airspeed) < 1e-2


def test_wing_carries_the_weight_at_13_m_s_and_not_below(ds1):
    from vtolftc.firmware_sim.vehicle.trim import TrimError, trim_level_flight

    # Stall speed as in the paper: wing-borne level flight trims at 13 m/s ...
    tp = trim_level_flight(ds1, 13.0)
    assert tp.rotor_lift_share == 0.0
    assert tp.lift_coefficient <= ds1.wing.CL_max
    # ... the wing's own maximum lift at 13 m/s exceeds the weight ...
    packed = dyn.pack(ds1)
    cl_max = max(dyn.lift_drag_coefficients(a, packed.P)[0] for a in np.linspace(0, 0.5, 2001))
    assert cl_max == pytest.approx(ds1.wing.CL_max, abs=1e-4)
    q_s = 0.5 * ds1.air_density_kg_m3 * 13.0**2 * ds1.wing.area_m2
    assert cl_max * q_s > ds1.weight_N
    # ... and it cannot at 12 m/s.
    with pytest.raises(TrimError):
        trim_level_flight(ds1, 12.0)


def test_cruise_trim_within_limits_and_plausible(ds1, cruise_trim):
    assert -1.0 < math.degrees(cruise_trim.pitch_rad) < 4.0
    assert abs(math.degrees(cruise_trim.elevator_rad)) < 10.0
    assert 0.0 < cruise_trim.pusher_thrust_fraction < 0.8
    from vtolftc.firmware_sim.vehicle.trim import trim_level_flight
    tp13 = trim_level_flight(ds1, 13.0)
    assert abs(tp13.elevator_rad) < ds1.surfaces.max_deflection_rad


def test_stall_lift_curve_shape(ds1):
    P = dyn.pack(ds1).P
    cl = [dyn.lift_drag_coefficients(a, P)[0] for a in np.radians([0.0, 5.0, 20.0, 45.0])]
    assert cl[0] == pytest.approx(ds1.wing.CL0, abs=1e-3)
    assert cl[1] == pytest.approx(ds1.wing.CL0 + ds1.wing.CL_alpha * math.radians(5), abs=1e-3)
    assert cl[2] < ds1.wing.CL_max  # past the stall
    assert cl[3] == pytest.approx(2 * math.sin(math.radians(45)) ** 2 * math.cos(
        math.radians(45)), abs=0.02)  # flat plate


# Expected signs of (Fx, Fy, Fz, L, M, N) in body FRD when an actuator's command rises from
# its trim value. Rotors: thrust up (-z) at (x, y): L = -y T, M = x T; reaction torque
# N = -k T for a rotor spinning clockwise seen from above. Surfaces (positive = trailing edge
# down / left): left aileron down rolls right, elevator down pitches nose down, rudders left
# yaw nose left. 0 = no effect expected (checked to be tiny).
SIGN_TABLE = {
    "rotor_1a": (0, 0, -1, +1, +1, -1),
    "rotor_1b": (0, 0, -1, +1, -1, +1),
    "rotor_2a": (0, 0, -1, +1, +1, +1),
    "rotor_2b": (0, 0, -1, +1, -1, -1),
    "rotor_3a": (0, 0, -1, -1, +1, -1),
    "rotor_3b": (0, 0, -1, -1, -1, +1),
    "rotor_4a": (0, 0, -1, -1, +1, +1),
    "rotor_4b": (0, 0, -1, -1, -1, -1),
    "pusher_left": (+1, 0, 0, None, 0, +1),
    "pusher_right": (+1, 0, 0, None, 0, -1),
    "aileron_left": (None, +1, None, +1, None, -1),
    "aileron_right": (None, -1, None, -1, None, +1),
    "elevator": (None, 0, -1, 0, -1, 0),
    "rudder_left": (None, +1, None, +1, 0, -1),
    "rudder_right": (None, +1, None, +1, 0, -1),
}


def _force_moment(v: Vehicle, x: np.ndarray) -> np.ndarray:
    _, fm = v.derivatives(x, x[dyn.N_RIGID:])
    return fm[:6].copy()


@pytest.mark.parametrize("name", list(SIGN_TABLE))
def test_actuator_moves_the_aircraft_with_the_designed_sign(ds1, hover_trim, cruise_trim, name):
    trim = hover_trim if name.startswith("rotor_") else cruise_trim
    v = Vehicle(ds1)
    i = dyn.N_RIGID + ds1.actuator_index(name)
    x = trim.state.copy()
    lo = x.copy()
    hi = x.copy()
    hi[i] += 0.05
    d = _force_moment(v, hi) - _force_moment(v, lo)
    scale = np.max(np.abs(d))
    assert scale > 0
    for k, expected in enumerate(SIGN_TABLE[name]):
        if expected is None:
            continue
        if expected == 0:
            assert abs(d[k]) < 1e-9 * max(1.0, scale) + 1e-12, (name, k, d)
        else:
            assert np.sign(d[k]) == expected, (name, "FyFzLMN"[k - 1] if k else "Fx", d)


@pytest.mark.parametrize("name", ["rotor_2b", "pusher_left", "aileron_left", "elevator",
                                  "rudder_right"])
def test_half_loss_halves_the_actuators_force_and_moment(ds1, cruise_trim, hover_trim, name):
    from vtolftc.firmware_sim.vehicle.faults import Fault

    trim = hover_trim if name.startswith("rotor_") else cruise_trim
    i = dyn.N_RIGID + ds1.actuator_index(name)
    on = trim.state.copy()
    on[i] = 0.6 if name.split("_")[0] in ("rotor", "pusher") else 0.4
    off = on.copy()
    off[i] = 0.0
    healthy = Vehicle(ds1)
    faulty = Vehicle(ds1, faults=[Fault(name, "loss", 0.5, 0.0)])
    full = _force_moment(healthy, on) - _force_moment(healthy, off)
    half = _force_moment(faulty, on) - _force_moment(faulty, off)
    assert np.linalg.norm(full) > 0.1
    assert np.allclose(half, 0.5 * full, rtol=1e-9, atol=1e-12)


def test_ground_contact_settles(ds1):
    v = Vehicle(ds1, state=_state(ds1, pos=(0, 0, -1.5)))
    v.step(np.zeros(ds1.n_actuators), 4000)
    assert v.altitude_m == pytest.approx(v.rest_height_m(), abs=5e-3)
    assert np.max(np.abs(v.velocity_ned_m_s)) < 1e-2
    assert np.max(np.abs(v.euler_rad)) < 1e-3
    # At rest the accelerometer reads 1 g upwards (FRD: -z).
    assert np.allclose(v.sensors().accel_m_s2, [0, 0, -ds1.gravity_m_s2], atol=1e-2)


def test_wind_gives_airspeed_at_rest(ds1, hover_trim):
    v = Vehicle(ds1, state=hover_trim.state, wind_ned_m_s=(-5.0, 0.0, 0.0))
    assert v.airspeed_m_s == pytest.approx(5.0, rel=1e-12)  # a headwind: air from the front
    assert v.alpha_rad == pytest.approx(0.0, abs=1e-12)
    assert v.force_body_N[0] < 0  # drag pushes the hovering aircraft backwards (south)
    v.step(hover_trim.commands, 1000)
    assert v.velocity_ned_m_s[0] < -0.1


def test_actuator_first_order_lag_and_rate_limit(ds1):
    v = Vehicle(ds1, physics=0)
    i = ds1.actuator_index("rotor_1a")
    u = np.zeros(ds1.n_actuators)
    u[i] = 0.1  # small step: rate limit inactive, pure first-order lag
    v.step(u, 50)
    tau = ds1.lift_rotors[0].time_constant_s
    assert v.actuator_positions[i] == pytest.approx(0.1 * (1 - math.exp(-0.05 / tau)), rel=1e-6)
    j = ds1.actuator_index("elevator")
    u[j] = 1.0  # full-range step: rate-limited at first
    v2 = Vehicle(ds1, physics=0)
    v2.step(u, 10)
    rate = ds1.surfaces.rate_limit_rad_s / ds1.surfaces.max_deflection_rad
    assert v2.actuator_positions[j] == pytest.approx(rate * 0.01, rel=1e-9)
    u[j] = 3.0  # beyond the limit: clipped
    v2.step(u, 2000)
    assert v2.actuator_positions[j] == pytest.approx(1.0)


def test_step_n_flat_is_step_n_bit_for_bit(ds1):
    """The flattened-airframe step (one buffer instead of 15 arrays) gives the very bits of
    ``step_n``, for DS-1 and a perturbed copy, in flight with faults and on the ground."""
    rng = np.random.default_rng(11)
    perturbed = dyn.perturb(dyn.pack(ds1), 1.1, (0.95, 1.05, 1.0), (0.02, -0.01, 0.0))
    for pk in (dyn.pack(ds1), perturbed):
        buf, lay = dyn.flatten_packed(pk)
        for trial in range(20):
            x = _state(ds1, pos=(1.0, 2.0, -30.0 if trial % 4 else 0.05),
                       vel=tuple(rng.normal(scale=6.0, size=3)),
                       euler=tuple(rng.normal(scale=0.3, size=3)),
                       omega=tuple(rng.normal(scale=0.5, size=3)))
            x[dyn.N_RIGID:] = rng.uniform(0.0, 1.0, ds1.n_actuators)
            u = rng.uniform(-1.0, 1.0, ds1.n_actuators)
            eff = np.where(rng.random(ds1.n_actuators) < 0.3, 0.5, 1.0)
            stuck = rng.random(ds1.n_actuators) < 0.1
            wind = rng.normal(size=3)
            xa, xb, fa, fb = x.copy(), x.copy(), np.zeros(9), np.zeros(9)
            dyn.step_n(xa, u, eff, stuck, 4, 1e-3, *pk, wind, dyn.ALL_PHYSICS, fa)
            dyn.step_n_flat(xb, u, eff, stuck, 4, 1e-3, buf, lay, wind, dyn.ALL_PHYSICS, fb)
            assert xa.tobytes() == xb.tobytes() and fa.tobytes() == fb.tobytes()


def test_step_refuses_non_finite_commands_and_keeps_the_previous_ones(ds1):
    v = Vehicle(ds1, state=_state(ds1))
    u = np.full(ds1.n_actuators, 0.25)
    v.step(u, 1)
    assert v.u.tolist() == u.tolist()
    x, t = v.x.copy(), v.time_usec
    for bad in (math.nan, math.inf, -math.inf):
        b = u.copy()
        b[3] = bad
        b[0] = 0.75  # a finite entry before the bad one: not taken either
        with pytest.raises(ValueError, match="NaN or inf"):
            v.step(b, 1)
        assert v.u.tolist() == u.tolist()
        assert v.x.tobytes() == x.tobytes() and v.time_usec == t
    v.step(np.asfortranarray(u[::-1].copy())[::-1], 1)  # a strided view is taken as well
    assert v.u.tolist() == u.tolist()


def test_idle_actuator_decays_to_exact_zero_not_to_a_subnormal(ds1, cruise_trim):
    """A lift rotor commanded to zero in cruise ends at exactly 0.0, never on a subnormal
    number (which rounding would hold for ever, putting every later product with it on the
    CPU's slow path: the physics step 2.7x slower after a minute of cruise); and the rotors
    below ``ACT_ZERO`` that it zeroes add nothing physical to the forces and moments (at
    most ~1e-198 N where a sum is exactly zero; against any non-zero sum, below its last
    bit: 150 s flights of cases 0-2 hashed step by step were unchanged by the flush)."""
    tiny = np.finfo(float).tiny
    v = Vehicle(ds1, state=cruise_trim.state.copy(), physics=0)
    u = cruise_trim.commands.copy()
    rotors = list(range(len(ds1.lift_rotors)))  # the first actuators, in airframe order
    v.x[[dyn.N_RIGID + i for i in rotors]] = 0.5
    u[rotors] = 0.0
    tau = max(r.time_constant_s for r in ds1.lift_rotors)
    steps = int(800 * tau / 1e-3)  # exp(-800) ~ 1e-348: below the subnormals without the flush
    seen_sub = False
    for _ in range(steps // 500 + 1):
        v.step(u, 500)
        a = np.abs(v.actuator_positions[rotors])
        seen_sub |= bool(np.any((a > 0) & (a < tiny)))
    assert not seen_sub
    assert np.all(v.actuator_positions[rotors] == 0.0)
    # just below the threshold: the forces and moments of zero
    w = Vehicle(ds1)
    at_zero = cruise_trim.state.copy()
    at_zero[[dyn.N_RIGID + i for i in rotors]] = 0.0
    below = at_zero.copy()
    below[[dyn.N_RIGID + i for i in rotors]] = 0.99 * dyn.ACT_ZERO
    assert np.max(np.abs(_force_moment(w, below) - _force_moment(w, at_zero))) < 1e-190

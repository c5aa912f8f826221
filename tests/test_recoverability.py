"""The physical recoverability oracle against independent answers.

Hand-computed: the healthy symmetric X quad's moment box (closed form from its orthogonal
mixer), the quad with one rotor off (no yaw trim; without yaw, a zero box: L - M = 2 a T3),
every lift rotor of DS-1 off in hover (the deficit is the whole weight: -g). Brute force: a
grid over the commands of a 4-rotor case agrees with the LP margin. DS-1: every single lift
rotor off in hover is recoverable. The wrench model is the vehicle's own equations of motion
(affine in the commands, checked against them).
"""

from __future__ import annotations

import itertools
import math
import tomllib
from pathlib import Path

import numpy as np
import pytest

from vtolftc.airframe.loader import DS1_PATH, airframe_from_dict, load_airframe
from vtolftc.firmware_sim.vehicle.faults import Fault, FaultKind
from vtolftc.firmware_sim.vehicle.model import Vehicle
from vtolftc.firmware_sim.vehicle.recoverability import (
    AXES,
    RECOVERABLE_MIN_MARGIN,
    FlightCondition,
    assess,
    recovery_margin,
    thrust_reserve,
    trim_condition,
    wrench_model,
)

A = 0.5          # quad arm (m), rotors at (+-A, +-A)
K = 0.016        # torque to thrust (m)
HOVER = FlightCondition("hover", 0.0)


def _quad(max_thrust_N: float | None = None) -> object:
    """DS-1's body with an X quad of lift rotors: 1 (A, A) cw, 2 (-A, A) ccw, 3 (-A, -A) cw,
    4 (A, -A) ccw; default max thrust half the weight each (hover at 50 %)."""
    doc = tomllib.loads(Path(DS1_PATH).read_text(encoding="utf-8"))
    weight = doc["mass"]["mass_kg"] * doc["environment"]["gravity_m_s2"]
    lr = doc["lift_rotors"]
    lr["max_thrust_N"] = weight / 2 if max_thrust_N is None else max_thrust_N
    lr["torque_to_thrust_m"] = K
    lr["rotor"] = [{"name": n, "x_m": x, "y_m": y, "z_m": -0.1, "spin": s} for n, x, y, s in (
        ("q1", A, A, "cw"), ("q2", -A, A, "ccw"), ("q3", -A, -A, "cw"), ("q4", A, -A, "ccw"))]
    doc["airframe"]["name"] = "X-quad"
    return airframe_from_dict(doc, source="x-quad")


def _pushers(af) -> list[str]:
    return [n for n in af.actuator_names if n.startswith("pusher_")]


def test_wrench_model_is_the_vehicles_own_physics():
    af = load_airframe()
    cond = FlightCondition("rotor-assisted", 6.0, 0.05, (1.0, 3.0, -0.5))
    m = wrench_model(af, cond)
    veh = Vehicle(af, wind_ned_m_s=cond.wind_ned_m_s)
    rng = np.random.default_rng(0)
    for _ in range(5):
        u = rng.uniform(m.lower, m.upper)
        x = np.zeros(13 + af.n_actuators)
        x[2], x[3] = -30.0, 6.0
        x[6:10] = [math.cos(0.025), 0.0, math.sin(0.025), 0.0]
        x[13:] = u
        _, fm = veh.derivatives(x, u)
        mass = af.mass_kg
        # the model's force is the non-gravitational force plus gravity in body axes
        acc_body = m.wrench(u)[0:3] / mass
        R_T_g = np.array([-math.sin(0.05), 0.0, math.cos(0.05)]) * af.gravity_m_s2
        assert np.allclose(acc_body, fm[0:3] / mass + R_T_g, atol=1e-9)
        assert np.allclose(m.wrench(u)[3:6], fm[3:6], atol=1e-9)


def _hand_healthy_quad_margin(af) -> float:
    """The closed form: rows [sum T, L, M, N] of the X quad are orthogonal, so the thrust
    changes of a moment corner are delta_i = a h_i(c) with
    h_i = Jx cL (-y_i) / (4 A^2) + Jy cM x_i / (4 A^2) + Jz cN (-K s_i) / (4 K^2); a common
    change s of all four (a vertical transient, |4 s| <= a m) may centre them. With the trim
    at T0 = Tmax / 2 the corner is feasible iff max(spread / 2, max h - m / 4, -min h - m / 4)
    a <= T0."""
    jx, jy, jz = af.inertia_kg_m2[0, 0], af.inertia_kg_m2[1, 1], af.inertia_kg_m2[2, 2]
    m = af.mass_kg
    t0 = af.weight_N / 4
    pos = [(A, A, 1), (-A, A, -1), (-A, -A, 1), (A, -A, -1)]
    best = math.inf
    for cl, cm, cn in itertools.product((-1, 1), repeat=3):
        h = [jx * cl * (-y) / (4 * A * A) + jy * cm * x / (4 * A * A)
             + jz * cn * (-K * s) / (4 * K * K) for x, y, s in pos]
        need = max((max(h) - min(h)) / 2, max(h) - m / 4, -min(h) - m / 4)
        best = min(best, t0 / need)
    return best


def test_healthy_quad_margin_is_the_hand_computed_one():
    af = _quad()
    r = recovery_margin(wrench_model(af, HOVER), hold=_pushers(af))
    hand = _hand_healthy_quad_margin(af)
    assert r.recoverable
    assert r.margin == pytest.approx(hand, rel=1e-6)
    assert 0.3 < hand < 1.5  # yaw-limited: the reaction torques are small (sanity)


def test_quad_with_one_rotor_off_is_not_recoverable():
    af = _quad()
    m = wrench_model(af, HOVER)
    off = [("rotor_q1", "off", 1.0)]
    r = recovery_margin(m, off, hold=_pushers(af))
    assert r.margin < 0 and not r.recoverable  # the diagonal pair cannot balance the yaw
    # yaw free: roll and pitch balance only with rotor 3 at zero thrust (L - M = 2 A T3 >= 0),
    # so the trim exists (rotors 2 and 4 at their maximum, Tmax = W / 2) but one moment corner
    # (L < 0 with M > 0) never does: a zero box
    no_yaw = recovery_margin(m, off, hold=_pushers(af),
                             demand=("Fx", "Fy", "Fz", "L", "M"))
    assert no_yaw.margin == pytest.approx(0.0, abs=1e-7)
    assert not no_yaw.recoverable
    assert no_yaw.commands is not None
    assert no_yaw.commands[:4] == pytest.approx([0.0, 1.0, 0.0, 1.0], abs=1e-6)
    # a quad too weak to hold rotors 2 and 4 at W / 2: no trim at all
    weak = _quad(max_thrust_N=0.45 * _quad().weight_N)
    assert recovery_margin(wrench_model(weak, HOVER), off, hold=_pushers(weak),
                           demand=("Fx", "Fy", "Fz", "L", "M")).margin < 0


def _brute_force_margin(af, faults, step: int = 20001) -> float:
    """The box margin by brute force over the commands of the four rotors (pushers held at
    0, surfaces idle in hover): rotor 1's command on a fine grid, the other three solved from
    the three moment equations of a corner; a corner is reached when some grid value gives
    all four commands within 0..1 and a vertical force within a m of the weight. Bisection on
    a over that test (the trim: the 4 x 4 solve within 0..1)."""
    m = wrench_model(af, HOVER)
    eff = np.ones(af.n_actuators)
    for a, _kind, loss in faults:
        eff[af.actuator_index(a)] = 1.0 - loss
    B = (m.B * eff)[:, :4]
    trim = np.linalg.solve(B[2:6], -m.w0[2:6])
    if np.any(trim < 0) or np.any(trim > 1):
        return -1.0
    u1 = np.linspace(0.0, 1.0, step)
    inv = np.linalg.inv(B[3:6, 1:4])
    S = m.scale

    def feasible(a: float) -> bool:
        for c in itertools.product((-1.0, 1.0), repeat=3):
            rhs = a * S[3:6] * np.array(c) - m.w0[3:6]
            rest = inv @ (rhs[:, None] - B[3:6, 0:1] * u1[None, :])   # (3, step)
            fz = m.w0[2] + B[2, 0] * u1 + B[2, 1:4] @ rest
            ok = (np.all((rest >= 0) & (rest <= 1), axis=0) & (np.abs(fz) <= a * S[2]))
            if not ok.any():
                return False
        return True

    lo, hi = 0.0, 5.0
    for _ in range(30):
        mid = 0.5 * (lo + hi)
        lo, hi = (mid, hi) if feasible(mid) else (lo, mid)
    return lo


@pytest.mark.parametrize("faults", [(), (("rotor_q1", "loss", 0.3),),
                                    (("rotor_q2", "loss", 0.2), ("rotor_q3", "loss", 0.1))])
def test_lp_margin_agrees_with_a_brute_force_grid_over_the_commands(faults):
    af = _quad(max_thrust_N=0.4 * _quad().weight_N)  # hover at 62.5 %: the bounds bind
    lp = recovery_margin(wrench_model(af, HOVER), faults, hold=_pushers(af)).margin
    bf = _brute_force_margin(af, faults)
    assert lp > 0.05
    assert bf == pytest.approx(lp, rel=2e-3)


def test_ds1_hover_single_rotors_recoverable_all_off_is_the_whole_weight():
    af = load_airframe()
    cond = trim_condition(af, "hover")
    m = wrench_model(af, cond)
    lift = [f"rotor_{r.name}" for r in af.lift_rotors]
    for name in lift:
        r = recovery_margin(m, [Fault(name, FaultKind.OFF)], hold=_pushers(af))
        assert r.recoverable, name
        assert r.margin >= RECOVERABLE_MIN_MARGIN
    allo = recovery_margin(m, [(n, "off", 1.0) for n in lift], hold=_pushers(af))
    assert not allo.recoverable
    # nothing can carry the weight: the smallest uniform deficit is g itself (m/s^2)
    assert allo.margin == pytest.approx(-af.gravity_m_s2, rel=1e-6)
    # losing effectiveness never helps; losing a rotor costs more than losing half of it
    healthy = recovery_margin(m, hold=_pushers(af)).margin
    half = recovery_margin(m, [("rotor_1b", "loss", 0.5)], hold=_pushers(af)).margin
    off = recovery_margin(m, [("rotor_1b", "off", 1.0)], hold=_pushers(af)).margin
    assert healthy >= half >= off > 0


def test_stuck_holds_the_position_and_wind_is_demand():
    af = load_airframe()
    cruise = trim_condition(af, "wing", 18.0)
    m = wrench_model(af, cruise)
    i = af.actuator_index("elevator")
    r = recovery_margin(m, [("elevator", "stuck", 0.0)])
    assert r.commands is not None
    assert r.commands[i] == pytest.approx(cruise.actuator_positions[i], abs=1e-12)
    assert r.recoverable  # the lift rotors' reserve holds the pitch (as the autopilot does)
    # without the lift rotors' reserve nothing else moves the pitch at a fixed attitude: a
    # zero box at the trim's deflection, no trim at all at full deflection
    lift = [(f"rotor_{r.name}", "off", 1.0) for r in af.lift_rotors]
    bare = recovery_margin(m, [("elevator", "stuck", 0.0), *lift])
    assert bare.margin == pytest.approx(0.0, abs=1e-7) and not bare.recoverable
    full = FlightCondition("wing", 18.0, cruise.pitch_rad, (0.0, 0.0, 0.0),
                           tuple(1.0 if k == i else v
                                 for k, v in enumerate(cruise.actuator_positions)))
    assert recovery_margin(wrench_model(af, full), [("elevator", "stuck", 0.0), *lift]).margin \
        < -1.0
    # a crosswind's forces and moments are demand: mirror images give mirror answers (rotor 1a
    # is on the left, 4a on the right), the two sides differ, and a gust is the smaller of
    # the steady and the peak wind
    hover = trim_condition(af, "hover")
    P = _pushers(af)

    def margin(rotor: str, wind: tuple[float, float, float]) -> float:
        return recovery_margin(wrench_model(af, hover.with_wind(wind)), [(rotor, "off", 1.0)],
                               hold=P).margin

    left, right = margin("rotor_1a", (0.0, 4.0, 0.0)), margin("rotor_1a", (0.0, -4.0, 0.0))
    assert left == pytest.approx(margin("rotor_4a", (0.0, -4.0, 0.0)), rel=1e-6)
    assert right == pytest.approx(margin("rotor_4a", (0.0, 4.0, 0.0)), rel=1e-6)
    assert abs(left - right) > 0.1
    peak = margin("rotor_4a", (0.0, 7.0, -1.0))
    gusty = assess(af, [("rotor_4a", "off", 1.0)], hover.with_wind((0.0, 4.0, 0.0)),
                   gust_peaks_ned_m_s=[(0.0, 3.0, -1.0)], hold=P).margin
    assert gusty == pytest.approx(min(right, peak), rel=1e-9)


def test_thrust_reserve_is_the_hover_margin_of_the_campaign_notes():
    """docs/campaigns/README.md: lost pairs 1b+2b 1.05, 1a+1b 1.12, 1a+2a 1.16 of the weight
    (roll and pitch balanced), computed before this module by its own LP."""
    af = load_airframe()
    m = wrench_model(af, HOVER)
    lift = [f"rotor_{r.name}" for r in af.lift_rotors]
    for pair, want in ((("1b", "2b"), 1.049), (("1a", "1b"), 1.122), (("1a", "2a"), 1.163)):
        got = thrust_reserve(m, [(f"rotor_{p}", "off", 1.0) for p in pair], use=lift)
        assert got == pytest.approx(want, abs=5e-4), pair
    total = sum(r.max_thrust_N for r in af.lift_rotors) / af.weight_N
    assert thrust_reserve(m, use=lift, balanced=()) == pytest.approx(total, rel=1e-9)
    # front arms 0.65 m, rear 0.60 m: pitch balance keeps the front rotors below full thrust
    assert thrust_reserve(m, use=lift) == pytest.approx(
        (4 * 35.0 + 4 * 35.0 * 0.60 / 0.65) / af.weight_N, rel=1e-9)


def test_bad_input_is_refused_in_one_line():
    af = load_airframe()
    m = wrench_model(af, HOVER)
    with pytest.raises(ValueError, match="unknown actuator 'rotor_9z'"):
        recovery_margin(m, [("rotor_9z", "off", 1.0)])
    with pytest.raises(ValueError, match="demand axis 'Q'"):
        recovery_margin(m, demand=("Q",))
    with pytest.raises(ValueError, match="actuator_positions of shape"):
        wrench_model(af, FlightCondition("hover", 0.0, actuator_positions=(0.0,)))
    assert set(AXES) == {"Fx", "Fy", "Fz", "L", "M", "N"}

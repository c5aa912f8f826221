"""Guidance, battery, low-battery failsafe, navigator modes and the ULog writer, each against
an independent answer (textbook second-order response, momentum theory, Ohm's law, pyulog as
the reader)."""

from __future__ import annotations

import math

import numpy as np
import pytest
from pyulog import ULog

from vtolftc.firmware_sim.autopilot.autopilot import Autopilot
from vtolftc.firmware_sim.autopilot.battery import BatteryMonitor
from vtolftc.firmware_sim.autopilot.guidance import L1Guidance, cross_track
from vtolftc.firmware_sim.autopilot.interface import (
    CommandResult,
    FlightMode,
    NavState,
    ParameterStore,
    decode_hil_state,
    encode_hil_state,
    wire_commands,
)
from vtolftc.firmware_sim.autopilot.ulog import TOPICS, ULogWriter
from vtolftc.firmware_sim.vehicle.battery import BatteryModel, propeller_power_w
from vtolftc.firmware_sim.vehicle.model import Vehicle
from vtolftc.firmware_sim.vehicle.sensors import Home
from vtolftc.protocols.px4 import mode_name
from vtolftc.runners.scenario import Action, Scenario, run_scenario

G = 9.80665


ROLL_MAX = math.radians(30.0)


def _unicycle(law, p0, course0, v=18.0, t_end=120.0, dt=0.02, roll_max=ROLL_MAX):
    """Kinematic coordinated-turn aircraft: course rate = g tan(phi) / V, phi = atan(a/g)."""
    p = np.array(p0, dtype=float)
    chi = course0
    track = []
    for _ in range(round(t_end / dt)):
        vel = (v * math.cos(chi), v * math.sin(chi))
        a = law(tuple(p), vel)
        phi = min(max(math.atan2(a, G), -roll_max), roll_max)
        chi += G * math.tan(phi) / v * dt
        p += np.array(vel) * dt
        track.append(p.copy())
    return np.array(track)


def test_l1_line_following_is_the_second_order_response_of_its_period_and_damping():
    l1 = L1Guidance(period=20.0, damping=0.75)
    a, b = (0.0, 0.0), (5000.0, 0.0)
    tr = _unicycle(lambda p, vel: l1.segment(a, b, p, vel), (0.0, 20.0), 0.0)
    xt = np.array([cross_track(a, b, tuple(p))[0] for p in tr])
    assert xt[0] == pytest.approx(20.0, abs=0.5)           # right of the line at the start
    assert abs(xt[-1]) < 0.05                               # converged
    # second order with damping 0.75: overshoot exp(-pi z / sqrt(1 - z^2)) = 2.8 %
    overshoot = -xt.min() / 20.0
    assert overshoot < 0.06
    # and it settles (2 %) within about two periods
    t = np.arange(1, len(xt) + 1) * 0.02
    settled = t[np.where(np.abs(xt) > 0.4)[0][-1]]
    assert settled < 45.0


def test_l1_loiter_settles_on_the_circle_in_the_commanded_direction():
    l1 = L1Guidance(period=20.0, damping=0.75)
    for direction in (1, -1):
        tr = _unicycle(lambda p, vel, d=direction: l1.loiter((0.0, 0.0), 80.0, d, p, vel),
                       (300.0, 0.0), math.pi / 2, t_end=200.0)
        r = np.hypot(tr[-500:, 0], tr[-500:, 1])
        assert np.all(np.abs(r - 80.0) < 2.0), (direction, r.min(), r.max())
        # clockwise seen from above (NED): the angle north->east increases
        ang = np.unwrap(np.arctan2(tr[-500:, 1], tr[-500:, 0]))
        assert np.sign(ang[-1] - ang[0]) == direction


def test_propeller_power_is_momentum_theory_and_the_pack_obeys_ohms_law():
    # hover: T v_i with v_i = sqrt(T / (2 rho A)), over figure of merit and motor efficiency
    t, d = 15.3, 0.56
    area = math.pi * d * d / 4
    v_i = math.sqrt(t / (2 * 1.225 * area))
    assert propeller_power_w(t, 0.0, d) == pytest.approx(t * v_i / (0.7 * 0.85), rel=1e-12)
    # axial flight at V >> v_i: P -> T V / efficiency
    assert propeller_power_w(10.0, 200.0, 0.41) == pytest.approx(10 * 200 / 0.595, rel=1e-3)
    b = BatteryModel()
    e0 = b.open_circuit_v()
    b.step(1.0, 1100.0)
    assert b.voltage_v * b.current_a == pytest.approx(1100.0, rel=1e-9)    # P = V I
    assert b.voltage_v == pytest.approx(e0 - b.current_a * b.spec.r_internal_ohm, rel=1e-9)
    assert b.voltage_v < e0 - 0.5                                          # sag under load
    assert b.consumed_mah == pytest.approx(b.current_a / 3.6, rel=1e-9)    # 1 s of current
    soc = b.soc
    for _ in range(600):
        b.step(1.0, 1100.0)
    assert b.soc < soc and b.open_circuit_v() < e0


def test_low_battery_levels_and_actions():
    ps = ParameterStore()
    actions = []
    mon = BatteryMonitor(ps, lambda a, text: actions.append(a))
    ps.set("COM_LOW_BAT_ACT", 3)
    ps.set("BAT1_CAPACITY", 1000.0)
    mon.update(0, 6 * 4.05, 0.0)
    assert mon.remaining == pytest.approx(1.0) and mon.charge_state == 1
    t = 0
    while mon.remaining > 0.03:
        t += 1_000_000
        mon.update(t, 22.0, 36.0)   # 36 A = 10 mAh per second
    assert actions == ["warn", "rtl", "land"]
    # trapezoidal current integral: 0 -> 36 A over the first second, then 36 A
    assert mon.consumed_mah == pytest.approx(36.0 * (t * 1e-6 - 0.5) / 3.6, rel=1e-9)


def _fly(ap: Autopilot, veh: Vehicle, seconds: float, until=None) -> None:
    home = veh.sensor_model.home
    h = (home.lat_deg, home.lon_deg, home.alt_m)
    for _ in range(round(seconds * 250)):
        x = veh.x
        nav = decode_hil_state(encode_hil_state(NavState(veh.time_usec, x[6:10], x[10:13],
                                                         x[0:3], x[3:6], float(veh.fm[6])),
                                                *h), *h)
        veh.step(wire_commands(ap.step(nav)), 4)
        if until is not None and until(ap, veh):
            return


@pytest.fixture
def flying():
    ap = Autopilot(controller="gs-shif")
    veh = Vehicle(ap.airframe)
    home = veh.sensor_model.home
    ap.set_home(home.lat_deg, home.lon_deg, home.alt_m)
    _fly(ap, veh, 0.1)
    return ap, veh


def _mode(ap) -> str:
    return mode_name(ap.status().px4_custom_mode)


def test_takeoff_altitude_is_amsl_and_modes_are_reported_as_px4(flying):
    ap, veh = flying
    home_alt = Home().alt_m
    assert _mode(ap) == "AUTO.LOITER"                        # on the ground: Hold
    assert ap.command(400, [1.0]) == CommandResult.ACCEPTED
    # more than 500 m above home: refused
    assert ap.command(22, [math.nan] * 6 + [home_alt + 600.0]) == CommandResult.DENIED
    assert ap.command(22, [math.nan] * 6 + [home_alt + 30.0]) == CommandResult.ACCEPTED
    _fly(ap, veh, 1.0)
    assert _mode(ap) == "AUTO.TAKEOFF"
    _fly(ap, veh, 40.0, until=lambda a, v: a.modes.mode == FlightMode.HOVER)
    _fly(ap, veh, 5.0)
    assert -veh.x[2] == pytest.approx(30.0, abs=0.5)
    assert _mode(ap) == "AUTO.LOITER"
    # DO_REPOSITION 20 m east, then RTL: back home and landed, disarmed
    lat, lon = ap.navigator.to_global(0.0, 20.0)
    assert ap.command(192, [-1, 1, 0, math.nan, lat, lon, home_alt + 25.0]) == \
        CommandResult.ACCEPTED
    _fly(ap, veh, 20.0)
    assert veh.x[1] == pytest.approx(20.0, abs=1.0) and -veh.x[2] == pytest.approx(25, abs=1)
    assert ap.command(20, []) == CommandResult.ACCEPTED
    assert _mode(ap) == "AUTO.RTL"
    _fly(ap, veh, 120.0, until=lambda a, v: not a.modes.armed)
    assert not ap.modes.armed and math.hypot(veh.x[0], veh.x[1]) < 1.0
    assert _mode(ap) == "AUTO.LOITER"


def test_ulog_of_a_flight_read_by_pyulog(tmp_path):
    path = tmp_path / "flight.ulg"
    writer = ULogWriter(path)

    def setup(ap):
        writer.ap = ap

    home_alt = Home().alt_m
    sc = Scenario("ulog", "", 12.0,
                  (Action(0.5, "command", "arm", 400, (1.0,) + (math.nan,) * 6),
                   Action(0.5, "command", "takeoff", 22, (math.nan,) * 6 + (home_alt + 10.0,))))
    run_scenario(sc, observers=[writer], autopilot_setup=setup)
    log = ULog(str(path))
    names = {d.name for d in log.data_list}
    assert set(TOPICS) - {"battery_status", "navigator_mission_item"} <= names, names
    att = log.get_dataset("vehicle_attitude")
    t = att.data["timestamp"]
    assert (t[-1] - t[0]) * 1e-6 == pytest.approx(12.0, abs=0.1)
    assert len(t) == pytest.approx(12.0 * 50, abs=2)
    lpos = log.get_dataset("vehicle_local_position")
    assert -lpos.data["z"][-1] == pytest.approx(10.0, abs=1.0)
    assert log.initial_parameters["MIS_TAKEOFF_ALT"] == pytest.approx(30.0)
    assert log.initial_parameters["SYS_FAILURE_EN"] == 0
    assert isinstance(log.initial_parameters["SYS_FAILURE_EN"], int)
    st = log.get_dataset("vehicle_status")
    assert set(st.data["arming_state"]) == {1, 2}
    texts = [m.message for m in log.logged_messages]
    assert any("takeoff" in x for x in texts), texts
    assert log.msg_info_dict["sys_name"] == "vtol-ftc"


@pytest.mark.slow
def test_vtol_takeoff_loiter_speed_change_and_vtol_land_in_process():
    """NAV_VTOL_TAKEOFF (climb, align, transition), DO_CHANGE_SPEED, NAV_LOITER_TIME in
    fixed-wing, NAV_VTOL_LAND (back transition at the braking distance, land at the point)."""
    from vtolftc.firmware_sim.autopilot.mission import MissionItem
    from vtolftc.runners.mission_run import _latlon, run_mission

    h = Home()
    rel = 6
    hx, hy = _latlon(h, 0.0, 0.0)

    def at(n, e):
        return _latlon(h, n, e)

    nan = math.nan
    items = [
        MissionItem(0, rel, 84, 1, 0.0, 0.0, 0.0, nan, *at(0.0, 0.0), 30.0),  # VTOL takeoff
        MissionItem(1, rel, 16, 1, 0.0, 0.0, 0.0, nan, *at(0.0, 400.0), 30.0),
        MissionItem(2, 2, 178, 1, 0.0, 16.0, -1.0, 0.0, 0, 0, 0.0),          # 16 m/s
        MissionItem(3, rel, 19, 1, 40.0, 0.0, 80.0, nan, *at(300.0, 400.0), 35.0),
        MissionItem(4, rel, 85, 1, 0.0, 0.0, 0.0, nan, hx, hy, 0.0),          # VTOL land
    ]
    r = run_mission(items, timeout_s=500.0)
    assert [s for _, s in r.reached] == [0, 1, 2, 3, 4]
    assert r.landed_disarmed and math.hypot(*r.final_position[:2]) < 5.0
    t_reached = dict((s, t) for t, s in r.reached)
    assert t_reached[3] - t_reached[2] > 40.0            # the loiter time, plus the approach
    sel = (r.seq == 3) & (r.mode == int(FlightMode.FIXED_WING))
    d = np.hypot(r.pos_ned[sel, 0] - 300.0, r.pos_ned[sel, 1] - 400.0)
    assert np.median(np.abs(d[-100:] - 80.0)) < 5.0      # on the 80 m circle at the end
    assert -r.pos_ned[sel, 2][-1] == pytest.approx(35.0, abs=2.0)


def test_low_battery_failsafe_returns_and_lands(flying):
    """COM_LOW_BAT_ACT = 3: at the critical level the autopilot returns home and lands."""
    ap, veh = flying
    home_alt = Home().alt_m
    ap.params.set("COM_LOW_BAT_ACT", 3)
    ap.params.set("BAT1_CAPACITY", 200.0)     # a small pack: minutes become seconds
    ap.command(400, [1.0])
    ap.command(22, [math.nan] * 6 + [home_alt + 10.0])
    _fly(ap, veh, 30.0, until=lambda a, v: a.modes.mode == FlightMode.HOVER)
    lat, lon = ap.navigator.to_global(15.0, 0.0)
    ap.command(192, [-1, 1, 0, math.nan, lat, lon, math.nan])
    _fly(ap, veh, 15.0)
    t = veh.time_usec
    bat = BatteryModel()
    while ap.status().px4_custom_mode != (4 << 16 | 5 << 24):
        t += 200_000
        bat.step(0.2, 1100.0)
        ap.battery_update(t, bat.voltage_v, bat.current_a)
        assert ap.battery.remaining > 0.0
    assert 0.05 <= ap.battery.remaining < 0.07 and ap.battery.level == 2
    assert any("battery critical" in e for _, e in ap.event_log)
    _fly(ap, veh, 90.0, until=lambda a, v: not a.modes.armed)
    assert not ap.modes.armed and math.hypot(veh.x[0], veh.x[1]) < 1.0

"""PX4 semantics a client depends on (issue 25), in-process and fast: NAV_TAKEOFF's param7
below home or NaN means MIS_TAKEOFF_ALT, auto-disarm on the ground (COM_DISARM_PRFLT,
COM_DISARM_LAND), the flight record, and the ground-station endpoint's GET_HOME_POSITION,
REQUEST_FLIGHT_INFORMATION, GET_MESSAGE_INTERVAL and the ODOMETRY, ALTITUDE, WIND_COV,
HIGHRES_IMU, SCALED_IMU, SYSTEM_TIME and FLIGHT_INFORMATION messages (fields and rates).

The same over real processes and UDP: tests/test_sitl_px4_semantics.py.
"""

from __future__ import annotations

import math
import time

import numpy as np
import pytest
from support.memory_link import CaptureTransport, parse, sent_messages

from vtolftc.airframe.loader import load_airframe
from vtolftc.firmware_sim.autopilot.arming import ArmingMonitor
from vtolftc.firmware_sim.autopilot.autopilot import Autopilot
from vtolftc.firmware_sim.autopilot.gcs_endpoint import GcsEndpoint
from vtolftc.firmware_sim.autopilot.gcs_telemetry import wind_estimate
from vtolftc.firmware_sim.autopilot.hil_bridge import HilBridge
from vtolftc.firmware_sim.autopilot.interface import (
    CommandResult,
    FlightMode,
    NavState,
    ParameterStore,
)
from vtolftc.protocols import Link, make_codec
from vtolftc.protocols.failure_units import ActuatorTable

NAN = math.nan
A, D, T = CommandResult.ACCEPTED, CommandResult.DENIED, CommandResult.TEMPORARILY_REJECTED
HOME = (45.5027, 9.1566, 122.0)


def _nav(t_s: float, alt: float = 0.29, vn: float = 0.0, airspeed: float = 0.0,
         q=(1.0, 0.0, 0.0, 0.0)) -> NavState:
    return NavState(round(t_s * 1e6), np.array(q, dtype=float), np.array([0.01, -0.02, 0.03]),
                    np.array([1.5, -2.5, -alt]), np.array([vn, 0.5, -0.25]), airspeed)


@pytest.fixture
def ap(ds1, hand_gains):
    a = Autopilot(ds1, controller="shif", gains_dir=hand_gains)
    a.step(_nav(0.0))
    a.set_home(*HOME)
    return a


def _takeoff(ap, param7: float) -> CommandResult:
    return ap.command(22, [NAN] * 6 + [param7])


# ------------------------------------------------------------------ NAV_TAKEOFF param7
def test_takeoff_param7_below_home_or_nan_is_mis_takeoff_alt(ap):
    """What MAVProxy's ``takeoff 30`` sends (param7 = 30, below home's 122 m AMSL): PX4 takes
    off to MIS_TAKEOFF_ALT and says so."""
    ap.params.set("MIS_TAKEOFF_ALT", 25.0)
    assert ap.command(400, [1.0]) == A
    assert ap.command(22, [0.0] * 6 + [30.0]) == A         # MAVProxy: params 1-6 are 0
    st = ap.status()
    assert st.mode == FlightMode.TAKEOFF and st.altitude_ref_m == 25.0
    assert st.message.startswith("Using minimum takeoff altitude: 25.00 m")
    assert "-92.0 m above home" in st.message


def test_takeoff_param7_nan(ap):
    assert ap.command(400, [1.0]) == A
    assert _takeoff(ap, NAN) == A
    assert ap.status().altitude_ref_m == 30.0                # MIS_TAKEOFF_ALT default
    assert ap.status().message == "Using minimum takeoff altitude: 30.00 m"


@pytest.mark.parametrize(("height", "result", "ref"), [
    (8.0, A, 8.0), (1.0, A, 1.0), (0.5, A, 30.0), (-0.1, A, 30.0), (-122.0, A, 30.0),
    (500.0, A, 500.0), (600.0, D, None)])
def test_takeoff_param7_heights(ds1, hand_gains, height, result, ref):
    a = Autopilot(ds1, controller="shif", gains_dir=hand_gains)
    a.step(_nav(0.0))
    a.set_home(*HOME)
    a.command(400, [1.0])
    assert _takeoff(a, HOME[2] + height) == result
    if ref is not None:
        assert a.status().altitude_ref_m == pytest.approx(ref)
    else:
        assert a.status().mode == FlightMode.IDLE


def test_takeoff_denied_while_disarmed_says_so_not_the_altitude(ap):
    assert _takeoff(ap, 30.0) == D
    assert "Using minimum" not in ap.status().message


def test_takeoff_without_home_is_temporarily_rejected(ds1, hand_gains):
    a = Autopilot(ds1, controller="shif", gains_dir=hand_gains)
    a.step(_nav(0.0))
    a.command(400, [1.0])
    assert _takeoff(a, 30.0) == T
    assert _takeoff(a, NAN) == A                             # NaN needs no home


# ------------------------------------------------------------------ auto-disarm
def _idle_until(ap, t0: float, t1: float, dt: float = 0.004) -> float:
    """Step the autopilot on the ground from t0 until disarmed or t1; returns the time."""
    t = t0
    while t < t1 and ap.modes.armed:
        t += dt
        ap.step(_nav(t))
    return t


def test_preflight_auto_disarm_after_com_disarm_prflt(ap):
    uuid0 = ap.params.get("COM_FLIGHT_UUID")
    assert ap.params.get("COM_DISARM_PRFLT") == 10.0 and ap.params.get("COM_DISARM_LAND") == 2.0
    assert ap.command(400, [1.0]) == A
    assert ap.arming.arming_usec == 1                        # armed at t = 0 (0 means never)
    t = _idle_until(ap, 0.0, 9.99)
    assert ap.modes.armed                                     # not before 10 s
    t = _idle_until(ap, t, 11.0)
    assert not ap.modes.armed and t == pytest.approx(10.0, abs=0.005)
    st = ap.status()
    assert st.message == "Disarmed by auto preflight disarming" and st.mode == FlightMode.IDLE
    assert ap.params.get("COM_FLIGHT_UUID") == uuid0 + 1
    assert ap.arming.takeoff_usec == 0 and ap.arming.landing_ms == 0


def test_preflight_disarm_parameter_acts_and_non_positive_disables(ap):
    ap.params.set("COM_DISARM_PRFLT", 3.0)
    ap.command(400, [1.0])
    t = _idle_until(ap, 0.0, 20.0)
    assert not ap.modes.armed and t == pytest.approx(3.0, abs=0.005)
    ap.params.set("COM_DISARM_PRFLT", 0.0)
    ap.command(400, [1.0])
    t = _idle_until(ap, t, t + 25.0)
    assert ap.modes.armed                                     # 0: never
    ap.params.set("COM_DISARM_PRFLT", -1.0)
    assert ap.modes.armed


def test_no_preflight_disarm_once_taken_off(ap):
    ap.command(400, [1.0])
    t = _idle_until(ap, 0.0, 9.0)
    assert _takeoff(ap, NAN) == A
    for _ in range(1000):                                     # 4 s more: TAKEOFF, climbing
        t += 0.004
        ap.step(_nav(t, alt=0.29 + (t - 9.0)))
    assert ap.modes.armed and ap.modes.mode == FlightMode.TAKEOFF
    assert ap.arming.takeoff_usec == pytest.approx(9.0e6, abs=5000)


def test_arming_monitor_landing_and_mission():
    ps = ParameterStore()
    mon = ArmingMonitor(ps)
    idle, land, hover = FlightMode.IDLE, FlightMode.LAND, FlightMode.HOVER
    assert mon.check(1_000_000, True, idle) == ""
    assert mon.arming_usec == 1_000_000
    assert mon.check(2_000_000, True, hover) == ""            # took off
    assert mon.takeoff_usec == 2_000_000
    assert mon.check(30_000_000, True, land) == ""
    assert mon.check(40_000_000, True, idle, mission_running=True) == ""   # amid a mission
    assert mon.landing_ms == 40_000
    assert mon.check(45_000_000, True, idle, mission_running=True) == ""
    # the mission finished after 45 s: COM_DISARM_LAND counts from its last running check
    assert mon.check(46_000_000, True, idle) == ""
    assert mon.check(46_999_000, True, idle) == ""
    assert mon.check(47_000_000, True, idle) == "Disarmed by landing"
    ps.set("COM_DISARM_LAND", -1.0)
    assert mon.check(90_000_000, True, idle) == ""            # disabled
    assert ps.get("COM_FLIGHT_UUID") == 0
    mon.track(91_000_000, False, idle)
    assert ps.get("COM_FLIGHT_UUID") == 1
    mon.track(92_000_000, True, idle)                         # re-armed: record reset
    assert (mon.arming_usec, mon.takeoff_usec, mon.landing_ms) == (92_000_000, 0, 0)
    assert not mon.taken_off


# ------------------------------------------------------------------ the endpoint


def _msgs(link: Link) -> list:
    return sent_messages(link.transport)


@pytest.fixture()
def ep():
    af = load_airframe()
    a = Autopilot(af)
    links = [Link(CaptureTransport(), system_id=1, component_id=1) for _ in range(2)]
    hil = HilBridge(Link(CaptureTransport(), system_id=1, component_id=1))
    e = GcsEndpoint(a, hil, links, actuators=ActuatorTable.from_names(af.actuator_names),
                    start=False)
    yield e
    e.close()


_GS = make_codec(255, 190)


def _command(ep, cmd: int, *params: float, link: int = 0) -> list:
    """COMMAND_LONG from a ground station on link ``link``; the messages it got back."""
    p = list(params) + [0.0] * (7 - len(params))
    data = _GS.command_long_encode(1, 1, cmd, 0, *p).pack(_GS)
    _GS.seq = (_GS.seq + 1) & 0xFF
    ep.io.queues[link].extend(parse([data]))
    ep.serve_once()
    return _msgs(ep.links[link])


def _ack(msgs, cmd: int) -> int:
    acks = [m.result for m in msgs if m.get_type() == "COMMAND_ACK" and m.command == cmd]
    assert len(acks) == 1, msgs
    return acks[0]


def _of(msgs, name: str):
    got = [m for m in msgs if m.get_type() == name]
    assert got, f"no {name} in {[m.get_type() for m in msgs]}"
    return got[-1]


def _feed(ep, t_s: float, *, alt: float = 10.0, vn: float = 0.0, airspeed: float = 0.0,
          q=(1.0, 0.0, 0.0, 0.0), sensor: bool = True) -> NavState:
    """A control step as the control thread publishes it (navigation, status, HIL sensor)."""
    nav = _nav(t_s, alt=alt, vn=vn, airspeed=airspeed, q=q)
    if sensor:
        ep.hil.last_sensor = _GS.hil_sensor_encode(
            nav.time_usec, 0.1, -0.2, -9.8, 0.01, 0.02, -0.03, 0.21, 0.01, 0.42, 1011.0, 0.5,
            133.5, 21.5, 0x1FFF)
        ep.hil.last_state = _GS.hil_state_quaternion_encode(
            nav.time_usec, list(q), 0, 0, 0, 0, 0, 0, 0, 0, 0, round(airspeed * 100),
            round(airspeed * 100), 0, 0, 0)
    ep.on_step(nav, ep.ap.status())
    return nav


def _step(ep, t_s: float, **kw) -> NavState:
    """:func:`_feed`, then one worker cycle (it sees the step), its output discarded."""
    nav = _feed(ep, t_s, **kw)
    ep.serve_once()
    for link in ep.links:
        link.transport.sent.clear()
    return nav


def test_get_home_position_is_answered_as_px4(ep):
    assert _ack(_command(ep, 410), 410) == T                  # no home yet: "no data yet"
    ep.hil.home = HOME
    _step(ep, 1.0)
    msgs = _command(ep, 410)
    assert _ack(msgs, 410) == A
    home = _of(msgs, "HOME_POSITION")
    assert (home.latitude, home.longitude, home.altitude) == (455027000, 91566000, 122000)
    msgs = _command(ep, 410, link=1)                           # answered on its own link
    assert _ack(msgs, 410) == A and _of(msgs, "HOME_POSITION").altitude == 122000


def test_flight_information_by_request_and_command_528(ep):
    _step(ep, 2.0)
    for cmd, msgs in ((512, _command(ep, 512, 264.0)), (528, _command(ep, 528))):
        assert _ack(msgs, cmd) == A
        fi = _of(msgs, "FLIGHT_INFORMATION")
        assert (fi.arming_time_utc, fi.takeoff_time_utc, fi.landing_time) == (0, 0, 0)
        assert fi.flight_uuid == 0 and fi.time_boot_ms == 2000
    ep.ap.arming.track(2_500_000, True, FlightMode.IDLE)
    ep.ap.arming.track(3_000_000, True, FlightMode.TAKEOFF)
    ep.ap.params.set("COM_FLIGHT_UUID", 7)
    fi = _of(_command(ep, 512, 264.0), "FLIGHT_INFORMATION")
    assert (fi.arming_time_utc, fi.takeoff_time_utc, fi.flight_uuid) == (2_500_000, 3_000_000, 7)


def test_new_streams_have_px4_field_semantics(ep):
    ep.hil.home = HOME
    nav = _step(ep, 3.0, alt=10.0)
    got = {}
    for mid in (331, 141, 231, 105, 26, 2):
        msgs = _command(ep, 512, float(mid))
        assert _ack(msgs, 512) == A, mid
        got[mid] = msgs[0]
    od = got[331]
    assert od.get_type() == "ODOMETRY" and od.time_usec == nav.time_usec
    assert (od.frame_id, od.child_frame_id, od.estimator_type) == (1, 1, 8)
    assert (od.x, od.y, od.z) == pytest.approx((1.5, -2.5, -10.0))
    assert (od.vx, od.vy, od.vz) == pytest.approx((0.0, 0.5, -0.25))
    assert list(od.q) == [1.0, 0.0, 0.0, 0.0]
    assert (od.rollspeed, od.pitchspeed, od.yawspeed) == pytest.approx((0.01, -0.02, 0.03))
    assert math.isnan(od.pose_covariance[0]) and math.isnan(od.velocity_covariance[0])
    alt = got[141]
    assert alt.get_type() == "ALTITUDE"
    assert alt.altitude_monotonic == pytest.approx(133.5)     # the barometer's
    assert alt.altitude_amsl == pytest.approx(132.0)          # home 122 + 10
    assert alt.altitude_local == pytest.approx(10.0) and alt.altitude_relative == pytest.approx(10)
    assert math.isnan(alt.altitude_terrain) and math.isnan(alt.bottom_clearance)
    wind = got[231]
    assert wind.get_type() == "WIND_COV" and math.isnan(wind.wind_x)   # hover: unknown
    assert wind.wind_z == 0.0 and wind.wind_alt == pytest.approx(132.0)
    imu = got[105]
    assert imu.get_type() == "HIGHRES_IMU" and imu.time_usec == nav.time_usec
    assert (imu.xacc, imu.zacc, imu.xgyro, imu.zmag) == pytest.approx((0.1, -9.8, 0.01, 0.42))
    assert (imu.abs_pressure, imu.diff_pressure, imu.temperature) == pytest.approx(
        (1011.0, 0.5, 21.5))
    assert imu.fields_updated == 0x1FFF
    sc = got[26]
    assert sc.get_type() == "SCALED_IMU" and sc.time_boot_ms == 3000
    assert (sc.xacc, sc.zacc) == (round(0.1 / 9.80665 * 1e3), round(-9.8 / 9.80665 * 1e3))
    assert (sc.xgyro, sc.zgyro, sc.zmag, sc.temperature) == (10, -30, 420, 2150)
    st = got[2]
    assert st.get_type() == "SYSTEM_TIME" and st.time_boot_ms == 3000
    assert abs(st.time_unix_usec - time.time() * 1e6) < 60e6


def test_wind_estimate_in_fixed_wing():
    yaw = math.radians(30.0)
    q = (math.cos(yaw / 2), 0.0, 0.0, math.sin(yaw / 2))
    vel = np.array([18.0 * math.cos(yaw) + 3.0, 18.0 * math.sin(yaw) - 1.0, 0.0])
    assert wind_estimate(q, vel, 18.0) == pytest.approx((3.0, -1.0))


def test_wind_cov_streamed_in_fixed_wing_only(ep):
    ep.hil.home = HOME
    ep.ap.modes.armed = True
    ep.ap.modes.mode = FlightMode.FIXED_WING
    _step(ep, 4.0, vn=20.0, airspeed=18.0)
    w = _of(_command(ep, 512, 231.0), "WIND_COV")
    assert (w.wind_x, w.wind_y) == pytest.approx((2.0, 0.5))     # v_east 0.5, heading N
    assert math.isnan(w.var_horiz) and w.var_vert == 0.0


def test_message_interval_set_and_get_change_the_rate(ep):
    """Default 5 Hz ODOMETRY; MAV_CMD_SET_MESSAGE_INTERVAL to 20 Hz on link 0 only;
    GET_MESSAGE_INTERVAL reports it; -1 stops it; 0 restores the default."""
    ep.hil.home = HOME

    def count(t0: float, seconds: float) -> tuple[int, int]:
        n = [0, 0]
        for k in range(round(seconds * 250)):
            _feed(ep, t0 + k * 0.004)
            ep.serve_once()
            for i in (0, 1):
                n[i] += sum(m.get_type() == "ODOMETRY" for m in _msgs(ep.links[i]))
        return n[0], n[1]

    n0, n1 = count(1.0, 4.0)
    assert n0 == pytest.approx(20, abs=1) and n1 == pytest.approx(20, abs=1)
    assert _ack(_command(ep, 511, 331.0, 50_000.0), 511) == A
    n0, n1 = count(5.0, 4.0)
    assert n0 == pytest.approx(80, abs=1) and n1 == pytest.approx(20, abs=1)
    msgs = _command(ep, 510, 331.0)
    assert _ack(msgs, 510) == A and _of(msgs, "MESSAGE_INTERVAL").interval_us == 50_000
    assert _of(_command(ep, 510, 331.0, link=1), "MESSAGE_INTERVAL").interval_us == 200_000
    assert _ack(_command(ep, 511, 331.0, -1.0), 511) == A
    assert count(9.0, 2.0)[0] == 0
    assert _of(_command(ep, 510, 331.0), "MESSAGE_INTERVAL").interval_us == -1
    assert _ack(_command(ep, 511, 264.0, 1e6), 511) == A          # FLIGHT_INFORMATION: on
    assert _ack(_command(ep, 510, 99999.0), 510) == CommandResult.UNSUPPORTED

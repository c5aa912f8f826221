"""Ground-station library against the autopilot's MAVLink endpoint (in-thread, no vehicle),
PX4 wire conventions, actuator numbering and the ``vtolftc gcs`` command line's input checks."""

from __future__ import annotations

import math
import struct
import threading
import time

import pytest

from vtolftc.cli.main import run as cli_run
from vtolftc.firmware_sim.autopilot.autopilot import Autopilot
from vtolftc.firmware_sim.autopilot.gcs_endpoint import GcsEndpoint
from vtolftc.firmware_sim.autopilot.hil_bridge import HilBridge
from vtolftc.gcs.actuators import default_table
from vtolftc.gcs.client import GcsError, GcsTimeout, GroundStation, command_name, result_name
from vtolftc.protocols import SigningConfig, open_link
from vtolftc.protocols.failure_units import FAILURE_UNIT_MOTOR, FAILURE_UNIT_SERVO, ActuatorTable
from vtolftc.protocols.netutil import free_udp_port
from vtolftc.protocols.px4 import (
    custom_mode,
    decode_param_value,
    encode_param_value,
    mode_from_name,
    mode_name,
)


# ------------------------------------------------------------------------------ conventions
def test_px4_custom_mode_layout_and_names():
    # PX4: main mode in bits 16-23, sub mode in bits 24-31
    assert custom_mode(4, 3) == (4 << 16) | (3 << 24) == 0x03040000
    assert mode_name(0x03040000) == "AUTO.LOITER"
    assert mode_name(3 << 16) == "POSCTL"
    assert mode_from_name("auto.land") == (4, 6)
    with pytest.raises(ValueError, match=r"AUTO\.LOITER"):
        mode_from_name("HOVER")


def test_int32_parameters_travel_bytewise():
    for v in (0, 1, -1, 7, 40_000, 2**31 - 1, -(2**31)):
        wire = encode_param_value(v, 6)
        # the float's four bytes are the int32's four bytes (not a conversion)
        assert struct.pack("<f", wire) == struct.pack("<i", v)
        assert decode_param_value(wire, 6) == v
    assert encode_param_value(1, 6) != 1.0  # 1 bytewise is a denormal, not 1.0
    assert decode_param_value(30.5, 9) == 30.5


def test_actuator_numbering_is_px4_order(ds1):
    table = ActuatorTable.from_names(ds1.actuator_names)
    assert list(table.motors[:8]) == [n for n in ds1.actuator_names if n.startswith("rotor_")]
    assert table.unit_instance("rotor_1a") == (FAILURE_UNIT_MOTOR, 1)
    assert table.unit_instance("rotor_2b") == (FAILURE_UNIT_MOTOR, 4)
    assert table.unit_instance("pusher_left") == (FAILURE_UNIT_MOTOR, 9)
    assert table.unit_instance("pusher_right") == (FAILURE_UNIT_MOTOR, 10)
    assert [table.unit_instance(n) for n in ("aileron_left", "aileron_right", "elevator",
                                             "rudder_left", "rudder_right")] == \
        [(FAILURE_UNIT_SERVO, i) for i in range(1, 6)]
    assert table.name_of(FAILURE_UNIT_SERVO, 3) == "elevator"
    assert table.expand("ailerons") == ["aileron_left", "aileron_right"]
    assert len(table.expand("lift_rotors")) == 8
    assert table == default_table()
    with pytest.raises(ValueError, match="did you mean rotor_2b"):
        table.expand("rotor_2c")


def test_command_and_result_names():
    assert command_name(3000) == "DO_VTOL_TRANSITION"
    assert command_name(59900) == "INJECT_PARTIAL_LOSS"
    assert command_name(12345) == "CMD_12345"
    assert result_name(2) == "DENIED" and result_name(None) == "TIMEOUT"


# ------------------------------------------------------------------------------ endpoint
class _EndpointThread:
    """The autopilot's ground-station endpoint served from a thread (no vehicle)."""

    def __init__(self, port: int, signing: SigningConfig | None = None) -> None:
        self.ap = Autopilot()
        self.hil_link = open_link("udp-server://127.0.0.1:0", system_id=1, component_id=1)
        self.hil = HilBridge(self.hil_link)
        gl = open_link(f"udp-client://127.0.0.1:{port}", system_id=1, component_id=1,
                       signing=signing)
        self.ep = GcsEndpoint(self.ap, self.hil, [gl], signing_required=signing is not None,
                              actuators=ActuatorTable.from_names(self.ap.airframe.actuator_names))
        self.running = True
        self.thread = threading.Thread(target=self._loop, daemon=True)
        self.thread.start()

    def _loop(self) -> None:
        while self.running:
            self.ep.poll()
            self.ep.tick()
            time.sleep(0.002)

    def close(self) -> None:
        self.running = False
        self.thread.join(2.0)
        self.ep.close()
        self.hil_link.close()


@pytest.fixture(scope="module")
def endpoint_and_gs():
    port = free_udp_port()
    gs = GroundStation(f"udp-server://127.0.0.1:{port}")
    ep = _EndpointThread(port)
    try:
        gs.wait_for(lambda s: s.connected, 10.0)
        yield ep, gs
    finally:
        gs.close()
        ep.close()


def test_heartbeat_and_snapshot(endpoint_and_gs):
    _, gs = endpoint_and_gs
    beats = []
    gs.add_listener(lambda m: beats.append(m) if m.get_type() == "HEARTBEAT"
                    and m.get_srcSystem() == 1 else None)
    s = gs.wait_for(lambda s: s.connected, 3.0)
    # on the ground PX4 reports Hold (AUTO.LOITER); AUTO.READY is UNKNOWN to pymavlink/MAVProxy
    assert not s.armed and s.mode_name == "AUTO.LOITER"
    deadline = time.monotonic() + 3.0
    while not beats and time.monotonic() < deadline:
        time.sleep(0.05)
    hb = beats[0]
    ext = []
    gs.add_listener(lambda m: ext.append(m) if m.get_type() in ("EXTENDED_SYS_STATE",
                                                                "SYS_STATUS") else None)
    deadline = time.monotonic() + 3.0
    while len({m.get_type() for m in ext}) < 2 and time.monotonic() < deadline:
        time.sleep(0.05)
    e = next(m for m in ext if m.get_type() == "EXTENDED_SYS_STATE")
    assert (e.vtol_state, e.landed_state) == (3, 1)  # defined before any vehicle data
    st = next(m for m in ext if m.get_type() == "SYS_STATUS")
    assert st.onboard_control_sensors_present & 32 and not st.onboard_control_sensors_health & 32
    assert (hb.get_srcSystem(), hb.get_srcComponent()) == (1, 1)
    assert hb.autopilot == 12 and hb.type == 22  # PX4, VTOL with separate lift/cruise rotors
    assert hb.base_mode & 1 and not hb.base_mode & 128  # custom mode on, disarmed


def test_commands_answered_quickly_with_true_results(endpoint_and_gs):
    _, gs = endpoint_and_gs
    out = gs.transition("fw")
    assert out.result_name == "DENIED" and "disarmed" in out.detail
    assert str(out) == f"DO_VTOL_TRANSITION: DENIED ({out.detail})"
    assert gs.arm().result_name == "DENIED"          # no navigation data: nothing to fly on
    assert gs.command_long(31010, []).result_name == "UNSUPPORTED"
    assert gs.command_long(511, [math.nan, math.nan]).result_name == "DENIED"  # no message id
    assert gs.command_long(512, [148.0]).accepted                  # AUTOPILOT_VERSION
    for out in (gs.transition("fw"), gs.command_long(31010, [])):
        assert out.elapsed_s < 0.5


def test_fault_injection_refused_unless_enabled(endpoint_and_gs):
    _, gs = endpoint_and_gs
    gs.param_set("SYS_FAILURE_EN", 0)
    out = gs.inject("rotor_2b", loss=0.5)
    assert out.result_name == "DENIED" and "SYS_FAILURE_EN" in out.detail
    gs.param_set("SYS_FAILURE_EN", 1)
    # enabled, but no vehicle on the HIL link to apply it
    assert gs.inject("rotor_2b", loss=0.5).result_name == "TEMPORARILY_REJECTED"
    # a bad instance or magnitude is refused before anything is forwarded
    assert gs.command_long(59900, [101.0, 11.0, 0.5]).result_name == "DENIED"
    assert gs.command_long(59900, [101.0, 1.0, math.nan]).result_name == "DENIED"
    assert gs.command_long(59900, [103.0, 1.0, 0.5]).result_name == "UNSUPPORTED"
    assert gs.command_long(420, [101.0, 100.0, 1.0]).result_name == "UNSUPPORTED"
    gs.param_set("SYS_FAILURE_EN", 0)
    with pytest.raises(GcsError, match="fraction"):
        gs.inject("rotor_2b", loss=50)


def test_parameters_round_trip(endpoint_and_gs):
    ep, gs = endpoint_and_gs
    raw = []
    gs.add_listener(lambda m: raw.append(m) if m.get_type() == "PARAM_VALUE" else None)
    assert gs.param_set("SYS_FAILURE_EN", 1) == 1.0
    assert ep.ap.params.get("SYS_FAILURE_EN") == 1.0
    echo = [m for m in raw if m.param_id == "SYS_FAILURE_EN"][-1]
    assert echo.param_type == 6 and struct.pack("<f", echo.param_value) == struct.pack("<i", 1)
    assert gs.param_get("SYS_FAILURE_EN") == 1.0
    gs.param_set("SYS_FAILURE_EN", 0)
    real = next(p for p in ep.ap.params if p.type == 9)
    new = real.default + 1.0 if real.maximum >= real.default + 1.0 else real.default
    assert gs.param_set(real.name, new) == pytest.approx(new, rel=1e-6)
    gs.param_set(real.name, real.default)
    allp = gs.params()
    assert len(allp) == len(ep.ap.params) and "SIM_HOLD_MS" in allp
    with pytest.raises(GcsError, match="kept"):
        gs.param_set("SYS_FAILURE_EN", 5)  # out of range: the echo keeps the old value
    with pytest.raises(GcsTimeout):
        gs.param_get("NO_SUCH_PARAM", timeout_s=0.2, retries=0)


def test_no_ack_is_a_timeout_not_a_hang():
    port = free_udp_port()
    silent = open_link(f"udp-client://127.0.0.1:{port}", system_id=1, component_id=1)
    gs = GroundStation(f"udp-server://127.0.0.1:{port}")
    try:
        silent.send(silent.codec.heartbeat_encode(22, 12, 0, 0, 3))  # gives the GS its peer
        gs.wait_for(lambda s: s.connected, 3.0)
        out = gs.command_long(400, [1.0], timeout_s=0.1, retries=1)
        assert out.result is None and out.result_name == "TIMEOUT" and not out.accepted
        assert len([m for m in silent.recv(0.5) if m.get_type() == "COMMAND_LONG"]) >= 1
    finally:
        gs.close()
        silent.close()
    with pytest.raises(GcsTimeout, match="no heartbeat"):
        GroundStation.connect(f"udp-server://127.0.0.1:{free_udp_port()}", timeout_s=0.3)


# ------------------------------------------------------------------------------ CLI input
@pytest.mark.parametrize("argv, fragment", [
    (["gcs", "--url", "tcp://1.2.3.4:5", "status"], "unknown scheme"),
    (["gcs", "inject", "--actuator", "rotor_2b", "--loss", "50"], "not a percentage"),
    (["gcs", "inject", "--actuator", "rotor_9z", "--loss", "0.5"], "unknown actuator"),
    (["gcs", "transition", "sideways"], "expected fw or mc"),
    (["gcs", "mode", "HOVERING"], "unknown PX4 mode"),
    (["gcs", "params", "set", "SYS_FAILURE_EN", "one"], "is not a number"),
    (["gcs", "takeoff", "-5"], "expected a height"),
])
def test_gcs_cli_rejects_bad_input(argv, fragment, capsys):
    assert cli_run(argv) == 2
    err = capsys.readouterr().err
    assert fragment in err and "Traceback" not in err and len(err.strip().splitlines()) == 1


def test_gcs_cli_reports_refusal_and_timeout(capsys):
    port = free_udp_port()
    ep = _EndpointThread(port)
    try:
        rc = cli_run(["gcs", "--url", f"udp-server://127.0.0.1:{port}", "transition", "fw"])
        err = capsys.readouterr().err
        assert rc == 1
        assert "DO_VTOL_TRANSITION: DENIED (vehicle is disarmed)" in err
        assert cli_run(["gcs", "--url", f"udp-server://127.0.0.1:{port}", "params", "get",
                        "SYS_FAILURE_EN"]) == 0
        assert "SYS_FAILURE_EN = 0" in capsys.readouterr().out
    finally:
        ep.close()
    assert cli_run(["gcs", "--url", f"udp-server://127.0.0.1:{free_udp_port()}", "--timeout",
                    "0.3", "status"]) == 1
    assert "no heartbeat" in capsys.readouterr().err


def test_signed_commands_required_for_arming_and_faults():
    port = free_udp_port()
    url = f"udp-server://127.0.0.1:{port}"
    ep = _EndpointThread(port, SigningConfig.from_passphrase("vtol-ftc test",
                                                            allow_unsigned=True))
    ep.ap.params.set("SYS_FAILURE_EN", 1)
    try:
        with GroundStation(url) as plain:
            plain.wait_for(lambda s: s.connected, 5.0)
            out = plain.inject("rotor_2b", loss=0.5)
            assert out.result_name == "DENIED" and "signed" in out.detail
            assert plain.arm().result_name == "DENIED"
            assert plain.command_long(31010, []).result_name == "UNSUPPORTED"  # others: fine
            assert plain.param_get("SYS_FAILURE_EN") == 1                    # telemetry: fine
        wrong = SigningConfig.from_passphrase("not the key", allow_unsigned=True)
        with GroundStation(url, signing=wrong) as bad:
            bad.wait_for(lambda s: s.connected, 5.0)
            assert bad.inject("rotor_2b", loss=0.5).result_name == "DENIED"
        with GroundStation(url, signing=SigningConfig.from_passphrase("vtol-ftc test")) as gs:
            gs.wait_for(lambda s: s.connected, 5.0)
            # the signature is accepted; what remains is that no vehicle is connected
            assert gs.inject("rotor_2b", loss=0.5).result_name == "TEMPORARILY_REJECTED"
            assert "signed" not in gs.arm().detail
    finally:
        ep.close()


def test_busy_port_says_which_port_to_use_instead():
    import socket

    port = free_udp_port()
    with socket.socket(socket.AF_INET, socket.SOCK_DGRAM) as taken:
        taken.bind(("127.0.0.1", port))
        with pytest.raises(GcsError, match=r"already listens there.*14540"):
            GroundStation(f"udp-server://127.0.0.1:{port}")


def test_long_statustext_arrives_whole(endpoint_and_gs):
    """Texts over STATUSTEXT's 50 bytes go out in MAVLink 2 chunks and are joined again."""
    ep, gs = endpoint_and_gs
    for text in ("mode TAKEOFF -> HOVER (takeoff altitude 20 m reached)",   # 54 bytes
                 "y" * 100,                                                # 2 full chunks
                 "short one"):
        ep.ep.statustext(text)
        s = gs.wait_for(lambda s, t=text: s.last_statustext == t, 3.0)
        assert s.last_statustext == text


def test_mission_download_ping_timesync_and_command_int(endpoint_and_gs):
    """The endpoint's PX4 services without a vehicle: a mission stored in the navigator comes
    back through the ground station; PING, TIMESYNC and COMMAND_INT are answered."""
    from vtolftc.firmware_sim.vehicle.sensors import Home
    from vtolftc.runners.mission_run import rectangle_mission

    ep, gs = endpoint_and_gs
    items = rectangle_mission()
    assert ep.ap.navigator.store.replace(0, items)[0] == 0
    got = gs.download_mission()
    assert [(m.seq, m.command, m.x, m.y, m.z) for m in got] == \
        [(it.seq, it.command, it.x, it.y, it.z) for it in items]
    answers = []
    gs.add_listener(lambda m: answers.append(m) if m.get_type() in ("PING", "TIMESYNC")
                    and m.get_srcSystem() == 1 else None)
    c = gs.link.codec
    gs.link.send(c.ping_encode(4242, 7, 0, 0))
    gs.link.send(c.timesync_encode(0, 99))
    deadline = time.monotonic() + 2.0
    while len(answers) < 2 and time.monotonic() < deadline:
        time.sleep(0.02)
    ping = next(m for m in answers if m.get_type() == "PING")
    assert (ping.time_usec, ping.seq, ping.target_system) == (4242, 7, gs.link.codec.srcSystem)
    ts = next(m for m in answers if m.get_type() == "TIMESYNC")
    assert ts.ts1 == 99 and ts.tc1 > 0
    # COMMAND_INT DO_REPOSITION on the ground: answered (DENIED: not flying), like the LONG form
    acks = []
    gs.add_listener(lambda m: acks.append(m) if m.get_type() == "COMMAND_ACK" else None)
    lat, lon = round(Home().lat_deg * 1e7), round(Home().lon_deg * 1e7)
    gs.link.send(c.command_int_encode(1, 1, 6, 192, 0, 0, -1, 1, 0, math.nan, lat, lon, 20.0))
    deadline = time.monotonic() + 2.0
    while not acks and time.monotonic() < deadline:
        time.sleep(0.02)
    assert acks and acks[0].command == 192 and acks[0].result == 2
    ep.ap.navigator.store.clear(0)

"""The vtol-ftc MAVLink dialect: generation, contents, pack/unpack, signing."""

from __future__ import annotations

import math
import os
import subprocess
import sys
from pathlib import Path

import pytest

from vtolftc.protocols import mavlink as pm
from vtolftc.protocols.mavlink import SigningConfig, dialect, make_codec

KEY = bytes(range(32))
WRONG_KEY = bytes(range(1, 33))


@pytest.fixture(scope="module")
def d():
    """The generated dialect module."""
    return dialect()


def _roundtrip(msg, sender=None, receiver=None):
    """Pack with one codec, parse with another; return the single decoded message."""
    sender = sender or make_codec(1, 1)
    receiver = receiver or make_codec(255, 190)
    data = msg.pack(sender)
    assert data[0] == 0xFD  # MAVLink 2 frame
    msgs = receiver.parse_buffer(data)
    assert msgs is not None and len(msgs) == 1
    return msgs[0]


# ------------------------------------------------------------------------------ generation
def test_dialect_is_the_committed_module_and_cached(d):
    assert dialect() is d
    assert d.WIRE_PROTOCOL_VERSION == "2.0"
    assert Path(d.__file__).resolve() == pm.GENERATED_MODULE
    assert d.__name__ == "vtolftc.protocols.generated.vtolftc"


def test_committed_dialect_is_current(tmp_path):
    """The committed module is byte for byte what mavgen makes from the XML today."""
    fresh = pm.generate_dialect(tmp_path / "vtolftc.py")
    assert fresh.read_bytes() == pm.GENERATED_MODULE.read_bytes(), (
        "protocols/generated/vtolftc.py is stale: run `python -m vtolftc.protocols.regenerate`")
    assert [p.name for p in tmp_path.iterdir()] == ["vtolftc.py"]  # no temporary leftovers


def test_committed_constants_are_current(tmp_path, d):
    fresh = pm.generate_constants(tmp_path / "constants.py", d)
    assert fresh.read_bytes() == pm.GENERATED_CONSTANTS.read_bytes(), (
        "protocols/generated/constants.py is stale: run `python -m vtolftc.protocols.regenerate`")
    from vtolftc.protocols.generated import constants as c

    assert (c.MAV_CMD_NAV_TAKEOFF, c.MAV_CMD_INJECT_PARTIAL_LOSS, c.MAV_RESULT_DENIED) == (
        d.MAV_CMD_NAV_TAKEOFF, 59900, d.MAV_RESULT_DENIED)
    assert c.MAVLINK_MSG_ID_FAULT_INJECTION_STATUS == 59900


def test_importing_the_dialect_writes_nothing(tmp_path):
    """A read-only install: importing and using the dialect creates no file anywhere."""
    code = ("from vtolftc.protocols.mavlink import make_codec; "
            "c = make_codec(1, 1); print(len(c.heartbeat_encode(1, 12, 0, 0, 0).pack(c)))")
    env = dict(os.environ, PYTHONDONTWRITEBYTECODE="1", HOME=str(tmp_path),
               XDG_CACHE_HOME=str(tmp_path / "cache"))
    before = {p.stat().st_mtime_ns for p in pm.GENERATED_MODULE.parent.iterdir()}
    r = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True,
                       env=env, cwd=tmp_path, timeout=120)
    assert r.returncode == 0, r.stderr
    assert list(tmp_path.iterdir()) == []
    assert {p.stat().st_mtime_ns for p in pm.GENERATED_MODULE.parent.iterdir()} == before


def test_dialect_contains_common_messages(d):
    for name in ("HEARTBEAT", "HIL_SENSOR", "HIL_ACTUATOR_CONTROLS", "COMMAND_LONG",
                 "COMMAND_ACK", "HIL_GPS", "HIL_STATE_QUATERNION", "PARAM_VALUE"):
        assert hasattr(d, f"MAVLINK_MSG_ID_{name}"), name
    assert d.MAVLINK_MSG_ID_HIL_SENSOR == 107
    assert d.MAVLINK_MSG_ID_HIL_ACTUATOR_CONTROLS == 93
    assert d.MAV_CMD_INJECT_FAILURE == 420
    assert d.FAILURE_UNIT_SYSTEM_MOTOR == 101 and d.FAILURE_UNIT_SYSTEM_SERVO == 102
    # common's failure types are untouched by the extension
    assert (d.FAILURE_TYPE_OK, d.FAILURE_TYPE_OFF, d.FAILURE_TYPE_STUCK) == (0, 1, 2)
    assert d.FAILURE_TYPE_INTERMITTENT == 7


def test_dialect_extension(d):
    assert d.FAILURE_TYPE_PARTIAL_LOSS == 100
    assert d.enums["FAILURE_TYPE"][100].name == "FAILURE_TYPE_PARTIAL_LOSS"
    assert d.MAV_CMD_INJECT_PARTIAL_LOSS == 59900
    entry = d.enums["MAV_CMD"][59900]
    assert entry.label[1] == "Failure unit"
    assert entry.label[2] == "Instance"
    assert entry.label[3] == "Loss"
    assert "SYS_FAILURE_EN" in entry.description
    assert d.MAVLINK_MSG_ID_FAULT_INJECTION_STATUS == 59900
    assert d.mavlink_map[59900].msgname == "FAULT_INJECTION_STATUS"


def test_extension_ids_do_not_collide_with_registered_dialects(d):
    from pymavlink.dialects.v20 import all as all_dialects
    from pymavlink.dialects.v20 import common

    assert 59900 not in common.mavlink_map
    assert 59900 not in all_dialects.mavlink_map
    assert 59900 not in all_dialects.enums["MAV_CMD"]
    assert 100 not in all_dialects.enums["FAILURE_TYPE"]
    # everything common defines is still there, with the same CRC extras
    for msgid, cls in common.mavlink_map.items():
        assert d.mavlink_map[msgid].crc_extra == cls.crc_extra


def test_changed_xml_changes_the_generated_module(tmp_path):
    xml = tmp_path / "vtolftc.xml"
    text = pm.DIALECT_XML.read_text()
    xml.write_text(text.replace("vtol-ftc: actuator faults", "vtol-ftc: the actuator faults"))
    out = pm.generate_dialect(tmp_path / "out" / "vtolftc.py", xml)
    assert out.is_file() and out.read_bytes() != pm.GENERATED_MODULE.read_bytes()


def test_bad_xml_gives_clear_error(tmp_path):
    xml = tmp_path / "broken.xml"
    xml.write_text(
        '<?xml version="1.0"?><mavlink><include>common.xml</include><messages>'
        '<message id="0" name="CLASHES_WITH_HEARTBEAT"><description>x</description>'
        '<field type="uint8_t" name="a">a</field></message></messages></mavlink>'
    )
    with pytest.raises(RuntimeError, match="mavgen failed"):
        pm.generate_dialect(tmp_path / "out" / "vtolftc.py", xml)


# ------------------------------------------------------------------------------ pack/unpack
def test_roundtrip_heartbeat(d):
    codec = make_codec(1, 1)
    msg = codec.heartbeat_encode(d.MAV_TYPE_VTOL_TILTROTOR, d.MAV_AUTOPILOT_PX4,
                                 d.MAV_MODE_FLAG_SAFETY_ARMED | d.MAV_MODE_FLAG_CUSTOM_MODE_ENABLED,
                                 (4 << 16) | (2 << 24), d.MAV_STATE_ACTIVE)
    got = _roundtrip(msg, sender=codec)
    assert got.get_type() == "HEARTBEAT"
    assert (got.get_srcSystem(), got.get_srcComponent()) == (1, 1)
    assert got.type == d.MAV_TYPE_VTOL_TILTROTOR and got.autopilot == d.MAV_AUTOPILOT_PX4
    assert got.custom_mode == (4 << 16) | (2 << 24)
    assert got.mavlink_version == 3


def test_roundtrip_hil_sensor_and_controls(d):
    codec = make_codec(1, 200)
    sensor = codec.hil_sensor_encode(123456789, 0.5, -0.25, -9.81, 0.01, -0.02, 0.03, 0.2, 0.0,
                                     0.4, 1013.25, 0.12, 1009.9, 21.5, 0x1FFF, 0)
    got = _roundtrip(sensor, sender=codec)
    assert got.time_usec == 123456789
    assert got.zacc == pytest.approx(-9.81, rel=1e-6)
    assert got.abs_pressure == pytest.approx(1013.25, rel=1e-6)
    assert got.fields_updated == 0x1FFF

    ap = make_codec(1, 1)
    controls = [i / 16.0 for i in range(16)]
    msg = ap.hil_actuator_controls_encode(123456789, controls, d.MAV_MODE_FLAG_SAFETY_ARMED, 1)
    got = _roundtrip(msg, sender=ap)
    assert got.controls == pytest.approx(controls)
    assert got.mode == d.MAV_MODE_FLAG_SAFETY_ARMED and got.flags == 1


def test_roundtrip_partial_loss_command_and_ack(d):
    gcs = make_codec(255, 190)
    cmd = gcs.command_long_encode(1, 1, d.MAV_CMD_INJECT_PARTIAL_LOSS, 0,
                                  d.FAILURE_UNIT_SYSTEM_MOTOR, 4, 0.5,
                                  math.nan, math.nan, math.nan, math.nan)
    got = _roundtrip(cmd, sender=gcs)
    assert got.get_type() == "COMMAND_LONG"
    assert got.command == 59900
    assert (got.param1, got.param2, got.param3) == (101, 4, 0.5)
    assert math.isnan(got.param4)

    ack = make_codec(1, 1).command_ack_encode(d.MAV_CMD_INJECT_PARTIAL_LOSS,
                                              d.MAV_RESULT_ACCEPTED)
    got = _roundtrip(ack)
    assert (got.command, got.result) == (59900, d.MAV_RESULT_ACCEPTED)


def test_roundtrip_fault_injection_status(d):
    codec = make_codec(1, 1)
    motor_failure = [0] * 16
    motor_loss = [0.0] * 16
    motor_failure[3], motor_loss[3] = d.FAILURE_TYPE_PARTIAL_LOSS, 0.5
    motor_failure[0], motor_loss[0] = d.FAILURE_TYPE_OFF, 1.0
    servo_failure = [0] * 16
    servo_loss = [0.0] * 16
    servo_failure[1], servo_loss[1] = d.FAILURE_TYPE_PARTIAL_LOSS, 0.2
    msg = codec.fault_injection_status_encode(22_000_000, 3, 10, 4, motor_failure, motor_loss,
                                              servo_failure, servo_loss)
    got = _roundtrip(msg, sender=codec)
    assert got.get_type() == "FAULT_INJECTION_STATUS"
    assert (got.time_usec, got.change_count, got.motor_count, got.servo_count) == (
        22_000_000, 3, 10, 4)
    assert list(got.motor_failure) == motor_failure
    assert got.motor_loss == pytest.approx(motor_loss)
    assert list(got.servo_failure) == servo_failure
    assert got.servo_loss == pytest.approx(servo_loss)


def test_robust_codec_returns_bad_data_not_exceptions(d):
    codec = make_codec()
    out = codec.parse_buffer(b"\x00\x01\x02 not mavlink")
    assert out and all(isinstance(m, d.MAVLink_bad_data) for m in out)


def test_codec_ids_validated():
    with pytest.raises(ValueError):
        make_codec(256, 1)


# ------------------------------------------------------------------------------ signing
def _signed_cmd(key: bytes, link_id: int = 1):
    d = dialect()
    gcs = make_codec(255, 190, signing=SigningConfig(key, link_id=link_id))
    cmd = gcs.command_long_encode(1, 1, d.MAV_CMD_COMPONENT_ARM_DISARM, 0, 1, 0, 0, 0, 0, 0, 0)
    return cmd.pack(gcs)


def test_signing_roundtrip_accepted_with_same_key(d):
    data = _signed_cmd(KEY, link_id=7)
    assert data[2] & d.MAVLINK_IFLAG_SIGNED
    assert len(data) == 10 + data[1] + 2 + 13
    ap = make_codec(1, 1, signing=SigningConfig(KEY))
    (msg,) = ap.parse_buffer(data)
    assert msg.get_type() == "COMMAND_LONG"
    assert msg.get_signed() is True
    assert msg.get_link_id() == 7
    assert ap.signing.goodsig_count == 1


def test_signing_wrong_key_rejected(d):
    ap = make_codec(1, 1, signing=SigningConfig(WRONG_KEY))
    (bad,) = ap.parse_buffer(_signed_cmd(KEY))
    assert isinstance(bad, d.MAVLink_bad_data)
    assert bad.reason == "Invalid signature"
    assert ap.signing.badsig_count == 1


def test_signing_wrong_key_flagged_when_unsigned_allowed(d):
    ap = make_codec(1, 1, signing=SigningConfig(WRONG_KEY, allow_unsigned=True))
    (msg,) = ap.parse_buffer(_signed_cmd(KEY))
    assert msg.get_type() == "COMMAND_LONG"
    assert msg.get_signed() is False  # accepted, but not as a verified signed message


def test_signing_unsigned_policy(d):
    plain = make_codec(255, 190).command_long_encode(1, 1, 400, 0, 1, 0, 0, 0, 0, 0, 0)
    data = plain.pack(make_codec(255, 190))
    strict = make_codec(1, 1, signing=SigningConfig(KEY))
    (bad,) = strict.parse_buffer(data)
    assert isinstance(bad, d.MAVLink_bad_data)
    only_heartbeat = make_codec(
        1, 1, signing=SigningConfig(KEY, allow_unsigned=lambda msgid: msgid == 0))
    (bad,) = only_heartbeat.parse_buffer(data)
    assert isinstance(bad, d.MAVLink_bad_data)
    hb = make_codec(255, 190).heartbeat_encode(6, 8, 0, 0, 0).pack(make_codec(255, 190))
    (ok,) = only_heartbeat.parse_buffer(hb)
    assert ok.get_type() == "HEARTBEAT" and ok.get_signed() is False


def test_signing_replay_rejected(d):
    data = _signed_cmd(KEY)
    ap = make_codec(1, 1, signing=SigningConfig(KEY))
    (first,) = ap.parse_buffer(data)
    assert first.get_signed()
    (replayed,) = ap.parse_buffer(data)
    assert isinstance(replayed, d.MAVLink_bad_data)


def test_signing_config_validation():
    with pytest.raises(ValueError, match="32 bytes"):
        SigningConfig(b"short")
    with pytest.raises(ValueError, match="link_id"):
        SigningConfig(KEY, link_id=300)
    cfg = SigningConfig.from_passphrase("vtolftc")
    assert len(cfg.secret_key) == 32
    assert pm.signing_timestamp_now() > 0

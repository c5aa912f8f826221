"""Links over UDP and zenoh through the same Link API (loopback only)."""

from __future__ import annotations

import socket
import time
from collections.abc import Iterator

import pytest

from vtolftc.protocols.link import Link, open_link, parse_link_url
from vtolftc.protocols.mavlink import SigningConfig, dialect, make_codec
from vtolftc.protocols.netutil import free_tcp_port, is_loopback_host, require_loopback

KEY = bytes(range(32))
TIMEOUT = 2.0


@pytest.fixture(scope="module")
def d():
    """The generated dialect module."""
    return dialect()


def _close_all(*links: Link) -> None:
    for link in links:
        link.close()


def _udp_pair(**kw) -> tuple[Link, Link]:
    """(vehicle-side client, autopilot-side server), handshake done."""
    server = open_link("udp-server://127.0.0.1:0", system_id=1, component_id=1,
                       **kw.get("server", {}))
    try:
        port = server.local_address[1]
        client = open_link(f"udp-client://127.0.0.1:{port}", system_id=1, component_id=200,
                           **kw.get("client", {}))
    except BaseException:
        server.close()
        raise
    # the server replies to the last peer heard from: say hello first
    client.send(client.codec.heartbeat_encode(6, 8, 0, 0, 0))
    assert server.wait_ready(TIMEOUT)
    server.recv(0)  # drop the hello (kept aside by wait_ready)
    return client, server


def _zenoh_pair(*, low: str = "", **kw) -> tuple[Link, Link]:
    """(publisher of 'up', publisher of 'down'), matched both ways; ``low``: a query suffix of
    both URLs (``&lowlatency=1``: zenoh's low-latency transport)."""
    last: Exception | None = None
    for _ in range(5):  # a free port can be taken between probing and listening: retry
        port = free_tcp_port()
        try:
            up = open_link(f"zenoh://ds1/hil/up?listen=tcp/127.0.0.1:{port}{low}",
                           system_id=1, component_id=200, **kw.get("client", {}))
        except OSError as exc:  # address in use
            last = exc
            continue
        try:
            down = open_link(f"zenoh://ds1/hil/down?connect=tcp/127.0.0.1:{port}{low}",
                             system_id=1, component_id=1, **kw.get("server", {}))
        except BaseException:
            up.close()
            raise
        if up.wait_ready(5.0) and down.wait_ready(5.0):
            return up, down
        _close_all(up, down)
        last = TimeoutError("zenoh peers did not match")
    raise RuntimeError(f"could not open a zenoh pair: {last}")


def _zenoh_lowlatency_pair(**kw) -> tuple[Link, Link]:
    """:func:`_zenoh_pair` on zenoh's low-latency unicast transport (both ends)."""
    up, down = _zenoh_pair(low="&lowlatency=1", **kw)
    assert up.transport.lowlatency and down.transport.lowlatency
    return up, down


PAIRS = {"udp": _udp_pair, "zenoh": _zenoh_pair, "zenoh-lowlatency": _zenoh_lowlatency_pair}


@pytest.fixture(params=sorted(PAIRS))
def pair(request) -> Iterator[tuple[Link, Link]]:
    """Two connected links of each transport; always closed."""
    a, b = PAIRS[request.param]()
    try:
        yield a, b
    finally:
        _close_all(a, b)


def _delta(link: Link, before: dict[str, int]) -> dict[str, int]:
    """Counter changes since ``before`` (a ``stats.as_dict()`` snapshot)."""
    return {k: v - before[k] for k, v in link.stats.as_dict().items()}


def _recv_n(link: Link, n: int, timeout: float = TIMEOUT) -> list:
    out: list = []
    deadline = time.monotonic() + timeout
    while len(out) < n and time.monotonic() < deadline:
        out.extend(link.recv(deadline - time.monotonic()))
    return out


# ------------------------------------------------------------------------------ roundtrips
def test_roundtrip_both_directions(pair, d):
    a, b = pair
    ca, cb = a.codec, b.codec
    a.send(ca.hil_sensor_encode(4000, 0.1, 0.2, -9.8, 0.0, 0.0, 0.1, 0.2, 0.0, 0.4, 1013.0,
                                0.0, 1010.0, 20.0, 0x1FFF, 0))
    a.send(ca.heartbeat_encode(d.MAV_TYPE_GENERIC, d.MAV_AUTOPILOT_INVALID, 0, 0, 0))
    a.send(ca.command_long_encode(1, 1, d.MAV_CMD_INJECT_PARTIAL_LOSS, 0, 101, 2, 0.5,
                                  0, 0, 0, 0))
    got = _recv_n(b, 3)
    assert [m.get_type() for m in got] == ["HIL_SENSOR", "HEARTBEAT", "COMMAND_LONG"]
    assert got[0].time_usec == 4000 and got[0].zacc == pytest.approx(-9.8)
    assert got[2].command == 59900 and got[2].param3 == pytest.approx(0.5)
    assert all(m.get_srcComponent() == 200 for m in got)

    b.send(cb.hil_actuator_controls_encode(4000, [0.25] * 16, 128, 1))
    b.send(cb.command_ack_encode(d.MAV_CMD_INJECT_PARTIAL_LOSS, d.MAV_RESULT_ACCEPTED))
    b.send(cb.fault_injection_status_encode(4000, 1, 10, 4, [0, 100] + [0] * 14,
                                            [0.0, 0.5] + [0.0] * 14, [0] * 16, [0.0] * 16))
    got = _recv_n(a, 3)
    assert [m.get_type() for m in got] == [
        "HIL_ACTUATOR_CONTROLS", "COMMAND_ACK", "FAULT_INJECTION_STATUS"]
    assert got[0].controls == pytest.approx([0.25] * 16) and got[0].flags == 1
    assert got[1].result == d.MAV_RESULT_ACCEPTED
    assert got[2].motor_loss[1] == pytest.approx(0.5)
    assert all((m.get_srcSystem(), m.get_srcComponent()) == (1, 1) for m in got)

    sa, sb = a.stats, b.stats
    assert sa.dropped == 0 and sb.dropped == 0
    assert sa.bytes_sent > 0 and sb.bytes_received > 0


def test_burst_in_order_with_sequence_numbers(pair):
    a, b = pair
    seq0 = a.codec.seq
    for i in range(50):
        a.send(a.codec.hil_actuator_controls_encode(i, [0.0] * 16, 0, 1))
    got = _recv_n(b, 50)
    assert [m.time_usec for m in got] == list(range(50))
    assert [m.get_seq() for m in got] == [(seq0 + i) & 0xFF for i in range(50)]
    assert b.stats.dropped == 0


def test_raw_bytes_forwarded_unchanged(pair):
    a, b = pair
    other = make_codec(42, 99)
    frame = other.heartbeat_encode(2, 3, 0, 0, 4).pack(other)
    assert a.send(frame) == len(frame)
    (msg,) = _recv_n(b, 1)
    assert (msg.get_srcSystem(), msg.get_srcComponent()) == (42, 99)
    assert bytes(msg.get_msgbuf()) == frame


def test_recv_match_keeps_later_messages(pair):
    a, b = pair
    for i in range(3):
        a.send(a.codec.hil_actuator_controls_encode(i, [0.0] * 16, 0, 0))
    a.send(a.codec.command_ack_encode(400, 0))
    a.send(a.codec.hil_actuator_controls_encode(99, [0.0] * 16, 0, 0))
    ack = b.recv_match("COMMAND_ACK", timeout_s=TIMEOUT)
    assert ack is not None and ack.command == 400
    rest = _recv_n(b, 1)
    assert [m.time_usec for m in rest] == [99]
    assert b.recv_match(["COMMAND_ACK"], timeout_s=0.05) is None


def test_recv_timeout_and_poll(pair):
    _a, b = pair
    t0 = time.monotonic()
    assert b.recv(0.1) == []
    assert 0.08 <= time.monotonic() - t0 < 1.0
    assert b.recv(0) == []


# ------------------------------------------------------------------------------ bad data
def _corrupt_crc(frame: bytes) -> bytes:
    bad = bytearray(frame)
    bad[-1] ^= 0xFF
    return bytes(bad)


def test_garbage_truncated_and_corrupt_frames_dropped_and_counted(pair):
    a, b = pair
    good = a.codec.hil_sensor_encode(8000, 0, 0, -9.8, 0, 0, 0, 0, 0, 0, 1013, 0, 1010, 20,
                                     0x1FFF, 0).pack(a.codec)
    before = b.stats.as_dict()
    a.send(b"\x00\x01 this is not mavlink \x7f" * 3)  # garbage (no start-of-frame byte)
    a.send(good[: len(good) // 2])  # truncated frame
    a.send(_corrupt_crc(good))  # CRC failure
    a.send(good)  # the next valid frame still arrives
    got = _recv_n(b, 1)
    assert [m.get_type() for m in got] == ["HIL_SENSOR"]
    assert got[0].time_usec == 8000
    assert b.recv(0.1) == []
    st = _delta(b, before)
    assert st["dropped_garbage"] == 1
    assert st["dropped_truncated"] == 1
    assert st["dropped_crc"] == 1
    assert st["frames_received"] == 1
    assert st["datagrams_received"] == 4
    assert st["dropped"] == 3


def test_valid_frame_after_bad_data_in_same_datagram(pair):
    a, b = pair
    c = a.codec
    f1 = c.command_ack_encode(1, 0).pack(c)
    f2 = c.command_ack_encode(2, 0).pack(c)
    f3 = c.command_ack_encode(3, 0).pack(c)
    before = b.stats.as_dict()
    # garbage (with a false start-of-frame byte) + frame; corrupt frame + frame; frame + cut frame
    a.send(b"junk\xfd\x03" + f1)
    a.send(_corrupt_crc(f2) + f2)
    a.send(f3 + f1[:5])
    got = _recv_n(b, 3)
    assert [m.command for m in got] == [1, 2, 3]
    st = _delta(b, before)
    # "junk" is garbage; "\xfd\x03..." is a false start of frame that never completes
    assert (st["dropped_garbage"], st["dropped_truncated"], st["dropped_crc"]) == (1, 2, 1)
    assert st["frames_received"] == 3


def test_unknown_message_id_dropped(pair):
    a, b = pair
    c = a.codec
    frame = bytearray(c.command_ack_encode(1, 0).pack(c))
    frame[7:10] = (0xABCDE).to_bytes(3, "little")  # an id no dialect defines
    a.send(bytes(frame))
    a.send(c.command_ack_encode(2, 0))
    got = _recv_n(b, 1)
    assert [m.command for m in got] == [2]
    assert b.stats.dropped_unknown == 1


def test_garbage_from_foreign_udp_sender_then_reply_goes_to_last_peer():
    server = open_link("udp-server://127.0.0.1:0", system_id=1, component_id=1)
    intruder = socket.socket(socket.AF_INET, socket.SOCK_DGRAM)
    client = None
    try:
        intruder.bind(("127.0.0.1", 0))
        intruder.settimeout(TIMEOUT)
        port = server.local_address[1]
        # before any peer, sends go nowhere and are counted
        assert server.send(server.codec.heartbeat_encode(1, 12, 0, 0, 0)) == 0
        assert server.stats.send_dropped == 1
        intruder.sendto(b"\xfd\xff\x00garbage-and-truncated", ("127.0.0.1", port))
        intruder.sendto(b"pure garbage", ("127.0.0.1", port))
        client = open_link(f"udp-client://127.0.0.1:{port}")
        client.send(client.codec.heartbeat_encode(6, 8, 0, 0, 0))
        assert [m.get_type() for m in _recv_n(server, 1)] == ["HEARTBEAT"]
        assert server.stats.dropped_truncated == 1 and server.stats.dropped_garbage == 1
        # PX4 GCS-port behaviour: replies go to the last peer heard from
        server.send(server.codec.command_ack_encode(400, 0))
        assert [m.get_type() for m in _recv_n(client, 1)] == ["COMMAND_ACK"]
        intruder.sendto(b"hello", ("127.0.0.1", port))
        assert server.recv(0.2) == []
        server.send(server.codec.command_ack_encode(401, 0))
        data, _ = intruder.recvfrom(1024)
        assert data[0] == 0xFD
        assert client.recv(0.1) == []
    finally:
        intruder.close()
        server.close()
        if client is not None:
            client.close()


# ------------------------------------------------------------------------------ signing
@pytest.mark.parametrize("kind", sorted(PAIRS))
def test_signed_link(kind, d):
    a, b = PAIRS[kind](
        client={"signing": SigningConfig(KEY, link_id=3)},
        server={"signing": SigningConfig(KEY, allow_unsigned=True)},
    )
    try:
        a.send(a.codec.command_long_encode(1, 1, d.MAV_CMD_COMPONENT_ARM_DISARM, 0, 1,
                                           0, 0, 0, 0, 0, 0))
        (cmd,) = _recv_n(b, 1)
        assert cmd.get_signed() is True and cmd.get_link_id() == 3
        # a frame signed with another key is not accepted as signed
        intruder = make_codec(255, 190, signing=SigningConfig(bytes(32), link_id=9))
        a.send(intruder.command_long_encode(1, 1, 400, 0, 1, 0, 0, 0, 0, 0, 0).pack(intruder))
        (forged,) = _recv_n(b, 1)
        assert forged.get_signed() is False
    finally:
        _close_all(a, b)


def test_wrong_key_dropped_and_counted():
    a, b = _udp_pair(client={"signing": SigningConfig(KEY)},
                     server={"signing": SigningConfig(bytes(32), allow_unsigned=False)})
    try:
        before = b.stats.as_dict()  # (the handshake heartbeat was already rejected)
        a.send(a.codec.command_ack_encode(1, 0))
        assert b.recv(0.3) == []
        assert _delta(b, before)["dropped_signature"] == 1
    finally:
        _close_all(a, b)


# ------------------------------------------------------------------------------ URLs, policy
@pytest.mark.parametrize(
    ("url", "match"),
    [
        ("", "expected one of"),
        ("127.0.0.1:14550", "expected one of"),
        ("tcp://127.0.0.1:4560", "unknown scheme"),
        ("udp-server://127.0.0.1", "missing port"),
        ("udp-server://:14550", "missing host"),
        ("udp-server://127.0.0.1:99999", "port must be"),
        ("udp-server://127.0.0.1:abc", "port must be"),
        ("udp-client://127.0.0.1:0", "not 0"),
        ("udp-client://127.0.0.1:14550/path", "no path"),
        ("udp-client://127.0.0.1:14550?x=1", "no path or query"),
        ("zenoh://ds1/hil?listen=tcp/127.0.0.1:7447", "VEHICLE/LINK/DIRECTION"),
        ("zenoh://ds1/hil/up/extra?listen=tcp/127.0.0.1:7447", "VEHICLE/LINK/DIRECTION"),
        ("zenoh://ds1/hil/sideways?listen=tcp/127.0.0.1:7447", "'up' or 'down'"),
        ("zenoh://ds*/hil/up?listen=tcp/127.0.0.1:7447", "must match"),
        ("zenoh://ds1/hil/up", "needs listen"),
        ("zenoh://ds1/hil/up?listen=127.0.0.1:7447", "bad zenoh endpoint"),
        ("zenoh://ds1/hil/up?listen=tcp/127.0.0.1:7447&bogus=1", "unknown parameter"),
        ("zenoh://ds1/hil/up?connect=tcp/127.0.0.1:7447&mode=router", "mode must be"),
        ("zenoh://ds1/hil/up?listen=tcp/127.0.0.1:7447&lowlatency=true", "lowlatency must be"),
        ("zenoh://ds1/hil/up?listen=tcp/127.0.0.1:7447&lowlatency=1&lowlatency=0",
         "lowlatency must be"),
    ],
)
def test_bad_url_clear_error(url, match):
    with pytest.raises(ValueError, match=match):
        open_link(url)


def test_url_parsing():
    spec = parse_link_url(
        "zenoh://ds1/hil/up?listen=tcp/127.0.0.1:7447,tcp/[::1]:7448&connect=tcp/localhost:7449"
    )
    assert (spec.vehicle, spec.link, spec.direction) == ("ds1", "hil", "up")
    assert spec.listen == ("tcp/127.0.0.1:7447", "tcp/[::1]:7448")
    assert spec.connect == ("tcp/localhost:7449",)
    assert not spec.lowlatency
    for flag, want in (("0", False), ("1", True)):
        spec = parse_link_url(f"zenoh://ds1/hil/up?listen=tcp/127.0.0.1:7447&lowlatency={flag}")
        assert spec.lowlatency is want
    spec = parse_link_url("udp-server://[::1]:14550")
    assert (spec.scheme, spec.host, spec.port) == ("udp-server", "::1", 14550)


@pytest.mark.parametrize(
    "url",
    [
        "udp-server://0.0.0.0:14550",
        "udp-server://192.168.1.10:14550",
        "udp-client://10.0.0.2:14550",
        "udp-client://example.com:14550",
        "zenoh://ds1/hil/up?listen=tcp/0.0.0.0:7447",
        "zenoh://ds1/hil/down?connect=tcp/192.168.1.2:7447",
        "zenoh://ds1/hil/down?listen=tcp/127.0.0.1:7447&connect=tcp/[::]:7447",
    ],
)
def test_non_loopback_refused(url):
    with pytest.raises(ValueError, match="loopback"):
        open_link(url)


def test_loopback_policy_helpers():
    assert is_loopback_host("127.0.0.1") and is_loopback_host("127.5.6.7")
    assert is_loopback_host("::1") and is_loopback_host("[::1]") and is_loopback_host("localhost")
    assert not is_loopback_host("0.0.0.0") and not is_loopback_host("example.com")
    require_loopback("10.0.0.1", allow_remote=True, what="x")  # explicit opt-in passes
    with pytest.raises(ValueError):
        require_loopback("10.0.0.1", allow_remote=False, what="x")


# ------------------------------------------------------------------------------ lifetime
def test_close_is_idempotent_and_context_manager():
    with open_link("udp-server://127.0.0.1:0") as link:
        assert not link.closed
        assert link.local_address[0] == "127.0.0.1"
    assert link.closed
    link.close()
    assert link.send(b"\xfd") == 0
    assert link.recv(0.01) == []


def test_zenoh_connect_before_listen_and_fast_close():
    port = free_tcp_port()
    down = open_link(f"zenoh://ds2/gcs/down?connect=tcp/127.0.0.1:{port}")
    up = None
    try:
        assert not down.wait_ready(0.05)
        up = open_link(f"zenoh://ds2/gcs/up?listen=tcp/127.0.0.1:{port}")
        assert down.wait_ready(5.0) and up.wait_ready(5.0)
        down.send(down.codec.command_ack_encode(7, 0))
        assert [m.command for m in _recv_n(up, 1)] == [7]
    finally:
        t0 = time.monotonic()
        down.close()
        if up is not None:
            up.close()
        assert time.monotonic() - t0 < 1.0
    assert "vtolftc/ds2/gcs/down" in repr(down)


def test_port_in_use_is_oserror():
    with open_link("udp-server://127.0.0.1:0") as first:
        port = first.local_address[1]
        with pytest.raises(OSError):
            open_link(f"udp-server://127.0.0.1:{port}")
    port = free_tcp_port()
    with (
        open_link(f"zenoh://ds3/hil/up?listen=tcp/127.0.0.1:{port}"),
        pytest.raises(OSError, match="zenoh"),
    ):
        open_link(f"zenoh://ds3/hil/down?listen=tcp/127.0.0.1:{port}")

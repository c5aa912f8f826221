"""The fast datagram parser gives the generated parser's messages, and declines bad data."""

from __future__ import annotations

import random
from typing import Any

import pytest

from vtolftc.protocols.fastparse import FastParser
from vtolftc.protocols.link import Link
from vtolftc.protocols.mavlink import SigningConfig, StreamTimestamps, dialect, make_codec
from vtolftc.protocols.transport import LoopTransport

KEY = bytes(range(32))
_INT_RANGES = {"int8_t": (-128, 127), "uint8_t": (0, 255), "int16_t": (-32768, 32767),
               "uint16_t": (0, 65535), "int32_t": (-2**31, 2**31 - 1),
               "uint32_t": (0, 2**32 - 1), "int64_t": (-2**63, 2**63 - 1),
               "uint64_t": (0, 2**64 - 1)}


def _value(rng: random.Random, ftype: str, n: int) -> Any:
    if ftype == "char":
        return bytes(rng.choice(b"abcxyz") for _ in range(rng.randint(0, max(1, n))))
    lo, hi = _INT_RANGES.get(ftype.replace("_mavlink_version", ""), (0, 0))

    def one() -> float | int:
        if ftype in ("float", "double"):
            return rng.uniform(-1e3, 1e3)
        return rng.randint(lo, hi)

    if n:
        return [one() if rng.random() < 0.7 else 0 for _ in range(n)]
    return one() if rng.random() < 0.8 else 0  # zeros: payloads cut short on the wire


def _random_message(cls: Any, rng: random.Random) -> Any:
    args = []
    for name, ftype in zip(cls.fieldnames, cls.fieldtypes, strict=True):
        n = cls.array_lengths[cls.ordered_fieldnames.index(name)]
        args.append(_value(rng, ftype, n))
    return cls(*args)


def _state(m: Any) -> dict[str, Any]:
    out = {k: v for k, v in vars(m).items() if k != "_header"}
    out["_header"] = vars(m._header)
    out["_type"] = type(m)
    return out


def _slow_parse(codec: Any, data: bytes) -> list[Any]:
    codec.buf = bytearray(data)
    codec.buf_index = 0
    codec.expected_length = 8
    out = []
    while True:
        m = codec.parse_char(b"")
        if m is None:
            break
        out.append(m)
        if codec.buf_len() == 0:
            break
    return out


@pytest.mark.parametrize("signed", [False, True])
def test_every_message_of_the_dialect_parses_as_the_generated_parser(signed: bool) -> None:
    """Every message class, random fields (zeros trimmed on the wire), several per datagram:
    the fast parser's objects equal the generated parser's attribute by attribute, and the
    codecs' signing state and counters end up the same."""
    d = dialect()
    rng = random.Random(7)
    classes = sorted(set(d.mavlink_map.values()), key=lambda c: c.id)
    sig = SigningConfig(KEY, link_id=3, timestamp=1000) if signed else None
    tx = make_codec(5, 7, signing=sig)
    rx_sig = SigningConfig(KEY, timestamp=500) if signed else None
    fast_codec = make_codec(1, 1, signing=rx_sig)
    slow_codec = make_codec(1, 1, signing=rx_sig)
    fast = FastParser(fast_codec, d)
    n = 0
    for i in range(0, len(classes), 3):
        data = b""
        for cls in classes[i:i + 3]:
            data += _random_message(cls, rng).pack(tx)
            tx.seq = (tx.seq + 1) & 0xFF
        got = fast.parse(data)
        want = _slow_parse(slow_codec, data)
        assert got is not None
        assert [_state(m) for m in got] == [_state(m) for m in want]
        n += len(got)
    assert n == len(classes)
    for attr in ("timestamp", "sig_count", "goodsig_count", "badsig_count"):
        assert getattr(fast_codec.signing, attr) == getattr(slow_codec.signing, attr)
    assert fast_codec.total_packets_received == slow_codec.total_packets_received


def _frames(signing: SigningConfig | None = None) -> tuple[bytes, bytes]:
    c = make_codec(1, 200, signing=signing)
    a = c.hil_sensor_encode(1000, 0.1, 0.2, -9.8, 0.0, 0.0, 0.0, 0.2, 0.0, 0.4, 1013.0, 0.1,
                            30.0, 15.0, 0x1FFF, 0).pack(c)
    c.seq += 1
    b = c.heartbeat_encode(6, 8, 0, 0, 0).pack(c)
    return a, b


@pytest.mark.parametrize("bad", ["garbage", "truncated", "crc", "unknown", "v1", "flags"])
def test_declines_bad_data_without_side_effects(bad: str) -> None:
    """A datagram with any bad frame is left to the generated parser (None, nothing
    changed), even when a good frame comes first."""
    a, b = _frames()
    if bad == "garbage":
        tail = b"\x01\x02\x03" + b
    elif bad == "truncated":
        tail = b[:-3]
    elif bad == "crc":
        tail = b[:-1] + bytes([b[-1] ^ 0xFF])
    elif bad == "unknown":
        tail = b[:7] + b"\x99\x99\x00" + b[10:]
    elif bad == "v1":
        tail = b"\xfe" + b[1:]
    else:
        tail = b[:2] + b"\x04" + b[3:]
    codec = make_codec(1, 1)
    fast = FastParser(codec, dialect())
    assert fast.parse(a + tail) is None
    assert codec.total_packets_received == 0
    assert [m.get_type() for m in fast.parse(a + b)] == ["HIL_SENSOR", "HEARTBEAT"]
    assert [m.get_type() for m in fast.parse(memoryview(bytearray(b)))] == ["HEARTBEAT"]


def test_signing_unsigned_bad_hash_and_replay() -> None:
    """On a signing codec: an unsigned frame or a bad hash is declined (the generated parser
    decides); a replayed frame is dropped and counted, as the generated parser does."""
    a, _ = _frames(SigningConfig(KEY, timestamp=10_000))
    unsigned, _ = _frames()
    codec = make_codec(1, 1, signing=SigningConfig(KEY, timestamp=10_000),
                       stream_table=StreamTimestamps())
    fast = FastParser(codec, dialect())
    assert fast.parse(unsigned) is None
    assert fast.parse(a[:-1] + bytes([a[-1] ^ 1])) is None
    assert codec.signing.goodsig_count == 0
    assert [m.get_type() for m in fast.parse(a)] == ["HIL_SENSOR"]
    assert fast.parse(a)[0:] == [] and fast.rejected == 1  # the same timestamp again


def test_link_counts_replays_as_signature_drops() -> None:
    """Through a Link: the replayed datagram is counted in ``dropped_signature``."""
    a, _ = _frames(SigningConfig(KEY, timestamp=10_000))
    link = Link(LoopTransport(), system_id=1, component_id=1,
                signing=SigningConfig(KEY, timestamp=10_000))
    link.send(a)
    assert [m.get_type() for m in link.recv(0)] == ["HIL_SENSOR"]
    link.send(a)
    assert link.recv(0) == []
    assert link.stats.dropped_signature == 1 and link.stats.frames_received == 1


class _Generated:
    """Stands in for :class:`FastParser`: declines everything (the generated path only)."""

    rejected = 0

    @staticmethod
    def parse(data: bytes) -> None:
        return None


def _hil_datagram(signing: SigningConfig | None, t: int) -> bytes:
    """A vehicle's step datagram: HIL_SENSOR + HIL_STATE_QUATERNION (+ HEARTBEAT)."""
    c = make_codec(1, 200, signing=signing)
    c.seq = t & 0xFF
    out = c.hil_sensor_encode(t, 0.1, 0.2, -9.8, 0.01, -0.02, 0.0, 0.2, 0.0, 0.4, 1013.0, 0.1,
                              30.0, 15.0, 0x1FFF, 0).pack(c)
    c.seq += 1
    out += c.hil_state_quaternion_encode(t, [0.9, 0.1, -0.2, 0.3], 0.1, 0.2, 0.3, 473977000,
                                         85400000, 500000, 100, -200, 5, 1200, 1200, 0, 0,
                                         0).pack(c)
    if t % 3 == 0:
        c.seq += 1
        out += c.heartbeat_encode(6, 8, 0, 0, 0).pack(c)
    return out


@pytest.mark.parametrize("signed", [False, True])
def test_corrupted_hil_datagrams_fall_back_exactly_as_the_generated_path(signed: bool) -> None:
    """Random corruptions of real HIL step datagrams (a flipped byte anywhere: CRC, length,
    id, flags, payload, signature; cut short; bytes appended): a link with the compiled scan
    hands over the same messages and counts the same drops as one that parses everything
    with the generated parser."""
    rng = random.Random(11)
    rx = [Link(LoopTransport(), system_id=1, component_id=1,
               signing=SigningConfig(KEY, timestamp=10) if signed else None)
          for _ in range(2)]
    rx[1]._fast = _Generated()  # type: ignore[assignment]
    for i in range(600):
        data = bytearray(_hil_datagram(SigningConfig(KEY, timestamp=1000 + 10 * i)
                                       if signed else None, 4000 * (i + 1)))
        kind = i % 4
        if kind == 0:
            data[rng.randrange(len(data))] ^= 1 << rng.randrange(8)
        elif kind == 1:
            del data[rng.randrange(1, len(data)):]
        elif kind == 2:
            data += bytes(rng.randrange(256) for _ in range(rng.randint(1, 20)))
        # kind 3: unchanged
        got = []
        for link in rx:
            link.transport.send_bytes(bytes(data))
            got.append([_state(m) for m in link.recv(0)])
        assert got[0] == got[1], i
    assert rx[0].stats.as_dict() == rx[1].stats.as_dict()
    assert rx[0].stats.frames_received > 600 and rx[0].stats.dropped > 300


def test_wrong_length_byte_declined() -> None:
    """A frame whose length byte is one more or less than sent is declined (CRC or framing
    differs), the good frame before it not handed over."""
    a, b = _frames()
    codec = make_codec(1, 1)
    fast = FastParser(codec, dialect())
    for delta in (-1, 1):
        bad = b[:1] + bytes([b[1] + delta]) + b[2:]
        assert fast.parse(a + bad) is None
        assert fast.parse(a + bad + bytes(3)) is None
    assert codec.total_packets_received == 0


def _recrc(frame: bytes, extra: int) -> bytes:
    """``frame`` (unsigned) with its CRC made anew over its bytes and ``extra``."""
    body = frame[:-2]
    crc = dialect().x25crc(body[1:])
    crc.accumulate(bytes((extra,)))
    return body + int(crc.crc).to_bytes(2, "little")


@pytest.mark.parametrize("bad", ["flags", "unknown"])
def test_declines_bad_frames_whose_crc_is_good(bad: str) -> None:
    """Bad incompat flags or an unknown id behind a *good* CRC (made for 0xFF, what a
    missing CRC_EXTRA would read as) are still declined; the link then counts them as the
    generated parser does."""
    a, b = _frames()
    extra = dialect().MAVLink_heartbeat_message.crc_extra
    if bad == "flags":
        tail = _recrc(b[:2] + b"\x04" + b[3:], extra)
    else:
        tail = _recrc(b[:7] + b"\x99\x99\x00" + b[10:], 0xFF)
    codec = make_codec(1, 1)
    assert FastParser(codec, dialect()).parse(a + tail) is None
    links = [Link(LoopTransport(), system_id=1, component_id=1) for _ in range(2)]
    links[1]._fast = _Generated()  # type: ignore[assignment]
    for link in links:
        link.transport.send_bytes(a + tail)
        assert [m.get_type() for m in link.recv(0)] == ["HIL_SENSOR"]
    assert links[0].stats.as_dict() == links[1].stats.as_dict()


class _Counting(LoopTransport):
    """:class:`LoopTransport` that counts its reads."""

    def __init__(self) -> None:
        super().__init__()
        self.reads = 0

    def recv_datagrams(self, timeout_s: float | None) -> list[bytes]:
        self.reads += 1
        return super().recv_datagrams(timeout_s)


def test_hil_drain_reads_once_a_step_and_everything_past_a_full_batch() -> None:
    """``HilBridge.drain``: one transport read for a step's datagram (the link says it is
    drained), a second read after pending messages or a full batch, and every message
    handled either way."""
    from vtolftc.firmware_sim.autopilot.hil_bridge import HilBridge
    from vtolftc.protocols.transport import MAX_BATCH

    tr = _Counting()
    link = Link(tr, system_id=1, component_id=1)
    bridge = HilBridge(link)
    a, b = _frames()
    tr.queue.append(a + b)
    assert bridge.drain(0.0) == 2 and tr.reads == 1 and link.drained
    tr.queue.extend([b] * (MAX_BATCH + 44))
    assert bridge.drain(0.0) == MAX_BATCH + 44
    assert tr.reads == 3  # the full batch, then the rest
    tr.queue.extend([a, b])
    assert link.recv_match("HIL_SENSOR", 0.0) is not None  # the HEARTBEAT stays pending
    tr.queue.append(b)
    assert bridge.drain(0.0) == 2 and not tr.queue  # the pending one, then the transport
    assert link.recv(0.0) == [] and link.drained


@pytest.mark.parametrize("signed", [False, True])
def test_a_flights_hil_datagrams_parse_as_the_generated_path(signed: bool) -> None:
    """A simulated vehicle's state datagrams of a short flight (HIL_SENSOR, HIL_STATE_QUATERNION,
    HIL_GPS, GPS_GLOBAL_ORIGIN, BATTERY_STATUS, status) and the autopilot's answers
    (HIL_ACTUATOR_CONTROLS from ``HilBridge.send_controls``), every fifth datagram with a
    flipped byte: the fast path hands over what the generated parser does, counters too."""
    import numpy as np

    from vtolftc.airframe.loader import load_airframe
    from vtolftc.firmware_sim.autopilot.hil_bridge import HilBridge
    from vtolftc.firmware_sim.vehicle.battery import BatteryModel
    from vtolftc.firmware_sim.vehicle.model import Vehicle
    from vtolftc.firmware_sim.vehicle.state_encoder import StateEncoder

    rng = random.Random(5)
    af = load_airframe()
    vehicle = Vehicle(af)
    sig = (lambda t: SigningConfig(KEY, timestamp=t)) if signed else (lambda t: None)
    codec = make_codec(1, 191, signing=sig(1000))
    enc = StateEncoder(vehicle, BatteryModel(rho=af.air_density_kg_m3), codec, 10.0,
                       lambda: codec.heartbeat_encode(0, 0, 0, 0, 0))
    tx = LoopTransport()
    bridge = HilBridge(Link(tx, system_id=1, component_id=1, signing=sig(1000)))
    rx = [Link(LoopTransport(), system_id=1, component_id=1, signing=sig(10)) for _ in range(4)]
    for link in rx[1::2]:
        link._fast = _Generated()  # type: ignore[assignment]
    u = np.linspace(0.2, 0.6, af.n_actuators)
    for k in range(300):
        vehicle.step(u, 4)
        bridge.send_controls(vehicle.time_usec, u * (1 + 0.001 * k), armed=k % 2 == 0)
        for pair, data in ((rx[0:2], bytearray(enc.datagram())),
                           (rx[2:4], bytearray(tx.queue.pop()))):
            if k % 5 == 0:
                data[rng.randrange(len(data))] ^= 1 << rng.randrange(8)
            got = []
            for link in pair:
                link.transport.send_bytes(bytes(data))
                got.append([_state(m) for m in link.recv(0)])
            assert got[0] == got[1], k
    assert rx[0].stats.as_dict() == rx[1].stats.as_dict()
    assert rx[2].stats.as_dict() == rx[3].stats.as_dict()
    assert rx[0].stats.frames_received > 500 and rx[0].stats.dropped >= 50
    assert rx[2].stats.frames_received >= 240 and rx[2].stats.dropped >= 50

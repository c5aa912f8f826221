"""MAVLink 2 signing as the autopilot's ground-station links check it: unsigned, wrong-key,
replayed, cross-link-replayed and forged-timestamp frames are refused, and the legitimate
signer is accepted right after a forged frame (pymavlink alone locks it out: shown too)."""

from __future__ import annotations

import hashlib
import struct

import pytest
from support.memory_link import CaptureTransport

from vtolftc.firmware_sim.autopilot.gcs_endpoint import UNSIGNED_ALLOWED
from vtolftc.protocols import Link, SigningConfig, StreamTimestamps, make_codec
from vtolftc.protocols.mavlink import signing_timestamp_now

KEY = hashlib.sha256(b"correct horse").digest()
OTHER_KEY = hashlib.sha256(b"battery staple").digest()




def _autopilot_links(n: int = 2) -> list[Link]:
    table = StreamTimestamps()
    cfg = SigningConfig(KEY, allow_unsigned=lambda mid: mid in UNSIGNED_ALLOWED)
    return [Link(CaptureTransport(), system_id=1, component_id=1, signing=cfg, stream_table=table)
            for _ in range(n)]


def _feed(link: Link, data: bytes) -> list:
    out: list = []
    link._parse_datagram(data, out)
    return out


def _signer(key: bytes = KEY, timestamp: int | None = None, sysid: int = 255):
    return make_codec(sysid, 190, signing=SigningConfig(key, timestamp=timestamp))


def _param_set(codec, value: float = 1.0) -> bytes:
    data = codec.param_set_encode(1, 1, b"SYS_FAILURE_EN", value, 6).pack(codec)
    codec.seq = (codec.seq + 1) & 0xFF
    return data


def test_unsigned_and_wrong_key_refused_allowlist_accepted():
    link = _autopilot_links(1)[0]
    plain = make_codec(255, 190)
    assert _feed(link, _param_set(plain)) == []
    cmd = plain.command_long_encode(1, 1, 400, 0, 1, 0, 0, 0, 0, 0, 0).pack(plain)
    assert _feed(link, cmd) == []
    assert _feed(link, _param_set(_signer(OTHER_KEY))) == []
    assert link.stats.dropped_signature == 3
    # the allowlist: heartbeat and parameter reads pass unsigned (and say so)
    hb = plain.heartbeat_encode(6, 8, 0, 0, 4).pack(plain)
    got = _feed(link, hb)
    assert [m.get_type() for m in got] == ["HEARTBEAT"] and not got[0].get_signed()
    good = _feed(link, _param_set(_signer()))
    assert [m.get_type() for m in good] == ["PARAM_SET"] and good[0].get_signed()


def test_replay_on_the_same_and_on_another_link_refused():
    a, b = _autopilot_links(2)
    frame = _param_set(_signer())
    assert len(_feed(a, frame)) == 1
    assert _feed(a, frame) == []          # replayed on the same link
    assert _feed(b, frame) == []          # captured on one link, replayed on the other
    assert a.stats.dropped_signature == 1 and b.stats.dropped_signature == 1


def _forge_future(frame: bytes, ts: int) -> bytes:
    """The legitimate frame with its timestamp raised and a made-up signature."""
    body = bytearray(frame)
    body[-12:-6] = struct.pack("<IH", ts & 0xFFFFFFFF, ts >> 32)
    body[-6:] = b"\x00" * 6
    return bytes(body)


def test_forged_future_timestamp_does_not_lock_the_signer_out():
    (link,) = _autopilot_links(1)
    signer = _signer()
    assert len(_feed(link, _param_set(signer))) == 1
    far = signing_timestamp_now() + 30 * 365 * 24 * 3600 * 100_000  # 30 years ahead
    assert _feed(link, _forge_future(_param_set(signer), far)) == []
    # the next legitimate frame still gets in
    nxt = _feed(link, _param_set(signer, 0.0))
    assert [m.get_type() for m in nxt] == ["PARAM_SET"] and nxt[0].get_signed()


def test_plain_pymavlink_is_locked_out_by_the_forged_frame():
    """The reason for the wrapper (independent evidence): the generated parser stores the
    forged timestamp before it checks the hash."""
    plain = make_codec(1, 1)
    s = plain.signing
    s.secret_key = KEY
    s.timestamp = signing_timestamp_now()
    s.allow_unsigned_callback = None
    signer = _signer()
    link = Link(CaptureTransport(), codec=plain)
    assert len(_feed(link, _param_set(signer))) == 1
    far = signing_timestamp_now() + 30 * 365 * 24 * 3600 * 100_000
    assert _feed(link, _forge_future(_param_set(signer), far)) == []
    assert _feed(link, _param_set(signer)) == []  # locked out


@pytest.mark.parametrize("minutes_old", [0.5, 2.0])
def test_new_stream_at_most_a_minute_old(minutes_old):
    (link,) = _autopilot_links(1)
    ts = signing_timestamp_now() - round(minutes_old * 60 * 100_000)
    got = _feed(link, _param_set(_signer(timestamp=ts, sysid=42)))
    assert (len(got) == 1) == (minutes_old < 1.0)

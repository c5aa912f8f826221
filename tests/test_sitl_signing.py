"""Signing through the real autopilot process: with a passphrase, parameter changes and
commands need a valid signature on every link; unsigned, wrong-key, cross-link-replayed and
forged-timestamp frames are refused; the legitimate signer is accepted right after a forged
frame."""

from __future__ import annotations

import struct
import time

import pytest

from vtolftc.protocols import SigningConfig, open_link
from vtolftc.protocols.mavlink import signing_timestamp_now
from vtolftc.protocols.netutil import free_udp_port
from vtolftc.runners.sitl import SitlConfig, SitlRun

pytestmark = pytest.mark.slow
PASS = "sitl signing test"


@pytest.fixture(scope="module")
def signed(tmp_path_factory):
    port = free_udp_port()
    # held at t = 0 for the whole module: these tests fly nothing, and a free-running lockstep
    # simulation would stream and record for as long as they take
    cfg = SitlConfig(out_dir=tmp_path_factory.mktemp("sitl_signing"), hold_at_start=True,
                     failure_injection=False, plots=False,
                     extra_autopilot_args=["--signing-passphrase", PASS,
                                           "--gcs-link", f"udp-server://127.0.0.1:{port}"])
    run = SitlRun(cfg)
    run.port = port
    try:
        run.start()
        yield run
    finally:
        run.close()


def _client(run, key: str | None, sysid: int):
    sig = None if key is None else SigningConfig.from_passphrase(key)
    return open_link(f"udp-client://127.0.0.1:{run.port}", system_id=sysid, component_id=190,
                     signing=sig)


def _frame(link, value: float) -> bytes:
    c = link.codec
    data = c.param_set_encode(1, 1, b"MIS_TAKEOFF_ALT", value, 9).pack(c)
    c.seq = (c.seq + 1) & 0xFF
    return data


def _read(link) -> float:
    """MIS_TAKEOFF_ALT as the autopilot answers on ``link`` (PARAM_REQUEST_READ is allowed
    unsigned). Echoes of earlier changes still queued are read away first: what has arrived by
    now, bounded by a count and a deadline (the link streams telemetry, so it is never silent).
    """
    deadline = time.monotonic() + 2.0
    for _ in range(10_000):
        if not link.recv(0.0) or time.monotonic() > deadline:
            break
    for _ in range(5):
        link.send(link.codec.param_request_read_encode(1, 1, b"MIS_TAKEOFF_ALT", -1))
        m = link.recv_match("PARAM_VALUE", 1.0,
                            lambda m: m.param_id.rstrip("\x00") == "MIS_TAKEOFF_ALT")
        if m is not None:
            return float(m.param_value)
    raise AssertionError("no PARAM_VALUE")


def _settle() -> None:
    time.sleep(0.3)  # the worker handles requests within milliseconds


def test_unsigned_and_wrong_key_changes_refused_signed_accepted(signed):
    a, b, c = _client(signed, PASS, 201), _client(signed, None, 202), _client(signed, "x", 203)
    try:
        assert _read(a) == 30.0
        b.send(_frame(b, 12.0))
        c.send(_frame(c, 13.0))
        b.send(b.codec.command_long_encode(1, 1, 400, 0, 1, 0, 0, 0, 0, 0, 0))
        _settle()
        assert b.recv_match("COMMAND_ACK", 1.0) is None  # dropped at the link: no answer
        assert _read(a) == 30.0
        a.send(_frame(a, 12.0))
        _settle()
        assert _read(a) == 12.0
        a.send(a.codec.command_long_encode(1, 1, 31010, 0, 1, 0, 0, 0, 0, 0, 0))
        ack = a.recv_match("COMMAND_ACK", 2.0)
        assert ack is not None and ack.command == 31010 and ack.result == 3
    finally:
        for link in (a, b, c):
            link.close()


def test_cross_link_replay_and_forged_timestamp_refused(signed):
    a = _client(signed, PASS, 211)
    try:
        first = _frame(a, 15.0)
        a.send(first)
        _settle()
        a.send(_frame(a, 16.0))
        _settle()
        assert _read(a) == 16.0
        signed.gs.link.send(first)  # the value-15 frame replayed on the other link
        _settle()
        assert _read(a) == 16.0
        # a forged frame with a far-future timestamp, then the legitimate signer
        forged = bytearray(_frame(a, 17.0))
        ts = signing_timestamp_now() + 30 * 365 * 24 * 3600 * 100_000
        forged[-12:-6] = struct.pack("<IH", ts & 0xFFFFFFFF, ts >> 32)
        forged[-6:] = b"\x00" * 6
        a.send(bytes(forged))
        _settle()
        assert _read(a) == 16.0
        a.send(_frame(a, 18.0))
        _settle()
        assert _read(a) == 18.0
    finally:
        a.close()

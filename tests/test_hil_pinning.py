"""HIL peer pinning that a stranger cannot win: the signed HIL link.

- the key comes from ``VTOLFTC_HIL_KEY`` (64 hex digits); a bad one is one line, exit 2;
- a vehicle with a key pins only a HEARTBEAT signed with that key: a forged one (unsigned, or
  signed with another key) sent first is dropped, over UDP and zenoh, and the stranger gets
  no answer over UDP;
- end to end (slow): the real processes over UDP, a stranger forging HEARTBEATs as system 1 /
  component 1 to the vehicle's HIL port from before the autopilot starts until the end; the
  real autopilot is pinned, arms and flies; the stranger receives nothing.
"""

from __future__ import annotations

import json
import math
import socket
import threading
import time

import pytest
from support.memory_link import CaptureTransport

from vtolftc.firmware_sim.vehicle.process import VehicleProcess
from vtolftc.protocols import SigningConfig, make_codec, open_link
from vtolftc.protocols.hil_signing import HIL_KEY_ENV, hil_signing_from_env, new_hil_key
from vtolftc.protocols.netutil import free_tcp_port, free_udp_port

HB = (22, 12, 0, 0, 3)  # type VTOL, autopilot PX4, base mode, custom mode, STANDBY


def _forged_heartbeats() -> list[bytes]:
    """HEARTBEATs as system 1 / component 1: unsigned, and signed with a wrong key."""
    plain = make_codec(1, 1)
    wrong = make_codec(1, 1, signing=SigningConfig(bytes(range(32))))
    return [plain.heartbeat_encode(*HB).pack(plain), wrong.heartbeat_encode(*HB).pack(wrong)]


def test_hil_key_from_the_environment():
    assert hil_signing_from_env({}) is None
    assert hil_signing_from_env({HIL_KEY_ENV: ""}) is None
    key = new_hil_key()
    assert len(key) == 64 and key != new_hil_key()
    cfg = hil_signing_from_env({HIL_KEY_ENV: key})
    assert cfg is not None and cfg.secret_key == bytes.fromhex(key)
    assert cfg.allow_unsigned is False and cfg.sign_outgoing
    for bad in ("abc", "zz" * 32, key + "00"):
        with pytest.raises(ValueError, match=HIL_KEY_ENV):
            hil_signing_from_env({HIL_KEY_ENV: bad})


@pytest.mark.parametrize("program", ["vehicle", "autopilot"])
def test_bad_hil_key_is_one_line_and_exit_2(program, monkeypatch, capsys):
    monkeypatch.setenv(HIL_KEY_ENV, "not-a-key")
    port = free_udp_port()
    if program == "vehicle":
        from vtolftc.runners.processes.vehicle import main
        rc = main(["--link", f"udp-server://127.0.0.1:{port}"])
    else:
        from vtolftc.runners.processes.autopilot import main
        rc = main(["--hil-link", f"udp-client://127.0.0.1:{port}", "--no-default-gcs",
                   "--no-warmup"])
    err = capsys.readouterr().err
    assert rc == 2
    assert err.count("\n") == 1 and HIL_KEY_ENV in err and "Traceback" not in err, err


class _Vehicle:
    """A signed VehicleProcess run in a thread (the physics never starts: nothing steps)."""

    def __init__(self, url: str, key: str, tmp_path) -> None:
        self.proc = VehicleProcess(url, out_dir=tmp_path, peer_timeout_s=5.0,
                                   connect_timeout_s=20.0,
                                   signing=hil_signing_from_env({HIL_KEY_ENV: key}))
        self.thread = threading.Thread(target=self.proc.run, daemon=True)

    def stop(self) -> None:
        self.proc.running = False
        self.thread.join(10.0)


def _wait(pred, timeout_s: float) -> bool:
    end = time.monotonic() + timeout_s
    while time.monotonic() < end:
        if pred():
            return True
        time.sleep(0.02)
    return pred()


def test_udp_forged_heartbeat_first_is_refused_and_the_key_holder_pinned(tmp_path):
    key = new_hil_key()
    port = free_udp_port()
    veh = _Vehicle(f"udp-server://127.0.0.1:{port}", key, tmp_path)
    stranger = socket.socket(socket.AF_INET, socket.SOCK_DGRAM)
    stranger.settimeout(0.05)
    real = open_link(f"udp-client://127.0.0.1:{port}", system_id=1, component_id=1,
                     signing=hil_signing_from_env({HIL_KEY_ENV: key}))
    try:
        for data in _forged_heartbeats():  # queued before the vehicle reads anything
            stranger.sendto(data, ("127.0.0.1", port))
        veh.thread.start()
        assert _wait(lambda: veh.proc.link.stats.dropped_signature >= 2, 20.0)
        assert veh.proc.pinned is None
        real.send(real.codec.heartbeat_encode(*HB))
        assert _wait(lambda: veh.proc.pinned is not None, 20.0)
        assert veh.proc.pinned == real.local_address
        got = []
        end = time.monotonic() + 10.0
        while not any(m.get_type() == "HIL_SENSOR" for m in got) and time.monotonic() < end:
            got += real.recv(0.2)
        sensor = [m for m in got if m.get_type() == "HIL_SENSOR"]
        assert sensor and all(m.get_signed() for m in sensor)
        for data in _forged_heartbeats():  # after pinning: another sender, dropped
            stranger.sendto(data, ("127.0.0.1", port))
        time.sleep(0.3)
        with pytest.raises(TimeoutError):
            stranger.recvfrom(65536)  # the stranger never hears from the vehicle
    finally:
        veh.stop()
        real.close()
        stranger.close()


def test_zenoh_forged_heartbeat_is_refused_and_the_key_holder_pinned(tmp_path):
    """zenoh has no source addresses: the signature is the only proof."""
    key = new_hil_key()
    port = free_tcp_port()
    veh = _Vehicle(f"zenoh://pin/hil/up?listen=tcp/127.0.0.1:{port}", key, tmp_path)
    down = f"zenoh://pin/hil/down?connect=tcp/127.0.0.1:{port}"
    stranger = open_link(down, system_id=1, component_id=1)
    real = open_link(down, system_id=1, component_id=1,
                     signing=hil_signing_from_env({HIL_KEY_ENV: key}))
    try:
        veh.thread.start()
        # until the stranger's frames are seen (zenoh routes once the peers met)
        assert _wait(lambda: (stranger.send(_forged_heartbeats()[0]),
                              stranger.send(_forged_heartbeats()[1]),
                              veh.proc.link.stats.dropped_signature >= 2)[-1], 30.0)
        assert veh.proc.pinned is None
        assert _wait(lambda: (real.send(real.codec.heartbeat_encode(*HB)),
                              veh.proc.pinned is not None)[-1], 30.0)
        assert veh.proc.pinned == "ids"
        got = []
        end = time.monotonic() + 10.0
        while not any(m.get_type() == "HIL_SENSOR" for m in got) and time.monotonic() < end:
            got += real.recv(0.2)
        assert any(m.get_type() == "HIL_SENSOR" and m.get_signed() for m in got)
    finally:
        veh.stop()
        real.close()
        stranger.close()


# ---------------------------------------------------------------------------- end to end
class _Stranger(threading.Thread):
    """Forges HEARTBEATs (system 1, component 1; unsigned and wrongly signed) to the
    vehicle's HIL port every 20 ms from its own socket, and records what comes back."""

    def __init__(self, port: int) -> None:
        super().__init__(daemon=True)
        self.port = port
        self.sock = socket.socket(socket.AF_INET, socket.SOCK_DGRAM)
        self.sock.settimeout(0.02)
        self.sent = 0
        self.received = 0
        self.addr: tuple[str, int] | None = None
        self.running = True

    def run(self) -> None:
        frames = _forged_heartbeats()
        while self.running:
            for data in frames:
                self.sock.sendto(data, ("127.0.0.1", self.port))
                self.sent += 1
            self.addr = self.sock.getsockname()
            try:
                self.sock.recvfrom(65536)
                self.received += 1
            except (TimeoutError, ConnectionRefusedError):
                pass

    def stop(self) -> None:
        self.running = False
        self.join(5.0)
        self.sock.close()


@pytest.mark.slow
def test_forged_heartbeat_first_race_refused_real_autopilot_arms_and_flies(tmp_path):
    """Real processes over UDP (``vtolftc sitl``'s runner, its per-run HIL key): the
    stranger forges from before the autopilot is started until the end of the flight."""
    from vtolftc.runners.sitl import SitlConfig, SitlRun

    strangers: list[_Stranger] = []

    class _Run(SitlRun):
        def _spawn(self, name, args):
            if name == "autopilot":  # the vehicle is started: forge before the autopilot
                port = int(self.urls["vehicle"].rsplit(":", 1)[1])
                strangers.append(_Stranger(port))
                strangers[0].start()
                assert _wait(lambda: strangers[0].sent >= 20, 10.0)
            super()._spawn(name, args)

    out = tmp_path / "run"
    cfg = SitlConfig(out_dir=out, hold_at_start=False, plots=False, failure_injection=False)
    try:
        with _Run(cfg) as run:
            run.start()
            gs = run.gs
            gs.wait_for(lambda s: s.connected and s.landed_state == 1
                        and math.isfinite(s.home_amsl_m), 120.0)
            assert gs.arm().accepted
            assert gs.takeoff(10.0).accepted
            gs.wait_for(lambda s: s.mode_name == "AUTO.LOITER" and s.altitude_m > 8.5, 120.0)
    finally:
        for s in strangers:
            s.stop()
    stranger = strangers[0]
    summary = json.loads((out / "vehicle" / "vehicle_summary.json").read_text())
    print("stranger sent", stranger.sent, "received", stranger.received, "vehicle link",
          summary["link"], "pinned", summary["pinned_autopilot"])
    assert stranger.sent > 100 and stranger.received == 0
    assert summary["hil_signed"] is True
    assert stranger.addr is not None and summary["pinned_autopilot"] is not None
    assert summary["pinned_autopilot"] != str(stranger.addr)
    assert summary["link"]["dropped_signature"] >= 2  # the forgeries before the pinning
    assert summary["link"]["dropped_foreign"] > 0     # and from another address after it
    assert summary["sim_time_s"] > 5.0




@pytest.mark.parametrize("signed", [True, False])
def test_state_sent_again_is_not_a_replay(signed, tmp_path):
    """Lockstep resends the last state when no answer came (lost, or held): on a signed link
    it is signed anew, so the autopilot does not drop it as a replay."""
    from vtolftc.protocols import Link

    key = new_hil_key()
    sig = hil_signing_from_env({HIL_KEY_ENV: key}) if signed else None
    proc = VehicleProcess(f"udp-server://127.0.0.1:{free_udp_port()}", out_dir=tmp_path,
                          signing=sig)
    try:
        first = proc.state_datagram()
        second = proc.again(first)
        third = proc.again(second)
        rx = Link(CaptureTransport(), system_id=1, component_id=1,
                  signing=hil_signing_from_env({HIL_KEY_ENV: key}) if signed else None)
        got: list = []
        for d in (first, second, third):
            rx._parse_datagram(d, got)
        assert (second == first) is (not signed)
        n = len([m for m in got if m.get_type() == "HIL_STATE_QUATERNION"])
        assert n == 3 and rx.stats.dropped_signature == 0
        if signed:
            assert all(m.get_signed() for m in got)
    finally:
        proc.close()

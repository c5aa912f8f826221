""":meth:`vtolftc.runners.sitl.SitlRun.start` when a port it chose is bound by someone else
before its process binds it (another program on a loaded machine): the start is tried again
with fresh ports, the failed attempt's logs are kept, and any other failure is not retried."""

from __future__ import annotations

import socket

import pytest

import vtolftc.runners.sitl as sitl_mod
from vtolftc.protocols.netutil import free_udp_port
from vtolftc.runners.sitl import START_ATTEMPTS, SitlConfig, SitlError, SitlRun


@pytest.fixture
def taken_port():
    """A loopback UDP port held by this test (someone else's, for the run)."""
    s = socket.socket(socket.AF_INET, socket.SOCK_DGRAM)
    s.bind(("127.0.0.1", 0))
    try:
        yield int(s.getsockname()[1])
    finally:
        s.close()


def _ports(monkeypatch, first: list[int]) -> list[int]:
    """The runner's free_udp_port hands out ``first``, then free ports; returns the list of
    ports handed out."""
    given: list[int] = []

    def pick() -> int:
        p = first.pop(0) if first else free_udp_port()
        given.append(p)
        return p

    monkeypatch.setattr(sitl_mod, "free_udp_port", pick)
    return given


@pytest.mark.parametrize("which", ["vehicle", "ground station"])
def test_a_taken_port_is_retried_with_fresh_ports(tmp_path, monkeypatch, taken_port, which):
    """The vehicle's HIL port (bound by the vehicle process) or the ground station's port
    (bound here) taken: the run starts on the second attempt, on other ports."""
    first = [taken_port] if which == "vehicle" else [free_udp_port(), taken_port]
    given = _ports(monkeypatch, first)
    run = SitlRun(SitlConfig(out_dir=tmp_path, plots=False, startup_timeout_s=120.0))
    try:
        run.start()
        assert run.ready()
        assert str(taken_port) not in run.urls["vehicle"] + run.urls["ground_station"]
        assert len(given) == 4                           # two ports per attempt
        if which == "vehicle":
            kept = (tmp_path / "vehicle.attempt1.log").read_text()
            assert "Address already in use" in kept, kept
            assert (tmp_path / "autopilot.attempt1.log").is_file()
        else:                                            # no process was started
            assert not list(tmp_path.glob("*.attempt1.log"))
        assert not list(tmp_path.glob("*.attempt2.log"))
    finally:
        run.close()


def test_a_port_taken_every_time_ends_the_start_after_the_last_attempt(tmp_path, monkeypatch,
                                                                        taken_port):
    given = _ports(monkeypatch, [taken_port, free_udp_port()] * START_ATTEMPTS)
    run = SitlRun(SitlConfig(out_dir=tmp_path, plots=False, startup_timeout_s=120.0))
    try:
        with pytest.raises(SitlError, match="Address already in use"):
            run.start()
    finally:
        run.close()
    assert given.count(taken_port) == START_ATTEMPTS
    for k in range(1, START_ATTEMPTS):
        assert (tmp_path / f"vehicle.attempt{k}.log").is_file()


def test_another_failure_is_not_retried(tmp_path, monkeypatch):
    """A process that ends for another reason (here an airframe file that does not exist)
    fails the start at once."""
    given = _ports(monkeypatch, [])
    run = SitlRun(SitlConfig(out_dir=tmp_path, plots=False, startup_timeout_s=120.0,
                             airframe=tmp_path / "missing.toml"))
    try:
        with pytest.raises(SitlError, match="ended early"):
            run.start()
    finally:
        run.close()
    assert len(given) == 2 and not list(tmp_path.glob("*.attempt*.log"))

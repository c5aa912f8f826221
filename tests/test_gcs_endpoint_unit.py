"""The ground-station endpoint driven by hand (no threads, in-memory links): intervals are per
link, floods are rate-limited per client, and nothing reaches the autopilot until the control
thread polls."""

from __future__ import annotations

import time
import types

import pytest
from support.memory_link import CaptureTransport, parse, sent_messages

from vtolftc.airframe.loader import load_airframe
from vtolftc.firmware_sim.autopilot import gcs_link
from vtolftc.firmware_sim.autopilot.autopilot import Autopilot
from vtolftc.firmware_sim.autopilot.gcs_endpoint import GcsEndpoint
from vtolftc.firmware_sim.autopilot.hil_bridge import HilBridge
from vtolftc.protocols import Link, make_codec
from vtolftc.protocols.failure_units import ActuatorTable


def _msgs(transport: CaptureTransport) -> list:
    return sent_messages(transport)


@pytest.fixture()
def ep():
    af = load_airframe()
    ap = Autopilot(af)
    links = [Link(CaptureTransport(), system_id=1, component_id=1) for _ in range(2)]
    hil = HilBridge(Link(CaptureTransport(), system_id=1, component_id=1))
    e = GcsEndpoint(ap, hil, links, actuators=ActuatorTable.from_names(af.actuator_names),
                    start=False)
    yield e
    e.close()


def _inject(ep, index: int, msgs) -> None:
    ep.io.queues[index].extend(parse(list(msgs)))


def _pack(codec, msg) -> bytes:
    data = msg.pack(codec)
    codec.seq = (codec.seq + 1) & 0xFF
    return data


def test_message_interval_is_per_link(ep):
    gs = make_codec(255, 190)
    _inject(ep, 0, [_pack(gs, gs.command_long_encode(1, 1, 511, 0, 0, -1, 0, 0, 0, 0, 0))])
    ep.serve_once()
    assert ep.rates_hz[0][0] == 0.0          # HEARTBEAT off on link 0 only
    assert ep.rates_hz[1][0] == 1.0
    acks0 = [m for m in _msgs(ep.links[0].transport) if m.get_type() == "COMMAND_ACK"]
    acks1 = [m for m in _msgs(ep.links[1].transport) if m.get_type() == "COMMAND_ACK"]
    assert [(a.command, a.result) for a in acks0] == [(511, 0)] and acks1 == []


def test_flood_rate_limited_per_client_and_kept_off_the_control_thread(ep, monkeypatch):
    # the token buckets read the wall clock: frozen here, so that a loaded machine, slow
    # between two serve_once, cannot refill them (it once handled 103 of the burst of 100)
    t0 = time.monotonic()
    monkeypatch.setattr(gcs_link, "time", types.SimpleNamespace(monotonic=lambda: t0,
                                                                 sleep=time.sleep))
    flood = make_codec(200, 1)
    frames = [_pack(flood, flood.param_set_encode(1, 1, f"NOPE_{k}".encode(), 1.0, 9))
              for k in range(300)]
    frames += [_pack(flood, flood.param_set_encode(1, 1, b"MIS_TAKEOFF_ALT", 1e9, 9))
               for _ in range(50)]
    _inject(ep, 0, frames)
    for _ in range(20):
        ep.serve_once()
    cnt = ep.io.counters[0]
    # one client: its burst (100) handled, the rest dropped and counted, nothing queued for
    # the control thread (unknown names and out-of-range values are refused in the worker)
    assert cnt["handled"] == ep.rate_burst
    assert cnt["handled"] + cnt["rate_limited"] == 350
    assert not ep.has_pending() and ep.ap.params.get("MIS_TAKEOFF_ALT") == 30.0
    # another client is not starved by the first
    gs = make_codec(255, 190)
    _inject(ep, 0, [_pack(gs, gs.param_set_encode(1, 1, b"MIS_TAKEOFF_ALT", 12.0, 9))])
    ep.serve_once()
    assert ep.has_pending()
    assert ep.ap.params.get("MIS_TAKEOFF_ALT") == 30.0  # not before the control thread polls
    assert ep.poll() == 1 and ep.ap.params.get("MIS_TAKEOFF_ALT") == 12.0
    ep.serve_once()
    echo = [m for m in _msgs(ep.links[1].transport) if m.get_type() == "PARAM_VALUE"]
    assert echo and echo[-1].param_value == 12.0  # echoed on every link


def test_control_queue_bounded_drop_oldest_answered(ep):
    gs = make_codec(255, 190)
    n = ep._control_queue_len + 5
    _inject(ep, 0, [_pack(gs, gs.command_long_encode(1, 1, 21, 0, 0, 0, 0, 0, 0, 0, 0))
                    for _ in range(n)])
    ep.serve_once()
    ep.serve_once()
    assert len(ep._control_q) == ep._control_queue_len
    acks = [m for m in _msgs(ep.links[0].transport) if m.get_type() == "COMMAND_ACK"]
    assert [a.result for a in acks] == [1] * 5  # TEMPORARILY_REJECTED for the dropped ones
    assert ep.poll(max_items=4) == 4           # the control thread takes a few per cycle


def _nav(t_usec: int):
    import numpy as np

    from vtolftc.protocols.hil import NavState

    return NavState(t_usec, np.array([1.0, 0.0, 0.0, 0.0]), np.zeros(3), np.zeros(3),
                    np.zeros(3), 0.0)


def test_worker_woken_only_when_a_stream_is_due_or_the_status_changed(ep):
    """One simulated second of steps (250): the worker is woken at the steps where a stream
    is due (10 Hz at most by default) or the mode changed, not at every step; each woken
    cycle still sends ATTITUDE at its 10 Hz of simulated time."""
    import dataclasses

    from vtolftc.firmware_sim.autopilot.interface import FlightMode

    st = ep.ap.status()
    wakes = []
    for k in range(250):
        s = st if k < 110 else dataclasses.replace(st, mode=FlightMode.HOVER)
        ep._wake.clear()
        ep.on_step(_nav(4000 * k), s)
        if ep._wake.is_set():
            wakes.append(k)
            ep.serve_once()
    assert 110 in wakes                     # the mode change, though no stream was due
    assert 10 <= len(wakes) <= 25, wakes    # not 250
    att = [m for m in _msgs(ep.links[0].transport) if m.get_type() == "ATTITUDE"]
    assert len(att) == 10


def test_every_autopilot_event_reaches_the_ground_stations_and_the_run_log(ep):
    """Two autopilot events of one control step (e.g. "mission complete" and "Disarmed by
    landing", which a loaded CI run's mission flight produced on one step), and events of
    steps the worker did not observe one by one, each go out as a STATUSTEXT on every link
    and as a run event (the ULog's logged messages); a message its command's COMMAND_ACK
    carried is not sent again. The status's last message alone lost the first of the two."""
    seen: list[tuple[str, str]] = []
    ep.on_event = lambda kind, text: seen.append((kind, text))
    ep.serve_once()
    ep.ap.commander.note("mission complete")
    ep.ap.commander.note("Disarmed by landing")
    ep.refresh_status()
    ep.serve_once()
    ep.ap.commander.note("first")
    ep.refresh_status()   # a snapshot the worker never observes: superseded by the next
    ep.ap.commander.note("second")
    ep.refresh_status()
    ep.serve_once()
    ep.ap.commander.note("takeoff denied: test")
    ep.reply(lambda: ep.mark_reported("takeoff denied: test"))
    ep.refresh_status()
    ep.serve_once()
    want = ["mission complete", "Disarmed by landing", "first", "second"]
    assert [t for k, t in seen if k == "autopilot"] == want
    for link in ep.links:
        texts = [m.text for m in _msgs(link.transport) if m.get_type() == "STATUSTEXT"]
        assert texts == want, texts

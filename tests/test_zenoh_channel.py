"""The zenoh transport's ``channel`` receive mode (the HIL link's): zenoh's FIFO channel read
directly, timed waits ended by a watchdog, closing wakes a blocked receiver; and the HIL link
of both SITL processes uses it."""

from __future__ import annotations

import json
import threading
import time
from collections.abc import Iterator

import pytest

from vtolftc.protocols.link import open_link
from vtolftc.protocols.netutil import free_tcp_port
from vtolftc.protocols.zenoh_transport import ZenohTransport, zenoh_config


def _pair(receive: str, lowlatency: bool = False) -> tuple[ZenohTransport, ZenohTransport]:
    for _ in range(5):  # a free port can be taken between probing and listening: retry
        port = free_tcp_port()
        try:
            up = ZenohTransport("ds1", "hil", "up", listen=[f"tcp/127.0.0.1:{port}"],
                                receive=receive, lowlatency=lowlatency)
        except OSError:
            continue
        down = ZenohTransport("ds1", "hil", "down", connect=[f"tcp/127.0.0.1:{port}"],
                              receive=receive, lowlatency=lowlatency)
        deadline = time.monotonic() + 10.0
        while not (up.ready() and down.ready()) and time.monotonic() < deadline:
            time.sleep(0.01)
        if up.ready() and down.ready():
            return up, down
        up.close()
        down.close()
    raise RuntimeError("could not open a zenoh pair")


@pytest.fixture(params=[False, True], ids=["universal", "lowlatency"])
def pair(request) -> Iterator[tuple[ZenohTransport, ZenohTransport]]:
    """A channel-mode pair on zenoh's universal and on its low-latency transport."""
    up, down = _pair("channel", request.param)
    try:
        yield up, down
    finally:
        up.close()
        down.close()


def _in_thread(fn, timeout_s: float = 5.0):
    """``fn()`` in a thread; (result, seconds), or the test fails if it did not return."""
    box: list = []

    def run() -> None:
        t0 = time.monotonic()
        box.append(fn())
        box.append(time.monotonic() - t0)

    th = threading.Thread(target=run, daemon=True)
    th.start()
    th.join(timeout_s)
    assert not th.is_alive(), "the receive never returned"
    return box[0], box[1]


def test_channel_delivers_in_order_and_polls(pair):
    up, down = pair
    assert down.recv_datagrams(0.0) == []  # poll: nothing there, no wait
    for k in range(5):
        assert up.send_bytes(bytes([65 + k]) * 10)
    got: list[bytes] = []
    deadline = time.monotonic() + 5.0
    while len(got) < 5 and time.monotonic() < deadline:
        got += down.recv_datagrams(1.0)
    assert got == [bytes([65 + k]) * 10 for k in range(5)]


def test_channel_timed_wait_ends_at_its_timeout(pair):
    _up, down = pair
    got, took = _in_thread(lambda: down.recv_datagrams(0.2))
    assert got == []
    assert 0.19 <= took < 1.0  # the watchdog ends it within _WATCH_S (5 ms) of the timeout


def test_channel_short_waits_wake_the_watchdog(pair):
    """A deadline sooner than the watchdog's next look (it looks every 5 ms) wakes it, so a
    1 ms wait is not a 5 ms one (the vehicle's real-time loop waits in slices of at most
    2 ms); the lockstep's long waits never do (no thread hand-off per step)."""
    _up, down = pair
    kicks = []
    real = down._kick

    class Spy:
        def set(self) -> None:
            kicks.append(time.monotonic())
            real.set()

    down._kick = Spy()
    _in_thread(lambda: [down.recv_datagrams(0.2) for _ in range(2)])
    assert kicks == []  # 200 ms waits: the watchdog's own 5 ms looks are soon enough
    _in_thread(lambda: [down.recv_datagrams(0.001) for _ in range(20)])
    assert kicks  # 1 ms waits: it is woken


def test_channel_wakes_a_waiting_receiver_when_data_comes(pair):
    up, down = pair
    threading.Timer(0.1, up.send_bytes, (b"late",)).start()
    got, took = _in_thread(lambda: down.recv_datagrams(3.0))
    assert got == [b"late"] and took < 2.0


def test_channel_drops_empty_payloads(pair):
    """Empty payloads are the watchdog's wake-ups: never handed to the caller."""
    up, down = pair
    up.send_bytes(b"")
    up.send_bytes(b"x")
    got: list[bytes] = []
    deadline = time.monotonic() + 5.0
    while not got and time.monotonic() < deadline:
        got += down.recv_datagrams(1.0)
    assert got == [b"x"]


def test_close_wakes_a_blocked_receiver(pair):
    _up, down = pair
    threading.Timer(0.1, down.close).start()
    got, took = _in_thread(lambda: down.recv_datagrams(30.0))
    assert got == [] and took < 3.0
    assert down.recv_datagrams(1.0) == []  # closed: nothing, no error


def test_bad_receive_mode_is_refused():
    with pytest.raises(ValueError, match="receive mode"):
        ZenohTransport("ds1", "hil", "up", listen=[f"tcp/127.0.0.1:{free_tcp_port()}"],
                       receive="fifo")


def test_open_link_passes_the_receive_mode():
    port = free_tcp_port()
    with open_link(f"zenoh://ds1/hil/up?listen=tcp/127.0.0.1:{port}",
                   zenoh_receive="channel") as link:
        assert link.transport.receive == "channel"
    with open_link(f"zenoh://ds1/gcs/up?listen=tcp/127.0.0.1:{free_tcp_port()}") as link:
        assert link.transport.receive == "callback"  # the default (ground-station links)


def test_lowlatency_is_the_session_config_and_only_when_asked():
    """zenoh's low-latency unicast transport needs its QoS off; the default keeps both."""
    ep = [f"tcp/127.0.0.1:{free_tcp_port()}"]
    for low, want in ((False, (False, True)), (True, (True, False))):
        cfg = zenoh_config(listen=ep, lowlatency=low)
        got = tuple(json.loads(cfg.get_json(k)) for k in ("transport/unicast/lowlatency",
                                                         "transport/unicast/qos/enabled"))
        assert got == want, (low, got)
    with open_link(f"zenoh://ds1/hil/up?listen={ep[0]}&lowlatency=1") as link:
        assert link.transport.lowlatency and "lowlatency" in link.transport.describe()
    with open_link(f"zenoh://ds1/hil/up?listen=tcp/127.0.0.1:{free_tcp_port()}") as link:
        assert not link.transport.lowlatency and "lowlatency" not in link.transport.describe()

"""zenoh transport: raw MAVLink 2 frames as payloads on ``vtolftc/<vehicle>/<link>/<direction>``.

Each :class:`ZenohTransport` opens its own embedded zenoh session (peer mode by default, no
router needed) on explicit endpoints only: multicast scouting and gossip are off, shared memory
is off, and with ``allow_remote=False`` every endpoint must be on a loopback address. One end
listens (``listen=tcp/127.0.0.1:PORT``), the other connects to it; connecting before the
listener exists is fine (the session retries every 50 ms .. 1 s in the background).

This end *publishes* on ``vtolftc/<vehicle>/<link>/<direction>`` and *subscribes* to the
opposite direction (``up`` <-> ``down``). Convention: ``up`` flows from the physics toward the
operator, ``down`` toward the physics: on the HIL link the vehicle simulator publishes ``up``
(sensors) and the autopilot ``down`` (actuator controls); on a ground-station link the autopilot
publishes ``up`` (telemetry) and the ground station ``down`` (commands).

Publications are reliable, ``express`` (no batching delay) and use congestion control BLOCK, so
a lockstep exchange never loses a frame to a full queue. Incoming samples are received in one of
two ways (``receive=``):

- ``"callback"`` (default): zenoh's receiving thread runs a Python callback (it takes the GIL)
  that puts the payload into a bounded in-process queue (full: dropped and counted), which
  :meth:`recv_datagrams` drains; the receiver wakes on that queue: two thread hand-offs and a
  GIL acquisition per sample.
- ``"channel"`` (the HIL link: lockstep, one datagram in flight each way): zenoh's own FIFO
  channel (``zenoh.handlers.FifoChannel``), filled by zenoh's thread without Python or the GIL
  and read by :meth:`recv_datagrams` directly (``try_recv``; when empty, the blocking ``recv``,
  which releases the GIL). Measured with ``benchmarks/bench_sitl.py --zenoh-floor`` (100-byte
  ping-pong, two processes, peer mode, loopback, load 9-10): round trip median 131-149 us with
  the callback and queue, 79-104 us with the channel. The channel has no timeout: a small
  watchdog thread ends a wait at its deadline (within ``_WATCH_S``) by publishing an empty
  payload to this session only, which :meth:`recv_datagrams` drops. A full channel makes
  zenoh's thread wait (back-pressure to the publisher, whose congestion control is BLOCK)
  instead of dropping.

Low-latency transport (``lowlatency=True``, URL ``lowlatency=1``; opt-in, for the lockstep HIL
link, both ends): zenoh's ``transport/unicast/lowlatency`` with its QoS off (the two go
together). The universal transport hands each publication to its TX thread, which writes the
socket; the low-latency one writes it in the publishing thread, and the receiving RX thread
reads the frames without the batch machinery: one thread wake-up less per hop and the
writing CPU in the thread that has the data in its cache. It has no priorities and no
fragmentation (payloads beyond the link's batch size are refused); a MAVLink datagram is far
below it. Both ends must choose it (the transport is negotiated when the session opens).
"""

from __future__ import annotations

import contextlib
import json
import math
import queue
import re
import threading
import time
from typing import Any
from urllib.parse import parse_qs, urlsplit

from vtolftc.protocols.netutil import require_loopback
from vtolftc.protocols.transport import MAX_BATCH, LinkUrl, Transport

__all__ = [
    "DIRECTIONS",
    "KEY_PREFIX",
    "ZenohTransport",
    "key_expr",
    "parse_zenoh_url",
    "zenoh_config",
]

KEY_PREFIX = "vtolftc"
DIRECTIONS = {"up": "down", "down": "up"}
"""Direction published -> direction subscribed."""
DEFAULT_QUEUE_MAX = 4096
RECEIVE_MODES = ("callback", "channel")
_WATCH_S = 0.005
"""Channel mode: the watchdog looks at the receiver's deadline at least this often [s] (an
idle watchdog costs ~200 short wake-ups a second); a wait whose deadline comes sooner than the
watchdog's next look wakes it (one thread hand-off), so a wait never ends late by more than a
wake-up (the lockstep's long timeouts never wake it)."""

_NAME_RE = re.compile(r"^[A-Za-z0-9_\-]+$")
_ENDPOINT_RE = re.compile(r"^(tcp|udp|tls|quic)/(\[[0-9A-Fa-f:.]+\]|[A-Za-z0-9_.\-]+):(\d{1,5})$")
_QUERY_KEYS = {"listen", "connect", "mode", "lowlatency"}


def key_expr(vehicle: str, link: str, direction: str) -> str:
    """``vtolftc/<vehicle>/<link>/<direction>`` after validating each chunk."""
    for what, name in (("vehicle", vehicle), ("link", link)):
        if not _NAME_RE.match(name or ""):
            raise ValueError(f"zenoh {what} name {name!r} must match [A-Za-z0-9_-]+")
    if direction not in DIRECTIONS:
        raise ValueError(f"zenoh direction {direction!r} must be 'up' or 'down'")
    return f"{KEY_PREFIX}/{vehicle}/{link}/{direction}"


def _check_endpoint(ep: str, *, allow_remote: bool) -> str:
    m = _ENDPOINT_RE.match(ep)
    if not m:
        raise ValueError(
            f"bad zenoh endpoint {ep!r}: expected PROTO/HOST:PORT with PROTO in tcp, udp, tls, "
            "quic (e.g. tcp/127.0.0.1:7447)"
        )
    port = int(m.group(3))
    if port > 65535:
        raise ValueError(f"bad zenoh endpoint {ep!r}: port must be 0..65535")
    require_loopback(m.group(2), allow_remote=allow_remote, what=f"zenoh endpoint {ep!r}: host")
    return ep


def zenoh_config(
    *,
    listen: tuple[str, ...] | list[str] = (),
    connect: tuple[str, ...] | list[str] = (),
    mode: str = "peer",
    allow_remote: bool = False,
    lowlatency: bool = False,
) -> Any:
    """Build a ``zenoh.Config`` with explicit endpoints only (no multicast, no gossip, no shm);
    ``lowlatency``: zenoh's low-latency unicast transport, QoS off (see the module docstring).

    Raises
    ------
    ValueError
        bad endpoint, non-loopback endpoint without ``allow_remote``, no endpoint
        at all, or a mode other than peer/client.
    """
    import zenoh

    if mode not in ("peer", "client"):
        raise ValueError(f"zenoh mode must be 'peer' or 'client', got {mode!r}")
    listen = [_check_endpoint(e, allow_remote=allow_remote) for e in listen]
    connect = [_check_endpoint(e, allow_remote=allow_remote) for e in connect]
    if not listen and not connect:
        raise ValueError("zenoh link needs at least one listen= or connect= endpoint")
    if mode == "client" and (listen or not connect):
        raise ValueError("zenoh client mode takes connect= endpoints only")
    cfg = zenoh.Config()
    cfg.insert_json5("mode", json.dumps(mode))
    # always set, even when empty: a peer's default listener is tcp/[::]:0 (all interfaces)
    cfg.insert_json5("listen/endpoints", json.dumps(listen))
    cfg.insert_json5("connect/endpoints", json.dumps(connect))
    cfg.insert_json5(
        "connect/retry",
        json.dumps({"period_init_ms": 50, "period_max_ms": 1000, "period_increase_factor": 2}),
    )
    cfg.insert_json5("scouting/multicast/enabled", "false")
    cfg.insert_json5("scouting/gossip/enabled", "false")
    # nothing to scout: do not wait for scouted peers before zenoh.open returns
    cfg.insert_json5("open/return_conditions/connect_scouted", "false")
    cfg.insert_json5("transport/shared_memory/enabled", "false")
    if lowlatency:
        cfg.insert_json5("transport/unicast/lowlatency", "true")
        cfg.insert_json5("transport/unicast/qos/enabled", "false")
    return cfg


def parse_zenoh_url(url: str) -> LinkUrl:
    """Parse ``zenoh://VEHICLE/LINK/DIRECTION?listen=EP&connect=EP&mode=peer|client&lowlatency=0|1``.

    Only the syntax is checked here; loopback policy applies when the transport is built.
    """
    parts = urlsplit(url)
    if parts.scheme.lower() != "zenoh":
        raise ValueError(f"bad zenoh URL {url!r}: scheme must be zenoh://")
    chunks = [parts.netloc, *[c for c in parts.path.split("/") if c != ""]]
    if len(chunks) != 3 or parts.path.endswith("/") or "//" in parts.path:
        raise ValueError(
            f"bad zenoh URL {url!r}: expected zenoh://VEHICLE/LINK/DIRECTION "
            "(e.g. zenoh://ds1/hil/up?listen=tcp/127.0.0.1:7447)"
        )
    vehicle, link, direction = chunks
    key_expr(vehicle, link, direction)  # validates the names
    try:
        query = parse_qs(parts.query, keep_blank_values=True, strict_parsing=bool(parts.query))
    except ValueError as exc:
        raise ValueError(f"bad zenoh URL {url!r}: malformed query ({exc})") from exc
    unknown = set(query) - _QUERY_KEYS
    if unknown:
        raise ValueError(
            f"bad zenoh URL {url!r}: unknown parameter(s) {sorted(unknown)} "
            f"(allowed: {sorted(_QUERY_KEYS)})"
        )

    def endpoints(name: str) -> tuple[str, ...]:
        out: list[str] = []
        for value in query.get(name, []):
            out.extend(e.strip() for e in value.split(",") if e.strip())
        for e in out:
            _check_endpoint(e, allow_remote=True)
        return tuple(out)

    listen, connect = endpoints("listen"), endpoints("connect")
    if not listen and not connect:
        raise ValueError(
            f"bad zenoh URL {url!r}: needs listen=ENDPOINT and/or connect=ENDPOINT "
            "(scouting is disabled, so there is no other way to find the peer)"
        )
    modes = query.get("mode", ["peer"])
    if len(modes) != 1 or modes[0] not in ("peer", "client"):
        raise ValueError(f"bad zenoh URL {url!r}: mode must be peer or client")
    low = query.get("lowlatency", ["0"])
    if len(low) != 1 or low[0] not in ("0", "1"):
        raise ValueError(f"bad zenoh URL {url!r}: lowlatency must be 0 or 1")
    return LinkUrl(
        scheme="zenoh",
        vehicle=vehicle,
        link=link,
        direction=direction,
        listen=listen,
        connect=connect,
        mode=modes[0],
        lowlatency=low[0] == "1",
    )


class ZenohTransport(Transport):
    """Publishes on ``vtolftc/<vehicle>/<link>/<direction>``, subscribes to the opposite one.

    Parameters
    ----------
    vehicle, link
        key-expression chunks ([A-Za-z0-9_-]+).
    direction
        ``up`` or ``down``, the direction this end publishes.
    listen, connect
        zenoh endpoints (loopback unless ``allow_remote``).
    mode
        ``peer`` (embedded, default) or ``client`` (through a router).
    allow_remote
        permit non-loopback endpoints.
    queue_max
        received samples kept before new ones are dropped (counted; ``"channel"``: before
        zenoh's thread waits).
    receive
        ``"callback"`` or ``"channel"`` (see the module docstring).
    lowlatency
        zenoh's low-latency unicast transport (see the module docstring; both ends).

    Raises
    ------
    ValueError
        bad names or endpoints.
    OSError
        the session could not be opened (e.g. listen port in use).
    """

    kind = "zenoh"

    def __init__(
        self,
        vehicle: str,
        link: str,
        direction: str,
        *,
        listen: tuple[str, ...] | list[str] = (),
        connect: tuple[str, ...] | list[str] = (),
        mode: str = "peer",
        allow_remote: bool = False,
        queue_max: int = DEFAULT_QUEUE_MAX,
        receive: str = "callback",
        lowlatency: bool = False,
    ) -> None:
        import zenoh

        if receive not in RECEIVE_MODES:
            raise ValueError(f"zenoh receive mode must be one of {RECEIVE_MODES}, got "
                             f"{receive!r}")
        self.receive = receive
        self.pub_key = key_expr(vehicle, link, direction)
        self.sub_key = key_expr(vehicle, link, DIRECTIONS[direction])
        self.lowlatency = bool(lowlatency)
        cfg = zenoh_config(listen=listen, connect=connect, mode=mode, allow_remote=allow_remote,
                           lowlatency=self.lowlatency)
        self._endpoints = (tuple(listen), tuple(connect))
        self._queue: queue.SimpleQueue[bytes] = queue.SimpleQueue()
        self._queue_max = int(queue_max)
        self._overflow = 0
        self._closed = False
        try:
            self._session = zenoh.open(cfg)
        except zenoh.ZError as exc:  # e.g. listen port in use: same error class as UDP's bind
            raise OSError(f"cannot open zenoh session ({self.describe()}): {exc}") from exc
        self._wake_at = math.inf
        """Channel mode: monotonic time at which the watchdog ends the receiver's wait."""
        self._watch_next = math.inf
        """Channel mode: monotonic time of the watchdog's next look at :attr:`_wake_at`."""
        self._kick = threading.Event()
        self._watchdog: threading.Thread | None = None
        try:
            channel = receive == "channel"
            self._sub = self._session.declare_subscriber(
                self.sub_key,
                zenoh.handlers.FifoChannel(self._queue_max) if channel else self._on_sample)
            self._pub = self._session.declare_publisher(
                self.pub_key,
                congestion_control=zenoh.CongestionControl.BLOCK,
                reliability=zenoh.Reliability.RELIABLE,
                express=True,
            )
            if channel:
                self._waker = self._session.declare_publisher(
                    self.sub_key, allowed_destination=zenoh.Locality.SESSION_LOCAL)
                self._watchdog = threading.Thread(target=self._watch, daemon=True,
                                                  name="zenoh-recv-watchdog")
                self._watchdog.start()
        except BaseException:
            self._closed = True
            self._session.close()
            raise

    def _watch(self) -> None:
        """Channel mode, watchdog thread: end a wait that reached its deadline (an empty
        payload to this session's own subscriber)."""
        kick = self._kick
        while not self._closed:
            now = time.monotonic()
            self._watch_next = now + _WATCH_S  # before reading the deadline: see _recv_channel
            wake_at = self._wake_at
            if now >= wake_at:
                self._wake_at = math.inf
                with contextlib.suppress(Exception):
                    self._waker.put(b"")
                continue
            self._watch_next = look = min(wake_at, now + _WATCH_S)
            kick.wait(look - now)
            kick.clear()

    def _on_sample(self, sample: Any) -> None:
        """zenoh callback thread: queue the payload (bounded)."""
        q = self._queue
        if q.qsize() >= self._queue_max:
            self._overflow += 1
            return
        q.put(sample.payload.to_bytes())

    @property
    def overflow_drops(self) -> int:
        """Samples dropped because the receive queue was full."""
        return self._overflow

    def send_bytes(self, data: bytes) -> bool:
        """Publish one datagram; False once closed."""
        if self._closed:
            return False
        self._pub.put(data)
        return True

    def recv_datagrams(self, timeout_s: float | None) -> list[bytes]:
        """See :meth:`Transport.recv_datagrams`."""
        if self._watchdog is not None:
            return self._recv_channel(timeout_s)
        q = self._queue
        out: list[bytes] = []
        try:
            if timeout_s is not None and timeout_s <= 0.0:
                out.append(q.get_nowait())
            else:
                out.append(q.get(timeout=timeout_s))
            while len(out) < MAX_BATCH:
                out.append(q.get_nowait())
        except queue.Empty:
            pass
        return out

    def _recv_channel(self, timeout_s: float | None) -> list[bytes]:
        """Channel mode: every payload the channel has, waiting up to ``timeout_s`` for the
        first (the watchdog's empty payloads end a wait and are dropped)."""
        out: list[bytes] = []
        if self._closed:
            return out
        sub = self._sub
        try:
            sample = sub.try_recv()
            if sample is None:
                if timeout_s is not None and timeout_s <= 0.0:
                    return out
                self._wake_at = wake_at = time.monotonic() + (
                    0.25 if timeout_s is None else timeout_s)
                if wake_at < self._watch_next:  # the watchdog would look too late: wake it
                    self._kick.set()
                try:
                    sample = sub.recv()
                finally:
                    self._wake_at = math.inf
            while sample is not None:
                data = sample.payload.to_bytes()
                if data:
                    out.append(data)
                    if len(out) >= MAX_BATCH:
                        break
                sample = sub.try_recv()
        except Exception:  # the subscriber is gone (closed meanwhile)
            if not self._closed:
                raise
        return out

    def ready(self) -> bool:
        """True when at least one remote subscriber matches our publisher."""
        if self._closed:
            return False
        return bool(self._pub.matching_status.matching)

    def close(self) -> None:
        """Undeclare, close the session and wake a blocked receiver. Idempotent."""
        if self._closed:
            return
        self._closed = True
        if self._watchdog is not None:  # (undeclaring the subscriber wakes its receiver)
            self._kick.set()
            self._watchdog.join(timeout=1.0)
        for entity in (self._sub, self._pub):
            with contextlib.suppress(Exception):
                entity.undeclare()
        with contextlib.suppress(Exception):
            self._session.close()
        self._queue.put(b"")  # wake a recv() blocked in q.get()

    def describe(self) -> str:
        """``zenoh pub=... sub=... listen=... connect=...``."""
        listen, connect = self._endpoints
        return (
            f"zenoh pub={self.pub_key} sub={self.sub_key} "
            f"listen={list(listen)} connect={list(connect)}"
            + (" lowlatency" if self.lowlatency else "")
        )

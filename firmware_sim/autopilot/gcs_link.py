"""Link handling of the ground-station endpoint (PX4: ``mavlink_receiver`` and the link side of
``mavlink_main``): receive queues, per-client rate limits, partner liveness, sending.

:class:`GcsLinks` owns the ground-station links of
:class:`~vtolftc.firmware_sim.autopilot.gcs_endpoint.GcsEndpoint`:

- one receiver per link (:meth:`GcsLinks.receive_loop`, run in its own thread by the endpoint)
  parses frames into a bounded per-link queue; when it is full the oldest message is dropped
  (``queue_dropped`` in :meth:`GcsLinks.stats`);
- :meth:`GcsLinks.serve` (the endpoint's worker thread) takes at most ``budget_per_cycle``
  messages per call, round robin over the links, passes each client (link, system,
  component) through a token bucket (``rate_limit_hz`` sustained, ``rate_burst`` burst;
  excess dropped, counted as ``rate_limited``) and hands it to the handler of its type;
- partners: a ground-station HEARTBEAT (signed when signing is on) or a command addressed to
  this autopilot proves the link (:attr:`GcsLinks.last_gcs_heartbeat`, monotonic seconds,
  read by the data-link-loss failsafe);
- sending (worker thread only: one sender per link keeps sequence numbers and signing
  timestamps consistent): :meth:`GcsLinks.send_all` and :meth:`GcsLinks.statustext` (chunked
  as MAVLink 2 specifies).

Signing itself is checked by the links (:mod:`vtolftc.protocols.mavlink`): a frame without a
valid signature never reaches the queues unless its id is allowed unsigned.
"""

from __future__ import annotations

import collections
import math
import time
from collections.abc import Callable, Sequence
from dataclasses import dataclass
from typing import Any

from vtolftc.protocols.generated import constants as mav
from vtolftc.protocols.link import Link

__all__ = ["GcsLinks", "Handler"]

MAV_TYPE_GCS = mav.MAV_TYPE_GCS
SEVERITY_WARNING, SEVERITY_INFO = mav.MAV_SEVERITY_WARNING, mav.MAV_SEVERITY_INFO
STATUSTEXT_BYTES = 50
"""Bytes of STATUSTEXT's ``text`` field (a longer text goes out in chunks)."""

Handler = Callable[[int, Link, Any], None]
"""Handler of one received message: ``f(link_index, link, msg)``, run in the worker thread."""


@dataclass
class _Client:
    """Token bucket of one ground-station client (link, system, component)."""

    tokens: float
    last: float


class GcsLinks:
    """The ground-station links, their receive queues and their sending (module docstring).

    Parameters
    ----------
    links
        ground-station links (closed by :meth:`close`).
    signing_required
        only signed heartbeats and commands count as a ground station's liveness.
    rate_limit_hz, rate_burst
        per-client token bucket (messages per second of wall-clock time, burst).
    queue_len
        per-link receive queue (drop-oldest).
    budget_per_cycle
        messages :meth:`serve` handles per call.
    """

    def __init__(self, links: Sequence[Link], *, signing_required: bool = False,
                 rate_limit_hz: float = 50.0, rate_burst: float = 100.0, queue_len: int = 512,
                 budget_per_cycle: int = 32) -> None:
        self.links = list(links)
        self.signing_required = signing_required
        self.rate_limit_hz = float(rate_limit_hz)
        self.rate_burst = float(rate_burst)
        self.budget_per_cycle = int(budget_per_cycle)
        n = len(self.links)
        self.queues: list[collections.deque[Any]] = [collections.deque(maxlen=queue_len)
                                                     for _ in range(n)]
        """Receive queue of each link (drop-oldest; filled by :meth:`receive_loop`)."""
        self.counters = [{"queue_dropped": 0, "rate_limited": 0, "handled": 0,
                          "control_dropped": 0} for _ in range(n)]
        """Drops and handled messages of each link (see :meth:`stats`)."""
        self.last_gcs_heartbeat = -math.inf
        """monotonic time of the last (signed, if signing is on) ground-station HEARTBEAT or
        command addressed to this autopilot."""
        self.closed = False
        self._clients: dict[tuple[int, int, int], _Client] = {}
        self._statustext_id = 0

    @property
    def codec(self) -> Any:
        """The codec of the first link (the frames are the same on every link), or None."""
        return self.links[0].codec if self.links else None

    # ------------------------------------------------------------------ receive
    def receive_loop(self, index: int) -> None:
        """Receiver thread of link ``index``: parse frames into its queue until :meth:`close`."""
        link = self.links[index]
        q = self.queues[index]
        cnt = self.counters[index]
        while not self.closed:
            try:
                msgs = link.recv(0.25)
            except Exception:
                if self.closed:
                    return
                time.sleep(0.05)
                continue
            for m in msgs:
                if len(q) == q.maxlen:
                    cnt["queue_dropped"] += 1  # the append drops the oldest
                q.append(m)

    def allow(self, index: int, msg: Any, now: float) -> bool:
        """Token bucket of the client that sent ``msg`` on link ``index`` at ``now`` [s]."""
        key = (index, msg.get_srcSystem(), msg.get_srcComponent())
        c = self._clients.get(key)
        if c is None:
            if len(self._clients) > 4096:  # a flood of made-up ids: forget the idle ones
                self._clients = {k: v for k, v in self._clients.items() if now - v.last < 10}
            c = self._clients[key] = _Client(self.rate_burst, now)
        c.tokens = min(self.rate_burst, c.tokens + (now - c.last) * self.rate_limit_hz)
        c.last = now
        if c.tokens < 1.0:
            return False
        c.tokens -= 1.0
        return True

    def serve(self, handlers: dict[str, Handler]) -> int:
        """Worker: hand queued messages (within the budget, rate-limited) to ``handlers`` by
        message type; a handler's exception is reported as a STATUSTEXT. Returns the number
        of messages handled."""
        budget = self.budget_per_cycle
        handled = 0
        now = time.monotonic()
        active = True
        while handled < budget and active:
            active = False
            for index, q in enumerate(self.queues):
                if handled >= budget:
                    break
                try:
                    msg = q.popleft()
                except IndexError:
                    continue
                active = True
                cnt = self.counters[index]
                if not self.allow(index, msg, now):
                    cnt["rate_limited"] += 1
                    continue
                handled += 1
                cnt["handled"] += 1
                handler = handlers.get(msg.get_type())
                if handler is None:
                    continue
                try:
                    handler(index, self.links[index], msg)
                except Exception as exc:  # one bad message must not stop the endpoint
                    self.statustext(f"error handling {msg.get_type()}: {exc}",
                                    SEVERITY_WARNING)
        return handled

    # ------------------------------------------------------------------ partners
    def on_heartbeat(self, index: int, link: Link, msg: Any) -> None:
        """HEARTBEAT handler: a ground station's (signed, if required) proves the link."""
        if int(msg.type) == MAV_TYPE_GCS and (not self.signing_required or msg.get_signed()):
            self.last_gcs_heartbeat = time.monotonic()

    def seen_partner(self, msg: Any) -> None:
        """A command from a ground station proves the link as its heartbeat does."""
        if not self.signing_required or msg.get_signed():
            self.last_gcs_heartbeat = time.monotonic()

    # ------------------------------------------------------------------ sending (worker)
    def send_all(self, msg: Any) -> None:
        """Worker: ``msg`` on every link."""
        for link in self.links:
            link.send(msg)

    def send(self, msg: Any, link: Link | None) -> None:
        """Worker: ``msg`` on ``link``, or on every link if ``link`` is None."""
        if link is None:
            self.send_all(msg)
        else:
            link.send(msg)

    def statustext(self, text: str, severity: int = SEVERITY_INFO,
                   link: Link | None = None) -> None:
        """Worker: STATUSTEXT to one link or to all. A text longer than the field's 50 bytes
        goes out in chunks as MAVLink 2 specifies: one ``id`` (1..65535) for all of them,
        ``chunk_seq`` 0, 1, ..., the last chunk shorter than 50 bytes (an empty one if
        needed)."""
        codec = self.codec
        if codec is None:
            return
        data = text.encode("utf-8", errors="replace")
        n = STATUSTEXT_BYTES
        if len(data) <= n:
            msgs = [codec.statustext_encode(severity, data)]
        else:
            self._statustext_id = self._statustext_id % 65535 + 1
            chunks = [data[i:i + n] for i in range(0, len(data), n)][:255]
            if len(chunks[-1]) == n:
                chunks.append(b"")
            msgs = [codec.statustext_encode(severity, c, self._statustext_id, k)
                    for k, c in enumerate(chunks)]
        for msg in msgs:
            self.send(msg, link)

    # ------------------------------------------------------------------ lifetime, counters
    def stats(self) -> list[dict[str, Any]]:
        """Counters of every link (garbage, CRC, truncated, signature ... drops of the link;
        queue, rate-limit and control-queue drops of the endpoint)."""
        return [{"link": repr(link), **link.stats.as_dict(), **self.counters[i]}
                for i, link in enumerate(self.links)]

    def stop(self) -> None:
        """Tell the receivers to end (they return within their 0.25 s receive timeout)."""
        self.closed = True

    def close(self) -> None:
        """Stop the receivers and close every link."""
        self.closed = True
        for link in self.links:
            link.close()

"""The transport interface under every :class:`~vtolftc.protocols.link.Link`, and parsed URLs.

A :class:`Transport` moves whole datagrams and knows nothing about MAVLink; the UDP
(:mod:`vtolftc.protocols.udp`) and zenoh (:mod:`vtolftc.protocols.zenoh_transport`) transports
implement it. :class:`LinkUrl` is a parsed link URL (the scheme is described in
:mod:`vtolftc.protocols.link`). Both live here, below the link and the transports, so that no
import runs in a circle.
"""

from __future__ import annotations

from abc import ABC, abstractmethod
from dataclasses import dataclass

__all__ = ["MAX_BATCH", "LinkUrl", "LoopTransport", "Transport"]

MAX_BATCH = 256
"""Most datagrams one :meth:`Transport.recv_datagrams` call returns; a call that returns
fewer read everything the transport had."""


class Transport(ABC):
    """Moves whole datagrams; knows nothing about MAVLink. Subclasses: UDP, zenoh."""

    kind: str = "?"

    @abstractmethod
    def send_bytes(self, data: bytes) -> bool:
        """Hand one datagram to the network. False if there is nowhere to send it (dropped)."""

    @abstractmethod
    def recv_datagrams(self, timeout_s: float | None) -> list[bytes]:
        """Wait up to ``timeout_s`` (None = forever, 0 = poll) for at least one datagram, then
        return every datagram already available (at most :data:`MAX_BATCH`: fewer means
        nothing else was available); ``[]`` on timeout."""

    @abstractmethod
    def ready(self) -> bool:
        """True if a datagram sent now has a destination (peer known / subscriber matched)."""

    @abstractmethod
    def close(self) -> None:
        """Release sockets / sessions. Idempotent."""

    @property
    def local_address(self) -> tuple[str, int] | None:
        """Bound address for socket transports, None otherwise."""
        return None

    @property
    def overflow_drops(self) -> int:
        """Datagrams dropped by the transport's own receive queue (if it has one)."""
        return 0

    foreign_drops: int = 0
    """Datagrams dropped because they came from another address than the pinned peer."""

    def recv_datagrams_from(self, timeout_s: float | None) -> list[tuple[bytes, object]]:
        """:meth:`recv_datagrams` with each datagram's source address (None where the
        transport has no addresses, e.g. zenoh)."""
        return [(d, None) for d in self.recv_datagrams(timeout_s)]

    def pin(self, addr: object) -> None:
        """Talk to ``addr`` only (see :meth:`vtolftc.protocols.udp.UdpServerTransport.pin`).
        Transports without addresses ignore it."""
        return None

    def describe(self) -> str:
        """Human-readable endpoint description."""
        return self.kind


class LoopTransport(Transport):
    """An in-memory transport that hands back what it is sent, in order: for tests and
    benchmarks that drive a :class:`~vtolftc.protocols.link.Link` without a network (a
    datagram sent now is received by the next :meth:`recv_datagrams`)."""

    kind = "loop"

    def __init__(self) -> None:
        self.queue: list[bytes] = []

    def send_bytes(self, data: bytes) -> bool:
        self.queue.append(data)
        return True

    def recv_datagrams(self, timeout_s: float | None) -> list[bytes]:
        """Every queued datagram, at most :data:`MAX_BATCH`; never waits (``timeout_s`` is
        ignored: nothing can arrive while the caller waits)."""
        out, self.queue = self.queue[:MAX_BATCH], self.queue[MAX_BATCH:]
        return out

    def ready(self) -> bool:
        return True

    def close(self) -> None:
        """Nothing to release."""


@dataclass(frozen=True)
class LinkUrl:
    """A parsed link URL (see the module docstring for the scheme)."""

    scheme: str
    host: str = ""
    port: int = 0
    vehicle: str = ""
    link: str = ""
    direction: str = ""
    listen: tuple[str, ...] = ()
    connect: tuple[str, ...] = ()
    mode: str = "peer"
    lowlatency: bool = False

"""An in-memory MAVLink transport for unit tests: it keeps what a link sends and receives
nothing, so a test can drive an endpoint and read back every frame it sent."""

from __future__ import annotations

from typing import Any

from vtolftc.protocols import Link
from vtolftc.protocols.transport import LoopTransport


class CaptureTransport(LoopTransport):
    """Keeps every datagram sent (``sent``); never receives anything."""

    kind = "memory"

    @property
    def sent(self) -> list[bytes]:
        """Every datagram sent so far (the list itself: clear it to forget them)."""
        return self.queue

    def recv_datagrams(self, timeout_s: float | None) -> list[bytes]:
        return []


def parse(datagrams: list[bytes]) -> list[Any]:
    """The MAVLink messages in ``datagrams``, decoded by a link of their own."""
    reader = Link(CaptureTransport())
    out: list[Any] = []
    for d in datagrams:
        reader._parse_datagram(d, out)
    return out


def sent_messages(transport: CaptureTransport) -> list[Any]:
    """What ``transport`` sent since the last call, decoded (and forgotten)."""
    out = parse(transport.sent)
    transport.sent.clear()
    return out

"""An in-memory MAVLink transport for unit tests: it keeps what a link sends and receives
nothing, so a test can drive an endpoint and read back every frame it sent."""

from __future__ import annotations

from typing import Any

from vtolftc.protocols import Link, Transport


class CaptureTransport(Transport):
    """Keeps every datagram sent (``sent``); never receives anything."""

    kind = "memory"

    def __init__(self) -> None:
        self.sent: list[bytes] = []

    def send_bytes(self, data: bytes) -> bool:
        self.sent.append(data)
        return True

    def recv_datagrams(self, timeout_s: float | None) -> list[bytes]:
        return []

    def ready(self) -> bool:
        return True

    def close(self) -> None:
        pass


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

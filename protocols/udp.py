"""UDP transports (loopback by default).

* :class:`UdpServerTransport` binds HOST:PORT and replies to the last peer it heard from, like
  PX4's ground-station port (14550); once :meth:`UdpServerTransport.pin` was called with an
  address, it talks to that address only and drops (and counts) every datagram from elsewhere
  (the vehicle pins its autopilot this way).
* :class:`UdpClientTransport` sends to HOST:PORT from an ephemeral local port and reads only
  datagrams coming from HOST:PORT (a connected UDP socket).

Both refuse non-loopback addresses unless built with ``allow_remote=True``. Sockets are
non-blocking; a receive first tries the socket and only waits in ``select`` when it is empty, so
the hot path is one system call per datagram.
"""

from __future__ import annotations

import contextlib
import select
import socket

from vtolftc.protocols.netutil import require_loopback, resolve_host
from vtolftc.protocols.transport import MAX_BATCH, Transport

__all__ = ["MAX_BATCH", "UdpClientTransport", "UdpServerTransport"]
_MAX_DATAGRAM = 65535
_SOCKET_BUFFER = 1 << 20


def _make_socket(host: str) -> socket.socket:
    family = socket.AF_INET6 if ":" in host else socket.AF_INET
    sock = socket.socket(family, socket.SOCK_DGRAM)
    for opt in (socket.SO_RCVBUF, socket.SO_SNDBUF):
        with contextlib.suppress(OSError):  # platform limits
            sock.setsockopt(socket.SOL_SOCKET, opt, _SOCKET_BUFFER)
    return sock


class _UdpBase(Transport):
    """Shared receive loop of the two UDP transports."""

    def __init__(self, sock: socket.socket) -> None:
        self._sock = sock
        self._closed = False
        sock.setblocking(False)

    def _on_datagram_from(self, addr: tuple[str, int]) -> bool:
        """Hook: the server remembers the peer. False drops the datagram."""
        return True

    def recv_datagrams(self, timeout_s: float | None) -> list[bytes]:
        """See :meth:`Transport.recv_datagrams`."""
        return [d for d, _ in self.recv_datagrams_from(timeout_s)]

    def recv_datagrams_from(self, timeout_s: float | None) -> list[tuple[bytes, object]]:
        """See :meth:`Transport.recv_datagrams_from`."""
        if self._closed:
            return []
        sock = self._sock
        out: list[tuple[bytes, object]] = []
        n = 0
        try:
            try:
                data, addr = sock.recvfrom(_MAX_DATAGRAM)
            except BlockingIOError:
                if timeout_s is not None and timeout_s <= 0.0:
                    return out
                ready, _, _ = select.select([sock], [], [], timeout_s)
                if not ready:
                    return out
                data, addr = sock.recvfrom(_MAX_DATAGRAM)
            n += 1
            if self._on_datagram_from(addr):
                out.append((data, addr))
            while n < MAX_BATCH:
                data, addr = sock.recvfrom(_MAX_DATAGRAM)
                n += 1
                if self._on_datagram_from(addr):
                    out.append((data, addr))
        except (BlockingIOError, InterruptedError):
            pass
        except ConnectionRefusedError:
            # ICMP port-unreachable from an earlier send (peer not up yet): not an error here
            pass
        except OSError:
            if not self._closed:
                raise
        return out

    @property
    def local_address(self) -> tuple[str, int] | None:
        """Bound (host, port)."""
        if self._closed:
            return None
        name = self._sock.getsockname()
        return (str(name[0]), int(name[1]))

    def close(self) -> None:
        """Close the socket. Idempotent."""
        if not self._closed:
            self._closed = True
            self._sock.close()


class UdpServerTransport(_UdpBase):
    """Bound to HOST:PORT; sends to the last peer heard from (nothing before the first one)."""

    kind = "udp-server"

    def __init__(self, host: str, port: int, *, allow_remote: bool = False) -> None:
        require_loopback(host, allow_remote=allow_remote, what="udp-server bind address")
        addr = resolve_host(host)
        sock = _make_socket(addr)
        try:
            sock.bind((addr, int(port)))
        except BaseException:
            sock.close()
            raise
        super().__init__(sock)
        self._peer: tuple[str, int] | None = None
        self._pinned = False
        self.foreign_drops = 0
        """Datagrams dropped because they came from another address than the pinned one."""

    @property
    def peer(self) -> tuple[str, int] | None:
        """Last peer heard from (where sends go), None before the first datagram."""
        return self._peer

    @property
    def pinned(self) -> tuple[str, int] | None:
        """The pinned peer address, None while not pinned."""
        return self._peer if self._pinned else None

    def pin(self, addr: object) -> None:
        """Talk to ``addr`` only from now on: sends go there, datagrams from any other
        address are dropped and counted in :attr:`foreign_drops`."""
        host, port = addr[0], addr[1]  # type: ignore[index]
        self._peer = (str(host), int(port))
        self._pinned = True

    def _on_datagram_from(self, addr: tuple[str, int]) -> bool:
        if self._pinned:
            if (addr[0], addr[1]) != self._peer:
                self.foreign_drops += 1
                return False
            return True
        self._peer = addr
        return True

    def send_bytes(self, data: bytes) -> bool:
        """Send to the last peer; False (dropped) if none yet or on a socket error."""
        peer = self._peer
        if peer is None or self._closed:
            return False
        try:
            self._sock.sendto(data, peer)
        except (BlockingIOError, ConnectionRefusedError):
            return False
        return True

    def ready(self) -> bool:
        """True once a peer has been heard from."""
        return self._peer is not None

    def describe(self) -> str:
        """``udp-server host:port (peer ...)``."""
        return f"udp-server {self.local_address} peer={self._peer}"


class UdpClientTransport(_UdpBase):
    """Sends to HOST:PORT from an ephemeral port on the matching loopback address."""

    kind = "udp-client"

    def __init__(self, host: str, port: int, *, allow_remote: bool = False) -> None:
        require_loopback(host, allow_remote=allow_remote, what="udp-client target address")
        addr = resolve_host(host)
        sock = _make_socket(addr)
        try:
            sock.connect((addr, int(port)))  # also binds an ephemeral local port
        except BaseException:
            sock.close()
            raise
        super().__init__(sock)
        self._target = (addr, int(port))

    def send_bytes(self, data: bytes) -> bool:
        """Send to the server; False (dropped) on a socket error (e.g. server not up yet)."""
        if self._closed:
            return False
        try:
            self._sock.send(data)
        except (BlockingIOError, ConnectionRefusedError):
            return False
        return True

    def ready(self) -> bool:
        """Always True: the destination is fixed."""
        return not self._closed

    def describe(self) -> str:
        """``udp-client -> host:port``."""
        return f"udp-client {self.local_address} -> {self._target}"

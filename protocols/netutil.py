"""Address helpers shared by the transports: loopback policy and free-port picking."""

from __future__ import annotations

import ipaddress
import socket

__all__ = ["free_tcp_port", "free_udp_port", "is_loopback_host", "require_loopback", "resolve_host"]


def resolve_host(host: str) -> str:
    """Numeric address for ``host``; ``localhost`` maps to ``127.0.0.1`` without DNS."""
    host = host.strip("[]")
    if host.lower() == "localhost":
        return "127.0.0.1"
    try:
        return str(ipaddress.ip_address(host))
    except ValueError:
        return socket.gethostbyname(host)


def is_loopback_host(host: str) -> bool:
    """True if ``host`` is ``localhost`` or a literal loopback address (127/8, ::1).

    Names other than ``localhost`` are never resolved here, so they count as non-loopback.
    """
    host = host.strip("[]")
    if host.lower() == "localhost":
        return True
    try:
        return ipaddress.ip_address(host).is_loopback
    except ValueError:
        return False


def require_loopback(host: str, *, allow_remote: bool, what: str) -> None:
    """Raise ValueError unless ``host`` is loopback or ``allow_remote`` is set."""
    if not allow_remote and not is_loopback_host(host):
        raise ValueError(
            f"{what} {host!r} is not a loopback address; vtol-ftc links stay on 127.0.0.1 "
            "unless opened with allow_remote=True"
        )


def _free_port(kind: int) -> int:
    with socket.socket(socket.AF_INET, kind) as s:
        s.bind(("127.0.0.1", 0))
        return int(s.getsockname()[1])


def free_udp_port() -> int:
    """A UDP port on 127.0.0.1 that was free a moment ago (racy: retry on EADDRINUSE)."""
    return _free_port(socket.SOCK_DGRAM)


def free_tcp_port() -> int:
    """A TCP port on 127.0.0.1 that was free a moment ago (racy: retry on EADDRINUSE)."""
    return _free_port(socket.SOCK_STREAM)

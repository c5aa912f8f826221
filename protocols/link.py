"""Links that carry MAVLink 2 frames, with one code path above the transport.

A :class:`Link` owns a codec of the vtol-ftc dialect (see :mod:`vtolftc.protocols.mavlink`) and a
:class:`Transport` that moves whole datagrams (one or more MAVLink frames each). Packing, parsing,
signing and the counters live in :class:`Link`; the transports (:mod:`vtolftc.protocols.udp`,
:mod:`vtolftc.protocols.zenoh_transport`) only move bytes. Every datagram is parsed on its own with
the
generated parser in robust mode: garbage, frames with a bad CRC (or bad header flags), frames cut
short at the end of a datagram, frames rejected by signing and frames of unknown message ids are
dropped and counted in :class:`LinkStats`, never raised; after a corrupt frame the parser re-syncs
on the next start-of-frame byte, so a valid frame that follows garbage in the same datagram still
gets through.

URL scheme of :func:`open_link`
    ``udp-server://HOST:PORT``
        Bind a UDP socket to HOST:PORT (PORT 0 = ephemeral, see ``Link.local_address``) and
        reply to the last peer heard from, like PX4's ground-station port 14550. Sends before any
        peer was heard are dropped and counted (``send_dropped``).
    ``udp-client://HOST:PORT``
        Send to HOST:PORT from an ephemeral local port; only datagrams from HOST:PORT are read.
    ``zenoh://VEHICLE/LINK/DIRECTION?listen=EP&connect=EP[&mode=peer|client][&lowlatency=1]``
        Embedded zenoh session (peer mode by default, multicast scouting off). This end
        publishes raw frames on ``vtolftc/VEHICLE/LINK/DIRECTION`` and subscribes to the opposite
        direction (``up`` <-> ``down``). EP is a zenoh endpoint such as ``tcp/127.0.0.1:7447``;
        ``listen`` and ``connect`` may be repeated or comma-separated, and at least one endpoint
        is required (there is no discovery). Direction convention: ``up`` flows from the physics
        toward the operator, ``down`` toward the physics; on the HIL link the vehicle simulator
        publishes ``up`` (HIL_SENSOR, HIL_GPS, HIL_STATE_QUATERNION) and the autopilot ``down``
        (HIL_ACTUATOR_CONTROLS); on a ground-station link the autopilot publishes ``up``
        (telemetry, COMMAND_ACK) and the ground station ``down`` (commands). ``lowlatency=1``
        (both ends): zenoh's low-latency unicast transport (see
        :mod:`vtolftc.protocols.zenoh_transport`).

    HOST must be a loopback address (``127.x.x.x``, ``::1`` written ``[::1]``, or ``localhost``)
    unless ``allow_remote=True`` is passed to :func:`open_link`; a URL alone can never open a
    link off the machine.
"""

from __future__ import annotations

import collections
import time
from collections.abc import Callable, Iterable
from dataclasses import dataclass, fields
from types import TracebackType
from typing import Any
from urllib.parse import urlsplit

from vtolftc.protocols.fastparse import FastParser
from vtolftc.protocols.mavlink import SigningConfig, StreamTimestamps, dialect, make_codec
from vtolftc.protocols.transport import MAX_BATCH, LinkUrl, Transport

__all__ = [
    "Link",
    "LinkStats",
    "LinkUrl",
    "Transport",
    "open_link",
    "parse_link_url",
]

_HEADER_LEN_V1_PLUS_CRC = 8  # parser's "expected length" reset value (generated code: V1 + 2)
_BAD_PREFIX = "Bad prefix"
_BAD_SIGNATURE = "Invalid signature"


@dataclass
class LinkStats:
    """Counters of a :class:`Link` (all monotonically increasing)."""

    frames_sent: int = 0
    bytes_sent: int = 0
    send_dropped: int = 0
    """Frames not sent: no destination yet (UDP server with no peer) or an OS send error."""
    datagrams_received: int = 0
    frames_received: int = 0
    """Valid frames handed to the caller."""
    bytes_received: int = 0
    """All received bytes, garbage included."""
    dropped_garbage: int = 0
    """Runs of bytes that are not part of any frame (one count per run)."""
    dropped_crc: int = 0
    """Frames with a bad checksum, bad incompat flags or an undecodable payload."""
    dropped_truncated: int = 0
    """Incomplete frames at the end of a datagram."""
    dropped_signature: int = 0
    """Frames rejected by MAVLink 2 signing (bad signature, or unsigned when not allowed)."""
    dropped_unknown: int = 0
    """Well-framed messages whose id is not in the dialect (their CRC cannot be checked)."""
    dropped_overflow: int = 0
    """Datagrams dropped because the transport's receive queue was full."""
    dropped_foreign: int = 0
    """Datagrams dropped because they came from another address than the pinned peer."""
    dropped_rate: int = 0
    """Datagrams dropped unparsed by the link's receive rate limit (``rate_limit_hz``)."""

    @property
    def dropped(self) -> int:
        """All received frames/runs dropped, whatever the reason."""
        return (
            self.dropped_garbage
            + self.dropped_crc
            + self.dropped_truncated
            + self.dropped_signature
            + self.dropped_unknown
            + self.dropped_overflow
            + self.dropped_foreign
            + self.dropped_rate
        )

    def as_dict(self) -> dict[str, int]:
        """Counters as a plain dict (for logs and JSON)."""
        d = {f.name: getattr(self, f.name) for f in fields(self)}
        d["dropped"] = self.dropped
        return d


class Link:
    """A MAVLink 2 endpoint over any :class:`Transport`.

    Parameters
    ----------
    transport
        the byte mover (owned: closed with the link).
    system_id, component_id
        source ids of frames packed by :meth:`send`.
    signing
        MAVLink 2 signing for outgoing frames and verification of incoming ones.
    keep_unknown
        pass messages of unknown ids to the caller (as ``MAVLink_unknown``)
        instead of dropping them.
    codec
        use this generated ``MAVLink`` object instead of making one (ids and signing
        arguments are then ignored).
    track_source
        remember each message's source address (:meth:`source_of`), so that a
        server can :meth:`pin` its peer.
    stream_table
        the signing replay window, shared with other links (see
        :class:`vtolftc.protocols.mavlink.StreamTimestamps`).
    rate_limit_hz, rate_burst
        receive at most this many datagrams per second (token
        bucket, ``rate_burst`` default twice the rate); the excess is dropped before it is
        parsed (counted as ``dropped_rate``), so a flood costs little more than the read.

    One thread may send while another receives (the counters are then approximate, and with
    signing a send racing a receive may very rarely reuse a signing timestamp).
    """

    def __init__(
        self,
        transport: Transport,
        *,
        system_id: int = 255,
        component_id: int = 190,
        signing: SigningConfig | None = None,
        keep_unknown: bool = False,
        codec: Any = None,
        track_source: bool = False,
        stream_table: StreamTimestamps | None = None,
        rate_limit_hz: float | None = None,
        rate_burst: float | None = None,
    ) -> None:
        mod = dialect()
        self._rate = rate_limit_hz
        self._burst = float(rate_burst if rate_burst is not None else 2.0 * (rate_limit_hz or 0))
        self._tokens = self._burst
        self._tokens_t = time.monotonic()
        self._track_source = track_source
        self._transport = transport
        self._codec = codec if codec is not None else make_codec(
            system_id, component_id, signing=signing, stream_table=stream_table
        )
        self._codec.robust_parsing = True
        self._fast = FastParser(self._codec, mod)
        self._bad_data_cls = mod.MAVLink_bad_data
        self._unknown_cls = mod.MAVLink_unknown
        self._keep_unknown = keep_unknown
        self._stats = LinkStats()
        self._pending: collections.deque[Any] = collections.deque()
        self._drained = False
        self._closed = False

    # ---------------------------------------------------------------- properties
    @property
    def codec(self) -> Any:
        """The generated ``MAVLink`` object (use its ``*_encode`` helpers to build messages)."""
        return self._codec

    @property
    def mav(self) -> Any:
        """Alias of :attr:`codec` (pymavlink's ``mavfile.mav`` spelling)."""
        return self._codec

    @property
    def transport(self) -> Transport:
        """The underlying transport."""
        return self._transport

    @property
    def local_address(self) -> tuple[str, int] | None:
        """Bound (host, port) of a UDP link, None for zenoh."""
        return self._transport.local_address

    @property
    def stats(self) -> LinkStats:
        """Live counters (the same object is updated as traffic flows)."""
        self._stats.dropped_overflow = self._transport.overflow_drops
        self._stats.dropped_foreign = self._transport.foreign_drops
        return self._stats

    @property
    def drained(self) -> bool:
        """True if the last :meth:`recv` handed over everything the link had then: it read
        the transport, and the transport's batch was not full (see ``MAX_BATCH``). A reader
        that wants all that came (``HilBridge.drain``) then needs no second, empty read."""
        return self._drained

    @property
    def closed(self) -> bool:
        """True once :meth:`close` was called."""
        return self._closed

    def __repr__(self) -> str:
        return f"Link({self._transport.describe()}{', closed' if self._closed else ''})"

    def defer(self, ids: Iterable[int]) -> None:
        """Hand valid frames of these message ids over as
        :class:`~vtolftc.protocols.fastparse.RawFrame` (checked and counted as any frame,
        the message object made by ``RawFrame.message()`` when asked for) on the fast path;
        a datagram the generated parser handles still gives message objects."""
        self._fast.defer = frozenset(int(i) for i in ids)

    # ---------------------------------------------------------------- sending
    def send(self, msg: Any) -> int:
        """Send a message (packed with this link's ids, sequence and signing) or raw bytes.

        Raw bytes are sent as they are (use ``msg.get_msgbuf()`` to forward a received frame
        unchanged). Returns the number of bytes handed to the transport, 0 if dropped.
        """
        if isinstance(msg, bytes | bytearray | memoryview):
            data = bytes(msg)
        else:
            codec = self._codec
            data = msg.pack(codec)
            codec.seq = (codec.seq + 1) & 0xFF
        st = self._stats
        if self._transport.send_bytes(data):
            st.frames_sent += 1
            st.bytes_sent += len(data)
            return len(data)
        st.send_dropped += 1
        return 0

    # ---------------------------------------------------------------- peers
    @staticmethod
    def source_of(msg: Any) -> object:
        """Source address of a message received with ``track_source`` (None if unknown)."""
        return getattr(msg, "_vtolftc_source", None)

    def pin(self, addr: object) -> None:
        """Talk to ``addr`` only from now on (UDP server); see :meth:`Transport.pin`."""
        self._transport.pin(addr)

    # ---------------------------------------------------------------- receiving
    def _admit(self) -> bool:
        """Receive rate limit: take a token (False = drop the datagram unparsed)."""
        now = time.monotonic()
        self._tokens = min(self._burst, self._tokens + (now - self._tokens_t) * self._rate)
        self._tokens_t = now
        if self._tokens < 1.0:
            self._stats.dropped_rate += 1
            return False
        self._tokens -= 1.0
        return True

    def _read(self, timeout_s: float | None, out: list[Any]) -> None:
        """One transport read, parsed into ``out``."""
        limited = self._rate is not None
        if self._track_source:
            batch_from = self._transport.recv_datagrams_from(timeout_s)
            self._drained = len(batch_from) < MAX_BATCH
            for datagram, src in batch_from:
                if limited and datagram and not self._admit():
                    continue
                n = len(out)
                self._parse_datagram(datagram, out)
                for m in out[n:]:
                    m._vtolftc_source = src
        else:
            batch = self._transport.recv_datagrams(timeout_s)
            self._drained = len(batch) < MAX_BATCH
            for datagram in batch:
                if limited and datagram and not self._admit():
                    continue
                self._parse_datagram(datagram, out)

    def recv(self, timeout_s: float | None = 0.0) -> list[Any]:
        """Messages received, waiting up to ``timeout_s`` for the first one.

        ``0`` polls, ``None`` waits forever. Returns every valid message already available
        (possibly several), ``[]`` on timeout. Bad data is dropped and counted, never raised.
        """
        if self._pending:
            out = list(self._pending)
            self._pending.clear()
            self._drained = False  # the transport was not read
            return out
        out: list[Any] = []
        if timeout_s is None:  # wait in slices so that close() from another thread ends it
            while not out and not self._closed:
                self._read(0.25, out)
            return out
        deadline = time.monotonic() + max(0.0, timeout_s)
        remaining = max(0.0, timeout_s)
        while True:
            self._read(remaining, out)
            if out:
                return out
            remaining = deadline - time.monotonic()
            if remaining <= 0.0 or self._closed:
                return out

    def recv_match(
        self,
        msg_type: str | Iterable[str] | None = None,
        timeout_s: float = 1.0,
        condition: Callable[[Any], bool] | None = None,
    ) -> Any | None:
        """First message of the given type(s) satisfying ``condition``, or None on timeout.

        Messages received before the match that do not match are discarded (as pymavlink's
        ``recv_match`` does); messages received after it in the same batch are kept for the
        next :meth:`recv`.
        """
        types = {msg_type} if isinstance(msg_type, str) else (
            None if msg_type is None else set(msg_type)
        )
        deadline = time.monotonic() + timeout_s
        while True:
            batch = self.recv(max(0.0, deadline - time.monotonic()))
            for i, m in enumerate(batch):
                if (types is None or m.get_type() in types) and (
                    condition is None or condition(m)
                ):
                    self._pending.extend(batch[i + 1 :])
                    return m
            if time.monotonic() >= deadline or self._closed:
                return None

    def wait_ready(self, timeout_s: float = 5.0) -> bool:
        """Wait until a send has a destination: always at once for a UDP client, when the first
        datagram arrived for a UDP server, when a remote subscriber matched for zenoh.

        Messages received meanwhile are kept for the next :meth:`recv`.
        """
        deadline = time.monotonic() + timeout_s
        while not self._transport.ready():
            remaining = deadline - time.monotonic()
            if remaining <= 0.0:
                return False
            batch: list[Any] = []
            self._read(min(remaining, 0.005), batch)
            self._pending.extend(batch)
        return True

    def _parse_datagram(self, data: bytes, out: list[Any]) -> None:
        """Parse one datagram: valid frames through :class:`FastParser`, anything else with
        the generated robust parser, which drops and counts bad data."""
        if not data:  # also the wake-up sentinel of a closing transport
            return
        st = self._stats
        st.datagrams_received += 1
        st.bytes_received += len(data)
        fast = self._fast
        rejected = fast.rejected
        msgs = fast.parse(data)
        if msgs is not None:
            st.dropped_signature += fast.rejected - rejected
            st.frames_received += len(msgs)
            out.extend(msgs)
            return
        mav = self._codec
        buf = bytearray(data)
        mav.buf = buf
        mav.buf_index = 0
        mav.expected_length = _HEADER_LEN_V1_PLUS_CRC
        resync = False  # inside the remains of a corrupt frame: do not count again
        bad_cls = self._bad_data_cls
        try:
            while True:
                start = mav.buf_index
                m = mav.parse_char(b"")
                if m is None:
                    if mav.buf_len() == 0:
                        break
                    # an incomplete frame at the end of the datagram
                    if not resync:
                        st.dropped_truncated += 1
                        resync = True
                    mav.buf = buf
                    mav.buf_index = start + 1
                    mav.expected_length = _HEADER_LEN_V1_PLUS_CRC
                    continue
                if type(m) is bad_cls:
                    reason = m.reason
                    if reason == _BAD_PREFIX:
                        if not resync:
                            st.dropped_garbage += 1
                    elif reason == _BAD_SIGNATURE:
                        st.dropped_signature += 1
                        resync = False
                    else:  # bad CRC / flags / payload: re-scan from the byte after its start
                        if not resync:
                            st.dropped_crc += 1
                            resync = True
                        mav.buf = buf
                        mav.buf_index = start + 1
                        mav.expected_length = _HEADER_LEN_V1_PLUS_CRC
                    if mav.buf_len() == 0:
                        break
                    continue
                resync = False
                if type(m) is self._unknown_cls and not self._keep_unknown:
                    st.dropped_unknown += 1
                else:
                    st.frames_received += 1
                    out.append(m)
                if mav.buf_len() == 0:
                    break
        finally:
            mav.buf = bytearray()
            mav.buf_index = 0
            mav.expected_length = _HEADER_LEN_V1_PLUS_CRC

    # ---------------------------------------------------------------- lifetime
    def close(self) -> None:
        """Close the transport. Idempotent."""
        if not self._closed:
            self._closed = True
            self._transport.close()

    def __enter__(self) -> Link:
        return self

    def __exit__(
        self,
        exc_type: type[BaseException] | None,
        exc: BaseException | None,
        tb: TracebackType | None,
    ) -> None:
        self.close()

    def __del__(self) -> None:  # last resort; fixtures should close explicitly
        try:
            if not self._closed:
                self.close()
        except Exception:
            pass


# ------------------------------------------------------------------------------------------
# URLs
# ------------------------------------------------------------------------------------------
_SCHEMES = ("udp-server", "udp-client", "zenoh")


def parse_link_url(url: str) -> LinkUrl:
    """Parse and validate a link URL (syntax only: the loopback policy is applied on open).

    Raises
    ------
    ValueError
        with a message saying what is wrong and what is expected.
    """
    if not isinstance(url, str) or "://" not in url:
        raise ValueError(
            f"bad link URL {url!r}: expected one of "
            "udp-server://HOST:PORT, udp-client://HOST:PORT, "
            "zenoh://VEHICLE/LINK/up|down?listen=tcp/127.0.0.1:PORT"
        )
    parts = urlsplit(url)
    scheme = parts.scheme.lower()
    if scheme not in _SCHEMES:
        raise ValueError(
            f"bad link URL {url!r}: unknown scheme {parts.scheme!r} "
            f"(expected {', '.join(_SCHEMES)})"
        )
    if parts.fragment:
        raise ValueError(f"bad link URL {url!r}: fragments ('#...') are not allowed")
    if scheme == "zenoh":
        from vtolftc.protocols.zenoh_transport import parse_zenoh_url

        return parse_zenoh_url(url)
    if parts.path not in ("", "/") or parts.query:
        raise ValueError(f"bad link URL {url!r}: {scheme} takes no path or query, only HOST:PORT")
    if parts.username or parts.password:
        raise ValueError(f"bad link URL {url!r}: user info is not allowed")
    host = parts.hostname
    if not host:
        raise ValueError(f"bad link URL {url!r}: missing host (e.g. {scheme}://127.0.0.1:14550)")
    try:
        port = parts.port
    except ValueError as exc:
        raise ValueError(f"bad link URL {url!r}: port must be an integer 0..65535") from exc
    if port is None:
        raise ValueError(f"bad link URL {url!r}: missing port (e.g. {scheme}://127.0.0.1:14550)")
    if scheme == "udp-client" and port == 0:
        raise ValueError(f"bad link URL {url!r}: a udp-client needs the server's port, not 0")
    return LinkUrl(scheme=scheme, host=host, port=port)


def open_link(
    url: str,
    *,
    system_id: int = 255,
    component_id: int = 190,
    signing: SigningConfig | None = None,
    allow_remote: bool = False,
    keep_unknown: bool = False,
    track_source: bool = False,
    stream_table: StreamTimestamps | None = None,
    rate_limit_hz: float | None = None,
    rate_burst: float | None = None,
    zenoh_receive: str = "callback",
) -> Link:
    """Open a :class:`Link` from a URL (see the module docstring for the scheme).

    Parameters
    ----------
    url
        ``udp-server://...``, ``udp-client://...`` or ``zenoh://...``.
    system_id, component_id
        source ids of the frames this link packs.
    signing
        MAVLink 2 signing configuration, None = no signing.
    allow_remote
        permit non-loopback addresses (never settable from the URL).
    keep_unknown
        deliver messages of ids unknown to the dialect instead of dropping them.
    track_source
        remember source addresses (see :meth:`Link.source_of`, :meth:`Link.pin`).
    stream_table
        signing replay window shared by several links.
    rate_limit_hz, rate_burst
        receive rate limit in datagrams/s (see :class:`Link`).
    zenoh_receive
        how a zenoh link receives: ``"callback"`` or ``"channel"`` (the lockstep HIL link;
        see :mod:`vtolftc.protocols.zenoh_transport`); ignored by UDP.

    Raises
    ------
    ValueError
        malformed URL, or a non-loopback address without ``allow_remote``.
    OSError
        the socket could not be bound (e.g. port in use).
    """
    spec = parse_link_url(url)
    transport: Transport
    if spec.scheme == "udp-server":
        from vtolftc.protocols.udp import UdpServerTransport

        transport = UdpServerTransport(spec.host, spec.port, allow_remote=allow_remote)
    elif spec.scheme == "udp-client":
        from vtolftc.protocols.udp import UdpClientTransport

        transport = UdpClientTransport(spec.host, spec.port, allow_remote=allow_remote)
    else:
        from vtolftc.protocols.zenoh_transport import ZenohTransport

        transport = ZenohTransport(
            spec.vehicle,
            spec.link,
            spec.direction,
            listen=spec.listen,
            connect=spec.connect,
            mode=spec.mode,
            allow_remote=allow_remote,
            receive=zenoh_receive,
            lowlatency=spec.lowlatency,
        )
    try:
        return Link(
            transport,
            system_id=system_id,
            component_id=component_id,
            signing=signing,
            keep_unknown=keep_unknown,
            track_source=track_source,
            stream_table=stream_table,
            rate_limit_hz=rate_limit_hz,
            rate_burst=rate_burst,
        )
    except BaseException:
        transport.close()
        raise

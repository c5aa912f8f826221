"""A fast path for parsing whole datagrams of well-formed MAVLink 2 frames.

The generated parser (pymavlink's ``parse_char`` / ``decode``) handles one frame per call
through generic code: buffer copies, a header object made twice, per-field loops over the
message's layout. On the HIL link that was about half of the codec's cost of a lockstep step.
:class:`FastParser` parses a datagram in which *every* frame is a valid MAVLink 2 frame of a
known message id, with a good CRC and (on a signed codec) a good signature hash, into the very
message objects ``decode`` makes (same class, fields, header, buffer, payload, CRC, signing
flags; a test compares them attribute by attribute over the whole dialect). It decodes with
the generated message classes' own layout tables (``unpacker``, ``orders``, ``lengths``,
``crc_extra``): nothing about a message's layout is written by hand here. The framing checks
and the CRC of every frame of a datagram run in one compiled call (:func:`_scan_kernel`, the
CRC_EXTRA of each id from a table made once from the dialect); only the signature's hash
(``hashlib``) and the message objects are made in Python.

Ids in :attr:`FastParser.defer` (``Link.defer``) are checked, counted and signature-checked
the same way but handed over as :class:`RawFrame`: the bytes and the frame's header fields,
the message object made by :meth:`RawFrame.message` only when asked for (the HIL step's
frames, decoded from their bytes by :mod:`vtolftc.protocols.hil_frames`).

Anything else (garbage, a MAVLink 1 frame, bad incompat flags, a truncated frame, a bad CRC,
an unknown id, an unsigned frame or a bad signature on a signing codec) makes
:meth:`FastParser.parse` return ``None`` *before any side effect*, and the caller parses the
datagram with the generated parser, which drops and counts the bad data exactly as before.

Signing (only as set up by :func:`vtolftc.protocols.mavlink.apply_signing`; a codec signed any
other way is left to the generated parser): the hash of every frame is checked first (no side
effect); then, frame by frame and in order, the timestamp goes through the codec's replay
window (``codec.stream_table``, see :mod:`vtolftc.protocols.mavlink`) as the generated path
would do it. A frame whose timestamp is refused there is handled as ``decode`` handles it:
accepted unsigned if the codec's ``allow_unsigned_callback`` says so, else dropped (reported
in :attr:`FastParser.rejected`).
"""

from __future__ import annotations

import hashlib
import hmac
import operator
import struct
from typing import Any

import numba
import numpy as np

__all__ = ["FastParser", "RawFrame"]

_MAGIC_V2 = 0xFD
_IFLAG_SIGNED = 0x01
_HEADER_LEN = 10
_SIG_LEN = 13
_SIGN_TS = struct.Struct("<IH")
_UNSET = object()
_ROW = 10
"""Columns of :func:`_scan_kernel`'s table: start, end, message id, CRC, payload length,
incompat flags, compat flags, sequence, system id, component id."""


class _Layout:
    """How to turn one message class's unpacked payload into its constructor arguments."""

    __slots__ = ("chars", "cls", "crc_extra", "pick", "plain", "plan", "size", "unpack")

    def __init__(self, cls: Any) -> None:
        self.cls = cls
        self.crc_extra = int(cls.crc_extra)
        self.size = cls.unpacker.size
        self.unpack = cls.unpacker.unpack
        lengths = list(cls.lengths)
        # (index of the field's first element in the unpacked tuple, its length), in the
        # constructor's order: exactly the generated decode's `tip` and `L`
        self.plan = [(sum(lengths[:order]), lengths[order]) for order in cls.orders]
        self.plain = sum(lengths) == len(lengths)
        self.pick = operator.itemgetter(*(tip for tip, _n in self.plan), 0)
        """The constructor's arguments of a layout without arrays, from the unpacked tuple
        (one trailing dummy item, so that a one-field message also gets a tuple)."""
        self.chars = "s" in cls.unpacker.format or "c" in cls.unpacker.format
        """The layout has char fields (unpacked as bytes, stripped of trailing NULs)."""


class FastParser:
    """Parse datagrams of valid MAVLink 2 frames for ``codec`` (see the module docstring).

    Parameters
    ----------
    codec : Any
        The link's generated ``MAVLink`` object (its signing state, stream table and
        counters are used and updated as the generated parser would).
    module : module
        The generated dialect module (message classes, ``mavlink_map``, CRC helper).
    """

    def __init__(self, codec: Any, module: Any) -> None:
        self.codec = codec
        self._map = module.mavlink_map
        self._header_cls = module.MAVLink_header
        self._layouts: dict[int, _Layout] = {}
        ids = list(self._map)
        self._crc_extra = np.full(max(ids) + 1, -1, dtype=np.int16)
        """CRC_EXTRA by message id (-1: not in the dialect), for :func:`_scan_kernel`."""
        for msg_id in ids:
            self._crc_extra[msg_id] = int(self._map[msg_id].crc_extra)
        self._table = np.zeros((64, _ROW), dtype=np.int64)
        # compile (or load from numba's cache) now, not at the first datagram of a flight
        _scan_kernel(b"", 0, self._crc_extra, self._table)
        self._key: bytes | None = None
        self._key_hash: Any = None
        """SHA-256 state after the signing key (copied per frame, as ``FramePacker``)."""
        self.rejected = 0
        """Frames dropped for a signature timestamp the replay window refused."""
        self.defer: frozenset[int] = frozenset()
        """Message ids handed over as :class:`RawFrame` (the message object made only when
        asked for) instead of message objects."""

    def _layout(self, msg_id: int) -> _Layout | None:
        lay = self._layouts.get(msg_id)
        if lay is None:
            cls = self._map.get(msg_id)
            if cls is None:
                return None
            lay = self._layouts[msg_id] = _Layout(cls)
        return lay

    def parse(self, data: bytes) -> list[Any] | None:
        """The messages of ``data``, or None if any frame in it is not a valid MAVLink 2
        frame of a known id with a good CRC and signature hash (nothing changed then)."""
        codec = self.codec
        signing = codec.signing
        key = signing.secret_key
        if key is not None and getattr(codec, "stream_table", None) is None:
            return None  # signing not set up by mavlink.apply_signing: its own check decides
        if type(data) is not bytes:
            data = bytes(data)  # a bytearray or memoryview from some transport
        n = len(data)
        table = self._table
        if n // (_HEADER_LEN + 2) >= len(table):
            table = self._table = np.zeros((n // (_HEADER_LEN + 2) + 1, _ROW), dtype=np.int64)
        count = _scan_kernel(data, n, self._crc_extra, table)
        if count < 0:
            return None
        frames = table[:count].tolist()
        if key is not None:
            if key is not self._key:
                self._key, self._key_hash = key, hashlib.sha256(key)
            key_hash = self._key_hash
            view = memoryview(data)
            for row in frames:
                pos, end = row[0], row[1]
                if not row[5] & _IFLAG_SIGNED:
                    return None  # unsigned on a signing codec: the generated path decides
                h = key_hash.copy()  # = sha256(key + frame without the hash)
                h.update(view[pos:end - 6])
                if not hmac.compare_digest(h.digest()[:6], data[end - 6:end]):
                    return None
        return self._build(data, frames, key)

    def _build(self, data: bytes, frames: list[list[int]], key: bytes | None) -> list[Any]:
        codec = self.codec
        signing = codec.signing
        out: list[Any] = []
        layout = self._layout
        defer = self.defer
        for pos, end, msg_id, crc, mlen, iflags, cflags, seq, src_sys, src_comp in frames:
            lay = layout(msg_id)
            assert lay is not None  # the kernel checked the id
            signed = bool(iflags & _IFLAG_SIGNED)
            codec.total_packets_received += 1
            if signed:
                signing.sig_count += 1
            sig_ok = False
            if key is not None:
                tlow, thigh = _SIGN_TS.unpack_from(data, end - 12)
                timestamp = tlow + (thigh << 32)
                link_id = data[end - 13]
                sig_ok = codec.stream_table.accept((int(link_id), src_sys, src_comp),
                                                   timestamp, int(signing.timestamp))
                if sig_ok:
                    if timestamp > signing.timestamp:
                        signing.timestamp = timestamp
                    signing.goodsig_count += 1
                else:
                    signing.badsig_count += 1
                    allow = signing.allow_unsigned_callback
                    if allow is not None and allow(codec, msg_id):
                        signing.unsigned_count += 1
                    else:
                        signing.reject_count += 1
                        codec.total_receive_errors += 1
                        self.rejected += 1
                        continue
            if msg_id in defer:
                out.append(RawFrame(self, data, pos, end, msg_id, crc, mlen, iflags, cflags,
                                    seq, src_sys, src_comp, sig_ok))
                continue
            m = self._make(lay, data, pos, end, msg_id, crc, mlen, iflags, cflags, seq,
                           src_sys, src_comp, sig_ok)
            out.append(m)
        return out

    def _make(self, lay: _Layout, data: bytes, pos: int, end: int, msg_id: int, crc: int,
              mlen: int, iflags: int, cflags: int, seq: int, src_sys: int, src_comp: int,
              sig_ok: bool) -> Any:
        """The generated ``decode``'s message object of the frame ``data[pos:end]`` (its
        signature already checked and accounted: ``sig_ok``)."""
        siglen = _SIG_LEN if iflags & _IFLAG_SIGNED else 0
        msgbuf = bytearray(data[pos:end])
        payload = data[pos + _HEADER_LEN:pos + _HEADER_LEN + mlen]
        if mlen < lay.size:
            payload += bytes(lay.size - mlen)
        t = lay.unpack(payload[:lay.size])
        if lay.plain and not lay.chars:
            m = lay.cls(*lay.pick(t)[:-1])
        elif not lay.chars:
            m = lay.cls(*[t[tip] if n == 1 else list(t[tip:tip + n])
                          for tip, n in lay.plan])
        else:
            args = []
            for tip, length in lay.plan:
                field = t[tip]
                if length == 1 or isinstance(field, bytes):
                    args.append(field)
                else:
                    args.append(list(t[tip:tip + length]))
            for i, elem in enumerate(args):
                if isinstance(elem, bytes):
                    args[i] = elem.rstrip(b"\x00")
            m = lay.cls(*args)
        m._signed = sig_ok
        if sig_ok:
            m._link_id = msgbuf[-13]
        m._msgbuf = msgbuf
        m._payload = msgbuf[6:-(2 + siglen)]
        m._crc = crc
        m._header = self._header_cls(msg_id, iflags, cflags, mlen, seq, src_sys, src_comp)
        return m


class RawFrame:
    """A frame :class:`FastParser` checked (framing, CRC, signature and its replay window,
    counters) but did not turn into a message object: the ids in :attr:`FastParser.defer`.

    A reader on the hot path decodes the numbers it needs from :attr:`data` itself
    (the payload is ``data[payload_start:payload_start + mlen]``, zero tail truncated as
    MAVLink 2 sends it); :meth:`message` makes, once, the very object the parser would have
    handed over (same class, fields, header, buffers, signing flags).
    """

    __slots__ = ("_msg", "_parser", "_row", "_sig_ok", "_vtolftc_source", "data", "mlen",
                 "msg_id", "payload_start")

    def __init__(self, parser: FastParser, data: bytes, pos: int, end: int, msg_id: int,
                 crc: int, mlen: int, iflags: int, cflags: int, seq: int, src_sys: int,
                 src_comp: int, sig_ok: bool) -> None:
        self._parser = parser
        self.data = data
        self.msg_id = msg_id
        self.mlen = mlen
        self.payload_start = pos + _HEADER_LEN
        self._row = (pos, end, msg_id, crc, mlen, iflags, cflags, seq, src_sys, src_comp)
        self._sig_ok = sig_ok
        self._msg: Any = None
        self._vtolftc_source: Any = _UNSET

    def get_type(self) -> str:
        """The message's name (as the message object's ``get_type``)."""
        return self._parser._map[self.msg_id].msgname  # type: ignore[no-any-return]

    def get_srcSystem(self) -> int:
        """The sender's system id (as the message object's)."""
        return self._row[8]

    def get_srcComponent(self) -> int:
        """The sender's component id (as the message object's)."""
        return self._row[9]

    def message(self) -> Any:
        """The message object of this frame (made at the first call, then the same one)."""
        m = self._msg
        if m is None:
            parser = self._parser
            lay = parser._layout(self.msg_id)
            assert lay is not None  # the kernel checked the id
            m = parser._make(lay, self.data, *self._row, self._sig_ok)
            if self._vtolftc_source is not _UNSET:  # set by a link that tracks sources
                m._vtolftc_source = self._vtolftc_source
            self._msg = m
        return m


@numba.njit(cache=True)
def _scan_kernel(data, n, crc_extra, out):  # pragma: no cover - compiled
    """Check that ``data[:n]`` is nothing but MAVLink 2 frames of known ids with good CRCs.

    Each frame: the magic byte 0xFD, at most the signed incompat flag, the whole frame
    (header, payload, CRC, 13 signature bytes if signed) inside ``data``, an id with
    ``crc_extra[id] >= 0``, and the X.25 CRC (CRC-16/MCRF4XX over the header without the
    magic byte and the payload, then ``crc_extra[id]``) equal to the little-endian CRC field.
    Writes one row per frame into ``out`` (start, end, id, CRC, payload length, incompat
    flags, compat flags, sequence, system id, component id) and returns the number of
    frames, or -1 at the first thing that is not such a frame (the signature's hash is not
    checked here). ``out`` has at least ``n // 12 + 1`` rows.
    """
    pos = 0
    k = 0
    while pos < n:
        if n - pos < _HEADER_LEN + 2 or data[pos] != _MAGIC_V2:
            return -1
        mlen = data[pos + 1]
        iflags = data[pos + 2]
        if iflags & ~_IFLAG_SIGNED:
            return -1
        siglen = _SIG_LEN if iflags & _IFLAG_SIGNED else 0
        body_end = pos + _HEADER_LEN + mlen
        end = body_end + 2 + siglen
        if end > n:
            return -1
        msg_id = data[pos + 7] | (data[pos + 8] << 8) | (data[pos + 9] << 16)
        if msg_id >= len(crc_extra) or crc_extra[msg_id] < 0:
            return -1
        crc = 0xFFFF
        for i in range(pos + 1, body_end + 1):
            b = data[i] if i < body_end else crc_extra[msg_id]
            tmp = (b ^ (crc & 0xFF)) & 0xFF
            tmp = (tmp ^ (tmp << 4)) & 0xFF
            crc = ((crc >> 8) ^ (tmp << 8) ^ (tmp << 3) ^ (tmp >> 4)) & 0xFFFF
        if crc != (data[body_end] | (data[body_end + 1] << 8)):
            return -1
        row = out[k]
        row[0] = pos
        row[1] = end
        row[2] = msg_id
        row[3] = crc
        row[4] = mlen
        row[5] = iflags
        row[6] = data[pos + 3]
        row[7] = data[pos + 4]
        row[8] = data[pos + 5]
        row[9] = data[pos + 6]
        k += 1
        pos = end
    return k

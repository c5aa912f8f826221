"""A fast path for parsing whole datagrams of well-formed MAVLink 2 frames.

The generated parser (pymavlink's ``parse_char`` / ``decode``) handles one frame per call
through generic code: buffer copies, a header object made twice, per-field loops over the
message's layout. On the HIL link that was about half of the codec's cost of a lockstep step.
:class:`FastParser` parses a datagram in which *every* frame is a valid MAVLink 2 frame of a
known message id, with a good CRC and (on a signed codec) a good signature hash, into the very
message objects ``decode`` makes (same class, fields, header, buffer, payload, CRC, signing
flags; a test compares them attribute by attribute over the whole dialect). It decodes with
the generated message classes' own layout tables (``unpacker``, ``orders``, ``lengths``,
``crc_extra``): nothing about a message's layout is written by hand here.

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

__all__ = ["FastParser"]

_MAGIC_V2 = 0xFD
_IFLAG_SIGNED = 0x01
_HEADER_LEN = 10
_SIG_LEN = 13
_HEADER = struct.Struct("<BBBBBBBHB")
_CRC = struct.Struct("<H")
_SIGN_TS = struct.Struct("<IH")


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
        fast = getattr(module, "mcrf4xx", None)
        if fast is not None:
            self._crc = lambda data, extra: fast(bytes((extra,)), fast(data, 0xFFFF))
        else:
            x25 = module.x25crc

            def slow(data: Any, extra: int) -> int:
                c = x25(bytes(data))
                c.accumulate(bytes((extra,)))
                return int(c.crc)

            self._crc = slow
        self.rejected = 0
        """Frames dropped for a signature timestamp the replay window refused."""

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
        pos = 0
        frames: list[tuple[int, int, tuple[int, ...], _Layout, int]] = []
        view = memoryview(data)
        crc_of = self._crc
        while pos < n:
            if n - pos < _HEADER_LEN + 2 or data[pos] != _MAGIC_V2:
                return None
            hdr = _HEADER.unpack_from(data, pos)
            mlen, iflags = hdr[1], hdr[2]
            if iflags & ~_IFLAG_SIGNED:
                return None
            siglen = _SIG_LEN if iflags & _IFLAG_SIGNED else 0
            end = pos + _HEADER_LEN + mlen + 2 + siglen
            if end > n:
                return None
            lay = self._layout(hdr[7] | (hdr[8] << 16))
            if lay is None:
                return None
            body_end = pos + _HEADER_LEN + mlen
            crc = _CRC.unpack_from(data, body_end)[0]
            if crc != crc_of(view[pos + 1:body_end], lay.crc_extra):
                return None
            if key is not None:
                if not siglen:
                    return None  # unsigned on a signing codec: the generated path decides
                digest = hashlib.sha256(key + data[pos:end - 6]).digest()[:6]
                if not hmac.compare_digest(digest, data[end - 6:end]):
                    return None
            frames.append((pos, end, hdr, lay, crc))
            pos = end
        return self._build(data, frames, key)

    def _build(self, data: bytes, frames: list[tuple[int, int, tuple[int, ...], _Layout, int]],
               key: bytes | None) -> list[Any]:
        codec = self.codec
        signing = codec.signing
        out: list[Any] = []
        header_cls = self._header_cls
        for pos, end, hdr, lay, crc in frames:
            _magic, mlen, iflags, cflags, seq, src_sys, src_comp, lo, hi = hdr
            signed = bool(iflags & _IFLAG_SIGNED)
            siglen = _SIG_LEN if signed else 0
            msg_id = lo | (hi << 16)
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
            m._header = header_cls(msg_id, iflags, cflags, mlen, seq, src_sys, src_comp)
            out.append(m)
        return out

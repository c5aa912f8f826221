"""A fast path for packing MAVLink 2 frames of one message type, the counterpart of
:mod:`vtolftc.protocols.fastparse`.

The generated ``*_encode(...).pack(codec)`` makes a message object, a header object, several
byte strings and runs the CRC in Python-level calls; on the lockstep HIL link that is paid on
the critical path every 4 ms (HIL_ACTUATOR_CONTROLS in the autopilot, HIL_SENSOR and
HIL_STATE_QUATERNION in the vehicle). :class:`FramePacker` packs the payload with the message
class's own ``unpacker`` (``struct.Struct.pack_into``) into a buffer made once, and does the
header, the MAVLink 2 truncation of trailing zero bytes and the CRC (with the class's
``crc_extra``) in one compiled call: nothing about a message's layout is written by hand here.
The frame is byte for byte what ``msg.pack(codec)`` returns for an unsigned codec, and the
codec's sequence number advances the same way (a test compares them over random values).

Signing as the generated ``sign_packet`` does it: on a codec whose ``signing.sign_outgoing``
is set the frame carries the signed incompat flag, the link id, the codec's signing timestamp
(then advanced by one) and the first 6 bytes of SHA-256(key + frame); the hash of the key is
computed once and copied per frame.
"""

from __future__ import annotations

import hashlib
import struct
from typing import Any

import numba
import numpy as np

__all__ = ["FramePacker", "frame_kernel"]

_HEADER_LEN = 10
_CRC_LEN = 2
_SIG_LEN = 13


class FramePacker:
    """Packs unsigned MAVLink 2 frames of one message class for ``codec``.

    Parameters
    ----------
    codec : Any
        The link's generated ``MAVLink`` object: its ``srcSystem``, ``srcComponent`` and
        ``seq`` are used, ``seq`` advanced per frame as the generated packing does.
    cls : type
        The generated message class (``MAVLink_..._message``): ``id``, ``unpacker``,
        ``crc_extra``.
    """

    __slots__ = ("_arr", "_buf", "_codec", "_crc_extra", "_key", "_key_hash", "_msg_id",
                 "_pack_into", "_size", "_view")

    def __init__(self, codec: Any, cls: Any) -> None:
        self._codec = codec
        self._msg_id = int(cls.id)
        self._crc_extra = int(cls.crc_extra)
        unpacker: struct.Struct = cls.unpacker
        self._pack_into = unpacker.pack_into
        self._size = unpacker.size
        self._buf = bytearray(_HEADER_LEN + self._size + _CRC_LEN + _SIG_LEN)
        self._arr = np.frombuffer(self._buf, dtype=np.uint8)
        self._view = memoryview(self._buf)
        self._key: Any = None
        self._key_hash: Any = None
        # compile (or load from numba's cache) now, not at the first frame of a flight
        frame_kernel(self._arr, self._size, 0, 0, 0, self._msg_id, self._crc_extra, False,
                      0, 0)

    def pack(self, *values: Any) -> bytes:
        """One frame of the message with the payload ``values``.

        Parameters
        ----------
        *values
            The payload's fields in wire order (the class's ``ordered_fieldnames``, arrays
            flattened), in the types the class's ``unpacker`` takes.

        Returns
        -------
        bytes
            The frame, equal to ``cls(...).pack(codec)`` (signed or not, as the codec).
        """
        codec = self._codec
        self._pack_into(self._buf, _HEADER_LEN, *values)
        seq = codec.seq
        s = codec.signing
        signed = bool(s.sign_outgoing)
        ts = s.timestamp if signed else 0
        n = frame_kernel(self._arr, self._size, seq, codec.srcSystem, codec.srcComponent,
                          self._msg_id, self._crc_extra, signed, s.link_id if signed else 0,
                          ts)
        return self._finish(n, signed, ts)

    def pack_compiled(self, kernel: Any, *args: Any) -> bytes | None:
        """One frame whose payload a compiled ``kernel`` writes from ``args`` (the values
        straight from their arrays, no per-field Python objects), or None if it declines.

        ``kernel(buf, size, seq, sys_id, comp_id, msg_id, crc_extra, signed, link_id,
        timestamp, *args)`` writes the ``size`` payload bytes at ``buf[10:]`` as the class's
        ``unpacker`` would pack them, then returns :func:`frame_kernel` of the same
        arguments (or -1, nothing written that counts, for a value ``struct`` would refuse:
        the caller then packs with :meth:`pack`, which raises its error). The sequence number
        and signing advance as in :meth:`pack`; the frame is the same bytes.
        """
        codec = self._codec
        s = codec.signing
        signed = bool(s.sign_outgoing)
        ts = s.timestamp if signed else 0
        n = kernel(self._arr, self._size, codec.seq, codec.srcSystem, codec.srcComponent,
                   self._msg_id, self._crc_extra, signed, s.link_id if signed else 0, ts,
                   *args)
        return None if n < 0 else self._finish(n, signed, ts)

    def _finish(self, n: int, signed: bool, ts: int) -> bytes:
        """The frame of ``n`` bytes in the buffer: signed (the hash appended, the signing
        timestamp advanced) if ``signed``; the codec's sequence number advanced."""
        codec = self._codec
        buf = self._buf
        codec.seq = (codec.seq + 1) & 0xFF
        if not signed:
            return bytes(buf[:n])
        s = codec.signing
        key = s.secret_key
        assert key is not None
        if key is not self._key:
            self._key, self._key_hash = key, hashlib.sha256(key)
        h = self._key_hash.copy()
        h.update(self._view[:n])
        buf[n:n + 6] = h.digest()[:6]
        s.timestamp = ts + 1
        return bytes(buf[:n + 6])

@numba.njit(cache=True)
def frame_kernel(buf, size, seq, sys_id, comp_id, msg_id, crc_extra, signed, link_id,
                  timestamp):  # pragma: no cover
    """Header, trailing-zero truncation and CRC of the payload at ``buf[10:10 + size]``;
    signed: the signed incompat flag and, after the CRC, the link id and the 48-bit
    timestamp (little-endian).

    The payload keeps at least one byte (as the generated packing). The CRC is X.25
    (CRC-16/MCRF4XX) over the header without the magic byte and the payload, then
    ``crc_extra``. Returns the frame's length in bytes so far (without the 6 bytes of the
    signature's hash).
    """
    plen = size
    while plen > 1 and buf[_HEADER_LEN + plen - 1] == 0:
        plen -= 1
    buf[0] = 0xFD
    buf[1] = plen
    buf[2] = 1 if signed else 0
    buf[3] = 0
    buf[4] = seq
    buf[5] = sys_id
    buf[6] = comp_id
    buf[7] = msg_id & 0xFF
    buf[8] = (msg_id >> 8) & 0xFF
    buf[9] = (msg_id >> 16) & 0xFF
    crc = 0xFFFF
    end = _HEADER_LEN + plen
    for i in range(1, end + 1):
        b = buf[i] if i < end else crc_extra
        tmp = (b ^ (crc & 0xFF)) & 0xFF
        tmp = (tmp ^ (tmp << 4)) & 0xFF
        crc = ((crc >> 8) ^ (tmp << 8) ^ (tmp << 3) ^ (tmp >> 4)) & 0xFFFF
    buf[end] = crc & 0xFF
    buf[end + 1] = crc >> 8
    n = end + _CRC_LEN
    if signed:
        buf[n] = link_id
        for k in range(6):
            buf[n + 1 + k] = (timestamp >> (8 * k)) & 0xFF
        n += 7
    return n

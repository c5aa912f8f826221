"""The vtol-ftc MAVLink dialect: loading, regeneration, codecs and signing.

The dialect is described by ``protocols/dialects/vtolftc.xml`` (which includes pymavlink's
``common.xml``) and turned into Python by pymavlink's own generator (mavgen, MAVLink 2.0 wire
protocol). Nothing is hand-written: the packers, the parser and the CRC extras all come from
mavgen.

The generated module is committed as ``protocols/generated/vtolftc.py`` and imported like any
other module (:func:`dialect`); nothing is written at run time, so a read-only install works.
After a change to the XML or to the pinned pymavlink, regenerate it with::

    python -m vtolftc.protocols.regenerate

and ``tests/test_protocols_dialect.py`` checks that the committed file is exactly what mavgen
makes from the XML today. The same command writes ``protocols/generated/constants.py``, every
enum value and message id as a plain integer (:func:`generate_constants`), which flight code
imports for its numbers without loading the codec (about 0.8 s to import uncompiled).

Codecs
    :func:`make_codec` returns the generated ``MAVLink`` object (packer + parser) with a given
    system/component id, robust parsing on (bad data comes back as ``MAVLink_bad_data`` instead of
    exceptions) and, when a :class:`SigningConfig` is given, MAVLink 2 message signing.

Signature check (how pymavlink is wrapped)
    pymavlink's ``MAVLink.check_signature`` stores a frame's timestamp in the stream table
    *before* it compares the hash, so one forged frame (any bytes, no key) with a far-future
    timestamp locks the legitimate signer out until restart; and each codec keeps its own table,
    so a signed frame captured on one link can be replayed on another. :func:`apply_signing`
    therefore replaces ``check_signature`` on the codec instance (the parser calls it through
    ``self``) with :func:`_verified_check`: the SHA-256 signature is compared first
    (constant-time), and only a frame with a valid signature has its timestamp checked against
    and stored in the :class:`StreamTimestamps` table; every codec given the same table (the
    autopilot passes one to all its ground-station links) shares one replay window. The rest of
    pymavlink's parser (unsigned-frame callback, counters) is unchanged.
"""

from __future__ import annotations

import contextlib
import hashlib
import hmac
import importlib
import io
import re
import shutil
import struct
import tempfile
import threading
import time
from collections.abc import Callable
from dataclasses import dataclass
from pathlib import Path
from types import ModuleType
from typing import Any

from vtolftc.jsonio import atomic_write, atomic_write_text

__all__ = [
    "DIALECT_NAME",
    "DIALECT_XML",
    "GENERATED_CONSTANTS",
    "GENERATED_MODULE",
    "MAVLINK_EPOCH_UNIX_S",
    "SigningConfig",
    "StreamTimestamps",
    "apply_signing",
    "dialect",
    "dialect_sources",
    "generate_constants",
    "generate_dialect",
    "make_codec",
    "signing_timestamp_now",
]

DIALECT_NAME = "vtolftc"
"""Base name of the dialect (XML file stem, ``DIALECT`` of the generated module)."""

DIALECT_XML = Path(__file__).resolve().parent / "dialects" / f"{DIALECT_NAME}.xml"
"""The dialect definition shipped with the package."""

MAVLINK_EPOCH_UNIX_S = 1420070400
"""1 January 2015 00:00 UTC, the origin of MAVLink signing timestamps (unit 10 us)."""

_MODULE_NAME = "vtolftc.protocols.generated.vtolftc"
_INCLUDE_RE = re.compile(rb"<include>\s*([^<\s]+)\s*</include>")
_lock = threading.Lock()
_gen_lock = threading.RLock()  # mavgen prints; stdout redirection is process-global
_module: ModuleType | None = None


# --------------------------------------------------------------------------------------------
# sources and generation
# --------------------------------------------------------------------------------------------
GENERATED_MODULE = Path(__file__).resolve().parent / "generated" / f"{DIALECT_NAME}.py"
"""The committed generated module (see the module docstring)."""

GENERATED_CONSTANTS = Path(__file__).resolve().parent / "generated" / "constants.py"
"""Every enum value and message id of the dialect as a plain integer constant, generated from
the generated module by :func:`generate_constants`: a small module the flight code imports for
numbers (``MAV_CMD_NAV_TAKEOFF``, ``MAV_RESULT_DENIED``, ...) without loading the whole codec."""


def _pymavlink_dialect_dir() -> Path:
    import pymavlink

    return Path(pymavlink.__file__).resolve().parent / "dialects" / "v20"


def _resolve_include(name: str, including: Path) -> Path:
    """Find an included XML: next to the including file first, then in pymavlink's dialects."""
    for base in (including.parent, _pymavlink_dialect_dir()):
        candidate = (base / name).resolve()
        if candidate.is_file():
            return candidate
    raise FileNotFoundError(f"MAVLink include {name!r} (from {including}) not found")


def dialect_sources(xml: Path = DIALECT_XML) -> list[Path]:
    """The dialect XML followed by every XML it includes (transitively), without duplicates.

    Parameters
    ----------
    xml : Path
        The dialect definition.

    Returns
    -------
    list of Path
        ``xml`` first, then its includes in breadth-first order.
    """
    xml = Path(xml).resolve()
    seen: dict[str, Path] = {}
    todo = [xml]
    while todo:
        path = todo.pop(0)
        if path.name in seen:
            if seen[path.name] != path:
                raise ValueError(f"two different MAVLink includes named {path.name}")
            continue
        seen[path.name] = path
        for match in _INCLUDE_RE.finditer(path.read_bytes()):
            todo.append(_resolve_include(match.group(1).decode(), path))
    return list(seen.values())


def generate_dialect(target: Path, xml: Path = DIALECT_XML) -> Path:
    """Run mavgen (MAVLink 2.0, Python 3) on ``xml`` and write the module to ``target``.

    mavgen writes into a temporary directory beside ``target``; the module is published with
    :func:`vtolftc.jsonio.atomic_write`: a reader never sees half a module.

    Parameters
    ----------
    target : Path
        Where the generated module goes (its directory is created).
    xml : Path
        The dialect definition; its includes are resolved next to it, then in pymavlink's.

    Returns
    -------
    Path
        ``target``.

    Raises
    ------
    OSError
        ``target`` cannot be written.
    RuntimeError
        mavgen rejected the XML (its output is in the message).
    """
    from pymavlink.generator import mavgen

    target = Path(target)
    target.parent.mkdir(parents=True, exist_ok=True)
    with _gen_lock:
        work = Path(tempfile.mkdtemp(prefix=".gen-", dir=target.parent))
        try:
            sources = dialect_sources(xml)
            for src in sources:  # flat copy: includes resolve by file name, next to the dialect
                shutil.copyfile(src, work / src.name)
            out_py = work / f"{DIALECT_NAME}.py"
            opts = mavgen.Opts(str(out_py), wire_protocol="2.0", language="Python3",
                               validate=True)
            log = io.StringIO()
            try:
                with contextlib.redirect_stdout(log), contextlib.redirect_stderr(log):
                    ok = mavgen.mavgen(opts, [str(work / sources[0].name)])
            except SystemExit as exc:  # mavgen calls exit() on some XML errors
                raise RuntimeError(f"mavgen failed on {xml}:\n{log.getvalue()}") from exc
            if not ok or not out_py.is_file():
                raise RuntimeError(f"mavgen failed on {xml}:\n{log.getvalue()}")
            atomic_write(target, lambda f: f.write(out_py.read_bytes()))
        finally:
            shutil.rmtree(work, ignore_errors=True)
    return target


def generate_constants(target: Path, module: ModuleType | None = None) -> Path:
    """Write every enum entry and message id of a generated dialect as ``NAME = value``.

    Parameters
    ----------
    target : Path
        The module to write (atomically).
    module : module, optional
        A mavgen-generated dialect; default :func:`dialect`.

    Returns
    -------
    Path
        ``target``.
    """
    d = dialect() if module is None else module
    lines = ['"""MAVLink constants of the vtol-ftc dialect (enum values and message ids).',
             "",
             "Generated from protocols/generated/vtolftc.py by",
             "``python -m vtolftc.protocols.regenerate``. DO NOT EDIT.",
             '"""', "", "# ruff: noqa: E501", ""]
    for enum_name in sorted(d.enums):
        entries = d.enums[enum_name]
        lines.append(f"# {enum_name}")
        for value in sorted(entries):
            name = entries[value].name
            if name.endswith("_ENUM_END") or not name.isidentifier():
                continue
            lines.append(f"{name} = {int(value)}")
    lines.append("# message ids")
    for name in sorted(n for n in dir(d) if n.startswith("MAVLINK_MSG_ID_")):
        lines.append(f"{name} = {int(getattr(d, name))}")
    return atomic_write_text(target, "\n".join(lines) + "\n")


def dialect() -> ModuleType:
    """The generated vtol-ftc dialect module (pymavlink ``MAVLink`` class, messages, enums).

    Returns
    -------
    module
        ``vtolftc.protocols.generated.vtolftc``, imported once per process.
    """
    global _module
    if _module is not None:
        return _module
    with _lock:
        if _module is None:
            _module = importlib.import_module(_MODULE_NAME)
        return _module


# --------------------------------------------------------------------------------------------
# codecs and signing
# --------------------------------------------------------------------------------------------
def signing_timestamp_now() -> int:
    """Current MAVLink signing timestamp: units of 10 us since 2015-01-01 00:00 UTC."""
    return int((time.time() - MAVLINK_EPOCH_UNIX_S) * 100_000)


@dataclass(frozen=True)
class SigningConfig:
    """MAVLink 2 message signing parameters.

    Attributes
    ----------
    secret_key
        the 32-byte shared secret (see :meth:`from_passphrase`).
    link_id
        signing link id (0..255) written into outgoing signatures.
    timestamp
        initial signing timestamp (10 us units since 2015-01-01); ``None`` = now.
    sign_outgoing
        sign every outgoing frame.
    allow_unsigned
        what to do with incoming frames that are unsigned *or* carry a bad
        signature: ``False`` rejects them all (the link drops and counts them), ``True``
        accepts them all, a callable ``f(msgid) -> bool`` decides per message id. Accepted
        frames report ``msg.get_signed()``: ``True`` only for a verified signature, so an
        application can accept unsigned telemetry yet demand signed arm/fault commands.
    """

    secret_key: bytes
    link_id: int = 0
    timestamp: int | None = None
    sign_outgoing: bool = True
    allow_unsigned: bool | Callable[[int], bool] = False

    def __post_init__(self) -> None:
        if not isinstance(self.secret_key, bytes | bytearray) or len(self.secret_key) != 32:
            raise ValueError("MAVLink signing secret_key must be 32 bytes")
        if not 0 <= int(self.link_id) <= 255:
            raise ValueError(f"MAVLink signing link_id must be 0..255, got {self.link_id}")

    @classmethod
    def from_passphrase(cls, passphrase: str, **kwargs: Any) -> SigningConfig:
        """Key = SHA-256 of the passphrase (the MAVProxy / QGroundControl convention)."""
        return cls(hashlib.sha256(passphrase.encode()).digest(), **kwargs)


class StreamTimestamps:
    """The replay window of MAVLink 2 signing: the last accepted timestamp of every stream
    ``(link_id, system, component)``, shared by every codec (link) it is given to; thread-safe
    (the links receive in their own threads).
    """

    def __init__(self) -> None:
        self._ts: dict[tuple[int, int, int], int] = {}
        self._lock = threading.Lock()

    def accept(self, key: tuple[int, int, int], timestamp: int, now: int) -> bool:
        """Accept ``timestamp`` for stream ``key`` (and store it) if it is newer than the last
        one of that stream, or, for a new stream, at most one minute older than ``now``
        (pymavlink's rule). Only ever called for frames whose signature was verified."""
        with self._lock:
            last = self._ts.get(key)
            if last is not None:
                if timestamp <= last:
                    return False
            elif timestamp + 6000 * 1000 < now:
                return False
            self._ts[key] = timestamp
            return True

    def __len__(self) -> int:
        return len(self._ts)


_SIGN_TS = struct.Struct("<IH")


def _verified_check(codec: Any, table: StreamTimestamps, msgbuf: bytearray, src_system: int,
                    src_component: int) -> bool:
    """``check_signature`` with the hash verified before any timestamp is looked at or stored
    (see the module docstring)."""
    s = codec.signing
    key = s.secret_key
    if key is None or len(msgbuf) < 13:
        return False
    digest = hashlib.sha256(bytes(key) + bytes(msgbuf[:-6])).digest()[:6]
    if not hmac.compare_digest(digest, bytes(msgbuf[-6:])):
        return False
    tlow, thigh = _SIGN_TS.unpack(bytes(msgbuf[-12:-6]))
    timestamp = tlow + (thigh << 32)
    link_id = msgbuf[-13]
    if not table.accept((int(link_id), int(src_system), int(src_component)), timestamp,
                        int(s.timestamp)):
        return False
    if timestamp > s.timestamp:  # pymavlink: send with max(received, own) from now on
        s.timestamp = timestamp
    return True


def apply_signing(codec: Any, signing: SigningConfig,
                  table: StreamTimestamps | None = None) -> None:
    """Enable MAVLink 2 signing on a generated ``MAVLink`` codec object.

    Incoming signatures are checked by :func:`_verified_check` against ``table`` (a new one
    for this codec when None; pass one table to every link of an endpoint).
    """
    s = codec.signing
    tbl = table if table is not None else StreamTimestamps()
    codec.check_signature = lambda msgbuf, sys_id, comp_id: _verified_check(
        codec, tbl, msgbuf, sys_id, comp_id)
    codec.stream_table = tbl
    s.secret_key = bytes(signing.secret_key)
    s.link_id = int(signing.link_id)
    s.timestamp = signing_timestamp_now() if signing.timestamp is None else int(signing.timestamp)
    s.sign_outgoing = bool(signing.sign_outgoing)
    allow = signing.allow_unsigned
    if allow is True:
        s.allow_unsigned_callback = lambda _mav, _msgid: True
    elif callable(allow):
        s.allow_unsigned_callback = lambda _mav, msgid: bool(allow(msgid))
    else:
        s.allow_unsigned_callback = None


def make_codec(
    system_id: int = 255,
    component_id: int = 190,
    *,
    signing: SigningConfig | None = None,
    robust: bool = True,
    stream_table: StreamTimestamps | None = None,
) -> Any:
    """A generated ``MAVLink`` object (encoder + parser) of the vtol-ftc dialect.

    Parameters
    ----------
    system_id
        source system id of packed frames (255 = ground-station convention; the
        autopilot is 1).
    component_id
        source component id (190 = MAV_COMP_ID_MISSIONPLANNER; autopilot 1).
    signing
        enable MAVLink 2 signing with these parameters.
    robust
        robust parsing (bad data returned as ``MAVLink_bad_data``, never raised).
    stream_table
        signing replay window shared with other codecs (see :class:`StreamTimestamps`).

    The codec's ``file`` is ``None``: pack with ``msg.pack(codec)`` (or let a
    :class:`vtolftc.protocols.link.Link` do it) rather than ``codec.send``.
    """
    if not 0 <= system_id <= 255 or not 0 <= component_id <= 255:
        raise ValueError(f"system/component id out of range: {system_id}/{component_id}")
    codec = dialect().MAVLink(None, srcSystem=system_id, srcComponent=component_id)
    codec.robust_parsing = robust
    if signing is not None:
        apply_signing(codec, signing, stream_table)
    return codec


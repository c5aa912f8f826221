"""The vtol-ftc MAVLink dialect: generation, loading, codecs and signing.

The dialect is described by ``protocols/dialects/vtolftc.xml`` (which includes pymavlink's
``common.xml``) and turned into Python by pymavlink's own generator (mavgen, MAVLink 2.0 wire
protocol) the first time :func:`dialect` is called in a process. Nothing is hand-written: the
packers, the parser and the CRC extras all come from mavgen.

Where the generated module goes
    The first writable directory among

    1. ``$VTOLFTC_MAVLINK_CACHE`` (if set),
    2. ``protocols/generated/`` next to this file (git-ignored),
    3. ``$XDG_CACHE_HOME/vtolftc/mavlink`` (default ``~/.cache/vtolftc/mavlink``).

    The file is named ``vtolftc_<hash>.py`` where the hash covers the dialect XML, every XML it
    includes, the pymavlink version and the generator source; any change to one of those
    regenerates. Generation writes into a private temporary directory and publishes with an atomic
    :func:`os.replace`, so two processes generating at once both end with the same, complete file.

Codecs
    :func:`make_codec` returns the generated ``MAVLink`` object (packer + parser) with a given
    system/component id, robust parsing on (bad data comes back as ``MAVLink_bad_data`` instead of
    exceptions) and, when a :class:`SigningConfig` is given, MAVLink 2 message signing.
"""

from __future__ import annotations

import contextlib
import hashlib
import importlib.util
import io
import os
import re
import shutil
import sys
import tempfile
import threading
import time
from collections.abc import Callable
from dataclasses import dataclass
from pathlib import Path
from types import ModuleType
from typing import Any

__all__ = [
    "DIALECT_NAME",
    "DIALECT_XML",
    "MAVLINK_EPOCH_UNIX_S",
    "SigningConfig",
    "apply_signing",
    "cache_candidates",
    "dialect",
    "dialect_hash",
    "dialect_sources",
    "generate_dialect",
    "locate_or_generate",
    "make_codec",
    "signing_timestamp_now",
]

DIALECT_NAME = "vtolftc"
"""Base name of the dialect (XML file stem, ``DIALECT`` of the generated module)."""

DIALECT_XML = Path(__file__).resolve().parent / "dialects" / f"{DIALECT_NAME}.xml"
"""The dialect definition shipped with the package."""

MAVLINK_EPOCH_UNIX_S = 1420070400
"""1 January 2015 00:00 UTC, the origin of MAVLink signing timestamps (unit 10 us)."""

_MODULE_NAME = "protocols._dialect_vtolftc"
_INCLUDE_RE = re.compile(rb"<include>\s*([^<\s]+)\s*</include>")
_lock = threading.Lock()
_gen_lock = threading.RLock()  # mavgen prints; stdout redirection is process-global
_module: ModuleType | None = None


# --------------------------------------------------------------------------------------------
# sources and hash
# --------------------------------------------------------------------------------------------
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
    """The dialect XML followed by every XML it includes (transitively), without duplicates."""
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


def dialect_hash(xml: Path = DIALECT_XML) -> str:
    """Hex digest identifying the generated code: XML sources, pymavlink version, generator."""
    import pymavlink
    from pymavlink.generator import mavgen_python, mavparse

    h = hashlib.sha256()
    h.update(b"wire=2.0;lang=Python3;")
    h.update(getattr(pymavlink, "__version__", "?").encode())
    for mod in (mavgen_python, mavparse):
        h.update(Path(mod.__file__).read_bytes())
    for src in dialect_sources(xml):
        h.update(src.name.encode() + b"\0")
        h.update(src.read_bytes())
    return h.hexdigest()


# --------------------------------------------------------------------------------------------
# generation
# --------------------------------------------------------------------------------------------
def cache_candidates() -> list[Path]:
    """Directories tried, in order, for the generated module (see module docstring)."""
    dirs: list[Path] = []
    env = os.environ.get("VTOLFTC_MAVLINK_CACHE")
    if env:
        dirs.append(Path(env).expanduser())
    dirs.append(Path(__file__).resolve().parent / "generated")
    xdg = os.environ.get("XDG_CACHE_HOME") or str(Path.home() / ".cache")
    dirs.append(Path(xdg).expanduser() / "vtolftc" / "mavlink")
    return dirs


def generate_dialect(out_dir: Path, xml: Path = DIALECT_XML) -> Path:
    """Generate the dialect into ``out_dir`` (if not already there) and return the module path.

    Safe against concurrent generation: each caller works in its own temporary directory inside
    ``out_dir`` and publishes with an atomic rename; identical inputs give identical files.

    Raises:
        OSError: ``out_dir`` cannot be created or written.
        RuntimeError: mavgen rejected the XML (its output is in the message).
    """
    from pymavlink.generator import mavgen

    out_dir = Path(out_dir)
    digest = dialect_hash(xml)
    target = out_dir / f"{DIALECT_NAME}_{digest[:20]}.py"
    if target.is_file():
        return target
    with _gen_lock:
        return _generate_locked(out_dir, xml, target, mavgen)


def _generate_locked(out_dir: Path, xml: Path, target: Path, mavgen: Any) -> Path:
    if target.is_file():
        return target
    out_dir.mkdir(parents=True, exist_ok=True)
    work = Path(tempfile.mkdtemp(prefix=".gen-", dir=out_dir))
    try:
        sources = dialect_sources(xml)
        for src in sources:  # flat copy: includes are resolved by file name, next to the dialect
            shutil.copyfile(src, work / src.name)
        out_py = work / f"{DIALECT_NAME}.py"
        opts = mavgen.Opts(str(out_py), wire_protocol="2.0", language="Python3", validate=True)
        log = io.StringIO()
        try:
            with contextlib.redirect_stdout(log), contextlib.redirect_stderr(log):
                ok = mavgen.mavgen(opts, [str(work / sources[0].name)])
        except SystemExit as exc:  # mavgen calls exit() on some XML errors
            raise RuntimeError(f"mavgen failed on {xml}:\n{log.getvalue()}") from exc
        if not ok or not out_py.is_file():
            raise RuntimeError(f"mavgen failed on {xml}:\n{log.getvalue()}")
        os.replace(out_py, target)
    finally:
        shutil.rmtree(work, ignore_errors=True)
    _remove_stale(out_dir, keep=target)
    return target


def _remove_stale(out_dir: Path, keep: Path, min_age_s: float = 3600.0) -> None:
    """Best effort: drop generated files of other hashes that nobody touched for an hour."""
    now = time.time()
    for old in out_dir.glob(f"{DIALECT_NAME}_*.py"):
        if old == keep:
            continue
        with contextlib.suppress(OSError):
            if now - old.stat().st_mtime > min_age_s:
                old.unlink()


def _load(path: Path) -> ModuleType:
    spec = importlib.util.spec_from_file_location(_MODULE_NAME, path)
    if spec is None or spec.loader is None:  # pragma: no cover - importlib contract
        raise ImportError(f"cannot import generated dialect {path}")
    module = importlib.util.module_from_spec(spec)
    sys.modules[_MODULE_NAME] = module
    try:
        spec.loader.exec_module(module)
    except BaseException:
        sys.modules.pop(_MODULE_NAME, None)
        raise
    return module


def dialect() -> ModuleType:
    """The generated vtol-ftc dialect module (pymavlink ``MAVLink`` class, messages, enums).

    Generated on first use (see the module docstring for where), then cached for the process.
    """
    global _module
    if _module is not None:
        return _module
    with _lock:
        if _module is not None:
            return _module
        _module = _load(locate_or_generate())
        return _module


def locate_or_generate(candidates: list[Path] | None = None, xml: Path = DIALECT_XML) -> Path:
    """Path of the generated module in the first usable directory (default
    :func:`cache_candidates`), generating it there if needed.

    Raises:
        OSError: no candidate directory is writable.
    """
    errors: list[str] = []
    for out_dir in cache_candidates() if candidates is None else candidates:
        try:
            return generate_dialect(out_dir, xml)
        except OSError as exc:  # read-only or unusable directory: try the next one
            errors.append(f"{out_dir}: {exc}")
    raise OSError("no writable directory for the generated MAVLink dialect: " + "; ".join(errors))


# --------------------------------------------------------------------------------------------
# codecs and signing
# --------------------------------------------------------------------------------------------
def signing_timestamp_now() -> int:
    """Current MAVLink signing timestamp: units of 10 us since 2015-01-01 00:00 UTC."""
    return int((time.time() - MAVLINK_EPOCH_UNIX_S) * 100_000)


@dataclass(frozen=True)
class SigningConfig:
    """MAVLink 2 message signing parameters.

    Attributes:
        secret_key: the 32-byte shared secret (see :meth:`from_passphrase`).
        link_id: signing link id (0..255) written into outgoing signatures.
        timestamp: initial signing timestamp (10 us units since 2015-01-01); ``None`` = now.
        sign_outgoing: sign every outgoing frame.
        allow_unsigned: what to do with incoming frames that are unsigned *or* carry a bad
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


def apply_signing(codec: Any, signing: SigningConfig) -> None:
    """Enable MAVLink 2 signing on a generated ``MAVLink`` codec object."""
    s = codec.signing
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
) -> Any:
    """A generated ``MAVLink`` object (encoder + parser) of the vtol-ftc dialect.

    Args:
        system_id: source system id of packed frames (255 = ground-station convention; the
            autopilot is 1).
        component_id: source component id (190 = MAV_COMP_ID_MISSIONPLANNER; autopilot 1).
        signing: enable MAVLink 2 signing with these parameters.
        robust: robust parsing (bad data returned as ``MAVLink_bad_data``, never raised).

    The codec's ``file`` is ``None``: pack with ``msg.pack(codec)`` (or let a
    :class:`protocols.link.Link` do it) rather than ``codec.send``.
    """
    if not 0 <= system_id <= 255 or not 0 <= component_id <= 255:
        raise ValueError(f"system/component id out of range: {system_id}/{component_id}")
    codec = dialect().MAVLink(None, srcSystem=system_id, srcComponent=component_id)
    codec.robust_parsing = robust
    if signing is not None:
        apply_signing(codec, signing)
    return codec

"""Files the project writes: one conversion of numpy values and non-finite floats for JSON,
and one atomic writer.

Every writer of ``metrics.json``, ``run.json``, summaries, campaign results and the synthesis'
gain files goes through :func:`json_safe` (or :func:`dumps`), so they agree on what a NaN or
a numpy array becomes. The convention: a NaN or infinity is written as ``null``. Strict JSON has
no such numbers, and strict readers (browsers' ``JSON.parse``, jq, most non-Python libraries)
accept ``null`` but neither a bare ``NaN`` nor a string "nan" as a number. Files written before
this convention spelt them ``"nan"`` / ``"inf"`` (only in gain-file metadata, which the
readers keep as it is and never compute with), so such files still load.
Every file that must never be seen half-written (gain files, reports, summaries, campaign
tables) goes through :func:`atomic_write` / :func:`atomic_write_text`: a temporary file in the
same folder, flushed to disk, then renamed over the target, so a crash, SIGKILL or Ctrl-C
leaves either the old file or the new one.
"""

from __future__ import annotations

import contextlib
import json
import math
import os
import tempfile
from collections.abc import Callable, Mapping
from pathlib import Path
from typing import IO, Any

import numpy as np

__all__ = ["atomic_write", "atomic_write_text", "dumps", "json_safe"]


def json_safe(x: Any) -> Any:
    """A JSON-serialisable copy of ``x``.

    Parameters
    ----------
    x : object
        Nested mappings, lists, tuples, numpy scalars and arrays, floats, complex numbers, ...

    Returns
    -------
    object
        The same structure with dict keys as strings, tuples and arrays as lists, numpy
        scalars as Python numbers, complex numbers as ``[re, im]`` and NaN / +-inf as
        ``None`` (JSON has no such numbers).
    """
    if isinstance(x, Mapping):
        return {str(k): json_safe(v) for k, v in x.items()}
    if isinstance(x, list | tuple):
        return [json_safe(v) for v in x]
    if isinstance(x, np.ndarray):
        return json_safe(x.tolist())
    if isinstance(x, np.generic):
        x = x.item()
    if isinstance(x, complex):
        return [json_safe(x.real), json_safe(x.imag)]
    if isinstance(x, float) and not math.isfinite(x):
        return None
    return x


def dumps(x: Any) -> str:
    """``json.dumps(json_safe(x), indent=2)`` with a final newline: the run files' format."""
    return json.dumps(json_safe(x), indent=2) + "\n"


def atomic_write(path: str | os.PathLike[str], write: Callable[[IO[bytes]], object]) -> Path:
    """Write a file atomically: ``write(fh)`` fills a temporary binary file in the same folder,
    which is flushed to disk and renamed over ``path``.

    Parameters
    ----------
    path : path-like
        The file to (re)place; its folder is created if missing.
    write : callable
        Called once with the open temporary file (binary, write mode).

    Returns
    -------
    pathlib.Path
        ``path``. The file gets the permissions a plain ``open(path, "w")`` would give (0666
        less the umask), not the owner-only mode of the temporary file. On any exception the
        temporary file is removed and ``path`` is left as it was.
    """
    p = Path(path)
    p.parent.mkdir(parents=True, exist_ok=True)
    fd, tmp = tempfile.mkstemp(prefix=f".{p.name}.", suffix=".tmp", dir=p.parent)
    try:
        umask = os.umask(0)
        os.umask(umask)
        os.fchmod(fd, 0o666 & ~umask)
        with os.fdopen(fd, "wb") as f:
            write(f)
            f.flush()
            os.fsync(f.fileno())
        os.replace(tmp, p)
    except BaseException:
        with contextlib.suppress(OSError):
            os.unlink(tmp)
        raise
    return p


def atomic_write_text(path: str | os.PathLike[str], text: str) -> Path:
    """:func:`atomic_write` of ``text`` encoded as UTF-8."""
    data = text.encode("utf-8")
    return atomic_write(path, lambda f: f.write(data))

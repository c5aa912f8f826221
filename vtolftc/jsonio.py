"""JSON for run files: one conversion of numpy values and non-finite floats.

Every writer of ``metrics.json``, ``run.json``, summaries and campaign results goes through
:func:`json_safe` (or :func:`dumps`), so they agree on what a NaN or a numpy array becomes.
"""

from __future__ import annotations

import json
import math
from typing import Any

import numpy as np

__all__ = ["dumps", "json_safe"]


def json_safe(x: Any) -> Any:
    """A JSON-serialisable copy of ``x``.

    Parameters
    ----------
    x : object
        Nested dicts, lists, tuples, numpy scalars and arrays, floats, ...

    Returns
    -------
    object
        The same structure with dict keys as strings, tuples and arrays as lists, numpy
        scalars as Python numbers and NaN / +-inf as ``None`` (JSON has no such numbers).
    """
    if isinstance(x, dict):
        return {str(k): json_safe(v) for k, v in x.items()}
    if isinstance(x, list | tuple):
        return [json_safe(v) for v in x]
    if isinstance(x, np.ndarray):
        return json_safe(x.tolist())
    if isinstance(x, np.generic):
        x = x.item()
    if isinstance(x, float) and not math.isfinite(x):
        return None
    return x


def dumps(x: Any) -> str:
    """``json.dumps(json_safe(x), indent=2)`` with a final newline: the run files' format."""
    return json.dumps(json_safe(x), indent=2) + "\n"

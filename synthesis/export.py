"""Write the designs as files the autopilot reads (it never imports this package).

- GS-SHIF and SHIF: format ``vtolftc-gain-schedule/1`` (specification: the docstring of
  :mod:`vtolftc.firmware_sim.autopilot.schedule`); SHIF is a schedule with a single breakpoint.
- LQR: format ``vtolftc-lqr-gains/1``::

    {"format": "vtolftc-lqr-gains/1", "controller": "lqr",
     "airframe": {"name": ..., "sha256": ...},
     "airspeed_breakpoints_m_s": [0.0],            # one breakpoint = constant gains
     "axes": {"roll": {"k_int": [..], "k_angle": [..], "k_rate": [..]}, "pitch": {...},
              "yaw": {...}},
     ... free metadata (Q, R, closed-loop poles, ...)}

  law: tau = k_int int(angle_ref - angle) dt + k_angle (angle_ref - angle) - k_rate rate,
  units k_int N m/(rad s), k_angle N m/rad, k_rate N m s/rad; one value per breakpoint.

Every file is written atomically (temporary file in the same folder, then ``os.replace``), so
an interrupted run never leaves a truncated file behind.
"""

from __future__ import annotations

import json
import math
import os
from collections.abc import Mapping, Sequence
from datetime import UTC, datetime
from pathlib import Path
from typing import Any

import numpy as np

from vtolftc.airframe.loader import Airframe
from vtolftc.jsonio import atomic_write_text
from vtolftc.synthesis.loops import PARAM_NAMES
from vtolftc.synthesis.models import AXES

__all__ = [
    "LQR_FORMAT",
    "SCHEDULE_FORMAT",
    "atomic_write_text",
    "jsonable",
    "lqr_document",
    "schedule_document",
    "tool_version",
    "write_json",
]

SCHEDULE_FORMAT = "vtolftc-gain-schedule/1"
LQR_FORMAT = "vtolftc-lqr-gains/1"


def tool_version() -> str:
    """Version string of the installed vtol-ftc distribution.

    Returns
    -------
    str
        The version, or ``unknown`` if the distribution is not installed.
    """
    try:
        from importlib.metadata import version

        return version("vtol-ftc")
    except Exception:
        return "unknown"


def jsonable(x: Any) -> Any:
    """numpy scalars/arrays, complex numbers, dataclass-free containers -> JSON values.

    Complex numbers become [re, im]; non-finite floats become strings ("inf", "nan") so the
    file stays strict JSON.

    Parameters
    ----------
    x : Any
        The value (dicts, lists, tuples, numpy arrays and scalars, numbers, strings).

    Returns
    -------
    Any
        The same structure of JSON values.
    """
    if isinstance(x, Mapping):
        return {str(k): jsonable(v) for k, v in x.items()}
    if isinstance(x, list | tuple):
        return [jsonable(v) for v in x]
    if isinstance(x, np.ndarray):
        return [jsonable(v) for v in x.tolist()]
    if isinstance(x, complex | np.complexfloating):
        return [jsonable(float(x.real)), jsonable(float(x.imag))]
    if isinstance(x, bool | np.bool_):
        return bool(x)
    if isinstance(x, int | np.integer):
        return int(x)
    if isinstance(x, float | np.floating):
        f = float(x)
        return f if math.isfinite(f) else str(f)
    return x




def write_json(path: str | os.PathLike[str], doc: Mapping[str, Any]) -> Path:
    """Atomically write a JSON document (strict JSON, indented).

    Parameters
    ----------
    path : str or os.PathLike
        Destination file.
    doc : mapping
        The document (passed through :func:`jsonable`).

    Returns
    -------
    pathlib.Path
        The path written.
    """
    return atomic_write_text(path, json.dumps(jsonable(doc), indent=2, allow_nan=False) + "\n")


def _common(af: Airframe) -> dict[str, Any]:
    return {
        "airframe": {"name": af.name, "sha256": af.sha256, "source": Path(af.source).name},
        "tool": {"name": "vtolftc synth", "version": tool_version()},
        "created_utc": datetime.now(UTC).strftime("%Y-%m-%dT%H:%M:%SZ"),
    }


def schedule_document(af: Airframe, controller: str, breakpoints_m_s: Sequence[float],
                      gains: Mapping[str, Sequence[Mapping[str, float]]],
                      axes_metadata: Mapping[str, Any] | None = None,
                      metadata: Mapping[str, Any] | None = None) -> dict[str, Any]:
    """A ``vtolftc-gain-schedule/1`` document.

    Values are rounded to 6 significant digits (well below the design's sensitivity) so the
    files stay readable.

    Parameters
    ----------
    af : Airframe
        The airframe (its file's sha256 is recorded).
    controller : str
        Controller name, e.g. ``"gs-shif"``.
    breakpoints_m_s : sequence of float
        Airspeed breakpoints (m/s).
    gains : mapping of str to sequence of mapping
        ``gains[axis][i]`` is the gain dict (keys :data:`vtolftc.synthesis.loops.PARAM_NAMES`)
        at breakpoint i.
    axes_metadata : mapping, optional
        Extra per-axis entries.
    metadata : mapping, optional
        Extra top-level metadata.

    Returns
    -------
    dict
        The document, ready for :func:`write_json`.

    Raises
    ------
    ValueError
        If an axis has not one gain set per breakpoint.
    """
    axes: dict[str, Any] = {}
    for ax in AXES:
        rows = gains[ax]
        if len(rows) != len(breakpoints_m_s):
            raise ValueError(f"{ax}: {len(rows)} gain sets for {len(breakpoints_m_s)} "
                             "breakpoints")
        axes[ax] = {k: [float(f"{r[k]:.6g}") for r in rows] for k in PARAM_NAMES}
        if axes_metadata and ax in axes_metadata:
            axes[ax]["metadata"] = axes_metadata[ax]
    doc: dict[str, Any] = {"format": SCHEDULE_FORMAT, "controller": controller}
    common = _common(af)
    doc["airframe"] = common.pop("airframe")
    doc["airspeed_breakpoints_m_s"] = [float(b) for b in breakpoints_m_s]
    doc["axes"] = axes
    doc.update(common)
    if metadata:
        doc.update(metadata)
    return doc


def lqr_document(af: Airframe, gains: Mapping[str, Mapping[str, float]],
                 metadata: Mapping[str, Any] | None = None) -> dict[str, Any]:
    """A ``vtolftc-lqr-gains/1`` document with one breakpoint (0 m/s): constant gains.

    Parameters
    ----------
    af : Airframe
        The airframe (its file's sha256 is recorded).
    gains : mapping of str to mapping
        ``gains[axis]`` with keys k_int, k_angle, k_rate (units in the module docstring).
    metadata : mapping, optional
        Extra top-level metadata.

    Returns
    -------
    dict
        The document, ready for :func:`write_json`.
    """
    common = _common(af)
    doc: dict[str, Any] = {
        "format": LQR_FORMAT,
        "controller": "lqr",
        "airframe": common.pop("airframe"),
        "airspeed_breakpoints_m_s": [0.0],
        "axes": {ax: {k: [float(f"{gains[ax][k]:.6g}")] for k in ("k_int", "k_angle",
                                                                   "k_rate")}
                 for ax in AXES},
        "units": {"k_int": "N m/(rad s)", "k_angle": "N m/rad", "k_rate": "N m s/rad"},
        "law": "tau = k_int * int(angle_ref - angle) dt + k_angle * (angle_ref - angle) "
               "- k_rate * rate",
    }
    doc.update(common)
    if metadata:
        doc.update(metadata)
    return doc

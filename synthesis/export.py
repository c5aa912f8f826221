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

Every file is written atomically (:func:`vtolftc.jsonio.atomic_write_text`), so an interrupted
run never leaves a truncated file behind, in the project's one JSON convention
(:func:`vtolftc.jsonio.json_safe`: a NaN or infinity is written as ``null``).
"""

from __future__ import annotations

import json
import os
from collections.abc import Mapping, Sequence
from datetime import UTC, datetime
from pathlib import Path
from typing import Any

from vtolftc.airframe.loader import Airframe
from vtolftc.jsonio import atomic_write_text, json_safe
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


#: the JSON conversion of the project (:func:`vtolftc.jsonio.json_safe`: NaN / inf -> null,
#: complex -> [re, im]), under the name this package has always exported
jsonable = json_safe


def write_json(path: str | os.PathLike[str], doc: Mapping[str, Any]) -> Path:
    """Atomically write a JSON document (strict JSON, indented).

    Parameters
    ----------
    path : str or os.PathLike
        Destination file.
    doc : mapping
        The document (passed through :func:`jsonable`: NaN / inf become null).

    Returns
    -------
    pathlib.Path
        The path written.
    """
    return atomic_write_text(path, json.dumps(json_safe(doc), indent=2, allow_nan=False) + "\n")


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

"""Reading a rerun recording (``.rrd``) back as time series (tests, reports, comparisons)."""

from __future__ import annotations

import warnings
from collections.abc import Sequence
from pathlib import Path
from typing import Any

import numpy as np

from vtolftc.telemetry.rerun_scene import TIMELINE

__all__ = ["flown_path", "read_recording"]


def read_recording(path: Path | str, entities: Sequence[str] | None = None,
                   ) -> dict[str, tuple[np.ndarray, Any]]:
    """Read the time series of a ``.rrd`` file: ``{entity_path: (times_s, values)}``.

    ``times_s`` is the ``sim_time`` timeline in seconds (sorted); ``values`` is a float array
    (one column per scalar, squeezed to 1-D when single) for numeric data, else a list of
    Python values (texts, states, transforms' translations). Entity paths have no leading
    slash. Static data and entities without a ``sim_time`` timeline are not included. Works
    also on files of an interrupted run (no footer).
    """
    from rerun.chunk import RrdReader

    parts: dict[str, list[tuple[np.ndarray, list[Any]]]] = {}
    with warnings.catch_warnings():
        warnings.filterwarnings("ignore", message=".*no footer.*")   # interrupted runs
        reader = RrdReader(str(path))
    for ch in reader.stream():
        if ch.is_static or TIMELINE not in ch.timeline_names:
            continue
        ent = ch.entity_path.lstrip("/")
        if entities is not None and ent not in entities:
            continue
        rb = ch.to_record_batch()
        names = rb.schema.names
        t = rb.column(names.index(TIMELINE)).cast("int64").to_numpy(zero_copy_only=False)
        data_cols = [n for n in names if n not in ("rerun.controls.RowId", "log_time", TIMELINE)]
        preferred = [n for n in data_cols if n.endswith((":scalars", ":text", ":state",
                                                         ":translation", ":strips"))]
        col = (preferred or data_cols or [None])[0]
        if col is None:
            continue
        vals = rb.column(names.index(col)).to_pylist()
        parts.setdefault(ent, []).append((t, vals))
    out: dict[str, tuple[np.ndarray, Any]] = {}
    for ent, chunks in parts.items():
        t = np.concatenate([c[0] for c in chunks])
        vals: list[Any] = [v for c in chunks for v in c[1]]
        order = np.argsort(t, kind="stable")
        ts = t[order] * 1e-9
        vs = [vals[i] for i in order]
        numeric = all(isinstance(v, list) and v and all(isinstance(x, (int, float)) for x in v)
                      for v in vs) and len(vs) > 0
        if numeric:
            arr = np.array(vs, dtype=float)
            out[ent] = (ts, arr[:, 0] if arr.shape[1] == 1 else arr)
        else:
            out[ent] = (ts, [v[0] if isinstance(v, list) and len(v) == 1 else v for v in vs])
    return out


def flown_path(data: dict[str, tuple[np.ndarray, Any]]) -> np.ndarray:
    """The whole flown path of a recording read by :func:`read_recording`, NED [m], (N, 3).

    Joins the last logged form of every path segment (``world/path/00000``, ``/00001``, ...,
    in order), each after the first without its first point (the last of the segment before).
    An empty (0, 3) array when the recording has no path.
    """
    keys = sorted(k for k in data if k.startswith("world/path/"))
    parts = []
    for i, k in enumerate(keys):
        strips = data[k][1][-1]                 # the segment's last form: one strip
        pts = np.asarray(strips[0] if strips and isinstance(strips[0][0], list) else strips,
                         dtype=float).reshape(-1, 3)
        parts.append(pts if i == 0 else pts[1:])
    return np.concatenate(parts) if parts else np.zeros((0, 3))

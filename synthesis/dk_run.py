"""``vtolftc synth --dk N``: the robust point design, then the D-K iteration
(:mod:`vtolftc.synthesis.dk_robust`) at every axis-point, written beside it.

``DIR`` keeps the robust design as ``vtolftc synth`` writes it; ``DIR/dk/`` gets
``gs-shif.json`` (the D-K gains, ``vtolftc-gain-schedule/1``), ``shif.json`` and ``lqr.json``
(copies of the robust run's, so ``vtolftc fly --gains DIR/dk`` flies the set), ``dk.json``
(every iteration: gains, measured peak mu, the fitted D(s), requirement norms) and ``DK.md``
(table 3 before/after).
"""

from __future__ import annotations

import shutil
from collections.abc import Callable, Mapping, Sequence
from concurrent.futures import ProcessPoolExecutor
from pathlib import Path
from typing import Any

from vtolftc.airframe.loader import Airframe
from vtolftc.synthesis.dk_robust import DKPoint, DKSettings, dk_gains, dk_schedule, dk_table
from vtolftc.synthesis.export import schedule_document, write_json
from vtolftc.synthesis.uncertainty import DesignPoint

__all__ = ["run_dk", "write_dk_outputs"]

_SETTINGS = DKSettings()


def write_dk_outputs(af: Airframe, points: Sequence[DesignPoint],
                     gains: Mapping[str, Sequence[Mapping[str, float]]],
                     results: Sequence[DKPoint], settings: DKSettings, out_dir: str | Path,
                     base_dir: str | Path) -> dict[str, Path]:
    """Write ``out_dir``'s gain files, ``dk.json`` and ``DK.md`` (module docstring).

    Parameters
    ----------
    af : Airframe
        The airframe.
    points : sequence of DesignPoint
        The schedule's design points.
    gains : mapping of str to sequence of mapping
        The starting schedule ``gains[axis][i]``.
    results : sequence of DKPoint
        The iterated axis-points.
    settings : DKSettings
        The iteration's settings (recorded).
    out_dir : str or pathlib.Path
        Output folder (created).
    base_dir : str or pathlib.Path
        Folder holding the starting design's ``shif.json`` and ``lqr.json`` (copied when
        present).

    Returns
    -------
    dict of str to pathlib.Path
        The files written, by name.
    """
    out = Path(out_dir)
    out.mkdir(parents=True, exist_ok=True)
    meta = {"synthesis_method": "robust + D-K (synthesis/dk_robust.py)",
            "dk_settings": settings.to_dict()}
    files = {"gs-shif": write_json(out / "gs-shif.json", schedule_document(
        af, "gs-shif", [p.airspeed_m_s for p in points], dk_gains(gains, points, results),
        None, meta))}
    for name in ("shif", "lqr"):
        src = Path(base_dir) / f"{name}.json"
        if src.is_file():
            shutil.copy(src, out / src.name)
            files[name] = out / src.name
    doc: dict[str, Any] = {"settings": settings.to_dict(),
                           "points": [r.to_dict() for r in results]}
    files["dk.json"] = write_json(out / "dk.json", doc)
    md = ("# D-K iteration (`vtolftc synth --dk`)\n\nmu from `synthesis/robustness.analyse` "
          "(upper bound; lower bound of the D-K gains beside), delay margin exact in "
          "frequency on the design plant (requirement >= 50 ms).\n\n" + dk_table(results))
    (out / "DK.md").write_text(md)
    files["DK.md"] = out / "DK.md"
    return files


def run_dk(af: Airframe, points: Sequence[DesignPoint],
           gains: Mapping[str, Sequence[Mapping[str, float]]], out_dir: str | Path,
           base_dir: str | Path, *, settings: DKSettings = _SETTINGS, jobs: int = 2,
           progress: Callable[[str], None] | None = None,
           ) -> tuple[list[DKPoint], dict[str, Path]]:
    """D-K at every axis-point of ``gains`` (``jobs`` worker processes), then the outputs.

    Parameters
    ----------
    af : Airframe
        The airframe.
    points : sequence of DesignPoint
        The schedule's design points.
    gains : mapping of str to sequence of mapping
        The starting schedule ``gains[axis][i]`` (stabilising).
    out_dir, base_dir : str or pathlib.Path
        As in :func:`write_dk_outputs`.
    settings : DKSettings, optional
        Iteration settings.
    jobs : int, optional
        Worker processes (1: this process).
    progress : callable, optional
        ``progress(label)`` after each axis-point.

    Returns
    -------
    results : list of DKPoint
        Per axis-point.
    files : dict of str to pathlib.Path
        The files written.
    """
    ex = ProcessPoolExecutor(jobs) if jobs > 1 else None
    try:
        res = dk_schedule(af, points, gains, settings=settings, executor=ex, progress=progress)
    finally:
        if ex is not None:
            ex.shutdown(cancel_futures=True)
    return res, write_dk_outputs(af, points, gains, res, settings, out_dir, base_dir)

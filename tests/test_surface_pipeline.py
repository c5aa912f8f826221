"""The surface synthesis' designs and validation on one pool
(:func:`vtolftc.synthesis.surface_run._pipeline`, ``vtolftc synth --method surface`` with
``--jobs`` > 1): the same designs, gain files and validation rows as the serial order, on a
tiny grid (two design points, degree 1, one iteration, no mu)."""

from __future__ import annotations

import json
from pathlib import Path
from typing import Any

import pytest

from vtolftc.airframe.loader import load_airframe
from vtolftc.synthesis import surface_run as sr
from vtolftc.synthesis.models import AXES
from vtolftc.synthesis.robust import robust_points
from vtolftc.synthesis.surfaces import surface_grid
from vtolftc.synthesis.validation import FlownSchedule, validate_schedule


def _setup() -> tuple[Any, dict[str, tuple[Any, ...]], dict[str, Any], dict[str, Any]]:
    af = load_airframe()
    by_v = {p.airspeed_m_s: p for p in robust_points(af)}
    grid = surface_grid([by_v[4.0], by_v[10.0]], 1)
    args = {ax: (af, ax, grid, 1, 0, 0, 1) for ax in AXES}
    meta = {"design_points": [{"number": p.number, "airspeed_m_s": p.airspeed_m_s,
                               "v_min_m_s": p.v_min_m_s, "v_max_m_s": p.v_max_m_s}
                              for p in grid]}
    return af, args, meta, {"density": 3, "mu": False, "certificate": False, "seed": 0}


def test_pipeline_is_the_serial_order(tmp_path: Path) -> None:
    af, args, meta, val_kw = _setup()
    files: dict[str, Path] = {}
    ticks: list[tuple[str, int]] = []
    times: dict[str, float] = {}
    cpu: dict[str, float] = {}
    designs, scheds, rows = sr._pipeline(
        af, args, val_kw, 2, lambda label, n: ticks.append((label, n)), times, cpu,
        lambda ds: files.update(sr.write_surface_gains_all(af, ds, tmp_path / "pool", meta)),
        meta)
    serial = {ax: sr._design_job(args[ax]) for ax in AXES}
    sfiles = sr.write_surface_gains_all(af, serial, tmp_path / "serial", meta)
    sdoc = json.loads(sfiles["gs-shif"].read_text(encoding="utf-8"))
    want = validate_schedule(af, sdoc, **val_kw)
    assert list(designs) == list(AXES)
    for ax in AXES:
        assert (designs[ax].surface.coefficients.tobytes()
                == serial[ax].surface.coefficients.tobytes())
        assert designs[ax].surface_objective == serial[ax].surface_objective
    pdoc = json.loads(files["gs-shif"].read_text(encoding="utf-8"))
    assert pdoc["axes"] == sdoc["axes"]
    assert [r.to_dict() for r in rows] == [r.to_dict() for r in want.rows]
    assert len(rows) == 3 * 4 and [r.axis for r in rows] == [ax for ax in AXES for _ in "abcd"]
    sr._check_same_gains(pdoc, scheds)
    assert sorted(label for label, _ in ticks[:3]) == sorted(f"surface {ax}" for ax in AXES)
    assert [label for label, _ in ticks[3:]] == [
        f"validation {r.axis} {r.airspeed_m_s:g} m/s" for r in rows]
    assert all(n == 1 for _, n in ticks)
    assert set(times) == set(cpu) == {"surface designs", "validation"}
    assert all(v > 0 for v in cpu.values())


def test_validation_with_other_gains_than_the_file_is_refused() -> None:
    doc = {"airspeed_breakpoints_m_s": [0.0, 10.0],
           "axes": {ax: {k: [1.0, 2.0] for k in ("kp_angle", "kp_rate", "ki_rate",
                                                 "kd_rate", "tf_rate_s")} for ax in AXES}}
    one = {"airspeed_breakpoints_m_s": [0.0, 10.0], "axes": {"pitch": doc["axes"]["pitch"]}}
    s = FlownSchedule(one)
    assert s.gains_at("pitch", 2.5) == FlownSchedule(doc).gains_at("pitch", 2.5)
    sr._check_same_gains(doc, {"pitch": s})
    doc["axes"]["pitch"]["ki_rate"][1] = 2.0000001
    with pytest.raises(RuntimeError, match="pitch"):
        sr._check_same_gains(doc, {"pitch": s})
    bp = dict(doc, airspeed_breakpoints_m_s=[0.0, 11.0])
    bp["axes"] = {"pitch": one["axes"]["pitch"]}
    with pytest.raises(RuntimeError, match="pitch"):
        sr._check_same_gains(bp, {"pitch": s})

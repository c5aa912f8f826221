"""The one JSON conversion of run files."""

from __future__ import annotations

import json
import math

import numpy as np
import pytest

from vtolftc.jsonio import dumps, json_safe


def test_json_safe_converts_numpy_and_non_finite_values():
    x = {1: np.float64(2.5), "a": (np.int32(3), math.nan), "b": np.array([[1.0, np.inf]]),
         "c": [np.bool_(True), -math.inf, "s", None]}
    out = json_safe(x)
    assert out == {"1": 2.5, "a": [3, None], "b": [[1.0, None]], "c": [True, None, "s", None]}
    assert type(out["a"][0]) is int and type(out["c"][0]) is bool
    assert json.loads(dumps(x)) == out and dumps(x).endswith("}\n")
    assert "NaN" not in dumps({"v": np.array([math.nan])})


def test_complex_numbers_and_mappings():
    from types import MappingProxyType

    assert json_safe(complex(1.0, math.nan)) == [1.0, None]
    assert json_safe(np.complex128(2 - 3j)) == [2.0, -3.0]
    assert json_safe(MappingProxyType({"a": np.float32(0.5)})) == {"a": 0.5}


def test_synthesis_files_use_the_same_convention(tmp_path):
    """The gain files of the synthesis follow this module's convention: null, never "nan"."""
    from vtolftc.synthesis.export import write_json

    p = write_json(tmp_path / "g.json", {"M": math.nan, "w": [math.inf, 1.0], "z": 1 + 2j})
    assert json.loads(p.read_text()) == {"M": None, "w": [None, 1.0], "z": [1.0, 2.0]}


def strict_loads(text: str) -> object:
    """json.loads as a strict reader (browser, jq) takes it: no NaN / Infinity literals."""
    def refuse(name: str) -> object:
        raise ValueError(f"non-standard JSON constant {name}")
    return json.loads(text, parse_constant=refuse)


def test_shipped_gain_files_are_strict_json_without_string_numbers():
    from pathlib import Path

    import vtolftc.firmware_sim.autopilot as ap

    files = sorted((Path(ap.__file__).parent / "gains").rglob("*.json"))
    assert len(files) >= 6
    def leaves(x: object) -> list[object]:
        if isinstance(x, dict):
            return [y for v in x.values() for y in leaves(v)]
        if isinstance(x, list):
            return [y for v in x for y in leaves(v)]
        return [x]

    for f in files:
        bad = [x for x in leaves(strict_loads(f.read_text())) if x in ("nan", "inf", "-inf")]
        assert not bad, f.name


def test_gain_files_of_the_old_spelling_still_load(tmp_path):
    """Files written before this convention spelt non-finite metadata "nan": they load, and
    so do the same files with null."""
    from vtolftc.firmware_sim.autopilot.schedule import GainSchedule

    ax = {"kp_angle": [4.0], "kp_rate": [1.0], "ki_rate": [0.5], "kd_rate": [0.1],
          "tf_rate_s": [0.02]}
    for spelt in ("nan", None):
        doc = {"format": "vtolftc-gain-schedule/1", "controller": "shif",
               "airframe": {"name": "DS-1", "sha256": "ab" * 32},
               "airspeed_breakpoints_m_s": [0.0],
               "axes": {a: {**ax, "metadata": {"table2_M": spelt}}
                        for a in ("roll", "pitch", "yaw")}}
        (tmp_path / "shif.json").write_text(json.dumps(doc))
        s = GainSchedule.load(tmp_path / "shif.json")
        assert s.gains_at(3.0)["yaw"].kp_angle == 4.0


def test_atomic_write_replaces_whole_or_not_at_all(tmp_path):
    """The one atomic writer: the file appears whole with ordinary permissions; a writer that
    fails leaves the old file and no temporary file."""
    import os

    from vtolftc.jsonio import atomic_write, atomic_write_text

    p = atomic_write_text(tmp_path / "sub" / "a.json", "{}\n")
    assert p.read_text() == "{}\n"
    umask = os.umask(0)
    os.umask(umask)
    assert p.stat().st_mode & 0o777 == 0o666 & ~umask

    def broken(fh):
        fh.write(b"half")
        raise RuntimeError("crash mid-write")

    with pytest.raises(RuntimeError):
        atomic_write(p, broken)
    assert p.read_text() == "{}\n"
    assert sorted(x.name for x in p.parent.iterdir()) == ["a.json"]

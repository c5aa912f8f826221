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

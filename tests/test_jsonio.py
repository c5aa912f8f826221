"""The one JSON conversion of run files."""

from __future__ import annotations

import json
import math

import numpy as np

from vtolftc.jsonio import dumps, json_safe


def test_json_safe_converts_numpy_and_non_finite_values():
    x = {1: np.float64(2.5), "a": (np.int32(3), math.nan), "b": np.array([[1.0, np.inf]]),
         "c": [np.bool_(True), -math.inf, "s", None]}
    out = json_safe(x)
    assert out == {"1": 2.5, "a": [3, None], "b": [[1.0, None]], "c": [True, None, "s", None]}
    assert type(out["a"][0]) is int and type(out["c"][0]) is bool
    assert json.loads(dumps(x)) == out and dumps(x).endswith("}\n")
    assert "NaN" not in dumps({"v": np.array([math.nan])})

"""DurationStats: bounded-memory step statistics against numpy on the full sample."""

from __future__ import annotations

import math

import numpy as np
import pytest

from vtolftc.telemetry.streamstats import DurationStats


@pytest.mark.parametrize("seed", [0, 1, 2])
def test_quantiles_match_numpy_within_half_a_bin(seed: int) -> None:
    rng = np.random.default_rng(seed)
    x = rng.lognormal(mean=math.log(4e-4), sigma=0.8, size=20_000)
    s = DurationStats()
    for v in x:
        s.add(float(v))
    assert s.n == x.size
    assert s.mean == pytest.approx(float(x.mean()), rel=1e-12)
    assert s.max == float(x.max()) and s.min == float(x.min())
    for q in (0.0, 0.1, 0.5, 0.9, 0.99, 1.0):
        want = float(np.percentile(x, 100 * q, method="lower"))
        assert s.quantile(q) == pytest.approx(want, rel=math.sqrt(1.01) - 1 + 1e-12), q


def test_memory_is_fixed_and_out_of_range_values_count() -> None:
    s = DurationStats(lo_s=1e-6, hi_s=1.0)
    size = s._counts.nbytes
    for v in (1e-9, 5.0, 1e-3):
        s.add(v)
    assert s._counts.nbytes == size
    assert s.n == 3 and s.min == 1e-9 and s.max == 5.0
    assert s.quantile(1.0) == 5.0  # clipped to the exact max
    assert s.quantile(0.0) == 1e-9


def test_empty_and_bad_arguments() -> None:
    s = DurationStats()
    assert math.isnan(s.mean) and math.isnan(s.quantile(0.5))
    with pytest.raises(ValueError):
        DurationStats(lo_s=1.0, hi_s=0.5)
    with pytest.raises(ValueError):
        DurationStats(ratio=1.0)

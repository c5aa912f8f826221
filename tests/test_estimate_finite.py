"""StateEstimate's finiteness test (13 values summed as x - x) against math.isfinite."""

from __future__ import annotations

import itertools
import math

import numpy as np

from vtolftc.firmware_sim.autopilot.estimate import StateEstimate
from vtolftc.firmware_sim.autopilot.interface import NavState

_BAD = (math.nan, math.inf, -math.inf)
_EDGE = (0.0, -0.0, 1e308, -1e308, 5e-324, math.pi)


def _nav(a: np.ndarray) -> NavState:
    return NavState(4000, a[0:4], a[4:7], a[7:10], a[10:13], 12.0)


def test_rejects_exactly_what_isfinite_rejects() -> None:
    rng = np.random.default_rng(3)
    base = np.array([1.0, 0.0, 0.0, 0.0, 0.1, -0.2, 0.3, 5.0, -6.0, -30.0, 1.0, 2.0, -0.5])
    cases = [base.copy()]
    for i, x in itertools.product(range(13), _BAD + _EDGE):  # one odd value anywhere
        a = base.copy()
        a[i] = x
        cases.append(a)
    for _ in range(300):  # several extreme finite values at once: no overflow to inf
        a = base.copy()
        idx = rng.choice(13, size=4, replace=False)
        a[idx] = rng.choice([1e308, -1e308, 1.7e308], size=4)
        cases.append(a)
    for a in cases:
        est = StateEstimate()
        got = est.update(_nav(a))
        finite = all(math.isfinite(x) for x in a.tolist())
        assert (got is not None) == finite, a
        assert est.have_nav == finite

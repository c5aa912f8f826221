"""The one outcome definition of a campaign scenario (used by the runner, report and gates).

A scenario **survived** when

1. it did not crash (:mod:`vtolftc.telemetry.metrics`: non-finite state, ground contact in
   flight after having climbed above 2 m, or roll or pitch beyond 60 deg at any time; a
   crash ends the run), and
2. at the end of the run the altitude is within ``ALTITUDE_TOLERANCE_M`` = 5 m of its
   reference (the autopilot's altitude setpoint at the last sample), and
3. roll and pitch, averaged over the last second, are each within ``ATTITUDE_TOLERANCE_DEG``
   = 20 deg of level.

A quad-chute back to hover is not a failure by itself: a vehicle that holds its altitude and
stays level survived. ``outcome`` names the first criterion that failed: ``survived``,
``crashed``, ``altitude`` or ``attitude``.
"""

from __future__ import annotations

import math
from collections.abc import Mapping
from typing import Any

ALTITUDE_TOLERANCE_M = 5.0
ATTITUDE_TOLERANCE_DEG = 20.0

__all__ = ["ALTITUDE_TOLERANCE_M", "ATTITUDE_TOLERANCE_DEG", "outcome", "survived"]


def outcome(metrics: Mapping[str, Any]) -> str:
    """``survived``, ``crashed``, ``altitude`` or ``attitude`` (see the module docstring)."""
    if metrics.get("crashed", True) or metrics.get("interrupted", False):
        return "crashed"
    e_h = metrics.get("final_altitude_error_m")
    if e_h is None or not math.isfinite(e_h) or abs(e_h) > ALTITUDE_TOLERANCE_M:
        return "altitude"
    for k in ("final_roll_deg", "final_pitch_deg"):
        v = metrics.get(k)
        if v is None or not math.isfinite(v) or abs(v) > ATTITUDE_TOLERANCE_DEG:
            return "attitude"
    return "survived"


def survived(metrics: Mapping[str, Any]) -> bool:
    """True when :func:`outcome` is ``survived``."""
    return outcome(metrics) == "survived"

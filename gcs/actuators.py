"""Actuator names <-> MAVLink failure units and instances, for the ground station.

The numbering itself lives in :mod:`vtolftc.protocols.failure_units` (shared with the vehicle and
the
autopilot); :func:`default_table` is the table of the shipped DS-1 airframe.
"""

from __future__ import annotations

import functools

from vtolftc.protocols.failure_units import (
    FAILURE_UNIT_MOTOR,
    FAILURE_UNIT_SERVO,
    GROUPS,
    ActuatorTable,
)

__all__ = ["FAILURE_UNIT_MOTOR", "FAILURE_UNIT_SERVO", "GROUPS", "ActuatorTable",
           "default_table"]


@functools.cache
def default_table() -> ActuatorTable:
    """The actuator table of the shipped DS-1 airframe (loaded once)."""
    from vtolftc.airframe.loader import load_airframe

    return ActuatorTable.from_names(load_airframe().actuator_names)

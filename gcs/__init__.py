"""Ground-station library and CLI speaking MAVLink to the autopilot.

:class:`vtolftc.gcs.client.GroundStation` connects (UDP 14550 by default, or any link URL), keeps a
:class:`vtolftc.gcs.client.VehicleSnapshot`, sends commands with acknowledgement and retries, reads
and
writes parameters and injects faults. ``vtolftc gcs ...`` is its command line.
"""

from vtolftc.gcs.client import (
    CommandOutcome,
    GcsError,
    GcsTimeout,
    GroundStation,
    VehicleSnapshot,
)

__all__ = ["CommandOutcome", "GcsError", "GcsTimeout", "GroundStation", "VehicleSnapshot"]

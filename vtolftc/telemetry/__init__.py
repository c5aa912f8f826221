"""The telemetry layer: what a run reports while it flies, and the observers that keep it.

- :mod:`vtolftc.telemetry.samples`: :class:`TelemetrySample`, :class:`VehicleTruth`, the
  :class:`RunObserver` protocol.
- :mod:`vtolftc.telemetry.autopilot_status`: the autopilot's ``AutopilotStatus`` and mode
  enums, defined at this layer because the samples carry them; code above imports them from
  the autopilot's interface, :mod:`vtolftc.firmware_sim.autopilot.interface`.
- :mod:`vtolftc.telemetry.metrics`: paper table 4 RMSEs, crash and transition detection, and
  the one survival definition of the fault campaigns.
- :mod:`vtolftc.telemetry.runfolder`: the run-folder writer (CSV, events, metrics, plots).
- :mod:`vtolftc.telemetry.recording`: the rerun recorder (``run.rrd``, live viewer).
- :mod:`vtolftc.telemetry.geometry`: the aircraft drawn from its airframe file.

This layer needs only the airframe and protocols layers: the firmware gets its observers
passed in, the runners and viewers sit above.
"""

from vtolftc.telemetry.samples import RunObserver, TelemetrySample, VehicleTruth

__all__ = ["RunObserver", "TelemetrySample", "VehicleTruth"]

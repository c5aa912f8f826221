"""The process programs of SITL: ``python -m vtolftc.runners.processes.autopilot`` and
``python -m vtolftc.runners.processes.vehicle``.

They parse the arguments, open the links and wire the run folder, the rerun recorder and the
metrics into the flight software (:mod:`vtolftc.firmware_sim.autopilot.process`,
:mod:`vtolftc.firmware_sim.vehicle.process`), which gets them passed in and imports no runner
or viewer. SIGTERM and SIGINT stop both cleanly (files flushed and closed, no traceback).
"""

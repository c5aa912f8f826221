"""Live visualisation: rerun recordings and the viser browser dashboard.

- :mod:`vtolftc.dashboard.recording`: :class:`~vtolftc.dashboard.recording.RerunRecorder`, the run
  observer
  that writes every run's ``.rrd`` (live viewer on request), and ``read_recording``.
- :mod:`vtolftc.dashboard.web`: :class:`~vtolftc.dashboard.web.Dashboard`, the viser page that
  watches and
  commands the vehicle over MAVLink through :mod:`gcs` (``vtolftc dashboard``).
- :mod:`vtolftc.dashboard.model`: the page's display logic, fed by ground-station snapshots.
- :mod:`vtolftc.dashboard.geometry`: aircraft shapes and the rotor layout from the airframe.
- :mod:`vtolftc.dashboard.browser`: headless-Chromium driver (Selenium) for tests and benchmarks.
- :mod:`vtolftc.dashboard.fake_autopilot`: a kinematic MAVLink autopilot stand-in for tests/demos.

Nothing here is imported by the autopilot, the vehicle, ``protocols`` or ``gcs``.
"""

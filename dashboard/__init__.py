"""Live visualisation: rerun recordings and the viser browser dashboard.

- :mod:`dashboard.recording`: :class:`~dashboard.recording.RerunRecorder`, the run observer
  that writes every run's ``.rrd`` (live viewer on request), and ``read_recording``.
- :mod:`dashboard.web`: :class:`~dashboard.web.Dashboard`, the viser page that watches and
  commands the vehicle over MAVLink through :mod:`gcs` (``vtolftc dashboard``).
- :mod:`dashboard.model`: the page's display logic, fed by ground-station snapshots.
- :mod:`dashboard.geometry`: aircraft shapes and the rotor layout from the airframe.
- :mod:`dashboard.browser`: headless-Chromium driver (Selenium) for tests and benchmarks.
- :mod:`dashboard.fake_autopilot`: a kinematic MAVLink autopilot stand-in for tests/demos.

Nothing here is imported by the autopilot, the vehicle, ``protocols`` or ``gcs``.
"""

"""Live visualisation: the viser browser dashboard (the rerun recorder is a run observer of
the telemetry layer, :mod:`vtolftc.telemetry.recording`).

- :mod:`vtolftc.dashboard.web`: :class:`~vtolftc.dashboard.web.Dashboard`, the viser page that
  watches and commands the vehicle over MAVLink through :mod:`vtolftc.gcs`
  (``vtolftc dashboard``).
- :mod:`vtolftc.dashboard.model`: the page's display logic, fed by ground-station snapshots.

Nothing here is imported by the autopilot, the vehicle, ``protocols`` or ``gcs``.
"""

"""The static part of a rerun recording: entity names, the viewer layout and the scene.

Used by :class:`~vtolftc.telemetry.recording.RerunRecorder` once per run: the default
blueprint (3-D view, attitude/altitude/airspeed plots, mode, actuators, events), the NED world
frame, the aircraft shape of boxes and discs in body FRD, and the names and colours of every
time series (``SeriesLines``, ``SeriesPoints``).
"""

from __future__ import annotations

from collections.abc import Sequence
from typing import Any

import numpy as np

from vtolftc.rotation import ATTITUDE_AXES

__all__ = ["TIMELINE", "VIRTUAL_AXES", "actuator_entity", "blueprint", "log_static_scene"]

#: The recording's timeline: simulated time since the start of the run (a duration).
TIMELINE = "sim_time"
#: Names of the virtual command's components [Fz, Fx (N); L, M, N (N m)].
VIRTUAL_AXES = ("Fz", "Fx", "L", "M", "N")


def actuator_entity(name: str) -> str:
    """Entity path prefix of an actuator: ``actuators/<group>/<name>``."""
    if name.startswith("rotor"):
        group = "rotors"
    elif name.startswith("pusher"):
        group = "pushers"
    else:
        group = "surfaces"
    return f"actuators/{group}/{name}"


def log_static_scene(rr: Any, rec: Any, airframe: Any, names: Sequence[str]) -> None:
    """Log the static scene to the recording stream ``rec`` (``rr`` the rerun module).

    Parameters
    ----------
    rr
        the ``rerun`` module.
    rec
        the ``rerun.RecordingStream``.
    airframe
        airframe for the aircraft shape (None: the shipped DS-1).
    names
        actuator names (one series entity each, :func:`actuator_entity`).
    """
    rec.log("world", rr.ViewCoordinates.RIGHT_HAND_Z_DOWN, static=True)   # NED
    try:
        from vtolftc.telemetry.geometry import aircraft_geometry

        af = airframe
        if af is None:
            from vtolftc.airframe.loader import load_airframe

            af = load_airframe()
        boxes, discs = aircraft_geometry(af)
    except Exception as exc:  # never break a run for a picture
        rec.log("events", rr.TextLog(f"no aircraft shape: {exc}", level="WARN"), static=True)
        return
    rec.log("world/aircraft/shape", rr.Boxes3D(
        centers=[b.center_m for b in boxes], half_sizes=[tuple(s / 2 for s in b.size_m)
                                                         for b in boxes],
        colors=[b.color for b in boxes], labels=None, fill_mode="solid"), static=True)
    halves = []
    for d in discs:
        ax = np.abs(np.asarray(d.axis))
        halves.append(tuple(0.01 if a > 0.5 else d.radius_m for a in ax))
    rec.log("world/aircraft/rotors", rr.Ellipsoids3D(
        centers=[d.center_m for d in discs], half_sizes=halves,
        colors=[(240, 120, 40) if d.name.startswith("rotor") else (60, 200, 90)
                for d in discs], fill_mode="solid"), static=True)
    rec.log("world/aircraft/axes", rr.Arrows3D(
        vectors=[(1.0, 0, 0), (0, 0.6, 0), (0, 0, 0.6)],
        colors=[(255, 0, 0), (0, 255, 0), (0, 0, 255)]), static=True)
    rec.log("faults/marker", rr.SeriesPoints(markers="diamond", marker_sizes=8.0,
                                             colors=(230, 40, 40), names="fault"),
            static=True)
    grey, blue, red = (150, 150, 150), (40, 120, 240), (230, 60, 40)
    for ax in ATTITUDE_AXES:
        rec.log(f"attitude/{ax}", rr.SeriesLines(names=[f"{ax} ref", ax],
                                                 colors=[grey, blue]), static=True)
    rec.log("altitude", rr.SeriesLines(names=["altitude ref", "altitude"],
                                       colors=[grey, blue]), static=True)
    rec.log("airspeed", rr.SeriesLines(names=["airspeed (autopilot)", "airspeed (truth)"],
                                       colors=[blue, grey]), static=True)
    rec.log("control/virtual", rr.SeriesLines(names=list(VIRTUAL_AXES)), static=True)
    for name in names:
        rec.log(actuator_entity(name), rr.SeriesLines(
            names=[f"{name} command", f"{name} effective"], colors=[blue, red]),
            static=True)


def blueprint() -> Any:
    """Default layout: 3-D view, attitude/altitude/airspeed plots, mode, actuators, events."""
    import rerun.blueprint as rrb

    return rrb.Blueprint(
        rrb.Horizontal(
            rrb.Vertical(
                rrb.Spatial3DView(name="pose and path", origin="world"),
                rrb.StateTimelineView(name="flight mode", origin="mode/state"),
                rrb.TextLogView(name="events", origin="events"),
                row_shares=[3, 1, 2],
            ),
            rrb.Vertical(
                rrb.TimeSeriesView(name="roll (deg)", origin="attitude/roll"),
                rrb.TimeSeriesView(name="pitch (deg)", origin="attitude/pitch"),
                rrb.TimeSeriesView(name="yaw (deg)", origin="attitude/yaw"),
                rrb.TimeSeriesView(name="altitude (m)", origin="altitude"),
                rrb.TimeSeriesView(name="airspeed (m/s)", origin="airspeed"),
            ),
            rrb.Vertical(
                rrb.TimeSeriesView(name="lift rotors", origin="actuators/rotors"),
                rrb.TimeSeriesView(name="pushers", origin="actuators/pushers"),
                rrb.TimeSeriesView(name="surfaces", origin="actuators/surfaces"),
                rrb.TimeSeriesView(name="faults", origin="faults"),
            ),
            column_shares=[3, 2, 2],
        ),
        collapse_panels=False,
    )

"""Ground-station client: connect to the autopilot, watch it, command it, inject faults.

A :class:`GroundStation` owns one MAVLink link (any URL of :func:`protocols.open_link`; by
default it binds UDP 14550 like QGroundControl, where the autopilot sends its ground-station
stream) and a receive thread that keeps a :class:`VehicleSnapshot` of the autopilot (system 1,
component 1) up to date, answers nothing on its own except a 1 Hz GCS HEARTBEAT, and hands
every received message to the listeners.

Commands are COMMAND_LONGs with retries (``confirmation`` counts the retries, as MAVLink's
command protocol asks); each returns a :class:`CommandOutcome` with the COMMAND_ACK's result
(``result`` None when no ACK came: a timeout) and, in ``detail``, the STATUSTEXT(s) the
autopilot sent while answering (e.g. why it refused).

Units: SI and radians in the snapshot except ``heading_deg``; NED positions relative to home.

    with GroundStation.connect("udp-server://127.0.0.1:14550") as gs:
        print(gs.snapshot().mode_name)
        gs.param_set("SYS_FAILURE_EN", 1)
        print(gs.arm(), gs.takeoff(30.0), gs.transition("fw"))
        gs.inject("rotor_2b", loss=0.5)

:class:`GroundStation` is its parts, along PX4's seams: the link, receive thread and
heartbeat (:mod:`.connection`), the telemetry cache (:mod:`.telemetry`), commands
(:mod:`.commands`), parameters (:mod:`.params`) and missions (:mod:`.mission`).
"""

from __future__ import annotations

from vtolftc.gcs.commands import (
    CMD_ARM_DISARM,
    CMD_DO_SET_MODE,
    CMD_DO_VTOL_TRANSITION,
    CMD_INJECT_FAILURE,
    CMD_INJECT_PARTIAL_LOSS,
    CMD_NAV_TAKEOFF,
    CommandClient,
    CommandOutcome,
    command_name,
    result_name,
)
from vtolftc.gcs.connection import GcsError, GcsTimeout
from vtolftc.gcs.mission import MissionClient
from vtolftc.gcs.params import ParamClient
from vtolftc.gcs.telemetry import VehicleSnapshot

__all__ = [
    "CMD_ARM_DISARM",
    "CMD_DO_SET_MODE",
    "CMD_DO_VTOL_TRANSITION",
    "CMD_INJECT_FAILURE",
    "CMD_INJECT_PARTIAL_LOSS",
    "CMD_NAV_TAKEOFF",
    "CommandOutcome",
    "GcsError",
    "GcsTimeout",
    "GroundStation",
    "VehicleSnapshot",
    "command_name",
    "result_name",
]


class GroundStation(CommandClient, ParamClient, MissionClient):
    """A MAVLink ground station talking to the autopilot (system 1, component 1).

    Parameters
    ----------
    url
        link URL (``udp-server://127.0.0.1:14550`` = QGroundControl's port; a zenoh URL
        such as ``zenoh://ds1/gcs/down?connect=tcp/127.0.0.1:7447`` works the same).
    system_id, component_id
        this ground station's ids (255 / 190 by convention).
    signing
        MAVLink 2 signing (:class:`protocols.SigningConfig`) for outgoing frames.
    target_system, target_component
        the autopilot's ids.
    actuators
        actuator numbering for :meth:`inject` (default: the shipped DS-1's).
    allow_remote
        allow a link to a non-loopback address.

    The receive thread starts at once; :meth:`connect` also waits for the first heartbeat.
    Connection, snapshot and listeners: :class:`.connection.GcsConnection`; commands:
    :class:`.commands.CommandClient`; parameters: :class:`.params.ParamClient`; missions:
    :class:`.mission.MissionClient`.
    """

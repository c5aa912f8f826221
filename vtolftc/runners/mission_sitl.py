"""A mission flown by the SITL processes, driven by a plain pymavlink client.

:func:`fly_sitl_mission` starts the vehicle and autopilot processes (lockstep, free-running,
no holds) with an extra UDP ground-station link for a pymavlink client that knows nothing of
this project; the client uploads the mission with MAVLink's mission protocol
(:func:`pymavlink_upload`), downloads it back (:func:`pymavlink_download`), checks TIMESYNC
and COMMAND_INT, arms, selects AUTO.MISSION and records the flight (MISSION_ITEM_REACHED,
MISSION_CURRENT, LOCAL_POSITION_NED, EXTENDED_SYS_STATE, BATTERY_STATUS, HEARTBEAT modes)
until the vehicle has landed and disarmed. Optionally the faults of a case are injected
(through the project's ground station, as MAV_CMD_INJECT_PARTIAL_LOSS) a few simulated
seconds into a given mission item. Used by the SITL mission test and the mission benchmark.
"""

from __future__ import annotations

import time
from pathlib import Path
from typing import Any

from pymavlink import mavutil

from vtolftc.firmware_sim.autopilot.mission import MissionItem
from vtolftc.firmware_sim.vehicle.faults import case_faults
from vtolftc.protocols.generated import constants as mav
from vtolftc.protocols.px4 import mode_name
from vtolftc.runners.mission_run import rectangle_mission
from vtolftc.runners.sitl import SitlConfig, SitlError, SitlRun

__all__ = ["fly_sitl_mission", "pymavlink_download", "pymavlink_upload"]


def _recv(conn, types, timeout):
    end = time.monotonic() + timeout
    while time.monotonic() < end:
        m = conn.recv_match(type=types, blocking=True, timeout=0.2)
        if m is not None and m.get_srcSystem() == 1 and m.get_srcComponent() == 1:
            return m
    return None


def pymavlink_upload(conn: Any, items: list[MissionItem]) -> Any:
    """pymavlink client side of the upload; returns the MISSION_ACK."""
    conn.mav.mission_count_send(1, 1, len(items), 0)
    while True:
        m = _recv(conn, ["MISSION_REQUEST_INT", "MISSION_REQUEST", "MISSION_ACK"], 5.0)
        if m is None:
            raise SitlError("no answer to the mission upload")
        if m.get_type() == "MISSION_ACK":
            return m
        it = items[m.seq]
        conn.mav.mission_item_int_send(1, 1, it.seq, it.frame, it.command, 0, it.autocontinue,
                                       it.param1, it.param2, it.param3, it.param4, it.x, it.y,
                                       it.z, 0)


def pymavlink_download(conn: Any) -> list[MissionItem]:
    """Download the mission from system 1 with plain pymavlink calls (an independent client).

    Raises
    ------
    SitlError
        no MISSION_COUNT, or an item missing or out of order, within 5 s each.
    """
    conn.mav.mission_request_list_send(1, 1, 0)
    cnt = _recv(conn, ["MISSION_COUNT"], 5.0)
    if cnt is None:
        raise SitlError("no MISSION_COUNT")
    out = []
    for seq in range(cnt.count):
        conn.mav.mission_request_int_send(1, 1, seq, 0)
        m = _recv(conn, ["MISSION_ITEM_INT"], 5.0)
        if m is None or m.seq != seq:
            raise SitlError(f"mission item {seq} not returned")
        out.append(MissionItem.from_msg(m))
    conn.mav.mission_ack_send(1, 1, 0, 0)
    return out


def fly_sitl_mission(out_dir: Path, inject_case: int | None = None, transport: str = "udp",
                     items: list[MissionItem] | None = None, fault_item: int = 2,
                     fault_delay_s: float = 5.0, wall_timeout_s: float = 900.0,
                     airframe: Path | None = None, gains_dir: Path | None = None,
                     ) -> dict[str, Any]:
    """Fly ``items`` (default :func:`rectangle_mission`) as the module docstring says;
    returns the record (lists of reached items, samples, modes, battery readings, checks).
    ``airframe`` / ``gains_dir``: another airframe file and its gain files (default DS-1 and
    the shipped gains)."""
    # this ground station's socket is bound first, on a port the kernel picks, and the
    # autopilot is told that port: a port found free and bound only after the processes
    # started could be taken meanwhile (a loaded CI run: EADDRINUSE)
    conn = mavutil.mavlink_connection("udpin:127.0.0.1:0", source_system=245,
                                      source_component=190)
    port = int(conn.port.getsockname()[1])
    cfg = SitlConfig(out_dir=out_dir, transport=transport, hold_at_start=False,
                     failure_injection=True, airframe=airframe, gains_dir=gains_dir,
                     plots=False, extra_autopilot_args=[
                         "--gcs-link", f"udp-client://127.0.0.1:{port}"])
    try:
        run = SitlRun(cfg)
    except BaseException:
        conn.close()
        raise
    rec: dict = {"reached": [], "t": [], "pos": [], "fw": [], "seq": [], "modes": set(),
                 "battery": [], "ground_modes": set(), "fault_acks": [], "items": items or
                 rectangle_mission()}
    try:
        try:
            run.start()
            if _recv(conn, ["HOME_POSITION"], 60.0) is None:
                raise SitlError("no HOME_POSITION from the autopilot: no vehicle")
            items = rec["items"]
            ack = pymavlink_upload(conn, items)
            rec["upload_ack"] = int(ack.type)
            if ack.type != 0:
                return rec
            rec["downloaded"] = pymavlink_download(conn)
            # TIMESYNC and COMMAND_INT are answered
            conn.mav.timesync_send(0, 123456789)
            ts = _recv(conn, ["TIMESYNC"], 3.0)
            rec["timesync"] = None if ts is None else (int(ts.tc1), int(ts.ts1))
            conn.mav.command_int_send(1, 1, 0, 512, 0, 0, 148.0, 0, 0, 0, 0, 0, 0)
            ack = _recv(conn, ["COMMAND_ACK"], 3.0)
            rec["command_int_ack"] = None if ack is None else (int(ack.command), int(ack.result))
            hb = _recv(conn, ["HEARTBEAT"], 3.0)
            rec["ground_modes"].add(mode_name(hb.custom_mode))
            bs = _recv(conn, ["BATTERY_STATUS"], 5.0)
            if bs is None:
                raise SitlError("no BATTERY_STATUS")
            rec["v_ground"] = bs.voltages[0] * 6e-3
            rec["pct_ground"] = bs.battery_remaining
            conn.mav.command_long_send(1, 1, mav.MAV_CMD_COMPONENT_ARM_DISARM, 0,
                                       1, 0, 0, 0, 0, 0, 0)
            conn.mav.command_long_send(1, 1, mav.MAV_CMD_DO_SET_MODE, 0, 1, 4, 4, 0, 0, 0, 0)
            faults = case_faults(inject_case, _actuators()) if inject_case else []
            fw_leg_since = None
            injected = False
            armed_seen = False
            seq = 0
            fw = False
            t_end = time.monotonic() + wall_timeout_s
            t_flight = time.monotonic()
            while time.monotonic() < t_end:
                m = conn.recv_match(blocking=True, timeout=0.5)
                if m is None or m.get_srcSystem() != 1:
                    continue
                t = m.get_type()
                if t == "MISSION_ITEM_REACHED":
                    if not rec["reached"] or rec["reached"][-1] != m.seq:
                        rec["reached"].append(m.seq)
                elif t == "MISSION_CURRENT":
                    seq = m.seq
                    if seq == fault_item and fw_leg_since is None:
                        fw_leg_since = time.monotonic()
                elif t == "EXTENDED_SYS_STATE":
                    fw = m.vtol_state == 4
                elif t == "LOCAL_POSITION_NED":
                    rec["t"].append(m.time_boot_ms * 1e-3)
                    rec["pos"].append((m.x, m.y, m.z))
                    rec["fw"].append(fw)
                    rec["seq"].append(seq)
                elif t == "BATTERY_STATUS":
                    rec["battery"].append((m.voltages[0] * 6e-3, m.current_battery * 0.01,
                                           m.battery_remaining))
                elif t == "HEARTBEAT":
                    armed = bool(m.base_mode & 128)
                    if armed:
                        armed_seen = True
                        rec["modes"].add(mode_name(m.custom_mode))
                    elif armed_seen:
                        break
                if faults and not injected and fw_leg_since is not None and rec["t"]:
                    # 5 s of simulated time into the first fixed-wing leg
                    t_leg = [tt for tt, s in zip(rec["t"], rec["seq"], strict=True)
                             if s == fault_item]
                    if t_leg and t_leg[-1] - t_leg[0] > fault_delay_s:
                        for f in faults:
                            out = run.gs.inject(f.actuator, loss=f.loss)
                            rec["fault_acks"].append(str(out))
                        injected = True
            rec["flight_wall_s"] = time.monotonic() - t_flight
            rec["injected"] = injected
        finally:
            conn.close()
    finally:
        run.close()
    return rec


def _actuators() -> tuple[str, ...]:
    from vtolftc.airframe.loader import load_airframe

    return tuple(load_airframe().actuator_names)



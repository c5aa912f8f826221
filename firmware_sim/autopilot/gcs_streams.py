"""Message streams of the ground-station endpoint (PX4: ``mavlink_main``'s streams and the
message-interval part of ``mavlink_receiver``).

:class:`StreamService` keeps, for each link of
:class:`~vtolftc.firmware_sim.autopilot.gcs_endpoint.GcsEndpoint`, the rate of every stream
(:data:`DEFAULT_RATES_HZ`, in Hz of simulated time; SET_MESSAGE_INTERVAL changes them for the
link it came on only; GET_MESSAGE_INTERVAL answers MESSAGE_INTERVAL of that link), sends what
is due after each step the worker observes, sends FAULT_INJECTION_STATUS at once when the
vehicle reports a change, and builds the messages themselves:

- HEARTBEAT: type MAV_TYPE_VTOL_FIXEDROTOR (22), autopilot MAV_AUTOPILOT_PX4 (12), PX4 custom
  mode, armed bit 128, system_status of :meth:`GcsEndpoint.system_status`;
- SYS_STATUS (present / enabled / healthy bits for gyro, accel, mag, baro, differential
  pressure, GPS, AHRS, motor outputs and pre-arm check, plus the geofence and battery of
  :mod:`.gcs_services`), EXTENDED_SYS_STATE (never UNDEFINED: MC / ON_GROUND until the
  autopilot says otherwise), AUTOPILOT_VERSION, HOME_POSITION, FAULT_INJECTION_STATUS,
  ACTUATOR_OUTPUT_STATUS, HIL_STATE_QUATERNION (the navigation input), ATTITUDE,
  ATTITUDE_QUATERNION, LOCAL_POSITION_NED, GLOBAL_POSITION_INT, VFR_HUD;
- GPS_RAW_INT, MISSION_CURRENT, BATTERY_STATUS (:mod:`.gcs_services`) and ODOMETRY, ALTITUDE,
  WIND_COV, HIGHRES_IMU, SCALED_IMU, SYSTEM_TIME, FLIGHT_INFORMATION (:mod:`.gcs_telemetry`).
"""

from __future__ import annotations

import math
from typing import Any

import numpy as np

from vtolftc.base.rotation import quat_to_euler
from vtolftc.firmware_sim.autopilot.gcs_services import STREAM_RATES_HZ
from vtolftc.firmware_sim.autopilot.gcs_telemetry import TELEMETRY_MSG, TELEMETRY_RATES_HZ
from vtolftc.firmware_sim.autopilot.interface import (
    CommandResult,
    FlightMode,
    LandedState,
    VtolState,
)
from vtolftc.firmware_sim.autopilot.modes import px4_custom_mode
from vtolftc.protocols.generated import constants as mav
from vtolftc.protocols.link import Link
from vtolftc.protocols.px4 import MAV_MODE_FLAG_CUSTOM_MODE_ENABLED, MAV_MODE_FLAG_SAFETY_ARMED

__all__ = ["DEFAULT_RATES_HZ", "MSG", "StreamService"]

# 22: named VTOL_FIXEDROTOR in current MAVLink, still VTOL_RESERVED2 in this dialect's common.xml
MAV_TYPE_VTOL_FIXEDROTOR = mav.MAV_TYPE_VTOL_RESERVED2
MAV_AUTOPILOT_PX4 = mav.MAV_AUTOPILOT_PX4
MAV_MODE_FLAG_AUTO = (mav.MAV_MODE_FLAG_AUTO_ENABLED | mav.MAV_MODE_FLAG_GUIDED_ENABLED
                      | mav.MAV_MODE_FLAG_STABILIZE_ENABLED)

MSG = {name: getattr(mav, "MAVLINK_MSG_ID_" + name) for name in (
    "HEARTBEAT", "SYS_STATUS", "ATTITUDE", "ATTITUDE_QUATERNION", "LOCAL_POSITION_NED",
    "GLOBAL_POSITION_INT", "VFR_HUD", "HIL_STATE_QUATERNION", "AUTOPILOT_VERSION",
    "HOME_POSITION", "EXTENDED_SYS_STATE", "ACTUATOR_OUTPUT_STATUS", "FAULT_INJECTION_STATUS")}
DEFAULT_RATES_HZ: dict[int, float] = {
    MSG["HEARTBEAT"]: 1.0, MSG["SYS_STATUS"]: 1.0, MSG["ATTITUDE"]: 10.0,
    MSG["ATTITUDE_QUATERNION"]: 10.0, MSG["LOCAL_POSITION_NED"]: 10.0,
    MSG["GLOBAL_POSITION_INT"]: 5.0, MSG["VFR_HUD"]: 4.0, MSG["HIL_STATE_QUATERNION"]: 10.0,
    MSG["HOME_POSITION"]: 0.2, MSG["EXTENDED_SYS_STATE"]: 2.0,
    MSG["ACTUATOR_OUTPUT_STATUS"]: 10.0, MSG["FAULT_INJECTION_STATUS"]: 1.0,
    **STREAM_RATES_HZ,  # GPS_RAW_INT, MISSION_CURRENT, BATTERY_STATUS (gcs_services.py)
    **TELEMETRY_RATES_HZ,  # ODOMETRY, ALTITUDE, WIND_COV, ... (gcs_telemetry.py)
}
"""Stream rates in Hz of simulated time (PX4-like, a little lower to spare the CPU)."""
MSG.update({name: getattr(mav, "MAVLINK_MSG_ID_" + name)
            for name in ("GPS_RAW_INT", "MISSION_CURRENT", "BATTERY_STATUS")})
MSG.update(TELEMETRY_MSG)

# SYS_STATUS sensor bits (MAV_SYS_STATUS_SENSOR)
_GYRO, _ACCEL, _MAG = (mav.MAV_SYS_STATUS_SENSOR_3D_GYRO, mav.MAV_SYS_STATUS_SENSOR_3D_ACCEL,
                       mav.MAV_SYS_STATUS_SENSOR_3D_MAG)
_BARO, _DIFF, _GPS = (mav.MAV_SYS_STATUS_SENSOR_ABSOLUTE_PRESSURE,
                      mav.MAV_SYS_STATUS_SENSOR_DIFFERENTIAL_PRESSURE,
                      mav.MAV_SYS_STATUS_SENSOR_GPS)
_ANGULAR_RATE_CTRL = mav.MAV_SYS_STATUS_SENSOR_ANGULAR_RATE_CONTROL
_ATTITUDE_CTRL = mav.MAV_SYS_STATUS_SENSOR_ATTITUDE_STABILIZATION
_MOTOR_OUTPUTS = mav.MAV_SYS_STATUS_SENSOR_MOTOR_OUTPUTS
_AHRS, _PREARM = mav.MAV_SYS_STATUS_AHRS, mav.MAV_SYS_STATUS_PREARM_CHECK
_SENSORS_PRESENT = (_GYRO | _ACCEL | _MAG | _BARO | _DIFF | _GPS | _ANGULAR_RATE_CTRL
                    | _ATTITUDE_CTRL | _MOTOR_OUTPUTS | _AHRS | _PREARM)


class StreamService:
    """Stream rates, scheduling and message building (module docstring) for ``endpoint``,
    the owning GcsEndpoint (what its worker knows: ``status``, ``nav``, ``commands``,
    ``sim_usec``; its ``io``, ``hil``, ``services``, ``telemetry``, ``version``)."""

    def __init__(self, endpoint: Any, n_links: int) -> None:
        self.ep = endpoint
        self.rates_hz: list[dict[int, float]] = [dict(DEFAULT_RATES_HZ)
                                                 for _ in range(n_links)]
        """Stream rates of each link (SET_MESSAGE_INTERVAL changes its own link only)."""
        self._next_due: list[dict[int, int]] = [{} for _ in range(n_links)]
        self._earliest_due = [0] * n_links
        self.earliest_due_usec = 0
        """Simulated time [us] of the next stream message due on any link (read by the
        control thread to decide whether to wake the worker)."""
        self.last_fault_status: Any = None
        """The vehicle's last FAULT_INJECTION_STATUS sent on (its identity marks a change)."""

    # ------------------------------------------------------------------ rates
    def set_interval(self, index: int, params: list[float]) -> tuple[int, str]:
        """SET_MESSAGE_INTERVAL (511) on link ``index``: param1 the id, param2 the interval
        [us] (0 or NaN default, < 0 off). Returns (MAV_RESULT, reason)."""
        mid, interval = params[0], params[1]
        rates = self.rates_hz[index]
        if not math.isfinite(mid) or int(mid) not in rates:
            return CommandResult.DENIED, f"cannot stream message {mid:g}"
        mid = int(mid)
        if not math.isfinite(interval) or interval == 0:
            rates[mid] = DEFAULT_RATES_HZ[mid]
        elif interval < 0:
            rates[mid] = 0.0
        else:
            rates[mid] = min(250.0, 1e6 / interval)
        self._next_due[index][mid] = self.ep.sim_usec
        self._earliest_due[index] = 0
        self.earliest_due_usec = 0
        return CommandResult.ACCEPTED, ""

    def get_interval(self, index: int, link: Link, mid: float) -> tuple[int, str]:
        """GET_MESSAGE_INTERVAL (510): MESSAGE_INTERVAL with this link's interval [us] (-1 =
        not streamed, as PX4), then the ACK; UNSUPPORTED for a message not served here."""
        rates = self.rates_hz[index]
        if not math.isfinite(mid) or int(mid) not in rates:
            return CommandResult.UNSUPPORTED, ""
        hz = rates[int(mid)]
        link.send(link.codec.message_interval_encode(int(mid), round(1e6 / hz) if hz > 0 else -1))
        return CommandResult.ACCEPTED, ""

    # ------------------------------------------------------------------ sending
    def run(self) -> None:
        """Worker: send what is due on each link at the observed simulated time, and
        FAULT_INJECTION_STATUS at once when it changed."""
        ep = self.ep
        if ep.nav is None:
            return
        fs = ep.hil.fault_status
        fid = MSG["FAULT_INJECTION_STATUS"]
        if fs is not None and fs is not self.last_fault_status:
            self.last_fault_status = fs
            self.send(fid)
            for i, due in enumerate(self._next_due):
                due[fid] = ep.sim_usec + 1_000_000
                self._earliest_due[i] = 0
        t = ep.sim_usec
        for i, link in enumerate(ep.io.links):
            if t < self._earliest_due[i]:
                continue
            earliest = 2**63
            next_due = self._next_due[i]
            for msg_id, hz in self.rates_hz[i].items():
                if hz <= 0:
                    continue
                due = next_due.get(msg_id, 0)
                if t >= due:
                    due = max(due + round(1e6 / hz), t)
                    next_due[msg_id] = due
                    self.send(msg_id, link)
                earliest = min(earliest, due)
            self._earliest_due[i] = earliest
        self.earliest_due_usec = min(self._earliest_due, default=2**63)

    def send(self, msg_id: int, link: Link | None = None) -> bool:
        """Worker: message ``msg_id`` now on ``link`` (None: every link); False without data."""
        msg = self.build(msg_id)
        if msg is None:
            return False
        self.ep.io.send(msg, link)
        return True

    # ------------------------------------------------------------------ building
    def build(self, msg_id: int) -> Any:
        """Message ``msg_id`` (one of :data:`MSG`) now, or None without data."""
        ep = self.ep
        c = ep.io.codec
        if c is None:
            return None
        if msg_id in STREAM_RATES_HZ:
            return ep.services.build(msg_id)
        if msg_id in TELEMETRY_RATES_HZ:
            return ep.telemetry.build(msg_id)
        msg = self._status(c, msg_id)
        if msg is not None:
            return msg
        return self._state(c, msg_id)

    def _status(self, c: Any, msg_id: int) -> Any:
        """HEARTBEAT, SYS_STATUS, EXTENDED_SYS_STATE, AUTOPILOT_VERSION, HOME_POSITION,
        FAULT_INJECTION_STATUS, ACTUATOR_OUTPUT_STATUS (None for any other id)."""
        ep = self.ep
        st = ep.status
        hil = ep.hil
        if msg_id == MSG["HEARTBEAT"]:
            armed = bool(st and st.armed)
            base = MAV_MODE_FLAG_CUSTOM_MODE_ENABLED | MAV_MODE_FLAG_AUTO | (
                MAV_MODE_FLAG_SAFETY_ARMED if armed else 0)
            cm = st.px4_custom_mode if st and st.px4_custom_mode >= 0 else px4_custom_mode(
                st.mode if st else FlightMode.IDLE)
            return c.heartbeat_encode(MAV_TYPE_VTOL_FIXEDROTOR, MAV_AUTOPILOT_PX4, base, cm,
                                      ep.system_status())
        if msg_id == MSG["SYS_STATUS"]:
            healthy = _ANGULAR_RATE_CTRL | _ATTITUDE_CTRL | _MOTOR_OUTPUTS
            if hil.connected and hil.last_sensor is not None:
                healthy |= _GYRO | _ACCEL | _MAG | _BARO | _DIFF | _AHRS
            gps = hil.last_gps
            if hil.connected and gps is not None and gps.fix_type >= 3:
                healthy |= _GPS
            if hil.connected and hil.home is not None and ep.nav is not None:
                healthy |= _PREARM
            # battery: voltage UINT16_MAX, current and remaining -1 until the first reading
            present, enabled, more_healthy = ep.services.sensor_bits()
            mv, ca, pct = ep.services.sys_status_battery()
            return c.sys_status_encode(_SENSORS_PRESENT | present, _SENSORS_PRESENT | enabled,
                                       healthy | more_healthy, 0, mv, ca, pct, 0, 0, 0, 0, 0,
                                       0)
        if msg_id == MSG["EXTENDED_SYS_STATE"]:
            vtol = int(st.vtol_state) if st else 0
            landed = int(st.landed_state) if st else 0
            return c.extended_sys_state_encode(vtol or int(VtolState.MC),
                                               landed or int(LandedState.ON_GROUND))
        if msg_id == MSG["AUTOPILOT_VERSION"]:
            major, minor, patch = ep.version
            sw = (major << 24) | (minor << 16) | (patch << 8) | 255
            # exactly what is served (MAV_PROTOCOL_CAPABILITY): MISSION_FLOAT 1, PARAM_FLOAT
            # 2, MISSION_INT 4, COMMAND_INT 8, PARAM_ENCODE_BYTEWISE 16, MAVLINK2 8192,
            # MISSION_FENCE 16384, MISSION_RALLY 32768
            caps = 1 | 2 | 4 | 8 | 16 | 8192 | 16384 | 32768
            return c.autopilot_version_encode(caps, sw, sw, 0, 0, [0] * 8, [0] * 8, [0] * 8,
                                              0, 0, 1)
        if msg_id == MSG["HOME_POSITION"]:
            if hil.home is None:
                return None
            lat, lon, alt = hil.home
            return c.home_position_encode(round(lat * 1e7), round(lon * 1e7), round(alt * 1e3),
                                          0.0, 0.0, 0.0, [1.0, 0.0, 0.0, 0.0], 0.0, 0.0, 0.0,
                                          ep.sim_usec)
        if msg_id == MSG["FAULT_INJECTION_STATUS"]:
            fs = hil.fault_status
            if fs is None:
                return None
            return c.fault_injection_status_encode(
                fs.time_usec, fs.change_count, fs.motor_count, fs.servo_count,
                fs.motor_failure, fs.motor_loss, fs.servo_failure, fs.servo_loss)
        if msg_id == MSG["ACTUATOR_OUTPUT_STATUS"]:
            out = [0.0] * 32
            out[: ep.commands.size] = [float(x) for x in ep.commands]
            return c.actuator_output_status_encode(ep.sim_usec, ep.commands.size, out)
        return None

    def _state(self, c: Any, msg_id: int) -> Any:
        """The navigation-state messages (None without a navigation state yet)."""
        ep = self.ep
        nav = ep.nav
        if nav is None:
            return None
        ms = ep.time_boot_ms
        q = nav.q_wxyz
        w = nav.omega_body_rad_s
        p = nav.pos_ned_m
        v = nav.vel_ned_m_s
        roll, pitch, yaw = quat_to_euler(q)
        if msg_id == MSG["ATTITUDE"]:
            return c.attitude_encode(ms, roll, pitch, yaw, w[0], w[1], w[2])
        if msg_id == MSG["ATTITUDE_QUATERNION"]:
            return c.attitude_quaternion_encode(ms, q[0], q[1], q[2], q[3], w[0], w[1], w[2],
                                                [0.0, 0.0, 0.0, 0.0])
        if msg_id == MSG["LOCAL_POSITION_NED"]:
            return c.local_position_ned_encode(ms, p[0], p[1], p[2], v[0], v[1], v[2])
        hs = ep.hil.last_state
        if msg_id == MSG["HIL_STATE_QUATERNION"]:
            if hs is None:
                return None
            return c.hil_state_quaternion_encode(
                hs.time_usec, hs.attitude_quaternion, hs.rollspeed, hs.pitchspeed, hs.yawspeed,
                hs.lat, hs.lon, hs.alt, hs.vx, hs.vy, hs.vz, hs.ind_airspeed, hs.true_airspeed,
                hs.xacc, hs.yacc, hs.zacc)
        home_alt = ep.hil.home[2] if ep.hil.home else 0.0
        hdg = math.degrees(yaw) % 360.0
        if msg_id == MSG["GLOBAL_POSITION_INT"]:
            lat = hs.lat if hs is not None else 0
            lon = hs.lon if hs is not None else 0
            return c.global_position_int_encode(
                ms, lat, lon, round((home_alt - p[2]) * 1e3), round(-p[2] * 1e3),
                round(v[0] * 100), round(v[1] * 100), round(v[2] * 100),
                round(hdg * 100) % 36000)
        if msg_id == MSG["VFR_HUD"]:
            n_motors = len(ep.actuators.motors)
            thr = float(np.clip(np.mean(ep.commands[:n_motors]), 0, 1)) if n_motors else 0.0
            return c.vfr_hud_encode(nav.airspeed_m_s, math.hypot(v[0], v[1]), round(hdg) % 360,
                                    round(thr * 100), home_alt - p[2], -v[2])
        return None

"""More of PX4's telemetry for ground stations and APIs: the messages MAVSDK subscribes to.

:class:`TelemetryStreams` builds, for the ground-station endpoint
(:class:`~vtolftc.firmware_sim.autopilot.gcs_endpoint.GcsEndpoint`), the messages below with
PX4's field semantics (``src/modules/mavlink/streams``); each is streamed at its default rate
(:data:`TELEMETRY_RATES_HZ`, simulated time, PX4-like), changed per link by
SET_MESSAGE_INTERVAL (message or command 511) and sent once by REQUEST_MESSAGE (512):

- ODOMETRY (331): the navigation solution; pose in MAV_FRAME_LOCAL_NED (origin at home, m),
  velocity in MAV_FRAME_LOCAL_NED too (``child_frame_id``, as PX4 for its NED velocity),
  quaternion body FRD -> NED (w, x, y, z), body rates FRD [rad/s], estimator type AUTOPILOT.
  The covariances are NaN: this autopilot flies on the vehicle's navigation data and has no
  estimator of its own that would know them (MAVLink: NaN = unknown); quality 0 (unknown).
- ALTITUDE (141): ``altitude_monotonic`` the barometric altitude of the last HIL_SENSOR [m],
  ``altitude_amsl`` home altitude + height (the barometric one before home is known, as
  PX4 without a global reference), ``altitude_local`` and ``altitude_relative`` the height
  above home [m] (the local origin is home), ``altitude_terrain`` and ``bottom_clearance``
  NaN (no distance sensor, as PX4 without one).
- WIND_COV (231): wind north / east [m/s] estimated in wing-borne flight (VTOL state FW) as
  the ground velocity minus the true airspeed along the body x axis (sideslip and angle of
  attack taken as zero); NaN outside fixed-wing flight (unknown: the pitot of a hovering
  vehicle says nothing about the wind). ``wind_z`` 0, ``var_vert`` 0, accuracies 0 (as
  PX4); ``var_horiz`` NaN (no variability estimate); ``wind_alt`` AMSL [m].
- HIGHRES_IMU (105) and SCALED_IMU (26): the last HIL_SENSOR (accelerometer [m/s^2],
  gyroscope [rad/s], magnetometer [gauss], absolute and differential pressure [hPa],
  pressure altitude [m], temperature [degC], ``fields_updated`` of that sample); SCALED_IMU in
  its integer units (mG, mrad/s, mgauss, cdegC).
- SYSTEM_TIME (2): ``time_unix_usec`` the wall clock (UTC, us), ``time_boot_ms`` simulated
  time since boot (the autopilot's clock, as in every ``time_boot_ms``).
- FLIGHT_INFORMATION (264): arming and takeoff times [us since boot], landing time [ms]
  (0 = not since the last arming) and the flight number ``COM_FLIGHT_UUID``
  (:mod:`.arming`). Not streamed by default (as PX4); REQUEST_MESSAGE,
  MAV_CMD_REQUEST_FLIGHT_INFORMATION (528) or an interval.
"""

from __future__ import annotations

import math
import time
from typing import Any

from vtolftc.protocols.generated import constants as mav

__all__ = ["TELEMETRY_MSG", "TELEMETRY_RATES_HZ", "TelemetryStreams"]

TELEMETRY_MSG: dict[str, int] = {name: getattr(mav, "MAVLINK_MSG_ID_" + name) for name in (
    "ODOMETRY", "ALTITUDE", "WIND_COV", "HIGHRES_IMU", "SCALED_IMU", "SYSTEM_TIME",
    "FLIGHT_INFORMATION")}
"""Message ids of the streams built here, by name."""

TELEMETRY_RATES_HZ: dict[int, float] = {
    TELEMETRY_MSG["ODOMETRY"]: 5.0, TELEMETRY_MSG["ALTITUDE"]: 1.0,
    TELEMETRY_MSG["WIND_COV"]: 0.5, TELEMETRY_MSG["HIGHRES_IMU"]: 2.0,
    TELEMETRY_MSG["SCALED_IMU"]: 1.0, TELEMETRY_MSG["SYSTEM_TIME"]: 1.0,
    TELEMETRY_MSG["FLIGHT_INFORMATION"]: 0.0,
}
"""Default rates [Hz of simulated time]: PX4's ground-station link streams ALTITUDE at 1 Hz
and WIND_COV at 0.5 Hz; ODOMETRY and the IMU messages, which PX4 streams only to onboard
links (30-50 Hz), at a few Hz; FLIGHT_INFORMATION on request."""

_G0 = 9.80665
_NAN = math.nan
_NAN21 = [_NAN] * 21
_VTOL_FW = mav.MAV_VTOL_STATE_FW
_FRAME_LOCAL_NED = mav.MAV_FRAME_LOCAL_NED
_ESTIMATOR_AUTOPILOT = mav.MAV_ESTIMATOR_TYPE_AUTOPILOT
_ODOMETRY, _ALTITUDE, _WIND_COV = (TELEMETRY_MSG["ODOMETRY"], TELEMETRY_MSG["ALTITUDE"],
                                   TELEMETRY_MSG["WIND_COV"])
_HIGHRES_IMU, _SCALED_IMU = TELEMETRY_MSG["HIGHRES_IMU"], TELEMETRY_MSG["SCALED_IMU"]
_SYSTEM_TIME, _FLIGHT_INFORMATION = (TELEMETRY_MSG["SYSTEM_TIME"],
                                     TELEMETRY_MSG["FLIGHT_INFORMATION"])


def _i16(x: float) -> int:
    """Round to int16 (saturating), for SCALED_IMU's integer fields."""
    return max(-32768, min(32767, round(x)))


def wind_estimate(q_wxyz: Any, vel_ned_m_s: Any, true_airspeed_m_s: float) -> tuple[float, float]:
    """Horizontal wind [m/s] (north, east): ground velocity minus the air velocity taken along
    the body x axis (zero sideslip and angle of attack).

    Parameters
    ----------
    q_wxyz
        attitude, body FRD -> NED, scalar first.
    vel_ned_m_s
        ground velocity in NED [m/s].
    true_airspeed_m_s
        true airspeed [m/s].
    """
    w, x, y, z = (float(c) for c in q_wxyz)
    bx_n = 1.0 - 2.0 * (y * y + z * z)     # body x axis in NED (first column of R)
    bx_e = 2.0 * (x * y + w * z)
    return (float(vel_ned_m_s[0]) - true_airspeed_m_s * bx_n,
            float(vel_ned_m_s[1]) - true_airspeed_m_s * bx_e)


class TelemetryStreams:
    """Builds the messages of the module docstring for ``endpoint`` (the owning
    GcsEndpoint: its latest navigation state, status, HIL bridge and autopilot)."""

    def __init__(self, endpoint: Any) -> None:
        self.ep = endpoint

    def build(self, msg_id: int) -> Any:
        """Message ``msg_id`` (one of :data:`TELEMETRY_MSG`) now, or None without data."""
        ep = self.ep
        if not ep.links:
            return None
        c = ep.links[0].codec
        if msg_id == _SYSTEM_TIME:
            return c.system_time_encode(int(time.time() * 1e6), ep.time_boot_ms)
        if msg_id == _FLIGHT_INFORMATION:
            return self._flight_information(c)
        if msg_id in (_HIGHRES_IMU, _SCALED_IMU):
            return self._imu(c, msg_id)
        nav = ep.nav
        if nav is None:
            return None
        p = nav.pos_ned_m
        v = nav.vel_ned_m_s
        home = ep.hil.home
        if msg_id == _ODOMETRY:
            w = nav.omega_body_rad_s
            q = nav.q_wxyz
            return c.odometry_encode(
                int(nav.time_usec), _FRAME_LOCAL_NED, _FRAME_LOCAL_NED, float(p[0]),
                float(p[1]), float(p[2]), [float(q[0]), float(q[1]), float(q[2]), float(q[3])],
                float(v[0]), float(v[1]), float(v[2]), float(w[0]), float(w[1]), float(w[2]),
                _NAN21, _NAN21, 0, _ESTIMATOR_AUTOPILOT, 0)
        h = -float(p[2])
        if msg_id == _ALTITUDE:
            s = ep.hil.last_sensor
            baro = float(s.pressure_alt) if s is not None else _NAN
            amsl = home[2] + h if home is not None else baro
            return c.altitude_encode(int(nav.time_usec), baro, amsl, h, h, _NAN, _NAN)
        if msg_id == _WIND_COV:
            st = ep.status
            wn = we = _NAN
            if st is not None and int(st.vtol_state) == _VTOL_FW:
                hs = ep.hil.last_state
                tas = (float(hs.true_airspeed) * 0.01 if hs is not None
                       else float(nav.airspeed_m_s))
                if math.isfinite(tas):
                    wn, we = wind_estimate(nav.q_wxyz, v, tas)
            alt = home[2] + h if home is not None else _NAN
            return c.wind_cov_encode(int(nav.time_usec), wn, we, 0.0, _NAN, 0.0, alt, 0.0, 0.0)
        return None

    def _imu(self, c: Any, msg_id: int) -> Any:
        s = self.ep.hil.last_sensor
        if s is None:
            return None
        if msg_id == _HIGHRES_IMU:
            return c.highres_imu_encode(
                int(s.time_usec), s.xacc, s.yacc, s.zacc, s.xgyro, s.ygyro, s.zgyro, s.xmag,
                s.ymag, s.zmag, s.abs_pressure, s.diff_pressure, s.pressure_alt, s.temperature,
                int(s.fields_updated) & 0x1FFF, 0)
        return c.scaled_imu_encode(
            int(s.time_usec) // 1000, _i16(s.xacc / _G0 * 1e3), _i16(s.yacc / _G0 * 1e3),
            _i16(s.zacc / _G0 * 1e3), _i16(s.xgyro * 1e3), _i16(s.ygyro * 1e3),
            _i16(s.zgyro * 1e3), _i16(s.xmag * 1e3), _i16(s.ymag * 1e3), _i16(s.zmag * 1e3),
            _i16(s.temperature * 100) or 1)  # 0 means "no temperature" in SCALED_IMU

    def _flight_information(self, c: Any) -> Any:
        ep = self.ep
        rec = getattr(ep.ap, "arming", None)
        params = ep.ap.params
        uuid = int(params.get("COM_FLIGHT_UUID")) if "COM_FLIGHT_UUID" in params else 0
        if rec is None:
            return c.flight_information_encode(ep.time_boot_ms, 0, 0, uuid, 0)
        return c.flight_information_encode(ep.time_boot_ms, int(rec.arming_usec),
                                           int(rec.takeoff_usec), uuid,
                                           int(rec.landing_ms) & 0xFFFFFFFF)

"""The ground station's picture of the autopilot: :class:`VehicleSnapshot` and the cache that
keeps it up to date from received messages (:class:`TelemetryCache`).

Units: SI and radians in the snapshot except ``heading_deg``; NED positions relative to home.
STATUSTEXTs are kept (the last 64, with the monotonic time they arrived), chunked ones joined
as MAVLink 2 specifies; the type of every parameter seen in a PARAM_VALUE is remembered (the
wire encoding of PARAM_SET depends on it).
"""

from __future__ import annotations

import collections
import math
import threading
import time
from dataclasses import dataclass, field, replace
from typing import Any

from vtolftc.protocols.generated import constants as mav
from vtolftc.protocols.px4 import MAV_MODE_FLAG_SAFETY_ARMED, mode_name

__all__ = ["HEARTBEAT_LOST_S", "VTOL_STATE_NAMES", "TelemetryCache", "VehicleSnapshot",
           "param_id_of"]

VTOL_STATE_NAMES = {mav.MAV_VTOL_STATE_UNDEFINED: "UNDEFINED",
                    mav.MAV_VTOL_STATE_TRANSITION_TO_FW: "TRANSITION_TO_FW",
                    mav.MAV_VTOL_STATE_TRANSITION_TO_MC: "TRANSITION_TO_MC",
                    mav.MAV_VTOL_STATE_MC: "MC", mav.MAV_VTOL_STATE_FW: "FW"}
LANDED_STATE_NAMES = {mav.MAV_LANDED_STATE_UNDEFINED: "UNDEFINED",
                      mav.MAV_LANDED_STATE_ON_GROUND: "ON_GROUND",
                      mav.MAV_LANDED_STATE_IN_AIR: "IN_AIR",
                      mav.MAV_LANDED_STATE_TAKEOFF: "TAKEOFF",
                      mav.MAV_LANDED_STATE_LANDING: "LANDING"}
HEARTBEAT_LOST_S = 3.0
"""Without a HEARTBEAT for this long [s] the snapshot says not connected."""
STATUSTEXT_BYTES = 50


def param_id_of(m: Any) -> str:
    """The ``param_id`` of a PARAM_VALUE / PARAM_SET as a str (NUL padding removed)."""
    pid = m.param_id
    if isinstance(pid, bytes | bytearray):
        pid = pid.decode(errors="replace")
    return pid.rstrip("\x00")


@dataclass
class VehicleSnapshot:
    """What the ground station knows of the autopilot now (SI units, radians, NED from home)."""

    time_boot_ms: int = 0
    connected: bool = False
    heartbeat_age_s: float = math.inf
    armed: bool = False
    system_status: int = 0
    """MAV_STATE of the last HEARTBEAT (1 BOOT, 3 STANDBY, 4 ACTIVE, 5 CRITICAL, 6 EMERGENCY)."""
    mode_name: str = "UNKNOWN"
    vtol_state: int = 0
    vtol_state_name: str = "UNDEFINED"
    landed_state: int = 0
    roll: float = 0.0
    pitch: float = 0.0
    yaw: float = 0.0
    rollspeed: float = 0.0
    pitchspeed: float = 0.0
    yawspeed: float = 0.0
    position_ned_m: tuple[float, float, float] = (0.0, 0.0, 0.0)
    altitude_m: float = 0.0
    """Height above home (m), from GLOBAL_POSITION_INT.relative_alt."""
    home_amsl_m: float = math.nan
    """Altitude of home above mean sea level (m), from HOME_POSITION (NaN until heard)."""
    home_lat_lon_deg: tuple[float, float] = (math.nan, math.nan)
    battery_v: float = math.nan
    """BATTERY_STATUS pack voltage (V; NaN until heard)."""
    battery_a: float = math.nan
    battery_remaining: float = math.nan
    """Remaining charge 0..1 (BATTERY_STATUS.battery_remaining / 100)."""
    gps_fix_type: int = 0
    gps_satellites: int = 0
    gps_hdop: float = math.nan
    mission_seq: int = 0
    """MISSION_CURRENT: current item, total items and MISSION_STATE."""
    mission_total: int = 0
    mission_state: int = 0
    airspeed_m_s: float = 0.0
    groundspeed_m_s: float = 0.0
    heading_deg: float = 0.0
    throttle: float = 0.0
    """VFR_HUD throttle, 0..1."""
    actuator_outputs: list[float] = field(default_factory=list)
    last_statustext: str = ""
    sim_time_s: float = 0.0
    """Autopilot time of the newest timestamped message (simulated time in SITL)."""


class TelemetryCache:
    """The latest :class:`VehicleSnapshot`, STATUSTEXTs and parameter types, fed with every
    message from the autopilot (:meth:`update`, in the receive thread; thread-safe)."""

    def __init__(self) -> None:
        self._lock = threading.Lock()
        self._snap = VehicleSnapshot()
        self._last_heartbeat = -math.inf
        self.heartbeat_event = threading.Event()
        """Set at the first HEARTBEAT of the autopilot."""
        self._statustexts: collections.deque[tuple[float, str]] = collections.deque(maxlen=64)
        self._chunks: dict[int, dict[int, bytes]] = {}
        self.param_types: dict[str, int] = {}
        """MAV_PARAM_TYPE of every parameter seen in a PARAM_VALUE, by name."""

    def snapshot(self) -> VehicleSnapshot:
        """A copy of the current vehicle state."""
        with self._lock:
            age = time.monotonic() - self._last_heartbeat
            return replace(self._snap, heartbeat_age_s=age, connected=age < HEARTBEAT_LOST_S,
                           actuator_outputs=list(self._snap.actuator_outputs))

    def statustexts(self, since: float = -math.inf) -> list[str]:
        """STATUSTEXT texts received at or after monotonic time ``since`` [s], oldest first."""
        with self._lock:
            return [t for ts, t in self._statustexts if ts >= since]

    def update(self, m: Any) -> None:
        """Receive thread: one message from the autopilot."""
        t = m.get_type()
        with self._lock:
            s = self._snap
            if t == "HEARTBEAT":
                self._last_heartbeat = time.monotonic()
                s.armed = bool(m.base_mode & MAV_MODE_FLAG_SAFETY_ARMED)
                s.system_status = int(m.system_status)
                s.mode_name = mode_name(m.custom_mode)
                self.heartbeat_event.set()
            elif t == "STATUSTEXT":
                text = self._statustext(m)
                if text is not None:
                    s.last_statustext = text
                    self._statustexts.append((time.monotonic(), text))
            elif t == "PARAM_VALUE":
                self.param_types[param_id_of(m)] = int(m.param_type)
            else:
                _update_state(s, t, m)

    def _statustext(self, m: Any) -> str | None:
        """The text of a STATUSTEXT, or None while a chunked text (MAVLink 2 ``id`` != 0)
        is incomplete: chunks of one id are joined until one shorter than 50 bytes."""
        raw = m.text if isinstance(m.text, bytes) else m.text.encode("utf-8", "replace")
        raw = raw.rstrip(b"\x00")
        text_id = int(getattr(m, "id", 0) or 0)
        if text_id == 0:
            return raw.decode("utf-8", "replace")
        parts = self._chunks.setdefault(text_id, {})
        parts[int(getattr(m, "chunk_seq", 0))] = raw
        if len(raw) == STATUSTEXT_BYTES:
            return None
        del self._chunks[text_id]
        return b"".join(parts[k] for k in sorted(parts)).decode("utf-8", "replace")


def _update_state(s: VehicleSnapshot, t: str, m: Any) -> None:
    """The vehicle-state fields of ``s`` from message ``m`` of type ``t``."""
    if t == "ATTITUDE":
        s.roll, s.pitch, s.yaw = m.roll, m.pitch, m.yaw
        s.rollspeed, s.pitchspeed, s.yawspeed = m.rollspeed, m.pitchspeed, m.yawspeed
        _time_ms(s, m.time_boot_ms)
    elif t == "LOCAL_POSITION_NED":
        s.position_ned_m = (float(m.x), float(m.y), float(m.z))
        _time_ms(s, m.time_boot_ms)
    elif t == "HOME_POSITION":
        s.home_amsl_m = m.altitude * 1e-3
        s.home_lat_lon_deg = (m.latitude * 1e-7, m.longitude * 1e-7)
    elif t == "BATTERY_STATUS":
        cells = [v for v in m.voltages[:10] if v != 65535]
        s.battery_v = sum(cells) * 1e-3 if cells else math.nan
        s.battery_a = m.current_battery * 0.01 if m.current_battery >= 0 else math.nan
        s.battery_remaining = (m.battery_remaining / 100.0
                               if m.battery_remaining >= 0 else math.nan)
    elif t == "GPS_RAW_INT":
        s.gps_fix_type = int(m.fix_type)
        s.gps_satellites = int(m.satellites_visible)
        s.gps_hdop = m.eph / 100.0 if m.eph != 65535 else math.nan
    elif t == "MISSION_CURRENT":
        s.mission_seq = int(m.seq)
        s.mission_total = int(getattr(m, "total", 0))
        s.mission_state = int(getattr(m, "mission_state", 0))
    elif t == "GLOBAL_POSITION_INT":
        s.altitude_m = m.relative_alt * 1e-3
        _time_ms(s, m.time_boot_ms)
    elif t == "VFR_HUD":
        s.airspeed_m_s = float(m.airspeed)
        s.groundspeed_m_s = float(m.groundspeed)
        s.heading_deg = float(m.heading)
        s.throttle = m.throttle / 100.0
    elif t == "EXTENDED_SYS_STATE":
        s.vtol_state = int(m.vtol_state)
        s.vtol_state_name = VTOL_STATE_NAMES.get(s.vtol_state, str(s.vtol_state))
        s.landed_state = int(m.landed_state)
    elif t == "ACTUATOR_OUTPUT_STATUS":
        s.actuator_outputs = [float(x) for x in m.actuator[: max(0, int(m.active))]]
        _time_us(s, m.time_usec)
    elif t == "SYSTEM_TIME":
        _time_ms(s, m.time_boot_ms)


def _time_ms(s: VehicleSnapshot, ms: int) -> None:
    s.time_boot_ms = int(ms)
    s.sim_time_s = ms * 1e-3


def _time_us(s: VehicleSnapshot, us: int) -> None:
    s.sim_time_s = us * 1e-6
    s.time_boot_ms = int(us) // 1000

"""A PX4-format ULog writer (file format version 1), as a run observer of the autopilot.

The file is what PX4's logger writes, so Flight Review, PlotJuggler and pyulog open it:
16-byte header (``ULog`` magic, version 1, start timestamp in microseconds), the flag-bits
message, the definitions (formats 'F', info 'I': ``sys_name`` "vtol-ftc", ``ver_sw``,
``sys_mcu``, the airframe and controller; every parameter 'P' with its value at start), then
the data section: subscriptions 'A', data 'D' with a uint64 ``timestamp`` first (simulated
microseconds), logged strings 'L' (events, STATUSTEXTs, faults; PX4's log levels as ASCII
'0'..'7') and changed parameters 'P'.

Topics (PX4's names and field names; rates on simulated time): ``vehicle_attitude`` (q) and
``vehicle_attitude_setpoint`` (roll/pitch/yaw_body, q_d) at 50 Hz, ``vehicle_local_position``
(x y z vx vy vz, ref_lat/lon/alt) at 50 Hz, ``actuator_outputs`` (16 outputs, the 15 normalised
commands) at 50 Hz, ``airspeed`` at 10 Hz, ``vehicle_status`` (nav_state, arming_state,
vehicle_type, is_vtol, in_transition_mode, in_transition_to_fw) at 10 Hz and on change,
``battery_status`` (voltage_v, current_a, discharged_mah, remaining) at 2 Hz, ``mission_result``
(seq_current, seq_reached, seq_total, finished) on change and ``navigator_mission_item`` (one
message per stored mission item, whenever the plan changes).

No padding fields (pyulog, like PX4's logger, leaves trailing padding out of the data).
Writes go to the file at once and are flushed once per simulated second and at the end, so a
crash or SIGTERM loses at most the last second.
"""

from __future__ import annotations

import math
import struct
from pathlib import Path
from typing import Any, BinaryIO

__all__ = ["TOPICS", "ULogWriter"]

_HEADER_MAGIC = b"ULog\x01\x12\x35"
_TYPES = {"uint64_t": "Q", "int64_t": "q", "uint32_t": "I", "int32_t": "i", "uint16_t": "H",
          "int16_t": "h", "uint8_t": "B", "int8_t": "b", "float": "f", "double": "d",
          "bool": "?", "char": "c"}

TOPICS: dict[str, list[tuple[str, str]]] = {
    "vehicle_attitude": [("uint64_t", "timestamp"), ("float[4]", "q")],
    "vehicle_attitude_setpoint": [("uint64_t", "timestamp"), ("float", "roll_body"),
                                  ("float", "pitch_body"), ("float", "yaw_body"),
                                  ("float[4]", "q_d")],
    "vehicle_local_position": [("uint64_t", "timestamp"), ("double", "ref_lat"),
                               ("double", "ref_lon"), ("float", "ref_alt"), ("float", "x"),
                               ("float", "y"), ("float", "z"), ("float", "vx"),
                               ("float", "vy"), ("float", "vz")],
    "airspeed": [("uint64_t", "timestamp"), ("float", "indicated_airspeed_m_s"),
                 ("float", "true_airspeed_m_s")],
    "actuator_outputs": [("uint64_t", "timestamp"), ("uint32_t", "noutputs"),
                         ("float[16]", "output")],
    "vehicle_status": [("uint64_t", "timestamp"), ("uint8_t", "nav_state"),
                       ("uint8_t", "arming_state"), ("uint8_t", "vehicle_type"),
                       ("bool", "is_vtol"), ("bool", "in_transition_mode"),
                       ("bool", "in_transition_to_fw")],
    "battery_status": [("uint64_t", "timestamp"), ("float", "voltage_v"),
                       ("float", "current_a"), ("float", "discharged_mah"),
                       ("float", "remaining"), ("uint8_t", "warning")],
    "mission_result": [("uint64_t", "timestamp"), ("int32_t", "seq_current"),
                       ("int32_t", "seq_reached"), ("uint16_t", "seq_total"),
                       ("bool", "finished")],
    "navigator_mission_item": [("uint64_t", "timestamp"), ("double", "latitude"),
                               ("double", "longitude"), ("float", "altitude"),
                               ("float", "param1"), ("float", "param2"), ("float", "param3"),
                               ("float", "param4"), ("uint16_t", "sequence"),
                               ("uint16_t", "nav_cmd"), ("uint8_t", "frame")],
}

# PX4 vehicle_status.nav_state of the (main, sub) custom modes
_NAV_STATE = {(2, 0): 1, (3, 0): 2, (4, 4): 3, (4, 3): 4, (4, 5): 5, (4, 6): 18,
              (4, 2): 17, (4, 1): 4, (1, 0): 0, (7, 0): 15, (5, 0): 10, (6, 0): 14}


def _struct_of(fields: list[tuple[str, str]]) -> struct.Struct:
    fmt = "<"
    for typ, _ in fields:
        base, _, n = typ.partition("[")
        count = int(n[:-1]) if n else 1
        fmt += f"{count}{_TYPES[base]}" if count > 1 else _TYPES[base]
    return struct.Struct(fmt)


class ULogWriter:
    """Run observer writing ``path`` (see the module docstring).

    Parameters
    ----------
    path
        the ``.ulg`` file (parent directory created).
    autopilot
        the autopilot (parameters, navigator, battery estimate), optional.
    home
        (lat, lon, alt) of the local frame's origin, if known at start.
    """

    def __init__(self, path: str | Path, autopilot: Any = None,
                 home: tuple[float, float, float] | None = None) -> None:
        self.path = Path(path)
        self.ap = autopilot
        self.home = home
        self._f: BinaryIO | None = None
        self._ids: dict[str, int] = {}
        self._structs = {name: _struct_of(f) for name, f in TOPICS.items()}
        self._last: dict[str, int] = {}
        self._next_flush = 0
        self._status_key: tuple | None = None
        self._mission_key: tuple | None = None
        self._plan_id: int | None = None
        self._params: dict[str, float] = {}
        self.t_first: int | None = None
        self.t_last = 0

    # ------------------------------------------------------------------ encoding
    def _msg(self, kind: bytes, payload: bytes) -> None:
        assert self._f is not None
        self._f.write(struct.pack("<HB", len(payload), kind[0]) + payload)

    @staticmethod
    def _kv(typ: str, name: str, value: bytes) -> bytes:
        key = f"{typ} {name}".encode()
        return bytes([len(key)]) + key + value

    def _info(self, name: str, value: str) -> None:
        v = value.encode()
        self._msg(b"I", self._kv(f"char[{len(v)}]", name, v))

    def _param(self, name: str, value: float, is_int: bool) -> None:
        if is_int:
            self._msg(b"P", self._kv("int32_t", name, struct.pack("<i", int(value))))
        else:
            self._msg(b"P", self._kv("float", name, struct.pack("<f", float(value))))

    def _data(self, topic: str, *values: Any) -> None:
        self._msg(b"D", struct.pack("<H", self._ids[topic]) + self._structs[topic].pack(*values))

    def _due(self, topic: str, t: int, period_us: int) -> bool:
        if t - self._last.get(topic, -(1 << 62)) >= period_us:
            self._last[topic] = t
            return True
        return False

    # ------------------------------------------------------------------ observer protocol
    def on_start(self, info: dict[str, Any]) -> None:
        """Create the ``.ulg`` file and write the header, flag bits, formats and parameters."""
        self.path.parent.mkdir(parents=True, exist_ok=True)
        self._f = self.path.open("wb")
        self._f.write(_HEADER_MAGIC + bytes([1]) + struct.pack("<Q", 0))
        self._msg(b"B", bytes(8) + bytes(8) + bytes(24))
        for name, fields in TOPICS.items():
            text = name + ":" + "".join(f"{t} {n};" for t, n in fields)
            self._msg(b"F", text.encode())
        self._info("sys_name", "vtol-ftc")
        self._info("ver_hw", "SITL")
        self._info("sys_mcu", "simulated autopilot (vtol-ftc)")
        self._info("sys_uuid", str(info.get("airframe_sha256", ""))[:32] or "unknown")
        for key in ("airframe", "controller", "case", "scenario"):
            if info.get(key):
                self._info(f"vtolftc_{key}", str(info[key]))
        if self.ap is not None:
            for prm in self.ap.params:
                is_int = int(prm.type) == 6
                self._param(prm.name, prm.value, is_int)
                self._params[prm.name] = prm.value
        for k, name in enumerate(TOPICS):
            self._ids[name] = k
            self._msg(b"A", struct.pack("<BH", 0, k) + name.encode())
        self._f.flush()

    def on_sample(self, sample: Any) -> None:
        """Append one control step's topics (timestamps relative to the first sample)."""
        if self._f is None:
            return
        t = int(sample.time_usec)
        if self.t_first is None:
            self.t_first = t
        self.t_last = t
        nav, st = sample.nav, sample.status
        if self._due("vehicle_attitude", t, 20_000):
            q = [float(x) for x in nav.q_wxyz]
            self._data("vehicle_attitude", t, *q)
            r, p, y = (float(x) for x in st.attitude_ref_rad)
            self._data("vehicle_attitude_setpoint", t, r, p, y, *_quat(r, p, y))
            pos, vel = nav.pos_ned_m, nav.vel_ned_m_s
            home = self._home()
            self._data("vehicle_local_position", t, home[0], home[1], home[2],
                       *(float(x) for x in pos), *(float(x) for x in vel))
            out = [float(x) for x in st.actuator_commands][:16]
            self._data("actuator_outputs", t, len(out), *(out + [0.0] * (16 - len(out))))
        if self._due("airspeed", t, 100_000):
            v = float(nav.airspeed_m_s)
            self._data("airspeed", t, v, v)
        cm = int(getattr(st, "px4_custom_mode", -1))
        main, sub = (cm >> 16) & 0xFF, (cm >> 24) & 0xFF
        vt = int(st.vtol_state)
        key = (main, sub, bool(st.armed), vt)
        if key != self._status_key or self._due("vehicle_status", t, 100_000):
            self._status_key = key
            self._data("vehicle_status", t, _NAV_STATE.get((main, sub), 4),
                       2 if st.armed else 1, 2 if vt == 4 else 1, True, vt in (1, 2), vt == 1)
        self._mission(t)
        self._battery(t)
        self._param_changes(t)
        if t >= self._next_flush:
            self._next_flush = t + 1_000_000
            self._f.flush()

    def on_event(self, time_usec: int, kind: str, text: str) -> None:
        """Log the event as a ULog string: WARNING for faults, failsafes and denials, else INFO."""
        if self._f is None:
            return
        level = b"4" if kind in ("fault", "failsafe") or "denied" in text else b"6"
        self._msg(b"L", level + struct.pack("<Q", max(0, int(time_usec)))
                  + f"[{kind}] {text}".encode())

    def on_finish(self, metrics: dict[str, Any]) -> None:
        """Flush and close the file (``metrics`` unused)."""
        if self._f is None:
            return
        self._f.flush()
        self._f.close()
        self._f = None

    # ------------------------------------------------------------------ helpers
    def _home(self) -> tuple[float, float, float]:
        nav = getattr(self.ap, "navigator", None)
        h = nav.home if nav is not None and nav.home is not None else self.home
        return h if h is not None else (math.nan, math.nan, math.nan)

    def _mission(self, t: int) -> None:
        nav = getattr(self.ap, "navigator", None)
        if nav is None:
            return
        items = nav.store.mission
        if id(items) != self._plan_id:
            self._plan_id = id(items)
            for it in items:
                self._data("navigator_mission_item", t, it.lat_deg, it.lon_deg, it.z,
                           it.param1, it.param2, it.param3, it.param4, it.seq, it.command,
                           it.frame)
        reached = nav.reached_log[-1][1] if nav.reached_log else -1
        key = (nav.store.current, reached, len(items), nav.mission_state)
        if key != self._mission_key:
            self._mission_key = key
            self._data("mission_result", t, nav.store.current, reached, len(items),
                       nav.mission_state == 5)

    def _battery(self, t: int) -> None:
        bat = getattr(self.ap, "battery", None)
        if bat is None or not math.isfinite(bat.voltage_v) or not self._due("battery_status",
                                                                             t, 500_000):
            return
        self._data("battery_status", t, bat.voltage_v, bat.current_a, bat.consumed_mah,
                   bat.remaining, bat.level)

    def _param_changes(self, t: int) -> None:
        if self.ap is None or not self._due("_params", t, 1_000_000):
            return
        for prm in self.ap.params:
            if self._params.get(prm.name) != prm.value:
                self._params[prm.name] = prm.value
                self._param(prm.name, prm.value, int(prm.type) == 6)


def _quat(roll: float, pitch: float, yaw: float) -> tuple[float, float, float, float]:
    """ZYX Euler angles [rad] -> quaternion (w, x, y, z)."""
    cr, sr = math.cos(roll / 2), math.sin(roll / 2)
    cp, sp = math.cos(pitch / 2), math.sin(pitch / 2)
    cy, sy = math.cos(yaw / 2), math.sin(yaw / 2)
    return (cr * cp * cy + sr * sp * sy, sr * cp * cy - cr * sp * sy,
            cr * sp * cy + sr * cp * sy, cr * cp * sy - sr * sp * cy)

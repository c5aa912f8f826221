"""A PX4-format ULog writer (file format version 1), as a run observer of the autopilot.

The file is what PX4's logger writes, so Flight Review, PlotJuggler and pyulog open it:
16-byte header (``ULog`` magic, version 1, start timestamp in microseconds), the flag-bits
message, the definitions (formats 'F', nested ``position_setpoint`` first; info 'I':
``sys_name`` "vtol-ftc", ``ver_sw`` (the git commit of the checkout, else the package version),
``ver_sw_release`` (PX4's 0xAABBCCTT encoding of the package version), ``ver_hw`` "SITL",
``sys_mcu``, ``sys_os_name``, ``sys_toolchain``/``sys_toolchain_ver``, ``sys_uuid``,
``time_ref_utc``, the airframe and controller; every parameter 'P' with its value at start),
then the data section: subscriptions 'A', data 'D' with a uint64 ``timestamp`` first
(simulated microseconds), logged strings 'L' (events, STATUSTEXTs, faults; PX4's log levels as
ASCII '0'..'7') and changed parameters 'P'.

Topics (PX4's names, field names and default logger rates, on simulated time; a topic's fields
are a subset of PX4's message, in PX4's units):

===============================  ======  ====================================================
topic                            rate    fields and source
===============================  ======  ====================================================
``vehicle_attitude``             50 Hz   q (body FRD -> NED)
``vehicle_attitude_setpoint``    50 Hz   roll/pitch/yaw_body, q_d (the attitude reference)
``vehicle_angular_velocity``     50 Hz   xyz (body rates the controller used), xyz_derivative
``vehicle_rates_setpoint``       50 Hz   roll, pitch, yaw (the P-PID outer loops' rate
                                         references; NaN for LQR, which has no rate loop)
``sensor_combined``              50 Hz   gyro_rad; accelerometer_m_s2: the HIL_SENSOR
                                         accelerometer when the autopilot has one (SITL), else
                                         the mean specific force over the 20 ms interval from
                                         the velocity change (``*_integral_dt`` 20000 us; the
                                         simulated vehicle's velocity when the sample carries
                                         it, in-process: a logged sensor, never fed back)
``vehicle_local_position``       50 Hz   x y z vx vy vz, ref_lat/lon/alt, xy/z/v_xy/v_z_valid
``actuator_outputs``             50 Hz   16 outputs (the 15 normalised commands)
``vehicle_gps_position``         10 Hz   lat/lon (1e-7 deg), alt (mm AMSL), vel_*_m_s, cog,
                                         eph/epv, fix_type, satellites_used, time_utc_usec:
                                         from HIL_GPS when the autopilot has it (SITL), else
                                         from the navigation state about home
``airspeed``                     10 Hz   indicated / true airspeed
``vehicle_status``               10 Hz   nav_state, arming_state, vehicle_type, is_vtol,
                                         in_transition_mode, in_transition_to_fw (+ changes)
``vehicle_global_position``       5 Hz   lat, lon (deg), alt (m AMSL), vel_n/e/d, eph, epv
``vehicle_air_data``              5 Hz   baro_alt_meter, baro_temp_celcius, baro_pressure_pa,
                                         rho (HIL_SENSOR's pressure in SITL, else the ISA
                                         standard atmosphere at the altitude)
``position_setpoint_triplet``     5 Hz   previous/current/next (lat, lon, alt AMSL, valid,
                                         type): the navigator's goal, else the altitude hold
``vtol_vehicle_status``           5 Hz   vehicle_vtol_state (MAV_VTOL_STATE values) (+ changes)
``battery_status``                2 Hz   voltage_v, current_a, discharged_mah, remaining
``cpuload``                       2 Hz   load (this process's CPU time over wall time, per
                                         core), ram_usage (resident set over physical memory)
``mission_result``               change  seq_current, seq_reached, seq_total, finished
``navigator_mission_item``       change  one message per stored mission item, per new plan
===============================  ======  ====================================================

No padding fields (pyulog, like PX4's logger, leaves trailing padding out of the data).
Writes go to the file at once and are flushed every 0.5 s of simulated time and at the end,
so a crash, SIGKILL or SIGTERM loses at most the last half second (a cut last message is
skipped by readers).
"""

from __future__ import annotations

import datetime as _dt
import math
import os
import platform
import struct
import subprocess
import time
from pathlib import Path
from typing import Any, BinaryIO

import numpy as np

from vtolftc.base.geodesy import FlatEarth
from vtolftc.base.rotation import dcm, euler_to_quat

__all__ = ["NESTED", "TOPICS", "ULogWriter"]

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
                               ("float", "vy"), ("float", "vz"), ("bool", "xy_valid"),
                               ("bool", "z_valid"), ("bool", "v_xy_valid"),
                               ("bool", "v_z_valid")],
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
    "vehicle_angular_velocity": [("uint64_t", "timestamp"), ("uint64_t", "timestamp_sample"),
                                 ("float[3]", "xyz"), ("float[3]", "xyz_derivative")],
    "vehicle_rates_setpoint": [("uint64_t", "timestamp"), ("float", "roll"), ("float", "pitch"),
                               ("float", "yaw")],
    "sensor_combined": [("uint64_t", "timestamp"), ("float[3]", "gyro_rad"),
                        ("uint32_t", "gyro_integral_dt"),
                        ("int32_t", "accelerometer_timestamp_relative"),
                        ("float[3]", "accelerometer_m_s2"),
                        ("uint32_t", "accelerometer_integral_dt"),
                        ("uint8_t", "accelerometer_clipping"), ("uint8_t", "gyro_clipping")],
    "vehicle_gps_position": [("uint64_t", "timestamp"), ("uint64_t", "time_utc_usec"),
                             ("int32_t", "lat"), ("int32_t", "lon"), ("int32_t", "alt"),
                             ("int32_t", "alt_ellipsoid"), ("float", "s_variance_m_s"),
                             ("float", "eph"), ("float", "epv"), ("float", "hdop"),
                             ("float", "vdop"), ("int32_t", "noise_per_ms"),
                             ("int32_t", "jamming_indicator"), ("float", "vel_m_s"),
                             ("float", "vel_n_m_s"), ("float", "vel_e_m_s"),
                             ("float", "vel_d_m_s"), ("float", "cog_rad"),
                             ("uint8_t", "fix_type"), ("bool", "vel_ned_valid"),
                             ("uint8_t", "satellites_used")],
    "vehicle_global_position": [("uint64_t", "timestamp"), ("uint64_t", "timestamp_sample"),
                                ("double", "lat"), ("double", "lon"), ("float", "alt"),
                                ("float", "alt_ellipsoid"), ("float", "vel_n"),
                                ("float", "vel_e"), ("float", "vel_d"), ("float", "eph"),
                                ("float", "epv"), ("bool", "dead_reckoning")],
    "vehicle_air_data": [("uint64_t", "timestamp"), ("uint64_t", "timestamp_sample"),
                         ("uint32_t", "baro_device_id"), ("float", "baro_alt_meter"),
                         ("float", "baro_temp_celcius"), ("float", "baro_pressure_pa"),
                         ("float", "rho")],
    "position_setpoint_triplet": [("uint64_t", "timestamp"), ("position_setpoint", "previous"),
                                  ("position_setpoint", "current"),
                                  ("position_setpoint", "next")],
    "vtol_vehicle_status": [("uint64_t", "timestamp"), ("uint8_t", "vehicle_vtol_state"),
                            ("bool", "fixed_wing_system_failure")],
    "cpuload": [("uint64_t", "timestamp"), ("float", "load"), ("float", "ram_usage")],
}

# nested message formats (PX4's position_setpoint, a part of position_setpoint_triplet)
NESTED: dict[str, list[tuple[str, str]]] = {
    "position_setpoint": [("uint64_t", "timestamp"), ("double", "lat"), ("double", "lon"),
                          ("float", "alt"), ("float", "vx"), ("float", "vy"), ("float", "vz"),
                          ("float", "yaw"), ("float", "acceptance_radius"),
                          ("float", "cruising_speed"), ("bool", "valid"), ("uint8_t", "type")],
}

# PX4 vehicle_status.nav_state of the (main, sub) custom modes
_NAV_STATE = {(2, 0): 1, (3, 0): 2, (4, 4): 3, (4, 3): 4, (4, 5): 5, (4, 6): 18,
              (4, 2): 17, (4, 1): 4, (1, 0): 0, (7, 0): 15, (5, 0): 10, (6, 0): 14}


# PX4 position_setpoint.type
SETPOINT_TYPE_POSITION, SETPOINT_TYPE_LOITER, SETPOINT_TYPE_TAKEOFF = 0, 2, 3
SETPOINT_TYPE_LAND, SETPOINT_TYPE_IDLE = 4, 5
_SP_TYPE = {21: SETPOINT_TYPE_LAND, 85: SETPOINT_TYPE_LAND, 22: SETPOINT_TYPE_TAKEOFF,
            84: SETPOINT_TYPE_TAKEOFF, 17: SETPOINT_TYPE_LOITER, 19: SETPOINT_TYPE_LOITER}
_GRAVITY = 9.80665
_NAN_SETPOINT = (0, math.nan, math.nan, math.nan, math.nan, math.nan, math.nan, math.nan,
                 math.nan, math.nan, False, SETPOINT_TYPE_IDLE)


def _fmt_of(fields: list[tuple[str, str]]) -> str:
    fmt = ""
    for typ, _ in fields:
        base, _, n = typ.partition("[")
        count = int(n[:-1]) if n else 1
        code = _fmt_of(NESTED[base]) if base in NESTED else _TYPES[base]
        fmt += code * count if base in NESTED else (f"{count}{code}" if count > 1 else code)
    return fmt


def _struct_of(fields: list[tuple[str, str]]) -> struct.Struct:
    return struct.Struct("<" + _fmt_of(fields))


def _isa(alt_m: float) -> tuple[float, float, float]:
    """ISA troposphere at ``alt_m`` AMSL: (pressure Pa, temperature degC, density kg/m^3)."""
    t_k = 288.15 - 0.0065 * alt_m
    p = 101_325.0 * (t_k / 288.15) ** 5.25588
    return p, t_k - 273.15, p / (287.053 * t_k)


def _software_version() -> tuple[str, int]:
    """(``ver_sw``: the checkout's git commit, else the package version; ``ver_sw_release``:
    PX4's 0xAABBCCTT encoding of the package version, TT = 255 for a release)."""
    import importlib.metadata as md

    try:
        version = md.version("vtol-ftc")
    except md.PackageNotFoundError:
        version = "0.0.0"
    nums = [int(x) if x.isdigit() else 0 for x in version.split(".")[:3]] + [0, 0, 0]
    release = ((nums[0] & 0xFF) << 24) | ((nums[1] & 0xFF) << 16) | ((nums[2] & 0xFF) << 8) | 255
    sha = ""
    try:
        r = subprocess.run(["git", "rev-parse", "HEAD"], cwd=Path(__file__).resolve().parent,
                           capture_output=True, text=True, timeout=5.0, check=False)
        if r.returncode == 0 and len(r.stdout.strip()) == 40:
            sha = r.stdout.strip()
    except (OSError, subprocess.SubprocessError):
        pass
    return sha or f"vtol-ftc {version}", release


def _ram_usage() -> float:
    """Resident set size of this process over the physical memory (NaN where unknown)."""
    try:
        with open("/proc/self/statm", "rb") as f:
            rss_pages = int(f.read().split()[1])
        return rss_pages / os.sysconf("SC_PHYS_PAGES")
    except (OSError, ValueError, IndexError, AttributeError):
        return math.nan


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
    hil
        the autopilot's HIL bridge (``last_sensor``: HIL_SENSOR, ``last_gps``: HIL_GPS), in
        SITL; without it the sensor topics are derived from the navigation state.
    flush_period_us
        longest simulated time between two flushes to the operating system [us].
    """

    def __init__(self, path: str | Path, autopilot: Any = None,
                 home: tuple[float, float, float] | None = None, hil: Any = None,
                 flush_period_us: int = 500_000) -> None:
        self.path = Path(path)
        self.ap = autopilot
        self.home = home
        self.hil = hil
        self.flush_period_us = int(flush_period_us)
        self._prev_vel: tuple[int, Any] | None = None     # (t, velocity NED) 20 ms ago
        self._prev_rates: tuple[int, tuple[float, float, float]] | None = None
        self._vtol_key: int | None = None
        self._cpu: tuple[float, float] | None = None      # (process time, wall time)
        self._utc0_us = 0
        self._ncpu = os.cpu_count() or 1
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

    def bind(self, autopilot: Any) -> None:
        """Attach the autopilot (parameters, navigator, battery) before the run starts, e.g.
        as ``run_scenario(..., autopilot_setup=writer.bind)``."""
        self.ap = autopilot

    def _info_int(self, typ: str, name: str, value: int) -> None:
        code = _TYPES[typ]
        self._msg(b"I", self._kv(typ, name, struct.pack("<" + code, value)))

    def _data(self, topic: str, *values: Any) -> None:
        self._msg(b"D", struct.pack("<H", self._ids[topic]) + self._structs[topic].pack(*values))

    def _due(self, topic: str, t: int, period_us: int) -> bool:
        """True once per ``period_us`` grid cell of simulated time (a step that skipped
        ahead, as a loaded SITL autopilot does, still logs the cell it lands in)."""
        if t >= self._last.get(topic, -(1 << 62)):
            self._last[topic] = (t // period_us + 1) * period_us
            return True
        return False

    # ------------------------------------------------------------------ observer protocol
    def on_start(self, info: dict[str, Any]) -> None:
        """Create the ``.ulg`` file and write the header, flag bits, formats and parameters."""
        self.path.parent.mkdir(parents=True, exist_ok=True)
        self._f = self.path.open("wb")
        self._f.write(_HEADER_MAGIC + bytes([1]) + struct.pack("<Q", 0))
        self._msg(b"B", bytes(8) + bytes(8) + bytes(24))
        for name, fields in (*NESTED.items(), *TOPICS.items()):
            text = name + ":" + "".join(f"{t} {n};" for t, n in fields)
            self._msg(b"F", text.encode())
        ver_sw, ver_release = _software_version()
        self._info("sys_name", "vtol-ftc")
        self._info("ver_hw", "SITL")
        self._info("ver_sw", ver_sw)
        self._info_int("uint32_t", "ver_sw_release", ver_release)
        self._info("sys_mcu", "simulated autopilot (vtol-ftc)")
        self._info("sys_os_name", platform.system() or "unknown")
        self._info("sys_toolchain", platform.python_implementation())
        self._info("sys_toolchain_ver", platform.python_version())
        self._info("sys_uuid", str(info.get("airframe_sha256", ""))[:32] or "unknown")
        self._info_int("int32_t", "time_ref_utc", 0)
        self._utc0_us = int(_dt.datetime.now(_dt.UTC).timestamp() * 1e6)
        self._cpu = (time.process_time(), time.monotonic())
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
        home = None
        if self._due("vehicle_attitude", t, 20_000):
            q = [float(x) for x in nav.q_wxyz]
            self._data("vehicle_attitude", t, *q)
            r, p, y = (float(x) for x in st.attitude_ref_rad)
            self._data("vehicle_attitude_setpoint", t, r, p, y, *euler_to_quat(r, p, y).tolist())
            pos, vel = nav.pos_ned_m, nav.vel_ned_m_s
            home = self._home()
            ok = math.isfinite(home[0])
            self._data("vehicle_local_position", t, home[0], home[1], home[2],
                       *(float(x) for x in pos), *(float(x) for x in vel), ok, ok, True, True)
            out = [float(x) for x in st.actuator_commands][:16]
            self._data("actuator_outputs", t, len(out), *(out + [0.0] * (16 - len(out))))
            self._rates_and_imu(t, sample, q)
        if self._due("airspeed", t, 100_000):
            v = float(nav.airspeed_m_s)
            self._data("airspeed", t, v, v)
            self._gps(t, nav, home or self._home())
        if self._due("vehicle_global_position", t, 200_000):
            home = home or self._home()
            self._global_and_air(t, nav, home)
            self._setpoints(t, st, home)
        vt = int(st.vtol_state)
        if vt != self._vtol_key or self._due("vtol_vehicle_status", t, 200_000):
            self._vtol_key = vt
            self._data("vtol_vehicle_status", t, vt, False)
        if self._due("cpuload", t, 500_000):
            self._cpuload(t)
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
            self._next_flush = t + self.flush_period_us
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

    def _rates_and_imu(self, t: int, sample: Any, q: list[float]) -> None:
        """vehicle_angular_velocity, vehicle_rates_setpoint and sensor_combined (50 Hz)."""
        nav = sample.nav
        w = (float(nav.omega_body_rad_s[0]), float(nav.omega_body_rad_s[1]),
             float(nav.omega_body_rad_s[2]))
        prev = self._prev_rates
        if prev is not None and t > prev[0]:
            k = 1e6 / (t - prev[0])
            dw = ((w[0] - prev[1][0]) * k, (w[1] - prev[1][1]) * k, (w[2] - prev[1][2]) * k)
        else:
            dw = (0.0, 0.0, 0.0)
        self._prev_rates = (t, w)
        self._data("vehicle_angular_velocity", t, t, *w, *dw)
        pids = getattr(getattr(self.ap, "attitude", None), "pids", None)
        if pids is not None and len(pids) == 3:
            self._data("vehicle_rates_setpoint", t, *(float(pid.rate_ref) for pid in pids))
        else:
            self._data("vehicle_rates_setpoint", t, math.nan, math.nan, math.nan)
        sens = getattr(self.hil, "last_sensor", None)
        if sens is not None:
            gyro = (float(sens.xgyro), float(sens.ygyro), float(sens.zgyro))
            acc = (float(sens.xacc), float(sens.yacc), float(sens.zacc))
        else:
            # mean specific force over the last interval: R^T (dv/dt - g), body FRD
            gyro = w
            tr = sample.truth
            vel = tr.vel_ned_m_s if tr is not None else nav.vel_ned_m_s
            vn, ve, vd = float(vel[0]), float(vel[1]), float(vel[2])
            pv = self._prev_vel
            if pv is not None and t > pv[0]:
                k = 1e6 / (t - pv[0])
                a = ((vn - pv[1][0]) * k, (ve - pv[1][1]) * k, (vd - pv[1][2]) * k - _GRAVITY)
            else:
                a = (0.0, 0.0, -_GRAVITY)
            self._prev_vel = (t, (vn, ve, vd))
            acc = tuple((dcm(q).T @ np.asarray(a)).tolist())
        self._data("sensor_combined", t, *gyro, 20_000, 0, *acc, 20_000, 0, 0)

    def _gps(self, t: int, nav: Any, home: tuple[float, float, float]) -> None:
        """vehicle_gps_position (10 Hz): HIL_GPS if the autopilot has it, else the navigation
        state about home (a 3-D fix)."""
        utc = self._utc0_us + t
        g = getattr(self.hil, "last_gps", None)
        if g is not None:
            vn, ve, vd = g.vn * 0.01, g.ve * 0.01, g.vd * 0.01
            cog = math.radians(g.cog * 0.01) if g.cog != 65535 else math.nan
            eph = g.eph * 0.01 if g.eph != 65535 else math.nan
            epv = g.epv * 0.01 if g.epv != 65535 else math.nan
            self._data("vehicle_gps_position", t, utc, int(g.lat), int(g.lon), int(g.alt),
                       int(g.alt), 0.3, eph, epv, eph, epv, 0, 0, g.vel * 0.01, vn, ve, vd,
                       cog, int(g.fix_type), True, int(g.satellites_visible) & 0xFF)
            return
        if not math.isfinite(home[0]):
            return
        pos, vel = nav.pos_ned_m, nav.vel_ned_m_s
        lat, lon = _to_global(home, float(pos[0]), float(pos[1]))
        alt = home[2] - float(pos[2])
        vn, ve, vd = float(vel[0]), float(vel[1]), float(vel[2])
        self._data("vehicle_gps_position", t, utc, round(lat * 1e7), round(lon * 1e7),
                   round(alt * 1e3), round(alt * 1e3), 0.3, 0.5, 0.8, 0.7, 1.1, 0, 0,
                   math.hypot(vn, ve), vn, ve, vd, math.atan2(ve, vn), 3, True, 10)

    def _global_and_air(self, t: int, nav: Any, home: tuple[float, float, float]) -> None:
        """vehicle_global_position and vehicle_air_data (5 Hz)."""
        pos, vel = nav.pos_ned_m, nav.vel_ned_m_s
        alt = home[2] - float(pos[2])
        if math.isfinite(home[0]):
            lat, lon = _to_global(home, float(pos[0]), float(pos[1]))
            self._data("vehicle_global_position", t, t, lat, lon, alt, alt, float(vel[0]),
                       float(vel[1]), float(vel[2]), 0.5, 0.8, False)
        sens = getattr(self.hil, "last_sensor", None)
        if sens is not None:
            p_pa = float(sens.abs_pressure) * 100.0
            temp = float(sens.temperature)
            baro_alt = float(sens.pressure_alt)
            rho = p_pa / (287.053 * (temp + 273.15))
        else:
            if not math.isfinite(alt):
                alt = -float(pos[2])
            p_pa, temp, rho = _isa(alt)
            baro_alt = alt
        self._data("vehicle_air_data", t, t, 1, baro_alt, temp, p_pa, rho)

    def _setpoints(self, t: int, st: Any, home: tuple[float, float, float]) -> None:
        """position_setpoint_triplet (5 Hz): the navigator's goal, else the altitude hold."""
        h_alt = home[2] if math.isfinite(home[2]) else 0.0
        goal = getattr(getattr(self.ap, "navigator", None), "goal", None)
        alt_ref = float(st.altitude_ref_m)
        lat = lon = math.nan
        sp_type = SETPOINT_TYPE_POSITION if st.armed else SETPOINT_TYPE_IDLE
        if goal is not None:
            if goal.has_position and math.isfinite(home[0]):
                lat, lon = _to_global(home, goal.north, goal.east)
            if math.isfinite(goal.alt):
                alt_ref = goal.alt
            sp_type = _SP_TYPE.get(int(goal.command), SETPOINT_TYPE_POSITION)
        cur = (t, lat, lon, h_alt + alt_ref, math.nan, math.nan, math.nan,
               float(st.attitude_ref_rad[2]), math.nan, math.nan, bool(st.armed), sp_type)
        self._data("position_setpoint_triplet", t, *_NAN_SETPOINT, *cur, *_NAN_SETPOINT)

    def _cpuload(self, t: int) -> None:
        """cpuload (2 Hz): CPU time of this process over wall time since the last one, per
        core, and the resident memory share."""
        now = (time.process_time(), time.monotonic())
        prev = self._cpu or now
        self._cpu = now
        wall = now[1] - prev[1]
        load = (now[0] - prev[0]) / (wall * self._ncpu) if wall > 0 else 0.0
        self._data("cpuload", t, min(max(load, 0.0), 1.0), _ram_usage())

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


def _to_global(home: tuple[float, float, float], north: float, east: float
               ) -> tuple[float, float]:
    """(lat, lon) [deg] of a point ``north``, ``east`` [m] of home (flat earth, as the HIL
    codec and the navigator project)."""
    return FlatEarth(home[0], home[1]).to_global(north, east)

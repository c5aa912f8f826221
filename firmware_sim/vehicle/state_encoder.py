"""The vehicle's state datagram: what the simulated sensors send the autopilot each step.

HIL_SENSOR + HIL_STATE_QUATERNION every step, HIL_GPS at the GPS rate, GPS_GLOBAL_ORIGIN and
FAULT_INJECTION_STATUS at 1 Hz, BATTERY_STATUS (the power module) at 5 Hz, packed back to back
in one datagram (the link parses several frames per datagram). The two messages of every
step are packed by :class:`~vtolftc.protocols.hil_frames.HilFramePackers` (one compiled call
each: payload, header and CRC into a :class:`~vtolftc.protocols.fastpack.FramePacker`'s buffer,
the generated encoding's bytes, signed or not; the state's encoding included), falling back to
``FramePacker.pack`` for what they decline; the occasional ones by the generated code.
"""

from __future__ import annotations

import math
from collections.abc import Callable
from typing import Any

from vtolftc.firmware_sim.vehicle.battery import BatteryModel
from vtolftc.firmware_sim.vehicle.model import Vehicle
from vtolftc.protocols.fastpack import FramePacker
from vtolftc.protocols.hil import HilStateEncoder
from vtolftc.protocols.hil_frames import HilFramePackers, warm_up

__all__ = ["StateEncoder"]

FIELDS_ALL = 0x1FFF
"""HIL_SENSOR.fields_updated: every field."""


class StateEncoder:
    """Encodes the state datagram of a vehicle at its current time.

    Parameters
    ----------
    vehicle : Vehicle
        The simulated vehicle (its sensors, state and time).
    battery : BatteryModel
        The power module.
    codec : Any
        The link's MAVLink codec (its sequence number advances per message).
    gps_rate_hz : float
        HIL_GPS rate [Hz] (0: no GPS).
    status_msg : callable
        Makes the FAULT_INJECTION_STATUS message.
    resign : bool
        The link signs its messages: :meth:`again` packs the last messages anew.
    """

    def __init__(self, vehicle: Vehicle, battery: BatteryModel, codec: Any, gps_rate_hz: float,
                 status_msg: Callable[[], Any], *, resign: bool = False) -> None:
        self.vehicle = vehicle
        self.battery = battery
        self.codec = codec
        self.home = vehicle.sensor_model.home
        self._encode = HilStateEncoder(self.home.lat_deg, self.home.lon_deg, self.home.alt_m)
        self.gps_period_usec = round(1e6 / gps_rate_hz) if gps_rate_hz > 0 else 0
        self._status_msg = status_msg
        self._resign = resign
        self._parts: list[tuple[Callable[..., bytes], tuple[Any, ...]]] = []
        """How the frames of the last state datagram were packed (packer, arguments)."""
        self._packers = HilFramePackers(codec, self.home.lat_deg, self.home.lon_deg,
                                        self.home.alt_m)
        self._sensor = self._packers.sensor
        warm_up()  # compile the frame kernels now, not at the first step of a flight
        self._state = self._packers.state
        self._next_gps = 0
        self._next_origin = 0
        self._next_status = 0
        self._next_battery = 0

    def _pack_msg(self, msg: Any) -> bytes:
        data: bytes = msg.pack(self.codec)
        self.codec.seq = (self.codec.seq + 1) & 0xFF
        return data

    def _pack(self, msg: Any) -> bytes:
        self._parts.append((self._pack_msg, (msg,)))
        return self._pack_msg(msg)

    def _pack_fast(self, packer: FramePacker, *values: Any) -> bytes:
        self._parts.append((packer.pack, values))
        return packer.pack(*values)

    def _pack_compiled(self, pack: Callable[..., bytes | None], *args: Any) -> bytes | None:
        """A frame of :class:`HilFramePackers` (None: it declined, nothing advanced)."""
        data = pack(*args)
        if data is not None:
            self._parts.append((pack, args))
        return data

    def again(self, datagram: bytes) -> bytes:
        """The last state datagram, to send again: the same bytes; on a signed link the same
        messages signed anew (the same bytes are a replay, which the autopilot drops)."""
        if not self._resign:
            return datagram
        return b"".join(pack(*args) for pack, args in self._parts)

    def battery_due(self) -> bool:
        """True if the next :meth:`datagram` (at the vehicle's current time) carries
        BATTERY_STATUS."""
        return self.vehicle.time_usec >= self._next_battery

    def datagram(self) -> bytes:
        """HIL_SENSOR [+ HIL_GPS] [+ GPS_GLOBAL_ORIGIN] + HIL_STATE_QUATERNION [+ status,
        battery] at the vehicle's current time."""
        v = self.vehicle
        t = v.time_usec
        c = self.codec
        parts: list[bytes] = []
        self._parts = []
        if t >= self._next_origin:
            self._next_origin = t + 1_000_000
            h = self.home
            parts.append(self._pack(c.gps_global_origin_encode(
                round(h.lat_deg * 1e7), round(h.lon_deg * 1e7), round(h.alt_m * 1e3), t)))
        s = v.sensors()
        data = self._pack_compiled(
            self._packers.sensor_frame, t, s.accel_m_s2, s.gyro_rad_s, s.mag_gauss,
            s.abs_pressure_hpa, s.diff_pressure_hpa, s.pressure_alt_m, s.temperature_c,
            FIELDS_ALL, 0)
        parts.append(data if data is not None else self._pack_fast(
            self._sensor, t, *s.accel_m_s2.tolist(), *s.gyro_rad_s.tolist(),
            *s.mag_gauss.tolist(), s.abs_pressure_hpa, s.diff_pressure_hpa, s.pressure_alt_m,
            s.temperature_c, FIELDS_ALL, 0))
        if self.gps_period_usec and t >= self._next_gps:
            self._next_gps = t + self.gps_period_usec
            vn, ve, vd = (float(x) for x in s.gps_vel_ned_m_s)
            cog = round(math.degrees(math.atan2(ve, vn)) % 360.0 * 100) % 36000
            parts.append(self._pack(c.hil_gps_encode(
                t, 3, round(s.gps_lat_deg * 1e7), round(s.gps_lon_deg * 1e7),
                round(s.gps_alt_m * 1e3), 100, 100, min(65535, round(100 * math.hypot(vn, ve))),
                round(100 * vn), round(100 * ve), round(100 * vd), cog, 12, 0, 0)))
        parts.append(self._state_frame(t, v))
        if t >= self._next_status:
            self._next_status = t + 1_000_000
            parts.append(self._pack(self._status_msg()))
        if t >= self._next_battery:  # the power module, 5 Hz
            self._next_battery = t + 200_000
            parts.append(self._pack(self._battery_msg()))
        return b"".join(parts)

    def _state_frame(self, t: int, v: Vehicle) -> bytes:
        """HIL_STATE_QUATERNION of the vehicle's state at ``t`` (one compiled call; the state
        copied for :meth:`again`), else through :class:`HilStateEncoder` (same bytes)."""
        x = v.x.copy() if self._resign else v.x
        data = self._pack_compiled(self._packers.state_frame, t, x, float(v.fm[6]))
        if data is not None:
            return data
        hs = self._encode(t, v.x, float(v.fm[6]))  # = encode_hil_state, bit for bit
        return self._pack_fast(
            self._state, hs.time_usec, *hs.attitude_quaternion, hs.rollspeed, hs.pitchspeed,
            hs.yawspeed, hs.lat, hs.lon, hs.alt, hs.vx, hs.vy, hs.vz, hs.ind_airspeed,
            hs.true_airspeed, hs.xacc, hs.yacc, hs.zacc)

    def _battery_msg(self) -> Any:
        """BATTERY_STATUS of the power module: cell voltages (mV), current (cA), consumed
        (mAh); no charge estimate (-1): the autopilot makes its own."""
        b = self.battery
        cells = [min(65534, round(1000 * b.voltage_v / b.spec.cells))] * b.spec.cells
        cells += [65535] * (10 - len(cells))
        return self.codec.battery_status_encode(
            0, 1, 3, 32767, cells, round(100 * b.current_a), round(b.consumed_mah), -1, -1)

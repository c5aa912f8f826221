"""The autopilot's MAVLink endpoint for ground stations and API clients (PX4 conventions).

One :class:`GcsEndpoint` serves any number of links at once (PX4's defaults: UDP client of
127.0.0.1:14550 for ground stations and 127.0.0.1:14540 for API clients, plus any UDP or
zenoh link). It is system 1, component 1 (MAV_COMP_ID_AUTOPILOT1) and does what
``DESIGN.md`` lists:

- HEARTBEAT at 1 Hz: type MAV_TYPE_VTOL_FIXEDROTOR (22, PX4's standard VTOL: separate lift
  and cruise propulsion), autopilot MAV_AUTOPILOT_PX4 (12), PX4 custom mode
  ``main << 16 | sub << 24`` (flight modes: IDLE = AUTO.READY, TAKEOFF = AUTO.TAKEOFF,
  HOVER / transitions / FIXED_WING = AUTO.LOITER, LAND = AUTO.LAND), armed bit 128 in
  base_mode, system_status STANDBY / ACTIVE.
- Streams (default rates in :data:`DEFAULT_RATES_HZ`, on simulated time; SET_MESSAGE_INTERVAL
  changes them for every link): ATTITUDE, ATTITUDE_QUATERNION, LOCAL_POSITION_NED,
  GLOBAL_POSITION_INT, HOME_POSITION, VFR_HUD, SYS_STATUS (present / enabled / healthy bits for
  gyro, accel, mag, baro, differential pressure, GPS, AHRS, motor outputs and pre-arm check),
  EXTENDED_SYS_STATE (vtol_state and landed_state never UNDEFINED: MC / ON_GROUND until the
  autopilot says otherwise), ACTUATOR_OUTPUT_STATUS (the 15 commands), HIL_STATE_QUATERNION
  (the navigation input), FAULT_INJECTION_STATUS (relayed from the vehicle), STATUSTEXT (mode
  changes, refusals, the autopilot's events). HEARTBEAT, SYS_STATUS and EXTENDED_SYS_STATE also
  go out on the wall clock (1 Hz) while simulated time stands still (no vehicle, or held).
- REQUEST_MESSAGE (512) for AUTOPILOT_VERSION, HOME_POSITION and every streamed message;
  REQUEST_AUTOPILOT_CAPABILITIES (520).
- PARAM protocol: PARAM_REQUEST_LIST, PARAM_REQUEST_READ (by name or index), PARAM_SET with
  the PARAM_VALUE echo on every link; INT32 values travel bytewise in the float (PX4,
  MAV_PROTOCOL_CAPABILITY_PARAM_ENCODE_BYTEWISE). A refused PARAM_SET is echoed with the value
  kept and explained in a STATUSTEXT.
- Every COMMAND_LONG addressed to (1, 1) or broadcast gets one COMMAND_ACK from (1, 1) on the
  link it came from, as soon as the main loop sees it (well under 0.5 s): flight commands
  (400, 22, 176, 3000, 21) go to :meth:`AutopilotAPI.command`; INJECT_FAILURE (420) and
  MAV_CMD_INJECT_PARTIAL_LOSS (59900) are DENIED unless SYS_FAILURE_EN == 1, checked against
  the airframe's actuators (bad unit UNSUPPORTED, bad instance or loss DENIED, no vehicle
  TEMPORARILY_REJECTED), then forwarded to the vehicle over the HIL link (never to the
  controller) and ACCEPTED; anything else UNSUPPORTED. NaN params mean default.
- MAVLink 2 signing: with a key, outgoing frames are signed, unsigned frames are accepted for
  telemetry and parameters, but arming and fault injection need a verified signature (else
  DENIED with a STATUSTEXT).
- Simulation hold (lockstep only, a vtol-ftc extension for exactly timed scripted runs): the
  INT32 parameter ``SIM_HOLD_MS`` (-1 = off) makes the autopilot wait before the control step
  at simulated time >= SIM_HOLD_MS ms; it then sends NAMED_VALUE_INT ``SIM_HOLD`` (value = the
  hold time in ms) and keeps serving commands and parameters until SIM_HOLD_MS is moved past
  the current time (or set to -1). Commands handled while held act at exactly that step.

Receiving happens in one thread per link (into a queue); everything else (handling, the
autopilot, sending) happens in the caller's thread through :meth:`poll`, :meth:`on_step` and
:meth:`tick`, so the autopilot is never touched from two threads.
"""

from __future__ import annotations

import math
import queue
import threading
import time
from collections.abc import Callable, Sequence
from typing import Any

import numpy as np

from vtolftc.firmware_sim.autopilot.hil_bridge import HilBridge
from vtolftc.firmware_sim.autopilot.interface import (
    AutopilotAPI,
    AutopilotStatus,
    CommandResult,
    FlightMode,
    LandedState,
    NavState,
    ParamError,
    ParamType,
    VtolState,
)
from vtolftc.firmware_sim.autopilot.modes import px4_custom_mode
from vtolftc.protocols.failure_units import FAILURE_UNIT_MOTOR, FAILURE_UNIT_SERVO, ActuatorTable
from vtolftc.protocols.link import Link
from vtolftc.protocols.px4 import (
    MAV_MODE_FLAG_CUSTOM_MODE_ENABLED,
    MAV_MODE_FLAG_SAFETY_ARMED,
    decode_param_value,
    encode_param_value,
)
from vtolftc.rotation import quat_to_euler

__all__ = ["DEFAULT_RATES_HZ", "GcsEndpoint", "px4_mode_of"]

MAV_TYPE_VTOL_FIXEDROTOR = 22
MAV_AUTOPILOT_PX4 = 12
MAV_STATE_STANDBY, MAV_STATE_ACTIVE = 3, 4
MAV_MODE_FLAG_AUTO = 4 | 8 | 16  # AUTO_ENABLED | GUIDED_ENABLED | STABILIZE_ENABLED
SEVERITY_WARNING, SEVERITY_NOTICE, SEVERITY_INFO = 4, 5, 6

CMD_NAV_LAND, CMD_NAV_TAKEOFF, CMD_DO_SET_MODE = 21, 22, 176
CMD_ARM_DISARM, CMD_INJECT_FAILURE, CMD_DO_VTOL_TRANSITION = 400, 420, 3000
CMD_SET_MESSAGE_INTERVAL, CMD_REQUEST_MESSAGE = 511, 512
CMD_REQUEST_AUTOPILOT_CAPABILITIES = 520
CMD_INJECT_PARTIAL_LOSS = 59900
FLIGHT_COMMANDS = (CMD_ARM_DISARM, CMD_NAV_TAKEOFF, CMD_DO_SET_MODE, CMD_DO_VTOL_TRANSITION,
                   CMD_NAV_LAND)
FAULT_COMMANDS = (CMD_INJECT_FAILURE, CMD_INJECT_PARTIAL_LOSS)
SIGNED_COMMANDS = (CMD_ARM_DISARM, *FAULT_COMMANDS)

MSG = {"HEARTBEAT": 0, "SYS_STATUS": 1, "ATTITUDE": 30, "ATTITUDE_QUATERNION": 31,
       "LOCAL_POSITION_NED": 32, "GLOBAL_POSITION_INT": 33, "VFR_HUD": 74,
       "HIL_STATE_QUATERNION": 115, "AUTOPILOT_VERSION": 148, "HOME_POSITION": 242,
       "EXTENDED_SYS_STATE": 245, "ACTUATOR_OUTPUT_STATUS": 375,
       "FAULT_INJECTION_STATUS": 59900}
DEFAULT_RATES_HZ: dict[int, float] = {
    MSG["HEARTBEAT"]: 1.0, MSG["SYS_STATUS"]: 1.0, MSG["ATTITUDE"]: 10.0,
    MSG["ATTITUDE_QUATERNION"]: 10.0, MSG["LOCAL_POSITION_NED"]: 10.0,
    MSG["GLOBAL_POSITION_INT"]: 5.0, MSG["VFR_HUD"]: 4.0, MSG["HIL_STATE_QUATERNION"]: 10.0,
    MSG["HOME_POSITION"]: 0.2, MSG["EXTENDED_SYS_STATE"]: 2.0,
    MSG["ACTUATOR_OUTPUT_STATUS"]: 10.0, MSG["FAULT_INJECTION_STATUS"]: 1.0,
}
"""Stream rates in Hz of simulated time (PX4-like, a little lower to spare the CPU)."""

# SYS_STATUS sensor bits (MAV_SYS_STATUS_SENSOR)
_GYRO, _ACCEL, _MAG, _BARO, _DIFF, _GPS = 1, 2, 4, 8, 16, 32
_ANGULAR_RATE_CTRL, _ATTITUDE_CTRL, _MOTOR_OUTPUTS = 1024, 2048, 32768
_AHRS, _PREARM = 0x200000, 0x10000000
_SENSORS_PRESENT = (_GYRO | _ACCEL | _MAG | _BARO | _DIFF | _GPS | _ANGULAR_RATE_CTRL
                    | _ATTITUDE_CTRL | _MOTOR_OUTPUTS | _AHRS | _PREARM)

SIM_HOLD_PARAM = "SIM_HOLD_MS"


def px4_mode_of(mode: FlightMode) -> tuple[int, int]:
    """PX4 (main, sub) custom mode reported for a flight mode (see
    :func:`vtolftc.firmware_sim.autopilot.modes.px4_custom_mode`)."""
    cm = px4_custom_mode(FlightMode(mode))
    return (cm >> 16) & 0xFF, (cm >> 24) & 0xFF


def _text(s: Any) -> str:
    if isinstance(s, bytes | bytearray):
        s = s.decode(errors="replace")
    return str(s).rstrip("\x00")


class GcsEndpoint:
    """Ground-station side of the autopilot (see the module docstring).

    Args:
        autopilot: the :class:`AutopilotAPI` (its ``params`` store gets ``SIM_HOLD_MS``).
        hil: the HIL bridge (fault commands are forwarded through it).
        links: ground-station links (owned: closed by :meth:`close`).
        actuators: numbering of motors and servos (from the airframe).
        signing_required: arming and fault injection need a verified MAVLink 2 signature.
        lockstep: enables the simulation hold.
        on_event: ``f(kind, text)`` for run logs ("command", "ack", "mode", "fault", ...).
    """

    def __init__(self, autopilot: AutopilotAPI, hil: HilBridge, links: Sequence[Link], *,
                 actuators: ActuatorTable, signing_required: bool = False,
                 lockstep: bool = True, hold_ms: int = -1,
                 on_event: Callable[[str, str], None] | None = None,
                 version: tuple[int, int, int] = (0, 1, 0)) -> None:
        self.ap = autopilot
        self.hil = hil
        self.links = list(links)
        self.actuators = actuators
        self.signing_required = signing_required
        self.lockstep = lockstep
        self.on_event = on_event or (lambda kind, text: None)
        self.version = version
        params = autopilot.params
        if SIM_HOLD_PARAM not in params:
            params.register(SIM_HOLD_PARAM, -1, ParamType.INT32, -1, 2**31 - 1,
                            "lockstep only: hold the simulation before the control step at "
                            "this simulated time in ms (-1 = off)")
        params.set(SIM_HOLD_PARAM, int(hold_ms))
        self.rates_hz = dict(DEFAULT_RATES_HZ)
        self._statustext_id = 0
        self._next_due: dict[int, int] = {}
        self._earliest_due = 0
        self._queue: queue.SimpleQueue[tuple[int, Any]] = queue.SimpleQueue()
        self._closed = False
        self.nav: NavState | None = None
        self.status: AutopilotStatus | None = None
        self.commands = np.zeros(15)
        self.sim_usec = 0
        self._last_mode: FlightMode | None = None
        self._last_message = ""
        self._wall_next = 0.0
        self._last_step_wall = -math.inf
        self.held_at_ms: int | None = None
        self._hold_announce_wall = 0.0
        self._last_fault_status: Any = None
        self.commands_answered = 0
        self._threads = [threading.Thread(target=self._rx, args=(i, link), daemon=True,
                                          name=f"gcs-rx-{i}")
                         for i, link in enumerate(self.links)]
        for th in self._threads:
            th.start()
        self.refresh_status()

    # ------------------------------------------------------------------ threads
    def _rx(self, index: int, link: Link) -> None:
        while not self._closed:
            try:
                msgs = link.recv(0.25)
            except Exception:
                if self._closed:
                    return
                time.sleep(0.05)
                continue
            for m in msgs:
                self._queue.put((index, m))

    def close(self) -> None:
        """Stop the receivers and close every link. Idempotent."""
        if self._closed:
            return
        self._closed = True
        for link in self.links:
            link.close()
        for th in self._threads:
            th.join(timeout=1.0)

    def link_stats(self) -> list[dict[str, Any]]:
        """Counters of every ground-station link (garbage, CRC, truncated ... drops)."""
        return [{"link": repr(link), **link.stats.as_dict()} for link in self.links]

    # ------------------------------------------------------------------ sending
    def _send_all(self, msg: Any) -> None:
        for link in self.links:
            link.send(msg)

    def statustext(self, text: str, severity: int = SEVERITY_INFO,
                   link: Link | None = None) -> None:
        """STATUSTEXT to one link or to all. A text longer than the field's 50 bytes goes out
        in chunks as MAVLink 2 specifies: one ``id`` (1..65535) for all of them, ``chunk_seq``
        0, 1, ..., the last chunk shorter than 50 bytes (an empty one if needed)."""
        codec = self.links[0].codec if self.links else None
        if codec is None:
            return
        data = text.encode("utf-8", errors="replace")
        if len(data) <= 50:
            msgs = [codec.statustext_encode(severity, data)]
        else:
            self._statustext_id = self._statustext_id % 65535 + 1
            chunks = [data[i:i + 50] for i in range(0, len(data), 50)][:255]
            if len(chunks[-1]) == 50:
                chunks.append(b"")
            msgs = [codec.statustext_encode(severity, c, self._statustext_id, k)
                    for k, c in enumerate(chunks)]
        for msg in msgs:
            if link is None:
                self._send_all(msg)
            else:
                link.send(msg)

    @property
    def time_boot_ms(self) -> int:
        return self.sim_usec // 1000

    # ------------------------------------------------------------------ status
    def refresh_status(self) -> None:
        """Read the autopilot's status; STATUSTEXT on mode changes and new messages."""
        self._observe(self.ap.status())

    def _observe(self, st: AutopilotStatus) -> None:
        self.status = st
        new_message = bool(st.message) and st.message != self._last_message
        if self._last_mode is not None and st.mode != self._last_mode:
            text = f"mode {self._last_mode.name} -> {FlightMode(st.mode).name}"
            self.on_event("mode", text)
            if not new_message:  # the autopilot's own message usually says it already
                self.statustext(text, SEVERITY_INFO)
        self._last_mode = FlightMode(st.mode)
        if new_message:
            self.statustext(st.message, SEVERITY_NOTICE)
            self.on_event("autopilot", st.message)
        self._last_message = st.message

    def hold_usec(self) -> int | None:
        """Simulated time at which to hold, None if no hold (or not lockstep)."""
        if not self.lockstep:
            return None
        v = int(self.ap.params.get(SIM_HOLD_PARAM))
        return None if v < 0 else v * 1000

    def announce_hold(self, time_usec: int) -> None:
        """Tell the ground stations the simulation is held at ``time_usec`` (repeat at 1 Hz)."""
        ms = time_usec // 1000
        now = time.monotonic()
        if self.held_at_ms != ms or now >= self._hold_announce_wall:
            self.held_at_ms = ms
            self._hold_announce_wall = now + 1.0
            if self.links:
                self._send_all(self.links[0].codec.named_value_int_encode(ms, b"SIM_HOLD", ms))

    # ------------------------------------------------------------------ main-thread entry points
    def poll(self) -> int:
        """Handle every queued message from the ground stations; returns how many."""
        n = 0
        while True:
            try:
                index, msg = self._queue.get_nowait()
            except queue.Empty:
                return n
            n += 1
            try:
                self._handle(self.links[index], msg)
            except Exception as exc:  # one bad message must not stop the autopilot
                self.statustext(f"error handling {msg.get_type()}: {exc}",
                                SEVERITY_WARNING)

    def has_pending(self) -> bool:
        return not self._queue.empty()

    def on_step(self, nav: NavState, status: AutopilotStatus) -> None:
        """After a control step: remember it and the status, send the streams due."""
        self.nav = nav
        self.commands = np.asarray(status.actuator_commands, dtype=float)
        self.sim_usec = int(nav.time_usec)
        self._last_step_wall = time.monotonic()
        self.held_at_ms = None
        self._observe(status)
        fs = self.hil.fault_status
        if fs is not None and fs is not self._last_fault_status:
            self._last_fault_status = fs
            self._send_stream(MSG["FAULT_INJECTION_STATUS"])
            self._next_due[MSG["FAULT_INJECTION_STATUS"]] = self.sim_usec + 1_000_000
            self._earliest_due = 0
        if self.sim_usec < self._earliest_due:
            return
        earliest = 2**63
        for msg_id, hz in self.rates_hz.items():
            if hz <= 0:
                continue
            due = self._next_due.get(msg_id, 0)
            if self.sim_usec >= due:
                due = max(due + round(1e6 / hz), self.sim_usec)
                self._next_due[msg_id] = due
                self._send_stream(msg_id)
            earliest = min(earliest, due)
        self._earliest_due = earliest

    def tick(self) -> None:
        """Wall-clock duties: 1 Hz HEARTBEAT, SYS_STATUS, EXTENDED_SYS_STATE while simulated
        time does not advance."""
        now = time.monotonic()
        if now >= self._wall_next and now - self._last_step_wall > 0.5:
            self._wall_next = now + 1.0
            self.refresh_status()
            for name in ("HEARTBEAT", "SYS_STATUS", "EXTENDED_SYS_STATE"):
                self._send_stream(MSG[name])

    # ------------------------------------------------------------------ streams
    def _send_stream(self, msg_id: int, link: Link | None = None) -> bool:
        msg = self._build(msg_id)
        if msg is None:
            return False
        if link is None:
            self._send_all(msg)
        else:
            link.send(msg)
        return True

    def _build(self, msg_id: int) -> Any:
        if not self.links:
            return None
        c = self.links[0].codec
        st = self.status
        nav = self.nav
        ms = self.time_boot_ms
        if msg_id == MSG["HEARTBEAT"]:
            armed = bool(st and st.armed)
            base = MAV_MODE_FLAG_CUSTOM_MODE_ENABLED | MAV_MODE_FLAG_AUTO | (
                MAV_MODE_FLAG_SAFETY_ARMED if armed else 0)
            return c.heartbeat_encode(MAV_TYPE_VTOL_FIXEDROTOR, MAV_AUTOPILOT_PX4, base,
                                      px4_custom_mode(st.mode if st else FlightMode.IDLE),
                                      MAV_STATE_ACTIVE if armed else MAV_STATE_STANDBY)
        if msg_id == MSG["SYS_STATUS"]:
            healthy = _ANGULAR_RATE_CTRL | _ATTITUDE_CTRL | _MOTOR_OUTPUTS
            if self.hil.connected and self.hil.last_sensor is not None:
                healthy |= _GYRO | _ACCEL | _MAG | _BARO | _DIFF | _AHRS
            gps = self.hil.last_gps
            if self.hil.connected and gps is not None and gps.fix_type >= 3:
                healthy |= _GPS
            if self.hil.connected and self.hil.home is not None and nav is not None:
                healthy |= _PREARM
            # no battery: voltage UINT16_MAX, current and remaining -1 ("not sent")
            return c.sys_status_encode(_SENSORS_PRESENT, _SENSORS_PRESENT, healthy, 0, 65535,
                                       -1, -1, 0, 0, 0, 0, 0, 0)
        if msg_id == MSG["EXTENDED_SYS_STATE"]:
            vtol = int(st.vtol_state) if st else 0
            landed = int(st.landed_state) if st else 0
            return c.extended_sys_state_encode(vtol or int(VtolState.MC),
                                               landed or int(LandedState.ON_GROUND))
        if msg_id == MSG["AUTOPILOT_VERSION"]:
            major, minor, patch = self.version
            sw = (major << 24) | (minor << 16) | (patch << 8) | 255
            caps = (1 << 0) | (1 << 2) | (1 << 3) | (1 << 8) | (1 << 15) | (1 << 17)
            # MISSION_FLOAT | PARAM_FLOAT | MISSION_INT | COMMAND_INT | MAVLINK2 |
            # PARAM_ENCODE_BYTEWISE
            return c.autopilot_version_encode(caps, sw, sw, 0, 0, [0] * 8, [0] * 8, [0] * 8,
                                              0, 0, 1)
        if msg_id == MSG["HOME_POSITION"]:
            if self.hil.home is None:
                return None
            lat, lon, alt = self.hil.home
            return c.home_position_encode(round(lat * 1e7), round(lon * 1e7), round(alt * 1e3),
                                          0.0, 0.0, 0.0, [1.0, 0.0, 0.0, 0.0], 0.0, 0.0, 0.0,
                                          self.sim_usec)
        if msg_id == MSG["FAULT_INJECTION_STATUS"]:
            fs = self.hil.fault_status
            if fs is None:
                return None
            return c.fault_injection_status_encode(
                fs.time_usec, fs.change_count, fs.motor_count, fs.servo_count,
                fs.motor_failure, fs.motor_loss, fs.servo_failure, fs.servo_loss)
        if msg_id == MSG["ACTUATOR_OUTPUT_STATUS"]:
            out = [0.0] * 32
            out[: self.commands.size] = [float(x) for x in self.commands]
            return c.actuator_output_status_encode(self.sim_usec, self.commands.size, out)
        if nav is None:
            return None
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
        hs = self.hil.last_state
        if msg_id == MSG["HIL_STATE_QUATERNION"]:
            if hs is None:
                return None
            return c.hil_state_quaternion_encode(
                hs.time_usec, hs.attitude_quaternion, hs.rollspeed, hs.pitchspeed, hs.yawspeed,
                hs.lat, hs.lon, hs.alt, hs.vx, hs.vy, hs.vz, hs.ind_airspeed, hs.true_airspeed,
                hs.xacc, hs.yacc, hs.zacc)
        home_alt = self.hil.home[2] if self.hil.home else 0.0
        hdg = math.degrees(yaw) % 360.0
        if msg_id == MSG["GLOBAL_POSITION_INT"]:
            lat = hs.lat if hs is not None else 0
            lon = hs.lon if hs is not None else 0
            return c.global_position_int_encode(
                ms, lat, lon, round((home_alt - p[2]) * 1e3), round(-p[2] * 1e3),
                round(v[0] * 100), round(v[1] * 100), round(v[2] * 100),
                round(hdg * 100) % 36000)
        if msg_id == MSG["VFR_HUD"]:
            n_motors = len(self.actuators.motors)
            thr = float(np.clip(np.mean(self.commands[:n_motors]), 0, 1)) if n_motors else 0.0
            return c.vfr_hud_encode(nav.airspeed_m_s, math.hypot(v[0], v[1]), round(hdg) % 360,
                                    round(thr * 100), home_alt - p[2], -v[2])
        return None

    # ------------------------------------------------------------------ receiving
    def _handle(self, link: Link, msg: Any) -> None:
        t = msg.get_type()
        if t == "COMMAND_LONG":
            if msg.target_system not in (0, 1) or msg.target_component not in (0, 1):
                return
            result, reason = self._command(link, msg)
            if reason:
                self.statustext(reason, SEVERITY_WARNING if result else SEVERITY_INFO,
                                link)
            link.send(link.codec.command_ack_encode(
                int(msg.command), int(result), 0, 0, msg.get_srcSystem(),
                msg.get_srcComponent()))
            self.commands_answered += 1
            self.on_event("ack", f"{_cmd_label(msg.command)} -> {CommandResult(result).name}"
                          + (f" ({reason})" if reason else ""))
        elif t == "PARAM_REQUEST_LIST":
            if msg.target_system in (0, 1):
                for i in range(len(self.ap.params)):
                    self._param_value(i, link)
        elif t == "PARAM_REQUEST_READ":
            if msg.target_system in (0, 1):
                self._param_read(link, msg)
        elif t == "PARAM_SET" and msg.target_system in (0, 1):
            self._param_set(link, msg)

    def _command(self, link: Link, msg: Any) -> tuple[int, str]:
        cmd = int(msg.command)
        params = [msg.param1, msg.param2, msg.param3, msg.param4, msg.param5, msg.param6,
                  msg.param7]
        if self.signing_required and cmd in SIGNED_COMMANDS and not msg.get_signed():
            return CommandResult.DENIED, "signed command required"
        if cmd in FLIGHT_COMMANDS:
            before = self.ap.status().message
            res = CommandResult(self.ap.command(cmd, params))
            self.refresh_status()
            after = self.status.message if self.status else ""
            reason = after if (res != CommandResult.ACCEPTED and after and after != before) \
                else ""
            if res != CommandResult.ACCEPTED and not reason:
                reason = _default_reason(cmd, res, self.status)
            self.on_event("command", f"{_cmd_label(cmd)} {_fmt_params(params)}")
            self._last_message = after  # already reported with the ACK
            return res, reason
        if cmd in FAULT_COMMANDS:
            res, reason = self._fault(msg, params)
            if res == CommandResult.ACCEPTED:
                self.hil.forward_command(msg)
                self.on_event("fault", f"{_cmd_label(cmd)} {_fmt_params(params)}")
            return res, reason
        if cmd == CMD_SET_MESSAGE_INTERVAL:
            mid, interval = params[0], params[1]
            if not math.isfinite(mid) or int(mid) not in self.rates_hz:
                return CommandResult.DENIED, f"cannot stream message {mid:g}"
            mid = int(mid)
            if not math.isfinite(interval) or interval == 0:
                self.rates_hz[mid] = DEFAULT_RATES_HZ[mid]
            elif interval < 0:
                self.rates_hz[mid] = 0.0
            else:
                self.rates_hz[mid] = min(250.0, 1e6 / interval)
            self._next_due[mid] = self.sim_usec
            self._earliest_due = 0
            return CommandResult.ACCEPTED, ""
        if cmd == CMD_REQUEST_MESSAGE:
            mid = params[0]
            if not math.isfinite(mid) or int(mid) not in MSG.values():
                return CommandResult.UNSUPPORTED, ""
            if not self._send_stream(int(mid), link):
                return CommandResult.TEMPORARILY_REJECTED, "no data yet"
            return CommandResult.ACCEPTED, ""
        if cmd == CMD_REQUEST_AUTOPILOT_CAPABILITIES:
            self._send_stream(MSG["AUTOPILOT_VERSION"], link)
            return CommandResult.ACCEPTED, ""
        return CommandResult.UNSUPPORTED, ""

    def _fault(self, msg: Any, p: list[float]) -> tuple[int, str]:
        if int(self.ap.params.get("SYS_FAILURE_EN")) != 1:
            return CommandResult.DENIED, "fault injection disabled: set SYS_FAILURE_EN to 1"
        unit = p[0]
        if not math.isfinite(unit) or int(unit) not in (FAILURE_UNIT_MOTOR, FAILURE_UNIT_SERVO):
            return CommandResult.UNSUPPORTED, "unit must be motor 101 or servo 102"
        names = self.actuators.motors if int(unit) == FAILURE_UNIT_MOTOR \
            else self.actuators.servos
        if int(msg.command) == CMD_INJECT_FAILURE:
            ftype, inst = p[1], p[2]
            if not math.isfinite(ftype) or int(ftype) not in (0, 1, 2):
                return CommandResult.UNSUPPORTED, "failure types: OK, OFF, STUCK"
        else:
            inst, loss = p[1], p[2]
            if not (math.isfinite(loss) and 0.0 <= loss <= 1.0):
                return CommandResult.DENIED, "loss must be in [0, 1]"
        if not (math.isfinite(inst) and inst == int(inst) and 0 <= inst <= len(names)):
            return CommandResult.DENIED, f"instance must be 0..{len(names)}"
        if not self.hil.connected:
            return CommandResult.TEMPORARILY_REJECTED, "no vehicle on the HIL link"
        return CommandResult.ACCEPTED, ""

    # ------------------------------------------------------------------ parameters
    def _param_value(self, index: int, link: Link | None) -> None:
        store = self.ap.params
        prm = store.by_index(index)
        codec = (link or self.links[0]).codec
        msg = codec.param_value_encode(prm.name.encode(), encode_param_value(prm.value, prm.type),
                                       int(prm.type), len(store), index)
        if link is None:
            self._send_all(msg)
        else:
            link.send(msg)

    def _param_read(self, link: Link, msg: Any) -> None:
        store = self.ap.params
        try:
            index = int(msg.param_index) if msg.param_index >= 0 \
                else store.index(_text(msg.param_id))
            self._param_value(index, link)
        except ParamError:
            return  # unknown parameter: no answer (MAVLink parameter protocol)

    def _param_set(self, link: Link, msg: Any) -> None:
        store = self.ap.params
        name = _text(msg.param_id)
        if name not in store:
            self.statustext(f"unknown parameter {name}", SEVERITY_WARNING, link)
            return
        index = store.index(name)
        prm = store.by_index(index)
        value = decode_param_value(msg.param_value, prm.type)
        try:
            store.set(name, value)
            self.on_event("param", f"{name} = {value:g}")
        except ParamError as exc:
            self.statustext(str(exc), SEVERITY_WARNING, link)
        self._param_value(index, None)  # echo on every link, as PX4 does


def _cmd_label(cmd: int) -> str:
    names = {CMD_ARM_DISARM: "ARM_DISARM", CMD_NAV_TAKEOFF: "TAKEOFF",
             CMD_DO_SET_MODE: "SET_MODE", CMD_DO_VTOL_TRANSITION: "VTOL_TRANSITION",
             CMD_NAV_LAND: "LAND", CMD_INJECT_FAILURE: "INJECT_FAILURE",
             CMD_INJECT_PARTIAL_LOSS: "INJECT_PARTIAL_LOSS",
             CMD_SET_MESSAGE_INTERVAL: "SET_MESSAGE_INTERVAL",
             CMD_REQUEST_MESSAGE: "REQUEST_MESSAGE"}
    return names.get(int(cmd), f"CMD {int(cmd)}")


def _fmt_params(p: Sequence[float]) -> str:
    return "(" + ", ".join("nan" if math.isnan(x) else f"{x:g}" for x in p) + ")"


def _default_reason(cmd: int, res: CommandResult, st: AutopilotStatus | None) -> str:
    if res == CommandResult.UNSUPPORTED:
        return "not supported"
    if st is not None and not st.armed and cmd in (CMD_NAV_TAKEOFF, CMD_DO_VTOL_TRANSITION):
        return "vehicle is disarmed"
    if st is not None:
        return f"refused in mode {FlightMode(st.mode).name}"
    return "refused"

"""The autopilot's MAVLink endpoint for ground stations and API clients (PX4 conventions).

One :class:`GcsEndpoint` serves any number of links at once (PX4's defaults: UDP client of
127.0.0.1:14550 for ground stations and 127.0.0.1:14540 for API clients, plus any UDP or
zenoh link). It is system 1, component 1 (MAV_COMP_ID_AUTOPILOT1) and does what
``DESIGN.md`` lists:

- HEARTBEAT at 1 Hz: type MAV_TYPE_VTOL_FIXEDROTOR (22, PX4's standard VTOL: separate lift
  and cruise propulsion), autopilot MAV_AUTOPILOT_PX4 (12), PX4 custom mode
  ``main << 16 | sub << 24`` as the navigator reports it (AUTO.LOITER = Hold on the ground and
  in hover, AUTO.TAKEOFF, AUTO.LAND, AUTO.MISSION, AUTO.RTL, POSCTL for fixed-wing course
  hold after a commanded transition; :meth:`.navigator.Navigator.custom_mode`), armed bit 128
  in base_mode, system_status STANDBY / ACTIVE. Missions, COMMAND_INT, TIMESYNC, PING,
  BATTERY_STATUS, GPS_RAW_INT and the geofence bits: :mod:`.gcs_services`.
- Streams (default rates in :data:`DEFAULT_RATES_HZ`, on simulated time; SET_MESSAGE_INTERVAL
  changes them for the link it came on only): ATTITUDE, ATTITUDE_QUATERNION, LOCAL_POSITION_NED,
  GLOBAL_POSITION_INT, HOME_POSITION, VFR_HUD, SYS_STATUS (present / enabled / healthy bits for
  gyro, accel, mag, baro, differential pressure, GPS, AHRS, motor outputs and pre-arm check),
  EXTENDED_SYS_STATE (vtol_state and landed_state never UNDEFINED: MC / ON_GROUND until the
  autopilot says otherwise), ACTUATOR_OUTPUT_STATUS (the 15 commands), HIL_STATE_QUATERNION
  (the navigation input), FAULT_INJECTION_STATUS (relayed from the vehicle), STATUSTEXT (mode
  changes, refusals, the autopilot's events). HEARTBEAT, SYS_STATUS and EXTENDED_SYS_STATE also
  go out on the wall clock (1 Hz) while simulated time stands still (no vehicle, or held).
- ODOMETRY, ALTITUDE, WIND_COV, HIGHRES_IMU, SCALED_IMU, SYSTEM_TIME and FLIGHT_INFORMATION
  (on request) with PX4's field semantics: :mod:`.gcs_telemetry`.
- GET_MESSAGE_INTERVAL (510): MESSAGE_INTERVAL of that link.
- REQUEST_MESSAGE (512) for AUTOPILOT_VERSION, HOME_POSITION and every streamed message;
  REQUEST_AUTOPILOT_CAPABILITIES (520), GET_HOME_POSITION (410) and
  REQUEST_FLIGHT_INFORMATION (528) as PX4 answers them (REQUEST_MESSAGE of AUTOPILOT_VERSION,
  HOME_POSITION, FLIGHT_INFORMATION).
- PARAM protocol: PARAM_REQUEST_LIST, PARAM_REQUEST_READ (by name or index), PARAM_SET with
  the PARAM_VALUE echo on every link; INT32 values travel bytewise in the float (PX4,
  MAV_PROTOCOL_CAPABILITY_PARAM_ENCODE_BYTEWISE). A refused PARAM_SET is echoed with the value
  kept and explained in a STATUSTEXT.
- Every COMMAND_LONG (and COMMAND_INT: params 1-4, x, y, z) addressed to (1, 1) or broadcast
  and not dropped by a rate limit gets one COMMAND_ACK from (1, 1) on the link it came from,
  well under 0.5 s (TEMPORARILY_REJECTED if the control thread's queue was full): flight commands
  (400, 22, 176, 3000, 21) go to :meth:`AutopilotAPI.command`; INJECT_FAILURE (420) and
  MAV_CMD_INJECT_PARTIAL_LOSS (59900) are DENIED unless SYS_FAILURE_EN == 1, checked against
  the airframe's actuators (bad unit UNSUPPORTED, bad instance or loss DENIED, no vehicle
  TEMPORARILY_REJECTED), then forwarded to the vehicle over the HIL link (never to the
  controller) and ACCEPTED; anything else UNSUPPORTED. NaN params mean default.
- MAVLink 2 signing: with a key, outgoing frames are signed, and every incoming frame must
  carry a valid signature except those in :data:`UNSIGNED_ALLOWED` (HEARTBEAT, RADIO_STATUS,
  PARAM_REQUEST_LIST, PARAM_REQUEST_READ: liveness and read-only requests, as ArduPilot keeps
  RADIO_STATUS); the links drop everything else unsigned or badly signed (counted as
  ``dropped_signature``), so every COMMAND_LONG / COMMAND_INT, PARAM_SET,
  SET_MESSAGE_INTERVAL and mission message needs the key. All ground-station links share one
  stream-timestamp table (a frame replayed on another link is refused), and the hash is checked
  before a timestamp is stored (:mod:`vtolftc.protocols.mavlink`). With signing on, only signed
  heartbeats count for the data-link-loss failsafe.
- Simulation hold (lockstep only, a vtol-ftc extension for exactly timed scripted runs): the
  INT32 parameter ``SIM_HOLD_MS`` (-1 = off) makes the autopilot wait before the control step
  at simulated time >= SIM_HOLD_MS ms; it then sends NAMED_VALUE_INT ``SIM_HOLD`` (value = the
  hold time in ms) and keeps serving commands and parameters until SIM_HOLD_MS is moved past
  the current time (or set to -1). Commands handled while held act at exactly that step.
- HEARTBEAT system_status: BOOT until the autopilot is warm (:attr:`GcsEndpoint.ready`, every
  compiled path compiled; meanwhile every flight and fault command is answered at once
  TEMPORARILY_REJECTED by the worker, as the control thread is busy compiling), then
  STANDBY (disarmed) / ACTIVE (armed), or CRITICAL / EMERGENCY
  while a failsafe says so (:attr:`GcsEndpoint.mav_state`).

Threads (the control step never waits for a ground station):

- one receiver per link parses frames (bad ones dropped and counted by the link; the process
  opens the links with a datagram rate limit, so a flood is dropped before it is parsed) into a
  bounded per-link queue; when it is full the oldest message is dropped (counted in
  :meth:`GcsEndpoint.link_stats` as ``queue_dropped``);
- one worker thread handles the queues: at most :attr:`GcsEndpoint.budget_per_cycle` messages
  per cycle (round robin over the links), a token bucket per client (link, system, component;
  ``rate_limit_hz`` sustained, ``rate_burst`` burst; excess dropped, counted as
  ``rate_limited``), one handler per message type (:attr:`GcsEndpoint.handlers`). Everything
  read-only or link-local (parameter reads, REQUEST_MESSAGE, SET_MESSAGE_INTERVAL, refusals of
  unknown commands or invalid parameter values, the streams, the heartbeats) is done there;
- what changes the autopilot (flight and fault commands, a valid PARAM_SET) is handed to the
  control thread through a bounded drop-oldest queue (a dropped request is answered
  TEMPORARILY_REJECTED) and applied by :meth:`GcsEndpoint.poll` at most ``max_items`` per
  control cycle; its answers go back to the worker, which alone sends on the ground-station
  links (one sender per link: sequence numbers and signing timestamps stay consistent).
"""

from __future__ import annotations

import collections
import contextlib
import math
import threading
import time
from collections.abc import Callable, Sequence
from dataclasses import dataclass
from typing import Any

import numpy as np

from vtolftc.firmware_sim.autopilot.gcs_services import (
    STREAM_RATES_HZ,
    Px4Services,
    command_int_params,
)
from vtolftc.firmware_sim.autopilot.gcs_telemetry import (
    TELEMETRY_MSG,
    TELEMETRY_RATES_HZ,
    TelemetryStreams,
)
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
from vtolftc.protocols.generated import constants as mav
from vtolftc.protocols.link import Link
from vtolftc.protocols.px4 import (
    MAV_MODE_FLAG_CUSTOM_MODE_ENABLED,
    MAV_MODE_FLAG_SAFETY_ARMED,
    decode_param_value,
    encode_param_value,
)
from vtolftc.rotation import quat_to_euler

__all__ = ["DEFAULT_RATES_HZ", "UNSIGNED_ALLOWED", "GcsEndpoint", "px4_mode_of"]

# 22: named VTOL_FIXEDROTOR in current MAVLink, still VTOL_RESERVED2 in this dialect's common.xml
MAV_TYPE_VTOL_FIXEDROTOR = mav.MAV_TYPE_VTOL_RESERVED2
MAV_AUTOPILOT_PX4 = mav.MAV_AUTOPILOT_PX4
MAV_TYPE_GCS = mav.MAV_TYPE_GCS
MAV_STATE_BOOT, MAV_STATE_STANDBY, MAV_STATE_ACTIVE = (
    mav.MAV_STATE_BOOT, mav.MAV_STATE_STANDBY, mav.MAV_STATE_ACTIVE)
MAV_STATE_CRITICAL, MAV_STATE_EMERGENCY = mav.MAV_STATE_CRITICAL, mav.MAV_STATE_EMERGENCY
MAV_MODE_FLAG_AUTO = (mav.MAV_MODE_FLAG_AUTO_ENABLED | mav.MAV_MODE_FLAG_GUIDED_ENABLED
                      | mav.MAV_MODE_FLAG_STABILIZE_ENABLED)
SEVERITY_CRITICAL, SEVERITY_WARNING = mav.MAV_SEVERITY_CRITICAL, mav.MAV_SEVERITY_WARNING
SEVERITY_NOTICE, SEVERITY_INFO = mav.MAV_SEVERITY_NOTICE, mav.MAV_SEVERITY_INFO

CMD_NAV_LAND, CMD_NAV_TAKEOFF = mav.MAV_CMD_NAV_LAND, mav.MAV_CMD_NAV_TAKEOFF
CMD_DO_SET_MODE = mav.MAV_CMD_DO_SET_MODE
CMD_ARM_DISARM = mav.MAV_CMD_COMPONENT_ARM_DISARM
CMD_INJECT_FAILURE = mav.MAV_CMD_INJECT_FAILURE
CMD_DO_VTOL_TRANSITION = mav.MAV_CMD_DO_VTOL_TRANSITION
CMD_SET_MESSAGE_INTERVAL = mav.MAV_CMD_SET_MESSAGE_INTERVAL
CMD_GET_MESSAGE_INTERVAL = mav.MAV_CMD_GET_MESSAGE_INTERVAL
CMD_REQUEST_MESSAGE = mav.MAV_CMD_REQUEST_MESSAGE
CMD_REQUEST_AUTOPILOT_CAPABILITIES = mav.MAV_CMD_REQUEST_AUTOPILOT_CAPABILITIES
CMD_GET_HOME_POSITION = mav.MAV_CMD_GET_HOME_POSITION
CMD_REQUEST_FLIGHT_INFORMATION = mav.MAV_CMD_REQUEST_FLIGHT_INFORMATION
CMD_INJECT_PARTIAL_LOSS = mav.MAV_CMD_INJECT_PARTIAL_LOSS
FLIGHT_COMMANDS = (CMD_ARM_DISARM, CMD_NAV_TAKEOFF, CMD_DO_SET_MODE, CMD_DO_VTOL_TRANSITION,
                   CMD_NAV_LAND, mav.MAV_CMD_NAV_RETURN_TO_LAUNCH, mav.MAV_CMD_DO_CHANGE_SPEED,
                   mav.MAV_CMD_DO_REPOSITION, mav.MAV_CMD_DO_SET_MISSION_CURRENT,
                   mav.MAV_CMD_MISSION_START)
# the last five are the navigator's (see navigator.py)
FAULT_COMMANDS = (CMD_INJECT_FAILURE, CMD_INJECT_PARTIAL_LOSS)

UNSIGNED_ALLOWED = frozenset({mav.MAVLINK_MSG_ID_HEARTBEAT, mav.MAVLINK_MSG_ID_RADIO_STATUS,
                              mav.MAVLINK_MSG_ID_PARAM_REQUEST_READ,
                              mav.MAVLINK_MSG_ID_PARAM_REQUEST_LIST})
"""Message ids accepted without a valid signature when signing is on: HEARTBEAT (0),
RADIO_STATUS (109, as ArduPilot), PARAM_REQUEST_READ (20) and PARAM_REQUEST_LIST (21)
(read-only). Everything else, every command, PARAM_SET and mission message included, needs
the key."""

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
MSG.update({name: getattr(mav, "MAVLINK_MSG_ID_" + name)
            for name in ("GPS_RAW_INT", "MISSION_CURRENT", "BATTERY_STATUS")})
MSG.update(TELEMETRY_MSG)
"""Stream rates in Hz of simulated time (PX4-like, a little lower to spare the CPU)."""

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

SIM_HOLD_PARAM = "SIM_HOLD_MS"

#: Commands that ask for one message: REQUEST_MESSAGE (param1 the id) and the older ones PX4
#: still answers the same way (the message they stand for).
_REQUEST_ONE: dict[int, float] = {
    CMD_REQUEST_MESSAGE: math.nan,
    CMD_REQUEST_AUTOPILOT_CAPABILITIES: float(MSG["AUTOPILOT_VERSION"]),
    CMD_GET_HOME_POSITION: float(MSG["HOME_POSITION"]),
    CMD_REQUEST_FLIGHT_INFORMATION: float(TELEMETRY_MSG["FLIGHT_INFORMATION"]),
}


def px4_mode_of(mode: FlightMode) -> tuple[int, int]:
    """PX4 (main, sub) custom mode reported for a flight mode (see
    :func:`vtolftc.firmware_sim.autopilot.modes.px4_custom_mode`)."""
    cm = px4_custom_mode(FlightMode(mode))
    return (cm >> 16) & 0xFF, (cm >> 24) & 0xFF


def _text(s: Any) -> str:
    if isinstance(s, bytes | bytearray):
        s = s.decode(errors="replace")
    return str(s).rstrip("\x00")


@dataclass
class _Client:
    """Token bucket of one ground-station client (link, system, component)."""

    tokens: float
    last: float


class GcsEndpoint:
    """Ground-station side of the autopilot (see the module docstring).

    Parameters
    ----------
    autopilot
        the :class:`AutopilotAPI` (its ``params`` store gets ``SIM_HOLD_MS``).
    hil
        the HIL bridge (fault commands are forwarded through it, by the control thread).
    links
        ground-station links (owned: closed by :meth:`close`).
    actuators
        numbering of motors and servos (from the airframe).
    signing_required
        the links verify signatures (see :data:`UNSIGNED_ALLOWED`); arming
        and fault commands are refused unsigned even if a link lets them through.
    lockstep
        enables the simulation hold.
    on_event
        ``f(kind, text)`` for run logs ("command", "ack", "mode", "fault", ...);
        called from the worker thread and from the control thread, so it must be
        thread-safe (the autopilot process only queues).
    rate_limit_hz, rate_burst
        per-client token bucket (messages per second, burst).
    queue_len
        per-link receive queue (drop-oldest).
    budget_per_cycle
        messages the worker handles per cycle.
    ready
        the autopilot is warm (else BOOT and no arming until :attr:`ready` is set).
    start
        start the threads (tests may drive :meth:`serve_once` by hand).
    """

    def __init__(self, autopilot: AutopilotAPI, hil: HilBridge, links: Sequence[Link], *,
                 actuators: ActuatorTable, signing_required: bool = False,
                 lockstep: bool = True, hold_ms: int = -1,
                 on_event: Callable[[str, str], None] | None = None,
                 version: tuple[int, int, int] = (0, 1, 0), rate_limit_hz: float = 50.0,
                 rate_burst: float = 100.0, queue_len: int = 512,
                 budget_per_cycle: int = 32, control_queue_len: int = 32,
                 ready: bool = True, start: bool = True) -> None:
        self.ap = autopilot
        self.hil = hil
        self.links = list(links)
        self.actuators = actuators
        self.signing_required = signing_required
        self.lockstep = lockstep
        self.on_event = on_event or (lambda kind, text: None)
        self.version = version
        self.rate_limit_hz = float(rate_limit_hz)
        self.rate_burst = float(rate_burst)
        self.budget_per_cycle = int(budget_per_cycle)
        params = autopilot.params
        if SIM_HOLD_PARAM not in params:
            params.register(SIM_HOLD_PARAM, -1, ParamType.INT32, -1, 2**31 - 1,
                            "lockstep only: hold the simulation before the control step at "
                            "this simulated time in ms (-1 = off)")
        params.set(SIM_HOLD_PARAM, int(hold_ms))
        n = len(self.links)
        self.rates_hz: list[dict[int, float]] = [dict(DEFAULT_RATES_HZ) for _ in range(n)]
        """Stream rates of each link (SET_MESSAGE_INTERVAL changes its own link only)."""
        self._next_due: list[dict[int, int]] = [{} for _ in range(n)]
        self._earliest_due = [0] * n
        self._statustext_id = 0
        self._inq: list[collections.deque[Any]] = [collections.deque(maxlen=queue_len)
                                                   for _ in range(n)]
        self._counters = [{"queue_dropped": 0, "rate_limited": 0, "handled": 0,
                           "control_dropped": 0} for _ in range(n)]
        self._clients: dict[tuple[int, int, int], _Client] = {}
        # control thread <-> worker
        self._control_q: collections.deque[tuple[int, Any, Callable[[], None]]] = \
            collections.deque()
        self._control_queue_len = int(control_queue_len)
        self._outbox: collections.deque[Callable[[], None]] = collections.deque()
        self._snap_lock = threading.Lock()
        self._snap: tuple[NavState | None, AutopilotStatus | None] = (None, None)
        self._snap_seq = 0
        self._seen_seq = -1
        self._wake = threading.Event()
        self._closed = False
        # what the worker knows
        self.nav: NavState | None = None
        self.status: AutopilotStatus | None = None
        self.commands = np.zeros(len(actuators.motors) + len(actuators.servos))
        self.sim_usec = 0
        self._last_mode: FlightMode | None = None
        self._last_message = ""
        self._wall_next = 0.0
        self._last_step_wall = -math.inf
        self._hold_notice_ms: int | None = None
        self._hold_sent_ms: int | None = None
        self._hold_announce_wall = 0.0
        self._last_fault_status: Any = None
        self.commands_answered = 0
        self.ready = ready
        """True once the autopilot is warm (HEARTBEAT says STANDBY/ACTIVE, not BOOT)."""
        self.mav_state: int | None = None
        """MAV_STATE set by a failsafe (CRITICAL / EMERGENCY), None = normal."""
        self.last_gcs_heartbeat = -math.inf
        """monotonic time of the last (signed, if signing is on) ground-station HEARTBEAT or
        command addressed to this autopilot."""
        self.handlers: dict[str, Callable[[int, Link, Any], None]] = {
            "HEARTBEAT": self._on_heartbeat,
            "COMMAND_LONG": self._on_command_long,
            "COMMAND_INT": self._on_command_int,
            "PARAM_REQUEST_LIST": self._on_param_request_list,
            "PARAM_REQUEST_READ": self._on_param_request_read,
            "PARAM_SET": self._on_param_set,
        }
        """Handler per message type, run in the worker thread: ``f(link_index, link, msg)``.
        A handler that must change the autopilot hands a function to :meth:`submit`."""
        self._status0 = autopilot.status()
        self._snap = (None, self._status0)
        self._snap_seq = 0
        self.services = Px4Services(self)
        self.telemetry = TelemetryStreams(self)
        for name in self.services.HANDLES - {"COMMAND_INT"}:  # missions, TIMESYNC, PING
            self.handlers.setdefault(name, self._on_service)
        self._threads: list[threading.Thread] = []
        if start:
            self._threads = [threading.Thread(target=self._rx, args=(i, link), daemon=True,
                                              name=f"gcs-rx-{i}")
                             for i, link in enumerate(self.links)]
            self._threads.append(threading.Thread(target=self._worker, daemon=True,
                                                  name="gcs-worker"))
            for th in self._threads:
                th.start()

    # ------------------------------------------------------------------ receive threads
    def _rx(self, index: int, link: Link) -> None:
        q = self._inq[index]
        cnt = self._counters[index]
        while not self._closed:
            try:
                msgs = link.recv(0.25)
            except Exception:
                if self._closed:
                    return
                time.sleep(0.05)
                continue
            for m in msgs:
                if len(q) == q.maxlen:
                    cnt["queue_dropped"] += 1  # the append drops the oldest
                q.append(m)

    def close(self) -> None:
        """Stop the threads and close every link. Idempotent."""
        if self._closed:
            return
        self._closed = True
        self._wake.set()
        for th in self._threads:
            if th.name == "gcs-worker":
                th.join(timeout=2.0)
        for link in self.links:
            link.close()
        for th in self._threads:
            th.join(timeout=1.0)

    def link_stats(self) -> list[dict[str, Any]]:
        """Counters of every ground-station link (garbage, CRC, truncated, signature ...
        drops of the link; queue, rate-limit and control-queue drops of the endpoint)."""
        return [{"link": repr(link), **link.stats.as_dict(), **self._counters[i]}
                for i, link in enumerate(self.links)]

    # ------------------------------------------------------------------ worker thread
    def _worker(self) -> None:
        while not self._closed:
            self._wake.wait(0.005)
            self._wake.clear()
            try:
                self.serve_once()
            except Exception as exc:  # the worker never dies
                if self._closed:
                    return
                self.on_event("error", f"ground-station worker: {exc!r}")
                time.sleep(0.01)
        # last answers (e.g. a command handled just before stop)
        with contextlib.suppress(Exception):
            self._drain_outbox()

    def serve_once(self) -> int:
        """One worker cycle: answers from the control thread, queued messages (within the
        budget), status changes, streams, wall-clock duties. Returns messages handled."""
        n = self._serve_inputs()
        self._drain_outbox()
        self._observe_snapshot()
        self._streams()
        self._wall_duties()
        return n

    def _drain_outbox(self) -> None:
        while True:
            try:
                fn = self._outbox.popleft()
            except IndexError:
                return
            fn()

    def _allow(self, index: int, msg: Any, now: float) -> bool:
        key = (index, msg.get_srcSystem(), msg.get_srcComponent())
        c = self._clients.get(key)
        if c is None:
            if len(self._clients) > 4096:  # a flood of made-up ids: forget the idle ones
                self._clients = {k: v for k, v in self._clients.items() if now - v.last < 10}
            c = self._clients[key] = _Client(self.rate_burst, now)
        c.tokens = min(self.rate_burst, c.tokens + (now - c.last) * self.rate_limit_hz)
        c.last = now
        if c.tokens < 1.0:
            return False
        c.tokens -= 1.0
        return True

    def _serve_inputs(self) -> int:
        budget = self.budget_per_cycle
        handled = 0
        now = time.monotonic()
        active = True
        while handled < budget and active:
            active = False
            for index, q in enumerate(self._inq):
                if handled >= budget:
                    break
                try:
                    msg = q.popleft()
                except IndexError:
                    continue
                active = True
                cnt = self._counters[index]
                if not self._allow(index, msg, now):
                    cnt["rate_limited"] += 1
                    continue
                handled += 1
                cnt["handled"] += 1
                handler = self.handlers.get(msg.get_type())
                if handler is None:
                    continue
                link = self.links[index]
                try:
                    handler(index, link, msg)
                except Exception as exc:  # one bad message must not stop the endpoint
                    self.statustext(f"error handling {msg.get_type()}: {exc}",
                                    SEVERITY_WARNING)
        return handled

    # ------------------------------------------------------------------ control thread side
    def submit(self, index: int, msg: Any, fn: Callable[[], None],
               on_drop: Callable[[], None] | None = None) -> None:
        """Worker: have the control thread run ``fn`` (at most ``max_items`` per control
        cycle). If the queue is full the oldest request is dropped and its ``on_drop`` run
        (in the worker)."""
        q = self._control_q
        if len(q) >= self._control_queue_len:
            old_index, _old, _fn = q.popleft()
            self._counters[old_index]["control_dropped"] += 1
            drop = getattr(_fn, "on_drop", None)
            if drop is not None:
                drop()
        fn.on_drop = on_drop  # type: ignore[attr-defined]
        q.append((index, msg, fn))

    def poll(self, max_items: int = 4) -> int:
        """Control thread: apply up to ``max_items`` requests (commands, parameter changes)
        the worker queued; returns how many."""
        n = 0
        while n < max_items:
            try:
                _index, _msg, fn = self._control_q.popleft()
            except IndexError:
                break
            n += 1
            try:
                fn()
            except Exception as exc:
                self.notify(f"error applying a ground-station request: {exc}",
                            SEVERITY_WARNING)
        if n:
            self._wake.set()
        return n

    def has_pending(self) -> bool:
        """Control thread: requests are waiting for :meth:`poll`."""
        return bool(self._control_q)

    def _reply(self, fn: Callable[[], None]) -> None:
        """Control thread: have the worker send something (it alone sends on the links)."""
        self._outbox.append(fn)
        self._wake.set()

    def notify(self, text: str, severity: int = SEVERITY_INFO) -> None:
        """Any thread: a STATUSTEXT to every ground station (sent by the worker)."""
        self._reply(lambda: self.statustext(text, severity))

    def on_step(self, nav: NavState, status: AutopilotStatus) -> None:
        """Control thread, after a control step: publish the step for the worker's streams."""
        with self._snap_lock:
            self._snap = (nav, status)
            self._snap_seq += 1
        self.services.on_step(nav)
        self._hold_notice_ms = None
        self._wake.set()

    def publish_status(self, status: AutopilotStatus) -> None:
        """Control thread: a new status without a step (e.g. after a command)."""
        with self._snap_lock:
            self._snap = (self._snap[0], status)
            self._snap_seq += 1
        self._wake.set()

    def hold_usec(self) -> int | None:
        """Simulated time at which to hold, None if no hold (or not lockstep)."""
        if not self.lockstep:
            return None
        v = int(self.ap.params.get(SIM_HOLD_PARAM))
        return None if v < 0 else v * 1000

    def announce_hold(self, time_usec: int) -> None:
        """Control thread: the simulation is held at ``time_usec`` (the worker tells the
        ground stations, repeated at 1 Hz)."""
        ms = time_usec // 1000
        if self._hold_notice_ms != ms:
            self._hold_notice_ms = ms
            self._wake.set()

    def tick(self) -> None:
        """Kept for callers of the single-threaded endpoint: the worker does the wall-clock
        duties now."""

    def refresh_status(self) -> None:
        """Read the autopilot's status (only from the control thread or before start)."""
        self.publish_status(self.ap.status())

    # ------------------------------------------------------------------ sending (worker)
    def _send_all(self, msg: Any) -> None:
        for link in self.links:
            link.send(msg)

    def statustext(self, text: str, severity: int = SEVERITY_INFO,
                   link: Link | None = None) -> None:
        """Worker: STATUSTEXT to one link or to all. A text longer than the field's 50 bytes
        goes out in chunks as MAVLink 2 specifies: one ``id`` (1..65535) for all of them,
        ``chunk_seq`` 0, 1, ..., the last chunk shorter than 50 bytes (an empty one if
        needed)."""
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
        """Simulated time since boot (ms), for the messages' ``time_boot_ms``."""
        return self.sim_usec // 1000

    def _observe_snapshot(self) -> None:
        with self._snap_lock:
            seq = self._snap_seq
            nav, st = self._snap
        if seq == self._seen_seq:
            return
        # answers queued before this snapshot was published go first (they carry the
        # command's message, which must not be reported twice)
        self._drain_outbox()
        self._seen_seq = seq
        if nav is not None and (self.nav is None or nav.time_usec != self.nav.time_usec):
            self.nav = nav
            self.sim_usec = int(nav.time_usec)
            self._last_step_wall = time.monotonic()
            self._hold_sent_ms = None
        if st is not None:
            self.commands = np.asarray(st.actuator_commands, dtype=float)
            self._observe(st)

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

    def _streams(self) -> None:
        if self.nav is None:
            return
        fs = self.hil.fault_status
        fid = MSG["FAULT_INJECTION_STATUS"]
        if fs is not None and fs is not self._last_fault_status:
            self._last_fault_status = fs
            self._send_stream(fid)
            for i, due in enumerate(self._next_due):
                due[fid] = self.sim_usec + 1_000_000
                self._earliest_due[i] = 0
        t = self.sim_usec
        for i, link in enumerate(self.links):
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
                    self._send_stream(msg_id, link)
                earliest = min(earliest, due)
            self._earliest_due[i] = earliest

    def _wall_duties(self) -> None:
        """1 Hz HEARTBEAT, SYS_STATUS, EXTENDED_SYS_STATE while simulated time does not
        advance; the SIM_HOLD notice."""
        now = time.monotonic()
        self.services.tick()
        if now >= self._wall_next and now - self._last_step_wall > 0.5:
            self._wall_next = now + 1.0
            for name in ("HEARTBEAT", "SYS_STATUS", "EXTENDED_SYS_STATE"):
                self._send_stream(MSG[name])
        ms = self._hold_notice_ms
        if ms is not None and (self._hold_sent_ms != ms or now >= self._hold_announce_wall):
            self._hold_sent_ms = ms
            self._hold_announce_wall = now + 1.0
            if self.links:
                self._send_all(self.links[0].codec.named_value_int_encode(ms, b"SIM_HOLD", ms))

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

    def system_status(self) -> int:
        """MAV_STATE of the HEARTBEAT (see the module docstring)."""
        if not self.ready:
            return MAV_STATE_BOOT
        if self.mav_state is not None:
            return self.mav_state
        st = self.status
        return MAV_STATE_ACTIVE if (st is not None and st.armed) else MAV_STATE_STANDBY

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
            cm = st.px4_custom_mode if st and st.px4_custom_mode >= 0 else px4_custom_mode(
                st.mode if st else FlightMode.IDLE)
            return c.heartbeat_encode(MAV_TYPE_VTOL_FIXEDROTOR, MAV_AUTOPILOT_PX4, base, cm,
                                      self.system_status())
        if msg_id == MSG["SYS_STATUS"]:
            healthy = _ANGULAR_RATE_CTRL | _ATTITUDE_CTRL | _MOTOR_OUTPUTS
            if self.hil.connected and self.hil.last_sensor is not None:
                healthy |= _GYRO | _ACCEL | _MAG | _BARO | _DIFF | _AHRS
            gps = self.hil.last_gps
            if self.hil.connected and gps is not None and gps.fix_type >= 3:
                healthy |= _GPS
            if self.hil.connected and self.hil.home is not None and nav is not None:
                healthy |= _PREARM
            # battery: voltage UINT16_MAX, current and remaining -1 until the first reading
            present, enabled, more_healthy = self.services.sensor_bits()
            mv, ca, pct = self.services.sys_status_battery()
            return c.sys_status_encode(_SENSORS_PRESENT | present, _SENSORS_PRESENT | enabled,
                                       healthy | more_healthy, 0, mv, ca, pct, 0, 0, 0, 0, 0,
                                       0)
        if msg_id == MSG["EXTENDED_SYS_STATE"]:
            vtol = int(st.vtol_state) if st else 0
            landed = int(st.landed_state) if st else 0
            return c.extended_sys_state_encode(vtol or int(VtolState.MC),
                                               landed or int(LandedState.ON_GROUND))
        if msg_id == MSG["AUTOPILOT_VERSION"]:
            major, minor, patch = self.version
            sw = (major << 24) | (minor << 16) | (patch << 8) | 255
            # exactly what is served (MAV_PROTOCOL_CAPABILITY): MISSION_FLOAT 1, PARAM_FLOAT
            # 2, MISSION_INT 4, COMMAND_INT 8, PARAM_ENCODE_BYTEWISE 16, MAVLINK2 8192,
            # MISSION_FENCE 16384, MISSION_RALLY 32768
            caps = 1 | 2 | 4 | 8 | 16 | 8192 | 16384 | 32768
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
        if msg_id in STREAM_RATES_HZ:
            return self.services.build(msg_id)
        if msg_id in TELEMETRY_RATES_HZ:
            return self.telemetry.build(msg_id)
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

    # ------------------------------------------------------------------ handlers (worker)
    def _on_service(self, index: int, link: Link, msg: Any) -> None:
        """Missions, TIMESYNC, PING (:mod:`.gcs_services`), answered in the worker."""
        self.services.handle(link, msg)

    def _on_heartbeat(self, index: int, link: Link, msg: Any) -> None:
        if int(msg.type) == MAV_TYPE_GCS and (not self.signing_required or msg.get_signed()):
            self.last_gcs_heartbeat = time.monotonic()

    def _seen_gcs(self, msg: Any) -> None:
        """A command from a ground station proves the link as its heartbeat does."""
        if not self.signing_required or msg.get_signed():
            self.last_gcs_heartbeat = time.monotonic()

    def _on_command_long(self, index: int, link: Link, msg: Any) -> None:
        if msg.target_system not in (0, 1) or msg.target_component not in (0, 1):
            return
        self._seen_gcs(msg)
        params = [msg.param1, msg.param2, msg.param3, msg.param4, msg.param5, msg.param6,
                  msg.param7]
        self._dispatch(index, link, msg, int(msg.command), [float(x) for x in params])

    def _on_command_int(self, index: int, link: Link, msg: Any) -> None:
        """COMMAND_INT, converted as PX4 does (:func:`.gcs_services.command_int_params`) and
        answered like COMMAND_LONG."""
        if msg.target_system not in (0, 1) or msg.target_component not in (0, 1):
            return
        self._seen_gcs(msg)
        self._dispatch(index, link, msg, int(msg.command),
                       command_int_params(msg, self.services.home_alt_m()))

    def _ack(self, link: Link, msg: Any, cmd: int, result: int, reason: str) -> None:
        """Worker: STATUSTEXT with the reason (if any) and the COMMAND_ACK on ``link``."""
        if reason:
            self.statustext(reason, SEVERITY_WARNING if result else SEVERITY_INFO, link)
        link.send(link.codec.command_ack_encode(cmd, int(result), 0, 0, msg.get_srcSystem(),
                                                msg.get_srcComponent()))
        self.commands_answered += 1
        self.on_event("ack", f"{_cmd_label(cmd)} -> {CommandResult(result).name}"
                      + (f" ({reason})" if reason else ""))

    def _dispatch(self, index: int, link: Link, msg: Any, cmd: int,
                  params: list[float]) -> None:
        if self.signing_required and cmd in (CMD_ARM_DISARM, *FAULT_COMMANDS) \
                and not msg.get_signed():
            self._ack(link, msg, cmd, CommandResult.DENIED, "signed command required")
            return

        def busy() -> None:
            self._ack(link, msg, cmd, CommandResult.TEMPORARILY_REJECTED,
                      "busy: too many requests")

        if cmd == CMD_ARM_DISARM and params[0] not in (0.0, 1.0):
            self._ack(link, msg, cmd, CommandResult.DENIED, "param1 must be 0 or 1")
            return
        if not self.ready and (cmd in FLIGHT_COMMANDS or cmd in FAULT_COMMANDS):
            # booting: the control thread is compiling and polls nothing; answer now
            self._ack(link, msg, cmd, CommandResult.TEMPORARILY_REJECTED,
                      "autopilot still starting (compiling)")
            return
        if cmd in FLIGHT_COMMANDS:
            self.submit(index, msg, lambda: self._flight_command(link, msg, cmd, params),
                        busy)
            return
        if cmd in FAULT_COMMANDS:
            res, reason = self._fault(cmd, params)
            if res != CommandResult.ACCEPTED:
                self._ack(link, msg, cmd, res, reason)
                return
            self.submit(index, msg, lambda: self._forward_fault(link, msg, cmd, params), busy)
            return
        if cmd == CMD_SET_MESSAGE_INTERVAL:
            res, reason = self._set_interval(index, params)
        elif cmd == CMD_GET_MESSAGE_INTERVAL:
            res, reason = self._get_interval(index, link, params[0])
        elif cmd in _REQUEST_ONE:
            mid = params[0] if cmd == CMD_REQUEST_MESSAGE else _REQUEST_ONE[cmd]
            if not math.isfinite(mid) or int(mid) not in MSG.values():
                res, reason = CommandResult.UNSUPPORTED, ""
            elif not self._send_stream(int(mid), link):
                res, reason = CommandResult.TEMPORARILY_REJECTED, "no data yet"
            else:
                res, reason = CommandResult.ACCEPTED, ""
        else:
            res, reason = CommandResult.UNSUPPORTED, ""
        self._ack(link, msg, cmd, res, reason)

    def _set_interval(self, index: int, params: list[float]) -> tuple[int, str]:
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
        self._next_due[index][mid] = self.sim_usec
        self._earliest_due[index] = 0
        return CommandResult.ACCEPTED, ""

    def _get_interval(self, index: int, link: Link, mid: float) -> tuple[int, str]:
        """GET_MESSAGE_INTERVAL (510): MESSAGE_INTERVAL with this link's interval [us] (-1 =
        not streamed, as PX4), then the ACK; UNSUPPORTED for a message not served here."""
        rates = self.rates_hz[index]
        if not math.isfinite(mid) or int(mid) not in rates:
            return CommandResult.UNSUPPORTED, ""
        hz = rates[int(mid)]
        link.send(link.codec.message_interval_encode(int(mid), round(1e6 / hz) if hz > 0 else -1))
        return CommandResult.ACCEPTED, ""

    # ------------------------------------------------------------------ control-thread work
    def _flight_command(self, link: Link, msg: Any, cmd: int, params: list[float]) -> None:
        """Control thread: a flight command on the autopilot; the answer goes to the worker."""
        before = self.ap.status().message
        res = CommandResult(self.ap.command(cmd, params))
        st = self.ap.status()
        after = st.message
        reason = after if (res != CommandResult.ACCEPTED and after and after != before) else ""
        if res != CommandResult.ACCEPTED and not reason:
            reason = _default_reason(cmd, res, st)
        self.on_event("command", f"{_cmd_label(cmd)} {_fmt_params(params)}")

        def answer() -> None:
            if reason == after:
                self._last_message = after  # reported with the ACK: not again
            # else a new message (e.g. of an accepted command) goes out as a STATUSTEXT to
            # every link when the worker sees the status
            self._ack(link, msg, cmd, res, reason)

        self._reply(answer)
        self.publish_status(st)

    def _forward_fault(self, link: Link, msg: Any, cmd: int, params: list[float]) -> None:
        """Control thread: forward an accepted fault command to the vehicle (the HIL link is
        the control thread's), so that in lockstep it acts at exactly this step."""
        res, reason = self._fault(cmd, params)  # SYS_FAILURE_EN may have changed meanwhile
        if res == CommandResult.ACCEPTED:
            self.hil.forward_command(msg)
            self.on_event("fault", f"{_cmd_label(cmd)} {_fmt_params(params)}")
        self._reply(lambda: self._ack(link, msg, cmd, res, reason))

    def _fault(self, cmd: int, p: list[float]) -> tuple[int, str]:
        if int(self.ap.params.get("SYS_FAILURE_EN")) != 1:
            return CommandResult.DENIED, "fault injection disabled: set SYS_FAILURE_EN to 1"
        unit = p[0]
        if not math.isfinite(unit) or int(unit) not in (FAILURE_UNIT_MOTOR, FAILURE_UNIT_SERVO):
            return CommandResult.UNSUPPORTED, "unit must be motor 101 or servo 102"
        names = self.actuators.motors if int(unit) == FAILURE_UNIT_MOTOR \
            else self.actuators.servos
        if cmd == CMD_INJECT_FAILURE:
            ftype, inst = p[1], p[2]
            if not math.isfinite(ftype) or int(ftype) not in (
                    mav.FAILURE_TYPE_OK, mav.FAILURE_TYPE_OFF, mav.FAILURE_TYPE_STUCK):
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

    def _on_param_request_list(self, index: int, link: Link, msg: Any) -> None:
        if msg.target_system in (0, 1):
            for i in range(len(self.ap.params)):
                self._param_value(i, link)

    def _on_param_request_read(self, index: int, link: Link, msg: Any) -> None:
        if msg.target_system not in (0, 1):
            return
        store = self.ap.params
        try:
            i = int(msg.param_index) if msg.param_index >= 0 \
                else store.index(_text(msg.param_id))
            self._param_value(i, link)
        except ParamError:
            return  # unknown parameter: no answer (MAVLink parameter protocol)

    def _on_param_set(self, index: int, link: Link, msg: Any) -> None:
        if msg.target_system not in (0, 1):
            return
        store = self.ap.params
        name = _text(msg.param_id)
        if name not in store:
            self.statustext(f"unknown parameter {name}", SEVERITY_WARNING, link)
            return
        pindex = store.index(name)
        prm = store.by_index(pindex)
        value = decode_param_value(msg.param_value, prm.type)
        problem = _param_problem(prm, value)
        if problem:  # refused here: the control thread never sees it
            self.statustext(problem, SEVERITY_WARNING, link)
            self._param_value(pindex, link)
            return

        def apply() -> None:  # control thread
            error = ""
            try:
                store.set(name, value)
                self.on_event("param", f"{name} = {value:g}")
            except ParamError as exc:
                error = str(exc)

            def answer() -> None:
                if error:
                    self.statustext(error, SEVERITY_WARNING, link)
                self._param_value(pindex, None)  # echo on every link, as PX4 does

            self._reply(answer)

        self.submit(index, msg, apply, lambda: self._param_value(pindex, link))


def _param_problem(prm: Any, value: float) -> str:
    """Why ``value`` cannot be set on ``prm`` ("" if it can): the checks of
    :meth:`ParameterStore.set`, made in the worker so that invalid requests cost the control
    thread nothing."""
    if not math.isfinite(value):
        return f"{prm.name} = {value!r}: expected a finite number"
    if prm.type == ParamType.INT32 and value != int(value):
        return f"{prm.name} = {value!r}: expected an integer"
    if not prm.minimum <= value <= prm.maximum:
        return f"{prm.name} = {value!r}: expected {prm.minimum:g} .. {prm.maximum:g}"
    return ""


def _cmd_label(cmd: int) -> str:
    names = {CMD_ARM_DISARM: "ARM_DISARM", CMD_NAV_TAKEOFF: "TAKEOFF",
             CMD_DO_SET_MODE: "SET_MODE", CMD_DO_VTOL_TRANSITION: "VTOL_TRANSITION",
             CMD_NAV_LAND: "LAND", CMD_INJECT_FAILURE: "INJECT_FAILURE",
             CMD_INJECT_PARTIAL_LOSS: "INJECT_PARTIAL_LOSS",
             CMD_SET_MESSAGE_INTERVAL: "SET_MESSAGE_INTERVAL",
             CMD_REQUEST_MESSAGE: "REQUEST_MESSAGE", CMD_GET_HOME_POSITION: "GET_HOME_POSITION",
             CMD_REQUEST_FLIGHT_INFORMATION: "REQUEST_FLIGHT_INFORMATION"}
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

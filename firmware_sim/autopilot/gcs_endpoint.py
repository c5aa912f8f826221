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
- one worker thread handles the queues: at most ``budget_per_cycle`` messages
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

Modules, along PX4's seams: this one holds the threads, the control-thread hand-over and the
status the worker observes; link handling (receive queues, rate limits, partners, sending) is
:mod:`.gcs_link`, the streams :mod:`.gcs_streams`, the parameter protocol :mod:`.gcs_params`,
commands :mod:`.gcs_commands`, the simulation hold :mod:`.gcs_hold`, missions, TIMESYNC, PING
and the geofence :mod:`.gcs_services`
(on :mod:`.mission`), the further telemetry :mod:`.gcs_telemetry`.
"""

from __future__ import annotations

import collections
import contextlib
import math
import threading
import time
from collections.abc import Callable, Sequence
from typing import Any

import numpy as np

from vtolftc.firmware_sim.autopilot.gcs_commands import CommandService
from vtolftc.firmware_sim.autopilot.gcs_hold import SimulationHold
from vtolftc.firmware_sim.autopilot.gcs_link import GcsLinks, Handler
from vtolftc.firmware_sim.autopilot.gcs_params import ParameterService
from vtolftc.firmware_sim.autopilot.gcs_services import Px4Services
from vtolftc.firmware_sim.autopilot.gcs_streams import DEFAULT_RATES_HZ, MSG, StreamService
from vtolftc.firmware_sim.autopilot.gcs_telemetry import TelemetryStreams
from vtolftc.firmware_sim.autopilot.hil_bridge import HilBridge
from vtolftc.firmware_sim.autopilot.interface import (
    AutopilotAPI,
    AutopilotStatus,
    FlightMode,
    NavState,
)
from vtolftc.firmware_sim.autopilot.modes import px4_custom_mode
from vtolftc.protocols.failure_units import ActuatorTable
from vtolftc.protocols.generated import constants as mav
from vtolftc.protocols.link import Link

__all__ = ["DEFAULT_RATES_HZ", "UNSIGNED_ALLOWED", "GcsEndpoint", "px4_mode_of"]

MAV_STATE_BOOT, MAV_STATE_STANDBY, MAV_STATE_ACTIVE = (
    mav.MAV_STATE_BOOT, mav.MAV_STATE_STANDBY, mav.MAV_STATE_ACTIVE)
MAV_STATE_CRITICAL, MAV_STATE_EMERGENCY = mav.MAV_STATE_CRITICAL, mav.MAV_STATE_EMERGENCY
SEVERITY_CRITICAL, SEVERITY_WARNING = mav.MAV_SEVERITY_CRITICAL, mav.MAV_SEVERITY_WARNING
SEVERITY_NOTICE, SEVERITY_INFO = mav.MAV_SEVERITY_NOTICE, mav.MAV_SEVERITY_INFO

UNSIGNED_ALLOWED = frozenset({mav.MAVLINK_MSG_ID_HEARTBEAT, mav.MAVLINK_MSG_ID_RADIO_STATUS,
                              mav.MAVLINK_MSG_ID_PARAM_REQUEST_READ,
                              mav.MAVLINK_MSG_ID_PARAM_REQUEST_LIST})
"""Message ids accepted without a valid signature when signing is on: HEARTBEAT (0),
RADIO_STATUS (109, as ArduPilot), PARAM_REQUEST_READ (20) and PARAM_REQUEST_LIST (21)
(read-only). Everything else, every command, PARAM_SET and mission message included, needs
the key."""



def px4_mode_of(mode: FlightMode) -> tuple[int, int]:
    """PX4 (main, sub) custom mode reported for a flight mode (see
    :func:`vtolftc.firmware_sim.autopilot.modes.px4_custom_mode`)."""
    cm = px4_custom_mode(FlightMode(mode))
    return (cm >> 16) & 0xFF, (cm >> 24) & 0xFF


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
        self.io = GcsLinks(links, signing_required=signing_required,
                           rate_limit_hz=rate_limit_hz, rate_burst=rate_burst,
                           queue_len=queue_len, budget_per_cycle=budget_per_cycle)
        """The links, their queues, rate limits and sending (:mod:`.gcs_link`)."""
        self.links = self.io.links
        self.actuators = actuators
        self.lockstep = lockstep
        self.on_event = on_event or (lambda kind, text: None)
        self.version = version
        self.hold = SimulationHold(autopilot.params, lockstep=lockstep, hold_ms=hold_ms)
        """``SIM_HOLD_MS`` and its announcement (:mod:`.gcs_hold`)."""
        # control thread <-> worker
        self._control_q: collections.deque[tuple[int, Any, Callable[[], None]]] = \
            collections.deque()
        self._control_queue_len = int(control_queue_len)
        self._outbox: collections.deque[Callable[[], None]] = collections.deque()
        self._snap_lock = threading.Lock()
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
        self._reported: str | None = None  # a message its COMMAND_ACK carried: not again
        self._events_seen = len(autopilot.event_log)  # the autopilot's events reported
        self._wall_next = 0.0
        self._last_step_wall = -math.inf
        self.ready = ready
        """True once the autopilot is warm (HEARTBEAT says STANDBY/ACTIVE, not BOOT)."""
        self.mav_state: int | None = None
        """MAV_STATE set by a failsafe (CRITICAL / EMERGENCY), None = normal."""
        self._snap: tuple[NavState | None, AutopilotStatus | None, int] = (
            None, autopilot.status(), self._events_seen)
        self._published: tuple[Any, ...] | None = None
        self.streams = StreamService(self, len(self.links))
        self.services = Px4Services(self)
        self.telemetry = TelemetryStreams(self)
        self.command_service = CommandService(self)
        self.param_service = ParameterService(self)
        self.handlers: dict[str, Handler] = {
            "HEARTBEAT": self.io.on_heartbeat,
            **self.command_service.handlers(),
            **self.param_service.handlers(),
        }
        """Handler per message type, run in the worker thread: ``f(link_index, link, msg)``.
        A handler that must change the autopilot hands a function to :meth:`submit`."""
        for name in self.services.HANDLES - {"COMMAND_INT"}:  # missions, TIMESYNC, PING
            self.handlers.setdefault(name, self._on_service)
        self._threads: list[threading.Thread] = []
        if start:
            self._threads = [threading.Thread(target=self.io.receive_loop, args=(i,),
                                              daemon=True, name=f"gcs-rx-{i}")
                             for i in range(len(self.links))]
            self._threads.append(threading.Thread(target=self._worker, daemon=True,
                                                  name="gcs-worker"))
            for th in self._threads:
                th.start()

    # ------------------------------------------------------------------ views of the parts
    @property
    def rates_hz(self) -> list[dict[int, float]]:
        """Stream rates [Hz] of each link (:attr:`.gcs_streams.StreamService.rates_hz`)."""
        return self.streams.rates_hz

    @property
    def rate_burst(self) -> float:
        """Burst of the per-client token bucket [messages]."""
        return self.io.rate_burst

    @property
    def signing_required(self) -> bool:
        """Incoming frames must be signed (see :data:`UNSIGNED_ALLOWED`)."""
        return self.io.signing_required

    @property
    def commands_answered(self) -> int:
        """COMMAND_ACKs sent so far."""
        return self.command_service.answered

    @property
    def last_gcs_heartbeat(self) -> float:
        """monotonic time [s] of the last (signed, if signing is on) ground-station HEARTBEAT
        or command addressed to this autopilot."""
        return self.io.last_gcs_heartbeat

    def _on_service(self, index: int, link: Link, msg: Any) -> None:
        """Missions, TIMESYNC, PING (:mod:`.gcs_services`), answered in the worker."""
        self.services.handle(link, msg)

    # ------------------------------------------------------------------ lifetime
    def close(self) -> None:
        """Stop the threads and close every link. Idempotent."""
        if self._closed:
            return
        self._closed = True
        self.io.stop()
        self._wake.set()
        for th in self._threads:
            if th.name == "gcs-worker":
                th.join(timeout=2.0)
        self.io.close()
        for th in self._threads:
            th.join(timeout=1.0)

    def link_stats(self) -> list[dict[str, Any]]:
        """Counters of every ground-station link (garbage, CRC, truncated, signature ...
        drops of the link; queue, rate-limit and control-queue drops of the endpoint)."""
        return self.io.stats()

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
        n = self.io.serve(self.handlers)
        self._drain_outbox()
        self._observe_snapshot()
        self.streams.run()
        self._wall_duties()
        return n

    def _drain_outbox(self) -> None:
        while True:
            try:
                fn = self._outbox.popleft()
            except IndexError:
                return
            fn()

    # ------------------------------------------------------------------ control thread side
    def submit(self, index: int, msg: Any, fn: Callable[[], None],
               on_drop: Callable[[], None] | None = None) -> None:
        """Worker: have the control thread run ``fn`` (at most ``max_items`` per control
        cycle). If the queue is full the oldest request is dropped and its ``on_drop`` run
        (in the worker)."""
        q = self._control_q
        if len(q) >= self._control_queue_len:
            old_index, _old, _fn = q.popleft()
            self.io.counters[old_index]["control_dropped"] += 1
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

    def reply(self, fn: Callable[[], None]) -> None:
        """Control thread: have the worker send something (it alone sends on the links)."""
        self._outbox.append(fn)
        self._wake.set()

    def notify(self, text: str, severity: int = SEVERITY_INFO) -> None:
        """Any thread: a STATUSTEXT to every ground station (sent by the worker)."""
        self.reply(lambda: self.statustext(text, severity))

    def on_step(self, nav: NavState, status: AutopilotStatus) -> None:
        """Control thread, after a control step: publish the step for the worker's streams.

        The worker is woken only when it has something to do at this step (:meth:`_news`);
        otherwise it sees the step within its 5 ms poll. Waking it at every step cost the
        lockstep a thread switch per step for nothing.
        """
        n_events = len(self.ap.event_log)
        with self._snap_lock:
            self._snap = (nav, status, n_events)
            self._snap_seq += 1
        self.services.on_step(nav)
        self.hold.notice_ms = None
        if self._news(nav, status, n_events):
            self._wake.set()

    def _news(self, nav: NavState, status: AutopilotStatus, n_events: int) -> bool:
        """Control thread: the worker has work at this step: a stream is due at its simulated
        time, the mode, armed state or the number of autopilot events (``n_events``) changed,
        the vehicle's fault status changed."""
        last = self._published
        self._published = (status.mode, status.armed, n_events)
        return (nav.time_usec >= self.streams.earliest_due_usec or last != self._published
                or self.hil.fault_status is not self.streams.last_fault_status)

    def publish_status(self, status: AutopilotStatus) -> None:
        """Control thread: a new status without a step (e.g. after a command)."""
        n_events = len(self.ap.event_log)
        with self._snap_lock:
            self._snap = (self._snap[0], status, n_events)
            self._snap_seq += 1
        self._wake.set()

    def hold_usec(self) -> int | None:
        """Simulated time at which to hold, None if no hold (or not lockstep)."""
        return self.hold.hold_usec()

    def announce_hold(self, time_usec: int) -> None:
        """Control thread: the simulation is held at ``time_usec`` (the worker tells the
        ground stations, repeated at 1 Hz)."""
        if self.hold.announce(time_usec):
            self._wake.set()

    def tick(self) -> None:
        """Kept for callers of the single-threaded endpoint: the worker does the wall-clock
        duties now."""

    def refresh_status(self) -> None:
        """Read the autopilot's status (only from the control thread or before start)."""
        self.publish_status(self.ap.status())

    # ------------------------------------------------------------------ sending (worker)
    def send_all(self, msg: Any) -> None:
        """Worker: ``msg`` on every ground-station link."""
        self.io.send_all(msg)

    def statustext(self, text: str, severity: int = SEVERITY_INFO,
                   link: Link | None = None) -> None:
        """Worker: STATUSTEXT to one link or to all (:meth:`.gcs_link.GcsLinks.statustext`)."""
        self.io.statustext(text, severity, link)

    def mark_reported(self, message: str) -> None:
        """Worker: the autopilot's ``message`` went out already (with a COMMAND_ACK): do not
        send it again as a STATUSTEXT when its event is observed."""
        self._reported = message

    # ------------------------------------------------------------------ observed status
    @property
    def time_boot_ms(self) -> int:
        """Simulated time since boot (ms), for the messages' ``time_boot_ms``."""
        return self.sim_usec // 1000

    def system_status(self) -> int:
        """MAV_STATE of the HEARTBEAT (see the module docstring)."""
        if not self.ready:
            return MAV_STATE_BOOT
        if self.mav_state is not None:
            return self.mav_state
        st = self.status
        return MAV_STATE_ACTIVE if (st is not None and st.armed) else MAV_STATE_STANDBY

    def _observe_snapshot(self) -> None:
        with self._snap_lock:
            seq = self._snap_seq
            nav, st, n_events = self._snap
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
            self.hold.stepped()
        if st is not None:
            self.commands = np.asarray(st.actuator_commands, dtype=float)
            self._observe(st, n_events)

    def _observe(self, st: AutopilotStatus, n_events: int) -> None:
        """Worker: a mode change, and every autopilot event up to the snapshot's
        ``n_events`` (STATUSTEXT and run event each, as PX4's: not only the last message,
        which lost one of two events of a step, e.g. "mission complete" at touchdown)."""
        self.status = st
        log = self.ap.event_log
        new = [text for _, text in log[self._events_seen:n_events] if text]
        self._events_seen = max(self._events_seen, n_events)
        if self._last_mode is not None and st.mode != self._last_mode:
            text = f"mode {self._last_mode.name} -> {FlightMode(st.mode).name}"
            self.on_event("mode", text)
            if not new:  # the autopilot's own message usually says it already
                self.statustext(text, SEVERITY_INFO)
        self._last_mode = FlightMode(st.mode)
        for text in new:
            if text == self._reported:  # went out with its command's COMMAND_ACK
                self._reported = None
                continue
            self.statustext(text, SEVERITY_NOTICE)
            self.on_event("autopilot", text)

    def _wall_duties(self) -> None:
        """1 Hz HEARTBEAT, SYS_STATUS, EXTENDED_SYS_STATE while simulated time does not
        advance; the SIM_HOLD notice."""
        now = time.monotonic()
        self.services.tick()
        if now >= self._wall_next and now - self._last_step_wall > 0.5:
            self._wall_next = now + 1.0
            for name in ("HEARTBEAT", "SYS_STATUS", "EXTENDED_SYS_STATE"):
                self.streams.send(MSG[name])
        ms = self.hold.due(now)
        if ms is not None and self.links:
            self.send_all(self.links[0].codec.named_value_int_encode(ms, b"SIM_HOLD", ms))

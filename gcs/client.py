"""Ground-station client: connect to the autopilot, watch it, command it, inject faults.

A :class:`GroundStation` owns one MAVLink link (any URL of :func:`protocols.open_link`; by
default it binds UDP 14550 like QGroundControl, where the autopilot sends its ground-station
stream) and a receive thread that keeps a :class:`VehicleSnapshot` of the autopilot (system 1,
component 1) up to date, answers nothing on its own except a 1 Hz GCS HEARTBEAT, and hands
every received message to the listeners.

Commands are COMMAND_LONGs with retries (``confirmation`` counts the retries, as MAVLink's
command protocol asks); each returns a :class:`CommandOutcome` with the COMMAND_ACK's result
(``result`` None when no ACK came: a timeout) and, in ``detail``, the STATUSTEXT(s) the
autopilot sent while answering (e.g. why it refused).

Units: SI and radians in the snapshot except ``heading_deg``; NED positions relative to home.

    with GroundStation.connect("udp-server://127.0.0.1:14550") as gs:
        print(gs.snapshot().mode_name)
        gs.param_set("SYS_FAILURE_EN", 1)
        print(gs.arm(), gs.takeoff(30.0), gs.transition("fw"))
        gs.inject("rotor_2b", loss=0.5)
"""

from __future__ import annotations

import collections
import contextlib
import errno
import math
import threading
import time
from collections.abc import Callable, Sequence
from dataclasses import dataclass, field, replace
from typing import Any

from vtolftc.gcs.actuators import ActuatorTable, default_table
from vtolftc.protocols import SigningConfig, dialect, open_link
from vtolftc.protocols.generated import constants as mav
from vtolftc.protocols.px4 import (
    MAV_MODE_FLAG_CUSTOM_MODE_ENABLED,
    MAV_MODE_FLAG_SAFETY_ARMED,
    decode_param_value,
    encode_param_value,
    mode_from_name,
    mode_name,
)

__all__ = [
    "CMD_ARM_DISARM",
    "CMD_DO_SET_MODE",
    "CMD_DO_VTOL_TRANSITION",
    "CMD_INJECT_FAILURE",
    "CMD_INJECT_PARTIAL_LOSS",
    "CMD_NAV_TAKEOFF",
    "CommandOutcome",
    "GcsError",
    "GcsTimeout",
    "GroundStation",
    "VehicleSnapshot",
    "command_name",
    "result_name",
]

CMD_NAV_TAKEOFF = mav.MAV_CMD_NAV_TAKEOFF
CMD_NAV_LAND = mav.MAV_CMD_NAV_LAND
CMD_DO_SET_MODE = mav.MAV_CMD_DO_SET_MODE
CMD_ARM_DISARM = mav.MAV_CMD_COMPONENT_ARM_DISARM
CMD_INJECT_FAILURE = mav.MAV_CMD_INJECT_FAILURE
CMD_DO_VTOL_TRANSITION = mav.MAV_CMD_DO_VTOL_TRANSITION
CMD_INJECT_PARTIAL_LOSS = mav.MAV_CMD_INJECT_PARTIAL_LOSS
ARM_FORCE_MAGIC = 21196.0  # PX4's force-arm/disarm magic in param2 (not a MAVLink enum)

FAILURE_TYPE = {"ok": mav.FAILURE_TYPE_OK, "off": mav.FAILURE_TYPE_OFF,
                "stuck": mav.FAILURE_TYPE_STUCK}
VTOL_STATE_NAMES = {mav.MAV_VTOL_STATE_UNDEFINED: "UNDEFINED",
                    mav.MAV_VTOL_STATE_TRANSITION_TO_FW: "TRANSITION_TO_FW",
                    mav.MAV_VTOL_STATE_TRANSITION_TO_MC: "TRANSITION_TO_MC",
                    mav.MAV_VTOL_STATE_MC: "MC", mav.MAV_VTOL_STATE_FW: "FW"}
LANDED_STATE_NAMES = {mav.MAV_LANDED_STATE_UNDEFINED: "UNDEFINED",
                      mav.MAV_LANDED_STATE_ON_GROUND: "ON_GROUND",
                      mav.MAV_LANDED_STATE_IN_AIR: "IN_AIR",
                      mav.MAV_LANDED_STATE_TAKEOFF: "TAKEOFF",
                      mav.MAV_LANDED_STATE_LANDING: "LANDING"}
_RESULT_IN_PROGRESS = mav.MAV_RESULT_IN_PROGRESS
_HEARTBEAT_LOST_S = 3.0


class GcsError(RuntimeError):
    """Not connected, bad argument, refused parameter ...: the message says what to do."""


class GcsTimeout(GcsError):  # noqa: N818 - name fixed by the API
    """No answer (heartbeat, PARAM_VALUE, condition) in time."""


def command_name(command: int) -> str:
    """``DO_VTOL_TRANSITION`` for 3000, ``INJECT_PARTIAL_LOSS`` for 59900, ``CMD_n`` if unknown."""
    entry = dialect().enums.get("MAV_CMD", {}).get(int(command))
    return entry.name.removeprefix("MAV_CMD_") if entry is not None else f"CMD_{int(command)}"


def result_name(result: int | None) -> str:
    """``ACCEPTED``, ``DENIED`` ... of a MAV_RESULT; ``TIMEOUT`` for None (no ACK)."""
    if result is None:
        return "TIMEOUT"
    entry = dialect().enums.get("MAV_RESULT", {}).get(int(result))
    return entry.name.removeprefix("MAV_RESULT_") if entry is not None else f"RESULT_{result}"


@dataclass
class CommandOutcome:
    """The answer to one command: MAV_RESULT (None = no ACK in time) and the time it took."""

    command: int
    name: str
    result: int | None
    result_name: str
    elapsed_s: float
    detail: str = ""
    """STATUSTEXT(s) the autopilot sent while answering (reason of a refusal), "" if none."""

    @property
    def accepted(self) -> bool:
        """True when the autopilot answered MAV_RESULT_ACCEPTED."""
        return self.result == 0

    def __str__(self) -> str:
        text = f"{self.name}: {self.result_name}"
        return f"{text} ({self.detail})" if self.detail and not self.accepted else text


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


@dataclass
class _Waiter:
    predicate: Callable[[Any], bool]
    event: threading.Event = field(default_factory=threading.Event)
    message: Any = None


class GroundStation:
    """A MAVLink ground station talking to the autopilot (system 1, component 1).

    Parameters
    ----------
    url
        link URL (``udp-server://127.0.0.1:14550`` = QGroundControl's port; a zenoh URL
        such as ``zenoh://ds1/gcs/down?connect=tcp/127.0.0.1:7447`` works the same).
    system_id, component_id
        this ground station's ids (255 / 190 by convention).
    signing
        MAVLink 2 signing (:class:`protocols.SigningConfig`) for outgoing frames.
    target_system, target_component
        the autopilot's ids.
    actuators
        actuator numbering for :meth:`inject` (default: the shipped DS-1's).

    The receive thread starts at once; :meth:`connect` also waits for the first heartbeat.
    """

    def __init__(
        self,
        url: str = "udp-server://127.0.0.1:14550",
        *,
        system_id: int = 255,
        component_id: int = 190,
        signing: SigningConfig | None = None,
        target_system: int = 1,
        target_component: int = 1,
        actuators: ActuatorTable | None = None,
        allow_remote: bool = False,
    ) -> None:
        try:
            self._link = open_link(url, system_id=system_id, component_id=component_id,
                                   signing=signing, allow_remote=allow_remote)
        except (ValueError, OSError) as exc:
            hint = ""
            if isinstance(exc, OSError) and exc.errno == errno.EADDRINUSE:
                hint = (" (another ground station, e.g. the dashboard or QGroundControl, "
                        "already listens there: use the autopilot's other port, "
                        "udp-server://127.0.0.1:14540, or one given with --gcs-link)")
            raise GcsError(f"cannot open ground-station link {url!r}: {exc}{hint}") from exc
        self.url = url
        self.target = (int(target_system), int(target_component))
        self._actuators = actuators
        self._lock = threading.Lock()
        self._send_lock = threading.Lock()
        self._snap = VehicleSnapshot()
        self._last_heartbeat = -math.inf
        self._heartbeat_event = threading.Event()
        self._listeners: list[Callable[[Any], None]] = []
        self._waiters: list[_Waiter] = []
        self._statustexts: collections.deque[tuple[float, str]] = collections.deque(maxlen=64)
        self._chunks: dict[int, dict[int, bytes]] = {}
        self._param_types: dict[str, int] = {}
        self._closed = False
        self._thread = threading.Thread(target=self._rx_loop, name="gcs-rx", daemon=True)
        self._thread.start()

    # ------------------------------------------------------------------ lifetime
    @classmethod
    def connect(cls, url: str = "udp-server://127.0.0.1:14550", timeout_s: float = 10.0,
                **kw: Any) -> GroundStation:
        """Open the link, start the receive thread, wait for the autopilot's first heartbeat.

        Raises
        ------
        GcsError
            the link cannot be opened (bad URL, port in use).
        GcsTimeout
            no heartbeat from the autopilot within ``timeout_s``.
        """
        gs = cls(url, **kw)
        if not gs._heartbeat_event.wait(timeout_s):
            gs.close()
            raise GcsTimeout(
                f"no heartbeat from system {gs.target[0]} component {gs.target[1]} on {url} "
                f"within {timeout_s:g} s: is the autopilot running and sending there?")
        return gs

    def close(self) -> None:
        """Stop the receive thread and close the link. Idempotent."""
        if self._closed:
            return
        self._closed = True
        self._link.close()
        if self._thread is not threading.current_thread():
            self._thread.join(timeout=2.0)

    def __enter__(self) -> GroundStation:
        return self

    def __exit__(self, *exc: object) -> None:
        self.close()

    @property
    def link(self) -> Any:
        """The underlying :class:`protocols.Link` (counters in ``link.stats``)."""
        return self._link

    # ------------------------------------------------------------------ state
    def snapshot(self) -> VehicleSnapshot:
        """A copy of the current vehicle state."""
        with self._lock:
            age = time.monotonic() - self._last_heartbeat
            return replace(self._snap, heartbeat_age_s=age, connected=age < _HEARTBEAT_LOST_S,
                           actuator_outputs=list(self._snap.actuator_outputs))

    def add_listener(self, callback: Callable[[Any], None]) -> None:
        """Call ``callback(msg)`` for every received MAVLink message (in the receive thread:
        keep it short; exceptions are swallowed)."""
        self._listeners.append(callback)

    def remove_listener(self, callback: Callable[[Any], None]) -> None:
        """Stop calling ``callback`` for received messages (no error if not added)."""
        with contextlib.suppress(ValueError):
            self._listeners.remove(callback)

    def statustexts(self) -> list[str]:
        """Recent STATUSTEXT texts from the autopilot, oldest first."""
        with self._lock:
            return [t for _, t in self._statustexts]

    def wait_for(self, predicate: Callable[[VehicleSnapshot], bool],
                 timeout_s: float) -> VehicleSnapshot:
        """Poll the snapshot until ``predicate`` holds; raises GcsTimeout otherwise."""
        deadline = time.monotonic() + timeout_s
        while True:
            snap = self.snapshot()
            if predicate(snap):
                return snap
            if time.monotonic() >= deadline:
                raise GcsTimeout(f"condition not met within {timeout_s:g} s")
            if self._closed:
                raise GcsError("ground station closed")
            time.sleep(0.01)

    # ------------------------------------------------------------------ commands
    def command_long(self, command: int, params: Sequence[float], timeout_s: float = 1.5,
                     retries: int = 2) -> CommandOutcome:
        """Send COMMAND_LONG (params padded with NaN = default to 7) and wait for its ACK.

        Retries ``retries`` times after ``timeout_s`` without an ACK (``confirmation``
        increments). IN_PROGRESS ACKs extend the wait. ``result`` is None if no ACK came.
        """
        if len(params) > 7:
            raise GcsError(f"COMMAND_LONG takes at most 7 params, got {len(params)}")
        p = [float(x) for x in params] + [math.nan] * (7 - len(params))
        cmd = int(command)
        name = command_name(cmd)
        t0 = time.monotonic()
        ack = None
        for attempt in range(max(0, int(retries)) + 1):
            w = self._add_waiter(lambda m, c=cmd: m.get_type() == "COMMAND_ACK"
                                 and m.command == c and self._from_target(m))
            try:
                self._send(self._link.codec.command_long_encode(
                    self.target[0], self.target[1], cmd, min(attempt, 255), *p))
                deadline = time.monotonic() + timeout_s
                while w.event.wait(max(0.0, deadline - time.monotonic())):
                    ack = w.message
                    if ack.result != _RESULT_IN_PROGRESS:
                        break
                    w.event.clear()  # keep waiting for the final result
                    deadline = time.monotonic() + timeout_s
                    ack = None
            finally:
                self._remove_waiter(w)
            if ack is not None:
                break
        elapsed = time.monotonic() - t0
        result = None if ack is None else int(ack.result)
        with self._lock:
            detail = "; ".join(t for ts, t in self._statustexts if ts >= t0)
        return CommandOutcome(cmd, name, result, result_name(result), elapsed, detail)

    def arm(self, force: bool = False) -> CommandOutcome:
        """COMPONENT_ARM_DISARM(1) (``force``: PX4's 21196 magic, skips pre-arm checks)."""
        return self.command_long(CMD_ARM_DISARM, [1.0, ARM_FORCE_MAGIC if force else 0.0])

    def disarm(self, force: bool = False) -> CommandOutcome:
        """COMPONENT_ARM_DISARM(0)."""
        return self.command_long(CMD_ARM_DISARM, [0.0, ARM_FORCE_MAGIC if force else 0.0])

    def takeoff(self, altitude_m: float | None = None) -> CommandOutcome:
        """NAV_TAKEOFF to ``altitude_m`` above home (None = NaN = the autopilot's default,
        ``MIS_TAKEOFF_ALT``). param7 is AMSL, as PX4 reads it and QGroundControl sends it:
        home's altitude (HOME_POSITION, requested if not heard yet) plus ``altitude_m``."""
        alt = math.nan if altitude_m is None else float(altitude_m)
        if altitude_m is not None and not (math.isfinite(alt) and alt > 0.0):
            raise GcsError(f"takeoff altitude {altitude_m!r}: expected a positive height in m")
        if altitude_m is not None:
            if not math.isfinite(self.snapshot().home_amsl_m):
                self.command_long(512, [242.0])  # REQUEST_MESSAGE HOME_POSITION
                try:
                    self.wait_for(lambda s: math.isfinite(s.home_amsl_m), 2.0)
                except GcsTimeout:
                    raise GcsError("takeoff: no HOME_POSITION from the vehicle yet (param7 is "
                                   "AMSL); wait for a position fix and try again") from None
            alt += self.snapshot().home_amsl_m
        return self.command_long(CMD_NAV_TAKEOFF, [math.nan] * 6 + [alt])

    def download_mission(self, timeout_s: float = 2.0, retries: int = 3) -> list[Any]:
        """The vehicle's mission (MISSION_REQUEST_LIST, then MISSION_REQUEST_INT per item):
        the MISSION_ITEM_INT messages in order. Raises :class:`GcsTimeout` if an answer does
        not come after ``retries`` tries."""
        c = self._link.codec

        def ask(msg: Any, pred: Callable[[Any], bool]) -> Any:
            for _ in range(max(0, retries) + 1):
                w = self._add_waiter(lambda m: self._from_target(m) and pred(m))
                try:
                    self._send(msg)
                    if w.event.wait(timeout_s):
                        return w.message
                finally:
                    self._remove_waiter(w)
            raise GcsTimeout(f"mission download: no answer to {msg.get_type()} within "
                             f"{timeout_s:g} s")

        cnt = ask(c.mission_request_list_encode(*self.target, mav.MAV_MISSION_TYPE_MISSION),
                  lambda m: m.get_type() == "MISSION_COUNT"
                  and m.mission_type == mav.MAV_MISSION_TYPE_MISSION)
        items = []
        for seq in range(int(cnt.count)):
            items.append(ask(c.mission_request_int_encode(*self.target, seq,
                                                          mav.MAV_MISSION_TYPE_MISSION),
                             lambda m, s=seq: m.get_type() == "MISSION_ITEM_INT"
                             and m.seq == s))
        self._send(c.mission_ack_encode(*self.target, mav.MAV_MISSION_ACCEPTED,
                                        mav.MAV_MISSION_TYPE_MISSION))
        return items

    def land(self) -> CommandOutcome:
        """NAV_LAND at the current position."""
        return self.command_long(CMD_NAV_LAND, [])

    def transition(self, to: str) -> CommandOutcome:
        """DO_VTOL_TRANSITION to ``"fw"`` (fixed wing, MAV_VTOL_STATE_FW 4) or ``"mc"`` (3)."""
        states = {"fw": float(mav.MAV_VTOL_STATE_FW), "mc": float(mav.MAV_VTOL_STATE_MC)}
        key = str(to).strip().lower()
        if key not in states:
            raise GcsError(f"transition target {to!r}: expected 'fw' or 'mc'")
        return self.command_long(CMD_DO_VTOL_TRANSITION, [states[key]])

    def set_mode(self, mode: str) -> CommandOutcome:
        """DO_SET_MODE with a PX4 mode name (``AUTO.LOITER``, ``AUTO.LAND``, ``POSCTL`` ...)."""
        try:
            main, sub = mode_from_name(mode)
        except ValueError as exc:
            raise GcsError(str(exc)) from None
        flags = float(MAV_MODE_FLAG_CUSTOM_MODE_ENABLED)
        return self.command_long(CMD_DO_SET_MODE, [flags, float(main), float(sub)])

    def inject(self, actuator: str, loss: float | None = None, kind: str = "loss",
               ) -> CommandOutcome:
        """Inject a fault into an actuator or a group (``rotor_2b``, ``elevator``, ``ailerons``,
        ``rudders``, ``surfaces``, ``lift_rotors``, ``pushers``).

        ``kind``: ``loss`` (MAV_CMD_INJECT_PARTIAL_LOSS 59900, ``loss`` 0..1, 0 clears), ``off``,
        ``stuck`` or ``ok`` (MAV_CMD_INJECT_FAILURE 420 with that failure type). A group sends
        one command per actuator; the outcome is the first refusal, else the last ACK.
        """
        kind = str(kind).strip().lower()
        if kind == "loss":
            if loss is None or not (isinstance(loss, int | float) and math.isfinite(loss)
                                    and 0.0 <= float(loss) <= 1.0):
                raise GcsError(f"loss {loss!r}: expected a fraction in [0, 1] (0.5 = 50 %)")
        elif kind in FAILURE_TYPE:
            if loss is not None:
                raise GcsError(f"kind {kind!r} takes no loss (use kind='loss')")
        else:
            raise GcsError(f"fault kind {kind!r}: expected loss, off, stuck or ok")
        table = self._actuators or default_table()
        try:
            names = table.expand(actuator)
        except ValueError as exc:
            raise GcsError(str(exc)) from None
        t0 = time.monotonic()
        outcome: CommandOutcome | None = None
        for name in names:
            unit, inst = table.unit_instance(name)
            if kind == "loss":
                out = self.command_long(CMD_INJECT_PARTIAL_LOSS,
                                        [float(unit), float(inst), float(loss)])
            else:
                out = self.command_long(CMD_INJECT_FAILURE,
                                        [float(unit), float(FAILURE_TYPE[kind]), float(inst)])
            outcome = out
            if not out.accepted:
                break
        assert outcome is not None
        outcome.elapsed_s = time.monotonic() - t0
        return outcome

    # ------------------------------------------------------------------ parameters
    def param_get(self, name: str, timeout_s: float = 1.0, retries: int = 2) -> float:
        """Value of parameter ``name`` (INT32 decoded from PX4's bytewise encoding)."""
        msg = self._param_request(name, timeout_s, retries)
        return decode_param_value(msg.param_value, msg.param_type)

    def param_set(self, name: str, value: float, timeout_s: float = 1.0,
                  retries: int = 2) -> float:
        """Set ``name``; returns the value the autopilot echoed (raises GcsError if it kept a
        different value, e.g. out of range)."""
        pid = self._param_id(name)
        ptype = self._param_types.get(pid)
        if ptype is None:
            self.param_get(pid, timeout_s, retries)
            ptype = self._param_types[pid]
        v = float(value)
        if not math.isfinite(v):
            raise GcsError(f"{pid} = {value!r}: expected a finite number")
        if ptype == 6 and v != int(v):
            raise GcsError(f"{pid} is an integer parameter: {value!r} is not an integer")
        wire = encode_param_value(v, ptype)
        for _ in range(max(0, retries) + 1):
            w = self._add_waiter(lambda m: m.get_type() == "PARAM_VALUE" and self._from_target(m)
                                 and _param_id_of(m) == pid)
            try:
                self._send(self._link.codec.param_set_encode(
                    self.target[0], self.target[1], pid.encode(), wire, ptype))
                if w.event.wait(timeout_s):
                    echoed = decode_param_value(w.message.param_value, w.message.param_type)
                    if echoed != v and not (ptype != 6 and abs(echoed - v) <= 1e-6 * abs(v)):
                        raise GcsError(f"{pid} = {v:g} refused: the autopilot kept {echoed:g}")
                    return echoed
            finally:
                self._remove_waiter(w)
        raise GcsTimeout(f"no PARAM_VALUE echo for {pid} within {timeout_s:g} s "
                         f"({retries + 1} attempts)")

    def params(self, timeout_s: float = 5.0) -> dict[str, float]:
        """Every parameter (PARAM_REQUEST_LIST, then PARAM_REQUEST_READ of missing indices)."""
        got: dict[int, tuple[str, float]] = {}
        count = [-1]
        done = threading.Event()

        def on_msg(m: Any) -> None:
            if m.get_type() == "PARAM_VALUE" and self._from_target(m):
                count[0] = int(m.param_count)
                got[int(m.param_index)] = (_param_id_of(m),
                                           decode_param_value(m.param_value, m.param_type))
                if len(got) >= count[0]:
                    done.set()

        self.add_listener(on_msg)
        try:
            self._send(self._link.codec.param_request_list_encode(*self.target))
            deadline = time.monotonic() + timeout_s
            while not done.wait(0.3):
                if time.monotonic() >= deadline:
                    raise GcsTimeout(f"parameter list incomplete after {timeout_s:g} s: got "
                                     f"{len(got)} of {max(count[0], 0)}")
                if count[0] > 0:  # ask for what is missing
                    for i in range(count[0]):
                        if i not in got:
                            self._send(self._link.codec.param_request_read_encode(
                                *self.target, b"", i))
        finally:
            self.remove_listener(on_msg)
        return {name: value for _, (name, value) in sorted(got.items())}

    # ------------------------------------------------------------------ internals
    @staticmethod
    def _param_id(name: str) -> str:
        pid = str(name).strip()
        if not 0 < len(pid) <= 16 or not pid.isascii():
            raise GcsError(f"parameter name {name!r}: expected 1-16 ASCII characters")
        return pid

    def _param_request(self, name: str, timeout_s: float, retries: int) -> Any:
        pid = self._param_id(name)
        for _ in range(max(0, retries) + 1):
            w = self._add_waiter(lambda m: m.get_type() == "PARAM_VALUE" and self._from_target(m)
                                 and _param_id_of(m) == pid)
            try:
                self._send(self._link.codec.param_request_read_encode(
                    *self.target, pid.encode(), -1))
                if w.event.wait(timeout_s):
                    return w.message
            finally:
                self._remove_waiter(w)
        raise GcsTimeout(f"no PARAM_VALUE for {pid} within {timeout_s:g} s: unknown parameter "
                         "or autopilot not answering")

    def _from_target(self, m: Any) -> bool:
        return (m.get_srcSystem(), m.get_srcComponent()) == self.target

    def _send(self, msg: Any) -> None:
        if self._closed:
            raise GcsError("ground station closed")
        with self._send_lock:
            self._link.send(msg)

    def _add_waiter(self, predicate: Callable[[Any], bool]) -> _Waiter:
        w = _Waiter(predicate)
        with self._lock:
            self._waiters.append(w)
        return w

    def _remove_waiter(self, w: _Waiter) -> None:
        with self._lock, contextlib.suppress(ValueError):
            self._waiters.remove(w)

    def _rx_loop(self) -> None:
        next_hb = 0.0
        codec = self._link.codec
        while not self._closed:
            now = time.monotonic()
            if now >= next_hb:
                next_hb = now + 1.0
                # no peer yet on a udp-server: dropped and counted by the link
                with contextlib.suppress(Exception), self._send_lock:
                    self._link.send(codec.heartbeat_encode(
                        mav.MAV_TYPE_GCS, mav.MAV_AUTOPILOT_INVALID, 0, 0, mav.MAV_STATE_ACTIVE))
            try:
                msgs = self._link.recv(0.2)
            except Exception:  # closed under us
                if self._closed:
                    return
                time.sleep(0.05)
                continue
            for m in msgs:
                self._handle(m)

    def _handle(self, m: Any) -> None:
        if self._from_target(m):
            self._update(m)
        with self._lock:
            waiters = list(self._waiters)
        for w in waiters:
            if not w.event.is_set():
                try:
                    if w.predicate(m):
                        w.message = m
                        w.event.set()
                except Exception:
                    pass
        for cb in list(self._listeners):
            with contextlib.suppress(Exception):
                cb(m)

    def _update(self, m: Any) -> None:
        t = m.get_type()
        with self._lock:
            s = self._snap
            if t == "HEARTBEAT":
                self._last_heartbeat = time.monotonic()
                s.armed = bool(m.base_mode & MAV_MODE_FLAG_SAFETY_ARMED)
                s.system_status = int(m.system_status)
                s.mode_name = mode_name(m.custom_mode)
                self._heartbeat_event.set()
            elif t == "ATTITUDE":
                s.roll, s.pitch, s.yaw = m.roll, m.pitch, m.yaw
                s.rollspeed, s.pitchspeed, s.yawspeed = m.rollspeed, m.pitchspeed, m.yawspeed
                self._time_ms(s, m.time_boot_ms)
            elif t == "LOCAL_POSITION_NED":
                s.position_ned_m = (float(m.x), float(m.y), float(m.z))
                self._time_ms(s, m.time_boot_ms)
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
                self._time_ms(s, m.time_boot_ms)
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
                self._time_us(s, m.time_usec)
            elif t == "STATUSTEXT":
                text = self._statustext(m)
                if text is not None:
                    s.last_statustext = text
                    self._statustexts.append((time.monotonic(), text))
            elif t == "PARAM_VALUE":
                self._param_types[_param_id_of(m)] = int(m.param_type)
            elif t == "SYSTEM_TIME":
                self._time_ms(s, m.time_boot_ms)

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
        if len(raw) == 50:
            return None
        del self._chunks[text_id]
        return b"".join(parts[k] for k in sorted(parts)).decode("utf-8", "replace")

    @staticmethod
    def _time_ms(s: VehicleSnapshot, ms: int) -> None:
        s.time_boot_ms = int(ms)
        s.sim_time_s = ms * 1e-3

    @staticmethod
    def _time_us(s: VehicleSnapshot, us: int) -> None:
        s.sim_time_s = us * 1e-6
        s.time_boot_ms = int(us) // 1000


def _param_id_of(m: Any) -> str:
    pid = m.param_id
    if isinstance(pid, bytes | bytearray):
        pid = pid.decode(errors="replace")
    return pid.rstrip("\x00")

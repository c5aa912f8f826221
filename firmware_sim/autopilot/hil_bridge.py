"""The autopilot's end of the HIL link to the simulated vehicle (PX4 SITL style).

:class:`HilBridge` turns what the vehicle sends into the autopilot's inputs and the
autopilot's outputs into HIL_ACTUATOR_CONTROLS:

- GPS_GLOBAL_ORIGIN gives the geodetic origin of the NED frame (home), needed to decode
  positions; degE7 / mm are turned back into the decimal degrees and metres they came from.
- HIL_SENSOR and HIL_STATE_QUATERNION of the same ``time_usec`` form one control step: the
  navigation state is :func:`interface.decode_hil_state` of the HIL_STATE_QUATERNION, bit for
  bit, computed by :class:`~vtolftc.protocols.hil.HilStateDecoder` straight from the message (the
  autopilot has no estimator; HIL_SENSOR and HIL_GPS are kept for health flags and telemetry).
  On the fast path the link hands HIL_SENSOR and HIL_STATE_QUATERNION over as ``RawFrame``
  (``Link.defer``): the step is decoded from the frame's bytes in one compiled call
  (:class:`~vtolftc.protocols.hil_frames.HilStateFrameDecoder`, the same bits), and
  :attr:`HilBridge.last_sensor` / :attr:`HilBridge.last_state` make the message objects only
  when an observer (ULog, ground-station streams) asks for them.
- :meth:`send_controls` answers a step with ``controls[0:15]`` = :func:`interface.wire_commands`,
  ``mode`` = MAV_MODE_FLAG_SAFETY_ARMED when armed, ``flags`` bit 0 = lockstep.
- :meth:`forward_command` sends a fault-injection COMMAND_LONG to the vehicle (faults act in
  the vehicle, never in the controller); the vehicle's COMMAND_ACK and FAULT_INJECTION_STATUS
  come back through :attr:`fault_status` and :attr:`vehicle_acks`.

A 1 Hz HEARTBEAT on this link (from system 1, component 1) tells the vehicle the autopilot is
alive (also while it holds the simulation); the vehicle pins the address of the first one and
talks to that address only (:mod:`vtolftc.firmware_sim.vehicle.process`). The first heartbeat
goes out once the autopilot is warm (:meth:`HilBridge.tick`), just before the control loop
runs.

:meth:`drain` reads everything the link has (not one bounded batch): after a stall in real
time the autopilot steps on the newest state, never on one queued seconds ago.
"""

from __future__ import annotations

import collections
import time
from typing import Any

import numpy as np
from numpy.typing import NDArray

from vtolftc.firmware_sim.autopilot.interface import (
    HilState,
    NavState,
    wire_commands,
)
from vtolftc.protocols.fastpack import FramePacker
from vtolftc.protocols.fastparse import RawFrame
from vtolftc.protocols.generated import constants as mav
from vtolftc.protocols.hil import HIL_OUTPUTS, HilStateDecoder
from vtolftc.protocols.hil_frames import HilStateFrameDecoder, frame_time_usec, warm_up
from vtolftc.protocols.link import Link
from vtolftc.protocols.mavlink import dialect

__all__ = ["HilBridge"]

MAV_MODE_FLAG_SAFETY_ARMED = mav.MAV_MODE_FLAG_SAFETY_ARMED
_HEARTBEAT_PERIOD_S = 1.0
_ID_SENSOR = dialect().MAVLink_hil_sensor_message.id
_ID_STATE = dialect().MAVLink_hil_state_quaternion_message.id


class HilBridge:
    """Decode the vehicle's HIL stream into :class:`NavState` steps; send the controls."""

    def __init__(self, link: Link, *, lockstep: bool = True) -> None:
        self.link = link
        self.lockstep = lockstep
        self._home: tuple[float, float, float] | None = None
        self._last_sensor: Any = None
        self.last_gps: Any = None
        self._last_state: Any = None
        self.last_battery: Any = None
        self.last_rx_wall = -np.inf
        self.last_step_wall = -np.inf
        """monotonic time at which the last complete HIL step (sensor + state pair) came."""
        self.superseded = 0
        """Steps replaced by a newer one before the autopilot could step on them."""
        self.fault_status: Any = None
        self.vehicle_acks: collections.deque[Any] = collections.deque(maxlen=32)
        self._sensor_time: int | None = None
        self._pending: NavState | None = None
        self._next_heartbeat = 0.0
        self.steps_answered = 0
        self.resent = 0
        self._last_answer: tuple[int, bytes] | None = None
        self.decode_errors = 0
        self._decode: HilStateDecoder | None = None
        """Decodes HIL_STATE_QUATERNION about :attr:`home` (made when home is known)."""
        self._decode_frame: HilStateFrameDecoder | None = None
        """The same from the frame's bytes (the step's frames come as ``RawFrame``)."""
        link.defer((_ID_SENSOR, _ID_STATE))
        warm_up()  # compile the frame kernels now, not at the first step of a flight
        self._controls_packer = FramePacker(link.codec,
                                            dialect().MAVLink_hil_actuator_controls_message)
        self._u32 = np.zeros(HIL_OUTPUTS, dtype=np.float32)
        """The 16 output slots as the wire carries them (the unused ones stay 0)."""

    @property
    def home(self) -> tuple[float, float, float] | None:
        """Geodetic origin of the NED frame (lat [deg], lon [deg], alt AMSL [m]) from
        GPS_GLOBAL_ORIGIN; None until it came (no step can be decoded before)."""
        return self._home

    @home.setter
    def home(self, home: tuple[float, float, float] | None) -> None:
        self._home = home
        self._decode = None if home is None else HilStateDecoder(*home)
        self._decode_frame = None if home is None else HilStateFrameDecoder(*home)

    @property
    def last_sensor(self) -> Any:
        """The last HIL_SENSOR message (made from its frame when first asked for)."""
        m = self._last_sensor
        return m.message() if type(m) is RawFrame else m

    @last_sensor.setter
    def last_sensor(self, msg: Any) -> None:
        self._last_sensor = msg

    @property
    def last_state(self) -> Any:
        """The last HIL_STATE_QUATERNION message (made from its frame when first asked
        for)."""
        m = self._last_state
        return m.message() if type(m) is RawFrame else m

    @last_state.setter
    def last_state(self, msg: Any) -> None:
        self._last_state = msg

    # ------------------------------------------------------------------ input
    def handle(self, msg: Any) -> None:
        """Take one message from the vehicle (a message object, or a :class:`RawFrame` of
        the ids this bridge deferred on its link: HIL_SENSOR and HIL_STATE_QUATERNION, read
        from their bytes, their message objects made only if an observer asks)."""
        self.last_rx_wall = time.monotonic()
        if type(msg) is RawFrame:
            if msg.msg_id == _ID_SENSOR:
                self._last_sensor = msg
                self._sensor_time = frame_time_usec(msg)
                return
            if msg.msg_id == _ID_STATE:
                self._last_state = msg
                self._state(frame_time_usec(msg), msg)
                return
            msg = msg.message()
        t = msg.get_type()
        if t == "HIL_SENSOR":
            self._last_sensor = msg
            self._sensor_time = int(msg.time_usec)
        elif t == "HIL_STATE_QUATERNION":
            self._last_state = msg
            self._state(int(msg.time_usec), msg)
        elif t == "HIL_GPS":
            self.last_gps = msg
        elif t == "BATTERY_STATUS":
            self.last_battery = msg
        elif t == "GPS_GLOBAL_ORIGIN":
            home = (float(f"{msg.latitude * 1e-7:.7f}"), float(f"{msg.longitude * 1e-7:.7f}"),
                    float(f"{msg.altitude * 1e-3:.3f}"))
            if home != self._home:
                self.home = home
        elif t == "FAULT_INJECTION_STATUS":
            self.fault_status = msg
        elif t == "COMMAND_ACK":
            self.vehicle_acks.append(msg)

    def _state(self, t_us: int, msg: Any) -> None:
        """A HIL_STATE_QUATERNION at ``t_us`` (message or :class:`RawFrame`): the step when
        it pairs with the last HIL_SENSOR and is newer than the last answer."""
        decode = self._decode
        if decode is None:
            self.decode_errors += 1
            return
        if self._sensor_time != t_us:
            return  # a step is the pair; an unpaired state is not a step
        if self._last_answer is not None and t_us <= self._last_answer[0]:
            if t_us == self._last_answer[0]:  # the vehicle resent: our answer was lost
                self.link.send(self._last_answer[1])
                self.resent += 1
            return
        nav = None
        if type(msg) is RawFrame:
            assert self._decode_frame is not None  # made with decode
            nav = self._decode_frame(msg)
            if nav is None:  # not a rotation quaternion: the reference raises its error
                msg = msg.message()
        if nav is None:
            try:
                nav = decode(msg)
            except ValueError:
                self.decode_errors += 1
                return
        if self._pending is not None and self._pending.time_usec != t_us:
            self.superseded += 1
        self._pending = nav
        self.last_step_wall = self.last_rx_wall

    def drain(self, timeout_s: float = 0.0, max_reads: int = 64) -> int:
        """Handle every message the link has now (waiting up to ``timeout_s`` for the first);
        a newer step replaces a pending one. Returns the number of messages.

        Reads again only while the link may hold more (:attr:`Link.drained` false): the
        lockstep's one datagram a step costs one read, not a second, empty one (a failed
        non-blocking read and its exception, 2-4 us a step warm)."""
        link = self.link
        n = 0
        msgs = link.recv(timeout_s)
        for _ in range(max_reads):
            if not msgs:
                break
            for m in msgs:
                self.handle(m)
            n += len(msgs)
            if link.drained:
                break
            msgs = link.recv(0.0)
        return n

    @staticmethod
    def hil_state(msg: Any) -> HilState:
        """The wire fields of a HIL_STATE_QUATERNION message."""
        q = msg.attitude_quaternion
        return HilState(
            time_usec=int(msg.time_usec),
            attitude_quaternion=(float(q[0]), float(q[1]), float(q[2]), float(q[3])),
            rollspeed=float(msg.rollspeed), pitchspeed=float(msg.pitchspeed),
            yawspeed=float(msg.yawspeed), lat=int(msg.lat), lon=int(msg.lon), alt=int(msg.alt),
            vx=int(msg.vx), vy=int(msg.vy), vz=int(msg.vz), ind_airspeed=int(msg.ind_airspeed),
            true_airspeed=int(msg.true_airspeed), xacc=int(msg.xacc), yacc=int(msg.yacc),
            zacc=int(msg.zacc))

    def peek(self) -> NavState | None:
        """The navigation state of the step waiting for an answer, if any."""
        return self._pending

    def take(self) -> NavState | None:
        """Remove and return the waiting step's navigation state."""
        nav, self._pending = self._pending, None
        return nav

    @property
    def connected(self) -> bool:
        """True once the vehicle was heard within the last 2 s."""
        return time.monotonic() - self.last_rx_wall < 2.0

    # ------------------------------------------------------------------ output
    def send_controls(self, time_usec: int, commands: NDArray[np.float64], armed: bool) -> None:
        """HIL_ACTUATOR_CONTROLS answering the step at ``time_usec``: slot ``i`` =
        ``wire_commands(commands)[i]``, the unused slots 0, packed by one
        :class:`~vtolftc.protocols.fastpack.FramePacker` (the generated encoding's bytes)."""
        u = self._u32
        n = len(commands)
        if n > HIL_OUTPUTS:
            wire_commands(commands)  # raises its error
        u[:n] = commands  # float32 rounding, as wire_commands
        u[n:] = 0.0
        data = self._controls_packer.pack(int(time_usec), 1 if self.lockstep else 0,
                                          *u.tolist(),
                                          MAV_MODE_FLAG_SAFETY_ARMED if armed else 0)
        self._last_answer = (int(time_usec), data)
        self.link.send(data)
        self.steps_answered += 1

    def forward_command(self, msg: Any) -> None:
        """Send a fault-injection COMMAND_LONG on to the vehicle (same command and params)."""
        p = [msg.param1, msg.param2, msg.param3, msg.param4, msg.param5, msg.param6,
             msg.param7]
        self.link.send(self.link.codec.command_long_encode(0, 0, int(msg.command), 0, *p))

    def tick(self, now: float | None = None) -> None:
        """Send the 1 Hz HIL-link heartbeat when due (wall clock)."""
        now = time.monotonic() if now is None else now
        if now >= self._next_heartbeat:
            self._next_heartbeat = now + _HEARTBEAT_PERIOD_S
            self.link.send(self.link.codec.heartbeat_encode(
                mav.MAV_TYPE_VTOL_RESERVED2, mav.MAV_AUTOPILOT_PX4, 0, 0, mav.MAV_STATE_ACTIVE))

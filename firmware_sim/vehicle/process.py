"""The simulated vehicle as a process: a :class:`Vehicle` behind a MAVLink HIL link.

:class:`VehicleProcess` is the simulator's loop; the program around it is
:mod:`vtolftc.runners.processes.vehicle` (``python -m vtolftc.runners.processes.vehicle``).

Physics runs at 1 kHz (the vehicle's RK4 step); every 4 ms of simulated time (one control
period) the process sends, in one datagram, PX4-SITL style:

- HIL_SENSOR: :meth:`Vehicle.sensors` in HIL units (m/s^2, rad/s, gauss, hPa, deg C),
  ``fields_updated`` = 0x1FFF (accel, gyro, mag, baro, diff pressure, pressure alt, temp);
- HIL_GPS at 10 Hz (fix 3D, degE7, mm, cm/s), as PX4's simulators do;
- HIL_STATE_QUATERNION: the ground truth through
  :func:`vtolftc.firmware_sim.autopilot.interface.encode_hil_state` (true airspeed in both airspeed
  fields), the very encoding the in-process runner uses, so the autopilot sees bit-identical
  inputs in both;
- GPS_GLOBAL_ORIGIN (first datagram, then at 1 Hz): the geodetic origin of the NED frame, from
  which the autopilot decodes positions.

It receives HIL_ACTUATOR_CONTROLS: ``controls[0:15]`` are the 15 normalised commands in the
airframe's actuator order, ``mode`` bit 7 (MAV_MODE_FLAG_SAFETY_ARMED) the armed state (logged;
the autopilot is responsible for disarmed outputs), ``flags`` bit 0 lockstep.

Lockstep (default): the vehicle advances from ``t`` to ``t + 4 ms`` only once the controls with
``time_usec == t`` have arrived, so the simulation runs as fast as both processes allow and is
reproducible. The process ends cleanly (exit status 3) if nothing arrives from the autopilot
for ``--peer-timeout`` wall seconds (the autopilot sends a 1 Hz HEARTBEAT on this link while it
holds the simulation). Real-time mode (``--realtime``): free-running at wall-clock pace with the
latest controls received.

Link integrity: the vehicle pins its autopilot. Until then it answers nothing and ignores
everything but a HEARTBEAT from system 1, component 1 (MAV_COMP_ID_AUTOPILOT1); the source
address of the first one is pinned (UDP: the server then talks to that address only and drops,
counting, every datagram from another one; zenoh has no addresses, there the system and
component ids are checked). Ids and addresses prove nothing: any local process can send that
HEARTBEAT first and be pinned. With a signed HIL link (``signing``, the key from
``VTOLFTC_HIL_KEY``, :mod:`vtolftc.protocols.hil_signing`; ``vtolftc sitl`` makes a fresh key
per run) both ends sign every frame and the link drops every frame unsigned, badly signed or
replayed, so only a holder of the key can be pinned or be heard, over UDP and zenoh alike.
From then on only messages from system 1, component 1 count;
HIL_ACTUATOR_CONTROLS whose ``time_usec`` is not newer than the last applied controls, or lies
in the vehicle's future, are rejected (counted in ``vehicle_summary.json``); fault commands
come only from the pinned autopilot, which forwards them after its own SYS_FAILURE_EN and
signing checks.

Output watchdog (real time): if no valid controls arrive for ``--output-timeout`` wall seconds
(default 0.5), the actuators get the documented safe output instead of the last commands:
every lift rotor and pusher 0 (stopped), every control surface 0 (neutral). This is what
electronic speed controllers and servos do on signal loss with PX4's failsafe PWM values
(``PWM_MAIN_FAILn``): a flight termination, never a frozen attitude command. Logged as an
event; controls arriving again take over.

Latency knob (``--hil-delay-ms D``, ``--hil-loss P``): the controls are applied D ms of
simulated time after they arrived (a delay line in simulated time: exact in lockstep, and on
the wall clock in real time), and a fraction P of them is dropped (seeded by ``--seed``), so the
latency margin of the control loop can be measured in SITL (the in-process runner has a delay
line of the same kind).

Faults: COMMAND_LONG INJECT_FAILURE (420: OK 0 / OFF 1 / STUCK 2) and the dialect's
MAV_CMD_INJECT_PARTIAL_LOSS (59900, loss 0..1) forwarded by the autopilot (never sent to the
controller) act from the next physics step (in lockstep: exactly at the time of the step the
autopilot was answering). Units and instances map to actuators as
:mod:`vtolftc.protocols.failure_units` documents (MOTOR 1-8 lift rotors in airframe order, 9-10
pushers; SERVO 1-5 aileron_left, aileron_right, elevator, rudder_left, rudder_right; instance 0
= every instance of the unit). A new fault on an actuator replaces its previous one. Every
fault command is answered with COMMAND_ACK and FAULT_INJECTION_STATUS (also sent at 1 Hz).

Run folder (``--out DIR``): ``vehicle_truth.csv`` (simulated time, NED position and velocity,
roll/pitch/yaw, body rates, airspeed, then per actuator: position, effectiveness, command; one
row per control step, flushed every 0.5 s of simulated time), ``vehicle_events.jsonl`` (faults,
start/stop), ``vehicle_summary.json`` (link counters, steps, wall time).
"""

from __future__ import annotations

import collections
import contextlib
import math
import os
import sys
import time
from pathlib import Path
from typing import Any, TextIO

import numpy as np

from vtolftc.airframe.loader import Airframe, load_airframe
from vtolftc.base.jsonio import atomic_write_text, dumps
from vtolftc.firmware_sim.vehicle.battery import BatteryModel, vehicle_power_w
from vtolftc.firmware_sim.vehicle.fault_service import FaultInjectionService
from vtolftc.firmware_sim.vehicle.faults import Fault
from vtolftc.firmware_sim.vehicle.model import Vehicle
from vtolftc.firmware_sim.vehicle.sensors import SensorNoise
from vtolftc.firmware_sim.vehicle.state_encoder import StateEncoder
from vtolftc.firmware_sim.vehicle.truth_log import TruthLog
from vtolftc.protocols import SigningConfig, open_link
from vtolftc.protocols.failure_units import ActuatorTable
from vtolftc.protocols.fastparse import RawFrame
from vtolftc.protocols.generated import constants as mav
from vtolftc.protocols.hil_frames import actuator_controls
from vtolftc.protocols.mavlink import dialect
from vtolftc.telemetry.step_parts import StepParts
from vtolftc.telemetry.streamstats import DurationStats

__all__ = ["AUTOPILOT_COMPONENT_ID", "AUTOPILOT_SYSTEM_ID", "EXIT_PEER_LOST", "SAFE_OUTPUT",
           "VehicleProcess"]

CONTROL_PERIOD_USEC = 4000
VEHICLE_SYSTEM_ID = 1
VEHICLE_COMPONENT_ID = mav.MAV_COMP_ID_USER1  # the simulator, not the autopilot
FIELDS_ALL = 0x1FFF
EXIT_PEER_LOST = 3
_FLUSH_ROWS = 125
AUTOPILOT_SYSTEM_ID, AUTOPILOT_COMPONENT_ID = 1, 1
SAFE_OUTPUT = 0.0
"""Output-watchdog value of every actuator: rotors and pushers stopped, surfaces neutral."""


def _controls(msg: Any, n: int) -> tuple[int, int, bool, Any]:
    """HIL_ACTUATOR_CONTROLS' ``time_usec``, ``mode``, whether ``controls[:n]`` are all finite,
    and ``controls[:n]``: from the frame's bytes when the link deferred it (a ``RawFrame``),
    else from the message object (the same values)."""
    if type(msg) is RawFrame:
        return actuator_controls(msg, n)
    c = msg.controls[:n]
    return int(msg.time_usec), int(msg.mode), all(map(math.isfinite, c)), c


class VehicleProcess:
    """The vehicle side of the HIL link (see the module docstring)."""

    def __init__(self, link_url: str, *, airframe: Airframe | None = None,
                 lockstep: bool = True, seed: int = 0, noise: bool = False,
                 initial_state: np.ndarray | None = None, duration_s: float | None = None,
                 out_dir: Path | None = None, peer_timeout_s: float = 5.0,
                 connect_timeout_s: float = 60.0, gps_rate_hz: float = 10.0,
                 allow_remote: bool = False, log: TextIO | None = None,
                 parent_pid: int | None = None, output_timeout_s: float = 0.5,
                 hil_delay_ms: float = 0.0, hil_loss: float = 0.0,
                 signing: SigningConfig | None = None) -> None:
        self.airframe = airframe or load_airframe()
        self.parent_pid = parent_pid
        self._next_parent_check = 0.0
        self.spin_s = 0.0
        """Lockstep: poll this long without sleeping before blocking (wake-up latency)."""
        self.vehicle = Vehicle(self.airframe, state=initial_state, seed=seed,
                               noise=SensorNoise.typical() if noise else None)
        self.table = ActuatorTable.from_names(self.airframe.actuator_names)
        self.battery = BatteryModel(rho=self.airframe.air_density_kg_m3)
        self.lockstep = lockstep
        self.duration_usec = None if duration_s is None else round(duration_s * 1e6)
        self.peer_timeout_s = peer_timeout_s
        self.connect_timeout_s = connect_timeout_s
        self.log = log or sys.stderr
        self.signing = signing
        """MAVLink 2 signing of the HIL link (None: unsigned, the first autopilot wins)."""
        self.link = open_link(link_url, system_id=VEHICLE_SYSTEM_ID,
                              component_id=VEHICLE_COMPONENT_ID, allow_remote=allow_remote,
                              track_source=True, signing=signing,
                              zenoh_receive="channel")
        self.link.defer((dialect().MAVLink_hil_actuator_controls_message.id,))
        self.pinned: object = None
        """Source of the autopilot's first heartbeat (address, or "ids" on zenoh)."""
        self.rejected = {"not_pinned": 0, "foreign_ids": 0, "stale_controls": 0,
                         "future_controls": 0, "lost_injected": 0}
        self.output_timeout_s = output_timeout_s
        self.watchdog_tripped = False
        self.watchdog_trips = 0
        self._last_controls_wall = time.monotonic()
        self._last_controls_usec = -1
        self.delay_usec = round(max(0.0, hil_delay_ms) * 1000)
        self.loss = min(1.0, max(0.0, hil_loss))
        self._loss_rng = np.random.default_rng(seed + 7919)
        self._delay_line: collections.deque[tuple[int, np.ndarray]] = collections.deque()
        self.codec = self.link.codec
        n = self.airframe.n_actuators
        self.commands = np.zeros(n)
        self.armed = False
        self.steps = 0
        self.step_rtt_s = DurationStats()
        """Lockstep: wall time from sending a step's state to receiving its controls [s]
        (bounded memory: count, mean, max exact; quantiles to 0.5 %)."""
        self.parts = StepParts(("wait_and_read", "record_and_physics", "sensors_and_encode",
                                "send", "after_send"))
        """Lockstep: wall and CPU time per step's part: waiting for the controls and reading
        them (a spin included); the critical path until the next state is sent; then the
        bookkeeping (battery, truth log) that overlaps with the autopilot's work."""
        self.running = True
        self._last_peer = time.monotonic()
        self.out_dir = out_dir
        self.truth_log = (TruthLog(out_dir, self.airframe.actuator_names, _FLUSH_ROWS)
                          if out_dir is not None else None)
        """The run folder's truth and event files (None without ``out_dir``)."""
        self.fault_injection = FaultInjectionService(
            self.vehicle, self.table, self.codec, self.link.send, self._event, self.log)
        self.encoder = StateEncoder(self.vehicle, self.battery, self.codec, gps_rate_hz,
                                    self.fault_injection.status_msg,
                                    resign=signing is not None)
        """Encodes the state datagram sent to the autopilot each step."""
        self.t_wall0 = time.monotonic()
        self._cpu0: float | None = None

    @property
    def faults(self) -> dict[str, Fault]:
        """Active faults by actuator name (set by the fault-injection commands)."""
        return self.fault_injection.faults

    @property
    def change_count(self) -> int:
        """Changes of the fault set so far."""
        return self.fault_injection.change_count

    # ------------------------------------------------------------------ output
    def _event(self, event: str, text: str, **extra: Any) -> None:
        if self.truth_log is not None:
            self.truth_log.event(self.vehicle.time_usec * 1e-6, event, text, **extra)

    def _record(self, flush: bool = True) -> None:
        """Snapshot the truth of the current step (formatted at the next flush, off the
        lockstep's critical path)."""
        if self.truth_log is not None:
            v = self.vehicle
            self.truth_log.record(v.time_usec, v.x, float(v.fm[6]), v.eff, self.commands,
                                  flush)

    def again(self, datagram: bytes) -> bytes:
        """The last state datagram, to send again (see :meth:`StateEncoder.again`)."""
        return self.encoder.again(datagram)

    def state_datagram(self) -> bytes:
        """The state datagram of the current time (see :meth:`StateEncoder.datagram`)."""
        return self.encoder.datagram()

    def _step_battery(self) -> None:
        self.battery.step(CONTROL_PERIOD_USEC * 1e-6, vehicle_power_w(self.battery,
                                                                      self.vehicle))

    # ------------------------------------------------------------------ input
    def handle(self, msg: Any) -> bool:
        """Process one message; True if it is the autopilot's controls for the current step
        (lockstep). Anything not from the pinned autopilot is ignored (see the module
        docstring)."""
        kind = msg.get_type()
        from_ap = (msg.get_srcSystem() == AUTOPILOT_SYSTEM_ID
                   and msg.get_srcComponent() == AUTOPILOT_COMPONENT_ID)
        if self.pinned is None:
            # signed link: the link already dropped what is unsigned, badly signed or
            # replayed; the check here keeps that true whatever the link's configuration
            if kind == "HEARTBEAT" and from_ap and (self.signing is None or msg.get_signed()):
                src = self.link.source_of(msg)
                self.pinned = src if src is not None else "ids"
                if src is not None:
                    self.link.pin(src)
                how = "signed heartbeat" if self.signing is not None else "first heartbeat"
                self._event("pinned", f"autopilot pinned at {self.pinned} ({how})")
                self._last_peer = time.monotonic()
            else:
                self.rejected["not_pinned"] += 1
            return False
        if not from_ap:
            self.rejected["foreign_ids"] += 1
            return False
        self._last_peer = time.monotonic()
        if kind == "HIL_ACTUATOR_CONTROLS":
            t, mode, finite, c = _controls(msg, self.airframe.n_actuators)
            now_usec = self.vehicle.time_usec
            if t <= self._last_controls_usec:
                self.rejected["stale_controls"] += 1
                return False
            if t > now_usec:
                self.rejected["future_controls"] += 1
                return False
            self._last_controls_usec = t
            self._last_controls_wall = self._last_peer
            if self.watchdog_tripped:
                self.watchdog_tripped = False
                self._event("watchdog", "controls back: the autopilot has the actuators again")
            self.armed = bool(mode & 128)
            if self.loss > 0 and self._loss_rng.random() < self.loss:
                self.rejected["lost_injected"] += 1
            elif finite:
                if self.delay_usec:
                    self._delay_line.append((now_usec + self.delay_usec, np.array(c)))
                else:
                    self.commands[:] = c
            return t == now_usec
        if kind == "COMMAND_LONG":
            self.fault_injection.handle_command(msg)
        return False

    # ------------------------------------------------------------------ loops
    def wait_for_peer(self) -> bool:
        """Wait until the autopilot's HIL-link heartbeat pinned it, so replies have a
        destination. False on timeout or stop."""
        deadline = time.monotonic() + self.connect_timeout_s
        while self.running and time.monotonic() < deadline and not self._orphaned():
            for m in self.link.recv(0.2):
                self.handle(m)
            if self.pinned is not None:
                self._last_controls_wall = time.monotonic()
                return True
        return False

    def warm_up(self) -> None:
        """Compile (or load from numba's cache) the physics and sensor kernels on a throwaway
        vehicle before the autopilot is pinned, so that a real-time run does not stall at its
        first step on a fresh install."""
        v = Vehicle(self.airframe)
        for _ in range(2):  # the 1st packs the aero tables, the 2nd flies _take_and_step
            v.step(np.zeros(self.airframe.n_actuators), CONTROL_PERIOD_USEC // v.dt_usec)
        v.sensors()

    def _apply_due(self) -> None:
        """Delay line: the controls whose time has come (the newest of them wins)."""
        line = self._delay_line
        t = self.vehicle.time_usec
        while line and line[0][0] <= t:
            self.commands[:] = line.popleft()[1]

    def _watchdog(self, now: float) -> None:
        """Real time: the safe output after ``output_timeout_s`` without valid controls."""
        if (self.output_timeout_s > 0 and not self.watchdog_tripped
                and now - self._last_controls_wall > self.output_timeout_s):
            self.watchdog_tripped = True
            self.watchdog_trips += 1
            self.commands[:] = SAFE_OUTPUT
            self._delay_line.clear()
            text = (f"output watchdog: no controls for {self.output_timeout_s:g} s: rotors and "
                    "pushers stopped, surfaces neutral")
            self._event("watchdog", text)
            print(f"vehicle: t = {self.vehicle.time_usec * 1e-6:.3f} s: {text}", file=self.log,
                  flush=True)

    def _spin(self, link: Any) -> list[Any]:
        """Poll without sleeping for up to ``spin_s`` (see ``--spin-us``)."""
        end = time.perf_counter() + self.spin_s
        while True:
            msgs = link.recv(0.0)
            if msgs or time.perf_counter() >= end:
                return msgs

    def _orphaned(self) -> bool:
        """True if ``parent_pid`` was given and that process is gone (checked at 1 Hz)."""
        if self.parent_pid is None:
            return False
        now = time.monotonic()
        if now < self._next_parent_check:
            return False
        self._next_parent_check = now + 1.0
        try:
            os.kill(self.parent_pid, 0)
        except ProcessLookupError:
            print(f"vehicle: parent process {self.parent_pid} is gone: stopping",
                  file=self.log, flush=True)
            return True
        except PermissionError:
            return False
        return False

    def _done(self) -> bool:
        return self.duration_usec is not None and self.vehicle.time_usec >= self.duration_usec

    def run(self) -> int:
        """Run until the duration, a stop signal or the loss of the autopilot. Exit status."""
        self._event("start", f"vehicle process, {'lockstep' if self.lockstep else 'real time'}")
        try:
            self.warm_up()
            if not self.wait_for_peer():
                bad = self.link.stats.dropped_signature
                hint = (f" ({bad} frames with no or a wrong signature: is VTOLFTC_HIL_KEY the "
                        "same on both sides?)" if bad else "")
                print(f"vehicle: no autopilot on {self.link!r} within "
                      f"{self.connect_timeout_s:g} s{hint}", file=self.log, flush=True)
                return EXIT_PEER_LOST
            return self._run_lockstep() if self.lockstep else self._run_realtime()
        finally:
            self.close()

    def _run_lockstep(self) -> int:
        self._cpu0 = time.process_time()
        link = self.link
        v = self.vehicle
        parts = self.parts
        if self._done():
            return 0
        datagram = self.state_datagram()
        t_sent = parts.start()[0]
        link.send(datagram)
        parts.start()
        while self.running:
            got = False
            while not got:
                msgs = self._spin(link) if self.spin_s > 0 else None
                if not msgs:
                    msgs = link.recv(0.5)
                if not msgs:
                    if not self.running:
                        return 0
                    # lost on the way (e.g. sent before a zenoh subscriber matched) or the
                    # autopilot holds: send the same state again (it answers a step once)
                    link.send(self.again(datagram))
                    if self._orphaned():
                        return EXIT_PEER_LOST
                    if time.monotonic() - self._last_peer > self.peer_timeout_s:
                        print(f"vehicle: autopilot silent for {self.peer_timeout_s:g} s at "
                              f"t = {v.time_usec * 1e-6:.3f} s: stopping", file=self.log,
                              flush=True)
                        return EXIT_PEER_LOST
                    continue
                for m in msgs:
                    got = self.handle(m) or got
            self.step_rtt_s.add(parts.lap("wait_and_read")[0] - t_sent)
            if self.delay_usec:
                self._apply_due()
            self._record(flush=False)
            v.step(self.commands, CONTROL_PERIOD_USEC // v.dt_usec)
            self.steps += 1
            if self._done():
                self._step_battery()
                break
            # the power module's integration only feeds BATTERY_STATUS (5 Hz): before the
            # state datagram when that carries it, else after the send, while the autopilot
            # computes (the same values in the same order either way)
            battery_now = self.encoder.battery_due()
            if battery_now:
                self._step_battery()
            parts.lap("record_and_physics")
            datagram = self.state_datagram()
            t_sent = parts.lap("sensors_and_encode")[0]
            link.send(datagram)
            parts.lap("send")
            # bookkeeping while the autopilot computes
            if not battery_now:
                self._step_battery()
            if self.truth_log is not None:
                self.truth_log.between_steps()
            parts.end_step("after_send", self._last_controls_usec)
        return 0

    def _run_realtime(self) -> int:
        link = self.link
        v = self.vehicle
        period = CONTROL_PERIOD_USEC * 1e-6
        next_tick = time.monotonic()
        prev = next_tick
        while self.running and not self._done():
            link.send(self.state_datagram())
            next_tick += period
            while True:
                remaining = next_tick - time.monotonic()
                for m in link.recv(max(0.0, min(remaining, 0.002))):
                    self.handle(m)
                if remaining <= 0:
                    break
            now = time.monotonic()
            if now - prev > 0.1:  # this process was not running (suspended, starved): the
                # autopilot could not have answered meanwhile; do not count it as silence
                self._last_controls_wall += now - prev
                self._last_peer += now - prev
            prev = now
            if now - self._last_peer > self.peer_timeout_s or self._orphaned():
                print("vehicle: autopilot silent: stopping", file=self.log, flush=True)
                return EXIT_PEER_LOST
            if now - next_tick > 1.0:  # fell behind (suspended): resync
                next_tick = now
            if self.delay_usec:
                self._apply_due()
            self._watchdog(now)
            self._record()
            v.step(self.commands, CONTROL_PERIOD_USEC // v.dt_usec)
            self._step_battery()
            self.steps += 1
        return 0

    def close(self) -> None:
        """Flush the run folder and close the link. Idempotent."""
        wall = time.monotonic() - self.t_wall0
        summary = {
            "sim_time_s": self.vehicle.time_usec * 1e-6, "steps": self.steps,
            "wall_time_s": wall, "lockstep": self.lockstep,
            "faults": {n: {"kind": f.kind.value, "loss": f.loss, "start_s": f.start_s}
                       for n, f in self.faults.items()},
            "link": self.link.stats.as_dict(),
            "pinned_autopilot": None if self.pinned is None else str(self.pinned),
            "hil_signed": self.signing is not None,
            "rejected": dict(self.rejected), "watchdog_trips": self.watchdog_trips,
            "hil_delay_ms": self.delay_usec / 1000, "hil_loss": self.loss,
        }
        if self._cpu0 is not None and self.steps:
            # CPU time of the process in the lockstep loop per step (far less sensitive to the
            # machine's load than the wall times)
            summary["cpu_per_step_us"] = 1e6 * (time.process_time() - self._cpu0) / self.steps
        if self.step_rtt_s.n:
            summary["step_round_trip_us"] = self.step_rtt_s.summary(1e6)
            summary.update(self.parts.summary(self.steps))
        if self.truth_log is not None:
            self._event("stop", f"{self.steps} steps, t = {summary['sim_time_s']:.3f} s")
            with contextlib.suppress(Exception):
                self.truth_log.close()
            self.truth_log = None
            assert self.out_dir is not None
            atomic_write_text(self.out_dir / "vehicle_summary.json", dumps(summary))
        self.link.close()

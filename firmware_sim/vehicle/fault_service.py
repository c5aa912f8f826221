"""Fault injection on the vehicle side of the HIL link (PX4's SYS_FAILURE_EN commands).

MAV_CMD_INJECT_FAILURE (OK / OFF / STUCK) and MAV_CMD_INJECT_PARTIAL_LOSS (loss fraction) on
FAILURE_UNIT_MOTOR / FAILURE_UNIT_SERVO instances (:mod:`vtolftc.protocols.failure_units`;
instance 0 = every instance of the unit) set the simulated vehicle's faults. A new fault on an
actuator replaces its previous one; faults act from the next physics step. Each command is
answered with COMMAND_ACK and FAULT_INJECTION_STATUS.
"""

from __future__ import annotations

import math
from collections.abc import Callable
from typing import Any, TextIO

import numpy as np

from vtolftc.firmware_sim.vehicle.faults import Fault, FaultKind
from vtolftc.firmware_sim.vehicle.model import Vehicle
from vtolftc.protocols.failure_units import FAILURE_UNIT_MOTOR, FAILURE_UNIT_SERVO, ActuatorTable
from vtolftc.protocols.generated import constants as mav

__all__ = ["FaultInjectionService", "decimal_of_float32"]

CMD_INJECT_FAILURE = mav.MAV_CMD_INJECT_FAILURE
CMD_INJECT_PARTIAL_LOSS = mav.MAV_CMD_INJECT_PARTIAL_LOSS
FAILURE_TYPE_OK, FAILURE_TYPE_OFF = mav.FAILURE_TYPE_OK, mav.FAILURE_TYPE_OFF
FAILURE_TYPE_STUCK = mav.FAILURE_TYPE_STUCK
FAILURE_TYPE_PARTIAL_LOSS = mav.FAILURE_TYPE_PARTIAL_LOSS
MAV_RESULT_ACCEPTED, MAV_RESULT_DENIED = mav.MAV_RESULT_ACCEPTED, mav.MAV_RESULT_DENIED
MAV_RESULT_UNSUPPORTED, MAV_RESULT_FAILED = mav.MAV_RESULT_UNSUPPORTED, mav.MAV_RESULT_FAILED


def decimal_of_float32(x: float) -> float:
    """The shortest decimal that the float32 ``x`` stands for (0.2f -> 0.2, not
    0.20000000298...): COMMAND_LONG params are float32, and a loss typed as 0.2 must act as
    the 0.2 of an in-process run."""
    return float(np.format_float_positional(np.float32(x), unique=True))


class FaultInjectionService:
    """The vehicle's fault-injection commands and status.

    Parameters
    ----------
    vehicle : Vehicle
        The simulated vehicle whose faults are set.
    table : ActuatorTable
        Failure units and instances of the airframe's actuators.
    codec : Any
        The link's MAVLink codec (encodes acks and FAULT_INJECTION_STATUS).
    send : callable
        Sends one MAVLink message on the HIL link.
    on_event : callable
        ``on_event(kind, text, **extra)``: the run folder's event log.
    log : text stream
        Where a line per applied fault is printed.
    """

    def __init__(self, vehicle: Vehicle, table: ActuatorTable, codec: Any,
                 send: Callable[[Any], None], on_event: Callable[..., None],
                 log: TextIO) -> None:
        self.vehicle = vehicle
        self.table = table
        self.codec = codec
        self._send = send
        self._on_event = on_event
        self.log = log
        self.faults: dict[str, Fault] = {}
        """Active faults by actuator name."""
        self.change_count = 0
        """Changes of the fault set so far (FAULT_INJECTION_STATUS.change_count)."""

    def handle_command(self, msg: Any) -> None:
        """Answer one COMMAND_LONG (any command: unknown ones are UNSUPPORTED; a failure
        inside is FAILED, never an exception)."""
        try:
            self._command(msg)
        except Exception as exc:  # never let one command stop the simulation
            print(f"vehicle: command {msg.command} failed: {exc!r}", file=self.log)
            self._ack(int(msg.command), MAV_RESULT_FAILED, msg)

    def _command(self, msg: Any) -> None:
        cmd = int(msg.command)
        if cmd == CMD_INJECT_FAILURE:
            unit, ftype, inst = msg.param1, msg.param2, msg.param3
            kinds = {FAILURE_TYPE_OK: None, FAILURE_TYPE_OFF: FaultKind.OFF,
                     FAILURE_TYPE_STUCK: FaultKind.STUCK}
            if not math.isfinite(ftype) or int(ftype) not in kinds:
                return self._ack(cmd, MAV_RESULT_UNSUPPORTED, msg)
            result = self.apply(unit, inst, kinds[int(ftype)], 0.0)
        elif cmd == CMD_INJECT_PARTIAL_LOSS:
            loss = msg.param3
            if not (math.isfinite(loss) and 0.0 <= loss <= 1.0):
                return self._ack(cmd, MAV_RESULT_DENIED, msg)
            kind = None if loss == 0.0 else FaultKind.LOSS
            result = self.apply(msg.param1, msg.param2, kind, decimal_of_float32(loss))
        else:
            return self._ack(cmd, MAV_RESULT_UNSUPPORTED, msg)
        self._ack(cmd, result, msg)
        self._send(self.status_msg())
        return None

    def apply(self, unit: float, instance: float, kind: FaultKind | None, loss: float) -> int:
        """Set (``kind``) or clear (None) the fault of a unit's instance; a MAV_RESULT."""
        if not math.isfinite(unit) or int(unit) not in (FAILURE_UNIT_MOTOR, FAILURE_UNIT_SERVO):
            return MAV_RESULT_UNSUPPORTED
        names = self.table.motors if int(unit) == FAILURE_UNIT_MOTOR else self.table.servos
        inst = int(instance) if math.isfinite(instance) else -1
        if inst == 0:
            targets = list(names)
        elif 1 <= inst <= len(names) and inst == instance:
            targets = [names[inst - 1]]
        else:
            return MAV_RESULT_DENIED
        t_s = self.vehicle.time_usec * 1e-6
        for name in targets:
            if kind is None:
                self.faults.pop(name, None)
            else:
                self.faults[name] = Fault(name, kind, loss if kind is FaultKind.LOSS else 0.0,
                                          t_s)
        # rebuild the vehicle's fault set (a new fault replaces the actuator's previous one);
        # the faults act from the next physics step (Vehicle.step applies due faults first)
        self.vehicle.clear_faults()
        for f in self.faults.values():
            self.vehicle.inject(Fault(f.actuator, f.kind, f.loss, t_s))
        self.change_count += 1
        what = "cleared" if kind is None else (
            f"{loss:.0%} loss" if kind is FaultKind.LOSS else kind.value)
        self._on_event("fault", f"{', '.join(targets)}: {what}", actuators=targets,
                       kind="ok" if kind is None else kind.value, loss=loss)
        print(f"vehicle: t = {t_s:.3f} s: {', '.join(targets)}: {what}", file=self.log,
              flush=True)
        return MAV_RESULT_ACCEPTED

    def _ack(self, cmd: int, result: int, msg: Any) -> None:
        self._send(self.codec.command_ack_encode(
            cmd, result, 0, 0, msg.get_srcSystem(), msg.get_srcComponent()))

    def status_msg(self) -> Any:
        """FAULT_INJECTION_STATUS: fault type and loss per motor and servo instance."""
        motor_f, motor_l = [0] * 16, [0.0] * 16
        servo_f, servo_l = [0] * 16, [0.0] * 16
        for name, f in self.faults.items():
            unit, inst = self.table.unit_instance(name)
            ftype = {FaultKind.LOSS: FAILURE_TYPE_PARTIAL_LOSS, FaultKind.OFF: FAILURE_TYPE_OFF,
                     FaultKind.STUCK: FAILURE_TYPE_STUCK}[f.kind]
            loss = 1.0 if f.kind is FaultKind.OFF else (
                float(f.loss) if f.kind is FaultKind.LOSS else 0.0)
            if unit == FAILURE_UNIT_MOTOR:
                motor_f[inst - 1], motor_l[inst - 1] = ftype, loss
            else:
                servo_f[inst - 1], servo_l[inst - 1] = ftype, loss
        return self.codec.fault_injection_status_encode(
            self.vehicle.time_usec, self.change_count & 0xFFFF, len(self.table.motors),
            len(self.table.servos), motor_f, motor_l, servo_f, servo_l)

"""Command service of the ground-station endpoint (PX4: ``mavlink_command`` and the command
part of ``mavlink_receiver``).

:class:`CommandService` answers every COMMAND_LONG (and COMMAND_INT: params 1-4, x, y, z,
converted as PX4 does by :func:`.gcs_services.command_int_params`) addressed to (1, 1) or
broadcast with one COMMAND_ACK from (1, 1) on the link it came from, preceded by a STATUSTEXT
with the reason when there is one:

- flight commands (:data:`FLIGHT_COMMANDS`) go to :meth:`AutopilotAPI.command` in the control
  thread (through the endpoint's bounded queue; TEMPORARILY_REJECTED if it was full);
- INJECT_FAILURE (420) and MAV_CMD_INJECT_PARTIAL_LOSS (59900) are DENIED unless
  SYS_FAILURE_EN == 1, checked against the airframe's actuators (bad unit UNSUPPORTED, bad
  instance or loss DENIED, no vehicle TEMPORARILY_REJECTED), then forwarded to the vehicle
  over the HIL link by the control thread (never to the controller) and ACCEPTED;
- with signing on, arming and fault commands must be signed (DENIED otherwise);
- while the autopilot boots (:attr:`GcsEndpoint.ready` false) flight and fault commands are
  answered TEMPORARILY_REJECTED at once;
- SET_MESSAGE_INTERVAL (511), GET_MESSAGE_INTERVAL (510), REQUEST_MESSAGE (512) and the older
  requests PX4 answers the same way (520, 410, 528) are answered in the worker
  (:mod:`.gcs_streams`); anything else UNSUPPORTED. NaN params mean default.
"""

from __future__ import annotations

import math
from collections.abc import Sequence
from typing import Any

from vtolftc.firmware_sim.autopilot.gcs_link import Handler
from vtolftc.firmware_sim.autopilot.gcs_services import command_int_params
from vtolftc.firmware_sim.autopilot.gcs_streams import MSG
from vtolftc.firmware_sim.autopilot.gcs_telemetry import TELEMETRY_MSG
from vtolftc.firmware_sim.autopilot.interface import AutopilotStatus, CommandResult, FlightMode
from vtolftc.protocols.failure_units import FAILURE_UNIT_MOTOR, FAILURE_UNIT_SERVO
from vtolftc.protocols.generated import constants as mav
from vtolftc.protocols.link import Link

__all__ = ["FAULT_COMMANDS", "FLIGHT_COMMANDS", "CommandService", "command_label"]

SEVERITY_WARNING, SEVERITY_INFO = mav.MAV_SEVERITY_WARNING, mav.MAV_SEVERITY_INFO
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
"""Commands the autopilot acts on (the last five are the navigator's, see navigator.py)."""
FAULT_COMMANDS = (CMD_INJECT_FAILURE, CMD_INJECT_PARTIAL_LOSS)
"""Commands forwarded to the vehicle (fault injection)."""

#: Commands that ask for one message: REQUEST_MESSAGE (param1 the id) and the older ones PX4
#: still answers the same way (the message they stand for).
_REQUEST_ONE: dict[int, float] = {
    CMD_REQUEST_MESSAGE: math.nan,
    CMD_REQUEST_AUTOPILOT_CAPABILITIES: float(MSG["AUTOPILOT_VERSION"]),
    CMD_GET_HOME_POSITION: float(MSG["HOME_POSITION"]),
    CMD_REQUEST_FLIGHT_INFORMATION: float(TELEMETRY_MSG["FLIGHT_INFORMATION"]),
}


class CommandService:
    """COMMAND_LONG / COMMAND_INT (module docstring) for ``endpoint``, the owning GcsEndpoint
    (its autopilot ``ap``, ``hil``, ``actuators``, ``io``, ``streams``, ``services``,
    ``ready``, ``submit``, ``reply``, ``publish_status``, ``on_event``)."""

    HANDLES = ("COMMAND_LONG", "COMMAND_INT")
    """Message types handled here (in the endpoint's worker thread)."""

    def __init__(self, endpoint: Any) -> None:
        self.ep = endpoint
        self.answered = 0
        """COMMAND_ACKs sent."""

    def handlers(self) -> dict[str, Handler]:
        """Handler of each message type of :attr:`HANDLES` (``f(link_index, link, msg)``)."""
        return {"COMMAND_LONG": self.on_command_long, "COMMAND_INT": self.on_command_int}

    # ------------------------------------------------------------------ worker
    def on_command_long(self, index: int, link: Link, msg: Any) -> None:
        """COMMAND_LONG addressed to (1, 1) or broadcast."""
        if msg.target_system not in (0, 1) or msg.target_component not in (0, 1):
            return
        self.ep.io.seen_partner(msg)
        params = [msg.param1, msg.param2, msg.param3, msg.param4, msg.param5, msg.param6,
                  msg.param7]
        self.dispatch(index, link, msg, int(msg.command), [float(x) for x in params])

    def on_command_int(self, index: int, link: Link, msg: Any) -> None:
        """COMMAND_INT, converted as PX4 does (:func:`.gcs_services.command_int_params`) and
        answered like COMMAND_LONG."""
        if msg.target_system not in (0, 1) or msg.target_component not in (0, 1):
            return
        self.ep.io.seen_partner(msg)
        self.dispatch(index, link, msg, int(msg.command),
                      command_int_params(msg, self.ep.services.home_alt_m()))

    def ack(self, link: Link, msg: Any, cmd: int, result: int, reason: str) -> None:
        """Worker: STATUSTEXT with the reason (if any) and the COMMAND_ACK on ``link``."""
        if reason:
            self.ep.io.statustext(reason, SEVERITY_WARNING if result else SEVERITY_INFO, link)
        link.send(link.codec.command_ack_encode(cmd, int(result), 0, 0, msg.get_srcSystem(),
                                                msg.get_srcComponent()))
        self.answered += 1
        self.ep.on_event("ack", f"{command_label(cmd)} -> {CommandResult(result).name}"
                         + (f" ({reason})" if reason else ""))

    def dispatch(self, index: int, link: Link, msg: Any, cmd: int,
                 params: list[float]) -> None:
        """Worker: answer ``cmd`` here or queue it for the control thread."""
        ep = self.ep
        if ep.io.signing_required and cmd in (CMD_ARM_DISARM, *FAULT_COMMANDS) \
                and not msg.get_signed():
            self.ack(link, msg, cmd, CommandResult.DENIED, "signed command required")
            return

        def busy() -> None:
            self.ack(link, msg, cmd, CommandResult.TEMPORARILY_REJECTED,
                     "busy: too many requests")

        if cmd == CMD_ARM_DISARM and params[0] not in (0.0, 1.0):
            self.ack(link, msg, cmd, CommandResult.DENIED, "param1 must be 0 or 1")
            return
        if not ep.ready and (cmd in FLIGHT_COMMANDS or cmd in FAULT_COMMANDS):
            # booting: the control thread is compiling and polls nothing; answer now
            self.ack(link, msg, cmd, CommandResult.TEMPORARILY_REJECTED,
                     "autopilot still starting (compiling)")
            return
        if cmd in FLIGHT_COMMANDS:
            ep.submit(index, msg, lambda: self.flight_command(link, msg, cmd, params), busy)
            return
        if cmd in FAULT_COMMANDS:
            res, reason = self.fault_check(cmd, params)
            if res != CommandResult.ACCEPTED:
                self.ack(link, msg, cmd, res, reason)
                return
            ep.submit(index, msg, lambda: self.forward_fault(link, msg, cmd, params), busy)
            return
        if cmd == CMD_SET_MESSAGE_INTERVAL:
            res, reason = ep.streams.set_interval(index, params)
        elif cmd == CMD_GET_MESSAGE_INTERVAL:
            res, reason = ep.streams.get_interval(index, link, params[0])
        elif cmd in _REQUEST_ONE:
            mid = params[0] if cmd == CMD_REQUEST_MESSAGE else _REQUEST_ONE[cmd]
            if not math.isfinite(mid) or int(mid) not in MSG.values():
                res, reason = CommandResult.UNSUPPORTED, ""
            elif not ep.streams.send(int(mid), link):
                res, reason = CommandResult.TEMPORARILY_REJECTED, "no data yet"
            else:
                res, reason = CommandResult.ACCEPTED, ""
        else:
            res, reason = CommandResult.UNSUPPORTED, ""
        self.ack(link, msg, cmd, res, reason)

    # ------------------------------------------------------------------ control thread
    def flight_command(self, link: Link, msg: Any, cmd: int, params: list[float]) -> None:
        """Control thread: a flight command on the autopilot; the answer goes to the worker."""
        ep = self.ep
        before = ep.ap.status().message
        res = CommandResult(ep.ap.command(cmd, params))
        st = ep.ap.status()
        after = st.message
        reason = after if (res != CommandResult.ACCEPTED and after and after != before) else ""
        if res != CommandResult.ACCEPTED and not reason:
            reason = default_reason(cmd, res, st)
        ep.on_event("command", f"{command_label(cmd)} {format_params(params)}")

        def answer() -> None:
            if reason == after:
                ep.mark_reported(after)  # reported with the ACK: not again
            # else a new message (e.g. of an accepted command) goes out as a STATUSTEXT to
            # every link when the worker sees the status
            self.ack(link, msg, cmd, res, reason)

        ep.reply(answer)
        ep.publish_status(st)

    def forward_fault(self, link: Link, msg: Any, cmd: int, params: list[float]) -> None:
        """Control thread: forward an accepted fault command to the vehicle (the HIL link is
        the control thread's), so that in lockstep it acts at exactly this step."""
        ep = self.ep
        res, reason = self.fault_check(cmd, params)  # SYS_FAILURE_EN may have changed
        if res == CommandResult.ACCEPTED:
            ep.hil.forward_command(msg)
            ep.on_event("fault", f"{command_label(cmd)} {format_params(params)}")
        ep.reply(lambda: self.ack(link, msg, cmd, res, reason))

    def fault_check(self, cmd: int, p: list[float]) -> tuple[int, str]:
        """(MAV_RESULT, reason) of fault command ``cmd`` with params ``p`` now."""
        ep = self.ep
        if int(ep.ap.params.get("SYS_FAILURE_EN")) != 1:
            return CommandResult.DENIED, "fault injection disabled: set SYS_FAILURE_EN to 1"
        unit = p[0]
        if not math.isfinite(unit) or int(unit) not in (FAILURE_UNIT_MOTOR, FAILURE_UNIT_SERVO):
            return CommandResult.UNSUPPORTED, "unit must be motor 101 or servo 102"
        names = ep.actuators.motors if int(unit) == FAILURE_UNIT_MOTOR \
            else ep.actuators.servos
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
        if not ep.hil.connected:
            return CommandResult.TEMPORARILY_REJECTED, "no vehicle on the HIL link"
        return CommandResult.ACCEPTED, ""


def command_label(cmd: int) -> str:
    """Short name of a command for the run log (``CMD n`` if not one of ours)."""
    names = {CMD_ARM_DISARM: "ARM_DISARM", CMD_NAV_TAKEOFF: "TAKEOFF",
             CMD_DO_SET_MODE: "SET_MODE", CMD_DO_VTOL_TRANSITION: "VTOL_TRANSITION",
             CMD_NAV_LAND: "LAND", CMD_INJECT_FAILURE: "INJECT_FAILURE",
             CMD_INJECT_PARTIAL_LOSS: "INJECT_PARTIAL_LOSS",
             CMD_SET_MESSAGE_INTERVAL: "SET_MESSAGE_INTERVAL",
             CMD_REQUEST_MESSAGE: "REQUEST_MESSAGE", CMD_GET_HOME_POSITION: "GET_HOME_POSITION",
             CMD_REQUEST_FLIGHT_INFORMATION: "REQUEST_FLIGHT_INFORMATION"}
    return names.get(int(cmd), f"CMD {int(cmd)}")


def format_params(p: Sequence[float]) -> str:
    """``(1, nan, 0.5)``: command params for the run log."""
    return "(" + ", ".join("nan" if math.isnan(x) else f"{x:g}" for x in p) + ")"


def default_reason(cmd: int, res: CommandResult, st: AutopilotStatus | None) -> str:
    """Reason of a refusal the autopilot did not explain itself."""
    if res == CommandResult.UNSUPPORTED:
        return "not supported"
    if st is not None and not st.armed and cmd in (CMD_NAV_TAKEOFF, CMD_DO_VTOL_TRANSITION):
        return "vehicle is disarmed"
    if st is not None:
        return f"refused in mode {FlightMode(st.mode).name}"
    return "refused"

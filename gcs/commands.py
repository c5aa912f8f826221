"""Commands of the ground station: COMMAND_LONG with acknowledgement and retries (MAVLink's
command protocol) and the flight and fault-injection commands built on it.

Every command returns a :class:`CommandOutcome` with the COMMAND_ACK's result (``result``
None when no ACK came: a timeout) and, in ``detail``, the STATUSTEXT(s) the autopilot sent
while answering (e.g. why it refused). ``confirmation`` counts the retries; IN_PROGRESS ACKs
extend the wait.
"""

from __future__ import annotations

import math
import time
from collections.abc import Sequence
from dataclasses import dataclass

from vtolftc.gcs.actuators import default_table
from vtolftc.gcs.connection import GcsConnection, GcsError, GcsTimeout
from vtolftc.protocols import dialect
from vtolftc.protocols.generated import constants as mav
from vtolftc.protocols.px4 import MAV_MODE_FLAG_CUSTOM_MODE_ENABLED, mode_from_name

__all__ = [
    "CMD_ARM_DISARM",
    "CMD_DO_SET_MODE",
    "CMD_DO_VTOL_TRANSITION",
    "CMD_INJECT_FAILURE",
    "CMD_INJECT_PARTIAL_LOSS",
    "CMD_NAV_TAKEOFF",
    "CommandClient",
    "CommandOutcome",
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
RESULT_IN_PROGRESS = mav.MAV_RESULT_IN_PROGRESS


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


class CommandClient(GcsConnection):
    """The command side of a ground station (module docstring)."""

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
            w = self.add_waiter(lambda m, c=cmd: m.get_type() == "COMMAND_ACK"
                                and m.command == c and self.from_target(m))
            try:
                self.send(self.codec.command_long_encode(
                    self.target[0], self.target[1], cmd, min(attempt, 255), *p))
                deadline = time.monotonic() + timeout_s
                while w.event.wait(max(0.0, deadline - time.monotonic())):
                    ack = w.message
                    if ack.result != RESULT_IN_PROGRESS:
                        break
                    w.event.clear()  # keep waiting for the final result
                    deadline = time.monotonic() + timeout_s
                    ack = None
            finally:
                self.remove_waiter(w)
            if ack is not None:
                break
        elapsed = time.monotonic() - t0
        result = None if ack is None else int(ack.result)
        detail = "; ".join(self.cache.statustexts(since=t0))
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
        table = self.actuators or default_table()
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

"""PX4's auto-disarm on the ground and the flight record that FLIGHT_INFORMATION reports.

:class:`ArmingMonitor` follows the arming state and the flight mode of the autopilot, step by
step on simulated time, as PX4's commander does (``Commander::handleAutoDisarm``):

- **pre-flight**: armed and never taken off since arming (mode IDLE since the arming), the
  vehicle disarms after ``COM_DISARM_PRFLT`` seconds (PX4 default 10 s; zero or negative:
  never). "Taken off" here means that the mode left IDLE (a takeoff command or a mission
  started), which is when this autopilot starts to fly; PX4 waits for its land detector.
- **after landing**: armed, taken off since arming and back on the ground (the landing
  detector ended LAND: mode IDLE, rotors at idle), the vehicle disarms after
  ``COM_DISARM_LAND`` seconds (PX4 default 2 s; zero or negative: never), except while a
  mission is running and not finished (PX4's ``landed_amid_mission``: the mission goes on).
- every disarm (commanded, forced, automatic) increments ``COM_FLIGHT_UUID``, as PX4 does.

The STATUSTEXT of an automatic disarm is PX4's: "Disarmed by auto preflight disarming",
"Disarmed by landing". The flight record (:attr:`ArmingMonitor.arming_usec`,
:attr:`~ArmingMonitor.takeoff_usec`, :attr:`~ArmingMonitor.landing_ms`, simulated time since
boot; 0 = not yet since the last arming) is what MAVLink's FLIGHT_INFORMATION carries.
"""

from __future__ import annotations

from vtolftc.firmware_sim.autopilot.interface import FlightMode, ParameterStore, ParamType

__all__ = ["ARMING_PARAMS", "ArmingMonitor"]

ARMING_PARAMS: tuple[tuple[str, float, ParamType, float, float, str], ...] = (
    ("COM_DISARM_PRFLT", 10.0, ParamType.REAL32, -1.0, 20.0,
     "auto-disarm when armed and not taken off after this long, s (<= 0: never)"),
    ("COM_DISARM_LAND", 2.0, ParamType.REAL32, -1.0, 20.0,
     "auto-disarm this long after landing, s (<= 0: never)"),
    ("COM_FLIGHT_UUID", 0, ParamType.INT32, 0, 2**31 - 1,
     "flight number, incremented at every disarm (FLIGHT_INFORMATION.flight_uuid)"),
)
"""The parameters, PX4's names, defaults and ranges: (name, default, type, min, max, text)."""

_IDLE = FlightMode.IDLE


class ArmingMonitor:
    """Arming state, auto-disarm on the ground and the flight record (module docstring).

    Parameters
    ----------
    params
        the autopilot's parameter store; :data:`ARMING_PARAMS` are registered in it if
        missing and read at every check (a change acts at once).
    """

    def __init__(self, params: ParameterStore) -> None:
        for name, default, typ, lo, hi, desc in ARMING_PARAMS:
            if name not in params:
                params.register(name, default, typ, lo, hi, desc)
        self._params = params
        self.armed = False
        """Arming state as last seen by :meth:`track`."""
        self.taken_off = False
        """The mode left IDLE since the last arming."""
        self.arming_usec = 0
        """Simulated time of the last arming [us since boot] (0: never armed)."""
        self.takeoff_usec = 0
        """Simulated time of the takeoff since the last arming [us] (0: none yet)."""
        self.landing_ms = 0
        """Simulated time of the landing since the last arming [ms] (0: none yet)."""
        self._ground_since = -1  # us: armed on the ground (IDLE) since then; -1 not on it
        self.airborne = False
        """Armed, taken off and not back on the ground, as :meth:`track` last left it: a
        :meth:`check` that is still armed in a mode other than IDLE then changes nothing and
        returns "" (the autopilot skips that call, every control step of a flight)."""

    def track(self, now_usec: int, armed: bool, mode: FlightMode) -> None:
        """Follow arming, takeoff and landing at simulated time ``now_usec`` [us]."""
        if armed != self.armed:
            self.armed = armed
            if armed:
                self.arming_usec = max(1, int(now_usec))
                self.takeoff_usec = 0
                self.landing_ms = 0
                self.taken_off = False
                self._ground_since = int(now_usec)
            else:
                self._ground_since = -1
                uuid = int(self._params.get("COM_FLIGHT_UUID"))
                self._params.set("COM_FLIGHT_UUID", (uuid + 1) % 2**31)
        if not armed:
            self.airborne = False
            return
        if mode != _IDLE:
            if not self.taken_off:
                self.taken_off = True
                self.takeoff_usec = max(1, int(now_usec))
            self._ground_since = -1
        elif self._ground_since < 0:  # back on the ground: landed
            self._ground_since = int(now_usec)
            self.landing_ms = max(1, int(now_usec) // 1000)
        self.airborne = self.taken_off and self._ground_since < 0

    def check(self, now_usec: int, armed: bool, mode: FlightMode,
              mission_running: bool = False) -> str:
        """Track (:meth:`track`), then say whether to disarm now.

        Parameters
        ----------
        now_usec
            simulated time [us].
        armed, mode
            the autopilot's arming state and flight mode after this step's mode changes.
        mission_running
            a mission is running and not finished (no disarm after a landing then).

        Returns
        -------
        str
            PX4's STATUSTEXT for the disarm ("Disarmed by landing", "Disarmed by auto
            preflight disarming"), or "" to stay armed.
        """
        self.track(now_usec, armed, mode)
        if not armed or mode != _IDLE:
            return ""
        now = int(now_usec)
        if self.taken_off:
            if mission_running:  # PX4's landed_amid_mission: the timer does not run
                self._ground_since = now
                return ""
            limit_s, why = self._params.get("COM_DISARM_LAND"), "landing"
        else:
            limit_s, why = self._params.get("COM_DISARM_PRFLT"), "auto preflight disarming"
        if limit_s > 0.0 and now - self._ground_since >= round(limit_s * 1e6):
            return f"Disarmed by {why}"
        return ""

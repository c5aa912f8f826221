"""Failsafes and failure detection of the autopilot process, named and parameterised as in PX4.

:class:`FailsafeMonitor` is pure logic: the autopilot process feeds it every control step
(:meth:`FailsafeMonitor.on_step`, simulated time) and, on the wall clock, the ages of the HIL
data and of the ground-station link (:meth:`FailsafeMonitor.check`); it answers with
:class:`FailsafeEvent` records that the process reports (STATUSTEXT, the HEARTBEAT's MAV_STATE
through :attr:`FailsafeMonitor.mav_state`) and acts on (:attr:`FailsafeEvent.action`).

Parameters (registered in the autopilot's store, so ground stations read and set them):

``COM_DL_LOSS_T`` (s, default 10, 1..300), ``NAV_DLL_ACT`` (default 0)
    Data-link loss: armed and in the air, once a ground station was heard, no ground-station
    HEARTBEAT or command (signed, when signing is on) for COM_DL_LOSS_T wall seconds.
    Action NAV_DLL_ACT: 0 none (report only), 1 hold (AUTO.LOITER: TAKEOFF / LAND stop and
    hover, hover and fixed-wing go on), 2 return (AUTO.RTL of the navigator: climb or descend
    to RTL_RETURN_ALT, fly home, land; where RTL is refused, e.g. no home yet, it lands),
    3 land (from fixed-wing: back transition first). PX4 allows
    COM_DL_LOSS_T from 5 s; 1 s is allowed here so that tests stay short. Regained: reported,
    the action stays.
``COM_HIL_LOSS_T`` (s, default 0.5, 0.05..10), a vtol-ftc parameter in PX4's style
    HIL / sensor data loss: no HIL_SENSOR + HIL_STATE_QUATERNION step for COM_HIL_LOSS_T wall
    seconds while armed. MAV_STATE_EMERGENCY, STATUSTEXT, action land (back transition first
    in fixed-wing) in real time. In lockstep the vehicle's simulated time stands still while it
    is silent (the aircraft cannot move), so the loss is reported but no action is taken
    (and the time-out is at least 1.5 s, as the waiting vehicle repeats a step every 0.5 s).
    Data back: reported; the landing goes on.
``FD_FAIL_R``, ``FD_FAIL_P`` (deg, default 60, 0 = off), ``FD_FAIL_R_TTRI``, ``FD_FAIL_P_TTRI``
    (s, default 0.3): attitude failure (PX4's failure detector): |roll| or |pitch| beyond the
    limit for longer than the trigger time, in the air. MAV_STATE_EMERGENCY and STATUSTEXT;
    no action (PX4's default without flight termination).
Crash detection (no parameter; the criterion of :mod:`vtolftc.telemetry.metrics`): ground
    contact in a flying mode (hover, transitions, fixed-wing), i.e. less than 0.5 m above the
    altitude at arming after having been more than 2 m above it, or a non-finite navigation
    state.
    MAV_STATE_EMERGENCY, STATUSTEXT, action ``disarm`` (the motors are stopped on the ground).

The HEARTBEAT reports MAV_STATE_EMERGENCY while an emergency condition holds (HIL data lost,
attitude failure, crash), MAV_STATE_CRITICAL while a failsafe action is in progress (after
data-link loss, or after the HIL data came back); everything clears on disarm.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

from vtolftc.base.rotation import quat_to_euler
from vtolftc.firmware_sim.autopilot.interface import (
    AutopilotStatus,
    FlightMode,
    NavState,
    ParameterStore,
    ParamType,
)
from vtolftc.protocols.generated import constants as mav

__all__ = ["FAILSAFE_PARAMS", "FailsafeEvent", "FailsafeMonitor", "register_failsafe_params"]

MAV_STATE_CRITICAL, MAV_STATE_EMERGENCY = mav.MAV_STATE_CRITICAL, mav.MAV_STATE_EMERGENCY
SEVERITY_EMERGENCY, SEVERITY_CRITICAL = mav.MAV_SEVERITY_EMERGENCY, mav.MAV_SEVERITY_CRITICAL
SEVERITY_WARNING, SEVERITY_INFO = mav.MAV_SEVERITY_WARNING, mav.MAV_SEVERITY_INFO

LOCKSTEP_HIL_LOSS_MIN_S = 1.5
"""Least HIL-loss time-out in lockstep, s: the vehicle repeats a state every 0.5 s while it
waits, so a silence shorter than this is no loss."""
DLL_NONE, DLL_HOLD, DLL_RETURN, DLL_LAND = 0, 1, 2, 3

FAILSAFE_PARAMS: tuple[tuple[str, float, ParamType, float, float, str], ...] = (
    ("COM_DL_LOSS_T", 10.0, ParamType.REAL32, 1.0, 300.0,
     "data-link loss time-out, s (ground-station heartbeats)"),
    ("NAV_DLL_ACT", 0, ParamType.INT32, 0, 3,
     "data-link loss action: 0 none, 1 hold, 2 return to launch, 3 land"),
    ("COM_HIL_LOSS_T", 0.5, ParamType.REAL32, 0.05, 10.0,
     "HIL/sensor data loss time-out, s (then land)"),
    ("FD_FAIL_R", 60, ParamType.INT32, 0, 180, "attitude failure: roll limit, deg (0 off)"),
    ("FD_FAIL_P", 60, ParamType.INT32, 0, 180, "attitude failure: pitch limit, deg (0 off)"),
    ("FD_FAIL_R_TTRI", 0.3, ParamType.REAL32, 0.02, 5.0, "attitude failure: roll time, s"),
    ("FD_FAIL_P_TTRI", 0.3, ParamType.REAL32, 0.02, 5.0, "attitude failure: pitch time, s"),
)
"""Name, default, type, minimum, maximum, description of every failsafe parameter."""

_FLYING = (FlightMode.HOVER, FlightMode.FRONT_TRANSITION, FlightMode.FIXED_WING,
           FlightMode.BACK_TRANSITION)


@dataclass(frozen=True)
class FailsafeEvent:
    """Something a failsafe detected: report ``text`` at ``severity``; do ``action``.

    ``action``: ``"land"``, ``"hold"``, ``"disarm"`` or ``""`` (report only).
    """

    name: str
    text: str
    severity: int
    action: str = ""


def register_failsafe_params(params: ParameterStore) -> None:
    """Register the failsafe parameters in ``params`` (those missing; idempotent)."""
    for name, default, typ, lo, hi, desc in FAILSAFE_PARAMS:
        if name not in params:
            params.register(name, default, typ, lo, hi, desc)


class FailsafeMonitor:
    """The failsafe state machine (see the module docstring).

    Parameters
    ----------
    params
        the autopilot's parameter store (the parameters are registered if missing).
    realtime
        the vehicle runs on the wall clock (HIL loss then lands the aircraft).
    """

    def __init__(self, params: ParameterStore, *, realtime: bool) -> None:
        register_failsafe_params(params)
        self.params = params
        self.realtime = realtime
        self.dll_lost = False
        self.hil_lost = False
        self.attitude_failed = False
        self.crashed = False
        self.action_taken = False
        self._gcs_seen = False
        self._armed = False
        self._ground_alt = math.nan
        self._was_high = False
        self._roll_since: int | None = None
        self._pitch_since: int | None = None

    # ------------------------------------------------------------------ state
    @property
    def mav_state(self) -> int | None:
        """MAV_STATE to report (None = normal)."""
        if self.hil_lost or self.attitude_failed or self.crashed:
            return MAV_STATE_EMERGENCY
        if self.dll_lost or self.action_taken:
            return MAV_STATE_CRITICAL
        return None

    def _clear(self) -> None:
        self.dll_lost = self.hil_lost = self.attitude_failed = self.crashed = False
        self.action_taken = False
        self._was_high = False
        self._roll_since = self._pitch_since = None

    # ------------------------------------------------------------------ per control step
    def on_step(self, nav: NavState, st: AutopilotStatus) -> list[FailsafeEvent]:
        """Attitude failure and crash detection on one control step (simulated time)."""
        out: list[FailsafeEvent] = []
        if st.armed and not self._armed:
            self._clear()
            self._ground_alt = -float(nav.pos_ned_m[2])
        self._armed = bool(st.armed)
        if not st.armed:
            if self.mav_state is not None:
                self._clear()
            return out
        h = -float(nav.pos_ned_m[2]) - self._ground_alt
        roll, pitch, _ = quat_to_euler(nav.q_wxyz)
        finite = math.isfinite(h) and math.isfinite(roll) and math.isfinite(pitch)
        flying = st.mode in _FLYING
        if h > 2.0:
            self._was_high = True
        if not self.crashed and (not finite or (flying and self._was_high and h < 0.5)):
            self.crashed = True
            out.append(FailsafeEvent(
                "crash", f"crash detected: ground contact in {FlightMode(st.mode).name}"
                if finite else "crash detected: invalid navigation state",
                SEVERITY_EMERGENCY, "disarm"))
            return out
        if not finite or st.mode == FlightMode.IDLE:
            return out
        t = int(nav.time_usec)
        p = self.params
        for axis, angle, lim_name, ttri_name in (("roll", roll, "FD_FAIL_R", "FD_FAIL_R_TTRI"),
                                                 ("pitch", pitch, "FD_FAIL_P",
                                                  "FD_FAIL_P_TTRI")):
            lim = p.get(lim_name)
            since_attr = f"_{axis}_since"
            if lim > 0 and abs(angle) > math.radians(lim):
                since = getattr(self, since_attr)
                if since is None:
                    setattr(self, since_attr, t)
                elif (t - since) * 1e-6 >= p.get(ttri_name) and not self.attitude_failed:
                    self.attitude_failed = True
                    out.append(FailsafeEvent(
                        "attitude", f"attitude failure: {axis} {math.degrees(angle):.0f} deg "
                        f"beyond {lim:.0f} deg", SEVERITY_EMERGENCY))
            else:
                setattr(self, since_attr, None)
        return out

    # ------------------------------------------------------------------ wall clock
    def check(self, *, armed: bool, in_air: bool, fixed_wing: bool, hil_age_s: float,
              gcs_age_s: float) -> list[FailsafeEvent]:
        """Data-link and HIL-data loss on the wall clock.

        Parameters
        ----------
        armed, in_air, fixed_wing
            the autopilot's state.
        hil_age_s
            wall seconds since the last HIL step arrived (real time), since the
            vehicle was last heard (lockstep); inf = never.
        gcs_age_s
            wall seconds since the last ground-station heartbeat (inf = never).
        """
        out: list[FailsafeEvent] = []
        p = self.params
        if math.isfinite(gcs_age_s):
            self._gcs_seen = True
        # ground-station link
        dl_t = p.get("COM_DL_LOSS_T")
        if self._gcs_seen and gcs_age_s > dl_t:
            if not self.dll_lost and armed and in_air:
                self.dll_lost = True
                act = int(p.get("NAV_DLL_ACT"))
                action, what = {DLL_NONE: ("", "no action (NAV_DLL_ACT 0)"),
                                DLL_HOLD: ("hold", "hold"),
                                DLL_RETURN: ("rtl", "return to launch"),
                                DLL_LAND: ("land", "landing")}.get(act, ("", "?"))
                if action == "land" and fixed_wing:
                    what += " (back transition first)"
                self.action_taken = self.action_taken or bool(action)
                out.append(FailsafeEvent(
                    "datalink", f"data link lost for {dl_t:g} s: {what}", SEVERITY_CRITICAL,
                    action))
        elif self.dll_lost and gcs_age_s <= dl_t:
            self.dll_lost = False
            out.append(FailsafeEvent("datalink", "data link regained", SEVERITY_INFO))
        # HIL / sensor data
        hil_t = p.get("COM_HIL_LOSS_T")
        if not self.realtime:  # the lockstep vehicle repeats a step every 0.5 s it waits
            hil_t = max(hil_t, LOCKSTEP_HIL_LOSS_MIN_S)
        if armed and hil_age_s > hil_t:
            if not self.hil_lost:
                self.hil_lost = True
                if self.realtime:
                    self.action_taken = True
                    what = "landing" + (" (back transition first)" if fixed_wing else "")
                else:
                    what = "lockstep: the simulation waits"
                out.append(FailsafeEvent(
                    "hil", f"sensor/HIL data lost for {hil_t:g} s: {what}", SEVERITY_EMERGENCY,
                    "land" if self.realtime else ""))
        elif self.hil_lost and hil_age_s <= hil_t:
            self.hil_lost = False
            out.append(FailsafeEvent("hil", "sensor/HIL data back", SEVERITY_WARNING))
        return out

"""Flight-mode state machine of the autopilot (no control law here, only the logic).

Modes (:class:`~vtolftc.firmware_sim.autopilot.interface.FlightMode`) and how they change:

=================== ==================================================================
IDLE                on the ground, disarmed or armed (rotors idle). ``arm`` / ``disarm``;
                    ``takeoff`` (armed) -> TAKEOFF.
TAKEOFF             multicopter climb to the takeoff altitude -> HOVER when within
                    ``TAKEOFF_TOL_M`` of it.
HOVER               multicopter position and altitude hold. ``transition(FW)`` ->
                    FRONT_TRANSITION; ``land`` -> LAND.
FRONT_TRANSITION    pusher ramps up, lift rotors hold altitude, wing takes over; -> FIXED_WING
                    when the airspeed reaches ``VT_ARSP_TRANS``; if it has not within
                    ``VT_TRANS_TMOUT`` seconds -> HOVER (quad-chute, with a message).
                    ``transition(MC)`` -> BACK_TRANSITION.
FIXED_WING          wing-borne cruise. ``transition(MC)`` -> BACK_TRANSITION; ``land`` ->
                    BACK_TRANSITION then LAND.
BACK_TRANSITION     pusher off, decelerate, rotors take over -> HOVER (or LAND) when the
                    airspeed is below ``VT_B_TRANS_ARSP`` or after ``VT_B_TRANS_DUR``.
LAND                multicopter descent -> IDLE once landed, still armed (rotors at idle:
                    the autopilot disarms ``COM_DISARM_LAND`` seconds later, as PX4;
                    :mod:`.arming`).
=================== ==================================================================

Commands that are not allowed in the current state are answered ``DENIED`` (and change
nothing). PX4's custom-mode numbers for the heartbeat are given by :func:`px4_custom_mode`.
"""

from __future__ import annotations

from dataclasses import dataclass, field

from vtolftc.firmware_sim.autopilot.interface import (
    CommandResult,
    FlightMode,
    LandedState,
    VtolState,
)

__all__ = [
    "AUTO_EXIT_MODES",
    "MC_MODES",
    "PX4_MAIN",
    "PX4_SUB_AUTO",
    "ModeMachine",
    "landed_state",
    "px4_custom_mode",
    "vtol_state",
]

#: Modes flown as a multicopter.
MC_MODES = frozenset({FlightMode.TAKEOFF, FlightMode.HOVER, FlightMode.LAND})

#: PX4 main modes (custom_mode >> 16 & 0xff) and AUTO sub modes (custom_mode >> 24).
PX4_MAIN = {"MANUAL": 1, "ALTCTL": 2, "POSCTL": 3, "AUTO": 4, "ACRO": 5, "OFFBOARD": 6,
            "STABILIZED": 7}
PX4_SUB_AUTO = {"READY": 1, "TAKEOFF": 2, "LOITER": 3, "MISSION": 4, "RTL": 5, "LAND": 6}

#: Modes that :meth:`ModeMachine.update` may leave by itself (take-off altitude reached,
#: transition complete or timed out, back transition complete, landed); in the others its
#: step only advances the clock (:meth:`ModeMachine.advance`).
AUTO_EXIT_MODES = frozenset({FlightMode.TAKEOFF, FlightMode.FRONT_TRANSITION,
                             FlightMode.BACK_TRANSITION, FlightMode.LAND})

TAKEOFF_TOL_M = 0.5


def px4_custom_mode(mode: FlightMode) -> int:
    """PX4 custom mode (``main << 16 | sub << 24``) that best describes ``mode`` alone (the
    navigator refines it: :meth:`.navigator.Navigator.custom_mode`). On the ground PX4
    reports Hold (AUTO.LOITER), not AUTO.READY (which pymavlink and MAVProxy do not know)."""
    main, sub = PX4_MAIN["AUTO"], PX4_SUB_AUTO["LOITER"]
    if mode == FlightMode.TAKEOFF:
        sub = PX4_SUB_AUTO["TAKEOFF"]
    elif mode == FlightMode.LAND:
        sub = PX4_SUB_AUTO["LAND"]
    return (main << 16) | (sub << 24)


def vtol_state(mode: FlightMode) -> VtolState:
    """MAV_VTOL_STATE of a mode."""
    if mode == FlightMode.FRONT_TRANSITION:
        return VtolState.TRANSITION_TO_FW
    if mode == FlightMode.BACK_TRANSITION:
        return VtolState.TRANSITION_TO_MC
    if mode == FlightMode.FIXED_WING:
        return VtolState.FW
    return VtolState.MC


#: FlightMode members as module constants for ``update`` (every control step; an Enum
#: class attribute costs ~75 ns in Python 3.11).
_M_BACK_TRANSITION = FlightMode.BACK_TRANSITION
_M_FRONT_TRANSITION = FlightMode.FRONT_TRANSITION
_M_LAND = FlightMode.LAND
_M_TAKEOFF = FlightMode.TAKEOFF


_LANDED_STATES = {FlightMode.IDLE: LandedState.ON_GROUND,
                  FlightMode.TAKEOFF: LandedState.TAKEOFF, FlightMode.LAND: LandedState.LANDING}


def landed_state(mode: FlightMode) -> LandedState:
    """MAV_LANDED_STATE of a mode."""
    return _LANDED_STATES.get(mode, LandedState.IN_AIR)


@dataclass
class ModeMachine:
    """Mode, arming state and timers; the autopilot asks it what to do and feeds it events.

    ``events`` collects (time_usec, text) of every change, for the status message and logs.
    """

    mode: FlightMode = FlightMode.IDLE
    armed: bool = False
    mode_since_usec: int = 0
    now_usec: int = 0
    land_after_back_transition: bool = False
    events: list[tuple[int, str]] = field(default_factory=list)

    def _say(self, text: str) -> None:
        self.events.append((self.now_usec, text))

    def set_mode(self, mode: FlightMode, why: str = "") -> None:
        """Enter ``mode`` now (no check: the caller decided)."""
        if mode != self.mode:
            old = self.mode
            self.mode = mode
            self.mode_since_usec = self.now_usec
            self._say(f"mode {old.name} -> {mode.name}" + (f" ({why})" if why else ""))

    def time_in_mode_s(self) -> float:
        """Time since the current mode was entered (s, simulated time)."""
        return (self.now_usec - self.mode_since_usec) * 1e-6

    @property
    def in_air(self) -> bool:
        """True in every mode but IDLE (the machine's notion of flying)."""
        return self.mode != FlightMode.IDLE

    # -- commands ---------------------------------------------------------------------------
    def arm(self) -> CommandResult:
        """Arm on the ground (IDLE); already armed is accepted, in any other mode denied."""
        if self.armed:
            return CommandResult.ACCEPTED
        if self.mode != FlightMode.IDLE:
            return CommandResult.DENIED
        self.armed = True
        self._say("armed")
        return CommandResult.ACCEPTED

    def disarm(self, force: bool) -> CommandResult:
        """Disarm and go to IDLE; in the air only with ``force`` (else DENIED).

        Already disarmed is accepted.
        """
        if not self.armed:
            return CommandResult.ACCEPTED
        if self.mode != FlightMode.IDLE and not force:
            return CommandResult.DENIED
        self.armed = False
        self.set_mode(FlightMode.IDLE, "disarmed" + (" (forced)" if force else ""))
        self._say("disarmed" + (" in the air (forced)" if force and self.in_air else ""))
        return CommandResult.ACCEPTED

    def takeoff(self) -> CommandResult:
        """Armed and IDLE: enter TAKEOFF (climb to the take-off altitude); else DENIED."""
        if not self.armed or self.mode != FlightMode.IDLE:
            return CommandResult.DENIED
        self.set_mode(FlightMode.TAKEOFF, "takeoff command")
        return CommandResult.ACCEPTED

    def transition(self, to_fw: bool) -> CommandResult:
        """Command a transition: ``to_fw`` True starts FRONT_TRANSITION, False BACK_TRANSITION.

        Denied when disarmed, in IDLE, TAKEOFF or LAND, and (to fixed-wing) during a back
        transition; accepted without change when already in or going to the requested state.
        """
        if not self.armed or self.mode in (FlightMode.IDLE, FlightMode.TAKEOFF, FlightMode.LAND):
            return CommandResult.DENIED
        if to_fw:
            if self.mode in (FlightMode.FIXED_WING, FlightMode.FRONT_TRANSITION):
                return CommandResult.ACCEPTED
            if self.mode == FlightMode.BACK_TRANSITION:
                return CommandResult.DENIED
            self.set_mode(FlightMode.FRONT_TRANSITION, "transition to fixed-wing commanded")
            return CommandResult.ACCEPTED
        if self.mode in (FlightMode.HOVER, FlightMode.BACK_TRANSITION):
            return CommandResult.ACCEPTED
        self.land_after_back_transition = False
        self.set_mode(FlightMode.BACK_TRANSITION, "transition to multicopter commanded")
        return CommandResult.ACCEPTED

    def land(self) -> CommandResult:
        """Land: in hover directly (LAND), from fixed-wing or a transition after a back transition.

        Denied when disarmed or IDLE; already landing is accepted.
        """
        if not self.armed or self.mode == FlightMode.IDLE:
            return CommandResult.DENIED
        if self.mode == FlightMode.LAND:
            return CommandResult.ACCEPTED
        if self.mode in (FlightMode.FIXED_WING, FlightMode.FRONT_TRANSITION,
                         FlightMode.BACK_TRANSITION):
            self.land_after_back_transition = True
            self.set_mode(FlightMode.BACK_TRANSITION, "land: back transition first")
            return CommandResult.ACCEPTED
        self.set_mode(FlightMode.LAND, "land command")
        return CommandResult.ACCEPTED

    # -- automatic changes --------------------------------------------------------------------
    def advance(self, now_usec: int) -> None:
        """:meth:`update` in a mode outside :data:`AUTO_EXIT_MODES`, where it does nothing
        but this: the clock set to ``now_usec`` [us]."""
        self.now_usec = int(now_usec)

    def update(self, now_usec: int, *, altitude_m: float, takeoff_alt_m: float,
               airspeed_m_s: float, arsp_trans: float, trans_timeout_s: float,
               b_trans_arsp: float, b_trans_dur_s: float, landed: bool) -> None:
        """Advance the timers and take the automatic transitions of the table above (only in
        :data:`AUTO_EXIT_MODES`; in the other modes this is :meth:`advance`)."""
        self.now_usec = int(now_usec)
        m = self.mode
        if m == _M_TAKEOFF and abs(altitude_m - takeoff_alt_m) < TAKEOFF_TOL_M:
            self.set_mode(FlightMode.HOVER, f"takeoff altitude {takeoff_alt_m:g} m reached")
        elif m == _M_FRONT_TRANSITION:
            if airspeed_m_s >= arsp_trans:
                self.set_mode(FlightMode.FIXED_WING,
                              f"transition complete at {airspeed_m_s:.1f} m/s")
            elif self.time_in_mode_s() > trans_timeout_s:
                self.set_mode(FlightMode.HOVER, f"quad-chute: transition timeout, airspeed "
                              f"{airspeed_m_s:.1f} m/s < {arsp_trans:g} m/s after "
                              f"{trans_timeout_s:g} s")
        elif m == _M_BACK_TRANSITION:
            if airspeed_m_s < b_trans_arsp or self.time_in_mode_s() > b_trans_dur_s:
                nxt = FlightMode.LAND if self.land_after_back_transition else FlightMode.HOVER
                self.land_after_back_transition = False
                self.set_mode(nxt, f"back transition complete at {airspeed_m_s:.1f} m/s")
        elif m == _M_LAND and landed:
            self.set_mode(FlightMode.IDLE, "landed")

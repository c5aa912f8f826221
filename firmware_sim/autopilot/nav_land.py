"""The navigator's landing: approach, back transition at the braking distance, descent.

PX4's ``Land`` navigator mode and the VTOL landing of its ``MissionBlock``. A NAV_LAND (21) /
NAV_VTOL_LAND (85) goal, or the RTL's landing: in fixed-wing the L1 approach on the line to
the land point, the back transition started at the braking distance before it
(:mod:`.backtrans`: the ground speed towards the point, the deceleration expected,
``VT_B_DEC_MSS``, then measured in flight, and the multicopter's stop), then multicopter to
the point (no faster than it can stop), descent (the mode machine's LAND, ``MPC_LAND_SPEED``)
and touchdown (the autopilot disarms). Latitude and longitude 0 of a land item: land where
it is. DO_VTOL_TRANSITION (3000) to multicopter is flown here too: the back transition, and
the hold over the waypoint it braked for.

AUTO.LAND commanded by a ground station is flown by the mode machine; the navigator reports it.
"""

from __future__ import annotations

import math

from vtolftc.firmware_sim.autopilot.interface import FlightMode, NavState
from vtolftc.firmware_sim.autopilot.nav_base import Goal, NavigatorMode

__all__ = ["Land"]


class Land(NavigatorMode):
    """Landing and back transitions (see the module docstring)."""

    def fly(self, g: Goal, nav: NavState, yaw: float, pos: tuple[float, float],
            h: float) -> bool:
        """Advance landing goal ``g`` from position ``pos`` (north, east m) at height ``h``
        (m above home); True once landed (the autopilot has disarmed)."""
        nv = self.navigator
        ap = nv.ap
        m = ap.modes
        mode = m.mode
        if not g.has_position:
            g.north, g.east = pos
        tgt = (g.north, g.east)
        d = math.hypot(tgt[0] - pos[0], tgt[1] - pos[1])
        if nv.phase in ("", "rtl"):
            nv.set_phase("approach")
            nv.seg_a = nv.prev_wp if (nv.prev_wp is not None
                                      and mode == FlightMode.FIXED_WING) else pos
        if mode == FlightMode.IDLE:
            return nv.phase in ("descend", "reposition")
        if nv.phase == "approach" and not self._approach(g, nav, tgt, d):
            return False
        if nv.phase == "back_transition":
            if mode in (FlightMode.HOVER, FlightMode.LAND):
                nv.set_phase("reposition")
            else:
                return False
        if nv.phase == "reposition":
            self._reposition(g, nav, tgt, d)
            return False
        if nv.phase == "descend":
            nv.hold_at(tgt)
        return False

    def _approach(self, g: Goal, nav: NavState, tgt: tuple[float, float], d: float) -> bool:
        """Phase "approach"; True when it ends in multicopter (go on to "reposition")."""
        nv = self.navigator
        ap = nv.ap
        m = ap.modes
        mode = m.mode
        if math.isfinite(g.alt) and g.seq < 0:
            # RTL: the return altitude; a land item's altitude is the ground's: the
            # approach and back transition stay at the current altitude (PX4)
            nv.set_alt_ref(g.alt)
        if mode == FlightMode.FIXED_WING:
            nv.fw_target = ("segment", nv.seg_a, tgt)
            if d <= self.brake_distance(tgt, nav):
                m.transition(False)
                nv.drain_events()
                nv.set_phase("back_transition")
            return False
        if mode == FlightMode.FRONT_TRANSITION:
            m.transition(False)
            nv.drain_events()
            nv.set_phase("back_transition")
            return False
        if mode == FlightMode.BACK_TRANSITION:
            nv.set_phase("back_transition")
            return False
        nv.set_phase("reposition")
        return True

    def _reposition(self, g: Goal, nav: NavState, tgt: tuple[float, float], d: float) -> None:
        """Phase "reposition": multicopter to the point, then the descent."""
        nv = self.navigator
        ap = nv.ap
        m = ap.modes
        if m.mode == FlightMode.LAND:
            nv.set_phase("descend")
            return
        if m.mode != FlightMode.HOVER:
            return
        if math.isfinite(g.alt) and g.seq < 0:
            nv.set_alt_ref(g.alt)
        nv.mc_goto(tgt, nav)
        v = math.hypot(float(nav.vel_ned_m_s[0]), float(nav.vel_ned_m_s[1]))
        if d < max(1.0, 0.5 * nv.param["NAV_ACC_RAD"].value) and v < 0.5:
            m.land()
            nv.drain_events()
            nv.set_phase("descend")

    def fly_back_transition_item(self) -> bool:
        """DO_VTOL_TRANSITION to multicopter; True once in multicopter (then holding over the
        waypoint braked for, if any)."""
        nv = self.navigator
        ap = nv.ap
        m = ap.modes
        mode = m.mode
        if mode in (FlightMode.HOVER, FlightMode.LAND, FlightMode.IDLE):
            if nv.bt_hold is not None and mode == FlightMode.HOVER:
                # braked for the waypoint before: hold over it (PX4 keeps the
                # waypoint as the multicopter's position setpoint)
                nv.hold_at(nv.bt_hold)
            nv.bt_hold = None
            return True
        if mode in (FlightMode.FIXED_WING, FlightMode.FRONT_TRANSITION):
            m.transition(False)
            nv.drain_events()
        return False

    def brake_distance(self, tgt: tuple[float, float], nav: NavState) -> float:
        """Metres before ``tgt`` where a back transition must start to stop over it (ground
        speed towards it, the planner's deceleration, see :mod:`.backtrans`)."""
        nv = self.navigator
        p = nv.param
        pos = (float(nav.pos_ned_m[0]), float(nav.pos_ned_m[1]))
        dn, de = tgt[0] - pos[0], tgt[1] - pos[1]
        d = math.hypot(dn, de)
        if d < 1e-6:
            return 0.0
        v_along = (float(nav.vel_ned_m_s[0]) * dn + float(nav.vel_ned_m_s[1]) * de) / d
        bt = nv.backtrans
        bt.set_params(p["VT_B_DEC_MSS"].value, p["VT_B_TRANS_ARSP"].value,
                      p["VT_B_TRANS_DUR"].value)
        a_mc = nv.ap.airframe.gravity_m_s2 * math.tan(math.radians(
            p["MPC_TILTMAX_AIR"].value))
        v_mc = nv.mc_speed if math.isfinite(nv.mc_speed) else p["MPC_XY_CRUISE"].value
        return bt.distance(v_along, float(nv.airspeed_m_s), a_mc, v_mc)

    def measure_back_transition(self, old: FlightMode, new: FlightMode,
                                nav: NavState) -> None:
        """At a flight-mode change: the start and end of every back transition, measured by
        the planner (what it achieved moves the deceleration estimate)."""
        nv = self.navigator
        p = nv.param
        bt = nv.backtrans
        pos = (float(nav.pos_ned_m[0]), float(nav.pos_ned_m[1]))
        vel = (float(nav.vel_ned_m_s[0]), float(nav.vel_ned_m_s[1]))
        if new == FlightMode.BACK_TRANSITION:
            bt.set_params(p["VT_B_DEC_MSS"].value, p["VT_B_TRANS_ARSP"].value,
                          p["VT_B_TRANS_DUR"].value)
            bt.start(nv.time_usec, pos, vel, float(nav.airspeed_m_s))
        elif old == FlightMode.BACK_TRANSITION:
            meas = bt.finish(nv.time_usec, pos, vel, float(nav.airspeed_m_s),
                             p["VT_B_DEC_ADAPT"].value)
            if meas is not None and math.isfinite(meas.decel_m_s2):
                nv.say(f"back transition: airspeed {meas.airspeed0_m_s:.1f} -> "
                       f"{meas.airspeed1_m_s:.1f} m/s in {meas.duration_s:.1f} s over "
                       f"{meas.distance_m:.0f} m ({meas.decel_m_s2:.2f} m/s^2); planning "
                       f"with {bt.decel:.2f} m/s^2")

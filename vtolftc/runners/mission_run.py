"""Missions: the reference VTOL mission, an in-process mission runner and path metrics.

:func:`rectangle_mission` builds the reference VTOL mission as MAVLink mission items:
NAV_TAKEOFF to ``alt`` above home (multicopter climb), DO_VTOL_TRANSITION to fixed-wing, four
NAV_WAYPOINTs on the corners of a ``length`` x ``width`` rectangle (north, then east, then
back; the fourth corner is home), DO_VTOL_TRANSITION back to multicopter and NAV_LAND at home.

:func:`run_mission` flies a mission in-process (vehicle at 1 kHz, autopilot at 250 Hz, the
same HIL encoding as :mod:`vtolftc.runners.scenario`): arm, AUTO.MISSION, until the autopilot has
landed and disarmed or ``timeout_s``. Faults may be injected when a given mission item becomes
current (plus a delay), e.g. case 1's during the first fixed-wing leg.

:func:`path_errors` is the path metric used by the tests and the benchmark: for the samples
flown in fixed-wing while a NAV_WAYPOINT was current, the distance to the planned polyline
of the fixed-wing legs (the nearest point of any leg, so the corner cut of a turn counts as
the distance to the corner's two legs), RMS and maximum per mission item.
"""

from __future__ import annotations

import math
import time
from collections.abc import Sequence
from dataclasses import dataclass, field

import numpy as np

from vtolftc.airframe.loader import Airframe, load_airframe
from vtolftc.base.geodesy import FlatEarth
from vtolftc.firmware_sim.autopilot.autopilot import Autopilot
from vtolftc.firmware_sim.autopilot.interface import (
    FlightMode,
    decode_hil_state,
    encode_hil_state,
    wire_commands,
)
from vtolftc.firmware_sim.autopilot.mission import (
    DO_VTOL_TRANSITION,
    FRAME_GLOBAL_RELATIVE_ALT_INT,
    FRAME_MISSION,
    NAV_LAND,
    NAV_TAKEOFF,
    NAV_VTOL_LAND,
    NAV_WAYPOINT,
    MissionItem,
)
from vtolftc.firmware_sim.vehicle.battery import BatteryModel, vehicle_power_w
from vtolftc.firmware_sim.vehicle.faults import Fault
from vtolftc.firmware_sim.vehicle.model import Vehicle
from vtolftc.firmware_sim.vehicle.sensors import Home

__all__ = ["MissionRun", "back_transition_mission", "path_errors", "rectangle_mission",
           "run_mission"]

NAN = math.nan


def _latlon(home: Home, north: float, east: float) -> tuple[int, int]:
    lat, lon = FlatEarth(home.lat_deg, home.lon_deg).to_global(north, east)
    return round(lat * 1e7), round(lon * 1e7)


def rectangle_mission(home: Home | None = None, alt: float = 30.0, length: float = 600.0,
                      width: float = 300.0) -> list[MissionItem]:
    """The reference VTOL mission (see the module docstring); altitudes relative to home."""
    home = home or Home()
    rel = FRAME_GLOBAL_RELATIVE_ALT_INT
    hx, hy = _latlon(home, 0.0, 0.0)
    corners = [(width, 0.0), (width, length), (0.0, length), (0.0, 0.0)]
    items = [MissionItem(0, rel, NAV_TAKEOFF, 1, 0.0, 0.0, 0.0, NAN, hx, hy, alt),
             MissionItem(1, FRAME_MISSION, DO_VTOL_TRANSITION, 1, 4.0, 0.0, 0.0, 0.0, 0, 0,
                         0.0)]
    for n, e in corners:
        x, y = _latlon(home, n, e)
        items.append(MissionItem(len(items), rel, NAV_WAYPOINT, 1, 0.0, 0.0, 0.0, NAN, x, y,
                                 alt))
    items.append(MissionItem(len(items), FRAME_MISSION, DO_VTOL_TRANSITION, 1, 3.0, 0.0, 0.0,
                             0.0, 0, 0, 0.0))
    items.append(MissionItem(len(items), rel, NAV_LAND, 1, 0.0, 0.0, 0.0, NAN, hx, hy, 0.0))
    return items


BT_STOP_NE = (500.0, 0.0)
"""Where :func:`back_transition_mission` stops the first time (m north, east of home)."""
BT_LAST_WP_NE = (300.0, 700.0)
"""Its last fixed-wing waypoint, the start of the landing approach to home."""


def back_transition_mission(home: Home | None = None, alt: float = 30.0) -> list[MissionItem]:
    """A mission with two back transitions, each to stop over a point.

    NAV_TAKEOFF to ``alt``, DO_VTOL_TRANSITION to fixed-wing, NAV_WAYPOINT 500 m north,
    DO_VTOL_TRANSITION to multicopter (the back transition stops over that waypoint), a
    multicopter NAV_WAYPOINT there with 3 s of hold, DO_VTOL_TRANSITION to fixed-wing,
    NAV_WAYPOINT at :data:`BT_LAST_WP_NE` and NAV_VTOL_LAND at home (the approach from that
    waypoint, the back transition at the braking distance). Altitudes relative to home.
    """
    home = home or Home()
    rel = FRAME_GLOBAL_RELATIVE_ALT_INT
    hx, hy = _latlon(home, 0.0, 0.0)
    ax, ay = _latlon(home, *BT_STOP_NE)
    bx, by = _latlon(home, *BT_LAST_WP_NE)

    def trans(seq: int, to: float) -> MissionItem:
        return MissionItem(seq, FRAME_MISSION, DO_VTOL_TRANSITION, 1, to, 0.0, 0.0, 0.0, 0, 0,
                           0.0)

    return [MissionItem(0, rel, NAV_TAKEOFF, 1, 0.0, 0.0, 0.0, NAN, hx, hy, alt),
            trans(1, 4.0),
            MissionItem(2, rel, NAV_WAYPOINT, 1, 0.0, 0.0, 0.0, NAN, ax, ay, alt),
            trans(3, 3.0),
            MissionItem(4, rel, NAV_WAYPOINT, 1, 3.0, 0.0, 0.0, NAN, ax, ay, alt),
            trans(5, 4.0),
            MissionItem(6, rel, NAV_WAYPOINT, 1, 0.0, 0.0, 0.0, NAN, bx, by, alt),
            MissionItem(7, rel, NAV_VTOL_LAND, 1, 0.0, 0.0, 0.0, NAN, hx, hy, 0.0)]


@dataclass
class MissionRun:
    """What an in-process mission flight gave (times in simulated seconds)."""

    reached: list[tuple[float, int]]
    """(time_s, seq) of every MISSION_ITEM_REACHED, in order."""
    t: np.ndarray
    pos_ned: np.ndarray
    """(n, 3) vehicle truth, m from home."""
    mode: np.ndarray
    seq: np.ndarray
    """current mission item at each sample."""
    landed_disarmed: bool
    sim_time_s: float
    wall_time_s: float
    events: list[tuple[int, str]] = field(default_factory=list)
    battery: list[tuple[float, float, float, float]] = field(default_factory=list)
    """(time_s, pack voltage V, current A, the autopilot's remaining estimate) at 5 Hz."""

    @property
    def final_position(self) -> np.ndarray:
        """Last recorded position, NED (m)."""
        return self.pos_ned[-1]


def run_mission(items: Sequence[MissionItem], *, airframe: Airframe | None = None,
                controller: str = "gs-shif", timeout_s: float = 400.0,
                faults_at_item: tuple[int, float, Sequence[Fault]] | None = None,
                sample_every: int = 25,
                wind_ned_m_s: Sequence[float] = (0.0, 0.0, 0.0)) -> MissionRun:
    """Fly ``items`` in-process (see the module docstring).

    ``faults_at_item`` = (seq, delay_s, faults): the faults act ``delay_s`` after item ``seq``
    became current (their own start times are replaced). Samples every ``sample_every``
    control steps (default 10 Hz); ``wind_ned_m_s``: a steady wind (m/s, NED, the air's
    velocity). The vehicle's battery (:mod:`.firmware_sim.vehicle.battery`)
    feeds the autopilot's battery monitor at 5 Hz, as the power module over the HIL link.
    """
    af = airframe if airframe is not None else load_airframe()
    ap = Autopilot(af, controller=controller)
    veh = Vehicle(af, wind_ned_m_s=wind_ned_m_s)
    battery = BatteryModel(rho=af.air_density_kg_m3)
    bat_rows: list[tuple[float, float, float, float]] = []
    home = veh.sensor_model.home
    h = (float(home.lat_deg), float(home.lon_deg), float(home.alt_m))
    ap.set_home(*h)
    res, why = ap.navigator.store.replace(0, list(items))
    if res != 0:
        raise ValueError(f"mission refused: {why}")
    n_sub = 4
    rows_t, rows_p, rows_m, rows_s = [], [], [], []
    fault_due: int | None = None
    armed_once = False
    wall0 = time.perf_counter()
    step = 0
    while veh.time_usec < timeout_s * 1e6:
        now = veh.time_usec
        nav = decode_hil_state(encode_hil_state(
            _nav_of(veh, now), *h), *h)
        u = ap.step(nav)
        if step == 5:
            ap.command(400, [1.0])
            ap.command(176, [1.0, 4.0, 4.0])
            armed_once = ap.modes.armed
        if faults_at_item is not None and fault_due is None \
                and ap.navigator.store.current == faults_at_item[0] \
                and ap.navigator.mission_state == 3:
            fault_due = now + round(faults_at_item[1] * 1e6)
        if fault_due is not None and now >= fault_due and faults_at_item is not None:
            for f in faults_at_item[2]:
                veh.inject(Fault(f.actuator, f.kind, f.loss, now * 1e-6))
            fault_due = -1
        veh.step(wire_commands(u), n_sub)
        battery.step(n_sub * veh.dt_usec * 1e-6, vehicle_power_w(battery, veh))
        if step % 50 == 0:  # the power module at 5 Hz, as over the HIL link
            ap.battery_update(veh.time_usec, battery.voltage_v, battery.current_a)
            bat_rows.append((veh.time_usec * 1e-6, battery.voltage_v, battery.current_a,
                             ap.battery.remaining))
        if step % sample_every == 0:
            rows_t.append(now * 1e-6)
            rows_p.append(veh.x[0:3].copy())
            rows_m.append(int(ap.modes.mode))
            rows_s.append(ap.navigator.store.current)
        step += 1
        if armed_once and step > 10 and not ap.modes.armed:
            break
        if -veh.x[2] < -1.0 or not np.all(np.isfinite(veh.x)):
            break
    landed = (armed_once and not ap.modes.armed and ap.modes.mode == FlightMode.IDLE
              and ap.navigator.mission_state == 5)
    return MissionRun(
        reached=[(t * 1e-6, s) for t, s in ap.navigator.reached_log],
        t=np.array(rows_t), pos_ned=np.array(rows_p), mode=np.array(rows_m),
        seq=np.array(rows_s), landed_disarmed=landed, sim_time_s=veh.time_usec * 1e-6,
        wall_time_s=time.perf_counter() - wall0, events=list(ap.event_log), battery=bat_rows)


def _nav_of(veh: Vehicle, now: int):
    from vtolftc.firmware_sim.autopilot.interface import NavState

    x = veh.x
    return NavState(now, x[6:10], x[10:13], x[0:3], x[3:6], float(veh.fm[6]))


def path_errors(items: Sequence[MissionItem], t: np.ndarray, pos_ned: np.ndarray,
                mode: np.ndarray, seq: np.ndarray,
                home: Home | None = None) -> dict[int, dict[str, float]]:
    """Distance to the planned fixed-wing polyline per NAV_WAYPOINT item (see the module
    docstring): ``{seq: {"rms_m", "max_m", "samples"}}``."""
    home = home or Home()
    pts: list[tuple[int, np.ndarray]] = []
    proj = FlatEarth(home.lat_deg, home.lon_deg)
    for it in items:
        if it.command in (NAV_WAYPOINT, NAV_TAKEOFF):
            n, e = proj.to_local(it.lat_deg, it.lon_deg)
            pts.append((it.seq, np.array([n, e])))
    legs = [(pts[k][1], pts[k + 1][1]) for k in range(len(pts) - 1)]
    out: dict[int, dict[str, float]] = {}
    wp_seqs = [s for s, _ in pts[1:]]
    for s in wp_seqs:
        sel = (seq == s) & (mode == int(FlightMode.FIXED_WING))
        if not np.any(sel):
            continue
        p = pos_ned[sel, :2]
        d = np.full(len(p), np.inf)
        for a, b in legs:
            ab = b - a
            L2 = float(ab @ ab)
            tt = np.clip(((p - a) @ ab) / L2, 0.0, 1.0) if L2 > 0 else np.zeros(len(p))
            d = np.minimum(d, np.linalg.norm(p - (a + tt[:, None] * ab), axis=1))
        out[s] = {"rms_m": float(np.sqrt(np.mean(d * d))), "max_m": float(np.max(d)),
                  "samples": len(p)}
    return out

"""PX4 services of the ground-station endpoint beyond commands and parameters.

:class:`Px4Services` is owned by :class:`~vtolftc.firmware_sim.autopilot.gcs_endpoint.GcsEndpoint`
and hooked into it at four points (receive, control step, wall-clock tick, stream build):

- the mission microservice (:class:`.mission.MissionProtocol` on the navigator's plans),
  MISSION_CURRENT (1 Hz and on every change) and MISSION_ITEM_REACHED;
- COMMAND_INT: answered like COMMAND_LONG (one COMMAND_ACK) after PX4's conversion: for the
  global frames ``x``/``y`` (degE7) become degrees in param5/6 and a relative altitude becomes
  AMSL (plus home); INT32_MAX in x/y means "not set" (NaN);
- TIMESYNC: a request (``tc1`` = 0) is answered with ``tc1`` = the autopilot's time in ns
  (simulated time, as PX4 SITL in lockstep) and the request's ``ts1``; PING: a broadcast ping
  (target 0/0) is answered with the same ``time_usec`` and ``seq`` addressed to the sender;
- telemetry: BATTERY_STATUS (the autopilot's estimate, :mod:`.battery`, from the vehicle's
  power-module readings), the battery fields of SYS_STATUS, GPS_RAW_INT (fix type,
  satellites, hdop/vdop, position and velocity of the vehicle's GPS, HIL_GPS);
- geofence: with a fence plan stored, SYS_STATUS shows the geofence present and enabled;
  healthy unless breached (as PX4: without a fence it is healthy too). A breach of an
  inclusion polygon/circle or entry into an exclusion one is reported once per breach
  (STATUSTEXT) and acted on by ``GF_ACTION`` (0 none, 1 warning, 3 return; others: warning).
"""

from __future__ import annotations

import math
import time
from typing import Any

from vtolftc.firmware_sim.autopilot.interface import ParamType
from vtolftc.firmware_sim.autopilot.mission import (
    FENCE,
    FENCE_CIRCLE_INCLUSION,
    FENCE_POLYGON_EXCLUSION,
    FENCE_POLYGON_INCLUSION,
    GLOBAL_FRAMES,
    RELATIVE_FRAMES,
    MissionProtocol,
)
from vtolftc.protocols.generated import constants as mav

__all__ = ["STREAM_RATES_HZ", "Px4Services"]

MSG_GPS_RAW_INT = mav.MAVLINK_MSG_ID_GPS_RAW_INT
MSG_MISSION_CURRENT = mav.MAVLINK_MSG_ID_MISSION_CURRENT
MSG_BATTERY_STATUS = mav.MAVLINK_MSG_ID_BATTERY_STATUS
STREAM_RATES_HZ = {MSG_GPS_RAW_INT: 2.0, MSG_MISSION_CURRENT: 1.0, MSG_BATTERY_STATUS: 1.0}
GEOFENCE_BIT = mav.MAV_SYS_STATUS_GEOFENCE
BATTERY_BIT = mav.MAV_SYS_STATUS_SENSOR_BATTERY
_INT32_MAX = 2**31 - 1


def command_int_params(msg: Any, home_alt_m: float) -> list[float]:
    """COMMAND_INT's parameters as the COMMAND_LONG it stands for (PX4's conversion).

    Parameters
    ----------
    msg : COMMAND_INT
        The received message.
    home_alt_m : float
        Home altitude AMSL [m], added to ``z`` of the relative-altitude frames.

    Returns
    -------
    list of float
        param1..4, then for the global frames ``x``/``y`` (degE7) as degrees (NaN where
        INT32_MAX means "not set") and ``z`` as altitude AMSL [m]; for other frames x, y, z
        as they are.
    """
    p = [float(msg.param1), float(msg.param2), float(msg.param3), float(msg.param4)]
    frame = int(msg.frame)
    x, y, z = int(msg.x), int(msg.y), float(msg.z)
    if frame in GLOBAL_FRAMES:
        p += [math.nan if x == _INT32_MAX else x * 1e-7,
              math.nan if y == _INT32_MAX else y * 1e-7,
              z + home_alt_m if frame in RELATIVE_FRAMES and math.isfinite(z) else z]
    else:
        p += [float(x), float(y), z]
    return p


def _inside_polygon(p: tuple[float, float], poly: list[tuple[float, float]]) -> bool:
    """Ray casting on local (north, east) coordinates."""
    inside = False
    n = len(poly)
    for i in range(n):
        (x1, y1), (x2, y2) = poly[i], poly[(i + 1) % n]
        if (y1 > p[1]) != (y2 > p[1]):
            x_at = x1 + (p[1] - y1) * (x2 - x1) / (y2 - y1)
            if p[0] < x_at:
                inside = not inside
    return inside


class Px4Services:
    """See the module docstring. ``endpoint``: the owning GcsEndpoint."""

    def __init__(self, endpoint: Any) -> None:
        self.ep = endpoint
        self.nav = getattr(endpoint.ap, "navigator", None)
        codec = endpoint.links[0].codec if endpoint.links else None
        self.mission: MissionProtocol | None = None
        if self.nav is not None and codec is not None:
            self.mission = MissionProtocol(
                self.nav.store, codec, mission_state=self.nav.mission_status,
                on_text=lambda text: endpoint.statustext(text, 4))
        params = endpoint.ap.params
        if "GF_ACTION" not in params:
            params.register("GF_ACTION", 1, ParamType.INT32, 0, 5,
                            "geofence breach action: 0 none, 1 warning, 3 return")
        self._home_set = False
        self._battery_msg: Any = None
        self._last_current: tuple[int, int] | None = None
        self.breached = False

    HANDLES = MissionProtocol.MESSAGES | {"TIMESYNC", "PING"}
    """Message types this service answers (in the endpoint's worker thread)."""

    def home_alt_m(self) -> float:
        """Home altitude AMSL [m] (0 before home is known)."""
        return float(self.nav.home_alt) if self.nav is not None else 0.0

    # ------------------------------------------------------------------ receive
    def handle(self, link: Any, msg: Any) -> None:
        """One received message of :attr:`HANDLES`."""
        t = msg.get_type()
        c = link.codec
        if t == "TIMESYNC":
            if int(msg.tc1) == 0:
                link.send(c.timesync_encode(max(1, self.ep.sim_usec * 1000), int(msg.ts1)))
        elif t == "PING":
            if msg.target_system == 0 and msg.target_component == 0:
                link.send(c.ping_encode(int(msg.time_usec), int(msg.seq), msg.get_srcSystem(),
                                        msg.get_srcComponent()))
        elif self.mission is not None:
            for reply in self.mission.handle(msg, time.monotonic()):
                link.send(reply)

    # ------------------------------------------------------------------ step and tick
    def on_step(self, pos: Any) -> None:
        """Control thread, after a control step: home, battery readings, mission progress.

        Runs where the autopilot runs (it may change it); what it sends goes through the
        endpoint's worker, which alone sends on the links.
        """
        ep, ap, hil = self.ep, self.ep.ap, self.ep.hil
        if not self._home_set and hil.home is not None and hasattr(ap, "set_home"):
            ap.set_home(*hil.home)
            self._home_set = True
        b = getattr(hil, "last_battery", None)
        if b is not None and b is not self._battery_msg and hasattr(ap, "battery_update"):
            self._battery_msg = b
            volts = sum(v for v in b.voltages[:10] if v != 65535) * 1e-3
            ap.battery_update(int(pos.time_usec), volts, b.current_battery * 0.01)
        if self.nav is None or not ep.links:
            return
        c = ep.links[0].codec
        out = [c.mission_item_reached_encode(seq) for seq in self.nav.reached]
        self.nav.reached.clear()
        cur = (self.nav.store.current, self.nav.mission_state)
        if cur != self._last_current:
            self._last_current = cur
            if self.mission is not None:
                out.append(self.mission.mission_current())
        if out:
            ep.reply(lambda: [ep.send_all(m) for m in out])
        self._check_fence(pos)

    def tick(self) -> None:
        """Mission-protocol wall-clock duties (request retries); replies go to all links."""
        if self.mission is not None:
            for reply in self.mission.tick(time.monotonic()):
                self.ep.send_all(reply)

    # ------------------------------------------------------------------ streams
    def build(self, msg_id: int) -> Any:
        """Stream message ``msg_id`` (GPS_RAW_INT, MISSION_CURRENT, BATTERY_STATUS) or None."""
        ep = self.ep
        c = ep.links[0].codec
        if msg_id == MSG_MISSION_CURRENT:
            return self.mission.mission_current() if self.mission is not None else None
        if msg_id == MSG_BATTERY_STATUS:
            bat = getattr(ep.ap, "battery", None)
            if bat is None or not math.isfinite(bat.voltage_v):
                return None
            n = max(1, int(ep.ap.params.get("BAT1_N_CELLS")))
            cells = [min(65534, round(1000 * bat.voltage_v / n))] * min(n, 10)
            cells += [65535] * (10 - len(cells))
            return c.battery_status_encode(
                0, 1, 3, 32767, cells, round(100 * bat.current_a), round(bat.consumed_mah),
                -1, round(100 * bat.remaining), 0, bat.charge_state)
        if msg_id == MSG_GPS_RAW_INT:
            g = ep.hil.last_gps
            if g is None:
                return None
            return c.gps_raw_int_encode(int(g.time_usec), int(g.fix_type), int(g.lat),
                                        int(g.lon), int(g.alt), int(g.eph), int(g.epv),
                                        int(g.vel), int(g.cog), int(g.satellites_visible))
        return None

    def sys_status_battery(self) -> tuple[int, int, int]:
        """(voltage mV, current cA, remaining %) of SYS_STATUS; (65535, -1, -1) unknown."""
        bat = getattr(self.ep.ap, "battery", None)
        if bat is None or not math.isfinite(bat.voltage_v):
            return 65535, -1, -1
        return (min(65534, round(1000 * bat.voltage_v)), round(100 * bat.current_a),
                round(100 * bat.remaining))

    def sensor_bits(self) -> tuple[int, int, int]:
        """Extra (present, enabled, healthy) SYS_STATUS bits: geofence and battery."""
        present = enabled = healthy = 0
        if self.nav is not None and self.nav.store.plans[FENCE]:
            present |= GEOFENCE_BIT
            enabled |= GEOFENCE_BIT
        if not self.breached:
            healthy |= GEOFENCE_BIT
        bat = getattr(self.ep.ap, "battery", None)
        if bat is not None and math.isfinite(bat.voltage_v):
            present |= BATTERY_BIT
            enabled |= BATTERY_BIT
            if bat.level < 2:
                healthy |= BATTERY_BIT
        return present, enabled, healthy

    # ------------------------------------------------------------------ geofence
    def _check_fence(self, pos: Any) -> None:
        nav = self.nav
        fence = nav.store.plans[FENCE] if nav is not None else []
        if not fence or pos is None or nav.home is None:
            self.breached = False
            return
        p = (float(pos.pos_ned_m[0]), float(pos.pos_ned_m[1]))
        breach = False
        k = 0
        while k < len(fence):
            it = fence[k]
            if it.command in (FENCE_POLYGON_INCLUSION, FENCE_POLYGON_EXCLUSION):
                n = int(it.param1)
                poly = [nav.to_local(f.lat_deg, f.lon_deg) for f in fence[k:k + n]]
                inside = _inside_polygon(p, poly)
                k += n
            else:
                cn, ce = nav.to_local(it.lat_deg, it.lon_deg)
                inside = math.hypot(p[0] - cn, p[1] - ce) <= it.param1
                k += 1
            inclusion = it.command in (FENCE_POLYGON_INCLUSION, FENCE_CIRCLE_INCLUSION)
            if inside != inclusion:
                breach = True
        if breach and not self.breached:
            action = int(self.ep.ap.params.get("GF_ACTION"))
            self.ep.notify("geofence breached", 4)
            if action == 3:
                nav.start_rtl("geofence breached")
        self.breached = breach


"""A small kinematic stand-in for the autopilot's ground-station side, for tests and demos.

:class:`FakeAutopilot` speaks the MAVLink subset a ground station needs, as the real
autopilot does (system 1, component 1, PX4 custom modes, DESIGN.md's streams): HEARTBEAT,
ATTITUDE, LOCAL_POSITION_NED, GLOBAL_POSITION_INT, VFR_HUD, EXTENDED_SYS_STATE,
ACTUATOR_OUTPUT_STATUS and STATUSTEXT; it answers every COMMAND_LONG with a COMMAND_ACK (arm,
takeoff, VTOL transition, fault injection gated by the INT32 parameter ``SYS_FAILURE_EN``,
UNSUPPORTED otherwise) and serves the PARAM protocol for its few parameters.

It is NOT a simulator: the "flight" is a scripted kinematic motion (climb at 3 m/s, transition
by ramping the airspeed at 2 m/s^2 to 18 m/s, fixed-wing above 13 m/s, straight north), enough
to see modes change and the aircraft move. Used by the dashboard tests when no SITL is wanted,
and to measure the dashboard's own cost. Everything runs on 127.0.0.1.
"""

from __future__ import annotations

import math
import threading
import time
from typing import Any

from vtolftc.protocols import open_link
from vtolftc.protocols.px4 import custom_mode, decode_param_value, encode_param_value

__all__ = ["FakeAutopilot"]

_MAV_TYPE_VTOL_FIXEDROTOR = 22
_MAV_AUTOPILOT_PX4 = 12
_ARMED = 128
_CUSTOM = 1
_AUTO, _TAKEOFF, _LOITER, _READY = 4, 2, 3, 1


class FakeAutopilot:
    """Kinematic MAVLink autopilot sending to a ground station at ``gcs_url``.

    Parameters
    ----------
    gcs_url
        where the ground station listens, e.g. ``udp-client://127.0.0.1:14550``.
    rate_hz
        telemetry rate (HEARTBEAT is always 1 Hz).
    speed
        simulated seconds per wall second.
    """

    def __init__(self, gcs_url: str, *, rate_hz: float = 20.0, speed: float = 1.0) -> None:
        self._link = open_link(gcs_url, system_id=1, component_id=1)
        self._mav = self._link.codec
        self.rate_hz = rate_hz
        self.speed = speed
        self.params: dict[str, tuple[float, int]] = {"SYS_FAILURE_EN": (0.0, 6),
                                                     "MIS_TAKEOFF_ALT": (30.0, 9)}
        self.armed = False
        self.stage = "idle"          # idle, takeoff, hover, to_fw, fw, to_mc
        self.alt = 0.0
        self.north = 0.0
        self.airspeed = 0.0
        self.target_alt = 30.0
        self.t = 0.0
        self.faults: dict[tuple[int, int], float] = {}
        self.commands: list[tuple[int, int]] = []     # (command, result) received
        self.paused = False          # True: send nothing (a dropped link)
        self._stop = threading.Event()
        self._lock = threading.Lock()
        self._thread = threading.Thread(target=self._run, name="fake-autopilot", daemon=True)
        self._thread.start()

    # -- lifetime ------------------------------------------------------------------------
    def close(self) -> None:
        self._stop.set()
        self._thread.join(timeout=2.0)
        self._link.close()

    def __enter__(self) -> FakeAutopilot:
        return self

    def __exit__(self, *exc: object) -> None:
        self.close()

    # -- state ---------------------------------------------------------------------------
    @property
    def vtol_state(self) -> int:
        return {"to_fw": 1, "to_mc": 2, "fw": 4}.get(self.stage, 3)

    def _mode(self) -> int:
        if self.stage == "idle":
            return custom_mode(_AUTO, _READY)
        if self.stage == "takeoff":
            return custom_mode(_AUTO, _TAKEOFF)
        return custom_mode(_AUTO, _LOITER)

    def _advance(self, dt: float) -> None:
        if self.stage == "takeoff":
            self.alt = min(self.target_alt, self.alt + 3.0 * dt)
            if self.alt >= self.target_alt - 1e-6:
                self.stage = "hover"
        elif self.stage in ("to_fw", "fw"):
            self.airspeed = min(18.0, self.airspeed + 2.0 * dt)
            if self.stage == "to_fw" and self.airspeed >= 13.0:
                self.stage = "fw"
                self._text("Transition to fixed-wing complete")
        elif self.stage == "to_mc":
            self.airspeed = max(0.0, self.airspeed - 2.0 * dt)
            if self.airspeed <= 0.5:
                self.airspeed = 0.0
                self.stage = "hover"
                self._text("Transition to multicopter complete")
        self.north += self.airspeed * dt

    def _outputs(self) -> list[float]:
        hover = 0.45 if self.armed else 0.0
        lift = hover * max(0.0, 1.0 - self.airspeed / 15.0)
        pusher = (0.6 if self.stage == "to_fw" else 0.4 if self.stage == "fw" else 0.0)
        wob = 0.05 * math.sin(2.0 * self.t)
        out = [lift + (wob if i % 2 else -wob) * (lift > 0) for i in range(8)]
        out += [pusher, pusher]
        out += [0.1 * math.sin(1.3 * self.t), -0.1 * math.sin(1.3 * self.t),
                0.12 if self.airspeed > 5 else 0.0, 0.0, 0.0]
        for (unit, inst), loss in self.faults.items():
            idx = inst - 1 if unit == 101 else 10 + inst - 1
            if 0 <= idx < len(out):
                out[idx] *= 1.0 - loss
        return out

    # -- loop ----------------------------------------------------------------------------
    def _run(self) -> None:
        period = 1.0 / self.rate_hz
        last = time.monotonic()
        next_hb = 0.0
        while not self._stop.is_set():
            now = time.monotonic()
            with self._lock:
                self._advance((now - last) * self.speed)
                self.t += (now - last) * self.speed
            last = now
            try:
                for m in self._link.recv(0.0):
                    self._handle(m)
                if not self.paused:
                    if now >= next_hb:
                        next_hb = now + 1.0
                        self._heartbeat()
                    self._telemetry()
            except Exception:  # a closed link at shutdown
                if self._stop.is_set():
                    return
            self._stop.wait(max(0.0, period - (time.monotonic() - now)))

    def _heartbeat(self) -> None:
        base = _CUSTOM | (_ARMED if self.armed else 0)
        self._link.send(self._mav.heartbeat_encode(_MAV_TYPE_VTOL_FIXEDROTOR, _MAV_AUTOPILOT_PX4,
                                                   base, self._mode(), 4 if self.armed else 3))
        # home at 0 m AMSL, so NAV_TAKEOFF's AMSL param7 is also the height above home here
        self._link.send(self._mav.home_position_encode(473977420, 85455940, 0, 0.0, 0.0, 0.0,
                                                       [1.0, 0.0, 0.0, 0.0], 0.0, 0.0, 0.0))

    def _telemetry(self) -> None:
        mav = self._mav
        ms = int(self.t * 1000)
        roll = 0.05 * math.sin(0.7 * self.t) if self.alt > 0.5 else 0.0
        pitch = -0.03 if self.stage == "to_fw" else (0.01 if self.stage == "fw" else 0.0)
        self._link.send(mav.attitude_encode(ms, roll, pitch, 0.0, 0.0, 0.0, 0.0))
        self._link.send(mav.local_position_ned_encode(ms, self.north, 0.0, -self.alt,
                                                      self.airspeed, 0.0, 0.0))
        self._link.send(mav.global_position_int_encode(
            ms, 473977420 + int(self.north / 111320.0 * 1e7), 85455940,
            int((488.0 + self.alt) * 1000), int(self.alt * 1000), int(self.airspeed * 100), 0,
            0, 0))
        self._link.send(mav.vfr_hud_encode(self.airspeed, self.airspeed, 0,
                                           40 if self.armed else 0, self.alt, 0.0))
        self._link.send(mav.extended_sys_state_encode(
            self.vtol_state, 2 if self.alt > 0.5 else (1 if self.stage == "idle" else 3)))
        out = self._outputs()
        self._link.send(mav.actuator_output_status_encode(int(self.t * 1e6), len(out),
                                                          out + [0.0] * (32 - len(out))))

    def _text(self, text: str, severity: int = 6) -> None:
        if not self.paused:
            self._link.send(self._mav.statustext_encode(severity, text.encode()[:50]))

    def _ack(self, m: Any, result: int, why: str = "") -> None:
        if why:
            self._text(why, 4)
        self.commands.append((int(m.command), result))
        self._link.send(self._mav.command_ack_encode(m.command, result, 0, 0,
                                                     m.get_srcSystem(), m.get_srcComponent()))

    def _handle(self, m: Any) -> None:
        t = m.get_type()
        if t == "COMMAND_LONG" and m.target_system in (0, 1):
            self._command(m)
        elif t == "PARAM_REQUEST_READ":
            name = m.param_id if isinstance(m.param_id, str) else m.param_id.decode()
            name = name.rstrip("\x00")
            names = list(self.params)
            if not name and 0 <= m.param_index < len(names):
                name = names[m.param_index]
            if name in self.params:
                self._param_value(name)
        elif t == "PARAM_REQUEST_LIST":
            for name in self.params:
                self._param_value(name)
        elif t == "PARAM_SET":
            name = m.param_id if isinstance(m.param_id, str) else m.param_id.decode()
            name = name.rstrip("\x00")
            if name in self.params:
                ptype = self.params[name][1]
                v = decode_param_value(m.param_value, ptype)
                if name != "SYS_FAILURE_EN" or v in (0.0, 1.0):
                    self.params[name] = (v, ptype)
                self._param_value(name)

    def _param_value(self, name: str) -> None:
        v, ptype = self.params[name]
        names = list(self.params)
        self._link.send(self._mav.param_value_encode(name.encode(), encode_param_value(v, ptype),
                                                     ptype, len(names), names.index(name)))

    def _command(self, m: Any) -> None:
        c = int(m.command)
        p1 = m.param1
        with self._lock:
            if c == 400:                                      # arm / disarm
                if p1 >= 0.5:
                    self.armed = True
                    self._ack(m, 0)
                elif self.alt > 0.5 and int(m.param2) != 21196:
                    self._ack(m, 2, "Disarm refused: vehicle in air")
                else:
                    self.armed = False
                    self.stage = "idle"
                    self._ack(m, 0)
            elif c == 22:                                     # takeoff
                if not self.armed:
                    self._ack(m, 2, "Takeoff refused: not armed")
                else:
                    alt = m.param7
                    self.target_alt = (alt if math.isfinite(alt) and alt > 0
                                       else self.params["MIS_TAKEOFF_ALT"][0])
                    self.stage = "takeoff"
                    self._ack(m, 0)
            elif c == 3000:                                   # VTOL transition
                to = int(p1) if math.isfinite(p1) else 0
                if to not in (3, 4):
                    self._ack(m, 2, "Transition: param1 must be 3 (MC) or 4 (FW)")
                elif self.alt < 5.0 or not self.armed:
                    self._ack(m, 2, "Transition refused: not flying")
                elif to == 4:
                    if self.stage in ("hover", "to_mc"):
                        self.stage = "to_fw"
                    self._ack(m, 0)
                else:
                    if self.stage in ("fw", "to_fw"):
                        self.stage = "to_mc"
                    self._ack(m, 0)
            elif c in (59900, 420):                            # fault injection
                if self.params["SYS_FAILURE_EN"][0] != 1.0:
                    self._ack(m, 2, "Fault injection disabled (SYS_FAILURE_EN=0)")
                else:
                    unit = int(p1)
                    if c == 59900:
                        inst, loss = int(m.param2), float(m.param3)
                    else:
                        inst, loss = int(m.param3), (1.0 if int(m.param2) == 1 else 0.0)
                    self.faults[(unit, inst)] = loss
                    self._ack(m, 0)
            else:
                self._ack(m, 3)

"""What the web dashboard shows, computed from ground-station snapshots (no GUI, no network).

:class:`DashboardModel` turns successive :class:`vtolftc.gcs.client.VehicleSnapshot` objects
(anything
with the same attributes works) into a :class:`DashboardView`: link state, mode, armed state,
airspeed, altitude, the aircraft's pose and path in the display frame, the time traces and the
actuator bars; it also keeps the feedback of the commands sent (accepted, refused, no answer).
:mod:`vtolftc.dashboard.web` only copies a view into viser's GUI elements, so everything here is
tested
without a browser (``tests/test_dashboard.py``).

Display frame: viser's world is z-up. The model shows NED positions in a frame rotated by 180
degrees about north: x = north, y = west, z = up (``display = diag(1, -1, -1) @ ned``). The
aircraft geometry stays in body FRD and is placed with the quaternion
``q_display = q_x(180 deg) * q_body->ned``.

Link states: ``waiting`` (no heartbeat yet), ``ok``, ``stale`` (heartbeat older than
``stale_after_s``), ``lost`` (older than ``lost_after_s``, or the snapshot says disconnected
after having been connected).
"""

from __future__ import annotations

import html
import math
from collections import deque
from collections.abc import Sequence
from dataclasses import dataclass, field
from typing import Any

import numpy as np

from vtolftc.base.geodesy import FlatEarth
from vtolftc.base.rotation import euler_to_quat, quat_mul
from vtolftc.protocols.generated import constants as mav

__all__ = [
    "CommandFeedback",
    "DashboardModel",
    "DashboardView",
    "commands_html",
    "ned_to_display",
]

_Q_FLIP = np.array([0.0, 1.0, 0.0, 0.0])      # 180 deg about x (w, x, y, z)


def ned_to_display(p: Sequence[float] | np.ndarray) -> np.ndarray:
    """NED position(s) (m) -> display frame (x north, y west, z up)."""
    a = np.asarray(p, dtype=float)
    return a * np.array([1.0, -1.0, -1.0])


_RELATIVE_FRAMES = (mav.MAV_FRAME_GLOBAL_RELATIVE_ALT, mav.MAV_FRAME_GLOBAL_RELATIVE_ALT_INT)
_NAV_COMMANDS = (mav.MAV_CMD_NAV_WAYPOINT, mav.MAV_CMD_NAV_LOITER_UNLIM,
                 mav.MAV_CMD_NAV_LOITER_TIME, mav.MAV_CMD_NAV_LAND, mav.MAV_CMD_NAV_TAKEOFF,
                 mav.MAV_CMD_NAV_VTOL_TAKEOFF, mav.MAV_CMD_NAV_VTOL_LAND)


def mission_points_display(items: Sequence[Any], home_lat_deg: float, home_lon_deg: float,
                           home_alt_m: float) -> tuple[np.ndarray, list[int]]:
    """Display-frame points (k, 3) of the positional items of a mission (MISSION_ITEM_INT
    messages or anything with seq, frame, command, x, y (degE7) and z (m)) and their seqs.
    Flat-earth projection about home (the autopilot's); lat/lon 0 (land here) is skipped."""
    pts, seqs = [], []
    proj = FlatEarth(home_lat_deg, home_lon_deg)
    for it in items:
        if int(it.command) not in _NAV_COMMANDS or (it.x == 0 and it.y == 0):
            continue
        n, e = proj.to_local(it.x * 1e-7, it.y * 1e-7)
        h = float(it.z) if int(it.frame) in _RELATIVE_FRAMES else float(it.z) - home_alt_m
        pts.append(ned_to_display((n, e, -h)))
        seqs.append(int(it.seq))
    return (np.array(pts) if pts else np.zeros((0, 3))), seqs


@dataclass
class CommandFeedback:
    """One command's fate, as shown to the user."""

    label: str                   # what the user pressed, e.g. "transition to fixed-wing"
    state: str                   # "pending", "accepted", "refused", "no answer", "error"
    text: str                    # one line for the user
    elapsed_s: float = 0.0
    seq: int = 0                 # 1, 2, ... in the order the commands were started

    @property
    def level(self) -> str:
        """``ok``, ``pending`` or ``error`` (colour of the message)."""
        return {"accepted": "ok", "pending": "pending"}.get(self.state, "error")


@dataclass
class DashboardView:
    """Everything the page shows at one update (values ready for display)."""

    update_count: int
    link_state: str                              # waiting / ok / stale / lost
    link_text: str
    mode_text: str
    armed: bool
    vtol_text: str
    landed_text: str
    airspeed_m_s: float
    groundspeed_m_s: float
    altitude_m: float
    heading_deg: float
    attitude_deg: tuple[float, float, float]
    position_ned_m: tuple[float, float, float]
    sim_time_s: float
    statustext: str
    pose_position: np.ndarray                    # display frame (m)
    pose_wxyz: np.ndarray                        # display frame quaternion
    path: np.ndarray                             # (k, 3) display frame
    path_changed: bool
    traces: dict[str, np.ndarray]                # t, roll, pitch, yaw (deg), altitude, airspeed
    actuators: dict[str, float | None]           # name -> normalised output (None = unknown)
    actuator_html: str
    commands: list[CommandFeedback] = field(default_factory=list)
    battery_text: str = "no data"
    gps_text: str = "no data"
    mission_text: str = "no mission"
    mission_seq: int = 0
    mission_total: int = 0

    @property
    def status_html(self) -> str:
        """The status panel as HTML; ``data-*`` attributes carry the raw values (for tests)."""
        colour = {"ok": "#16a34a", "stale": "#ca8a04", "lost": "#dc2626",
                  "waiting": "#6b7280"}[self.link_state]
        r, p, y = self.attitude_deg
        n, e, d = self.position_ned_m
        esc = html.escape
        armed = "ARMED" if self.armed else "disarmed"
        rows = [
            ("mode", f"{esc(self.mode_text)} · <b>{armed}</b>"),
            ("VTOL", f"{esc(self.vtol_text)} · {esc(self.landed_text)}"),
            ("airspeed", f"{self.airspeed_m_s:.1f} m/s (ground {self.groundspeed_m_s:.1f})"),
            ("altitude", f"{self.altitude_m:.1f} m · heading {self.heading_deg:.0f}°"),
            ("roll/pitch/yaw", f"{r:+.1f}° / {p:+.1f}° / {y:+.1f}°"),
            ("N / E / D", f"{n:.1f} / {e:.1f} / {d:.1f} m"),
            ("sim time", f"{self.sim_time_s:.1f} s · update #{self.update_count}"),
            ("battery", esc(self.battery_text)),
            ("GPS", esc(self.gps_text)),
            ("mission", esc(self.mission_text)),
        ]
        # the autopilot row is always there and no cell wraps (a long text ends in an
        # ellipsis, whole in its tooltip): the panel keeps one height, so the command buttons
        # below it never move under the operator's pointer while the texts change
        rows.append(("autopilot", f'<i title="{esc(self.statustext)}">{esc(self.statustext)}</i>'
                     if self.statustext else "—"))
        cell = "white-space:nowrap;overflow:hidden;text-overflow:ellipsis"
        body = "".join(f'<tr><td style="color:#666;padding-right:8px;{cell}">{k}</td>'
                       f'<td style="{cell}">{v}</td></tr>' for k, v in rows)
        return (
            f'<div id="vtolftc-status" data-link="{self.link_state}" '
            f'data-mode="{esc(self.mode_text)}" data-vtol="{esc(self.vtol_text)}" '
            f'data-armed="{int(self.armed)}" data-update="{self.update_count}" '
            f'data-north="{n:.2f}" data-altitude="{self.altitude_m:.2f}" '
            f'data-airspeed="{self.airspeed_m_s:.2f}" style="font-size:13px">'
            f'<div id="vtolftc-link" style="background:{colour};color:white;padding:4px 8px;'
            f'border-radius:4px;margin-bottom:6px;{cell}">{esc(self.link_text)}</div>'
            f'<table style="table-layout:fixed;width:100%"><colgroup><col style="width:7.5em">'
            f"<col></colgroup>{body}</table></div>")

    @property
    def commands_html(self) -> str:
        """The latest command results, newest first."""
        return commands_html(self.commands)


def commands_html(commands: Sequence[CommandFeedback]) -> str:
    """HTML of command feedback, newest first (one coloured line each)."""
    if not commands:
        return ('<div id="vtolftc-commands" data-count="0" style="font-size:12px;color:#666">'
                "no command sent yet</div>")
    colour = {"ok": "#15803d", "pending": "#a16207", "error": "#b91c1c"}
    mark = {"ok": "✓", "pending": "…", "error": "✗"}
    lines = "".join(
        f'<div class="vtolftc-cmd" data-state="{html.escape(c.state)}" data-seq="{c.seq}" '
        f'style="color:{colour[c.level]}">{mark[c.level]} {html.escape(c.text)}</div>'
        for c in reversed(commands))
    return (f'<div id="vtolftc-commands" data-count="{len(commands)}" '
            f'style="font-size:12px">{lines}</div>')


class DashboardModel:
    """Turns snapshots into :class:`DashboardView` objects and keeps command feedback.

    Parameters
    ----------
    actuator_names
        the vehicle's actuators in output order (ACTUATOR_OUTPUT_STATUS order).
    rotor_grid
        lift-rotor names laid out as seen from above (see
        :func:`vtolftc.telemetry.geometry.rotor_grid`).
    url
        the ground-station link URL (for messages).
    history_s
        length of the time traces (s of autopilot time).
    stale_after_s, lost_after_s
        heartbeat ages for the link states.
    max_path_points
        the path keeps at most this many points (older ones are thinned).
    path_step_m
        a new path point is added when the aircraft moved this far.
    """

    def __init__(self, actuator_names: Sequence[str], rotor_grid: Sequence[Sequence[str | None]],
                 *, url: str = "", history_s: float = 60.0, stale_after_s: float = 1.5,
                 lost_after_s: float = 3.0, max_path_points: int = 2000,
                 path_step_m: float = 0.25, max_commands: int = 6) -> None:
        self.actuator_names = tuple(actuator_names)
        self.rotor_grid = [list(r) for r in rotor_grid]
        self.url = url
        self.history_s = float(history_s)
        self.stale_after_s = float(stale_after_s)
        self.lost_after_s = float(lost_after_s)
        self.max_path_points = int(max_path_points)
        self.path_step_m = float(path_step_m)
        self._count = 0
        self._ever_connected = False
        self._t0_wall: float | None = None
        self._last_t: float | None = None
        self._traces: dict[str, deque[float]] = {k: deque() for k in (
            "t", "roll", "pitch", "yaw", "altitude", "airspeed")}
        self._path: list[np.ndarray] = []
        self._commands: deque[CommandFeedback] = deque(maxlen=max_commands)
        self._seq = 0
        self.faults: dict[str, float] = {}      # actuator -> loss (0..1) injected from here

    # -- commands ------------------------------------------------------------------------
    def command_started(self, label: str) -> CommandFeedback:
        """Record a command being sent (shown as pending)."""
        self._seq += 1
        fb = CommandFeedback(label, "pending", f"{label}: sending…", seq=self._seq)
        self._commands.append(fb)
        return fb

    def command_finished(self, fb: CommandFeedback, outcome: Any = None,
                         error: BaseException | None = None) -> CommandFeedback:
        """Record the outcome of ``fb``: a CommandOutcome (``result``, ``result_name``,
        ``elapsed_s``, optional ``detail``) or the exception raised while sending."""
        if error is not None:
            fb.state = "error"
            fb.text = f"{fb.label}: not sent: {error}"
        elif outcome is None or getattr(outcome, "result", None) is None:
            fb.state = "no answer"
            el = getattr(outcome, "elapsed_s", 0.0) if outcome is not None else 0.0
            fb.elapsed_s = el
            fb.text = (f"{fb.label}: no acknowledgement after {el:.1f} s: is the autopilot "
                       f"running and sending to {self.url or 'this port'}?")
        else:
            fb.elapsed_s = float(outcome.elapsed_s)
            name = str(outcome.result_name)
            detail = str(getattr(outcome, "detail", "") or "")
            if outcome.result == 0:
                fb.state = "accepted"
                fb.text = f"{fb.label}: {name} ({fb.elapsed_s * 1e3:.0f} ms)"
            else:
                fb.state = "refused"
                fb.text = f"{fb.label}: refused by the autopilot: {name}" + (
                    f" ({detail})" if detail else "")
                if "INJECT" in str(getattr(outcome, "name", "")).upper() and name == "DENIED":
                    fb.text += " — fault injection needs SYS_FAILURE_EN = 1"
        return fb

    def commands_html(self) -> str:
        """HTML of the latest commands' feedback, newest first."""
        return commands_html(list(self._commands))

    def refuse_offline(self, label: str, view_state: str) -> CommandFeedback:
        """Feedback for a command not sent because the link is down."""
        why = "no heartbeat yet" if view_state == "waiting" else "link lost"
        self._seq += 1
        fb = CommandFeedback(label, "error",
                             f"{label}: not sent: autopilot not connected ({why} on "
                             f"{self.url or 'the link'})", seq=self._seq)
        self._commands.append(fb)
        return fb

    def record_faults(self, actuators: Sequence[str], loss: float) -> None:
        """Remember faults injected from this dashboard (shown on the actuator bars)."""
        for a in actuators:
            if loss <= 0.0:
                self.faults.pop(a, None)
            else:
                self.faults[a] = float(loss)

    # -- snapshots -----------------------------------------------------------------------
    def link_state(self, snap: Any) -> tuple[str, str]:
        """(state, text) of the link for a snapshot."""
        age = float(getattr(snap, "heartbeat_age_s", math.inf))
        if not math.isfinite(age) and not self._ever_connected:
            return "waiting", f"waiting for the autopilot on {self.url or 'the link'}…"
        if snap.connected and age <= self.stale_after_s:
            self._ever_connected = True
            return "ok", f"connected (heartbeat {age:.1f} s ago)"
        if not self._ever_connected and not snap.connected:
            return "waiting", f"waiting for the autopilot on {self.url or 'the link'}…"
        self._ever_connected = True
        if age > self.lost_after_s or not snap.connected:
            return "lost", (f"link lost: no heartbeat for {age:.1f} s; showing the last "
                            "known state")
        return "stale", f"link stale: last heartbeat {age:.1f} s ago"

    def update(self, snap: Any, now_s: float) -> DashboardView:
        """Fold one snapshot (taken at wall time ``now_s``, seconds) into a view."""
        self._count += 1
        state, text = self.link_state(snap)
        if self._t0_wall is None:
            self._t0_wall = now_s
        t = float(getattr(snap, "sim_time_s", 0.0) or 0.0)
        if t <= 0.0:
            t = now_s - self._t0_wall
        if self._last_t is not None and t < self._last_t - 1.0:
            self._reset_history()                 # autopilot restarted
        path_changed = False
        live = state in ("ok", "stale")
        if live and (self._last_t is None or t > self._last_t):
            self._last_t = t
            tr = self._traces
            tr["t"].append(t)
            tr["roll"].append(math.degrees(snap.roll))
            tr["pitch"].append(math.degrees(snap.pitch))
            tr["yaw"].append(math.degrees(snap.yaw))
            tr["altitude"].append(float(snap.altitude_m))
            tr["airspeed"].append(float(snap.airspeed_m_s))
            while tr["t"] and tr["t"][0] < t - self.history_s:
                for d in tr.values():
                    d.popleft()
        pos_disp = ned_to_display(snap.position_ned_m)
        if live and (not self._path or float(np.linalg.norm(pos_disp - self._path[-1]))
                     >= self.path_step_m):
            self._path.append(pos_disp)
            path_changed = True
            if len(self._path) > self.max_path_points:
                self._path = self._path[::2]
        q = quat_mul(_Q_FLIP, euler_to_quat(snap.roll, snap.pitch, snap.yaw))
        outs = list(getattr(snap, "actuator_outputs", []) or [])
        acts: dict[str, float | None] = {
            n: (float(outs[i]) if i < len(outs) and math.isfinite(outs[i]) else None)
            for i, n in enumerate(self.actuator_names)}
        return DashboardView(
            update_count=self._count, link_state=state, link_text=text,
            mode_text=str(snap.mode_name), armed=bool(snap.armed),
            vtol_text=str(getattr(snap, "vtol_state_name", snap.vtol_state)),
            landed_text=_LANDED.get(int(getattr(snap, "landed_state", 0)), "?"),
            airspeed_m_s=float(snap.airspeed_m_s),
            groundspeed_m_s=float(getattr(snap, "groundspeed_m_s", 0.0)),
            altitude_m=float(snap.altitude_m), heading_deg=float(snap.heading_deg),
            attitude_deg=(math.degrees(snap.roll), math.degrees(snap.pitch),
                          math.degrees(snap.yaw)),
            position_ned_m=tuple(float(v) for v in snap.position_ned_m),  # type: ignore[arg-type]
            sim_time_s=t, statustext=str(getattr(snap, "last_statustext", "") or ""),
            pose_position=pos_disp, pose_wxyz=q,
            path=np.array(self._path) if self._path else np.zeros((0, 3)),
            path_changed=path_changed,
            traces={k: np.fromiter(v, dtype=float, count=len(v))
                    for k, v in self._traces.items()},
            actuators=acts, actuator_html=self.actuator_html(acts, state != "ok"),
            commands=list(self._commands), **_extras(snap),
        )

    def _reset_history(self) -> None:
        for d in self._traces.values():
            d.clear()
        self._path.clear()
        self._last_t = None

    # -- actuator bars -------------------------------------------------------------------
    def actuator_html(self, acts: dict[str, float | None], dim: bool = False) -> str:
        """HTML of the actuator bars: lift rotors as on the airframe seen from above (nose
        up), then the pushers (0..1) and the surfaces (-1..1 of full deflection, centred)."""
        def bar(name: str, signed: bool) -> str:
            v = acts.get(name)
            fault = self.faults.get(name)
            label = html.escape(name.removeprefix("rotor_").removeprefix("pusher_"))
            if v is None:
                txt, fill = "—", ""
            elif signed:
                c = max(-1.0, min(1.0, v))
                left = 50.0 + min(0.0, c) * 50.0
                fill = (f'<div style="position:absolute;left:{left:.1f}%;width:{abs(c) * 50:.1f}%;'
                        f'top:0;bottom:0;background:#3b82f6"></div>')
                txt = f"{v:+.2f}"
            else:
                c = max(0.0, min(1.0, v))
                fill = (f'<div style="position:absolute;left:0;width:{c * 100:.1f}%;top:0;'
                        f'bottom:0;background:#f97316"></div>')
                txt = f"{100 * v:.0f}%"
            border = "2px solid #dc2626" if fault else "1px solid #999"
            ftxt = (f'<span style="color:#dc2626"> −{100 * fault:.0f}%</span>' if fault else "")
            return (f'<div class="vtolftc-act" data-name="{html.escape(name)}" '
                    f'style="margin:2px;font-size:11px">'
                    f'<div>{label}{ftxt}</div>'
                    f'<div style="position:relative;height:10px;border:{border};'
                    f'background:#eee">{fill}</div><div>{txt}</div></div>')

        rows = []
        for row in self.rotor_grid:
            cells = "".join(f'<td style="width:25%">{bar(n, False) if n else ""}</td>'
                            for n in row)
            rows.append(f"<tr>{cells}</tr>")
        pushers = [n for n in self.actuator_names if n.startswith("pusher")]
        surfaces = [n for n in self.actuator_names
                    if not n.startswith("pusher") and not n.startswith("rotor")]
        prow = "".join(f"<td>{bar(n, False)}</td>" for n in pushers)
        srow = "".join(f"<td>{bar(n, True)}</td>" for n in surfaces)
        opacity = "0.45" if dim else "1"
        return (f'<div id="vtolftc-actuators" style="opacity:{opacity}">'
                '<div style="font-size:11px;color:#666">lift rotors (top view, nose up)</div>'
                f'<table style="width:100%;table-layout:fixed">{"".join(rows)}</table>'
                '<div style="font-size:11px;color:#666">pushers</div>'
                f'<table style="width:100%;table-layout:fixed"><tr>{prow}</tr></table>'
                '<div style="font-size:11px;color:#666">surfaces (−1..1 of full deflection)'
                f'</div><table style="width:100%;table-layout:fixed"><tr>{srow}</tr></table>'
                "</div>")


_LANDED = {0: "undefined", 1: "on ground", 2: "in air", 3: "taking off", 4: "landing"}


_MISSION_STATES = {1: "no mission", 2: "not started", 3: "active", 4: "paused", 5: "complete"}
_FIX = {0: "no GPS", 1: "no fix", 2: "2D fix", 3: "3D fix", 4: "DGPS", 5: "RTK float",
        6: "RTK fixed"}


def _extras(snap: Any) -> dict[str, Any]:
    """Battery, GPS and mission lines of the status panel from a snapshot."""
    v = float(getattr(snap, "battery_v", math.nan))
    rem = float(getattr(snap, "battery_remaining", math.nan))
    amp = float(getattr(snap, "battery_a", math.nan))
    bat = "no data" if not math.isfinite(v) else (
        f"{v:.2f} V" + (f" · {amp:.1f} A" if math.isfinite(amp) else "")
        + (f" · {100 * rem:.0f} %" if math.isfinite(rem) else ""))
    fix = int(getattr(snap, "gps_fix_type", 0))
    hdop = float(getattr(snap, "gps_hdop", math.nan))
    gps = "no data" if fix == 0 else (
        f"{_FIX.get(fix, str(fix))} · {int(getattr(snap, 'gps_satellites', 0))} sats"
        + (f" · hdop {hdop:.1f}" if math.isfinite(hdop) else ""))
    total = int(getattr(snap, "mission_total", 0))
    seq = int(getattr(snap, "mission_seq", 0))
    state = _MISSION_STATES.get(int(getattr(snap, "mission_state", 0)), "")
    mission = "no mission" if total == 0 else f"item {seq} of {total} · {state}"
    return {"battery_text": bat, "gps_text": gps, "mission_text": mission,
            "mission_seq": seq, "mission_total": total}

"""The viser web dashboard: watch the aircraft and command it over MAVLink.

:class:`Dashboard` serves a page (viser, http://127.0.0.1:8080 by default) and connects to the
autopilot as a ground station through :class:`vtolftc.gcs.client.GroundStation` (UDP 14550 by
default, or any link URL). The page shows

- the aircraft in 3-D (fuselage, wing, booms, rotors and pushers from the airframe file) at
  its attitude and position, with the path it flew; the view follows it: the aircraft stays
  at the scene's origin and the world (ground grid, path, mission) moves the other way, so
  every browser's camera, wherever the user turned it, keeps the aircraft in frame without
  a camera round trip to the browser (which a loaded machine delays by seconds);
- live traces of roll/pitch/yaw, altitude and airspeed (uPlot);
- mode, armed state, VTOL state, airspeed, altitude and the link state (heartbeat age);
- actuator bars: the airframe's lift rotors laid out as on the airframe (top view), the pushers and
  the surfaces;
- buttons for arm, disarm, takeoff, transition to fixed-wing and back, and fault injection
  (actuator or group, loss slider, inject / clear); each sends a real MAVLink command through
  ``gcs/`` and shows the COMMAND_ACK (accepted, refused with the autopilot's reason, or no
  answer). Commands are not sent while the link is down; the page says why.

All display logic is in :class:`vtolftc.dashboard.model.DashboardModel` (tested without a browser);
this module only moves its views into viser's elements, from one update thread (``rate_hz``)
and one command thread (commands never block the page).
"""

from __future__ import annotations

import contextlib
import math
import queue
import sys
import threading
import time
from collections.abc import Callable
from typing import Any

import numpy as np

from vtolftc.dashboard.model import DashboardModel, DashboardView
from vtolftc.telemetry.geometry import aircraft_geometry, rotor_grid

__all__ = ["FAULT_GROUPS", "SKY_HORIZON_RGB", "SKY_TOP_RGB", "Dashboard", "sky_gradient"]

FAULT_GROUPS = ("ailerons", "rudders", "surfaces", "lift_rotors", "pushers")
"""Group names offered in the fault-injection dropdown after the single actuators."""

_RGB_ROTOR = (240, 120, 40)
_RGB_PUSHER = (60, 200, 90)


SKY_TOP_RGB = (118, 166, 219)
SKY_HORIZON_RGB = (214, 228, 240)


def sky_gradient(rows: int = 64) -> np.ndarray:
    """The 3-D view's background: (rows, 2, 3) uint8, :data:`SKY_TOP_RGB` at the top row
    fading linearly to :data:`SKY_HORIZON_RGB` at the bottom (stretched over the view)."""
    f = np.linspace(0.0, 1.0, rows)[:, None, None]
    top = np.asarray(SKY_TOP_RGB, dtype=float)
    bottom = np.asarray(SKY_HORIZON_RGB, dtype=float)
    img = top + f * (bottom - top)
    return np.repeat(np.round(img), 2, axis=1).astype(np.uint8)


def _quat_from_z_to(axis: np.ndarray) -> tuple[float, float, float, float]:
    """Quaternion (w, x, y, z) turning +z onto the unit vector ``axis`` (cylinders are
    built along z)."""
    a = np.asarray(axis, dtype=float)
    a = a / np.linalg.norm(a)
    z = np.array([0.0, 0.0, 1.0])
    c = float(np.dot(z, a))
    if c > 1 - 1e-9:
        return (1.0, 0.0, 0.0, 0.0)
    if c < -1 + 1e-9:
        return (0.0, 1.0, 0.0, 0.0)
    v = np.cross(z, a)
    w = 1.0 + c
    q = np.array([w, *v])
    q /= np.linalg.norm(q)
    return (float(q[0]), float(q[1]), float(q[2]), float(q[3]))


class Dashboard:
    """The web dashboard (see the module docstring).

    Parameters
    ----------
    url
        the ground-station link URL (where the autopilot sends its GCS stream).
    host, port
        where the page is served (127.0.0.1 unless told otherwise).
    rate_hz
        page updates per second (status, pose, actuator bars).
    plot_hz
        trace (uPlot) updates per second, at most ``rate_hz``.
    airframe
        the airframe (default: the shipped DS-1) for geometry and actuator names.
    ground_station
        an already open ground station to use instead of opening ``url``
        (it is not closed by :meth:`close`).
    allow_remote
        allow a non-loopback address in ``url`` (autopilot on another host).

    Raises
    ------
    RuntimeError
        the ground-station link or the web port cannot be opened.
    """

    def __init__(self, url: str = "udp-server://127.0.0.1:14550", *, host: str = "127.0.0.1",
                 port: int = 8080, rate_hz: float = 10.0, airframe: Any = None,
                 ground_station: Any = None, plot_hz: float = 4.0,
                 verbose: bool = False, allow_remote: bool = False) -> None:
        import viser

        from vtolftc.gcs.client import GcsError, GroundStation

        if airframe is None:
            from vtolftc.airframe.loader import load_airframe

            airframe = load_airframe()
        self.airframe = airframe
        self.url = url
        self.rate_hz = float(rate_hz)
        self._own_gs = ground_station is None
        if ground_station is None:
            try:
                ground_station = GroundStation(url, allow_remote=allow_remote)
            except GcsError as exc:
                raise RuntimeError(str(exc)) from None
        self.gs = ground_station
        self.model = DashboardModel(airframe.actuator_names, rotor_grid(airframe), url=url)
        from vtolftc.gcs.actuators import ActuatorTable

        self._table = ActuatorTable.from_names(airframe.actuator_names)
        try:
            self.server = viser.ViserServer(host=host, port=port, label="vtol-ftc",
                                            verbose=verbose)
        except OSError as exc:
            if self._own_gs:
                self.gs.close()
            raise RuntimeError(f"cannot serve the dashboard on {host}:{port}: {exc}") from None
        self.host = host
        self.port = int(self.server.get_port())
        self.view: DashboardView | None = None
        self.updates = 0
        self._stop = threading.Event()
        self._cmd_queue: queue.Queue[tuple[str, Callable[[], Any], Callable[[Any], None]]
                                     | None] = queue.Queue()
        self._last_md: dict[str, str] = {}
        self._last_pose: np.ndarray | None = None
        self._plot_every = max(1, round(self.rate_hz / plot_hz))
        self._build_scene()
        self._build_gui()
        self._threads = [
            threading.Thread(target=self._update_loop, name="dashboard-update", daemon=True),
            threading.Thread(target=self._command_loop, name="dashboard-commands", daemon=True),
        ]
        for t in self._threads:
            t.start()

    @property
    def page_url(self) -> str:
        """The page's URL (``http://HOST:PORT/``)."""
        return f"http://{self.host}:{self.port}/"

    # -- scene ---------------------------------------------------------------------------
    def _build_scene(self) -> None:
        sc = self.server.scene
        sc.set_up_direction("+z")
        # a sky behind the scene: no part of the view is empty white (above the horizon the
        # grid alone left a blank band), and a view not yet rendered is told from one rendered
        sc.set_background_image(sky_gradient(), format="png")
        # the world, drawn relative to the aircraft (see the module docstring)
        self._world = sc.add_frame("/world", show_axes=False)
        self._grid = sc.add_grid("/world/ground", width=400.0, height=400.0, cell_size=5.0,
                                 section_size=25.0, plane="xy")
        self._grid_at = (0.0, 0.0)
        self._aircraft = sc.add_frame("/aircraft", show_axes=False)
        boxes, discs = aircraft_geometry(self.airframe)
        for b in boxes:
            sc.add_box(f"/aircraft/{b.name}", color=b.color, dimensions=b.size_m,
                       position=b.center_m, cast_shadow=False, receive_shadow=False)
        for d in discs:
            sc.add_cylinder(f"/aircraft/{d.name}", radius=d.radius_m, height=0.02,
                            color=_RGB_ROTOR if d.name.startswith("rotor") else _RGB_PUSHER,
                            position=d.center_m, wxyz=_quat_from_z_to(np.asarray(d.axis)),
                            opacity=0.8, cast_shadow=False, receive_shadow=False)
        sc.add_frame("/aircraft/axes", axes_length=0.6, axes_radius=0.02)
        self._path = None
        self._mission_total = 0           # mission size drawn (0 = none)
        self._mission_seq = -1
        self._mission_pts: tuple[np.ndarray, list[int]] | None = None
        self._mission_loading = False
        self._mission_new = False
        self._mission_current = None

        # where a new browser's camera starts (behind-left of the aircraft, above it); the
        # aircraft stays at the origin, so the camera keeps it in view
        cam = self.server.initial_camera
        cam.position = (-8.0, -8.0, 5.0)
        cam.look_at = (0.0, 0.0, 0.0)
        cam.up = (0.0, 0.0, 1.0)

    # -- GUI -----------------------------------------------------------------------------
    def _build_gui(self) -> None:
        gui = self.server.gui
        gui.configure_theme(control_width="large")
        self._md_status = gui.add_html('<div id="vtolftc-status">connecting…</div>')
        with gui.add_folder("Commands"):
            self._btn_arm = gui.add_button("Arm", color="green")
            self._btn_disarm = gui.add_button("Disarm")
            self._num_alt = gui.add_number("Takeoff altitude (m)", 30.0, min=2.0, max=200.0,
                                           step=1.0)
            self._btn_takeoff = gui.add_button("Takeoff")
            self._btn_fw = gui.add_button("Transition to fixed-wing", color="blue")
            self._btn_mc = gui.add_button("Transition to multicopter")
        with gui.add_folder("Fault injection"):
            names = list(self.airframe.actuator_names) + list(FAULT_GROUPS)
            self._dd_act = gui.add_dropdown("Actuator", names, initial_value=names[0])
            self._sl_loss = gui.add_slider("Loss", min=0.0, max=1.0, step=0.05,
                                           initial_value=0.5)
            self._btn_inject = gui.add_button("Inject fault", color="red")
            self._btn_clear = gui.add_button("Clear fault")
            self._btn_enable = gui.add_button("Allow fault injection (SYS_FAILURE_EN=1)")
        self._md_cmd = gui.add_html(self.model.commands_html())
        with gui.add_folder("Actuators"):
            self._html_act = gui.add_html(self.model.actuator_html({}, dim=True))
        with gui.add_folder("Traces"):
            empty = (np.zeros(0),) * 4
            from viser import uplot

            def series(label: str, color: str) -> Any:
                return uplot.Series(label=label, stroke=color, width=2)

            self._plot_att = gui.add_uplot(
                data=empty,
                series=(uplot.Series(label="t (s)"), series("roll", "red"),
                        series("pitch", "green"), series("yaw", "blue")),
                title="attitude (deg)", aspect=2.0,
                scales={"x": uplot.Scale(time=False, auto=True)})
            self._plot_alt = gui.add_uplot(
                data=(np.zeros(0),) * 2,
                series=(uplot.Series(label="t (s)"), series("altitude (m)", "purple")),
                title="altitude (m)", aspect=2.5,
                scales={"x": uplot.Scale(time=False, auto=True)})
            self._plot_air = gui.add_uplot(
                data=(np.zeros(0),) * 2,
                series=(uplot.Series(label="t (s)"), series("airspeed (m/s)", "orange")),
                title="airspeed (m/s)", aspect=2.5,
                scales={"x": uplot.Scale(time=False, auto=True)})

        self._btn_arm.on_click(lambda _: self.send("arm", lambda: self.gs.arm()))
        self._btn_disarm.on_click(lambda _: self.send("disarm", lambda: self.gs.disarm()))
        self._btn_takeoff.on_click(lambda _: self._takeoff())
        self._btn_fw.on_click(lambda _: self.send("transition to fixed-wing",
                                                  lambda: self.gs.transition("fw")))
        self._btn_mc.on_click(lambda _: self.send("transition to multicopter",
                                                  lambda: self.gs.transition("mc")))
        self._btn_inject.on_click(lambda _: self._inject(float(self._sl_loss.value)))
        self._btn_clear.on_click(lambda _: self._inject(0.0))
        self._btn_enable.on_click(lambda _: self.send(
            "allow fault injection", lambda: self._param_outcome("SYS_FAILURE_EN", 1)))

    def _takeoff(self) -> None:
        alt = float(self._num_alt.value)
        self.send(f"takeoff to {alt:g} m", lambda: self.gs.takeoff(alt))

    def _inject(self, loss: float) -> None:
        act = str(self._dd_act.value)
        label = (f"inject {act} loss {100 * loss:.0f} %" if loss > 0 else f"clear fault {act}")

        def done(outcome: Any) -> None:
            if getattr(outcome, "accepted", False):
                with contextlib.suppress(ValueError):
                    self.model.record_faults(self._table.expand(act), loss)

        self.send(label, lambda: self.gs.inject(act, loss=loss), done)

    def _param_outcome(self, name: str, value: float) -> Any:
        """Set a parameter and report it like a command outcome."""
        t0 = time.monotonic()
        v = self.gs.param_set(name, value)

        class _Out:
            command = 0
            result = 0
            result_name = f"{name} = {v:g}"
            elapsed_s = time.monotonic() - t0
            detail = ""
            accepted = True
        return _Out()

    # -- commands ------------------------------------------------------------------------
    def send(self, label: str, action: Callable[[], Any],
             on_done: Callable[[Any], None] | None = None) -> None:
        """Queue a command (returns at once). Refused locally while the link is down."""
        state, _ = self.model.link_state(self.gs.snapshot())
        if state not in ("ok", "stale"):
            self.model.refuse_offline(label, state)
            self._refresh_commands()
            return
        self._cmd_queue.put((label, action, on_done or (lambda _o: None)))

    def _command_loop(self) -> None:
        from vtolftc.gcs.client import GcsError

        while not self._stop.is_set():
            try:
                item = self._cmd_queue.get(timeout=0.2)
            except queue.Empty:
                continue
            if item is None:
                return
            label, action, on_done = item
            fb = self.model.command_started(label)
            self._refresh_commands()
            try:
                outcome = action()
            except (GcsError, ValueError) as exc:
                self.model.command_finished(fb, error=exc)
            except Exception as exc:  # never let a command kill the dashboard
                self.model.command_finished(fb, error=exc)
            else:
                self.model.command_finished(fb, outcome)
                with contextlib.suppress(Exception):
                    on_done(outcome)
            self._refresh_commands()

    def _refresh_commands(self) -> None:
        self._set_md(self._md_cmd, "cmd", self.model.commands_html())

    # -- updates -------------------------------------------------------------------------
    def _set_md(self, handle: Any, key: str, content: str) -> None:
        if self._last_md.get(key) != content:
            self._last_md[key] = content
            handle.content = content

    def update_once(self) -> DashboardView:
        """Take a snapshot, fold it into the model and push the view to the page."""
        view = self.model.update(self.gs.snapshot(), time.monotonic())
        self.view = view
        with self.server.atomic():
            self._set_md(self._md_status, "status", view.status_html)
            self._set_md(self._html_act, "act", view.actuator_html)
            pose = np.concatenate([view.pose_position, view.pose_wxyz])
            if self._last_pose is None or float(np.max(np.abs(pose - self._last_pose))) > 1e-3:
                self._last_pose = pose        # a scene change costs the browser a render
                self._place_world(view.pose_position)
                self._aircraft.wxyz = tuple(view.pose_wxyz)
            if view.path_changed and len(view.path) >= 2:
                seg = np.stack([view.path[:-1], view.path[1:]], axis=1).astype(np.float32)
                # re-created rather than resized: a growing point buffer is not redrawn whole
                self._path = self.server.scene.add_line_segments(
                    "/world/path", points=seg, colors=(250, 180, 20), thickness=3.0,
                    thickness_units="screen")
            self._draw_mission(view)
            tr = view.traces
            if tr["t"].size and self.updates % self._plot_every == 0:
                self._plot_att.data = (tr["t"], tr["roll"], tr["pitch"], tr["yaw"])
                self._plot_alt.data = (tr["t"], tr["altitude"])
                self._plot_air.data = (tr["t"], tr["airspeed"])
        self.updates += 1
        return view

    def _load_mission(self) -> None:
        """Download the vehicle's mission (in a thread) for the 3-D view."""
        from vtolftc.dashboard.model import mission_points_display

        try:
            items = self.gs.download_mission()
            snap = self.gs.snapshot()
            lat, lon = snap.home_lat_lon_deg
            if math.isfinite(lat) and math.isfinite(snap.home_amsl_m):
                self._mission_pts = mission_points_display(items, lat, lon, snap.home_amsl_m)
                self._mission_new = True
        except Exception:  # the next MISSION_CURRENT change tries again
            self._mission_total = 0
        finally:
            self._mission_loading = False

    def _draw_mission(self, view: DashboardView) -> None:
        """The mission's path (blue) and its current waypoint (red sphere) in the scene."""
        if view.mission_total != self._mission_total and not self._mission_loading:
            self._mission_total = view.mission_total
            if view.mission_total > 0:
                self._mission_loading = True
                threading.Thread(target=self._load_mission, daemon=True,
                                 name="dashboard-mission").start()
        sc = self.server.scene
        if self._mission_new and self._mission_pts is not None:
            self._mission_new = False
            self._mission_seq = -1
            pts, _ = self._mission_pts
            if len(pts) >= 2:
                seg = np.stack([pts[:-1], pts[1:]], axis=1).astype(np.float32)
                sc.add_line_segments("/world/mission", points=seg, colors=(40, 120, 250),
                                     thickness=2.0, thickness_units="screen")
        if self._mission_pts is not None and view.mission_seq != self._mission_seq:
            self._mission_seq = view.mission_seq
            pts, seqs = self._mission_pts
            nxt = [k for k, s in enumerate(seqs) if s >= view.mission_seq]
            if nxt:
                self._mission_current = sc.add_icosphere(
                    "/world/mission_current", radius=3.0, color=(220, 40, 40),
                    position=tuple(float(x) for x in pts[nxt[0]]))

    def _place_world(self, aircraft_display: np.ndarray) -> None:
        """Move the world so the aircraft (display frame, m) is at the scene's origin; the
        400 m ground grid moves in whole sections (25 m) to stay under the aircraft."""
        p = np.asarray(aircraft_display, dtype=float)
        self._world.position = (-float(p[0]), -float(p[1]), -float(p[2]))
        at = (round(float(p[0]) / 25.0) * 25.0, round(float(p[1]) / 25.0) * 25.0)
        if at != self._grid_at:
            self._grid_at = at
            self._grid.position = (at[0], at[1], 0.0)

    def _update_loop(self) -> None:
        period = 1.0 / self.rate_hz
        while not self._stop.is_set():
            t0 = time.monotonic()
            try:
                self.update_once()
            except Exception as exc:  # keep the page alive; say what went wrong
                print(f"dashboard: update failed: {exc}", file=sys.stderr)
            self._stop.wait(max(0.0, period - (time.monotonic() - t0)))

    # -- lifetime ------------------------------------------------------------------------
    def close(self) -> None:
        """Stop the threads, the web server and (if opened here) the ground station."""
        if self._stop.is_set():
            return
        self._stop.set()
        self._cmd_queue.put(None)
        for t in self._threads:
            t.join(timeout=5.0)
        with contextlib.suppress(Exception):
            self.server.stop()
        if self._own_gs:
            with contextlib.suppress(Exception):
                self.gs.close()

    def __enter__(self) -> Dashboard:
        return self

    def __exit__(self, *exc: object) -> None:
        self.close()

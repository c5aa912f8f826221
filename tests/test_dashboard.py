"""Dashboard logic without a browser: snapshot -> displayed values, command feedback, link
state; the geometry; and the dashboard against a kinematic MAVLink autopilot on loopback."""

from __future__ import annotations

import math
import re
import socket
import time
from typing import Any

import numpy as np
import pytest

from vtolftc.base.rotation import euler_to_quat as euler_to_quaternion
from vtolftc.dashboard.model import DashboardModel, ned_to_display
from vtolftc.gcs.client import CommandOutcome, VehicleSnapshot
from vtolftc.telemetry.geometry import aircraft_geometry, rotor_grid


def Snap(**fields: Any) -> VehicleSnapshot:
    """A ground-station snapshot of a connected vehicle hovering in multicopter mode."""
    base: dict[str, Any] = {"connected": True, "heartbeat_age_s": 0.2, "mode_name": "AUTO.LOITER",
                            "vtol_state": 3, "vtol_state_name": "MC", "landed_state": 2,
                            "sim_time_s": 1.0}
    return VehicleSnapshot(**(base | fields))


Outcome = CommandOutcome


def _model(ds1, **kw) -> DashboardModel:
    return DashboardModel(ds1.actuator_names, rotor_grid(ds1), url="udp-server://x:1", **kw)


def _rotate(q: np.ndarray, v: np.ndarray) -> np.ndarray:
    """Rotate v by unit quaternion q (w, x, y, z) through the rotation matrix."""
    w, x, y, z = q
    R = np.array([
        [1 - 2 * (y * y + z * z), 2 * (x * y - w * z), 2 * (x * z + w * y)],
        [2 * (x * y + w * z), 1 - 2 * (x * x + z * z), 2 * (y * z - w * x)],
        [2 * (x * z - w * y), 2 * (y * z + w * x), 1 - 2 * (x * x + y * y)],
    ])
    return R @ v


# -- geometry and frames -----------------------------------------------------------------
def test_rotor_grid_is_the_top_view_of_ds1(ds1):
    assert rotor_grid(ds1) == [["rotor_1a", "rotor_2a", "rotor_3a", "rotor_4a"],
                               ["rotor_1b", "rotor_2b", "rotor_3b", "rotor_4b"]]


def test_geometry_puts_a_disc_on_every_rotor(ds1):
    boxes, discs = aircraft_geometry(ds1)
    by_name = {d.name: d for d in discs}
    assert set(by_name) == {n for n in ds1.actuator_names if n.startswith(("rotor", "pusher"))}
    for r in ds1.lift_rotors:
        assert np.allclose(by_name[f"rotor_{r.name}"].center_m, r.position_m)
    wing = next(b for b in boxes if b.name == "wing")
    assert wing.size_m[1] == pytest.approx(ds1.wing.span_m)
    # discs of neighbouring rotors do not overlap
    pos = np.array([d.center_m for d in discs if d.name.startswith("rotor")])
    gaps = [np.linalg.norm(a - b) for i, a in enumerate(pos) for b in pos[i + 1:]]
    assert 2 * discs[0].radius_m < min(gaps)


def test_euler_quaternion_against_rotation_matrix():
    roll, pitch, yaw = 0.3, -0.2, 1.1
    q = euler_to_quaternion(roll, pitch, yaw)
    cr, sr, cp, sp, cy, sy = (math.cos(roll), math.sin(roll), math.cos(pitch), math.sin(pitch),
                              math.cos(yaw), math.sin(yaw))
    Rz = np.array([[cy, -sy, 0], [sy, cy, 0], [0, 0, 1]])
    Ry = np.array([[cp, 0, sp], [0, 1, 0], [-sp, 0, cp]])
    Rx = np.array([[1, 0, 0], [0, cr, -sr], [0, sr, cr]])
    v = np.array([0.3, -1.2, 0.7])
    assert np.allclose(_rotate(q, v), Rz @ Ry @ Rx @ v)


def test_pose_in_display_frame(ds1):
    m = _model(ds1)
    view = m.update(Snap(yaw=math.pi / 2, position_ned_m=(10.0, 5.0, -30.0)), 0.0)
    # display frame: x north, y west, z up
    assert np.allclose(view.pose_position, [10.0, -5.0, 30.0])
    assert np.allclose(ned_to_display([1.0, 2.0, 3.0]), [1.0, -2.0, -3.0])
    # heading east: the nose (body +x) points east = display -y; body down = display -z
    assert np.allclose(_rotate(view.pose_wxyz, np.array([1.0, 0, 0])), [0, -1, 0], atol=1e-12)
    assert np.allclose(_rotate(view.pose_wxyz, np.array([0, 0, 1.0])), [0, 0, -1], atol=1e-12)


# -- displayed values ---------------------------------------------------------------------
def test_snapshot_to_displayed_values(ds1):
    m = _model(ds1)
    outs = [0.5] * 8 + [0.25, 0.0] + [-0.5, 0.5, 0.0, 0.0, 0.0]
    view = m.update(Snap(armed=True, mode_name="AUTO.TAKEOFF", vtol_state_name="FW",
                         roll=math.radians(10), pitch=math.radians(-5), airspeed_m_s=14.25,
                         altitude_m=29.94, actuator_outputs=outs,
                         last_statustext="Transition complete"), 0.0)
    assert view.link_state == "ok"
    assert view.mode_text == "AUTO.TAKEOFF" and view.armed and view.vtol_text == "FW"
    assert view.attitude_deg[0] == pytest.approx(10.0)
    assert view.attitude_deg[1] == pytest.approx(-5.0)
    h = view.status_html
    for needle in ('data-mode="AUTO.TAKEOFF"', 'data-vtol="FW"', 'data-armed="1"',
                   "14.2 m/s", "29.9 m", "+10.0°", "-5.0°", "Transition complete"):
        assert needle in h, needle
    assert view.actuators["rotor_2b"] == 0.5 and view.actuators["pusher_left"] == 0.25
    assert view.actuators["aileron_left"] == -0.5
    # bars: rotors in top-view order, a rotor's bar filled to its output, a surface centred
    names = re.findall(r'data-name="([a-z0-9_]+)"', view.actuator_html)
    assert names[:8] == ["rotor_1a", "rotor_2a", "rotor_3a", "rotor_4a",
                         "rotor_1b", "rotor_2b", "rotor_3b", "rotor_4b"]
    assert names[8:] == list(ds1.actuator_names[8:])
    assert "width:50.0%" in view.actuator_html and "50%" in view.actuator_html
    assert "left:25.0%;width:25.0%" in view.actuator_html       # aileron_left = -0.5
    # unknown outputs (short list) show a dash, not a number
    v2 = m.update(Snap(actuator_outputs=[0.1, 0.2], sim_time_s=1.1), 0.1)
    assert v2.actuators["rotor_2a"] is None and "—" in v2.actuator_html


def test_status_panel_keeps_its_rows_whatever_the_texts(ds1):
    """The panel above the command buttons has one height: the same rows with or without an
    autopilot message, and no cell that wraps (long texts end in an ellipsis)."""
    m = _model(ds1)
    quiet = m.update(Snap(sim_time_s=1.0), 0.0).status_html
    long = "Transition denied: " + "not armed, " * 30
    loud = m.update(Snap(sim_time_s=2.0, last_statustext=long,
                         mode_name="AUTO.LOITER " * 10), 0.1).status_html
    for h in (quiet, loud):
        cells = re.findall(r"<td style=\"([^\"]*)\"", h)
        assert h.count("<tr>") == 11 and len(cells) == 22, h
        assert all("white-space:nowrap" in c and "text-overflow:ellipsis" in c for c in cells)
        assert "table-layout:fixed" in h
    assert "—</td>" in quiet
    assert f'title="{long}"' in loud                    # the whole message, in its tooltip


def test_traces_keep_a_window_and_reset_on_restart(ds1):
    m = _model(ds1, history_s=5.0)
    for k in range(100):
        view = m.update(Snap(sim_time_s=0.1 * (k + 1), altitude_m=float(k)), 0.0)
    t = view.traces["t"]
    assert t[-1] == pytest.approx(10.0) and t[0] >= 10.0 - 5.0 - 1e-9
    assert view.traces["altitude"][-1] == 99.0
    assert len(t) == len(view.traces["roll"]) == len(view.traces["airspeed"])
    # the same time again adds nothing; an autopilot restart (time jumps back) clears
    assert len(m.update(Snap(sim_time_s=10.0), 0.0).traces["t"]) == len(t)
    assert len(m.update(Snap(sim_time_s=0.5), 0.0).traces["t"]) == 1


def test_path_grows_only_when_the_aircraft_moves(ds1):
    m = _model(ds1, path_step_m=1.0)
    m.update(Snap(position_ned_m=(0, 0, 0)), 0)
    v = m.update(Snap(position_ned_m=(0.5, 0, 0), sim_time_s=2), 0)
    assert len(v.path) == 1 and not v.path_changed
    v = m.update(Snap(position_ned_m=(2.0, 0, -1.0), sim_time_s=3), 0)
    assert v.path_changed and np.allclose(v.path[-1], [2.0, 0.0, 1.0])


# -- link state and command feedback -----------------------------------------------------
def test_link_states(ds1):
    m = _model(ds1)
    assert m.update(Snap(connected=False, heartbeat_age_s=math.inf), 0).link_state == "waiting"
    assert "waiting for the autopilot on udp-server://x:1" in m.update(
        Snap(connected=False, heartbeat_age_s=math.inf), 0).link_text
    assert m.update(Snap(heartbeat_age_s=0.3), 0).link_state == "ok"
    v = m.update(Snap(heartbeat_age_s=2.0), 0)
    assert v.link_state == "stale" and "2.0 s" in v.link_text
    v = m.update(Snap(connected=False, heartbeat_age_s=4.5), 0)
    assert v.link_state == "lost" and "no heartbeat for 4.5 s" in v.link_text
    assert 'data-link="lost"' in v.status_html
    assert m.update(Snap(heartbeat_age_s=0.1), 0).link_state == "ok"      # back again


def test_command_feedback(ds1):
    m = _model(ds1)
    fb = m.command_started("arm")
    assert fb.state == "pending" and "sending" in m.commands_html()
    m.command_finished(fb, Outcome(400, "COMPONENT_ARM_DISARM", 0, "ACCEPTED", 0.042))
    assert fb.state == "accepted" and fb.level == "ok" and "ACCEPTED (42 ms)" in fb.text

    fb = m.command_finished(m.command_started("transition to fixed-wing"),
                            Outcome(3000, "DO_VTOL_TRANSITION", 2, "DENIED", 0.01,
                                    "Transition refused: not flying"))
    assert fb.state == "refused" and fb.level == "error"
    assert fb.text == ("transition to fixed-wing: refused by the autopilot: DENIED "
                       "(Transition refused: not flying)")

    fb = m.command_finished(m.command_started("inject rotor_2b"),
                            Outcome(59900, "INJECT_PARTIAL_LOSS", 2, "DENIED", 0.01))
    assert "SYS_FAILURE_EN = 1" in fb.text

    fb = m.command_finished(m.command_started("takeoff"),
                            Outcome(22, "NAV_TAKEOFF", None, "TIMEOUT", 4.5))
    assert fb.state == "no answer" and "no acknowledgement after 4.5 s" in fb.text

    fb = m.command_finished(m.command_started("inject bogus"), error=ValueError("unknown "
                                                                                "actuator"))
    assert fb.state == "error" and "not sent: unknown actuator" in fb.text

    fb = m.refuse_offline("arm", "lost")
    assert "not connected (link lost" in fb.text
    html = m.commands_html()
    assert html.index("not connected") < html.index("ACCEPTED (42 ms)")   # newest first
    assert html.count('class="vtolftc-cmd"') == 6


def test_fault_marks_on_bars(ds1):
    m = _model(ds1)
    m.record_faults(["rotor_2b"], 0.5)
    h = m.update(Snap(actuator_outputs=[0.4] * 15), 0).actuator_html
    cell = h[h.index('data-name="rotor_2b"'):]
    cell = cell[: cell.index('class="vtolftc-act"') if 'class="vtolftc-act"' in cell else None]
    assert "−50%" in cell and "#dc2626" in cell
    m.record_faults(["rotor_2b"], 0.0)
    assert "−50%" not in m.update(Snap(actuator_outputs=[0.4] * 15), 0).actuator_html


# -- the dashboard against a MAVLink autopilot on loopback -------------------------------
def _free_port(kind: int) -> int:
    with socket.socket(socket.AF_INET, kind) as s:
        s.bind(("127.0.0.1", 0))
        return int(s.getsockname()[1])


def _wait(pred, timeout_s: float, what: str):
    deadline = time.monotonic() + timeout_s
    while time.monotonic() < deadline:
        v = pred()
        if v:
            return v
        time.sleep(0.05)
    raise AssertionError(f"timed out after {timeout_s} s waiting for {what}")


@pytest.fixture
def dash_and_ap(ds1):
    from support.fake_autopilot import FakeAutopilot

    from vtolftc.dashboard.web import Dashboard

    udp = _free_port(socket.SOCK_DGRAM)
    dash = Dashboard(f"udp-server://127.0.0.1:{udp}", port=_free_port(socket.SOCK_STREAM),
                     rate_hz=20.0, airframe=ds1)
    ap = None
    try:
        ap = FakeAutopilot(f"udp-client://127.0.0.1:{udp}", speed=10.0)
        yield dash, ap
    finally:
        if ap is not None:
            ap.close()
        dash.close()


def _last(dash, label):
    return next((c for c in reversed(dash.model._commands) if c.label == label
                 and c.state != "pending"), None)


def test_dashboard_commands_reach_the_autopilot(dash_and_ap):
    dash, ap = dash_and_ap
    _wait(lambda: dash.view and dash.view.link_state == "ok", 10, "the link")
    dash.send("transition to fixed-wing", lambda: dash.gs.transition("fw"))
    fb = _wait(lambda: _last(dash, "transition to fixed-wing"), 10, "the ack")
    assert fb.state == "refused" and "not flying" in fb.text
    dash.send("arm", dash.gs.arm)
    dash.send("takeoff", lambda: dash.gs.takeoff(20.0))
    _wait(lambda: dash.view.altitude_m > 19.5, 20, "the climb")
    _wait(lambda: dash.view.armed, 3, "the armed flag (1 Hz heartbeat)")
    assert (400, 0) in ap.commands and (22, 0) in ap.commands
    dash._dd_act.value = "rotor_2b"
    dash._sl_loss.value = 0.5
    dash._inject(0.5)
    fb = _wait(lambda: _last(dash, "inject rotor_2b loss 50 %"), 10, "the inject ack")
    assert fb.state == "refused" and "SYS_FAILURE_EN" in fb.text
    assert "rotor_2b" not in dash.model.faults
    dash.send("allow", lambda: dash._param_outcome("SYS_FAILURE_EN", 1))
    _wait(lambda: _last(dash, "allow"), 10, "the parameter")
    dash._inject(0.5)
    _wait(lambda: dash.model.faults.get("rotor_2b") == 0.5, 10, "the accepted injection")
    assert ap.faults[(101, 4)] == 0.5            # rotor_2b = motor 4
    dash.send("transition to fixed-wing", lambda: dash.gs.transition("fw"))
    _wait(lambda: dash.view.vtol_text == "FW", 20, "fixed-wing")
    assert dash.view.position_ned_m[0] > 10.0 and len(dash.view.path) > 5


def test_dashboard_reports_dropout_and_refuses_offline(dash_and_ap):
    dash, ap = dash_and_ap
    dash.model.stale_after_s, dash.model.lost_after_s = 0.4, 0.8
    _wait(lambda: dash.view and dash.view.link_state == "ok", 10, "the link")
    ap.paused = True
    _wait(lambda: dash.view.link_state == "lost", 5, "the link loss")
    assert "no heartbeat for" in dash.view.status_html
    dash.send("arm", dash.gs.arm)
    assert "not connected (link lost" in dash.model.commands_html()
    assert (400, 0) not in ap.commands
    ap.paused = False
    _wait(lambda: dash.view.link_state == "ok", 5, "the link coming back")


def test_dashboard_without_autopilot_says_so(ds1):
    from vtolftc.dashboard.web import Dashboard

    udp = _free_port(socket.SOCK_DGRAM)
    with Dashboard(f"udp-server://127.0.0.1:{udp}", port=_free_port(socket.SOCK_STREAM),
                   airframe=ds1) as dash:
        _wait(lambda: dash.view is not None, 5, "a first update")
        assert dash.view.link_state == "waiting"
        assert f"waiting for the autopilot on udp-server://127.0.0.1:{udp}" in \
            dash.view.status_html
        dash.send("takeoff", dash.gs.takeoff)
        assert "not connected (no heartbeat yet" in dash.model.commands_html()


def test_cli_dashboard_arguments(capsys):
    from vtolftc.cli.main import run

    assert run(["dashboard", "--host", "10.1.2.3"]) == 2
    assert "needs --allow-remote" in capsys.readouterr().err
    assert run(["dashboard", "--url", "tcp://127.0.0.1:5"]) == 2
    assert "unknown scheme" in capsys.readouterr().err
    assert run(["dashboard", "--rate", "0"]) == 2
    udp = _free_port(socket.SOCK_DGRAM)
    with socket.socket(socket.AF_INET, socket.SOCK_DGRAM) as s:   # port taken
        s.bind(("127.0.0.1", udp))
        assert run(["dashboard", "--url", f"udp-server://127.0.0.1:{udp}", "--duration",
                    "0.1"]) == 1
    assert "cannot open ground-station link" in capsys.readouterr().err
    port = _free_port(socket.SOCK_STREAM)
    assert run(["dashboard", "--url", f"udp-server://127.0.0.1:{udp}", "--port", str(port),
                "--duration", "0.6"]) == 0
    out = capsys.readouterr()
    assert f"http://127.0.0.1:{port}/" in out.out and "waiting for the autopilot" in out.err


def test_mission_points_and_status_lines():
    """The mission drawn in the 3-D view: the display frame of the planned positions."""
    from types import SimpleNamespace

    from vtolftc.dashboard.model import _extras, mission_points_display
    from vtolftc.firmware_sim.vehicle.sensors import Home
    from vtolftc.runners.mission_run import rectangle_mission

    h = Home()
    pts, seqs = mission_points_display(rectangle_mission(), h.lat_deg, h.lon_deg, h.alt_m)
    # takeoff at home, corners (300, 0), (300, 600), (0, 600), (0, 0) N/E at 30 m, land home
    want = [(0, 0, 30), (300, 0, 30), (300, -600, 30), (0, -600, 30), (0, 0, 30), (0, 0, 0)]
    assert seqs == [0, 2, 3, 4, 5, 7]
    assert np.allclose(pts, want, atol=0.05)
    snap = SimpleNamespace(battery_v=24.1, battery_a=48.0, battery_remaining=0.87,
                           gps_fix_type=3, gps_satellites=12, gps_hdop=1.0, mission_total=8,
                           mission_seq=3, mission_state=3)
    ex = _extras(snap)
    assert ex["battery_text"] == "24.10 V · 48.0 A · 87 %"
    assert ex["gps_text"] == "3D fix · 12 sats · hdop 1.0"
    assert ex["mission_text"] == "item 3 of 8 · active"

"""The SITL processes in real time against a hostile or faulty neighbour on loopback.

One pair of processes (real time, UDP) flies several short flights in file order: a flood of
invalid PARAM_SET and COMMAND_LONG in hover, stray datagrams and a fault command sent straight
to the vehicle, and each failsafe (data-link loss, HIL data loss, the vehicle's output watchdog
with the crash detection that follows). Every bound is generous (the machine is shared) but
would fail if the property did not hold; every wait polls for readiness.

Both processes run with ``--rt-priority`` (SCHED_FIFO once compiled, where permitted: root,
as CI; :data:`support.procs.RT_PRIORITY`). A loaded CI run (2 CPU burners, load 3.3-5.3) lost
the take-off that the output-watchdog test needs before its subject: ordinary processes can be
runnable yet get no CPU for longer than the 0.5 s HIL-loss and watchdog tolerances, so a
failsafe fired during the take-off and the next one timed out (60 s). The tolerances are the
subject of two of these tests and stay; the starvation is taken out. Session 15, beside 4
burners and a dd/fsync writer (load 8-15): main's module passed 2/2 and the watchdog test
alone 3/3 (not reproduced); with the priority the module passed 5/5 (3 with it set at
process start, 2 once ready) and the test alone 3/3 (set at start);
with the vehicle's watchdog disabled (mutation) the watchdog test fails.
"""

from __future__ import annotations

import csv
import json
import math
import os
import signal
import socket
import threading
import time
from pathlib import Path

import pytest
from support.procs import RT_PRIORITY

from vtolftc.gcs.client import GroundStation
from vtolftc.protocols import make_codec, open_link
from vtolftc.protocols.netutil import free_udp_port
from vtolftc.runners.sitl import SitlConfig, SitlRun

pytestmark = pytest.mark.slow

TAKEOFF_M = 5.0
DL_LOSS_T = 2.0
HIL_LOSS_T = 0.5
OUTPUT_TIMEOUT = 0.5


class Observer:
    """A passive ground-station link: receives the autopilot's telemetry, never sends (so it
    never counts as a live ground station)."""

    def __init__(self, port: int) -> None:
        self.link = open_link(f"udp-server://127.0.0.1:{port}")
        self.texts: list[tuple[float, str]] = []
        self.heartbeats: list[tuple[float, int, bool]] = []  # (time, system_status, armed)
        self.landed = 0
        self._closed = False
        self._th = threading.Thread(target=self._run, daemon=True)
        self._th.start()

    def _run(self) -> None:
        while not self._closed:
            for m in self.link.recv(0.1):
                t = m.get_type()
                now = time.monotonic()
                if t == "STATUSTEXT":
                    text = m.text if isinstance(m.text, str) else m.text.decode(errors="replace")
                    self.texts.append((now, text.rstrip("\x00")))
                elif t == "HEARTBEAT" and m.get_srcComponent() == 1:
                    self.heartbeats.append((now, int(m.system_status),
                                            bool(m.base_mode & 128)))
                elif t == "EXTENDED_SYS_STATE":
                    self.landed = int(m.landed_state)

    def wait_text(self, needle: str, since: float, timeout_s: float) -> float:
        deadline = time.monotonic() + timeout_s
        while time.monotonic() < deadline:
            for t, text in list(self.texts):
                if t >= since and needle in text:
                    return t
            time.sleep(0.01)
        raise AssertionError(f"no STATUSTEXT with {needle!r}; got "
                             f"{[x for t, x in self.texts if t >= since]}")

    def state_seen(self, state: int, since: float, timeout_s: float = 3.0) -> bool:
        """A HEARTBEAT with this MAV_STATE since ``since`` (waits: they come at 1 Hz)."""
        deadline = time.monotonic() + timeout_s
        while True:
            if any(t >= since and s == state for t, s, _ in self.heartbeats):
                return True
            if time.monotonic() > deadline:
                return False
            time.sleep(0.02)

    def wait_disarmed_on_ground(self, timeout_s: float) -> None:
        deadline = time.monotonic() + timeout_s
        while time.monotonic() < deadline:
            if self.heartbeats and not self.heartbeats[-1][2] and self.landed == 1:
                return
            time.sleep(0.05)
        raise AssertionError(f"not landed and disarmed within {timeout_s:g} s")

    def close(self) -> None:
        self._closed = True
        self._th.join(2.0)
        self.link.close()


@pytest.fixture(scope="module")
def rt(tmp_path_factory):
    out = tmp_path_factory.mktemp("sitl_resilience")
    obs_port, flood_port = free_udp_port(), free_udp_port()
    obs = Observer(obs_port)
    cfg = SitlConfig(out_dir=out, realtime=True, plots=False, failure_injection=False,
                     extra_autopilot_args=[
                         "--gcs-link", f"udp-client://127.0.0.1:{obs_port}",
                         "--gcs-link", f"udp-server://127.0.0.1:{flood_port}",
                         "--param", f"COM_DL_LOSS_T={DL_LOSS_T}",
                         "--param", "NAV_DLL_ACT=3",
                         "--param", f"COM_HIL_LOSS_T={HIL_LOSS_T}", *RT_PRIORITY],
                     extra_vehicle_args=["--output-timeout", str(OUTPUT_TIMEOUT), *RT_PRIORITY])
    run = SitlRun(cfg)
    run.obs = obs
    run.flood_port = flood_port
    try:
        run.start()
        yield run
    finally:
        run.close()
        obs.close()


def _take_off(run) -> None:
    gs = run.gs
    gs.wait_for(lambda s: s.connected and not s.armed and s.landed_state == 1
                and math.isfinite(s.home_amsl_m), 120.0)
    assert gs.arm().accepted
    assert gs.takeoff(TAKEOFF_M).accepted
    gs.wait_for(lambda s: s.mode_name == "AUTO.LOITER" and s.altitude_m > TAKEOFF_M - 0.5,
                60.0)
    time.sleep(3.0)  # settle in hover (wall = simulated time here)


def _telemetry(run, t0: float, t1: float) -> list[dict[str, float]]:
    """Rows of the autopilot's telemetry.csv with t0 <= time_s < t1 (flushed every 1 s)."""
    path = Path(run.out) / "autopilot" / "telemetry.csv"
    rows = []
    with path.open(newline="") as f:
        for r in csv.DictReader(f):
            try:
                t = float(r["time_s"])
            except (TypeError, ValueError):
                continue
            if t0 <= t < t1:
                rows.append({k: float(r[k]) for k in ("time_s", "roll_deg", "pitch_deg",
                                                      "roll_ref_deg", "pitch_ref_deg",
                                                      "altitude_m", "altitude_ref_m")})
    return rows


def _window_stats(run, t0: float, t1: float) -> dict[str, float]:
    deadline = time.monotonic() + 10.0
    while run.gs.snapshot().sim_time_s < t1 + 1.5 and time.monotonic() < deadline:
        time.sleep(0.05)  # the telemetry file is flushed every simulated second
    rows = _telemetry(run, t0, t1)
    assert rows
    return {"steps_frac": len(rows) / ((t1 - t0) / 0.004),
            "att_err_deg": max(max(abs(r["roll_deg"] - r["roll_ref_deg"]),
                                   abs(r["pitch_deg"] - r["pitch_ref_deg"])) for r in rows),
            "alt_err_m": max(abs(r["altitude_m"] - r["altitude_ref_m"]) for r in rows)}


def _flood_frames(n: int) -> list[bytes]:
    """Invalid PARAM_SET (unknown names, out-of-range values) and COMMAND_LONG (unsupported
    ids, flight commands with bad params) from a few made-up clients."""
    frames = []
    codecs = [make_codec(sysid, 1) for sysid in (200, 201, 202, 203)]
    for k in range(n):
        c = codecs[k % len(codecs)]
        kind = k % 4
        if kind == 0:
            msg = c.param_set_encode(1, 1, f"NOPE_{k % 97}".encode(), 1.0, 9)
        elif kind == 1:
            msg = c.param_set_encode(1, 1, b"MIS_TAKEOFF_ALT", 1e9, 9)
        elif kind == 2:
            msg = c.command_long_encode(1, 1, 31010 + k % 7, 0, 1, 2, 3, 4, 5, 6, 7)
        else:
            msg = c.command_long_encode(1, 1, 400, 0, 7.0, 0, 0, 0, 0, 0, 0)  # bad arm param
        frames.append(msg.pack(c))
        c.seq = (c.seq + 1) & 0xFF
    return frames


def _hovering(run) -> None:
    """In hover at the take-off altitude: taken off here unless an earlier test of the module
    left the aircraft there (so each test also runs alone)."""
    s = run.gs.snapshot()
    if not (s.armed and s.mode_name == "AUTO.LOITER" and s.altitude_m > TAKEOFF_M - 0.5):
        _take_off(run)


def test_flood_of_invalid_requests_does_not_disturb_hover(rt):
    """10,000 invalid PARAM_SET and COMMAND_LONG in 5 s in real-time hover: attitude within
    2 deg of its reference, altitude within 0.5 m, and the control loop not starved (at least
    half the steps of the same machine without the flood; the benchmark measures the 95 %)."""
    _take_off(rt)
    gs = rt.gs
    t0 = gs.snapshot().sim_time_s
    time.sleep(5.0)
    idle = _window_stats(rt, t0, t0 + 5.0)
    frames = _flood_frames(10_000)
    sock = socket.socket(socket.AF_INET, socket.SOCK_DGRAM)
    t_start = gs.snapshot().sim_time_s
    w0 = time.monotonic()
    for i in range(0, len(frames), 20):  # 20 frames every 10 ms
        for f in frames[i:i + 20]:
            sock.sendto(f, ("127.0.0.1", rt.flood_port))
        time.sleep(max(0.0, w0 + (i + 20) / 2000.0 - time.monotonic()))
    flood_wall = time.monotonic() - w0
    t_end = gs.snapshot().sim_time_s
    sock.close()
    flood = _window_stats(rt, t_start, t_end)
    print(f"idle {idle}, flood {flood} ({flood_wall:.2f} s wall)")
    assert flood_wall < 7.0
    assert idle["att_err_deg"] < 2.0 and idle["alt_err_m"] < 0.5  # the test is meaningful
    assert flood["att_err_deg"] < 2.0
    assert flood["alt_err_m"] < 0.5
    # the flood must not starve the control loop. How many real-time steps a process gets is
    # the machine's business (this test's own sender shares the 2 cores; measured 0.89 against
    # 0.97 idle on a loaded 2-core CI run): the 95 % figure is measured by
    # benchmarks/bench_resilience.py; here a flood that starves the loop (a fraction of the
    # idle steps) fails, scheduler noise does not
    assert flood["steps_frac"] >= 0.5 * min(1.0, idle["steps_frac"])
    # the commands were answered (some) and the excess dropped and counted, never queued
    assert gs.command_long(31010, [1.0]).result_name == "UNSUPPORTED"
    assert gs.param_get("MIS_TAKEOFF_ALT") == pytest.approx(30.0)


def test_stray_datagrams_and_direct_fault_command_change_nothing(rt):
    """Garbage, valid HIL_ACTUATOR_CONTROLS and a fault command sent straight to the vehicle's
    HIL port from another port: refused; the hover goes on."""
    _hovering(rt)
    gs = rt.gs
    port = int(rt.urls["vehicle"].rsplit(":", 1)[1])
    stray = open_link(f"udp-client://127.0.0.1:{port}", system_id=1, component_id=1)
    c = stray.codec
    t0 = gs.snapshot().sim_time_s
    t_sim = int(t0 * 1e6)
    for k in range(200):
        stray.send(b"\xfe\x21garbage garbage")
        stray.send(c.hil_actuator_controls_encode(t_sim + 4000 * k, [0.0] * 16, 128, 0))
        stray.send(c.command_long_encode(0, 0, 59900, 0, 101.0, 0.0, 1.0, 0, 0, 0, 0))
        time.sleep(0.01)
    got = stray.recv(0.2)
    stray.close()
    assert got == []
    t1 = gs.snapshot().sim_time_s
    st = _window_stats(rt, t0, t1)
    assert st["att_err_deg"] < 2.0 and st["alt_err_m"] < 0.5
    assert gs.snapshot().altitude_m > TAKEOFF_M - 0.5
    # no fault reached the vehicle: every actuator still commanded, none reported failed
    assert not any("fault" in t.lower() for _, t in rt.obs.texts)


def test_datalink_loss_lands(rt):
    """No ground-station heartbeat for COM_DL_LOSS_T: STATUSTEXT, MAV_STATE_CRITICAL, land
    (NAV_DLL_ACT 3)."""
    gs = rt.gs
    assert gs.snapshot().armed
    url = rt.urls["ground_station"]
    gs.close()  # its heartbeats stop
    t_lost = time.monotonic()
    t_fire = rt.obs.wait_text("data link lost", t_lost, DL_LOSS_T + 10.0)
    # the last heartbeat left up to 1 s before the close
    assert DL_LOSS_T - 1.2 <= t_fire - t_lost <= DL_LOSS_T + 1.5
    assert rt.obs.state_seen(5, t_lost)  # MAV_STATE_CRITICAL
    rt.obs.wait_disarmed_on_ground(TAKEOFF_M / 0.7 + 20.0)
    rt.gs = GroundStation(url)
    rt.gs.add_listener(rt._on_message)
    rt.gs.wait_for(lambda s: s.connected, 10.0)


def test_hil_data_loss_reported_and_lands(rt):
    """The vehicle stops (SIGSTOP) in hover: after COM_HIL_LOSS_T the autopilot reports
    EMERGENCY and switches to land; the vehicle back, it lands."""
    _take_off(rt)
    veh = rt.procs["vehicle"]
    t_stop = time.monotonic()
    os.kill(veh.pid, signal.SIGSTOP)
    try:
        t_fire = rt.obs.wait_text("HIL data lost", t_stop, HIL_LOSS_T + 10.0)
        assert HIL_LOSS_T - 0.05 <= t_fire - t_stop <= HIL_LOSS_T + 1.5
        assert rt.obs.state_seen(6, t_stop)  # MAV_STATE_EMERGENCY
    finally:
        os.kill(veh.pid, signal.SIGCONT)
    rt.obs.wait_text("HIL data back", t_stop, 10.0)
    rt.gs.wait_for(lambda s: s.mode_name == "AUTO.LAND" or not s.armed, 10.0)
    rt.obs.wait_disarmed_on_ground(TAKEOFF_M / 0.7 + 20.0)


def test_autopilot_silent_vehicle_safe_output_then_crash_reported(rt):
    """The autopilot stops (SIGSTOP) in hover: the vehicle's watchdog stops the rotors after
    --output-timeout (not the last commands); the autopilot back, it reports the crash and
    disarms."""
    _take_off(rt)
    ap = rt.procs["autopilot"]
    os.kill(ap.pid, signal.SIGSTOP)
    t_stop = time.monotonic()
    try:
        time.sleep(OUTPUT_TIMEOUT + 3.0)  # watchdog, then a 5 m fall
    finally:
        os.kill(ap.pid, signal.SIGCONT)
    rt.obs.wait_text("crash detected", t_stop, 15.0)
    rt.obs.wait_disarmed_on_ground(15.0)
    events = [json.loads(x) for x in
              (Path(rt.out) / "vehicle" / "vehicle_events.jsonl").read_text().splitlines()]
    trip = [e for e in events if e["event"] == "watchdog" and "stopped" in e["text"]]
    assert trip, events
    # the commands froze when the autopilot stopped and went to 0 OUTPUT_TIMEOUT later
    path = Path(rt.out) / "vehicle" / "vehicle_truth.csv"
    deadline = time.monotonic() + 10.0
    while True:
        with path.open(newline="") as f:
            rows = list(csv.DictReader(f))
        last_t = float(rows[-1]["time_s"]) if rows else 0.0
        if last_t > trip[-1]["time_s"] + 0.2 or time.monotonic() > deadline:
            break
        time.sleep(0.2)
    cmd_cols = [k for k in rows[0] if k.startswith("cmd_rotor")]
    t_trip = trip[-1]["time_s"]
    before = [r for r in rows if float(r["time_s"]) < t_trip - 1e-9]
    frozen = [float(before[i]["time_s"]) for i in range(1, len(before))
              if any(before[i][k] != before[i - 1][k] for k in cmd_cols)]
    t_frozen = frozen[-1]
    assert OUTPUT_TIMEOUT - 0.05 <= t_trip - t_frozen <= OUTPUT_TIMEOUT + 1.0
    after = [r for r in rows if float(r["time_s"]) > t_trip + 0.005]
    assert after and all(float(after[0][k]) == 0.0 for k in cmd_cols)
    assert math.isfinite(t_frozen)


def test_fresh_install_first_real_time_flight_takes_off_and_transitions(tmp_path,
                                                                        monkeypatch):
    """An empty numba cache (a fresh install): the processes compile before they report
    ready, and the first real-time flight takes off and completes a front transition."""
    monkeypatch.setenv("NUMBA_CACHE_DIR", str(tmp_path / "empty_numba_cache"))
    cfg = SitlConfig(out_dir=tmp_path / "run", realtime=True, plots=False,
                     failure_injection=False, startup_timeout_s=600.0,
                     vehicle_timeout_s=5.0)  # the processes' default: a 5 s stall ends it
    with SitlRun(cfg) as run:
        run.start()  # returns once the autopilot says MAV_STATE_STANDBY
        gs = run.gs
        # ready to fly, as a ground station sees it: HIL data flowing and home known (the
        # vehicle may still be compiling its own kernels when the autopilot is warm)
        gs.wait_for(lambda s: s.connected and s.landed_state == 1
                    and math.isfinite(s.home_amsl_m), 300.0)
        assert gs.arm().accepted
        assert gs.takeoff(10.0).accepted
        gs.wait_for(lambda s: s.mode_name == "AUTO.LOITER" and s.altitude_m > 9.0, 90.0)
        assert gs.transition("fw").accepted
        gs.wait_for(lambda s: s.vtol_state_name == "FW", 60.0)
        assert gs.snapshot().altitude_m > 5.0
    log = (tmp_path / "run" / "autopilot.log").read_text()
    assert "warm in" in log and "silent" not in log

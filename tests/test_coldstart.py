"""Cold start: nothing compiles after the autopilot says STANDBY, and it answers while booting.

- the warm-up visits every flight mode and prepares every kernel of the flight path;
- the allocator hands its compiled kernels one array type whatever matrix it is given (a
  cached read-only one, its own writable one, another layout);
- a flight through every mode after the warm-up compiles no new specialisation of any
  autopilot kernel and no step takes 50 ms of CPU (subprocess: a fresh interpreter);
- while booting (not ready) every flight and fault command is answered TEMPORARILY_REJECTED
  by the worker itself, without the control thread;
- SITL with an empty numba cache (slow, real time): commands during BOOT get an ACK within
  0.5 s; after STANDBY a flight through hover, transitions, fixed-wing, a fault, AUTO.MISSION,
  AUTO.RTL and land has no step over 50 ms of CPU, no watchdog cut and no new specialisation.
"""

from __future__ import annotations

import json
import math
import subprocess
import sys
import threading
import time
from pathlib import Path

import pytest
from support.memory_link import CaptureTransport, parse, sent_messages
from support.procs import RT_PRIORITY

from vtolftc.airframe.loader import load_airframe
from vtolftc.firmware_sim.autopilot.autopilot import Autopilot
from vtolftc.firmware_sim.autopilot.gcs_endpoint import GcsEndpoint
from vtolftc.firmware_sim.autopilot.hil_bridge import HilBridge
from vtolftc.firmware_sim.autopilot.interface import FlightMode
from vtolftc.firmware_sim.autopilot.mission import (
    FRAME_GLOBAL_RELATIVE_ALT_INT,
    NAV_WAYPOINT,
    MissionItem,
)
from vtolftc.firmware_sim.autopilot.warmup import (
    compiled_specialisations,
    new_specialisations,
    warm_up,
)
from vtolftc.protocols import Link, make_codec
from vtolftc.protocols.failure_units import ActuatorTable
from vtolftc.protocols.generated import constants as mav
from vtolftc.protocols.netutil import free_udp_port

HERE = Path(__file__).resolve().parent
AP = "vtolftc.firmware_sim.autopilot."
STEP_CPU_MAX_S = 0.05


def _autopilot_only(d: dict) -> dict:
    return {k: v for k, v in d.items() if k.startswith(AP)}


def test_warm_up_visits_every_mode_and_prepares_the_flight_kernels():
    seen: list[FlightMode] = []
    made: list[Autopilot] = []
    af = load_airframe()

    def make() -> Autopilot:
        ap = Autopilot(af)
        step = ap.step

        def recording_step(nav):
            u = step(nav)
            seen.append(ap.status().mode)
            return u

        ap.step = recording_step  # type: ignore[method-assign]
        made.append(ap)
        return ap

    n = warm_up(make)
    assert len(made) == 1 and n == len(seen)
    order = [m for i, m in enumerate(seen) if i == 0 or m != seen[i - 1]]
    assert order == [FlightMode.IDLE, FlightMode.TAKEOFF, FlightMode.HOVER,
                     FlightMode.FRONT_TRANSITION, FlightMode.FIXED_WING,
                     FlightMode.BACK_TRANSITION, FlightMode.HOVER, FlightMode.LAND,
                     FlightMode.IDLE], order
    assert not made[0].status().armed  # landed and disarmed
    # fixed-wing long enough for the lift rotors to become the reserve (the second allocator)
    dt = made[0].dt
    fw = sum(1 for m in seen if m == FlightMode.FIXED_WING) * dt
    assert fw > made[0].params.get("VT_TRANS_P2_DUR") + 0.5
    sigs = compiled_specialisations(AP)
    for name in ("allocation.active_set._ppid_allocate_step_tracked",  # the ones that fly
                 "outer_kernels.mc_hold_step", "estimate.estimate_step",
                 "outer_kernels.outer_aero_step", "outer_kernels.fw_longitudinal_step",
                 "outer_kernels.mc_transition_step", "outer_kernels.mc_z_force_step"):
        assert sigs[AP + name], name


def test_warm_up_stops_on_request():
    af = load_airframe()
    calls = [0]

    def stop() -> bool:
        calls[0] += 1
        return calls[0] > 20

    assert warm_up(lambda: Autopilot(af), stop=stop) <= 20


_ONE_TYPE = r"""
import json
import numpy as np
from vtolftc.airframe.loader import load_airframe
from vtolftc.firmware_sim.autopilot.autopilot import Autopilot
from vtolftc.firmware_sim.autopilot.allocation import active_set
ap = Autopilot(load_airframe())
alloc = ap.allocator
B = ap.effectiveness.matrix_on_grid(12.0)          # cached, read-only
v = np.array([-100.0, 10.0, 0.5, -0.3, 0.1])
counts = []
for b in (B, B.copy(), np.asfortranarray(B), np.hstack([B, B])[:, : B.shape[1]]):
    alloc.allocate(v, b, u_pref=ap.u_pref_mc)
    counts.append(len(active_set._allocate_step_packed.signatures))
print(json.dumps(counts))
"""


def test_allocator_compiles_one_specialisation_for_any_matrix_type():
    """A fresh interpreter (no other test's calls): read-only, writable, Fortran-ordered and
    strided matrices all run on the first specialisation."""
    out = subprocess.run([sys.executable, "-c", _ONE_TYPE], capture_output=True, text=True,
                         timeout=600, check=True)
    assert json.loads(out.stdout.strip().splitlines()[-1]) == [1, 1, 1, 1]


def test_new_specialisations_lists_only_the_new_ones():
    before = {"a": ["(int64,)"], "b": []}
    after = {"a": ["(float64,)", "(int64,)"], "b": [], "c": ["(bool,)"]}
    assert new_specialisations(before, after) == {"a": ["(float64,)"], "c": ["(bool,)"]}
    assert new_specialisations(after, after) == {}


@pytest.mark.slow
def test_flight_through_every_mode_compiles_nothing_after_warm_up():
    """In-process, a fresh interpreter: warm-up, then take-off, hover, front transition,
    fixed-wing (rotor ramp, then the reserve), a case-1 fault, AUTO.MISSION, AUTO.RTL (back
    transition), land, disarm."""
    out = subprocess.run([sys.executable, str(HERE / "support" / "every_mode_flight.py")],
                         capture_output=True, text=True, timeout=900, check=True)
    res = json.loads(out.stdout.strip().splitlines()[-1])
    assert res["stage"] == "landed", res
    assert set(res["modes"]) >= {"TAKEOFF", "HOVER", "FRONT_TRANSITION", "FIXED_WING",
                                 "BACK_TRANSITION", "LAND", "IDLE"}, res["modes"]
    assert set(res["px4_modes"]) >= {"AUTO.TAKEOFF", "AUTO.LOITER", "AUTO.MISSION",
                                     "AUTO.RTL", "AUTO.LAND"}, res["px4_modes"]
    assert _autopilot_only(res["compiled_during_flight"]) == {}
    assert res["max_step_cpu_s"] < STEP_CPU_MAX_S, res["max_step_cpu_s"]


# ---------------------------------------------------------------------------- booting


def test_every_flight_and_fault_command_rejected_at_once_while_booting():
    """The worker answers alone (no ``poll`` by the control thread, which is compiling)."""
    af = load_airframe()
    ap = Autopilot(af)
    link = Link(CaptureTransport(), system_id=1, component_id=1)
    hil = HilBridge(Link(CaptureTransport(), system_id=1, component_id=1))
    ep = GcsEndpoint(ap, hil, [link], actuators=ActuatorTable.from_names(af.actuator_names),
                     start=False, ready=False)
    ap.params.set("SYS_FAILURE_EN", 1)
    gs = make_codec(255, 190)
    nan = math.nan
    cmds = [(400, [1.0, 0, 0, 0, 0, 0, 0]), (22, [nan] * 7),
            (176, [1.0, 4.0, 3.0, 0, 0, 0, 0]), (3000, [4.0, 0, 0, 0, 0, 0, 0]),
            (21, [nan] * 7), (20, [nan] * 7), (420, [101, 1, 1, 0, 0, 0, 0]),
            (mav.MAV_CMD_INJECT_PARTIAL_LOSS, [101, 1, 0.5, 0, 0, 0, 0])]
    for cid, p in cmds:
        data = gs.command_long_encode(1, 1, cid, 0, *p).pack(gs)
        gs.seq = (gs.seq + 1) & 0xFF
        ep.io.queues[0].extend(parse([data]))
    ep.serve_once()
    acks = [m for m in sent_messages(link.transport) if m.get_type() == "COMMAND_ACK"]
    assert [(a.command, a.result) for a in acks] == [
        (cid, mav.MAV_RESULT_TEMPORARILY_REJECTED) for cid, _ in cmds]
    assert not ep.has_pending() and not ap.status().armed
    ep.close()


# ---------------------------------------------------------------------------- SITL, cold
def _recv(conn, types, timeout_s, pred=lambda m: True):
    end = time.monotonic() + timeout_s
    while time.monotonic() < end:
        m = conn.recv_match(type=types, blocking=True, timeout=0.1)
        if (m is not None and m.get_srcSystem() == 1 and m.get_srcComponent() == 1
                and pred(m)):
            return m
    return None


@pytest.mark.slow
def test_fresh_cache_sitl_flight_through_every_mode_never_stalls(tmp_path, monkeypatch):
    """Real time, an empty numba cache for both processes. While the autopilot boots, each
    command is answered TEMPORARILY_REJECTED within 0.5 s. Then: take-off to 10 m, hover,
    front transition, fixed-wing past the rotor ramp, a rotor fault, AUTO.MISSION, AUTO.RTL
    (back transition), land, disarm: no control step over 50 ms of CPU, no watchdog cut, no
    numba specialisation compiled after STANDBY.

    A stall probe watches the flight from outside (:mod:`support.stall_probe`): if the
    simulated time stops for 0.4 s (the vehicle's output watchdog cuts at 0.5 s), it writes
    what both processes' threads were doing (scheduler state, CPU, kernel wait channel,
    Python stacks by py-spy) and the machine's load to ``run/stall_probe/``, and the failure
    message says so. Seen under load (session 13, load 11-16 on 2 cores): one loop gap of
    1014 ms (step CPU max 1.0 ms, nothing compiled after ready) at t = 7.9 s, watchdog cut;
    a plain Python process sleeping 50 ms in a loop beside it overslept by up to 1.02 s in
    150 s: the processes were not scheduled, the autopilot's code did not stall. Session 14,
    twice beside 2 burners (load 7.6-12.5 with the other helpers): one pass (137 s); one
    failure: the probe saw stalls of 1.41 s (sim t = 1.7 s), 0.66 s and 0.73 s (t = 19.4,
    20.4 s), the vehicle thread runnable (state R) with 0 ms of CPU between samples, CPU
    pressure "some" 96-98 %; the vehicle's watchdog cut at t = 23.3 s. Same cause.

    The subject is a stall of *our* code after STANDBY, so OS starvation is taken out rather
    than excused: both processes run with ``--rt-priority`` (SCHED_FIFO from the moment they
    are compiled and ready, where permitted: root, as CI; :mod:`support.procs`), as PX4's
    threads do on POSIX, so ordinary processes cannot starve the flight; a stall of the
    flight code itself still stops the steps (mutation: a 1 s sleep in the autopilot's loop
    at t = 20 s fails this test). Session 15, beside 4 CPU burners and a dd/fsync writer
    (load 9-13, PSI cpu 97-99 %): main passed once (not reproduced); with the priority set at
    process start 2/2 failed (the two compilers at SCHED_FIFO held both cores: a boot ACK
    after 4.8 s), hence "once ready"; so set, it passed. The probe may still report 0.4-1.3 s
    "stalls" while both processes sleep between steps and the simulated time then jumps by
    as much: the probe's own process (ordinary priority) starved, not the flight; the probe
    reports, the checks below decide."""
    from pymavlink import mavutil
    from support.stall_probe import StallProbe

    from vtolftc.runners.mission_sitl import pymavlink_upload
    from vtolftc.runners.sitl import SitlConfig, SitlRun

    monkeypatch.setenv("NUMBA_CACHE_DIR", str(tmp_path / "empty_numba_cache"))
    port = free_udp_port()
    out = tmp_path / "run"
    cfg = SitlConfig(out_dir=out, realtime=True, plots=False, startup_timeout_s=600.0,
                     vehicle_timeout_s=5.0, extra_autopilot_args=[
                         "--gcs-link", f"udp-client://127.0.0.1:{port}",
                         "--param", "MPC_LAND_SPEED=1.5", *RT_PRIORITY],  # shorter, same paths
                     extra_vehicle_args=RT_PRIORITY)
    conn = mavutil.mavlink_connection(f"udpin:127.0.0.1:{port}", source_system=245,
                                      source_component=190, dialect="common")
    boot_acks: list[tuple[int, int, float]] = []
    probe: StallProbe | None = None
    try:
        with SitlRun(cfg) as run:
            failed: list[BaseException] = []

            def start() -> None:
                try:
                    run.start()
                except BaseException as exc:  # handed to the test thread
                    failed.append(exc)

            th = threading.Thread(target=start, daemon=True)
            th.start()
            hb = _recv(conn, ["HEARTBEAT"], 300.0)
            assert hb is not None, "no heartbeat from the booting autopilot"
            assert hb.system_status == mav.MAV_STATE_BOOT, hb  # cold: seconds of compiling
            for cid, params in ((mav.MAV_CMD_NAV_TAKEOFF, [math.nan] * 7),
                                (mav.MAV_CMD_DO_SET_MODE, [1.0, 4.0, 3.0, 0, 0, 0, 0]),
                                (mav.MAV_CMD_COMPONENT_ARM_DISARM, [1.0, 0, 0, 0, 0, 0, 0])):
                t0 = time.monotonic()
                conn.mav.command_long_send(1, 1, cid, 0, *params)
                ack = _recv(conn, ["COMMAND_ACK"], 5.0, lambda m, c=cid: m.command == c)
                assert ack is not None, f"no COMMAND_ACK to {cid} while booting"
                boot_acks.append((cid, int(ack.result), time.monotonic() - t0))
            th.join(600.0)
            assert not failed, failed
            gs = run.gs
            probe = StallProbe(lambda: gs.snapshot().sim_time_s,
                               {n: p.pid for n, p in run.procs.items()},
                               out / "stall_probe", stall_s=0.4, period_s=0.1).start()
            gs.wait_for(lambda s: s.connected and s.landed_state == 1
                        and math.isfinite(s.home_amsl_m), 300.0)
            home = _recv(conn, ["HOME_POSITION"], 30.0)
            assert home is not None
            lat = round(home.latitude + math.degrees(400.0 / 6_378_137.0) * 1e7)
            wp = MissionItem(0, FRAME_GLOBAL_RELATIVE_ALT_INT, NAV_WAYPOINT, 1, 0.0, 0.0, 0.0,
                             math.nan, lat, int(home.longitude), 10.0)
            assert pymavlink_upload(conn, [wp]).type == 0
            assert gs.arm().accepted
            assert gs.takeoff(10.0).accepted
            gs.wait_for(lambda s: s.mode_name == "AUTO.LOITER" and s.altitude_m > 8.5, 90.0)
            assert gs.transition("fw").accepted
            gs.wait_for(lambda s: s.vtol_state_name == "FW", 60.0)
            t_fw = gs.snapshot().sim_time_s
            gs.wait_for(lambda s: s.sim_time_s > t_fw + 3.0, 30.0)  # past VT_TRANS_P2_DUR
            assert gs.inject("rotor_2b", 0.5).accepted
            assert gs.set_mode("AUTO.MISSION").accepted
            gs.wait_for(lambda s: s.mode_name == "AUTO.MISSION", 10.0)
            t_m = gs.snapshot().sim_time_s
            gs.wait_for(lambda s: s.sim_time_s > t_m + 4.0, 30.0)
            assert gs.set_mode("AUTO.RTL").accepted
            gs.wait_for(lambda s: s.mode_name == "AUTO.RTL", 10.0)
            t_r = gs.snapshot().sim_time_s
            gs.wait_for(lambda s: s.sim_time_s > t_r + 4.0, 30.0)
            assert gs.land().accepted
            gs.wait_for(lambda s: s.mode_name == "AUTO.LAND", 10.0)
            gs.wait_for(lambda s: not s.armed and s.landed_state == 1, 180.0)
            probe.stop()   # before the processes stop (their stop is no stall)
    finally:
        if probe is not None:
            probe.stop()
        conn.close()
    stalls = "no probe" if probe is None else probe.summary()
    print(stalls)
    print("boot ACKs (command, result, s):", boot_acks)
    assert [(c, r) for c, r, _ in boot_acks] == [
        (mav.MAV_CMD_NAV_TAKEOFF, mav.MAV_RESULT_TEMPORARILY_REJECTED),
        (mav.MAV_CMD_DO_SET_MODE, mav.MAV_RESULT_TEMPORARILY_REJECTED),
        (mav.MAV_CMD_COMPONENT_ARM_DISARM, mav.MAV_RESULT_TEMPORARILY_REJECTED)]
    assert max(dt for _, _, dt in boot_acks) < 0.5, boot_acks
    summary = json.loads((out / "autopilot" / "autopilot_summary.json").read_text())
    vehicle = json.loads((out / "vehicle" / "vehicle_summary.json").read_text())
    print("autopilot step CPU max ms:", summary["step_cpu_max_ms"], "wall:",
          summary["step_wall_us"], "numba:", summary["numba"])
    assert summary["numba"]["specialisations_at_ready"] >= 2
    assert summary["numba"]["compiled_after_ready"] == {}
    assert summary["step_cpu_max_ms"] < 1e3 * STEP_CPU_MAX_S, stalls
    # the vehicle outlives the autopilot at the end (stopped first): a trip after that is
    # the stop, not the flight
    events = [json.loads(x) for x in
              (out / "vehicle" / "vehicle_events.jsonl").read_text().splitlines()]
    trips = [e for e in events if e["event"] == "watchdog"
             and e["time_s"] <= summary["sim_time_s"] + 0.4]
    assert not trips, (trips, stalls)
    assert vehicle["watchdog_trips"] <= 1, stalls
    assert not summary["failsafe_events"], (summary["failsafe_events"], stalls)


def test_summary_reports_what_was_compiled_after_ready():
    """The process summary's ``numba`` entry lists every specialisation that appeared after
    the recorded ready point (here: ready recorded as "nothing compiled")."""
    from vtolftc.firmware_sim.autopilot.process import AutopilotProcess

    af = load_airframe()
    link = Link(CaptureTransport(), system_id=1, component_id=1)
    proc = AutopilotProcess(Autopilot(af), link, [],
                            actuators=ActuatorTable.from_names(af.actuator_names))
    try:
        s = proc.summary()
        assert "numba" not in s and "part_mean_us" not in s  # not ready, no step yet
        proc.compiled_at_ready = {}
        warm_up(lambda: Autopilot(af), steps=40)
        late = proc.summary()["numba"]["compiled_after_ready"]
        assert late[AP + "allocation.active_set._ppid_allocate_step_tracked"], late
        proc.compiled_at_ready = compiled_specialisations()
        assert proc.summary()["numba"]["compiled_after_ready"] == {}
    finally:
        proc.gcs.close()
        proc.hil.link.close()

"""The rerun recorder: the .rrd file of a run holds the expected entities, each with a
non-empty time series on the simulated-time timeline, with the values that were fed in."""

from __future__ import annotations

import itertools
import math
import socket
import subprocess
import sys
import textwrap
import time
from pathlib import Path

import numpy as np
import pytest
from support.protocols import protocol_mismatches

from vtolftc.firmware_sim.autopilot.interface import (
    AutopilotStatus,
    FlightMode,
    LandedState,
    NavState,
    VtolState,
)
from vtolftc.telemetry import RunObserver, TelemetrySample, VehicleTruth
from vtolftc.telemetry.recording import RerunRecorder, actuator_entity, read_recording
from vtolftc.telemetry.rerun_reader import flown_path

NAMES = ("rotor_1a", "rotor_1b", "rotor_2a", "rotor_2b", "rotor_3a", "rotor_3b", "rotor_4a",
         "rotor_4b", "pusher_left", "pusher_right", "aileron_left", "aileron_right", "elevator",
         "rudder_left", "rudder_right")


def _sample(k: int, truth: bool = True) -> TelemetrySample:
    """Control step k at 250 Hz with values that are simple functions of time."""
    t_usec = 4000 * k
    t = t_usec * 1e-6
    pos = np.array([2.0 * t, -0.5 * t, -min(3.0 * t, 30.0)])
    yaw = 0.1 * t
    q = np.array([math.cos(yaw / 2), 0.0, 0.0, math.sin(yaw / 2)])
    nav = NavState(t_usec, q, np.zeros(3), pos, np.array([2.0, -0.5, 0.0]), 0.5 * t)
    mode = FlightMode.TAKEOFF if t < 2.0 else FlightMode.HOVER
    cmd = np.linspace(0.0, 1.4, 15) * (0.5 + 0.1 * math.sin(t))
    st = AutopilotStatus(t_usec, mode, True, VtolState.MC, LandedState.IN_AIR,
                         np.array([0.1, -0.05, yaw]), np.array([0.09, -0.04, yaw + 0.01]),
                         30.0, 0.5 * t, np.array([-120.0, 0.0, 1.0, -2.0, 0.5]), cmd, "ok",
                         "gs-shif")
    tr = None
    if truth:
        eff = np.ones(15)
        if t_usec >= 2_200_000:
            eff[3] = 0.5            # rotor_2b loses half its thrust at 2.2 s
        tr = VehicleTruth(pos, nav.vel_ned_m_s, q, np.array([0.09, -0.04, yaw]), np.zeros(3),
                          0.5 * t + 0.25, cmd * 0.9, eff)
    return TelemetrySample(t_usec, nav, st, tr)


def _feed(rec: RerunRecorder, n: int, truth: bool = True) -> None:
    rec.on_start({"actuator_names": list(NAMES), "case": "synthetic"})
    for k in range(n):
        s = _sample(k, truth)
        rec.on_sample(s)
        if k == 550:
            rec.on_event(s.time_usec, "fault", "injected rotor_2b: 50% loss")
        if k == 600:
            rec.on_event(s.time_usec, "command", "transition: DENIED")
    rec.on_finish({"rmse_altitude_m": 0.25})


EXPECTED = (
    [f"attitude/{a}" for a in ("roll", "pitch", "yaw")]
    + ["altitude", "airspeed", "mode/id", "mode/state", "mode/armed", "control/virtual",
       "events", "faults/log", "faults/marker", "world/aircraft", "world/path/00000"]
    + [actuator_entity(n) for n in NAMES]
)


def test_recorder_is_a_run_observer(tmp_path):
    rec = RerunRecorder(tmp_path / "r.rrd")
    try:
        assert isinstance(rec, RunObserver)
        assert protocol_mismatches(rec, RunObserver) == []
    finally:
        rec.close()


def test_synthetic_run_entities_and_values(tmp_path):
    path = tmp_path / "run" / "recording.rrd"
    rec = RerunRecorder(path)                 # 50 Hz, chunks of 500 rows
    _feed(rec, 1500)                          # 6 s at 250 Hz -> 300 rows
    data = read_recording(path)
    missing = [e for e in EXPECTED if e not in data]
    assert not missing, missing
    for e in EXPECTED:
        t, v = data[e]
        assert len(t) > 0 and len(v) == len(t), e
    # decimation: 250 Hz -> 50 Hz on the sim_time timeline, in seconds
    t, roll = data["attitude/roll"]
    assert len(t) == 300 and np.allclose(np.diff(t), 0.02)
    assert t[0] == 0.0 and t[-1] == pytest.approx(5.98)
    # degrees at the edge: [reference, actual]
    assert np.allclose(roll[:, 0], math.degrees(0.1)) and np.allclose(roll[:, 1],
                                                                     math.degrees(0.09))
    _, yaw = data["attitude/yaw"]
    assert np.allclose(yaw[:, 0], np.degrees(0.1 * t))
    # altitude up positive, [reference, actual]
    _, alt = data["altitude"]
    assert np.allclose(alt[:, 0], 30.0) and np.allclose(alt[:, 1], np.minimum(3.0 * t, 30.0))
    _, air = data["airspeed"]
    assert np.allclose(air[:, 0], 0.5 * t) and np.allclose(air[:, 1], 0.5 * t + 0.25)
    # actuators: [command, truth position x effectiveness]
    _, r2b = data["actuators/rotors/rotor_2b"]
    cmd = np.linspace(0.0, 1.4, 15)[3] * (0.5 + 0.1 * np.sin(t))
    assert np.allclose(r2b[:, 0], cmd)
    eff = np.where(t >= 2.2 - 1e-9, 0.5, 1.0)
    assert np.allclose(r2b[:, 1], 0.9 * cmd * eff)
    _, ail = data["actuators/surfaces/aileron_left"]
    assert ail.shape == (300, 2)
    # modes: scalar every row, names on change
    tm, names = data["mode/state"]
    assert names == ["TAKEOFF", "HOVER"] and tm[1] == pytest.approx(2.0)
    assert set(np.unique(data["mode/id"][1])) == {FlightMode.TAKEOFF, FlightMode.HOVER}
    # fault marker and text at the event time
    tf, fv = data["faults/marker"]
    assert tf.tolist() == [pytest.approx(2.2)] and fv.tolist() == [1.0]
    assert "rotor_2b" in data["faults/log"][1][0]
    assert any("[command] transition: DENIED" in s for s in data["events"][1])
    # pose: translation in NED
    tp, tr = data["world/aircraft"]
    assert np.allclose(np.array(tr)[-1], [2.0 * tp[-1], -0.5 * tp[-1], -min(3 * tp[-1], 30)],
                       atol=1e-5)
    path = flown_path(data)                  # every 10th row (5 Hz) over 6 s, one segment
    assert path.shape == (30, 3) and [k for k in data if k.startswith("world/path")] == [
        "world/path/00000"]
    assert np.allclose(path, [_sample(50 * i).truth.pos_ned_m for i in range(30)], atol=1e-5)


def test_flown_path_in_bounded_segments(tmp_path):
    """A long path goes out in segments of at most path_segment_points points, each logged
    again only while open (so neither memory nor the bytes of a send grow with the run);
    joined they are the whole path, every point once; the rows never keep sent points."""
    path = tmp_path / "seg.rrd"
    rec = RerunRecorder(path, path_segment_points=7)
    _feed(rec, 1500)                          # 30 path points: segments 7, 7, 7, 7, 6 (joints)
    assert rec._rows.path_pts == [] and len(rec._sender._seg) <= 7
    data = read_recording(path)
    segs = sorted(k for k in data if k.startswith("world/path/"))
    assert segs == [f"world/path/{i:05d}" for i in range(5)]
    for k in segs:
        t, forms = data[k]
        assert all(2 <= len(f) <= 7 for f in forms), k
        assert len(t) <= 3                    # full after <= 1.2 s: sent at most 3 times
    for a, b in itertools.pairwise(segs):
        assert data[a][1][-1][-1] == data[b][1][-1][0]       # each starts where one ended
    assert np.allclose(flown_path(data), [_sample(50 * i).truth.pos_ned_m for i in range(30)],
                       atol=1e-5)


def test_file_has_no_footer_but_verifies(tmp_path):
    """No rerun footer by default (its manifest would keep an entry for every chunk in memory
    for the whole run: issue 24); the file still verifies; write_footer=True writes one."""
    for footer in (False, True):
        path = tmp_path / f"f{footer}.rrd"
        _feed(RerunRecorder(path, write_footer=footer), 300)
        args = [sys.executable, "-m", "rerun", "rrd", "verify", str(path)]
        strict = subprocess.run(args, capture_output=True, text=True, timeout=120)
        assert (strict.returncode == 0) == footer, strict.stderr
        lax = subprocess.run([*args[:5], "--check-footers", "false", *args[5:]],
                             capture_output=True, text=True, timeout=120)
        assert lax.returncode == 0, lax.stderr


def test_without_truth_only_commands(tmp_path):
    path = tmp_path / "sitl.rrd"
    _feed(RerunRecorder(path), 300, truth=False)
    data = read_recording(path)
    _, r = data["actuators/rotors/rotor_1b"]
    assert r.ndim == 1 and len(r) == 60       # command only
    _, air = data["airspeed"]
    assert air.ndim == 1


def test_interrupted_run_leaves_a_readable_file(tmp_path):
    """A process killed without on_finish (no footer) still leaves every sent chunk."""
    path = tmp_path / "killed.rrd"
    code = textwrap.dedent(f"""
        import os, sys
        sys.path.insert(0, {str(Path(__file__).parent)!r})
        from test_recording import _sample
        from vtolftc.telemetry.recording import RerunRecorder
        rec = RerunRecorder({str(path)!r}, chunk_rows=100)
        rec.on_start({{}})
        for k in range(2600):          # 520 rows: 5 chunks sent, 20 rows buffered
            rec.on_sample(_sample(k))
        rec._rec.flush()
        os._exit(0)                     # like a kill: no on_finish, no footer
    """)
    subprocess.run([sys.executable, "-c", code], check=True, timeout=120)
    data = read_recording(path)
    t, _ = data["altitude"]
    assert len(t) == 500 and t[-1] == pytest.approx(9.98)


def test_live_web_viewer_on_loopback(tmp_path, monkeypatch):
    """Headless live mode: a rerun web-viewer server on 127.0.0.1, stopped by close()."""
    monkeypatch.delenv("DISPLAY", raising=False)
    monkeypatch.delenv("WAYLAND_DISPLAY", raising=False)
    ports = []
    for _ in range(2):
        with socket.socket() as s:
            s.bind(("127.0.0.1", 0))
            ports.append(s.getsockname()[1])
    rec = RerunRecorder(tmp_path / "live.rrd", live=True, grpc_port=ports[0],
                        web_port=ports[1])
    try:
        assert rec.viewer_url == (f"http://127.0.0.1:{ports[1]}/?url=rerun+http://127.0.0.1:"
                                  f"{ports[0]}/proxy")
        import urllib.error
        import urllib.request

        # the server process may still be starting on a loaded machine: poll until it serves
        deadline = time.monotonic() + 60.0
        while True:
            try:
                with urllib.request.urlopen(f"http://127.0.0.1:{ports[1]}/", timeout=10) as r:
                    assert r.status == 200
                    break
            except (urllib.error.URLError, ConnectionError):
                if time.monotonic() > deadline:
                    raise
                time.sleep(0.1)
        _feed(rec, 300)
        assert len(read_recording(tmp_path / "live.rrd")["altitude"][0]) == 60
    finally:
        rec.close()
    assert rec._server is not None and rec._server.poll() is not None


def test_case_run_recording(tmp_path, ds1):
    """A short real in-process run (takeoff, a rotor fault at 2 s, a refused transition)."""
    from vtolftc.firmware_sim.vehicle.faults import parse_fault_spec
    from vtolftc.runners.scenario import paper_scenario, run_scenario

    scen = paper_scenario(0, 4.0, airframe=ds1, arm_s=0.2, transition_s=3.0,
                          extra_faults=parse_fault_spec("rotor_2b:loss=0.5@2",
                                                        ds1.actuator_names))
    path = tmp_path / "case" / "recording.rrd"
    res = run_scenario(scen, airframe=ds1, observers=[RerunRecorder(path)])
    data = read_recording(path)
    missing = [e for e in EXPECTED if e not in data]
    assert not missing, missing
    for e in EXPECTED:
        assert len(data[e][0]) > 0, e
    t, alt = data["altitude"]
    assert len(t) == 200 and t[-1] == pytest.approx(3.98)
    assert alt[-1, 1] > 2.0 and alt[-1, 0] == pytest.approx(30.0)     # climbing to 30 m
    assert res.sim_time_s == pytest.approx(4.0)
    _, r2b = data["actuators/rotors/rotor_2b"]
    assert 0.4 < r2b[-1, 1] / r2b[-1, 0] < 0.6       # effective = half the command
    _, r1a = data["actuators/rotors/rotor_1a"]
    assert 0.9 < r1a[-1, 1] / r1a[-1, 0] < 1.1
    assert data["faults/marker"][0].tolist() == [pytest.approx(2.0)]
    assert data["mode/state"][1][-1] == "TAKEOFF"


def _feed_deferred(rec: RerunRecorder, n: int, pieces_per_sample: int) -> int:
    """As :func:`_feed`, with ``pieces_per_sample`` calls of ``idle_work`` after each sample
    (a control loop's waits); returns the most pieces a send was cut into."""
    rec.on_start({"actuator_names": list(NAMES), "case": "synthetic"})
    longest = run = 0
    for k in range(n):
        s = _sample(k, True)
        rec.on_sample(s)
        if k == 550:
            rec.on_event(s.time_usec, "fault", "injected rotor_2b: 50% loss")
        if k == 600:
            rec.on_event(s.time_usec, "command", "transition: DENIED")
        for _ in range(pieces_per_sample):
            if rec._pending:
                run += 1
                longest = max(longest, run)
                if not rec.idle_work():
                    run = 0
    rec.on_finish({"rmse_altitude_m": 0.25})
    return longest


@pytest.mark.parametrize("pieces_per_sample", [0, 1, 3, 100])
def test_deferred_sends_write_the_same_recording(tmp_path, pieces_per_sample):
    """``deferred=True`` (the SITL autopilot's recorder): the sends cut into pieces run by
    ``idle_work`` while later samples refill the rows (or never, 0: each send finished by the
    next one and the last by ``on_finish``) write the very series of the default recorder."""
    kw = {"path_segment_points": 7, "file_flush_s": 1e9}  # flushes on simulated time only
    ref = RerunRecorder(tmp_path / "ref.rrd", **kw)
    _feed(ref, 1500)
    rec = RerunRecorder(tmp_path / "deferred.rrd", deferred=True, **kw)
    longest = _feed_deferred(rec, 1500, pieces_per_sample)
    assert not rec._pending
    if pieces_per_sample:  # one entity per piece (24 here), then it says it is done
        assert 20 < longest <= 30, longest
    want, got = read_recording(tmp_path / "ref.rrd"), read_recording(tmp_path / "deferred.rrd")
    assert sorted(got) == sorted(want)
    for e, (t, v) in want.items():
        assert np.array_equal(got[e][0], t), e
        if isinstance(v, np.ndarray):
            assert np.array_equal(got[e][1], v), e
        else:
            assert [np.asarray(x).tolist() for x in got[e][1]] == [
                np.asarray(x).tolist() for x in v], e

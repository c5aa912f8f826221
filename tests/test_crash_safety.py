"""Runs are crash-safe: ``vtolftc fly`` stops cleanly on SIGTERM and Ctrl-C, refuses to mix a
new run into an old ``--out``, and killed (SIGKILL) leaves every file readable (CSV, ULog by
pyulog, ``.rrd`` by rerun's own reader, JSON) with at most 1.5 s of simulated time lost against
the furthest time it reached (its progress lines); the SITL processes killed (SIGKILL) or
stopped (SIGTERM) mid-run leave a run folder that reads back, with at most 1 s lost and a rerun
file that verifies."""

from __future__ import annotations

import csv
import json
import os
import re
import signal
import subprocess
import sys
import threading
import time
from pathlib import Path

import pytest

from vtolftc.runners.sitl import SitlConfig, SitlRun

REPO = Path(__file__).resolve().parents[1]


def _rrd_verify(path: Path, footers: bool) -> subprocess.CompletedProcess[str]:
    """``rerun rrd verify``; ``footers=False`` for a killed run or the recorder's default
    footer-less file (``RerunRecorder(write_footer=False)``: bounded memory, issue 24)."""
    args = [sys.executable, "-m", "rerun", "rrd", "verify", str(path)]
    if not footers:
        args[5:5] = ["--check-footers", "false"]
    return subprocess.run(args, capture_output=True, text=True, timeout=120)


def _rrd_rows(path: Path, entity: str = "/altitude") -> int:
    """Rows of ``entity`` scalars in a recording (``rerun rrd print``)."""
    r = subprocess.run([sys.executable, "-m", "rerun", "rrd", "print", str(path)],
                       capture_output=True, text=True, timeout=120)
    n = 0
    for line in r.stdout.splitlines():
        if f"- {entity} -" in line and "Scalars:scalars" in line:
            n += int(line.split(" with ")[1].split(" rows")[0])
    return n


def _rrd_finished(path: Path) -> bool:
    """The recorder finished the file (``on_finish`` logs ``run/metrics`` last; the file has
    no footer to tell)."""
    r = subprocess.run([sys.executable, "-m", "rerun", "rrd", "print", str(path)],
                       capture_output=True, text=True, timeout=120)
    return any(" - /run/metrics - " in line for line in r.stdout.splitlines())


def _csv_times(path: Path) -> list[float]:
    """The ``time_s`` of every complete row (a killed writer may leave half a line)."""
    out = []
    with path.open(newline="") as f:
        reader = csv.reader(f)
        header = next(reader)
        for row in reader:
            if len(row) == len(header):
                out.append(float(row[0]))
    return out


def _wait_file_rows(path: Path, n: int, timeout_s: float) -> None:
    deadline = time.monotonic() + timeout_s
    while time.monotonic() < deadline:
        if path.is_file() and path.read_text(errors="replace").count("\n") > n:
            return
        time.sleep(0.1)
    raise AssertionError(f"{path} never got {n} rows")


# ---------------------------------------------------------------------------- vtolftc fly
def _fly(args: list[str]) -> subprocess.Popen[str]:
    return subprocess.Popen([sys.executable, "-m", "vtolftc.cli", "fly", *args],
                            stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True,
                            cwd=REPO)


@pytest.mark.parametrize("sig", [signal.SIGTERM, signal.SIGINT])
def test_fly_stops_cleanly_on_signal(tmp_path, hand_gains, sig):
    out = tmp_path / "run"
    p = _fly(["--case", "1", "--controller", "lqr", "--duration", "600", "--gains",
              str(hand_gains), "--out", str(out), "--no-plots"])
    try:
        _wait_file_rows(out / "telemetry.csv", 200, 120.0)
        p.send_signal(sig)
        stdout, stderr = p.communicate(timeout=60)
    finally:
        if p.poll() is None:
            p.kill()
            p.wait()
    assert p.returncode == 130, stderr
    assert "Traceback" not in stderr and "interrupted" in stderr
    assert "interrupted: what was flown so far is in" in stdout
    m = json.loads((out / "metrics.json").read_text())
    assert m["interrupted"] is True
    assert len(_csv_times(out / "telemetry.csv")) >= 200
    assert _rrd_verify(out / "run.rrd", footers=False).returncode == 0
    assert _rrd_finished(out / "run.rrd")


def _ulog_last_s(path: Path) -> float:
    """The newest timestamp [s] of the ULog's 50 Hz topics, read by pyulog."""
    from pyulog import ULog

    log = ULog(str(path))
    names = ("vehicle_attitude", "vehicle_local_position", "vehicle_angular_velocity",
             "sensor_combined", "actuator_outputs")
    return min(float(log.get_dataset(n).data["timestamp"][-1]) for n in names) * 1e-6


def _rrd_last_s(path: Path) -> dict[str, float]:
    """Newest ``sim_time`` [s] of every time series in a recording (rerun's own reader)."""
    from vtolftc.telemetry.recording import read_recording

    data = read_recording(path)
    return {ent: float(t[-1]) for ent, (t, _) in data.items()
            if not ent.startswith(("events", "faults", "mode/state"))}


@pytest.mark.slow
@pytest.mark.parametrize("t_kill", [31.0, 44.5])
def test_fly_sigkill_loses_at_most_1_5_s_in_every_file(tmp_path, t_kill):
    """SIGKILL in hover/transition/fixed-wing: every file parses, none lags the furthest
    simulated time reached (the last progress line, printed every 0.1 s) by more than 1.5 s
    (the flown path, a 5 Hz re-send of the pose, by at most 2 s)."""
    out = tmp_path / "run"
    p = subprocess.Popen([sys.executable, "-m", "vtolftc.cli", "fly", "--case", "1",
                          "--duration", "600", "--out", str(out), "--no-plots",
                          "--progress", "0.1"], stdout=subprocess.PIPE,
                         stderr=subprocess.PIPE, text=True, cwd=REPO)
    furthest = -1.0
    watchdog = threading.Timer(600.0, p.kill)     # a hung run ends the reading loop below
    watchdog.start()
    try:
        assert p.stdout is not None
        for line in p.stdout:
            m = re.match(r"\s+t = ([0-9.]+) s", line)
            if m:
                furthest = float(m.group(1))
                if furthest >= t_kill:
                    p.kill()
                    break
        for line in p.stdout:      # what it printed before the kill landed
            m = re.match(r"\s+t = ([0-9.]+) s", line)
            if m:
                furthest = float(m.group(1))
        p.wait(timeout=60)
    finally:
        watchdog.cancel()
        if p.poll() is None:
            p.kill()
            p.wait()
    assert p.returncode == -signal.SIGKILL and furthest >= t_kill, (p.returncode, furthest)
    reached = furthest + 0.1          # the next progress line was never printed
    lost = {"telemetry.csv": reached - _csv_times(out / "telemetry.csv")[-1],
            "flight.ulg": reached - _ulog_last_s(out / "flight.ulg")}
    rrd = _rrd_last_s(out / "run.rrd")
    assert len(rrd) >= 20, sorted(rrd)
    path_t = max(rrd.pop(k) for k in [k for k in rrd if k.startswith("world/path/")])
    lost["run.rrd"] = reached - min(rrd.values())
    assert all(0.0 <= v <= 1.5 for v in lost.values()), lost
    assert reached - path_t <= 2.0, (reached, path_t)
    assert _rrd_verify(out / "run.rrd", footers=False).returncode == 0
    cfg = json.loads((out / "run.json").read_text())
    assert cfg["controller"] == "gs-shif"
    events = (out / "events.log").read_text().splitlines()
    assert events and all(re.match(r"\s*[0-9.]+ \S+", e) for e in events)
    from vtolftc.telemetry.recording import read_recording

    _, rrd_events = read_recording(out / "run.rrd", ["events"])["events"]
    for line in events:                 # every event of the log that is old enough, in the rrd
        t_s, _kind, text = line.split(maxsplit=2)
        if float(t_s) <= reached - 1.5:
            assert any(text in str(e) for e in rrd_events), (line, rrd_events[-3:])
    assert not (out / "metrics.json").exists()    # written at the end only, never half
    print(f"SIGKILL at t = {reached:.1f} s: lost {lost} s, path {reached - path_t:.2f} s")


def test_fly_out_refused_unless_overwrite_and_never_mixed(tmp_path, hand_gains, capsys):
    from vtolftc.cli.main import run

    out = tmp_path / "run"
    base = ["fly", "--case", "0", "--controller", "lqr", "--duration", "0.5", "--gains",
            str(hand_gains), "--out", str(out), "--no-plots"]
    assert run(base) == 0
    (out / "stale.png").write_text("from the first run")
    capsys.readouterr()
    assert run(base) == 2
    err = capsys.readouterr().err
    assert "already exists" in err and "--overwrite" in err and err.count("\n") == 1
    assert (out / "stale.png").exists()
    assert run([*base, "--overwrite"]) == 0
    assert not (out / "stale.png").exists() and (out / "metrics.json").is_file()
    # a folder that holds something else is never deleted
    other = tmp_path / "precious"
    other.mkdir()
    (other / "thesis.tex").write_text("x")
    capsys.readouterr()
    assert run(["fly", "--duration", "0.5", "--gains", str(hand_gains), "--out", str(other),
                "--overwrite"]) == 2
    assert "holds no vtol-ftc run" in capsys.readouterr().err
    assert (other / "thesis.tex").exists()


@pytest.mark.parametrize("bad", ["/proc/nope/run", "FILE"])
def test_fly_bad_out_is_one_line_exit_2(tmp_path, hand_gains, capsys, bad):
    from vtolftc.cli.main import run

    if bad == "FILE":
        bad = str(tmp_path / "a_file")
        Path(bad).write_text("x")
    assert run(["fly", "--duration", "0.5", "--gains", str(hand_gains), "--out", bad]) == 2
    err = capsys.readouterr().err
    assert "--out" in err and "Traceback" not in err and err.count("\n") == 1


# ---------------------------------------------------------------------------- SITL processes
def _sitl(out: Path) -> SitlRun:
    cfg = SitlConfig(out_dir=out, realtime=True, plots=False, failure_injection=False,
                     vehicle_timeout_s=60.0)
    run = SitlRun(cfg)
    run.start()
    run.gs.wait_for(lambda s: s.sim_time_s > 4.0, 60.0)
    return run


def _stop(p: subprocess.Popen[bytes], sig: int) -> None:
    os.killpg(p.pid, sig)
    p.wait(timeout=30)


@pytest.mark.slow
@pytest.mark.parametrize("sig", [signal.SIGKILL, signal.SIGTERM])
def test_autopilot_killed_mid_run_leaves_a_readable_run_folder(tmp_path, sig):
    run = _sitl(tmp_path)
    try:
        t_kill = run.gs.snapshot().sim_time_s
        _stop(run.procs["autopilot"], sig)
        ap = tmp_path / "autopilot"
        times = _csv_times(ap / "telemetry.csv")
        assert times and t_kill - times[-1] <= 1.0, (t_kill, times[-1])
        assert _rrd_verify(ap / "run.rrd", footers=False).returncode == 0
        assert _rrd_finished(ap / "run.rrd") == (sig == signal.SIGTERM)
        rows = _rrd_rows(ap / "run.rrd")  # 50 Hz recording from the first step on
        assert rows >= 50 * (t_kill - times[0] - 1.0), (rows, t_kill, times[0])
        rrd = _rrd_last_s(ap / "run.rrd")
        rrd = {k: v for k, v in rrd.items() if not k.startswith("world/path/")}
        assert rrd and t_kill - min(rrd.values()) <= 1.0, (t_kill, rrd)
        assert t_kill - _ulog_last_s(ap / "flight.ulg") <= 1.0   # pyulog reads it
        events = [json.loads(x) for x in
                  (ap / "autopilot_events.jsonl").read_text().splitlines() if x.strip()]
        assert all("kind" in e for e in events)
        if sig == signal.SIGTERM:
            # the same instant in two representations (us / 1e6 against the telemetry's
            # seconds): equal to the simulation's resolution, 1 us
            assert json.loads((ap / "metrics.json").read_text())["sim_time_s"] >= t_kill - 1e-6
            assert json.loads((ap / "autopilot_summary.json").read_text())["steps"] > 0
    finally:
        run.close()
    veh = tmp_path / "vehicle"  # the vehicle was stopped by SIGTERM afterwards
    assert json.loads((veh / "vehicle_summary.json").read_text())["steps"] > 0


@pytest.mark.slow
@pytest.mark.parametrize("sig", [signal.SIGKILL, signal.SIGTERM])
def test_vehicle_killed_mid_run_leaves_a_readable_run_folder(tmp_path, sig):
    run = _sitl(tmp_path)
    try:
        _stop(run.procs["vehicle"], sig)
        time.sleep(0.5)  # the autopilot's last step is the vehicle's last state
        run.stop()
        ap_times = _csv_times(tmp_path / "autopilot" / "telemetry.csv")
        veh = tmp_path / "vehicle"
        times = _csv_times(veh / "vehicle_truth.csv")
        assert times and ap_times[-1] - times[-1] <= 1.0, (ap_times[-1], times[-1])
        events = [json.loads(x) for x in
                  (veh / "vehicle_events.jsonl").read_text().splitlines() if x.strip()]
        assert events[0]["event"] == "start"
        if sig == signal.SIGTERM:
            assert events[-1]["event"] == "stop"
            assert json.loads((veh / "vehicle_summary.json").read_text())["steps"] > 0
        # the autopilot, stopped by SIGTERM, finished its folder completely
        assert _rrd_verify(tmp_path / "autopilot" / "run.rrd", footers=False).returncode == 0
        assert _rrd_finished(tmp_path / "autopilot" / "run.rrd")
        assert json.loads((tmp_path / "autopilot" / "metrics.json").read_text())
    finally:
        run.close()

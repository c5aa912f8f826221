"""The in-process runner: scenario definition, run folder, determinism, quad-chute, a lost
rotor, and the paper's cases flown with the shipped (synthesised) gains."""

from __future__ import annotations

import csv
import json
import math

import numpy as np
import pytest

from vtolftc.firmware_sim.autopilot.attitude import default_gains_dir
from vtolftc.firmware_sim.autopilot.interface import FlightMode
from vtolftc.firmware_sim.vehicle.faults import Fault
from vtolftc.firmware_sim.vehicle.sensors import Home
from vtolftc.runners.scenario import paper_scenario, run_scenario
from vtolftc.telemetry.runfolder import RunFolderWriter

CONTROLLERS = ("gs-shif", "shif", "lqr")
CRUISE_TRIM_PITCH_DEG = 0.6


class Recorder:
    """Keeps every sample and event."""

    def __init__(self, stop_at_s: float | None = None) -> None:
        self.samples = []
        self.events = []
        self.finished = None
        self.stop_at_s = stop_at_s

    def on_start(self, info):
        self.info = info

    def on_sample(self, s):
        self.samples.append(s)
        if self.stop_at_s is not None and s.time_usec >= self.stop_at_s * 1e6:
            raise KeyboardInterrupt

    def on_event(self, t, kind, text):
        self.events.append((t, kind, text))

    def on_finish(self, metrics):
        self.finished = metrics


def test_paper_scenario_timeline(ds1):
    sc = paper_scenario(1, 40.0, airframe=ds1)
    cmds = [(a.t_s, a.command_id, a.params[0]) for a in sc.actions if a.kind == "command"]
    assert cmds == [(1.0, 400, 1.0), (1.0, 22, pytest.approx(math.nan, nan_ok=True)),
                    (20.0, 3000, 4.0)]
    takeoff = next(a for a in sc.actions if a.command_id == 22)
    assert len(takeoff.params) == 7 and takeoff.params[6] == Home().alt_m + 30.0  # AMSL
    faults = sorted((f.actuator, f.loss) for f in sc.faults)
    assert faults == sorted([("rotor_2b", 0.5), ("elevator", 0.2), ("aileron_left", 0.2),
                             ("aileron_right", 0.2), ("rudder_left", 0.2),
                             ("rudder_right", 0.2)])
    assert all(a.t_s == 22.0 for a in sc.actions if a.kind == "fault")
    assert paper_scenario(0, 40.0).faults == []
    assert len(paper_scenario(2, 40.0).faults) == 8
    with pytest.raises(ValueError, match="duration"):
        paper_scenario(1, -1.0)


def test_run_folder_contents(tmp_path, hand_gains):
    out = tmp_path / "run"
    res = run_scenario(paper_scenario(0, 3.0), "shif", gains_dir=hand_gains,
                       observers=[RunFolderWriter(out)], info={"seed": 0})
    for f in ("telemetry.csv", "events.log", "metrics.json", "run.json", "trajectory.png",
              "attitude.png", "surfaces.png", "rotors.png", "pushers_airspeed.png"):
        assert (out / f).is_file() and (out / f).stat().st_size > 0, f
    with open(out / "telemetry.csv") as fh:
        rows = list(csv.DictReader(fh))
    assert len(rows) == 750
    assert rows[-1]["mode"] == "TAKEOFF" and float(rows[-1]["altitude_m"]) > 1.0
    assert float(rows[0]["u_rotor_1a"]) == 0.0
    cfg = json.loads((out / "run.json").read_text())
    assert cfg["controller"] == "shif" and len(cfg["airframe_sha256"]) == 64
    assert len(cfg["gains_sha256"]) == 64 and cfg["seed"] == 0 and "numpy" in cfg["versions"]
    m = json.loads((out / "metrics.json").read_text())
    assert m["samples"] == 750 and m["crashed"] is False and m == json.loads(
        json.dumps(m))
    assert res.metrics["samples"] == 750
    ev = (out / "events.log").read_text()
    assert "arm: command 400 -> ACCEPTED" in ev and "IDLE -> TAKEOFF" in ev


def test_interrupted_run_keeps_what_was_written(tmp_path, hand_gains):
    out = tmp_path / "run"
    rec = Recorder(stop_at_s=2.0)
    with pytest.raises(KeyboardInterrupt):
        run_scenario(paper_scenario(0, 10.0), "shif", gains_dir=hand_gains,
                     observers=[RunFolderWriter(out, plots=False), rec])
    m = json.loads((out / "metrics.json").read_text())
    assert m["interrupted"] is True and rec.finished["interrupted"] is True
    with open(out / "telemetry.csv") as fh:
        rows = list(csv.DictReader(fh))
    assert len(rows) == 501


def test_determinism(hand_gains):
    a = run_scenario(paper_scenario(1, 24.0), "gs-shif", gains_dir=hand_gains)
    b = run_scenario(paper_scenario(1, 24.0), "gs-shif", gains_dir=hand_gains)
    strip = {"allocation"}
    ma = {k: v for k, v in a.metrics.items() if k not in strip}
    mb = {k: v for k, v in b.metrics.items() if k not in strip}
    assert ma == mb
    assert a.metrics["rmse_roll_deg"] > 0.0


def test_quad_chute_when_the_transition_fails(hand_gains):
    """Pushers off: the airspeed never reaches 13 m/s; after VT_TRANS_TMOUT back to hover."""
    sc = paper_scenario(0, 28.0, extra_faults=[Fault("pusher_left", "off", start_s=19.0),
                                               Fault("pusher_right", "off", start_s=19.0)])
    rec = Recorder()
    res = run_scenario(sc, "shif", gains_dir=hand_gains, observers=[rec],
                       autopilot_setup=lambda ap: ap.params.set("VT_TRANS_TMOUT", 4.0))
    m = res.metrics
    assert m["quad_chute"] and not m["crashed"] and m["transition_complete_s"] is None
    modes = {round(s.time_usec * 1e-6, 3): s.status.mode for s in rec.samples}
    assert modes[21.0] == FlightMode.FRONT_TRANSITION and modes[25.0] == FlightMode.HOVER
    assert any("quad-chute" in text for _, _, text in rec.events)
    assert abs(m["final_altitude_m"] - 30.0) < 0.5


def test_lost_rotor_in_hover_absorbed_by_the_others(hand_gains):
    """Rotor 2b fails completely in hover: the QP redistributes onto the seven others and the
    (passive) loops bring the attitude and altitude back."""
    sc = paper_scenario(0, 22.0, extra_faults=[Fault("rotor_2b", "off", start_s=15.0)])
    rec = Recorder()
    res = run_scenario(sc, "shif", gains_dir=hand_gains, observers=[rec])
    m = res.metrics
    assert not m["crashed"]
    assert abs(m["final_altitude_m"] - 30.0) < 0.5
    assert abs(m["final_roll_deg"]) < 2.0 and abs(m["final_pitch_deg"]) < 2.0
    last = rec.samples[-1]
    u = last.status.actuator_commands
    assert last.truth.effectiveness[3] == 0.0
    hover = np.mean([s.status.actuator_commands[:8] for s in rec.samples
                     if 14.0 <= s.time_usec * 1e-6 < 15.0], axis=0)
    others = [i for i in range(8) if i != 3]
    # the remaining rotors carry the weight: their mean throttle rose
    assert np.mean(u[others]) > np.mean(hover[others]) + 0.02


def _check_limits(samples, dt=0.004):
    U = np.array([s.status.actuator_commands for s in samples])
    assert np.all(U[:, :10] >= 0.0) and np.all(U[:, :10] <= 1.0)
    assert np.all(U[:, 10:] >= -1.0) and np.all(U[:, 10:] <= 1.0)
    du = np.abs(np.diff(U, axis=0)) / dt
    assert np.all(du[:, :10] <= 10.0 + 1e-6)            # rotor slew limit
    assert np.all(du[:, 10:] <= 14.0 + 1e-6)            # 350 deg/s of 25 deg
    fw = [s for s in samples if s.status.mode == FlightMode.FIXED_WING]
    late = [s for s in fw if s.time_usec - fw[0].time_usec > 2.5e6]
    # fixed-wing: the lift rotors are a reserve (weighted, not bounded to 0): idle to within
    # the secondary objective's share (measured 1.4e-4 nominal), unless the surfaces fall short
    assert late and all(np.all(s.status.actuator_commands[:8] < 1e-3) for s in late)


def _shipped():
    if not (default_gains_dir() / "gs-shif.json").is_file():
        pytest.fail(f"shipped gains missing in {default_gains_dir()}")


@pytest.mark.slow
@pytest.mark.parametrize("controller", CONTROLLERS)
def test_nominal_transition_completes(controller):
    _shipped()
    rec = Recorder()
    m = run_scenario(paper_scenario(0, 40.0), controller, observers=[rec]).metrics
    assert not m["crashed"]
    assert m["transition_complete_s"] is not None and m["transition_complete_s"] < 32.0
    assert abs(m["final_altitude_error_m"]) < 1.0
    assert abs(m["final_roll_deg"]) < 3.0 and abs(m["final_yaw_deg"]) < 3.0
    assert abs(m["final_pitch_deg"] - CRUISE_TRIM_PITCH_DEG) < 5.0
    assert abs(m["final_airspeed_m_s"] - 18.0) < 1.0
    assert m["allocation"]["counts"]["fallback"] == 0
    _check_limits(rec.samples)


@pytest.mark.slow
@pytest.mark.parametrize("case", [1, 2])
@pytest.mark.parametrize("controller", CONTROLLERS)
def test_fault_cases_complete(controller, case):
    """Cases 1 and 2 (faults at 22 s): no crash, transition reached, altitude back to 30 m and
    attitude at the cruise trim. Flown to 60 s: the LQR's fixed-wing pitch loop (hover design)
    needs longer than the paper's 40 s to settle."""
    _shipped()
    rec = Recorder()
    m = run_scenario(paper_scenario(case, 60.0), controller, observers=[rec]).metrics
    assert not m["crashed"] and not m["quad_chute"]
    assert m["transition_complete_s"] is not None
    assert abs(m["final_altitude_error_m"]) < 1.0
    assert abs(m["final_roll_deg"]) < 2.0 and abs(m["final_yaw_deg"]) < 2.0
    assert abs(m["final_pitch_deg"] - CRUISE_TRIM_PITCH_DEG) < 3.0
    assert all(s.truth.effectiveness[3] == 0.5 for s in rec.samples if s.time_usec > 22.1e6)
    _check_limits(rec.samples)


def test_cli_fly_and_compare(tmp_path, hand_gains, capsys):
    from vtolftc.cli.main import run

    out = tmp_path / "fly"
    assert run(["fly", "--case", "1", "--controller", "lqr", "--duration", "2",
                "--gains", str(hand_gains), "--out", str(out), "--no-plots",
                "--fault", "rotor_1a:loss=0.3@1.5"]) == 0
    text = capsys.readouterr().out
    assert "RMSE" in text and (out / "metrics.json").is_file()
    cfg = json.loads((out / "run.json").read_text())
    assert "rotor_1a: 30% loss from t = 1.5 s" in cfg["faults"]
    cmp_dir = tmp_path / "cmp"
    assert run(["compare", "--case", "2", "--duration", "1", "--gains", str(hand_gains),
                "--out", str(cmp_dir), "--no-plots"]) == 0
    text = capsys.readouterr().out
    assert "| GS-SHIF |" in text and "Paper (table 4)" in text
    assert (cmp_dir / "comparison.md").is_file() and (cmp_dir / "rmse.png").is_file()
    for c in CONTROLLERS:
        assert (cmp_dir / c / "telemetry.csv").is_file()
        assert (cmp_dir / c / "flight.ulg").is_file()


@pytest.mark.parametrize("argv, match", [
    (["fly", "--case", "3"], "--case '3'"),
    (["fly", "--duration", "-1"], "--duration"),
    (["fly", "--gains", "/nonexistent/dir"], "--gains"),
    (["fly", "--fault", "rotor_9z:loss=0.5"], "unknown actuator"),
    (["fly", "--fault", "rotor_1a:loss=150"], "fraction"),
    (["fly", "--progress", "-1"], "--progress"),
    (["fly", "--progress", "nan"], "--progress"),
])
def test_cli_bad_input_is_one_line_exit_2(argv, match, capsys):
    from vtolftc.cli.main import run

    assert run(argv) == 2
    err = capsys.readouterr().err
    assert match in err and "Traceback" not in err and err.count("\n") == 1


def test_cli_missing_gain_file_is_reported_before_flying(tmp_path, capsys):
    from vtolftc.cli.main import run

    out = tmp_path / "never"
    assert run(["fly", "--gains", str(tmp_path), "--out", str(out)]) == 2
    cap = capsys.readouterr()
    assert "gs-shif.json not found" in cap.err and "flying" not in cap.out
    assert not out.exists()


@pytest.mark.slow
def test_full_flight_back_transition_and_landing(hand_gains):
    """Takeoff, front transition, fixed-wing, back transition (commanded), hover, land:
    the vehicle ends on the ground, disarmed, without a crash."""
    from dataclasses import replace

    from vtolftc.runners.scenario import Action

    nan = float("nan")
    sc = paper_scenario(0, 66.0)
    sc = replace(sc, actions=(
        *sc.actions,
        Action(32.0, "command", "back to MC", 3000, (3.0,) + (nan,) * 6),
        Action(43.0, "command", "land", 21, (nan,) * 7)))

    def setup(ap):
        ap.params.set("MPC_LAND_SPEED", 2.0)
        ap.params.set("VT_B_TRANS_DUR", 10.0)

    rec = Recorder()
    m = run_scenario(sc, "shif", gains_dir=hand_gains, observers=[rec],
                     autopilot_setup=setup).metrics
    modes = [s.status.mode for s in rec.samples]
    order = [x for i, x in enumerate(modes) if i == 0 or x != modes[i - 1]]
    assert order == [FlightMode.IDLE, FlightMode.TAKEOFF, FlightMode.HOVER,
                     FlightMode.FRONT_TRANSITION, FlightMode.FIXED_WING,
                     FlightMode.BACK_TRANSITION, FlightMode.HOVER, FlightMode.LAND,
                     FlightMode.IDLE]
    last = rec.samples[-1]
    assert not m["crashed"] and not last.status.armed
    assert -last.nav.pos_ned_m[2] < 0.5
    assert np.all(last.status.actuator_commands == 0.0)

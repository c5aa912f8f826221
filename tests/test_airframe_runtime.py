"""Airframes beyond DS-1 (issue 22, items 1-2): the dual-system format (any number of lift
rotors, canted axes, one or two pushers, declared or derived airspeeds), the refusals of files
that cannot fly (one line naming the field, exit status 2 from every command that reads an
airframe), and an actuator vector of any size through HIL, autopilot, telemetry and ULog:
QP-4 (4+1 quadplane) and HX-6 (hexa) synthesised and flown in-process and over UDP."""

from __future__ import annotations

import copy
import json
import math
import subprocess
import sys
import tomllib
from pathlib import Path

import numpy as np
import pytest

from vtolftc.airframe.loader import (
    DS1_PATH,
    AirframeError,
    airframe_from_dict,
    hover_effectiveness,
    load_airframe,
)
from vtolftc.cli import run as cli_run
from vtolftc.firmware_sim.vehicle.flyable import check_flyable
from vtolftc.protocols.hil import HIL_OUTPUTS, wire_commands

ROOT = Path(__file__).resolve().parents[1]
QP4 = ROOT / "airframe" / "qp4.toml"
HX6 = ROOT / "airframe" / "hx6.toml"


def _ds1_doc() -> dict:
    return tomllib.loads(DS1_PATH.read_text(encoding="utf-8"))


def _toml(doc: dict) -> str:
    """A small TOML writer for the airframe documents (tables, arrays of tables, scalars)."""
    def val(v):
        if isinstance(v, str):
            return json.dumps(v)
        if isinstance(v, bool):
            return "true" if v else "false"
        if isinstance(v, list):
            return "[" + ", ".join(val(x) for x in v) + "]"
        return repr(v)

    out = []
    for sec, table in doc.items():
        out.append(f"[{sec}]")
        subs = []
        for k, v in table.items():
            if isinstance(v, list) and v and isinstance(v[0], dict):
                subs.append((k, v))
            else:
                out.append(f"{k} = {val(v)}")
        for k, entries in subs:
            for e in entries:
                out.append(f"[[{sec}.{k}]]")
                out += [f"{kk} = {val(vv)}" for kk, vv in e.items()]
    return "\n".join(out) + "\n"


# -- the format ---------------------------------------------------------------------------------


def test_quadplane_and_hexa_load_with_their_actuator_vectors():
    qp, hx, ds = load_airframe(QP4), load_airframe(HX6), load_airframe()
    assert qp.actuator_names == ("rotor_1a", "rotor_1b", "rotor_4a", "rotor_4b", "pusher_centre",
                                 "aileron_left", "aileron_right", "elevator", "rudder_left",
                                 "rudder_right")
    assert (qp.n_actuators, hx.n_actuators, ds.n_actuators) == (10, 13, 15)
    # the derived airspeeds: stall of the wing, transition end and cruise above it
    a = ds.airspeeds
    assert a is not None and a.declared == ()
    assert a.stall_m_s == pytest.approx(ds.stall_speed_m_s())
    assert a.stall_m_s < a.transition_end_m_s < a.cruise_m_s


def test_a_canted_rotor_thrusts_and_reacts_along_its_axis():
    hx = load_airframe(HX6)
    r = next(r for r in hx.lift_rotors if r.name == "1m")
    assert np.linalg.norm(r.thrust_axis) == pytest.approx(1.0, abs=1e-12)
    assert math.degrees(math.acos(-r.thrust_axis[2])) == pytest.approx(3.0, abs=1e-3)
    assert r.thrust_axis[1] < 0  # outboard on the left boom
    # ccw seen from above: the spin axis is the thrust axis (up), the reaction torque yaws right
    np.testing.assert_allclose(r.spin_axis, r.thrust_axis)
    B = hover_effectiveness(hx)
    j = [x.name for x in hx.lift_rotors].index("1m")
    assert B[0, j] == pytest.approx(math.cos(math.radians(3.0)), abs=1e-6)
    # an uncanted rotor of DS-1 keeps its exact axes (flights bit-identical)
    ds = load_airframe()
    assert ds.lift_rotors[0].thrust_axis.tolist() == [0.0, 0.0, -1.0]
    assert ds.lift_rotors[0].spin_axis.tolist() == [0.0, 0.0, 1.0]


def test_declared_airspeeds_are_used_and_checked():
    doc = _ds1_doc()
    doc["airspeeds"] = {"transition_end_m_s": 14.0, "cruise_m_s": 20.0}
    a = airframe_from_dict(doc).airspeeds
    assert (a.transition_end_m_s, a.cruise_m_s) == (14.0, 20.0)
    assert a.declared == ("cruise_m_s", "transition_end_m_s")
    doc["airspeeds"] = {"transition_end_m_s": 11.0}
    with pytest.raises(AirframeError, match=r"airspeeds.transition_end_m_s.*stall <= "):
        airframe_from_dict(doc)
    doc["airspeeds"] = {"cruise_speed": 18.0}
    with pytest.raises(AirframeError, match=r"unknown key 'airspeeds.cruise_speed'"):
        airframe_from_dict(doc)


def _with_rotors(doc: dict, rotors: list[dict], thrust: float | None = None) -> dict:
    d = copy.deepcopy(doc)
    d["lift_rotors"]["rotor"] = rotors
    if thrust is not None:
        d["lift_rotors"]["max_thrust_N"] = thrust
    return d


@pytest.mark.parametrize("change, field, reason", [
    # every rotor turning the same way: the reaction torques can only yaw one way
    (lambda d: _with_rotors(d, [{**r, "spin": "cw"} for r in d["lift_rotors"]["rotor"]]),
     "lift_rotors.rotor", "no yaw authority in hover"),
    # torque-free rotors (k = 0) and no cant: yaw row zero
    (lambda d: {**d, "lift_rotors": {**d["lift_rotors"], "torque_to_thrust_m": 0.0}},
     "lift_rotors.rotor", "no yaw authority in hover"),
    # all rotors on one line: no pitch (or roll) moment
    (lambda d: _with_rotors(d, [{**r, "x_m": 0.0} for r in d["lift_rotors"]["rotor"]]),
     "lift_rotors.rotor", "no pitch authority in hover"),
    # 8 x 18 N = 144 N for 122.6 N: thrust-to-weight 1.17 < 1.2
    (lambda d: {**d, "lift_rotors": {**d["lift_rotors"], "max_thrust_N": 18.0}},
     "lift_rotors.max_thrust_N", "thrust-to-weight 1.17"),
    # 12 lift rotors + 2 pushers + 5 surfaces = 19 actuators > 16 HIL outputs
    (lambda d: _with_rotors(d, d["lift_rotors"]["rotor"] + [
        {**r, "name": r["name"] + "x", "z_m": -0.2} for r in d["lift_rotors"]["rotor"][:4]]),
     "lift_rotors.rotor", "HIL_ACTUATOR_CONTROLS has 16 outputs; this file has 19"),
    # a rotor tilted 30 deg is not a small cant
    (lambda d: _with_rotors(d, [{**d["lift_rotors"]["rotor"][0], "axis": [0.0, 0.5, -0.866]},
                                *d["lift_rotors"]["rotor"][1:]]),
     "lift_rotors.rotor[0].axis", "within 20 deg"),
    (lambda d: _with_rotors(d, [{**d["lift_rotors"]["rotor"][0], "axis": [0.0, "up"]},
                                *d["lift_rotors"]["rotor"][1:]]),
     "lift_rotors.rotor[0].axis", "a thrust direction"),
    (lambda d: {**d, "pushers": {**d["pushers"], "rotor": d["pushers"]["rotor"] + [
        {**d["pushers"]["rotor"][0], "name": "third", "y_m": 0.0}]}},
     "pushers.rotor", "one or two pushers"),
])
def test_files_that_cannot_fly_are_refused_naming_the_field(change, field, reason):
    with pytest.raises(AirframeError) as exc:
        airframe_from_dict(change(_ds1_doc()), source="bad.toml")
    msg = str(exc.value)
    assert msg.startswith(f"bad.toml: field '{field}'") and reason in msg and "\n" not in msg


def test_a_transition_that_cannot_trim_is_refused():
    """Pushers of 2 N cannot overcome the drag of the rotor-assisted transition."""
    doc = _ds1_doc()
    doc["pushers"]["max_thrust_N"] = 2.0
    af = airframe_from_dict(doc, source="weak.toml", sha256="")
    with pytest.raises(AirframeError) as exc:
        check_flyable(af)
    msg = str(exc.value)
    assert msg.startswith("weak.toml: field 'pushers.max_thrust_N' = 2.0")
    assert "the transition cannot trim" in msg and "\n" not in msg


@pytest.mark.parametrize("path", [DS1_PATH, QP4, HX6])
def test_shipped_airframes_trim_through_the_transition(path):
    af = airframe_from_dict(tomllib.loads(path.read_text(encoding="utf-8")), source=str(path),
                            sha256="")  # no hash: not skipped as the known DS-1
    check_flyable(af)


# -- every command that reads an airframe: one line, exit status 2 ------------------------------


@pytest.fixture(scope="module")
def bad_files(tmp_path_factory):
    d = tmp_path_factory.mktemp("bad")
    malformed = d / "malformed.toml"
    malformed.write_text("[airframe\nname = 'x'\n", encoding="utf-8")
    doc = _ds1_doc()
    for r in doc["lift_rotors"]["rotor"]:
        r["spin"] = "ccw"
    noyaw = d / "noyaw.toml"
    noyaw.write_text(_toml(doc), encoding="utf-8")
    doc = _ds1_doc()
    doc["pushers"]["max_thrust_N"] = 2.0
    notrim = d / "notrim.toml"
    notrim.write_text(_toml(doc), encoding="utf-8")
    spec_dir = d / "spec"
    spec_dir.mkdir()
    return {"malformed": (malformed, "not valid TOML"),
            "noyaw": (noyaw, "no yaw authority in hover"),
            "notrim": (notrim, "the transition cannot trim")}, d


def _commands(path: Path, tmp: Path) -> dict[str, list[str]]:
    spec = tmp / f"campaign-{path.stem}.toml"
    spec.write_text(f'[campaign]\nname = "x"\nduration_s = 30.0\ncontrollers = ["gs-shif"]\n'
                    f'phases = ["hover"]\nairframe = "{path}"\n'
                    '[[faults]]\nfamily = "rotor-off"\ngenerate = "each"\n'
                    'actuators = ["lift_rotors"]\nkinds = ["off"]\n', encoding="utf-8")
    return {
        "trim": ["trim", "--airframe", str(path)],
        "synth": ["synth", "--airframe", str(path), "--out", str(tmp / "synth"), "--quiet"],
        "fly": ["fly", "--case", "0", "--airframe", str(path), "--out", str(tmp / "fly")],
        "sitl": ["sitl", "--case", "0", "--airframe", str(path), "--out", str(tmp / "sitl")],
        "campaign": ["campaign", str(spec), "--out", str(tmp / "campaign")],
    }


@pytest.mark.parametrize("kind", ["malformed", "noyaw", "notrim"])
@pytest.mark.parametrize("command", ["trim", "synth", "fly", "sitl", "campaign"])
def test_every_command_refuses_a_bad_airframe_in_one_line(bad_files, kind, command, capsys):
    files, tmp = bad_files
    path, reason = files[kind]
    argv = _commands(path, tmp)[command]
    assert cli_run(argv) == 2
    err = capsys.readouterr().err.strip()
    assert "\n" not in err and "Traceback" not in err, err
    assert err.startswith(f"vtolftc {command}: error: ") and reason in err, err
    assert str(path) in err
    for out in ("synth", "fly", "sitl", "campaign"):  # nothing written (synth may make --out)
        assert not [f for f in (tmp / out).rglob("*") if f.is_file()]


def test_a_bad_airframe_through_the_installed_command_exits_2(bad_files):
    files, _ = bad_files
    path, reason = files["noyaw"]
    p = subprocess.run([sys.executable, "-m", "vtolftc.cli", "trim", "--airframe", str(path)],
                       capture_output=True, text=True, timeout=300, cwd=ROOT)
    assert p.returncode == 2 and p.stdout == ""
    assert len(p.stderr.strip().splitlines()) == 1 and reason in p.stderr


# -- the actuator vector of any size -------------------------------------------------------------


def test_wire_commands_carry_any_count_up_to_16():
    u = np.linspace(-1.0, 1.0, 10) / 3.0
    w = wire_commands(u)
    assert w.shape == (10,) and np.array_equal(w, u.astype(np.float32).astype(np.float64))
    assert wire_commands(np.ones(HIL_OUTPUTS)).shape == (16,)
    with pytest.raises(ValueError, match="at most 16"):
        wire_commands(np.zeros(17))


def test_failure_units_and_fault_names_come_from_the_airframe():
    from vtolftc.firmware_sim.vehicle.faults import parse_fault_spec
    from vtolftc.protocols.failure_units import FAILURE_UNIT_MOTOR, ActuatorTable

    qp = load_airframe(QP4)
    t = ActuatorTable.from_names(qp.actuator_names)
    assert t.unit_instance("pusher_centre") == (FAILURE_UNIT_MOTOR, 5)
    assert t.expand("lift_rotors") == ["rotor_1a", "rotor_1b", "rotor_4a", "rotor_4b"]
    with pytest.raises(ValueError, match="unknown actuator 'rotor_2b'"):
        t.unit_instance("rotor_2b")
    assert [f.actuator for f in parse_fault_spec("rotor_4a:off@25", qp.actuator_names)] == [
        "rotor_4a"]


def test_campaign_families_cover_every_actuator_of_the_file(tmp_path):
    from vtolftc.campaign.spec import load_spec

    spec = tmp_path / "qp4.toml"
    spec.write_text(f'[campaign]\nname = "qp4"\nduration_s = 30.0\ncontrollers = ["gs-shif"]\n'
                    f'phases = ["hover"]\nairframe = "{QP4}"\n'
                    '[[faults]]\nfamily = "any-off"\ngenerate = "each"\n'
                    'actuators = ["lift_rotors", "pushers", "surfaces"]\nkinds = ["off"]\n',
                    encoding="utf-8")
    s = load_spec(spec)
    names = sorted({a for fam in s.families for fs in fam.sets for (a, _, _) in fs.faults})
    assert names == sorted(load_airframe(QP4).actuator_names)


def test_dashboard_layout_is_drawn_from_the_rotor_positions():
    from vtolftc.telemetry.geometry import rotor_grid

    assert rotor_grid(load_airframe(QP4)) == [["rotor_1a", "rotor_4a"], ["rotor_1b", "rotor_4b"]]
    assert rotor_grid(load_airframe(HX6)) == [["rotor_1a", "rotor_2a"], ["rotor_1m", "rotor_2m"],
                                              ["rotor_1b", "rotor_2b"]]


# -- flown: synthesis, in-process flight, ULog, SITL over UDP -----------------------------------


def _vtolftc(*argv: str, timeout: float = 900) -> subprocess.CompletedProcess:
    return subprocess.run([sys.executable, "-m", "vtolftc.cli", *argv], capture_output=True,
                          text=True, timeout=timeout, cwd=ROOT)


class _PaperGains:
    """``vtolftc synth --method paper --airframe F`` (one classical start, no mu, no report:
    the gains only), run once per airframe on first use."""

    def __init__(self, factory: pytest.TempPathFactory) -> None:
        self._factory = factory
        self._dirs: dict[str, Path] = {}

    def __getitem__(self, stem: str) -> Path:
        if stem not in self._dirs:
            d = self._factory.mktemp(stem)
            path = ROOT / "airframe" / f"{stem}.toml"
            p = _vtolftc("synth", "--method", "paper", "--airframe", str(path), "--out",
                         str(d), "--starts", "0", "--no-mu", "--no-report", "--quiet",
                         "--jobs", "1")
            assert p.returncode == 0, p.stderr[-2000:]
            self._dirs[stem] = d
        return self._dirs[stem]


@pytest.fixture(scope="module")
def paper_gains(tmp_path_factory):
    """Gain directories by airframe stem (``qp4``, ``hx6``), synthesised on first use."""
    return _PaperGains(tmp_path_factory)


@pytest.mark.slow
@pytest.mark.parametrize("path", [QP4, HX6], ids=["qp4", "hx6"])
def test_quadplane_and_hexa_fly_the_nominal_transition(paper_gains, path, tmp_path):
    from pyulog import ULog

    af = load_airframe(path)
    run = tmp_path / "run"
    p = _vtolftc("fly", "--case", "0", "--duration", "32", "--airframe", str(path),
                 "--gains", str(paper_gains[path.stem]), "--out", str(run), "--no-plots")
    assert p.returncode == 0, p.stderr[-2000:]
    m = json.loads((run / "metrics.json").read_text())
    text = json.dumps(m)
    assert '"crashed": false' in text, text[:2000]
    assert "transition" in text
    assert "complete 2" in p.stdout, p.stdout  # the transition completed (in the 20 s)
    header = (run / "telemetry.csv").read_text().splitlines()[0].split(",")
    assert [h for h in header if h.startswith("u_")] == [f"u_{n}" for n in af.actuator_names]
    ulog = ULog(str(run / "flight.ulg"), ["actuator_outputs"])
    data = ulog.get_dataset("actuator_outputs").data
    assert set(data["noutputs"].tolist()) == {af.n_actuators}
    # the unused outputs stay 0; a lift rotor carries the hover thrust before the transition
    assert np.all(data[f"output[{af.n_actuators}]"] == 0.0)
    assert np.max(data["output[0]"]) > 0.3


@pytest.mark.slow
def test_quadplane_flies_sitl_over_udp(paper_gains, tmp_path):
    from pyulog import ULog

    af = load_airframe(QP4)
    run = tmp_path / "sitl"
    p = _vtolftc("sitl", "--case", "0", "--duration", "8", "--transport", "udp",
                 "--airframe", str(QP4), "--gains-dir", str(paper_gains["qp4"]),
                 "--out", str(run))
    assert p.returncode == 0, (p.stdout[-2000:], p.stderr[-2000:])
    ulgs = sorted(run.rglob("*.ulg"))
    assert ulgs, sorted(str(x) for x in run.rglob("*"))
    data = ULog(str(ulgs[0]), ["actuator_outputs"]).get_dataset("actuator_outputs").data
    assert set(data["noutputs"].tolist()) == {af.n_actuators}
    assert np.max(data["output[0]"]) > 0.3  # took off on the four lift rotors


def test_gcs_fault_names_come_from_the_airframe(bad_files, capsys):
    """``vtolftc gcs --airframe F inject``: the names are the file's (refused before any
    link is opened, so no vehicle is needed)."""
    argv = ["gcs", "--airframe", str(QP4), "--timeout", "0.1", "inject", "--actuator",
            "rotor_2b", "--loss", "0.5"]
    assert cli_run(argv) == 2
    err = capsys.readouterr().err.strip()
    assert "unknown actuator 'rotor_2b'" in err and "rotor_4a" in err and "\n" not in err
    path, reason = bad_files[0]["malformed"]
    assert cli_run(["gcs", "--airframe", str(path), "status"]) == 2
    err = capsys.readouterr().err.strip()
    assert reason in err and "\n" not in err


def test_one_aileron_and_one_rudder_act_as_the_pairs_deflected_together():
    """``[surfaces] ailerons = 1, rudders = 1``: one surface carries the whole aircraft
    derivative, in the vehicle model and in the autopilot's effectiveness alike."""
    from vtolftc.firmware_sim.autopilot.effectiveness import EffectivenessModel
    from vtolftc.firmware_sim.vehicle import dynamics as dyn
    from vtolftc.firmware_sim.vehicle.model import Vehicle
    from vtolftc.firmware_sim.vehicle.trim import _base_state

    doc = _ds1_doc()
    doc["surfaces"]["ailerons"] = 1
    doc["surfaces"]["rudders"] = 1
    one = airframe_from_dict(doc)
    two = load_airframe()
    assert one.actuator_names[-3:] == ("aileron", "elevator", "rudder")
    assert one.n_actuators == 13
    for bad in (0, 3, 1.5):
        doc["surfaces"]["ailerons"] = bad
        with pytest.raises(AirframeError, match=r"field 'surfaces.ailerons'"):
            airframe_from_dict(doc)
    B1 = EffectivenessModel(one).matrix(18.0)
    B2 = EffectivenessModel(two).matrix(18.0)
    i2 = two.actuator_index
    np.testing.assert_allclose(B1[:, one.actuator_index("aileron")],
                               B2[:, i2("aileron_left")] - B2[:, i2("aileron_right")])
    np.testing.assert_allclose(B1[:, one.actuator_index("rudder")],
                               B2[:, i2("rudder_left")] + B2[:, i2("rudder_right")])
    assert np.any(B1[:, one.actuator_index("aileron")] != 0.0)

    def accel(af, cmd: dict[str, float]) -> np.ndarray:
        x = _base_state(af, 30.0, 18.0, 0.0)
        for name, c in cmd.items():
            x[dyn.N_RIGID + af.actuator_index(name)] = c
        dx, _ = Vehicle(af).derivatives(x, x[dyn.N_RIGID:])
        return dx[10:13]

    np.testing.assert_allclose(
        accel(one, {"aileron": 0.3, "rudder": -0.2, "elevator": 0.1}),
        accel(two, {"aileron_left": 0.3, "aileron_right": -0.3, "rudder_left": -0.2,
                    "rudder_right": -0.2, "elevator": 0.1}), rtol=1e-12, atol=1e-12)
    assert not np.allclose(accel(one, {"aileron": 0.3}), accel(one, {}))

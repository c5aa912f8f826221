"""The airframe file: DS-1 loads into an immutable object; bad files give one clear error."""

from __future__ import annotations

import dataclasses
import math
import subprocess
import sys
import tomllib

import numpy as np
import pytest

from vtolftc.airframe.loader import DS1_PATH, AirframeError, airframe_from_dict, load_airframe


def _doc() -> dict:
    return tomllib.loads(DS1_PATH.read_text())


def test_ds1_values_match_the_design_card(ds1):
    assert ds1.name == "DS-1"
    assert ds1.mass_kg == 12.5
    assert np.allclose(np.diag(ds1.inertia_kg_m2), [1.6, 1.3, 2.7])
    assert (ds1.wing.area_m2, ds1.wing.span_m, ds1.wing.chord_m) == (0.95, 2.9, 0.33)
    assert [r.name for r in ds1.lift_rotors] == ["1a", "1b", "2a", "2b", "3a", "3b", "4a", "4b"]
    assert all(r.max_thrust_N == 35.0 for r in ds1.lift_rotors)
    assert all(r.max_thrust_N == 25.0 for r in ds1.pushers)
    assert math.isclose(math.degrees(ds1.surfaces.max_deflection_rad), 25.0)
    rotors = ["1a", "1b", "2a", "2b", "3a", "3b", "4a", "4b"]
    assert ds1.actuator_names[:8] == tuple(f"rotor_{n}" for n in rotors)
    assert ds1.actuator_names[8:] == ("pusher_left", "pusher_right", "aileron_left",
                                      "aileron_right", "elevator", "rudder_left", "rudder_right")
    # Front rotors "a" ahead of the CG, rear "b" behind; booms 1, 2 left, 3, 4 right.
    for r in ds1.lift_rotors:
        assert (r.position_m[0] > 0) == r.name.endswith("a")
        assert (r.position_m[1] < 0) == (r.name[0] in "12")
    # Alternating spin: yaw torques cancel at equal thrust.
    assert np.allclose(sum(r.spin_axis for r in ds1.lift_rotors), 0.0)
    # Aerosonde derivatives at 18 m/s, as the file says.
    d = ds1.derivatives.at(18.0)
    assert d == pytest.approx({"C_lp": -0.51, "C_mq": -38.2, "C_malpha": -2.74, "C_nr": -0.095,
                               "C_nbeta": 0.073})
    assert len(ds1.sha256) == 64


def test_airframe_is_immutable(ds1):
    with pytest.raises(dataclasses.FrozenInstanceError):
        ds1.mass_kg = 1.0
    with pytest.raises(ValueError):
        ds1.inertia_kg_m2[0, 0] = 5.0
    with pytest.raises(ValueError):
        ds1.derivatives.C_mq[0] = 0.0


def test_derivative_tables_interpolate_and_clamp(ds1):
    t = ds1.derivatives
    assert t.at(3.0)["C_mq"] == pytest.approx(0.5 * (t.C_mq[2] + t.C_mq[3]))
    assert t.at(50.0)["C_lp"] == t.C_lp[-1]
    assert t.at(0.0)["C_nbeta"] == t.C_nbeta[0]


def _set(doc: dict, dotted: str, value) -> dict:
    *path, key = dotted.split(".")
    t = doc
    for p in path:
        t = t[p]
    if value is _DELETE:
        del t[key]
    else:
        t[key] = value
    return doc


_DELETE = object()


@pytest.mark.parametrize(
    ("dotted", "value", "expect"),
    [
        ("mass.mass_kg", -12.5, ["mass.mass_kg", "-12.5", "[0.05, 500]", "kg"]),
        ("mass.mass_kg", "heavy", ["mass.mass_kg", "'heavy'", "expected a number"]),
        ("mass.mass_kg", _DELETE, ["missing field 'mass.mass_kg'"]),
        ("mass.mass_lbs", 27.5, ["unknown key 'mass.mass_lbs'", "mass_kg"]),
        ("wing.CL_max", 0.2, ["wing.CL_max", "0.2"]),
        ("lift_rotors.time_constant_s", 50.0, ["lift_rotors.time_constant_s", "50.0", "(s)"]),
        ("surfaces.max_deflection_deg", 0.0, ["surfaces.max_deflection_deg", "(deg)"]),
        ("derivatives.airspeed_m_s", [0.0, 1.0, 4.0, 2.0, 7.0, 10.0, 13.0, 18.0],
         ["derivatives.airspeed_m_s", "strictly increasing"]),
        ("derivatives.C_mq", [-1.0, -2.0], ["derivatives.C_mq", "8 values"]),
        ("derivatives.C_lp", [0.3] * 8, ["derivatives.C_lp", "<= 0"]),
        ("mass.Jxz_kg_m2", 5.0, ["mass.Jxz_kg_m2", "positive definite"]),
        ("lift_rotors.max_thrust_N", 5.0, ["lift_rotors.max_thrust_N", "1.2 x the weight"]),
        ("landing_gear.points_m", [[0, 0]], ["landing_gear.points_m", "[x, y, z]"]),
    ],
)
def test_bad_field_gives_one_clear_error(dotted, value, expect):
    doc = _set(_doc(), dotted, value)
    with pytest.raises(AirframeError) as ei:
        airframe_from_dict(doc, source="bad.toml")
    msg = str(ei.value)
    assert msg.startswith("bad.toml: ")
    for part in expect:
        assert part in msg, msg


def test_bad_rotor_entries():
    doc = _doc()
    doc["lift_rotors"]["rotor"][1]["name"] = "1a"
    with pytest.raises(AirframeError, match=r"lift_rotors.rotor\[1\].name.*not used by another"):
        airframe_from_dict(doc)
    doc = _doc()
    doc["lift_rotors"]["rotor"][0]["spin"] = "clockwise"
    with pytest.raises(AirframeError, match=r"rotor\[0\].spin.*'clockwise'.*\['cw', 'ccw'\]"):
        airframe_from_dict(doc)
    doc = _doc()
    del doc["pushers"]["rotor"][0]["x_m"]
    with pytest.raises(AirframeError, match=r"missing field 'pushers.rotor\[0\].x_m'"):
        airframe_from_dict(doc)


def test_bad_files(tmp_path):
    with pytest.raises(AirframeError, match="cannot read"):
        load_airframe(tmp_path / "nope.toml")
    p = tmp_path / "syntax.toml"
    p.write_text("[mass\nmass_kg = 1\n")
    with pytest.raises(AirframeError, match="not valid TOML"):
        load_airframe(p)


def test_cli_reports_bad_airframe_without_traceback(tmp_path):
    bad = tmp_path / "bad.toml"
    bad.write_text(DS1_PATH.read_text().replace("mass_kg = 12.5", "mass_kg = -12.5"))
    r = subprocess.run([sys.executable, "-m", "vtolftc.cli", "trim", "--airframe", str(bad)],
                       capture_output=True, text=True, timeout=120)
    assert r.returncode == 2
    assert "Traceback" not in r.stderr
    assert "mass.mass_kg" in r.stderr and "-12.5" in r.stderr

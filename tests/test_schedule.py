"""Tests of the gain-schedule reader (``vtolftc.firmware_sim.autopilot.schedule``)."""

from __future__ import annotations

import copy
import json
import math

import numpy as np
import pytest

from vtolftc.firmware_sim.autopilot.pid import PPIDGains
from vtolftc.firmware_sim.autopilot.schedule import (
    FORMAT,
    GAIN_FIELDS,
    GainSchedule,
    GainScheduleError,
)
from vtolftc.rotation import ATTITUDE_AXES

BP = [0.0, 1.0, 4.0, 7.0, 10.0, 13.0]
SHA = "ab" * 32


def axis_table(offset: float) -> dict[str, list[float]]:
    """Distinct, non-linear-in-V gains so that interpolation errors would show."""
    return {
        "kp_angle": [offset + 4.0 + 0.1 * b for b in BP],
        "kp_rate": [offset + 0.5 + 0.02 * b * b for b in BP],
        "ki_rate": [offset + 0.1 + 0.3 * math.sqrt(b) for b in BP],
        "kd_rate": [0.01 + 0.001 * b for b in BP],
        "tf_rate_s": [0.02 + 0.001 * b for b in BP],
    }


def schedule_dict() -> dict:
    return {
        "format": FORMAT,
        "controller": "gs-shif",
        "airframe": {"name": "DS-1", "sha256": SHA},
        "airspeed_breakpoints_m_s": list(BP),
        "axes": {"roll": axis_table(0.0), "pitch": axis_table(1.0), "yaw": axis_table(2.0)},
        "achieved": {"gamma": [0.9, 0.95, 1.0, 0.97, 0.93, 0.91]},
        "mu_rp_peak": 0.98,
    }


def test_interpolation_exact_at_breakpoints():
    d = schedule_dict()
    s = GainSchedule.from_dict(d)
    for i, V in enumerate(BP):
        g = s.gains_at(V)
        for ax in ATTITUDE_AXES:
            for f in GAIN_FIELDS:
                assert getattr(g[ax], f) == d["axes"][ax][f][i]  # bit-exact


def test_interpolation_linear_between_breakpoints():
    d = schedule_dict()
    s = GainSchedule.from_dict(d)
    rng = np.random.default_rng(0)
    for V in [0.5, 2.5, 5.5, 9.99, 12.0, *rng.uniform(0, 13, 20)]:
        g = s.gains_at(float(V))
        for ax in ATTITUDE_AXES:
            for f in GAIN_FIELDS:
                expected = np.interp(V, BP, d["axes"][ax][f])
                assert getattr(g[ax], f) == pytest.approx(expected, rel=1e-12, abs=1e-15)
    # midpoint is the mean
    g = s.gains_at(5.5)
    assert g["pitch"].kp_rate == pytest.approx(
        0.5 * (d["axes"]["pitch"]["kp_rate"][2] + d["axes"]["pitch"]["kp_rate"][3])
    )


def test_clamped_outside_the_range():
    d = schedule_dict()
    s = GainSchedule.from_dict(d)
    assert s.gains_at(-3.0) == s.gains_at(0.0)
    assert s.gains_at(25.0) == s.gains_at(13.0)
    assert s.gains_at(25.0)["yaw"].ki_rate == d["axes"]["yaw"]["ki_rate"][-1]
    assert s.gains_at(float("nan")) == s.gains_at(0.0)
    assert s.gains_at(float("inf")) == s.gains_at(13.0)


def test_returns_ppid_gains_per_axis():
    g = GainSchedule.from_dict(schedule_dict()).gains_at(3.0)
    assert set(g) == set(ATTITUDE_AXES)
    assert all(isinstance(x, PPIDGains) for x in g.values())


def test_single_breakpoint_constant_schedule():
    d = schedule_dict()
    d["controller"] = "shif"
    d["airspeed_breakpoints_m_s"] = [7.0]
    for ax in ATTITUDE_AXES:
        d["axes"][ax] = {f: [v[3]] for f, v in d["axes"][ax].items()}
    s = GainSchedule.from_dict(d)
    assert s.is_constant
    for V in (0.0, 7.0, 13.0, -1.0, float("nan")):
        assert s.gains_at(V)["roll"] == PPIDGains(*(d["axes"]["roll"][f][0] for f in GAIN_FIELDS))


def test_load_from_file_and_round_trip(tmp_path):
    p = tmp_path / "gs.json"
    d = schedule_dict()
    d["axes"]["roll"]["metadata"] = {"mu": 0.7}
    p.write_text(json.dumps(d))
    s = GainSchedule.load(p)
    assert s.controller == "gs-shif" and s.airframe_name == "DS-1"
    assert s.metadata["mu_rp_peak"] == 0.98
    assert s.metadata["axes_metadata"]["roll"] == {"mu": 0.7}
    s2 = GainSchedule.from_dict(json.loads(json.dumps(s.to_dict())))
    assert s2.gains_at(5.0) == s.gains_at(5.0)
    assert s2.to_dict() == s.to_dict()


def test_verify_airframe():
    s = GainSchedule.from_dict(schedule_dict())
    s.verify_airframe(name="DS-1", sha256=SHA.upper())
    with pytest.raises(GainScheduleError, match=r"airframe\.sha256"):
        s.verify_airframe(sha256="cd" * 32)
    with pytest.raises(GainScheduleError, match=r"airframe\.name"):
        s.verify_airframe(name="DS-2")


def test_gains_at_is_cheap():
    import time

    s = GainSchedule.from_dict(schedule_dict())
    n = 5000
    t0 = time.perf_counter()
    for i in range(n):
        s.gains_at((i % 140) * 0.1)
    per_call = (time.perf_counter() - t0) / n
    assert per_call < 100e-6  # generous: a few us on a desktop, shared CI machines vary


# ---- validation: every error path names the field, the value and the expectation --------
def _mut(fn):
    d = schedule_dict()
    fn(d)
    return d


def _set(path, value):
    def f(d):
        cur = d
        for k in path[:-1]:
            cur = cur[k]
        cur[path[-1]] = value

    return f


def _del(path):
    def f(d):
        cur = d
        for k in path[:-1]:
            cur = cur[k]
        del cur[path[-1]]

    return f


def _set_item(path, i, value):
    def f(d):
        cur = d
        for k in path:
            cur = cur[k]
        cur[i] = value

    return f


CASES = [
    ("missing format", _del(["format"]), r"format: missing; expected 'vtolftc-gain-schedule/1'"),
    (
        "format version",
        _set(["format"], "vtolftc-gain-schedule/2"),
        r"format: unsupported version 'vtolftc-gain-schedule/2'",
    ),
    ("unknown format", _set(["format"], "pid-gains"), r"format: unknown format 'pid-gains'"),
    ("controller", _set(["controller"], ""), r"controller: expected a non-empty string"),
    ("airframe", _set(["airframe"], "DS-1"), r"airframe: expected an object"),
    ("airframe name", _del(["airframe", "name"]), r"airframe.name: expected a non-empty string"),
    (
        "sha",
        _set(["airframe", "sha256"], "1234"),
        r"airframe.sha256: expected 64 hexadecimal digits, got '1234'",
    ),
    ("bp missing", _del(["airspeed_breakpoints_m_s"]), r"airspeed_breakpoints_m_s: expected a"),
    ("bp empty", _set(["airspeed_breakpoints_m_s"], []), r"non-empty list"),
    (
        "bp order",
        _set_item(["airspeed_breakpoints_m_s"], 3, 4.0),
        r"airspeed_breakpoints_m_s\[3\]: breakpoints must be strictly increasing, "
        r"got 4.0 after 4.0",
    ),
    (
        "bp decreasing",
        _set_item(["airspeed_breakpoints_m_s"], 5, 2.0),
        r"airspeed_breakpoints_m_s\[5\]: .*strictly increasing",
    ),
    (
        "bp nan",
        _set_item(["airspeed_breakpoints_m_s"], 1, float("nan")),
        r"airspeed_breakpoints_m_s\[1\]: expected a finite number",
    ),
    (
        "bp str",
        _set_item(["airspeed_breakpoints_m_s"], 1, "1"),
        r"airspeed_breakpoints_m_s\[1\]: expected a finite number \[m/s\], got '1'",
    ),
    ("axes", _set(["axes"], []), r"axes: expected an object with keys \['roll', 'pitch', 'yaw'\]"),
    ("missing axis", _del(["axes", "yaw"]), r"axes.yaw: missing axis"),
    ("unknown axis", _set(["axes", "altitude"], {}), r"axes: unknown axis 'altitude'"),
    ("axis type", _set(["axes", "roll"], [1, 2]), r"axes.roll: expected an object"),
    (
        "unknown gain",
        _set(["axes", "pitch", "kp_angel"], [1.0] * 6),
        r"axes.pitch.kp_angel: unknown field",
    ),
    ("missing gain", _del(["axes", "pitch", "ki_rate"]), r"axes.pitch.ki_rate: missing gain list"),
    (
        "gain not list",
        _set(["axes", "roll", "kp_rate"], 0.5),
        r"axes.roll.kp_rate: expected a list of 6 numbers",
    ),
    (
        "length",
        _set(["axes", "yaw", "kd_rate"], [0.1] * 5),
        r"axes.yaw.kd_rate: length mismatch: 5 values for 6 airspeed breakpoints",
    ),
    (
        "negative",
        _set_item(["axes", "roll", "ki_rate"], 2, -0.5),
        r"axes.roll.ki_rate\[2\]: negative gain -0.5; gains must be >= 0",
    ),
    (
        "nan gain",
        _set_item(["axes", "roll", "kp_angle"], 0, float("nan")),
        r"axes.roll.kp_angle\[0\]: expected a finite number, got nan",
    ),
    (
        "inf gain",
        _set_item(["axes", "roll", "kp_angle"], 0, float("inf")),
        r"axes.roll.kp_angle\[0\]: expected a finite number, got inf",
    ),
    (
        "bool gain",
        _set_item(["axes", "roll", "kp_angle"], 0, True),
        r"axes.roll.kp_angle\[0\]: expected a finite number, got True",
    ),
    (
        "null gain",
        _set_item(["axes", "roll", "kp_angle"], 0, None),
        r"axes.roll.kp_angle\[0\]: expected a finite number, got None",
    ),
    (
        "tf zero with kd",
        _set_item(["axes", "pitch", "tf_rate_s"], 4, 0.0),
        r"axes.pitch.tf_rate_s\[4\]: expected > 0 where kd_rate > 0",
    ),
]


@pytest.mark.parametrize("mutate, message", [c[1:] for c in CASES], ids=[c[0] for c in CASES])
def test_validation_errors(mutate, message):
    with pytest.raises(GainScheduleError, match=message):
        GainSchedule.from_dict(_mut(mutate))


def test_tf_zero_allowed_without_derivative():
    d = schedule_dict()
    d["axes"]["yaw"]["kd_rate"] = [0.0] * 6
    d["axes"]["yaw"]["tf_rate_s"] = [0.0] * 6
    assert GainSchedule.from_dict(d).gains_at(3.0)["yaw"].tf_rate_s == 0.0


def test_not_an_object():
    with pytest.raises(GainScheduleError, match="top level: expected a JSON object, got list"):
        GainSchedule.from_dict([1, 2])  # type: ignore[arg-type]


def test_file_errors_name_the_file(tmp_path):
    p = tmp_path / "bad.json"
    p.write_text("{not json")
    with pytest.raises(GainScheduleError, match=r"bad.json: not valid JSON"):
        GainSchedule.load(p)
    d = schedule_dict()
    d["axes"]["roll"]["kp_rate"][1] = -1.0
    p.write_text(json.dumps(d))
    with pytest.raises(GainScheduleError, match=r"bad.json: axes.roll.kp_rate\[1\]: negative"):
        GainSchedule.load(p)
    with pytest.raises(GainScheduleError, match="cannot read"):
        GainSchedule.load(tmp_path / "missing.json")


def test_error_is_a_value_error():
    assert issubclass(GainScheduleError, ValueError)
    d = copy.deepcopy(schedule_dict())
    d["format"] = 1
    with pytest.raises(ValueError, match="unknown format 1"):
        GainSchedule.from_dict(d)

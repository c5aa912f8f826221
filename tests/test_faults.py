"""Fault injection on the physical actuators: timing, kinds, composition, cases, bad specs."""

from __future__ import annotations

import numpy as np
import pytest

from vtolftc.firmware_sim.vehicle import dynamics as dyn
from vtolftc.firmware_sim.vehicle.faults import (
    Fault,
    FaultError,
    FaultKind,
    case_faults,
    faults_from_records,
    parse_fault_spec,
)
from vtolftc.firmware_sim.vehicle.model import Vehicle


def test_fault_starts_exactly_at_its_time_whatever_the_batch(ds1, hover_trim):
    i = ds1.actuator_index("rotor_2b")
    v = Vehicle(ds1, state=hover_trim.state, faults=[Fault("rotor_2b", "loss", 0.5, 0.5005)])
    v.step(hover_trim.commands, 500)
    assert v.effectiveness[i] == 1.0
    v.step(None, 1)  # t = 0.501 s >= 0.5005: active from this step boundary
    assert v.effectiveness[i] == 0.5
    # Same trajectory when stepped in one batch.
    w = Vehicle(ds1, state=hover_trim.state, faults=[Fault("rotor_2b", "loss", 0.5, 0.5005)])
    w.step(hover_trim.commands, 1000)
    v.step(None, 499)
    assert np.array_equal(v.state, w.state)


def test_losses_compose_and_off_is_total(ds1):
    v = Vehicle(ds1, faults=[Fault("elevator", "loss", 0.2), Fault("elevator", "loss", 0.5),
                             Fault("rotor_1a", "off")])
    assert v.effectiveness[ds1.actuator_index("elevator")] == pytest.approx(0.4)
    assert v.effectiveness[ds1.actuator_index("rotor_1a")] == 0.0


def test_off_rotor_produces_no_thrust(ds1, hover_trim):
    x = hover_trim.state.copy()
    healthy = Vehicle(ds1)
    off = Vehicle(ds1, faults=[Fault("rotor_3a", FaultKind.OFF)])
    _, fm_h = healthy.derivatives(x, x[dyn.N_RIGID:])
    _, fm_o = off.derivatives(x, x[dyn.N_RIGID:])
    t3a = x[dyn.N_RIGID + ds1.actuator_index("rotor_3a")] * 35.0
    assert fm_o[2] - fm_h[2] == pytest.approx(t3a)  # less upward (-z) force


def test_stuck_actuator_holds_its_position(ds1, cruise_trim):
    j = ds1.actuator_index("aileron_left")
    v = Vehicle(ds1, state=cruise_trim.state, faults=[Fault("aileron_left", "stuck", 0, 0.2)])
    u = cruise_trim.commands.copy()
    u[j] = 0.3
    v.step(u, 200)
    held = v.actuator_positions[j]
    assert held > 0.2
    u[j] = -0.5
    v.step(u, 300)
    assert v.actuator_positions[j] == held
    k = ds1.actuator_index("aileron_right")
    u[k] = -0.5
    v.step(u, 300)
    assert v.actuator_positions[k] < -0.45  # the healthy one still moves


def test_runtime_injection_and_clear(ds1, hover_trim):
    v = Vehicle(ds1, state=hover_trim.state)
    v.step(hover_trim.commands, 100)
    v.inject(Fault("rotor_4b", "loss", 0.3, 0.0))  # start in the past: acts from now
    v.step(None, 1)
    assert v.effectiveness[ds1.actuator_index("rotor_4b")] == pytest.approx(0.7)
    v.clear_faults()
    assert np.all(v.effectiveness == 1.0)


def test_paper_cases_are_data(ds1):
    c1 = case_faults(1, ds1.actuator_names)
    assert {(f.actuator, f.loss, f.start_s) for f in c1} == {
        ("rotor_2b", 0.5, 22.0), ("elevator", 0.2, 22.0), ("aileron_left", 0.2, 22.0),
        ("aileron_right", 0.2, 22.0), ("rudder_left", 0.2, 22.0), ("rudder_right", 0.2, 22.0)}
    c2 = case_faults("case2", ds1.actuator_names)
    rotors = {f.actuator for f in c2 if f.actuator.startswith("rotor_")}
    assert rotors == {"rotor_1a", "rotor_2b", "rotor_4a"}
    assert all(f.loss == 0.5 for f in c2 if f.actuator.startswith("rotor_"))
    assert len(c2) == 8
    assert case_faults(0, ds1.actuator_names) == []


def test_fault_spec_strings(ds1):
    names = ds1.actuator_names
    assert parse_fault_spec("rotor_2b:loss=0.5@22", names) == [Fault("rotor_2b", "loss", 0.5, 22)]
    assert [f.actuator for f in parse_fault_spec("ailerons:loss=20%@22", names)] == [
        "aileron_left", "aileron_right"]
    assert parse_fault_spec("ailerons:loss=20%", names)[0].loss == pytest.approx(0.2)
    assert parse_fault_spec("elevator:stuck@10", names)[0].kind is FaultKind.STUCK
    assert parse_fault_spec("rotor_1a:off", names)[0].loss == 1.0
    assert len(parse_fault_spec("lift_rotors:loss=0.1", names)) == 8


@pytest.mark.parametrize(
    ("spec", "expect"),
    [
        ("rotor_9z:loss=0.5", "unknown actuator 'rotor_9z'"),
        ("rotor_2c:loss=0.5", "did you mean"),
        ("rotor_2b:loss=50", "not a percentage"),
        ("rotor_2b:loss", "needs a value"),
        ("rotor_2b:broken=1", "expected ACTUATOR:KIND"),
        ("rotor_2b:stuck=0.3", "takes no value"),
        ("elevator", "expected ACTUATOR:KIND"),
    ],
)
def test_bad_fault_specs_are_explained(ds1, spec, expect):
    with pytest.raises(FaultError, match=expect):
        parse_fault_spec(spec, ds1.actuator_names)


def test_bad_fault_records_and_objects(ds1):
    with pytest.raises(FaultError, match=r"faults\[0\].*unknown key"):
        faults_from_records([{"actuators": ["elevator"], "los": 0.2}], ds1.actuator_names)
    with pytest.raises(FaultError, match="start time -1"):
        Fault("elevator", "loss", 0.2, -1)
    with pytest.raises(FaultError, match="unknown kind 'melted'"):
        Fault("elevator", "melted")
    with pytest.raises(FaultError, match="unknown fault case 7: known cases: 0, 1, 2"):
        case_faults(7, ds1.actuator_names)
    with pytest.raises(FaultError, match="unknown actuator"):
        Vehicle(ds1, faults=[Fault("rotor_5a", "off")])

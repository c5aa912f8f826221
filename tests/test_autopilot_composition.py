"""The autopilot as a composition of stages, and the rerun recorder as one of parts (issue 21):
each class stays small, and the names callers use still reach the state the stages hold."""

from __future__ import annotations

import ast
from pathlib import Path

import numpy as np
import pytest

from vtolftc.firmware_sim.autopilot.autopilot import CMD_COMPONENT_ARM_DISARM, Autopilot
from vtolftc.firmware_sim.autopilot.delegation import Delegated
from vtolftc.firmware_sim.autopilot.interface import FlightMode, NavState
from vtolftc.telemetry.rerun_rows import RowBuffer

ROOT = Path(__file__).resolve().parents[1]
NAN = float("nan")

#: (file, class, most lines of its body): the composed classes and their parts.
SIZES = (
    ("firmware_sim/autopilot/autopilot.py", "Autopilot", 300),
    ("firmware_sim/autopilot/commander.py", "Commander", 400),
    ("firmware_sim/autopilot/outer_loops.py", "OuterLoops", 400),
    ("firmware_sim/autopilot/output.py", "OutputStage", 400),
    ("firmware_sim/autopilot/estimate.py", "StateEstimate", 400),
    ("firmware_sim/autopilot/attitude_stage.py", "AttitudeStage", 400),
    ("vtolftc/telemetry/recording.py", "RerunRecorder", 400),
)


def class_lines(path: Path, name: str) -> int:
    """Lines of the class ``name`` defined at the top level of ``path``."""
    for node in ast.parse(path.read_text()).body:
        if isinstance(node, ast.ClassDef) and node.name == name:
            return node.end_lineno - node.lineno + 1
    raise LookupError(f"{path}: no class {name}")


@pytest.mark.parametrize(("rel", "name", "most"), SIZES)
def test_composed_classes_stay_small(rel, name, most):
    assert class_lines(ROOT / rel, name) <= most


def test_class_lines_counts_the_body(tmp_path):
    f = tmp_path / "m.py"
    f.write_text("x = 1\n\n\nclass A:\n    a = 1\n\n    def f(self):\n        return 2\n")
    assert class_lines(f, "A") == 5
    with pytest.raises(LookupError):
        class_lines(f, "B")


def test_delegated_reads_and_writes_the_part():
    class Part:
        x = 1

    class Owner:
        y = Delegated("part", "x")

        def __init__(self) -> None:
            self.part = Part()

    o = Owner()
    assert o.y == 1
    o.y = 5
    assert o.part.x == 5 and o.y == 5
    assert isinstance(Owner.y, Delegated)


def _nav(t_s: float, alt: float = 0.29) -> NavState:
    return NavState(round(t_s * 1e6), np.array([1.0, 0.0, 0.0, 0.0]), np.zeros(3),
                    np.array([0.0, 0.0, -alt]), np.zeros(3), 0.0)


@pytest.fixture
def ap(ds1, hand_gains):
    return Autopilot(ds1, controller="shif", gains_dir=hand_gains)


def test_an_assigned_allocator_is_the_one_flown(ap):
    """Benchmarks swap ``ap.allocator`` for a recording wrapper: the step must use it."""
    calls = []
    inner = ap.allocator

    class Spy:
        stats = inner.stats

        def allocate(self, *a, **kw):
            calls.append(1)
            return inner.allocate(*a, **kw)

        def reset(self, u0=None):
            inner.reset(u0)

    spy = Spy()
    ap.allocator = spy
    assert ap.output.allocator is spy
    ap.step(_nav(0.0))
    assert ap.command(CMD_COMPONENT_ARM_DISARM, [1.0] + [NAN] * 6).name == "ACCEPTED"
    ap.modes.set_mode(FlightMode.HOVER, "test")       # armed in the air: allocation runs
    ap.step(_nav(0.004, alt=10.0))
    assert calls, "the assigned allocator was not called"


def test_navigator_view_is_the_stages_state(ap):
    """The navigator steers through its public view of the autopilot (no private names of
    the Autopilot cross a module); what it reads and sets is the stages' state."""
    nv = ap.navigator
    nv.set_alt_ref(12.5)
    assert ap.setpoints.alt_ref == 12.5
    nv.set_takeoff_alt(20.0)
    assert (ap.setpoints.takeoff_alt, ap.setpoints.alt_ref) == (20.0, 20.0)
    nv.yaw_hold = 0.25
    assert ap.setpoints.yaw_hold == 0.25
    ap.step(_nav(0.0, alt=7.0))
    assert nv.altitude_m == pytest.approx(7.0) and nv.altitude_m == ap.estimate.alt
    assert nv.last_nav is ap.estimate.last_nav
    assert nv.airspeed_m_s == ap.estimate.airspeed
    assert ap.status().attitude_ref_rad[2] == 0.25        # idle: heading reference held


def test_invalid_navigation_holds_the_previous_command(ap):
    ap.step(_nav(0.0))
    u0 = ap.output.u.copy()
    bad = NavState(4000, np.array([NAN, 0.0, 0.0, 0.0]), np.zeros(3), np.zeros(3),
                   np.zeros(3), 0.0)
    u = ap.step(bad)
    assert np.array_equal(u, u0) and ap.status().allocation_status == "invalid navigation data"
    assert ap.estimate.time_usec == 0                     # the bad data was not taken in


def test_row_buffer_keeps_every_nth_path_point():
    from test_recording import _sample

    rows = RowBuffer(20, 15, path_every=3)
    for k in range(7):
        assert rows.add(k * 20_000, _sample(k, truth=k % 2 == 0)) == int(
            _sample(k).status.mode)
    assert rows.n == 7 and rows.has_truth
    assert len(rows.path_pts) == 3                       # rows 0, 3 and 6
    assert np.isnan(rows.buf[1, rows.sl["eff"]]).all()   # no truth in row 1
    assert rows.buf[0, rows.sl["misc"]][0] == -rows.buf[0, rows.sl["pos"]][2]

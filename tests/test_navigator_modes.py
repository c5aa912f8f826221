"""The navigator split along PX4's seams, and the autopilot's types read from its interface.

Issue 21: the navigator is one small :class:`Navigator` owning the state and dispatching to
one module per PX4 navigator mode (mission, rtl, takeoff, land, loiter); no class of it over
300 lines. The autopilot's boundary types (NavState, FlightMode, AutopilotStatus, VtolState,
LandedState) are defined at the lowest layer that needs them and everything that may import
the autopilot reads them from its interface. The flights themselves are tested in
test_navigation.py, test_backtransition.py and test_sitl_mission.py.
"""

from __future__ import annotations

import ast
import math
from pathlib import Path

import numpy as np
import pytest

from vtolftc.base.geodesy import FlatEarth
from vtolftc.firmware_sim.autopilot import interface
from vtolftc.firmware_sim.autopilot.autopilot import Autopilot
from vtolftc.firmware_sim.autopilot.mission import (
    DO_JUMP,
    FRAME_GLOBAL_RELATIVE_ALT_INT,
    FRAME_MISSION,
    NAV_WAYPOINT,
    RALLY,
    MissionItem,
)
from vtolftc.firmware_sim.autopilot.nav_base import (
    MS_COMPLETE,
    MS_NOT_STARTED,
    NavigatorMode,
    NavMode,
)
from vtolftc.firmware_sim.autopilot.nav_land import Land
from vtolftc.firmware_sim.autopilot.nav_loiter import Loiter
from vtolftc.firmware_sim.autopilot.nav_mission import Mission
from vtolftc.firmware_sim.autopilot.nav_rtl import Rtl
from vtolftc.firmware_sim.autopilot.nav_takeoff import Takeoff
from vtolftc.firmware_sim.vehicle.sensors import Home
from vtolftc.protocols import hil
from vtolftc.telemetry import autopilot_status

ROOT = Path(__file__).resolve().parents[1]
AUTOPILOT = ROOT / "firmware_sim" / "autopilot"
MODES = {"nav_mission": Mission, "nav_rtl": Rtl, "nav_takeoff": Takeoff, "nav_land": Land,
         "nav_loiter": Loiter}


def _classes(path: Path) -> dict[str, int]:
    tree = ast.parse(path.read_text(encoding="utf-8"))
    return {n.name: n.end_lineno - n.lineno + 1 for n in tree.body if isinstance(n, ast.ClassDef)}


def test_one_module_per_px4_mode_and_no_class_over_300_lines():
    files = [AUTOPILOT / "navigator.py", AUTOPILOT / "nav_base.py",
             *(AUTOPILOT / f"{m}.py" for m in MODES)]
    sizes = {f"{f.name}:{c}": n for f in files for c, n in _classes(f).items()}
    assert sizes and max(sizes.values()) <= 300, sizes
    for module, cls in MODES.items():
        assert issubclass(cls, NavigatorMode)
        assert list(_classes(AUTOPILOT / f"{module}.py")) == [cls.__name__], module


def test_navigator_dispatches_each_px4_mode_to_its_module():
    nv = Autopilot(controller="gs-shif").navigator
    for attr, cls in (("mission", Mission), ("rtl", Rtl), ("takeoff", Takeoff),
                      ("land", Land), ("loiter", Loiter)):
        assert type(getattr(nv, attr)) is cls
    flown = []
    for attr in ("mission", "rtl", "takeoff", "land", "loiter"):
        getattr(nv, attr).on_active = lambda nav, yaw, a=attr: flown.append(a)
    nav = interface.NavState(0, np.array([1.0, 0, 0, 0]), np.zeros(3), np.zeros(3),
                             np.zeros(3), 0.0)
    nv.ap.modes.armed = True
    for mode, want in ((NavMode.MISSION, "mission"), (NavMode.RTL, "rtl"),
                       (NavMode.TAKEOFF, "takeoff"), (NavMode.LAND, "land"),
                       (NavMode.LOITER, "loiter"), (NavMode.POSCTL, None),
                       (NavMode.ALTCTL, None)):
        flown.clear()
        nv.nav_mode = mode
        nv.update(nav, 0.0)
        assert flown == ([want] if want else []), mode
    nv.ap.modes.armed = False
    nv.nav_mode = NavMode.MISSION
    flown.clear()
    nv.update(nav, 0.0)
    assert flown == []                          # disarmed: no mode flies


def _wp(seq: int, home: Home, north: float) -> MissionItem:
    lat, lon = FlatEarth(home.lat_deg, home.lon_deg).to_global(north, 0.0)
    return MissionItem(seq, FRAME_GLOBAL_RELATIVE_ALT_INT, NAV_WAYPOINT, 1, 0.0, 0.0, 0.0,
                       math.nan, round(lat * 1e7), round(lon * 1e7), 30.0)


def test_mission_sequencing_do_jump_repeats_then_completes():
    """Items reached one after the other: DO_JUMP to item 0 twice (param2 = 2 repeats), then
    on to the last item and MISSION complete; a new upload resets the jump counters."""
    ap = Autopilot(controller="gs-shif")
    home = Home()
    ap.set_home(home.lat_deg, home.lon_deg, home.alt_m)
    nv = ap.navigator
    items = [_wp(0, home, 100.0), _wp(1, home, 200.0),
             MissionItem(2, FRAME_MISSION, DO_JUMP, 1, 0.0, 2.0, 0.0, 0.0, 0, 0, 0.0),
             _wp(3, home, 300.0)]
    assert nv.store.replace(0, items)[0] == 0

    def fly_through() -> list[int]:
        order = []
        while nv.mission_state != MS_COMPLETE and len(order) < 20:
            seq = nv.store.current
            order.append(seq)
            nv.mission.item_reached(nv.goal_of(nv.store.mission[seq]))
        return order

    assert fly_through() == [0, 1, 2, 0, 1, 2, 0, 1, 2, 3]
    assert nv.reached == [0, 1, 2, 0, 1, 2, 0, 1, 2, 3]
    assert nv.prev_wp == pytest.approx((300.0, 0.0), abs=0.01)   # last waypoint reached
    assert nv.store.replace(0, items)[0] == 0
    assert nv.mission_state == MS_NOT_STARTED and nv.store.current == 0
    assert fly_through() == [0, 1, 2, 0, 1, 2, 0, 1, 2, 3]


def test_rtl_returns_to_the_nearest_of_home_and_the_rally_points():
    ap = Autopilot(controller="gs-shif")
    home = Home()
    ap.set_home(home.lat_deg, home.lon_deg, home.alt_m)
    nv = ap.navigator
    fe = FlatEarth(home.lat_deg, home.lon_deg)

    def rally(seq: int, north: float, east: float) -> MissionItem:
        lat, lon = fe.to_global(north, east)
        return MissionItem(seq, FRAME_GLOBAL_RELATIVE_ALT_INT, 5100, 1, 0.0, 0.0, 0.0, 0.0,
                           round(lat * 1e7), round(lon * 1e7), 30.0, RALLY)

    assert nv.rtl.destination() == (0.0, 0.0)          # no position yet: home
    assert nv.store.replace(RALLY, [rally(0, 400.0, 0.0), rally(1, 0.0, -300.0)])[0] == 0

    def at(north: float, east: float) -> tuple[float, float]:
        ap.estimate.last_nav = interface.NavState(0, np.array([1.0, 0, 0, 0]), np.zeros(3),
                                          np.array([north, east, -30.0]), np.zeros(3), 0.0)
        return nv.rtl.destination()

    assert at(10.0, 10.0) == (0.0, 0.0)                 # home is nearest
    assert at(350.0, 0.0) == pytest.approx((400.0, 0.0), abs=0.05)
    assert at(0.0, -250.0) == pytest.approx((0.0, -300.0), abs=0.05)


@pytest.mark.parametrize("name, home", [
    ("NavState", hil), ("FlightMode", autopilot_status), ("AutopilotStatus", autopilot_status),
    ("VtolState", autopilot_status), ("LandedState", autopilot_status),
])
def test_the_autopilots_types_are_re_exported_by_its_interface(name, home):
    assert getattr(interface, name) is getattr(home, name)
    assert name in interface.__all__


TYPES = {"NavState", "FlightMode", "AutopilotStatus", "VtolState", "LandedState"}
# the packages that may import the autopilot (layers 3-5 above it, the autopilot itself)
ABOVE = [AUTOPILOT, ROOT / "vtolftc" / "processes", ROOT / "vtolftc" / "campaign",
         ROOT / "dashboard", *(ROOT / "vtolftc").glob("*.py")]


def _type_imports(path: Path) -> list[str]:
    tree = ast.parse(path.read_text(encoding="utf-8"))
    return [f"{path.relative_to(ROOT)}:{n.lineno} {n.module}.{a.name}"
            for n in ast.walk(tree) if isinstance(n, ast.ImportFrom)
            for a in n.names if a.name in TYPES
            and n.module != "vtolftc.firmware_sim.autopilot.interface"]


def test_above_the_autopilot_its_types_come_from_its_interface():
    files = [f for p in ABOVE for f in ([p] if p.is_file() else p.rglob("*.py"))
             if f.name != "interface.py"
             and f.stem not in {"geodesy", "rotation", "jsonio", "errors", "__init__"}]
    assert len(files) > 30
    bad = [hit for f in files for hit in _type_imports(f)]
    assert not bad, bad

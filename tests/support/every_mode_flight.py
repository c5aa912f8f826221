"""In-process flight through every mode after a warm-up; prints one JSON line.

Run as a script in a fresh interpreter (``python tests/support/every_mode_flight.py``), so that
no other test's calls have compiled anything before: warm up exactly as the autopilot process
does, record every numba dispatcher's specialisations, then fly the real autopilot against the
simulated vehicle through take-off, hover, front transition, fixed-wing (rotor ramp, then the
reserve), a case-1 fault, AUTO.MISSION, AUTO.RTL (and its back transition), LAND, disarm, and
print the modes visited and every specialisation compiled during the flight.
"""

from __future__ import annotations

import json
import math
import time

from vtolftc.airframe.loader import load_airframe
from vtolftc.firmware_sim.autopilot.autopilot import Autopilot
from vtolftc.firmware_sim.autopilot.interface import FlightMode
from vtolftc.firmware_sim.autopilot.mission import (
    FRAME_GLOBAL_RELATIVE_ALT_INT,
    NAV_WAYPOINT,
    MissionItem,
)
from vtolftc.firmware_sim.autopilot.warmup import (
    compiled_specialisations,
    freeze_heap,
    new_specialisations,
    warm_up,
)
from vtolftc.firmware_sim.vehicle.faults import Fault, case_faults
from vtolftc.firmware_sim.vehicle.model import Vehicle
from vtolftc.protocols.hil import decode_hil_state, encode_hil_state, wire_commands
from vtolftc.protocols.px4 import mode_name

NAN = math.nan


def main() -> None:
    """Fly (see the module docstring) and print the JSON result."""
    af = load_airframe()
    t0 = time.monotonic()
    warm_up(lambda: Autopilot(af))
    freeze_heap()  # as the autopilot process does before it reports ready
    warm_s = time.monotonic() - t0
    before = compiled_specialisations()
    ap = Autopilot(af)
    ap.params.set("MIS_TAKEOFF_ALT", 15.0)
    veh = Vehicle(af)
    home = veh.sensor_model.home
    h = (float(home.lat_deg), float(home.lon_deg), float(home.alt_m))
    ap.set_home(*h)
    lat = round((h[0] + math.degrees(400.0 / 6_378_137.0)) * 1e7)
    lon = round(h[1] * 1e7)
    wp = MissionItem(0, FRAME_GLOBAL_RELATIVE_ALT_INT, NAV_WAYPOINT, 1, 0.0, 0.0, 0.0, NAN,
                     lat, lon, 15.0)
    res, why = ap.navigator.store.replace(0, [wp])
    assert res == 0, why
    modes: set[str] = set()
    px4: set[str] = set()
    stage, t_stage = "ground", 0.0
    max_step_s = 0.0
    step = 0
    while veh.time_usec < 300e6:
        now = veh.time_usec
        t = now * 1e-6
        nav = decode_hil_state(encode_hil_state(_nav_of(veh, now), *h), *h)
        c0 = time.thread_time()
        u = ap.step(nav)
        max_step_s = max(max_step_s, time.thread_time() - c0)
        st = ap.status()
        modes.add(st.mode.name)
        px4.add(mode_name(ap.navigator.custom_mode(st.mode)))
        since = t - t_stage
        if stage == "ground" and step == 5:
            ap.command(400, [1.0, *[NAN] * 6])
            ap.command(22, [NAN] * 7)
            stage, t_stage = "takeoff", t
        elif stage == "takeoff" and st.mode == FlightMode.HOVER:
            stage, t_stage = "hover", t
        elif stage == "hover" and since > 1.0:
            ap.command(3000, [4.0, *[NAN] * 6])
            stage, t_stage = "transition", t
        elif stage == "transition" and st.mode == FlightMode.FIXED_WING:
            stage, t_stage = "fixed_wing", t
        elif stage == "fixed_wing" and since > 3.0:  # past VT_TRANS_P2_DUR: the reserve
            for f in case_faults(1, af.actuator_names):
                veh.inject(Fault(f.actuator, f.kind, f.loss, t))
            ap.command(176, [1.0, 4.0, 4.0, NAN, NAN, NAN, NAN])  # AUTO.MISSION
            stage, t_stage = "mission", t
        elif stage == "mission" and since > 4.0:
            ap.command(20, [NAN] * 7)  # RTL
            stage, t_stage = "rtl", t
        elif stage == "rtl" and since > 4.0:
            ap.command(21, [NAN] * 7)  # land here
            stage, t_stage = "land", t
        elif stage == "land" and not st.armed:
            stage = "landed"
            break
        veh.step(wire_commands(u), 4)
        step += 1
    after = compiled_specialisations()
    print(json.dumps({"stage": stage, "sim_time_s": veh.time_usec * 1e-6, "warm_s": warm_s,
                      "modes": sorted(modes), "px4_modes": sorted(px4),
                      "max_step_cpu_s": max_step_s,
                      "specialisations": sum(map(len, after.values())),
                      "compiled_during_flight": new_specialisations(before, after)}))


def _nav_of(veh: Vehicle, now: int):
    from vtolftc.runners.mission_run import _nav_of as nav_of

    return nav_of(veh, now)


if __name__ == "__main__":
    main()

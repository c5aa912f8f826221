"""Mission benchmark: path following of the reference VTOL mission and its wall time.

    python benchmarks/bench_mission.py [--transport udp|zenoh|none] [--faults]

1. The reference mission (:func:`vtolftc.runners.mission_run.rectangle_mission`: NAV_TAKEOFF 30 m,
   transition, four waypoints on a 300 m x 600 m rectangle, back transition, land at home)
   flown in-process: per fixed-wing leg the RMS and maximum distance to the planned polyline
   (:func:`vtolftc.runners.mission_run.path_errors`, the corner cut of the turns included), the
   landing
   error, simulated and wall time.
2. The same mission flown by the SITL processes in lockstep (free-running, uploaded by a
   pymavlink client, :func:`vtolftc.runners.mission_sitl.fly_sitl_mission`): the same per-leg
   figures
   from the telemetry (LOCAL_POSITION_NED at 10 Hz) and the wall time of the flight (arming to
   disarm after landing, process start-up excluded).

``--faults``: case 1's faults injected 5 s into the first fixed-wing leg in both.
"""

from __future__ import annotations

import argparse
import math
import tempfile
from pathlib import Path

import numpy as np

from vtolftc.airframe.loader import load_airframe
from vtolftc.firmware_sim.vehicle.faults import case_faults
from vtolftc.runners.mission_run import path_errors, rectangle_mission, run_mission


def _table(title: str, errs: dict[int, dict[str, float]]) -> None:
    print(f"\n{title}\n\n| item (leg to) | samples | cross-track RMS (m) | max (m) |")
    print("|---|---|---|---|")
    for seq, e in sorted(errs.items()):
        print(f"| {seq} | {e['samples']} | {e['rms_m']:.2f} | {e['max_m']:.2f} |")


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--transport", default="udp", choices=("udp", "zenoh", "none"))
    ap.add_argument("--faults", action="store_true", help="case 1's faults in the first leg")
    args = ap.parse_args()
    items = rectangle_mission()
    faults = case_faults(1, load_airframe().actuator_names) if args.faults else None
    r = run_mission(items, faults_at_item=(2, 5.0, faults) if faults else None)
    _table(f"in-process ({'case 1 faults' if faults else 'nominal'})",
           path_errors(items, r.t, r.pos_ned, r.mode, r.seq))
    n, e, _d = r.final_position
    print(f"\nin-process: items reached {[s for _, s in r.reached]}, landed "
          f"{math.hypot(n, e):.2f} m from home, disarmed {r.landed_disarmed}; "
          f"{r.sim_time_s:.1f} s simulated in {r.wall_time_s:.1f} s wall "
          f"({r.sim_time_s / r.wall_time_s:.1f}x real time)")
    if args.transport == "none":
        return
    from vtolftc.runners.mission_sitl import fly_sitl_mission

    with tempfile.TemporaryDirectory() as tmp:
        rec = fly_sitl_mission(Path(tmp), inject_case=1 if faults else None,
                               transport=args.transport)
    pos = np.array(rec["pos"])
    mode = np.where(np.array(rec["fw"]), 4, 0)
    _table(f"SITL lockstep over {args.transport}",
           path_errors(items, np.array(rec["t"]), pos, mode, np.array(rec["seq"])))
    sim = rec["t"][-1] - rec["t"][0]
    print(f"\nSITL ({args.transport}): items reached {rec['reached']}, landed "
          f"{math.hypot(pos[-1][0], pos[-1][1]):.2f} m from home; flight {sim:.1f} s simulated "
          f"in {rec['flight_wall_s']:.1f} s wall ({sim / rec['flight_wall_s']:.1f}x real "
          "time)")


if __name__ == "__main__":
    main()

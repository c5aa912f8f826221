"""SITL benchmark: real-time factor of the 40 s case in lockstep, and the HIL step round trip.

    python benchmarks/bench_sitl.py [--transport udp|zenoh|both] [--duration 40] [--case 1]

For each transport it flies the case with ``vtolftc.runners.sitl.run_sitl`` (vehicle and autopilot
as
separate processes, ground-station commands, no plots) and reports:

- the real-time factor: simulated seconds / wall seconds from the start hold to the end hold
  (process start-up excluded);
- the round trip of one HIL step, measured in the vehicle process: from sending the step's
  HIL_SENSOR + HIL_STATE_QUATERNION datagram to receiving its HIL_ACTUATOR_CONTROLS (median,
  p90, p99), and the part of it spent in the autopilot's control step (step, status and the
  answer), the rest being the two link hops, parsing and the wake-ups;
- the CPU time per step of each process (all its threads), far less sensitive than the wall
  times to what else the machine runs (a heavily loaded machine still inflates it), and the
  load average;
- the per-part breakdown of a step: in the autopilot process ``Autopilot.step``, status +
  HIL_ACTUATOR_CONTROLS, and the work after the answer (metrics, run-folder writer, ground-
  station streams; overlaps with the vehicle); in the vehicle process the truth snapshot +
  physics, sensors + encoding of the next datagram, and its send;

and, for reference, the in-process run of the same scenario (same autopilot, no links).
Target of the issue: >= 20x real time over either transport.
"""

from __future__ import annotations

import argparse
import os
import tempfile
import time
from pathlib import Path

from vtolftc.runners.scenario import paper_scenario, run_scenario
from vtolftc.runners.sitl import SitlConfig, run_sitl


def _in_process_step_cpu_us(scenario: object, controller: str) -> float:
    """Mean CPU time of ``Autopilot.step`` in an in-process flight [us] (thread CPU clock
    read around each call), the yardstick of the SITL process's ``step_cpu_mean_us``."""
    from vtolftc.firmware_sim.autopilot.autopilot import Autopilot

    step = Autopilot.step
    acc = [0.0, 0]

    def timed(self: Autopilot, nav: object) -> object:
        c0 = time.thread_time()
        u = step(self, nav)  # type: ignore[arg-type]
        acc[0] += time.thread_time() - c0
        acc[1] += 1
        return u

    Autopilot.step = timed  # type: ignore[assignment,method-assign]
    try:
        run_scenario(scenario, controller)  # type: ignore[arg-type]
    finally:
        Autopilot.step = step  # type: ignore[method-assign]
    return 1e6 * acc[0] / max(1, acc[1])


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--transport", default="both", choices=("udp", "zenoh", "both"))
    ap.add_argument("--duration", type=float, default=40.0)
    ap.add_argument("--case", default="1")
    ap.add_argument("--controller", default="gs-shif")
    ap.add_argument("--spin-us", type=float, default=0.0,
                    help="busy-poll time of both processes before sleeping (default 0)")
    args = ap.parse_args()
    scenario = paper_scenario(args.case, args.duration)

    t0 = time.perf_counter()
    ref = run_scenario(scenario, args.controller)
    wall = time.perf_counter() - t0
    print(f"in-process: {args.duration:g} s simulated in {wall:.2f} s "
          f"({args.duration / wall:.1f}x real time); autopilot "
          f"{1e6 * ref.timing_s['autopilot'] / (args.duration * 250):.0f} us/step, physics "
          f"{1e6 * ref.timing_s['physics'] / (args.duration * 250):.0f} us/step; "
          f"Autopilot.step CPU {_in_process_step_cpu_us(scenario, args.controller):.0f} us "
          "(mean, a second flight)")

    transports = ("udp", "zenoh") if args.transport == "both" else (args.transport,)
    print("\n| transport | real-time factor | flight wall (s) | HIL step round trip mean / "
          "median / p90 / p99 (us) | in autopilot, mean (us/step) | link + rest, mean "
          "(us/step) |")
    print("|---|---:|---:|---|---:|---:|")
    for tr in transports:
        with tempfile.TemporaryDirectory(prefix=f"bench_sitl_{tr}_") as tmp:
            res = run_sitl(SitlConfig(case=args.case, controller=args.controller, transport=tr,
                                      duration_s=args.duration, out_dir=Path(tmp),
                                      plots=False, spin_us=args.spin_us), scenario)
            rtt = res.vehicle_summary.get("step_round_trip_us", {})
            steps = max(1, res.autopilot_summary.get("steps", 1))
            in_ap = 1e6 * res.autopilot_summary.get("wall_in_autopilot_s", 0.0) / steps
            sw = res.autopilot_summary.get("step_wall_us", {})
            nan = float("nan")
            mean = rtt.get("mean", nan)
            print(f"| {tr} | {res.real_time_factor:.1f}x | {res.flight_wall_s:.2f} | "
                  f"{mean:.0f} / {rtt.get('median', nan):.0f} / {rtt.get('p90', nan):.0f} / "
                  f"{rtt.get('p99', nan):.0f} | {in_ap:.0f} | {mean - in_ap:.0f} |")
            same = {k: (ref.metrics[k], res.metrics.get(k))
                    for k in ("rmse_altitude_m", "rmse_roll_deg")}
            print(f"    autopilot control step in the process: median {sw.get('median', nan):.0f}"
                  f" us, p99 {sw.get('p99', nan):.0f} us, CPU mean "
                  f"{res.autopilot_summary.get('step_cpu_mean_us', nan):.0f} us (step, status, "
                  f"answer); metrics (in-process, SITL): {same}")
            print(f"    CPU per step (every thread): autopilot process "
                  f"{res.autopilot_summary.get('cpu_per_step_us', nan):.0f} us, vehicle "
                  f"process {res.vehicle_summary.get('cpu_per_step_us', nan):.0f} us; load "
                  f"average {os.getloadavg()[0]:.1f} on {os.cpu_count()} cores")
            ap_parts = res.autopilot_summary.get("part_mean_us", {})
            veh_parts = res.vehicle_summary.get("part_mean_us", {})
            step_wall = 1e6 * res.flight_wall_s / steps
            print(f"    per step ({step_wall:.0f} us of wall time each): autopilot process "
                  + ", ".join(f"{k} {x:.0f} us" for k, x in ap_parts.items())
                  + "; vehicle process " + ", ".join(f"{k} {x:.0f} us"
                                                     for k, x in veh_parts.items()))


if __name__ == "__main__":
    main()

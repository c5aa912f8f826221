"""Physics steps per second of the full DS-1 vehicle model (RK4, 1 kHz), on one core.

Run: python benchmarks/bench_vehicle.py [--steps N]

Prints the machine it ran on and three figures: one Python call per physics step (the
worst case of a caller that cannot batch), one call per 250 Hz control period (4 steps, what
the SITL does), and one call for a long batch. Target: >= 50,000 steps/s (20 us a step).
"""

from __future__ import annotations

import argparse
import os
import platform
import time

import numpy as np

from vtolftc.firmware_sim.vehicle.model import Vehicle
from vtolftc.firmware_sim.vehicle.trim import trim_level_flight


def machine() -> str:
    cpu = platform.processor() or "unknown CPU"
    try:
        with open("/proc/cpuinfo") as fh:
            for line in fh:
                if line.startswith("model name"):
                    cpu = line.split(":", 1)[1].strip()
                    break
    except OSError:
        pass
    return (f"{cpu}, {os.cpu_count()} cores, Python {platform.python_version()}, "
            f"{platform.system()} {platform.machine()}")


def rate(v: Vehicle, u: np.ndarray, steps: int, per_call: int) -> float:
    calls = steps // per_call
    t0 = time.perf_counter()
    for _ in range(calls):
        v.step(u, per_call)
    return calls * per_call / (time.perf_counter() - t0)


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--steps", type=int, default=200_000)
    args = ap.parse_args()
    tp = trim_level_flight(None, 13.0, pitch_rad=0.0)  # transition: every actuator working
    v = Vehicle(state=tp.state)
    v.step(tp.commands, 10)  # compile / load the cache before timing
    print(f"machine: {machine()}")
    print(f"model: DS-1, {v.x.size} states, {v.n_actuators} actuators, RK4 at 1 kHz")
    for label, per_call in (("1 step per call", 1), ("4 steps per call (250 Hz control)", 4),
                            ("1000 steps per call", 1000)):
        r = max(rate(v, tp.commands, args.steps, per_call) for _ in range(3))
        print(f"{label:36s} {r:12,.0f} steps/s  ({1e6 / r:6.2f} us/step, "
              f"{r / 50_000:5.1f}x the 50k target)")


if __name__ == "__main__":
    main()

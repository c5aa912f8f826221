"""Physics steps per second of the full DS-1 vehicle model (RK4, 1 kHz), on one core.

Run: python benchmarks/bench_vehicle.py [--steps N]

Prints the machine it ran on and three figures: one Python call per physics step (the
worst case of a caller that cannot batch), one call per 250 Hz control period (4 steps, what
the SITL does), and one call for a long batch. Target: >= 50,000 steps/s (20 us a step).

Session 18, branch phys-18 (2026-12-03, 2 cores shared with two other helpers, load 2.3-4.8).
Profiled with ``perf`` on a replay of a recorded 60 s case-1 flight (14,998 control steps
through ``step_n_flat_memo``, the JIT code's addresses mapped from the engine's symbol table):
65 % of the kernel's samples were two instructions, the atomic increment and decrement in
numba's ``NRT_incref`` / ``NRT_decref``. numba counts a reference to every array argument on
entry to a compiled callee and releases it on exit; its pruning pass leaves them in
``derivatives`` (several branches, mid-function releases), so each of the 16 evaluations per
control step did 16 + 20 atomic operations (~20 cycles each). Built, every flight
bit-identical (same operations in the same order; ``command_digest.py`` unchanged, 150 s
flights of cases 1, 2, 0 and case 1 lqr hashed step by step equal to main's):
``vtolftc.base.nrt.borrowed`` (array views without ``meminfo``: the count functions return at
once) for ``step_n_memo``'s arguments and its stage arrays (one allocation instead of five),
``derivatives`` compiled with ``_nrt=False`` (it allocates nothing: no counting at all), a
rotor at exactly zero skipped (its terms are +-0 and the sums are never -0.0; not when
``eff * tmax`` is not finite), ``lift_drag_coefficients`` inlined (one ``sincos`` a call),
the five airspeed tables read with one search and one division (``table_bracket`` /
``table_at``). Tests: ``tests/test_vehicle_borrowed.py`` (main's ``derivatives``,
``lift_drag_coefficients`` and ``step_n_memo`` kept word for word as the reference).

Measured: the replayed flight, main's kernel and this branch's in one process (thread CPU,
7 interleaved runs, load 3.0): 7.38 -> 4.05 us per control step (x0.55; 7.23 -> 4.37 with the
borrowed views alone, -> 3.97 with ``_nrt=False``), bits equal. This script, main / branch
processes alternated, 6 pairs (load ~3), steps/s medians: 1 step a call 228k -> 360k (pair
ratios 1.25-2.21, median 1.70), 4 steps a call 471k -> 788k (1.19-2.74, median 1.71), 1000
steps a call 635k -> 1,172k (1.46-2.09, median 1.90): the 1000-step figure is ~0.85 us a step.
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

"""Benchmark of the autopilot flown in-process on the paper's cases.

1. The autopilot's allocation during a real case (case 1, gs-shif, 40 s: hover, transition
   with faults, fixed-wing): median and p99 wall time of ``allocate`` per control step, of the
   solver's own solve, its iterations, and the status counts (target: median < 50 us).
2. One 40 s case flown in-process: wall time, real-time factor (target >= 100x on one core)
   and a per-part breakdown: physics (1 kHz RK4, numba), encode/decode of the HIL state,
   autopilot (split into allocation, attitude controller and the rest: modes, outer loops,
   B(V)), observers (metrics; optionally the run-folder writer).

Usage: ``python benchmarks/bench_autopilot.py [--case 1] [--controller gs-shif]
[--gains DIR] [--runs 3] [--with-writer]``
"""

from __future__ import annotations

import argparse
import statistics
import tempfile
import time

import numpy as np

from vtolftc.firmware_sim.autopilot.autopilot import Autopilot
from vtolftc.runners.scenario import paper_scenario, run_scenario
from vtolftc.telemetry.runfolder import RunFolderWriter


class _Timed:
    """Wraps a bound method and records the wall time of every call."""

    def __init__(self, fn):
        self.fn = fn
        self.times: list[float] = []
        self.results: list = []

    def __call__(self, *a, **k):
        t0 = time.perf_counter()
        r = self.fn(*a, **k)
        self.times.append(time.perf_counter() - t0)
        self.results.append(r)
        return r


def _pct(x: list[float], p: float) -> float:
    return float(np.percentile(np.asarray(x), p)) if x else float("nan")


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--case", default="1")
    ap.add_argument("--controller", default="gs-shif")
    ap.add_argument("--gains", default=None)
    ap.add_argument("--duration", type=float, default=40.0)
    ap.add_argument("--runs", type=int, default=3)
    ap.add_argument("--with-writer", action="store_true",
                    help="also time a run with the run-folder writer (CSV + plots)")
    args = ap.parse_args()
    scen = paper_scenario(args.case, args.duration)

    # warm-up (numba compilation, imports, solver setup)
    run_scenario(paper_scenario(args.case, 2.0), args.controller, gains_dir=args.gains)

    timers: dict[str, _Timed] = {}

    def instrument(a: Autopilot) -> None:
        timers["alloc"] = _Timed(a.allocator.allocate)
        a.allocator.allocate = timers["alloc"]  # type: ignore[method-assign]
        timers["ctrl"] = _Timed(a.attitude.update)
        a.attitude.update = timers["ctrl"]  # type: ignore[method-assign]

    res = run_scenario(scen, args.controller, gains_dir=args.gains, autopilot_setup=instrument)
    al = timers["alloc"]
    solve = [r.solve_time_s for r in al.results if r.iterations > 0]
    iters = [r.iterations for r in al.results]
    print(f"## allocation ({type(al.fn.__self__).__name__}), case {args.case}, "
          f"{args.controller}, {args.duration:g} s ({len(al.times)} steps)\n")
    print("| quantity | median | p99 | max |")
    print("|---|---:|---:|---:|")
    for name, xs, unit in (("allocate() wall time", al.times, 1e6),
                           ("solver solve time", solve, 1e6)):
        print(f"| {name} (us) | {_pct(xs, 50) * unit:.1f} | {_pct(xs, 99) * unit:.1f} | "
              f"{max(xs) * unit:.1f} |")
    print(f"| solver iterations | {_pct(iters, 50):.0f} | {_pct(iters, 99):.0f} | {max(iters)} |")
    print(f"\nstatus counts: {res.allocation['counts']}")
    print(f"target median < 50 us: {'met' if _pct(al.times, 50) < 50e-6 else 'NOT met'}\n")

    # full runs without instrumentation (best of N)
    walls = []
    cpus = []
    best = None
    for _ in range(args.runs):
        c0 = time.process_time()
        r = run_scenario(scen, args.controller, gains_dir=args.gains,
                         autopilot_setup=instrument)
        cpus.append(time.process_time() - c0)
        walls.append(r.wall_time_s)
        if best is None or r.wall_time_s < best[0].wall_time_s:
            best = (r, sum(timers["alloc"].times), sum(timers["ctrl"].times))
    assert best is not None
    r, t_alloc, t_ctrl = best
    t = r.timing_s
    print(f"## One {args.duration:g} s case in-process ({args.runs} runs, best shown; "
          f"median wall {statistics.median(walls):.2f} s)\n")
    print(f"wall time {r.wall_time_s:.2f} s for {r.sim_time_s:.1f} s simulated: real-time "
          f"factor {r.real_time_factor:.1f}x (target >= 100x: "
          f"{'met' if r.real_time_factor >= 100 else 'NOT met'})")
    print(f"CPU time (less sensitive to other load on the machine): best {min(cpus):.2f} s, "
          f"real-time factor {r.sim_time_s / min(cpus):.1f}x\n")
    print("| part | wall (s) | share | per control step (us) |")
    print("|---|---:|---:|---:|")
    n = round(r.sim_time_s * 250)
    rest = t["autopilot"] - t_alloc - t_ctrl
    for name, v in (("physics (4 x RK4 @ 1 kHz)", t["physics"]),
                    ("encode/decode HIL state", t["encode_decode"]),
                    ("autopilot: allocation (QP)", t_alloc),
                    ("autopilot: attitude controller", t_ctrl),
                    ("autopilot: modes, outer loops, B(V)", rest),
                    ("observers (metrics)", t["observers"])):
        print(f"| {name} | {v:.3f} | {100 * v / t['total']:.0f} % | {1e6 * v / n:.1f} |")
    other = t["total"] - t["physics"] - t["encode_decode"] - t["autopilot"] - t["observers"]
    print(f"| runner loop (actions, NavState, wire_commands) | {other:.3f} | "
          f"{100 * other / t['total']:.0f} % | {1e6 * other / n:.1f} |")
    print("\n(allocation and controller times include the timing wrapper, ~0.3 us each)")

    if args.with_writer:
        with tempfile.TemporaryDirectory() as d:
            r = run_scenario(scen, args.controller, gains_dir=args.gains,
                             observers=[RunFolderWriter(d)])
            print(f"\nwith the run-folder writer (CSV + plots at the end): wall "
                  f"{r.wall_time_s:.2f} s, real-time factor {r.real_time_factor:.1f}x, "
                  f"observers {r.timing_s['observers']:.2f} s")


if __name__ == "__main__":
    main()

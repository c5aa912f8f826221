"""Memory benchmark: resident memory of the SITL processes over a long flight.

    python benchmarks/bench_memory.py [--minutes 12] [--recorder both|on|off] [--case 0]
                                      [--transport udp] [--realtime]

Flies the SITL (:class:`vtolftc.runners.sitl.SitlRun`: vehicle and autopilot as two processes;
lockstep unless ``--realtime``) for ``--minutes`` of simulated time, once with the autopilot's
rerun recorder on (as every run records ``run.rrd``) and once with it off (the autopilot's
``--no-rerun``), and samples the resident set size (``VmRSS`` of ``/proc/PID/status``) of the
two processes it started every ``--every`` simulated seconds (the simulated time the ground
station sees). After the warm-up (``--skip-minutes`` of simulated time: take-off,
transition, numba, the heap settling) it fits a straight line to each process's RSS against
simulated time and prints the slope in KB per simulated second and its extrapolation to one
hour. Issue 24: < 50 MB per hour for each process, from a slope measured over >= 10 min (the
default 12 minutes with 1.5 of warm-up fit 10.5).

Memory grows per row logged (the recorder logs per simulated second), so the slope per
simulated second of a lockstep flight is that of a real-time flight (``tests/test_memory_sitl.py``
says why, and runs a shorter version of this in CI).

Measured (case 0, gs-shif, UDP, lockstep at 0.8-1.1x real time on the shared 2-core machine
at load 13-21; 12 simulated minutes; RSS fit over the last 10-10.5 simulated minutes):

| recorder | fit over (simulated s) | autopilot | vehicle |
|---|---:|---|---|
| on, before the fix (test_memory_sitl.py) | 90 | 141 KB/s, 495 MB/h | flat (last session) |
| on, after the fix | 629 | 0.30 KB/s, 1.0 MB/h | 0.00 KB/s, 0 MB/h |
| on, after the fix (another run) | 599 | 0.12 KB/s, 0.4 MB/h | 0.00 KB/s, 0 MB/h |
| off (``--no-rerun``) | 600 | 0.00 KB/s, 0 MB/h | 0.00 KB/s, 0 MB/h |

(KB per simulated second; MB per hour extrapolated.) Before the fix the growth was rerun's
footer manifest (an entry per chunk, kept in memory until the file closes) and the whole flown
path re-sent every simulated second; see :mod:`vtolftc.telemetry.recording`.
"""

from __future__ import annotations

import argparse
import tempfile
from pathlib import Path

from vtolftc.runners.memory_probe import fly_sampled, slope_mb_per_h
from vtolftc.runners.sitl import SitlConfig


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--minutes", type=float, default=12.0, help="simulated minutes flown")
    ap.add_argument("--skip-minutes", type=float, default=1.5,
                    help="simulated minutes of warm-up left out of the fit")
    ap.add_argument("--recorder", default="both", choices=("both", "on", "off"),
                    help="the autopilot's rerun recorder")
    ap.add_argument("--case", default="0")
    ap.add_argument("--controller", default="gs-shif")
    ap.add_argument("--transport", default="udp", choices=("udp", "zenoh"))
    ap.add_argument("--realtime", action="store_true")
    ap.add_argument("--every", type=float, default=1.0, help="sampling period, simulated s")
    args = ap.parse_args()
    duration = 60.0 * args.minutes
    if not 0 <= args.skip_minutes < args.minutes:
        raise SystemExit("--skip-minutes must be in [0, --minutes)")
    rows = []
    for rec in (("on", "off") if args.recorder == "both" else (args.recorder,)):
        with tempfile.TemporaryDirectory(prefix="bench_memory_") as tmp:
            cfg = SitlConfig(case=args.case, controller=args.controller,
                             transport=args.transport, realtime=args.realtime,
                             duration_s=duration, out_dir=Path(tmp), plots=False,
                             extra_autopilot_args=[] if rec == "on" else ["--no-rerun"])
            data, res = fly_sampled(cfg, every_sim_s=args.every)
            rtf = res.real_time_factor
        fit = data[data[:, 0] >= 60.0 * args.skip_minutes]
        if len(fit) < 10:
            raise SystemExit(f"only {len(fit)} samples after the warm-up: fly longer")
        span = fit[-1, 0] - fit[0, 0]
        print(f"recorder {rec}: {duration:g} s simulated "
              f"({'real time' if args.realtime else 'lockstep'}, {args.transport}), "
              f"{rtf:.1f}x real time, {len(data)} samples; fit over {len(fit)} samples, "
              f"{span:.0f} simulated s{'' if span >= 600 else ' (< 10 min)'}", flush=True)
        for j, label in ((1, "autopilot"), (2, "vehicle")):
            slope = slope_mb_per_h(fit[:, 0], fit[:, j], from_s=fit[0, 0]) * 1024 / 3600
            rows.append(f"| {rec} | {label} | {fit[0, j] / 1024:.1f} | {fit[-1, j] / 1024:.1f} "
                        f"| {slope:.2f} | {slope * 3600 / 1024:.1f} |")
    print("| recorder | process | RSS at start of fit (MB) | RSS at end (MB) "
          "| slope (KB per simulated s) | extrapolated growth per hour (MB) |")
    print("|---|---|---:|---:|---:|---:|")
    print("\n".join(rows))


if __name__ == "__main__":
    main()

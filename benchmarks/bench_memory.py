"""Memory benchmark: resident memory of the SITL processes over a long flight.

    python benchmarks/bench_memory.py [--duration 600] [--case 0] [--transport udp] [--realtime]

Flies ``vtolftc.runners.sitl.run_sitl`` (vehicle and autopilot as two processes; lockstep unless
``--realtime``) and samples the resident set size (``VmRSS`` of ``/proc/PID/status``) of each
child process every ``--every`` wall seconds. After the warm-up (the first ``--skip`` fraction
of the flight, when numba, the ground-station streams and the heap settle) it fits a straight
line to each process's RSS against *simulated* time and prints the slope in KB per simulated
second and its extrapolation to one hour. Target of issue 24: < 50 MB per hour for each process.

The simulated time of a sample is interpolated from the flight's wall time (lockstep runs at a
steady rate once started), so the slope is per simulated second in either mode.
"""

from __future__ import annotations

import argparse
import os
import tempfile
import threading
import time
from pathlib import Path

import numpy as np

from vtolftc.runners.scenario import paper_scenario
from vtolftc.runners.sitl import SitlConfig, run_sitl


def _children(root: int) -> dict[int, str]:
    """Descendant processes of ``root``: pid -> a short label from the command line."""
    parent: dict[int, int] = {}
    for d in os.listdir("/proc"):
        if not d.isdigit():
            continue
        try:
            with open(f"/proc/{d}/stat", encoding="ascii", errors="replace") as f:
                stat = f.read()
        except OSError:
            continue
        parent[int(d)] = int(stat.rsplit(")", 1)[1].split()[1])
    out: dict[int, str] = {}
    frontier = [root]
    while frontier:
        p = frontier.pop()
        for c, pp in parent.items():
            if pp == p and c not in out:
                try:
                    with open(f"/proc/{c}/cmdline", "rb") as f:
                        cmd = f.read().replace(b"\0", b" ").decode(errors="replace")
                except OSError:
                    continue
                label = ("autopilot" if "processes.autopilot" in cmd else
                         "vehicle" if "processes.vehicle" in cmd else cmd[:40])
                out[c] = label
                frontier.append(c)
    return out


def _rss_kb(pid: int) -> float | None:
    try:
        with open(f"/proc/{pid}/status", encoding="ascii") as f:
            for line in f:
                if line.startswith("VmRSS:"):
                    return float(line.split()[1])
    except OSError:
        return None
    return None


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--duration", type=float, default=600.0, help="simulated seconds")
    ap.add_argument("--case", default="0")
    ap.add_argument("--controller", default="gs-shif")
    ap.add_argument("--transport", default="udp", choices=("udp", "zenoh"))
    ap.add_argument("--realtime", action="store_true")
    ap.add_argument("--every", type=float, default=1.0, help="sampling period, wall s")
    ap.add_argument("--skip", type=float, default=0.2,
                    help="fraction of the samples left out of the fit (warm-up)")
    args = ap.parse_args()

    samples: list[tuple[float, dict[str, float]]] = []
    done = threading.Event()

    def sampler() -> None:
        while not done.wait(args.every):
            kids = _children(os.getpid())
            row = {}
            for pid, label in kids.items():
                if label in ("autopilot", "vehicle"):
                    kb = _rss_kb(pid)
                    if kb is not None:
                        row[label] = kb
            if len(row) == 2:
                samples.append((time.monotonic(), row))

    th = threading.Thread(target=sampler, daemon=True)
    scenario = paper_scenario(args.case, args.duration)
    with tempfile.TemporaryDirectory(prefix="bench_memory_") as tmp:
        th.start()
        res = run_sitl(SitlConfig(case=args.case, controller=args.controller,
                                  transport=args.transport, realtime=args.realtime,
                                  duration_s=args.duration, out_dir=Path(tmp), plots=False),
                       scenario)
        done.set()
        th.join()
    if len(samples) < 10:
        raise SystemExit(f"only {len(samples)} samples: fly longer (--duration)")
    t = np.array([s[0] for s in samples])
    t_sim = (t - t[0]) / (t[-1] - t[0]) * args.duration  # steady lockstep / real-time rate
    k0 = int(args.skip * len(samples))
    print(f"{args.duration:g} s simulated ({'real time' if args.realtime else 'lockstep'}, "
          f"{args.transport}), {res.real_time_factor:.1f}x real time, {len(samples)} samples "
          f"every {args.every:g} s; fit over the last {len(samples) - k0} samples "
          f"({t_sim[-1] - t_sim[k0]:.0f} simulated s)")
    print("| process | RSS at start of fit (MB) | RSS at end (MB) | slope (KB per simulated s) "
          "| extrapolated growth per hour (MB) |")
    print("|---|---:|---:|---:|---:|")
    for label in ("autopilot", "vehicle"):
        rss = np.array([s[1][label] for s in samples])
        slope = float(np.polyfit(t_sim[k0:], rss[k0:], 1)[0])
        print(f"| {label} | {rss[k0] / 1024:.1f} | {rss[-1] / 1024:.1f} | {slope:.1f} | "
              f"{slope * 3600 / 1024:.1f} |")


if __name__ == "__main__":
    main()

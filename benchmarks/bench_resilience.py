"""Benchmark of the SITL autopilot under a ground-station flood, and its lockstep speed.

    python benchmarks/bench_resilience.py [--part flood|rtf|both] [--rtf-runs 2]

``flood``: the processes in real time (UDP), armed and hovering at 5 m; 5 s without traffic,
then 5 s of 10,000 invalid PARAM_SET and COMMAND_LONG (2,000 frames/s from four made-up
clients) on a listening ground-station port. Reported for both windows, from the autopilot's
``telemetry.csv`` (one row per control step, simulated time = wall time in real time): the
control-step period p50 / p99 / max, the fraction of the vehicle's 250 Hz steps the autopilot
answered, the largest attitude error to its reference and the largest altitude error.

``rtf``: the real-time factor of the 40 s case 1 in lockstep (``run_sitl``), the figure of
``bench_sitl.py``.

Only APIs that the project had before the isolation work are used, so the same script measures
an older checkout too (put it first on ``PYTHONPATH``) for a before/after comparison.
"""

from __future__ import annotations

import argparse
import csv
import socket
import statistics
import tempfile
import time
from pathlib import Path

import numpy as np

from vtolftc.protocols import make_codec
from vtolftc.protocols.netutil import free_udp_port
from vtolftc.runners.sitl import SitlConfig, SitlRun, run_sitl


def _frames(n: int) -> list[bytes]:
    out = []
    codecs = [make_codec(s, 1) for s in (200, 201, 202, 203)]
    for k in range(n):
        c = codecs[k % 4]
        kind = k % 4
        if kind == 0:
            msg = c.param_set_encode(1, 1, f"NOPE_{k % 97}".encode(), 1.0, 9)
        elif kind == 1:
            msg = c.param_set_encode(1, 1, b"MIS_TAKEOFF_ALT", 1e9, 9)
        elif kind == 2:
            msg = c.command_long_encode(1, 1, 31010 + k % 7, 0, 1, 2, 3, 4, 5, 6, 7)
        else:
            msg = c.command_long_encode(1, 1, 400, 0, 7.0, 0, 0, 0, 0, 0, 0)
        out.append(msg.pack(c))
        c.seq = (c.seq + 1) & 0xFF
    return out


def _window(path: Path, t0: float, t1: float) -> dict[str, float]:
    rows = []
    with path.open(newline="") as f:
        for r in csv.DictReader(f):
            try:
                t = float(r["time_s"])
            except (TypeError, ValueError):
                continue
            if t0 <= t < t1:
                rows.append((t, abs(float(r["roll_deg"]) - float(r["roll_ref_deg"])),
                             abs(float(r["pitch_deg"]) - float(r["pitch_ref_deg"])),
                             abs(float(r["altitude_m"]) - float(r["altitude_ref_m"]))))
    a = np.array(rows)
    dt = np.diff(a[:, 0]) * 1e3
    return {"p50_ms": float(np.median(dt)), "p99_ms": float(np.percentile(dt, 99)),
            "max_ms": float(dt.max()), "steps": len(rows) / ((t1 - t0) / 0.004),
            "att_deg": float(max(a[:, 1].max(), a[:, 2].max())), "alt_m": float(a[:, 3].max())}


def flood() -> None:
    flood_port = free_udp_port()
    with tempfile.TemporaryDirectory(prefix="bench_resilience_") as tmp:
        cfg = SitlConfig(out_dir=Path(tmp), realtime=True, plots=False,
                         failure_injection=False,
                         extra_autopilot_args=["--gcs-link",
                                               f"udp-server://127.0.0.1:{flood_port}"])
        with SitlRun(cfg) as run:
            run.start()
            gs = run.gs
            gs.wait_for(lambda s: s.connected and s.landed_state == 1, 60.0)
            gs.arm()
            gs.takeoff(5.0)
            gs.wait_for(lambda s: s.mode_name == "AUTO.LOITER" and s.altitude_m > 4.5, 60.0)
            time.sleep(3.0)
            t0 = gs.snapshot().sim_time_s
            time.sleep(5.0)
            t1 = gs.snapshot().sim_time_s
            frames = _frames(10_000)
            sock = socket.socket(socket.AF_INET, socket.SOCK_DGRAM)
            w0 = time.monotonic()
            for i in range(0, len(frames), 20):
                for f in frames[i:i + 20]:
                    sock.sendto(f, ("127.0.0.1", flood_port))
                time.sleep(max(0.0, w0 + (i + 20) / 2000.0 - time.monotonic()))
            t2 = gs.snapshot().sim_time_s
            sock.close()
            time.sleep(2.0)
            ack = gs.command_long(31010, [1.0])
            path = Path(tmp) / "autopilot" / "telemetry.csv"
            idle, fl = _window(path, t0, t1), _window(path, t1 + 0.05, t2)
    print("| window | step period p50 (ms) | p99 (ms) | max (ms) | steps answered | "
          "max attitude error (deg) | max altitude error (m) |")
    print("|---|---:|---:|---:|---:|---:|---:|")
    for name, w in (("idle", idle), ("flood 2000/s", fl)):
        print(f"| {name} | {w['p50_ms']:.2f} | {w['p99_ms']:.2f} | {w['max_ms']:.1f} | "
              f"{100 * w['steps']:.1f} % | {w['att_deg']:.2f} | {w['alt_m']:.3f} |")
    print(f"a command right after the flood: {ack.result_name} in {ack.elapsed_s * 1e3:.0f} ms")


def rtf(runs: int) -> None:
    vals = []
    for _ in range(runs):
        with tempfile.TemporaryDirectory(prefix="bench_resilience_rtf_") as tmp:
            res = run_sitl(SitlConfig(case="1", out_dir=Path(tmp), plots=False))
            vals.append(res.real_time_factor)
    print(f"lockstep case 1, 40 s: real-time factor {statistics.median(vals):.1f}x "
          f"(runs: {', '.join(f'{v:.1f}' for v in vals)})")


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--part", default="both", choices=("flood", "rtf", "both"))
    ap.add_argument("--rtf-runs", type=int, default=2)
    args = ap.parse_args()
    if args.part in ("flood", "both"):
        flood()
    if args.part in ("rtf", "both"):
        rtf(args.rtf_runs)


if __name__ == "__main__":
    main()

"""Latency margin of the hover in SITL: injected one-way delay of the controls on the HIL link.

    python benchmarks/bench_latency.py [--delays-ms 0,10,20,30] [--hover-s 10]

For each delay, the processes run in lockstep (so the figures do not depend on the machine's
load: the delay is one of simulated time, applied by the vehicle, see
``vtolftc.runners.sitl.SitlConfig.hil_delay_ms``); the aircraft takes off to 10 m, hovers
2 s, then rotor_1a loses 30 % of its thrust (a step disturbance: without one a perfect hover
is an equilibrium that no delay disturbs) and the largest |roll|, |pitch| and altitude error
of the next ``--hover-s`` seconds (from the autopilot's telemetry) are printed; "reached hover" no
means the take-off never settled into AUTO.LOITER (the whole flight is then shown). A growing
oscillation means the delay is beyond the margin.
"""

from __future__ import annotations

import argparse
import csv
import tempfile
import time
from pathlib import Path

from vtolftc.runners.sitl import SitlConfig, SitlRun


def hover(delay_ms: float, hover_s: float) -> dict[str, float]:
    with tempfile.TemporaryDirectory(prefix="bench_latency_") as tmp:
        cfg = SitlConfig(out_dir=Path(tmp), plots=False, failure_injection=True,
                         hold_at_start=False, hil_delay_ms=delay_ms)
        with SitlRun(cfg) as run:
            run.start()
            gs = run.gs
            gs.wait_for(lambda s: s.connected and s.landed_state == 1, 60.0)
            gs.arm()
            gs.takeoff(10.0)
            try:
                snap = gs.wait_for(lambda s: s.mode_name == "AUTO.LOITER", 120.0)
                t0 = snap.sim_time_s + 2.0
                gs.wait_for(lambda s: s.sim_time_s > t0, 120.0)
                gs.inject("rotor_1a", loss=0.3)  # the disturbance: a step in roll and pitch
                gs.wait_for(lambda s: s.sim_time_s > t0 + hover_s + 1.5, 600.0)
                ok = True
            except Exception:
                t0, ok = 0.0, False
            time.sleep(0.2)
            rows = []
            with (Path(tmp) / "autopilot" / "telemetry.csv").open(newline="") as f:
                for r in csv.DictReader(f):
                    try:
                        t = float(r["time_s"])
                    except (TypeError, ValueError):
                        continue
                    if (t0 <= t < t0 + hover_s) if ok else t > 1.0:
                        rows.append(r)
    if not rows:
        return {"ok": 0.0}
    return {"ok": float(ok),
            "roll": max(abs(float(r["roll_deg"])) for r in rows),
            "pitch": max(abs(float(r["pitch_deg"])) for r in rows),
            "alt": max(abs(float(r["altitude_m"]) - float(r["altitude_ref_m"])) for r in rows)}


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--delays-ms", default="0,10,20,30")
    ap.add_argument("--hover-s", type=float, default=10.0)
    args = ap.parse_args()
    print("| one-way delay (ms) | reached hover | max abs roll (deg) | max abs pitch (deg) | "
          "max altitude error (m) |")
    print("|---:|---|---:|---:|---:|")
    for d in (float(x) for x in args.delays_ms.split(",")):
        r = hover(d, args.hover_s)
        if "roll" not in r:
            print(f"| {d:g} | no | - | - | - |")
            continue
        print(f"| {d:g} | {'yes' if r['ok'] else 'no'} | {r['roll']:.2f} | {r['pitch']:.2f} | "
              f"{r['alt']:.3f} |")


if __name__ == "__main__":
    main()

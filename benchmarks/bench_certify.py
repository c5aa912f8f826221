"""The full ``vtolftc certify`` of DS-1 and where the time goes (target < 10 min on 2 cores).

    python benchmarks/bench_certify.py [--out DIR] [--profile full|quick] [--jobs N]

Runs the real command (trim, robust synthesis, mixed-mu certificate, the envelope campaign of
the synthesised GS-SHIF, the SITL mission) into a fresh folder (default: a temporary one),
then prints the wall time of every stage, the synthesis' own stage times, the campaign's
scenario rate and the SITL flight's wall time, and the gates' verdict. A benchmark, not a test:
the numbers depend on the machine and its load (``uptime`` is printed with them).
"""

from __future__ import annotations

import argparse
import json
import os
import sys
import tempfile
import time
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]
TARGET_S = 600.0


def main() -> int:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("--out", type=Path, default=None, help="output folder (default: temporary)")
    ap.add_argument("--profile", choices=("full", "quick"), default="full")
    ap.add_argument("--jobs", type=int, default=None, help="campaign processes (default: cores)")
    ap.add_argument("--airframe", type=Path, default=ROOT / "airframe" / "ds1.toml")
    args = ap.parse_args()
    from vtolftc.cmd_certify import run_certify

    tmp = None
    out = args.out
    if out is None:
        tmp = tempfile.TemporaryDirectory(prefix="bench-certify-")
        out = Path(tmp.name) / "certify"
    print(f"load before: {os.getloadavg()[0]:.1f} (1 min), {os.cpu_count()} cores", flush=True)
    t0 = time.perf_counter()
    rc = run_certify(args.airframe, out, profile=args.profile, jobs=args.jobs)
    total = time.perf_counter() - t0
    recs = {p.stem: json.loads(p.read_text())["record"] for p in (out / "stages").glob("*.json")}
    print(f"\nwhere the time goes ({args.profile} profile, {args.airframe.name}):")
    for name in ("trim", "synth", "certificate", "campaign", "sitl"):
        r = recs.get(name)
        if r is None:
            print(f"  {name:<12s} (not finished)")
            continue
        extra = ""
        if name == "campaign":
            n = r.get("scenarios", 0)
            extra = f"  {n} scenarios, {60.0 * n / r['wall_s']:.1f} scenarios/min"
        elif name == "sitl":
            extra = f"  mission flight {r.get('flight_wall_s') or 0:.1f} s wall"
        elif name == "certificate":
            extra = f"  {len(r.get('rows', []))} axis-points"
        print(f"  {name:<12s} {r['wall_s']:8.1f} s{extra}")
        if name == "synth":
            for k, v in r.get("times_s", {}).items():
                print(f"      {k:<34s} {v:7.1f} s")
    print(f"  {'total':<12s} {total:8.1f} s (target < {TARGET_S:.0f} s: "
          f"{'met' if total < TARGET_S else 'NOT met'}); exit status {rc}")
    print(f"load after: {os.getloadavg()[0]:.1f} (1 min)")
    if tmp is not None:
        tmp.cleanup()
    return 0


if __name__ == "__main__":
    sys.exit(main())

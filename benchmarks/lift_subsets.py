"""k lift rotors off at one moment of DS-1's transition: oracle-recoverable subsets and survival.

Judges every k-subset of the lift rotors switched off at ``--at`` seconds with the
recoverability oracle, flies the recoverable ones (or ``--all``) on the paper's timeline with
one controller and prints one JSON line per flight and the counts::

    python benchmarks/lift_subsets.py [--k 4] [--at 22] [--duration 40]
        [--controller gs-shif] [--jobs 2] [--all]
"""

from __future__ import annotations

import argparse
import json
import time

from vtolftc.runners.campaign.lift_subsets import fly_subsets, lift_subsets, recoverable_subsets


def main() -> None:
    """Parse the arguments, judge, fly and print."""
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--k", type=int, default=4)
    ap.add_argument("--at", type=float, default=22.0, help="fault time, s")
    ap.add_argument("--duration", type=float, default=40.0, help="flight length, s")
    ap.add_argument("--controller", default="gs-shif")
    ap.add_argument("--jobs", type=int, default=2)
    ap.add_argument("--all", action="store_true", help="fly every subset, not only the "
                    "recoverable ones")
    a = ap.parse_args()
    t0 = time.perf_counter()
    subsets = lift_subsets(a.k)
    rec = recoverable_subsets(subsets, a.at)
    print(f"{len(subsets)} subsets, {len(rec)} recoverable at t = {a.at:g} s", flush=True)
    rows = fly_subsets(subsets if a.all else list(rec), a.at, a.duration, a.controller,
                       a.jobs)
    for r in rows:
        r["recoverable"] = r["rotors"] in rec
        print(json.dumps(r), flush=True)
    n = sum(r["outcome"] == "survived" for r in rows)
    nr = sum(r["outcome"] == "survived" for r in rows if r["recoverable"])
    print(f"{a.controller}: survived {n}/{len(rows)}; recoverable survived {nr}/{len(rec)}; "
          f"{time.perf_counter() - t0:.0f} s")


if __name__ == "__main__":
    main()

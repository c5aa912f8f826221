"""Which sets of lift rotors off the aircraft can physically recover from, per phase.

    python docs/campaigns/recoverability.py [--airframe FILE] [--k 1 2 4] [--wind N,E,D]
        [--steady N,E,D]

The physical recoverability oracle (``vtolftc.firmware_sim.vehicle.recoverability``) for
every k-subset of the lift rotors switched off, at the campaign's hover (15 s) and
mid-transition (23 s) conditions, read from the same reference flight as ``vtolftc
campaign`` (``vtolftc.runners.campaign.oracle``, its rules), calm unless ``--wind`` (a gust's peak,
NED m/s, felt in every phase) or ``--steady`` (a steady wind, NED m/s, felt only in hover, where
the position is held; with ``--wind`` the hover is judged at the steady wind and at the steady
wind plus the peak, the campaign's rule: ``--steady 0,4,0 --wind 0,3,-1`` is the envelope's
crosswind with its gust).
Prints, per phase and k, how many subsets are recoverable (margin >= 0.001 rad/s^2) and the
lowest margins.
"""

from __future__ import annotations

import argparse
import itertools
import sys

from vtolftc.airframe.loader import AirframeError, load_airframe
from vtolftc.runners.campaign.oracle import judge, reference_conditions

PHASES = (("hover", 15.0), ("mid-transition", 23.0))


def main(argv: list[str] | None = None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--airframe", default=None, help="airframe TOML (default: DS-1)")
    ap.add_argument("--k", type=int, nargs="+", default=[1, 2, 4],
                    help="numbers of rotors off at once (default 1 2 4)")
    ap.add_argument("--wind", default="0,0,0", help="a gust's peak N,E,D (m/s)")
    ap.add_argument("--steady", default="0,0,0", help="steady wind N,E,D (m/s), hover only")
    ap.add_argument("--show", type=int, default=6, help="lowest margins shown per row")
    a = ap.parse_args(argv)
    winds = []
    for opt, text in (("--wind", a.wind), ("--steady", a.steady)):
        try:
            w = tuple(float(v) for v in text.split(","))
            if len(w) != 3:
                raise ValueError
        except ValueError:
            print(f"recoverability: {opt} {text!r}: expected three numbers N,E,D (m/s)",
                  file=sys.stderr)
            return 2
        winds.append(w)
    wind, steady = winds
    try:
        af = load_airframe(a.airframe)
    except AirframeError as exc:
        print(exc, file=sys.stderr)
        return 2
    lift = [f"rotor_{r.name}" for r in af.lift_rotors]
    if any(not 0 < k <= len(lift) for k in a.k):
        print(f"recoverability: --k must be between 1 and {len(lift)}, got {a.k}",
              file=sys.stderr)
        return 2
    conds = reference_conditions([t for _, t in PHASES], a.airframe)
    models: dict = {}
    print("| phase | condition | rotors off | recoverable | lowest margins (rad/s^2) |")
    print("|---|---|---:|---:|---|")
    for phase, t in PHASES:
        pc = conds.get(t)
        if pc is None:
            print(f"| {phase} | not reached by the reference flight | | | |")
            continue
        where = f"{pc.mode}, {pc.speed_m_s:.2f} m/s, pitch {pc.pitch_rad * 57.29578:.1f} deg"
        for k in a.k:
            res = []
            for off in itertools.combinations(lift, k):
                r = judge(af, [(n, "off", 1.0) for n in off], pc, steady,
                          [wind], model_cache=models)
                res.append((r.margin, r.recoverable, "+".join(n[6:] for n in off)))
            res.sort()
            low = ", ".join(f"{lab} {m:.3f}" for m, _, lab in res[:a.show])
            print(f"| {phase} | {where} | {k} | {sum(x[1] for x in res)}/{len(res)} | "
                  f"{low} |")
    return 0


if __name__ == "__main__":
    sys.exit(main())

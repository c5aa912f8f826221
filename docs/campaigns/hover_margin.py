"""What the eight-rotor aircraft can physically hold in hover with lift rotors off.

    python docs/campaigns/hover_margin.py [--airframe FILE] [--k 2]

For every set of ``k`` lift rotors switched off, the largest total thrust the remaining
rotors can give with zero roll and pitch moment (and, in the second column, zero yaw
reaction torque as well) is found by a linear program over the rotor thrusts
(0 <= T_i <= T_max, T_i = 0 for the dead ones), and printed as a multiple of the weight.
Below 1 the aircraft cannot hover at all; just above 1 it can only with an allocation that
knows which rotors are dead and puts every live rotor at its optimum. The autopilot's
allocation is passive (nominal effectiveness, the dead rotors still in ``B``), so it reaches
less than this bound. Hover: no airspeed, so the surfaces give nothing and the pushers no
moment.
"""

from __future__ import annotations

import argparse
import itertools
import sys

import numpy as np
from scipy.optimize import linprog

from vtolftc.airframe.loader import load_airframe


def hover_thrust_margin(af: object, off: tuple[int, ...], yaw: bool) -> float:
    """Largest moment-balanced total lift-rotor thrust over the weight (dimensionless)."""
    rotors = af.lift_rotors  # type: ignore[attr-defined]
    x = np.array([float(r.position_m[0]) for r in rotors])
    y = np.array([float(r.position_m[1]) for r in rotors])
    k = np.array([r.torque_to_thrust_m * float(r.spin_axis[2]) for r in rotors])
    ub = np.array([r.max_thrust_N for r in rotors], float)
    ub[list(off)] = 0.0
    rows = [y, x] + ([k] if yaw else [])
    res = linprog(-np.ones(len(rotors)), A_eq=np.array(rows), b_eq=np.zeros(len(rows)),
                  bounds=list(zip(np.zeros(len(rotors)), ub, strict=True)), method="highs")
    if not res.success:
        return 0.0
    return float(-res.fun / af.weight_N)  # type: ignore[attr-defined]


def main(argv: list[str] | None = None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--airframe", default=None, help="airframe TOML (default: DS-1)")
    ap.add_argument("--k", type=int, default=2, help="rotors off at once (default 2)")
    a = ap.parse_args(argv)
    af = load_airframe(a.airframe)
    n = len(af.lift_rotors)
    if not 0 <= a.k < n:
        print(f"hover_margin: --k must be between 0 and {n - 1}, got {a.k}", file=sys.stderr)
        return 2
    names = [r.name for r in af.lift_rotors]
    rows = []
    for off in itertools.combinations(range(n), a.k):
        rows.append((hover_thrust_margin(af, off, False), hover_thrust_margin(af, off, True),
                     "+".join(names[i] for i in off) or "none"))
    print("| rotors off | max thrust / weight, roll+pitch balanced | ... and yaw balanced |")
    print("|---|---:|---:|")
    for rp, rpy, label in sorted(rows):
        rp, rpy = max(rp, 0.0), max(rpy, 0.0)  # no "-0.000"
        print(f"| {label} | {rp:.3f} | {rpy:.3f} |")
    return 0


if __name__ == "__main__":
    sys.exit(main())

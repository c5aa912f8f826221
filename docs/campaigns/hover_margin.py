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

from vtolftc.airframe.loader import load_airframe
from vtolftc.firmware_sim.vehicle.recoverability import (
    FlightCondition,
    thrust_reserve,
    wrench_model,
)


def hover_thrust_margin(af: object, off: tuple[int, ...], yaw: bool) -> float:
    """Largest moment-balanced total lift-rotor thrust over the weight (dimensionless).

    The one home of this LP is :func:`vtolftc.firmware_sim.vehicle.recoverability.
    thrust_reserve`: hover (no airspeed), only the lift rotors move, ``off`` (lift-rotor
    indices) switched off, roll and pitch (and with ``yaw`` the yaw) moments held at zero.
    """
    model = wrench_model(af, FlightCondition("hover", 0.0))  # type: ignore[arg-type]
    lift = [f"rotor_{r.name}" for r in af.lift_rotors]  # type: ignore[attr-defined]
    return thrust_reserve(model, [(lift[i], "off", 1.0) for i in off],
                          balanced=("L", "M", "N") if yaw else ("L", "M"), use=lift)


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

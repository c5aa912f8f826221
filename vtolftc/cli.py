"""``vtolftc`` command line.

Every command reports bad input (a broken airframe file, an impossible trim, a malformed fault)
as one clear line on stderr and exit status 2, never a traceback; Ctrl-C exits with 130.
"""

from __future__ import annotations

import argparse
import importlib
import json
import math
import sys
from collections.abc import Callable, Sequence
from pathlib import Path

from vtolftc.airframe.loader import AirframeError, load_airframe
from vtolftc.errors import UsageError
from vtolftc.firmware_sim.vehicle.faults import FaultError

# Each of these modules defines ``register(subparsers)``, adding its sub-command(s) with
# ``set_defaults(func=...)``; the functions raise UsageError / RuntimeError as described above.
# Modules are imported when the parser is built, so keep their top-level imports light.
_COMMAND_MODULES: tuple[str, ...] = (
    "vtolftc.cmd_campaign",
    "vtolftc.cmd_dashboard",
    "vtolftc.cmd_fly",
    "vtolftc.cmd_gcs",
    "vtolftc.cmd_sitl",
    "vtolftc.cmd_synth",
)


def _fmt(v: float, nd: int = 2) -> str:
    return f"{v:.{nd}f}"


def _airspeeds(text: str) -> list[float]:
    """``--airspeeds`` as a list of airspeeds [m/s]: comma-separated numbers in [0, 60].

    Raises
    ------
    UsageError
        an empty list or item, an item that is not a number, or one outside [0, 60] m/s.
    """
    items = [s.strip() for s in text.split(",")]
    if not any(items):
        raise UsageError("--airspeeds: expected comma-separated airspeeds in m/s, e.g. 0,13,18")
    speeds = []
    for item in items:
        try:
            s = float(item)
        except ValueError:
            raise UsageError(f"--airspeeds: {item!r} is not a number (expected comma-separated "
                             "airspeeds in m/s, e.g. 0,13,18)") from None
        if not (math.isfinite(s) and 0.0 <= s <= 60.0):
            raise UsageError(f"--airspeeds: {item!r} is not an airspeed in [0, 60] m/s")
        speeds.append(s)
    return speeds


def cmd_trim(args: argparse.Namespace) -> int:
    """Trim table of the airframe at the paper's airspeeds (hover, transition, cruise)."""
    from vtolftc.firmware_sim.vehicle.flyable import check_flyable
    from vtolftc.firmware_sim.vehicle.trim import trim_table

    af = load_airframe(args.airframe)
    check_flyable(af)
    speeds = _airspeeds(args.airspeeds) if args.airspeeds is not None else [
        0.0, 4.0, 7.0, 10.0, 13.0, 18.0]
    if not (math.isfinite(args.altitude) and -500.0 <= args.altitude <= 20_000.0):
        raise UsageError(f"--altitude: {args.altitude!r} is not an altitude in "
                         "[-500, 20000] m")
    if not (math.isfinite(args.transition_pitch_deg)
            and abs(args.transition_pitch_deg) <= 45.0):
        raise UsageError(f"--transition-pitch-deg: {args.transition_pitch_deg!r} is not a "
                         "pitch in [-45, 45] deg")
    rows = trim_table(af, speeds, altitude_m=args.altitude,
                      transition_pitch_rad=math.radians(args.transition_pitch_deg))
    if args.json:
        out = []
        for V, mode, tp, note in rows:
            rec: dict[str, object] = {"airspeed_m_s": V, "mode": mode, "feasible": tp is not None}
            if tp is None:
                rec["note"] = note
            else:
                rec.update(
                    pitch_deg=math.degrees(tp.pitch_rad), alpha_deg=math.degrees(tp.alpha_rad),
                    elevator_deg=math.degrees(tp.elevator_rad),
                    pusher_thrust_fraction=tp.pusher_thrust_fraction,
                    lift_rotor_fractions=dict(zip(
                        [r.name for r in af.lift_rotors], tp.lift_rotor_fractions.tolist(),
                        strict=True)),
                    rotor_lift_share=tp.rotor_lift_share, lift_coefficient=tp.lift_coefficient,
                    residual=tp.residual)
            out.append(rec)
        print(json.dumps({"airframe": af.name, "sha256": af.sha256, "trims": out}, indent=2))
        return 0
    lim = math.degrees(af.surfaces.max_deflection_rad)
    print(f"Trim of {af.name} ({af.source}) at {args.altitude:g} m, no wind.")
    print(f"Stall speed (wing alone at CL_max {af.wing.CL_max:g}): "
          f"{af.stall_speed_m_s():.2f} m/s; surface limits +-{lim:g} deg.\n")
    print("| V (m/s) | mode | pitch (deg) | alpha (deg) | elevator (deg) | pusher (%) "
          "| lift rotors front/rear (%) | rotor lift share (%) | CL |")
    print("|---:|---|---:|---:|---:|---:|---:|---:|---:|")
    for V, mode, tp, note in rows:
        if tp is None:
            print(f"| {V:g} | {mode} | — | — | — | — | — | — | {note} |")
            continue
        fr = tp.lift_rotor_fractions
        front = [f for f, r in zip(fr, af.lift_rotors, strict=True) if r.position_m[0] > 0]
        rear = [f for f, r in zip(fr, af.lift_rotors, strict=True) if r.position_m[0] <= 0]
        fr_txt = f"{100 * sum(front) / len(front):.1f} / {100 * sum(rear) / len(rear):.1f}"
        print(f"| {V:g} | {mode} | {_fmt(math.degrees(tp.pitch_rad))} | "
              f"{_fmt(math.degrees(tp.alpha_rad))} | {_fmt(math.degrees(tp.elevator_rad))} | "
              f"{100 * tp.pusher_thrust_fraction:.1f} | {fr_txt} | "
              f"{100 * tp.rotor_lift_share:.1f} | {tp.lift_coefficient:.3f} |")
    return 0


def build_parser() -> argparse.ArgumentParser:
    """The ``vtolftc`` argument parser with all subcommands."""
    ap = argparse.ArgumentParser(
        prog="vtolftc",
        description="Passive fault-tolerant control of a dual-system VTOL UAV: synthesis, "
                    "simulation, SITL over MAVLink.")
    sub = ap.add_subparsers(dest="command", required=True, metavar="COMMAND")

    p = sub.add_parser("trim", help="trim table (hover, transition, cruise) of an airframe",
                       description=cmd_trim.__doc__)
    p.add_argument("--airframe", type=Path, default=None,
                   help="airframe TOML file (default: the shipped DS-1)")
    p.add_argument("--airspeeds", default=None,
                   help="comma-separated airspeeds in m/s (default 0,4,7,10,13,18)")
    p.add_argument("--altitude", type=float, default=30.0, help="altitude in m (default 30)")
    p.add_argument("--transition-pitch-deg", type=float, default=0.0,
                   help="pitch held by the rotor-assisted transition trims (default 0 deg)")
    p.add_argument("--json", action="store_true", help="print JSON instead of a table")
    p.set_defaults(func=cmd_trim)
    for module in _COMMAND_MODULES:
        importlib.import_module(module).register(sub)
    return ap


def run(argv: Sequence[str] | None, handler: Callable[[argparse.Namespace], int] | None = None,
        ) -> int:
    """Parse ``argv`` and run the subcommand (or ``handler``); return the exit status.

    Bad input (airframe, fault or usage errors) prints one line and returns 2, Ctrl-C 130,
    domain failures (RuntimeError) 1.
    """
    ap = build_parser()
    args = ap.parse_args(argv)
    func = handler or args.func
    try:
        return int(func(args) or 0)
    except (AirframeError, FaultError, UsageError) as exc:
        print(f"vtolftc {args.command}: error: {exc}", file=sys.stderr)
        return 2
    except KeyboardInterrupt:
        print(f"vtolftc {args.command}: interrupted", file=sys.stderr)
        return 130
    except RuntimeError as exc:
        # Domain failures (no trim, solver failure) are reported, not dumped.
        print(f"vtolftc {args.command}: failed: {exc}", file=sys.stderr)
        return 1


def main(argv: Sequence[str] | None = None) -> int:
    """Entry point of the ``vtolftc`` command; returns the exit status."""
    return run(argv)


if __name__ == "__main__":  # pragma: no cover
    sys.exit(main())

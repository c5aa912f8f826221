"""``vtolftc gcs``: a command-line ground station (one command per call, or ``watch``).

    vtolftc gcs [--url URL] [--timeout S] status
    vtolftc gcs arm [--force] | disarm | takeoff [ALT] | land | transition fw|mc
    vtolftc gcs mode AUTO.LOITER
    vtolftc gcs inject --actuator rotor_2b --loss 0.5     (or --kind off|stuck|ok)
    vtolftc gcs params get NAME | params set NAME VALUE | params list
    vtolftc gcs watch [--count N] [--rate HZ]

It binds ``udp-server://127.0.0.1:14550`` by default (where the autopilot sends its
ground-station stream, as for QGroundControl; close QGroundControl first or use another
``--url``), waits for the autopilot's heartbeat, sends the command, waits for the COMMAND_ACK
(with retries) and prints e.g. ``DO_VTOL_TRANSITION: DENIED (vehicle is disarmed)``. Exit
status 0 when accepted, 1 when refused or unanswered, 2 on bad input.
"""

from __future__ import annotations

import argparse
import math
import time
from pathlib import Path
from typing import Any

from vtolftc.errors import UsageError

__all__ = ["register"]


def register(sub: Any) -> None:
    """Add the ``gcs`` sub-command."""
    p = sub.add_parser("gcs", help="ground station: status, arm, takeoff, transition, inject, "
                                   "params, watch",
                       description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    p.add_argument("--url", default="udp-server://127.0.0.1:14550",
                   help="link URL (default udp-server://127.0.0.1:14550; zenoh: "
                        "zenoh://ds1/gcs/down?connect=tcp/127.0.0.1:7448)")
    p.add_argument("--timeout", type=float, default=10.0,
                   help="seconds to wait for the autopilot's heartbeat (default 10)")
    p.add_argument("--allow-remote", action="store_true",
                   help="allow a non-loopback link address (ground station on another host)")
    p.add_argument("--airframe", type=Path, default=None,
                   help="airframe TOML whose actuator names and motor/servo numbering the "
                        "vehicle uses (default: the shipped DS-1)")
    p.add_argument("--signing-passphrase", default=None,
                   help="sign outgoing frames with this MAVLink 2 key passphrase")
    ops = p.add_subparsers(dest="gcs_command", required=True, metavar="ACTION")
    ops.add_parser("status", help="one snapshot of the vehicle")
    a = ops.add_parser("arm", help="arm the vehicle")
    a.add_argument("--force", action="store_true", help="skip pre-arm checks (PX4 21196)")
    ops.add_parser("disarm", help="disarm the vehicle")
    t = ops.add_parser("takeoff", help="take off (altitude in m above home, default: autopilot)")
    t.add_argument("altitude", nargs="?", type=float, default=None)
    ops.add_parser("land", help="land here")
    tr = ops.add_parser("transition", help="VTOL transition to fw or mc")
    tr.add_argument("target", help="fw (fixed wing) or mc (multicopter)")
    m = ops.add_parser("mode", help="set a PX4 mode (AUTO.LOITER, AUTO.LAND, ...)")
    m.add_argument("name")
    i = ops.add_parser("inject", help="inject an actuator fault (SYS_FAILURE_EN must be 1)")
    i.add_argument("--actuator", required=True,
                   help="an actuator of the airframe (--airframe; DS-1: rotor_1a..rotor_4b, "
                        "pusher_left/right, aileron_left/right, elevator, rudder_left/right) "
                        "or a group: ailerons, rudders, surfaces, lift_rotors, pushers")
    i.add_argument("--loss", type=float, default=None,
                   help="fraction of effectiveness lost, 0..1 (0 clears)")
    i.add_argument("--kind", default=None, help="loss (default with --loss), off, stuck, ok")
    pr = ops.add_parser("params", help="get, set or list parameters")
    pops = pr.add_subparsers(dest="params_command", required=True, metavar="get|set|list")
    g = pops.add_parser("get")
    g.add_argument("name")
    s = pops.add_parser("set")
    s.add_argument("name")
    s.add_argument("value")
    pops.add_parser("list")
    w = ops.add_parser("watch", help="print the vehicle state continuously (Ctrl-C ends)")
    w.add_argument("--rate", type=float, default=2.0, help="lines per second (default 2)")
    w.add_argument("--count", type=int, default=0, help="stop after N lines (default: never)")
    p.set_defaults(func=cmd_gcs)


def _status_line(s: Any) -> str:
    n, e, d = s.position_ned_m
    return (f"t={s.sim_time_s:8.2f}s {'ARMED' if s.armed else 'disarmed':8s} "
            f"{s.mode_name:13s} {s.vtol_state_name:16s} alt={s.altitude_m:6.2f}m "
            f"NED=({n:7.1f},{e:6.1f},{d:6.1f}) V={s.airspeed_m_s:5.2f}m/s "
            f"rpy=({math.degrees(s.roll):6.1f},{math.degrees(s.pitch):6.1f},"
            f"{math.degrees(s.yaw):6.1f})deg")


def cmd_gcs(args: argparse.Namespace) -> int:
    """Connect, run one action, print the result."""
    from vtolftc.gcs.client import GcsError, GroundStation
    from vtolftc.protocols import SigningConfig, parse_link_url

    try:
        parse_link_url(args.url)
    except ValueError as exc:
        raise UsageError(str(exc)) from None
    if not (math.isfinite(args.timeout) and args.timeout > 0):
        raise UsageError(f"--timeout {args.timeout!r}: expected a positive number of seconds")
    op = args.gcs_command
    # validate the arguments before connecting
    if op == "transition" and args.target.lower() not in ("fw", "mc"):
        raise UsageError(f"transition {args.target!r}: expected fw or mc")
    if op == "takeoff" and args.altitude is not None and not (
            math.isfinite(args.altitude) and args.altitude > 0):
        raise UsageError(f"takeoff altitude {args.altitude!r}: expected a height > 0 in m")
    if op == "mode":
        from vtolftc.protocols.px4 import mode_from_name

        try:
            mode_from_name(args.name)
        except ValueError as exc:
            raise UsageError(str(exc)) from None
    kind = None
    from vtolftc.gcs.actuators import ActuatorTable, default_table

    table = default_table()
    if args.airframe is not None:
        from vtolftc.airframe.loader import load_airframe

        table = ActuatorTable.from_names(load_airframe(args.airframe).actuator_names)
    if op == "inject":
        kind = (args.kind or "loss").lower()
        if kind == "loss" and args.loss is None:
            raise UsageError("inject: give --loss 0..1 (or --kind off|stuck|ok)")
        if kind not in ("loss", "off", "stuck", "ok"):
            raise UsageError(f"--kind {args.kind!r}: expected loss, off, stuck or ok")
        if kind == "loss" and not (math.isfinite(args.loss) and 0.0 <= args.loss <= 1.0):
            raise UsageError(f"--loss {args.loss!r}: expected a fraction in [0, 1] "
                             "(0.5 = 50 %), not a percentage")
        if kind != "loss" and args.loss is not None:
            raise UsageError(f"--kind {kind} takes no --loss")
        try:
            table.expand(args.actuator)
        except ValueError as exc:
            raise UsageError(str(exc)) from None
    if op == "params" and args.params_command == "set":
        try:
            value = float(args.value)
        except ValueError:
            raise UsageError(f"params set {args.name}: {args.value!r} is not a number") from None
        if not math.isfinite(value):
            raise UsageError(f"params set {args.name}: {args.value!r} is not a finite number")
    signing = (SigningConfig.from_passphrase(args.signing_passphrase, allow_unsigned=True)
               if args.signing_passphrase else None)
    try:
        gs = GroundStation.connect(args.url, timeout_s=args.timeout, signing=signing,
                                   allow_remote=args.allow_remote, actuators=table)
    except GcsError as exc:
        raise RuntimeError(str(exc)) from None
    with gs:
        return _run_op(gs, args, kind)


def _run_op(gs: Any, args: argparse.Namespace, kind: str | None) -> int:
    from vtolftc.gcs.client import GcsError

    op = args.gcs_command
    try:
        if op == "status":
            s = gs.snapshot()
            time.sleep(0.3)  # collect one round of streams
            s = gs.snapshot()
            print(_status_line(s))
            if s.actuator_outputs:
                print("actuators: " + " ".join(f"{x:.2f}" for x in s.actuator_outputs))
            if s.last_statustext:
                print(f"last message: {s.last_statustext}")
            return 0
        if op == "watch":
            period = 1.0 / max(0.1, args.rate)
            n = 0
            while args.count <= 0 or n < args.count:
                print(_status_line(gs.snapshot()), flush=True)
                n += 1
                time.sleep(period)
            return 0
        if op == "params":
            if args.params_command == "get":
                print(f"{args.name} = {gs.param_get(args.name):g}")
            elif args.params_command == "set":
                print(f"{args.name} = {gs.param_set(args.name, float(args.value)):g}")
            else:
                for name, value in gs.params().items():
                    print(f"{name:16s} {value:g}")
            return 0
        if op == "arm":
            out = gs.arm(force=args.force)
        elif op == "disarm":
            out = gs.disarm()
        elif op == "takeoff":
            out = gs.takeoff(args.altitude)
        elif op == "land":
            out = gs.land()
        elif op == "transition":
            out = gs.transition(args.target)
        elif op == "mode":
            out = gs.set_mode(args.name)
        elif op == "inject":
            out = gs.inject(args.actuator, loss=args.loss if kind == "loss" else None,
                            kind=kind or "loss")
        else:  # pragma: no cover - argparse restricts the choices
            raise GcsError(f"unknown action {op}")
    except GcsError as exc:
        raise RuntimeError(str(exc)) from None
    if not out.accepted:
        raise RuntimeError(str(out) if out.result is not None
                           else f"{out.name}: no COMMAND_ACK within {out.elapsed_s:.1f} s")
    print(f"{out} ({out.elapsed_s * 1000:.0f} ms)")
    return 0

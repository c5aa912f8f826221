"""``vtolftc sitl``: fly a paper case with the vehicle and the autopilot as two processes.

    vtolftc sitl --case 1 --controller gs-shif [--transport udp|zenoh] [--realtime]
                 [--duration 40] [--out DIR] [--compare]
    vtolftc sitl --transport zenoh --spin-us 300 --cpus 0,1 --rt-priority 10
                 --zenoh-lowlatency --zenoh-peer-cpu   # zenoh's fast headless lockstep

Starts ``vtolftc.runners.processes.vehicle`` and ``vtolftc.runners.processes.autopilot`` on
free
loopback ports (UDP, or embedded zenoh peers on tcp/127.0.0.1), flies the case through a
ground station with the real MAVLink commands (arm, takeoff, transition, fault injection with
SYS_FAILURE_EN = 1) at the scenario's simulated times, stops both processes (also on Ctrl-C)
and prints the metrics, computed by the same function as the in-process run. ``--compare``
also flies the case in-process and prints both side by side.
"""

from __future__ import annotations

import argparse
import math
import os
from pathlib import Path
from typing import Any

from vtolftc.base.errors import UsageError

__all__ = ["METRIC_ROWS", "register"]

METRIC_ROWS = (
    ("rmse_altitude_m", "RMSE altitude (m)"),
    ("rmse_roll_deg", "RMSE roll (deg)"),
    ("rmse_pitch_deg", "RMSE pitch (deg)"),
    ("rmse_yaw_deg", "RMSE yaw (deg)"),
    ("transition_complete_s", "transition complete (s)"),
    ("final_altitude_m", "final altitude (m)"),
    ("final_airspeed_m_s", "final airspeed (m/s)"),
    ("crashed", "crashed"),
)


def register(sub: Any) -> None:
    """Add the ``sitl`` sub-command."""
    p = sub.add_parser("sitl", help="fly a case with separate vehicle and autopilot processes "
                                    "over MAVLink (UDP or zenoh)",
                       description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    p.add_argument("--case", default="1", help="fault case: 0 (nominal), 1 or 2 (default 1)")
    p.add_argument("--controller", default="gs-shif", help="gs-shif (default), shif or lqr")
    p.add_argument("--transport", default="udp", help="udp (default) or zenoh")
    p.add_argument("--realtime", action="store_true",
                   help="real-time vehicle instead of lockstep (commands land a few steps late)")
    p.add_argument("--rt-priority", type=int, default=0, metavar="N",
                   help="both processes run as SCHED_FIFO at priority N once compiled (1-99; "
                        "needs root or CAP_SYS_NICE, else one line and ordinary scheduling): "
                        "for --realtime on a loaded machine; default 0 = ordinary scheduling")
    p.add_argument("--spin-us", type=float, default=0.0, metavar="US",
                   help="both processes busy-poll the HIL link this long before sleeping "
                        "(0-100000 us; default 0): with --cpus and --rt-priority, the headless "
                        "lockstep's fast setting on a machine with two free cores")
    p.add_argument("--cpus", default=None, metavar="A,V",
                   help="pin the autopilot to CPU A and the vehicle to CPU V once compiled "
                        "(e.g. 0,1; default: not pinned)")
    p.add_argument("--zenoh-lowlatency", action="store_true",
                   help="zenoh: the HIL link on zenoh's low-latency unicast transport (the "
                        "publishing thread writes the socket; default: the universal one)")
    p.add_argument("--zenoh-peer-cpu", action="store_true",
                   help="zenoh, with --cpus: each process's zenoh runtime threads on the other "
                        "process's CPU (the socket reader wakes where the sample was sent)")
    p.add_argument("--duration", type=float, default=40.0,
                   help="simulated seconds (default 40)")
    p.add_argument("--out", type=Path, default=None,
                   help="run folder (default runs/sitl-case<N>-<controller>-<transport>-<UTC>)")
    p.add_argument("--airframe", type=Path, default=None, help="airframe TOML (default DS-1)")
    p.add_argument("--gains-dir", type=Path, default=None, help="directory of the gain files")
    p.add_argument("--compare", action="store_true",
                   help="also fly the case in-process and compare the metrics")
    p.add_argument("--dashboard", action="store_true",
                   help="also serve the web dashboard on 127.0.0.1 (its own ground-station "
                        "link to the autopilot); best with --realtime")
    p.add_argument("--dashboard-port", type=int, default=8080,
                   help="web port of --dashboard (default 8080)")
    p.set_defaults(func=cmd_sitl)


def _fmt(v: Any) -> str:
    if v is None:
        return "-"
    if isinstance(v, bool):
        return "yes" if v else "no"
    if isinstance(v, float):
        return "nan" if math.isnan(v) else f"{v:.4f}"
    return str(v)


def _start_dashboard(args: argparse.Namespace, cfg: Any, af: Any) -> Any:
    """Serve the dashboard on its own ground-station link (a free loopback UDP port that the
    autopilot is told to stream to), before the processes start."""
    from vtolftc.protocols.netutil import free_udp_port

    if not 0 <= args.dashboard_port <= 65535:
        raise UsageError(f"--dashboard-port {args.dashboard_port}: expected 0..65535")
    from vtolftc.dashboard.web import Dashboard

    port = free_udp_port()
    cfg.extra_autopilot_args += ["--gcs-link", f"udp-client://127.0.0.1:{port}"]
    dash = Dashboard(f"udp-server://127.0.0.1:{port}", port=args.dashboard_port, airframe=af)
    print(f"dashboard: {dash.page_url}", flush=True)
    return dash


def _cpus(text: str | None) -> tuple[int, int]:
    """``--cpus A,V`` as (autopilot CPU, vehicle CPU); (-1, -1) when not given.

    Raises
    ------
    UsageError
        If the text is not two different CPUs this process may use.
    """
    from vtolftc.runners.processes.affinity import CPU_OFF, check_cpu

    if text is None:
        return CPU_OFF, CPU_OFF
    parts = text.split(",")
    try:
        a, v = (int(x) for x in parts)
    except ValueError:
        raise UsageError(f"--cpus {text!r}: expected two CPU numbers, autopilot and vehicle, "
                         "e.g. 0,1") from None
    for n in (a, v):
        if n == CPU_OFF or check_cpu(n) is not None:
            allowed = sorted(os.sched_getaffinity(0))
            raise UsageError(f"--cpus {text!r}: CPU {n} is not one this process may use: "
                             f"{allowed}")
    if a == v:
        raise UsageError(f"--cpus {text!r}: the autopilot and the vehicle need different CPUs")
    return a, v


def cmd_sitl(args: argparse.Namespace) -> int:
    """Start the processes, fly, stop, print the metrics."""

    if args.transport not in ("udp", "zenoh"):
        raise UsageError(f"--transport {args.transport!r}: expected udp or zenoh")
    if args.controller not in ("gs-shif", "shif", "lqr"):
        raise UsageError(f"--controller {args.controller!r}: expected gs-shif, shif or lqr")
    if not (math.isfinite(args.duration) and 0 < args.duration <= 3600):
        raise UsageError(f"--duration {args.duration!r}: expected 0 < seconds <= 3600")
    from vtolftc.runners.processes.priority import check_rt_priority

    if (bad := check_rt_priority(args.rt_priority)) is not None:
        raise UsageError(bad)
    if not (math.isfinite(args.spin_us) and 0 <= args.spin_us <= 100_000):
        raise UsageError(f"--spin-us {args.spin_us!r}: expected 0 <= microseconds <= 100000")
    ap_cpu, veh_cpu = _cpus(args.cpus)
    if args.zenoh_peer_cpu and args.cpus is None:
        raise UsageError("--zenoh-peer-cpu needs --cpus A,V")
    case = str(args.case).removeprefix("case")
    from vtolftc.firmware_sim.vehicle.faults import FaultError, load_cases

    if f"case{case}" not in load_cases():
        raise UsageError(f"--case {args.case!r}: expected one of "
                         f"{', '.join(k.removeprefix('case') for k in load_cases())}")
    from vtolftc.runners.scenario import paper_scenario
    from vtolftc.runners.sitl import SitlConfig, SitlError, run_sitl
    from vtolftc.telemetry.runfolder import default_run_dir

    af = None
    if args.airframe is not None:
        from vtolftc.firmware_sim.vehicle.flyable import load_flyable_airframe

        af = load_flyable_airframe(args.airframe)
    try:
        scenario = paper_scenario(case, args.duration, airframe=af)
    except (FaultError, ValueError) as exc:
        raise UsageError(str(exc)) from None
    out = args.out or default_run_dir(case, f"{args.controller}-sitl-{args.transport}")
    cfg = SitlConfig(case=case, controller=args.controller, transport=args.transport,
                     realtime=args.realtime, duration_s=args.duration, out_dir=out,
                     airframe=args.airframe, gains_dir=args.gains_dir,
                     rt_priority=args.rt_priority, spin_us=args.spin_us,
                     autopilot_cpu=ap_cpu, vehicle_cpu=veh_cpu,
                     zenoh_lowlatency=args.zenoh_lowlatency,
                     zenoh_peer_cpu=args.zenoh_peer_cpu)
    mode = "real time" if args.realtime else "lockstep"
    print(f"SITL {scenario.name} ({scenario.description}), {args.controller}, "
          f"{args.transport}, {mode}; run folder {out}", flush=True)
    dash = _start_dashboard(args, cfg, af) if args.dashboard else None
    try:
        res = run_sitl(cfg, scenario)
    except SitlError as exc:
        raise RuntimeError(f"{exc} (run folder kept: {out})") from None
    except KeyboardInterrupt:
        print(f"interrupted: processes stopped, run folder kept: {out}")
        raise
    finally:
        if dash is not None:
            dash.close()
    for o in res.outcomes:
        line = f"  t = {o['t_s']:6.2f} s  {o['label']}: {o['command']} {o['result']}"
        print(line + (f" ({o['detail']})" if o["result"] != "ACCEPTED" and o["detail"] else ""))
    ref = None
    if args.compare:
        from vtolftc.runners.scenario import run_scenario

        ref = run_scenario(scenario, args.controller, airframe=af, gains_dir=args.gains_dir
                           ).metrics
    head = f"| metric | SITL ({args.transport}) |" + (" in-process |" if ref else "")
    print("\n" + head)
    print("|---|---:|" + ("---:|" if ref else ""))
    for key, label in METRIC_ROWS:
        row = f"| {label} | {_fmt(res.metrics.get(key))} |"
        if ref is not None:
            row += f" {_fmt(ref.get(key))} |"
        print(row)
    print(f"\nsimulated {res.sim_time_s:.2f} s in {res.flight_wall_s:.2f} s of wall time "
          f"({res.real_time_factor:.1f}x real time); metrics in {out}/autopilot/metrics.json")
    return 0

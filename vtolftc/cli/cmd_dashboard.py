"""``vtolftc dashboard``: the viser web dashboard, connected to the autopilot over MAVLink."""

from __future__ import annotations

import argparse
import ipaddress
import sys
import time
from pathlib import Path
from typing import Any

from vtolftc.base.errors import UsageError

__all__ = ["cmd_dashboard", "register"]


def _check_host(host: str, allow_remote: bool) -> None:

    if host == "localhost":
        return
    try:
        addr = ipaddress.ip_address(host)
    except ValueError:
        raise UsageError(f"--host {host!r}: expected an IP address such as 127.0.0.1") from None
    if not addr.is_loopback and not allow_remote:
        raise UsageError(f"--host {host}: not a loopback address; the dashboard can arm and "
                         "fault the vehicle, so serving it to the network needs --allow-remote")


def cmd_dashboard(args: argparse.Namespace) -> int:
    """Serve the web dashboard and connect to the autopilot as a ground station."""

    _check_host(args.host, args.allow_remote)
    if not 0 <= args.port <= 65535:
        raise UsageError(f"--port {args.port}: expected 0..65535")
    if not 0.5 <= args.rate <= 60.0:
        raise UsageError(f"--rate {args.rate:g}: expected 0.5 .. 60 updates per second")
    try:
        from vtolftc.protocols.link import parse_link_url

        parse_link_url(args.url)
    except ValueError as exc:
        raise UsageError(f"--url: {exc}") from None
    from vtolftc.airframe.loader import load_airframe
    from vtolftc.dashboard.web import Dashboard

    af = load_airframe(args.airframe)
    dash = Dashboard(args.url, host=args.host, port=args.port, rate_hz=args.rate, airframe=af,
                     allow_remote=args.allow_remote)
    print(f"dashboard: {dash.page_url}  (autopilot link {args.url}; Ctrl-C to stop)",
          flush=True)
    try:
        _wait(dash, args.duration)
    finally:
        dash.close()
    return 0


def _wait(dash: Any, duration: float | None) -> None:
    t_end = None if duration is None else time.monotonic() + duration
    warned = False
    while t_end is None or time.monotonic() < t_end:
        time.sleep(0.5)
        view = dash.view
        if view is not None and view.link_state in ("waiting", "lost") and not warned:
            print(f"dashboard: {view.link_text}", file=sys.stderr, flush=True)
            warned = True
        elif view is not None and view.link_state == "ok" and warned:
            print("dashboard: autopilot connected", file=sys.stderr, flush=True)
            warned = False


def register(sub: Any) -> None:
    """Add the ``dashboard`` subcommand to the CLI's subparsers."""
    p = sub.add_parser("dashboard", help="web dashboard (viser) that watches and commands the "
                       "vehicle over MAVLink", description=cmd_dashboard.__doc__)
    p.add_argument("--url", default="udp-server://127.0.0.1:14550",
                   help="ground-station link URL where the autopilot sends its stream "
                        "(default udp-server://127.0.0.1:14550; zenoh://... works too)")
    p.add_argument("--host", default="127.0.0.1", help="address to serve on (default 127.0.0.1)")
    p.add_argument("--port", type=int, default=8080, help="web port (default 8080)")
    p.add_argument("--rate", type=float, default=10.0,
                   help="page updates per second (default 10)")
    p.add_argument("--airframe", type=Path, default=None,
                   help="airframe TOML file (default DS-1)")
    p.add_argument("--allow-remote", action="store_true",
                   help="allow non-loopback addresses for --host and --url (dashboard or "
                        "autopilot on another host)")
    p.add_argument("--duration", type=float, default=None,
                   help="stop after this many seconds (default: until Ctrl-C)")
    p.set_defaults(func=cmd_dashboard)

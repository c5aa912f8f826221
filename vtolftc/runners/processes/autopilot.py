"""The autopilot process program.

    python -m vtolftc.runners.processes.autopilot --hil-link udp-client://127.0.0.1:4560
        [--gcs-link URL ...] [--no-default-gcs] [--lockstep|--realtime]
        [--controller gs-shif|shif|lqr] [--airframe FILE] [--gains-dir DIR]
        [--hold-ms MS] [--param NAME=VALUE ...] [--signing-passphrase TEXT]
        [--out DIR] [--case LABEL] [--window-start S] [--vehicle-timeout S] [--max-wall S]
        [--rt-priority N] [--cpu N] [--trace-steps N]

Ground-station links: by default, like PX4 SITL, it sends to UDP 127.0.0.1:14550 (ground
stations: QGroundControl, ``vtolftc gcs``) and 127.0.0.1:14540 (API clients: MAVSDK), as a UDP
client of those ports; ``--gcs-link`` adds any link (UDP or zenoh, several allowed) and
``--no-default-gcs`` drops the two defaults. What it says on those links is documented in
:mod:`vtolftc.firmware_sim.autopilot.gcs_endpoint`; the HIL side in
:mod:`vtolftc.firmware_sim.autopilot.hil_bridge`; the loop and its threads in
:mod:`vtolftc.firmware_sim.autopilot.process`; the failsafes in
:mod:`vtolftc.firmware_sim.autopilot.failsafe`.

HIL signing: with ``VTOLFTC_HIL_KEY`` (64 hexadecimal digits) in the environment the HIL link
is signed both ways and unsigned frames are dropped; the vehicle then pins only an autopilot
with the same key (:mod:`vtolftc.protocols.hil_signing`).

Signing (``--signing-passphrase``): key = SHA-256 of the passphrase; outgoing frames signed;
incoming frames need a valid signature except the few of
:data:`~vtolftc.firmware_sim.autopilot.gcs_endpoint.UNSIGNED_ALLOWED`; one stream-timestamp
table for all ground-station links.

Run folder (``--out DIR``), wired here and passed into the flight software: ``metrics.json``
(:class:`vtolftc.telemetry.metrics.MetricsAccumulator` over the autopilot's own samples, the
very function of the in-process runner), the telemetry of the autopilot's view
(:class:`vtolftc.telemetry.runfolder.RunFolderWriter`: ``telemetry.csv``, events, plots), its
rerun
recording ``run.rrd``, ``autopilot_events.jsonl`` and ``autopilot_summary.json`` (link
counters incl. dropped garbage / CRC / truncated / signature / rate-limited frames, steps,
control-step periods, failsafes, wall time). Written on every exit: end of run, SIGTERM,
Ctrl-C, lost vehicle; a SIGKILL loses at most about a second of telemetry and recording.

Exit status: 0 stopped by signal or ``--max-wall``, 2 bad arguments, 3 vehicle lost.
"""

from __future__ import annotations

import argparse
import json
import signal
import sys
from pathlib import Path
from typing import Any, TextIO

from vtolftc.base.jsonio import atomic_write_text, json_safe
from vtolftc.firmware_sim.autopilot.failsafe import register_failsafe_params
from vtolftc.firmware_sim.autopilot.gcs_endpoint import UNSIGNED_ALLOWED
from vtolftc.firmware_sim.autopilot.interface import AutopilotAPI, ParamError
from vtolftc.firmware_sim.autopilot.process import AutopilotProcess
from vtolftc.protocols import SigningConfig, StreamTimestamps, open_link
from vtolftc.protocols.failure_units import ActuatorTable
from vtolftc.protocols.hil_signing import hil_signing_from_env
from vtolftc.protocols.link import Link
from vtolftc.runners.processes.affinity import add_cpu_argument, apply_cpu, check_cpu
from vtolftc.runners.processes.priority import (
    add_rt_priority_argument,
    apply_rt_priority,
    check_rt_priority,
)
from vtolftc.runners.processes.procstate import enable_stack_dump
from vtolftc.telemetry.step_parts import check_trace_steps

__all__ = ["DEFAULT_GCS_LINKS", "main", "run_observers"]

DEFAULT_GCS_LINKS = ("udp-client://127.0.0.1:14550", "udp-client://127.0.0.1:14540")
GCS_LINK_RATE_HZ = 200.0
"""Datagrams per second a ground-station link reads (burst twice that); the excess is
dropped unparsed. A ground station sends a few tens per second."""


def _parse_args(argv: list[str] | None) -> argparse.Namespace:
    ap = argparse.ArgumentParser(
        prog="python -m vtolftc.runners.processes.autopilot",
        description="vtol-ftc autopilot: HIL link to the simulated vehicle, MAVLink to ground "
                    "stations (PX4 conventions).")
    ap.add_argument("--hil-link", required=True,
                    help="HIL link URL, e.g. udp-client://127.0.0.1:4560 or "
                         "zenoh://ds1/hil/down?connect=tcp/127.0.0.1:7447")
    ap.add_argument("--gcs-link", action="append", default=[],
                    help="extra ground-station link URL (repeatable), e.g. "
                         "udp-client://127.0.0.1:14551 or "
                         "zenoh://ds1/gcs/up?listen=tcp/127.0.0.1:7448")
    ap.add_argument("--no-default-gcs", action="store_true",
                    help="do not send to 127.0.0.1:14550 and :14540")
    mode = ap.add_mutually_exclusive_group()
    mode.add_argument("--lockstep", dest="lockstep", action="store_true", default=True,
                      help="lockstep with the vehicle (default)")
    mode.add_argument("--realtime", dest="lockstep", action="store_false",
                      help="the vehicle runs in real time (no hold)")
    ap.add_argument("--controller", default="gs-shif", help="gs-shif (default), shif or lqr")
    ap.add_argument("--airframe", type=Path, default=None, help="airframe TOML (default DS-1)")
    ap.add_argument("--gains-dir", type=Path, default=None, help="directory of the gain files")
    ap.add_argument("--hold-ms", type=int, default=-1,
                    help="initial SIM_HOLD_MS: hold before the step at this simulated time "
                         "(ms; 0 = hold at start; -1 = no hold, default)")
    ap.add_argument("--param", action="append", default=[], metavar="NAME=VALUE",
                    help="set a parameter at start (repeatable), e.g. SYS_FAILURE_EN=1")
    ap.add_argument("--signing-passphrase", default=None,
                    help="MAVLink 2 signing key passphrase (SHA-256): sign outgoing frames, "
                         "require a valid signature on every command, parameter change and "
                         "mission message")
    ap.add_argument("--out", type=Path, default=None, help="run folder")
    ap.add_argument("--no-plots", action="store_true",
                    help="no PNG plots in the run folder at the end")
    ap.add_argument("--no-rerun", action="store_true",
                    help="no rerun recording run.rrd in the run folder (memory benchmark)")
    ap.add_argument("--no-warmup", action="store_true",
                    help="skip compiling the allocation kernels before reporting ready")
    ap.add_argument("--case", default="", help="case label for the run folder and metrics")
    ap.add_argument("--window-start", type=float, default=20.0,
                    help="metrics window start, simulated s (default 20, the transition)")
    ap.add_argument("--vehicle-timeout", type=float, default=0.0,
                    help="stop if the vehicle is silent this long, wall s (default 0 = never)")
    ap.add_argument("--max-wall", type=float, default=0.0,
                    help="stop after this many wall seconds (default 0 = never)")
    ap.add_argument("--allow-remote", action="store_true",
                    help="allow non-loopback link addresses (containers on separate hosts)")
    ap.add_argument("--parent-pid", type=int, default=None,
                    help="stop when this process is gone (used by vtolftc sitl)")
    ap.add_argument("--spin-us", type=float, default=0.0,
                    help="busy-poll the HIL link this long before sleeping (lower wake-up "
                         "latency on idle cores, costs CPU; default 0)")
    add_rt_priority_argument(ap)
    add_cpu_argument(ap)
    ap.add_argument("--trace-steps", type=int, default=0, metavar="N",
                    help="record the wall / CPU time of each part of the first N lockstep "
                         "steps into step_trace.npz in the run folder (StepParts; read by "
                         "benchmarks/bench_sitl.py --trace); default 0 = off")
    return ap.parse_args(argv)


def _make_autopilot(args: argparse.Namespace) -> tuple[AutopilotAPI, Any]:
    from vtolftc.airframe.loader import load_airframe
    from vtolftc.firmware_sim.autopilot.autopilot import Autopilot

    af = load_airframe(args.airframe) if args.airframe else load_airframe()
    return Autopilot(af, controller=args.controller, gains_dir=args.gains_dir), af


class EventLog:
    """Run observer writing ``autopilot_events.jsonl`` (one JSON object per event, flushed)."""

    def __init__(self, path: Path) -> None:
        path.parent.mkdir(parents=True, exist_ok=True)
        self._f: TextIO | None = path.open("w", encoding="utf-8")

    def on_start(self, info: dict[str, Any]) -> None:
        """Nothing to do."""

    def on_sample(self, sample: Any) -> None:
        """Nothing to do."""

    def on_event(self, time_usec: int, kind: str, text: str) -> None:
        """Append the event as one JSON line and flush."""
        if self._f is not None:
            self._f.write(json.dumps({"time_s": time_usec * 1e-6, "kind": kind,
                                      "text": text}) + "\n")
            self._f.flush()

    def on_finish(self, metrics: dict[str, Any]) -> None:
        """Close the file."""
        if self._f is not None:
            self._f.close()
            self._f = None


def run_observers(out: Path, plots: bool = True, autopilot: Any = None,
                  rerun: bool = True) -> list[Any]:
    """The run folder of the autopilot's own view (telemetry, events, metrics, plots), its
    rerun recording ``run.rrd`` (no vehicle truth here: commands, not effective outputs;
    unless ``rerun`` is False), the event log and, given the autopilot (for its parameters
    and mission), the PX4 ULog ``flight.ulg`` (:mod:`vtolftc.firmware_sim.autopilot.ulog`)."""
    from vtolftc.firmware_sim.autopilot.ulog import ULogWriter
    from vtolftc.telemetry.recording import RerunRecorder
    from vtolftc.telemetry.runfolder import RunFolderWriter

    obs: list[Any] = [RunFolderWriter(out, plots=plots), EventLog(out / "autopilot_events.jsonl")]
    if rerun:
        # its sends in pieces while the control loop waits for the vehicle: made at once they
        # stalled a control step 2-7 ms every 0.5 s of simulated time (bench_sitl, session 16)
        obs.insert(1, RerunRecorder(out / "run.rrd", deferred=True))
    if autopilot is not None:
        obs.append(ULogWriter(out / "flight.ulg", autopilot))
    return obs


def _write_json(path: Path, data: Any) -> None:
    """Write JSON atomically (a crash never leaves half a file)."""
    atomic_write_text(path, json.dumps(json_safe(data), indent=2))


def main(argv: list[str] | None = None) -> int:
    """Run the autopilot process (see the module docstring); returns the exit status."""
    args = _parse_args(argv)
    err = sys.stderr
    for bad in (check_rt_priority(args.rt_priority), check_cpu(args.cpu),
                check_cpu(args.zenoh_cpu, "--zenoh-cpu"),
                check_trace_steps(args.trace_steps)):
        if bad is not None:
            print(f"autopilot: error: {bad}", file=err)
            return 2
    try:
        autopilot, af = _make_autopilot(args)
    except Exception as exc:  # bad airframe, unknown controller, missing gains
        print(f"autopilot: error: {exc}", file=err)
        return 2
    register_failsafe_params(autopilot.params)
    for item in args.param:
        name, sep, value = item.partition("=")
        try:
            if not sep:
                raise ParamError(f"--param {item!r}: expected NAME=VALUE")
            autopilot.params.set(name.strip(), float(value))
        except (ParamError, ValueError) as exc:
            print(f"autopilot: error: {exc}", file=err)
            return 2
    signing = None
    table = StreamTimestamps()
    if args.signing_passphrase:
        signing = SigningConfig.from_passphrase(
            args.signing_passphrase, allow_unsigned=lambda msgid: msgid in UNSIGNED_ALLOWED)
    urls = ([] if args.no_default_gcs else list(DEFAULT_GCS_LINKS)) + list(args.gcs_link)
    links: list[Link] = []
    try:
        hil = open_link(args.hil_link, system_id=1, component_id=1,
                        allow_remote=args.allow_remote, signing=hil_signing_from_env(),
                        zenoh_receive="channel")
        links.append(hil)
        gcs_links = []
        for url in urls:
            gl = open_link(url, system_id=1, component_id=1, signing=signing,
                           allow_remote=args.allow_remote, stream_table=table,
                           rate_limit_hz=GCS_LINK_RATE_HZ)
            links.append(gl)
            gcs_links.append(gl)
    except (ValueError, OSError) as exc:
        for link in links:
            link.close()
        print(f"autopilot: error: {exc}", file=err)
        return 2
    info = {"airframe": af.name, "airframe_sha256": af.sha256,
            "actuator_names": list(af.actuator_names), "controller": args.controller,
            "case": args.case, "scenario": f"sitl-{args.case}" if args.case else "sitl",
            "hil_link": args.hil_link, "gcs_links": urls, "lockstep": args.lockstep,
            "run_folder": str(args.out) if args.out else None}
    from vtolftc.telemetry.metrics import MetricsAccumulator

    observers: list[Any] = []
    on_finish = None
    if args.out is not None:
        try:
            args.out.mkdir(parents=True, exist_ok=True)
            observers = run_observers(args.out, plots=not args.no_plots,
                                      autopilot=autopilot, rerun=not args.no_rerun)
        except OSError as exc:
            for link in links:
                link.close()
            print(f"autopilot: error: --out {args.out}: {exc.strerror or exc}", file=err)
            return 2
        out: Path = args.out

        def on_finish(m: dict[str, Any], summary: dict[str, Any]) -> None:
            _write_json(out / "metrics.json", m)
            _write_json(out / "autopilot_summary.json", summary)
            if proc is not None:
                proc.parts.save_trace(out / "step_trace.npz")

    proc: AutopilotProcess | None = None

    def make() -> AutopilotAPI:
        ap, _ = _make_autopilot(args)
        return ap

    def warm() -> None:
        from vtolftc.firmware_sim.autopilot.warmup import warm_up

        warm_up(make, stop=lambda: proc is not None and not proc.running)
        apply_rt_priority(args.rt_priority, "autopilot", err)  # compiled: now real time
        apply_cpu(args.cpu, "autopilot", err, args.zenoh_cpu)  # and pinned

    proc = AutopilotProcess(
        autopilot, hil, gcs_links, actuators=ActuatorTable.from_names(af.actuator_names),
        lockstep=args.lockstep, hold_ms=args.hold_ms, signing_required=signing is not None,
        observers=observers, metrics=MetricsAccumulator(window_start_s=args.window_start),
        on_finish=on_finish, info=info, vehicle_timeout_s=args.vehicle_timeout,
        max_wall_s=args.max_wall, parent_pid=args.parent_pid,
        warmup=None if args.no_warmup else warm)
    if args.no_warmup:
        apply_rt_priority(args.rt_priority, "autopilot", err)
        apply_cpu(args.cpu, "autopilot", err, args.zenoh_cpu)
    proc.spin_s = max(0.0, args.spin_us) * 1e-6
    proc.parts.enable_trace(args.trace_steps)
    for obs in observers:  # the ULog's sensor topics from HIL_SENSOR / HIL_GPS
        if hasattr(obs, "hil"):
            obs.hil = proc.hil

    def stop(_sig: int, _frame: Any) -> None:
        proc.running = False

    signal.signal(signal.SIGTERM, stop)
    signal.signal(signal.SIGINT, stop)
    enable_stack_dump()  # SitlRun.stop's evidence when this process does not end
    # the control thread gets the interpreter back within 1 ms from the ground-station threads
    sys.setswitchinterval(0.001)
    return proc.run()


if __name__ == "__main__":
    sys.exit(main())

"""The autopilot as a process: HIL link to the vehicle, MAVLink links to ground stations.

    python -m vtolftc.firmware_sim.autopilot.process --hil-link udp-client://127.0.0.1:4560
        [--gcs-link URL ...] [--no-default-gcs] [--lockstep|--realtime]
        [--controller gs-shif|shif|lqr] [--airframe FILE] [--gains-dir DIR]
        [--hold-ms MS] [--param NAME=VALUE ...] [--signing-passphrase TEXT]
        [--out DIR] [--case LABEL] [--window-start S] [--vehicle-timeout S] [--max-wall S]

Ground-station links: by default, like PX4 SITL, it sends to UDP 127.0.0.1:14550 (ground
stations: QGroundControl, ``vtolftc gcs``) and 127.0.0.1:14540 (API clients: MAVSDK), as a UDP
client of those ports; ``--gcs-link`` adds any link (UDP or zenoh, several allowed) and
``--no-default-gcs`` drops the two defaults. What it says on those links is documented in
:mod:`vtolftc.firmware_sim.autopilot.gcs_endpoint`; the HIL side in :mod:`.hil_bridge`.

Main loop (one thread; the link receivers only queue): take the vehicle's messages; handle the
queued ground-station messages; when a HIL_SENSOR / HIL_STATE_QUATERNION pair has arrived,
step the autopilot once on the decoded navigation state and answer HIL_ACTUATOR_CONTROLS with
``wire_commands`` of its output, unless the simulation is held (``SIM_HOLD_MS``, lockstep only:
then ground-station messages are served until the hold moves on). Commands therefore act at
the next control step, exactly as in the in-process runner (:mod:`vtolftc.scenario`), which
executes actions due at a step before that step.

Run folder (``--out DIR``): ``metrics.json``
(:class:`~vtolftc.telemetry.metrics.MetricsAccumulator` over the autopilot's own samples, the
very function of the in-process runner), the telemetry of the autopilot's view
(:class:`~vtolftc.telemetry.runfolder.RunFolderWriter`: ``telemetry.csv``, events, plots),
its rerun recording ``run.rrd``, ``autopilot_events.jsonl`` and ``autopilot_summary.json`` (link
counters incl. dropped garbage / CRC / truncated frames, steps, wall time). Written on every
exit: end of run, SIGTERM, Ctrl-C, lost vehicle.

Exit status: 0 stopped by signal or ``--max-wall``, 2 bad arguments, 3 vehicle lost.
"""

from __future__ import annotations

import argparse
import contextlib
import json
import os
import signal
import sys
import time
from pathlib import Path
from typing import Any, TextIO

import numpy as np

from vtolftc.firmware_sim.autopilot.gcs_endpoint import GcsEndpoint
from vtolftc.firmware_sim.autopilot.hil_bridge import HilBridge
from vtolftc.firmware_sim.autopilot.interface import AutopilotAPI, ParamError
from vtolftc.jsonio import json_safe
from vtolftc.protocols import SigningConfig, open_link
from vtolftc.protocols.failure_units import ActuatorTable
from vtolftc.protocols.link import Link

__all__ = ["DEFAULT_GCS_LINKS", "AutopilotProcess", "main", "make_deterministic"]

DEFAULT_GCS_LINKS = ("udp-client://127.0.0.1:14550", "udp-client://127.0.0.1:14540")
EXIT_VEHICLE_LOST = 3


class AutopilotProcess:
    """Wires an :class:`AutopilotAPI` to a HIL link and ground-station links."""

    def __init__(self, autopilot: AutopilotAPI, hil_link: Link, gcs_links: list[Link], *,
                 actuators: ActuatorTable, lockstep: bool = True, hold_ms: int = -1,
                 signing_required: bool = False, out_dir: Path | None = None,
                 info: dict[str, Any] | None = None, window_start_s: float = 20.0,
                 vehicle_timeout_s: float = 0.0, max_wall_s: float = 0.0,
                 log: TextIO | None = None, parent_pid: int | None = None) -> None:
        self.ap = autopilot
        self.parent_pid = parent_pid
        self._next_parent_check = 0.0
        self.spin_s = 0.0
        """Poll this long without sleeping before blocking on the HIL link."""
        self.log = log or sys.stderr
        self.lockstep = lockstep
        self.hil = HilBridge(hil_link, lockstep=lockstep)
        self.out_dir = out_dir
        self.info = dict(info or {})
        self.vehicle_timeout_s = vehicle_timeout_s
        self.max_wall_s = max_wall_s
        self.events: list[dict[str, Any]] = []
        self._events_file: TextIO | None = None
        self.observers: list[Any] = []
        if out_dir is not None:
            out_dir.mkdir(parents=True, exist_ok=True)
            self._events_file = (out_dir / "autopilot_events.jsonl").open("w")
        self.gcs = GcsEndpoint(autopilot, self.hil, gcs_links, actuators=actuators,
                               signing_required=signing_required, lockstep=lockstep,
                               hold_ms=hold_ms, on_event=self._event)
        from vtolftc.telemetry.metrics import MetricsAccumulator

        self.metrics = MetricsAccumulator(window_start_s=window_start_s)
        self.steps = 0
        self.running = True
        self.vehicle_lost = False
        self.t_wall0 = time.monotonic()
        self.wall_in_step = 0.0
        self.step_wall_s: list[float] = []
        """Wall time of each control step (autopilot step, status, answer), s."""
        self.part_wall_s = {"autopilot_step": 0.0, "status_and_answer": 0.0,
                            "after_answer": 0.0}
        """Wall time summed over the steps [s]: ``Autopilot.step``; status + encoding and
        sending HIL_ACTUATOR_CONTROLS; after the answer (metrics, run-folder writer,
        ground-station streams), which overlaps with the vehicle's work."""
        self._finished = False

    def add_observer(self, obs: Any) -> None:
        self.observers.append(obs)

    def _event(self, kind: str, text: str) -> None:
        t = self.gcs.sim_usec if hasattr(self, "gcs") else 0
        rec = {"time_s": t * 1e-6, "kind": kind, "text": text}
        self.events.append(rec)
        if self._events_file is not None:
            self._events_file.write(json.dumps(rec) + "\n")
            self._events_file.flush()
        for o in self.observers:
            with contextlib.suppress(Exception):
                o.on_event(t, kind, text)

    # ------------------------------------------------------------------ loop
    def run(self) -> int:
        """Serve until stopped (signal, ``max_wall_s``, lost vehicle). Exit status."""
        from vtolftc.telemetry import TelemetrySample

        for o in self.observers:
            with contextlib.suppress(Exception):
                o.on_start(self.info)
        hil, gcs, ap = self.hil, self.gcs, self.ap
        link = hil.link
        ever_connected = False
        pc = time.perf_counter
        next_duty = 0.0
        try:
            while self.running:
                nav = hil.peek()
                hold = gcs.hold_usec() if nav is not None else None
                held = nav is not None and hold is not None and nav.time_usec >= hold
                if nav is None or held:
                    # nothing to step on: wait for the vehicle (or, held, poll the ground
                    # stations often: their commands are what the hold waits for)
                    wait = 0.002 if (held or gcs.has_pending()) else 0.01
                    msgs = []
                    if self.spin_s > 0 and not held:
                        end = pc() + self.spin_s
                        while not msgs and pc() < end:
                            msgs = link.recv(0.0)
                    for m in msgs or link.recv(wait):
                        hil.handle(m)
                    gcs.poll()
                    if held:
                        gcs.announce_hold(nav.time_usec)
                else:
                    ever_connected = True
                    gcs.poll()  # commands that arrived meanwhile act at this step
                    if gcs.hold_usec() is None or nav.time_usec < gcs.hold_usec():
                        hil.take()
                        t0 = pc()
                        u = ap.step(nav)
                        t1 = pc()
                        st = ap.status()
                        hil.send_controls(nav.time_usec, u, st.armed)
                        t2 = pc()
                        dt = t2 - t0
                        self.wall_in_step += dt
                        self.step_wall_s.append(dt)
                        # the rest overlaps with the vehicle's physics step
                        sample = TelemetrySample(nav.time_usec, nav, st, None)
                        self.metrics.add(sample)
                        for o in self.observers:
                            o.on_sample(sample)
                        gcs.on_step(nav, st)
                        self.steps += 1
                        part = self.part_wall_s
                        part["autopilot_step"] += t1 - t0
                        part["status_and_answer"] += t2 - t1
                        part["after_answer"] += pc() - t2
                    for m in link.recv(0.0):
                        hil.handle(m)
                now = time.monotonic()
                if now < next_duty:
                    continue
                next_duty = now + 0.05
                hil.tick(now)
                gcs.tick()
                if self.max_wall_s > 0 and now - self.t_wall0 > self.max_wall_s:
                    print(f"autopilot: --max-wall {self.max_wall_s:g} s reached: stopping",
                          file=self.log, flush=True)
                    break
                if self.parent_pid is not None and now >= self._next_parent_check:
                    self._next_parent_check = now + 1.0
                    if not _alive(self.parent_pid):
                        print(f"autopilot: parent process {self.parent_pid} is gone: stopping",
                              file=self.log, flush=True)
                        break
                if (self.vehicle_timeout_s > 0 and ever_connected
                        and now - hil.last_rx_wall > self.vehicle_timeout_s):
                    print(f"autopilot: vehicle silent for {self.vehicle_timeout_s:g} s: "
                          "stopping", file=self.log, flush=True)
                    self.vehicle_lost = True
                    break
        finally:
            self.finish()
        return EXIT_VEHICLE_LOST if self.vehicle_lost else 0

    def finish(self) -> dict[str, Any]:
        """Write metrics, summary and telemetry; close the links. Idempotent."""
        if self._finished:
            return {}
        self._finished = True
        m = self.metrics.result()
        m["controller"] = self.info.get("controller", "")
        m["case"] = self.info.get("case", "")
        stats = getattr(self.ap, "allocation_stats", None)
        if stats is not None:
            m["allocation"] = stats
        m["sim_time_s"] = self.gcs.sim_usec * 1e-6
        wall = time.monotonic() - self.t_wall0
        for o in self.observers:
            with contextlib.suppress(Exception):
                o.on_finish(m)
        summary = {
            "steps": self.steps, "sim_time_s": self.gcs.sim_usec * 1e-6, "wall_time_s": wall,
            "wall_in_autopilot_s": self.wall_in_step, "lockstep": self.lockstep,
            "commands_answered": self.gcs.commands_answered,
            "hil_link": self.hil.link.stats.as_dict(), "gcs_links": self.gcs.link_stats(),
            "hil_decode_errors": self.hil.decode_errors,
        }
        if self.step_wall_s:
            w = np.asarray(self.step_wall_s) * 1e6
            summary["step_wall_us"] = {"mean": float(w.mean()), "median": float(np.median(w)),
                                       "p99": float(np.percentile(w, 99))}
            summary["part_mean_us"] = {k: 1e6 * v / len(self.step_wall_s)
                                       for k, v in self.part_wall_s.items()}
        if self.out_dir is not None:
            with contextlib.suppress(OSError):
                (self.out_dir / "metrics.json").write_text(
                    json.dumps(json_safe(m), indent=2))
                (self.out_dir / "autopilot_summary.json").write_text(
                    json.dumps(json_safe(summary), indent=2))
        if self._events_file is not None:
            self._events_file.close()
            self._events_file = None
        drops = self.hil.link.stats.dropped + sum(s["dropped"] for s in self.gcs.link_stats())
        print(f"autopilot: stopped at t = {self.gcs.sim_usec * 1e-6:.3f} s after {self.steps} "
              f"steps, {self.gcs.commands_answered} commands answered; frames dropped "
              f"(garbage/CRC/truncated/...): {drops}", file=self.log, flush=True)
        self.gcs.close()
        self.hil.link.close()
        return m


def _alive(pid: int) -> bool:
    try:
        os.kill(pid, 0)
    except ProcessLookupError:
        return False
    except PermissionError:
        return True
    return True


def _parse_args(argv: list[str] | None) -> argparse.Namespace:
    ap = argparse.ArgumentParser(
        prog="python -m vtolftc.firmware_sim.autopilot.process",
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
                         "require signed arm and fault-injection commands")
    ap.add_argument("--out", type=Path, default=None, help="run folder")
    ap.add_argument("--deterministic", action="store_true",
                    help="no wall-clock time limit in the allocation's QP solver, so that the "
                         "commands do not depend on the CPU load (runs reproduce bit for bit)")
    ap.add_argument("--no-plots", action="store_true",
                    help="no PNG plots in the run folder at the end")
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
    return ap.parse_args(argv)


def _make_autopilot(args: argparse.Namespace) -> tuple[AutopilotAPI, Any]:
    from vtolftc.airframe.loader import load_airframe
    from vtolftc.firmware_sim.autopilot.autopilot import Autopilot

    af = load_airframe(args.airframe) if args.airframe else load_airframe()
    return Autopilot(af, controller=args.controller, gains_dir=args.gains_dir), af


def main(argv: list[str] | None = None) -> int:
    args = _parse_args(argv)
    err = sys.stderr
    try:
        autopilot, af = _make_autopilot(args)
    except Exception as exc:  # bad airframe, unknown controller, missing gains
        print(f"autopilot: error: {exc}", file=err)
        return 2
    if args.deterministic:
        make_deterministic(autopilot)
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
    if args.signing_passphrase:
        signing = SigningConfig.from_passphrase(args.signing_passphrase, allow_unsigned=True)
    urls = ([] if args.no_default_gcs else list(DEFAULT_GCS_LINKS)) + list(args.gcs_link)
    links: list[Link] = []
    try:
        hil = open_link(args.hil_link, system_id=1, component_id=1,
                        allow_remote=args.allow_remote)
        links.append(hil)
        gcs_links = []
        for url in urls:
            gl = open_link(url, system_id=1, component_id=1, signing=signing,
                           allow_remote=args.allow_remote)
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
    proc = AutopilotProcess(
        autopilot, hil, gcs_links, actuators=ActuatorTable.from_names(af.actuator_names),
        lockstep=args.lockstep, hold_ms=args.hold_ms, signing_required=signing is not None,
        out_dir=args.out, info=info, window_start_s=args.window_start,
        vehicle_timeout_s=args.vehicle_timeout, max_wall_s=args.max_wall,
        parent_pid=args.parent_pid)
    proc.spin_s = max(0.0, args.spin_us) * 1e-6
    if args.out is not None:
        for obs in _run_observers(args.out, plots=not args.no_plots):
            proc.add_observer(obs)

    def stop(_sig: int, _frame: Any) -> None:
        proc.running = False

    signal.signal(signal.SIGTERM, stop)
    signal.signal(signal.SIGINT, stop)
    return proc.run()


def make_deterministic(autopilot: Any) -> None:
    """Switch off the OSQP wall-clock ``time_limit`` of the autopilot's QP allocator (if it
    has one): the solver then stops on its tolerances or its iteration cap only, so the same
    inputs give the same commands whatever the machine's load."""
    settings = getattr(getattr(autopilot, "allocator", None), "settings", None)
    if isinstance(settings, dict) and "time_limit" in settings:
        settings["time_limit"] = 1e6  # s: never reached (0 is rejected by OSQP 1.x)


def _run_observers(out: Path, plots: bool = True) -> list[Any]:
    """The run folder of the autopilot's own view (telemetry, events, metrics, plots) and its
    rerun recording ``run.rrd`` (no vehicle truth here: commands, not effective outputs)."""
    from vtolftc.telemetry.recording import RerunRecorder
    from vtolftc.telemetry.runfolder import RunFolderWriter

    return [RunFolderWriter(out, plots=plots), RerunRecorder(out / "run.rrd")]


if __name__ == "__main__":
    sys.exit(main())

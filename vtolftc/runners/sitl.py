"""SITL runner: the vehicle and the autopilot as separate processes, flown by a ground station.

:class:`SitlRun` starts ``python -m vtolftc.runners.processes.vehicle`` and ``python -m
vtolftc.runners.processes.autopilot`` (each in its own process group, output in log files of the
run folder) on free loopback ports, over UDP or zenoh (embedded peers, explicit
``tcp/127.0.0.1`` endpoints, no scouting), connects a :class:`vtolftc.gcs.client.GroundStation` and
flies a :class:`vtolftc.runners.scenario.Scenario` by sending the real MAVLink commands: arming,
NAV_TAKEOFF, DO_VTOL_TRANSITION, and the faults as MAV_CMD_INJECT_PARTIAL_LOSS /
INJECT_FAILURE after setting SYS_FAILURE_EN = 1. The autopilot forwards the faults to the
vehicle process; the controller never sees them.

Timing (lockstep, the default): the ground station is not in the lockstep loop, so a command
sent "when the telemetry says t" would land some steps late, by an amount that depends on the
machine's load. The runner therefore uses the autopilot's simulation hold (parameter
``SIM_HOLD_MS``, see :mod:`vtolftc.firmware_sim.autopilot.gcs_endpoint`): the autopilot starts held
at
t = 0; for each action time T the runner sets SIM_HOLD_MS = T (releasing the previous hold),
waits for the autopilot's ``SIM_HOLD`` notice (NAMED_VALUE_INT) that it stopped before the
control step at T, sends the commands (each acknowledged) and moves on. Commands then act at
exactly the control step at which the in-process runner executes them, and a fault forwarded
to the vehicle arrives before the controls of that step, so it acts from the same physics
step as the in-process ``Vehicle.inject`` (fault magnitudes travel as float32 and are read back
as the decimal they stand for: 0.2, not 0.200000003). The autopilot's inputs are bit-identical
to the in-process run's (same HIL_STATE_QUATERNION encoding, float32 commands both ways), and
the allocator has no wall-clock time limit (its solver stops on its tolerance or iteration cap
only), so every metric is *equal* to the in-process run's, tested over UDP and zenoh, whatever
the machine's load.

Real-time mode (``realtime=True``): no hold; each action is sent when the ground station's
telemetry shows the simulated time has reached it, so it lands tens of milliseconds (a few
control steps) late and the metrics differ slightly from the in-process run.

Readiness: :meth:`SitlRun.start` returns once the autopilot's HEARTBEAT says
MAV_STATE_STANDBY (warm: every compiled path compiled) and, in lockstep with the start hold,
once it holds at t = 0; nothing is assumed from elapsed time.

HIL link: signed (MAVLink 2) with a fresh random key per run, handed to both processes in
their environment (``VTOLFTC_HIL_KEY``), so that no other local process can be pinned by the
vehicle in the autopilot's place (``SitlConfig.hil_signing = False``: unsigned).

Latency knob: ``SitlConfig.hil_delay_ms`` and ``hil_loss`` make the vehicle apply the
autopilot's controls that many milliseconds (simulated time) after they arrived and drop that
fraction of them (seeded), see :mod:`vtolftc.firmware_sim.vehicle.process`.

Stopping: after the last action the hold is set to the scenario's end; once held there, the
autopilot is stopped with SIGTERM (it writes ``metrics.json``), then the vehicle. Ctrl-C or any
error stops both the same way (SIGTERM to the process group, SIGKILL after a grace period);
the run folder is kept.
"""

from __future__ import annotations

import contextlib
import errno
import json
import math
import os
import signal
import subprocess
import sys
import threading
import time
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

from vtolftc.base.jsonio import atomic_write_text, json_safe
from vtolftc.gcs.client import CommandOutcome, GcsError, GroundStation
from vtolftc.protocols.hil_signing import HIL_KEY_ENV, new_hil_key
from vtolftc.protocols.netutil import free_tcp_port, free_udp_port
from vtolftc.runners.processes.procstate import DUMP_SIGNAL, describe_threads

__all__ = ["SitlConfig", "SitlError", "SitlResult", "SitlRun", "run_sitl"]

TRANSPORTS = ("udp", "zenoh")
KILL_WAIT_S = 60.0
"""Wall seconds :meth:`SitlRun.stop` waits for a process to end after its SIGKILL."""


class SitlError(RuntimeError):
    """A SITL run could not start or did not complete (the message says why)."""


class _PortTakenError(SitlError):
    """A port this run chose was bound by someone else before its process bound it."""


START_ATTEMPTS = 3
"""Times :meth:`SitlRun.start` tries, with fresh ports, when a port it chose was taken."""

_IN_USE = ("address already in use", "os error 98")


@dataclass
class SitlConfig:
    """What to fly and how.

    ``duration_s``: simulated seconds; ``out_dir``: run folder (created); ``hold_timeout_s``:
    wall seconds allowed per simulated second between two actions (plus a fixed 60 s).
    """

    case: str = "1"
    controller: str = "gs-shif"
    transport: str = "udp"
    realtime: bool = False
    duration_s: float = 40.0
    out_dir: Path = Path("runs/sitl")
    airframe: Path | None = None
    gains_dir: Path | None = None
    vehicle: str = "ds1"
    startup_timeout_s: float = 120.0
    hold_timeout_s: float = 5.0
    plots: bool = True
    hold_at_start: bool = True
    """Lockstep: start held at t = 0 (needed by :meth:`SitlRun.fly`); False = free-running."""
    failure_injection: bool = True
    """Start the autopilot with SYS_FAILURE_EN = 1."""
    spin_us: float = 0.0
    """Busy-poll time of both processes before sleeping on the HIL link (``--spin-us``)."""
    hil_delay_ms: float = 0.0
    """Injected one-way delay of the controls on the HIL link (ms of simulated time)."""
    hil_loss: float = 0.0
    """Injected loss of the controls on the HIL link (fraction, seeded)."""
    vehicle_timeout_s: float = 30.0
    """Each process stops when the other is silent this long (wall s)."""
    extra_autopilot_args: list[str] = field(default_factory=list)
    extra_vehicle_args: list[str] = field(default_factory=list)
    rt_priority: int = 0
    """``SCHED_FIFO`` priority both processes take once compiled (``--rt-priority``; 0 =
    ordinary scheduling): a loaded machine then cannot starve the real-time loop."""
    autopilot_cpu: int = -1
    """CPU the autopilot process runs on once compiled (``--cpu``; -1 = not pinned)."""
    vehicle_cpu: int = -1
    """CPU the vehicle process runs on once compiled (``--cpu``; -1 = not pinned): with
    ``autopilot_cpu`` on another core, each process keeps its caches between steps (for an
    idle machine, :mod:`vtolftc.runners.processes.affinity`)."""
    trace_steps: int = 0
    """Both processes record a per-step trace of their first N lockstep steps
    (``--trace-steps``; ``<out>/{autopilot,vehicle}/step_trace.npz``; 0 = off)."""
    stop_grace_s: float = 10.0
    """Wall seconds a process gets to end by itself after SIGTERM before the SIGKILL."""
    zenoh_lowlatency: bool = False
    """zenoh: the HIL link (both ends) on zenoh's low-latency unicast transport
    (``lowlatency=1``, :mod:`vtolftc.protocols.zenoh_transport`): the publishing thread writes
    the socket, no TX thread hand-over per sample; ignored over UDP."""
    zenoh_peer_cpu: bool = False
    """zenoh, both processes pinned: each process's zenoh runtime threads on the *other*
    process's CPU (``--zenoh-cpu``, :mod:`vtolftc.runners.processes.affinity`): the socket
    reader wakes on the core the sample was sent from, while that process waits; ignored over
    UDP."""
    hil_signing: bool = True
    """Sign the HIL link with a fresh random key for this run (``VTOLFTC_HIL_KEY`` in both
    processes' environment): only this run's autopilot can be pinned by the vehicle."""


@dataclass
class SitlResult:
    """Metrics (from the autopilot's run folder) and timing of a SITL run."""

    metrics: dict[str, Any]
    sim_time_s: float
    flight_wall_s: float
    out_dir: Path
    outcomes: list[dict[str, Any]] = field(default_factory=list)
    autopilot_summary: dict[str, Any] = field(default_factory=dict)
    vehicle_summary: dict[str, Any] = field(default_factory=dict)

    @property
    def real_time_factor(self) -> float:
        """Simulated seconds per wall second of the flight (start hold to end hold)."""
        return self.sim_time_s / self.flight_wall_s if self.flight_wall_s > 0 else math.inf


def _python() -> str:
    return sys.executable or "python3"


class SitlRun:
    """Two processes and a ground station (see the module docstring). Use as a context
    manager: the processes are always stopped on exit."""

    def __init__(self, config: SitlConfig) -> None:
        if config.transport not in TRANSPORTS:
            raise ValueError(f"transport {config.transport!r}: expected udp or zenoh")
        if config.zenoh_peer_cpu and min(config.autopilot_cpu, config.vehicle_cpu) < 0:
            raise ValueError("zenoh_peer_cpu needs both processes pinned (autopilot_cpu and "
                             "vehicle_cpu)")
        self.cfg = config
        self.out = Path(config.out_dir)
        self.procs: dict[str, subprocess.Popen[bytes]] = {}
        self._logs: list[Any] = []
        self._log_of: dict[str, Any] = {}
        self.gs: GroundStation | None = None
        self._hold_cond = threading.Condition()
        self._hold_ms: int | None = None
        self.urls: dict[str, str] = {}
        self._hil_key = new_hil_key() if config.hil_signing else None

    # ------------------------------------------------------------------ urls
    def _urls(self) -> tuple[str, str, str, str]:
        """(vehicle HIL, autopilot HIL, autopilot GCS, ground station) link URLs."""
        v = self.cfg.vehicle
        if self.cfg.transport == "udp":
            hil, gcs = free_udp_port(), free_udp_port()
            return (f"udp-server://127.0.0.1:{hil}", f"udp-client://127.0.0.1:{hil}",
                    f"udp-client://127.0.0.1:{gcs}", f"udp-server://127.0.0.1:{gcs}")
        hil, gcs = free_tcp_port(), free_tcp_port()
        low = "&lowlatency=1" if self.cfg.zenoh_lowlatency else ""
        return (f"zenoh://{v}/hil/up?listen=tcp/127.0.0.1:{hil}{low}",
                f"zenoh://{v}/hil/down?connect=tcp/127.0.0.1:{hil}{low}",
                f"zenoh://{v}/gcs/up?listen=tcp/127.0.0.1:{gcs}",
                f"zenoh://{v}/gcs/down?connect=tcp/127.0.0.1:{gcs}")

    # ------------------------------------------------------------------ processes
    def _spawn(self, name: str, args: list[str]) -> None:
        log = (self.out / f"{name}.log").open("wb")
        self._logs.append(log)
        self._log_of[name] = log
        env = dict(os.environ)
        env.setdefault("PYTHONUNBUFFERED", "1")
        if self._hil_key is not None:
            env[HIL_KEY_ENV] = self._hil_key
        else:
            env.pop(HIL_KEY_ENV, None)
        self.procs[name] = subprocess.Popen(
            [_python(), *args], stdout=log, stderr=subprocess.STDOUT, stdin=subprocess.DEVNULL,
            start_new_session=True, env=env)

    def _check_alive(self, starting: bool = False) -> None:
        """SitlError if a process has ended (:class:`_PortTakenError` while ``starting``, when it
        ended because a port of its link was in use)."""
        for name, p in self.procs.items():
            rc = p.poll()
            if rc is not None:
                tail = ""
                with contextlib.suppress(OSError):
                    tail = (self.out / f"{name}.log").read_text(errors="replace")[-800:]
                err = _PortTakenError if starting and any(
                    m in tail.lower() for m in _IN_USE) else SitlError
                raise err(f"the {name} process ended early (exit status {rc}); end of "
                          f"{self.out / (name + '.log')}:\n{tail}")

    def start(self) -> None:
        """Start both processes and connect the ground station (autopilot held at t = 0).

        The links' ports are ones the kernel just reported free; one that another program
        binds before this run's process does (a loaded machine running many links) is not an
        error of the run: the processes are stopped, their logs kept as
        ``<name>.attempt<k>.log``, and the start is tried again with fresh ports, at most
        :data:`START_ATTEMPTS` times in all."""
        for attempt in range(1, START_ATTEMPTS + 1):
            try:
                self._start_once()
                return
            except _PortTakenError:
                if attempt == START_ATTEMPTS:
                    raise
                self._undo_start(attempt)

    def _undo_start(self, attempt: int) -> None:
        """Stop what a failed start began; keep its logs beside the next attempt's."""
        self.stop(grace_s=5.0)
        if self.gs is not None:
            self.gs.close()
            self.gs = None
        for f in self._logs:
            with contextlib.suppress(OSError):
                f.close()
        for name in self.procs:
            with contextlib.suppress(OSError):
                (self.out / f"{name}.log").replace(self.out / f"{name}.attempt{attempt}.log")
        self.procs.clear()
        self._logs.clear()
        self._log_of.clear()

    def _start_once(self) -> None:
        cfg = self.cfg
        self.out.mkdir(parents=True, exist_ok=True)
        v_url, a_hil, a_gcs, gs_url = self._urls()
        self.urls = {"vehicle": v_url, "autopilot_hil": a_hil, "autopilot_gcs": a_gcs,
                     "ground_station": gs_url}
        common = []
        if cfg.airframe is not None:
            common += ["--airframe", str(cfg.airframe)]
        mode = ["--realtime"] if cfg.realtime else ["--lockstep"]
        # the ground station first: a udp-server must be bound before the autopilot sends
        if cfg.transport == "udp":
            try:
                self.gs = GroundStation(gs_url)
            except (OSError, GcsError) as e:
                cause = e if isinstance(e, OSError) else e.__cause__
                if getattr(cause, "errno", None) == errno.EADDRINUSE:
                    raise _PortTakenError(f"the ground station's port: {e}") from e
                raise
        common += ["--parent-pid", str(os.getpid())]  # no orphans if this process is killed
        if cfg.spin_us > 0:
            common += ["--spin-us", f"{cfg.spin_us:g}"]
        if cfg.rt_priority:
            common += ["--rt-priority", str(int(cfg.rt_priority))]
        if cfg.trace_steps > 0:
            common += ["--trace-steps", str(int(cfg.trace_steps))]
        latency = []
        if cfg.hil_delay_ms > 0:
            latency += ["--hil-delay-ms", f"{cfg.hil_delay_ms:g}"]
        if cfg.hil_loss > 0:
            latency += ["--hil-loss", f"{cfg.hil_loss:g}"]
        timeout = f"{cfg.vehicle_timeout_s:g}"
        pin = {name: ["--cpu", str(int(n))] if n >= 0 else []
               for name, n in (("vehicle", cfg.vehicle_cpu), ("autopilot", cfg.autopilot_cpu))}
        if cfg.zenoh_peer_cpu and cfg.transport == "zenoh":
            pin["vehicle"] += ["--zenoh-cpu", str(int(cfg.autopilot_cpu))]
            pin["autopilot"] += ["--zenoh-cpu", str(int(cfg.vehicle_cpu))]
        self._spawn("vehicle", ["-m", "vtolftc.runners.processes.vehicle", "--link", v_url,
                                *mode, *common, *pin["vehicle"], "--out",
                                str(self.out / "vehicle"),
                                "--peer-timeout", timeout, "--connect-timeout",
                                str(cfg.startup_timeout_s), *latency,
                                *cfg.extra_vehicle_args])
        ap_args = ["-m", "vtolftc.runners.processes.autopilot", "--hil-link", a_hil,
                   "--gcs-link", a_gcs, "--no-default-gcs", *mode, *common, *pin["autopilot"],
                   "--controller", cfg.controller,
                   "--out", str(self.out / "autopilot"), "--case", str(cfg.case),
                   "--vehicle-timeout", timeout,
                   "--param", f"SYS_FAILURE_EN={1 if cfg.failure_injection else 0}"]
        if not cfg.realtime and cfg.hold_at_start:
            ap_args += ["--hold-ms", "0"]
        if not cfg.plots:
            ap_args.append("--no-plots")
        if cfg.gains_dir is not None:
            ap_args += ["--gains-dir", str(cfg.gains_dir)]
        self._spawn("autopilot", ap_args + list(cfg.extra_autopilot_args))
        if self.gs is None:
            self.gs = GroundStation(gs_url)
        self.gs.add_listener(self._on_message)
        deadline = time.monotonic() + cfg.startup_timeout_s
        while not self.ready():
            self._check_alive(starting=True)
            if time.monotonic() > deadline:
                raise SitlError(f"the autopilot did not report ready (heartbeat, "
                                f"MAV_STATE_STANDBY) within {cfg.startup_timeout_s:g} s "
                                f"(see {self.out}/autopilot.log)")
            time.sleep(0.05)

    def ready(self) -> bool:
        """The autopilot heartbeats and is warm (MAV_STATE_STANDBY or later)."""
        assert self.gs is not None
        s = self.gs.snapshot()
        return s.heartbeat_age_s < 2.0 and s.system_status >= 3

    def _on_message(self, m: Any) -> None:
        if m.get_type() == "NAMED_VALUE_INT":
            name = m.name if isinstance(m.name, str) else m.name.decode(errors="replace")
            if name.rstrip("\x00") == "SIM_HOLD":
                with self._hold_cond:
                    self._hold_ms = int(m.value)
                    self._hold_cond.notify_all()

    def wait_hold(self, t_ms: int, timeout_s: float) -> None:
        """Wait for the autopilot's notice that it holds at ``t_ms``."""
        deadline = time.monotonic() + timeout_s
        with self._hold_cond:
            while self._hold_ms != t_ms:
                self._check_alive()
                left = deadline - time.monotonic()
                if left <= 0:
                    raise SitlError(f"the simulation did not reach t = {t_ms / 1000:g} s within "
                                    f"{timeout_s:g} s (last hold {self._hold_ms} ms)")
                self._hold_cond.wait(min(left, 0.2))

    def hold_at(self, t_ms: int, prev_ms: int) -> None:
        """Release the current hold and wait until the simulation holds at ``t_ms``."""
        assert self.gs is not None
        self.gs.param_set("SIM_HOLD_MS", t_ms)
        budget = 60.0 + self.cfg.hold_timeout_s * max(0, t_ms - prev_ms) / 1000.0
        self.wait_hold(t_ms, budget)

    # ------------------------------------------------------------------ flight
    def fly(self, scenario: Any) -> SitlResult:
        """Fly ``scenario`` (a :class:`vtolftc.runners.scenario.Scenario`) and return the
        metrics."""
        from vtolftc.airframe.loader import load_airframe

        assert self.gs is not None
        cfg = self.cfg
        af = load_airframe(cfg.airframe) if cfg.airframe else load_airframe()
        groups: dict[int, list[Any]] = {}
        for a in sorted(scenario.actions, key=lambda a: a.t_s):
            groups.setdefault(math.ceil(round(a.t_s * 1e6) / 1000), []).append(a)
        end_ms = round(scenario.duration_s * 1000)
        outcomes: list[dict[str, Any]] = []
        if cfg.realtime:
            wall0 = time.monotonic()
            for t_ms, actions in sorted(groups.items()):
                if t_ms >= end_ms:
                    break
                self._wait_sim(t_ms / 1000.0)
                outcomes += self._execute(actions, af, t_ms)
            self._wait_sim(scenario.duration_s)
            flight_wall = time.monotonic() - wall0
        else:
            self.wait_hold(0, cfg.startup_timeout_s)
            wall0 = time.monotonic()
            prev = 0
            for t_ms, actions in sorted(groups.items()):
                if t_ms >= end_ms:
                    break
                if t_ms != prev:
                    self.hold_at(t_ms, prev)
                    prev = t_ms
                outcomes += self._execute(actions, af, t_ms)
            self.hold_at(end_ms, prev)
            flight_wall = time.monotonic() - wall0
        self.stop()
        metrics = _read_json(self.out / "autopilot" / "metrics.json")
        if not metrics:
            raise SitlError(f"the autopilot wrote no metrics (see {self.out}/autopilot.log)")
        result = SitlResult(
            metrics=metrics, sim_time_s=float(metrics.get("sim_time_s", scenario.duration_s)),
            flight_wall_s=flight_wall, out_dir=self.out, outcomes=outcomes,
            autopilot_summary=_read_json(self.out / "autopilot" / "autopilot_summary.json"),
            vehicle_summary=_read_json(self.out / "vehicle" / "vehicle_summary.json"))
        atomic_write_text(self.out / "sitl.json", json.dumps(json_safe({
            "config": {k: str(v) if isinstance(v, Path) else v
                       for k, v in cfg.__dict__.items()},
            "real_time_factor": result.real_time_factor, "flight_wall_s": flight_wall,
            "outcomes": outcomes, "metrics": metrics}), indent=2, default=str))
        return result

    def _wait_sim(self, t_s: float) -> None:
        assert self.gs is not None
        deadline = time.monotonic() + 60.0 + 2.0 * t_s
        while self.gs.snapshot().sim_time_s < t_s:
            self._check_alive()
            if time.monotonic() > deadline:
                raise SitlError(f"simulated time did not reach {t_s:g} s")
            time.sleep(0.002)

    def _execute(self, actions: list[Any], af: Any, t_ms: int) -> list[dict[str, Any]]:
        assert self.gs is not None
        out = []
        for a in actions:
            if a.kind == "command":
                res = self.gs.command_long(a.command_id, list(a.params))
                outs = [res]
            elif a.kind == "fault" and a.fault is not None:
                f = a.fault
                kind = f.kind.value if hasattr(f.kind, "value") else str(f.kind)
                loss = float(f.loss) if kind == "loss" else None
                outs = [self.gs.inject(f.actuator, loss=loss, kind=kind)]
            else:
                continue
            for res in outs:
                out.append({"t_s": t_ms / 1000.0, "label": a.label, "command": res.name,
                            "result": res.result_name, "detail": res.detail})
                if res.result is None:
                    raise SitlError(f"t = {t_ms / 1000:g} s: {a.label}: no COMMAND_ACK")
        return out

    # ------------------------------------------------------------------ stop
    def stop(self, grace_s: float | None = None) -> None:
        """SIGTERM the autopilot (it writes its metrics), then the vehicle; SIGKILL whatever
        is still alive after ``grace_s`` (default ``cfg.stop_grace_s``). Idempotent.

        A process still alive after the grace has what its threads were doing appended to
        its log (``<name>.log``: every thread's Python stack, dumped by the program on
        ``DUMP_SIGNAL``; state, CPU used over half a second, kernel wait channel, kernel stack
        of a thread in uninterruptible sleep or running) before the SIGKILL. A process in
        uninterruptible sleep (an ``fsync`` on a loaded disk, for one) ends only once that I/O
        completes, SIGKILL or not: :class:`SitlError` with the same description if it is
        still there ``KILL_WAIT_S`` after the SIGKILL."""
        grace = self.cfg.stop_grace_s if grace_s is None else grace_s
        for name in ("autopilot", "vehicle"):
            p = self.procs.get(name)
            if p is None or p.poll() is not None:
                continue
            with contextlib.suppress(ProcessLookupError, PermissionError):
                os.killpg(p.pid, signal.SIGTERM)
            try:
                p.wait(timeout=grace)
            except subprocess.TimeoutExpired:
                # its Python stacks into its log (the programs' faulthandler), then its threads
                # as the kernel sees them, sampled over half a second
                self._log_line(name, f"runner: {name} still running {grace:g} s after "
                               f"SIGTERM; its Python stacks (signal {DUMP_SIGNAL.name}):")
                with contextlib.suppress(ProcessLookupError, PermissionError):
                    os.kill(p.pid, DUMP_SIGNAL)
                threads = describe_threads(p.pid, sample_s=0.5)
                self._log_line(name, f"runner: sending {name} SIGKILL; its threads:\n{threads}")
                with contextlib.suppress(ProcessLookupError, PermissionError):
                    os.killpg(p.pid, signal.SIGKILL)
                try:
                    p.wait(timeout=KILL_WAIT_S)
                except subprocess.TimeoutExpired:
                    raise SitlError(f"{name} (pid {p.pid}) still there {KILL_WAIT_S:g} s after "
                                    f"SIGKILL; its threads:\n{describe_threads(p.pid)}") from None

    def _log_line(self, name: str, text: str) -> None:
        """Append ``text`` to ``<name>.log`` (the runner's own lines among the process's)."""
        log = self._log_of.get(name)
        if log is not None:  # the child's stdout: one file offset, shared with the child
            with contextlib.suppress(OSError, ValueError):
                log.write(text.encode() + b"\n")
                log.flush()

    def close(self) -> None:
        """Stop the processes, close the ground station and the log files."""
        try:
            self.stop()
        finally:
            if self.gs is not None:
                self.gs.close()
            for f in self._logs:
                with contextlib.suppress(OSError):
                    f.close()

    def __enter__(self) -> SitlRun:
        return self

    def __exit__(self, *exc: object) -> None:
        self.close()


def _read_json(path: Path) -> dict[str, Any]:
    try:
        return json.loads(path.read_text())
    except (OSError, ValueError):
        return {}


def run_sitl(config: SitlConfig, scenario: Any = None) -> SitlResult:
    """Start, fly (default: ``paper_scenario(case, duration)``) and stop; always cleans up."""
    if scenario is None:
        from vtolftc.runners.scenario import paper_scenario

        scenario = paper_scenario(config.case, config.duration_s)
    with SitlRun(config) as run:
        try:
            run.start()
            return run.fly(scenario)
        except GcsError as exc:
            raise SitlError(f"ground station: {exc}") from exc


def outcome_line(o: CommandOutcome) -> str:
    """One line for a command outcome (CLI output)."""
    return str(o)

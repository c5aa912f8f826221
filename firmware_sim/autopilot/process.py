"""The autopilot as a process: HIL link to the vehicle, MAVLink links to ground stations.

:class:`AutopilotProcess` is the flight software's main loop; the program around it (argument
parsing, links, run folder, recorder, metrics) is :mod:`vtolftc.runners.processes.autopilot`
(``python -m vtolftc.runners.processes.autopilot``), which passes its observers in: this module
imports no runner, no run-folder writer and no viewer.

Threads. The control thread (the caller of :meth:`AutopilotProcess.run`) owns the autopilot and
the HIL link: it drains the vehicle's messages (all of them: it steps on the newest state),
applies at most a few queued ground-station requests per cycle, steps the autopilot on a
HIL_SENSOR / HIL_STATE_QUATERNION pair and answers HIL_ACTUATOR_CONTROLS with
``wire_commands`` of its output, unless the simulation is held (``SIM_HOLD_MS``, lockstep
only). Commands therefore act at the next control step, exactly as in the in-process runner
(:mod:`vtolftc.runners.scenario`). The ground-station links are received, parsed, rate-limited and
answered by the threads of :class:`~vtolftc.firmware_sim.autopilot.gcs_endpoint.GcsEndpoint`:
the control step never waits for a ground station.

Start-up. ``warmup`` (if given) runs first, while the ground-station worker already sends
HEARTBEATs with MAV_STATE_BOOT and refuses arming; it compiles (or loads from numba's cache)
every compiled path, so that the first real-time flight does not stall at the first
allocation (nor later: :func:`~vtolftc.firmware_sim.autopilot.warmup.warm_up` visits every
mode; the specialisations are recorded here and any compiled after this point is reported in
the summary's ``numba`` entry). Then the objects that exist are frozen out of the garbage
collector (``gc.freeze``: a full collection over the compiler's objects would stall a control
step for 0.1-0.26 s). Then the HEARTBEAT says STANDBY and the first HIL-link heartbeat goes
out, on which the vehicle pins this autopilot and starts its clock.

Failsafes (:mod:`vtolftc.firmware_sim.autopilot.failsafe`): checked every control step
(attitude failure, crash) and every 20 ms of wall clock (data-link loss, HIL data loss),
reported by STATUSTEXT and the HEARTBEAT's MAV_STATE, acted on here (land, hold, disarm).

Observers get ``on_start(info)``, ``on_sample`` per step, ``on_event`` and one ``on_finish``
(with the metrics), all from the control thread; events of the ground-station threads are
queued and handed over in the control thread. An observer with ``idle_work()`` (a deferred
rerun recorder) has it called, one piece at a time, while the loop waits for the vehicle and
as long as nothing arrived (it returns whether more remains).

Exit status of :meth:`run`: 0 stopped (:attr:`running` cleared, ``max_wall_s``, parent gone),
3 vehicle lost (``vehicle_timeout_s``).
"""

from __future__ import annotations

import collections
import contextlib
import math
import os
import sys
import time
from collections.abc import Callable, Sequence
from typing import Any, TextIO

from vtolftc.firmware_sim.autopilot.failsafe import FailsafeEvent, FailsafeMonitor
from vtolftc.firmware_sim.autopilot.gcs_endpoint import GcsEndpoint
from vtolftc.firmware_sim.autopilot.hil_bridge import HilBridge
from vtolftc.firmware_sim.autopilot.interface import (
    AutopilotAPI,
    CommandResult,
    FlightMode,
    LandedState,
)
from vtolftc.firmware_sim.autopilot.warmup import (
    compiled_specialisations,
    freeze_heap,
    new_specialisations,
)
from vtolftc.protocols.failure_units import ActuatorTable
from vtolftc.protocols.generated import constants as mav
from vtolftc.protocols.link import Link
from vtolftc.telemetry import TelemetrySample
from vtolftc.telemetry.step_parts import StepParts
from vtolftc.telemetry.streamstats import DurationStats

__all__ = ["EXIT_VEHICLE_LOST", "AutopilotProcess"]

EXIT_VEHICLE_LOST = 3
CMD_NAV_LAND, CMD_DO_SET_MODE, CMD_ARM_DISARM = (mav.MAV_CMD_NAV_LAND, mav.MAV_CMD_DO_SET_MODE,
                                              mav.MAV_CMD_COMPONENT_ARM_DISARM)
CMD_NAV_RTL = mav.MAV_CMD_NAV_RETURN_TO_LAUNCH
FORCE_DISARM = 21196.0
_NAN7 = [math.nan] * 7


class AutopilotProcess:
    """Wires an :class:`AutopilotAPI` to a HIL link and ground-station links.

    Parameters
    ----------
    autopilot
        the flight software.
    hil_link, gcs_links
        the links (owned: closed at the end).
    actuators
        numbering of motors and servos.
    lockstep
        the vehicle waits for every answer (else it runs on the wall clock).
    hold_ms
        initial ``SIM_HOLD_MS``.
    signing_required
        the ground-station links verify signatures.
    observers
        run observers (see the module docstring).
    metrics
        object with ``add(sample)`` and ``result() -> dict`` (or None).
    on_finish
        ``f(metrics, summary)`` called once at the end (writes the files).
    info
        run description for ``on_start``.
    vehicle_timeout_s
        stop (exit 3) after the vehicle was silent this long (0 = never).
    max_wall_s
        stop after this long (0 = never).
    warmup
        called once before the autopilot reports itself ready (compile everything).
    parent_pid
        stop when that process is gone.
    """

    def __init__(self, autopilot: AutopilotAPI, hil_link: Link, gcs_links: list[Link], *,
                 actuators: ActuatorTable, lockstep: bool = True, hold_ms: int = -1,
                 signing_required: bool = False, observers: Sequence[Any] = (),
                 metrics: Any = None,
                 on_finish: Callable[[dict[str, Any], dict[str, Any]], None] | None = None,
                 info: dict[str, Any] | None = None, vehicle_timeout_s: float = 0.0,
                 max_wall_s: float = 0.0, warmup: Callable[[], None] | None = None,
                 log: TextIO | None = None, parent_pid: int | None = None) -> None:
        self.ap = autopilot
        self.parent_pid = parent_pid
        self._next_parent_check = 0.0
        self.spin_s = 0.0
        """Poll this long without sleeping before blocking on the HIL link."""
        self.log = log or sys.stderr
        self.lockstep = lockstep
        self.hil = HilBridge(hil_link, lockstep=lockstep)
        self.info = dict(info or {})
        self.vehicle_timeout_s = vehicle_timeout_s
        self.max_wall_s = max_wall_s
        self.warmup = warmup
        self.observers: list[Any] = list(observers)
        self.metrics = metrics
        self._on_finish = on_finish
        self.events: list[dict[str, Any]] = []
        self._event_q: collections.deque[tuple[int, str, str]] = collections.deque()
        self.failsafe = FailsafeMonitor(autopilot.params, realtime=not lockstep)
        self.gcs = GcsEndpoint(autopilot, self.hil, gcs_links, actuators=actuators,
                               signing_required=signing_required, lockstep=lockstep,
                               hold_ms=hold_ms, on_event=self._event, ready=False)
        self.steps = 0
        self.running = True
        self.vehicle_lost = False
        self.t_wall0 = time.monotonic()
        self.wall_in_step = 0.0
        self.step_wall_s = DurationStats()
        """Wall time of the control steps (autopilot step, status, answer) [s] (bounded
        memory: count, mean, max exact; quantiles to 0.5 %)."""
        self.step_period_s = DurationStats()
        """Wall time between the starts of consecutive control steps [s] (likewise)."""
        self.step_cpu_max_s = 0.0
        """Longest control step in CPU time of the control thread, s (unlike the wall time,
        blind to the scheduler's preemptions on a loaded machine; a compilation shows)."""
        self.step_cpu_s = 0.0
        """CPU time of the control thread in the control steps (autopilot step, status,
        answer), summed [s]: near the wall time, and some 3-5 times the same step's CPU time
        in-process, the code running on caches the other processes emptied while this one
        waited for the vehicle (``benchmarks/bench_sitl.py``)."""
        self.parts = StepParts(("wait_and_read", "autopilot_step", "status_and_answer",
                                "after_answer"))
        """Wall and CPU time per step's part: waiting for the vehicle's next state and reading
        and decoding it (a spin included); ``Autopilot.step``; encoding and sending
        HIL_ACTUATOR_CONTROLS, then the status snapshot; after the answer (metrics,
        observers, failsafe checks, publishing to the ground-station worker), which overlaps
        with the vehicle's work."""
        self.failsafe_events: list[dict[str, Any]] = []
        self._finished = False
        self._sim_usec = 0
        self._held = False
        self._cpu0: float | None = None
        self.compiled_at_ready: dict[str, list[str]] | None = None
        """numba specialisations when the autopilot reported ready (``numba`` in the
        summary lists any compiled after that: there should be none)."""

    def add_observer(self, obs: Any) -> None:
        """Add a run observer (gets ``on_start``, ``on_sample``, ``on_event``, ``on_finish``)."""
        self.observers.append(obs)

    def _event(self, kind: str, text: str) -> None:
        """Any thread: queue an event (handed to the observers by the control thread)."""
        self._event_q.append((self._sim_usec, kind, text))

    def _flush_events(self) -> None:
        q = self._event_q
        while q:
            t, kind, text = q.popleft()
            self.events.append({"time_s": t * 1e-6, "kind": kind, "text": text})
            for o in self.observers:
                with contextlib.suppress(Exception):
                    o.on_event(t, kind, text)

    # ------------------------------------------------------------------ failsafes
    def _apply_failsafe(self, events: list[FailsafeEvent]) -> None:
        gcs, ap = self.gcs, self.ap
        for ev in events:
            gcs.notify(ev.text, ev.severity)
            self._event("failsafe", ev.text)
            self.failsafe_events.append({"time_s": self._sim_usec * 1e-6,
                                         "wall_s": time.monotonic() - self.t_wall0,
                                         "name": ev.name, "text": ev.text,
                                         "action": ev.action})
            print(f"autopilot: failsafe: {ev.text}", file=self.log, flush=True)
            if ev.action == "rtl":  # the navigator's RTL; land where it is refused
                if ap.command(CMD_NAV_RTL, _NAN7) != CommandResult.ACCEPTED:
                    ap.command(CMD_NAV_LAND, _NAN7)
            elif ev.action == "land":
                ap.command(CMD_NAV_LAND, _NAN7)
            elif ev.action == "hold":
                ap.command(CMD_DO_SET_MODE, [1.0, 4.0, 3.0, *_NAN7[:4]])
            elif ev.action == "disarm":
                ap.command(CMD_ARM_DISARM, [0.0, FORCE_DISARM, *_NAN7[:5]])
        gcs.mav_state = self.failsafe.mav_state
        if events:
            gcs.refresh_status()

    def _check_failsafes(self, now: float) -> None:
        st = self.ap.status()
        ev = self.failsafe.check(
            armed=st.armed, in_air=st.armed and st.landed_state != LandedState.ON_GROUND,
            fixed_wing=st.mode in (FlightMode.FIXED_WING, FlightMode.FRONT_TRANSITION),
            hil_age_s=0.0 if self._held else now - (
                self.hil.last_rx_wall if self.lockstep else self.hil.last_step_wall),
            gcs_age_s=now - self.gcs.last_gcs_heartbeat)
        if ev or self.gcs.mav_state != self.failsafe.mav_state:
            self._apply_failsafe(ev)

    # ------------------------------------------------------------------ loop
    def run(self) -> int:
        """Serve until stopped (signal, ``max_wall_s``, lost vehicle). Exit status."""
        hil, gcs, ap = self.hil, self.gcs, self.ap
        try:
            if self.warmup is not None:
                t0 = time.monotonic()
                self.warmup()
                print(f"autopilot: warm in {time.monotonic() - t0:.1f} s", file=self.log,
                      flush=True)
            self.compiled_at_ready = compiled_specialisations()
            freeze_heap()  # a full garbage collection would stall a step 0.1-0.26 s
            gcs.ready = True
            hil.tick(time.monotonic())  # the vehicle pins us on this heartbeat and starts
            for o in self.observers:
                with contextlib.suppress(Exception):
                    o.on_start(self.info)
            return self._loop(hil, gcs, ap)
        finally:
            self.finish()

    def _loop(self, hil: HilBridge, gcs: GcsEndpoint, ap: AutopilotAPI) -> int:
        ever_connected = False
        self._cpu0 = time.process_time()
        pc = time.perf_counter
        parts = self.parts
        next_duty = 0.0
        last_step_start = None
        failsafe = self.failsafe
        armed_of = getattr(ap, "metrics_inputs", None)
        idle = [o.idle_work for o in self.observers if hasattr(o, "idle_work")]
        # Autopilot.metrics_inputs: (mode, armed, ...) without the status snapshot
        while self.running:
            nav = hil.peek()
            hold = gcs.hold_usec() if nav is not None else None
            held = nav is not None and hold is not None and nav.time_usec >= hold
            self._held = held
            if nav is None or held:
                # nothing to step on: wait for the vehicle (or, held, poll the ground
                # stations often: their commands are what the hold waits for)
                parts.start()
                for work in idle:  # observers' deferred work, a piece at a time
                    while hil.peek() is None and work():
                        hil.drain(0.0)
                wait = 0.002 if (held or gcs.has_pending()) else 0.01
                if self.spin_s > 0 and not held:
                    end = pc() + self.spin_s
                    while hil.peek() is None and pc() < end:
                        hil.drain(0.0)
                if hil.peek() is None or held:
                    hil.drain(wait)
                gcs.poll()
                if held:
                    gcs.announce_hold(nav.time_usec)
                elif last_step_start is not None:
                    parts.lap("wait_and_read")
            else:
                ever_connected = True
                gcs.poll()  # commands that arrived meanwhile act at this step
                if gcs.hold_usec() is None or nav.time_usec < gcs.hold_usec():
                    hil.take()
                    t0, c0 = parts.start()
                    if last_step_start is not None:
                        self.step_period_s.add(t0 - last_step_start)
                    last_step_start = t0
                    u = ap.step(nav)
                    parts.lap("autopilot_step")
                    # answer first: the armed flag without building the status snapshot
                    # (made right after the send, from the same unchanged state)
                    armed = (armed_of(nav)[1] if armed_of is not None
                             else ap.status().armed)
                    hil.send_controls(nav.time_usec, u, armed)
                    st = ap.status()
                    t2, c2 = parts.lap("status_and_answer")
                    cpu = c2 - c0
                    self.step_cpu_s += cpu
                    if cpu > self.step_cpu_max_s:
                        self.step_cpu_max_s = cpu
                    dt = t2 - t0
                    self.wall_in_step += dt
                    self.step_wall_s.add(dt)
                    self._sim_usec = int(nav.time_usec)
                    # the rest overlaps with the vehicle's physics step
                    sample = TelemetrySample(nav.time_usec, nav, st, None)
                    if self.metrics is not None:
                        self.metrics.add(sample)
                    for o in self.observers:
                        o.on_sample(sample)
                    fs = failsafe.on_step(nav, st)
                    if fs:
                        self._apply_failsafe(fs)
                        st = ap.status()
                    gcs.on_step(nav, st)
                    self.steps += 1
                    parts.end_step("after_answer", nav.time_usec)
                # (no read here: the next pass reads what came meanwhile, one select and
                # one read when the vehicle's next step is there)
            now = time.monotonic()
            if now < next_duty:
                continue
            stalled = now - next_duty > 0.25  # this process did not run: ages are stale
            next_duty = now + 0.02
            hil.tick(now)
            self._flush_events()
            if not stalled:
                self._check_failsafes(now)
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
        return EXIT_VEHICLE_LOST if self.vehicle_lost else 0

    def summary(self) -> dict[str, Any]:
        """Counters and timing of the run so far (``autopilot_summary.json``)."""
        wall = time.monotonic() - self.t_wall0
        out: dict[str, Any] = {
            "steps": self.steps, "sim_time_s": self._sim_usec * 1e-6, "wall_time_s": wall,
            "wall_in_autopilot_s": self.wall_in_step, "lockstep": self.lockstep,
            "commands_answered": self.gcs.commands_answered,
            "hil_link": self.hil.link.stats.as_dict(), "gcs_links": self.gcs.link_stats(),
            "hil_decode_errors": self.hil.decode_errors,
            "hil_steps_superseded": self.hil.superseded,
            "failsafe_events": list(self.failsafe_events),
        }
        if self._cpu0 is not None and self.steps:
            # CPU time of the whole process (every thread) in the loop, per control step: far
            # less sensitive than the wall times to the other processes of a loaded machine
            out["cpu_per_step_us"] = 1e6 * (time.process_time() - self._cpu0) / self.steps
        if self.step_wall_s.n:
            out["step_wall_us"] = self.step_wall_s.summary(1e6)
            out["step_cpu_max_ms"] = self.step_cpu_max_s * 1e3
            out["step_cpu_mean_us"] = 1e6 * self.step_cpu_s / self.step_wall_s.n
            out.update(self.parts.summary(self.step_wall_s.n))
        if self.compiled_at_ready is not None:
            now = compiled_specialisations()
            out["numba"] = {
                "specialisations_at_ready": sum(map(len, self.compiled_at_ready.values())),
                "specialisations_at_end": sum(map(len, now.values())),
                "compiled_after_ready": new_specialisations(self.compiled_at_ready, now)}
        if self.step_period_s.n:
            out["step_period_ms"] = self.step_period_s.summary(1e3)
        return out

    def finish(self) -> dict[str, Any]:
        """Metrics and summary to the observers and ``on_finish``; close the links.
        Idempotent."""
        if self._finished:
            return {}
        self._finished = True
        self._flush_events()
        m: dict[str, Any] = {}
        if self.metrics is not None:
            with contextlib.suppress(Exception):
                m = dict(self.metrics.result())
        m["controller"] = self.info.get("controller", "")
        m["case"] = self.info.get("case", "")
        stats = getattr(self.ap, "allocation_stats", None)
        if stats is not None:
            m["allocation"] = stats
        steps = getattr(self.metrics, "n", 0)
        if hasattr(self.ap, "saturated_steps") and steps:
            # the in-process runner's figure: share of the metrics' steps with a saturated QP
            m["allocation_saturated_share"] = self.ap.saturated_steps / steps
        m["sim_time_s"] = self._sim_usec * 1e-6
        m["failsafes"] = [e["text"] for e in self.failsafe_events]
        summary = self.summary()
        late = summary.get("numba", {}).get("compiled_after_ready")
        if late:
            print(f"autopilot: numba compiled after ready (a stall in flight): {late}",
                  file=self.log, flush=True)
        for o in self.observers:
            with contextlib.suppress(Exception):
                o.on_finish(m)
        if self._on_finish is not None:
            with contextlib.suppress(Exception):
                self._on_finish(m, summary)
        drops = self.hil.link.stats.dropped + sum(s["dropped"] for s in self.gcs.link_stats())
        print(f"autopilot: stopped at t = {self._sim_usec * 1e-6:.3f} s after {self.steps} "
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

"""Scenarios and the in-process runner (above both the vehicle and the autopilot).

A :class:`Scenario` is a list of timed :class:`Action` s: MAVLink commands as a ground station
sends them (command id and seven params) and fault injections into the vehicle. The same
scenario is replayed by the in-process runner (:func:`run_scenario`) and by the SITL runner
through a ground station, so both fly the very same timeline.

:func:`paper_scenario` is the paper's timeline (section 5): start on the ground at home,
disarmed; t = 1 s arm and take off to 30 m; t = 20 s DO_VTOL_TRANSITION to fixed-wing;
t = 22 s the case's faults (``fault_cases.toml``) injected into the vehicle; end at 40 s.

The in-process runner is deterministic: vehicle at 1 kHz (RK4), autopilot at 250 Hz (4
physics steps per control step), the autopilot fed ``decode_hil_state(encode_hil_state(...))``
(fused into one call, ``HilRoundTrip``) of the vehicle truth (bit-identical to what it
receives over MAVLink HIL_STATE_QUATERNION),
its output rounded as ``wire_commands`` rounds it (float32) before the vehicle (inside the
vehicle's compiled step, ``Vehicle.step(..., wire=True)``, ``wire_round``): the very
arithmetic of the SITL processes (:mod:`vtolftc.protocols.hil`). ``hil_delay_s`` adds a one-way
transport delay on the HIL state path: the autopilot gets the state of
ceil(hil_delay_s x control rate) control steps earlier (a FIFO; 25 ms at 250 Hz = 7 steps =
28 ms; the first steps of the run see the oldest state there is; telemetry and metrics keep
the current state). Actions due at a control step are executed before that step's
``Autopilot.step``.

Without observers, state noise or HIL delay, what a step does after ``Autopilot.step`` is
one compiled call (:func:`~vtolftc.runners.inproc_kernel.runner_tail_step`): the metrics'
sample, the vehicle's physics steps and the next step's HIL round trip, the same kernels in
the same order (so ``RunResult.timing_s``' ``physics`` then holds the metrics and the round
trip too, and ``encode_decode`` only what is left of it).
"""

from __future__ import annotations

import contextlib
import math
import time
from collections import deque
from collections.abc import Callable, Iterable, Mapping, Sequence
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import numpy as np

from vtolftc.airframe.loader import Airframe, load_airframe
from vtolftc.firmware_sim.autopilot.autopilot import (
    CMD_COMPONENT_ARM_DISARM,
    CMD_DO_VTOL_TRANSITION,
    CMD_NAV_TAKEOFF,
    Autopilot,
)
from vtolftc.firmware_sim.autopilot.interface import (
    CommandResult,
    NavState,
)
from vtolftc.firmware_sim.vehicle.faults import Fault, case_description, case_faults
from vtolftc.firmware_sim.vehicle.model import Vehicle
from vtolftc.firmware_sim.vehicle.sensors import Home
from vtolftc.protocols.hil import HilRoundTrip, nav_of_round_trip
from vtolftc.runners.inproc_kernel import runner_tail_step
from vtolftc.telemetry import RunObserver, TelemetrySample, VehicleTruth
from vtolftc.telemetry.metrics import MetricsAccumulator

__all__ = [
    "Action",
    "RunResult",
    "Scenario",
    "paper_scenario",
    "run_scenario",
]

NAN = float("nan")


@dataclass(frozen=True)
class Action:
    """One timed action of a scenario.

    ``kind`` ``"command"``: a COMMAND_LONG ``command_id`` with ``params`` (7 floats, NaN =
    default) sent to the autopilot. ``kind`` ``"fault"``: ``fault`` injected into the vehicle
    (its own ``start_s`` says when it acts; normally equal to ``t_s``).
    """

    t_s: float
    kind: str
    label: str
    command_id: int = 0
    params: tuple[float, ...] = ()
    fault: Fault | None = None

    @property
    def t_usec(self) -> int:
        """Action time in simulated time (us)."""
        return round(self.t_s * 1e6)


@dataclass(frozen=True)
class Scenario:
    """A named, timed list of actions and a duration [s of simulated time]."""

    name: str
    case: str
    duration_s: float
    actions: tuple[Action, ...]
    description: str = ""
    transition_start_s: float = 20.0
    window_start_s: float | None = None  # metrics window start; None: transition_start_s

    @property
    def faults(self) -> list[Fault]:
        """The fault actions' faults, in scenario order."""
        return [a.fault for a in self.actions if a.fault is not None]


def _cmd(t: float, label: str, cid: int, *params: float) -> Action:
    p = tuple(float(x) for x in params) + (NAN,) * (7 - len(params))
    return Action(t, "command", label, command_id=cid, params=p)


def paper_scenario(case: int | str = 1, duration_s: float = 40.0, *,
                   airframe: Airframe | None = None, extra_faults: Iterable[Fault] = (),
                   takeoff_alt_m: float = 30.0, arm_s: float = 1.0,
                   transition_s: float = 20.0, window_start_s: float | None = None,
                   ) -> Scenario:
    """The paper's timeline for fault case ``case`` (0 = nominal, 1, 2), see module docstring.

    ``extra_faults`` are added (each injected at its own start time). The takeoff altitude is
    sent as NAV_TAKEOFF param7 AMSL, as PX4 reads it: the vehicle's home altitude
    (:class:`~vtolftc.firmware_sim.vehicle.sensors.Home`) plus ``takeoff_alt_m``. The metrics'
    window starts at ``window_start_s`` (default: the transition command).
    """
    af = airframe if airframe is not None else load_airframe()
    if not (math.isfinite(duration_s) and duration_s > 0):
        raise ValueError(f"duration {duration_s!r}: expected a positive number of seconds")
    faults = list(case_faults(case, af.actuator_names)) + list(extra_faults)
    actions = [
        _cmd(arm_s, "arm", CMD_COMPONENT_ARM_DISARM, 1.0, 0.0),
        _cmd(arm_s, f"takeoff to {takeoff_alt_m:g} m", CMD_NAV_TAKEOFF,
             NAN, NAN, NAN, NAN, NAN, NAN, Home().alt_m + takeoff_alt_m),
        _cmd(transition_s, "transition to fixed-wing", CMD_DO_VTOL_TRANSITION, 4.0, 0.0),
    ]
    actions += [Action(f.start_s, "fault", f"fault {f.describe()}", fault=f) for f in faults]
    actions.sort(key=lambda a: a.t_s)  # stable: commands at equal times keep their order
    key = str(case).removeprefix("case")
    return Scenario(name=f"case{key}", case=key, duration_s=float(duration_s),
                    actions=tuple(actions), description=case_description(key),
                    transition_start_s=transition_s, window_start_s=window_start_s)


@dataclass
class RunResult:
    """What a run produced: metrics, events and timing."""

    metrics: dict[str, Any]
    events: list[tuple[int, str, str]] = field(default_factory=list)
    wall_time_s: float = 0.0
    sim_time_s: float = 0.0
    interrupted: bool = False
    timing_s: dict[str, float] = field(default_factory=dict)
    allocation: dict[str, Any] = field(default_factory=dict)

    @property
    def real_time_factor(self) -> float:
        """Simulated over wall-clock time (inf for a zero wall time)."""
        return self.sim_time_s / self.wall_time_s if self.wall_time_s > 0 else math.inf


def _run_due_actions(actions: Sequence[Action], act_usec: Sequence[int], i: int, now: int,
                     ap: Autopilot, veh: Vehicle,
                     event: Callable[[int, str, str], None]) -> int:
    """Execute ``actions[i:]`` due at ``now`` [us] (``act_usec``: their times [us]) on the
    autopilot (commands) and the vehicle (faults), each reported through ``event``; returns
    the index of the first action not yet due."""
    while i < len(actions) and act_usec[i] <= now:
        a = actions[i]
        i += 1
        if a.kind == "command":
            res = ap.command(a.command_id, a.params)
            event(now, "command", f"{a.label}: command {a.command_id} -> "
                  f"{CommandResult(res).name}")
        elif a.kind == "fault" and a.fault is not None:
            veh.inject(a.fault)
            event(now, "fault", f"injected {a.fault.describe()}")
    return i


def _observe(now: int, nav: NavState, ap: Autopilot, veh: Vehicle, acc: MetricsAccumulator,
             obs: Sequence[RunObserver]) -> bool:
    """The step's :class:`TelemetrySample` (the autopilot's status, the vehicle's truth) to
    the metrics and every observer; returns :attr:`MetricsAccumulator.crashed`."""
    x = veh.x
    truth = VehicleTruth(x[0:3].copy(), x[3:6].copy(), x[6:10].copy(),
                         np.array(veh.euler_rad), x[10:13].copy(), float(veh.fm[6]),
                         veh.actuator_positions, veh.effectiveness)
    sample = TelemetrySample(now, nav, ap.status(), truth)
    acc.add(sample)
    for o in obs:
        o.on_sample(sample)
    return acc.crashed


def run_scenario(scenario: Scenario, controller: str = "gs-shif", *,
                 airframe: Airframe | None = None, gains_dir: str | Path | None = None,
                 observers: Sequence[RunObserver] = (), physics_hz: int = 1000,
                 control_hz: int = 250, stop_on_crash: bool = True,
                 autopilot_setup: Callable[[Autopilot], None] | None = None,
                 info: dict[str, Any] | None = None,
                 vehicle_options: Mapping[str, Any] | None = None,
                 hil_delay_s: float = 0.0) -> RunResult:
    """Fly ``scenario`` in-process with ``controller``; see the module docstring.

    Observers get ``on_start``, every sample, every event and exactly one ``on_finish``
    (also on Ctrl-C, which is re-raised after the observers have finished). With
    ``stop_on_crash`` the run ends at the first crashed sample. ``autopilot_setup`` may
    change parameters before the flight. ``RunResult.timing_s`` holds the
    wall time of each part (physics, encode/decode, autopilot, observers).
    ``vehicle_options`` are passed to :class:`Vehicle` (``perturbation``, ``wind``,
    ``state_noise``, ``seed``): the physical vehicle and its environment, never the
    autopilot's airframe (passive FTC). With ``state_noise`` the autopilot is fed the
    vehicle's noisy :meth:`Vehicle.estimated_state` (and the metrics, computed from what the
    autopilot flew on, see that too).
    """
    af = airframe if airframe is not None else load_airframe()
    if physics_hz % control_hz:
        raise ValueError(f"physics rate {physics_hz} Hz is not a multiple of the control "
                         f"rate {control_hz} Hz")
    n_sub = physics_hz // control_hz
    if not (math.isfinite(hil_delay_s) and 0.0 <= hil_delay_s <= 1.0):
        raise ValueError(f"HIL delay {hil_delay_s!r} s: expected 0 .. 1 s")
    n_delay = math.ceil(hil_delay_s * control_hz - 1e-9) if hil_delay_s > 0 else 0
    fifo: deque[NavState] = deque()
    ap = Autopilot(af, controller=controller, gains_dir=gains_dir, dt_s=1.0 / control_hz)
    if autopilot_setup is not None:
        autopilot_setup(ap)
    veh = Vehicle(af, dt_usec=1_000_000 // physics_hz, **dict(vehicle_options or {}))
    noisy = veh.state_noise is not None
    home = veh.sensor_model.home
    home_lat, home_lon, home_alt = float(home.lat_deg), float(home.lon_deg), float(home.alt_m)
    ap.set_home(home_lat, home_lon, home_alt)
    round_trip = HilRoundTrip(home_lat, home_lon, home_alt)
    acc = MetricsAccumulator(window_start_s=scenario.transition_start_s
                             if scenario.window_start_s is None else scenario.window_start_s)
    result = RunResult(metrics={})
    obs = list(observers)

    def event(t_usec: int, kind: str, text: str) -> None:
        result.events.append((t_usec, kind, text))
        for o in obs:
            o.on_event(t_usec, kind, text)

    start_info = {
        "airframe": af.name, "airframe_sha256": af.sha256,
        "actuator_names": list(af.actuator_names), "controller": controller,
        "case": scenario.case, "scenario": scenario.name, "duration_s": scenario.duration_s,
        "description": scenario.description, "physics_hz": physics_hz,
        "control_hz": control_hz, "gains_file": str(ap.attitude.gains_path),
        "hil_delay_s": n_delay / control_hz,
        "gains_sha256": ap.attitude.gains_sha256,
    }
    if info:
        start_info.update(info)
    for o in obs:
        o.on_start(start_info)

    actions = sorted(scenario.actions, key=lambda a: a.t_s)
    i_act = 0
    # the next action's time [us] (Action.t_usec, computed once, not every step)
    act_usec = [a.t_usec for a in actions]
    next_usec = act_usec[0] if act_usec else None
    n_steps = round(scenario.duration_s * control_hz)
    t_phys = t_enc = t_ap = t_obs = 0.0
    pc = time.perf_counter
    # the metrics' sample, the vehicle's step and the next step's HIL round trip in one
    # compiled call (runner_tail_step) when nothing else needs the state between them
    fuse = not obs and not noisy and not n_delay
    nav_next: NavState | None = None  # the fused call's round trip, for the next step
    # the fused call's decoded states: two buffers written in turn, each with its NavState
    # views made once (nav_of_round_trip). The one written is never the current step's,
    # the only one the autopilot still holds then (as its estimate's last_nav: the call is
    # made only when the autopilot flew on this step's nav); a fresh NavState each step
    ring = [np.empty(14), np.empty(14)]
    ring_views = [(t.q_wxyz, t.omega_body_rad_s, t.pos_ned_m, t.vel_ned_m_s)
                  for t in (nav_of_round_trip(0, b, 0.0) for b in ring)]
    slot = 0
    wall0 = pc()
    n_events = 0
    try:
        for _ in range(n_steps):
            now = veh.time_usec
            if next_usec is not None and next_usec <= now:
                i_act = _run_due_actions(actions, act_usec, i_act, now, ap, veh, event)
                next_usec = act_usec[i_act] if i_act < len(act_usec) else None
            t0 = pc()
            x = veh.x
            if nav_next is not None:  # computed by the last step's fused call
                nav = nav_next
                nav_next = None
            else:
                if noisy:
                    xe, air = veh.estimated_state()
                else:
                    xe, air = x, float(veh.fm[6])
                # exactly decode_hil_state(encode_hil_state(...)): what a SITL autopilot
                # receives
                nav = round_trip(now, xe, air)
            nav_ap = nav
            if n_delay:  # the autopilot sees the delayed state, telemetry the current one
                fifo.append(nav)
                nav_ap = fifo.popleft() if len(fifo) > n_delay else fifo[0]
            t1 = pc()
            u = ap.step(nav_ap)
            t2 = pc()
            log = ap.commander.event_log  # (ap.event_log, without the delegation's call)
            while n_events < len(log):
                te, text = log[n_events]
                n_events += 1
                warn = "quad-chute" in text or "denied" in text or "forced" in text
                event(te, "warning" if warn else "mode", text)
            if obs:
                crashed = _observe(now, nav, ap, veh, acc, obs)
                t3 = pc()
                veh.step(u, n_sub, wire=True)  # the commands as wire_commands(u) carries them
            else:  # nobody reads the status: the metrics take its fields directly
                mode, armed, ref, alt_ref, euler = ap.metrics_inputs(nav)
                args = veh.control_step_args(u) if fuse and euler is not None else None
                r = 0
                if args is not None:  # the metrics, the vehicle, the next round trip: one call
                    t3 = t2
                    s_m, tail = acc.kernel_arrays
                    slot ^= 1
                    a = ring[slot]
                    r = runner_tail_step(s_m, tail, now, nav.pos_ned_m, *euler, int(mode),
                                         armed, ref, alt_ref, nav.airspeed_m_s, u, args[0],
                                         args[1], n_sub, args[2], args[3], args[4], args[5],
                                         round_trip.kernel_home, a)
                    if 0 < r < 3:  # flown
                        veh.time_usec += n_sub * veh.dt_usec
                        crashed = r == 2
                        air_cm_s = a.item(13)
                        if air_cm_s >= 0:  # else the next step's round_trip raises the error
                            # nav_of_round_trip(veh.time_usec, a, air_cm_s), on the
                            # buffer's views
                            nq, nw, npos, nvel = ring_views[slot]
                            nav_next = NavState(int(veh.time_usec), nq, nw, npos, nvel,
                                                air_cm_s * 0.01)
                    elif r:  # non-finite commands, nothing flown: the vehicle raises its error
                        veh.step(u, n_sub, wire=True)
                if not r:  # the separate calls (not fused, or the metrics' tail ring is full)
                    crashed = acc.add_step(now, nav, mode, armed, ref, alt_ref, euler)
                    t3 = pc()
                    veh.step(u, n_sub, wire=True)  # the commands as wire_commands(u) carries
            t4 = pc()
            t_enc += t1 - t0
            t_ap += t2 - t1
            t_obs += t3 - t2
            t_phys += t4 - t3
            if stop_on_crash and crashed:
                event(now, "warning", f"crash detected at t = {now * 1e-6:.2f} s: run stopped")
                break
    except KeyboardInterrupt:
        result.interrupted = True
    finally:
        result.wall_time_s = pc() - wall0
        result.sim_time_s = veh.time_usec * 1e-6
        m = acc.result()
        m["controller"] = controller
        m["case"] = scenario.case
        m["allocation"] = ap.allocation_stats
        m["allocation_saturated_share"] = ap.saturated_steps / max(acc.n, 1)
        if result.interrupted:
            m["interrupted"] = True
        result.metrics = m
        result.allocation = ap.allocation_stats
        result.timing_s = {"physics": t_phys, "encode_decode": t_enc, "autopilot": t_ap,
                           "observers": t_obs, "total": result.wall_time_s}
        for o in obs:
            # observers must not raise; never lose the others' output
            with contextlib.suppress(Exception):
                o.on_finish(m)
    if result.interrupted:
        raise KeyboardInterrupt
    return result

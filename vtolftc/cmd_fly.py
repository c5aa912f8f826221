"""``vtolftc fly`` and ``vtolftc compare``: the paper's cases flown in-process.

``vtolftc fly --case 1 --controller gs-shif`` flies one case and writes a run folder;
``vtolftc compare --case 1`` flies the three controllers and prints a table like the paper's
table 4 (RMSE of altitude and attitude tracking over the transition window), with bar charts
like figs 13/14 in the output folder.

Stopping: Ctrl-C (SIGINT) and SIGTERM only set a flag, which the run checks between control
steps (never inside compiled code): the run stops at the next step, every observer finishes
(``metrics.json`` with ``"interrupted": true``, telemetry, ``run.rrd``), one line is printed and
the exit status is 130. An existing ``--out`` folder is refused (exit 2) unless ``--overwrite``
is given, which first removes the old run folder (only a folder that holds a previous run, or
an empty one), so stale files of an earlier run are never mixed in; an ``--out`` that cannot
be created is one line and exit 2.
"""

from __future__ import annotations

import argparse
import contextlib
import json
import math
import shutil
import signal
import threading
from collections.abc import Iterator
from pathlib import Path
from typing import Any

from vtolftc.errors import UsageError

CONTROLLER_NAMES = ("gs-shif", "shif", "lqr")
_PAPER_TABLE4 = {
    "1": {"lqr": (0.2997, 4.7117, 1.432, 6.6718), "shif": (0.2817, 1.2638, 0.6627, 1.683),
          "gs-shif": (0.2812, 0.5411, 0.4223, 1.6551)},
    "2": {"lqr": (0.2761, 3.1536, 2.9905, 3.9939), "shif": (0.2744, 1.0816, 1.2335, 1.3610),
          "gs-shif": (0.2758, 0.1921, 0.6891, 0.9096)},
}


class _StopRequest:
    """Run observer that ends a run at the next control step once a stop signal came (raises
    KeyboardInterrupt from Python code, which the runner turns into an interrupted run)."""

    requested: bool = False

    def on_start(self, info: dict[str, Any]) -> None:
        """Nothing to do."""

    def on_sample(self, sample: Any) -> None:
        if _StopRequest.requested:
            raise KeyboardInterrupt

    def on_event(self, time_usec: int, kind: str, text: str) -> None:
        """Nothing to do."""

    def on_finish(self, metrics: dict[str, Any]) -> None:
        """Nothing to do."""


@contextlib.contextmanager
def _stop_on_signals() -> Iterator[None]:
    """SIGINT and SIGTERM set :attr:`_StopRequest.requested` (restored afterwards)."""
    def handler(_sig: int, _frame: Any) -> None:
        _StopRequest.requested = True

    _StopRequest.requested = False
    if threading.current_thread() is not threading.main_thread():
        yield  # signals are delivered to the main thread only
        return
    old = {sig: signal.signal(sig, handler) for sig in (signal.SIGINT, signal.SIGTERM)}
    try:
        yield
    finally:
        for sig, h in old.items():
            signal.signal(sig, h)
        if _StopRequest.requested:
            _StopRequest.requested = False
            raise KeyboardInterrupt


def prepare_out(path: Path, overwrite: bool, marker: tuple[str, ...] = ("run.json",)) -> Path:
    """Create the output folder; an existing one only with ``overwrite`` (then emptied first,
    if it holds a previous run or nothing). Raises UsageError with one line otherwise."""

    path = Path(path)
    if path.exists():
        if not path.is_dir():
            raise UsageError(f"--out {path}: exists and is not a folder; choose another path")
        if any(path.iterdir()):
            if not overwrite:
                raise UsageError(f"--out {path}: already exists; choose another folder or "
                                 "pass --overwrite to replace that run")
            if not any((path / m).exists() for m in marker):
                raise UsageError(f"--out {path}: exists and holds no vtol-ftc run; "
                                 "refusing to delete it, choose another folder")
            try:
                shutil.rmtree(path)
            except OSError as exc:
                raise UsageError(f"--out {path}: cannot remove the old run: "
                                 f"{exc.strerror or exc}") from None
    try:
        path.mkdir(parents=True, exist_ok=True)
        probe = path / ".write-test"
        probe.write_text("")
        probe.unlink()
    except OSError as exc:
        raise UsageError(f"--out {path}: cannot create or write it: "
                         f"{exc.strerror or exc}") from None
    return path


def default_observers(run_dir: Path, args: argparse.Namespace) -> list[Any]:
    """The observers of a run: the run-folder writer (telemetry, events, metrics, plots), the
    autopilot's PX4 ULog ``flight.ulg`` (bound to the autopilot by :func:`_bind_autopilot`),
    the rerun recorder (``run.rrd`` always; a live viewer too with ``--rerun``), after the
    stop-signal check, and the progress lines (``--progress``)."""
    from vtolftc.firmware_sim.autopilot.ulog import ULogWriter
    from vtolftc.telemetry.recording import RerunRecorder
    from vtolftc.telemetry.runfolder import RunFolderWriter

    obs: list[Any] = [_StopRequest(),
                      RunFolderWriter(run_dir, plots=not getattr(args, "no_plots", False)),
                      ULogWriter(run_dir / "flight.ulg"),
                      RerunRecorder(run_dir / "run.rrd",
                                    live=bool(getattr(args, "rerun", False)))]
    every = float(getattr(args, "progress", 0.0) or 0.0)
    if every > 0:
        obs.append(_Progress(every))
    return obs


def _bind_autopilot(observers: list[Any]) -> Any:
    """``autopilot_setup`` for :func:`~vtolftc.scenario.run_scenario` that hands the run's
    autopilot to the observers that read it (the ULog writer: parameters, mission, rates)."""
    def setup(ap: Any) -> None:
        for obs in observers:
            bind = getattr(obs, "bind", None)
            if bind is not None:
                bind(ap)

    return setup


class _Progress:
    """Run observer printing ``t = <s> s <mode> altitude <m> m airspeed <m/s>`` to stdout
    (flushed) every ``every_s`` of simulated time: how far the flight got."""

    def __init__(self, every_s: float) -> None:
        self._period = max(1, round(every_s * 1e6))
        self._next = 0

    def on_start(self, info: dict[str, Any]) -> None:
        """Nothing to do."""

    def on_sample(self, sample: Any) -> None:
        t = int(sample.time_usec)
        if t < self._next:
            return
        self._next = t + self._period
        st = sample.status
        print(f"  t = {t * 1e-6:.2f} s  {st.mode.name}  altitude "
              f"{-float(sample.nav.pos_ned_m[2]):.1f} m  airspeed "
              f"{float(sample.nav.airspeed_m_s):.1f} m/s", flush=True)

    def on_event(self, time_usec: int, kind: str, text: str) -> None:
        """Nothing to do."""

    def on_finish(self, metrics: dict[str, Any]) -> None:
        """Nothing to do."""


def _keep_viewer(observers: list[Any]) -> None:
    """With ``--rerun`` and no display, keep the web viewer serving until Ctrl-C (a no-op
    when a native viewer was spawned)."""
    for obs in observers:
        wait = getattr(obs, "wait_viewer", None)
        if wait is not None:
            wait()


def _check_common(args: argparse.Namespace) -> None:

    if not (math.isfinite(args.duration) and 0.0 < args.duration <= 3600.0):
        raise UsageError(f"--duration {args.duration!r}: expected seconds in (0, 3600]")
    every = getattr(args, "progress", 0.0)
    if not (math.isfinite(every) and 0.0 <= every <= 3600.0):
        raise UsageError(f"--progress {every!r}: expected simulated seconds in [0, 3600] "
                         "(0: off)")
    delay = getattr(args, "hil_delay_ms", 0.0)
    if not (math.isfinite(delay) and 0.0 <= delay <= 1000.0):
        raise UsageError(f"--hil-delay-ms {delay!r}: expected milliseconds in [0, 1000]")
    if args.gains is not None and not Path(args.gains).is_dir():
        raise UsageError(f"--gains {args.gains}: not a directory (expected one holding "
                         "gs-shif.json, shif.json and lqr.json)")


def _fly_one(case: str, controller: str, args: argparse.Namespace, run_dir: Path,
             extra_faults: list[Any]) -> Any:
    from vtolftc.firmware_sim.vehicle.flyable import load_flyable_airframe
    from vtolftc.scenario import paper_scenario, run_scenario

    af = load_flyable_airframe(getattr(args, "airframe", None))
    scen = paper_scenario(case, args.duration, airframe=af, extra_faults=extra_faults,
                          window_start_s=getattr(args, "window_start", None))
    _check_controller(controller, args)
    vopts = _vehicle_options(args)
    info = {"seed": getattr(args, "noise_seed", 0),
            "max_deflection_deg": math.degrees(af.surfaces.max_deflection_rad),
            "vehicle": {k: repr(v) for k, v in vopts.items()},
            "faults": [f.describe() for f in scen.faults],
            "actions": [{"t_s": a.t_s, "kind": a.kind, "label": a.label,
                         "command_id": a.command_id, "params": list(a.params)}
                        for a in scen.actions]}
    observers = default_observers(run_dir, args)
    res = run_scenario(scen, controller, airframe=af, gains_dir=args.gains,
                       observers=observers, info=info, vehicle_options=vopts,
                       hil_delay_s=getattr(args, "hil_delay_ms", 0.0) * 1e-3,
                       autopilot_setup=_bind_autopilot(observers))
    if getattr(args, "rerun", False):
        _keep_viewer(observers)
    return res


def _floats(text: str, n: int, what: str, unit: str) -> tuple[float, ...]:

    try:
        v = tuple(float(x) for x in text.split(","))
    except ValueError:
        v = ()
    if len(v) != n or not all(math.isfinite(x) for x in v):
        raise UsageError(f"{what} {text!r}: expected {n} comma-separated numbers {unit}")
    return v


def _vehicle_options(args: argparse.Namespace) -> dict[str, Any]:
    """The physical vehicle and its environment from ``--wind``, ``--gust``, ``--mass-scale``,
    ``--inertia-scale``, ``--cg-offset``, ``--noise`` and ``--noise-seed`` (as a campaign
    scenario flies them, see :func:`vtolftc.campaign.execute.vehicle_options`)."""
    from vtolftc.campaign.execute import vehicle_options

    wind = (_floats(args.wind, 3, "--wind", "N,E,D (m/s)")
            if getattr(args, "wind", None) else (0.0, 0.0, 0.0))
    gusts = []
    for g in getattr(args, "gust", None) or []:
        st, dur, *amp = _floats(g, 5, "--gust", "START_S,DURATION_S,N,E,D (s, s, m/s)")
        if st < 0 or dur <= 0:
            raise UsageError(f"--gust {g!r}: expected a start >= 0 s and a duration > 0 s")
        gusts.append((st, dur, tuple(amp)))
    ms = getattr(args, "mass_scale", 1.0)
    js = (_floats(args.inertia_scale, 3, "--inertia-scale", "SX,SY,SZ")
          if getattr(args, "inertia_scale", None) else (1.0, 1.0, 1.0))
    cg = (_floats(args.cg_offset, 3, "--cg-offset", "X,Y,Z (m, body FRD)")
          if getattr(args, "cg_offset", None) else (0.0, 0.0, 0.0))
    if not (math.isfinite(ms) and 0.5 <= ms <= 2.0) or not all(0.5 <= x <= 2.0 for x in js):
        raise UsageError(f"--mass-scale {ms:g} / --inertia-scale {js}: expected factors in "
                         "[0.5, 2]")
    if not all(abs(x) <= 0.5 for x in cg):
        raise UsageError(f"--cg-offset {cg}: expected offsets within +-0.5 m")
    return vehicle_options(wind, gusts, ms, js, cg, getattr(args, "noise", "none"),
                           getattr(args, "noise_seed", 0))


def _check_controller(controller: str, args: argparse.Namespace) -> None:
    """Load the controller's gain file once, so that a missing or invalid file is reported
    (exit 2) before anything is flown or written."""
    from vtolftc.firmware_sim.autopilot.attitude import ControllerError, make_controller
    from vtolftc.firmware_sim.vehicle.flyable import load_flyable_airframe

    af = load_flyable_airframe(getattr(args, "airframe", None))
    try:
        make_controller(controller, args.gains, airframe_name=af.name,
                        airframe_sha256=af.sha256)
    except ControllerError as exc:
        raise UsageError(str(exc)) from None


def _summary_lines(res: Any) -> list[str]:
    m = res.metrics

    def f(x: Any, nd: int = 3) -> str:
        return "—" if x is None or (isinstance(x, float) and not math.isfinite(x)) \
            else f"{x:.{nd}f}"

    return [
        f"  crashed: {m['crashed']}" + (f" at t = {m['crash_time_s']:.2f} s"
                                         if m["crashed"] else ""),
        f"  transition: start {f(m['transition_start_s'], 2)} s, complete "
        f"{f(m['transition_complete_s'], 2)} s"
        + (" (quad-chute back to hover)" if m["quad_chute"] else ""),
        f"  RMSE over t >= {m['window_start_s']:g} s: altitude {f(m['rmse_altitude_m'])} m, "
        f"roll {f(m['rmse_roll_deg'])} deg, pitch {f(m['rmse_pitch_deg'])} deg, "
        f"yaw {f(m['rmse_yaw_deg'])} deg",
        f"  max |error|: roll {f(m['max_abs_roll_error_deg'], 2)}, pitch "
        f"{f(m['max_abs_pitch_error_deg'], 2)}, yaw {f(m['max_abs_yaw_error_deg'], 2)} deg",
        f"  final: altitude {f(m['final_altitude_m'], 2)} m (error "
        f"{f(m['final_altitude_error_m'], 2)} m), airspeed {f(m['final_airspeed_m_s'], 1)} m/s,"
        f" attitude ({f(m['final_roll_deg'], 2)}, {f(m['final_pitch_deg'], 2)}, "
        f"{f(m['final_yaw_deg'], 2)}) deg",
        f"  allocation: {res.allocation['counts']['solved']} solved, "
        f"{res.allocation['counts']['fallback']} fallbacks; wall {res.wall_time_s:.2f} s "
        f"({res.real_time_factor:.1f}x real time)",
    ]


def cmd_fly(args: argparse.Namespace) -> int:
    """Fly one of the paper's cases in-process and write a run folder."""
    from vtolftc.firmware_sim.vehicle.faults import parse_fault_spec
    from vtolftc.firmware_sim.vehicle.flyable import load_flyable_airframe
    from vtolftc.telemetry.runfolder import default_run_dir

    _check_common(args)
    af = load_flyable_airframe(getattr(args, "airframe", None))
    extra: list[Any] = []
    for spec in args.fault or []:
        extra += parse_fault_spec(spec, af.actuator_names)
    _check_controller(args.controller, args)
    run_dir = Path(args.out) if args.out else default_run_dir(args.case, args.controller)
    prepare_out(run_dir, bool(getattr(args, "overwrite", False)))
    print(f"flying case {args.case} with {args.controller} for {args.duration:g} s "
          f"-> {run_dir}", flush=True)
    try:
        with _stop_on_signals():
            res = _fly_one(args.case, args.controller, args, run_dir, extra)
    except KeyboardInterrupt:
        print(f"interrupted: what was flown so far is in {run_dir}", flush=True)
        raise
    for line in _summary_lines(res):
        print(line)
    return 0


def cmd_compare(args: argparse.Namespace) -> int:
    """Fly a case with the three controllers and print a table like the paper's table 4."""
    from vtolftc.jsonio import json_safe
    from vtolftc.telemetry.runfolder import default_run_dir

    _check_common(args)
    for ctrl in CONTROLLER_NAMES:
        _check_controller(ctrl, args)
    out = Path(args.out) if args.out else default_run_dir(args.case, "compare")
    prepare_out(out, bool(getattr(args, "overwrite", False)),
                marker=("comparison.json", *CONTROLLER_NAMES))
    results: dict[str, dict[str, Any]] = {}
    table = ""
    print(f"comparing gs-shif, shif, lqr on case {args.case} -> {out}", flush=True)
    try:
        with _stop_on_signals():
            _compare_all(args, out, results)
    except KeyboardInterrupt:
        print(f"interrupted: what was flown so far is in {out}", flush=True)
        raise
    finally:
        if results:
            table = comparison_table(args.case, results)
            (out / "comparison.md").write_text(table + "\n", encoding="utf-8")
            (out / "comparison.json").write_text(
                json.dumps(json_safe(results), indent=2) + "\n", encoding="utf-8")
            try:
                comparison_plot(args.case, results, out / "rmse.png")
            except Exception as exc:  # plots never lose the tables
                print(f"bar chart failed: {exc}")
    print()
    print(table)
    return 0


def _compare_all(args: argparse.Namespace, out: Path, results: dict[str, Any]) -> None:
    for ctrl in CONTROLLER_NAMES:
        res = _fly_one(args.case, ctrl, args, out / ctrl, [])
        results[ctrl] = res.metrics
        print(f"{ctrl}:")
        for line in _summary_lines(res):
            print(line)


def comparison_table(case: str, results: dict[str, dict[str, Any]]) -> str:
    """Markdown table like the paper's table 4 (and the paper's numbers for reference)."""
    lines = [f"Case {case}: RMSE of the reference tracking over t >= 20 s",
             "", "| FTC method | e_h (m) | e_phi (deg) | e_theta (deg) | e_psi (deg) | "
             "transition complete (s) | crashed |", "|---|---:|---:|---:|---:|---:|---|"]
    for ctrl in ("lqr", "shif", "gs-shif"):
        if ctrl not in results:
            continue
        m = results[ctrl]
        tc = m.get("transition_complete_s")

        def g(x: Any) -> str:
            return "—" if x is None or not math.isfinite(x) else f"{x:.4f}"

        lines.append(f"| {ctrl.upper()} | {g(m['rmse_altitude_m'])} | {g(m['rmse_roll_deg'])} "
                     f"| {g(m['rmse_pitch_deg'])} | {g(m['rmse_yaw_deg'])} | "
                     f"{'—' if tc is None else f'{tc:.2f}'} | {m['crashed']} |")
    paper = _PAPER_TABLE4.get(str(case))
    if paper:
        lines += ["", "Paper (table 4), for reference:", "",
                  "| FTC method | e_h (m) | e_phi (deg) | e_theta (deg) | e_psi (deg) |",
                  "|---|---:|---:|---:|---:|"]
        for ctrl in ("lqr", "shif", "gs-shif"):
            v = paper[ctrl]
            lines.append(f"| {ctrl.upper()} | " + " | ".join(f"{x:.4f}" for x in v) + " |")
    return "\n".join(lines)


def comparison_plot(case: str, results: dict[str, dict[str, Any]], path: Path) -> None:
    """Bar charts of the RMSEs (paper figs 13/14)."""
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt
    import numpy as np

    keys = [("rmse_altitude_m", "e_h (m)"), ("rmse_roll_deg", "e_phi (deg)"),
            ("rmse_pitch_deg", "e_theta (deg)"), ("rmse_yaw_deg", "e_psi (deg)")]
    ctrls = [c for c in ("lqr", "shif", "gs-shif") if c in results]
    fig, axs = plt.subplots(1, 4, figsize=(12, 3.5))
    for a, (k, label) in zip(axs, keys, strict=True):
        vals = [results[c].get(k) or 0.0 for c in ctrls]
        a.bar(np.arange(len(ctrls)), vals, color=["tab:red", "tab:blue", "tab:green"][
            : len(ctrls)])
        a.set_xticks(np.arange(len(ctrls)), [c.upper() for c in ctrls])
        a.set_title(label)
        a.grid(True, axis="y")
    fig.suptitle(f"RMSE of the reference tracking, case {case}")
    fig.tight_layout()
    fig.savefig(path, dpi=110)
    plt.close(fig)


def _case(text: str) -> str:

    t = text.strip().removeprefix("case")
    if t not in ("0", "1", "2"):
        raise UsageError(f"--case {text!r}: expected 0 (nominal), 1 or 2")
    return t


def register(sub: Any) -> None:
    """Add ``fly`` and ``compare`` to the ``vtolftc`` sub-commands."""
    p = sub.add_parser("fly", help="fly one of the paper's cases in-process (run folder)",
                       description=cmd_fly.__doc__)
    p.add_argument("--case", default="1", help="fault case: 0 (nominal), 1 or 2 (default 1)")
    p.add_argument("--controller", default="gs-shif", choices=CONTROLLER_NAMES,
                   help="attitude controller (default gs-shif)")
    _common(p)
    p.add_argument("--fault", action="extend", nargs="+", metavar="SPEC",
                   help="extra fault(s) ACTUATOR:KIND[=VALUE][@START_S], e.g. "
                        "rotor_1a:loss=0.5@25 (several allowed)")
    p.add_argument("--wind", default=None, metavar="N,E,D",
                   help="steady wind, NED m/s (the velocity of the air), e.g. 0,5,0")
    p.add_argument("--gust", action="append", default=None, metavar="T,DUR,N,E,D",
                   help="1 - cosine gust from T s lasting DUR s, peak N,E,D m/s (repeatable)")
    p.add_argument("--mass-scale", type=float, default=1.0,
                   help="physical mass / the airframe file's (the autopilot keeps the file's)")
    p.add_argument("--inertia-scale", default=None, metavar="SX,SY,SZ",
                   help="physical inertia / the airframe file's, per body axis")
    p.add_argument("--cg-offset", default=None, metavar="X,Y,Z",
                   help="CG moved from the airframe file's, body FRD m")
    p.add_argument("--noise", choices=("none", "typical"), default="none",
                   help="state-estimate noise fed to the autopilot (default none)")
    p.add_argument("--noise-seed", type=int, default=0, help="seed of that noise")
    p.add_argument("--window-start", type=float, default=None, metavar="S",
                   help="metrics window start, s (default: the transition command, 20 s)")
    p.add_argument("--rerun", action="store_true",
                   help="also show the run live in rerun (a native viewer if there is a "
                        "display, else a web viewer on 127.0.0.1 whose URL is printed)")
    p.set_defaults(func=_wrap(cmd_fly))
    p = sub.add_parser("compare", help="fly a case with gs-shif, shif and lqr; table 4",
                       description=cmd_compare.__doc__)
    p.add_argument("--case", default="1", help="fault case: 0, 1 or 2 (default 1)")
    _common(p)
    p.set_defaults(func=_wrap(cmd_compare))


def _common(p: argparse.ArgumentParser) -> None:
    p.add_argument("--duration", type=float, default=40.0,
                   help="simulated seconds (default 40)")
    p.add_argument("--out", default=None, help="output folder (default runs/<case>-...)")
    p.add_argument("--overwrite", action="store_true",
                   help="replace an existing --out run folder (default: refuse)")
    p.add_argument("--gains", default=None,
                   help="gains directory (default firmware_sim/autopilot/gains)")
    p.add_argument("--hil-delay-ms", type=float, default=0.0,
                   help="one-way delay on the in-process HIL state path, ms (rounded up to "
                        "whole 4 ms control steps; default 0)")
    p.add_argument("--airframe", type=Path, default=None,
                   help="airframe TOML file (default: the shipped DS-1)")
    p.add_argument("--no-plots", action="store_true", help="skip the PNG plots")
    p.add_argument("--progress", type=float, default=0.0, metavar="S",
                   help="print the simulated time, mode, altitude and airspeed every S "
                        "simulated seconds (default 0: off)")


def _wrap(func: Any) -> Any:
    def run(args: argparse.Namespace) -> int:
        args.case = _case(str(args.case))
        return func(args)

    run.__doc__ = func.__doc__
    return run

"""``vtolftc synth``: the attitude synthesis of an airframe (paper sections 3-4).

``--method robust`` (default) is the robust design of ``synthesis/robust.py``;
``--method paper`` reproduces the paper's design as published (the gains in
``firmware_sim/autopilot/gains/paper/``); ``--method surface [--degree D]`` tunes each axis'
gains as one smooth function of airspeed (Legendre polynomials of degree D, default 2; SHIF is
the degree-0 member) over a dense airspeed grid with the robust design's objectives
(``synthesis/surfaces.py``), then validates the GS-SHIF schedule between its breakpoints
(``synthesis/validation.py``: stability, margins and mu on a 4x denser grid, the mixed-mu
certificate over the continuous airspeed range; ``DIR/validation.json``,
``DIR/report/validation.md``).

``--dk N`` (robust method only) then runs a D-K iteration with the fixed P-PID structure at
every GS-SHIF axis-point (``synthesis/dk.py``, ``synthesis/dk_robust.py``: fit a rational
D(s) to the mu scalings of the robust-performance interconnection, paper eq. 14, re-tune the
gains on ||D N D^-1||_inf keeping the 50 ms delay-margin and rotor-out channels no worse, at
most N times, stop when mu_RP falls by less than 1 %) and writes the D-K gains with
``dk.json`` and ``DK.md`` (table 3 before/after) to ``DIR/dk/`` (``vtolftc fly --gains
DIR/dk``); ``DIR`` keeps the robust design.

Writes ``DIR/gs-shif.json``, ``DIR/shif.json`` (format ``vtolftc-gain-schedule/1``),
``DIR/lqr.json`` (``vtolftc-lqr-gains/1``) and ``DIR/report/`` (markdown tables and PNG
plots). A progress bar goes to stderr; the per-stage wall times and a summary are printed at
the end. Ctrl-C stops at once (exit 130) and keeps the files already written (every file is
written atomically, the gain files as soon as the tunes are done).
"""

from __future__ import annotations

import argparse
import os
import signal
import sys
import time
from collections.abc import Callable
from pathlib import Path
from typing import Any

from vtolftc.base.errors import UsageError


def _check(args: argparse.Namespace) -> None:

    if args.starts is None:
        args.starts = 4 if args.method == "paper" else 2
    if args.method != "surface" and (args.degree is not None or args.max_iter is not None):
        raise UsageError("--degree and --max-iter apply to --method surface only")
    if args.degree is None:
        args.degree = 2
    if args.dk is not None:
        if args.method != "robust":
            raise UsageError("--dk applies to --method robust only (the D-K iteration starts "
                             "from the robust point design)")
        if not 1 <= args.dk <= 20:
            raise UsageError(f"--dk {args.dk}: expected 1..20 D-K iterations per axis-point")
    if not 0 <= args.degree <= 8:
        raise UsageError(f"--degree {args.degree}: expected 0..8 (the polynomial degree of "
                         "the gain surfaces)")
    if args.max_iter is not None and not 1 <= args.max_iter <= 10000:
        raise UsageError(f"--max-iter {args.max_iter}: expected 1..10000 iterations per "
                         "start")
    if not 0 <= args.starts <= 200:
        raise UsageError(f"--starts {args.starts}: expected 0..200 random starts per tune")
    if not 1 <= args.jobs <= 64:
        raise UsageError(f"--jobs {args.jobs}: expected 1..64 worker processes")
    if not 0 <= args.seed < 2**32:
        raise UsageError(f"--seed {args.seed}: expected an integer in [0, 2^32)")
    if args.airframe is not None and not Path(args.airframe).is_file():
        raise UsageError(f"--airframe {args.airframe}: no such file (give an airframe TOML "
                         "file such as airframe/ds1.toml)")
    out = Path(args.out)
    if out.exists() and not out.is_dir():
        raise UsageError(f"--out {out}: exists and is not a directory")
    try:
        out.mkdir(parents=True, exist_ok=True)
    except OSError as exc:
        raise UsageError(f"--out {out}: cannot create the directory: {exc}") from None
    if not os.access(out, os.W_OK):
        raise UsageError(f"--out {out}: directory is not writable")


def _with_progress(total: int, desc: str, quiet: bool,
                   run: Callable[[Callable[[str, int], None]], Any]) -> Any:
    """Call ``run(progress)`` under a progress bar on stderr, with SIGTERM stopping it as
    Ctrl-C does (a ``KeyboardInterrupt``, so finished files are kept)."""
    from tqdm import tqdm

    bar = tqdm(total=total, desc=desc, unit="step", file=sys.stderr, dynamic_ncols=True,
               disable=quiet)

    def progress(label: str, n: int) -> None:
        bar.set_postfix_str(label[:40])
        bar.update(n)

    def _term(signum: int, frame: Any) -> None:
        raise KeyboardInterrupt  # SIGTERM: same clean stop as Ctrl-C

    old_term = signal.signal(signal.SIGTERM, _term)
    try:
        return run(progress)
    finally:
        signal.signal(signal.SIGTERM, old_term)
        bar.close()


def cmd_synth(args: argparse.Namespace) -> int:
    """Structured H-infinity GS-SHIF and SHIF designs, LQR baseline, mu analysis, report."""
    from vtolftc.firmware_sim.vehicle.flyable import load_flyable_airframe

    _check(args)
    af = load_flyable_airframe(args.airframe)
    if args.method == "surface":
        return _cmd_surface(args, af)
    from vtolftc.synthesis.pipeline import run_synthesis, work_units

    n_points = 7 if args.method == "robust" else 6
    t0 = time.perf_counter()
    res = _with_progress(
        work_units(n_points, mu=not args.no_mu, report=not args.no_report), "synth", args.quiet,
        lambda progress: run_synthesis(af, args.out, n_starts=args.starts, jobs=args.jobs,
                                       seed=args.seed, mu=not args.no_mu,
                                       report=not args.no_report, progress=progress,
                                       method=args.method))
    total = time.perf_counter() - t0
    _summary(res, total)
    if args.dk is not None:
        return _cmd_dk(args, af, res)
    return 0


def _cmd_dk(args: argparse.Namespace, af: Any, res: Any) -> int:
    """``--dk N``: D-K at every GS-SHIF axis-point of the robust run ``res``."""
    from vtolftc.synthesis.dk_robust import DKSettings, dk_table
    from vtolftc.synthesis.dk_run import run_dk
    from vtolftc.synthesis.models import AXES

    t0 = time.perf_counter()
    gains = {ax: [d.gains for d in res.gs[ax]] for ax in AXES}
    results, files = _with_progress(
        3 * len(res.points), "synth D-K", args.quiet,
        lambda progress: run_dk(af, res.points, gains, Path(args.out) / "dk", args.out,
                                settings=DKSettings(max_iter=args.dk), jobs=args.jobs,
                                progress=lambda s: progress(s, 1)))
    print(f"\nD-K iteration (at most {args.dk} per axis-point), "
          f"{time.perf_counter() - t0:.1f} s:\n")
    print(dk_table(results))
    for k, p in files.items():
        print(f"  {k:<8s} {p}")
    return 0


def _cmd_surface(args: argparse.Namespace, af: Any) -> int:
    """``--method surface``: gain surfaces, gain files, validation, report."""
    from vtolftc.synthesis.robust import robust_points
    from vtolftc.synthesis.surface_run import run_surface_synthesis, work_units

    t0 = time.perf_counter()
    n_grid = 2 * len(robust_points(af)) - 1   # the surface grid: points and midpoints
    run = _with_progress(
        work_units(report=not args.no_report, n_grid=n_grid), "synth surface", args.quiet,
        lambda progress: run_surface_synthesis(
            af, args.out, degree=args.degree, n_starts=args.starts, seed=args.seed,
            max_iter=40 if args.max_iter is None else args.max_iter, jobs=args.jobs,
            mu=not args.no_mu, report=not args.no_report, progress=progress))
    total = time.perf_counter() - t0
    print(f"Gain surfaces of {af.name} ({af.sha256[:12]}...), degree {args.degree}.")
    print("\n| axis | SHIF objective | GS-SHIF objective |\n|---|---:|---:|")
    for ax, d in run.designs.items():
        print(f"| {ax} | {d.constant_objective:.4f} | {d.surface_objective:.4f} |")
    if run.validation is not None:
        v = run.validation
        print(f"\nValidation of gs-shif on {len(v.grid_m_s)} airspeeds ({v.density}x the "
              f"{len(v.design_airspeeds_m_s)} breakpoints):")
        for ax, s in v.summary().items():
            print(f"  {ax}: max Re(pole) {s['max_real_pole_rad_s']:.3f} rad/s, min delay "
                  f"margin {_num(s['min_delay_margin_s'], 1e3)} ms, max mu_RS "
                  f"{_num(s['max_mu_rs'])}, max mixed mu (cell) "
                  f"{_num(s['max_mixed_mu_cell'])}, failures {s['failures']} "
                  f"({s['failures_between']} between breakpoints)")
    _times_and_files(run.times, total, run.files, width=18)
    if run.validation is not None and run.validation.failures_between:
        print(f"WARNING: {len(run.validation.failures_between)} grid point(s) between "
              "breakpoints fail the validation (see report/validation.md)")
    return 0


def _times_and_files(times: dict[str, float], total: float, files: dict[str, Any],
                     width: int) -> None:
    """Print the per-stage wall times [s], their total and the files written."""
    print("\nStage times:")
    for k, t in times.items():
        print(f"  {k:<34s} {t:7.2f} s")
    print(f"  {'total':<34s} {total:7.2f} s")
    print("\nFiles:")
    for k, p in files.items():
        print(f"  {k:<{width}s} {p}")


def _num(x: float | None, k: float = 1.0) -> str:
    return "-" if x is None else f"{k * x:.3g}"


def _summary(res: Any, total: float) -> None:
    from vtolftc.synthesis.models import AXES

    print(f"Synthesis of {res.airframe.name} ({res.airframe.sha256[:12]}...), "
          f"{len(res.points)} design points x 3 axes.")
    print("\n| axis | point | gamma | ||Ws S|| | ||Wt T|| | ||Wr R|| | stable | mu_Delta | "
          "mu_Delta-hat |")
    print("|---|---:|---:|---:|---:|---:|---|---:|---:|")
    for ax in AXES:
        for k, d in enumerate(res.gs[ax]):
            m = res.mu_gs.get(ax)
            mu = (f"{m[k].mu_rs:.3f} | {m[k].mu_rp:.3f}" if m else "- | -")
            n = d.norms
            print(f"| {ax} | {res.points[k].number} | {n['gamma']:.3f} | {n['Ws*S']:.3f} | "
                  f"{n['Wt*T']:.3f} | {n['Wr*R']:.3f} | {'yes' if d.stable else 'NO'} | {mu} |")
    print("\nSHIF max gamma over points: "
          + ", ".join(f"{ax} {res.shif[ax].norms['gamma']:.3f}" for ax in AXES))
    _times_and_files(res.times, total, res.files, width=8)
    unstable = [f"{ax} {d.label}" for ax in AXES for d in res.gs[ax] if not d.stable]
    if unstable:
        print("WARNING: nominally unstable closed loops: " + ", ".join(unstable))


def register(sub: Any) -> None:
    """Add the ``synth`` subcommand to the CLI's subparsers."""
    p = sub.add_parser("synth", help="attitude synthesis: GS-SHIF/SHIF/LQR gains, mu, report",
                       description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    p.add_argument("--airframe", type=Path, default=None,
                   help="airframe TOML file (default: the shipped DS-1)")
    p.add_argument("--method", choices=("robust", "paper", "surface"), default="robust",
                   help="robust (default): centred nominal, loop delays, rotor-out and "
                        "delay-margin objectives, Ws by rule, a cruise point; paper: the "
                        "paper's design as published (table 2 weights, six points; for "
                        "another aircraft than DS-1, table 1's airspeeds are scaled to its "
                        "transition end, M kept and omega_b scaled by its authority "
                        "bandwidth sqrt(u_max/(J r_max)) over DS-1's, omega_a by its "
                        "actuator bandwidth). Both derive the design airspeeds and gain "
                        "bounds from the airframe (synthesis/scaling.py); surface: the "
                        "robust objectives on a dense airspeed grid, each gain a polynomial "
                        "of the airspeed (--degree), validated between the breakpoints")
    p.add_argument("--degree", type=int, default=None,
                   help="--method surface: polynomial degree of the gain surfaces (default 2; "
                        "0 = constant gains)")
    p.add_argument("--max-iter", type=int, default=None,
                   help="--method surface: tuner iterations per start (default 40)")
    p.add_argument("--out", type=Path, default=Path("synth_out"),
                   help="output directory (default synth_out)")
    p.add_argument("--starts", type=int, default=None,
                   help="random starts per tune in addition to the classical start (default "
                        "2 for robust, 4 for paper)")
    p.add_argument("--jobs", type=int, default=2, help="worker processes (default 2)")
    p.add_argument("--seed", type=int, default=0, help="seed of the random starts (default 0)")
    p.add_argument("--dk", type=int, default=None, metavar="N",
                   help="--method robust: then a D-K iteration (at most N, 1..20) at every "
                        "GS-SHIF axis-point on the robust-performance interconnection "
                        "(eq. 14), D-K gains and table 3 before/after in DIR/dk/")
    p.add_argument("--no-mu", action="store_true",
                   help="skip the mu analysis (surface: validation without mu)")
    p.add_argument("--no-report", action="store_true", help="skip the report folder")
    p.add_argument("--quiet", action="store_true", help="no progress bar")
    p.set_defaults(func=cmd_synth)

"""End-to-end gain-surface synthesis (``vtolftc synth --method surface``).

The robust design's channels (:class:`vtolftc.synthesis.robust.RobustMethod`) on the surface
grid (:func:`vtolftc.synthesis.surfaces.surface_grid`: the robust design points and the
midpoints between them), SHIF as the degree-0 surface and GS-SHIF as the degree-``D``
surface started from it (:func:`vtolftc.synthesis.surfaces.design_surfaces`), the LQR
baseline, then the validation of the GS-SHIF schedule between its breakpoints
(:mod:`vtolftc.synthesis.validation`). With ``jobs`` > 1 both run on one process pool: the
axes' designs longest first, each axis' validation points as soon as its design is done (so
the second core is busy while the last design runs), the same jobs as in order.

Outputs in ``out_dir``, the layout of the other methods (``vtolftc fly --gains-dir`` flies
it): ``gs-shif.json``, ``shif.json`` (``vtolftc-gain-schedule/1``, breakpoints = the grid,
``design_points`` = the grid points with their perturbed ranges), ``lqr.json``; and
``surfaces.json`` (coefficients, objectives), ``validation.json`` and ``report/``
(``README.md`` and ``validation.md`` with SVG figures).
"""

from __future__ import annotations

import json
import time
from collections.abc import Callable
from concurrent.futures import FIRST_COMPLETED, Future, ProcessPoolExecutor, wait
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

from vtolftc.airframe.loader import Airframe
from vtolftc.synthesis.baselines import LQR_Q, LQR_R, lqr_design
from vtolftc.synthesis.export import atomic_write_text, lqr_document, write_json
from vtolftc.synthesis.models import AXES, Axis
from vtolftc.synthesis.surfaces import SurfaceDesign, design_surfaces, surface_grid
from vtolftc.synthesis.validation import (
    FlownSchedule,
    GridPointResult,
    ValidationResult,
    plan_validation,
    validate_job,
    validate_schedule,
)

__all__ = ["DESIGN_ORDER", "SurfaceRun", "run_surface_synthesis"]

#: The order the axes' design jobs are submitted to the pool, longest first (so that the
#: last one to start is the shortest and the validation jobs of the axes done fill the
#: other core).
DESIGN_ORDER: tuple[Axis, ...] = ("yaw", "pitch", "roll")


@dataclass
class SurfaceRun:
    """What :func:`run_surface_synthesis` produced.

    Parameters
    ----------
    designs : dict of str to SurfaceDesign
        Per axis.
    validation : ValidationResult or None
        The validation of ``gs-shif.json`` (None if interrupted before it).
    files : dict of str to pathlib.Path
        Files written, by name.
    times : dict of str to float
        Wall time per stage [s].
    cpu_times : dict of str to float
        CPU time per stage [s]. Serially (``jobs`` 1): user + system of this process. On a
        pool the designs and the validation overlap: each is the CPU its jobs used in the
        workers (``time.process_time``), and "designs and validation, all processes" is
        user + system of this process and the workers from the pool's start to its shut
        down (with the workers' start-up, imports and the transfers).
    """

    designs: dict[str, SurfaceDesign]
    validation: ValidationResult | None
    files: dict[str, Path] = field(default_factory=dict)
    times: dict[str, float] = field(default_factory=dict)
    cpu_times: dict[str, float] = field(default_factory=dict)


def _cpu_s() -> float:
    """User + system CPU seconds of this process and its finished (waited-for) children."""
    import resource

    s = resource.getrusage(resource.RUSAGE_SELF)
    c = resource.getrusage(resource.RUSAGE_CHILDREN)
    return s.ru_utime + s.ru_stime + c.ru_utime + c.ru_stime


def _timed_design_job(args: tuple[Any, ...]) -> tuple[SurfaceDesign, float]:
    c = time.process_time()
    d = _design_job(args)
    return d, time.process_time() - c


def _timed_validate_job(j: tuple[Any, ...]) -> tuple[GridPointResult, float]:
    c = time.process_time()
    r = validate_job(j)
    return r, time.process_time() - c


def _design_job(args: tuple[Any, ...]) -> SurfaceDesign:
    from vtolftc.synthesis.robust import RobustMethod

    af, axis, grid, degree, n_starts, seed, max_iter = args
    return design_surfaces(RobustMethod(), af, axis, grid, degree, n_starts=n_starts,
                           seed=seed, max_iter=max_iter)


def run_surface_synthesis(af: Airframe, out_dir: str | Path, *, degree: int = 2,
                          n_starts: int = 2, seed: int = 0, max_iter: int | None = 40,
                          jobs: int = 2, mu: bool = True, report: bool = True,
                          density: int = 4,
                          progress: Callable[[str, int], None] | None = None) -> SurfaceRun:
    """Gain surfaces of all three axes, the gain files, the validation and the report.

    Parameters
    ----------
    af : Airframe
        The airframe.
    out_dir : str or pathlib.Path
        The gains directory (created if missing).
    degree : int
        Degree of the GS-SHIF surface (>= 0).
    n_starts : int
        Random starts of the constant (SHIF) tune besides its initial point.
    seed : int
        Seed of the random starts.
    max_iter : int or None
        Iteration cap per start of the tuner.
    jobs : int
        Worker processes of one pool for the three axes' designs and the validation's
        axis-points; an axis' validation starts when its design is done (1: all in this
        process, in order). The numbers are the same either way.
    mu : bool
        Compute mu_RS and the mixed-mu certificate in the validation (False: stability and
        margins only).
    report : bool
        Write ``report/``.
    density : int
        The validation grid's intervals per breakpoint interval (default 4).
    progress : callable, optional
        ``progress(label, n)`` after ``n`` more work units (3 designs + the validation's
        axis-points + 1 report).

    Returns
    -------
    SurfaceRun
        Designs, validation, files and times.
    """
    from vtolftc.synthesis.robust import robust_points

    tick = progress or (lambda label, n: None)
    out = Path(out_dir)
    out.mkdir(parents=True, exist_ok=True)
    grid = surface_grid(robust_points(af), 2)
    times: dict[str, float] = {}
    cpu: dict[str, float] = {}
    t0, c0 = time.perf_counter(), _cpu_s()
    args = {ax: (af, ax, grid, degree, n_starts, seed, max_iter) for ax in AXES}
    meta = {"design_points": [{"number": p.number, "airspeed_m_s": p.airspeed_m_s,
                               "v_min_m_s": p.v_min_m_s, "v_max_m_s": p.v_max_m_s}
                              for p in grid],
            "settings": {"degree": degree, "n_starts": n_starts, "seed": seed,
                         "max_iter": max_iter},
            "method": "surface: robust design channels (synthesis/robust.py) on a dense "
                      "airspeed grid, gains as Legendre polynomials of the airspeed tuned "
                      "as one design (synthesis/surfaces.py)"}
    val_kw: dict[str, Any] = {"density": density, "mu": mu, "certificate": mu, "seed": seed}
    if jobs > 1:
        files: dict[str, Path] = {}
        c0 = _cpu_s()
        designs, scheds, rows = _pipeline(
            af, args, val_kw, jobs, tick, times, cpu,
            lambda ds: files.update(write_surface_gains_all(af, ds, out, meta)), meta)
        cpu["designs and validation, all processes"] = _cpu_s() - c0  # the pool is down
        doc = json.loads(files["gs-shif"].read_text(encoding="utf-8"))
        _check_same_gains(doc, scheds)
        val = plan_validation(af, doc, **val_kw).result(rows)
    else:
        designs = {}
        for ax in AXES:
            designs[ax] = _design_job(args[ax])
            tick(f"surface {ax}", 1)
        times["surface designs"] = time.perf_counter() - t0
        cpu["surface designs"] = _cpu_s() - c0
        files = dict(write_surface_gains_all(af, designs, out, meta))
        t1, c1 = time.perf_counter(), _cpu_s()
        doc = json.loads(files["gs-shif"].read_text(encoding="utf-8"))
        val = validate_schedule(af, doc, **val_kw, progress=lambda label: tick(label, 1))
        times["validation"] = time.perf_counter() - t1
        cpu["validation"] = _cpu_s() - c1
    files["validation"] = val.write(out / "validation.json")
    run = SurfaceRun(designs, val, files, times, cpu)
    if report:
        t2, c2 = time.perf_counter(), _cpu_s()
        from vtolftc.synthesis.validation_report import write_validation_report

        files["validation report"] = write_validation_report(doc, val, out / "report")
        files["report"] = _write_readme(af, run, out / "report")
        times["report"] = time.perf_counter() - t2
        cpu["report"] = _cpu_s() - c2
        tick("report", 1)
    return run


def _axis_document(af: Airframe, axis: Axis, design: SurfaceDesign,
                   meta: dict[str, Any]) -> dict[str, Any]:
    """``gs-shif.json`` of one axis as parsed back (the same numbers as the whole file's)."""
    from vtolftc.base.jsonio import json_safe
    from vtolftc.synthesis.surfaces import schedule_from_surfaces

    doc = schedule_from_surfaces(af, dict.fromkeys(AXES, design.surface),  # a whole doc
                                 [p.airspeed_m_s for p in design.grid], "gs-shif", meta)
    doc["axes"] = {axis: doc["axes"][axis]}
    return json.loads(json.dumps(json_safe(doc), allow_nan=False))


def _pipeline(af: Airframe, args: dict[str, tuple[Any, ...]], val_kw: dict[str, Any],
              jobs: int, tick: Callable[[str, int], None], times: dict[str, float],
              cpu: dict[str, float], on_designs: Callable[[dict[str, SurfaceDesign]], None],
              meta: dict[str, Any],
              ) -> tuple[dict[str, SurfaceDesign], dict[str, FlownSchedule],
                         list[GridPointResult]]:
    """The designs and the validation on one pool of ``jobs`` processes: the axes' designs
    longest first (:data:`DESIGN_ORDER`), each axis' validation jobs as soon as its design
    is done, ``on_designs(designs)`` in this process once all are (the gain files, while the
    workers validate). Every job is the serial order's, so are the numbers.

    Returns the designs (in :data:`AXES` order), the flown schedule each axis was validated
    with, and the validation rows (axis-major, as :func:`validate_schedule`'s). ``times`` /
    ``cpu`` get "surface designs" (wall until the last design; the designs' CPU in their
    workers) and "validation" (wall from then on; the rows' CPU in their workers).
    """
    t0 = time.perf_counter()
    pending: dict[Future[tuple[SurfaceDesign, float]], str] = {}
    done: dict[str, SurfaceDesign] = {}
    rows: dict[str, list[Future[tuple[GridPointResult, float]]]] = {}
    scheds: dict[str, FlownSchedule] = {}
    c_design = c_val = 0.0
    with ProcessPoolExecutor(jobs) as ex:
        pending = {ex.submit(_timed_design_job, args[ax]): ax for ax in DESIGN_ORDER}
        while pending:
            finished, _ = wait(pending, return_when=FIRST_COMPLETED)
            for f in sorted(finished, key=lambda f: AXES.index(pending[f])):
                ax = pending.pop(f)
                done[ax], c = f.result()
                c_design += c
                tick(f"surface {ax}", 1)
                plan = plan_validation(af, _axis_document(af, ax, done[ax], meta),
                                       axes=(ax,), **val_kw)
                scheds[ax] = plan.jobs[0][4]
                rows[ax] = [ex.submit(_timed_validate_job, j) for j in plan.jobs]
        t1 = time.perf_counter()
        designs = {ax: done[ax] for ax in AXES}
        on_designs(designs)
        out: list[GridPointResult] = []
        for ax in AXES:
            for f in rows[ax]:
                r, c = f.result()
                c_val += c
                out.append(r)
                tick(f"validation {ax} {r.airspeed_m_s:g} m/s", 1)
    times["surface designs"], cpu["surface designs"] = t1 - t0, c_design
    times["validation"], cpu["validation"] = time.perf_counter() - t1, c_val
    return designs, scheds, out


def _check_same_gains(doc: dict[str, Any], scheds: dict[str, FlownSchedule]) -> None:
    """Raise RuntimeError unless every axis was validated with ``doc``'s gains."""
    whole = FlownSchedule(doc)
    for ax, sc in scheds.items():
        if (sc.breakpoints_m_s != whole.breakpoints_m_s
                or sc.table[ax] != whole.table[ax]):
            raise RuntimeError(f"the {ax} validation's gains are not gs-shif.json's")


def write_surface_gains_all(af: Airframe, designs: dict[str, SurfaceDesign], out: Path,
                            metadata: dict[str, Any]) -> dict[str, Path]:
    """``gs-shif.json``, ``shif.json``, ``surfaces.json`` and ``lqr.json`` in ``out``.

    Parameters
    ----------
    af : Airframe
        The airframe.
    designs : dict of str to SurfaceDesign
        Per axis.
    out : pathlib.Path
        The gains directory.
    metadata : dict
        Extra top-level entries of the two schedules.

    Returns
    -------
    dict of str to pathlib.Path
        The files, by name.
    """
    from vtolftc.synthesis.surfaces import write_surface_gains

    files = write_surface_gains(af, designs, out, metadata)
    lqr = lqr_design(af)
    files["lqr"] = write_json(out / "lqr.json", lqr_document(
        af, {ax: lqr[ax].gains() for ax in AXES},
        {"Q": list(LQR_Q), "R": LQR_R,
         "states": ["int(angle_ref - angle) [rad s]", "angle [rad]", "rate [rad/s]"],
         "design_model": "hover (V = 0): J rate' = D rate + K angle + tau",
         "closed_loop_poles": {ax: list(lqr[ax].poles) for ax in AXES}}))
    return files


def _write_readme(af: Airframe, run: SurfaceRun, out: Path) -> Path:
    md = [f"# Attitude synthesis report (gain surfaces): {af.name}", "",
          f"Airframe file sha256 `{af.sha256}`. SHIF is the degree-0 surface, GS-SHIF the "
          "degree-d surface started from it (`synthesis/surfaces.py`); the objective is the "
          "max over the grid's channels of their H-infinity norms.", "",
          "| axis | degree | SHIF objective | GS-SHIF objective | kept SHIF start | "
          "time (s) |", "|---|---:|---:|---:|---|---:|"]
    for ax in AXES:
        d = run.designs[ax]
        md.append(f"| {ax} | {d.surface.basis.degree} | {d.constant_objective:.4f} | "
                  f"{d.surface_objective:.4f} | {'yes' if d.kept_start else 'no'} | "
                  f"{sum(d.time_s.values()):.1f} |")
    md += ["", "Validation between the breakpoints (4x grid, gains as flown, margins, mu, "
           "the mixed-mu certificate over the continuous range): "
           "[validation.md](validation.md).", ""]
    p = out / "README.md"
    out.mkdir(parents=True, exist_ok=True)
    atomic_write_text(p, "\n".join(md) + "\n")
    return p


def work_units(mu: bool = True, report: bool = True, n_grid: int = 13,
               density: int = 4, axes: tuple[Axis, ...] = AXES) -> int:
    """Progress units of :func:`run_surface_synthesis` (3 designs, validation, report).

    Parameters
    ----------
    mu : bool
        Unused (every axis-point is one unit either way); kept for symmetry.
    report : bool
        Whether the report is written.
    n_grid : int
        Breakpoints of the schedule (the surface grid: 13 for seven design points).
    density : int
        The validation grid's density.
    axes : tuple of str
        The axes.

    Returns
    -------
    int
        The total.
    """
    del mu
    return len(axes) + len(axes) * (density * (n_grid - 1) + 1) + int(report)

"""End-to-end synthesis of an airframe: the 18 GS-SHIF tunes, SHIF, LQR, mu analysis,
the three gain files and the report (what ``vtolftc synth`` and the benchmark run).

Outputs in ``out_dir``: ``gs-shif.json`` and ``shif.json`` (``vtolftc-gain-schedule/1``),
``lqr.json`` (``vtolftc-lqr-gains/1``), ``report/`` (markdown + PNG). The gain files are
written (atomically) as soon as the tunes are done and rewritten with the mu results after
the analysis, so an interrupted run keeps the gains it has computed.
"""

from __future__ import annotations

import contextlib
import dataclasses
import math
import os
import signal
import time
from collections.abc import Callable
from concurrent.futures import Executor, Future, ProcessPoolExecutor, as_completed
from pathlib import Path
from typing import Any

from vtolftc.airframe.loader import Airframe
from vtolftc.synthesis.baselines import LQR_Q, LQR_R, lqr_design
from vtolftc.synthesis.design import (
    A_SENSITIVITY,
    OMEGA_A_RAD_S,
    R_MAX_RAD,
    TABLE2,
    control_weight_bandwidth,
    paper_points,
    run_designs,
)
from vtolftc.synthesis.export import lqr_document, schedule_document, write_json
from vtolftc.synthesis.models import AXES, Axis, attitude_model
from vtolftc.synthesis.result import SynthesisResult
from vtolftc.synthesis.robustness import AxisRobustness, analyse
from vtolftc.synthesis.uncertainty import GAMMA_RANGE, PAPER_DESIGN_POINTS, DesignPoint

__all__ = ["METHODS", "SynthesisResult", "run_synthesis"]

#: ``paper``: the paper's design as published (table 2 weights, healthy nominal at the
#: nominal airspeed, six points); ``robust``: :mod:`vtolftc.synthesis.robust`.
METHODS: tuple[str, ...] = ("robust", "paper")


def _mu_job(args: tuple[Any, ...]) -> AxisRobustness:
    af, axis, point, theta, w, seed = args
    G = w.plant(af) if hasattr(w, "plant") else attitude_model(af, axis, point.airspeed_m_s)
    return analyse(G, theta, w.Ws, w.Wt, w.Wr, seed=seed)


def _weights_meta(res: SynthesisResult) -> dict[str, Any]:
    if res.method == "robust":
        from vtolftc.synthesis.robust import RobustSpec

        return {
            "Ws_form": "(s/M + omega_b) / (s + A omega_b)  (paper eq. 5; M, omega_b by the "
                       "rule of synthesis/robust.py, table 2 beside)",
            "Wr_form": "((r_max/u_max) s + omega_a 1e-3) / (s + omega_a)  (paper eq. 6)",
            "Wt_form": "gain * prod (s/z_i + 1)/(s/p_i + 1)  (cover about the centred nominal)",
            "Wd_form": "Wd (s + w_i)/(s + 0.01 w_i), Wd = 1.25 d_max / e_max",
            "A": A_SENSITIVITY, "omega_a_rad_s": OMEGA_A_RAD_S, "r_max_rad": R_MAX_RAD,
            "gamma_range": list(GAMMA_RANGE), "spec": RobustSpec().to_dict(),
            "per_axis": {ax: [w.to_dict() for d in res.gs[ax] for w in d.weights]
                         for ax in AXES},
        }
    return {
        "Ws_form": "(s/M + omega_b) / (s + A omega_b)  (paper eq. 5, table 2 for DS-1; "
                   "another aircraft: M kept, omega_b times its authority bandwidth over "
                   "DS-1's, synthesis/design.py table2_scaled)",
        "Wr_form": "((r_max/u_max) s + omega_a 1e-3) / (s + omega_a)  (paper eq. 6)",
        "Wt_form": "gain * prod (s/z_i + 1)/(s/p_i + 1)  (fitted cover, paper fig. 3)",
        "A": A_SENSITIVITY, "omega_a_rad_s": control_weight_bandwidth(res.airframe),
        "r_max_rad": R_MAX_RAD,
        "gamma_range": list(GAMMA_RANGE),
        "per_axis": {ax: [w.to_dict() for d in res.gs[ax] for w in d.weights] for ax in AXES},
    }


def _design_points_meta(points: tuple[DesignPoint, ...]) -> list[dict[str, float]]:
    return [{"number": p.number, "airspeed_m_s": p.airspeed_m_s,
             "v_min_m_s": p.v_min_m_s, "v_max_m_s": p.v_max_m_s} for p in points]


def _axis_meta_gs(res: SynthesisResult, ax: Axis) -> dict[str, Any]:
    out: dict[str, Any] = {
        "achieved_norms": [d.norms for d in res.gs[ax]],
        "nominal_stable": [d.stable for d in res.gs[ax]],
        "closed_loop_poles": [d.poles[0] for d in res.gs[ax]],
    }
    if ax in res.mu_gs:
        out["mu"] = [m.summary() for m in res.mu_gs[ax]]
    if ax in res.margins_gs:
        out["loop_margins"] = [m.to_dict() for m in res.margins_gs[ax]]
    return out


def _axis_meta_shif(res: SynthesisResult, ax: Axis) -> dict[str, Any]:
    d = res.shif[ax]
    out: dict[str, Any] = {
        "achieved_norms_max_over_points": d.norms,
        "achieved_norms_per_point": d.per_model_norms,
        "nominal_stable": d.stable,
        "closed_loop_poles_per_point": d.poles,
    }
    if ax in res.mu_shif:
        out["mu"] = [m.summary() for m in res.mu_shif[ax]]
    if ax in res.margins_shif:
        out["loop_margins_per_point"] = [m.to_dict() for m in res.margins_shif[ax]]
    return out


def write_gain_files(res: SynthesisResult, out_dir: Path) -> dict[str, Path]:
    """(Re)write gs-shif.json, shif.json and lqr.json from ``res`` (atomically).

    Parameters
    ----------
    res : SynthesisResult
        The synthesis result.
    out_dir : pathlib.Path
        Output folder.

    Returns
    -------
    dict of str to pathlib.Path
        The files written, keyed by controller (``"gs-shif"``, ``"shif"``, ``"lqr"``).
    """
    af = res.airframe
    common = {
        "design_points": _design_points_meta(res.points),
        "weights": _weights_meta(res),
        "settings": res.settings,
        "method": "structured H-infinity mixed sensitivity (paper eq. 4-8) on the cascaded "
                  "P-PID of fig. 5; mu analysis eq. 12-14",
    }
    if res.method == "robust":
        common["method"] = ("robust: structured H-infinity mixed sensitivity (paper eq. 4-8) "
                            "on the cascaded P-PID of fig. 5 at the centred nominal with loop "
                            "delays, a rotor-out input-disturbance objective and a 50 ms "
                            "delay-margin requirement (synthesis/robust.py); mu analysis "
                            "eq. 12-14")
        common["synthesis_method"] = "robust"
    files: dict[str, Path] = {}
    gs_doc = schedule_document(
        af, "gs-shif", [p.airspeed_m_s for p in res.points],
        {ax: [d.gains for d in res.gs[ax]] for ax in AXES},
        {ax: _axis_meta_gs(res, ax) for ax in AXES}, common)
    files["gs-shif"] = write_json(out_dir / "gs-shif.json", gs_doc)
    if res.shif:
        npts = "six" if len(res.points) == 6 else str(len(res.points))
        sh_doc = schedule_document(
            af, "shif", [0.0], {ax: [res.shif[ax].gains] for ax in AXES},
            {ax: _axis_meta_shif(res, ax) for ax in AXES},
            {**common, "note": f"one constant P-PID per axis tuned over all {npts} design "
                               "points at once (multi-model minimax, same weights per point)"})
        files["shif"] = write_json(out_dir / "shif.json", sh_doc)
    if res.lqr:
        lq_doc = lqr_document(af, {ax: res.lqr[ax].gains() for ax in AXES}, {
            "Q": list(LQR_Q), "R": LQR_R,
            "states": ["int(angle_ref - angle) [rad s]", "angle [rad]", "rate [rad/s]"],
            "design_model": "hover (V = 0): J rate' = D rate + K angle + tau",
            "closed_loop_poles": {ax: list(res.lqr[ax].poles) for ax in AXES},
        })
        files["lqr"] = write_json(out_dir / "lqr.json", lq_doc)
    return files


def run_synthesis(af: Airframe, out_dir: str | Path, *, n_starts: int = 4, jobs: int = 2,
                  seed: int = 0, report: bool = True, mu: bool = True,
                  points: tuple[DesignPoint, ...] | None = None,
                  progress: Callable[[str, int], None] | None = None,
                  method: str = "robust",
                  ) -> SynthesisResult:
    """The whole synthesis; see the module docstring.

    Parameters
    ----------
    af : Airframe
        The airframe.
    out_dir : str or pathlib.Path
        Output folder (gain files and report).
    n_starts : int
        Random starts per tune.
    jobs : int
        Worker processes (1 = in-process).
    seed : int
        Seed of the random starts.
    report : bool
        Write the report.
    mu : bool
        Run the mu analysis.
    points : tuple of DesignPoint, optional
        The design points (default: the method's, six for ``paper``, seven for ``robust``).
    progress : callable, optional
        ``progress(label, n)`` is called when ``n`` more work units are done (the total is
        :func:`work_units`).
    method : str
        One of :data:`METHODS`.

    Returns
    -------
    SynthesisResult
        Everything produced, with the files written and per-stage times.

    Raises
    ------
    ValueError
        For an unknown method.
    """
    if method not in METHODS:
        raise ValueError(f"method {method!r}: expected one of {', '.join(METHODS)}")
    if points is None:
        if method == "robust":
            from vtolftc.synthesis.robust import robust_points

            points = robust_points(af)
        else:
            points = paper_points(af)
    out = Path(out_dir)
    out.mkdir(parents=True, exist_ok=True)
    times: dict[str, float] = {}
    tick = (lambda label, n=1: progress(label, n)) if progress else (lambda label, n=1: None)
    executor: Executor | None = (ProcessPoolExecutor(jobs, initializer=_worker_init)
                                 if jobs > 1 else None)
    interrupted = False
    # with workers, the mu analysis of a finished tune is queued at once, behind the tunes
    # still waiting (the pool runs jobs in submission order): it fills the workers while the
    # last, longest tunes finish. The same jobs as after the tuning, the same numbers.
    pre_mu: dict[tuple[str, str, int], Future[AxisRobustness]] = {}
    index = {p.number: i for i, p in enumerate(points)}

    def queue_mu(key: tuple[str, int], d: Any) -> None:
        if executor is None or not mu:
            return
        ax, num = key
        if num == 0:
            for i, p in enumerate(points):
                if max(z.real for z in d.poles[i]) < 0:
                    pre_mu[("shif", ax, i)] = executor.submit(
                        _mu_job, (af, ax, p, d.theta, d.weights[i], seed))
        elif d.stable:
            i = index[num]
            pre_mu[("gs", ax, i)] = executor.submit(
                _mu_job, (af, ax, points[i], d.theta, d.weights[0], seed))

    try:
        t0 = time.perf_counter()
        if method == "robust":
            from vtolftc.synthesis.robust import run_robust_designs

            gs, sh = run_robust_designs(af, n_starts=n_starts, seed=seed, points=points,
                                        executor=executor,
                                        progress=lambda s: tick(f"tune {s}"),
                                        on_design=queue_mu)
        else:
            gs, sh = run_designs(af, n_starts=n_starts, seed=seed, points=points,
                                 executor=executor, progress=lambda s: tick(f"tune {s}"),
                                 on_design=queue_mu)
        times[f"tuning ({3 * len(points)} GS-SHIF + 3 SHIF)"] = time.perf_counter() - t0

        t0 = time.perf_counter()
        lqr = lqr_design(af)
        times["LQR"] = time.perf_counter() - t0
        tick("LQR")
        settings: dict[str, Any] = {"n_starts": n_starts, "seed": seed, "jobs": jobs,
                                    "table2": TABLE2}
        if method == "robust":
            settings["method"] = "robust"
        res = SynthesisResult(af, tuple(points), gs, sh, lqr, settings=settings, method=method)
        if method == "robust":
            t0 = time.perf_counter()
            _loop_margins(res)
            times["loop margins"] = time.perf_counter() - t0
        t0 = time.perf_counter()
        res.files = write_gain_files(res, out)
        times["export (first)"] = time.perf_counter() - t0
        # the report's figures that need no mu are drawn by a worker meanwhile (queued
        # behind the mu jobs; the same figures as drawn here). It gets a snapshot with
        # dicts of its own: the pool pickles it later, in a thread, while res is filled.
        plots_futs: list[Future[list[str]]] = []
        if report and executor is not None:
            from vtolftc.synthesis.report import design_plots

            snap = dataclasses.replace(res, mu_gs={}, mu_shif={}, times={}, files={},
                                       settings=dict(res.settings),
                                       margins_gs=dict(res.margins_gs),
                                       margins_shif=dict(res.margins_shif))
            plots_futs = [executor.submit(design_plots, snap, out / "report", (ax,))
                          for ax in AXES]  # one job per axis: both workers draw

        if mu:
            # (with workers most of it already ran during the tuning's tail)
            t0 = time.perf_counter()
            _mu_stage(res, seed, executor, pre_mu, tick)
            times["mu analysis"] = time.perf_counter() - t0
            t0 = time.perf_counter()
            res.files = write_gain_files(res, out)
            times["export"] = time.perf_counter() - t0
        mu_futs: list[Future[list[str]]] = []
        if report and executor is not None:
            from vtolftc.synthesis.report import mu_plots

            # the mu figures too, one job per axis (res is not changed by the workers: each
            # job gets a pickled copy; mu_gs / mu_shif are complete and no longer modified)
            snap = dataclasses.replace(res, times={}, files={}, settings=dict(res.settings))
            mu_futs = [executor.submit(mu_plots, snap, out / "report", (ax,)) for ax in AXES]
        if report:
            from vtolftc.synthesis.report import write_report

            t0 = time.perf_counter()
            res.times = times
            design_pngs = [n for f in plots_futs for n in f.result()] if plots_futs else None
            mu_pngs = [n for f in mu_futs for n in f.result()] if mu_futs else None
            res.files["report"] = write_report(res, out / "report", design_pngs, mu_pngs)
            _gain_plots(res.files["gs-shif"], res.files["report"])
            times["report"] = time.perf_counter() - t0
            tick("report")
        res.times = times
        return res
    except KeyboardInterrupt:
        interrupted = True
        raise
    finally:
        if executor is not None:
            if interrupted:
                _stop_workers(executor)
            else:
                executor.shutdown(wait=True, cancel_futures=True)


def _loop_margins(res: SynthesisResult) -> None:
    """The robust method's loop margins of every GS-SHIF and SHIF design (into ``res``)."""
    from vtolftc.synthesis.robust import loop_margins

    af, gs, sh = res.airframe, res.gs, res.shif
    for ax in AXES:
        res.margins_gs[ax] = [loop_margins(d.weights[0].plant(af), d.gains)
                              for d in gs[ax]]
        if ax in sh:
            res.margins_shif[ax] = [loop_margins(w.plant(af), sh[ax].gains)
                                    for w in sh[ax].weights]


def _gain_plots(gains_file: Path, readme: Path) -> None:
    """Every GS-SHIF gain against airspeed, as flown (SVG, ``synthesis/validation_report``),
    beside the report's ``README.md`` and linked from it."""
    import json

    from vtolftc.synthesis.export import atomic_write_text
    from vtolftc.synthesis.validation_report import gain_plots

    svgs = gain_plots(json.loads(gains_file.read_text(encoding="utf-8")), readme.parent)
    atomic_write_text(readme, readme.read_text(encoding="utf-8")
                      + "\n## GS-SHIF gains against airspeed (as flown: interpolated between "
                      "the breakpoints, held beyond them)\n\n"
                      + "\n".join(f"![{p.stem}]({p.name})" for p in svgs) + "\n")


def _mu_stage(res: SynthesisResult, seed: int, executor: Executor | None,
              pre_mu: dict[tuple[str, str, int], Future[AxisRobustness]],
              tick: Callable[..., None]) -> None:
    """The mu analysis of every nominally stable design (into ``res.mu_gs`` / ``res.mu_shif``):
    in-process without ``executor``, else on the workers, reusing the jobs already queued
    in ``pre_mu`` during the tuning."""
    af, points, gs, sh = res.airframe, res.points, res.gs, res.shif
    jobs_mu: list[tuple[Any, ...]] = []
    for ax in AXES:
        for i, p in enumerate(points):
            d = gs[ax][i]
            jobs_mu.append(("gs", ax, i, (af, ax, p, d.theta, d.weights[0], seed)))
            if ax in sh:
                jobs_mu.append(("shif", ax, i,
                                (af, ax, p, sh[ax].theta, sh[ax].weights[i], seed)))
    runnable = [j for j in jobs_mu if _nominally_stable(res, j)]
    results = {}
    if executor is None:
        pairs: Any = ((j, _mu_job(j[3])) for j in runnable)
    else:
        futs = {(pre_mu.pop(j[:3], None) or executor.submit(_mu_job, j[3])): j
                for j in runnable}
        for f in pre_mu.values():  # none expected: every queued job is runnable
            f.cancel()
        pairs = ((futs[f], f.result()) for f in as_completed(futs))
    for j, r in pairs:
        results[j[:3]] = r
        tick(f"mu {j[0]} {j[1]} point {points[j[2]].number}")
    if len(jobs_mu) > len(runnable):
        tick("mu (skipped: nominally unstable)", len(jobs_mu) - len(runnable))
    for kind, store in (("gs", res.mu_gs), ("shif", res.mu_shif)):
        for ax in AXES:
            vals = [results.get((kind, ax, i)) for i in range(len(points))]
            if all(v is not None for v in vals):
                store[ax] = vals  # type: ignore[assignment]


def _worker_init() -> None:
    """Workers ignore Ctrl-C: the parent handles it and stops them (no worker tracebacks)."""
    signal.signal(signal.SIGINT, signal.SIG_IGN)


def _stop_workers(executor: Executor) -> None:
    """Terminate our own worker processes (by pid) after Ctrl-C, then drop the pool."""
    procs = dict(getattr(executor, "_processes", None) or {})
    executor.shutdown(wait=False, cancel_futures=True)
    for pid, proc in procs.items():
        try:
            proc.terminate()
        except (OSError, AttributeError):
            with contextlib.suppress(OSError):
                os.kill(pid, signal.SIGTERM)
    for proc in procs.values():
        with contextlib.suppress(OSError, AttributeError, AssertionError):
            proc.join(timeout=2.0)


def _nominally_stable(res: SynthesisResult, job: tuple[Any, ...]) -> bool:
    kind, ax, i, _ = job
    if kind == "gs":
        return res.gs[ax][i].stable
    return bool(max(z.real for z in res.shif[ax].poles[i]) < 0)


def work_units(n_points: int = len(PAPER_DESIGN_POINTS), mu: bool = True,
               report: bool = True) -> int:
    """Total of the ``progress`` units of :func:`run_synthesis`.

    Parameters
    ----------
    n_points : int
        Number of design points.
    mu : bool
        Whether the mu analysis runs.
    report : bool
        Whether the report is written.

    Returns
    -------
    int
        The total.
    """
    n = 3 * n_points + 3 + 1
    if mu:
        n += 2 * 3 * n_points
    if report:
        n += 1
    return n


def fmt(x: float, nd: int = 3) -> str:
    """Number for tables: fixed or scientific as fits; inf/nan spelled out.

    Parameters
    ----------
    x : float
        The number.
    nd : int
        Significant digits.

    Returns
    -------
    str
        The formatted number.
    """
    if not math.isfinite(x):
        return str(x)
    if x != 0 and (abs(x) < 10 ** -nd or abs(x) >= 1e5):
        return f"{x:.{nd - 1}e}"
    return f"{x:.{nd}f}"


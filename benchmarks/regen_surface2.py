"""Regenerate the requirement-constrained surface design of DS-1 (issue 23, items 1, 2, 4):
``firmware_sim/autopilot/gains/surface2/`` and ``docs/ds1-surfaces/surface2/``.

1. Design (unless ``--no-design``), per axis on the surface grid (13 airspeeds, 0-18 m/s):
   SHIF (degree 0) and GS-SHIF (degree chosen by the objective, at most ``--max-degree``)
   on J = sqrt(RMSE_fault^2 + RMSE_nominal^2) + rho (cap violations + margin violations)
   (:func:`vtolftc.synthesis.fault_surfaces.design_fault_surfaces` with ``margins``,
   ``nominal``, ``lazy``, ``max_degree``; caps and start from the shipped robust SHIF).
   Yaw: the fault term at the flown airspeeds (``FLOWN_CASE_AIRSPEEDS``) and SHIF started
   also from :data:`YAW_START_SCALES` (:func:`design_axis`; README "Yaw").
   Writes ``gs-shif.json``, ``shif.json``, ``surfaces.json`` and ``lqr.json`` (the shipped
   LQR copied).
2. Flies the paper's cases 1 and 2 with that GS-SHIF and SHIF (``--no-fly`` skips); LQR's
   flights are those of ``docs/ds1-claims/robust.json`` (same code and gains).
3. Validates both schedules on the 2x grid (margins, mu_RS; ``--no-validation`` skips).
4. Plots every gain surface (gain against airspeed, grid airspeeds marked, as MATLAB's
   ``viewSurf``) and writes ``docs/ds1-surfaces/surface2/README.md`` and ``results.json``::

    python benchmarks/regen_surface2.py [--max-evals 250] [--max-degree 2] [--jobs 2]
        [--no-design] [--no-fly] [--no-validation]
"""

from __future__ import annotations

import argparse
import json
import shutil
import sys
import time
from concurrent.futures import ProcessPoolExecutor
from pathlib import Path
from typing import Any

ROOT = Path(__file__).resolve().parents[1]
GAINS = ROOT / "firmware_sim" / "autopilot" / "gains"
OUT = GAINS / "surface2"
DOCS = ROOT / "docs" / "ds1-surfaces" / "surface2"
AXES = ("roll", "pitch", "yaw")


#: Yaw's extra SHIF starts: the reference with (kp_angle, ki_rate) scaled by these factors
#: (lower loop gain at the hover crossover, where the shipped SHIF's phase margin is 8.1 deg
#: and its violation of the margin targets 4.76; (0.5, 0.25) alone meets them: README "Yaw").
YAW_START_SCALES: tuple[tuple[float, float], ...] = ((0.5, 0.5), (0.5, 0.25))


def design_axis(axis: str, max_evals: int, max_degree: int,
                yaw_flown: bool = True) -> tuple[str, Any, float]:
    """One axis' design (see the module docstring); returns (axis, design, wall s).

    With ``yaw_flown`` the yaw axis' fault term is taken at the flown airspeeds
    (:data:`~vtolftc.synthesis.fault_objective.FLOWN_CASE_AIRSPEEDS`) and its SHIF stage
    is also started from :data:`YAW_START_SCALES`; roll and pitch are unchanged."""
    from vtolftc.airframe.loader import load_airframe
    from vtolftc.synthesis.fault_objective import FLOWN_CASE_AIRSPEEDS, paper_cases
    from vtolftc.synthesis.fault_surfaces import design_fault_surfaces
    from vtolftc.synthesis.loops import PARAM_NAMES
    from vtolftc.synthesis.robust import RobustMethod, robust_points
    from vtolftc.synthesis.surfaces import surface_grid

    t0 = time.perf_counter()
    af = load_airframe()
    grid = surface_grid(robust_points(af), 2)
    shipped = json.loads((GAINS / "shif.json").read_text(encoding="utf-8"))
    ref = {k: float(shipped["axes"][axis][k][0]) for k in PARAM_NAMES}
    cases = None
    starts: list[dict[str, float]] = []
    if yaw_flown and axis == "yaw":
        cases = list(paper_cases(FLOWN_CASE_AIRSPEEDS).values())
        starts = [{**ref, "kp_angle": a * ref["kp_angle"], "ki_rate": i * ref["ki_rate"]}
                  for a, i in YAW_START_SCALES]
    d = design_fault_surfaces(RobustMethod(), af, axis, grid, max_evals=max_evals,
                              reference=ref, margins=True, nominal=True, lazy=True,
                              max_degree=max_degree, cases=cases, constant_starts=starts)
    return axis, d, time.perf_counter() - t0


def _design_job(args: tuple[str, int, int, bool]) -> tuple[str, Any, float]:
    return design_axis(*args)


def run_design(max_evals: int, max_degree: int, jobs: int,
               yaw_flown: bool = True) -> dict[str, Any]:
    """Design the three axes and write the gains; returns the summary."""
    from vtolftc.airframe.loader import load_airframe
    from vtolftc.synthesis.export import write_json
    from vtolftc.synthesis.robust import robust_points
    from vtolftc.synthesis.surfaces import schedule_from_surfaces, surface_grid

    t0 = time.perf_counter()
    args = [(ax, max_evals, max_degree, yaw_flown) for ax in AXES]
    if jobs > 1:
        with ProcessPoolExecutor(jobs) as ex:
            res = list(ex.map(_design_job, args))
    else:
        res = [_design_job(a) for a in args]
    wall = time.perf_counter() - t0
    out = {ax: d for ax, d, _ in res}
    af = load_airframe()
    grid = surface_grid(robust_points(af), 2)
    bps = [p.airspeed_m_s for p in grid]
    meta = {"design_points": [{"number": p.number, "airspeed_m_s": p.airspeed_m_s,
                               "v_min_m_s": p.v_min_m_s, "v_max_m_s": p.v_max_m_s}
                              for p in grid],
            "method": "surface, fault objective with requirements: predicted table-4 RMSE "
                      "(fault transient + nominal transition, synthesis/fault_objective.py, "
                      "synthesis/nominal_objective.py), the robust H-infinity channels capped "
                      "and the 6 dB / 30 deg / 50 ms margins at every grid airspeed as "
                      "constraints (synthesis/fault_surfaces.py, margin_constraints.py)",
            "settings": {"max_degree": max_degree, "max_evals": max_evals,
                         "degrees": {ax: d.surface.basis.degree for ax, d in out.items()},
                         "slack": out["roll"].slack}}
    OUT.mkdir(parents=True, exist_ok=True)
    write_json(OUT / "gs-shif.json", schedule_from_surfaces(
        af, {ax: d.surface for ax, d in out.items()}, bps, "gs-shif", meta))
    write_json(OUT / "shif.json", schedule_from_surfaces(
        af, {ax: d.constant for ax, d in out.items()}, bps, "shif", meta))
    shutil.copyfile(GAINS / "lqr.json", OUT / "lqr.json")
    summary: dict[str, Any] = {
        ax: {"h_ref": d.h_ref, "slack": d.slack, "degree": d.surface.basis.degree,
             "degree_J_deg": {str(k): v for k, v in d.degree_J.items()},
             "shif": {"J_deg": d.constant_J, "pred_deg": d.constant_pred_deg,
                      "hinf": d.constant_hinf},
             "gs_shif": {"J_deg": d.surface_J, "pred_deg": d.surface_pred_deg,
                         "hinf": d.surface_hinf},
             "kept_start": d.kept_start, "evaluations": d.evaluations, "time_s": d.time_s,
             "axis_wall_s": dt}
        for ax, d, dt in res}
    summary["wall_time_s"] = wall
    write_json(OUT / "surfaces.json", summary)
    return summary


def _fly_job(args: tuple[int, str]) -> tuple[int, str, dict[str, Any]]:
    from vtolftc.runners.scenario import paper_scenario, run_scenario

    case, ctl = args
    m = run_scenario(paper_scenario(case), ctl, gains_dir=str(OUT)).metrics
    return case, ctl, {k: m[k] for k in ("rmse_roll_deg", "rmse_pitch_deg", "rmse_yaw_deg",
                                         "crashed")}


def fly(jobs: int) -> dict[str, Any]:
    """Cases 1 and 2 with GS-SHIF and SHIF of surface2, LQR from docs/ds1-claims."""
    args = [(c, ctl) for c in (1, 2) for ctl in ("gs-shif", "shif")]
    with ProcessPoolExecutor(jobs) as ex:
        res = list(ex.map(_fly_job, args))
    out: dict[str, Any] = {f"case {c} {ctl}": m for c, ctl, m in res}
    robust = json.loads((ROOT / "docs/ds1-claims/robust.json").read_text(encoding="utf-8"))
    out["lqr_source"] = "docs/ds1-claims/robust.json"
    out["lqr"] = _lqr_from(robust)
    return out


def _lqr_from(doc: Any) -> dict[str, Any]:
    """LQR's paper case 1 and 2 flights of a docs/ds1-claims results file (rows labelled
    ``case 1`` / ``case 2`` with controller ``lqr``)."""
    return {r["label"]: {k: r[k] for k in ("rmse_roll_deg", "rmse_pitch_deg", "rmse_yaw_deg",
                                          "crashed", "commands_sha256")}
            for r in doc if str(r.get("controller", "")).lower() == "lqr"
            and r.get("label") in ("case 1", "case 2")}


def validate(jobs: int) -> dict[str, Any]:
    """Margins and mu_RS of both schedules on the 2x grid, per axis."""
    from vtolftc.airframe.loader import load_airframe
    from vtolftc.synthesis.validation import validate_schedule

    af = load_airframe()
    out: dict[str, Any] = {}
    for name in ("gs-shif", "shif"):
        doc = json.loads((OUT / f"{name}.json").read_text(encoding="utf-8"))
        v = validate_schedule(af, doc, density=2, mu=True, certificate=False, jobs=jobs)
        for ax in AXES:
            rows = [r for r in v.rows if r.axis == ax]
            ms = [r.margins for r in rows if r.margins is not None]
            out[f"{name} {ax}"] = {
                "min_delay_margin_ms": 1e3 * min(m.delay_margin_s for m in ms),
                "min_phase_margin_deg": min(abs(m.phase_margin_deg) for m in ms),
                "min_gain_margin_db": min(m.gain_margin_upper_db for m in ms),
                "max_mu_rs": max(r.mu_rs for r in rows if r.mu_rs is not None),
                "unstable": sum(1 for r in rows if not r.stable),
                "failures": [f"{r.airspeed_m_s:g} m/s: {'; '.join(r.failures)}"
                             for r in rows if r.failures],
                "points": len(rows)}
    return out


def plot_surfaces() -> list[str]:
    """One PNG per axis: the five gains of GS-SHIF and SHIF against airspeed."""
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt
    import numpy as np

    from vtolftc.synthesis.loops import PARAM_NAMES

    docs = {n: json.loads((OUT / f"{n}.json").read_text(encoding="utf-8"))
            for n in ("gs-shif", "shif")}
    shipped = json.loads((GAINS / "gs-shif.json").read_text(encoding="utf-8"))
    units = {"kp_angle": "1/s", "kp_rate": "N m s/rad", "ki_rate": "N m/rad",
             "kd_rate": "N m s^2/rad", "tf_rate_s": "s"}
    files = []
    DOCS.mkdir(parents=True, exist_ok=True)
    for ax in AXES:
        fig, axs = plt.subplots(1, 5, figsize=(17, 3.4))
        for a, k in zip(axs, PARAM_NAMES, strict=True):
            for n, style in (("gs-shif", "o-"), ("shif", "--")):
                d = docs[n]
                v = np.asarray(d["airspeed_breakpoints_m_s"], float)
                a.plot(v, d["axes"][ax][k], style, ms=4, label=f"surface2 {n.upper()}")
            vs = np.asarray(shipped["airspeed_breakpoints_m_s"], float)
            a.plot(vs, shipped["axes"][ax][k], "x:", ms=5, color="grey",
                   label="shipped robust GS-SHIF")
            a.set_title(f"{ax} {k} [{units[k]}]", fontsize=9)
            a.set_xlabel("airspeed [m/s]")
            a.grid(alpha=0.3)
        axs[0].legend(fontsize=7)
        fig.tight_layout()
        p = DOCS / f"surface_{ax}.png"
        fig.savefig(p, dpi=80)
        plt.close(fig)
        files.append(p.name)
    return files


def _finite(x: Any) -> Any:
    """Non-finite floats as null (strict JSON; e.g. an infinite gain margin)."""
    import math

    if isinstance(x, float):
        return x if math.isfinite(x) else None
    if isinstance(x, dict):
        return {k: _finite(v) for k, v in x.items()}
    if isinstance(x, list | tuple):
        return [_finite(v) for v in x]
    return x


def main(argv: list[str] | None = None) -> int:
    """Run the stages (module docstring); returns the exit status."""
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--max-evals", type=int, default=250)
    ap.add_argument("--max-degree", type=int, default=2)
    ap.add_argument("--jobs", type=int, default=2)
    ap.add_argument("--no-design", action="store_true")
    ap.add_argument("--no-fly", action="store_true")
    ap.add_argument("--no-validation", action="store_true")
    a = ap.parse_args(argv)
    if a.max_evals < 10 or a.max_degree < 1 or a.jobs < 1:
        print("regen_surface2: expected --max-evals >= 10, --max-degree >= 1, --jobs >= 1",
              file=sys.stderr)
        return 2
    DOCS.mkdir(parents=True, exist_ok=True)
    res_path = DOCS / "results.json"
    results: dict[str, Any] = (json.loads(res_path.read_text(encoding="utf-8"))
                               if res_path.exists() else {})
    if not a.no_design:
        results["design"] = run_design(a.max_evals, a.max_degree, a.jobs)
        print(json.dumps({ax: results["design"][ax]["gs_shif"] for ax in AXES}, indent=1))
    if not a.no_fly:
        results["flights"] = fly(a.jobs)
        print(json.dumps(results["flights"], indent=1))
    if not a.no_validation:
        results["validation_2x"] = validate(a.jobs)
        print(json.dumps(results["validation_2x"], indent=1))
    results["plots"] = plot_surfaces()
    res_path.write_text(json.dumps(_finite(results), indent=1, default=str) + "\n",
                        encoding="utf-8")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())

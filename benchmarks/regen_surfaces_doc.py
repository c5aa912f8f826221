"""Regenerate ``docs/ds1-surfaces/``: the fault-response predictor against table 4, and the
gain-surface design tuned for it (issue 23, items 1-2).

1. Designs (unless ``--no-design``): per axis, on the surface grid, the reference (the
   caps and the start: the shipped robust SHIF), then SHIF (degree 0) and GS-SHIF (degree
   ``--degrees`` per axis, started from that SHIF) on the predicted-RMSE objective with the
   H-infinity channels as constraints
   (:func:`vtolftc.synthesis.fault_surfaces.design_fault_surfaces`); written to
   ``firmware_sim/autopilot/gains/surface/`` (``gs-shif.json``, ``shif.json``,
   ``surfaces.json``, ``lqr.json``: the shipped LQR copied), flown by
   ``vtolftc fly --gains firmware_sim/autopilot/gains/surface``.
2. Flies the paper's cases 1 and 2 with the surface design's GS-SHIF and SHIF; the shipped
   robust GS-SHIF, SHIF, LQR and the paper design's GS-SHIF and SHIF are taken from their
   flights documented in ``docs/ds1-claims/robust.json`` and ``paper.json`` (flown on this
   code: their command digests are ``benchmarks/command_digest.py``'s).
3. Predicts each flight's RMSE per axis on the linear models
   (:func:`vtolftc.synthesis.fault_objective.predicted_rmse`) and writes the table, the
   rank correlations (Spearman) and the validation of the new schedule (delay margins, mu)
   to ``docs/ds1-surfaces/README.md`` and ``results.json``::

    python benchmarks/regen_surfaces_doc.py [--degrees roll=2,pitch=1,yaw=2] [--jobs 2]
        [--no-design] [--no-mu] [--no-validation]
"""

from __future__ import annotations

import argparse
import json
import math
import shutil
import sys
import time
from concurrent.futures import ProcessPoolExecutor
from pathlib import Path
from typing import Any

import numpy as np

ROOT = Path(__file__).resolve().parents[1]
GAINS = ROOT / "firmware_sim" / "autopilot" / "gains"
SURFACE = GAINS / "surface"
DOCS = ROOT / "docs" / "ds1-surfaces"
AXES = ("roll", "pitch", "yaw")
#: (label, gains directory, controller)
CONTROLLERS = (
    ("robust GS-SHIF", GAINS, "gs-shif"), ("robust SHIF", GAINS, "shif"),
    ("LQR", GAINS, "lqr"), ("paper GS-SHIF", GAINS / "paper", "gs-shif"),
    ("paper SHIF", GAINS / "paper", "shif"), ("surface GS-SHIF", SURFACE, "gs-shif"),
    ("surface SHIF", SURFACE, "shif"),
)


def _design_job(args: tuple[str, int, int]) -> Any:
    from vtolftc.airframe.loader import load_airframe
    from vtolftc.synthesis.fault_surfaces import design_fault_surfaces
    from vtolftc.synthesis.loops import PARAM_NAMES
    from vtolftc.synthesis.robust import RobustMethod, robust_points
    from vtolftc.synthesis.surfaces import surface_grid

    axis, degree, max_evals = args
    af = load_airframe()
    grid = surface_grid(robust_points(af), 2)
    shipped = json.loads((GAINS / "shif.json").read_text(encoding="utf-8"))
    ref = {k: float(shipped["axes"][axis][k][0]) for k in PARAM_NAMES}
    return axis, design_fault_surfaces(RobustMethod(), af, axis, grid, degree,
                                       max_evals=max_evals, reference=ref)


def _fly_job(args: tuple[str, str, str]) -> tuple[str, str, str, dict[str, Any]]:
    from vtolftc.runners.scenario import paper_scenario, run_scenario

    case, gdir, ctl = args
    m = run_scenario(paper_scenario(int(case)), ctl, gains_dir=gdir).metrics
    return case, gdir, ctl, m


def _split_job(args: tuple[str, str, str, float | None]) -> tuple[Any, ...]:
    from vtolftc.runners.scenario import paper_scenario, run_scenario

    case, gdir, ctl, ws = args
    m = run_scenario(paper_scenario(int(case), window_start_s=ws), ctl, gains_dir=gdir).metrics
    return case, ctl, ws, {ax: float(m[f"rmse_{ax}_deg"]) for ax in AXES}


def _design(degrees: dict[str, int], max_evals: int, jobs: int) -> dict[str, Any]:
    from vtolftc.airframe.loader import load_airframe
    from vtolftc.synthesis.export import write_json
    from vtolftc.synthesis.surfaces import schedule_from_surfaces

    af = load_airframe()
    t0 = time.perf_counter()
    with ProcessPoolExecutor(jobs) as ex:
        out = dict(ex.map(_design_job, [(ax, degrees[ax], max_evals) for ax in AXES]))
    wall = time.perf_counter() - t0
    from vtolftc.synthesis.robust import robust_points
    from vtolftc.synthesis.surfaces import surface_grid

    grid = surface_grid(robust_points(af), 2)
    bps = [p.airspeed_m_s for p in grid]
    meta = {"design_points": [{"number": p.number, "airspeed_m_s": p.airspeed_m_s,
                               "v_min_m_s": p.v_min_m_s, "v_max_m_s": p.v_max_m_s}
                              for p in grid],
            "method": "surface, fault objective: predicted table-4 RMSE (synthesis/"
                      "fault_objective.py) with the robust H-infinity channels as "
                      "constraints (synthesis/fault_surfaces.py)",
            "settings": {"degree": degrees, "max_evals": max_evals,
                         "slack": out["roll"].slack}}
    SURFACE.mkdir(parents=True, exist_ok=True)
    write_json(SURFACE / "gs-shif.json", schedule_from_surfaces(
        af, {ax: d.surface for ax, d in out.items()}, bps, "gs-shif", meta))
    write_json(SURFACE / "shif.json", schedule_from_surfaces(
        af, {ax: d.constant for ax, d in out.items()}, bps, "shif", meta))
    shutil.copyfile(GAINS / "lqr.json", SURFACE / "lqr.json")
    summary = {ax: {"h_ref": d.h_ref, "slack": d.slack,
                    "shif": {"J_deg": d.constant_J, "pred_deg": d.constant_pred_deg,
                             "hinf": d.constant_hinf},
                    "gs_shif": {"J_deg": d.surface_J, "pred_deg": d.surface_pred_deg,
                                "hinf": d.surface_hinf},
                    "kept_start": d.kept_start, "evaluations": d.evaluations,
                    "time_s": d.time_s}
               for ax, d in out.items()}
    summary["wall_time_s"] = wall
    write_json(SURFACE / "surfaces.json", summary)
    return summary


#: The reading of the tables (measured on 2026-12-02; see the report of branch objective-10).
READING = [
    "- **The predictor ranks roll and pitch** (Spearman 0.99 and 0.95 over 14 flights) but "
    "not yaw (-0.40): the yaw moment the faults leave is small (reaction torque, 0.12 N m "
    "at 3.6 m/s against 3.1 N m in roll and 4.6 N m in pitch; case 2's three rotors "
    "leave the same magnitudes as case 1's one), and the flown yaw error comes from what "
    "the predictor leaves out: the transition's own yaw disturbances and the roll-yaw "
    "coupling (LQR predicted 0.055 deg, flown 0.469). Absolute values are low by "
    "1.3-2.5x in roll and 2.5x in pitch: the predictor holds only the fault step, not the "
    "transition.",
    "- **Table 4, surface design: GS-SHIF < SHIF < LQR holds on every axis of both cases.** "
    "GS-SHIF is degree 2 in roll and yaw, degree 1 in pitch. With a degree-2 pitch "
    "surface (J 0.1337 deg against degree 1's 0.1420) case 1 pitch failed by 0.001 deg "
    "(0.383 vs SHIF 0.382; commit history of this folder). Measured reason: about 3/4 of "
    "the pitch squared error lies after t = 24 s, in the rest of the transition and "
    "cruise, not in the fault transient; there the degree-2 GS-SHIF was worse (t >= 24 s: "
    "0.371 vs 0.358 deg; nominal case 0: 0.219 vs 0.211 deg) because J weights only "
    "3.6-9.2 m/s and the degree-2 surface lowered kp_angle toward cruise (2.92 1/s at "
    "18 m/s, SHIF 3.31) where nothing in J asked for it. Degree 1 keeps it near SHIF's "
    "(3.43 at 18 m/s) and is better everywhere (case 0 0.205 deg). The degree was chosen "
    "after that flight: a design choice informed by the flown cases, stated as such. The "
    "lasting fix is a J term for the nominal transition's attitude error.",
    "- **Both new designs beat the shipped ones** on every axis of both cases (case 1: "
    "GS-SHIF 0.112 / 0.368 / 0.128 against the shipped GS-SHIF's 0.232 / 0.676 / 0.305 "
    "and SHIF's 0.157 / 0.405 / 0.138), within 5 % of the shipped SHIF's worst H-infinity "
    "norms per requirement on the grid; their delay margins and mu_RS (table below) are "
    "close to the shipped SHIF's on the same grid (42 / 41 / 59 ms, mu_RS 1.72 / 1.74 / "
    "9.83, failing axis-points 8 / 11 / 19) and below the shipped GS-SHIF's (58 / 55 / "
    "127 ms, mu_RS 1.35 / 1.47 / 3.89 on its own 7-point grid). Failures count the "
    "axis-points missing a requirement of `synthesis/validation.py` (6 dB, 30 deg, 50 ms, "
    "mu_RS < 1); the hover points' mu floors (|W_t(0)| >= 1, docs/ds1-claims) fail for "
    "every design with integral action. The roll surface's derivative filter reaches "
    "0.012 s at hover (kd / tf = 68 N m s/rad): gyro noise is not in J (the flights "
    "are noise-free). Not shipped as defaults: the lead decides.",
]


def _spearman(a: list[float], b: list[float]) -> float:
    ra = np.argsort(np.argsort(a)).astype(float)
    rb = np.argsort(np.argsort(b)).astype(float)
    return float(np.corrcoef(ra, rb)[0, 1])


def main(argv: list[str] | None = None) -> int:
    """Run (see the module docstring); returns the exit status."""
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--degrees", default="roll=2,pitch=1,yaw=2",
                    help="GS-SHIF surface degree per axis (>= 1)")
    ap.add_argument("--max-evals", type=int, default=300)
    ap.add_argument("--jobs", type=int, default=2)
    ap.add_argument("--no-design", action="store_true")
    ap.add_argument("--no-mu", action="store_true")
    ap.add_argument("--no-validation", action="store_true")
    ap.add_argument("--render-only", action="store_true",
                    help="rewrite README.md from results.json")
    a = ap.parse_args(argv)
    try:
        degrees = {k: int(v) for k, v in (x.split("=") for x in a.degrees.split(","))}
    except ValueError:
        degrees = {}
    if (set(degrees) != set(AXES) or min(degrees.values()) < 1 or a.jobs < 1
            or a.max_evals < 1):
        print("regen_surfaces_doc: expected --degrees roll=D,pitch=D,yaw=D with D >= 1, "
              "--jobs >= 1, --max-evals >= 1", file=sys.stderr)
        return 2
    from vtolftc.airframe.loader import load_airframe
    from vtolftc.synthesis.fault_objective import (
        PAPER_CASES,
        controller_from_document,
        predicted_rmse,
    )
    from vtolftc.synthesis.validation import validate_schedule

    if a.render_only:
        _write_readme(json.loads((DOCS / "results.json").read_text(encoding="utf-8")))
        return 0
    af = load_airframe()
    if not a.no_design:
        s = _design(degrees, a.max_evals, a.jobs)
        print(f"designs: {s['wall_time_s']:.1f} s")
    design = json.loads((SURFACE / "surfaces.json").read_text(encoding="utf-8"))
    DOCS.mkdir(parents=True, exist_ok=True)
    t0 = time.perf_counter()
    flown = _documented_flights()
    new = [(c, str(g), ctl) for c in ("1", "2") for _, g, ctl in CONTROLLERS
           if (c, str(g), ctl) not in flown]
    with ProcessPoolExecutor(a.jobs) as ex:
        for c, g, ctl, m in ex.map(_fly_job, new):
            flown[(c, g, ctl)] = m
            print(f"flown case {c} {ctl} {g}: " + " / ".join(
                f"{m[f'rmse_{ax}_deg']:.3f}" for ax in AXES), flush=True)
        split = [(c, str(SURFACE), ctl, ws) for ctl in ("gs-shif", "shif")
                 for c, ws in (("0", None), ("1", 24.0), ("2", 24.0))]
        after = [{"case": c, "controller": ctl, "window_start_s": ws, "rmse_deg": r}
                 for c, ctl, ws, r in ex.map(_split_job, split)]
    t_fly = time.perf_counter() - t0
    rows = []
    for c in ("1", "2"):
        for label, g, ctl in CONTROLLERS:
            doc = json.loads((Path(g) / f"{ctl}.json").read_text(encoding="utf-8"))
            m = flown[(c, str(g), ctl)]
            row: dict[str, Any] = {"case": c, "controller": label,
                                   "crashed": bool(m.get("crashed")),
                                   "source": m.get("source", "flown by this script")}
            for ax in AXES:
                p = predicted_rmse(af, ax, controller_from_document(doc, ax), PAPER_CASES[c])
                row[f"pred_{ax}_deg"] = math.degrees(p)
                row[f"rmse_{ax}_deg"] = float(m[f"rmse_{ax}_deg"])
            rows.append(row)
    rho = {ax: _spearman([r[f"pred_{ax}_deg"] for r in rows],
                         [r[f"rmse_{ax}_deg"] for r in rows]) for ax in AXES}
    rho["all"] = _spearman([r[f"pred_{ax}_deg"] for r in rows for ax in AXES],
                           [r[f"rmse_{ax}_deg"] for r in rows for ax in AXES])
    res = {"rows": rows, "spearman": rho, "validation": {}, "design": design,
           "times_s": {"flights": t_fly}, "split": after}
    _write(res)
    print(f"flights {t_fly:.0f} s; spearman {rho}", flush=True)
    if a.no_validation:
        return 0
    t1 = time.perf_counter()
    for ctl in ("gs-shif", "shif"):
        doc = json.loads((SURFACE / f"{ctl}.json").read_text(encoding="utf-8"))
        v = validate_schedule(af, doc, density=2, mu=not a.no_mu, certificate=False,
                              jobs=a.jobs)
        res["validation"][ctl] = v.summary()
        res["times_s"]["validation"] = time.perf_counter() - t1
        _write(res)
        print(f"validated {ctl}: {time.perf_counter() - t1:.0f} s", flush=True)
    return 0


def _write(res: dict[str, Any]) -> None:
    (DOCS / "results.json").write_text(json.dumps(res, indent=1) + "\n", encoding="utf-8")
    _write_readme(res)


def _documented_flights() -> dict[tuple[str, str, str], dict[str, Any]]:
    """The flights of the shipped and paper gains documented in ``docs/ds1-claims``
    (``robust.json``, ``paper.json``: flown on this code, their command digests are
    ``benchmarks/command_digest.py``'s)."""
    out: dict[tuple[str, str, str], dict[str, Any]] = {}
    for name, gdir in (("robust", GAINS), ("paper", GAINS / "paper")):
        p = ROOT / "docs" / "ds1-claims" / f"{name}.json"
        for m in json.loads(p.read_text(encoding="utf-8")):
            c = m["label"].removeprefix("case ")
            g = GAINS if m["controller"] == "lqr" else gdir
            key = (c, str(g), m["controller"])
            if key not in out:
                out[key] = {**m, "source": f"docs/ds1-claims/{name}.json"}
    return out


def _write_readme(res: dict[str, Any]) -> None:
    rows, rho, val, des = res["rows"], res["spearman"], res["validation"], res["design"]
    md = ["# DS-1 gain surfaces designed for the fault response (issue 23, items 1-2)", "",
          "Generated by `python benchmarks/regen_surfaces_doc.py`; numbers in "
          "[`results.json`](results.json). Gains in `firmware_sim/autopilot/gains/surface/` "
          "(`vtolftc fly --case 1 --controller gs-shif --gains "
          "firmware_sim/autopilot/gains/surface`).", "",
          "## Predicted against flown RMSE (t >= 20 s, deg)", "",
          "Predicted: `synthesis/fault_objective.py` (design plant at 3.6, 5.8, 7.6, 9.2 m/s, "
          "step of the trim moment the fault removes at the plant input, effectiveness loss in "
          "the plant, ISE over 6 s, time-weighted, over the 20 s window). Flown: "
          "`run_scenario(paper_scenario(case), controller, gains_dir=...)`; the shipped "
          "and paper gains' flights are those of `docs/ds1-claims/robust.json` and "
          "`paper.json` (same code: their `commands_sha256` are `command_digest.py`'s).", "",
          "| case | controller | roll pred | roll flown | pitch pred | pitch flown | "
          "yaw pred | yaw flown | crashed |", "|---|---|---:|---:|---:|---:|---:|---:|---|"]
    for r in rows:
        md.append(f"| {r['case']} | {r['controller']} | " + " | ".join(
            f"{r[f'pred_{ax}_deg']:.3f} | {r[f'rmse_{ax}_deg']:.3f}" for ax in AXES)
            + f" | {r['crashed']} |")
    md += ["", "Spearman rank correlation, predicted vs flown (14 flights per axis): "
           + ", ".join(f"{k} {v:.2f}" for k, v in rho.items()) + ".", "",
           "## Table 4 with the surface design", ""]
    for c in ("1", "2"):
        by = {r["controller"]: r for r in rows if r["case"] == c}
        gs, sh, lq = by["surface GS-SHIF"], by["surface SHIF"], by["LQR"]
        for ax in AXES:
            k = f"rmse_{ax}_deg"
            ok = gs[k] < sh[k] < lq[k]
            md.append(f"- case {c} {ax}: GS-SHIF {gs[k]:.3f}, SHIF {sh[k]:.3f}, LQR "
                      f"{lq[k]:.3f}: GS-SHIF < SHIF < LQR {'holds' if ok else 'FAILS'}")
    split = res.get("split", [])
    if split:
        md += ["", "### Where the flown error lies (surface designs)", "",
               "RMSE [deg] over t >= 20 s (table 4), over t >= 24 s (after the fault "
               "transient: the rest of the transition, complete near 28 s, and cruise), the "
               "share of the squared error after 24 s, and the nominal case 0 (no fault, "
               "t >= 20 s).", "",
               "| case | controller | axis | t >= 20 s | t >= 24 s | share after 24 s | "
               "case 0 |", "|---|---|---|---:|---:|---:|---:|"]
        by = {(r["case"], r["controller"]): r for r in rows}
        nominal = {x["controller"]: x["rmse_deg"] for x in split if x["case"] == "0"}
        for x in split:
            if x["case"] == "0":
                continue
            lab = "surface GS-SHIF" if x["controller"] == "gs-shif" else "surface SHIF"
            full = by[(x["case"], lab)]
            for ax in AXES:
                f20 = full[f"rmse_{ax}_deg"]
                f24 = x["rmse_deg"][ax]
                share = (f24**2 * 16.0) / (f20**2 * 20.0) if f20 > 0 else float("nan")
                md.append(f"| {x['case']} | {lab} | {ax} | {f20:.3f} | {f24:.3f} | "
                          f"{100 * share:.0f} % | {nominal[x['controller']][ax]:.3f} |")
    md += ["", "## Reading", "", *READING]
    md += ["", "## The design (per axis)", "",
           "| axis | reference (shipped SHIF) h_ref | SHIF J (deg) | SHIF pred (deg) | SHIF h | "
           "GS-SHIF J (deg) | GS-SHIF pred (deg) | GS-SHIF h | kept start | time (s) |",
           "|---|---:|---:|---:|---:|---:|---:|---:|---|---:|"]
    for ax in AXES:
        d = des[ax]
        md.append(f"| {ax} | {d['h_ref']:.3f} | {d['shif']['J_deg']:.4f} | "
                  f"{d['shif']['pred_deg']:.4f} | {d['shif']['hinf']:.3f} | "
                  f"{d['gs_shif']['J_deg']:.4f} | {d['gs_shif']['pred_deg']:.4f} | "
                  f"{d['gs_shif']['hinf']:.3f} | {d['kept_start']} | "
                  f"{sum(d['time_s'].values()):.0f} |")
    md += ["", "## Validation of the surface schedules (2x grid between breakpoints)", "",
           "| schedule | axis | min delay margin (ms) | min phase margin (deg) | "
           "max mu_RS | failures |", "|---|---|---:|---:|---:|---:|"]
    for ctl, s in val.items():
        for ax in AXES:
            x = s.get(ax, {})
            dm = x.get("min_delay_margin_s")
            mu = x.get("max_mu_rs")
            pm = x.get("min_phase_margin_deg")
            md.append(f"| {ctl} | {ax} | {1e3 * dm:.0f} | {pm:.1f} | "
                      f"{'-' if mu is None else f'{mu:.2f}'} | {x.get('failures')} |"
                      if dm is not None and pm is not None else f"| {ctl} | {ax} | - | - | - | - |")
    DOCS.mkdir(parents=True, exist_ok=True)
    (DOCS / "README.md").write_text("\n".join(md) + "\n", encoding="utf-8")


if __name__ == "__main__":
    raise SystemExit(main())

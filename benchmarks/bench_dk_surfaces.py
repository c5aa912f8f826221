"""D-K iteration on DS-1's gain surfaces (issue 23, item 3 on the surfaces): table 3 over the
surface grid before/after, for SHIF (degree 0) and GS-SHIF (degree ``--degree``).

Per axis (one worker process per axis with ``--jobs``): the surface grid of the seven robust
points (:func:`vtolftc.synthesis.surfaces.surface_grid`, density 2: 13 airspeeds, 0-18 m/s),
SHIF D-K from the shipped SHIF (``firmware_sim/autopilot/gains/shif.json``), then GS-SHIF D-K
from the SHIF result (:func:`vtolftc.synthesis.dk_surfaces.dk_surfaces`). Every gain set is
then analysed independently of the D-K code (:func:`vtolftc.synthesis.robustness.analyse`,
mu_sweep upper and lower bounds; exact delay margin) at every grid airspeed: the shipped SHIF,
the shipped GS-SHIF (the robust point design, interpolated linearly in airspeed as the
autopilot does), SHIF D-K and GS-SHIF D-K. ``--fly`` flies case 1 (in-process, a temporary
gains directory) with the D-K surfaces beside the shipped gains. ``--doc`` writes
``docs/ds1-synthesis-robust/DK-SURFACES.json``; ``--render`` writes ``DK-SURFACES.md`` from it::

    python benchmarks/bench_dk_surfaces.py [--jobs 2] [--degree 1] [--order 2] [--max-iter 3]
        [--tune-iter 20] [--axes roll,pitch,yaw] [--fly] [--doc] [--render] [--unscaled]

``--unscaled`` drops the D scaling (the K step minimises ||N_i|| / f_i: what D buys).

Measured (2026-12-02, 2 cores shared with other sessions, load average 16-25): ``--jobs 3
--degree 1 --density 1 --order 2 --max-iter 2 --tune-iter 8 --fly --doc``: 1050 s wall for
the three axes (864-987 s per axis, about 8-13 % of a core each), then two case-1 flights.
M = max over the grid of mu_RP / max(1, |Wt(0)|): roll 1.698 -> 1.462 (SHIF D-K) -> 1.414
(GS-SHIF D-K), pitch 2.460 -> 2.352 -> 1.685, yaw 6.447 -> 6.403 -> 3.199. Case 1 RMSE roll /
pitch / yaw [deg]: GS-SHIF D-K 0.148 / 0.469 / 0.308 (shipped GS-SHIF 0.232 / 0.676 / 0.305),
SHIF D-K 0.147 / 0.398 / 0.151 (shipped SHIF 0.157 / 0.405 / 0.138). The 13-point grid
(density 2) with 3 K steps of 12 iterations was stopped unfinished after 13 minutes at load 20
(93 s of CPU per axis by then; estimated 2-4 times the work of the run above).
"""

from __future__ import annotations

import argparse
import json
import os
import sys
import tempfile
import time
from concurrent.futures import ProcessPoolExecutor
from pathlib import Path
from typing import Any

import numpy as np

ROOT = Path(__file__).resolve().parents[1]
SHIPPED = ROOT / "firmware_sim" / "autopilot" / "gains"
DOC_DIR = ROOT / "docs" / "ds1-synthesis-robust"


def _shipped(axis: str) -> tuple[dict[str, float], Any]:
    """The shipped SHIF gains of ``axis`` and the shipped GS-SHIF schedule document."""
    from vtolftc.synthesis.loops import PARAM_NAMES

    shif = json.loads((SHIPPED / "shif.json").read_text())
    gs = json.loads((SHIPPED / "gs-shif.json").read_text())
    return {k: float(shif["axes"][axis][k][0]) for k in PARAM_NAMES}, gs


def _interp(doc: dict[str, Any], axis: str, v: float) -> list[float]:
    """The schedule's gains at airspeed ``v`` [m/s] (linear, end values held)."""
    from vtolftc.synthesis.loops import PARAM_NAMES

    bp = doc["airspeed_breakpoints_m_s"]
    return [float(np.interp(v, bp, doc["axes"][axis][k])) for k in PARAM_NAMES]


def _analyse(m: Any, theta: Any) -> dict[str, float]:
    """mu_RS, mu_RP (upper, lower), the peak's frequency, the delay margin and the nominal
    diagnosis at the peak of one grid model and gains."""
    from vtolftc.synthesis.hinfnorm import hinf_norm
    from vtolftc.synthesis.robust import loop_margins
    from vtolftc.synthesis.robustness import analyse, rp_matrix

    w = m.weights
    G = m.rp.G
    th = [float(x) for x in theta]
    try:
        a = analyse(G, th, w.Ws, w.Wt, w.Wr)
    except ValueError:
        return {"stable": False}
    wp = a.rp.peak_upper_frequency_rad_s
    N = rp_matrix(G, th, w.Ws, w.Wt, w.Wr, np.array([wp]))[0]
    out = {"stable": True, "mu_rs": a.mu_rs, "mu_rp": a.mu_rp, "mu_rp_lower": a.rp.peak_lower,
           "peak_rad_s": wp, "delay_margin_s": loop_margins(G, th).delay_margin_s,
           "WsS": float(abs(N[1, 1])), "WrR": float(abs(N[2, 1])),
           "Wt_peak": float(abs(w.Wt.tf()(1j * wp))), "Wt0": float(w.Wt.gain),
           "plateau": float(w.Ws.omega_b_rad_s / th[0])}
    for nm, r in zip(("Wdelay*T", "Wd*Sd"), m.requirements, strict=False):
        out[nm] = hinf_norm(r(th)).value
    return out


def _axis_job(args: tuple[Any, ...]) -> dict[str, Any]:
    axis, degree, density, st_kw = args
    from vtolftc.airframe.loader import load_airframe
    from vtolftc.synthesis.dk_surfaces import SurfaceDKSettings, dk_surfaces, surface_dk_problem
    from vtolftc.synthesis.robust import robust_points
    from vtolftc.synthesis.surfaces import surface_grid

    af = load_airframe()
    st = SurfaceDKSettings(**st_kw)
    pb = surface_dk_problem(af, axis, surface_grid(robust_points(af), density))  # type: ignore[arg-type]
    g0, gs_doc = _shipped(axis)
    t0 = time.perf_counter()
    shif, gs = dk_surfaces(pb, g0, degree, st)
    t_dk = time.perf_counter() - t0
    vs = pb.airspeeds_m_s
    sets = {"shif_shipped": shif.steps[0].surface.gain_matrix(vs),
            "gs_shipped": np.array([_interp(gs_doc, axis, v) for v in vs]),
            "shif_dk": shif.surface.gain_matrix(vs), "gs_dk": gs.surface.gain_matrix(vs)}
    analysis = {k: [_analyse(m, K[i]) for i, m in enumerate(pb.models)]
                for k, K in sets.items()}
    return {"axis": axis, "airspeeds_m_s": vs, "floors": [m.floor for m in pb.models],
            "time_dk_s": t_dk, "time_total_s": time.perf_counter() - t0,
            "gains": {k: K.tolist() for k, K in sets.items()},
            "shif": {"measured": shif.measured, "stop": shif.stop,
                     "steps": [s.to_dict() for s in shif.steps]},
            "gs": {"measured": gs.measured, "stop": gs.stop,
                   "steps": [s.to_dict() for s in gs.steps]},
            "surfaces": {"shif": _surface_dict(shif.surface), "gs": _surface_dict(gs.surface)},
            "analysis": analysis}


def _surface_dict(sf: Any) -> dict[str, Any]:
    from vtolftc.synthesis.loops import PARAM_NAMES

    return {"degree": sf.basis.degree, "v_lo_m_s": sf.basis.v_lo_m_s,
            "v_hi_m_s": sf.basis.v_hi_m_s, "lower": sf.lower.tolist(),
            "upper": sf.upper.tolist(),
            "coefficients": {k: sf.coefficients[i].tolist() for i, k in enumerate(PARAM_NAMES)}}


def _fly_job(args: tuple[str, str]) -> dict[str, Any]:
    from vtolftc.airframe.loader import load_airframe
    from vtolftc.runners.scenario import paper_scenario, run_scenario

    ctl, gdir = args
    m = run_scenario(paper_scenario(1), ctl, airframe=load_airframe(), gains_dir=gdir).metrics
    return {k: v for k, v in m.items() if isinstance(v, (int, float, bool))}


def _fly(results: dict[str, Any], jobs: int) -> dict[str, dict[str, Any]]:
    """Case 1 with the D-K surfaces (SHIF and GS-SHIF, ``jobs`` processes), beside the
    shipped gains' case 1 from ``docs/ds1-claims/robust.json`` (stamped against the shipped
    gain files; the flights are deterministic, ``benchmarks/command_digest.py``)."""
    import shutil

    from vtolftc.airframe.loader import load_airframe
    from vtolftc.synthesis.export import write_json
    from vtolftc.synthesis.loops import PARAM_NAMES
    from vtolftc.synthesis.surfaces import GainSurface, SurfaceBasis, schedule_from_surfaces

    if set(results) != {"roll", "pitch", "yaw"}:
        print("  (not flown: the D-K gain files need all three axes)")
        return {}
    af = load_airframe()
    out: dict[str, dict[str, Any]] = {}
    recs = json.loads((ROOT / "docs" / "ds1-claims" / "robust.json").read_text())
    for ctl, label in (("shif", "SHIF shipped"), ("gs-shif", "GS-SHIF shipped")):
        r = next(x for x in recs if x["label"] == "case 1" and x["controller"] == ctl)
        out[label + " (docs/ds1-claims/robust.json)"] = {
            k: v for k, v in r.items() if isinstance(v, (int, float, bool))}

    def surf(d: dict[str, Any]) -> GainSurface:
        b = SurfaceBasis(d["degree"], d["v_lo_m_s"], d["v_hi_m_s"])
        C = np.array([d["coefficients"][k] for k in PARAM_NAMES])
        return GainSurface(b, C, np.array(d["lower"]), np.array(d["upper"]))

    bps = next(iter(results.values()))["airspeeds_m_s"]
    with tempfile.TemporaryDirectory(prefix="vtolftc-dksurf-") as tmp:
        for ctl, key in (("gs-shif", "gs"), ("shif", "shif")):
            sfs = {ax: surf(r["surfaces"][key]) for ax, r in results.items()}
            write_json(Path(tmp) / f"{ctl}.json", schedule_from_surfaces(
                af, sfs, bps, ctl, {"synthesis_method": "surface D-K "
                                                         "(synthesis/dk_surfaces.py)"}))
        shutil.copy(SHIPPED / "lqr.json", Path(tmp) / "lqr.json")
        runs = (("SHIF D-K surface", "shif"), ("GS-SHIF D-K surface", "gs-shif"))
        args = [(ctl, tmp) for _, ctl in runs]
        if jobs > 1:
            with ProcessPoolExecutor(min(jobs, 2)) as ex:
                ms = list(ex.map(_fly_job, args))
        else:
            ms = [_fly_job(x) for x in args]
        for (label, _), m in zip(runs, ms, strict=True):
            out[label] = m
    for label, m in out.items():
        print(f"  case 1 {label:45} RMSE roll / pitch / yaw {m['rmse_roll_deg']:.3f} / "
              f"{m['rmse_pitch_deg']:.3f} / {m['rmse_yaw_deg']:.3f} deg, "
              f"crashed={m.get('crashed')}", flush=True)
    return out


def main(argv: list[str] | None = None) -> int:
    """Run the benchmark; see the module docstring."""
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--jobs", type=int, default=2)
    ap.add_argument("--degree", type=int, default=1)
    ap.add_argument("--density", type=int, default=2)
    ap.add_argument("--order", type=int, default=2)
    ap.add_argument("--max-iter", type=int, default=3)
    ap.add_argument("--tune-iter", type=int, default=20)
    ap.add_argument("--axes", default="roll,pitch,yaw")
    ap.add_argument("--fly", action="store_true")
    ap.add_argument("--doc", action="store_true")
    ap.add_argument("--render", action="store_true")
    ap.add_argument("--unscaled", action="store_true")
    a = ap.parse_args(argv)
    axes = [x for x in a.axes.split(",") if x]
    if (a.degree < 1 or a.density < 1 or a.order not in (0, 1, 2) or a.max_iter < 1
            or a.tune_iter < 1 or a.jobs < 1
            or not axes or any(x not in ("roll", "pitch", "yaw") for x in axes)):
        print("bench_dk_surfaces: expected --degree >= 1, --density >= 1, --order 0|1|2, "
              "--max-iter >= 1, --tune-iter >= 1, --jobs >= 1, --axes of roll,pitch,yaw",
              file=sys.stderr)
        return 2
    if a.render:
        from dk_surfaces_doc import render  # benchmarks/ on sys.path when run as a script

        render(DOC_DIR)
        return 0
    st = {"max_iter": a.max_iter, "order": a.order, "tune_iter": a.tune_iter,
          "scaled": not a.unscaled}
    jobs = [(ax, a.degree, a.density, st) for ax in axes]
    t0 = time.perf_counter()
    if a.jobs > 1:
        with ProcessPoolExecutor(min(a.jobs, len(jobs))) as ex:
            res = list(ex.map(_axis_job, jobs))
    else:
        res = [_axis_job(j) for j in jobs]
    wall = time.perf_counter() - t0
    load = os.getloadavg()
    results = {r["axis"]: r for r in res}
    print(f"surface D-K of DS-1: degree {a.degree}, order {a.order}, max_iter {a.max_iter}, "
          f"tune_iter {a.tune_iter}, {'unscaled' if a.unscaled else 'scaled'}; wall "
          f"{wall:.0f} s, jobs {a.jobs}, load average {load[0]:.1f}")
    for ax, r in results.items():
        m0 = r["shif"]["steps"][0]["measured"]
        print(f"{ax}: M (max mu_RP / floor over the grid) SHIF {m0:.3f}"
              f" -> {r['shif']['measured']:.3f} ({r['shif']['stop']}); GS-SHIF -> "
              f"{r['gs']['measured']:.3f} ({r['gs']['stop']}); {r['time_dk_s']:.0f} s")
        for k in ("shif_shipped", "gs_shipped", "shif_dk", "gs_dk"):
            mus = [x.get("mu_rp", float("inf")) for x in r["analysis"][k]]
            print(f"   {k:13} mu_RP " + " ".join(f"{x:.2f}" for x in mus))
    doc = {"settings": {**st, "degree": a.degree, "density": a.density}, "wall_s": wall,
           "jobs": a.jobs, "load_average": load, "axes": results, "case1": {}}
    name = "DK-SURFACES-unscaled.json" if a.unscaled else "DK-SURFACES.json"
    if a.doc:   # written before the flights, again with them
        (DOC_DIR / name).write_text(json.dumps(doc, indent=1) + "\n")
    if a.fly:
        doc["case1"] = _fly(results, a.jobs)
    if a.doc:
        (DOC_DIR / name).write_text(json.dumps(doc, indent=1) + "\n")
        print(f"wrote {DOC_DIR / name}")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())

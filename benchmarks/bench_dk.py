"""D-K iteration on DS-1's robust point design (issue 23, item 3): table 3 before/after.

From the shipped robust gains (``firmware_sim/autopilot/gains/gs-shif.json``, DS-1, seven
points x three axes), :func:`vtolftc.synthesis.dk_robust.dk_schedule` runs the D-K iteration
with the fixed P-PID structure at every axis-point (or ``--only roll:3,pitch:2``) and writes

- ``docs/ds1-synthesis-robust/DK.md`` (``--doc``; default: print only) with the table of
  mu_RS / mu_RP / delay margins before and after, the weights' meaning, the D(s) fits and the
  wall time, and ``DK.json`` beside it (every iteration);
- a gains directory (``--gains-out DIR``): ``gs-shif.json`` with the D-K gains, ``shif.json``
  and ``lqr.json`` copied from the shipped ones, so ``vtolftc fly --case 1 --controller gs-shif
  --gains DIR`` flies them; ``--fly`` flies case 1 with both and prints RMSE [deg].

::

    python benchmarks/bench_dk.py [--jobs 2] [--order 2] [--max-iter 4] [--only roll:3]
        [--gains-out DIR] [--fly] [--doc] [--pure]

``--pure`` drops the delay-margin and rotor-out requirement channels from the K step (a
diagnostic: what the structure reaches on mu_RP alone; the gains are then not for flight).
Measured figures are in ``docs/ds1-synthesis-robust/DK.md`` (with the load average).
"""

from __future__ import annotations

import argparse
import json
import os
import shutil
import sys
import time
from concurrent.futures import ProcessPoolExecutor
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]
SHIPPED = ROOT / "firmware_sim" / "autopilot" / "gains"
DOC_DIR = ROOT / "docs" / "ds1-synthesis-robust"


def main(argv: list[str] | None = None) -> int:
    """Run the benchmark; see the module docstring."""
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--jobs", type=int, default=2)
    ap.add_argument("--order", type=int, default=2)
    ap.add_argument("--max-iter", type=int, default=4)
    ap.add_argument("--only", default=None, help="axis:point,... (default: all 21)")
    ap.add_argument("--gains-out", default=None)
    ap.add_argument("--fly", action="store_true")
    ap.add_argument("--doc", action="store_true")
    ap.add_argument("--pure", action="store_true")
    a = ap.parse_args(argv)

    from vtolftc.airframe.loader import load_airframe
    from vtolftc.synthesis.dk_robust import DKSettings, dk_gains, dk_schedule, dk_table
    from vtolftc.synthesis.export import schedule_document, write_json
    from vtolftc.synthesis.loops import PARAM_NAMES
    from vtolftc.synthesis.models import AXES
    from vtolftc.synthesis.robust import robust_points

    af = load_airframe()
    doc = json.loads((SHIPPED / "gs-shif.json").read_text())
    if doc["airframe"].get("sha256") != af.sha256:
        print("bench_dk: the shipped gains are not DS-1's", file=sys.stderr)
        return 2
    pts = robust_points(af)
    gains = {ax: [{k: doc["axes"][ax][k][i] for k in PARAM_NAMES} for i in range(len(pts))]
             for ax in AXES}
    only = None
    if a.only:
        want = {(s.split(":")[0], int(s.split(":")[1])) for s in a.only.split(",")}
        only = lambda ax, p: (ax, p.number) in want  # noqa: E731
    st = DKSettings(max_iter=a.max_iter, order=a.order, keep_requirements=not a.pure)
    t0 = time.perf_counter()
    ex = ProcessPoolExecutor(a.jobs) if a.jobs > 1 else None
    try:
        res = dk_schedule(af, pts, gains, only=only, settings=st, executor=ex,
                          progress=lambda s: print(f"  done {s} ({time.perf_counter() - t0:.0f} s)",
                                                   flush=True))
    finally:
        if ex is not None:
            ex.shutdown()
    wall = time.perf_counter() - t0
    load = os.getloadavg()
    table = dk_table(res)
    print(table)
    print(f"wall {wall:.1f} s, jobs {a.jobs}, load average {load[0]:.1f} / {load[1]:.1f}")
    flights = {}
    if a.gains_out:
        out = Path(a.gains_out)
        out.mkdir(parents=True, exist_ok=True)
        new = dk_gains(gains, pts, res)
        meta = {"synthesis_method": "robust + D-K (synthesis/dk_robust.py)",
                "dk_settings": st.to_dict(), "dk_from": "firmware_sim/autopilot/gains/gs-shif.json"}
        write_json(out / "gs-shif.json", schedule_document(
            af, "gs-shif", [p.airspeed_m_s for p in pts], new, None, meta))
        for f in ("shif.json", "lqr.json"):
            shutil.copy(SHIPPED / f, out / f)
        if a.fly:
            from vtolftc.runners.scenario import paper_scenario, run_scenario

            for label, gdir in (("robust (shipped)", None), ("robust + D-K", str(out))):
                m = run_scenario(paper_scenario(1), "gs-shif", airframe=af,
                                 gains_dir=gdir).metrics
                flights[label] = m
                print(f"  case 1 gs-shif {label:18} RMSE roll / pitch / yaw "
                      f"{m['rmse_roll_deg']:.3f} / {m['rmse_pitch_deg']:.3f} / "
                      f"{m['rmse_yaw_deg']:.3f} deg, crashed={m.get('crashed')}")
    if a.doc:
        name = "DK-pure" if a.pure else "DK"
        (DOC_DIR / f"{name}.json").write_text(json.dumps(
            {"settings": st.to_dict(), "wall_s": wall, "jobs": a.jobs, "load_average": load,
             "points": [r.to_dict() for r in res],
             "case1": {k: {m: v for m, v in f.items() if isinstance(v, (int, float, bool))}
                       for k, f in flights.items()}}, indent=1) + "\n")
        (DOC_DIR / f"{name}.table.md").write_text(table)
        print(f"wrote {DOC_DIR / name}.json and .table.md")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())

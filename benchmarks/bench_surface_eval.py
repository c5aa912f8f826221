"""Where one evaluation of the surface design's J goes, and what the speed-ups buy, measured
pairwise in one process (issue 23, the < 90 s target).

Roll, the 13-airspeed surface grid, degree 1, caps and start from the shipped robust SHIF,
with the margin constraints and the nominal term (``synthesis/fault_surfaces.py``):

1. per term, mean over ``--n`` evaluations at the start: the predictor with the modal ISE
   (today) and with the matrix-exponential ISE (before), the margins at 13 airspeeds, the 39
   cap norms;
2. the same Nelder-Mead run (``--evals`` evaluations) with the lazy objective and with the
   full one: identical decisions (same result), the time ratio is what skipping buys, and
   where the lazy evaluations stopped::

    python benchmarks/bench_surface_eval.py [--n 10] [--evals 120]

Measured (2026-12-02, 2 cores shared, absolute times several times an idle machine's; the
ratios are pairwise): at load average 24.2, predictor 16.6 ms (modal ISE) against 427.6 ms
(matrix exponential), x25.7; margins at 13 airspeeds 76.2 ms; 39 cap norms 172.8 ms.
Nelder-Mead, 80 evaluations: lazy 24.4 s, full 13.9 s (x0.57, same result); 13 lazy
evaluations stopped early, all at the caps. At load 23.5 the predictor ratio was x12.3 and
the margins took 136 ms (before the plain resolvent), lazy 20.7 s against full 18.5 s.
"""

from __future__ import annotations

import argparse
import json
import math
import os
import time
from pathlib import Path

import numpy as np

ROOT = Path(__file__).resolve().parents[1]


def main(argv: list[str] | None = None) -> int:
    """Run the benchmark (module docstring); returns the exit status."""
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--n", type=int, default=10)
    ap.add_argument("--evals", type=int, default=120)
    a = ap.parse_args(argv)
    from vtolftc.airframe.loader import load_airframe
    from vtolftc.synthesis import fault_objective as fo
    from vtolftc.synthesis import fault_surfaces as fs
    from vtolftc.synthesis.lazy_simplex import lazy_nelder_mead
    from vtolftc.synthesis.loops import PARAM_NAMES
    from vtolftc.synthesis.margin_constraints import MarginConstraints
    from vtolftc.synthesis.nominal_objective import NOMINAL_STEPS
    from vtolftc.synthesis.robust import RobustMethod, robust_points
    from vtolftc.synthesis.surfaces import (
        GainSurface,
        SurfaceBasis,
        surface_grid,
        surface_problem,
    )

    af = load_airframe()
    axis = "roll"
    grid = surface_grid(robust_points(af), 2)
    doc = json.loads((ROOT / "firmware_sim/autopilot/gains/shif.json").read_text("utf-8"))
    ref = {k: float(doc["axes"][axis][k][0]) for k in PARAM_NAMES}
    m = RobustMethod()
    ws = [m.weights(af, axis, p) for p in grid]
    basis = SurfaceBasis(0, grid[0].airspeed_m_s, grid[-1].airspeed_m_s)
    sp0 = surface_problem(m, af, axis, grid, 0, start=GainSurface.constant(basis, ref),
                          weights=ws)
    caps = fs._caps(sp0, sp0.problem.channel_norms(sp0.problem.initial), 0.05)
    sp = surface_problem(m, af, axis, grid, 1, start=sp0.surface(sp0.problem.initial),
                         weights=ws)
    mc = MarginConstraints(af, axis, [p.airspeed_m_s for p in grid])
    cases = [fo.PAPER_CASES["1"], fo.PAPER_CASES["2"]]
    f = fs.FaultObjective(sp, af, axis, caps, cases, margins=mc,
                          nominal_steps=NOMINAL_STEPS[axis])
    th = sp.problem.initial
    f(th)

    def timed(fn: object) -> float:
        t = time.perf_counter()
        for _ in range(a.n):
            fn()  # type: ignore[operator]
        return (time.perf_counter() - t) / a.n

    t_modal = timed(lambda: f.predicted_deg(th))
    keep = fo._EIG_COND_MAX
    fo._EIG_COND_MAX = 0.0                            # force the expm path
    t_expm = timed(lambda: f.predicted_deg(th))
    fo._EIG_COND_MAX = keep
    t_marg = timed(lambda: f.margin_violation(th))
    t_caps = timed(lambda: sp.problem.channel_norms(th))
    print(f"load average {os.getloadavg()[0]:.1f}; per evaluation [ms]: predictor modal "
          f"{1e3 * t_modal:.1f}, expm {1e3 * t_expm:.1f} (x{t_expm / t_modal:.1f}); "
          f"margins (13 airspeeds) {1e3 * t_marg:.1f}; caps (39 norms) {1e3 * t_caps:.1f}")
    pb = sp.problem
    lo, hi, sc = pb.lower, pb.upper, pb.scales

    def lazy(z: np.ndarray, bound: float) -> float:
        return f.bounded(np.clip(th + z * sc, lo, hi), bound)

    def full(z: np.ndarray, bound: float) -> float:
        return f.bounded(np.clip(th + z * sc, lo, hi), math.inf)

    n = th.size
    sim = fs._simplex(n)
    out = {}
    for name, g in (("lazy", lazy), ("full", full)):
        f.stops = dict.fromkeys(f.stops, 0)
        t = time.perf_counter()
        _z, fz, k = lazy_nelder_mead(g, sim, (lo - th) / sc, (hi - th) / sc, a.evals)
        out[name] = (time.perf_counter() - t, fz, k, dict(f.stops))
    (tl, fl, kl, sl), (tf, ff, kf, _) = out["lazy"], out["full"]
    print(f"Nelder-Mead, {kl} evaluations: lazy {tl:.1f} s, full {tf:.1f} s "
          f"(x{tf / tl:.2f}); same result: {fl == ff and kl == kf}; lazy stops {sl}")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())

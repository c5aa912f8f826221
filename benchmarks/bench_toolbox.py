"""Benchmark of the robust-control toolbox against SLICOT (slycot), per call, in one run.

1. ``hinf_norm`` (default: AB13DD with the re-check near sigma_max(D); and the pure
   Hamiltonian-pencil method) against raw ``slycot.ab13dd`` on: the COMPleib AC4 static-gain
   loop, the design's 11-state weighted channel (DS-1 yaw, point 1, shipped gains) and random
   stable systems of 4, 11 and 30 states. Prints microseconds per call, the ratio to raw
   AB13DD and the largest relative difference of the values.
2. mu sweeps: a robust-performance-like 4x4 problem (blocks 1, 1, 2 complex) over 401
   frequencies with ``mu_sweep`` (AB13MD upper bound + power-iteration lower bound), with the
   numpy D-scaling (``method="dscale"``) and raw ``slycot.ab13md`` alone (upper bound only);
   and ``mixed_mu_sweep`` on a 10x10 M with two repeated real scalars (3x each) and two 2x2
   complex blocks over 100 frequencies (a generic mixed case).
3. The real-parametric certificate (``synthesis/certificate.py``): the mixed-mu sweep
   (D-G upper bound, lower bound, w = 0, refinement, vertex crossings) of every airspeed
   piece of one axis-point, over the 21 axis-points of the shipped robust GS-SHIF gains;
   prints wall and CPU seconds per axis-point (mean, max), and the grid check's. Issue 11's
   target is < 1 s per axis-point: measured on the idle 2-core machine (2026-12-01, load
   average 0.8-0.9, two runs) mean 0.35 / 0.37 s, max 0.65 / 0.71 s wall; on the loaded
   machine (load 4-7) the max was 0.96-1.06 s wall for 0.65-0.74 s of CPU.

Usage: ``python benchmarks/bench_toolbox.py [--repeat N] [--only hinf|mu|certificate]``.
Timings are wall-clock on whatever else the machine is doing; run it on an idle machine for
comparable figures.
"""

from __future__ import annotations

import argparse
import time
from collections.abc import Callable
from typing import Any

import control
import numpy as np
from slycot import ab13dd, ab13md

from vtolftc.synthesis.hinfnorm import frequency_response, hinf_norm
from vtolftc.synthesis.mixed_mu import mixed_mu_sweep
from vtolftc.synthesis.mu import Block, mu_sweep


def _per_call(f: Callable[[], Any], repeat: int) -> float:
    f()
    best = float("inf")
    for _ in range(3):
        t0 = time.perf_counter()
        for _ in range(repeat):
            f()
        best = min(best, (time.perf_counter() - t0) / repeat)
    return best


def _ac4() -> tuple[np.ndarray, ...]:
    A = np.array([[-0.876, 1, -0.1209, 0], [8.9117, 0, -130.75, 0], [0, 0, -150, 0],
                  [-1, 0, 0, -0.05]])
    B1 = np.array([[0, 0], [0, 0], [0, 0], [0, 1.0]])
    B2 = np.array([[0], [0], [150], [0.0]])
    C1 = np.array([[-0.25, 0, 0, 3.487], [0, 0, -3, 0.0]])
    C2 = np.array([[-1, 0, 0, 0], [0, -1, 0, 0.0]])
    D11, D12, D21 = np.array([[0, 0.25], [0, 0.0]]), np.array([[0], [3.0]]), np.array(
        [[0, 1], [0.01, 0]])
    K = np.array([[-0.30048, -0.07271]])
    return A + B2 @ K @ C2, B1 + B2 @ K @ D21, C1 + D12 @ K @ C2, D11 + D12 @ K @ D21


def _design_channel() -> tuple[np.ndarray, ...] | None:
    try:
        import json

        from vtolftc.airframe.loader import load_airframe
        from vtolftc.firmware_sim.autopilot.attitude import default_gains_dir
        from vtolftc.synthesis import design
        from vtolftc.synthesis.loops import CascadeChannel
        from vtolftc.synthesis.models import attitude_model
    except ImportError:
        return None
    af = load_airframe()
    sh = json.loads((default_gains_dir() / "gs-shif.json").read_text())["axes"]["yaw"]
    pt = design.PAPER_DESIGN_POINTS[0]
    th = np.array([sh[k][0] for k in design.PARAM_NAMES])
    w = design.weights_for(af, "yaw", pt)
    ch = CascadeChannel(attitude_model(af, "yaw", pt.airspeed_m_s), w.Ws, w.Wt.tf(), w.Wr)
    return tuple(np.asarray(x, float) for x in ch(th))


def bench_hinf(repeat: int) -> None:
    np.random.seed(1)
    cases: list[tuple[str, tuple[np.ndarray, ...]]] = [("AC4 SOF loop (n=4)", _ac4())]
    dc = _design_channel()
    if dc is not None:
        cases.append((f"DS-1 yaw channel (n={dc[0].shape[0]})", dc))
    for n in (4, 11, 30):
        s = control.rss(n, 3, 3)
        cases.append((f"random n={n}, 3x3, D!=0", (s.A, s.B, s.C, s.D + 0.1)))
    print("hinf_norm per call (us), ratio to raw AB13DD, value difference")
    print(f"{'system':28s} {'AB13DD':>9s} {'hinf_norm':>10s} {'ratio':>6s} "
          f"{'hamiltonian':>12s} {'ratio':>6s} {'max rel diff':>13s}")
    for name, (A, B, C, D) in cases:
        n, (p, m) = A.shape[0], D.shape
        E = np.eye(n)
        raw = _per_call(lambda A=A, B=B, C=C, D=D, n=n, p=p, m=m, E=E: ab13dd(
            "C", "I", "N", "D", n, m, p, A, E, B, C, D, tol=1e-9), repeat)
        ours = _per_call(lambda A=A, B=B, C=C, D=D: hinf_norm((A, B, C, D)), repeat)
        ham = _per_call(lambda A=A, B=B, C=C, D=D: hinf_norm((A, B, C, D),
                                                              method="hamiltonian"),
                        max(1, repeat // 10))
        ref = float(ab13dd("C", "I", "N", "D", n, m, p, A, E, B, C, D, tol=1e-10)[0])
        v1 = hinf_norm((A, B, C, D)).value
        v2 = hinf_norm((A, B, C, D), method="hamiltonian").value
        diff = max(abs(v1 - ref), abs(v2 - ref)) / ref
        print(f"{name:28s} {raw * 1e6:9.1f} {ours * 1e6:10.1f} {ours / raw:6.2f} "
              f"{ham * 1e6:12.1f} {ham / raw:6.1f} {diff:13.2e}")


def bench_mu() -> None:
    np.random.seed(7)
    sys4 = control.rss(6, 4, 4)
    w = np.logspace(-2, 2, 401)
    F = frequency_response(sys4, w)
    blocks = [Block.full(1), Block.full(1), Block.full(2)]
    t0 = time.perf_counter()
    sw = mu_sweep(F, blocks, w)
    t_auto = time.perf_counter() - t0
    t0 = time.perf_counter()
    sw_np = mu_sweep(F, blocks, w, method="dscale")
    t_np = time.perf_counter() - t0
    t0 = time.perf_counter()
    ups = [ab13md(Fi, np.array([1, 1, 2]), np.array([2, 2, 2]))[0] for Fi in F]
    t_raw = time.perf_counter() - t0
    print("\nmu sweep, 4x4, blocks (1, 1, 2) complex, 401 frequencies (s per sweep)")
    print(f"  raw AB13MD upper bound only       {t_raw:7.3f} s")
    print(f"  mu_sweep (AB13MD + lower bound)   {t_auto:7.3f} s   ratio {t_auto / t_raw:5.1f}")
    print(f"  mu_sweep method='dscale' (numpy)  {t_np:7.3f} s   ratio {t_np / t_raw:5.1f}")
    print(f"  peak upper: AB13MD {max(ups):.6f}, mu_sweep {sw.peak_upper:.6f}, "
          f"dscale {sw_np.peak_upper:.6f}; max rel diff upper "
          f"{np.max(np.abs(sw.upper - np.array(ups)) / np.array(ups)):.1e}")

    np.random.seed(3)
    sys10 = control.rss(8, 10, 10)
    w = np.logspace(-2, 2, 100)
    F = frequency_response(sys10, w) * 0.5
    blocks = [Block.real(3), Block.real(3), Block.full(2), Block.full(2)]
    t0 = time.perf_counter()
    sw = mixed_mu_sweep(F, blocks, w)
    t_mix = time.perf_counter() - t0
    t0 = time.perf_counter()
    sw_up = mixed_mu_sweep(F, blocks, w, lower=False)
    t_up = time.perf_counter() - t0
    print("\nmixed_mu_sweep, 10x10, blocks (real x3, real x3, 2x2, 2x2), 100 frequencies")
    print(f"  bounds (lower + upper)            {t_mix:7.3f} s  peak {sw.peak_lower:.4f} <= mu "
          f"<= {sw.peak_upper:.4f}")
    print(f"  upper bound only                  {t_up:7.3f} s  peak {sw_up.peak_upper:.4f}")


def bench_certificate() -> None:
    import json
    from pathlib import Path

    from vtolftc.airframe.loader import load_airframe
    from vtolftc.synthesis import certificate as cert

    af = load_airframe()
    path = Path(__file__).resolve().parents[1] / "firmware_sim/autopilot/gains/gs-shif.json"
    doc = json.loads(path.read_text())
    walls, cpus, grid = [], [], []
    for axis in ("roll", "pitch", "yaw"):
        for i, p in enumerate(cert.design_points(doc)):
            th = cert.gains_at(doc, axis, i)
            t0, c0 = time.perf_counter(), time.process_time()
            for lo, hi in cert.airspeed_pieces(af, p):
                cert.mu_real_sweep(cert.family(af, axis, lo, hi), th)
            walls.append(time.perf_counter() - t0)
            cpus.append(time.process_time() - c0)
            t0 = time.perf_counter()
            cert.grid_check(af, axis, p, th)
            grid.append(time.perf_counter() - t0)
    print("\nreal-parametric mixed-mu sweep per axis-point (robust GS-SHIF, 21 axis-points, "
          "1-3 airspeed pieces each)")
    print(f"  wall  mean {np.mean(walls):6.3f} s  max {np.max(walls):6.3f} s")
    print(f"  CPU   mean {np.mean(cpus):6.3f} s  max {np.max(cpus):6.3f} s")
    print(f"  41x41 grid check (true model poles): mean {np.mean(grid) * 1e3:6.1f} ms")


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--repeat", type=int, default=50, help="calls per timing (default 50)")
    ap.add_argument("--only", choices=("hinf", "mu", "certificate"), help="one part only")
    args = ap.parse_args()
    if args.repeat < 1:
        ap.error("--repeat must be >= 1")
    if args.only in (None, "hinf"):
        bench_hinf(args.repeat)
    if args.only in (None, "mu"):
        bench_mu()
    if args.only in (None, "certificate"):
        bench_certificate()


if __name__ == "__main__":
    main()

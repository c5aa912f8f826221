"""Benchmark of the control allocators at the 250 Hz control rate.

Runs a realistic sequence of slowly varying virtual commands (hover -> transition: airspeed
ramping 0 -> 13 m/s over the run, so the surface effectiveness, hence ``B``, changes every step,
plus small attitude-moment oscillations and a pusher force ramp) through

- ``QPAllocator`` with ``B`` changing every step (P updated in place + KKT refactorisation),
- ``QPAllocator`` with ``B`` held constant (only q and bounds updated),
- ``QPAllocator`` through the public OSQP Python API (``fast_path=False``), to show the
  wrapper's per-call overhead,
- the PX4-style ``PseudoInverseAllocator`` baseline,

and prints median / p99 wall-clock time per step, OSQP's own solve time, iterations and the
status counts. The synthetic effectiveness matrix is the one of ``tests/test_allocation.py``
(duplicated here so the benchmark stands alone).

Usage: ``python benchmarks/bench_allocation.py [--steps N] [--seed S]``
"""

from __future__ import annotations

import argparse
import time

import numpy as np

from vtolftc.firmware_sim.autopilot.allocation import PseudoInverseAllocator, QPAllocator

N_U = 15
U_MIN = np.r_[np.zeros(10), -np.ones(5)]
U_MAX = np.ones(N_U)
U_PREF = np.r_[np.full(8, 12.5 * 9.81 / 280.0), 0.0, 0.0, np.zeros(5)]
W_V = np.array([1.0, 1.0, 10.0, 10.0, 3.0])
RATE = np.r_[np.full(10, 20.0), np.full(5, 8.0)]


def synth_B(V: float) -> np.ndarray:
    """5 x 15 DS-1-like effectiveness at airspeed V [m/s] (see tests/test_allocation.py)."""
    cols = []
    for k, (x, y) in enumerate((x, y) for x in (0.6, -0.6) for y in (-1.05, -0.4, 0.4, 1.05)):
        spin = 1.0 if k % 2 == 0 else -1.0
        cols.append([-35.0, 0.0, -y * 35.0, x * 35.0, spin * 0.016 * 35.0])
    for y in (-0.5, 0.5):
        cols.append([0.0, 25.0, 0.0, 0.0, -y * 25.0])
    qbar = 0.5 * 1.225 * V**2
    d = np.deg2rad(25.0)
    ail, ele, rud = (
        qbar * 0.95 * 2.9 * 0.17 * d / 2,
        qbar * 0.95 * 0.33 * 0.99 * d,
        (qbar * 0.95 * 2.9 * 0.069 * d / 2),
    )
    cols += [[0, 0, -ail, 0, 0], [0, 0, ail, 0, 0], [0, 0, 0, -ele, 0]]
    cols += [[0, 0, 0, 0, rud], [0, 0, 0, 0, rud]]
    return np.array(cols, dtype=float).T


def scenario(steps: int, seed: int) -> tuple[np.ndarray, list[np.ndarray]]:
    rng = np.random.default_rng(seed)
    t = np.arange(steps) / 250.0
    V = np.clip(13.0 * t / t[-1] + 0.05 * rng.standard_normal(steps), 0.0, None)
    v = np.stack(
        [
            -122.6 * (1 - 0.5 * (V / 13.0) ** 2) + 6 * np.sin(0.9 * t),
            40.0 * np.minimum(1.0, 3 * t / t[-1]) + 2 * np.sin(0.4 * t),
            8 * np.sin(2.1 * t) + 0.5 * rng.standard_normal(steps),
            6 * np.cos(1.3 * t) + 0.5 * rng.standard_normal(steps),
            1.5 * np.sin(0.8 * t) + 0.1 * rng.standard_normal(steps),
        ],
        axis=1,
    )
    return v, [synth_B(x) for x in V]


def run(alloc, v: np.ndarray, Bs: list[np.ndarray]) -> dict[str, np.ndarray]:
    wall, solve, iters = [], [], []
    alloc.allocate(v[0], Bs[0])  # setup / JIT outside the timing
    for vi, Bi in zip(v, Bs, strict=True):
        t0 = time.perf_counter()
        res = alloc.allocate(vi, Bi)
        wall.append(time.perf_counter() - t0)
        solve.append(res.solve_time_s)
        iters.append(res.iterations)
    return {"wall": np.array(wall), "solve": np.array(solve), "iters": np.array(iters)}


def report(name: str, r: dict[str, np.ndarray], stats=None) -> None:
    us = 1e6
    line = (
        f"{name:<38s} wall median {np.median(r['wall']) * us:7.1f} us  "
        f"p99 {np.percentile(r['wall'], 99) * us:7.1f} us  "
        f"max {np.max(r['wall']) * us:8.1f} us"
    )
    if np.any(r["solve"] > 0):
        line += (
            f" | OSQP solve median {np.median(r['solve']) * us:5.1f} us, "
            f"iters median {np.median(r['iters']):.0f} p99 {np.percentile(r['iters'], 99):.0f}"
        )
    print(line)
    if stats is not None:
        counts = {k: n for k, n in stats.as_dict()["counts"].items() if n}
        print(f"{'':<38s} statuses {counts}")


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--steps", type=int, default=2500, help="control steps (250 Hz)")
    ap.add_argument("--seed", type=int, default=0)
    args = ap.parse_args()
    v, Bs = scenario(args.steps, args.seed)
    print(f"{args.steps} steps at 250 Hz, n_v = 5, n_u = {N_U}; times per allocate() call")

    qp = QPAllocator(5, U_MIN, U_MAX, w_v=W_V, u_pref=U_PREF, rate_limit=RATE)
    report("QP, B changes every step", run(qp, v, Bs), qp.stats)

    qp = QPAllocator(5, U_MIN, U_MAX, w_v=W_V, u_pref=U_PREF, rate_limit=RATE)
    B_const = [Bs[len(Bs) // 2]] * len(Bs)
    report("QP, B constant", run(qp, v, B_const), qp.stats)

    qp = QPAllocator(5, U_MIN, U_MAX, w_v=W_V, u_pref=U_PREF, rate_limit=RATE, fast_path=False)
    report("QP, public OSQP API (no fast path)", run(qp, v, Bs), qp.stats)

    qp = QPAllocator(5, U_MIN, U_MAX, w_v=W_V, u_pref=U_PREF, rate_limit=RATE, polish=False)
    report("QP, no active-set polish", run(qp, v, Bs), qp.stats)

    pi = PseudoInverseAllocator(U_MIN, U_MAX, u_trim=U_PREF)
    report("PX4-style pseudo-inverse (baseline)", run(pi, v, Bs))


if __name__ == "__main__":
    main()

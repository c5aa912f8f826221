"""Benchmark of the control allocators at the 250 Hz control rate.

Two parts.

**Replay of paper case 1** (``--case 1``, the default; ``--case none`` skips it): flies case 1
(gs-shif) in-process through a wrapper that records every QP the autopilot hands its
allocator (``v``, ``B``, per-step upper limits, ``u_pref``, the previous command that sets the
rate limits, and the resets), then replays all of them through each candidate solver on the
very same QPs (same bounds, since ``u_prev`` is replayed), each warm-started from its own
previous answer:

- (a) ``QPAllocator``: OSQP + active-set polish (tolerance 1e-9), the solver flown before,
- (b) ``ActiveSetAllocator``: the compiled active set alone, warm-started from the previous
  command, at tolerance 1e-9 (the polish's) and 1e-12 (its default),
- (c) DAQP (dual active set, ``pip install daqp``; skipped when not installed) on the same
  normalised QP, warm-started from the previous answer's working set. With ``eps_prox = 0``
  DAQP rejects every QP as non-convex (exit -5: the rotor null-space curvature, ~5e-12, is
  below its singularity tolerance); with its default proximal regularisation it solves them
  all but stops early along that null space,

and prints the per-QP wall time of ``allocate()`` (median, p99 [us]), the statuses, and the
largest difference of the answers from a tight reference: scipy's bounded-variable least
squares (``lsq_linear(method="bvls", tol=1e-14)``) on the un-normalised least-squares form,
which never squares the condition number. ``|du|`` is in normalised actuator units (max over
all QPs; "worse": only over the QPs where the candidate's cost exceeds the reference's, the
others being ties to rounding), ``|dBu|`` in N or N m, ``dJ`` is the cost excess
``J - J_ref`` relative to ``J_ref + eps``.

**Synthetic sequence**: runs a realistic sequence of slowly varying virtual commands (hover ->
transition: airspeed ramping 0 -> 13 m/s over the run, so the surface effectiveness, hence
``B``, changes every step, plus small attitude-moment oscillations and a pusher force ramp)
through

- ``QPAllocator`` with ``B`` changing every step (P updated in place + KKT refactorisation),
- ``QPAllocator`` with ``B`` held constant (only q and bounds updated),
- the PX4-style ``PseudoInverseAllocator`` baseline,

and prints median / p99 wall-clock time per step, OSQP's own solve time, iterations and the
status counts. The synthetic effectiveness matrix is the one of ``tests/test_allocation.py``
(duplicated here so the benchmark stands alone).

Usage: ``python benchmarks/bench_allocation.py [--case 1|2|none] [--steps N] [--seed S]``
"""

from __future__ import annotations

import argparse
import time
from typing import Any

import numpy as np
from scipy.optimize import lsq_linear

from vtolftc.firmware_sim.autopilot.allocation import (
    ActiveSetAllocator,
    PseudoInverseAllocator,
    QPAllocator,
    WLSAllocator,
    step_bounds,
)
from vtolftc.firmware_sim.autopilot.allocation.wls import ST_FALLBACK, ST_SOLVED

try:
    import daqp
except ImportError:  # optional: the benchmark runs without it
    daqp = None

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
            f" | solver solve median {np.median(r['solve']) * us:5.1f} us, "
            f"iters median {np.median(r['iters']):.0f} p99 {np.percentile(r['iters'], 99):.0f}"
        )
    print(line)
    if stats is not None:
        counts = {k: n for k, n in stats.as_dict()["counts"].items() if n}
        print(f"{'':<38s} statuses {counts}")


# -- replay of a paper case ---------------------------------------------------------------
class _Recorder:
    """Stands in for the autopilot's allocator: records each QP, then calls the real one."""

    def __init__(self, inner: WLSAllocator) -> None:
        self.inner = inner
        self.log: list[tuple[str, Any]] = []

    def __getattr__(self, name: str) -> Any:
        return getattr(self.inner, name)

    def reset(self, u0: np.ndarray | None = None) -> None:
        self.log.append(("reset", None if u0 is None else np.array(u0, dtype=float)))
        self.inner.reset(u0)

    def allocate(self, v, B, *, u_max=None, u_pref=None, **kw):
        assert not kw, kw  # the autopilot passes only u_max and u_pref
        prev = self.inner.u_last
        self.log.append(("qp", (np.array(v, dtype=float), np.array(B, dtype=float),
                                np.array(u_max, dtype=float), np.array(u_pref, dtype=float),
                                prev)))
        return self.inner.allocate(v, B, u_max=u_max, u_pref=u_pref)


def record_case(case: str, controller: str = "gs-shif") -> tuple[WLSAllocator, list]:
    """Fly ``case`` in-process and return (the autopilot's allocator, its QP log)."""
    from vtolftc.runners.scenario import paper_scenario, run_scenario

    box: dict[str, _Recorder] = {}

    def setup(ap) -> None:
        box["rec"] = _Recorder(ap.allocator)
        ap.allocator = box["rec"]

    run_scenario(paper_scenario(case), controller, autopilot_setup=setup)
    return box["rec"].inner, box["rec"].log


class DAQPAllocator(WLSAllocator):
    """The ``wls`` problem solved by DAQP (dual active set), warm-started from the previous
    step's working set (benchmark candidate, not flown)."""

    def __init__(self, *args: Any, **kw: Any) -> None:
        super().__init__(*args, **kw)
        self._lam: np.ndarray | None = None
        self._A = np.zeros((0, self.n_u))

    def reset(self, u0: np.ndarray | None = None) -> None:
        super().reset(u0)
        self._lam = None

    def _solve(self, v, B, pref, lo, hi, B_changed, t0):
        kw = {} if self._lam is None else {"dual_start": self._lam}
        # default eps_prox (< 0: proximal iterations when H is near singular, as Hn is along
        # the rotor null space; eps_prox = 0 makes DAQP reject Hn as non-convex)
        x, _, flag, info = daqp.solve(self._Hn, self._qn, self._A, hi, lo, **kw)
        if flag > 0:
            self._lam = info["lam"]
            return self._finish(np.clip(x, lo, hi), v, B, ST_SOLVED, int(info["iterations"]),
                                float(info["solve_time"]), t0, "solved", False)
        self._lam = None
        u = self._fallback(v, B, lo, hi, pref, x if np.all(np.isfinite(x)) else None)
        return self._finish(u, v, B, ST_FALLBACK, int(info["iterations"]), 0.0, t0,
                            f"daqp exit flag {flag}", False)


def _clone(flown: WLSAllocator, cls: type, **kw: Any) -> WLSAllocator:
    """A fresh allocator of class ``cls`` with the flown one's problem data."""
    return cls(flown.n_v, flown.u_min, flown.u_max, w_v=flown.w_v, w_u=flown.w_u,
               eps=flown.eps, u_pref=flown.u_pref, rate_limit=flown.rate_limit, dt=flown.dt,
               **kw)


def replay(alloc: WLSAllocator, log: list) -> tuple[np.ndarray, np.ndarray]:
    """Replay the QP log through ``alloc``; returns (answers (n, n_u), wall times [s])."""
    us, wall = [], []
    for kind, data in log:
        if kind == "reset":
            alloc.reset(data)
            continue
        v, B, hi, pref, prev = data
        t0 = time.perf_counter()
        res = alloc.allocate(v, B, u_max=hi, u_pref=pref, u_prev=prev)
        wall.append(time.perf_counter() - t0)
        us.append(res.u)
    return np.array(us), np.array(wall)


def reference(flown: WLSAllocator, log: list) -> np.ndarray:
    """Tight answers of every QP in the log: scipy BVLS on ``[W_v B; sqrt(eps) W_u] u ≈
    [W_v v; sqrt(eps) W_u u_pref]`` within the step's bounds."""
    n = flown.n_u
    lo, hi = np.empty(n), np.empty(n)
    out = []
    se = np.sqrt(flown.eps) * flown.w_u
    for kind, data in log:
        if kind == "reset":
            continue
        v, B, umax, pref, prev = data
        step_bounds(flown.u_min, flown.u_max, flown.u_min, umax,
                    flown._zeros_u if prev is None else prev, prev is not None,
                    flown.rate_limit, flown.rate_limit is not None, flown.dt, lo, hi)
        A = np.vstack([flown.w_v[:, None] * B, np.diag(se)])
        b = np.r_[flown.w_v * v, se * pref]
        if np.all(hi - lo > 0):
            out.append(lsq_linear(A, b, bounds=(lo, hi), method="bvls", tol=1e-14).x)
        else:  # fixed actuators: BVLS needs lo < hi; solve over the free ones
            free = hi > lo
            u = lo.copy()
            r = lsq_linear(A[:, free], b - A[:, ~free] @ lo[~free],
                           bounds=(lo[free], hi[free]), method="bvls", tol=1e-14).x
            u[free] = r
            out.append(u)
    return np.array(out)


def replay_case(case: str) -> None:
    """Record ``case``, replay it through each candidate and print the figures."""
    t = time.perf_counter()
    flown, log = record_case(case)
    qps = [d for k, d in log if k == "qp"]
    print(f"case {case}: {len(qps)} QPs recorded ({time.perf_counter() - t:.0f} s); "
          f"{sum(k == 'reset' for k, _ in log)} resets")
    u_ref = reference(flown, log)
    B_all = np.array([d[1] for d in qps])
    v_all = np.array([d[0] for d in qps])
    pref_all = np.array([d[3] for d in qps])

    def cost(u: np.ndarray) -> np.ndarray:
        r = flown.w_v * (np.einsum("kij,kj->ki", B_all, u) - v_all)
        d = flown.w_u * (u - pref_all)
        return (r**2).sum(1) + flown.eps * (d**2).sum(1)

    j_ref = cost(u_ref)
    cands: list[tuple[str, Any]] = [
        ("(a) OSQP + polish (tol 1e-9)", lambda: _clone(flown, QPAllocator)),
        ("(b) active set alone, tol 1e-9", lambda: _clone(flown, ActiveSetAllocator, tol=1e-9)),
        ("(b) active set alone, tol 1e-12", lambda: _clone(flown, ActiveSetAllocator, tol=1e-12)),
        ("(b) active set alone, tol 1e-15", lambda: _clone(flown, ActiveSetAllocator, tol=1e-15)),
    ]
    if daqp is not None:
        cands.append(("(c) DAQP, warm", lambda: _clone(flown, DAQPAllocator)))
    else:
        print("(c) DAQP not installed (pip install daqp): skipped")
    answers = {}
    print(f"{'solver':<34s} {'median':>8s} {'p99':>8s} [us]  {'max|du|':>8s} {'worse':>8s} "
          f"{'max|dBu|':>9s} {'max dJ':>8s}  statuses")
    for name, make in cands:
        alloc = make()
        replay(alloc, log[:50])  # JIT / setup outside the timing
        alloc = make()
        u, wall = replay(alloc, log)
        answers[name] = u
        du_k = np.abs(u - u_ref).max(1)
        du = du_k.max()
        # where the candidate's cost is not above the reference's the two are a tie to
        # rounding (e.g. on the ground, J ~ 6e3 swamps the eps term): "worse" leaves those out
        worse = cost(u) > j_ref
        du_w = du_k[worse].max() if np.any(worse) else 0.0
        dBu = np.abs(np.einsum("kij,kj->ki", B_all, u - u_ref)).max()
        dJ = ((cost(u) - j_ref) / (j_ref + flown.eps)).max()
        counts = {k: n for k, n in alloc.stats.as_dict()["counts"].items() if n}
        print(f"{name:<34s} {np.median(wall) * 1e6:8.1f} {np.percentile(wall, 99) * 1e6:8.1f}"
              f"       {du:8.1e} {du_w:8.1e} {dBu:9.1e} {dJ:8.1e}  {counts}")
    first = next(iter(answers))
    for name in list(answers)[1:]:
        print(f"max |du| between {first} and {name}: "
              f"{np.abs(answers[first] - answers[name]).max():.1e}")


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--case", default="1", help="paper case to replay (1, 2, ...; none: skip)")
    ap.add_argument("--steps", type=int, default=2500, help="control steps (250 Hz)")
    ap.add_argument("--seed", type=int, default=0)
    args = ap.parse_args()
    if args.case != "none":
        replay_case(args.case)
        print()
    v, Bs = scenario(args.steps, args.seed)
    print(f"{args.steps} steps at 250 Hz, n_v = 5, n_u = {N_U}; times per allocate() call")

    qp = QPAllocator(5, U_MIN, U_MAX, w_v=W_V, u_pref=U_PREF, rate_limit=RATE)
    report("QP, B changes every step", run(qp, v, Bs), qp.stats)

    qp = QPAllocator(5, U_MIN, U_MAX, w_v=W_V, u_pref=U_PREF, rate_limit=RATE)
    B_const = [Bs[len(Bs) // 2]] * len(Bs)
    report("QP, B constant", run(qp, v, B_const), qp.stats)

    qp = QPAllocator(5, U_MIN, U_MAX, w_v=W_V, u_pref=U_PREF, rate_limit=RATE, polish=False)
    report("QP, no active-set polish", run(qp, v, Bs), qp.stats)

    qp = ActiveSetAllocator(5, U_MIN, U_MAX, w_v=W_V, u_pref=U_PREF, rate_limit=RATE)
    report("active set alone (tol 1e-15)", run(qp, v, Bs), qp.stats)

    pi = PseudoInverseAllocator(U_MIN, U_MAX, u_trim=U_PREF)
    report("PX4-style pseudo-inverse (baseline)", run(pi, v, Bs))


if __name__ == "__main__":
    main()

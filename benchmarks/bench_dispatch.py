"""What a compiled (numba) call costs before it does anything: dispatch and argument unboxing.

    python benchmarks/bench_dispatch.py [--calls 200000]

Times, in one process, a plain Python function call and no-op numba kernels taking 1 and 13
float64 arrays and 6 scalars, and prints ns per call and the load average. The per-step
kernels of an in-process flight are called with tens of array arguments per control step,
so this overhead is what fusing or packing them saves (``bench_inproc.py``).

Measured (2026-12-02, 2 cores shared, load average 17-18, two rounds): Python call 75-110 ns;
no-op kernel of 1 array 270-410 ns, of 13 arrays 2,180-2,780 ns (~160-200 ns per array),
of 6 scalars 450-800 ns. Once more at load 24: 414, 1,255, 7,579 and 2,203 ns: the absolute
figures follow the load, the ratios (13 arrays ~6x one array) hold.
"""

from __future__ import annotations

import argparse
import os
import time
from collections.abc import Callable
from typing import Any

import numba
import numpy as np


@numba.njit
def _one(a: np.ndarray) -> int:  # pragma: no cover - compiled
    return 0


@numba.njit
def _thirteen(a, b, c, d, e, f, g, h, i, j, k, m, n):  # type: ignore[no-untyped-def]
    return 0


@numba.njit
def _scalars(a, b, c, d, e, f):  # type: ignore[no-untyped-def]
    return 0


def _py(a: np.ndarray) -> int:
    return 0


def _ns(fn: Callable[..., Any], args: tuple[Any, ...], n: int) -> float:
    """Mean wall time of ``fn(*args)`` over ``n`` calls [ns]."""
    t0 = time.perf_counter()
    for _ in range(n):
        fn(*args)
    return (time.perf_counter() - t0) / n * 1e9


def main() -> None:
    """Print the cost of each kind of call."""
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--calls", type=int, default=200_000)
    args = ap.parse_args()
    if args.calls < 1:
        ap.error(f"--calls {args.calls}: expected a positive number")
    a = np.zeros(15)
    cases: list[tuple[str, Callable[..., Any], tuple[Any, ...]]] = [
        ("python call", _py, (a,)), ("kernel, 1 array", _one, (a,)),
        ("kernel, 13 arrays", _thirteen, (a,) * 13),
        ("kernel, 6 scalars", _scalars, (1.0, 2.0, True, False, 3, 4.0))]
    for _, fn, xs in cases:
        fn(*xs)  # compile
    for _, fn, xs in cases:
        _ns(fn, xs, 1000)
    for name, fn, xs in cases:
        print(f"{name:18s} {_ns(fn, xs, args.calls):8.0f} ns per call")
    print(f"load average {os.getloadavg()[0]:.1f} on {os.cpu_count()} cores")


if __name__ == "__main__":
    main()

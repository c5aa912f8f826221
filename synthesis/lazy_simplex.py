"""Bounded Nelder-Mead that asks its objective only what each decision needs.

Every Nelder-Mead decision compares a trial point's value with a threshold (the worst
vertex, or the reflected point's value), and a rejected trial point's value is never
stored. An objective that is a sum of non-negative terms, cheap ones first, can therefore
stop as soon as its partial sum reaches the threshold: the decision is the same as with the
full value. :func:`lazy_nelder_mead` passes that threshold (``bound``) to ``f(x, bound)``,
which must return the exact value when it is below ``bound`` and any value >= ``bound``
(e.g. a partial sum) otherwise. With ``bound = inf`` the value is exact: the simplex only
ever stores exact values.

Steps (Lagarias et al., the standard coefficients 1, 2, 1/2, 1/2), points clipped to the
bounds; strict comparisons throughout (a trial point is accepted only if strictly better
than its threshold).
"""

from __future__ import annotations

import math
from collections.abc import Callable

import numpy as np
from numpy.typing import NDArray

__all__ = ["lazy_nelder_mead"]


def lazy_nelder_mead(f: Callable[[NDArray[np.float64], float], float],
                     simplex: NDArray[np.float64], lower: NDArray[np.float64],
                     upper: NDArray[np.float64], max_evals: int, xatol: float = 1e-4,
                     fatol: float = 1e-5) -> tuple[NDArray[np.float64], float, int]:
    """Minimise ``f`` from ``simplex`` within [lower, upper].

    Parameters
    ----------
    f : callable
        ``f(x, bound)``: exact when below ``bound``, else any value >= ``bound``.
    simplex : ndarray of float, shape (n + 1, n)
        The initial simplex (vertex 0 the start).
    lower, upper : ndarray of float, shape (n,)
        Bounds.
    max_evals : int
        Evaluations of ``f`` (calls, whether they stopped early or not).
    xatol, fatol : float
        Stop when every vertex is within ``xatol`` of the best (max norm) and every value
        within ``fatol`` of the best.

    Returns
    -------
    x : ndarray of float
        The best vertex.
    fx : float
        Its exact value.
    nfev : int
        Calls of ``f``.
    """
    sim = np.clip(np.asarray(simplex, float), lower, upper)
    n = sim.shape[1]
    fs = np.array([f(x, math.inf) for x in sim])
    nfev = n + 1
    while nfev < max_evals:
        order = np.argsort(fs, kind="stable")
        sim, fs = sim[order], fs[order]
        if (np.max(np.abs(sim[1:] - sim[0])) <= xatol
                and np.max(np.abs(fs[1:] - fs[0])) <= fatol):
            break
        xbar = sim[:-1].mean(axis=0)
        xr = np.clip(2.0 * xbar - sim[-1], lower, upper)
        fr = f(xr, fs[-1])
        nfev += 1
        if fr < fs[0]:
            xe = np.clip(3.0 * xbar - 2.0 * sim[-1], lower, upper)
            fe = f(xe, fr)
            nfev += 1
            sim[-1], fs[-1] = (xe, fe) if fe < fr else (xr, fr)
            continue
        if fr < fs[-2]:
            sim[-1], fs[-1] = xr, fr
            continue
        if fr < fs[-1]:                                   # outside contraction
            xc = np.clip(xbar + 0.5 * (xr - xbar), lower, upper)
            fc = f(xc, fr)
            nfev += 1
            if fc < fr:
                sim[-1], fs[-1] = xc, fc
                continue
        else:                                             # inside contraction
            xc = np.clip(xbar + 0.5 * (sim[-1] - xbar), lower, upper)
            fc = f(xc, fs[-1])
            nfev += 1
            if fc < fs[-1]:
                sim[-1], fs[-1] = xc, fc
                continue
        for j in range(1, n + 1):                         # shrink toward the best
            sim[j] = np.clip(sim[0] + 0.5 * (sim[j] - sim[0]), lower, upper)
            fs[j] = f(sim[j], math.inf)
            nfev += 1
    i = int(np.argmin(fs))
    return sim[i].copy(), float(fs[i]), nfev

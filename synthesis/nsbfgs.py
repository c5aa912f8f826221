"""BFGS with a weak Wolfe line search for nonsmooth objectives (Lewis & Overton, HIFOO).

The final stage of the structured H-infinity tuner's polish (``tune(..., polish=True)`` in
:mod:`vtolftc.synthesis.structured`): on a max of singular values the frequency-exchange
trust-region solver creeps along a flat, curved valley (COMPleib HE3: about 1e-5 relative per
iteration, every stop rule ending above 0.8157), because its model of the step knows only
the local slopes at a fixed frequency set. BFGS on the exact objective builds the valley's
curvature from successive gradients, and with an inexact weak Wolfe line search it keeps
converging on functions that are nonsmooth at their minimiser (A. S. Lewis and M. L.
Overton, *Nonsmooth optimization via quasi-Newton methods*, Math. Programming 141, 2013;
the method of HIFOO). The iterates stay where the objective is finite: a trial point with an
infinite value (an unstable closed loop, a parameter outside its bounds) is treated as too
long a step.
"""

from __future__ import annotations

import math
from collections.abc import Callable
from dataclasses import dataclass

import numpy as np
from numpy.typing import NDArray
from scipy.optimize import nnls

__all__ = ["BfgsResult", "nonsmooth_bfgs"]

ValueAndGradient = Callable[[NDArray[np.float64]], tuple[float, NDArray[np.float64] | None]]
"""x -> (f(x), a gradient of f at x); (inf, None) where f is not finite."""

ARMIJO = 1e-4
"""c1 of the sufficient-decrease (Armijo) condition f(x + t d) <= f(x) + c1 t g'd."""
WOLFE = 0.9
"""c2 of the weak Wolfe condition g(x + t d)'d >= c2 g'd."""
MAX_TRIALS = 50
"""Trial steps of one line search (doublings and bisections) before it is said to fail."""


@dataclass(frozen=True)
class BfgsResult:
    """Outcome of :func:`nonsmooth_bfgs`.

    Parameters
    ----------
    x : ndarray of float, shape (n,)
        The best point (the last accepted iterate).
    value : float
        f(x).
    history : list of float
        f after each accepted iteration (the first entry is f(x0)).
    iterations : int
        Accepted iterations.
    evaluations : int
        Calls of the objective.
    status : str
        Why it stopped.
    """

    x: NDArray[np.float64]
    value: float
    history: list[float]
    iterations: int
    evaluations: int
    status: str


def _line_search(
    fg: ValueAndGradient, x: NDArray[np.float64], f: float, g: NDArray[np.float64],
    d: NDArray[np.float64],
) -> tuple[float, float, NDArray[np.float64] | None, int]:
    """Weak Wolfe bracketing: (t, f(x + t d), g(x + t d), evaluations); t = 0 on failure."""
    gd = float(g @ d)
    t, lo, hi = 1.0, 0.0, math.inf
    for n in range(1, MAX_TRIALS + 1):
        fn, gn = fg(x + t * d)
        if not math.isfinite(fn) or gn is None or fn > f + ARMIJO * t * gd:
            hi = t
        elif float(gn @ d) < WOLFE * gd:
            lo = t
        else:
            return t, fn, gn, n
        t = 2.0 * lo if math.isinf(hi) else 0.5 * (lo + hi)
    return 0.0, f, None, MAX_TRIALS


SAMPLE_RADII = (1e-2, 1e-3, 1e-4, 1e-5, 1e-6)
"""Radii (in the caller's scaled coordinates) of the gradient-sampling steps that take over
when the BFGS line search fails, largest first (Burke, Lewis & Overton's gradient sampling;
BFGS then gradient sampling is their HANSO)."""


def _min_norm_in_hull(G: NDArray[np.float64]) -> NDArray[np.float64]:
    """The element of least 2-norm of the convex hull of the rows of G (a small NNLS)."""
    m = G.shape[0]
    big = 1e3 * max(float(np.max(np.abs(G))), 1.0)
    lam, _ = nnls(np.vstack([G.T, big * np.ones((1, m))]),
                  np.concatenate([np.zeros(G.shape[1]), [big]]))
    tot = float(lam.sum())
    lam = lam / tot if tot > 0 else np.full(m, 1.0 / m)
    return lam @ G


def _sampling_step(
    fg: ValueAndGradient, x: NDArray[np.float64], f: float, g: NDArray[np.float64],
    radius: float, rng: np.random.Generator,
) -> tuple[NDArray[np.float64], float, NDArray[np.float64], int] | None:
    """One gradient-sampling step: the least-norm convex combination g* of the gradients at
    x and at n + 1 points drawn uniformly in the box of half-width ``radius`` around x, then
    Armijo backtracking along -g*. None when no step lowers f (x is ``radius``-stationary
    as far as the sample can tell); else (x_new, f_new, g_new, evaluations)."""
    n = x.size
    grads = [g]
    nfe = 0
    for _ in range(n + 1):
        _, gs = fg(x + radius * rng.uniform(-1.0, 1.0, n))
        nfe += 1
        if gs is not None:
            grads.append(gs)
    gstar = _min_norm_in_hull(np.array(grads))
    slope = float(gstar @ gstar)
    if not slope > 0:
        return None
    t = 1.0
    for _ in range(MAX_TRIALS):
        fn, gn = fg(x - t * gstar)
        nfe += 1
        if math.isfinite(fn) and gn is not None and fn < f - ARMIJO * t * slope:
            return x - t * gstar, fn, gn, nfe
        t *= 0.5
        if t * math.sqrt(slope) < 1e-3 * radius:
            break
    return None


def nonsmooth_bfgs(
    fg: ValueAndGradient, x0: NDArray[np.float64], *, max_iter: int,
    window: int, rel_tol: float, should_stop: Callable[[], str] | None = None,
) -> BfgsResult:
    """Minimise f from x0 by BFGS with a weak Wolfe line search (nonsmooth f allowed).

    Parameters
    ----------
    fg : callable
        x -> (f(x), gradient at x), (inf, None) where f is infinite. x is in the caller's
        scaled coordinates (the inverse-Hessian estimate starts as the identity in them).
    x0 : ndarray of float, shape (n,)
        Start; f(x0) must be finite.
    max_iter : int
        Cap on the iterations.
    window, rel_tol : int, float
        Stop when f fell by less than ``rel_tol`` (relative) over the last ``window``
        iterations (no progress).
    should_stop : callable, optional
        Called before each iteration; a non-empty string stops the run with that status
        (a deadline, an interruption).

    Returns
    -------
    BfgsResult
        The last iterate and why the run stopped: "no progress", "stationary (gradient
        sampling found no descent)" (the line search failed, and so did a gradient-sampling
        step at every radius of :data:`SAMPLE_RADII`), "zero gradient", "iteration cap" or
        ``should_stop``'s status. Where the weak Wolfe line search fails (x on a kink, the
        one gradient there no descent direction), a gradient-sampling step is taken and
        BFGS restarts from its point with the identity as its inverse-Hessian estimate; the
        random sample is seeded (0), so a run is reproducible.

    Raises
    ------
    ValueError
        If f(x0) is not finite.
    """
    x = np.array(x0, dtype=float)
    f, g = fg(x)
    if not math.isfinite(f) or g is None:
        raise ValueError(f"nonsmooth_bfgs needs a start with a finite objective, got {f}")
    n = x.size
    H = np.eye(n)
    hist = [f]
    nfe = 1
    status = "iteration cap"
    it = 0
    ir = 0  # the gradient-sampling radius in use, SAMPLE_RADII[ir]
    rng = np.random.default_rng(0)
    while it < max_iter:
        if should_stop is not None and (why := should_stop()):
            status = why
            break
        if not np.any(g):
            status = "zero gradient"
            break
        d = -H @ g
        if not float(g @ d) < 0:  # H lost positive definiteness to round-off: reset
            H = np.eye(n)
            d = -g
        t, fn, gn, k = _line_search(fg, x, f, g, d)
        nfe += k
        if gn is None:  # at a kink: gradient sampling, then BFGS afresh from its point
            step = None
            while step is None and ir < len(SAMPLE_RADII):
                step = _sampling_step(fg, x, f, g, SAMPLE_RADII[ir], rng)
                ir += step is None
            if step is None:
                status = "stationary (gradient sampling found no descent)"
                break
            xn, fn, gn, k = step
            nfe += k
            s, H = xn - x, np.eye(n)
        else:
            s = t * d
        y = gn - g
        sy = float(s @ y)
        if sy > 0:
            r = 1.0 / sy
            Hy = H @ y
            H = (H - r * (np.outer(s, Hy) + np.outer(Hy, s))
                 + (r * r * float(y @ Hy) + r) * np.outer(s, s))
        x, f, g = x + s, fn, gn
        hist.append(f)
        it += 1
        if it >= window and hist[-1 - window] - f <= rel_tol * abs(f):
            status = "no progress"
            break
    return BfgsResult(x, f, hist, it, nfe, status)

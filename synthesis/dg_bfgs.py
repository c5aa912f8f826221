"""Compiled quasi-Newton minimisation of the D-G objective (:mod:`vtolftc.synthesis.dg_scaling`).

The D-G upper bound minimises lambda_max of the scaled LMI over the scalings, through a
continuation of log-sum-exp smoothings (relative widths ``stages``, the last 0). Each stage is
SciPy's BFGS (``scipy.optimize._minimize_bfgs``, SciPy 1.17: H0 = I, a first step of length
~1, MINPACK-2's dcsrch line search (More & Thuente) with SciPy's ``line_search_wolfe2`` as
its fallback, c1 = 1e-4, c2 = 0.9) written out here, compiled with numba, on the compiled
objective :func:`vtolftc.synthesis.dg_kernel.dg_objective`, the whole continuation in one
call: SciPy's BFGS on the same objective spent ~90 % of its time in its own Python (line
search, wrappers), the objective ~10 %. The same steps as SciPy's where the arithmetic
agrees (it does not always bit for bit: BLAS, the order of a few operations).

The optimiser only proposes scalings: every evaluated point's lambda_max is an exact
evaluation of the LMI, the smallest one seen (and its parameters) is what the caller keeps,
and the caller re-checks the returned scalings outside this module (``certified_value``).
"""

from __future__ import annotations

import math

import numba
import numpy as np
from numpy.typing import NDArray

from vtolftc.synthesis.dg_kernel import dg_objective

__all__ = ["dg_minimise"]

_BIG = 1e300
_XMAX = 300.0  # beyond |x_i| = 300 the objective is 1e300 (a wall)
_C1 = 1e-4
_C2 = 0.9


@numba.njit(cache=True)
def _fg(M: NDArray[np.complex128], x: NDArray[np.float64], ka: tuple, smooth: float,
        best: NDArray[np.float64], best_x: NDArray[np.float64]) -> tuple[float,
                                                                         NDArray[np.float64]]:
    """The smoothed objective and its gradient at x (1e300 and 0 where x is non-finite, too
    large or the eigenproblem fails); records the smallest lambda_max in ``best`` /
    ``best_x`` (in place)."""
    best[1] += 1.0
    g0 = np.zeros(x.size)
    for i in range(x.size):
        if not math.isfinite(x[i]) or abs(x[i]) > _XMAX:
            return _BIG, g0
    try:
        l1, f, g = dg_objective(M, x, ka[0], ka[1], ka[2], ka[3], ka[4], ka[5], ka[6], ka[7],
                                ka[8], ka[9], ka[10], ka[11], ka[12], smooth, True)
    except Exception:  # a failed eigen / linear solve (numba catches no finer class)
        return _BIG, g0
    if math.isfinite(l1) and l1 < best[0]:
        best[0] = l1
        best_x[:] = x
    return f, g


@numba.njit(cache=True)
def _sign(v: float) -> float:
    """np.sign of a float (0 at 0, NaN at NaN)."""
    if v > 0.0:
        return 1.0
    if v < 0.0:
        return -1.0
    return v


@numba.njit(cache=True)
def _clip(v: float, lo: float, hi: float) -> float:
    """np.clip of a float (NaN stays NaN)."""
    if v != v:
        return v
    return min(max(v, lo), hi)


@numba.njit(cache=True, error_model="numpy")
def _dcstep(stx: float, fx: float, dx: float, sty: float, fy: float, dy: float, stp: float,
            fp: float, dp: float, brackt: bool, stpmin: float, stpmax: float
            ) -> tuple[float, float, float, float, float, float, float, bool]:
    """MINPACK-2's dcstep (More & Thuente), as SciPy's ``_dcsrch.dcstep``: a safeguarded
    step and the update of the interval that brackets a Wolfe step."""
    sgnd = _sign(dp) * _sign(dx)
    if fp > fx:
        theta = 3.0 * (fx - fp) / (stp - stx) + dx + dp
        s = max(abs(theta), abs(dx), abs(dp))
        gamma = s * np.sqrt((theta / s) ** 2 - (dx / s) * (dp / s))
        if stp < stx:
            gamma *= -1
        p = (gamma - dx) + theta
        q = ((gamma - dx) + gamma) + dp
        r = p / q
        stpc = stx + r * (stp - stx)
        stpq = stx + ((dx / ((fx - fp) / (stp - stx) + dx)) / 2.0) * (stp - stx)
        stpf = stpc if abs(stpc - stx) <= abs(stpq - stx) else stpc + (stpq - stpc) / 2.0
        brackt = True
    elif sgnd < 0.0:
        theta = 3 * (fx - fp) / (stp - stx) + dx + dp
        s = max(abs(theta), abs(dx), abs(dp))
        gamma = s * np.sqrt((theta / s) ** 2 - (dx / s) * (dp / s))
        if stp > stx:
            gamma *= -1
        p = (gamma - dp) + theta
        q = ((gamma - dp) + gamma) + dx
        r = p / q
        stpc = stp + r * (stx - stp)
        stpq = stp + (dp / (dp - dx)) * (stx - stp)
        stpf = stpc if abs(stpc - stp) > abs(stpq - stp) else stpq
        brackt = True
    elif abs(dp) < abs(dx):
        theta = 3 * (fx - fp) / (stp - stx) + dx + dp
        s = max(abs(theta), abs(dx), abs(dp))
        gamma = s * np.sqrt(max(0.0, (theta / s) ** 2 - (dx / s) * (dp / s)))
        if stp > stx:
            gamma = -gamma
        p = (gamma - dp) + theta
        q = (gamma + (dx - dp)) + gamma
        r = p / q
        if r < 0 and gamma != 0:
            stpc = stp + r * (stx - stp)
        elif stp > stx:
            stpc = stpmax
        else:
            stpc = stpmin
        stpq = stp + (dp / (dp - dx)) * (stx - stp)
        if brackt:
            stpf = stpc if abs(stpc - stp) < abs(stpq - stp) else stpq
            if stp > stx:
                stpf = min(stp + 0.66 * (sty - stp), stpf)
            else:
                stpf = max(stp + 0.66 * (sty - stp), stpf)
        else:
            stpf = stpc if abs(stpc - stp) > abs(stpq - stp) else stpq
            stpf = _clip(stpf, stpmin, stpmax)
    else:
        if brackt:
            theta = 3.0 * (fp - fy) / (sty - stp) + dy + dp
            s = max(abs(theta), abs(dy), abs(dp))
            gamma = s * np.sqrt((theta / s) ** 2 - (dy / s) * (dp / s))
            if stp > sty:
                gamma = -gamma
            p = (gamma - dp) + theta
            q = ((gamma - dp) + gamma) + dy
            r = p / q
            stpc = stp + r * (sty - stp)
            stpf = stpc
        elif stp > stx:
            stpf = stpmax
        else:
            stpf = stpmin
    if fp > fx:
        sty = stp
        fy = fp
        dy = dp
    else:
        if sgnd < 0:
            sty = stx
            fy = fx
            dy = dx
        stx = stp
        fx = fp
        dx = dp
    return stx, fx, dx, sty, fy, dy, stpf, brackt


@numba.njit(cache=True, error_model="numpy")
def _wolfe1(M: NDArray[np.complex128], x: NDArray[np.float64], p: NDArray[np.float64],
            f0: float, d0: float, alpha1: float, ka: tuple, smooth: float,
            best: NDArray[np.float64], best_x: NDArray[np.float64]
            ) -> tuple[bool, float, float, NDArray[np.float64]]:
    """SciPy's ``line_search_wolfe1`` (MINPACK-2's dcsrch: ftol c1, gtol c2, xtol 1e-14,
    steps in [1e-100, 1e100], 100 iterations): (found, alpha, f, gradient)."""
    stpmin, stpmax, xtol = 1e-100, 1e100, 1e-14
    fail = (False, 0.0, f0, np.zeros(x.size))
    stp = alpha1
    if stp < stpmin or stp > stpmax or d0 >= 0:
        return fail
    brackt = False
    stage = 1
    finit, ginit = f0, d0
    gtest = _C1 * ginit
    width = stpmax - stpmin
    width1 = width / 0.5
    stx, fx, gx = 0.0, finit, ginit
    sty, fy, gy = 0.0, finit, ginit
    stmin, stmax = 0.0, stp + 4.0 * stp
    f, gv = _fg(M, x + stp * p, ka, smooth, best, best_x)
    g = float(np.dot(gv, p))
    for _ in range(99):
        ftest = finit + stp * gtest
        if stage == 1 and f <= ftest and g >= 0:
            stage = 2
        warn = False
        if brackt and (stp <= stmin or stp >= stmax):
            warn = True
        if brackt and stmax - stmin <= xtol * stmax:
            warn = True
        if stp == stpmax and f <= ftest and g <= gtest:
            warn = True
        if stp == stpmin and (f > ftest or g >= gtest):
            warn = True
        if f <= ftest and abs(g) <= _C2 * -ginit:
            return True, stp, f, gv
        if warn:
            return fail
        if stage == 1 and f <= fx and f > ftest:
            fm = f - stp * gtest
            fxm = fx - stx * gtest
            fym = fy - sty * gtest
            gm = g - gtest
            gxm = gx - gtest
            gym = gy - gtest
            stx, fxm, gxm, sty, fym, gym, stp, brackt = _dcstep(
                stx, fxm, gxm, sty, fym, gym, stp, fm, gm, brackt, stmin, stmax)
            fx = fxm + stx * gtest
            fy = fym + sty * gtest
            gx = gxm + gtest
            gy = gym + gtest
        else:
            stx, fx, gx, sty, fy, gy, stp, brackt = _dcstep(
                stx, fx, gx, sty, fy, gy, stp, f, g, brackt, stmin, stmax)
        if brackt:
            if abs(sty - stx) >= 0.66 * width1:
                stp = stx + 0.5 * (sty - stx)
            width1 = width
            width = abs(sty - stx)
        if brackt:
            stmin = min(stx, sty)
            stmax = max(stx, sty)
        else:
            stmin = stp + 1.1 * (stp - stx)
            stmax = stp + 4.0 * (stp - stx)
        stp = _clip(stp, stpmin, stpmax)
        if ((brackt and (stp <= stmin or stp >= stmax))
                or (brackt and stmax - stmin <= xtol * stmax)):
            stp = stx
        if not math.isfinite(stp):
            return fail
        f, gv = _fg(M, x + stp * p, ka, smooth, best, best_x)
        g = float(np.dot(gv, p))
    return fail


@numba.njit(cache=True, error_model="numpy")
def _cubicmin(a: float, fa: float, fpa: float, b: float, fb: float, c: float,
              fc: float) -> float:
    """SciPy's ``_linesearch._cubicmin`` (NaN for its None)."""
    C = fpa
    db = b - a
    dc = c - a
    denom = (db * dc) ** 2 * (db - dc)
    r0 = fb - fa - C * db
    r1 = fc - fa - C * dc
    A = dc ** 2 * r0 + -db ** 2 * r1
    B = -dc ** 3 * r0 + db ** 3 * r1
    if denom == 0.0 or not (math.isfinite(A) and math.isfinite(B)):
        return math.nan
    A /= denom
    B /= denom
    radical = B * B - 3 * A * C
    if not radical >= 0.0 or A == 0.0:
        return math.nan
    xmin = a + (-B + np.sqrt(radical)) / (3 * A)
    return xmin if math.isfinite(xmin) else math.nan


@numba.njit(cache=True, error_model="numpy")
def _quadmin(a: float, fa: float, fpa: float, b: float, fb: float) -> float:
    """SciPy's ``_linesearch._quadmin`` (NaN for its None)."""
    db = b - a * 1.0
    if db == 0.0:
        return math.nan
    B = (fb - fa - fpa * db) / (db * db)
    if B == 0.0 or not math.isfinite(B):
        return math.nan
    xmin = a - fpa / (2.0 * B)
    return xmin if math.isfinite(xmin) else math.nan


@numba.njit(cache=True, error_model="numpy")
def _wolfe2(M: NDArray[np.complex128], x: NDArray[np.float64], p: NDArray[np.float64],
            f0: float, d0: float, alpha1: float, ka: tuple, smooth: float,
            best: NDArray[np.float64], best_x: NDArray[np.float64]
            ) -> tuple[bool, float, float, NDArray[np.float64]]:
    """SciPy's ``scalar_search_wolfe2`` with its ``_zoom`` (amax 1e100, 10 iterations each):
    (found, alpha, f, gradient)."""
    amax = 1e100
    fail = (False, 0.0, f0, np.zeros(x.size))
    alpha0 = 0.0
    alpha1 = min(alpha1, amax)
    phi_a1, g_a1 = _fg(M, x + alpha1 * p, ka, smooth, best, best_x)
    phi_a0, derphi_a0 = f0, d0
    for i in range(10):
        if alpha1 == 0 or alpha0 > amax:
            return fail
        if phi_a1 > f0 + _C1 * alpha1 * d0 or (phi_a1 >= phi_a0 and i > 0):
            return _zoom(M, x, p, alpha0, alpha1, phi_a0, phi_a1, derphi_a0, f0, d0, ka,
                         smooth, best, best_x)
        derphi_a1 = float(np.dot(g_a1, p))
        if abs(derphi_a1) <= -_C2 * d0:
            return True, alpha1, phi_a1, g_a1
        if derphi_a1 >= 0:
            return _zoom(M, x, p, alpha1, alpha0, phi_a1, phi_a0, derphi_a1, f0, d0, ka,
                         smooth, best, best_x)
        alpha2 = min(2 * alpha1, amax)
        alpha0 = alpha1
        alpha1 = alpha2
        phi_a0 = phi_a1
        phi_a1, g_a1 = _fg(M, x + alpha1 * p, ka, smooth, best, best_x)
        derphi_a0 = derphi_a1
    return True, alpha1, phi_a1, g_a1


@numba.njit(cache=True, error_model="numpy")
def _zoom(M: NDArray[np.complex128], x: NDArray[np.float64], p: NDArray[np.float64],
          a_lo: float, a_hi: float, phi_lo: float, phi_hi: float, derphi_lo: float,
          f0: float, d0: float, ka: tuple, smooth: float, best: NDArray[np.float64],
          best_x: NDArray[np.float64]) -> tuple[bool, float, float, NDArray[np.float64]]:
    """SciPy's ``_linesearch._zoom`` (cubic, quadratic, bisection; 10 iterations)."""
    phi_rec, a_rec = f0, 0.0
    cchk = 0.0
    a_j = math.nan
    for i in range(11):
        dalpha = a_hi - a_lo
        if dalpha < 0:
            a, b = a_hi, a_lo
        else:
            a, b = a_lo, a_hi
        if i > 0:
            cchk = 0.2 * dalpha
            a_j = _cubicmin(a_lo, phi_lo, derphi_lo, a_hi, phi_hi, a_rec, phi_rec)
        if i == 0 or a_j != a_j or a_j > b - cchk or a_j < a + cchk:
            qchk = 0.1 * dalpha
            a_j = _quadmin(a_lo, phi_lo, derphi_lo, a_hi, phi_hi)
            if a_j != a_j or a_j > b - qchk or a_j < a + qchk:
                a_j = a_lo + 0.5 * dalpha
        phi_aj, g_aj = _fg(M, x + a_j * p, ka, smooth, best, best_x)
        if phi_aj > f0 + _C1 * a_j * d0 or phi_aj >= phi_lo:
            phi_rec = phi_hi
            a_rec = a_hi
            a_hi = a_j
            phi_hi = phi_aj
        else:
            derphi_aj = float(np.dot(g_aj, p))
            if abs(derphi_aj) <= -_C2 * d0:
                return True, a_j, phi_aj, g_aj
            if derphi_aj * (a_hi - a_lo) >= 0:
                phi_rec = phi_hi
                a_rec = a_hi
                a_hi = a_lo
                phi_hi = phi_lo
            else:
                phi_rec = phi_lo
                a_rec = a_lo
            a_lo = a_j
            phi_lo = phi_aj
            derphi_lo = derphi_aj
    return False, 0.0, f0, np.zeros(x.size)


@numba.njit(cache=True, error_model="numpy")
def _bfgs_stage(M: NDArray[np.complex128], x: NDArray[np.float64], ka: tuple, smooth: float,
                maxiter: int, stop2: float, rtol: float, best: NDArray[np.float64],
                best_x: NDArray[np.float64]) -> None:
    """One continuation stage: SciPy's BFGS (``_minimize_bfgs``: H0 = I, the first step of
    length ~1, ``line_search_wolfe1`` then ``line_search_wolfe2``) from x until ``maxiter``
    iterations, a failed line search, gradient sup-norm <= 1e-12 |best| or the caller's
    callback's stop: the target (best <= stop2 or < 0) or a stall (best improved by no more
    than rtol relative over the last 8 iterations)."""
    n = x.size
    gtol = 1e-12 * max(abs(best[0]), 1e-300)
    f, g = _fg(M, x, ka, smooth, best, best_x)
    H = np.eye(n)
    f_old = f + math.sqrt(float(np.dot(g, g))) / 2  # numpy.linalg.norm of a vector
    hist = np.empty(maxiter + 1)
    k = 0
    while np.max(np.abs(g)) > gtol and k < maxiter:
        p = -np.dot(H, g)
        d0 = float(np.dot(g, p))
        alpha1 = 1.0
        if d0 != 0:
            alpha1 = min(1.0, 1.01 * 2 * (f - f_old) / d0)
            if alpha1 < 0:
                alpha1 = 1.0
        ok, a, f_new, g_new = _wolfe1(M, x, p, f, d0, alpha1, ka, smooth, best, best_x)
        if not ok:
            ok, a, f_new, g_new = _wolfe2(M, x, p, f, d0, alpha1, ka, smooth, best, best_x)
        if not ok:
            break
        s = a * p
        x = x + s
        y = g_new - g
        g = g_new
        f_old, f = f, f_new
        hist[k] = best[0]
        k += 1
        if best[0] < 0.0 or best[0] <= stop2:
            break
        if k > 8 and hist[k - 9] - hist[k - 1] <= rtol * abs(hist[k - 1]):
            break
        if np.max(np.abs(g)) <= gtol:
            break
        if a * math.sqrt(float(np.dot(p, p))) <= 0.0:
            break
        if not math.isfinite(f):
            break
        sy = float(np.dot(y, s))
        rho = 1000.0 if sy == 0.0 else 1.0 / sy
        A1 = np.eye(n) - np.outer(s, y) * rho
        A2 = np.eye(n) - np.outer(y, s) * rho
        H = np.dot(A1, np.dot(H, A2)) + np.outer(rho * s, s)


@numba.njit(cache=True, error_model="numpy")
def dg_minimise(M: NDArray[np.complex128], x0: NDArray[np.float64], ka: tuple,
                stages: NDArray[np.float64], maxiter: int, stop2: float, rtol: float,
                best0: float, best_x0: NDArray[np.float64]
                ) -> tuple[float, NDArray[np.float64], int]:
    """Minimise lambda_max of the D-G LMI from x0 through the continuation ``stages``.

    Parameters
    ----------
    M : ndarray of complex, shape (n, n)
        The (padded, square) matrix.
    x0 : ndarray of float, shape (n_params,)
        Start parameters.
    ka : tuple of ndarray
        ``dg_scaling._DG.kernel_args`` (the parametrisation's index arrays).
    stages : ndarray of float
        Relative log-sum-exp widths, one BFGS stage each, in order.
    maxiter : int
        BFGS iterations per stage.
    stop2 : float
        Stop once lambda_max <= stop2 (or < 0) has been seen.
    rtol : float
        A stage stops when 8 iterations improved the best lambda_max by <= rtol relative.
    best0 : float
        The best lambda_max already known (inf if none), with its parameters ``best_x0``.
    best_x0 : ndarray of float, shape (n_params,)
        Parameters of ``best0``.

    Returns
    -------
    best : float
        The smallest lambda_max evaluated (an exact evaluation at ``best_x``).
    best_x : ndarray of float
        Its parameters.
    nfev : int
        Objective evaluations.
    """
    best = np.array([best0, 0.0])
    best_x = best_x0.copy()
    x = x0.copy()
    for i in range(stages.size):
        if best[0] < 0.0 or best[0] <= stop2:
            break
        _bfgs_stage(M, x, ka, stages[i], maxiter, stop2, rtol, best, best_x)
        if math.isfinite(best[0]):
            x = best_x.copy()
    return best[0], best_x, int(best[1])

"""Compiled Packard-Fan-Doyle power iteration of the mu lower bound (:mod:`.mu`).

The iteration (Packard, Fan and Doyle; Packard and Doyle 1993, section 9) alternates

    a <- M b,   z <- blockwise align(a -> w),   w <- M^H z,   b <- blockwise align(w -> a),

normalising a and w, until the gain beta = ||M b|| settles. Full blocks align by norms
(z_k = a_k ||w_k|| / ||a_k||), repeated complex scalars by the phase q_k maximising
Re(w_k^H q a_k), repeated real scalars by its sign. It is the same arithmetic as the numpy
reference ``_Power.run_numpy`` in :mod:`vtolftc.synthesis.mu` (kept and tested against this
kernel): a mu sweep runs it a few thousand times on 2 x 2 to 4 x 4 matrices, where numpy
spends nearly all the time in per-call overhead. Whatever vectors it returns, the bound built
from them (:func:`vtolftc.synthesis.mu._delta_from_q`) is verified separately, so the lower
bound stays a valid one.
"""

from __future__ import annotations

import math

import numba
import numpy as np
from numpy.typing import NDArray

__all__ = ["power_iteration", "power_iteration_scalar"]


@numba.njit(cache=True)
def _matvec(M: NDArray[np.complex128], x: NDArray[np.complex128]) -> NDArray[np.complex128]:
    n, m = M.shape
    y = np.empty(n, dtype=np.complex128)
    for i in range(n):
        s = 0j
        for j in range(m):
            s += M[i, j] * x[j]
        y[i] = s
    return y


@numba.njit(cache=True)
def _norm(x: NDArray[np.complex128]) -> float:
    s = 0.0
    for i in range(x.size):
        s += x[i].real * x[i].real + x[i].imag * x[i].imag
    return math.sqrt(s)


@numba.njit(cache=True)
def _blk_norms(v: NDArray[np.complex128], blk: NDArray[np.intp], K: int) -> NDArray[np.float64]:
    out = np.zeros(K)
    for i in range(v.size):
        out[blk[i]] += v[i].real * v[i].real + v[i].imag * v[i].imag
    return np.sqrt(out)


@numba.njit(cache=True)
def _phases(a: NDArray[np.complex128], w: NDArray[np.complex128], K: int,
            rep_row: NDArray[np.intp], rep_col: NDArray[np.intp], rep_blk: NDArray[np.intp],
            is_real: NDArray[np.bool_]) -> NDArray[np.complex128]:
    inner = np.zeros(K, dtype=np.complex128)
    for i in range(rep_row.size):
        inner[rep_blk[i]] += np.conj(w[rep_col[i]]) * a[rep_row[i]]
    q = np.ones(K, dtype=np.complex128)
    for k in range(K):
        if is_real[k]:
            q[k] = -1.0 if inner[k].real < 0 else 1.0
        else:
            mag = abs(inner[k])
            if mag > 0:
                q[k] = np.conj(inner[k]) / mag
    return q


@numba.njit(cache=True)
def power_iteration(M: NDArray[np.complex128], b: NDArray[np.complex128],
                    w: NDArray[np.complex128], iters: int, tol: float, K: int,
                    blk_of_row: NDArray[np.intp], blk_of_col: NDArray[np.intp],
                    full_row: NDArray[np.intp], full_col: NDArray[np.intp],
                    rep_row: NDArray[np.intp], rep_col: NDArray[np.intp],
                    rep_blk: NDArray[np.intp], is_real: NDArray[np.bool_],
                    ) -> tuple[NDArray[np.complex128], NDArray[np.complex128]]:
    """The mu power iteration for any mix of full, repeated complex and repeated real blocks.

    Parameters
    ----------
    M : ndarray of complex, shape (n, n)
        The matrix.
    b, w : ndarray of complex, shape (n,)
        Start vectors (unit norm).
    iters : int
        Maximum iterations.
    tol : float
        Relative tolerance on the change of the iteration's growth estimate beta.
    K : int
        Number of blocks.
    blk_of_row, blk_of_col, full_row, full_col, rep_row, rep_col, rep_blk, is_real : ndarray
        The index maps of ``mu_blocks.BlockStructure``.

    Returns
    -------
    a, w : ndarray of complex, shape (n,)
        The converged vector pair, a normalised.
    """
    Mh = np.ascontiguousarray(np.conj(M).T)
    has_rep = rep_row.size > 0
    a = _matvec(M, b)
    beta_old = -1.0
    for _ in range(iters):
        na = _norm(a)
        if na == 0.0:
            break
        a = a / na
        an = _blk_norms(a, blk_of_row, K)
        wn = _blk_norms(w, blk_of_col, K)
        z = np.empty_like(a)
        for i in range(full_row.size):
            r = full_row[i]
            k = blk_of_row[r]
            z[r] = a[r] * (wn[k] / an[k] if an[k] > 0 else 0.0)
        if has_rep:
            q = _phases(a, w, K, rep_row, rep_col, rep_blk, is_real)
            for i in range(rep_row.size):
                z[rep_row[i]] = np.conj(q[rep_blk[i]]) * w[rep_col[i]]
        w = _matvec(Mh, z)
        nw = _norm(w)
        if nw == 0.0:
            break
        w = w / nw
        wn = _blk_norms(w, blk_of_col, K)
        b = np.empty_like(w)
        for i in range(full_col.size):
            c = full_col[i]
            k = blk_of_col[c]
            b[c] = w[c] * (an[k] / wn[k] if wn[k] > 0 else 0.0)
        if has_rep:
            q = _phases(a, w, K, rep_row, rep_col, rep_blk, is_real)
            for i in range(rep_col.size):
                b[rep_col[i]] = q[rep_blk[i]] * a[rep_row[i]]
        a = _matvec(M, b)
        beta = _norm(a)
        if abs(beta - beta_old) <= tol * max(beta, 1e-300):
            break
        beta_old = beta
    na = _norm(a)
    if na > 0:
        a = a / na
    return a, w


@numba.njit(cache=True)
def power_iteration_scalar(M: NDArray[np.complex128], b: NDArray[np.complex128],
                           w: NDArray[np.complex128], iters: int, tol: float,
                           ) -> tuple[NDArray[np.complex128], NDArray[np.complex128]]:
    """The mu power iteration when every block is 1 x 1 (real ones iterate as complex).

    Parameters
    ----------
    M : ndarray of complex, shape (n, n)
        The matrix.
    b, w : ndarray of complex, shape (n,)
        Start vectors (unit norm).
    iters : int
        Maximum iterations.
    tol : float
        Relative tolerance on the change of the iteration's growth estimate beta.

    Returns
    -------
    a, w : ndarray of complex, shape (n,)
        As :func:`power_iteration` returns for that structure, without the final
        normalisation of a (as the numpy reference).
    """
    Mh = np.ascontiguousarray(np.conj(M).T)
    n = b.size
    a = _matvec(M, b)
    beta_old = -1.0
    for _ in range(iters):
        z = np.empty(n, dtype=np.complex128)
        na = np.empty(n)
        for i in range(n):
            na[i] = abs(a[i])
            z[i] = a[i] * (abs(w[i]) / na[i]) if na[i] > 0 else 0.0 * a[i]
        w = _matvec(Mh, z)
        nw = _norm(w)
        if nw == 0.0:
            break
        w = w / nw
        b = np.empty(n, dtype=np.complex128)
        for i in range(n):
            aw = abs(w[i])
            b[i] = w[i] * (na[i] / aw) if aw > 0 else 0.0 * w[i]
        a = _matvec(M, b)
        beta = _norm(a)
        if beta == 0.0:
            break
        a = a / beta
        if abs(beta - beta_old) <= tol * beta:
            break
        beta_old = beta
    return a, w

"""Compiled frequency responses of single-input channels and the gradients of their gains.

The structured H-infinity tuner (:mod:`vtolftc.synthesis.structured`) evaluates, thousands
of times per tune, the largest singular value of each channel's frequency response

    T(j w) = C (j w I - A)^-1 B + D

at a few frequencies w, and its gradient with respect to the tunable parameters theta_k
from the state-space derivatives (dA_k, dB_k, dC_k, dD_k). The channels of the attitude
design are single-input (B has one column: the stacked mixed-sensitivity channel of eq. 8,
the input-disturbance channel), so T(j w) is a column vector and

    sigma_max = ||T||_2,   u = T / ||T||_2,   v = 1,
    d sigma / d theta_k = Re(u^H dT_k v)
                        = Re(u^H dC_k x + a dA_k x + a dB_k + u^H dD_k),

with x = (j w I - A)^-1 B and the row a = u^H C (j w I - A)^-1. Both come from one complex LU
factorisation of j w I - A (partial pivoting): x by the forward/back substitution, a^T by the
transposed one. The numpy reference (``_Evaluator`` in :mod:`.structured`: batched
``numpy.linalg.solve`` for x and C (j w I - A)^-1, an SVD of T, the full dT_k products) gives
the same numbers to round-off and stays the path for multi-input channels; most of its time
was per-call overhead on these 11-13 state, 1-3 output systems. A test compares the two and
checks the gradient against finite differences.
"""

from __future__ import annotations

import math

import numba
import numpy as np
from numpy.typing import NDArray

__all__ = ["siso_sigma", "siso_sigma_grad"]


@numba.njit(cache=True)
def _lu(Z: NDArray[np.complex128], piv: NDArray[np.intp]) -> bool:
    """In-place LU with partial pivoting (LAPACK getrf's row swaps in ``piv``); False if a
    pivot is exactly zero (singular: j w is an eigenvalue of A)."""
    n = Z.shape[0]
    for k in range(n):
        p = k
        best = abs(Z[k, k])
        for i in range(k + 1, n):
            a = abs(Z[i, k])
            if a > best:
                best = a
                p = i
        piv[k] = p
        if best == 0.0:
            return False
        if p != k:
            for j in range(n):
                t = Z[k, j]
                Z[k, j] = Z[p, j]
                Z[p, j] = t
        inv = 1.0 / Z[k, k]
        for i in range(k + 1, n):
            f = Z[i, k] * inv
            Z[i, k] = f
            if f != 0.0:
                for j in range(k + 1, n):
                    Z[i, j] -= f * Z[k, j]
    return True


@numba.njit(cache=True)
def _solve(Z: NDArray[np.complex128], piv: NDArray[np.intp], b: NDArray[np.complex128]) -> None:
    """b <- Z^-1 b with the LU of :func:`_lu`."""
    n = Z.shape[0]
    for k in range(n):
        p = piv[k]
        if p != k:
            t = b[k]
            b[k] = b[p]
            b[p] = t
    for i in range(n):
        s = b[i]
        for j in range(i):
            s -= Z[i, j] * b[j]
        b[i] = s
    for i in range(n - 1, -1, -1):
        s = b[i]
        for j in range(i + 1, n):
            s -= Z[i, j] * b[j]
        b[i] = s / Z[i, i]


@numba.njit(cache=True)
def _solve_t(Z: NDArray[np.complex128], piv: NDArray[np.intp],
             c: NDArray[np.complex128]) -> None:
    """c <- Z^-T c (plain transpose, no conjugation) with the LU of :func:`_lu`."""
    n = Z.shape[0]
    for i in range(n):  # U^T y = c
        s = c[i]
        for j in range(i):
            s -= Z[j, i] * c[j]
        c[i] = s / Z[i, i]
    for i in range(n - 1, -1, -1):  # L^T z = y
        s = c[i]
        for j in range(i + 1, n):
            s -= Z[j, i] * c[j]
        c[i] = s
    for k in range(n - 1, -1, -1):  # the row swaps, undone in reverse
        p = piv[k]
        if p != k:
            t = c[k]
            c[k] = c[p]
            c[p] = t


@numba.njit(cache=True)
def _kernel(A: NDArray[np.float64], B: NDArray[np.float64], C: NDArray[np.float64],
            D: NDArray[np.float64], w: NDArray[np.float64], dA: NDArray[np.float64],
            dB: NDArray[np.float64], dC: NDArray[np.float64], dD: NDArray[np.float64],
            want_grad: bool) -> tuple[NDArray[np.float64], NDArray[np.float64], bool]:
    n = A.shape[0]
    q = C.shape[0]
    m = w.size
    p = dA.shape[0]
    sig = np.empty(m)
    g = np.zeros((m, p))
    Z = np.empty((n, n), dtype=np.complex128)
    piv = np.empty(n, dtype=np.intp)
    x = np.empty(n, dtype=np.complex128)
    a = np.empty(n, dtype=np.complex128)
    T = np.empty(q, dtype=np.complex128)
    u = np.empty(q, dtype=np.complex128)
    for k in range(m):
        wk = w[k]
        finite = math.isfinite(wk)
        if finite and n > 0:
            for i in range(n):
                for j in range(n):
                    Z[i, j] = -A[i, j]
                Z[i, i] += 1j * wk
            if not _lu(Z, piv):
                return sig, g, False
            for i in range(n):
                x[i] = B[i, 0]
            _solve(Z, piv, x)
            for r in range(q):
                s = D[r, 0] + 0j
                for j in range(n):
                    s += C[r, j] * x[j]
                T[r] = s
        else:
            for i in range(n):
                x[i] = 0.0
            for r in range(q):
                T[r] = D[r, 0]
        nrm = 0.0
        for r in range(q):
            nrm += T[r].real * T[r].real + T[r].imag * T[r].imag
        nrm = math.sqrt(nrm)
        sig[k] = nrm
        if not want_grad:
            continue
        if nrm > 0.0:
            for r in range(q):
                u[r] = T[r] / nrm
        else:
            for r in range(q):
                u[r] = 0.0
            u[0] = 1.0
        if finite and n > 0:
            for j in range(n):  # a^T = Z^-T C^T conj(u)
                s = 0j
                for r in range(q):
                    s += C[r, j] * np.conj(u[r])
                a[j] = s
            _solve_t(Z, piv, a)
        for kk in range(p):
            tot = 0j
            for r in range(q):
                s = dD[kk, r, 0] + 0j
                for j in range(n):
                    s += dC[kk, r, j] * x[j]
                tot += np.conj(u[r]) * s
            if finite and n > 0:
                for i in range(n):
                    s = dB[kk, i, 0] + 0j
                    for j in range(n):
                        s += dA[kk, i, j] * x[j]
                    tot += a[i] * s
            g[k, kk] = tot.real
    return sig, g, True


_EMPTY3 = np.zeros((0, 0, 0))


def siso_sigma(A: NDArray[np.float64], B: NDArray[np.float64], C: NDArray[np.float64],
               D: NDArray[np.float64], w: NDArray[np.float64]) -> NDArray[np.float64]:
    """||T(j w_k)||_2 of a single-input channel at the frequencies ``w``.

    Parameters
    ----------
    A, B, C, D : ndarray of float
        The channel, shapes (n, n), (n, 1), (q, n), (q, 1).
    w : ndarray of float, shape (m,)
        Frequencies (rad/s; +inf: D).

    Returns
    -------
    ndarray of float, shape (m,)
        The gains.

    Raises
    ------
    numpy.linalg.LinAlgError
        Where j w is an eigenvalue of A.
    """
    sig, _, ok = _kernel(A, B, C, D, w, np.zeros((0, A.shape[0], A.shape[0])), _EMPTY3,
                         _EMPTY3, _EMPTY3, False)
    if not ok:
        raise np.linalg.LinAlgError("singular j w I - A: a frequency is a pole of the channel")
    return sig


def siso_sigma_grad(A: NDArray[np.float64], B: NDArray[np.float64], C: NDArray[np.float64],
                    D: NDArray[np.float64], w: NDArray[np.float64], dA: NDArray[np.float64],
                    dB: NDArray[np.float64], dC: NDArray[np.float64], dD: NDArray[np.float64],
                    ) -> tuple[NDArray[np.float64], NDArray[np.float64]]:
    """:func:`siso_sigma` and its gradient with respect to p parameters.

    Parameters
    ----------
    A, B, C, D : ndarray of float
        The channel, shapes (n, n), (n, 1), (q, n), (q, 1).
    w : ndarray of float, shape (m,)
        Frequencies (rad/s).
    dA, dB, dC, dD : ndarray of float
        Derivatives stacked over the p parameters: (p, n, n), (p, n, 1), (p, q, n), (p, q, 1).

    Returns
    -------
    sigma : ndarray of float, shape (m,)
        The gains.
    grad : ndarray of float, shape (m, p)
        Their derivatives.

    Raises
    ------
    numpy.linalg.LinAlgError
        Where j w is an eigenvalue of A.
    """
    sig, g, ok = _kernel(A, B, C, D, w, dA, dB, dC, dD, True)
    if not ok:
        raise np.linalg.LinAlgError("singular j w I - A: a frequency is a pole of the channel")
    return sig, g

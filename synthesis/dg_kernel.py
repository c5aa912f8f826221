"""Compiled objective of the D-G mu upper bound (:mod:`vtolftc.synthesis.dg_scaling`).

One call evaluates, for the scalings x of the parametrisation ``_DG``, the largest eigenvalue
lambda_max of N^H N + j(Ghat N - N^H Ghat) (N = T M T^-1, the module docstring of
:mod:`.dg_scaling`), its log-sum-exp smoothing and the gradient of the smoothed value. It is
the same arithmetic as the numpy reference (``_DGObjective._eig`` and ``_DG.gradient``, kept
and tested against it), compiled: the D-G optimisation of a 4 x 4 M calls it a few hundred
times per frequency, and the numpy version spends most of its time in per-call overhead of
small-matrix operations. Every value is still an exact evaluation of the LMI at the given
(D, G): the bound stays a certificate whichever implementation computes it.
"""

from __future__ import annotations

import math

import numba
import numpy as np
from numpy.typing import NDArray

__all__ = ["dg_objective"]


@numba.njit(cache=True)
def dg_objective(M: NDArray[np.complex128], x: NDArray[np.float64], tpos: NDArray[np.intp],
                 tpar: NDArray[np.intp], tcoef: NDArray[np.float64], off_r: NDArray[np.intp],
                 off_c: NDArray[np.intp], off_re: NDArray[np.intp], off_im: NDArray[np.intp],
                 gd_pos: NDArray[np.intp], gd_par: NDArray[np.intp], gu_r: NDArray[np.intp],
                 gu_c: NDArray[np.intp], gu_re: NDArray[np.intp], gu_im: NDArray[np.intp],
                 smooth: float, want_grad: bool) -> tuple[float, float, NDArray[np.float64]]:
    """The D-G objective lambda_max(M^H D M + j(G M - M^H G), D), smoothed, and its gradient.

    Parameters
    ----------
    M : ndarray of complex, shape (n, n)
        The (padded, square) matrix.
    x : ndarray of float, shape (n_params,)
        The scaling parameters.
    tpos, tpar, tcoef, off_r, off_c, off_re, off_im : ndarray
        The index arrays of ``dg_scaling._DG`` for T (where each parameter enters it).
    gd_pos, gd_par, gu_r, gu_c, gu_re, gu_im : ndarray
        The index arrays of ``dg_scaling._DG`` for Ghat.
    smooth : float
        Relative log-sum-exp width (0: f = lambda_max).
    want_grad : bool
        Compute the gradient; without it the gradient is all zeros and f = lambda_max.

    Returns
    -------
    lam : float
        lambda_max.
    f : float
        The smoothed value.
    grad : ndarray of float, shape (n_params,)
        df/dx.

    Raises
    ------
    numpy.linalg.LinAlgError
        Where the eigenproblem fails (non-finite entries).
    """
    n = M.shape[0]
    tdiag = np.exp(tcoef * x[tpar])
    has_off = off_r.size > 0
    has_g = gd_pos.size > 0
    Ti = np.zeros((1, 1), dtype=np.complex128)
    if has_off:
        T = np.zeros((n, n), dtype=np.complex128)
        for i in range(tpos.size):
            T[tpos[i], tpos[i]] = tdiag[i]
        for i in range(off_r.size):
            T[off_r[i], off_c[i]] = x[off_re[i]] - 1j * x[off_im[i]]
        Ti = np.linalg.inv(T)
        N = T @ M @ Ti
    else:
        N = np.empty((n, n), dtype=np.complex128)
        for i in range(n):
            for j in range(n):
                N[i, j] = (tdiag[i] * M[i, j]) / tdiag[j]
    NH = np.ascontiguousarray(np.conj(N).T)
    H = NH @ N
    Gh = np.zeros((n, n), dtype=np.complex128)
    if has_g:
        for i in range(gd_pos.size):
            Gh[gd_pos[i], gd_pos[i]] = x[gd_par[i]]
        for i in range(gu_r.size):
            z = x[gu_re[i]] + 1j * x[gu_im[i]]
            Gh[gu_r[i], gu_c[i]] = z
            Gh[gu_c[i], gu_r[i]] = np.conj(z)
        GN = Gh @ N
        H = H + 1j * (GN - np.ascontiguousarray(np.conj(GN).T))
    lam, U = np.linalg.eigh(H)
    l1 = lam[-1]
    g = np.zeros(x.size)
    if not want_grad:
        return l1, l1, g
    if smooth > 0.0:
        s = smooth * max(abs(l1), 1e-300)
        e = np.exp((lam - l1) / s)
        tot = e.sum()
        f = l1 + s * math.log(tot)
        wts = e / tot
    else:
        f = l1
        wts = np.zeros(lam.size)
        wts[-1] = 1.0
    keep = np.nonzero(wts > 1e-12)[0]
    k = keep.size
    Uk = np.empty((n, k), dtype=np.complex128)
    w = np.empty(k)
    for e_ in range(k):
        w[e_] = wts[keep[e_]]
        for i in range(n):
            Uk[i, e_] = U[i, keep[e_]]
    Y = N @ Uk
    R = Y - 1j * (Gh @ Uk) if has_g else Y
    Rw = np.empty((k, n), dtype=np.complex128)       # w_e r_e^H
    for e_ in range(k):
        for i in range(n):
            Rw[e_, i] = np.conj(R[i, e_] * w[e_])
    X = Y @ Rw - Uk @ (Rw @ N)
    zdiag = np.empty(tpos.size)
    if has_off:
        Z = np.ascontiguousarray(Ti) @ X
        for i in range(tpos.size):
            zdiag[i] = Z[tpos[i], tpos[i]].real
        for i in range(off_r.size):
            zo = Z[off_c[i], off_r[i]]
            g[off_re[i]] = 2.0 * zo.real
            g[off_im[i]] = 2.0 * zo.imag
    else:
        for i in range(tpos.size):
            zdiag[i] = X[tpos[i], tpos[i]].real / tdiag[i]
    for i in range(tpar.size):
        g[tpar[i]] += 2.0 * tcoef[i] * tdiag[i] * zdiag[i]
    if has_g:
        Cw = np.empty((n, k), dtype=np.complex128)
        for i in range(n):
            for e_ in range(k):
                Cw[i, e_] = np.conj(Uk[i, e_]) * w[e_]
        C = Cw @ np.ascontiguousarray(Y.T)       # C_ij = sum_e w_e conj(u_ie) y_je
        for i in range(gd_pos.size):
            g[gd_par[i]] = -2.0 * C[gd_pos[i], gd_pos[i]].imag
        for i in range(gu_r.size):
            c1 = C[gu_r[i], gu_c[i]]
            c2 = C[gu_c[i], gu_r[i]]
            g[gu_re[i]] = -2.0 * (c1 + c2).imag
            g[gu_im[i]] = -2.0 * (c1 - c2).real
    return l1, f, g

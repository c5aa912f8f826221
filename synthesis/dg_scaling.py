"""Mixed real/complex mu upper bound by D-G scaling (Young, Newlin & Doyle; MATLAB's mussv)
on a :class:`~vtolftc.synthesis.mu_blocks.BlockStructure` (possibly non-square M; the type
is re-exported here). The analysis functions built on it are in :mod:`.mixed_mu`; see there
for the theory and the validation.
"""

from __future__ import annotations

import functools
import math
from collections.abc import Sequence
from dataclasses import dataclass, field
from typing import Any

import numpy as np
from numpy.typing import NDArray

from vtolftc.synthesis.dg_bfgs import dg_minimise
from vtolftc.synthesis.dg_kernel import dg_objective
from vtolftc.synthesis.mu_blocks import Block, BlockStructure

__all__ = [
    "BlockStructure",
    "MixedMuUpper",
    "certified_value",
    "mixed_mu_upper",
    "mixed_mu_upper_start",
]


# ------------------------------------------------------------------------------------------
# D-G upper bound
# ------------------------------------------------------------------------------------------


class _DG:
    """Parametrisation of the scalings for a square-block structure.

    D = T^H T with T block diagonal: T_k = sqrt(d_k) I (full blocks, x = log d_k) or
    T_k = L_k^H (repeated blocks, L_k lower triangular, diagonal exp(x), strictly lower
    entries x_re + j x_im). G enters as G = T^H Ghat T with Ghat_k Hermitian on the real
    blocks (a bijection), so that with N = T M T^-1

        lambda(M^H D M + j(G M - M^H G), D) = lambda(N^H N + j(Ghat N - N^H Ghat)),

    a standard Hermitian eigenproblem.
    """

    def __init__(self, st: BlockStructure):
        self.st = st
        n = st.m_shape[0]
        self.n = n
        self.rep: list[tuple[int, NDArray[np.intp], int, int]] = []  # (x0, idx, m, nl)
        self.real: list[tuple[int, NDArray[np.intp], int]] = []  # (x0, idx, m)
        tpos: list[int] = []
        tpar: list[int] = []
        tcoef: list[float] = []
        off_r: list[int] = []
        off_c: list[int] = []
        off_re: list[int] = []
        off_im: list[int] = []
        p = 0
        r0 = 0
        self.block_x0: list[int] = []
        for b in st.blocks:
            idx = np.arange(r0, r0 + b.rows)
            self.block_x0.append(p)
            if b.kind == "full":  # T_k = exp(x / 2) I
                tpos.extend(idx)
                tpar.extend([p] * idx.size)
                tcoef.extend([0.5] * idx.size)
                p += 1
            else:  # T_k = L_k^H
                m = b.rows
                nl = m * (m - 1) // 2
                self.rep.append((p, idx, m, nl))
                tpos.extend(idx)
                tpar.extend(range(p, p + m))
                tcoef.extend([1.0] * m)
                il, jl = np.tril_indices(m, -1)
                off_r.extend(idx[jl])  # T[j, i] = conj(L[i, j])
                off_c.extend(idx[il])
                off_re.extend(range(p + m, p + m + nl))
                off_im.extend(range(p + m + nl, p + m + 2 * nl))
                p += m + 2 * nl
            r0 += b.rows
        self.nd = p
        gd_pos: list[int] = []
        gd_par: list[int] = []
        gu_r: list[int] = []
        gu_c: list[int] = []
        gu_re: list[int] = []
        gu_im: list[int] = []
        for k, b in enumerate(st.blocks):
            if b.kind == "real":
                idx = self._block_idx(k)
                m = b.rows
                self.real.append((p, idx, m))
                gd_pos.extend(idx)
                gd_par.extend(range(p, p + m))
                iu, ju = np.triu_indices(m, 1)
                nu = iu.size
                gu_r.extend(idx[iu])
                gu_c.extend(idx[ju])
                gu_re.extend(range(p + m, p + m + nu))
                gu_im.extend(range(p + m + nu, p + m + 2 * nu))
                p += m * m  # m diag + m(m-1)/2 re + m(m-1)/2 im
        self.n_params = p

        def arr(v: list[Any], dt: Any = np.intp) -> NDArray[Any]:
            return np.array(v, dtype=dt)

        self.tpos, self.tpar, self.tcoef = arr(tpos), arr(tpar), arr(tcoef, float)
        self.off_r, self.off_c, self.off_re, self.off_im = (
            arr(off_r), arr(off_c), arr(off_re), arr(off_im))
        self.gd_pos, self.gd_par = arr(gd_pos), arr(gd_par)
        self.gu_r, self.gu_c, self.gu_re, self.gu_im = arr(gu_r), arr(gu_c), arr(gu_re), arr(gu_im)
        self.has_off = self.off_r.size > 0
        self.has_g = self.gd_pos.size > 0
        # block index pairs of the Osborne start (np.ix_ of every pair of blocks)
        idxs = [self._block_idx(k) for k in range(len(st.blocks))]
        self.pair_ix = [[np.ix_(a, b) for b in idxs] for a in idxs]
        # the index arrays in the order of the compiled objective's arguments
        self.kernel_args = tuple(np.ascontiguousarray(a) for a in (
            self.tpos, self.tpar, self.tcoef, self.off_r, self.off_c, self.off_re, self.off_im,
            self.gd_pos, self.gd_par, self.gu_r, self.gu_c, self.gu_re, self.gu_im))

    def _block_idx(self, k: int) -> NDArray[np.intp]:
        r0 = sum(b.rows for b in self.st.blocks[:k])
        return np.arange(r0, r0 + self.st.blocks[k].rows)

    def t_matrix(self, x: NDArray[np.float64]) -> tuple[NDArray[Any], NDArray[Any]]:
        """T (block upper-triangular within repeated blocks) and its diagonal."""
        n = self.n
        tdiag = np.exp(self.tcoef * x[self.tpar])
        if not self.has_off:
            return np.diag(tdiag), tdiag
        T = np.zeros((n, n), dtype=complex)
        T[self.tpos, self.tpos] = tdiag
        T[self.off_r, self.off_c] = x[self.off_re] - 1j * x[self.off_im]
        return T, tdiag

    def g_matrix(self, x: NDArray[np.float64]) -> NDArray[np.complex128] | None:
        if not self.has_g:
            return None
        Gh = np.zeros((self.n, self.n), dtype=complex)
        Gh[self.gd_pos, self.gd_pos] = x[self.gd_par]
        z = x[self.gu_re] + 1j * x[self.gu_im]
        Gh[self.gu_r, self.gu_c] = z
        Gh[self.gu_c, self.gu_r] = np.conj(z)
        return Gh

    def matrices(self, x: NDArray[np.float64]) -> tuple[NDArray[Any], NDArray[Any]]:
        """(D, G) of the LMI certificate M^H D M + j(G M - M^H G) <= beta^2 D."""
        T, _ = self.t_matrix(x)
        T = T.astype(complex)
        Gh = self.g_matrix(x)
        D = T.conj().T @ T
        G = np.zeros_like(D) if Gh is None else T.conj().T @ Gh @ T
        return D, G

    def gradient(self, N: NDArray[Any], Ti: NDArray[Any] | None, tdiag: NDArray[Any],
                 Gh: NDArray[Any] | None, U: NDArray[Any], w: NDArray[Any],
                 x: NDArray[np.float64]) -> NDArray[np.float64]:
        """sum_e w_e d lambda_e / dx, U the eigenvectors (columns) of N^H N + j(Gh N - N^H Gh).

        With Y = N U, R = Y - j Gh U: d lambda = 2 Re tr(dT Z), Z = T^-1 X, X = Y R^H - U R^H N
        (weighted by w), and d lambda / d Gh = -2 Im(u^H dGh y).
        """
        g = np.zeros_like(x)
        Y = N @ U
        R = Y if Gh is None else Y - 1j * (Gh @ U)
        Rw = (R * w).conj().T  # (neig x n): w_e r_e^H
        X = Y @ Rw - U @ (Rw @ N)
        if Ti is None:  # diagonal T
            zdiag = np.real(np.diag(X)) / tdiag
        else:
            Z = Ti @ X
            zdiag = np.real(Z[self.tpos, self.tpos])
            zo = Z[self.off_c, self.off_r]
            g[self.off_re] = 2.0 * zo.real
            g[self.off_im] = 2.0 * zo.imag
        g += np.bincount(self.tpar, weights=2.0 * self.tcoef * tdiag * zdiag, minlength=x.size)
        if Gh is not None:
            C = (np.conj(U) * w) @ Y.T  # C_ij = sum_e w_e conj(u_ie) y_je
            g[self.gd_par] = -2.0 * np.imag(C[self.gd_pos, self.gd_pos])
            if self.gu_r.size:
                c1, c2 = C[self.gu_r, self.gu_c], C[self.gu_c, self.gu_r]
                g[self.gu_re] = -2.0 * np.imag(c1 + c2)
                g[self.gu_im] = -2.0 * np.real(c1 - c2)
        return g


class _DGObjective:
    """lambda_max and its smoothed value with gradient, for the optimiser.

    ``compiled`` (default): :func:`vtolftc.synthesis.dg_kernel.dg_objective`; False: the numpy
    reference (:meth:`_eig`, :meth:`_DG.gradient`), the same arithmetic.
    """

    def __init__(self, M: NDArray[Any], par: _DG, compiled: bool = True):
        self.M = np.ascontiguousarray(M, dtype=complex)
        self.par = par
        self.compiled = compiled
        self.smooth = 0.0
        self.best = math.inf
        self.best_x: NDArray[np.float64] | None = None
        self.nfev = 0

    def _eig(self, x: NDArray[np.float64]) -> tuple[Any, ...]:
        par = self.par
        T, tdiag = par.t_matrix(x)
        if par.has_off:
            Ti = np.linalg.inv(T)
            N = T @ self.M @ Ti
        else:
            Ti = None
            N = (tdiag[:, None] * self.M) / tdiag[None, :]
        H = N.conj().T @ N
        Gh = par.g_matrix(x)
        if Gh is not None:
            GN = Gh @ N
            H = H + 1j * (GN - GN.conj().T)
        lam, U = np.linalg.eigh(H)
        return lam, U, N, Ti, tdiag, Gh

    def _kernel(self, x: NDArray[np.float64], grad: bool) -> tuple[float, float, Any]:
        return dg_objective(self.M, np.ascontiguousarray(x, dtype=float),
                            *self.par.kernel_args, float(self.smooth), grad)

    def value(self, x: NDArray[np.float64]) -> float:
        try:
            lam = self._kernel(x, False)[0] if self.compiled else self._eig(x)[0][-1]
            lmax = float(lam)
        except (np.linalg.LinAlgError, ValueError, ZeroDivisionError):
            return math.inf
        self._record(lmax, x)
        return lmax

    def _record(self, val: float, x: NDArray[np.float64]) -> None:
        if val < self.best and math.isfinite(val):
            self.best = val
            self.best_x = np.array(x, dtype=float)

    def __call__(self, x: NDArray[np.float64]) -> tuple[float, NDArray[np.float64]]:
        self.nfev += 1
        if not np.all(np.isfinite(x)) or np.max(np.abs(x)) > 300:
            return 1e300, np.zeros_like(x)
        if self.compiled:
            try:
                l1, f, g = self._kernel(x, True)
            except (np.linalg.LinAlgError, ValueError, ZeroDivisionError):
                return 1e300, np.zeros_like(x)
            self._record(float(l1), x)
            return float(f), g
        try:
            lam, U, N, Ti, tdiag, Gh = self._eig(x)
        except (np.linalg.LinAlgError, ValueError):
            return 1e300, np.zeros_like(x)
        l1 = float(lam[-1])
        self._record(l1, x)
        if self.smooth > 0.0:
            s = self.smooth * max(abs(l1), 1e-300)
            e = np.exp((lam - l1) / s)
            tot = float(e.sum())
            f = l1 + s * math.log(tot)
            wts = e / tot
        else:
            f = l1
            wts = np.zeros_like(lam)
            wts[-1] = 1.0
        keep = wts > 1e-12
        g = self.par.gradient(N, Ti, tdiag, Gh, U[:, keep], wts[keep], x)
        return f, g


@dataclass(frozen=True)
class MixedMuUpper:
    """A certified mixed-mu upper bound: mu(M) <= value.

    Parameters
    ----------
    value : float
        The bound beta (>= 0; 0 means mu = 0 is certified).
    D, G : ndarray of complex, shape (N, N)
        The scalings of the certificate, for the square (padded) M: D > 0 commutes with Delta,
        G Hermitian on the real blocks, M^H D M + j(G M - M^H G) <= value^2 D.
    method : {"dg", "ab13md"}
        ``"ab13md"`` or ``"dg"`` (the D-G optimisation of this module).
    params : ndarray of float, optional
        Internal parametrisation of (D, G) for ``warm_start`` (``"dg"`` only), or AB13MD's
        ``x`` vector.
    """

    value: float
    D: NDArray[np.complex128] = field(repr=False)
    G: NDArray[np.complex128] = field(repr=False)
    method: str = "dg"
    params: NDArray[np.float64] | None = field(default=None, repr=False)

    def __float__(self) -> float:
        return float(self.value)


def _osborne_x(M: NDArray[Any], par: _DG, sweeps: int = 20) -> NDArray[np.float64]:
    """Block-Osborne balancing start (log d_k for every block, G = 0)."""
    st = par.st
    K = len(st.blocks)
    A2 = np.abs(M) ** 2
    Bn = np.array([[A2[ix].sum() for ix in row] for row in par.pair_ix])
    np.fill_diagonal(Bn, 0.0)
    d2 = np.ones(K)
    for _ in range(sweeps):
        changed = 0.0
        for k in range(K):
            num = float(np.dot(Bn[:, k], d2))
            den = float(np.dot(Bn[k, :], 1.0 / d2))
            if num > 0.0 and den > 0.0:
                new = math.sqrt(num / den)
                changed = max(changed, abs(math.log(new / d2[k])))
                d2[k] = new
        if changed < 1e-3:
            break
    logd = np.log(d2)  # D_k ~ d_k^2 I in the "D" (not square-root) convention of the LMI
    logd -= logd.mean()
    x = np.zeros(par.n_params)
    for k, b in enumerate(st.blocks):
        x0 = par.block_x0[k]
        if b.kind == "full":
            x[x0] = logd[k]  # T_k = exp(x/2) = d_k
        else:
            x[x0 : x0 + b.rows] = 0.5 * logd[k]  # T_k = L_k^H, L_k = diag(exp(x))
    return x


@functools.lru_cache(maxsize=64)
def _dg_parametrisation(blocks: tuple[Block, ...]) -> _DG:
    """The (read-only) parametrisation of a square-block structure, built once per
    structure: a frequency sweep calls the bound thousands of times with the same blocks."""
    return _DG(BlockStructure(blocks))


_WARM_STAGES = (1e-4, 0.0)
_COLD_STAGES = (3e-2, 3e-3, 3e-4, 3e-5, 0.0)


def dg_upper_bound(
    M: NDArray[Any], st: BlockStructure, x0: NDArray[np.float64] | None, target: float,
    rtol: float, maxiter: int,
) -> MixedMuUpper:
    """The D-G optimiser's upper bound of mixed mu of a square-block problem.

    Parameters
    ----------
    M : ndarray of complex, shape (N, N)
        Square matrix of a square-block structure.
    st : BlockStructure
        Its structure (square blocks).
    x0 : ndarray of float or None
        Start parameters (a previous ``MixedMuUpper.params``), or None for the identity and
        Osborne starts.
    target : float
        Stop once a bound <= target (1 + rtol) is proven.
    rtol : float
        Relative tolerance on beta.
    maxiter : int
        BFGS iterations per continuation stage.

    Returns
    -------
    MixedMuUpper
        The bound that the returned (D, G) prove (:func:`certified_value`).
    """
    par = _dg_parametrisation(st.blocks)
    obj = _DGObjective(M, par)
    starts = [np.zeros(par.n_params), _osborne_x(M, par)]
    if x0 is not None:
        if x0.shape != (par.n_params,):
            raise ValueError(
                f"warm start has {x0.size} parameters, expected {par.n_params} for this "
                "block structure"
            )
        starts.append(np.asarray(x0, dtype=float))
    vals = [obj.value(s) for s in starts]
    k0 = int(np.argmin(vals))
    x = starts[k0].copy()
    stop2 = (target * (1.0 + rtol)) ** 2 if target > 0 else -math.inf
    # beta^2 = lambda: a relative rtol on beta is ~2 rtol on lambda
    warm = x0 is not None and k0 == len(starts) - 1

    if obj.best > stop2 and obj.best >= 0.0:
        stages = np.array(_WARM_STAGES if warm else _COLD_STAGES)
        bx = obj.best_x if obj.best_x is not None else x
        best, best_x, nfev = dg_minimise(obj.M, np.ascontiguousarray(x, dtype=float),
                                         par.kernel_args, stages, int(maxiter), float(stop2),
                                         float(rtol), float(obj.best),
                                         np.ascontiguousarray(bx, dtype=float))
        obj.nfev += nfev
        if best < obj.best:
            obj.best, obj.best_x = float(best), best_x
    assert obj.best_x is not None
    D, G = par.matrices(obj.best_x)
    cert = certified_value(M, D, G)
    if not math.isfinite(cert):  # the scalings cannot be checked: fall back to D = I, G = 0
        D, G = np.eye(M.shape[0], dtype=complex), np.zeros_like(D)
        cert = float(np.linalg.norm(M, 2))
    # the value the returned (D, G) prove, recomputed outside the optimiser's kernel
    return MixedMuUpper(max(math.sqrt(max(obj.best, 0.0)), cert), D, G, "dg", obj.best_x)


def ab13md_upper_bound(
    M: NDArray[Any], spec: tuple[NDArray[Any], NDArray[Any]], x: NDArray[np.float64] | None
) -> MixedMuUpper | None:
    """SLICOT AB13MD's mixed-mu upper bound, checked.

    Parameters
    ----------
    M : ndarray of complex, shape (N, N)
        Square matrix.
    spec : (ndarray, ndarray)
        AB13MD's block sizes and types (``BlockStructure.ab13md_spec()``).
    x : ndarray of float or None
        AB13MD's warm-start vector, or None for a cold start.

    Returns
    -------
    MixedMuUpper or None
        The bound with its (D, G); None when AB13MD fails or its (D, G) do not prove its value.
    """
    from slycot import ab13md

    try:
        if x is not None:
            mu, d, g, xo = ab13md(M, spec[0], spec[1], x)
        else:
            mu, d, g, xo = ab13md(M, spec[0], spec[1])
    except Exception:
        return None
    if not math.isfinite(float(mu)):
        return None
    d = np.asarray(d, float)
    g = np.asarray(g, float)
    if not (np.all(np.isfinite(d)) and np.all(d > 0) and np.all(np.isfinite(g))):
        return None
    D, G = np.diag(d**2).astype(complex), np.diag(g).astype(complex)
    cert = certified_value(M, D, G)
    # AB13MD's value is kept where its scalings prove it (to rounding); where they do not
    # (e.g. a value of 0 for M = 6.78j with one real scalar, returned with D = 1, G = 0) the
    # caller falls back to the D-G optimiser
    if not cert <= float(mu) * (1.0 + _CERT_RTOL) + _CERT_ATOL * float(np.linalg.norm(M, 2)):
        return None
    return MixedMuUpper(max(float(mu), cert), D, G, "ab13md", np.asarray(xo, float))


_CERT_RTOL = 1e-6
_CERT_ATOL = 1e-9


def certified_value(M: Any, D: Any, G: Any | None = None) -> float:
    """The mu upper bound that the scalings (D, G) prove for the square M.

    beta = sqrt(max(lambda_max(M^H D M + j(G M - M^H G), D), 0)), the largest generalised
    eigenvalue with D > 0: then M^H D M + j(G M - M^H G) <= beta^2 D, which implies
    mu(M) <= beta when D commutes with the structure and G is Hermitian on its real blocks
    (module :mod:`.mixed_mu`).

    Parameters
    ----------
    M : array_like, shape (N, N)
        Square complex matrix (the padded M for non-square structures).
    D : array_like, shape (N, N)
        Hermitian positive definite scaling.
    G : array_like, shape (N, N), optional
        Hermitian scaling of the real blocks (None or 0 for a pure D scaling).

    Returns
    -------
    float
        beta; ``inf`` when D is not numerically positive definite.

    Examples
    --------
    >>> import numpy as np
    >>> round(certified_value(np.array([[3.0]]), np.eye(1)), 12)
    3.0
    """
    from scipy.linalg import eigh

    M = np.asarray(M, dtype=complex)
    D = np.asarray(D, dtype=complex)
    H = M.conj().T @ D @ M
    if G is not None:
        GM = np.asarray(G, dtype=complex) @ M
        H = H + 1j * (GM - GM.conj().T)
    try:
        lam = eigh(0.5 * (H + H.conj().T), 0.5 * (D + D.conj().T), eigvals_only=True)
    except (np.linalg.LinAlgError, ValueError):
        return math.inf
    top = float(lam[-1])
    return math.sqrt(max(top, 0.0)) if math.isfinite(top) else math.inf


_UPPER_METHODS = ("auto", "ab13md", "dg")


def mixed_mu_upper_start(M: Any, blocks: Sequence[Block] | BlockStructure) -> float:
    """The D-G bound at the optimiser's starting scalings, without optimising.

    The smaller of sigma_max(M) (D = I, G = 0) and the block-Osborne balanced D (G = 0). A
    valid upper bound of mu(M) (each is a certificate), cheap, and the value of
    ``mixed_mu_upper(M, blocks, method="dg", maxiter=0, target=inf)`` to rounding (that one
    also re-checks its scalings outside the compiled kernel and returns the larger of the two
    evaluations, which may differ in the last bits): a sweep uses it to order frequencies and
    to skip those already below a known lower bound.

    Parameters
    ----------
    M : array_like, shape ``BlockStructure(blocks).m_shape``
        Complex matrix.
    blocks : sequence of Block or BlockStructure
        The uncertainty structure.

    Returns
    -------
    float
        The upper bound.
    """
    st = BlockStructure(blocks)
    Mp, sq = st.pad(st.check(M))
    par = _dg_parametrisation(sq.blocks)
    obj = _DGObjective(Mp, par)
    for x in (np.zeros(par.n_params), _osborne_x(Mp, par)):
        obj.value(x)
    return math.sqrt(max(obj.best, 0.0))


def mixed_mu_upper(
    M: Any,
    blocks: Sequence[Block] | BlockStructure,
    *,
    method: str = "auto",
    warm_start: MixedMuUpper | None = None,
    rtol: float = 1e-9,
    maxiter: int = 200,
    target: float = 0.0,
) -> MixedMuUpper:
    """Mixed real/complex mu upper bound with D-G scaling (see :mod:`.mixed_mu`).

    Parameters
    ----------
    M : array_like, shape ``BlockStructure(blocks).m_shape``
        Complex matrix (non-square allowed).
    blocks : sequence of Block or BlockStructure
        The uncertainty structure.
    method : {"auto", "ab13md", "dg"}
        ``"auto"`` (AB13MD where it applies, else ``"dg"``), ``"ab13md"`` (error if the
        structure has repeated or non-square blocks) or ``"dg"`` (D-G optimisation: compiled BFGS,
        :mod:`vtolftc.synthesis.dg_bfgs`, on the objective of :mod:`.dg_kernel`).
    warm_start : MixedMuUpper, optional
        A previous result for the same structure (a neighbouring frequency): its scalings
        start the optimiser.
    rtol : float
        Optimiser tolerance (relative, on beta).
    maxiter : int
        BFGS iterations per continuation stage.
    target : float
        Stop as soon as the bound is <= target (1 + rtol), e.g. a known lower bound.

    Returns
    -------
    MixedMuUpper
        ``value`` >= mu(M), with the (D, G) certificate. Every certificate is checked before
        it is returned (:func:`certified_value`): ``value`` is at least what (D, G) prove,
        and AB13MD's result is replaced by the D-G optimiser's where its scalings do not
        prove AB13MD's value.

    Raises
    ------
    ValueError
        If M does not fit the structure, ``method`` is unknown, or ``"ab13md"`` is asked for a
        structure outside its scope.

    Examples
    --------
    >>> import numpy as np
    >>> r = mixed_mu_upper(np.diag([1.0, 2j]), [Block.real(2)], method="dg")
    >>> round(r.value, 4), round(certified_value(np.diag([1.0, 2j]), r.D, r.G), 4)
    (1.0, 1.0)
    """
    st = BlockStructure(blocks)
    Mc = st.check(M)
    if method not in _UPPER_METHODS:
        raise ValueError(f"unknown method {method!r}; expected one of {_UPPER_METHODS}")
    spec = st.ab13md_spec()
    if method == "ab13md" and spec is None:
        raise ValueError(
            "AB13MD only takes square full complex blocks and 1x1 real blocks; use "
            "method='dg' for repeated scalars or non-square blocks"
        )
    if method != "dg" and spec is not None:
        # never warm-started: a chain of AB13MD warm starts (its x output fed back in) along a
        # frequency sweep was seen to degenerate and then hang inside the Fortran routine;
        # a cold call costs ~1 ms
        res = ab13md_upper_bound(Mc, spec, None)
        if res is not None:
            return res
    Mp, sq = st.pad(Mc)
    x0 = warm_start.params if warm_start is not None and warm_start.method == "dg" else None
    return dg_upper_bound(Mp, sq, x0, target, rtol, maxiter)


# ------------------------------------------------------------------------------------------
# lower bound, both bounds, sweep
# ------------------------------------------------------------------------------------------

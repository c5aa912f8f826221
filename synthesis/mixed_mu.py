"""Mixed real/complex structured singular value: D-G upper bound, lower bound, sweep.

For M (rows x cols) and a structure Delta = diag(Delta_1, ..., Delta_K) of

* full complex blocks ``Block.full(r, c)`` (an r x c complex matrix, r != c allowed),
* repeated complex scalars ``Block.repeated_complex(n)`` (delta I_n, delta complex),
* repeated real scalars ``Block.real(n)`` (delta I_n, delta real; n = 1 a plain real
  parameter, n > 1 a parameter entering n times, e.g. an airspeed),

the structured singular value is mu(M) = 1 / min{sigma_max(Delta) : det(I - M Delta) = 0}.
Delta_k is r_k x c_k, so M is (sum c_k) x (sum r_k): M's rows are partitioned by the blocks'
``cols``, its columns by their ``rows`` (MATLAB ``mussv`` convention). :class:`BlockStructure`
states this and checks the shape of M.

Upper bound (Fan, Tits & Doyle 1991; Young, Newlin & Doyle 1995, the LMI form): for every
scaling D > 0 commuting with Delta and every Hermitian G that is non-zero only on the real
blocks (and commutes with them),

    M^H D M + j (G M - M^H G) <= beta^2 D   implies   mu(M) <= beta.

:func:`mixed_mu_upper` minimises beta^2 = lambda_max(M^H D M + j(G M - M^H G), D), the largest
generalised eigenvalue (a quasi-convex function of (D, G)), by BFGS on a log-sum-exp smoothed
lambda_max with continuation, in a parametrisation D_k = d_k I (full blocks), D_k = L_k L_k^H
(repeated blocks, L_k lower triangular with positive diagonal), G_k Hermitian (real blocks).
*Every* evaluated (D, G) is a certificate, the smallest is returned, so the value is a valid
bound whatever the optimiser does. With G = 0 it is the complex D-scaling bound; the G term
is what makes real blocks cheaper than complex ones (diag(1, 2j) with a repeated real scalar:
complex bound 2, D-G bound 1 = mu). Non-square full blocks are handled by zero padding (M
padded with zero rows/columns so every block is square: mu and both bounds are unchanged).

Where SLICOT ``AB13MD`` applies (every block a square full complex block or a single real
scalar, as in the robust-performance checks) ``method="auto"`` uses it: same bound (it solves
the same problem), compiled, 5-20x faster. Repeated scalars (real or complex) use the numpy
implementation, which also serves as the independent check of AB13MD in the tests.

Lower bound (:func:`mixed_mu_lower`): any structured Delta with det(I - M Delta) = 0 proves
mu >= 1/sigma_max(Delta). Candidates come from the Packard-Fan-Doyle power iteration with the
real blocks restricted to +-1 (the real-eigenvalue form mu = max_Q rho_R(M Q) of Young & Doyle),
from the vertices of the real parameters and a 1-D search along the real directions with the
complex blocks solved exactly (see :mod:`vtolftc.synthesis.mu`); each candidate is verified
(sigma_min(I - M Delta) ~ 0) before it is accepted. Real mu is discontinuous and NP-hard: the
lower bound can be conservative, the upper bound never is.
"""

from __future__ import annotations

import math
from collections.abc import Sequence
from dataclasses import dataclass, field
from typing import Any

import numpy as np
from numpy.typing import NDArray
from scipy.optimize import minimize

from vtolftc.synthesis.mu import Block, MuSweep

__all__ = [
    "BlockStructure",
    "MixedMuBounds",
    "MixedMuUpper",
    "mixed_mu_bounds",
    "mixed_mu_lower",
    "mixed_mu_sweep",
    "mixed_mu_upper",
]


# ------------------------------------------------------------------------------------------
# block structure
# ------------------------------------------------------------------------------------------


@dataclass(frozen=True)
class BlockStructure:
    """A block-diagonal uncertainty structure and the shape of the M it applies to.

    Parameters
    ----------
    blocks:
        The blocks (:class:`vtolftc.synthesis.mu.Block`) in order. ``Block.full(r, c)`` is an
        r x c complex block; ``Block.real(n)`` / ``Block.repeated_complex(n)`` are delta I_n.

    Attributes
    ----------
    m_shape:
        (rows, cols) of M = (sum of block cols, sum of block rows).
    delta_shape:
        (rows, cols) of Delta = (sum of block rows, sum of block cols).
    """

    blocks: tuple[Block, ...]

    def __init__(self, blocks: Sequence[Block] | Block | BlockStructure):
        if isinstance(blocks, BlockStructure):
            blocks = blocks.blocks
        if isinstance(blocks, Block):
            blocks = [blocks]
        blocks = tuple(blocks)
        if not blocks:
            raise ValueError("the block structure is empty; expected a list of Block objects")
        for b in blocks:
            if not isinstance(b, Block):
                raise ValueError(
                    f"unknown block specification {b!r}; expected Block.full(rows, cols), "
                    "Block.repeated_complex(n) or Block.real(n)"
                )
        object.__setattr__(self, "blocks", blocks)

    @property
    def m_shape(self) -> tuple[int, int]:
        return sum(b.cols for b in self.blocks), sum(b.rows for b in self.blocks)

    @property
    def delta_shape(self) -> tuple[int, int]:
        return sum(b.rows for b in self.blocks), sum(b.cols for b in self.blocks)

    @property
    def has_real(self) -> bool:
        return any(b.kind == "real" for b in self.blocks)

    def ab13md_spec(self) -> tuple[NDArray[np.int64], NDArray[np.int64]] | None:
        """(nblock, itype) for SLICOT AB13MD, or None if the structure is outside its scope.

        AB13MD takes square full complex blocks and 1 x 1 real blocks only.
        """
        nblock, itype = [], []
        for b in self.blocks:
            if b.kind == "full" and b.rows == b.cols:
                nblock.append(b.rows)
                itype.append(2)
            elif b.kind == "real" and b.rows == 1:
                nblock.append(1)
                itype.append(1)
            else:
                return None
        return np.array(nblock, dtype=np.int64), np.array(itype, dtype=np.int64)

    def check(self, M: Any) -> NDArray[np.complex128]:
        """M as a complex array, with a one-line error if its shape does not fit."""
        M = np.asarray(M)
        if M.ndim != 2:
            raise ValueError(f"M must be a 2-D matrix, got shape {M.shape}")
        if M.shape != self.m_shape:
            raise ValueError(
                f"M is {M.shape[0]}x{M.shape[1]} but the block structure needs "
                f"{self.m_shape[0]}x{self.m_shape[1]} (rows = sum of block cols, cols = sum "
                "of block rows)"
            )
        if not np.all(np.isfinite(M)):
            raise ValueError("M contains NaN or inf entries")
        return M.astype(complex)

    # padding to square blocks -----------------------------------------------------------
    def padded(self) -> tuple[BlockStructure, NDArray[np.intp], NDArray[np.intp]]:
        """Square-block structure and the positions of M's rows/cols in the padded M."""
        rows_keep: list[int] = []
        cols_keep: list[int] = []
        new: list[Block] = []
        r0 = 0
        for b in self.blocks:
            s = max(b.rows, b.cols)
            rows_keep.extend(range(r0, r0 + b.cols))  # M rows of this block: b.cols
            cols_keep.extend(range(r0, r0 + b.rows))  # M cols of this block: b.rows
            new.append(Block.full(s) if b.kind == "full" else b)
            r0 += s
        return BlockStructure(new), np.array(rows_keep, np.intp), np.array(cols_keep, np.intp)

    def pad(self, M: NDArray[Any]) -> tuple[NDArray[np.complex128], BlockStructure]:
        """Zero-padded square M and its square-block structure (mu is unchanged)."""
        sq, rk, ck = self.padded()
        if self.m_shape[0] == len(rk) == len(ck) and np.array_equal(rk, ck) and (
            rk.size == 0 or rk[-1] == rk.size - 1
        ):
            return M, sq
        n = sq.m_shape[0]
        Mp = np.zeros((n, n), dtype=complex)
        Mp[np.ix_(rk, ck)] = M
        return Mp, sq

    def unpad_delta(self, Delta: NDArray[Any]) -> NDArray[np.complex128]:
        """Delta of the padded problem restricted to this structure (drops padding)."""
        _, rk, ck = self.padded()
        return np.asarray(Delta)[np.ix_(ck, rk)]


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
    def __init__(self, M: NDArray[Any], par: _DG):
        self.M = M
        self.par = par
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

    def value(self, x: NDArray[np.float64]) -> float:
        try:
            lam = self._eig(x)[0]
        except (np.linalg.LinAlgError, ValueError):
            return math.inf
        self._record(float(lam[-1]), x)
        return float(lam[-1])

    def _record(self, val: float, x: NDArray[np.float64]) -> None:
        if val < self.best and math.isfinite(val):
            self.best = val
            self.best_x = np.array(x, dtype=float)

    def __call__(self, x: NDArray[np.float64]) -> tuple[float, NDArray[np.float64]]:
        self.nfev += 1
        if not np.all(np.isfinite(x)) or np.max(np.abs(x)) > 300:
            return 1e300, np.zeros_like(x)
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

    Attributes
    ----------
    value:
        The bound beta (>= 0; 0 means mu = 0 is certified).
    D, G:
        The scalings of the certificate, for the square (padded) M: D > 0 commutes with Delta,
        G Hermitian on the real blocks, M^H D M + j(G M - M^H G) <= value^2 D.
    method:
        ``"ab13md"`` or ``"dg"`` (the numpy D-G optimisation).
    params:
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
    idxs = [par._block_idx(k) for k in range(K)]
    A2 = np.abs(M) ** 2
    Bn = np.array([[A2[np.ix_(idxs[k], idxs[l_])].sum() for l_ in range(K)] for k in range(K)])
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


_WARM_STAGES = (1e-4, 0.0)


def _dg_upper(
    M: NDArray[Any], st: BlockStructure, x0: NDArray[np.float64] | None, target: float,
    rtol: float, maxiter: int,
) -> MixedMuUpper:
    par = _DG(st)
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

    def done() -> bool:
        return obj.best < 0.0 or obj.best <= stop2

    for rel in (_WARM_STAGES if warm else (3e-2, 3e-3, 3e-4, 3e-5, 0.0)):
        if done():
            break
        obj.smooth = rel
        hist: list[float] = []

        def _cb(intermediate_result: Any, hist: list[float] = hist) -> None:
            hist.append(obj.best)
            if done() or (len(hist) > 8 and hist[-9] - hist[-1] <= rtol * abs(hist[-1])):
                raise StopIteration

        opts: dict[str, Any] = {"maxiter": maxiter, "gtol": 1e-12 * max(abs(obj.best), 1e-300)}
        res = minimize(obj, x, jac=True, method="BFGS", callback=_cb, options=opts)
        x = obj.best_x if obj.best_x is not None else np.asarray(res.x)
    assert obj.best_x is not None
    D, G = par.matrices(obj.best_x)
    return MixedMuUpper(math.sqrt(max(obj.best, 0.0)), D, G, "dg", obj.best_x)


def _ab13md_upper(
    M: NDArray[Any], spec: tuple[NDArray[Any], NDArray[Any]], x: NDArray[np.float64] | None
) -> MixedMuUpper | None:
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
    return MixedMuUpper(float(mu), np.diag(d**2).astype(complex), np.diag(g).astype(complex),
                        "ab13md", np.asarray(xo, float))


_UPPER_METHODS = ("auto", "ab13md", "dg")


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
    """Mixed real/complex mu upper bound with D-G scaling (module docstring).

    Parameters
    ----------
    M:
        Complex matrix of shape ``BlockStructure(blocks).m_shape`` (non-square allowed).
    blocks:
        The uncertainty structure (list of :class:`~vtolftc.synthesis.mu.Block`).
    method:
        ``"auto"`` (AB13MD where it applies, else ``"dg"``), ``"ab13md"`` (error if the
        structure has repeated or non-square blocks) or ``"dg"`` (numpy D-G optimisation).
    warm_start:
        A previous result for the same structure (a neighbouring frequency): its scalings
        start the optimiser.
    rtol, maxiter:
        Optimiser tolerance (relative, on beta) and BFGS iterations per continuation stage.
    target:
        Stop as soon as the bound is <= target (1 + rtol), e.g. a known lower bound.

    Returns
    -------
    MixedMuUpper
        ``value`` >= mu(M), with the (D, G) certificate.
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
        res = _ab13md_upper(Mc, spec, None)
        if res is not None:
            return res
    Mp, sq = st.pad(Mc)
    x0 = warm_start.params if warm_start is not None and warm_start.method == "dg" else None
    return _dg_upper(Mp, sq, x0, target, rtol, maxiter)


# ------------------------------------------------------------------------------------------
# lower bound, both bounds, sweep
# ------------------------------------------------------------------------------------------


def mixed_mu_lower(
    M: Any,
    blocks: Sequence[Block] | BlockStructure,
    *,
    n_starts: int = 4,
    seed: int = 0,
    iters: int = 80,
) -> tuple[float, NDArray[np.complex128] | None]:
    """Mixed-mu lower bound: (value, Delta) with det(I - M Delta) = 0, ||Delta|| = 1/value.

    Power iteration (complex blocks; real blocks as +-1 signs), vertex enumeration of the
    real parameters and a 1-D search along real directions with the complex part solved
    exactly (see the module docstring). Every returned Delta is verified. ``(0.0, None)``
    if no destabilising perturbation was found (e.g. mu = 0).
    """
    from vtolftc.synthesis.mu import _lower, _Structure

    st = BlockStructure(blocks)
    Mc = st.check(M)
    if n_starts < 0:
        raise ValueError(f"n_starts must be >= 0, got {n_starts}")
    Mp, sq = st.pad(Mc)
    s = _Structure(list(sq.blocks), Mp.shape[0])
    rng = np.random.default_rng(seed)
    val, Delta, _ = _lower(Mp, s, n_starts, rng, [], iters)
    if all(b.kind == "real" for b in sq.blocks):
        v2, D2 = _real_det_search(Mp, sq, val, rng)
        if v2 > val:
            val, Delta = v2, D2
    if Delta is None:
        return 0.0, None
    return val, st.unpad_delta(Delta)


def _real_det_search(
    M: NDArray[Any], st: BlockStructure, lb: float, rng: np.random.Generator, n_rand: int = 4
) -> tuple[float, NDArray[np.complex128] | None]:
    """Pure real structure: min ||delta||_inf s.t. det(I - M Delta(delta)) = 0 (SLSQP).

    The power iteration only moves the real parameters by signs; with a complex M the
    smallest real destabilising point has |delta_i| of different sizes. Starts: every sign
    vertex (up to 16, else random signs) at radii around 1/sigma_max(M) and 1/lb.
    """
    from vtolftc.synthesis.mu import _verify

    sizes = np.array([b.rows for b in st.blocks])
    k = sizes.size
    n = M.shape[0]
    eye = np.eye(n)

    def delta(d: NDArray[np.float64]) -> NDArray[np.complex128]:
        return np.diag(np.repeat(d, sizes)).astype(complex)

    def det_ri(y: NDArray[np.float64]) -> NDArray[np.float64]:
        f = np.linalg.det(eye - M @ delta(y[:k]))
        return np.array([f.real, f.imag])

    smax = float(np.linalg.norm(M, 2))
    if smax == 0.0:
        return 0.0, None
    if 2**k <= 16:
        signs = np.array(np.meshgrid(*([[-1.0, 1.0]] * k), indexing="ij")).reshape(k, -1).T
    else:
        signs = np.where(rng.random((16, k)) < 0.5, -1.0, 1.0)
    radii = [1.0 / smax, 2.0 / smax] + ([1.0 / lb] if lb > 0 else [])
    starts = [s * r for s in signs for r in radii]
    starts += [rng.uniform(-1, 1, k) * 2.0 / smax for _ in range(n_rand)]
    cons = [
        {"type": "eq", "fun": det_ri},
        {"type": "ineq", "fun": lambda y: y[k] - y[:k]},
        {"type": "ineq", "fun": lambda y: y[k] + y[:k]},
    ]
    best: tuple[float, NDArray[np.complex128] | None] = (lb, None)
    for d0 in starts:
        y0 = np.concatenate([d0, [np.max(np.abs(d0))]])
        try:
            res = minimize(lambda y: y[k], y0, method="SLSQP", constraints=cons,
                           jac=lambda y: np.eye(k + 1)[k],
                           options={"maxiter": 100, "ftol": 1e-12})
        except (ValueError, np.linalg.LinAlgError):
            continue
        d = np.asarray(res.x[:k])
        t = float(np.max(np.abs(d)))
        if t <= 0 or not np.isfinite(t) or 1.0 / t <= best[0]:
            continue
        Delta = delta(d)
        if _verify(M, Delta):
            best = (1.0 / t, Delta)
    return best


@dataclass(frozen=True)
class MixedMuBounds:
    """lower <= mu(M) <= upper, with the lower bound's Delta and the upper bound's (D, G)."""

    lower: float
    upper: float
    delta: NDArray[np.complex128] | None = field(repr=False)
    certificate: MixedMuUpper = field(repr=False)

    @property
    def gap(self) -> float:
        return self.upper - self.lower


def mixed_mu_bounds(
    M: Any,
    blocks: Sequence[Block] | BlockStructure,
    *,
    method: str = "auto",
    n_starts: int = 4,
    seed: int = 0,
    rtol: float = 1e-9,
) -> MixedMuBounds:
    """Both mixed-mu bounds of M (:func:`mixed_mu_lower`, :func:`mixed_mu_upper`)."""
    st = BlockStructure(blocks)
    lo, Delta = mixed_mu_lower(M, st, n_starts=n_starts, seed=seed)
    up = mixed_mu_upper(M, st, method=method, rtol=rtol, target=lo)
    return MixedMuBounds(lo, max(up.value, 0.0), Delta, up)


def mixed_mu_sweep(
    freq_response: Any,
    blocks: Sequence[Block] | BlockStructure,
    omegas: Any,
    *,
    method: str = "auto",
    n_starts: int = 0,
    seed: int = 0,
    rtol: float = 1e-4,
    lower: bool = True,
) -> MuSweep:
    """Mixed-mu bounds of M(j w_i) over a frequency grid (robust stability / performance).

    Parameters
    ----------
    freq_response:
        Array (nw, rows, cols) of M(j w), e.g. from
        :func:`vtolftc.synthesis.hinfnorm.frequency_response`; rows x cols must be
        ``BlockStructure(blocks).m_shape``.
    blocks:
        The structure, e.g. ``[Block.real(2), Block.real(1), Block.full(2, 3)]``.
    omegas:
        The nw frequencies (rad/s).
    method:
        Upper-bound method, see :func:`mixed_mu_upper`.
    n_starts:
        Random power-iteration starts per frequency for the lower bound (in addition to the
        eigenvector and warm starts).
    rtol:
        Relative tolerance of the upper-bound optimiser.
    lower:
        False skips the lower bound (then ``lower`` is all zeros).

    Returns
    -------
    MuSweep
        Pointwise bounds and their grid peaks (the same type as
        :func:`vtolftc.synthesis.mu.mu_sweep`). Scalings are warm-started from the previous
        frequency.
    """
    st = BlockStructure(blocks)
    F = np.asarray(freq_response)
    w = np.asarray(omegas, dtype=float).reshape(-1)
    if F.ndim != 3 or F.shape[1:] != st.m_shape:
        raise ValueError(
            f"freq_response must have shape (nw, {st.m_shape[0]}, {st.m_shape[1]}) for this "
            f"block structure, got {F.shape}"
        )
    if F.shape[0] != w.size or w.size == 0:
        raise ValueError(
            f"omegas has {w.size} entries but freq_response has {F.shape[0]} frequencies "
            "(both must be the same, non-zero)"
        )
    from vtolftc.synthesis.mu import _lower, _Structure

    lo = np.zeros(w.size)
    up = np.zeros(w.size)
    prev: MixedMuUpper | None = None
    sq = st.padded()[0]
    s = _Structure(list(sq.blocks), sq.m_shape[0])
    rng = np.random.default_rng(seed)
    vec: list[tuple[NDArray[Any], NDArray[Any]]] = []
    for i in range(w.size):
        Mi = st.check(F[i])
        if lower:  # fast per-frequency lower bound: power iteration, warm-started
            Mp, _ = st.pad(Mi)
            lo[i], _, v = _lower(Mp, s, n_starts, rng, vec, 30, real_search=False)
            vec = [] if v is None else [v]
        res = mixed_mu_upper(Mi, st, method=method, warm_start=prev, rtol=rtol, target=lo[i],
                             maxiter=60)
        up[i] = res.value
        prev = res
    if lower:  # the full real-parameter search where it matters: at the peaks
        for i in {int(np.argmax(up)), int(np.argmax(lo))}:
            val, _ = mixed_mu_lower(F[i], st, n_starts=max(n_starts, 2), seed=seed)
            lo[i] = max(lo[i], val)
    il, iu = int(np.argmax(lo)), int(np.argmax(up))
    return MuSweep(w, lo, up, float(lo[il]), float(w[il]), float(up[iu]), float(w[iu]))

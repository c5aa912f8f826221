"""Structured singular value (mu) bounds (MATLAB ``mussv`` role).

For a complex matrix M and a block-diagonal uncertainty structure
Delta = diag(Delta_1, ..., Delta_K), the structured singular value is (paper eq. 12)

    mu(M) = 1 / min { sigma_max(Delta) : det(I - M Delta) = 0, Delta structured },

(mu = 0 if no structured Delta makes I - M Delta singular). Robust stability and robust
performance are mu(M(j w)) < 1 and mu(N(j w)) < 1 for all w (paper eqs. 13-14), where the
robust-performance structure appends a full complex "performance" block.

Computing mu exactly is NP-hard in general; this module returns guaranteed bounds:

* upper bound (:func:`mu_upper_bound`): mu(M) <= sigma_max(D_l M D_r^-1) for every scaling
  commuting with the structure. Scalings are positive scalars d_k for full blocks and
  (w.l.o.g., by a QR argument) upper-triangular matrices with positive diagonal for
  repeated scalar blocks. The bound is minimised from an Osborne-balanced start (plus an
  eigenvector-based start for repeated blocks) by BFGS on a smoothed sigma_max
  (log-sum-exp of the singular values, with continuation) in the log-scalings. Every
  evaluated scaling yields a valid bound; the smallest is returned.
* lower bound (:func:`mu_lower_bound`): the Packard-Fan-Doyle power iteration produces a
  structured contraction Q; for an eigenvalue lambda of M Q, Delta = Q / lambda makes
  I - M Delta singular, so mu(M) >= 1 / sigma_max(Delta). The value returned is always of
  this form (it is a *valid* lower bound up to the rounding of an eigenvalue computation).

Real blocks (repeated real scalars delta I_n, delta in R): the upper bound treats them as
repeated *complex* scalars (valid because the complex set contains the real one, but
without the G-scaling refinement it can be conservative). In the lower bound the real
blocks use real signs q = +-1 in the power iteration and a candidate is accepted only if
the corresponding eigenvalue of M Q is real (verified: sigma_min(I - M Delta) ~ 0); in
addition, setting every real block to 0 and bounding the remaining complex sub-problem
always gives a valid bound. The lower bound for real blocks can therefore be quite
conservative (real mu is discontinuous and notoriously hard).

Block conventions (same as MATLAB ``mussv``): ``Block.full(rows, cols)`` is a rows x cols
complex block; M must be square of size sum(cols) = sum(rows). M's rows are partitioned by
the blocks' ``cols`` and its columns by the blocks' ``rows`` so that M Delta is defined.
"""

from __future__ import annotations

import math
from collections.abc import Sequence
from dataclasses import dataclass, field
from typing import Any

import numpy as np
from numpy.typing import NDArray
from scipy.optimize import minimize, minimize_scalar

from vtolftc.synthesis.mu_blocks import Block, BlockStructure
from vtolftc.synthesis.power_kernel import power_iteration, power_iteration_scalar

__all__ = [
    "Block",
    "DScaling",
    "MuBounds",
    "MuSweep",
    "mu_bounds",
    "mu_lower_bound",
    "mu_sweep",
    "mu_upper_bound",
]



@dataclass(frozen=True)
class DScaling:
    """D-scaling of the upper bound: bound = sigma_max(left @ M @ inv(right)).

    With real blocks the bound is the mixed D-G bound: ``g`` is then the Hermitian G of the
    certificate M^H D M + j (G M - M^H G) <= bound^2 D with D = left^H left (square
    structures), and sigma_max(left M right^-1) alone may exceed the bound.

    Parameters
    ----------
    left : ndarray of complex, shape (n, n)
        D_l, acting on M's rows (partition by block cols).
    right : ndarray of complex, shape (n, n)
        D_r, acting on M's columns (partition by block rows); equal to ``left`` for
        structures of square blocks.
    params : ndarray of float, shape (n_params,)
        The internal log-parametrisation of the D-scaling (usable as a warm start).
    g : ndarray of complex, shape (n, n), optional
        G of the D-G certificate (real blocks), else None.
    method : {"dscale", "ab13md", "dg"}
        The algorithm that produced the scaling.
    warm : ndarray of float, optional
        That algorithm's warm-start vector.
    """

    left: NDArray[np.complex128]
    right: NDArray[np.complex128]
    params: NDArray[np.float64]
    g: NDArray[np.complex128] | None = field(default=None, repr=False)
    method: str = "dscale"
    warm: NDArray[np.float64] | None = field(default=None, repr=False)

    def scaled(self, M: NDArray[Any]) -> NDArray[np.complex128]:
        """Return D_l M D_r^-1.

        Parameters
        ----------
        M : array_like, shape (n, n)
            The matrix the scaling applies to.

        Returns
        -------
        ndarray of complex, shape (n, n)
            ``left @ M @ inv(right)``.
        """
        return self.left @ np.asarray(M) @ np.linalg.inv(self.right)


@dataclass(frozen=True)
class MuBounds:
    """Lower and upper bounds on mu and the (absolute) gap upper - lower (dimensionless).

    Parameters
    ----------
    lower, upper : float
        lower <= mu(M) <= upper.
    gap : float
        upper - lower.
    scaling : DScaling, optional
        The scaling that proves the upper bound.
    delta : ndarray of complex, optional
        The destabilising structured perturbation of the lower bound: det(I - M delta) ~ 0
        and sigma_max(delta) = 1 / lower (``None`` if lower == 0).
    """

    lower: float
    upper: float
    gap: float
    scaling: DScaling | None = field(default=None, repr=False)
    delta: NDArray[np.complex128] | None = field(default=None, repr=False)

    @property
    def relative_gap(self) -> float:
        """(upper - lower) / upper (0 if upper == 0)."""
        return 0.0 if self.upper == 0.0 else self.gap / self.upper


@dataclass(frozen=True)
class MuSweep:
    """mu bounds over a frequency grid (paper eqs. 13-14 checked pointwise in frequency).

    The peaks are grid maxima: the true sup over w of mu can be larger between grid points.

    Parameters
    ----------
    omegas : ndarray of float, shape (nw,)
        Frequencies (rad/s).
    lower, upper : ndarray of float, shape (nw,)
        Bounds on mu(M(j w)) at each frequency.
    peak_lower, peak_upper : float
        Largest lower and upper bound over the grid.
    peak_lower_frequency_rad_s, peak_upper_frequency_rad_s : float
        Frequencies (rad/s) of those peaks.
    """

    omegas: NDArray[np.float64]
    lower: NDArray[np.float64]
    upper: NDArray[np.float64]
    peak_lower: float
    peak_lower_frequency_rad_s: float
    peak_upper: float
    peak_upper_frequency_rad_s: float

    @property
    def gap(self) -> NDArray[np.float64]:
        """Pointwise upper - lower."""
        return self.upper - self.lower


# ------------------------------------------------------------------------------------------
# D-scalings of a structure (index maps in BlockStructure)
# ------------------------------------------------------------------------------------------


def _scalings(
    st: BlockStructure, x: NDArray[np.float64]
) -> tuple[NDArray[Any], NDArray[Any], NDArray[Any], NDArray[Any]]:
    """Return D_l, D_r^-1 and the diagonal values (dl, dr) of the parameters x."""
    dl = np.exp(x[st.diag_param_l])
    dr = np.exp(x[st.diag_param_r])
    if not st.has_off:
        return np.diag(dl), np.diag(1.0 / dr), dl, dr
    z = x[st.off_pre] + 1j * x[st.off_pim]
    Dl = np.diag(dl).astype(complex)
    Dr = np.diag(dr).astype(complex)
    Dl[st.off_il, st.off_jl] = z
    Dr[st.off_ir, st.off_jr] = z
    return Dl, np.linalg.inv(Dr), dl, dr


def _scaled(st: BlockStructure, M: NDArray[Any], x: NDArray[np.float64]) -> NDArray[Any]:
    """D_l M D_r^-1 for the parameters x."""
    if not st.has_off:
        dl = np.exp(x[st.diag_param_l])
        dr = np.exp(x[st.diag_param_r])
        return (dl[:, None] * M) / dr[None, :]
    Dl, Dr_inv, _, _ = _scalings(st, x)
    return Dl @ M @ Dr_inv


def _dscaling(st: BlockStructure, x: NDArray[np.float64]) -> DScaling:
    """The :class:`DScaling` of the parameters x."""
    Dl, Dr_inv, _, _ = _scalings(st, x)
    return DScaling(
        left=np.asarray(Dl, dtype=complex),
        right=np.asarray(np.linalg.inv(Dr_inv), dtype=complex),
        params=np.array(x, dtype=float),
    )


def _check_matrix(M: Any) -> NDArray[np.complex128]:
    M = np.asarray(M)
    if M.ndim != 2 or M.shape[0] != M.shape[1]:
        raise ValueError(f"M must be a square 2-D matrix (n x n), got shape {M.shape}")
    if M.shape[0] == 0:
        raise ValueError("M must be at least 1x1")
    if not np.all(np.isfinite(M)):
        raise ValueError("M contains NaN or inf entries")
    return M.astype(complex)


# ------------------------------------------------------------------------------------------
# upper bound
# ------------------------------------------------------------------------------------------


def _osborne_init(M: NDArray[Any], st: BlockStructure, sweeps: int = 20) -> NDArray[np.float64]:
    """Osborne balancing of the block-norm matrix: minimise ||D B D^-1||_F (log params)."""
    K = st.K
    Bn = np.zeros((K, K))
    A2 = np.abs(M) ** 2
    for k in range(K):
        rows = A2[st.row_idx[k]]
        for l in range(K):
            Bn[k, l] = rows[:, st.col_idx[l]].sum()
    np.fill_diagonal(Bn, 0.0)
    d2 = np.ones(K)  # d_k^2
    for _ in range(sweeps):
        changed = 0.0
        for k in range(K):
            num = float(np.dot(Bn[:, k], d2))  # sum_l d_l^2 B_lk
            den = float(np.dot(Bn[k, :], 1.0 / d2))  # sum_l B_kl / d_l^2
            if num > 0.0 and den > 0.0:
                new = math.sqrt(num / den)
                changed = max(changed, abs(math.log(new / d2[k])))
                d2[k] = new
        if changed < 1e-3:
            break
    logd = 0.5 * np.log(d2)
    logd -= logd.mean()
    x = np.zeros(st.n_params)
    for k in range(K):
        sl = st.block_param_slices[k]
        if st.blocks[k].kind == "full":
            x[sl.start] = logd[k]
        else:
            m = st.blocks[k].rows
            x[sl.start : sl.start + m] = logd[k]
    return x


def _eig_init(M: NDArray[Any], st: BlockStructure, x: NDArray[np.float64]) -> NDArray[np.float64]:
    """Replace the scalings of repeated blocks by R from QR(V^-1) of their diagonal block.

    For a single repeated complex block this gives sigma_max(R M R^-1) = rho(M) exactly
    (M diagonalisable), the tight upper bound.
    """
    x = x.copy()
    for k in st.rep_blocks:
        m = st.blocks[k].rows
        if m == 1:
            continue
        Mkk = M[np.ix_(st.row_idx[k], st.col_idx[k])]
        _, V = np.linalg.eig(Mkk)
        if not np.all(np.isfinite(V)) or np.linalg.cond(V) > 1e8:
            continue
        R = np.linalg.qr(np.linalg.inv(V))[1]
        ph = np.diag(R) / np.abs(np.diag(R))
        R = np.conj(ph)[:, None] * R  # unitary row rotation: positive real diagonal
        sl = st.block_param_slices[k]
        mean_log = float(x[sl.start : sl.start + m].mean())
        logdiag = np.log(np.abs(np.diag(R)))
        shift = mean_log - logdiag.mean()
        R = R * math.exp(shift)
        x[sl.start : sl.start + m] = logdiag + shift
        iu, ju = np.triu_indices(m, 1)
        nu = iu.size
        x[sl.start + m : sl.start + m + nu] = R[iu, ju].real
        x[sl.start + m + nu : sl.start + m + 2 * nu] = R[iu, ju].imag
    return x


class _UpperObjective:
    """Smoothed sigma_max(D_l M D_r^-1) and its gradient in the log-parametrisation."""

    def __init__(self, M: NDArray[Any], st: BlockStructure):
        self.M = M
        self.st = st
        self.smooth = 0.0
        self.best_val = math.inf
        self.best_x: NDArray[np.float64] | None = None
        self.nfev = 0

    def true_value(self, x: NDArray[np.float64]) -> float:
        N = _scaled(self.st, self.M, x)
        val = float(np.linalg.norm(N, 2))
        self._record(val, x)
        return val

    def _record(self, val: float, x: NDArray[np.float64]) -> None:
        if val < self.best_val and math.isfinite(val):
            self.best_val = val
            self.best_x = np.array(x, dtype=float)

    def __call__(self, x: NDArray[np.float64]) -> tuple[float, NDArray[np.float64]]:
        st = self.st
        self.nfev += 1
        Dl, Dr_inv, dl, dr = _scalings(st, x)
        N = Dl @ self.M @ Dr_inv if st.has_off else (dl[:, None] * self.M) / dr[None, :]
        try:
            U, s, Vh = np.linalg.svd(N)
        except np.linalg.LinAlgError:
            return math.inf, np.zeros_like(x)
        s1 = float(s[0])
        self._record(s1, x)
        if s1 == 0.0:
            return 0.0, np.zeros_like(x)
        if self.smooth > 0.0:
            e = np.exp((s - s1) / self.smooth)
            tot = float(e.sum())
            f = s1 + self.smooth * math.log(tot)
            wts = e / tot
        else:
            f = s1
            wts = np.zeros_like(s)
            wts[0] = 1.0
        ws = wts * s
        g = np.zeros_like(x)
        if not st.has_off:
            cl = (np.abs(U) ** 2) @ ws  # diag of U diag(ws) U^H
            cr = (np.abs(Vh.conj().T) ** 2) @ ws
            g += np.bincount(st.diag_param_l, weights=cl, minlength=x.size)
            g -= np.bincount(st.diag_param_r, weights=cr, minlength=x.size)
            return f, g
        V = Vh.conj().T
        Wl = (U * ws) @ U.conj().T
        Wr = (V * ws) @ V.conj().T
        Gl = np.linalg.solve(Dl, Wl)  # D_l^-1 W_l (block diagonal inverse)
        Gr = Dr_inv @ Wr
        g += np.bincount(st.diag_param_l, weights=np.real(np.diag(Gl)) * dl, minlength=x.size)
        g -= np.bincount(st.diag_param_r, weights=np.real(np.diag(Gr)) * dr, minlength=x.size)
        gl = Gl[st.off_jl, st.off_il]
        gr = Gr[st.off_jr, st.off_ir]
        g[st.off_pre] += gl.real - gr.real
        g[st.off_pim] += -gl.imag + gr.imag
        return f, g


def _upper(
    M: NDArray[Any],
    st: BlockStructure,
    x0: NDArray[np.float64] | None,
    target: float,
    rtol: float,
    maxiter: int,
) -> tuple[float, NDArray[np.float64]]:
    obj = _UpperObjective(M, st)
    x_id = np.zeros(st.n_params)
    obj.true_value(x_id)  # D = I: guarantees upper <= sigma_max(M)
    starts = [_osborne_init(M, st)]
    if st.rep_blocks:
        starts.append(_eig_init(M, st, starts[0]))
    if x0 is not None:
        if x0.shape != (st.n_params,):
            raise ValueError(
                f"warm-start scaling has {x0.size} parameters, expected {st.n_params}"
            )
        starts.append(np.asarray(x0, dtype=float))
    vals = [obj.true_value(s) for s in starts]
    x = starts[int(np.argmin(vals))].copy()
    if st.K == 1 and st.blocks[0].kind == "full":
        return obj.best_val, obj.best_x  # type: ignore[return-value]
    stop = target * (1.0 + rtol)
    for rel in (3e-2, 3e-3, 3e-4, 3e-5, 0.0):
        if obj.best_val <= stop:
            break
        obj.smooth = rel * obj.best_val

        def _stop(intermediate_result: Any) -> None:
            if obj.best_val <= stop:
                raise StopIteration

        res = minimize(
            obj, x, jac=True, method="BFGS", callback=_stop,
            options={"maxiter": maxiter, "gtol": 1e-9 * max(obj.best_val, 1e-300)},
        )
        x = np.asarray(res.x) if np.all(np.isfinite(res.x)) else x
    assert obj.best_x is not None
    return obj.best_val, obj.best_x


_MU_METHODS = ("auto", "ab13md", "dg", "dscale")


def _upper_any(
    M: NDArray[Any],
    st: BlockStructure,
    warm: DScaling | None,
    target: float,
    rtol: float,
    maxiter: int,
    method: str,
) -> tuple[float, DScaling]:
    """Upper bound by AB13MD (where it applies), D-G scaling (real blocks) or D-scaling."""
    if method not in _MU_METHODS:
        raise ValueError(f"unknown method {method!r}; expected one of {_MU_METHODS}")
    spec = st.ab13md_spec() if st.all_square else None
    if method == "ab13md" and spec is None:
        raise ValueError(
            "AB13MD only takes square full complex blocks and 1x1 real blocks; use "
            "method='dg' (real blocks) or 'dscale' for this structure"
        )
    if method in ("auto", "ab13md") and spec is not None:
        from vtolftc.synthesis.dg_scaling import ab13md_upper_bound

        # cold start only: chained AB13MD warm starts can hang (see mixed_mu); None when
        # AB13MD fails or its (D, G) do not prove its value: then the D-G optimiser below
        res_ab = ab13md_upper_bound(M, spec, None)
        if res_ab is not None:
            d = np.sqrt(np.real(np.diag(res_ab.D)))
            Dl = np.diag(d).astype(complex)
            G = res_ab.G if st.has_real else None
            x = np.log(d[st.row_starts])
            return res_ab.value, DScaling(Dl, Dl.copy(), x, G, "ab13md", res_ab.params)
    if st.has_real and method in ("auto", "dg", "ab13md"):
        from vtolftc.synthesis.dg_scaling import dg_upper_bound

        x0 = warm.warm if warm is not None and warm.method == "dg" else None
        # the budget of mixed_mu_upper (200 per stage), so that the two agree
        res = dg_upper_bound(M, st, x0, target, rtol, max(maxiter, 200))
        T = np.linalg.cholesky(res.D).conj().T  # D = T^H T
        return res.value, DScaling(T, T.copy(), np.zeros(st.n_params), res.G, "dg",
                                   res.params)
    x0 = warm.params if warm is not None and warm.method == "dscale" else None
    val, x = _upper(M, st, x0, target, rtol, maxiter)
    return val, _dscaling(st, x)


def mu_upper_bound(
    M: NDArray[Any],
    blocks: Sequence[Block] | BlockStructure,
    *,
    warm_start: DScaling | NDArray[np.float64] | None = None,
    rtol: float = 1e-9,
    maxiter: int = 60,
    method: str = "auto",
) -> tuple[float, DScaling]:
    """Upper bound on mu_Delta(M) (eq. 12) by D-scaling: min_D sigma_max(D_l M D_r^-1).

    Parameters
    ----------
    M : array_like, shape (n, n)
        Square complex matrix.
    blocks : sequence of Block or BlockStructure
        Block structure; sizes must sum to n.
    warm_start : DScaling or ndarray, optional
        A previous :class:`DScaling` (or its ``params``) for the same structure, e.g. from a
        neighbouring frequency.
    rtol : float
        Optimiser relative tolerance per continuation stage: a stage stops when eight
        iterations lower the bound by less than ``rtol`` (relative). It is a stall test, not
        the bound's error: on a nonsmooth D-G problem 1e-6 stopped 0.5 % above what 1e-9
        reaches (a [real(1), real(3)] structure), so the default is 1e-9, as in
        :func:`~vtolftc.synthesis.mixed_mu.mixed_mu_upper`, and the two agree.
    maxiter : int
        Optimiser iteration cap per continuation stage.
    method : {"auto", "ab13md", "dg", "dscale"}
        ``"auto"`` (default): SLICOT AB13MD where it applies (square full complex blocks and
        1x1 real blocks), the mixed D-G bound of :mod:`vtolftc.synthesis.mixed_mu` for other
        structures with real blocks, D-scaling otherwise. ``"ab13md"``, ``"dg"`` or
        ``"dscale"`` (the numpy D-scaling, real blocks scaled as complex) force one.

    Returns
    -------
    value : float
        ``value`` >= mu(M), value <= sigma_max(M). Without real blocks value =
        sigma_max(D.left @ M @ inv(D.right)).
    D : DScaling
        The scaling; with real blocks (D-G bound) ``D.g`` holds G.

    Raises
    ------
    ValueError
        If M is not square and finite, the blocks do not fit it, or ``method`` is unknown or
        does not apply to the structure.

    Examples
    --------
    >>> import numpy as np
    >>> M = np.array([[1.0, 10.0], [0.0, 1.0]])
    >>> value, D = mu_upper_bound(M, [Block.full(1), Block.full(1)])
    >>> round(value, 4)                 # sigma_max(M) = 10.1; the scalings bring it to rho(M)
    1.0
    """
    Mc = _check_matrix(M)
    st = BlockStructure(blocks).require_square(Mc.shape[0])
    if isinstance(warm_start, DScaling):
        warm = warm_start
    elif warm_start is not None:
        x0 = np.asarray(warm_start, float)
        warm = DScaling(np.eye(1), np.eye(1), x0)
    else:
        warm = None
    return _upper_any(Mc, st, warm, 0.0, rtol, maxiter, method)


# ------------------------------------------------------------------------------------------
# lower bound
# ------------------------------------------------------------------------------------------


def _blk_norms(v: NDArray[Any], idx_blk: NDArray[np.intp], K: int) -> NDArray[np.float64]:
    return np.sqrt(np.bincount(idx_blk, weights=v.real**2 + v.imag**2, minlength=K))


class _Power:
    """Packard-Fan-Doyle power iteration for the complex (and signed real) mu lower bound."""

    def __init__(self, M: NDArray[Any], st: BlockStructure):
        self.M = M
        self.Mh = M.conj().T
        self.st = st

    def phases(self, a: NDArray[Any], w: NDArray[Any]) -> NDArray[Any]:
        """q_k for repeated blocks maximising Re(w_k^H q a_k) (|q|=1, or q=+-1 if real)."""
        st = self.st
        inner = np.bincount(
            st.rep_blk, weights=(np.conj(w[st.rep_col]) * a[st.rep_row]).real, minlength=st.K
        ) + 1j * np.bincount(
            st.rep_blk, weights=(np.conj(w[st.rep_col]) * a[st.rep_row]).imag, minlength=st.K
        )
        q = np.ones(st.K, dtype=complex)
        mag = np.abs(inner)
        nz = mag > 0
        q[nz] = np.conj(inner[nz]) / mag[nz]
        if st.has_real:
            re = np.sign(inner.real)
            re[re == 0] = 1.0
            q[st.is_real] = re[st.is_real]
        return q

    def run(
        self, b: NDArray[Any], w: NDArray[Any], iters: int = 60, tol: float = 1e-10
    ) -> tuple[NDArray[Any], NDArray[Any]]:
        """(a, w) after the iteration from (b, w): the compiled kernel of
        :mod:`vtolftc.synthesis.power_kernel` (:meth:`run_numpy` is the reference)."""
        st = self.st
        M = np.ascontiguousarray(self.M, dtype=complex)
        b = np.ascontiguousarray(b, dtype=complex)
        w = np.ascontiguousarray(w, dtype=complex)
        if st.scalar:
            return power_iteration_scalar(M, b, w, iters, tol)
        return power_iteration(M, b, w, iters, tol, st.K, st.blk_of_row, st.blk_of_col,
                               st.full_row, st.full_col, st.rep_row, st.rep_col,
                               st.rep_blk, st.is_real)

    def run_numpy(
        self, b: NDArray[Any], w: NDArray[Any], iters: int = 60, tol: float = 1e-10
    ) -> tuple[NDArray[Any], NDArray[Any]]:
        """:meth:`run` in numpy (the reference the kernel is tested against)."""
        st, M, Mh = self.st, self.M, self.Mh
        K = st.K
        has_rep = bool(st.rep_blocks)
        full_row, full_col = st.full_row, st.full_col
        bfr, bfc = st.blk_of_row[full_row], st.blk_of_col[full_col]
        rep_row, rep_col, rep_blk = st.rep_row, st.rep_col, st.rep_blk
        a = M @ b
        beta_old = -1.0
        if st.scalar:  # fast path: all blocks 1x1 (real ones iterate as complex)
            for _ in range(iters):
                na = np.abs(a)
                z = a * (np.abs(w) / np.where(na > 0, na, np.inf))
                w = Mh @ z
                nw = math.sqrt(np.vdot(w, w).real)
                if nw == 0.0:
                    break
                w = w / nw
                aw = np.abs(w)
                b = w * (na / np.where(aw > 0, aw, np.inf))
                a = M @ b
                beta = math.sqrt(np.vdot(a, a).real)
                if beta == 0.0:
                    break
                a = a / beta
                if abs(beta - beta_old) <= tol * beta:
                    break
                beta_old = beta
            return a, w
        for _ in range(iters):
            na = math.sqrt(np.vdot(a, a).real)
            if na == 0.0:
                break
            a = a / na
            an = _blk_norms(a, st.blk_of_row, K)
            wn = _blk_norms(w, st.blk_of_col, K)
            z = np.empty_like(a)
            ratio = wn / np.where(an > 0, an, np.inf)
            z[full_row] = a[full_row] * ratio[bfr]
            if has_rep:
                q = self.phases(a, w)
                z[rep_row] = np.conj(q[rep_blk]) * w[rep_col]
            w = Mh @ z
            nw = math.sqrt(np.vdot(w, w).real)
            if nw == 0.0:
                break
            w = w / nw
            wn = _blk_norms(w, st.blk_of_col, K)
            b = np.empty_like(w)
            ratio = an / np.where(wn > 0, wn, np.inf)
            b[full_col] = w[full_col] * ratio[bfc]
            if has_rep:
                q = self.phases(a, w)
                b[rep_col] = q[rep_blk] * a[rep_row]
            a = M @ b
            beta = math.sqrt(np.vdot(a, a).real)
            if abs(beta - beta_old) <= tol * max(beta, 1e-300):
                break
            beta_old = beta
        na = math.sqrt(np.vdot(a, a).real)
        if na > 0:
            a = a / na
        return a, w

    def q_matrix(self, a: NDArray[Any], w: NDArray[Any]) -> NDArray[np.complex128]:
        """Structured Q aligning a -> w blockwise; every block has norm exactly 1."""
        st = self.st
        if st.scalar:
            na, nw = np.abs(a), np.abs(w)
            ok = (na > 0) & (nw > 0)
            q = np.ones(st.n, dtype=complex)
            q[ok] = (w[ok] / nw[ok]) * np.conj(a[ok] / na[ok])
            if st.has_real:  # project onto the admissible real signs
                q[st.is_real] = np.where(q[st.is_real].real < 0, -1.0, 1.0)
            return np.diag(q)
        Q = np.zeros((st.n, st.n), dtype=complex)
        q = self.phases(a, w)
        for k, blk in enumerate(st.blocks):
            ri, ci = st.row_idx[k], st.col_idx[k]
            if blk.kind == "full":
                ak, wk = a[ri], w[ci]
                na, nw = np.linalg.norm(ak), np.linalg.norm(wk)
                if na > 0 and nw > 0:
                    Q[np.ix_(ci, ri)] = np.outer(wk / nw, np.conj(ak / na))
                else:
                    Q[ci[0], ri[0]] = 1.0
            else:
                Q[ci, ri] = q[k]
        return Q


def _delta_from_q(
    M: NDArray[Any], Q: NDArray[Any], st: BlockStructure
) -> tuple[float, NDArray[np.complex128] | None]:
    """Valid bound |lambda| from Delta = Q / lambda, lambda an eigenvalue of M Q (||Q|| = 1).

    det(I - M Q / lambda) = 0 and sigma_max(Q / lambda) = 1/|lambda|. With real blocks only
    (numerically) real eigenvalues are admissible; the candidate is then verified.
    """
    lam = np.linalg.eigvals(M @ Q)
    if not st.has_real:
        i = int(np.argmax(np.abs(lam)))
        li = lam[i]
        return (0.0, None) if li == 0 else (float(abs(li)), Q / li)
    for i in np.argsort(-np.abs(lam)):
        li = lam[i]
        if li == 0:
            break
        if abs(li.imag) > 1e-9 * abs(li):
            continue
        Delta = Q / li.real
        if makes_singular(M, Delta):
            return float(abs(li.real)), Delta
    return 0.0, None


def makes_singular(M: NDArray[Any], Delta: NDArray[Any]) -> bool:
    """True if I - M Delta is singular to working accuracy.

    Parameters
    ----------
    M : ndarray, shape (n, m)
        The matrix.
    Delta : ndarray, shape (m, n)
        The perturbation.

    Returns
    -------
    bool
        sigma_min(I - M Delta) <= 1e-8 (1 + ||M||_2 ||Delta||_2).
    """
    n = M.shape[0]
    smin = float(np.linalg.svd(np.eye(n) - M @ Delta, compute_uv=False)[-1])
    return smin <= 1e-8 * (1.0 + float(np.linalg.norm(M, 2)) * float(np.linalg.norm(Delta, 2)))


def _sign_vectors(kr: int, rng: np.random.Generator, cap: int = 16) -> list[NDArray[Any]]:
    if 2**kr <= cap:
        grid = np.array(np.meshgrid(*([[-1.0, 1.0]] * kr), indexing="ij")).reshape(kr, -1).T
        return list(grid)
    return [np.where(rng.random(kr) < 0.5, -1.0, 1.0) for _ in range(cap)]


def _lower_real(
    M: NDArray[Any],
    st: BlockStructure,
    lb: float,
    rng: np.random.Generator,
    dirs_extra: Sequence[NDArray[Any]],
) -> tuple[float, NDArray[np.complex128] | None]:
    """Lower bound candidates exploiting the real blocks (see module docstring).

    Pure real structure: real eigenvalues of M S for sign patterns S. Mixed structure: for
    real values delta_r = t s (s a sign pattern) the complex blocks see the LFT
    M'(delta_r) = M_cc + M_cr Delta_r (I - M_rr Delta_r)^-1 M_rc, and
    mu >= min(1/t, mu_c(M')) is maximised over t on a grid, then refined.
    """
    n = st.n
    ridx = np.flatnonzero(st.is_real)
    cidx = np.flatnonzero(~st.is_real)
    best: tuple[float, NDArray[np.complex128] | None] = (0.0, None)
    signs = _sign_vectors(ridx.size, rng)
    if 2 ** ridx.size > len(signs):  # not all vertices enumerated: add power-iteration signs
        signs += [np.where(d < 0, -1.0, 1.0) for d in dirs_extra]
    if cidx.size == 0:
        for s in signs:
            S = np.zeros((n, n), dtype=complex)
            for k, sk in zip(ridx, s, strict=True):
                S[st.col_idx[k], st.row_idx[k]] = sk
            val, Delta = _delta_from_q(M, S, st)
            if val > best[0]:
                best = (val, Delta)
        return best
    rr = np.concatenate([st.row_idx[k] for k in ridx])
    cr = np.concatenate([st.col_idx[k] for k in ridx])
    rc = np.concatenate([st.row_idx[k] for k in cidx])
    cc = np.concatenate([st.col_idx[k] for k in cidx])
    Mrr, Mrc = M[np.ix_(rr, cr)], M[np.ix_(rr, cc)]
    Mcr, Mcc = M[np.ix_(rc, cr)], M[np.ix_(rc, cc)]
    sub = BlockStructure([st.blocks[k] for k in cidx]).require_square(rc.size)
    single_full = sub.K == 1 and sub.blocks[0].kind == "full"
    sizes = np.array([st.blocks[k].rows for k in ridx])
    eye_r = np.eye(rr.size)

    def evaluate(t: float, s: NDArray[Any]) -> tuple[float, NDArray[Any] | None]:
        dr = np.repeat(t * s, sizes)
        try:
            X = np.linalg.solve(eye_r - Mrr * dr[None, :], Mrc)
        except np.linalg.LinAlgError:
            return 0.0, None
        Mp = Mcc + (Mcr * dr[None, :]) @ X
        if single_full:
            U, sv, Vh = np.linalg.svd(Mp)
            if sv[0] == 0:
                return 0.0, None
            Dc = np.outer(Vh[0].conj(), U[:, 0].conj()) / sv[0]
            mu_c = float(sv[0])
        else:
            mu_c, Dc, _ = power_lower_bound(Mp, sub, 0, rng, [], 25)
            if Dc is None:
                return 0.0, None
        return min(1.0 / t, mu_c), Dc

    scale = float(np.linalg.norm(M, 2))
    if scale == 0.0:
        return best
    # the optimum balances 1/t = mu_c(M'(t s)) and mu <= sigma_max(M): t in [1/|M|, 1/lb]
    T = 1.0 / max(lb, 1e-3 * scale)
    ts = np.geomspace(0.999 / scale, T, 24 if single_full else 12)
    for s in signs:
        vals = np.array([evaluate(t, s)[0] for t in ts])
        j = int(np.argmax(vals))
        if vals[j] <= best[0]:
            continue
        lo_t = ts[j - 1] if j > 0 else 0.9 * ts[0]
        hi_t = ts[j + 1] if j + 1 < ts.size else ts[j]
        res = minimize_scalar(
            lambda t, s=s: -evaluate(t, s)[0], bounds=(lo_t, hi_t), method="bounded",
            options={"xatol": 1e-8 * ts[j], "maxiter": 40},
        )
        t_best = float(res.x) if -res.fun > vals[j] else float(ts[j])
        val, Dc = evaluate(t_best, s)
        if Dc is None or val <= best[0]:
            continue
        Delta = np.zeros((n, n), dtype=complex)
        Delta[cr, rr] = np.repeat(t_best * s, sizes)
        Delta[np.ix_(cc, rc)] = Dc
        if makes_singular(M, Delta):
            dn = max(t_best, float(np.linalg.norm(Dc, 2)))
            best = (1.0 / dn, Delta)
    return best


def power_lower_bound(
    M: NDArray[Any],
    st: BlockStructure,
    n_starts: int,
    rng: np.random.Generator,
    vec_starts: Sequence[tuple[NDArray[Any], NDArray[Any]]],
    iters: int,
    include_eig: bool = True,
    real_search: bool = True,
) -> tuple[float, NDArray[np.complex128] | None, tuple[NDArray[Any], NDArray[Any]] | None]:
    """Lower bound of mu by the power iteration (Packard-Fan-Doyle; signed for real blocks).

    Parameters
    ----------
    M : ndarray of complex, shape (n, n)
        The matrix.
    st : BlockStructure
        Its (square) block structure.
    n_starts : int
        Seeded random starts, in addition to the deterministic ones.
    rng : numpy.random.Generator
        Source of the random starts.
    vec_starts : sequence of (ndarray, ndarray)
        Vector pairs (b, w) to start from, e.g. the converged pair of a neighbouring frequency.
    iters : int
        Power iterations per start.
    include_eig : bool
        Also start from the dominant eigenvectors of M.
    real_search : bool
        With real blocks, also search the real directions (see :mod:`.mixed_mu`).

    Returns
    -------
    value : float
        The lower bound (0 if no destabilising perturbation was found).
    Delta : ndarray of complex, shape (n, n) or None
        The destabilising structured perturbation of norm 1/value that proves it (checked
        with :func:`makes_singular`).
    vectors : (ndarray, ndarray) or None
        The converged vector pair (a warm start for the next frequency).
    """
    n = st.n
    if st.has_real:
        iters = min(iters, 25)  # the signed-real iteration rarely converges: keep it short
    pw = _Power(M, st)
    best: tuple[
        float, NDArray[np.complex128] | None, tuple[NDArray[Any], NDArray[Any]] | None
    ] = (0.0, None, None)
    starts = list(vec_starts)
    if st.all_square and include_eig:
        # Q = I is admissible: mu >= rho(M) (rho_R(M) for real blocks)
        val, Delta = _delta_from_q(M, np.eye(n, dtype=complex), st)
        if val > best[0]:
            best = (val, Delta, None)
        lam, X = np.linalg.eig(M)
        i = int(np.argmax(np.abs(lam)))
        lamh, Y = np.linalg.eig(M.conj().T)
        j = int(np.argmin(np.abs(lamh - np.conj(lam[i]))))
        starts.append((X[:, i], Y[:, j]))
    for _ in range(n_starts):
        b = rng.standard_normal(n) + 1j * rng.standard_normal(n)
        w = rng.standard_normal(n) + 1j * rng.standard_normal(n)
        starts.append((b / np.linalg.norm(b), w / np.linalg.norm(w)))
    real_dirs: list[NDArray[Any]] = []
    for b0, w0 in starts:
        a, w = pw.run(np.asarray(b0, complex), np.asarray(w0, complex), iters=iters)
        Q = pw.q_matrix(a, w)
        val, Delta = _delta_from_q(M, Q, st)
        if val > best[0]:
            best = (val, Delta, (a, w))
        elif best[2] is None:
            best = (best[0], best[1], (a, w))
        if st.has_real:
            ridx = np.flatnonzero(st.is_real)
            real_dirs.append(
                np.array([Q[st.col_idx[k][0], st.row_idx[k][0]].real for k in ridx])
            )
    if st.has_real and real_search:
        if not st.is_real.all():
            # valid fallback: real blocks set to zero, complex sub-structure only
            cb = [k for k in range(st.K) if not st.is_real[k]]
            ri = np.concatenate([st.row_idx[k] for k in cb])
            ci = np.concatenate([st.col_idx[k] for k in cb])
            sub = BlockStructure([st.blocks[k] for k in cb]).require_square(ri.size)
            val, Dsub, _ = power_lower_bound(M[np.ix_(ri, ci)], sub, max(1, n_starts // 2),
                                             rng, [], iters)
            if val > best[0] and Dsub is not None:
                Delta = np.zeros((n, n), dtype=complex)
                Delta[np.ix_(ci, ri)] = Dsub
                best = (val, Delta, best[2])
        val, Delta = _lower_real(M, st, best[0], rng, real_dirs[:4])
        if val > best[0]:
            best = (val, Delta, best[2])
    return best


def mu_lower_bound(
    M: NDArray[Any],
    blocks: Sequence[Block] | BlockStructure,
    *,
    n_starts: int = 4,
    seed: int = 0,
    iters: int = 80,
    scaling: DScaling | None = None,
) -> tuple[float, NDArray[np.complex128] | None]:
    """Lower bound on mu_Delta(M) (eq. 12) by the Packard-Fan-Doyle power iteration.

    Starts: the dominant eigenvectors of M (Q = I, so the bound is >= rho(M) when all
    blocks are square and complex), the singular vectors of D_l M D_r^-1 if a ``scaling``
    from :func:`mu_upper_bound` is given, and ``n_starts`` seeded random vectors.

    Parameters
    ----------
    M : array_like, shape (n, n)
        Square complex matrix.
    blocks : sequence of Block or BlockStructure
        Block structure; sizes must sum to n.
    n_starts : int
        Seeded random starts.
    seed : int
        Seed of the random starts.
    iters : int
        Power iterations per start.
    scaling : DScaling, optional
        Upper-bound scaling whose singular vectors give a further start.

    Returns
    -------
    value : float
        The lower bound.
    Delta : ndarray of complex, shape (n, n) or None
        A structured perturbation with det(I - M Delta) = 0 (to rounding) and
        sigma_max(Delta) = 1 / value, which proves mu(M) >= value; ``(0.0, None)`` if no
        destabilising perturbation was found.

    Raises
    ------
    ValueError
        If M is not square and finite or the blocks do not fit it.
    """
    Mc = _check_matrix(M)
    st = BlockStructure(blocks).require_square(Mc.shape[0])
    if n_starts < 0:
        raise ValueError(f"n_starts must be >= 0, got {n_starts}")
    starts = [] if scaling is None else [_svd_start(Mc, scaling)]
    val, Delta, _ = power_lower_bound(Mc, st, n_starts, np.random.default_rng(seed), starts, iters)
    return val, Delta


def _svd_start(M: NDArray[Any], D: DScaling) -> tuple[NDArray[Any], NDArray[Any]]:
    """Power-iteration start (b, w) from the top singular pair of N = D_l M D_r^-1."""
    Dr_inv = np.linalg.inv(D.right)
    N = D.left @ M @ Dr_inv
    _, _, Vh = np.linalg.svd(N)
    v = Vh[0].conj()
    b = Dr_inv @ v
    w = D.right.conj().T @ v
    return b / np.linalg.norm(b), w / np.linalg.norm(w)


# ------------------------------------------------------------------------------------------
# both bounds, frequency sweep
# ------------------------------------------------------------------------------------------


def _bounds(
    M: NDArray[Any],
    st: BlockStructure,
    warm: DScaling | None,
    extra_starts: Sequence[tuple[NDArray[Any], NDArray[Any]]],
    n_starts: int,
    rng: np.random.Generator,
    rtol: float,
    maxiter: int,
    iters: int,
    method: str = "auto",
) -> tuple[MuBounds, tuple[NDArray[Any], NDArray[Any]] | None]:
    # quick lower bound first: it lets the upper-bound optimiser stop early when tight
    lo0, Delta0, vec0 = power_lower_bound(M, st, 0, rng, list(extra_starts), iters,
                                          real_search=False)
    up, D = _upper_any(M, st, warm, lo0, rtol, maxiter, method)
    lo, Delta, vec = lo0, Delta0, vec0
    if up > lo0 * (1.0 + rtol) or st.has_real:
        lo1, Delta1, vec1 = power_lower_bound(
            M, st, n_starts, rng, [_svd_start(M, D)], iters, include_eig=False
        )
        if lo1 > lo:
            lo, Delta, vec = lo1, Delta1, vec1
    return MuBounds(lo, up, up - lo, D, Delta), vec


def mu_bounds(
    M: NDArray[Any],
    blocks: Sequence[Block] | BlockStructure,
    *,
    n_starts: int = 4,
    seed: int = 0,
    rtol: float = 1e-9,
    warm_start: DScaling | None = None,
    method: str = "auto",
) -> MuBounds:
    """Lower and upper bounds of mu_Delta(M) (eq. 12); see the module docstring.

    Parameters
    ----------
    M : array_like, shape (n, n)
        Square complex matrix.
    blocks : sequence of Block or BlockStructure
        Block structure; sizes must sum to n.
    n_starts : int
        Random power-iteration starts added to the deterministic ones (eigen- and
        singular-vector based).
    seed : int
        Makes the random starts reproducible.
    rtol : float
        Relative tolerance of the upper-bound optimiser (see :func:`mu_upper_bound`; 1e-9
        as in :func:`~vtolftc.synthesis.mixed_mu.mixed_mu_upper`).
    warm_start : DScaling, optional
        Scaling of a neighbouring problem for the upper bound.
    method : {"auto", "ab13md", "dg", "dscale"}
        Upper-bound algorithm (see :func:`mu_upper_bound`).

    Returns
    -------
    MuBounds
        ``lower <= mu(M) <= upper`` with the scaling and the destabilising Delta.

    Raises
    ------
    ValueError
        If M is not square and finite, the blocks do not fit it, or ``method`` is unknown.

    Examples
    --------
    >>> import numpy as np
    >>> M = np.array([[0.5, 2.0], [0.125, 0.5]])
    >>> b = mu_bounds(M, [Block.full(1), Block.full(1)])
    >>> round(b.lower, 6), round(b.upper, 6)      # mu = |0.5| + sqrt(2 * 0.125)
    (1.0, 1.0)
    """
    Mc = _check_matrix(M)
    st = BlockStructure(blocks).require_square(Mc.shape[0])
    if n_starts < 0:
        raise ValueError(f"n_starts must be >= 0, got {n_starts}")
    res, _ = _bounds(Mc, st, warm_start, [], n_starts, np.random.default_rng(seed), rtol, 60,
                     80, method)
    return res


def mu_sweep(
    freq_response: NDArray[Any],
    blocks: Sequence[Block] | BlockStructure,
    omegas: NDArray[np.float64],
    *,
    n_starts: int = 1,
    seed: int = 0,
    rtol: float = 1e-5,
    method: str = "auto",
) -> MuSweep:
    """mu bounds of M(j w_i) over a frequency grid (robust stability/performance, eqs. 13-14).

    For non-square M or mixed real/complex structures with repeated real scalars see also
    :func:`vtolftc.synthesis.mixed_mu.mixed_mu_sweep`.

    Parameters
    ----------
    freq_response : ndarray of complex, shape (nw, n, n)
        M(j w) (e.g. from :func:`vtolftc.synthesis.hinfnorm.frequency_response`).
    blocks : sequence of Block or BlockStructure
        Block structure.
    omegas : ndarray of float, shape (nw,)
        The frequencies in rad/s (used for reporting the peak frequencies).
    n_starts : int
        Random power-iteration starts per frequency in addition to the warm starts from the
        neighbouring frequency and from the upper-bound scaling.
    seed : int
        Seed of the random starts.
    rtol : float
        Relative tolerance of the upper-bound optimiser.
    method : {"auto", "ab13md", "dg", "dscale"}
        Upper-bound algorithm (see :func:`mu_upper_bound`; AB13MD where it applies).

    Returns
    -------
    MuSweep
        Bounds at every frequency and their peaks.

    Raises
    ------
    ValueError
        If the response is not (nw, n, n), does not match ``omegas``, is empty or not finite,
        or the blocks do not fit it.

    Examples
    --------
    >>> import numpy as np
    >>> w = np.array([0.1, 1.0, 10.0])
    >>> F = np.array([np.diag([1 / (1j * wi + 1), 0.5]) for wi in w])
    >>> sw = mu_sweep(F, [Block.full(1), Block.full(1)], w)
    >>> round(sw.peak_upper, 4), sw.peak_upper_frequency_rad_s
    (0.995, 0.1)
    """
    F = np.asarray(freq_response)
    w = np.asarray(omegas, dtype=float).reshape(-1)
    if F.ndim != 3 or F.shape[1] != F.shape[2]:
        raise ValueError(
            f"freq_response must have shape (nw, n, n), got {F.shape}"
        )
    if F.shape[0] != w.size:
        raise ValueError(
            f"omegas has {w.size} entries but freq_response has {F.shape[0]} frequencies"
        )
    if F.shape[0] == 0:
        raise ValueError("empty frequency grid")
    if not np.all(np.isfinite(F)):
        raise ValueError("freq_response contains NaN or inf entries")
    st = BlockStructure(blocks).require_square(F.shape[1])
    rng = np.random.default_rng(seed)
    lower = np.zeros(w.size)
    upper = np.zeros(w.size)
    warm: DScaling | None = None
    vec: tuple[NDArray[Any], NDArray[Any]] | None = None
    for i in range(w.size):
        Mi = F[i].astype(complex)
        res, new_vec = _bounds(
            Mi, st, warm, [] if vec is None else [vec], n_starts, rng, rtol, 40, 60, method
        )
        lower[i], upper[i] = res.lower, res.upper
        warm = res.scaling
        if new_vec is not None:
            vec = (new_vec[0], new_vec[1])
    il, iu = int(np.argmax(lower)), int(np.argmax(upper))
    return MuSweep(w, lower, upper, float(lower[il]), float(w[il]), float(upper[iu]), float(w[iu]))

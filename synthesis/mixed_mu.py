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
generalised eigenvalue (a quasi-convex function of (D, G)), by BFGS (SciPy's, compiled:
:mod:`vtolftc.synthesis.dg_bfgs`) on a log-sum-exp smoothed
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

from collections.abc import Sequence
from dataclasses import dataclass, field
from typing import Any

import numpy as np
from numpy.typing import NDArray
from scipy.optimize import minimize

from vtolftc.synthesis.dg_scaling import (
    MixedMuUpper,
    mixed_mu_upper,
    mixed_mu_upper_start,
)
from vtolftc.synthesis.mu import Block, MuSweep, makes_singular, power_lower_bound
from vtolftc.synthesis.mu_blocks import BlockStructure

__all__ = [
    "BlockStructure",
    "MixedMuBounds",
    "MixedMuUpper",
    "mixed_mu_bounds",
    "mixed_mu_lower",
    "mixed_mu_sweep",
    "mixed_mu_upper",
    "mixed_mu_upper_start",
]


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
    exactly (see the module docstring). Every returned Delta is verified.

    Parameters
    ----------
    M : array_like, shape ``BlockStructure(blocks).m_shape``
        Complex matrix (non-square allowed).
    blocks : sequence of Block or BlockStructure
        The uncertainty structure.
    n_starts : int
        Seeded random power-iteration starts (>= 0).
    seed : int
        Seed of the random starts.
    iters : int
        Power iterations per start.

    Returns
    -------
    value : float
        The lower bound (0 if no destabilising perturbation was found, e.g. mu = 0).
    Delta : ndarray of complex, shape ``BlockStructure(blocks).delta_shape`` or None
        The structured perturbation that proves it.

    Raises
    ------
    ValueError
        If M does not fit the structure or ``n_starts`` < 0.

    Examples
    --------
    >>> import numpy as np
    >>> value, Delta = mixed_mu_lower(np.array([[0.0, 1.0], [4.0, 0.0]]), [Block.real(1)] * 2)
    >>> round(value, 6), np.allclose(Delta, Delta.real)
    (2.0, True)
    """

    st = BlockStructure(blocks)
    Mc = st.check(M)
    if n_starts < 0:
        raise ValueError(f"n_starts must be >= 0, got {n_starts}")
    Mp, sq = st.pad(Mc)
    s = sq.require_square(Mp.shape[0])
    rng = np.random.default_rng(seed)
    val, Delta, _ = power_lower_bound(Mp, s, n_starts, rng, [], iters)
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
        if makes_singular(M, Delta):
            best = (1.0 / t, Delta)
    return best


@dataclass(frozen=True)
class MixedMuBounds:
    """lower <= mu(M) <= upper, with the lower bound's Delta and the upper bound's (D, G).

    Parameters
    ----------
    lower, upper : float
        The bounds (dimensionless).
    delta : ndarray of complex or None
        The destabilising perturbation that proves ``lower`` (None if lower == 0).
    certificate : MixedMuUpper
        The (D, G) scalings that prove ``upper``.
    """

    lower: float
    upper: float
    delta: NDArray[np.complex128] | None = field(repr=False)
    certificate: MixedMuUpper = field(repr=False)

    @property
    def gap(self) -> float:
        """Upper minus lower bound."""
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
    """Both mixed-mu bounds of M (:func:`mixed_mu_lower`, :func:`mixed_mu_upper`).

    Parameters
    ----------
    M : array_like, shape ``BlockStructure(blocks).m_shape``
        Complex matrix (non-square allowed).
    blocks : sequence of Block or BlockStructure
        The uncertainty structure.
    method : {"auto", "ab13md", "dg"}
        Upper-bound method, see :func:`mixed_mu_upper`.
    n_starts : int
        Random starts of the lower bound.
    seed : int
        Seed of the random starts.
    rtol : float
        Relative tolerance of the upper-bound optimiser.

    Returns
    -------
    MixedMuBounds
        Both bounds with their proofs.

    Raises
    ------
    ValueError
        If M does not fit the structure or ``method`` is unknown.

    Examples
    --------
    >>> import numpy as np
    >>> b = mixed_mu_bounds(np.diag([1.0, 2j]), [Block.real(2)])
    >>> round(b.lower, 4), round(b.upper, 4)    # a complex scalar would give 2
    (1.0, 1.0)
    """
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
    freq_response : array_like, shape (nw, rows, cols)
        M(j w), e.g. from :func:`vtolftc.synthesis.hinfnorm.frequency_response`; rows x cols
        must be ``BlockStructure(blocks).m_shape``.
    blocks : sequence of Block or BlockStructure
        The structure, e.g. ``[Block.real(2), Block.real(1), Block.full(2, 3)]``.
    omegas : array_like, shape (nw,)
        The frequencies (rad/s).
    method : {"auto", "ab13md", "dg"}
        Upper-bound method, see :func:`mixed_mu_upper`.
    n_starts : int
        Random power-iteration starts per frequency for the lower bound (in addition to the
        eigenvector and warm starts).
    seed : int
        Seed of the random starts.
    rtol : float
        Relative tolerance of the upper-bound optimiser.
    lower : bool
        False skips the lower bound (then ``lower`` is all zeros).

    Returns
    -------
    MuSweep
        Pointwise bounds and their grid peaks (the same type as
        :func:`vtolftc.synthesis.mu.mu_sweep`). Scalings are warm-started from the previous
        frequency.

    Raises
    ------
    ValueError
        If the response's shape does not fit the structure or ``omegas``, or it is not finite.

    Examples
    --------
    >>> import numpy as np
    >>> w = np.array([0.5, 1.0, 2.0])
    >>> F = np.array([[[1 / (1j * wi + 1)]] for wi in w])
    >>> sw = mixed_mu_sweep(F, [Block.real(1)], w)
    >>> sw.peak_upper < 1e-6     # at w > 0 no real delta makes 1 - delta / (jw + 1) vanish
    True
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

    lo = np.zeros(w.size)
    up = np.zeros(w.size)
    prev: MixedMuUpper | None = None
    sq = st.padded()[0]
    s = sq.require_square(sq.m_shape[0])
    rng = np.random.default_rng(seed)
    vec: list[tuple[NDArray[Any], NDArray[Any]]] = []
    for i in range(w.size):
        Mi = st.check(F[i])
        if lower:  # fast per-frequency lower bound: power iteration, warm-started
            Mp, _ = st.pad(Mi)
            lo[i], _, v = power_lower_bound(Mp, s, n_starts, rng, vec, 30, real_search=False)
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

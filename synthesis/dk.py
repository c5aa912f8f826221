"""D-K iteration with a fixed controller structure (robust performance designed for, not only
analysed; MATLAB's ``musyn`` with a tunable structure).

The robust-performance interconnection N(theta) has the uncertainty channel first: input 0
is the perturbation input d (d = Delta z, Delta one complex scalar), output 0 is the
perturbation output z; the other inputs are the exogenous signals, the other outputs the
weighted performance outputs, closed by a full complex performance block Delta_P. For that
two-block structure the mu upper bound is

    mu_hat(w) = min_{d > 0} sigma_max( diag(d, I) N(j w) diag(1/d, I) )

(one positive scalar per frequency: the performance block's scaling is normalised to 1), and
for two full complex blocks the bound equals mu (Packard & Doyle 1993: no gap with at most
three full blocks). Iteration, from a stabilising theta_0:

1. **D step** (:func:`optimal_scalings`): d(w) on the frequency grid, exactly (the scaled
   sigma_max is convex in log d: a bounded Brent search);
2. **fit** (:func:`fit_scaling`): a stable, minimum-phase D(s) = k prod_i (s + z_i)/(s + p_i),
   z_i, p_i > 0 real (order 0, 1 or 2: a constant, one or two real zero/pole pairs), fitted to
   |d(w)| by weighted least squares on log-magnitude (weights (mu_hat(w)/peak)^4 so the fit is
   exact where mu is near its peak, zero where d does not change the bound), then refined
   (:func:`refine_scaling`) to minimise the grid peak of sigma_max(D N D^-1), what the K step
   starts from (a loose fit away from the peak can otherwise put that peak well above mu);
3. **K step**: the structured H-infinity tuner (:func:`vtolftc.synthesis.structured.tune`,
   warm-started at the current gains) minimises ||diag(D, I) N(theta) diag(D^-1, I)||_inf
   (the channel :class:`ScaledChannel`; D^-1 stable because D is minimum phase), normalised
   by its value at the current gains, together with optional requirement channels
   (e.g. a delay-margin weight) normalised by max(1, their value at theta_0), so a
   requirement met at the start stays met (the tuner never returns a worse objective than
   its start) and an unmet one does not get worse;
4. **stop** when the measured peak mu_hat (step 1 on the grid, not the fitted norm) falls by
   less than ``rel_tol`` (default 1 %) from the best so far, or after ``max_iter`` D-K
   iterations; the best gains seen are returned (never worse than theta_0 by the grid peak).

:func:`cascade_rp` gives N for the P-PID cascade of :mod:`vtolftc.synthesis.loops` with the
uncertainty at the plant input (paper eq. 14, the matrix of
:func:`vtolftc.synthesis.robustness.rp_matrix`: z = W_t u, performance [Ws e; Wr u]).
:mod:`vtolftc.synthesis.dk_robust` applies the iteration to the robust point design.
"""

from __future__ import annotations

import math
from collections.abc import Callable, Sequence
from dataclasses import dataclass, field
from typing import Any

import numpy as np
from numpy.typing import NDArray
from scipy.optimize import least_squares, minimize, minimize_scalar

from vtolftc.synthesis.hinfnorm import (
    StateSpaceData,
    as_state_space,
    frequency_response,
    hinf_norm,
)
from vtolftc.synthesis.loops import closed_loop, series
from vtolftc.synthesis.structured import Parameter, TuningProblem, tune

__all__ = [
    "CascadeRP",
    "DKResult",
    "DKStep",
    "MuProfile",
    "Normalised",
    "RationalScaling",
    "ScaledChannel",
    "cascade_rp",
    "dk_iterate",
    "fit_scaling",
    "mu_profile",
    "optimal_scalings",
    "refine_scaling",
    "scaled_system",
]

#: Search half-width of log d about the off-diagonal balance (natural log units: e^12 ~ 1.6e5).
_LOG_D_SPAN = 12.0


# ------------------------------------------------------------------------------------------
# the rational scaling D(s)
# ------------------------------------------------------------------------------------------


@dataclass(frozen=True)
class RationalScaling:
    """D(s) = gain prod_i (s + z_i) / (s + p_i), stable and minimum phase (z_i, p_i > 0).

    Parameters
    ----------
    gain : float
        k > 0 (dimensionless: the ratio of the scaled signals' units).
    zeros_rad_s, poles_rad_s : tuple of float
        z_i and p_i [rad/s], > 0, as many zeros as poles (the order).

    Raises
    ------
    ValueError
        For a non-positive gain, zero or pole, or unequal numbers of zeros and poles.

    Examples
    --------
    >>> D = RationalScaling(2.0, (1.0,), (10.0,))
    >>> [round(float(abs(x)), 3) for x in D.response([0.0, 1e6])]   # k z/p at DC, k at HF
    [0.2, 2.0]
    """

    gain: float
    zeros_rad_s: tuple[float, ...] = ()
    poles_rad_s: tuple[float, ...] = ()

    def __post_init__(self) -> None:
        if not (self.gain > 0 and math.isfinite(self.gain)):
            raise ValueError(f"D(s) gain must be finite and > 0, got {self.gain}")
        if len(self.zeros_rad_s) != len(self.poles_rad_s):
            raise ValueError("D(s) needs as many zeros as poles (biproper, invertible)")
        for v in (*self.zeros_rad_s, *self.poles_rad_s):
            if not (v > 0 and math.isfinite(v)):
                raise ValueError(f"D(s) zeros and poles must be > 0 rad/s (stable, minimum "
                                 f"phase), got {v}")

    @property
    def order(self) -> int:
        """Number of zero/pole pairs (states of D and of D^-1)."""
        return len(self.poles_rad_s)

    def response(self, omegas: Sequence[float] | NDArray[np.float64]) -> NDArray[np.complex128]:
        """D(j w).

        Parameters
        ----------
        omegas : array_like of float, shape (nw,)
            Frequencies [rad/s].

        Returns
        -------
        ndarray of complex, shape (nw,)
            D(j w).
        """
        s = 1j * np.asarray(omegas, float)
        out = np.full(s.shape, self.gain, complex)
        for z, p in zip(self.zeros_rad_s, self.poles_rad_s, strict=True):
            out *= (s + z) / (s + p)
        return out

    def ss(self, inverse: bool = False) -> StateSpaceData:
        """State space of D(s) (or of D(s)^-1), one state per zero/pole pair.

        Parameters
        ----------
        inverse : bool, optional
            Realise D^-1 = (1/k) prod (s + p_i)/(s + z_i) instead.

        Returns
        -------
        tuple of ndarray
            (A, B, C, D), SISO.
        """
        zs, ps = (self.poles_rad_s, self.zeros_rad_s) if inverse else (self.zeros_rad_s,
                                                                       self.poles_rad_s)
        sys = _static(1.0 / self.gain if inverse else self.gain)
        for z, p in zip(zs, ps, strict=True):
            # (s + z)/(s + p) = 1 + (z - p)/(s + p)
            sys = series(sys, (np.array([[-p]]), np.array([[1.0]]), np.array([[z - p]]),
                               np.array([[1.0]])))
        return sys

    def to_dict(self) -> dict[str, Any]:
        """Gain, zeros and poles [rad/s] as a JSON-ready dict.

        Returns
        -------
        dict of str to object
            ``gain``, ``zeros_rad_s``, ``poles_rad_s``, ``order``.
        """
        return {"gain": self.gain, "zeros_rad_s": list(self.zeros_rad_s),
                "poles_rad_s": list(self.poles_rad_s), "order": self.order}


def _static(k: float, n: int = 1) -> StateSpaceData:
    return (np.zeros((0, 0)), np.zeros((0, n)), np.zeros((n, 0)), k * np.eye(n))


def _blkdiag(*systems: StateSpaceData) -> StateSpaceData:
    """Block-diagonal (parallel, separate inputs and outputs) connection."""
    ns = [s[0].shape[0] for s in systems]
    ms = [s[3].shape[1] for s in systems]
    ps = [s[3].shape[0] for s in systems]
    A = np.zeros((sum(ns), sum(ns)))
    B = np.zeros((sum(ns), sum(ms)))
    C = np.zeros((sum(ps), sum(ns)))
    D = np.zeros((sum(ps), sum(ms)))
    i = j = k = 0
    for (a, b, c, d), n, m, p in zip(systems, ns, ms, ps, strict=True):
        A[i:i + n, i:i + n] = a
        B[i:i + n, j:j + m] = b
        C[k:k + p, i:i + n] = c
        D[k:k + p, j:j + m] = d
        i, j, k = i + n, j + m, k + p
    return A, B, C, D


def scaled_system(N: StateSpaceData, D: RationalScaling) -> StateSpaceData:
    """diag(D, I) N diag(D^-1, I): the D-scaled interconnection (uncertainty channel first).

    Parameters
    ----------
    N : tuple of ndarray
        (A, B, C, D) of N, p outputs x m inputs, output 0 and input 0 the uncertainty
        channel.
    D : RationalScaling
        The scaling of the uncertainty channel.

    Returns
    -------
    tuple of ndarray
        (A, B, C, D) of the scaled system (D^-1's states first, then N's, then D's).
    """
    Na = as_state_space(N)
    p, m = Na[3].shape
    left = _blkdiag(D.ss(), _static(1.0, p - 1)) if p > 1 else D.ss()
    right = _blkdiag(D.ss(inverse=True), _static(1.0, m - 1)) if m > 1 else D.ss(inverse=True)
    return series(series(right, Na), left)


# ------------------------------------------------------------------------------------------
# D step and fit
# ------------------------------------------------------------------------------------------


def _scaled_sigma(M: NDArray[np.complex128], x: float) -> float:
    S = M.copy()
    S[0, 1:] *= math.exp(x)
    S[1:, 0] *= math.exp(-x)
    return float(np.linalg.svd(S, compute_uv=False)[0])


def optimal_scalings(F: NDArray[np.complex128],
                     ) -> tuple[NDArray[np.float64], NDArray[np.float64], NDArray[np.bool_]]:
    """Optimal d(w) of the two-block structure at every frequency of a response.

    Parameters
    ----------
    F : ndarray of complex, shape (nw, p, m)
        N(j w), uncertainty channel first (p, m >= 2; N need not be square).

    Returns
    -------
    d : ndarray of float, shape (nw,)
        The minimising scaling d(w) > 0 (dimensionless ratio of the channel units).
    mu_hat : ndarray of float, shape (nw,)
        sigma_max(diag(d, I) N diag(1/d, I)), the mu upper bound (equal to mu for this
        structure).
    free : ndarray of bool, shape (nw,)
        True where d does not change the bound (a coupling term is zero): d is then
        arbitrary and should not be fitted.

    Raises
    ------
    ValueError
        For a response of the wrong shape.
    """
    F = np.asarray(F, complex)
    if F.ndim != 3 or F.shape[1] < 2 or F.shape[2] < 2:
        raise ValueError(f"expected a response of shape (nw, p>=2, m>=2), got {F.shape}")
    nw = F.shape[0]
    d, mu, free = np.ones(nw), np.zeros(nw), np.zeros(nw, bool)
    for i in range(nw):
        M = F[i]
        up, lo = float(np.linalg.norm(M[0, 1:])), float(np.linalg.norm(M[1:, 0]))
        x0 = 0.5 * math.log(lo / up) if up > 0 and lo > 0 else 0.0
        r = minimize_scalar(lambda x, M=M: _scaled_sigma(M, x),
                            bounds=(x0 - _LOG_D_SPAN, x0 + _LOG_D_SPAN), method="bounded",
                            options={"xatol": 1e-7})
        x, val = float(r.x), float(r.fun)
        base = _scaled_sigma(M, x0)
        if base < val:
            x, val = x0, base
        d[i], mu[i] = math.exp(x), val
        free[i] = (max(_scaled_sigma(M, x + 1.0), _scaled_sigma(M, x - 1.0))
                   <= val * (1 + 1e-9) + 1e-15)
    return d, mu, free


def _log_mag(x: NDArray[np.float64], w2: NDArray[np.float64], order: int) -> NDArray[np.float64]:
    out = np.full(w2.shape, x[0])
    for i in range(order):
        z, p = math.exp(x[1 + i]), math.exp(x[1 + order + i])
        out = out + 0.5 * (np.log(w2 + z * z) - np.log(w2 + p * p))
    return out


def fit_scaling(omegas: Sequence[float] | NDArray[np.float64],
                d: Sequence[float] | NDArray[np.float64], order: int = 1,
                weights: Sequence[float] | NDArray[np.float64] | None = None,
                ) -> RationalScaling:
    """Fit D(s) = k prod (s + z_i)/(s + p_i) (``order`` real pairs, z_i, p_i > 0) to |d(w)|.

    Weighted least squares on log-magnitude, sum_j w_j (log|D(j w_j)| - log d_j)^2, over
    log k, log z_i, log p_i (so D is stable and minimum phase by construction), from a
    grid of starts (zeros and poles at the grid's quantiles); the best fit is returned.

    Parameters
    ----------
    omegas : array_like of float, shape (nw,)
        Frequencies [rad/s], > 0.
    d : array_like of float, shape (nw,)
        The scalings, > 0.
    order : {0, 1, 2}
        Number of zero/pole pairs.
    weights : array_like of float, shape (nw,), optional
        Non-negative weights (default 1).

    Returns
    -------
    RationalScaling
        The fit (zeros and poles within [min(omegas)/100, 100 max(omegas)]).

    Raises
    ------
    ValueError
        For an order outside 0..2, non-positive frequencies or scalings, mismatched shapes
        or all-zero weights.

    Examples
    --------
    >>> import numpy as np
    >>> w = np.logspace(-2, 2, 50)
    >>> D = fit_scaling(w, np.abs(3.0 * (1j * w + 0.5) / (1j * w + 5.0)), order=1)
    >>> round(D.gain, 4), round(D.zeros_rad_s[0], 4), round(D.poles_rad_s[0], 4)
    (3.0, 0.5, 5.0)
    """
    w = np.asarray(omegas, float).reshape(-1)
    dv = np.asarray(d, float).reshape(-1)
    wt = np.ones_like(w) if weights is None else np.asarray(weights, float).reshape(-1)
    if order not in (0, 1, 2):
        raise ValueError(f"D(s) order {order}: expected 0, 1 or 2")
    if w.shape != dv.shape or w.shape != wt.shape or w.size == 0:
        raise ValueError("omegas, d and weights must be non-empty and of one length")
    if np.any(w <= 0) or np.any(dv <= 0) or not np.all(np.isfinite(dv)):
        raise ValueError("frequencies and scalings must be finite and > 0")
    if np.any(wt < 0) or not np.any(wt > 0):
        raise ValueError("weights must be >= 0 and not all zero")
    y = np.log(dv)
    sq = np.sqrt(wt)
    if order == 0:
        return RationalScaling(float(math.exp(np.sum(wt * y) / np.sum(wt))))
    w2 = w * w
    lo, hi = math.log(w.min() / 100.0), math.log(w.max() * 100.0)
    used = w[wt > 0]
    qs = np.log(np.quantile(used, [0.1, 0.3, 0.5, 0.7, 0.9]))
    starts = []
    for a in qs:
        for b in qs:
            if a == b:
                continue
            if order == 1:
                starts.append([a, b])
            else:
                starts.append([a, a + 1.0, b, b + 1.0])
    best, best_cost = None, math.inf
    for s in starts:
        x0 = np.concatenate([[0.0], np.clip(s, lo + 1e-6, hi - 1e-6)])
        x0[0] = float(np.sum(wt * (y - _log_mag(x0, w2, order))) / np.sum(wt))
        r = least_squares(lambda x: sq * (_log_mag(x, w2, order) - y), x0,
                          bounds=([-np.inf] + [lo] * 2 * order, [np.inf] + [hi] * 2 * order),
                          xtol=1e-12, ftol=1e-12, gtol=1e-12)
        if r.cost < best_cost:
            best, best_cost = r.x, float(r.cost)
    assert best is not None
    return RationalScaling(float(math.exp(best[0])),
                           tuple(float(math.exp(v)) for v in best[1:1 + order]),
                           tuple(float(math.exp(v)) for v in best[1 + order:]))


def _grid_peak(F: NDArray[np.complex128], Dw: NDArray[np.complex128]) -> float:
    S = F.copy()
    S[:, 0, 1:] *= Dw[:, None]
    S[:, 1:, 0] /= Dw[:, None]
    return float(np.max(np.linalg.svd(S, compute_uv=False)[:, 0]))


def refine_scaling(D: RationalScaling, F: NDArray[np.complex128],
                   omegas: Sequence[float] | NDArray[np.float64]) -> RationalScaling:
    """Refine a fitted D(s) for what the K step sees: minimise the grid peak
    max_w sigma_max(diag(D(jw), I) N(jw) diag(D(jw)^-1, I)) over log k, log z_i, log p_i
    (Nelder-Mead from ``D``, same order, zeros and poles within [min w / 100, 100 max w]).

    A log-magnitude fit weighted towards the mu peak can still leave the scaled sigma above
    the peak at a frequency where the fit is loose (then ||D N D^-1|| overstates mu and the
    K step starts from a poorer bound); the refinement removes that. ``D`` is returned
    unchanged when the refinement does not lower the grid peak.

    Parameters
    ----------
    D : RationalScaling
        The starting fit (:func:`fit_scaling`).
    F : ndarray of complex, shape (nw, p, m)
        N(j w) on ``omegas``, uncertainty channel first.
    omegas : array_like of float, shape (nw,)
        Frequencies [rad/s], > 0.

    Returns
    -------
    RationalScaling
        The refined scaling (or ``D``).
    """
    w = np.asarray(omegas, float)
    F = np.asarray(F, complex)
    n = D.order
    lo, hi = math.log(w.min() / 100.0), math.log(w.max() * 100.0)

    def make(x: NDArray[np.float64]) -> RationalScaling:
        xz = np.clip(x[1:], lo, hi)
        return RationalScaling(math.exp(float(np.clip(x[0], -300.0, 300.0))),
                               tuple(math.exp(float(v)) for v in xz[:n]),
                               tuple(math.exp(float(v)) for v in xz[n:]))

    def cost(x: NDArray[np.float64]) -> float:
        return _grid_peak(F, make(x).response(w))

    x0 = np.array([math.log(D.gain), *np.log(D.zeros_rad_s), *np.log(D.poles_rad_s)])
    c0 = cost(x0)
    r = minimize(cost, x0, method="Nelder-Mead",
                 options={"xatol": 1e-6, "fatol": 1e-9 * c0, "maxfev": 400 * (1 + 2 * n)})
    return make(np.asarray(r.x)) if float(r.fun) < c0 else D


# ------------------------------------------------------------------------------------------
# interconnections
# ------------------------------------------------------------------------------------------


def _ss(W: Any) -> StateSpaceData:
    if hasattr(W, "ss"):
        return as_state_space(W.ss())
    if hasattr(W, "tf"):
        return as_state_space(W.tf())
    return as_state_space(W)


@dataclass
class CascadeRP:
    """theta -> N(theta) of the P-PID cascade (paper eq. 14; picklable, numpy only).

    Inputs [d (N m), r (rad)], outputs [z = W_t u; Ws e; Wr u] (Wr's row omitted when
    ``Wr`` is None): the matrix of :func:`vtolftc.synthesis.robustness.rp_matrix` as a state
    space, with d the multiplicative input perturbation's signal (plant input u + d).

    Parameters
    ----------
    G : control.StateSpace or tuple
        Plant moment [N m] -> [rate rad/s; angle rad], strictly proper.
    Ws, Wt, Wr : weight
        Objects with ``ss()`` or ``tf()``, or any SISO LTI; ``Wr`` may be None.
    """

    G: Any
    Ws: Any
    Wt: Any
    Wr: Any = None

    def __post_init__(self) -> None:
        self._G = as_state_space(self.G)
        ws = [_ss(self.Wt), _ss(self.Ws)] + ([] if self.Wr is None else [_ss(self.Wr)])
        self._Wout = _blkdiag(*ws)
        self._rows = [1, 0] + ([] if self.Wr is None else [1])   # cl outputs: u, e, u

    def __getstate__(self) -> dict[str, Any]:
        return {"G": self._G, "Ws": _ss(self.Ws), "Wt": _ss(self.Wt),
                "Wr": None if self.Wr is None else _ss(self.Wr)}

    def __setstate__(self, st: dict[str, Any]) -> None:
        self.G, self.Ws, self.Wt, self.Wr = st["G"], st["Ws"], st["Wt"], st["Wr"]
        self.__post_init__()

    def __call__(self, theta: NDArray[np.float64]) -> StateSpaceData:
        cl = closed_loop(self._G, np.asarray(theta, float))
        rows = self._rows
        Ncl = (cl.A, cl.B[:, [1, 0]], cl.C[rows], cl.D[rows][:, [1, 0]])
        return series(Ncl, self._Wout)


def cascade_rp(G: Any, Ws: Any, Wt: Any, Wr: Any | None = None) -> CascadeRP:
    """:class:`CascadeRP` ``(G, Ws, Wt, Wr)``.

    Parameters
    ----------
    G : control.StateSpace or tuple
        Plant moment [N m] -> [rate rad/s; angle rad].
    Ws, Wt, Wr : weight
        As in :class:`CascadeRP`.

    Returns
    -------
    CascadeRP
        The interconnection as a function of the gains.
    """
    return CascadeRP(G, Ws, Wt, Wr)


@dataclass
class ScaledChannel:
    """theta -> diag(D, I) N(theta) diag(D^-1, I) / norm (a tuner channel, picklable when
    ``rp`` is).

    Parameters
    ----------
    rp : callable
        theta -> (A, B, C, D) of N (uncertainty channel first).
    D : RationalScaling
        The scaling.
    norm : float, optional
        Divides the system (the K step's normalisation), > 0.
    """

    rp: Callable[[NDArray[np.float64]], StateSpaceData]
    D: RationalScaling
    norm: float = 1.0

    def __call__(self, theta: NDArray[np.float64]) -> StateSpaceData:
        A, B, C, D = scaled_system(self.rp(theta), self.D)
        return A, B, C / self.norm, D / self.norm


@dataclass
class Normalised:
    """theta -> channel(theta) / norm: a requirement channel of the K step, divided by
    max(1, its norm at the start) so a requirement met there stays met and an unmet one
    does not get worse (picklable when ``channel`` is).

    Parameters
    ----------
    channel : callable
        theta -> (A, B, C, D) (or any LTI :func:`as_state_space` takes).
    norm : float
        The divisor, > 0.
    """

    channel: Callable[[NDArray[np.float64]], Any]
    norm: float

    def __call__(self, theta: NDArray[np.float64]) -> StateSpaceData:
        A, B, C, D = as_state_space(self.channel(theta))
        return A, B, C / self.norm, D / self.norm


# ------------------------------------------------------------------------------------------
# the iteration
# ------------------------------------------------------------------------------------------


@dataclass(frozen=True)
class DKStep:
    """One D-K iteration (iteration 0: the starting gains, no K step).

    Parameters
    ----------
    index : int
        0 for theta_0, then 1, 2, ...
    theta : ndarray of float
        The gains after this K step.
    mu_peak : float
        Peak over the grid of mu_hat at ``theta`` (exact D step).
    mu_peak_rad_s : float
        Frequency of that peak [rad/s].
    scaling : RationalScaling or None
        The D(s) the K step used (None for iteration 0).
    scaled_norm_before, scaled_norm_after : float
        ||D N D^-1||_inf at the previous and at the new gains (nan for iteration 0).
    requirement_norms : tuple of float
        The requirement channels' H-infinity norms at ``theta`` (unnormalised).
    message : str
        The tuner's closing message.
    """

    index: int
    theta: NDArray[np.float64]
    mu_peak: float
    mu_peak_rad_s: float
    scaling: RationalScaling | None
    scaled_norm_before: float
    scaled_norm_after: float
    requirement_norms: tuple[float, ...]
    message: str = ""

    def to_dict(self) -> dict[str, Any]:
        """The step as a JSON-ready dict.

        Returns
        -------
        dict of str to object
            The fields by name, gains as a list, the scaling as
            :meth:`RationalScaling.to_dict`.
        """
        return {"index": self.index, "theta": [float(x) for x in self.theta],
                "mu_peak": self.mu_peak, "mu_peak_rad_s": self.mu_peak_rad_s,
                "scaling": None if self.scaling is None else self.scaling.to_dict(),
                "scaled_norm_before": self.scaled_norm_before,
                "scaled_norm_after": self.scaled_norm_after,
                "requirement_norms": list(self.requirement_norms), "message": self.message}


@dataclass(frozen=True)
class DKResult:
    """Outcome of :func:`dk_iterate`.

    Parameters
    ----------
    theta : ndarray of float
        The best gains (smallest measured peak mu_hat).
    mu_peak : float
        Their peak mu_hat over the grid.
    steps : list of DKStep
        Every iteration, iteration 0 first.
    stop : str
        Why the iteration stopped.
    """

    theta: NDArray[np.float64]
    mu_peak: float
    steps: list[DKStep] = field(default_factory=list)
    stop: str = ""

    @property
    def start_mu_peak(self) -> float:
        """Peak mu_hat at theta_0."""
        return self.steps[0].mu_peak


@dataclass(frozen=True)
class MuProfile:
    """The D step of one interconnection at one set of gains (:func:`mu_profile`).

    Parameters
    ----------
    omegas : ndarray of float, shape (nw,)
        The frequency grid [rad/s].
    F : ndarray of complex, shape (nw, p, m)
        N(j w), uncertainty channel first.
    d, mu_hat, free : ndarray, shape (nw,)
        :func:`optimal_scalings` of ``F``.
    """

    omegas: NDArray[np.float64]
    F: NDArray[np.complex128]
    d: NDArray[np.float64]
    mu_hat: NDArray[np.float64]
    free: NDArray[np.bool_]

    @property
    def peak(self) -> tuple[float, float]:
        """(peak mu_hat over the grid, its frequency [rad/s])."""
        k = int(np.argmax(self.mu_hat))
        return float(self.mu_hat[k]), float(self.omegas[k])

    def scaling(self, order: int, refine: bool = True) -> RationalScaling:
        """The D(s) of the K step: :func:`fit_scaling` of d(w) (weights
        (mu_hat/peak)^4, zero where d is free), refined for the grid peak
        (:func:`refine_scaling`) when ``refine`` and ``order`` > 0.

        Parameters
        ----------
        order : {0, 1, 2}
            Order of D(s).
        refine : bool, optional
            Refine the fit for the grid peak of the scaled N.

        Returns
        -------
        RationalScaling
            Stable, minimum-phase D(s).
        """
        D = fit_scaling(self.omegas, self.d, order, _fit_weights(self.mu_hat, self.free))
        if refine and order > 0:
            D = refine_scaling(D, self.F, self.omegas)
        return D


def mu_profile(rp: Callable[[NDArray[np.float64]], StateSpaceData], theta: NDArray[np.float64],
               omegas: NDArray[np.float64]) -> MuProfile:
    """The exact D step of ``rp(theta)`` on ``omegas`` (:func:`optimal_scalings` of its
    frequency response).

    Parameters
    ----------
    rp : callable
        theta -> (A, B, C, D) of N, uncertainty channel first.
    theta : ndarray of float
        The gains.
    omegas : ndarray of float, shape (nw,)
        Frequencies [rad/s].

    Returns
    -------
    MuProfile
        Response, scalings, mu_hat and the free mask.
    """
    w = np.asarray(omegas, float)
    F = frequency_response(rp(theta), w)
    return MuProfile(w, F, *optimal_scalings(F))


def _fit_weights(mu: NDArray[np.float64], free: NDArray[np.bool_]) -> NDArray[np.float64]:
    wt = (mu / max(float(np.max(mu)), 1e-300)) ** 4
    wt[free] = 0.0
    if not np.any(wt > 0):
        wt = np.ones_like(mu)
    return wt


def dk_iterate(rp: Callable[[NDArray[np.float64]], StateSpaceData],
               parameters: Sequence[Parameter], theta0: Sequence[float] | NDArray[np.float64],
               *, requirements: Sequence[Callable[[NDArray[np.float64]], Any]] = (),
               order: int = 1, max_iter: int = 5, rel_tol: float = 0.01,
               omegas: NDArray[np.float64] | None = None, tune_iter: int | None = 40,
               refine: bool = True) -> DKResult:
    """D-K iteration with a fixed structure (module docstring).

    Parameters
    ----------
    rp : callable
        theta -> (A, B, C, D) of N, uncertainty channel first (e.g. :func:`cascade_rp`);
        picklable is not required (everything runs in this process).
    parameters : sequence of Parameter
        The tunable parameters with their bounds (their ``initial`` is replaced by the
        current gains at each K step).
    theta0 : array_like of float
        Starting gains; N(theta0) must be stable.
    requirements : sequence of callable, optional
        Further channels theta -> (A, B, C, D) kept in the K step (normalised by
        max(1, their norm at theta0), see the module docstring).
    order : {0, 1, 2}, optional
        Order of the fitted D(s).
    max_iter : int, optional
        Maximum number of D-K iterations (K steps), >= 1.
    rel_tol : float, optional
        Stop when the peak mu_hat falls by less than this fraction of the best so far.
    omegas : ndarray of float, optional
        Frequency grid [rad/s] of the D step and of the measured peak; default 121 points
        log-spaced over 1e-3..1e3.
    tune_iter : int or None, optional
        ``max_iter`` of each K step's tune (None: to convergence).
    refine : bool, optional
        Refine each fit for the grid peak of the scaled N (:func:`refine_scaling`).

    Returns
    -------
    DKResult
        Best gains, their peak mu_hat and the history.

    Raises
    ------
    ValueError
        For ``max_iter`` < 1, a negative ``rel_tol`` or an unstable N(theta0).
    """
    if max_iter < 1:
        raise ValueError(f"max_iter must be >= 1, got {max_iter}")
    if not rel_tol >= 0:
        raise ValueError(f"rel_tol must be >= 0, got {rel_tol}")
    w = np.logspace(-3, 3, 121) if omegas is None else np.asarray(omegas, float)
    params = list(parameters)
    theta = np.clip(np.asarray(theta0, float).reshape(-1),
                    [p.lower for p in params], [p.upper for p in params])
    A0 = as_state_space(rp(theta))[0]
    if A0.size and float(np.max(np.linalg.eigvals(A0).real)) >= 0:
        raise ValueError("N(theta0) is unstable: D-K iteration starts from stabilising gains")
    req_norm = [max(1.0, hinf_norm(r(theta)).value) for r in requirements]
    reqs = [Normalised(r, n) for r, n in zip(requirements, req_norm, strict=True)]

    def req_values(th: NDArray[np.float64]) -> tuple[float, ...]:
        return tuple(hinf_norm(r(th)).value for r in requirements)

    prof = mu_profile(rp, theta, w)
    steps = [DKStep(0, theta, *prof.peak, None, math.nan, math.nan, req_values(theta))]
    best = steps[0]
    stop = f"max_iter ({max_iter}) reached"
    for it in range(1, max_iter + 1):
        D = prof.scaling(order, refine)
        ch = ScaledChannel(rp, D)
        before = hinf_norm(ch(theta)).value
        ch = ScaledChannel(rp, D, before)
        ps = [Parameter(p.name, float(t), p.lower, p.upper, p.scale, p.sample_sd)
              for p, t in zip(params, theta, strict=True)]
        pb = TuningProblem(ps, [ch, *reqs], ["D N D^-1", *(f"req{i}" for i in range(len(reqs)))])
        res = tune(pb, n_starts=0, max_iter=tune_iter)
        th = np.asarray(res.theta, float)
        after = hinf_norm(ScaledChannel(rp, D)(th)).value
        prof = mu_profile(rp, th, w)
        step = DKStep(it, th, *prof.peak, D, before, after, req_values(th), res.message)
        steps.append(step)
        theta = th
        if step.mu_peak < best.mu_peak * (1.0 - rel_tol):
            best = step
            continue
        if step.mu_peak < best.mu_peak:
            best = step
        stop = (f"peak mu fell by less than {rel_tol:.0%} (iteration {it}: "
                f"{step.mu_peak:.4f}, best {best.mu_peak:.4f})")
        break
    return DKResult(best.theta, best.mu_peak, steps, stop)

"""Structured (fixed-order, fixed-structure) H-infinity tuning (MATLAB ``hinfstruct``/``systune``).

Problem (paper eqs. 7-8, multi-model form): given tunable parameters theta (controller
gains, filter constants, ...) and closed-loop "channels" T_i(s; theta) (for example the
weighted mixed-sensitivity stack [Ws S; Wt T; Wr R] of eq. 8 for each design model),

    minimise_theta  f(theta) = max_i ||T_i(theta)||_inf
    subject to      every channel realisation internally stable, lower <= theta <= upper.

f is nonsmooth (max over channels and frequencies) and +inf where a channel is unstable.
The local solver is a frequency-exchange / nonsmooth-aware trust-region method:

1. at the iterate theta_k the exact norms are computed with
   :func:`vtolftc.synthesis.hinfnorm.hinf_norm`; each channel's peak frequency (and secondary local
   maxima of sigma_max on a coarse grid) is added to a growing frequency set Omega_i;
2. the local minimax sub-problem over (channels x Omega_i)

       min_{theta, t} t  s.t.  sigma_max(T_i(j w; theta)) <= t  (w in Omega_i),
                               spectral abscissa(A_i(theta)) <= -margin,
                               |theta - theta_k| <= Delta (scaled), bounds,

   is solved in epigraph form by SLSQP with exact gradients of sigma_max from its singular
   vectors, d sigma = Re(u^H dT v), dT = dC X + C R dA X + C R dB + dD
   (R = (j w I - A)^-1, X = R B), the state-space derivatives being taken by central
   differences of the channel matrices (single-input channels through the compiled kernel
   of :mod:`vtolftc.synthesis.freq_kernel`, which needs only the vectors u^H C R and X v);
3. the candidate is re-verified with the exact H-infinity norm: it is accepted on
   sufficient decrease (trust radius expanded) or rejected (radius shrunk; the new peak
   frequencies still enrich Omega).

Unstable starting points are first stabilised by minimising the largest spectral abscissa
over the channels (Nelder-Mead), and reported clearly if that fails. Several random starts
(seeded with ``numpy.random.SeedSequence.spawn``, so results do not depend on execution
order and can be run through any ``map`` such as ``ProcessPoolExecutor.map``) are
supported. A local method: the result is a local optimum, as with ``systune``.

Mixed-sensitivity helpers (:func:`closed_loops`, :func:`mixed_sensitivity`,
:func:`mixed_sensitivity_channel`) build S, T, R of eq. 4 and the stacked channel of eq. 8
directly with numpy (fast enough to be called inside the optimiser).
"""

from __future__ import annotations

import math
import time
from collections.abc import Callable, Iterable, Sequence
from dataclasses import dataclass, field, replace
from typing import Any

import numpy as np
from numpy.typing import NDArray
from scipy.linalg import lapack
from scipy.optimize import minimize

from vtolftc.synthesis.freq_kernel import siso_sigma, siso_sigma_grad
from vtolftc.synthesis.hinfnorm import StateSpaceData, as_state_space, hinf_norm
from vtolftc.synthesis.nsbfgs import nonsmooth_bfgs

__all__ = [
    "Channel",
    "Parameter",
    "Progress",
    "StartAnchor",
    "StartRecord",
    "TunableSystem",
    "TuneResult",
    "TuningProblem",
    "closed_loops",
    "collect_starts",
    "mixed_sensitivity",
    "mixed_sensitivity_channel",
    "pid",
    "run_start",
    "start_anchor",
    "start_jobs",
    "tune",
]

Channel = Callable[[NDArray[np.float64]], Any]
"""A channel maps theta to a state-space (A, B, C, D) tuple or a python-control LTI object.

The state dimension (and input/output sizes) must not depend on theta."""


# ------------------------------------------------------------------------------------------
# problem definition
# ------------------------------------------------------------------------------------------


@dataclass(frozen=True)
class Parameter:
    """A tunable scalar: name, initial value, bounds and a typical magnitude.

    Parameters
    ----------
    name : str
        Name (unique within a problem).
    initial : float
        Initial value (the first start of :func:`tune`), in the parameter's own unit.
    lower, upper : float
        Bounds; use ``lower=0`` for gains that must stay non-negative.
    scale : float, optional
        Unit of the optimiser's step and of random restarts; by default max(|initial|, 1e-3)
        if initial != 0, else 1.
    sample_sd : float, optional
        If given, random starts are initial + sample_sd N(0, 1) (clipped to the bounds), e.g.
        a gain scale derived from the plant (:mod:`vtolftc.synthesis.blocks`); otherwise see
        :func:`tune`'s ``spread``.

    Raises
    ------
    ValueError
        For bounds that do not contain the initial value, or a non-positive scale.
    """

    name: str
    initial: float
    lower: float = -math.inf
    upper: float = math.inf
    scale: float | None = None
    sample_sd: float | None = None

    def __post_init__(self) -> None:
        if not (self.lower <= self.initial <= self.upper):
            raise ValueError(
                f"parameter {self.name!r}: initial value {self.initial} is outside its bounds "
                f"[{self.lower}, {self.upper}]"
            )
        if self.scale is not None and not (self.scale > 0 and math.isfinite(self.scale)):
            raise ValueError(f"parameter {self.name!r}: scale must be > 0, got {self.scale}")
        if self.sample_sd is not None and not (
            self.sample_sd > 0 and math.isfinite(self.sample_sd)
        ):
            raise ValueError(
                f"parameter {self.name!r}: sample_sd must be > 0, got {self.sample_sd}"
            )

    @property
    def typical(self) -> float:
        """Magnitude that scales this parameter in the optimiser.

        ``scale`` if given, else ``|initial|`` (at least 1e-3), and 1 when ``initial`` is 0.
        """
        if self.scale is not None:
            return float(self.scale)
        return max(abs(self.initial), 1e-3) if self.initial != 0 else 1.0


@dataclass
class TuningProblem:
    """Structured H-infinity problem: minimise max_i ||channel_i(theta)||_inf (eq. 7-8).

    Parameters
    ----------
    parameters : sequence of Parameter
        The tunable parameters (order defines theta).
    channels : sequence of callable
        Callables theta -> (A, B, C, D) (or python-control LTI) of weighted closed loops.
        One channel per design model / requirement; the objective is their max.
    channel_names : sequence of str, optional
        Labels for reporting.
    stability_margin : float
        Required decay rate (1/s): every channel's A must have eigenvalues with real part
        < -stability_margin. 0 means plain (strict) internal stability.
    realizer : callable, optional
        theta -> every channel's (A, B, C, D), equal bit for bit to
        ``[as_state_space(c(theta)) for c in channels]`` and raising where that raises
        (a faster path for channels that share work, e.g.
        :class:`~vtolftc.synthesis.surfaces.SurfaceRealizer`); None: channel by channel.

    Raises
    ------
    ValueError
        Without parameters or channels, for a channel that is not callable, duplicate
        parameter names or a negative stability margin.
    """

    parameters: Sequence[Parameter]
    channels: Sequence[Channel]
    channel_names: Sequence[str] | None = None
    stability_margin: float = 0.0
    realizer: Callable[[NDArray[np.float64]], list[StateSpaceData]] | None = None

    def __post_init__(self) -> None:
        self.parameters = list(self.parameters)
        self.channels = list(self.channels)
        if not self.parameters:
            raise ValueError("at least one Parameter is required")
        if not self.channels:
            raise ValueError("at least one channel is required")
        for c in self.channels:
            if not callable(c):
                raise ValueError(f"channels must be callables theta -> (A, B, C, D), got {c!r}")
        names = [p.name for p in self.parameters]
        if len(set(names)) != len(names):
            raise ValueError(f"parameter names must be unique, got {names}")
        if self.channel_names is None:
            self.channel_names = [f"channel{i}" for i in range(len(self.channels))]
        elif len(self.channel_names) != len(self.channels):
            raise ValueError(
                f"{len(self.channel_names)} channel names given for {len(self.channels)} channels"
            )
        if self.stability_margin < 0:
            raise ValueError(f"stability_margin must be >= 0, got {self.stability_margin}")

    @property
    def names(self) -> list[str]:
        """Names of the tunable parameters, in vector order."""
        return [p.name for p in self.parameters]

    @property
    def initial(self) -> NDArray[np.float64]:
        """Initial parameter vector."""
        return np.array([p.initial for p in self.parameters], dtype=float)

    @property
    def lower(self) -> NDArray[np.float64]:
        """Lower bounds of the parameter vector."""
        return np.array([p.lower for p in self.parameters], dtype=float)

    @property
    def upper(self) -> NDArray[np.float64]:
        """Upper bounds of the parameter vector."""
        return np.array([p.upper for p in self.parameters], dtype=float)

    @property
    def scales(self) -> NDArray[np.float64]:
        """Typical magnitude of each parameter (see :attr:`Parameter.typical`)."""
        return np.array([p.typical for p in self.parameters], dtype=float)

    def realize(self, theta: NDArray[np.float64]) -> list[StateSpaceData]:
        """State-space data (A, B, C, D) of every channel at theta.

        Parameters
        ----------
        theta : ndarray of float, shape (n_params,)
            The parameter values.

        Returns
        -------
        list of tuple of ndarray
            One (A, B, C, D) per channel.
        """
        theta = self._check_theta(theta)
        if self.realizer is not None:
            return self.realizer(theta)
        return [as_state_space(c(theta)) for c in self.channels]

    def channel_norms(self, theta: NDArray[np.float64]) -> NDArray[np.float64]:
        """||channel_i(theta)||_inf for every channel.

        Parameters
        ----------
        theta : ndarray of float, shape (n_params,)
            The parameter values.

        Returns
        -------
        ndarray of float, shape (n_channels,)
            The norms (inf if unstable or the stability margin is violated).
        """
        out = []
        for A, B, C, D in self.realize(theta):
            if self.stability_margin > 0 and A.size and (
                np.max(np.linalg.eigvals(A).real) >= -self.stability_margin
            ):
                out.append(math.inf)
            else:
                out.append(hinf_norm((A, B, C, D)).value)
        return np.array(out)

    def objective(self, theta: NDArray[np.float64]) -> float:
        """max_i ||channel_i(theta)||_inf (the gamma of eq. 8).

        Parameters
        ----------
        theta : ndarray of float, shape (n_params,)
            The parameter values.

        Returns
        -------
        float
            The objective.
        """
        return float(np.max(self.channel_norms(theta)))

    def _check_theta(self, theta: NDArray[np.float64]) -> NDArray[np.float64]:
        theta = np.asarray(theta, dtype=float).reshape(-1)
        if theta.size != len(self.parameters):
            raise ValueError(
                f"theta has {theta.size} entries, expected {len(self.parameters)} "
                f"({self.names})"
            )
        return theta


TunableSystem = TuningProblem
"""Alias (MATLAB vocabulary)."""


@dataclass(frozen=True)
class StartRecord:
    """Outcome of one local run of :func:`tune`.

    Parameters
    ----------
    index : int
        Start index (0 = the initial point).
    theta0, theta : ndarray of float, shape (n_params,)
        Start and final points.
    value : float
        Final objective.
    history : list of float
        Objective after each accepted step.
    iterations : int
        Outer iterations run.
    status : str
        Why the run stopped.
    """

    index: int
    theta0: NDArray[np.float64]
    theta: NDArray[np.float64]
    value: float
    history: list[float]
    iterations: int
    status: str


@dataclass(frozen=True)
class TuneResult:
    """Best point over all starts of :func:`tune`.

    Parameters
    ----------
    theta : ndarray of float, shape (n_params,)
        The best point.
    names : list of str
        Parameter names, in theta's order.
    value : float
        The achieved max_i ||channel_i||_inf (inf if no stabilising point was found), plus the
        regularisation penalty if any.
    channel_values : ndarray of float, shape (n_channels,)
        The per-channel norms.
    channel_names : list of str
        Channel labels.
    stable : bool
        Whether the best point stabilises every channel.
    starts : list of StartRecord
        The per-start records.
    message : str
        Summary (best start, stop reason).
    """

    theta: NDArray[np.float64]
    names: list[str]
    value: float
    channel_values: NDArray[np.float64]
    channel_names: list[str]
    stable: bool
    starts: list[StartRecord] = field(repr=False)
    message: str = ""

    @property
    def params(self) -> dict[str, float]:
        """Best theta as a name -> value dict."""
        return {n: float(v) for n, v in zip(self.names, self.theta, strict=True)}


# ------------------------------------------------------------------------------------------
# local solver
# ------------------------------------------------------------------------------------------


class _Evaluator:
    """Cached channel realisations, exact norms, frequency responses and derivatives."""

    def __init__(self, problem: TuningProblem):
        self.pb = problem
        self.p = len(problem.parameters)
        self.scales = problem.scales
        self._cache: dict[bytes, list[StateSpaceData]] = {}
        self._dcache: dict[bytes, list[list[StateSpaceData]]] = {}
        # the same derivatives stacked over the parameters, (p, ., .) per channel (when the
        # channels realise in batches), for the gradients' batched products
        self._dstack: dict[bytes, list[tuple[NDArray[np.float64], ...]] | None] = {}
        self.shapes: list[tuple[int, ...]] | None = None
        # SLSQP asks for the constraints and their Jacobian at the same point (in either
        # order): the frequency responses, SVDs and eigen-decompositions of the last few
        # points are kept so the second call reuses them (same numbers, computed once)
        self._fcache: dict[bytes, list[tuple[Any, ...] | None]] = {}
        self.compiled = True
        self._ecache: dict[bytes, list[tuple[Any, ...] | None]] = {}
        self._vcache: dict[bytes, NDArray[np.float64]] = {}
        # derivatives by the chain rule through a realizer's local parameters (a surface
        # problem's five gains per grid point) when there are fewer of them than of theta
        rz = problem.realizer
        self.chain_rule = (hasattr(rz, "gain_derivatives") and getattr(rz, "chain_rule", True)
                           and getattr(rz, "n_local", self.p) < self.p)
        self._chcache: dict[bytes, list[tuple[Any, NDArray[np.float64]]] | None] = {}

    def realize(self, theta: NDArray[np.float64]) -> list[StateSpaceData]:
        key = theta.tobytes()
        r = self._cache.get(key)
        if r is None:
            r = self.pb.realize(theta)
            shapes = [(A.shape[0], *D.shape) for A, _, _, D in r]
            if self.shapes is None:
                self.shapes = shapes
            elif shapes != self.shapes:
                raise ValueError(
                    f"channel dimensions changed with theta: {shapes} vs {self.shapes} "
                    "(n_states, n_outputs, n_inputs); channels must have fixed dimensions"
                )
            if len(self._cache) > 4096:
                self._cache.clear()
            self._cache[key] = r
        return r

    def derivatives(self, theta: NDArray[np.float64]) -> list[list[StateSpaceData]]:
        """d(A, B, C, D)/d theta_k by central differences, per channel, per parameter."""
        key = theta.tobytes()
        r = self._dcache.get(key)
        if r is not None:
            return r
        stacks = self.derivative_stacks(theta)
        if stacks is None:
            out = self._derivatives_loop(theta)
        else:
            out = [[tuple(d[k] for d in st) for k in range(self.p)]  # type: ignore[misc]
                   for st in stacks]
        if len(self._dcache) > 1024:
            self._dcache.clear()
        self._dcache[key] = out
        return out

    def chain(self, theta: NDArray[np.float64],
              ) -> list[tuple[Any, NDArray[np.float64]]] | None:
        """Per channel ((dA, dB, dC, dD) over the realizer's q local parameters, each
        (q, ., .); J (q, p) their Jacobian in theta), or None (no chain rule: ``chain_rule``
        off, or a perturbed realisation not finite)."""
        if not self.chain_rule:
            return None
        key = theta.tobytes()
        if key in self._chcache:
            return self._chcache[key]
        r = self.pb.realizer.gain_derivatives(theta, self.scales)  # type: ignore[union-attr]
        if len(self._chcache) > 1024:
            self._chcache.clear()
        self._chcache[key] = r
        return r

    def derivative_stacks(self, theta: NDArray[np.float64],
                          ) -> list[tuple[NDArray[np.float64], ...]] | None:
        """:meth:`derivatives` stacked over the parameters: per channel (dA, dB, dC, dD),
        each (p, ., .); None when the channels are differentiated one point at a time
        (no ``realize_batch``, or a perturbed realisation not finite). The per-parameter
        lists of :meth:`derivatives` are only built when asked for (the same arrays)."""
        key = theta.tobytes()
        if key in self._dstack:
            return self._dstack[key]
        ch = self.chain(theta)
        if ch is not None:  # d X / d theta_k = sum_j J[j, k] d X / d g_j
            stacks = [tuple(np.tensordot(J.T, X, axes=1) for X in d) for d, J in ch]
        else:
            stacks = self._derivatives_batch(theta)
        if len(self._dstack) > 1024:
            self._dstack.clear()
        self._dstack[key] = stacks
        return stacks

    def _derivatives_batch(self, theta: NDArray[np.float64],
                           ) -> list[tuple[NDArray[np.float64], ...]] | None:
        """:meth:`_derivatives_loop` through the channels' ``realize_batch`` (all 2p
        perturbed points of a channel in one call): the same perturbed points, the same
        element operations, hence the same numbers bit for bit. None when a channel has no
        ``realize_batch`` or a perturbed realisation is not finite (the loop then raises
        as :meth:`realize` does)."""
        chans = self.pb.channels
        if not all(hasattr(c, "realize_batch") for c in chans):
            return None
        p = self.p
        hs = [1e-6 * max(abs(theta[k]), self.scales[k]) for k in range(p)]
        pts = np.repeat(theta[None, :], 2 * p, axis=0)
        for k, h in enumerate(hs):
            pts[2 * k, k] += h
            pts[2 * k + 1, k] -= h
        h2 = (2 * np.array(hs))[:, None, None]
        out: list[tuple[NDArray[np.float64], ...]] = []
        batch = getattr(self.pb.realizer, "batch", None)
        every = batch(pts) if batch is not None else None  # the same, with shared work
        for i, c in enumerate(chans):
            mats = c.realize_batch(pts) if every is None else every[i]
            ders = []
            for X in mats:
                if not np.isfinite(X).all():
                    return None
                ders.append((X[0::2] - X[1::2]) / h2)
            out.append(tuple(ders))
        return out

    def _derivatives_loop(self, theta: NDArray[np.float64]) -> list[list[StateSpaceData]]:
        """Central differences, one realisation of every channel per perturbed point."""
        per_param: list[list[StateSpaceData]] = []
        for k in range(self.p):
            h = 1e-6 * max(abs(theta[k]), self.scales[k])
            tp, tm = theta.copy(), theta.copy()
            tp[k] += h
            tm[k] -= h
            rp, rm = self.realize(tp), self.realize(tm)
            per_param.append(
                [
                    tuple((xp - xm) / (2 * h) for xp, xm in zip(sp, sm, strict=True))
                    for sp, sm in zip(rp, rm, strict=True)
                ]  # type: ignore[misc]
            )
        return [[per_param[k][i] for k in range(self.p)] for i in range(len(self.pb.channels))]

    def exact(self, theta: NDArray[np.float64]) -> tuple[NDArray[np.float64], list[float]]:
        vals, peaks = [], []
        margin = self.pb.stability_margin
        for A, B, C, D in self.realize(theta):
            if margin > 0 and A.size and np.max(np.linalg.eigvals(A).real) >= -margin:
                vals.append(math.inf)
                peaks.append(math.nan)
                continue
            r = hinf_norm((A, B, C, D))
            vals.append(r.value)
            peaks.append(r.peak_frequency_rad_s)
        return np.array(vals), peaks

    def abscissa(self, theta: NDArray[np.float64]) -> float:
        return max(
            (float(np.max(np.linalg.eigvals(A).real)) if A.size else -math.inf)
            for A, _, _, _ in self.realize(theta)
        )

    def _responses(
        self, theta: NDArray[np.float64], omegas: list[NDArray[np.float64]]
    ) -> list[tuple[Any, ...] | None]:
        """Per channel (Z, X, T, U, s, Vh, finite) at ``omegas[i]`` (None: no frequency)."""
        key = theta.tobytes() + b"".join(
            np.asarray(w.size, np.int64).tobytes() + w.tobytes() for w in omegas
        )
        r = self._fcache.get(key)
        if r is not None:
            return r
        sys = self.realize(theta)
        r = []
        for i, (A, B, C, D) in enumerate(sys):
            w = omegas[i]
            if w.size == 0:
                r.append(None)
                continue
            n = A.shape[0]
            finite = np.isfinite(w)
            wf = np.where(finite, w, 0.0)
            if n:
                Z = 1j * wf[:, None, None] * np.eye(n) - A
                X = np.linalg.solve(Z, np.broadcast_to(B, (w.size, *B.shape)))
                T = C @ X + D
            else:
                Z = X = None
                T = np.broadcast_to(D.astype(complex), (w.size, *D.shape)).copy()
            T[~finite] = D
            U, s, Vh = np.linalg.svd(T)
            r.append((Z, X, T, U, s, Vh, finite))
        if len(self._fcache) >= 4:
            self._fcache.clear()
        self._fcache[key] = r
        return r

    def sigma_and_grad(
        self, theta: NDArray[np.float64], omegas: list[NDArray[np.float64]], grad: bool
    ) -> tuple[NDArray[np.float64], NDArray[np.float64] | None]:
        """sigma_max(T_i(j w)) for all (i, w in omegas[i]) and its theta-gradient.

        Single-input channels go through the compiled kernel of
        :mod:`vtolftc.synthesis.freq_kernel` (``compiled``, the default), the others (and
        every channel with ``compiled = False``) through :meth:`_sigma_and_grad_numpy`;
        the two agree to round-off (tested)."""
        sys = self.realize(theta)
        if not self.compiled or any(B.shape[1] != 1 for _, B, _, _ in sys):
            return self._sigma_and_grad_numpy(theta, omegas, grad)
        dstk = None
        ch = self.chain(theta) if grad else None
        if grad and ch is None:
            dstk = self.derivative_stacks(theta)
            if dstk is None:
                dsys = self.derivatives(theta)
                dstk = [tuple(np.stack([d[k][m] for k in range(self.p)]) for m in range(4))
                        for d in dsys]
        sig_all, grad_all = [], []
        for i, (A, B, C, D) in enumerate(sys):
            w = omegas[i]
            if w.size == 0:
                continue
            if ch is not None:  # the gradient in the local parameters, then J
                s, g = siso_sigma_grad(A, B, C, D, w, *ch[i][0])
                sig_all.append(s)
                grad_all.append(g @ ch[i][1])
            elif dstk is None:
                sig_all.append(siso_sigma(A, B, C, D, w))
            else:
                s, g = siso_sigma_grad(A, B, C, D, w, *dstk[i])
                sig_all.append(s)
                grad_all.append(g)
        sig = np.concatenate(sig_all) if sig_all else np.zeros(0)
        gr = np.concatenate(grad_all, axis=0) if grad and grad_all else None
        return sig, gr

    def _sigma_and_grad_numpy(
        self, theta: NDArray[np.float64], omegas: list[NDArray[np.float64]], grad: bool
    ) -> tuple[NDArray[np.float64], NDArray[np.float64] | None]:
        """:meth:`sigma_and_grad` with numpy: batched solves, an SVD of T and the full
        dT_k products (any number of inputs)."""
        sys = self.realize(theta)
        resp = self._responses(theta, omegas)
        dstk = self.derivative_stacks(theta) if grad else None
        dsys = self.derivatives(theta) if grad and dstk is None else None
        sig_all, grad_all = [], []
        for i, (A, _, C, _) in enumerate(sys):
            ri = resp[i]
            if ri is None:
                continue
            w = omegas[i]
            n = A.shape[0]
            Z, X, T, U, s, Vh, finite = ri
            sig_all.append(s[:, 0])
            if not grad:
                continue
            u = U[:, :, 0]
            v = Vh[:, 0, :].conj()
            g = np.zeros((w.size, self.p))
            if n:
                # CR = C (jwI - A)^-1  (rows), via the transposed solve
                CR = np.swapaxes(
                    np.linalg.solve(
                        np.swapaxes(Z, 1, 2), np.broadcast_to(C.T, (w.size, *C.T.shape))
                    ),
                    1,
                    2,
                )
                CR[~finite] = 0.0
                X = X.copy()
                X[~finite] = 0.0
            uc = u.conj()
            if dstk is not None:
                # all parameters at once: the same products slice by slice (stacked matmul)
                sA, sB, sC, sD = dstk[i]
                dTs = np.broadcast_to(sD.astype(complex)[:, None], (self.p, *T.shape)).copy()
                if n:
                    dTs += sC[:, None] @ X[None] + CR[None] @ (sA[:, None] @ X[None]) \
                        + CR[None] @ sB[:, None]
                for k in range(self.p):
                    g[:, k] = np.real(np.einsum("wi,wij,wj->w", uc, dTs[k], v))
                grad_all.append(g)
                continue
            assert dsys is not None
            for k in range(self.p):
                dA, dB, dC, dD = dsys[i][k]
                dT = np.broadcast_to(dD.astype(complex), T.shape).copy()
                if n:
                    dT += dC @ X + CR @ (dA @ X) + CR @ dB
                g[:, k] = np.real(np.einsum("wi,wij,wj->w", uc, dT, v))
            grad_all.append(g)
        sig = np.concatenate(sig_all) if sig_all else np.zeros(0)
        gr = np.concatenate(grad_all, axis=0) if grad and grad_all else None
        return sig, gr

    def abscissa_and_grad(
        self, theta: NDArray[np.float64], grad: bool = True
    ) -> tuple[NDArray[np.float64], NDArray[np.float64] | None]:
        """Spectral abscissa of every channel's A and (``grad``) its generalised gradient."""
        sys = self.realize(theta)
        key = theta.tobytes()
        eigs = self._ecache.get(key)
        if eigs is None and not grad:
            # the values alone: no eigenvectors (LAPACK gives the same eigenvalues, bit for
            # bit); SLSQP asks for the constraints at about three times as many points as
            # for their Jacobian
            vals = self._vcache.get(key)
            if vals is None:
                vals = np.array([_rightmost_real(A) if A.size else -1e6 for A, _, _, _ in sys])
                if len(self._vcache) >= 4:
                    self._vcache.clear()
                self._vcache[key] = vals
            return vals.copy(), None
        if eigs is None:
            eigs = []
            for A, _, _, _ in sys:
                if A.size == 0:
                    eigs.append(None)
                    continue
                eigs.append(_rightmost_eig(A))
            if len(self._ecache) >= 4:
                self._ecache.clear()
            self._ecache[key] = eigs
        vals = np.full(len(sys), -1e6)
        for i, e in enumerate(eigs):
            if e is not None:
                vals[i] = e[0].real
        if not grad:
            return vals, None
        ch = self.chain(theta)
        dstk = self.derivative_stacks(theta) if ch is None else [d for d, _ in ch]
        dsys = self.derivatives(theta) if dstk is None else None
        grads = np.zeros((len(sys), self.p))
        for i, e in enumerate(eigs):
            if e is None:
                continue
            _, y, x = e
            den = np.vdot(y, x)
            if abs(den) < 1e-14:
                continue
            # dA_k x for every k: one stacked product when the derivatives are stacked
            dAx = (dstk[i][0] @ x if dstk is not None
                   else [dsys[i][k][0] @ x for k in range(self.p)])  # type: ignore[index]
            # the same complex quotient per k as float(np.real(...)), less call overhead
            gi = [(np.vdot(y, v) / den).real for v in dAx]
            grads[i] = gi if ch is None else np.asarray(gi) @ ch[i][1]
        return vals, grads


_GEEV_LWORK: dict[int, int] = {}


def _geev_lwork(n: int) -> int:
    lwork = _GEEV_LWORK.get(n)
    if lwork is None:
        lwork = _GEEV_LWORK[n] = int(lapack.dgeev_lwork(n, compute_vl=1, compute_vr=1)[0])
    return lwork


def _rightmost_real(A: NDArray[np.float64]) -> float:
    """The largest real part of the eigenvalues of A (the spectral abscissa): the real part
    of :func:`_rightmost_eig`'s eigenvalue, bit for bit (the same LAPACK dgeev with the same
    workspace, without the eigenvectors: the Hessenberg QR iteration does the same
    arithmetic on the active block either way, tested)."""
    if not np.isfinite(A).all():
        raise ValueError("array must not contain infs or NaNs")
    wr, _, _, _, info = lapack.dgeev(A, compute_vl=0, compute_vr=0,
                                     lwork=_geev_lwork(A.shape[0]))
    if info > 0:
        raise np.linalg.LinAlgError("eig algorithm (geev) did not converge")
    return max(wr.tolist())


def _rightmost_eig(A: NDArray[np.float64]) -> tuple[complex, NDArray[Any], NDArray[Any]]:
    """(lambda, left eigenvector, right eigenvector) of the eigenvalue of A with the largest
    real part: what ``scipy.linalg.eig(A, left=True, right=True)`` gives for that column, bit
    for bit (the same LAPACK dgeev call with the same workspace; the complex vector of only
    that column built as scipy builds them; real vectors when every eigenvalue is real),
    without the per-call overhead of the wrapper (about two thirds of its time at n = 13)."""
    if not np.isfinite(A).all():
        raise ValueError("array must not contain infs or NaNs")
    n = A.shape[0]
    wr, wi, vl, vr, info = lapack.dgeev(A, compute_vl=1, compute_vr=1, lwork=_geev_lwork(n))
    if info > 0:
        raise np.linalg.LinAlgError("eig algorithm (geev) did not converge")
    # python scalars from here: numpy's per-call overhead on 13-vectors is most of the time
    re, im = wr.tolist(), wi.tolist()
    j = max(range(n), key=re.__getitem__)  # the first largest, as numpy.argmax
    lam = re[j] + 1j * im[j]
    if not any(im):
        return lam, vl[:, j], vr[:, j]
    m = [x > 0 for x in im]
    for i in range(n - 1):  # scipy's workaround for a LAPACK bug (its ticket #709)
        m[i] = m[i] or im[i + 1] < 0
    if any(m[i] and m[i + 1] for i in range(n - 1)):  # chained pairs: scipy's construction
        from scipy.linalg._decomp import _make_complex_eigvecs

        w = wr + 1j * wi
        return (lam, _make_complex_eigvecs(w, vl, w.dtype.char)[:, j],
                _make_complex_eigvecs(w, vr, w.dtype.char)[:, j])

    def column(v: NDArray[np.float64]) -> NDArray[np.complex128]:
        if m[j]:
            return v[:, j] + 1j * v[:, j + 1]
        if j > 0 and m[j - 1]:
            return np.conj(v[:, j - 1] + 1j * v[:, j])
        return v[:, j].astype(complex)

    return lam, column(vl), column(vr)


def _grid_peaks(A: NDArray[Any], B: NDArray[Any], C: NDArray[Any], D: NDArray[Any],
                level: float, npts: int = 60) -> list[float]:
    """Local maxima of sigma_max on a coarse log grid that exceed ``level``."""
    n = A.shape[0]
    if n == 0:
        return []
    mags = np.abs(np.linalg.eigvals(A))
    mags = mags[mags > 0]
    if mags.size == 0:
        return []
    w = np.geomspace(mags.min() / 20, mags.max() * 20, npts)
    Z = 1j * w[:, None, None] * np.eye(n) - A
    T = C @ np.linalg.solve(Z, np.broadcast_to(B, (w.size, *B.shape))) + D
    s = np.linalg.svd(T, compute_uv=False)[:, 0]
    idx = [j for j in range(1, npts - 1) if s[j] >= s[j - 1] and s[j] >= s[j + 1]]
    return [float(w[j]) for j in idx if s[j] >= level]


def _same_freq(w1: float, w2: float) -> bool:
    if math.isinf(w1) or math.isinf(w2):
        return w1 == w2
    return abs(w1 - w2) <= 1e-6 * max(abs(w1), abs(w2), 1e-9)


INNER_FTOL = 1e-10
"""Default tolerance of each trust-region step's SLSQP subproblem, relative to the current
objective (:func:`tune`'s ``inner_ftol``)."""

ITER_CAP = 1000
"""Safety cap on the iterations of one start when :func:`tune` runs to convergence
(``max_iter=None``): the stationarity and progress tests below stop well before it."""

PROGRESS_WINDOW = 15
PROGRESS_TOL = 1e-4
"""With ``max_iter=None`` a start also stops when its objective fell by less than
PROGRESS_TOL (relative) over the last PROGRESS_WINDOW iterations (no progress)."""


@dataclass
class _Options:
    max_iter: int
    tol: float
    max_freqs: int
    trust_radius: float
    stabilize_maxfev: int
    deadline: float | None = None  # time.monotonic() value
    regularization: float = 0.0
    progress: Callable[[Progress], None] | None = None
    t_start: float = 0.0
    interrupted: bool = False
    to_convergence: bool = False  # max_iter=None: stop on stationarity / progress
    inner_ftol: float = INNER_FTOL  # SLSQP's ftol relative to the objective, per step


@dataclass(frozen=True)
class Progress:
    """What :func:`tune`'s ``progress`` callback receives after each accepted step.

    Parameters
    ----------
    start : int
        Index of the start (0 = the initial point).
    iteration : int
        Iteration within the start.
    value : float
        The start's current objective (max norm, plus the regularisation if any).
    theta : ndarray of float, shape (n_params,)
        Its current point.
    elapsed_s : float
        Seconds (wall clock) since :func:`tune` was called.
    """

    start: int
    iteration: int
    value: float
    theta: NDArray[np.float64]
    elapsed_s: float


def _reg(theta: NDArray[np.float64], s: NDArray[np.float64], rho: float) -> float:
    return rho * float(np.sum((theta / s) ** 2)) if rho > 0 else 0.0


def _stabilize(
    ev: _Evaluator, theta: NDArray[np.float64], lo: NDArray[np.float64],
    hi: NDArray[np.float64], opts: _Options,
) -> tuple[NDArray[np.float64], bool]:
    """Minimise the largest spectral abscissa until every channel is stable (phase 1)."""
    target = -max(ev.pb.stability_margin, 0.0) - 1e-6
    s = ev.scales

    class _DoneError(Exception):
        pass

    found: list[NDArray[np.float64]] = []

    def to_theta(x: NDArray[np.float64]) -> NDArray[np.float64]:
        return np.clip(theta + s * x, lo, hi)

    def fun(x: NDArray[np.float64]) -> float:
        th = to_theta(x)
        try:
            a = ev.abscissa(th)
        except (np.linalg.LinAlgError, ValueError):
            return 1e300
        if a < target and math.isfinite(float(np.max(ev.exact(th)[0]))):
            found.append(th)
            raise _DoneError
        return a

    p = theta.size
    for attempt in range(3):
        simplex = np.vstack([np.zeros(p), (0.5 * 2.0**attempt) * np.eye(p)])
        try:
            res = minimize(
                fun, np.zeros(p), method="Nelder-Mead",
                options={"maxfev": opts.stabilize_maxfev, "xatol": 1e-8, "fatol": 1e-10,
                         "initial_simplex": simplex},
            )
            theta = to_theta(res.x)
        except _DoneError:
            return found[-1], True
    return theta, False


def _local(
    ev: _Evaluator, theta0: NDArray[np.float64], opts: _Options, index: int = 0
) -> tuple[NDArray[np.float64], float, list[float], int, str]:
    pb = ev.pb
    lo, hi = pb.lower, pb.upper
    theta = np.clip(np.asarray(theta0, dtype=float), lo, hi)
    rho = opts.regularization
    s_reg = ev.scales
    vals, peaks = ev.exact(theta)
    f = float(np.max(vals)) + _reg(theta, s_reg, rho)
    history: list[float] = []
    if not math.isfinite(f):
        theta, ok = _stabilize(ev, theta, lo, hi, opts)
        if not ok:
            return theta, math.inf, [math.inf], 0, "unstable: no stabilising point found"
        vals, peaks = ev.exact(theta)
        f = float(np.max(vals)) + _reg(theta, s_reg, rho)
    history.append(f)
    nch = len(pb.channels)
    omegas: list[list[float]] = [[] for _ in range(nch)]

    def add_freqs(th: NDArray[np.float64], pk: list[float], level: float) -> None:
        sys = ev.realize(th)
        for i in range(nch):
            cand = [pk[i]] if math.isfinite(pk[i]) or pk[i] == math.inf else []
            cand += _grid_peaks(*sys[i], level=level)
            for wv in cand:
                if not any(_same_freq(wv, wo) for wo in omegas[i]):
                    omegas[i].append(wv)
            if len(omegas[i]) > opts.max_freqs:
                w = np.array(omegas[i])
                sig, _ = ev.sigma_and_grad(
                    th, [w if j == i else np.zeros(0) for j in range(nch)], False
                )
                keep = np.argsort(-sig)[: opts.max_freqs]
                omegas[i] = [omegas[i][j] for j in sorted(keep)]

    add_freqs(theta, peaks, 0.5 * f)
    radius = opts.trust_radius
    it = 0
    status = "max_iter reached" if not opts.to_convergence else "iteration cap reached"
    margin = pb.stability_margin
    f_iter = [f]  # objective after every iteration (accepted or not), for the progress test
    abs_target = -max(margin, 0.0) - 1e-9
    while it < opts.max_iter:
        if opts.deadline is not None and time.monotonic() >= opts.deadline:
            status = "time limit reached"
            break
        if opts.interrupted:
            status = "interrupted"
            break
        try:
            f_old = f
            stop, theta, f, peaks, radius, status = _step(
                ev, opts, theta, f, peaks, radius, omegas, add_freqs, abs_target, history,
                index, it + 1, status,
            )
            it += 1
            f_iter.append(f)
            if opts.progress is not None and f < f_old:
                opts.progress(Progress(index, it, f, theta.copy(),
                                       time.monotonic() - opts.t_start))
        except KeyboardInterrupt:
            opts.interrupted = True
            status = "interrupted"
            break
        if stop:
            break
        if (opts.to_convergence and it >= PROGRESS_WINDOW
                and f_iter[-1 - PROGRESS_WINDOW] - f <= PROGRESS_TOL * abs(f)):
            status = (f"converged (no progress: < {PROGRESS_TOL:g} relative decrease in "
                      f"{PROGRESS_WINDOW} iterations)")
            break
    return theta, f, history, it, status


def _step(
    ev: _Evaluator, opts: _Options, theta: NDArray[np.float64], f: float, peaks: list[float],
    radius: float, omegas: list[list[float]], add_freqs: Callable[..., None],
    abs_target: float, history: list[float], index: int, it: int, status: str,
) -> tuple[bool, NDArray[np.float64], float, list[float], float, str]:
    """One trust-region step of :func:`_local`; returns (stop, theta, f, peaks, radius, status)."""
    pb = ev.pb
    lo, hi = pb.lower, pb.upper
    p = theta.size
    nch = len(pb.channels)
    rho = opts.regularization
    s_reg = ev.scales
    W = [np.array(o) for o in omegas]
    th_k = theta.copy()
    s = np.maximum(ev.scales, np.abs(theta))  # relative trust region

    def unpack(
        y: NDArray[np.float64], th_k: NDArray[np.float64] = th_k, s: NDArray[np.float64] = s
    ) -> NDArray[np.float64]:
        return np.clip(th_k + s * y[:p], lo, hi)

    def cons_f(y: NDArray[np.float64], W: list[NDArray[np.float64]] = W) -> NDArray[np.float64]:
        th = unpack(y)
        sig, _ = ev.sigma_and_grad(th, W, False)
        a, _ = ev.abscissa_and_grad(th, grad=False)
        return np.concatenate([y[p] - sig, abs_target - a])

    def cons_j(
        y: NDArray[np.float64], W: list[NDArray[np.float64]] = W, s: NDArray[np.float64] = s
    ) -> NDArray[np.float64]:
        th = unpack(y)
        _, g = ev.sigma_and_grad(th, W, True)
        _, ga = ev.abscissa_and_grad(th)
        assert ga is not None
        rows = []
        if g is not None:
            rows.append(np.hstack([-g * s, np.ones((g.shape[0], 1))]))
        rows.append(np.hstack([-ga * s, np.zeros((ga.shape[0], 1))]))
        return np.vstack(rows)

    blo = np.maximum(-radius, (lo - th_k) / s)
    bhi = np.minimum(radius, (hi - th_k) / s)
    bounds = [(float(a), float(b)) for a, b in zip(blo, bhi, strict=True)] + [(None, None)]
    y0 = np.zeros(p + 1)
    y0[p] = f - _reg(th_k, s_reg, rho)

    def obj_f(y: NDArray[np.float64]) -> float:
        return float(y[p]) + _reg(unpack(y), s_reg, rho)

    def obj_j(y: NDArray[np.float64]) -> NDArray[np.float64]:
        g = np.zeros(p + 1)
        g[p] = 1.0
        if rho > 0:
            g[:p] = 2.0 * rho * unpack(y) / s_reg**2 * s
        return g

    try:
        res = minimize(
            obj_f, y0, jac=obj_j, method="SLSQP",
            bounds=bounds, constraints=[{"type": "ineq", "fun": cons_f, "jac": cons_j}],
            options={"maxiter": 100, "ftol": opts.inner_ftol * max(f, 1e-12)},
        )
        y = res.x
    except (np.linalg.LinAlgError, ValueError):
        y = y0
    theta_new = unpack(y)
    predicted = f - obj_f(y)
    step = float(np.max(np.abs(y[:p]))) if p else 0.0
    try:
        vals_new, peaks_new = ev.exact(theta_new)
    except (np.linalg.LinAlgError, ValueError):
        vals_new, peaks_new = np.full(nch, math.inf), [math.nan] * nch
    f_new = float(np.max(vals_new)) + _reg(theta_new, s_reg, rho)
    if math.isfinite(f_new):
        add_freqs(theta_new, peaks_new, 0.5 * f_new)
    if math.isfinite(f_new) and f_new < f - 1e-3 * max(predicted, 0.0) and f_new < f:
        rel_dec = (f - f_new) / f
        theta, f, peaks = theta_new, f_new, peaks_new
        history.append(f)
        if step >= 0.9 * radius:
            radius = min(2.0 * radius, 1e3)
        if rel_dec < opts.tol and predicted <= opts.tol * f:
            return True, theta, f, peaks, radius, "converged (small decrease)"
    else:
        if predicted <= opts.tol * f and step < 1e-3 * radius:
            return (True, theta, f, peaks, radius,
                    "converged (stationary for the frequency model)")
        radius = 0.3 * min(radius, max(step, 1e-12))
        if radius < 1e-8:
            return True, theta, f, peaks, radius, "converged (trust radius collapsed)"
    return False, theta, f, peaks, radius, status


# ------------------------------------------------------------------------------------------
# driver
# ------------------------------------------------------------------------------------------


def _sample_start(
    pb: TuningProblem, rng: np.random.Generator, spread: float
) -> NDArray[np.float64]:
    th = np.empty(len(pb.parameters))
    for k, prm in enumerate(pb.parameters):
        if prm.sample_sd is not None:  # scaled to the plant by the block that made it
            th[k] = prm.initial + prm.sample_sd * rng.standard_normal()
        elif math.isfinite(prm.lower) and math.isfinite(prm.upper):
            if prm.lower > 0 and prm.upper / prm.lower > 10:
                th[k] = math.exp(rng.uniform(math.log(prm.lower), math.log(prm.upper)))
            else:
                th[k] = rng.uniform(prm.lower, prm.upper)
        elif prm.initial != 0 and (prm.lower >= 0 or prm.upper <= 0):
            th[k] = prm.initial * 10.0 ** rng.uniform(-spread, spread)
        else:
            th[k] = prm.initial + prm.typical * rng.standard_normal() * 10.0**spread / 3
        th[k] = min(max(th[k], prm.lower), prm.upper)
    return th


SHRINK_STEPS = 40
"""Plant-scaled random starts (``Parameter.sample_sd``) that are less stable than their anchor
are pulled halfway back to it up to SHRINK_STEPS times (see :func:`_no_less_stable`)."""


def _abscissa(ev: _Evaluator, theta: NDArray[np.float64]) -> float:
    try:
        a = ev.abscissa(theta)
    except (np.linalg.LinAlgError, ValueError):
        return math.inf
    return a if math.isfinite(a) else math.inf


@dataclass(frozen=True)
class StartAnchor:
    """Where :func:`tune`'s plant-scaled random starts are centred and what they must satisfy.

    Parameters
    ----------
    theta : ndarray of float, shape (n_params,)
        The centre: the initial point if it is stable (with the problem's margin), else the
        stabilising point that the spectral-abscissa phase (:func:`_stabilize`, the phase 1
        of every start) finds from it, else the initial point.
    abscissa : float
        Largest closed-loop spectral abscissa at ``theta`` (1/s).
    target : float
        Random starts are shrunk towards ``theta`` until their abscissa is <= target (1/s).
    stabilised : bool
        Whether ``theta`` came from the spectral-abscissa phase.
    """

    theta: NDArray[np.float64]
    abscissa: float
    target: float
    stabilised: bool


def start_anchor(problem: TuningProblem) -> StartAnchor:
    """The anchor of the plant-scaled random starts of :func:`tune` (see :class:`StartAnchor`).

    An open-loop unstable plant with the initial gain K = 0 would otherwise draw its random
    starts around an unstable point; with a plant scale far larger than the stabilising set
    (COMPleib AC10: ||A|| = 1.6e7 from fast modes, random gains spread 1.5e4) no start
    stabilises. Centred on a stabilising point and shrunk towards it, every random start is
    stabilising (issue 23).

    Parameters
    ----------
    problem : TuningProblem
        The problem.

    Returns
    -------
    StartAnchor
        The anchor.
    """
    ev = _Evaluator(problem)
    lo, hi = problem.lower, problem.upper
    x0 = np.clip(problem.initial, lo, hi)
    a0 = _abscissa(ev, x0)
    stable_target = -max(problem.stability_margin, 0.0) - 1e-6
    if a0 <= stable_target:
        return StartAnchor(x0, a0, max(a0, -problem.stability_margin), False)
    opts = _Options(1, 0.0, 1, 1.0, 200 * len(problem.parameters) + 200)
    try:
        th, ok = _stabilize(ev, x0, lo, hi, opts)
    except (np.linalg.LinAlgError, FloatingPointError):
        ok = False
    if not ok:
        return StartAnchor(x0, a0, max(a0, -problem.stability_margin), False)
    a = _abscissa(ev, th)
    return StartAnchor(th, a, stable_target, True)


def _no_less_stable(
    ev: _Evaluator, theta: NDArray[np.float64], anchor: StartAnchor
) -> NDArray[np.float64]:
    """A random start scaled so that it is no less stable than its anchor.

    The deviation of the plant-scaled entries (``sample_sd``) from the anchor is halved while
    the largest closed-loop spectral abscissa exceeds ``anchor.target``: a stabilising anchor
    gives stabilising random starts, an unstable one (no stabilising point found) random
    starts no worse off than it (a plant scale that is too large for the loop, e.g. one set by
    a large ||A|| of fast modes, no longer throws every start far outside the stabilising
    set). Other parameters are left as drawn.
    """
    pb = ev.pb
    mask = np.array([p.sample_sd is not None for p in pb.parameters])
    if not mask.any():
        return theta
    target = anchor.target
    x0 = anchor.theta
    th = theta.copy()
    for _ in range(SHRINK_STEPS):
        if _abscissa(ev, th) <= target + 1e-9 * max(abs(target), 1.0):
            break
        th = np.where(mask, x0 + 0.5 * (th - x0), th)
    return th


def _run_start(args: tuple[TuningProblem, int, NDArray[np.float64], _Options]) -> StartRecord:
    pb, index, theta0, opts = args
    ev = _Evaluator(pb)
    try:
        theta, f, hist, it, status = _local(ev, theta0, opts, index)
    except (np.linalg.LinAlgError, FloatingPointError) as exc:
        theta, f, hist, it, status = theta0, math.inf, [math.inf], 0, f"failed: {exc}"
    return StartRecord(index, np.array(theta0), np.array(theta), f, hist, it, status)


POLISH_ROUNDS = 4
"""At most POLISH_ROUNDS restarts of :func:`_polish` from the best point (each stops as a start
does); fewer when a restart no longer lowers the objective by PROGRESS_TOL (relative)."""


def _alt_units(problem: TuningProblem) -> TuningProblem | None:
    """``problem`` with the other step unit for the plant-scaled parameters.

    Parameters with a ``sample_sd`` (plant-scaled, :mod:`vtolftc.synthesis.blocks`) step in
    their own unit (``scale``); the restart takes ``sample_sd`` as the unit instead when the
    two differ (and the other way round when they were equal). None if that changes no
    parameter's unit (no parameter has a ``sample_sd``, or each equals its unit).
    """
    prm = list(problem.parameters)
    if not any(p.sample_sd is not None for p in prm):
        return None
    alt = []
    for p in prm:
        if p.sample_sd is None:
            alt.append(p)
        elif p.scale is None or p.scale != p.sample_sd:
            alt.append(replace(p, scale=p.sample_sd))
        else:
            alt.append(replace(p, scale=None))
    out = TuningProblem(alt, problem.channels, problem.channel_names,
                        problem.stability_margin, problem.realizer)
    return None if np.array_equal(out.scales, problem.scales) else out


def _units_at(problem: TuningProblem, theta: NDArray[np.float64]) -> TuningProblem | None:
    """``problem`` with each parameter's step unit set to its magnitude at ``theta``.

    Relative coordinates at the point being polished: on COMPleib AC10 the best gain is
    [0.166, 1.5e-5; 0.167, 8.7e-5] while the plant's gain scales are 1.46e4 and 7.8e-4 per
    column and the default unit is 1, so in either unit the entries differ by 1e4 or more
    in size and the SLSQP model of the step is that badly conditioned. Zero entries keep
    their unit. None if that changes nothing.
    """
    prm = [replace(p, scale=abs(float(t))) if t != 0 and math.isfinite(t) else p
           for p, t in zip(problem.parameters, theta, strict=True)]
    out = TuningProblem(prm, problem.channels, problem.channel_names,
                        problem.stability_margin, problem.realizer)
    return None if np.array_equal(out.scales, problem.scales) else out


BFGS_WINDOW = 50
BFGS_TOL = 1e-6
BFGS_RESTART = 300
BFGS_CAP = 2000
"""The polish's BFGS stage (:func:`_bfgs_stage`) stops when its objective fell by less than
BFGS_TOL (relative) over the last BFGS_WINDOW iterations, when neither its line search nor a
gradient-sampling step finds descent (a kink as stationary as it can tell), or after BFGS_CAP
iterations; every BFGS_RESTART iterations it restarts in units of
the current point's magnitudes with a fresh inverse-Hessian estimate (on HE3 from K = 0: 0.8286
after 1000 iterations without the restarts, 0.80696 in 880 with them)."""


def _bfgs_stage(
    ev: _Evaluator, theta0: NDArray[np.float64], opts: _Options,
) -> tuple[NDArray[np.float64], float, list[float], int, str]:
    """Nonsmooth BFGS (:func:`vtolftc.synthesis.nsbfgs.nonsmooth_bfgs`) on the exact objective.

    The objective is :func:`_local`'s (max of the exact channel norms plus the
    regularisation); its gradient is that of sigma_max of the largest channel at its exact
    peak frequency (the same singular-vector formula as the trust-region model, at one
    frequency). Coordinates are relative to the start's magnitudes (zero entries: their
    ``Parameter.scale``), re-scaled at every restart; a point outside the bounds counts as
    infinite, so the iterates stay within them. Returns (theta, f, history, iterations,
    status) as :func:`_local`.
    """
    pb = ev.pb
    lo, hi = pb.lower, pb.upper
    rho, s_reg = opts.regularization, ev.scales
    nch = len(pb.channels)
    th0 = np.clip(np.asarray(theta0, dtype=float), lo, hi)
    unit = np.where((th0 != 0) & np.isfinite(th0), np.abs(th0), ev.scales)

    def fg(x: NDArray[np.float64]) -> tuple[float, NDArray[np.float64] | None]:
        th = x * unit
        if np.any(th < lo) or np.any(th > hi):
            return math.inf, None
        try:
            vals, peaks = ev.exact(th)
            f = float(np.max(vals))
            if not math.isfinite(f):
                return math.inf, None
            i = int(np.argmax(vals))
            w = [np.array([peaks[i]]) if j == i else np.zeros(0) for j in range(nch)]
            _, g = ev.sigma_and_grad(th, w, True)
        except (np.linalg.LinAlgError, ValueError):
            return math.inf, None
        if g is None or not np.all(np.isfinite(g)):
            return math.inf, None
        grad = g[0].copy()
        if rho > 0:
            f += _reg(th, s_reg, rho)
            grad += 2.0 * rho * th / s_reg**2
        return f, grad * unit

    def should_stop() -> str:
        if opts.interrupted:
            return "interrupted"
        if opts.deadline is not None and time.monotonic() >= opts.deadline:
            return "time limit reached"
        return ""

    th, hist, its, status = th0, [], 0, "iteration cap"
    while its < BFGS_CAP:
        r = nonsmooth_bfgs(fg, th / unit, max_iter=min(BFGS_RESTART, BFGS_CAP - its),
                           window=BFGS_WINDOW, rel_tol=BFGS_TOL, should_stop=should_stop)
        th, its, status = r.x * unit, its + r.iterations, r.status
        hist += r.history if not hist else r.history[1:]
        if r.status != "iteration cap":
            break
        unit = np.where((th != 0) & np.isfinite(th), np.abs(th), ev.scales)
    return th, hist[-1], hist, its, f"BFGS: {status}"


BFGS_JITTER = 1e-3
BFGS_JITTER_SEEDS = (0, 1)
""":func:`_bfgs_from` also runs from the start moved by BFGS_JITTER of each parameter's scale
(uniform, one draw per seed of BFGS_JITTER_SEEDS) and keeps the best run. From exactly K = 0
the path of COMPleib HE3 is decided by the CPU's rounding: 0.80696 on one machine, 0.85458 on
an AVX512_SPR Xeon, where it ends against the stability boundary (a closed-loop pole pair at
-2.5e-7 1/s; of 200 random points at relative distance 1e-3 to 1e-1 about half are unstable
and none is lower). From the jittered starts 0.80695 and 0.80415 on that machine."""


def _bfgs_from(
    problem: TuningProblem, theta0: NDArray[np.float64], opts: _Options,
) -> tuple[NDArray[np.float64], float, list[float], int, str] | None:
    """:func:`_bfgs_stage` from a start point and from its jittered copies (BFGS_JITTER), each
    stabilised first as :func:`_local` does (the spectral-abscissa phase); the best run, with
    the iterations of all; None if no start can be stabilised."""
    ev = _Evaluator(problem)
    lo, hi = problem.lower, problem.upper
    th0 = np.asarray(theta0, dtype=float)
    starts = [th0] + [th0 + BFGS_JITTER * problem.scales
                      * np.random.default_rng(s).uniform(-1.0, 1.0, th0.size)
                      for s in BFGS_JITTER_SEEDS]
    best, its = None, 0
    for start in starts:
        th = np.clip(start, lo, hi)
        if not math.isfinite(float(np.max(ev.exact(th)[0]))):
            th, ok = _stabilize(ev, th, lo, hi, opts)
            if not ok:
                continue
        out = _bfgs_stage(ev, th, opts)
        its += out[3]
        if best is None or out[1] < best[1]:
            best = out
        if opts.interrupted or (opts.deadline is not None and time.monotonic() >= opts.deadline):
            break
    if best is None:
        return None
    return best[0], best[1], best[2], its, best[4]


def _polish(problem: TuningProblem, rec: StartRecord, opts: _Options) -> StartRecord:
    """Restart the local solver from the best start's point (``tune(..., polish=True)``).

    A start stops where the frequency model is stationary or its trust region collapsed: on a
    nonsmooth max of singular values that is often a kink that the step unit or the active
    frequency set of that run cannot resolve. First nonsmooth BFGS (:func:`_bfgs_stage`) runs
    from the best start's own start point (stabilised first if need be, :func:`_bfgs_from`):
    on COMPleib HE3 the trust-region run from K = 0 ends at 0.82254 with a closed-loop pole
    pair held on its abscissa constraint (-1e-9 1/s), a kink where every direction that
    lowers the norm leaves the stable set, so neither BFGS nor gradient sampling can move
    from there, while BFGS from the start follows the valley to 0.80696. Then each round
    restarts :func:`_local` from the best
    point, first in units of the point's own magnitudes (:func:`_units_at`), then with the
    other step unit (:func:`_alt_units`), then with the problem's own, each with a fresh
    frequency set and trust radius, and last by BFGS from the best point; the
    rounds end when one lowers the
    objective by less than PROGRESS_TOL (relative), after POLISH_ROUNDS, or at the deadline.
    The record returned is ``rec`` with the better point, its history extended, the
    iterations added and the status saying by how much the polish improved it.
    """
    if not math.isfinite(rec.value):
        return rec
    theta, f = np.array(rec.theta), float(rec.value)
    hist, its = list(rec.history), rec.iterations
    if not np.array_equal(rec.theta0, rec.theta):
        try:
            out = _bfgs_from(problem, np.asarray(rec.theta0, dtype=float), opts)
        except (np.linalg.LinAlgError, FloatingPointError, ValueError):
            out = None
        if out is not None:
            its += out[3]
            if out[1] < f:
                hist += [v for v in out[2] if v < f]
                theta, f = out[0], out[1]
    for _ in range(POLISH_ROUNDS):
        f_round = f
        variants = [problem]
        if opts.regularization == 0:  # the penalty is in units of the problem's own scales
            variants = [v for v in (_units_at(problem, theta), _alt_units(problem))
                        if v is not None] + variants
        for pb in [*variants, None]:
            if opts.interrupted or (opts.deadline is not None
                                    and time.monotonic() >= opts.deadline):
                break
            try:
                if pb is None:  # the final BFGS stage, in the point's own units
                    th, fn, h, it, _ = _bfgs_stage(_Evaluator(problem), theta, opts)
                else:
                    th, fn, h, it, _ = _local(_Evaluator(pb), theta, opts, rec.index)
            except (np.linalg.LinAlgError, FloatingPointError, ValueError):
                continue
            its += it
            if fn < f:
                hist += [v for v in h if v < f]
                theta, f = th, fn
        if not f < f_round * (1 - PROGRESS_TOL):
            break
    if f >= rec.value:
        return rec
    return StartRecord(rec.index, rec.theta0, theta, f, hist, its,
                       f"{rec.status}; polished from {rec.value:.6g} to {f:.6g}")


def tune(
    problem: TuningProblem,
    *,
    n_starts: int = 0,
    seed: int | None = 0,
    max_iter: int | None = None,
    tol: float = 1e-7,
    max_freqs: int = 40,
    trust_radius: float = 1.0,
    spread: float = 1.0,
    start_sampler: Callable[[np.random.Generator], NDArray[np.float64]] | None = None,
    map_fn: Callable[[Callable[[Any], StartRecord], Iterable[Any]], Iterable[StartRecord]]
    | None = None,
    time_limit: float | None = None,
    progress: Callable[[Progress], None] | None = None,
    regularization: float = 0.0,
    polish: bool = False,
    inner_ftol: float = INNER_FTOL,
) -> TuneResult:
    """Minimise max_i ||channel_i(theta)||_inf over theta (paper eqs. 7-8, ``systune`` role).

    Ctrl-C (KeyboardInterrupt) during a sequential run stops it and returns the best point
    found so far (message "interrupted").

    Parameters
    ----------
    problem : TuningProblem
        The problem.
    n_starts : int
        Number of random starts in addition to the initial point (``Parameter.initial``).
    seed : int or None
        Seed of the random starts (``SeedSequence(seed).spawn``); same seed, same result.
    max_iter : int or None
        Outer iterations per start. ``None`` (default): run each start to convergence: until
        a step is stationary for the frequency model, the decrease falls below ``tol``, the
        trust region collapses, or the objective fell by less than ``PROGRESS_TOL`` over the
        last ``PROGRESS_WINDOW`` iterations (at most ``ITER_CAP`` iterations). An int is a
        hard cap (the stationarity tests still apply, the progress test does not).
    tol : float
        Relative-decrease tolerance.
    max_freqs : int
        Cap on the size of each channel's active frequency set.
    trust_radius : float
        Initial trust radius in units of ``Parameter.scale``.
    spread : float
        Random starts multiply positive parameters by 10**U(-spread, spread) (bounded
        parameters are drawn uniformly / log-uniformly within their bounds).
    start_sampler : callable, optional
        ``rng -> theta`` replacing the default random start distribution.
    map_fn : callable, optional
        ``map`` for parallel execution, e.g. ``ProcessPoolExecutor().map`` (the problem's
        channels must then be picklable). Default: the starts run one after the other in this
        process.
    time_limit : float, optional
        Wall-clock budget in seconds (None: unlimited). Checked between iterations: running
        starts stop at their current point, no new start begins after it; the result says
        "time limit reached".
    progress : callable, optional
        Callback receiving a :class:`Progress` after every accepted step (sequential runs;
        with ``map_fn`` only the time limit applies inside workers).
    regularization : float
        rho >= 0: minimise max_i ||T_i||_inf + rho sum_k (theta_k / scale_k)^2 instead (a
        small rho keeps gains finite on problems whose infimum is approached only as gains
        grow without bound). ``value`` then includes the penalty; ``channel_values`` do not.
    polish : bool
        Run nonsmooth BFGS on the exact objective (:mod:`vtolftc.synthesis.nsbfgs`) from
        the best start's start point, then restart the local solver from the best point in
        its own units, in the other step unit of the plant-scaled parameters and in the
        problem's units, each with a fresh frequency set, and BFGS from there, until it
        stops improving (:data:`POLISH_ROUNDS` at most;
        the best start's record says by how much; never worse than without). Off by default:
        the result then stays :func:`collect_starts` of :func:`start_jobs`, bit for bit, and
        the DS-1 design's numbers are unchanged (COMPleib AC10: 14.554 without, 13.2365 with;
        ``benchmarks/bench_compleib.py``).
    inner_ftol : float
        Tolerance of each step's SLSQP subproblem relative to the current objective (> 0;
        default :data:`INNER_FTOL`). A looser one visits fewer points per step.

    Returns
    -------
    TuneResult
        The best start's theta, overall norm, per-channel norms and all start records.

    Raises
    ------
    ValueError
        For n_starts < 0, max_iter < 1, time_limit <= 0, a negative or non-finite
        regularization or an inner_ftol that is not a finite float > 0.

    Examples
    --------
    A proportional gain k on the unstable G(s) = 1/(s - 1), minimising ||[0.5 S; 0.5 k S]||_inf:
    the norm is 0.5 sqrt(1 + k^2) / (k - 1) (its DC value) for 1 < k < 2 and
    0.5 sqrt(1 + k^2) (high frequency) above, so the optimum is k = 2, 0.5 sqrt(5):

    >>> import control as ct
    >>> ch = mixed_sensitivity_channel(ct.tf([1], [1, -1]), lambda th: th[0],
    ...                                Ws=0.5, Wr=0.5)
    >>> pb = TuningProblem([Parameter("k", 3.0, 0.0, 100.0)], [ch])
    >>> res = tune(pb)
    >>> res.stable, round(res.value, 6), round(float(res.theta[0]), 4)
    (True, 1.118034, 2.0)
    """
    jobs = start_jobs(problem, n_starts=n_starts, seed=seed, max_iter=max_iter, tol=tol,
                      max_freqs=max_freqs, trust_radius=trust_radius, spread=spread,
                      start_sampler=start_sampler, time_limit=time_limit,
                      progress=progress if map_fn is None else None,
                      regularization=regularization, inner_ftol=inner_ftol)
    opts = jobs[0][3]
    records: list[StartRecord] = []
    stopped = ""
    if map_fn is None:
        for job in jobs:
            if opts.deadline is not None and time.monotonic() >= opts.deadline and records:
                stopped = "time limit reached"
                break
            try:
                records.append(run_start(job))
            except KeyboardInterrupt:
                opts.interrupted = True
            if opts.interrupted:
                stopped = "interrupted"
                break
        if not records:  # interrupted before the first start produced anything
            th0 = np.clip(problem.initial, problem.lower, problem.upper)
            records.append(StartRecord(0, th0, th0, math.inf, [math.inf], 0, "interrupted"))
    else:
        records = list(map_fn(run_start, jobs))
    if polish and not stopped:
        best = min(records, key=lambda r: (r.value, r.index))
        try:
            records = [_polish(problem, r, opts) if r is best else r for r in records]
        except KeyboardInterrupt:
            stopped = "interrupted"
    return collect_starts(problem, records, opts.t_start, stopped)


def start_jobs(
    problem: TuningProblem,
    *,
    n_starts: int = 0,
    seed: int | None = 0,
    max_iter: int | None = None,
    tol: float = 1e-7,
    max_freqs: int = 40,
    trust_radius: float = 1.0,
    spread: float = 1.0,
    start_sampler: Callable[[np.random.Generator], NDArray[np.float64]] | None = None,
    time_limit: float | None = None,
    progress: Callable[[Progress], None] | None = None,
    regularization: float = 0.0,
    inner_ftol: float = INNER_FTOL,
) -> list[tuple[Any, ...]]:
    """The independent local runs of :func:`tune`, one picklable job per start.

    Run each job with :func:`run_start` (anywhere, in any order, e.g. in worker processes)
    and combine the records with :func:`collect_starts`; the result is :func:`tune`'s, bit
    for bit. ``progress`` only works in this process.

    Parameters
    ----------
    problem : TuningProblem
        The problem.
    n_starts, seed, max_iter, tol, max_freqs, trust_radius, spread : int, float or None
        As in :func:`tune`.
    start_sampler, time_limit, progress, regularization, inner_ftol : callable, float or None
        As in :func:`tune`.

    Returns
    -------
    list of tuple
        The jobs, in start order.
    """
    if n_starts < 0:
        raise ValueError(f"n_starts must be >= 0, got {n_starts}")
    if max_iter is not None and max_iter < 1:
        raise ValueError(f"max_iter must be >= 1 (or None: to convergence), got {max_iter}")
    if time_limit is not None and not time_limit > 0:
        raise ValueError(f"time_limit must be > 0 s (or None), got {time_limit}")
    if not (regularization >= 0 and math.isfinite(regularization)):
        raise ValueError(f"regularization must be a finite float >= 0, got {regularization}")
    if not (inner_ftol > 0 and math.isfinite(inner_ftol)):
        raise ValueError(f"inner_ftol must be a finite float > 0, got {inner_ftol}")
    t_start = time.monotonic()
    opts = _Options(ITER_CAP if max_iter is None else max_iter, tol, max_freqs, trust_radius,
                    200 * len(problem.parameters) + 200,
                    None if time_limit is None else t_start + time_limit, float(regularization),
                    progress, t_start, to_convergence=max_iter is None,
                    inner_ftol=float(inner_ftol))
    starts = [problem.initial]
    children = np.random.SeedSequence(seed).spawn(n_starts)
    ev: _Evaluator | None = None
    anchor: StartAnchor | None = None
    mask = np.array([p.sample_sd is not None for p in problem.parameters])
    for child in children:
        rng = np.random.default_rng(child)
        if start_sampler is not None:
            th = problem._check_theta(start_sampler(rng))
        else:
            th = _sample_start(problem, rng, spread)
            if mask.any():
                if ev is None or anchor is None:
                    ev = _Evaluator(problem)
                    anchor = start_anchor(problem)
                if anchor.stabilised:  # the plant-scaled draw, centred on the anchor
                    th = np.where(mask, np.clip(th - problem.initial + anchor.theta,
                                                problem.lower, problem.upper), th)
                th = _no_less_stable(ev, th, anchor)
        starts.append(th)
    return [(problem, i, th, opts) for i, th in enumerate(starts)]


def run_start(job: tuple[Any, ...]) -> StartRecord:
    """One local run of a :func:`start_jobs` job (picklable; a top-level function).

    Parameters
    ----------
    job : tuple
        One job of :func:`start_jobs`.

    Returns
    -------
    StartRecord
        The run's outcome.
    """
    return _run_start(job)  # type: ignore[arg-type]


def collect_starts(problem: TuningProblem, records: Sequence[StartRecord],
                   t_start: float | None = None, stopped: str = "") -> TuneResult:
    """The :class:`TuneResult` of the start records (any order) of :func:`start_jobs`.

    Parameters
    ----------
    problem : TuningProblem
        The problem the jobs were made from.
    records : sequence of StartRecord
        The records, in any order.
    t_start : float, optional
        ``time.monotonic()`` when tuning began (for the message's elapsed time).
    stopped : str
        Stop reason to report ("" when every start ran to its end).

    Returns
    -------
    TuneResult
        The best start's result, as :func:`tune` returns it.
    """
    records = sorted(records, key=lambda r: r.index)
    if t_start is None:
        t_start = time.monotonic()
    if not stopped and any(r.status == "time limit reached" for r in records):
        stopped = "time limit reached"
    best = min(records, key=lambda r: (r.value, r.index))
    stable = math.isfinite(best.value)
    chan = problem.channel_norms(best.theta) if stable else np.full(len(problem.channels), np.inf)
    msg = (
        f"best of {len(records)} start(s): start {best.index}, {best.status}"
        + (f"; {stopped} after {time.monotonic() - t_start:.1f} s" if stopped else "")
        if stable
        else "no start reached a stabilising parameter vector; the problem may not be "
        "stabilisable with this structure/bounds (try other initial values or bounds)"
    )
    return TuneResult(
        theta=best.theta,
        names=problem.names,
        value=float(best.value),
        channel_values=chan,
        channel_names=list(problem.channel_names or []),
        stable=stable,
        starts=list(records),
        message=msg,
    )


# ------------------------------------------------------------------------------------------
# mixed sensitivity helpers (eq. 4 and eq. 8)
# ------------------------------------------------------------------------------------------


def pid(kp: float, ki: float, kd: float, tf: float) -> StateSpaceData:
    """PID with filtered derivative K(s) = kp + ki/s + kd s/(tf s + 1) as (A, B, C, D).

    States: integrator and derivative filter (always present, so the state dimension does
    not depend on the gains). Note: with ki = 0 the integrator state is unobservable and
    gives a closed-loop eigenvalue at 0, i.e. an infinite norm under the internal-stability
    convention of :func:`vtolftc.synthesis.hinfnorm.hinf_norm`; keep ki > 0 or use a PD
    structure of your own.

    Parameters
    ----------
    kp : float
        Proportional gain (output unit per input unit).
    ki : float
        Integral gain (per s).
    kd : float
        Derivative gain (s).
    tf : float
        Derivative filter time constant (s), > 0.

    Returns
    -------
    A, B, C, D : ndarray
        Shapes (2, 2), (2, 1), (1, 2), (1, 1).

    Raises
    ------
    ValueError
        If tf <= 0.

    Examples
    --------
    >>> A, B, C, D = pid(2.0, 1.0, 0.5, 0.1)
    >>> A.shape, float(D[0, 0])                  # D = kp + kd / tf
    ((2, 2), 7.0)
    """
    if not tf > 0:
        raise ValueError(f"derivative filter time constant tf must be > 0 s, got {tf}")
    A = np.array([[0.0, 0.0], [0.0, -1.0 / tf]])
    B = np.array([[1.0], [1.0 / tf]])
    C = np.array([[ki, -kd / tf]])
    D = np.array([[kp + kd / tf]])
    return A, B, C, D


def _lti(sys: Any, what: str) -> StateSpaceData:
    if isinstance(sys, int | float | np.integer | np.floating):
        return (np.zeros((0, 0)), np.zeros((0, 1)), np.zeros((1, 0)), np.array([[float(sys)]]))
    try:
        return as_state_space(sys)
    except ValueError as exc:
        raise ValueError(f"{what}: {exc}") from exc


def _weight(W: Any, name: str, size: int) -> StateSpaceData | None:
    """Validate a weight (proper, stable) and expand a SISO weight to W * I_size."""
    if W is None:
        return None
    try:
        import control

        if isinstance(W, control.TransferFunction):
            for i in range(W.noutputs):
                for j in range(W.ninputs):
                    num = np.trim_zeros(np.atleast_1d(W.num[i][j]), "f")
                    den = np.trim_zeros(np.atleast_1d(W.den[i][j]), "f")
                    if num.size > den.size:
                        raise ValueError(
                            f"weight {name} is improper (numerator degree {num.size - 1} > "
                            f"denominator degree {den.size - 1}); it has no state-space "
                            "realisation. Make it proper with far-away poles, e.g. "
                            "W(s) / (s / (100 w_c) + 1)^k"
                        )
    except ImportError:  # pragma: no cover
        pass
    A, B, C, D = _lti(W, f"weight {name}")
    if A.size and np.max(np.linalg.eigvals(A).real) >= 0:
        poles = np.linalg.eigvals(A)
        raise ValueError(
            f"weight {name} has pole(s) {poles[poles.real >= 0]} in the closed right half "
            "plane; an integrator-like weight (e.g. A = 0 in eq. 5, Ws = (s/M + wb)/s) makes "
            "the weighted channel marginally stable, with infinite H-infinity norm. Use a "
            "small positive A (e.g. 1e-4) instead"
        )
    if D.shape == (1, 1) and size > 1:
        eye = np.eye(size)
        A, B, C, D = (np.kron(eye, X) for X in (A, B, C, D))
    if D.shape[1] != size:
        raise ValueError(
            f"weight {name} has {D.shape[1]} inputs but the weighted signal has {size} "
            "components (use a SISO weight or a weight with matching inputs)"
        )
    return A, B, C, D


def _loop(G: StateSpaceData, K: StateSpaceData) -> tuple[
    NDArray[Any], NDArray[Any], tuple[NDArray[Any], NDArray[Any]],
    tuple[NDArray[Any], NDArray[Any]], tuple[NDArray[Any], NDArray[Any]],
]:
    """Negative-feedback loop e = r - y, u = K e, y = G u: (A, B, (C,D)_S, (C,D)_T, (C,D)_R)."""
    Ag, Bg, Cg, Dg = G
    Ak, Bk, Ck, Dk = K
    p, m = Dg.shape
    if Dk.shape != (m, p):
        raise ValueError(
            f"controller must be {m}x{p} (inputs = plant outputs) for a {p}x{m} plant, got "
            f"{Dk.shape[0]}x{Dk.shape[1]}"
        )
    ng, nk = Ag.shape[0], Ak.shape[0]
    F = np.eye(p) + Dg @ Dk
    try:
        E = np.linalg.inv(F)
    except np.linalg.LinAlgError as exc:
        raise ValueError("feedback loop is ill-posed: I + G(inf) K(inf) is singular") from exc
    Ce = -E @ np.hstack([Cg, Dg @ Ck])
    De = E
    Cu = np.hstack([np.zeros((m, ng)), Ck]) + Dk @ Ce
    Du = Dk @ De
    dtype = np.result_type(Ag, Ak, Bg, Bk, Cg, Ck, Dg, Dk)
    A = np.zeros((ng + nk, ng + nk), dtype=dtype)
    A[:ng, :ng] = Ag
    A[ng:, ng:] = Ak
    A[:ng] += Bg @ Cu
    A[ng:] += Bk @ Ce
    B = np.vstack([Bg @ Du, Bk @ De])
    return A, B, (Ce, De), (-Ce, np.eye(p) - De), (Cu, Du)


def closed_loops(G: Any, K: Any) -> tuple[Any, Any, Any]:
    """S, T, R of eq. 4 for the negative-feedback loop of plant G and controller K.

    S = (I + G K)^-1 (r -> e), T = (I + G K)^-1 G K (r -> y), R = K (I + G K)^-1 (r -> u).

    Parameters
    ----------
    G : LTI, tuple or scalar
        The plant (python-control LTI, (A, B, C, D) or a scalar), ny outputs, nu inputs.
    K : LTI, tuple or scalar
        The controller, nu outputs, ny inputs.

    Returns
    -------
    S, T, R : control.StateSpace
        Sharing the realisation [x_G; x_K] (not minimal).
    """
    import control

    A, B, (Cs, Ds), (Ct, Dt), (Cr, Dr) = _loop(_lti(G, "plant G"), _lti(K, "controller K"))
    return (
        control.ss(A, B, Cs, Ds),
        control.ss(A, B, Ct, Dt),
        control.ss(A, B, Cr, Dr),
    )


def _mixed(
    G: StateSpaceData, K: StateSpaceData, Ws: StateSpaceData | None,
    Wt: StateSpaceData | None, Wr: StateSpaceData | None,
) -> StateSpaceData:
    A, B, *outs = _loop(G, K)
    n = A.shape[0]
    blocks_A = [A]
    rows_couple: list[NDArray[Any]] = []
    C_rows: list[NDArray[Any]] = []
    D_rows: list[NDArray[Any]] = []
    weights = [Ws, Wt, Wr]
    nw_tot = sum(W[0].shape[0] for W in weights if W is not None)
    offset = n
    for W, (Cx, Dx) in zip(weights, outs, strict=True):
        if W is None:
            continue
        Aw, Bw, Cw, Dw = W
        nw = Aw.shape[0]
        blocks_A.append(Aw)
        coup = np.zeros((nw, n + nw_tot), dtype=np.result_type(A, Aw))
        coup[:, :n] = Bw @ Cx
        coup[:, offset : offset + nw] = Aw
        rows_couple.append((coup, Bw @ Dx))  # type: ignore[arg-type]
        Crow = np.zeros((Dw.shape[0], n + nw_tot), dtype=np.result_type(Cx, Cw))
        Crow[:, :n] = Dw @ Cx
        Crow[:, offset : offset + nw] = Cw
        C_rows.append(Crow)
        D_rows.append(Dw @ Dx)
        offset += nw
    if not C_rows:
        raise ValueError("at least one of Ws, Wt, Wr must be given")
    Atot = np.zeros((n + nw_tot, n + nw_tot), dtype=np.result_type(*blocks_A))
    Atot[:n, :n] = A
    Btot = [B]
    r0 = n
    for coup, bw in rows_couple:  # type: ignore[misc]
        Atot[r0 : r0 + coup.shape[0]] = coup
        Btot.append(bw)
        r0 += coup.shape[0]
    return Atot, np.vstack(Btot), np.vstack(C_rows), np.vstack(D_rows)


def mixed_sensitivity(G: Any, K: Any, Ws: Any = None, Wt: Any = None, Wr: Any = None) -> Any:
    """Stacked weighted closed loop [Ws S; Wt T; Wr R] of eq. 8 as a python-control StateSpace.

    A SISO weight applied to a vector signal means W * I. Weights must be proper and stable
    (eqs. 5 and 6 of the paper are).

    Parameters
    ----------
    G : LTI, tuple or scalar
        The plant.
    K : LTI, tuple or scalar
        The controller.
    Ws, Wt, Wr : LTI, tuple or scalar, optional
        Weights of S, T and R; None omits the row.

    Returns
    -------
    control.StateSpace
        The stacked channel r -> [Ws e; Wt y; Wr u].

    Raises
    ------
    ValueError
        For an improper Wt or Wr (e.g. Wt(s) = s/wt + ...: add high-frequency poles), a Ws
        with a pole at s = 0 (A = 0 in eq. 5: use a small A > 0), no weight at all, or an
        ill-posed loop (I + G(inf) K(inf) singular).
    """
    import control

    Gd, Kd = _lti(G, "plant G"), _lti(K, "controller K")
    p, m = Gd[3].shape
    data = _mixed(Gd, Kd, _weight(Ws, "Ws", p), _weight(Wt, "Wt", p), _weight(Wr, "Wr", m))
    return control.ss(*data)


def mixed_sensitivity_channel(
    G: Any,
    controller: Callable[[NDArray[np.float64]], Any],
    Ws: Any = None,
    Wt: Any = None,
    Wr: Any = None,
) -> Channel:
    """Channel theta -> (A, B, C, D) of [Ws S; Wt T; Wr R] (eq. 8) for K = controller(theta).

    Plant and weights are converted and validated once (see :func:`mixed_sensitivity`);
    each call only assembles numpy matrices, so it is cheap inside the tuner.

    Parameters
    ----------
    G : LTI, tuple or scalar
        The plant.
    controller : callable
        theta -> K (LTI, (A, B, C, D) or scalar).
    Ws, Wt, Wr : LTI, tuple or scalar, optional
        Weights of S, T and R; None omits the row.

    Returns
    -------
    callable
        The channel, for :class:`TuningProblem`.

    Raises
    ------
    ValueError
        For improper or unstable weights, as :func:`mixed_sensitivity`.
    """
    Gd = _lti(G, "plant G")
    p, m = Gd[3].shape
    Wsd, Wtd, Wrd = _weight(Ws, "Ws", p), _weight(Wt, "Wt", p), _weight(Wr, "Wr", m)
    if Wsd is None and Wtd is None and Wrd is None:
        raise ValueError("at least one of Ws, Wt, Wr must be given")

    def channel(theta: NDArray[np.float64]) -> StateSpaceData:
        return _mixed(Gd, _lti(controller(theta), "controller(theta)"), Wsd, Wtd, Wrd)

    return channel

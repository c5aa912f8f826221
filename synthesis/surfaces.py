"""Gain surfaces: P-PID gains as smooth functions of airspeed, tuned as one design.

The role of MATLAB's ``tunableSurface`` / ``varyingGoal``. Each tunable gain of an axis' P-PID
(:data:`~vtolftc.synthesis.loops.PARAM_NAMES`: kp_angle, kp_rate, ki_rate, kd_rate,
tf_rate_s) is

    K(V) = sum_j c_j phi_j(s(V)),   s(V) = 2 (V - V_lo) / (V_hi - V_lo) - 1 in [-1, 1],

over a declared basis of the normalised airspeed s (:class:`SurfaceBasis`: Legendre
polynomials P_0 .. P_d; degree 0 is the constant gain). All coefficients of an axis are tuned
together in one multi-model problem (:func:`surface_problem`) over a dense airspeed grid
(:func:`surface_grid`: the design points of the airframe's transition range and the midpoints
between them). At every grid airspeed the channels are the point design's own (the
:class:`~vtolftc.synthesis.design_loop.DesignMethod` builds them: weights evaluated at that
airspeed, "varyingGoal"); the objective is the max over grid points and channels of their
H-infinity norms, minimised by the structured tuner (:func:`~vtolftc.synthesis.structured.tune`).

SHIF is this problem with a degree-0 surface; GS-SHIF (:func:`design_surfaces`) starts from
the SHIF solution embedded in the higher-degree basis (the extra coefficients 0: the same
gains at every airspeed, bit for bit), so the surface's objective is never worse than the
constant's: by construction, and by a final check that keeps the start if the optimiser
returned a worse point.

Gains are clipped to their bounds at each airspeed (the point design's bounds, from the
airframe's physics), inside the objective and in the exported schedule alike: what is
evaluated is what flies. :func:`schedule_from_surfaces` writes the gain-schedule JSON the
autopilot reads (breakpoints = the grid), so a surface design flies with
``vtolftc fly --gains-dir``.

Examples
--------
>>> import numpy as np
>>> b = SurfaceBasis(degree=2, v_lo_m_s=0.0, v_hi_m_s=18.0)
>>> b.evaluate([0.0, 9.0, 18.0]).round(3).tolist()    # P0, P1, P2 at s = -1, 0, 1
[[1.0, -1.0, 1.0], [1.0, 0.0, -0.5], [1.0, 1.0, 1.0]]
>>> sf = GainSurface.constant(b, {"kp_angle": 2.0, "kp_rate": 0.5, "ki_rate": 0.1,
...                               "kd_rate": 0.01, "tf_rate_s": 0.02})
>>> sf.gains_at(7.0)["kp_rate"]
0.5
"""

from __future__ import annotations

import itertools
import math
import time
from collections.abc import Mapping, Sequence
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import numpy as np
from numpy.typing import ArrayLike, NDArray

from vtolftc.airframe.loader import Airframe
from vtolftc.synthesis.design_loop import DesignMethod, point_seed
from vtolftc.synthesis.export import schedule_document, write_json
from vtolftc.synthesis.hinfnorm import StateSpaceData, as_state_space
from vtolftc.synthesis.loops import PARAM_NAMES, CascadeChannel
from vtolftc.synthesis.models import Axis
from vtolftc.synthesis.structured import INNER_FTOL, Parameter, TuningProblem, tune
from vtolftc.synthesis.uncertainty import DesignPoint

__all__ = [
    "GRID_NUMBER_OFFSET",
    "SURFACE_INNER_FTOL",
    "SURFACE_TAG",
    "SURFACE_TUNE",
    "GainSurface",
    "SurfaceBasis",
    "SurfaceChannel",
    "SurfaceDesign",
    "SurfaceProblem",
    "SurfaceRealizer",
    "SurfaceTune",
    "coefficient_parameters",
    "design_surfaces",
    "legendre_basis",
    "schedule_from_surfaces",
    "surface_grid",
    "surface_problem",
    "write_surface_gains",
]

#: Grid points are numbered from this offset (so no grid point is mistaken for one of the
#: paper's table 1 points, whose numbers key table 2's reference values).
GRID_NUMBER_OFFSET = 100
#: The seed tag of a surface tune (point designs use their point number, SHIF 100).
SURFACE_TAG = 200
#: The fast surface (GS-SHIF) tune's SLSQP step tolerance relative to its objective
#: (:func:`~vtolftc.synthesis.structured.tune`'s ``inner_ftol``; the point designs and SHIF
#: keep :data:`~vtolftc.synthesis.structured.INNER_FTOL`, 1e-10): it started from SHIF, the
#: outer trust-region loop converges anyway and each step visits far fewer points (issue 23:
#: the surface design's time; ``benchmarks/bench_synth_surface.py``).
SURFACE_INNER_FTOL = 1e-8


@dataclass(frozen=True)
class SurfaceTune:
    """How the surface (GS-SHIF) tune of one axis runs.

    Parameters
    ----------
    inner_ftol : float
        SLSQP step tolerance relative to the objective (``tune``'s ``inner_ftol``).
    chain_rule : bool
        Derivatives by the chain rule through each grid point's gains
        (:meth:`SurfaceRealizer.gain_derivatives`) rather than central differences in the
        coefficients.
    """

    inner_ftol: float
    chain_rule: bool


#: The surface tune per axis (:func:`design_surfaces`' default). Roll and pitch: the fast
#: tune (chain rule, :data:`SURFACE_INNER_FTOL`), 13x / 2.8x less CPU than the precise one
#: for objectives within 0.02 % and validations as good (session 16). Yaw: the precise one
#: (central differences, 1e-10), where the fast one does not pay (15.7 s against 12.6 s of
#: CPU, the same load) and, on this flat objective (2.238937 against 2.238606, hover gains
#: far apart), lands on another surface that validates worse (hover phase margin 29.9 deg
#: against 58.0, mu_RS >= 1 at 5 more airspeeds of 11-15 m/s): either lever alone moves it
#: there (session 17, ``benchmarks/bench_synth_surface.py``).
SURFACE_TUNE: dict[str, SurfaceTune] = {
    "roll": SurfaceTune(SURFACE_INNER_FTOL, True),
    "pitch": SurfaceTune(SURFACE_INNER_FTOL, True),
    "yaw": SurfaceTune(INNER_FTOL, False),
}


# ------------------------------------------------------------------------------------------
# basis and surface
# ------------------------------------------------------------------------------------------


def legendre_basis(s: ArrayLike, degree: int) -> NDArray[np.float64]:
    """Legendre polynomials P_0 .. P_degree at ``s`` (Bonnet's recurrence).

    Parameters
    ----------
    s : array_like of float, shape (n,)
        Normalised airspeeds, in [-1, 1] (dimensionless).
    degree : int
        Highest degree d >= 0.

    Returns
    -------
    ndarray of float, shape (n, degree + 1)
        ``out[i, j] = P_j(s[i])``; column 0 is exactly 1.

    Raises
    ------
    ValueError
        For a negative degree.
    """
    if degree < 0:
        raise ValueError(f"degree {degree!r}: expected an integer >= 0")
    x = np.atleast_1d(np.asarray(s, dtype=float))
    out = np.empty((x.size, degree + 1))
    out[:, 0] = 1.0
    if degree >= 1:
        out[:, 1] = x
    for n in range(1, degree):  # (n + 1) P_{n+1} = (2n + 1) x P_n - n P_{n-1}
        out[:, n + 1] = ((2 * n + 1) * x * out[:, n] - n * out[:, n - 1]) / (n + 1)
    return out


@dataclass(frozen=True)
class SurfaceBasis:
    """A polynomial basis (Legendre P_0 .. P_d) of the normalised airspeed.

    Parameters
    ----------
    degree : int
        d >= 0 (0: constant gains).
    v_lo_m_s, v_hi_m_s : float
        The airspeeds [m/s] mapped to s = -1 and s = +1; outside them s is clamped (the
        autopilot holds the end gains beyond the last breakpoint too).

    Raises
    ------
    ValueError
        For a negative degree or ``v_hi_m_s <= v_lo_m_s``.

    Examples
    --------
    >>> b = SurfaceBasis(1, 0.0, 18.0)
    >>> b.normalise([0.0, 4.5, 18.0, 25.0]).tolist()      # clamped beyond v_hi
    [-1.0, -0.5, 1.0, 1.0]
    >>> b.evaluate([4.5]).tolist()
    [[1.0, -0.5]]
    """

    degree: int
    v_lo_m_s: float
    v_hi_m_s: float

    def __post_init__(self) -> None:
        if not (isinstance(self.degree, int) and self.degree >= 0):
            raise ValueError(f"degree {self.degree!r}: expected an integer >= 0")
        if not (math.isfinite(self.v_lo_m_s) and math.isfinite(self.v_hi_m_s)
                and self.v_hi_m_s > self.v_lo_m_s):
            raise ValueError(f"airspeed range [{self.v_lo_m_s}, {self.v_hi_m_s}] m/s: expected "
                             "finite bounds with v_hi > v_lo")

    @property
    def size(self) -> int:
        """Number of basis functions (d + 1)."""
        return self.degree + 1

    def normalise(self, airspeed_m_s: ArrayLike) -> NDArray[np.float64]:
        """s(V) = 2 (V - V_lo) / (V_hi - V_lo) - 1, clamped to [-1, 1].

        Parameters
        ----------
        airspeed_m_s : array_like of float
            Airspeeds V [m/s].

        Returns
        -------
        ndarray of float, shape (n,)
            s (dimensionless).
        """
        v = np.atleast_1d(np.asarray(airspeed_m_s, dtype=float))
        s = 2.0 * (v - self.v_lo_m_s) / (self.v_hi_m_s - self.v_lo_m_s) - 1.0
        return np.clip(s, -1.0, 1.0)

    def evaluate(self, airspeed_m_s: ArrayLike) -> NDArray[np.float64]:
        """phi_j(s(V)) for every airspeed.

        Parameters
        ----------
        airspeed_m_s : array_like of float
            Airspeeds V [m/s].

        Returns
        -------
        ndarray of float, shape (n, d + 1)
            ``out[i, j] = P_j(s(V_i))``.
        """
        return legendre_basis(self.normalise(airspeed_m_s), self.degree)


@dataclass(frozen=True)
class GainSurface:
    """The five P-PID gains of one axis as functions of airspeed.

    Parameters
    ----------
    basis : SurfaceBasis
        The basis.
    coefficients : ndarray of float, shape (5, d + 1)
        Row k: the coefficients of gain :data:`PARAM_NAMES` [k] (in that gain's unit:
        kp_angle 1/s, kp_rate N m s/rad, ki_rate N m/rad, kd_rate N m s^2/rad, tf_rate_s s).
    lower, upper : ndarray of float, shape (5,)
        Gain bounds; :meth:`gains_at` clips to them (default: unbounded).

    Examples
    --------
    >>> import numpy as np
    >>> b = SurfaceBasis(1, 0.0, 10.0)
    >>> c = np.array([[2.0, 1.0], [0.5, 0.0], [0.1, 0.0], [0.01, 0.0], [0.02, 0.0]])
    >>> sf = GainSurface(b, c, lower=np.zeros(5), upper=np.full(5, 2.5))
    >>> [round(sf.gains_at(v)["kp_angle"], 3) for v in (0.0, 5.0, 10.0)]  # 1, 2, 3 -> clip
    [1.0, 2.0, 2.5]
    """

    basis: SurfaceBasis
    coefficients: NDArray[np.float64]
    lower: NDArray[np.float64] = field(default_factory=lambda: np.full(5, -np.inf))
    upper: NDArray[np.float64] = field(default_factory=lambda: np.full(5, np.inf))

    def __post_init__(self) -> None:
        c = np.asarray(self.coefficients, dtype=float)
        if c.shape != (len(PARAM_NAMES), self.basis.size):
            raise ValueError(f"coefficients of shape {c.shape}: expected "
                             f"({len(PARAM_NAMES)}, {self.basis.size})")
        object.__setattr__(self, "coefficients", c)
        object.__setattr__(self, "lower", np.asarray(self.lower, dtype=float).reshape(-1))
        object.__setattr__(self, "upper", np.asarray(self.upper, dtype=float).reshape(-1))

    @classmethod
    def constant(cls, basis: SurfaceBasis, gains: Mapping[str, float], *,
                 lower: ArrayLike | None = None, upper: ArrayLike | None = None,
                 ) -> GainSurface:
        """The surface of constant gains: c_0 the gain, every other coefficient 0 (P_0 = 1,
        so the gains are reproduced exactly at every airspeed).

        Parameters
        ----------
        basis : SurfaceBasis
            The basis.
        gains : mapping of str to float
            The gains (keys :data:`PARAM_NAMES`).
        lower, upper : array_like of float, shape (5,), optional
            Gain bounds (default: none).

        Returns
        -------
        GainSurface
            The constant surface.
        """
        c = np.zeros((len(PARAM_NAMES), basis.size))
        c[:, 0] = [float(gains[k]) for k in PARAM_NAMES]
        lo = np.full(5, -np.inf) if lower is None else np.asarray(lower, float)
        hi = np.full(5, np.inf) if upper is None else np.asarray(upper, float)
        return cls(basis, c, lo, hi)

    def embed(self, degree: int) -> GainSurface:
        """The same surface in a basis of higher degree (new coefficients 0: the same gains
        at every airspeed, bit for bit).

        Parameters
        ----------
        degree : int
            The new degree, at least this surface's.

        Returns
        -------
        GainSurface
            The embedded surface (same airspeed range and bounds).

        Raises
        ------
        ValueError
            If ``degree`` is below this surface's.
        """
        if degree < self.basis.degree:
            raise ValueError(f"cannot embed degree {self.basis.degree} in degree {degree}")
        b = SurfaceBasis(degree, self.basis.v_lo_m_s, self.basis.v_hi_m_s)
        c = np.zeros((len(PARAM_NAMES), b.size))
        c[:, : self.basis.size] = self.coefficients
        return GainSurface(b, c, self.lower, self.upper)

    def gain_matrix(self, airspeeds_m_s: ArrayLike) -> NDArray[np.float64]:
        """Gains at every airspeed, clipped to the bounds.

        Parameters
        ----------
        airspeeds_m_s : array_like of float
            Airspeeds [m/s].

        Returns
        -------
        ndarray of float, shape (n, 5)
            Columns in :data:`PARAM_NAMES` order.
        """
        K = self.basis.evaluate(airspeeds_m_s) @ self.coefficients.T
        return np.clip(K, self.lower, self.upper)

    def gains_at(self, airspeed_m_s: float) -> dict[str, float]:
        """The gains at one airspeed.

        Parameters
        ----------
        airspeed_m_s : float
            Airspeed [m/s].

        Returns
        -------
        dict of str to float
            Gain name -> value (clipped to the bounds).
        """
        row = self.gain_matrix([airspeed_m_s])[0]
        return dict(zip(PARAM_NAMES, (float(x) for x in row), strict=True))


# ------------------------------------------------------------------------------------------
# the multi-model problem
# ------------------------------------------------------------------------------------------


def surface_grid(points: Sequence[DesignPoint], density: int = 2) -> tuple[DesignPoint, ...]:
    """A dense airspeed grid over ``points`` (sorted by airspeed): every design point and
    ``density - 1`` evenly spaced airspeeds between each consecutive pair, each with a
    perturbed range interpolated linearly between the pair's ranges (widened to contain its
    airspeed). Numbered from :data:`GRID_NUMBER_OFFSET` + 1. ``density`` 2 gives
    2 n - 1 points (DS-1's seven robust points: 13).

    Parameters
    ----------
    points : sequence of DesignPoint
        The design points (e.g. :func:`~vtolftc.synthesis.robust.robust_points`).
    density : int
        Grid intervals per design interval (>= 1; 1: the design points themselves).

    Returns
    -------
    tuple of DesignPoint
        The grid, by increasing airspeed.

    Raises
    ------
    ValueError
        For fewer than two points or ``density`` < 1.
    """
    pts = sorted(points, key=lambda p: p.airspeed_m_s)
    if len(pts) < 2 or density < 1:
        raise ValueError("a surface grid needs at least two design points and density >= 1")
    out: list[tuple[float, float, float]] = []
    for a, b in itertools.pairwise(pts):
        for k in range(density):
            t = k / density
            v = a.airspeed_m_s + t * (b.airspeed_m_s - a.airspeed_m_s)
            lo = a.v_min_m_s + t * (b.v_min_m_s - a.v_min_m_s)
            hi = a.v_max_m_s + t * (b.v_max_m_s - a.v_max_m_s)
            out.append((v, min(lo, v), max(hi, v)))
    last = pts[-1]
    out.append((last.airspeed_m_s, last.v_min_m_s, last.v_max_m_s))
    return tuple(DesignPoint(GRID_NUMBER_OFFSET + i + 1, v, lo, hi)
                 for i, (v, lo, hi) in enumerate(out))


@dataclass
class SurfaceChannel:
    """coefficients -> (A, B, C, D) of one point design channel at one grid airspeed.

    The coefficient vector theta is the (5, d + 1) coefficient matrix flattened row by row
    (gain-major); the gains at the grid point are ``clip(C phi, lower, upper)`` and the
    channel is the point design's ``inner(gains)``. Picklable.

    Parameters
    ----------
    inner : callable
        gains (5,) -> (A, B, C, D), e.g. a :class:`~vtolftc.synthesis.loops.CascadeChannel`.
    phi : ndarray of float, shape (d + 1,)
        The basis at the grid airspeed.
    lower, upper : ndarray of float, shape (5,)
        Gain bounds.
    """

    inner: Any
    phi: NDArray[np.float64]
    lower: NDArray[np.float64]
    upper: NDArray[np.float64]

    def gains(self, theta: NDArray[np.float64]) -> NDArray[np.float64]:
        """The five gains at this grid point.

        Parameters
        ----------
        theta : ndarray of float, shape (5 (d + 1),)
            The coefficient vector.

        Returns
        -------
        ndarray of float, shape (5,)
            The clipped gains in :data:`PARAM_NAMES` order.
        """
        C = np.asarray(theta, float).reshape(len(PARAM_NAMES), self.phi.size)
        return np.clip(C @ self.phi, self.lower, self.upper)

    def __call__(self, theta: NDArray[np.float64]) -> Any:
        return self.inner(self.gains(theta))

    def batch_gains(self, thetas: NDArray[np.float64]) -> NDArray[np.float64]:
        """:meth:`gains` of every row of ``thetas``.

        Parameters
        ----------
        thetas : ndarray of float, shape (nb, 5 (d + 1))
            Coefficient vectors, one per row.

        Returns
        -------
        ndarray of float, shape (nb, 5)
            The clipped gains of each row in :data:`PARAM_NAMES` order.
        """
        T = np.asarray(thetas, float).reshape(-1, len(PARAM_NAMES), self.phi.size)
        return np.clip(T @ self.phi, self.lower, self.upper)

    def realize_batch(self, thetas: NDArray[np.float64]) -> tuple[NDArray[np.float64], ...]:
        """The channel at every row of ``thetas`` (through ``inner.realize_batch``; each
        slice equals ``self(thetas[i])``).

        Parameters
        ----------
        thetas : ndarray of float, shape (nb, 5 (d + 1))
            Coefficient vectors, one per row.

        Returns
        -------
        A, B, C, D : ndarray
            Stacked realisations, each of shape (nb, ., .).
        """
        G = self.batch_gains(thetas)
        if hasattr(self.inner, "realize_batch"):
            return self.inner.realize_batch(G)
        mats = [as_state_space(self.inner(g)) for g in G]
        return tuple(np.stack([m[i] for m in mats]) for i in range(4))


class SurfaceRealizer:
    """theta -> (A, B, C, D) of every :class:`SurfaceChannel` of a problem, bit for bit
    ``[as_state_space(c(theta)) for c in channels]`` with less work per point.

    The channels of one grid point share the basis values, the gain bounds and (the robust
    design's eq. 8, disturbance and delay channels) the plant: their gains ``clip(C phi)``
    and their closed loop are computed once per group (the same operations on the same
    operands), each channel is assembled around that loop
    (:meth:`~vtolftc.synthesis.loops.CascadeChannel.assemble`, fresh float64 arrays of
    fixed shapes), and instead of :func:`~vtolftc.synthesis.hinfnorm.as_state_space`'s
    checked copy of every matrix one finiteness test covers the whole point (a non-finite
    point goes through ``as_state_space`` channel by channel, which raises the same error).
    Picklable.

    Parameters
    ----------
    channels : sequence of SurfaceChannel
        The channels; their ``inner`` must be
        :class:`~vtolftc.synthesis.loops.CascadeChannel` (see :meth:`applies`).
    chain_rule : bool
        Offer :meth:`gain_derivatives` to the tuner (default True).
    """

    def __init__(self, channels: Sequence[SurfaceChannel], chain_rule: bool = True):
        self.channels = list(channels)
        #: Whether the tuner differentiates through :meth:`gain_derivatives` (False: central
        #: differences in the coefficients, the tuner's default).
        self.chain_rule = bool(chain_rule)
        if not self.applies(self.channels):
            raise ValueError("SurfaceRealizer needs SurfaceChannels around CascadeChannels")
        groups: dict[bytes, list[int]] = {}
        for i, c in enumerate(self.channels):
            key = b"".join([c.phi.tobytes(), c.lower.tobytes(), c.upper.tobytes(),
                            np.asarray(c.phi.shape, np.int64).tobytes(), c.inner._gkey])
            groups.setdefault(key, []).append(i)
        self.groups = list(groups.values())

    @staticmethod
    def applies(channels: Sequence[Any]) -> bool:
        """Whether every channel is a SurfaceChannel around a CascadeChannel.

        Parameters
        ----------
        channels : sequence
            A problem's channels.

        Returns
        -------
        bool
            True when :class:`SurfaceRealizer` can realise them.
        """
        return all(isinstance(c, SurfaceChannel) and isinstance(c.inner, CascadeChannel)
                   for c in channels)

    def __call__(self, theta: NDArray[np.float64]) -> list[StateSpaceData]:
        chans = self.channels
        out: list[Any] = [None] * len(chans)
        for idx in self.groups:
            first = chans[idx[0]]
            cl = first.inner.loop(first.gains(theta))
            for i in idx:
                out[i] = chans[i].inner.assemble(cl)
        if not np.isfinite(np.concatenate([x.ravel() for m in out for x in m])).all():
            return [as_state_space(m) for m in out]   # raises for the first bad channel
        return out

    n_local = len(PARAM_NAMES)
    """Gains per grid point: the parameters :meth:`gain_derivatives` differentiates in."""

    def gain_derivatives(self, theta: NDArray[np.float64], scales: NDArray[np.float64],
                         ) -> list[tuple[tuple[NDArray[np.float64], ...],
                                         NDArray[np.float64]]] | None:
        """Per channel the derivatives of (A, B, C, D) with respect to its grid point's five
        gains, by central differences in the gains, and d gains / d theta (the chain rule).

        The coefficients enter a channel only through ``g = clip(C phi, lower, upper)``, so
        d X / d theta = sum_j d X / d g_j * d g_j / d theta: 10 perturbed realisations per
        grid point instead of the 2 p of differences in theta. d g_j / d C[j, m] =
        ``phi[m]`` where ``lower_j < (C phi)_j < upper_j``, 0 where clipped and 1/2 on a
        bound (what central differences in theta see there). The gain steps are
        ``1e-6 max(|g_j|, s_j)``, s_j the scale of gain j's coefficient c_0.

        Parameters
        ----------
        theta : ndarray of float, shape (5 (d + 1),)
            The coefficient vector (gain-major).
        scales : ndarray of float, shape (5 (d + 1),)
            The coefficients' scales (gain-major); those of the c_0 are the gains'.

        Returns
        -------
        list of tuple or None
            Per channel ``((dA, dB, dC, dD), J)``: each derivative stacked over the five
            gains (5, ., .), ``J`` of shape (5, 5 (d + 1)) the gains' Jacobian; None when a
            perturbed realisation is not finite.
        """
        chans = self.channels
        theta = np.asarray(theta, float)
        out: list[Any] = [None] * len(chans)
        ng = len(PARAM_NAMES)
        for idx in self.groups:
            first = chans[idx[0]]
            phi = first.phi
            raw = theta.reshape(ng, phi.size) @ phi
            g = np.clip(raw, first.lower, first.upper)
            hs = 1e-6 * np.maximum(np.abs(g), scales[::phi.size])
            pts = np.repeat(g[None, :], 2 * ng, axis=0)
            for j in range(ng):
                pts[2 * j, j] += hs[j]
                pts[2 * j + 1, j] -= hs[j]
            h2 = (2.0 * hs)[:, None, None]
            slope = np.where((raw > first.lower) & (raw < first.upper), 1.0,
                             np.where((raw == first.lower) | (raw == first.upper), 0.5, 0.0))
            J = np.zeros((ng, theta.size))
            for j in range(ng):
                J[j, j * phi.size:(j + 1) * phi.size] = slope[j] * phi
            for i in idx:
                ders = []
                for X in chans[i].inner.realize_batch(pts):
                    if not np.isfinite(X).all():
                        return None
                    ders.append((X[0::2] - X[1::2]) / h2)
                out[i] = (tuple(ders), J)
        return out

    def batch(self, thetas: NDArray[np.float64]) -> list[tuple[NDArray[np.float64], ...]]:
        """Per channel ``c.realize_batch(thetas)``, bit for bit, the gains of each group
        computed once.

        Parameters
        ----------
        thetas : ndarray of float, shape (nb, 5 (d + 1))
            Coefficient vectors, one per row.

        Returns
        -------
        list of tuple of ndarray
            Per channel the stacked (A, B, C, D), each (nb, ., .).
        """
        chans = self.channels
        out: list[Any] = [None] * len(chans)
        for idx in self.groups:
            G = chans[idx[0]].batch_gains(thetas)
            for i in idx:
                out[i] = chans[i].inner.realize_batch(G)
        return out


@dataclass
class SurfaceProblem:
    """The tuning problem of one axis' gain surface and what it was made of.

    Parameters
    ----------
    problem : TuningProblem
        Over the flattened coefficients (gain-major).
    basis : SurfaceBasis
        The basis.
    grid : tuple of DesignPoint
        The grid points.
    point_of_channel : list of int
        Grid index of each channel.
    lower, upper : ndarray of float, shape (5,)
        Gain bounds (the point design's).
    gain_parameters : list of Parameter
        The point design's gain parameters (initial value, bounds, scale).
    """

    problem: TuningProblem
    basis: SurfaceBasis
    grid: tuple[DesignPoint, ...]
    point_of_channel: list[int]
    lower: NDArray[np.float64]
    upper: NDArray[np.float64]
    gain_parameters: list[Parameter]

    def surface(self, theta: ArrayLike) -> GainSurface:
        """The gain surface of a coefficient vector.

        Parameters
        ----------
        theta : array_like of float, shape (5 (d + 1),)
            Coefficients, gain-major.

        Returns
        -------
        GainSurface
            The surface (with this problem's gain bounds).
        """
        c = np.asarray(theta, float).reshape(len(PARAM_NAMES), self.basis.size)
        return GainSurface(self.basis, c, self.lower, self.upper)

    def grid_norms(self, theta: ArrayLike) -> NDArray[np.float64]:
        """Per grid point, the max H-infinity norm over its channels (the objective is
        their max).

        Parameters
        ----------
        theta : array_like of float, shape (5 (d + 1),)
            Coefficients, gain-major.

        Returns
        -------
        ndarray of float, shape (n_grid,)
            The norms (inf where a loop is unstable).
        """
        vals = self.problem.channel_norms(np.asarray(theta, float))
        out = np.full(len(self.grid), -np.inf)
        for v, i in zip(vals, self.point_of_channel, strict=True):
            out[i] = max(out[i], v)
        return out


def _embedded(c: NDArray[np.float64], size: int) -> NDArray[np.float64]:
    C = np.zeros((len(PARAM_NAMES), size))
    C[:, : c.shape[1]] = c
    return C


def surface_problem(method: DesignMethod, af: Airframe, axis: Axis,
                    grid: Sequence[DesignPoint], degree: int, *,
                    start: GainSurface | None = None,
                    weights: Sequence[Any] | None = None,
                    chain_rule: bool = True) -> SurfaceProblem:
    """The multi-model problem of ``axis``' gain surface of ``degree`` over ``grid``.

    At every grid point the channels are those of ``method``'s point design
    (``method.setup(af, axis, [weights])``); the gain bounds, initial gains and scales are
    those of ``method``'s problem over the whole grid (e.g. the robust method bounds the gains
    by the smallest authority on the grid). Coefficient parameters: c_0 with the gain's
    initial value, bounds and scale; c_j (j >= 1) start at 0, bounded by +-(upper - lower)
    (by +-10 scales where a bound is infinite), scale a third of the gain's.

    Parameters
    ----------
    method : DesignMethod
        A method whose weights are defined at any airspeed, e.g.
        :class:`~vtolftc.synthesis.robust.RobustMethod` (its channels, weights, bounds; its
        weights are formulae of the airspeed and the perturbed range). The paper's method is
        not one: its Ws comes from table 2, defined only at table 1's six points.
    af : Airframe
        The airframe.
    axis : {"roll", "pitch", "yaw"}
        The axis.
    grid : sequence of DesignPoint
        The grid (:func:`surface_grid`); the basis spans its airspeed range.
    degree : int
        Polynomial degree d >= 0.
    start : GainSurface, optional
        Initial coefficients (embedded into ``degree``; clipped into the coefficient bounds).
    weights : sequence, optional
        ``method.weights`` of every grid point, if already computed.
    chain_rule : bool
        Derivatives by the chain rule through each grid point's gains
        (:meth:`SurfaceRealizer.gain_derivatives`; default True) rather than central
        differences in the coefficients.

    Returns
    -------
    SurfaceProblem
        The problem.
    """
    grid = tuple(grid)
    ws = [method.weights(af, axis, p) for p in grid] if weights is None else list(weights)
    vs = [p.airspeed_m_s for p in grid]
    basis = SurfaceBasis(degree, min(vs), max(vs))
    whole = method.setup(af, axis, ws).problem
    gp = list(whole.parameters)
    if [p.name for p in gp] != list(PARAM_NAMES):
        raise ValueError(f"the method's parameters {[p.name for p in gp]} are not "
                         f"{list(PARAM_NAMES)}")
    lo = np.array([p.lower for p in gp])
    hi = np.array([p.upper for p in gp])
    Phi = basis.evaluate(vs)
    chans: list[SurfaceChannel] = []
    names: list[str] = []
    owner: list[int] = []
    for i, w in enumerate(ws):
        pb = method.setup(af, axis, [w]).problem
        for c, nm in zip(pb.channels, pb.channel_names or [], strict=True):
            chans.append(SurfaceChannel(c, Phi[i].copy(), lo, hi))
            names.append(f"{nm} @ {vs[i]:g} m/s")
            owner.append(i)
    pb = TuningProblem(coefficient_parameters(gp, basis, start), chans, names,
                       realizer=SurfaceRealizer(chans, chain_rule)
                       if SurfaceRealizer.applies(chans) else None)
    return SurfaceProblem(pb, basis, grid, owner, lo, hi, gp)


def coefficient_parameters(gain_parameters: Sequence[Parameter], basis: SurfaceBasis,
                           start: GainSurface | None = None) -> list[Parameter]:
    """The tunable coefficients of a gain surface (gain-major: c_0 .. c_d of each gain).

    c_0 takes the gain's initial value (or ``start``'s c_0), bounds and scale; c_j (j >= 1)
    start at 0 (or ``start``'s, embedded into ``basis``' degree), bounded by
    +-(upper - lower) (by +-10 scales where a bound is infinite), scale a third of the gain's.

    Parameters
    ----------
    gain_parameters : sequence of Parameter
        The point design's five gain parameters (:data:`PARAM_NAMES` order).
    basis : SurfaceBasis
        The surface's basis.
    start : GainSurface, optional
        Initial coefficients (degree at most ``basis``'; clipped into the bounds).

    Returns
    -------
    list of Parameter
        5 (d + 1) parameters named ``"kp_angle[0]"`` ...

    Raises
    ------
    ValueError
        For a start of higher degree than ``basis``.
    """
    gp = list(gain_parameters)
    if start is not None and start.basis.degree > basis.degree:
        raise ValueError(f"start of degree {start.basis.degree} above the problem's "
                         f"{basis.degree}")
    C0 = (_embedded(np.array([[p.initial] for p in gp]), basis.size) if start is None
          else start.embed(basis.degree).coefficients)
    params: list[Parameter] = []
    for k, p in enumerate(gp):
        for j in range(basis.size):
            if j == 0:
                x = float(np.clip(C0[k, 0], p.lower, p.upper))
                params.append(Parameter(f"{p.name}[0]", x, p.lower, p.upper, scale=p.typical))
                continue
            span = p.upper - p.lower
            r = span if math.isfinite(span) else 10.0 * p.typical
            x = float(np.clip(C0[k, j], -r, r))
            params.append(Parameter(f"{p.name}[{j}]", x, -r, r, scale=p.typical / 3.0))
    return params


# ------------------------------------------------------------------------------------------
# SHIF then GS-SHIF
# ------------------------------------------------------------------------------------------


@dataclass
class SurfaceDesign:
    """The constant (SHIF) and surface (GS-SHIF) designs of one axis over one grid.

    Parameters
    ----------
    axis : str
        The axis.
    grid : tuple of DesignPoint
        The grid.
    constant, surface : GainSurface
        Degree-0 design and the degree-d design started from it.
    constant_objective, surface_objective : float
        The design objective (max over grid points and channels of the H-infinity norms) of
        each, evaluated exactly on the surface problem.
    constant_grid_norms, surface_grid_norms : ndarray of float
        Per grid point, the max norm over its channels.
    kept_start : bool
        True when the surface tune returned a worse point and the SHIF start was kept.
    time_s : dict of str to float
        Wall time of the two tunes [s].
    messages : dict of str to str
        The tuner's messages.
    """

    axis: Axis
    grid: tuple[DesignPoint, ...]
    constant: GainSurface
    surface: GainSurface
    constant_objective: float
    surface_objective: float
    constant_grid_norms: NDArray[np.float64]
    surface_grid_norms: NDArray[np.float64]
    kept_start: bool
    time_s: dict[str, float]
    messages: dict[str, str]

    def to_dict(self) -> dict[str, Any]:
        """A JSON-ready summary.

        Returns
        -------
        dict
            Basis, grid, objectives, per-point norms, coefficients, times [s].
        """
        return {"axis": self.axis, "degree": self.surface.basis.degree,
                "basis": "legendre", "v_lo_m_s": self.surface.basis.v_lo_m_s,
                "v_hi_m_s": self.surface.basis.v_hi_m_s,
                "grid_m_s": [p.airspeed_m_s for p in self.grid],
                "constant_objective": self.constant_objective,
                "surface_objective": self.surface_objective,
                "constant_grid_norms": self.constant_grid_norms.tolist(),
                "surface_grid_norms": self.surface_grid_norms.tolist(),
                "coefficients": {k: self.surface.coefficients[i].tolist()
                                 for i, k in enumerate(PARAM_NAMES)},
                "kept_start": self.kept_start, "time_s": self.time_s,
                "messages": self.messages}


def design_surfaces(method: DesignMethod, af: Airframe, axis: Axis,
                    grid: Sequence[DesignPoint], degree: int = 2, *, n_starts: int = 2,
                    surface_starts: int = 0, seed: int = 0, max_iter: int | None = 40,
                    settings: SurfaceTune | None = None) -> SurfaceDesign:
    """SHIF (degree 0) then GS-SHIF (``degree``, started from SHIF) for ``axis`` on ``grid``.

    Parameters
    ----------
    method : DesignMethod
        The point design whose channels and bounds are used at each grid point.
    af : Airframe
        The airframe.
    axis : {"roll", "pitch", "yaw"}
        The axis.
    grid : sequence of DesignPoint
        The airspeed grid (:func:`surface_grid`).
    degree : int
        Degree of the surface (>= 0; 0 makes both designs the same problem).
    n_starts : int
        Random starts of the constant tune besides its initial point.
    surface_starts : int
        Random starts of the surface tune besides the embedded SHIF solution (which is
        always its first start).
    seed : int
        Seed (streams per axis, as the point designs').
    max_iter : int or None
        Iteration cap per start (:func:`~vtolftc.synthesis.structured.tune`).
    settings : SurfaceTune, optional
        How the surface tune runs (default ``SURFACE_TUNE[axis]``; SHIF keeps the tuner's
        defaults).

    Returns
    -------
    SurfaceDesign
        Both designs; ``surface_objective <= constant_objective`` always holds.
    """
    grid = tuple(grid)
    ws = [method.weights(af, axis, p) for p in grid]
    t0 = time.perf_counter()
    sp0 = surface_problem(method, af, axis, grid, 0, weights=ws)
    r0 = tune(sp0.problem, n_starts=n_starts, seed=point_seed(seed, axis, SURFACE_TAG),
              max_iter=max_iter)
    const = sp0.surface(r0.theta)
    t1 = time.perf_counter()
    st = SURFACE_TUNE[axis] if settings is None else settings
    spd = surface_problem(method, af, axis, grid, degree, start=const, weights=ws,
                          chain_rule=st.chain_rule)
    start = spd.problem.initial
    f0 = spd.problem.objective(start)
    rd = tune(spd.problem, n_starts=surface_starts,
              seed=point_seed(seed, axis, SURFACE_TAG + 1), max_iter=max_iter,
              inner_ftol=st.inner_ftol)
    fd = spd.problem.objective(rd.theta)
    kept = not (fd <= f0)
    theta = start if kept else rd.theta
    t2 = time.perf_counter()
    return SurfaceDesign(
        axis, grid, const, spd.surface(theta), f0, f0 if kept else fd,
        spd.grid_norms(start), spd.grid_norms(theta), kept,
        {"constant": t1 - t0, "surface": t2 - t1},
        {"constant": r0.message, "surface": rd.message})


# ------------------------------------------------------------------------------------------
# export
# ------------------------------------------------------------------------------------------


def schedule_from_surfaces(af: Airframe, surfaces: Mapping[str, GainSurface],
                           breakpoints_m_s: Sequence[float], controller: str = "gs-shif",
                           metadata: Mapping[str, Any] | None = None) -> dict[str, Any]:
    """The ``vtolftc-gain-schedule/1`` document of one gain surface per axis, sampled at
    ``breakpoints_m_s`` [m/s] (the autopilot interpolates linearly between them and holds the
    end values beyond); write it with :func:`vtolftc.synthesis.export.write_json` as
    ``gs-shif.json`` (or ``shif.json`` for a degree-0 design) in a gains directory.

    Parameters
    ----------
    af : Airframe
        The airframe (its sha256 is recorded; the autopilot checks it).
    surfaces : mapping of str to GainSurface
        One surface per axis (roll, pitch, yaw).
    breakpoints_m_s : sequence of float
        Strictly increasing airspeeds [m/s], e.g. the design grid.
    controller : str
        The controller name written in the file.
    metadata : mapping, optional
        Extra top-level entries.

    Returns
    -------
    dict
        The document.

    Examples
    --------
    >>> from vtolftc.airframe.loader import load_airframe
    >>> b = SurfaceBasis(0, 0.0, 18.0)
    >>> g = {"kp_angle": 2.0, "kp_rate": 0.5, "ki_rate": 0.1, "kd_rate": 0.01,
    ...      "tf_rate_s": 0.02}
    >>> doc = schedule_from_surfaces(load_airframe(), {ax: GainSurface.constant(b, g)
    ...                              for ax in ("roll", "pitch", "yaw")}, [0.0, 9.0, 18.0])
    >>> doc["format"], doc["axes"]["pitch"]["kp_rate"]
    ('vtolftc-gain-schedule/1', [0.5, 0.5, 0.5])
    """
    bps = [float(v) for v in breakpoints_m_s]
    gains = {ax: [dict(zip(PARAM_NAMES, (float(x) for x in row), strict=True))
                  for row in sf.gain_matrix(bps)]
             for ax, sf in surfaces.items()}
    meta = {"synthesis_method": "surface",
            "surfaces": {ax: {"basis": "legendre", "degree": sf.basis.degree,
                              "v_lo_m_s": sf.basis.v_lo_m_s, "v_hi_m_s": sf.basis.v_hi_m_s,
                              "coefficients": {k: sf.coefficients[i].tolist()
                                               for i, k in enumerate(PARAM_NAMES)}}
                         for ax, sf in surfaces.items()}}
    meta.update(metadata or {})
    return schedule_document(af, controller, bps, gains, metadata=meta)


def write_surface_gains(af: Airframe, designs: Mapping[str, SurfaceDesign],
                        out_dir: str | Path, metadata: Mapping[str, Any] | None = None,
                        ) -> dict[str, Path]:
    """Write a gains directory of surface designs that the autopilot flies
    (``vtolftc fly --gains DIR``, ``run_scenario(..., gains_dir=DIR)``).

    ``gs-shif.json``: the surfaces sampled at the grid airspeeds (the breakpoints);
    ``shif.json``: the constant (degree-0) designs; ``surfaces.json``: every design's
    :meth:`SurfaceDesign.to_dict`. No ``lqr.json`` (copy the shipped one to fly LQR from it).

    Parameters
    ----------
    af : Airframe
        The airframe the designs are for (its sha256 goes in the files).
    designs : mapping of str to SurfaceDesign
        One design per axis (roll, pitch, yaw), all on the same grid.
    out_dir : str or pathlib.Path
        The directory (created if missing).
    metadata : mapping, optional
        Extra top-level entries of both gain files (e.g. ``design_points``).

    Returns
    -------
    dict of str to pathlib.Path
        ``"gs-shif"``, ``"shif"``, ``"surfaces"`` -> the files written.

    Raises
    ------
    ValueError
        If the designs are not on one grid.
    """
    grids = {tuple(p.airspeed_m_s for p in d.grid) for d in designs.values()}
    if len(grids) != 1:
        raise ValueError("the axes' surface designs are on different grids")
    bps = list(grids.pop())
    out = Path(out_dir)
    out.mkdir(parents=True, exist_ok=True)
    summary = {"axes": {ax: d.to_dict() for ax, d in designs.items()}}
    return {
        "gs-shif": write_json(out / "gs-shif.json", schedule_from_surfaces(
            af, {ax: d.surface for ax, d in designs.items()}, bps, "gs-shif", metadata)),
        "shif": write_json(out / "shif.json", schedule_from_surfaces(
            af, {ax: d.constant for ax, d in designs.items()}, bps, "shif", metadata)),
        "surfaces": write_json(out / "surfaces.json", summary),
    }

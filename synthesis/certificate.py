"""Real-parametric robust-stability certificate of a designed P-PID axis loop (mixed mu).

The paper's table 3 covers the perturbed model set by one complex multiplicative weight
(lumped complex mu, :mod:`vtolftc.synthesis.robustness`). This module analyses the *real
parametric* family itself: every model of eq. 1-3 with the airspeed V in the design point's
interval [v_min, v_max] and the loss of effectiveness gamma in ``GAMMA_RANGE`` (0 .. 0.6),
the same box the cover of :mod:`vtolftc.synthesis.uncertainty` is fitted to, closed by the
controller with the gains of one design point.

The family as an exact LFT
--------------------------
The airframe's derivative tables (C_lp, C_mq, C_malpha, C_nr, C_nbeta) are linear in V
between their breakpoints (:meth:`vtolftc.airframe.loader.DerivativeTables.at`), so the
coefficients of :func:`vtolftc.synthesis.models.axis_coefficients` are polynomials in V only
piecewise: on one linear piece [V_a, V_b] of the tables,

    damping   D(V) = k_D V C_rate(V)            quadratic in V,
    stiffness K(V) = k_K V^2 C_stiff(V)         cubic in V (roll: 0),
    effectiveness (1 - gamma)                    affine in gamma.

A design point's interval is therefore split at the table breakpoints it contains
(:func:`airspeed_pieces`) and each piece gets its own exact LFT with the normalised real
parameters V = V_c + r_V dV, gamma = g_c + r_g dg, dV, dg in [-1, 1] (V_c, r_V the piece's
centre and half-width, g_c = r_g = 0.3). The row [K, D](dV) is a polynomial of degree n
(2 for roll, 3 for pitch and yaw; one less where a table segment is flat); Horner's scheme
z_n = p_n xi, z_i = p_i xi + w_{i+1}, w_i = dV z_i, [K, D] xi = p_0 xi + w_1, with
xi = [angle; rate], realises it with dV repeated n times, and (1 - gamma) u = (1 - g_c) u -
r_g dg u with dg once. The structure is diag(dV I_n, dg) (``Block.real(n)``,
``Block.real(1)``); the feedthrough z -> w is strictly upper triangular, so the LFT is well
posed for every dV, dg and M(inf) has mu = 0. The point is robustly stable iff every piece
is; its mixed mu is the largest over its pieces (each in its own normalisation).

Plants (:class:`PlantKind`): ``"lagged"`` is the robust design's plant
(:func:`vtolftc.synthesis.robust.design_plant`: eq. 1-3 behind the first-order actuator lag
with the 8 ms loop delay folded in, 1 / ((tau_act + T) s + 1)); ``"paper"`` is the paper's
plant (eq. 1-3 alone, :func:`vtolftc.synthesis.models.attitude_model`). The dense grid and
the LFT use the same plant.

Three numbers per point and axis
--------------------------------
1. Mixed-mu **upper bound** (D-G scaling, :func:`vtolftc.synthesis.mixed_mu.mixed_mu_upper`,
   numpy D-G: AB13MD takes 1 x 1 real blocks only, and splitting dV I_n into n independent
   real scalars would be a larger family) over w = 0, a log grid refined around the largest
   local maxima, and the frequencies where the family first loses stability towards the
   box's vertices (:func:`vertex_crossings`: with two real parameters the peak of real mu
   is smooth or a kink on a vertex ray; real mu is discontinuous in frequency, so there the
   bound is also taken with a small complex part added to each real scalar). w = 0 is
   included exactly (M(0) is real: a real closed-loop pole crossing the origin), and
   :func:`zero_frequency_margin` checks det(I - M(0) Delta) over the box directly.
   mu < 1 at every frequency certifies robust stability of the box (:func:`mu_real_sweep`).
2. Mixed-mu **lower bound**: verified destabilising real perturbations
   (:func:`two_parameter_lower`, exact for diag(dV I_n, dg) up to its grid, and
   :func:`vtolftc.synthesis.mixed_mu.mixed_mu_lower` at the peak where that one falls short).
3. **Dense grid** (:func:`grid_check`): closed-loop poles of the true model family (the
   airframe's interpolated tables through ``axis_coefficients``, not the LFT) on a 41 x 41
   grid over V x gamma: the verdict and the largest real part; and the **grid margin**: the
   smallest scaling k of each piece's box (about its centre, the coefficient polynomials
   continued beyond the piece, as the LFT continues them) at which a grid member is
   unstable, found by bisection. A grid member unstable at scale k proves mu >= 1/k (the
   segment from the stable centre crosses the imaginary axis within the box of scale k), so
   1/k is an independent estimate of mu from below. Robust stability is the question
   answered; robust performance is not part of this certificate.
"""

from __future__ import annotations

import itertools
import math
from collections.abc import Mapping, Sequence
from dataclasses import dataclass, field
from typing import Any, Literal

import numpy as np
from numpy.polynomial import polynomial as npoly
from numpy.typing import NDArray
from scipy.optimize import brentq

from vtolftc.airframe.loader import Airframe
from vtolftc.synthesis.hinfnorm import StateSpaceData, frequency_response
from vtolftc.synthesis.lft import GeneralizedPlant, lft
from vtolftc.synthesis.loops import PARAM_NAMES, rate_controller
from vtolftc.synthesis.mixed_mu import mixed_mu_lower, mixed_mu_upper, mixed_mu_upper_start
from vtolftc.synthesis.models import Axis, axis_coefficients
from vtolftc.synthesis.mu import Block, MuSweep
from vtolftc.synthesis.mu_blocks import BlockStructure
from vtolftc.synthesis.robust import LoopDelays, actuator_time_constant
from vtolftc.synthesis.uncertainty import GAMMA_RANGE, DesignPoint

__all__ = [
    "GridCheck",
    "ParametricFamily",
    "PieceResult",
    "PlantKind",
    "PointCertificate",
    "airspeed_pieces",
    "certify_point",
    "certify_schedule",
    "closed_loop_lft",
    "design_points",
    "family",
    "gains_at",
    "grid_check",
    "grid_margin",
    "mu_real_sweep",
    "plant_lft",
    "true_closed_loop_matrices",
    "two_parameter_lower",
    "upper_lft_plant",
    "vertex_crossings",
    "zero_frequency_margin",
]

PlantKind = Literal["lagged", "paper"]
#: Frequencies of the sweep besides w = 0 [rad/s] (refined around the peak).
SWEEP_OMEGAS = np.logspace(-3, 3, 37)
#: The robust design's loop delays (8 ms modelled transport).
DEFAULT_DELAYS = LoopDelays()
#: Complex part added to the real scalars at the crossing frequencies (see mu_real_sweep).
REGULARISATION = 1e-3
#: Largest box scaling the grid margin searches (beyond: "> K_MAX").
K_MAX = 8.0

_RATE = {"roll": "C_lp", "pitch": "C_mq", "yaw": "C_nr"}
_STIFF = {"pitch": "C_malpha", "yaw": "C_nbeta"}


# ------------------------------------------------------------------------------------------
# the parametric family
# ------------------------------------------------------------------------------------------


def airspeed_pieces(af: Airframe, point: DesignPoint) -> list[tuple[float, float]]:
    """The point's airspeed interval split at the derivative-table breakpoints inside it.

    On each piece the tables are linear in V.

    Parameters
    ----------
    af : Airframe
        The airframe (its derivative tables).
    point : DesignPoint
        The design point (its perturbed airspeed range).

    Returns
    -------
    list of (float, float)
        (v_lo, v_hi) of each piece (m/s), in increasing order.

    Raises
    ------
    ValueError
        For an empty airspeed range.
    """
    lo, hi = float(point.v_min_m_s), float(point.v_max_m_s)
    if not hi > lo:
        raise ValueError(f"design point {point.number}: empty airspeed range [{lo}, {hi}]")
    cuts = [float(v) for v in af.derivatives.airspeed_m_s if lo < float(v) < hi]
    edges = [lo, *cuts, hi]
    return list(itertools.pairwise(edges))


@dataclass(frozen=True)
class ParametricFamily:
    """One axis on one linear piece: the coefficients as polynomials in the normalised parameters.

    Polynomials are in ``numpy.polynomial`` order (lowest power first). V = ``v_centre`` +
    ``v_half`` dV [m/s], gamma = ``g_centre`` + ``rg`` dg, dV and dg in [-1, 1].

    Parameters
    ----------
    axis : {"roll", "pitch", "yaw"}
        The axis.
    inertia : float
        J of the axis (kg m^2).
    damping : ndarray of float
        Damping polynomial in dV (N m s / rad).
    stiffness : ndarray of float
        Stiffness polynomial in dV (N m / rad).
    v_centre, v_half : float
        Centre and half width of the airspeed piece (m/s).
    g_centre, rg : float
        Centre and half width of the gamma range; effectiveness 1 - gamma = ``b0`` - ``rg`` dg.
    tau_s : float or None
        The lag of the plant (s) (None: the paper's plant, no lag).
    """

    axis: Axis
    inertia: float
    damping: NDArray[np.float64]
    stiffness: NDArray[np.float64]
    v_centre: float
    v_half: float
    g_centre: float
    rg: float
    tau_s: float | None

    @property
    def b0(self) -> float:
        """Effectiveness 1 - gamma at the centre."""
        return 1.0 - self.g_centre

    @property
    def row(self) -> NDArray[np.float64]:
        """p_i = [K_i, D_i] (rows i = 0..n): [K, D](dV) = sum_i p_i dV^i."""
        n = max(self.damping.size, self.stiffness.size)
        p = np.zeros((n, 2))
        p[: self.stiffness.size, 0] = self.stiffness
        p[: self.damping.size, 1] = self.damping
        while p.shape[0] > 1 and not np.any(p[-1]):
            p = p[:-1]
        return p

    @property
    def n_v(self) -> int:
        """Repetitions of dV in the LFT (the degree of [K, D] in dV)."""
        return self.row.shape[0] - 1

    @property
    def blocks(self) -> list[Block]:
        """diag(dV I_n, dg) (dV omitted if the coefficients do not depend on V)."""
        return ([Block.real(self.n_v)] if self.n_v > 0 else []) + [Block.real(1)]

    def coefficients(self, dV: Any, dg: Any) -> tuple[NDArray[Any], NDArray[Any], NDArray[Any]]:
        """(damping, stiffness, 1 - gamma) at normalised parameters.

        The polynomials are continued beyond [-1, 1].

        Parameters
        ----------
        dV, dg : float or array_like
            Normalised airspeed and effectiveness-loss parameters (arrays broadcast).

        Returns
        -------
        damping, stiffness, effectiveness : ndarray
            N m s / rad, N m / rad and 1 - gamma.
        """
        dV = np.asarray(dV, float)
        dg = np.asarray(dg, float)
        return (npoly.polyval(dV, self.damping) + 0 * dg,
                npoly.polyval(dV, self.stiffness) + 0 * dg,
                self.b0 - self.rg * dg + 0 * dV)

    def scaled(self, factor: float) -> ParametricFamily:
        """The same family with its box scaled by ``factor`` about the centre.

        dV and dg are renormalised: the polynomial coefficients of dV^i are multiplied by
        factor^i.

        Parameters
        ----------
        factor : float
            Box scaling (1: unchanged).

        Returns
        -------
        ParametricFamily
            The scaled family.
        """
        f = float(factor)
        pw = f ** np.arange(max(self.damping.size, self.stiffness.size))
        return ParametricFamily(self.axis, self.inertia, self.damping * pw[: self.damping.size],
                                self.stiffness * pw[: self.stiffness.size], self.v_centre,
                                self.v_half * f, self.g_centre, self.rg * f, self.tau_s)

    def airspeed(self, dV: Any) -> Any:
        """V [m/s] at normalised dV.

        Parameters
        ----------
        dV : float or array_like
            Normalised airspeed parameter.

        Returns
        -------
        float or ndarray
            Airspeed (m/s).
        """
        return self.v_centre + self.v_half * np.asarray(dV, float)

    def gamma(self, dg: Any) -> Any:
        """gamma at normalised dg.

        Parameters
        ----------
        dg : float or array_like
            Normalised effectiveness-loss parameter.

        Returns
        -------
        float or ndarray
            The loss of effectiveness gamma.
        """
        return self.g_centre + self.rg * np.asarray(dg, float)


def _plant_tau(af: Airframe, plant: PlantKind, delays: LoopDelays) -> float | None:
    if plant == "lagged":
        return actuator_time_constant(af) + max(0.0, delays.transport_s)
    if plant == "paper":
        return None
    raise ValueError(f"plant {plant!r}: expected 'lagged' or 'paper'")


def family(af: Airframe, axis: Axis, v_lo: float, v_hi: float,
           gamma_range: tuple[float, float] = GAMMA_RANGE, plant: PlantKind = "lagged",
           delays: LoopDelays = DEFAULT_DELAYS) -> ParametricFamily:
    """The exact polynomial parametrisation of ``axis`` on one airspeed piece.

    Same formulas as :func:`vtolftc.synthesis.models.axis_coefficients` (tested against it):
    damping = rho V S L^2 C_rate(V) / 4 (L = span for roll and yaw, chord for pitch),
    stiffness = qbar S c C_malpha(V) (pitch), -qbar S b C_nbeta(V) (yaw), 0 (roll), with
    C(V) = C(V_c) + (C(V_b) - C(V_a)) / 2 dV on the piece.

    Parameters
    ----------
    af : Airframe
        The airframe.
    axis : {"roll", "pitch", "yaw"}
        The axis.
    v_lo, v_hi : float
        The piece (m/s); the tables must be linear on it (see :func:`airspeed_pieces`).
    gamma_range : (float, float)
        Range of the loss of effectiveness.
    plant : {"lagged", "paper"}
        With the actuator and loop-delay lag of the robust design, or the paper's plant.
    delays : LoopDelays
        Loop delays of the lagged plant.

    Returns
    -------
    ParametricFamily
        The family.

    Raises
    ------
    ValueError
        For a piece outside 0 <= v_lo < v_hi, one that straddles a table breakpoint, or an
        unknown plant kind.
    """
    if not v_hi > v_lo >= 0.0:
        raise ValueError(f"airspeed piece [{v_lo}, {v_hi}]: expected 0 <= v_lo < v_hi m/s")
    bp = np.asarray(af.derivatives.airspeed_m_s, float)
    if np.any((bp > v_lo) & (bp < v_hi)):
        raise ValueError(f"airspeed piece [{v_lo}, {v_hi}] straddles a derivative-table "
                         "breakpoint; split it with airspeed_pieces")
    vc, r = 0.5 * (v_lo + v_hi), 0.5 * (v_hi - v_lo)
    da, db, dc = (af.derivatives.at(v) for v in (v_lo, v_hi, vc))
    w = af.wing
    rho = af.air_density_kg_m3
    V = np.array([vc, r])

    def cpoly(name: str) -> NDArray[np.float64]:
        return np.array([dc[name], 0.5 * (db[name] - da[name])])

    length = w.chord_m if axis == "pitch" else w.span_m
    damping = rho * w.area_m2 * length**2 / 4 * npoly.polymul(V, cpoly(_RATE[axis]))
    if axis == "roll":
        stiffness = np.zeros(1)
    else:
        kk = (0.5 * rho * w.area_m2 * w.chord_m if axis == "pitch"
              else -0.5 * rho * w.area_m2 * w.span_m)
        stiffness = kk * npoly.polymul(npoly.polymul(V, V), cpoly(_STIFF[axis]))
    g0, g1 = gamma_range
    J = float(np.diag(af.inertia_kg_m2)[{"roll": 0, "pitch": 1, "yaw": 2}[axis]])
    return ParametricFamily(axis, J, np.asarray(damping, float), np.asarray(stiffness, float),
                            vc, r, 0.5 * (g0 + g1), 0.5 * (g1 - g0),
                            _plant_tau(af, plant, delays))


# ------------------------------------------------------------------------------------------
# LFT realisation
# ------------------------------------------------------------------------------------------


def plant_lft(fam: ParametricFamily) -> GeneralizedPlant:
    """Generalised plant of the family with its real parameters pulled out.

    Inputs [w (n_v + 1); u] and outputs [z (n_v + 1); rate; angle] (module docstring):
    closing w = diag(dV I_n, dg) z gives the plant of (V, gamma).

    Parameters
    ----------
    fam : ParametricFamily
        The family.

    Returns
    -------
    GeneralizedPlant
        The LFT form (u in N m, rate in rad/s, angle in rad).
    """
    p = fam.row
    n = p.shape[0] - 1
    J = fam.inertia
    lag = fam.tau_s is not None
    nx = 3 if lag else 2
    nw = n + 1
    A = np.zeros((nx, nx))
    A[0, 1] = 1.0
    A[1, :2] = p[0] / J
    B1 = np.zeros((nx, nw))
    B2 = np.zeros((nx, 1))
    C1 = np.zeros((nw, nx))
    D11 = np.zeros((nw, nw))
    D12 = np.zeros((nw, 1))
    if n > 0:
        B1[1, 0] = 1.0 / J                  # w_1 enters J q'
        for i in range(1, n + 1):           # z_i = p_i xi + w_{i+1}
            C1[i - 1, :2] = p[i]
            if i < n:
                D11[i - 1, i] = 1.0
    B1[1, n] = -fam.rg / J                  # -(r_g dg) u_in
    if lag:
        tau = float(fam.tau_s)  # type: ignore[arg-type]
        A[1, 2] = fam.b0 / J
        A[2, 2] = -1.0 / tau
        B2[2, 0] = 1.0 / tau
        C1[n, 2] = 1.0                      # z_g = actuator output
    else:
        B2[1, 0] = fam.b0 / J
        D12[n, 0] = 1.0                     # z_g = u
    C2 = np.zeros((2, nx))
    C2[0, 1] = 1.0                          # rate
    C2[1, 0] = 1.0                          # angle
    return GeneralizedPlant.from_matrices(A, B1, B2, C1, C2, D11, D12)


def _controller(theta: Any) -> StateSpaceData:
    th = [float(theta[k]) for k in PARAM_NAMES] if isinstance(theta, Mapping) else [
        float(x) for x in theta]
    kpa, kp, ki, kd, tf = th
    Ak, Bk, Ck, Dk = rate_controller(kp, ki, kd, tf)
    E = np.array([[-1.0, -kpa]])            # e_rate = -(rate + kp_angle angle), r = 0
    return Ak, Bk @ E, Ck, Dk @ E


def closed_loop_lft(fam: ParametricFamily, theta: Any) -> StateSpaceData:
    """M(s): the closed loop (controller ``theta``) seen by the real blocks, w -> z.

    Parameters
    ----------
    fam : ParametricFamily
        The family.
    theta : sequence of float or mapping
        P-PID gains (:data:`vtolftc.synthesis.loops.PARAM_NAMES`).

    Returns
    -------
    A, B, C, D : ndarray
        M(s) as state space.
    """
    return lft(plant_lft(fam), _controller(theta))


def upper_lft_plant(fam: ParametricFamily, dV: float, dg: float) -> StateSpaceData:
    """The plant u -> [rate; angle] with the real blocks closed (for checks).

    Parameters
    ----------
    fam : ParametricFamily
        The family.
    dV, dg : float
        Normalised airspeed and effectiveness-loss parameters, in [-1, 1].

    Returns
    -------
    A, B, C, D : ndarray
        The plant, moment (N m) -> [rate (rad/s); angle (rad)].
    """
    P = plant_lft(fam)
    n = fam.n_v
    Delta = np.diag([dV] * n + [dg])
    Q = np.linalg.inv(np.eye(n + 1) - P.D11 @ Delta)
    A = P.A + P.B1 @ Delta @ Q @ P.C1
    B = P.B2 + P.B1 @ Delta @ Q @ P.D12
    C = P.C2 + P.D21 @ Delta @ Q @ P.C1
    D = P.D22 + P.D21 @ Delta @ Q @ P.D12
    return A, B, C, D


# ------------------------------------------------------------------------------------------
# the true family on a grid
# ------------------------------------------------------------------------------------------


def true_closed_loop_matrices(inertia: float, damping: Any, stiffness: Any, effectiveness: Any,
                              tau_s: float | None, theta: Any) -> NDArray[np.float64]:
    """Closed-loop state matrices of the P-PID cascade around the physical plant.

    The plant J q' = D q + K angle + b u_in (u_in = u, or the lag output), assembled directly
    from the coefficients. States [angle, rate, (lag), integral, filter], as
    :func:`vtolftc.synthesis.loops.closed_loop` of the same plant.

    Parameters
    ----------
    inertia : float
        J (kg m^2).
    damping, stiffness, effectiveness : array_like
        D (N m s / rad), K (N m / rad) and b = 1 - gamma, arrays of one shape (batch,).
    tau_s : float or None
        Lag time constant (s), or None for no lag.
    theta : sequence of float or mapping
        P-PID gains.

    Returns
    -------
    ndarray of float, shape (batch, n, n)
        The state matrices (n = 4, or 5 with the lag).
    """
    th = [float(theta[k]) for k in PARAM_NAMES] if isinstance(theta, Mapping) else [
        float(x) for x in theta]
    kpa, kp, ki, kd, tf = th
    D = np.asarray(damping, float).reshape(-1)
    K = np.asarray(stiffness, float).reshape(-1)
    b = np.asarray(effectiveness, float).reshape(-1)
    lag = tau_s is not None
    nx = 3 if lag else 2
    n = nx + 2
    A = np.zeros((D.size, n, n))
    ii, iff = nx, nx + 1
    # u = ki xi - (kd/tf) xf + (kp + kd/tf) e,  e = -(rate + kpa angle)
    dk = kp + kd / tf
    u_row = np.zeros(n)
    u_row[0], u_row[1] = -dk * kpa, -dk
    u_row[ii], u_row[iff] = ki, -kd / tf
    A[:, 0, 1] = 1.0
    A[:, 1, 0] = K / inertia
    A[:, 1, 1] = D / inertia
    if lag:
        t = float(tau_s)  # type: ignore[arg-type]
        A[:, 1, 2] = b / inertia
        A[:, 2, :] = u_row / t
        A[:, 2, 2] -= 1.0 / t
    else:
        A[:, 1, :] += (b / inertia)[:, None] * u_row[None, :]
    A[:, ii, 0], A[:, ii, 1] = -kpa, -1.0
    A[:, iff, 0], A[:, iff, 1] = -kpa / tf, -1.0 / tf
    A[:, iff, iff] = -1.0 / tf
    return A


@dataclass(frozen=True)
class GridCheck:
    """Closed-loop poles of the true family over an n x n grid of V x gamma.

    Parameters
    ----------
    max_real_pole : float
        Largest real part of a closed-loop pole over the grid (rad/s).
    unstable_members, members : int
        Unstable grid members and all members.
    worst_airspeed_m_s, worst_gamma : float
        The member with the largest real pole.
    """

    max_real_pole: float     # rad/s, over the grid
    unstable_members: int
    members: int
    worst_airspeed_m_s: float
    worst_gamma: float

    @property
    def stable(self) -> bool:
        """Every grid member strictly stable."""
        return self.unstable_members == 0


def grid_check(af: Airframe, axis: Axis, point: DesignPoint, theta: Any,
               plant: PlantKind = "lagged", n: int = 41,
               gamma_range: tuple[float, float] = GAMMA_RANGE,
               delays: LoopDelays = DEFAULT_DELAYS) -> GridCheck:
    """Dense-grid verdict of the true model family on the point's box, on the LFT's plant.

    Parameters
    ----------
    af : Airframe
        The airframe.
    axis : {"roll", "pitch", "yaw"}
        The axis.
    point : DesignPoint
        The design point (airspeed range).
    theta : sequence of float or mapping
        P-PID gains.
    plant : {"lagged", "paper"}
        The plant kind.
    n : int
        Grid points per parameter.
    gamma_range : (float, float)
        Range of the loss of effectiveness.
    delays : LoopDelays
        Loop delays of the lagged plant.

    Returns
    -------
    GridCheck
        The poles' verdict.
    """
    tau = _plant_tau(af, plant, delays)
    Vs = np.linspace(point.v_min_m_s, point.v_max_m_s, n)
    gs = np.linspace(gamma_range[0], gamma_range[1], n)
    cs = [axis_coefficients(af, axis, float(V)) for V in Vs]
    D = np.repeat([c.damping for c in cs], n)
    K = np.repeat([c.stiffness for c in cs], n)
    b = np.tile(1.0 - gs, n)
    A = true_closed_loop_matrices(cs[0].inertia, D, K, b, tau, theta)
    re = np.linalg.eigvals(A).real.max(axis=1)
    i = int(np.argmax(re))
    return GridCheck(float(re[i]), int(np.sum(re >= 0.0)), int(re.size),
                     float(Vs[i // n]), float(gs[i % n]))


def _max_re_scaled(fam: ParametricFamily, theta: Any, k: float, n: int) -> float:
    d = np.linspace(-k, k, n)
    dV, dg = np.meshgrid(d, d, indexing="ij")
    D, K, b = fam.coefficients(dV.ravel(), dg.ravel())
    A = true_closed_loop_matrices(fam.inertia, D, K, b, fam.tau_s, theta)
    return float(np.linalg.eigvals(A).real.max())


def grid_margin(fam: ParametricFamily, theta: Any, n: int = 41, k_max: float = K_MAX,
                iters: int = 16) -> tuple[float, float]:
    """Stability margin of the scaled parameter box, by bisection on a grid.

    The n x n grid of the piece's box scaled by k (about its centre) is stable at k_lo and
    has an unstable member at k_hi.

    Parameters
    ----------
    fam : ParametricFamily
        The family.
    theta : sequence of float or mapping
        P-PID gains.
    n : int
        Grid points per parameter.
    k_max : float
        Largest scaling tried.
    iters : int
        Bisection steps.

    Returns
    -------
    k_lo, k_hi : float
        k_hi = inf if stable up to ``k_max``; k_lo = k_hi = 0 if the centre itself is unstable.
    """
    if _max_re_scaled(fam, theta, 0.0, 1) >= 0.0:
        return 0.0, 0.0
    if not _has_unstable_scaled(fam, theta, k_max, n):
        return k_max, math.inf
    lo, hi = 0.0, k_max
    for _ in range(iters):
        mid = 0.5 * (lo + hi)
        if _has_unstable_scaled(fam, theta, mid, n):
            hi = mid
        else:
            lo = mid
    return lo, hi


def _has_unstable_scaled(fam: ParametricFamily, theta: Any, k: float, n: int) -> bool:
    """Whether the n x n grid of the box scaled by k has a member with a pole in Re >= 0
    (the same members and eigenvalues as :func:`_max_re_scaled`): the boundary ring of the
    grid first, where the first unstable member of a growing box usually is, then the rest
    in chunks, stopping at the first unstable one."""
    d = np.linspace(-k, k, n)
    i, j = np.meshgrid(np.arange(n), np.arange(n), indexing="ij")
    ring = np.maximum(np.abs(2 * i - (n - 1)), np.abs(2 * j - (n - 1))).ravel()
    order = np.argsort(-ring, kind="stable")
    dV, dg = d[i.ravel()[order]], d[j.ravel()[order]]
    step = max(4 * n - 4, 1)
    for a in range(0, dV.size, step):
        D, K, b = fam.coefficients(dV[a:a + step], dg[a:a + step])
        A = true_closed_loop_matrices(fam.inertia, D, K, b, fam.tau_s, theta)
        if np.linalg.eigvals(A).real.max() >= 0.0:
            return True
    return False


def zero_frequency_margin(M0: NDArray[Any], fam: ParametricFamily, n: int = 401,
                          k_max: float = K_MAX) -> float:
    """Smallest box scaling at which a real closed-loop pole crosses the origin.

    The smallest ||(dV, dg)||_inf on an n x n grid of [-k_max, k_max]^2 at which
    det(I - M(0) Delta) <= 0 (it is 1 at Delta = 0): then mu(M(0)) >= 1 / value.

    Parameters
    ----------
    M0 : ndarray, shape (n_v + 1, n_v + 1)
        M(0), the DC gain of :func:`closed_loop_lft`.
    fam : ParametricFamily
        The family.
    n : int
        Grid points per parameter.
    k_max : float
        Box half width.

    Returns
    -------
    float
        The scaling; inf if none on the grid.
    """
    d = np.linspace(-k_max, k_max, n)
    dV, dg = np.meshgrid(d, d, indexing="ij")
    nv = fam.n_v
    M = np.real(np.asarray(M0))
    # dg scales one column of M Delta: det(I - M Delta) = a(dV) + b(dV) dg exactly, so two
    # determinants per dV give the whole row of the grid
    rows = np.zeros((2, n, nv + 1))
    rows[:, :, :nv] = d[None, :, None]
    rows[1, :, nv] = 1.0
    ab = np.linalg.det(np.eye(nv + 1)[None, None] - M[None, None] * rows[:, :, None, :])
    det = (ab[0][:, None] + (ab[1] - ab[0])[:, None] * d[None, :]).ravel()
    bad = det <= 0.0
    if not np.any(bad):
        return math.inf
    return float(np.max(np.abs(np.stack([dV.ravel(), dg.ravel()], 1))[bad], axis=1).min())


# ------------------------------------------------------------------------------------------
# mixed mu
# ------------------------------------------------------------------------------------------


def vertex_crossings(fam: ParametricFamily, theta: Any, k_max: float = K_MAX,
                     n: int = 400) -> list[float]:
    """Frequencies at which the family first loses stability along the rays to the vertices.

    Along (dV, dg) = t (+-1, +-1): a scan of t in (0, k_max], then bisection; the crossing
    pole's |Im|. With two real parameters the real mu over frequency is the inverse of
    max(|dV(w)|, |dg(w)|) along the stability boundary: its peak is either a smooth maximum
    (found by the refined grid) or a kink where |dV| = |dg|, i.e. on one of these rays, at
    one of these frequencies.

    Parameters
    ----------
    fam : ParametricFamily
        The family.
    theta : sequence of float or mapping
        P-PID gains.
    k_max : float
        Largest scaling along a ray.
    n : int
        Scan points per ray.

    Returns
    -------
    list of float
        Crossing frequencies (rad/s).
    """
    out = []
    ts = np.linspace(k_max / n, k_max, n)
    for sv in (-1.0, 1.0):
        for sg in (-1.0, 1.0):
            def max_re(t: NDArray[np.float64], sv: float = sv, sg: float = sg) -> Any:
                D, K, b = fam.coefficients(sv * t, sg * t)
                ev = np.linalg.eigvals(true_closed_loop_matrices(fam.inertia, D, K, b,
                                                                 fam.tau_s, theta))
                return ev, ev.real.max(axis=1)
            _, re = max_re(ts)
            bad = np.nonzero(re >= 0.0)[0]
            if bad.size == 0:
                continue
            j = int(bad[0])
            lo, hi = (0.0 if j == 0 else float(ts[j - 1])), float(ts[j])
            for _ in range(40):
                mid = 0.5 * (lo + hi)
                if max_re(np.array([mid]))[1][0] >= 0.0:
                    hi = mid
                else:
                    lo = mid
            ev, _ = max_re(np.array([hi]))
            out.append(float(abs(ev[0][np.argmax(ev[0].real)].imag)))
    return out


def two_parameter_lower(M: NDArray[Any], n_v: int, k_max: float = K_MAX,
                        n: int = 801) -> float:
    """Real-mu lower bound of M for the structure diag(dV I_n_v, dg).

    det(I - M Delta) is affine in dg, a(dV) + b(dV) dg, so for each dV of a fine grid on
    [-k_max, k_max] the only candidate is dg = -a / b, admissible where it is real
    (Im(a conj(b)) = 0: sign changes, refined by Brent's method). Each candidate is verified
    (sigma_min(I - M Delta) ~ 0).

    Parameters
    ----------
    M : ndarray of complex, shape (n_v + 1, n_v + 1)
        M(j w).
    n_v : int
        Repetitions of dV.
    k_max : float
        Search range of dV.
    n : int
        Grid points of dV.

    Returns
    -------
    float
        1 / the smallest max(|dV|, |dg|) found (0 if none).
    """
    m = n_v + 1
    eye = np.eye(m)
    M = np.asarray(M)

    def ab(dv: NDArray[np.float64]) -> tuple[NDArray[Any], NDArray[Any]]:
        d0 = np.concatenate([np.repeat(dv[:, None], n_v, 1), np.zeros((dv.size, 1))], 1)
        d1 = d0.copy()
        d1[:, -1] = 1.0
        a = np.linalg.det(eye[None] - M[None] * d0[:, None, :])
        return a, np.linalg.det(eye[None] - M[None] * d1[:, None, :]) - a

    # one dV (Brent's iterations): both determinants in one stacked call, same arithmetic
    pair = np.zeros((2, 1, m))
    pair[1, 0, -1] = 1.0

    def ab1(x: float) -> tuple[complex, complex]:
        pair[:, 0, :n_v] = x
        d = np.linalg.det(eye[None] - M[None] * pair)
        return d[0], d[1] - d[0]

    def im(x: float) -> float:
        a, b = ab1(x)
        return float(np.imag(a * np.conj(b)))

    dv = np.linspace(-k_max, k_max, n) if n_v > 0 else np.zeros(1)
    a, b = ab(dv)
    f = np.imag(a * np.conj(b))
    cands = list(dv[np.abs(f) <= 1e-14 * (np.abs(a * b) + 1e-300)])
    for i in np.nonzero(np.sign(f[:-1]) * np.sign(f[1:]) < 0)[0]:
        cands.append(brentq(im, float(dv[i]), float(dv[i + 1]), xtol=1e-13))
    # dg without effect at some dV (b = 0): det = a(dV) itself must vanish (dg = 0)
    ra = np.real(a)
    zero_g = [brentq(lambda x: float(np.real(ab1(x)[0])), float(dv[i]), float(dv[i + 1]),
                     xtol=1e-13)
              for i in np.nonzero(np.sign(ra[:-1]) * np.sign(ra[1:]) < 0)[0]]
    vs = np.array([float(v) for v in [*cands, *zero_g]])
    if vs.size == 0:
        return 0.0
    # every candidate's dg = -a / b, then verified in increasing max(|dV|, |dg|): the first
    # verified one is the smallest (the same as checking all of them)
    av, bv = ab(vs)
    flat = np.abs(bv) <= 1e-12 * (1.0 + np.abs(av))
    g = np.where(flat, 0.0, np.real(-av / np.where(flat, 1.0, bv)))
    t = np.maximum(np.abs(vs), np.abs(g))
    mnorm = np.linalg.norm(M, 2)
    best = math.inf
    for j in np.argsort(t, kind="stable"):
        if t[j] == 0.0:
            continue
        Delta = np.diag([float(vs[j])] * n_v + [float(g[j])])
        smin = np.linalg.svd(eye - M @ Delta, compute_uv=False)[-1]
        if smin <= 1e-8 * (1.0 + mnorm * float(t[j])):
            best = float(t[j])
            break
    return 0.0 if not math.isfinite(best) else 1.0 / best


def mu_real_sweep(fam: ParametricFamily, theta: Any,
                  omegas: NDArray[np.float64] | None = None, refine: int = 2,
                  seed: int = 0, rtol: float = 1e-3) -> MuSweep:
    """Mixed-mu bounds of the family's M(j w) over frequency, refined at the peaks.

    Over w = 0 plus ``omegas``, refined ``refine`` times on a 7-point grid between the
    neighbours of each of the (up to three) largest local maxima of the upper bound, and the
    :func:`vertex_crossings`. Only the peak matters for the certificate. The D-G upper bound
    (:func:`vtolftc.synthesis.mixed_mu.mixed_mu_upper`) starts from a verified lower bound
    at w = 0 as its ``target`` and is optimised, frequency by frequency in decreasing order
    of the cheap D-only bound, only until it is below the current target (which rises only
    when a frequency's bound converges above it); a warm start from the nearest solved
    frequency is tried first, a cold start if that stalls above the target. Every value is
    a valid upper bound at its frequency; the maximum over the sampled frequencies is the
    certified peak (to ``rtol`` above the target). At the vertex-crossing frequencies the
    bound is also taken with each real scalar given a complex part of relative size
    :data:`REGULARISATION` (a larger family, continuous in frequency), which catches the
    spikes of real mu there.

    The lower bound (:func:`two_parameter_lower`, exact for this structure up to its grid;
    at the upper peak also :func:`vtolftc.synthesis.mixed_mu.mixed_mu_lower` where the
    largest of the first is more than 1 % below the peak upper bound; both verified real
    perturbations) is computed at w = 0, the vertex-crossing frequencies and the four
    largest upper values, and is zero at the other frequencies.

    Parameters
    ----------
    fam : ParametricFamily
        The family.
    theta : sequence of float or mapping
        P-PID gains.
    omegas : ndarray of float, optional
        Frequencies (rad/s); default :data:`SWEEP_OMEGAS`.
    refine : int
        Refinement rounds at the peaks.
    seed : int
        Seed of the random lower-bound starts.
    rtol : float
        Relative tolerance of the upper bound.

    Returns
    -------
    MuSweep
        Bounds at every sampled frequency (sorted) and their peaks.
    """
    M = closed_loop_lft(fam, theta)
    crossings = vertex_crossings(fam, theta)
    w = np.concatenate([[0.0], SWEEP_OMEGAS if omegas is None else np.asarray(omegas, float),
                        crossings])
    w = np.unique(w)
    blocks = fam.blocks
    # repeated real scalars: mixed_mu_upper is the numpy D-G bound, whose value without
    # optimising (the ordering proxy below) is its start, computed directly; 1 x 1 real
    # blocks only (AB13MD's case): the call itself
    dg_only = BlockStructure(blocks).ab13md_spec() is None
    W = np.zeros(0)
    UP = np.zeros(0)
    peak = 0.0
    solved: dict[int, tuple[float, Any]] = {}

    def solve(ws: NDArray[np.float64], base: float) -> tuple[NDArray[np.float64], float]:
        F = frequency_response(M, ws)
        proxy = np.array([mixed_mu_upper_start(Fi, blocks) if dg_only else
                          mixed_mu_upper(Fi, blocks, maxiter=0, target=math.inf).value
                          for Fi in F])
        up = np.zeros(ws.size)
        lw = np.log(np.maximum(ws, 1e-9))
        for i in np.argsort(-proxy):
            target = base * (1.0 + rtol)
            if proxy[i] <= target:
                up[i] = proxy[i]
                continue
            near = min(solved, key=lambda j: abs(solved[j][0] - lw[i])) if solved else None
            warm = solved[near][1] if near is not None else None
            res = mixed_mu_upper(F[i], blocks, rtol=1e-6, target=target, warm_start=warm)
            if warm is not None and res.value > target:
                cold = mixed_mu_upper(F[i], blocks, rtol=1e-6, target=target)
                res = cold if cold.value < res.value else res
            solved[len(solved)] = (float(lw[i]), res)
            up[i] = res.value
            if res.value > target:     # optimised to convergence above the base: a new base
                base = res.value
        return up, base

    # a verified lower bound first (w = 0, where a real pole can cross the origin): the
    # upper bound then only has to be pushed below it at the other frequencies
    peak = two_parameter_lower(frequency_response(M, np.array([0.0]))[0], fam.n_v)
    up, peak = solve(w, peak)
    # At a crossing frequency found numerically M(j w) is real only to rounding, and real mu
    # is discontinuous there (a one-parameter spike, or a kink whose side is steep): bound
    # the slightly larger family with each real scalar d replaced by d + eps c, c complex,
    # |c| <= |d|-scale (continuous in w, >= the real mu at the same frequency).
    F = frequency_response(M, w)
    for i in np.nonzero(np.isin(w, crossings) & (w > 0))[0]:
        Maug = np.block([[F[i], F[i]], [REGULARISATION * F[i], REGULARISATION * F[i]]])
        aug = [*blocks, *[Block.repeated_complex(b.rows) for b in blocks]]
        reg = mixed_mu_upper(Maug, aug, rtol=1e-6, target=peak * (1.0 + rtol)).value
        up[i] = max(up[i], reg)
        if reg > peak * (1.0 + rtol):
            peak = reg
    W, UP = w, up
    for _ in range(refine):
        # every local maximum within 20 % of the peak
        big = 0.8 * UP.max() <= UP
        left = np.concatenate([[True], UP[1:] >= UP[:-1]])
        right = np.concatenate([UP[:-1] >= UP[1:], [True]])
        order = np.nonzero(big & left & right)[0]
        order = order[np.argsort(-UP[order])][:3]
        loc_all = []
        for i in order:
            a = W[max(i - 1, 0)]
            b = W[min(i + 1, W.size - 1)]
            loc = np.geomspace(a, b, 9)[1:-1] if a > 0 else np.linspace(a, b, 9)[1:-1]
            loc_all.append(loc)
        loc = np.unique(np.concatenate(loc_all))
        loc = loc[~np.isin(loc, W)]
        if loc.size == 0:
            break
        up2, peak = solve(loc, peak)
        W = np.concatenate([W, loc])
        UP = np.concatenate([UP, up2])
        o = np.argsort(W)
        W, UP = W[o], UP[o]
    LO = np.zeros(W.size)
    iu = int(np.argmax(UP))
    at = {iu, int(np.nonzero(W == 0.0)[0][0])}
    at |= {int(np.argmin(np.abs(W - x))) for x in crossings}
    big = np.argsort(-UP)[:4]
    at |= {int(i) for i in big}
    for i in sorted(at):
        Mi = frequency_response(M, W[[i]])[0]
        LO[i] = two_parameter_lower(Mi, fam.n_v)
    if LO.max() < 0.99 * UP[iu]:   # the general mixed lower bound too, at the peak
        Mi = frequency_response(M, W[[iu]])[0]
        LO[iu] = max(LO[iu], mixed_mu_lower(Mi, blocks, n_starts=2, seed=seed)[0])
    il = int(np.argmax(LO))
    return MuSweep(W, LO, UP, float(LO[il]), float(W[il]), float(UP[iu]), float(W[iu]))


@dataclass(frozen=True)
class PieceResult:
    """Mixed mu and grid margin of one airspeed piece (its own normalisation).

    Parameters
    ----------
    v_lo_m_s, v_hi_m_s : float
        The piece (m/s).
    n_v : int
        Repetitions of the airspeed parameter in the LFT.
    mu_upper, mu_lower : float
        Peak mixed-mu bounds over frequency.
    peak_frequency_rad_s : float
        Frequency of the upper peak (rad/s).
    mu_upper_at_zero : float
        Upper bound at w = 0 (tight only if it is the peak).
    zero_frequency_k : float
        det(I - M(0) Delta) <= 0 first at this box scaling.
    grid_k_lo, grid_k_hi : float
        The scaled grid is stable at k_lo, has an unstable member at k_hi (inf: none).
    centre_stable : bool
        Whether the piece's centre model is stable.
    """

    v_lo_m_s: float
    v_hi_m_s: float
    n_v: int
    mu_upper: float
    mu_lower: float
    peak_frequency_rad_s: float
    mu_upper_at_zero: float          # upper bound at w = 0 (tight only if it is the peak)
    zero_frequency_k: float          # det(I - M(0) Delta) <= 0 first at this box scaling
    grid_k_lo: float                 # scaled-grid stable at this scaling
    grid_k_hi: float                 # ... an unstable member at this one (inf: none)
    centre_stable: bool

    @property
    def grid_mu(self) -> float:
        """1 / k_hi: the grid's (lower) estimate of mu."""
        return 0.0 if not math.isfinite(self.grid_k_hi) else (
            math.inf if self.grid_k_hi == 0 else 1.0 / self.grid_k_hi)

    def to_dict(self) -> dict[str, Any]:
        """All fields (and ``grid_mu``) as a JSON-ready dict (inf as None).

        Returns
        -------
        dict
            The fields.
        """
        d = {k: (None if isinstance(v, float) and not math.isfinite(v) else v)
             for k, v in self.__dict__.items()}
        g = self.grid_mu
        d["grid_mu"] = g if math.isfinite(g) else None
        return d


@dataclass(frozen=True)
class PointCertificate:
    """One axis at one design point: the three numbers and the verdict.

    Parameters
    ----------
    axis : {"roll", "pitch", "yaw"}
        The axis.
    point : int
        Design point number.
    v_min_m_s, v_max_m_s : float
        Airspeed range (m/s).
    plant : {"lagged", "paper"}
        The plant kind.
    mu_upper, mu_lower : float
        Max over pieces of the mixed-mu bounds.
    grid : GridCheck
        The dense-grid verdict.
    grid_mu : float
        Max over pieces of 1 / k_hi.
    pieces : list of PieceResult
        Per-piece results.
    """

    axis: Axis
    point: int
    v_min_m_s: float
    v_max_m_s: float
    plant: PlantKind
    mu_upper: float        # max over pieces
    mu_lower: float
    grid: GridCheck
    grid_mu: float         # max over pieces of 1 / k_hi
    pieces: list[PieceResult] = field(default_factory=list)

    @property
    def certified(self) -> bool:
        """Robust stability over the whole box proved: mu upper bound < 1 on every piece
        (and every piece's centre stable)."""
        return bool(self.mu_upper < 1.0 and all(p.centre_stable for p in self.pieces))

    @property
    def verdict(self) -> str:
        """"certified", "not certified: centre unstable" (the nominal of a piece, at its
        box centre, is unstable: mu is infinite), "not certified: unstable member" (the grid
        or the lower bound found one) or "not certified: bound >= 1"."""
        if self.certified:
            return "certified"
        if not all(p.centre_stable for p in self.pieces):
            return "not certified: centre unstable"
        if not self.grid.stable or self.mu_lower >= 1.0:
            return "not certified: unstable member"
        return "not certified: bound >= 1"

    def to_dict(self) -> dict[str, Any]:
        """JSON-ready summary with the pieces.

        Returns
        -------
        dict
            The summary.
        """
        g = self.grid
        return {"axis": self.axis, "point": self.point, "v_min_m_s": self.v_min_m_s,
                "v_max_m_s": self.v_max_m_s, "plant": self.plant,
                "mu_upper": _fin(self.mu_upper), "mu_lower": _fin(self.mu_lower),
                "grid_stable": g.stable, "grid_max_real_pole_rad_s": g.max_real_pole,
                "grid_unstable_members": g.unstable_members, "grid_members": g.members,
                "grid_worst_airspeed_m_s": g.worst_airspeed_m_s,
                "grid_worst_gamma": g.worst_gamma, "grid_mu": _fin(self.grid_mu),
                "certified": self.certified, "verdict": self.verdict,
                "centre_stable": all(p.centre_stable for p in self.pieces),
                "pieces": [p.to_dict() for p in self.pieces]}


def _fin(x: float) -> float | None:
    return x if math.isfinite(x) else None


def certify_point(af: Airframe, axis: Axis, point: DesignPoint, theta: Any,
                  plant: PlantKind = "lagged", *, grid_n: int = 41,
                  gamma_range: tuple[float, float] = GAMMA_RANGE,
                  delays: LoopDelays = DEFAULT_DELAYS, seed: int = 0,
                  margin: bool = True) -> PointCertificate:
    """Mixed mu (every piece), the dense grid and the grid margin of one axis-point.

    Parameters
    ----------
    af : Airframe
        The airframe.
    axis : {"roll", "pitch", "yaw"}
        The axis.
    point : DesignPoint
        The design point.
    theta : sequence of float or mapping
        The P-PID gains (mapping with :data:`vtolftc.synthesis.loops.PARAM_NAMES` keys or a
        sequence in that order).
    plant : {"lagged", "paper"}
        The plant kind.
    grid_n : int
        Grid points per parameter of the dense grid.
    gamma_range : (float, float)
        Range of the loss of effectiveness.
    delays : LoopDelays
        Loop delays of the lagged plant.
    seed : int
        Seed of the random lower-bound starts.
    margin : bool
        False skips the grid-margin bisection.

    Returns
    -------
    PointCertificate
        The certificate.
    """
    pieces = []
    for lo, hi in airspeed_pieces(af, point):
        fam = family(af, axis, lo, hi, gamma_range, plant, delays)
        centre = true_closed_loop_matrices(fam.inertia, *fam.coefficients(0.0, 0.0),
                                           fam.tau_s, theta)
        centre_stable = bool(np.linalg.eigvals(centre[0]).real.max() < 0.0)
        if not centre_stable:
            pieces.append(PieceResult(lo, hi, fam.n_v, math.inf, math.inf, math.nan, math.inf,
                                      0.0, 0.0, 0.0, False))
            continue
        sw = mu_real_sweep(fam, theta, seed=seed)
        M0 = frequency_response(closed_loop_lft(fam, theta), np.array([0.0]))[0]
        k0 = zero_frequency_margin(M0, fam)
        klo, khi = grid_margin(fam, theta, n=grid_n) if margin else (math.nan, math.nan)
        i0 = int(np.nonzero(sw.omegas == 0.0)[0][0])
        pieces.append(PieceResult(lo, hi, fam.n_v, sw.peak_upper, sw.peak_lower,
                                  sw.peak_upper_frequency_rad_s, float(sw.upper[i0]), k0,
                                  klo, khi, True))
    g = grid_check(af, axis, point, theta, plant, grid_n, gamma_range, delays)
    return PointCertificate(axis, point.number, point.v_min_m_s, point.v_max_m_s, plant,
                            max(p.mu_upper for p in pieces), max(p.mu_lower for p in pieces),
                            g, max(p.grid_mu for p in pieces), pieces)


def gains_at(doc: Mapping[str, Any], axis: Axis, index: int) -> dict[str, float]:
    """The P-PID gains of one breakpoint of a ``vtolftc-gain-schedule/1`` document.

    A constant schedule (one breakpoint) gives the same gains at every index.

    Parameters
    ----------
    doc : mapping
        The gain-schedule document (parsed JSON).
    axis : {"roll", "pitch", "yaw"}
        The axis.
    index : int
        Breakpoint index.

    Returns
    -------
    dict of str to float
        Gains keyed by :data:`vtolftc.synthesis.loops.PARAM_NAMES`.
    """
    t = doc["axes"][axis]
    i = 0 if len(doc["airspeed_breakpoints_m_s"]) == 1 else index
    return {k: float(t[k][i]) for k in PARAM_NAMES}


def design_points(doc: Mapping[str, Any]) -> list[DesignPoint]:
    """The design points recorded in a gain-schedule document.

    Parameters
    ----------
    doc : mapping
        The gain-schedule document (parsed JSON).

    Returns
    -------
    list of DesignPoint
        In the document's order.
    """
    return [DesignPoint(int(p["number"]), float(p["airspeed_m_s"]), float(p["v_min_m_s"]),
                        float(p["v_max_m_s"])) for p in doc["design_points"]]


def certify_schedule(af: Airframe, doc: Mapping[str, Any], plant: PlantKind,
                     axes: Sequence[Axis] = ("roll", "pitch", "yaw"), *, grid_n: int = 41,
                     seed: int = 0) -> list[dict[str, Any]]:
    """Certificate records (one per axis and design point) for a gain-schedule document.

    Each record holds the lumped complex mu_RS the document records (table 3 form,
    ``mu_rs``) and the certificate.

    Parameters
    ----------
    af : Airframe
        The airframe.
    doc : mapping
        The gain-schedule document (parsed JSON).
    plant : {"lagged", "paper"}
        The plant kind.
    axes : sequence of str
        Axes to certify.
    grid_n : int
        Grid points per parameter of the dense grid.
    seed : int
        Seed of the random lower-bound starts.

    Returns
    -------
    list of dict
        JSON-ready records.
    """
    out = []
    for axis in axes:
        meta = doc["axes"][axis].get("metadata", {})
        lumped = [m.get("mu_rs") for m in meta.get("mu", [])]
        for i, p in enumerate(design_points(doc)):
            c = certify_point(af, axis, p, gains_at(doc, axis, i), plant, grid_n=grid_n,
                              seed=seed)
            rec = c.to_dict()
            rec["lumped_mu_rs"] = lumped[i] if i < len(lumped) else None
            rec["gains"] = gains_at(doc, axis, i)
            out.append(rec)
    return out

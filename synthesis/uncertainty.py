"""Multiplicative uncertainty weights over a perturbed model set (the role of MATLAB ``ucover``).

For each axis and design point (paper table 1) the perturbed set is every model of eq 1-3 with
the airspeed in the point's range and the loss of effectiveness gamma in [0, 0.6]; the nominal
model is the healthy one (gamma = 0) at the nominal airspeed. The relative error

    l(w) = max over the set of | G_p(jw) / G_nom(jw) - 1 |

is bounded from above by a stable, minimum-phase, low-order weight

    W_t(s) = k * prod_i (s / z_i + 1) / (s / p_i + 1),   k, z_i, p_i > 0,

fitted as the tightest such weight (least mean log-gap over frequency) with |W_t(jw)| >= l(w) at
every frequency of a dense grid (paper fig 3, eq 11: G_p = G_nom (1 + W_t Delta)).

The paper's nominal (healthy, nominal airspeed) sits at a corner of the set in gamma: every
perturbed model has less effectiveness, so the cover must reach 0.6 at low frequency from
gamma alone. The robust design instead takes the nominal where the cover is smallest
(:func:`centred_nominal`: the model of the set, on a grid over airspeed x gamma, that
minimises the peak relative error), and refits the cover about it (:func:`cover` with
``nominal``). For gamma alone the centre is gamma = 0.3 (error 0.3/0.7 = 0.43 instead of 0.6).
"""

from __future__ import annotations

import math
from collections.abc import Sequence
from dataclasses import dataclass

import control as ct
import numpy as np
from scipy.optimize import minimize

from vtolftc.airframe.loader import Airframe
from vtolftc.synthesis.models import Axis, axis_coefficients


@dataclass(frozen=True)
class DesignPoint:
    """A nominal design point and its perturbed airspeed range (paper table 1).

    Parameters
    ----------
    number : int
        Point number (1-based, as in the paper's table 1).
    airspeed_m_s : float
        Nominal airspeed (m/s).
    v_min_m_s, v_max_m_s : float
        Perturbed airspeed range (m/s), containing the nominal airspeed.
    """

    number: int
    airspeed_m_s: float
    v_min_m_s: float
    v_max_m_s: float


PAPER_DESIGN_POINTS: tuple[DesignPoint, ...] = (
    DesignPoint(1, 0.0, 0.0, 0.8),
    DesignPoint(2, 1.0, 0.8, 2.5),
    DesignPoint(3, 4.0, 2.5, 5.5),
    DesignPoint(4, 7.0, 5.5, 8.5),
    DesignPoint(5, 10.0, 8.5, 11.5),
    DesignPoint(6, 13.0, 11.5, 13.0),
)
GAMMA_RANGE = (0.0, 0.6)


def rate_response(af: Airframe, axis: Axis, airspeed_m_s: float, gamma: float,
                  omegas: np.ndarray) -> np.ndarray:
    """Frequency response of the eq 1-3 rate model, evaluated directly (no cancellations).

    Parameters
    ----------
    af : Airframe
        The airframe.
    axis : {"roll", "pitch", "yaw"}
        The axis.
    airspeed_m_s : float
        Airspeed (m/s), >= 0.
    gamma : float
        Loss of control effectiveness, in [0, 1].
    omegas : ndarray of float, shape (nw,)
        Frequencies (rad/s).

    Returns
    -------
    ndarray of complex, shape (nw,)
        G(j w), moment (N m) -> body rate (rad/s).
    """
    c = axis_coefficients(af, axis, airspeed_m_s)
    s = 1j * np.asarray(omegas, dtype=float)
    # Both forms reduce to (1-gamma) s / (J s^2 - D s - K); roll has K = 0.
    return (1.0 - gamma) * s / (c.inertia * s * s - c.damping * s - c.stiffness)


@dataclass(frozen=True)
class RelativeError:
    """Relative model error ``|G_p / G_nom - 1|`` of the rate models over a grid.

    Parameters
    ----------
    omegas : ndarray of float, shape (n_omega,)
        Frequencies (rad/s).
    errors : ndarray of float, shape (n_models, n_omega)
        |G_p / G_nom - 1| of each perturbed model (dimensionless).
    bound : ndarray of float, shape (n_omega,)
        Its maximum over the models.
    models : tuple of (float, float)
        (airspeed m/s, effectiveness loss gamma) of each row.
    """
    omegas: np.ndarray      # rad/s
    errors: np.ndarray      # (n_models, n_omega) |G_p/G_nom - 1|
    bound: np.ndarray       # (n_omega,) maximum over the models
    models: tuple[tuple[float, float], ...]  # (airspeed, gamma) of each row


def relative_error(af: Airframe, axis: Axis, point: DesignPoint, omegas: np.ndarray,
                   gamma_range: tuple[float, float] = GAMMA_RANGE, n_airspeeds: int = 17,
                   n_gammas: int = 4, nominal: tuple[float, float] | None = None,
                   ) -> RelativeError:
    """Relative error of the perturbed set against the nominal model.

    Parameters
    ----------
    af : Airframe
        The airframe.
    axis : {"roll", "pitch", "yaw"}
        The axis.
    point : DesignPoint
        The design point (its airspeed range is the perturbed set's).
    omegas : ndarray of float, shape (n_omega,)
        Frequencies (rad/s).
    gamma_range : (float, float)
        Range of the loss of effectiveness gamma.
    n_airspeeds, n_gammas : int
        Grid sizes over the airspeed range and the gamma range.
    nominal : (float, float), optional
        (airspeed m/s, gamma) of the nominal model; default the healthy model at the point's
        nominal airspeed (the paper).

    Returns
    -------
    RelativeError
        The errors of every grid model and their bound.

    Raises
    ------
    ValueError
        If the nominal airspeed lies outside the point's range.
    """
    if point.v_min_m_s > point.airspeed_m_s or point.v_max_m_s < point.airspeed_m_s:
        raise ValueError(f"design point {point.number}: nominal airspeed {point.airspeed_m_s} "
                         f"outside its range [{point.v_min_m_s}, {point.v_max_m_s}]")
    v_nom, g_nom_gamma = (point.airspeed_m_s, 0.0) if nominal is None else nominal
    g_nom = rate_response(af, axis, v_nom, g_nom_gamma, omegas)
    rows = []
    models = []
    for V in np.linspace(point.v_min_m_s, point.v_max_m_s, n_airspeeds):
        for gamma in np.linspace(gamma_range[0], gamma_range[1], n_gammas):
            g = rate_response(af, axis, float(V), float(gamma), omegas)
            rows.append(np.abs(g / g_nom - 1.0))
            models.append((float(V), float(gamma)))
    errors = np.array(rows)
    return RelativeError(np.asarray(omegas, float), errors, errors.max(axis=0), tuple(models))


@dataclass(frozen=True)
class UncertaintyWeight:
    """A fitted W_t(s) = k prod (s/z_i + 1) / (s/p_i + 1) (dimensionless).

    Parameters
    ----------
    gain : float
        k, the low-frequency gain (> 0).
    zeros_rad_s, poles_rad_s : tuple of float
        z_i and p_i (rad/s, > 0), as many zeros as poles.

    Examples
    --------
    >>> import numpy as np
    >>> W = UncertaintyWeight(0.5, (2.0,), (20.0,))
    >>> np.round(W.magnitude(np.array([0.0, 1e6])), 3).tolist()    # k at DC, k p / z above
    [0.5, 5.0]
    """

    gain: float
    zeros_rad_s: tuple[float, ...]
    poles_rad_s: tuple[float, ...]

    @property
    def order(self) -> int:
        """Number of pole/zero pairs of W_t(s)."""
        return len(self.poles_rad_s)

    def tf(self) -> ct.TransferFunction:
        """W_t(s) as a python-control transfer function.

        Returns
        -------
        control.TransferFunction
            W_t(s).
        """
        W = ct.tf([self.gain], [1.0])
        for z, p in zip(self.zeros_rad_s, self.poles_rad_s, strict=True):
            W = W * ct.tf([1.0 / z, 1.0], [1.0 / p, 1.0])
        return W

    def magnitude(self, omegas: np.ndarray) -> np.ndarray:
        """|W_t(j omega)| at the frequencies ``omegas`` (rad/s).

        Parameters
        ----------
        omegas : array_like, shape (nw,)
            Frequencies (rad/s).

        Returns
        -------
        ndarray of float, shape (nw,)
            The magnitudes.
        """
        s = 1j * np.asarray(omegas, dtype=float)
        m = np.full(s.shape, self.gain, dtype=complex)
        for z, p in zip(self.zeros_rad_s, self.poles_rad_s, strict=True):
            m *= (s / z + 1.0) / (s / p + 1.0)
        return np.abs(m)

    def to_dict(self) -> dict[str, object]:
        """Gain, zeros and poles (rad/s) as a JSON-ready dict.

        Returns
        -------
        dict
            Keys ``gain``, ``zeros_rad_s``, ``poles_rad_s``.
        """
        return {"gain": self.gain, "zeros_rad_s": list(self.zeros_rad_s),
                "poles_rad_s": list(self.poles_rad_s)}


def _mag_log(params: np.ndarray, logw: np.ndarray, order: int) -> np.ndarray:
    out = np.full(logw.shape, params[0])
    w = np.exp(logw)
    for i in range(order):
        z = math.exp(params[1 + 2 * i])
        p = math.exp(params[2 + 2 * i])
        out += 0.5 * (np.log1p((w / z) ** 2) - np.log1p((w / p) ** 2))
    return out


def fit_weight(omegas: np.ndarray, bound: np.ndarray, order: int = 1,
               margin: float = 1.01) -> UncertaintyWeight:
    """The tightest order-``order`` stable minimum-phase weight with |W| >= bound * margin.

    Minimises the mean log-gap between |W| and the bound over the (log-spaced) grid subject to
    |W| >= bound at every grid point (SLSQP on log-parameters), then rescales the gain so that
    the bound holds with ``margin`` on the grid exactly.

    Parameters
    ----------
    omegas : ndarray of float, shape (nw,)
        Positive frequencies (rad/s), increasing.
    bound : ndarray of float, shape (nw,)
        The relative error to cover (dimensionless, > 0).
    order : int
        Number of pole/zero pairs, 0..4.
    margin : float
        Factor by which |W| exceeds the bound at the tightest grid point.

    Returns
    -------
    UncertaintyWeight
        The fitted weight.

    Raises
    ------
    ValueError
        For mismatched or non-positive arrays, or an order outside 0..4.

    Examples
    --------
    >>> import numpy as np
    >>> w = np.logspace(-2, 3, 60)
    >>> bound = np.abs(0.2 * (1j * w / 1.0 + 1) / (1j * w / 50.0 + 1))
    >>> W = fit_weight(w, bound, order=1)
    >>> bool(np.all(W.magnitude(w) >= bound)), round(float(np.min(W.magnitude(w) / bound)), 4)
    (True, 1.01)
    """
    om = np.asarray(omegas, dtype=float)
    lb = np.log(np.maximum(np.asarray(bound, dtype=float), 1e-12) * margin)
    if om.ndim != 1 or om.shape != lb.shape or om.size < 4 or np.any(om <= 0):
        raise ValueError("fit_weight: expected matching 1-D arrays of positive frequencies "
                         "(rad/s) and bounds, at least 4 points")
    if order < 0 or order > 4:
        raise ValueError(f"order {order}: expected 0..4")
    logw = np.log(om)
    lo, hi = float(logw[0]) - 2.0, float(logw[-1]) + 2.0
    x0 = [float(lb.max())]
    centre = 0.5 * (lo + hi)
    for _ in range(order):
        x0 += [centre, centre]  # flat start: feasible
    x0 = np.array(x0)
    bounds = [(None, None)] + [(lo, hi)] * (2 * order)
    if order > 0:
        res = minimize(
            lambda x: float(np.mean(_mag_log(x, logw, order) - lb)), x0, method="SLSQP",
            bounds=bounds,
            constraints=[{"type": "ineq", "fun": lambda x: _mag_log(x, logw, order) - lb}],
            options={"maxiter": 300, "ftol": 1e-10},
        )
        x = res.x if np.all(np.isfinite(res.x)) else x0
    else:
        x = x0
    # Rescale so the bound holds on the grid whatever the optimiser left.
    gap = float(np.min(_mag_log(x, logw, order) - lb))
    x = x.copy()
    x[0] -= min(gap, 0.0)
    return UncertaintyWeight(
        gain=float(math.exp(x[0])),
        zeros_rad_s=tuple(float(math.exp(x[1 + 2 * i])) for i in range(order)),
        poles_rad_s=tuple(float(math.exp(x[2 + 2 * i])) for i in range(order)),
    )


def centred_nominal(af: Airframe, axis: Axis, point: DesignPoint,
                    gamma_range: tuple[float, float] = GAMMA_RANGE, n_airspeeds: int = 9,
                    n_gammas: int = 13, omegas: Sequence[float] | None = None,
                    ) -> tuple[float, float]:
    """The member of the perturbed set about which the multiplicative cover is smallest.

    The candidate (on an ``n_airspeeds`` x ``n_gammas`` grid over the set) minimising the
    peak over frequency of the relative error bound; among the candidates within 0.1 % of that
    peak (at hover points the peak is the low-frequency error of the airspeed range, which no
    choice of gamma changes) the one with the smallest mean log bound over frequency.

    Parameters
    ----------
    af : Airframe
        The airframe.
    axis : {"roll", "pitch", "yaw"}
        The axis.
    point : DesignPoint
        The design point.
    gamma_range : (float, float)
        Range of the loss of effectiveness gamma.
    n_airspeeds, n_gammas : int
        Candidate grid sizes.
    omegas : sequence of float, optional
        Frequencies (rad/s) of the error evaluation (default: a log grid).

    Returns
    -------
    (float, float)
        (airspeed m/s, gamma) of the centred nominal model.
    """
    om = np.logspace(-3, 3, 121) if omegas is None else np.asarray(omegas, dtype=float)
    members = [(float(V), float(g))
               for V in np.linspace(point.v_min_m_s, point.v_max_m_s, 17)
               for g in np.linspace(gamma_range[0], gamma_range[1], 4)]
    cands = [(float(V), float(g))
             for V in np.linspace(point.v_min_m_s, point.v_max_m_s, n_airspeeds)
             for g in np.linspace(gamma_range[0], gamma_range[1], n_gammas)]
    resp: dict[tuple[float, float], np.ndarray] = {}
    for key in members + cands:
        if key not in resp:
            resp[key] = rate_response(af, axis, key[0], key[1], om)
    Gm = np.array([resp[k] for k in members])           # (n_members, n_omega)
    Gc = np.array([resp[k] for k in cands])             # (n_candidates, n_omega)
    bound = np.abs(Gm[None, :, :] / Gc[:, None, :] - 1.0).max(axis=1)
    peaks = bound.max(axis=1)
    means = np.mean(np.log(np.maximum(bound, 1e-12)), axis=1)
    ok = np.nonzero(peaks <= peaks.min() * (1 + 1e-3))[0]
    i = int(ok[np.argmin(means[ok])])
    return cands[i]


def cover(af: Airframe, axis: Axis, point: DesignPoint, omegas: Sequence[float] | None = None,
          orders: Sequence[int] = (1, 2), tolerance_db: float = 1.0,
          nominal: tuple[float, float] | None = None,
          ) -> tuple[UncertaintyWeight, RelativeError]:
    """Fit W_t for one axis and design point (MATLAB ``ucover``).

    The lowest order whose mean gap to the relative error is within ``tolerance_db`` of the
    best order tried.

    Parameters
    ----------
    af : Airframe
        The airframe.
    axis : {"roll", "pitch", "yaw"}
        The axis.
    point : DesignPoint
        The design point.
    omegas : sequence of float, optional
        Frequencies (rad/s) of the fit (default: a log grid).
    orders : sequence of int
        Weight orders to try.
    tolerance_db : float
        Mean-gap tolerance (dB) against the best order.
    nominal : (float, float), optional
        (airspeed m/s, gamma) of the nominal model (default: the paper's, healthy at the
        nominal airspeed).

    Returns
    -------
    weight : UncertaintyWeight
        W_t, |W_t(j w)| >= the relative error on a dense grid.
    error : RelativeError
        The relative error it covers.

    Examples
    --------
    >>> from vtolftc.airframe.loader import load_airframe
    >>> W, err = cover(load_airframe(), "roll", DesignPoint(4, 10.0, 8.5, 11.5))
    >>> import numpy as np
    >>> bool(np.all(W.magnitude(err.omegas) >= err.bound)), W.order
    (True, 1)
    """
    om = np.logspace(-3, 3, 241) if omegas is None else np.asarray(omegas, dtype=float)
    rel = relative_error(af, axis, point, om, nominal=nominal)
    # Resonances of lightly damped perturbed models make narrow peaks: the fitted weight is
    # checked, and its gain raised where needed, on a grid 16 times denser and wider.
    dense_om = np.logspace(np.log10(om[0]) - 1, np.log10(om[-1]) + 1, 16 * om.size)
    dense = relative_error(af, axis, point, dense_om, nominal=nominal)
    fits = []
    for order in orders:
        f = fit_weight(om, rel.bound, order)
        short = float(np.max(dense.bound * 1.01 / f.magnitude(dense_om)))
        if short > 1.0:
            f = UncertaintyWeight(f.gain * short, f.zeros_rad_s, f.poles_rad_s)
        fits.append(f)
    gaps = [float(np.mean(20 * np.log10(f.magnitude(om) / rel.bound))) for f in fits]
    best = min(gaps)
    chosen = next(f for f, g in zip(fits, gaps, strict=True) if g <= best + tolerance_db)
    return chosen, rel

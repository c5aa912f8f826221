"""Robust stability and robust performance of a designed axis loop by mu analysis
(paper section 4, eqs. 12-14, table 3).

Interconnection (one axis; signals as in :mod:`vtolftc.synthesis.loops`). The perturbed plant is
G_p = G (1 + W_t Delta) (eq. 11) with the uncertainty at the plant input: the plant sees
u + d with d = Delta z, z = W_t u. The exogenous input is the angle reference r, the
weighted performance outputs are p = [Ws e; Wr u] (the two requirements of eq. 8 that are
not the uncertainty itself). From the closed loop (inputs [d, r], outputs [e, u]):

    u = -T_u d + R r,        e = (e/d) d + S r,        e/d = -G_angle / (1 + L_u)

so the matrix seen by the augmented perturbation diag(Delta, Delta_P) is

        [ z    ]   [ -W_t T_u      W_t R  ] [ d ]
    N = [ Ws e ] = [ Ws (e/d)      Ws S   ] [ r ],   d = Delta z,  r = Delta_P [Ws e; Wr u]
        [ Wr u ]   [ -Wr T_u       Wr R   ]

- robust stability (eq. 13): M = N_11 = -W_t T_u with one complex scalar block (1 x 1), so
  mu_Delta(M(jw)) = |W_t T_u(jw)| exactly; it is computed with :func:`vtolftc.synthesis.mu.mu_sweep`
  anyway and cross-checked against the closed form (:attr:`AxisRobustness.rs_check`).
- robust performance (eq. 14): mu of N with blocks Delta (1 x 1, complex) and the
  fictitious full performance block Delta_P (1 x 2: two performance outputs back to the
  one reference input). :func:`vtolftc.synthesis.mu.mu_sweep` wants a square matrix, so N is padded
  with a zero column and Delta_P taken 2 x 2: the extra row of Delta_P only feeds the zero
  column, so mu is unchanged (:func:`square_rp`). For a plain unity-feedback SISO loop
  without Wr the structure is the textbook one and mu_hat = |Ws S| + |Wt T| at every
  frequency (tested).

Because the P-PID has integral action, T_u(0) = 1: mu_Delta >= |W_t(0)| at low frequency,
whatever the gains. Where the fitted uncertainty weight exceeds 1 at low frequency (the
model set contains gains more than 100 % away from the nominal) robust stability cannot be
certified by this test for any controller with integral action.
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import Any

import numpy as np
from numpy.typing import NDArray

from vtolftc.synthesis.hinfnorm import frequency_response
from vtolftc.synthesis.loops import closed_loop
from vtolftc.synthesis.mu import Block, MuSweep, mu_sweep

__all__ = [
    "RP_BLOCKS",
    "RS_BLOCKS",
    "AxisRobustness",
    "analyse",
    "rp_matrix",
]

RS_BLOCKS = (Block.full(1, 1),)
RP_BLOCKS = (Block.full(1, 1), Block.full(2, 2))


def _resp(W: Any, omegas: NDArray[np.float64]) -> NDArray[np.complex128]:
    if W is None:
        return np.zeros(omegas.shape, complex)
    if hasattr(W, "response"):
        return W.response(omegas)
    if hasattr(W, "magnitude") and hasattr(W, "tf"):
        W = W.tf()
    return frequency_response(W, omegas)[:, 0, 0]


def rp_matrix(G: Any, theta: Any, Ws: Any, Wt: Any, Wr: Any | None,
              omegas: NDArray[np.float64]) -> NDArray[np.complex128]:
    """N(j w) of the module docstring (robust-performance matrix of one axis loop).

    Parameters
    ----------
    G : control.StateSpace or tuple
        Plant moment (N m) -> [rate (rad/s); angle (rad)].
    theta : sequence of float or mapping
        The P-PID gains.
    Ws, Wt, Wr : weight or None
        Objects with ``response`` (:class:`vtolftc.synthesis.loops.SensitivityWeight`,
        ``ControlWeight``), an :class:`vtolftc.synthesis.uncertainty.UncertaintyWeight` or any
        SISO LTI; ``Wr`` may be None.
    omegas : ndarray of float, shape (nw,)
        Frequencies (rad/s).

    Returns
    -------
    ndarray of complex, shape (nw, 3, 2)
        N(j w); (nw, 2, 2) if ``Wr`` is None.
    """
    w = np.asarray(omegas, float)
    cl = closed_loop(G, theta)
    F = frequency_response(cl.lti(), w)          # (nw, 4 outputs [e,u,rate,angle], 2 in [r,d])
    e_r, e_d, u_r, u_d = F[:, 0, 0], F[:, 0, 1], F[:, 1, 0], F[:, 1, 1]
    ws, wt = _resp(Ws, w), _resp(Wt, w)
    rows = [np.stack([wt * u_d, wt * u_r], -1), np.stack([ws * e_d, ws * e_r], -1)]
    if Wr is not None:
        wr = _resp(Wr, w)
        rows.append(np.stack([wr * u_d, wr * u_r], -1))
    return np.stack(rows, 1)


def square_rp(N: NDArray[np.complex128]) -> NDArray[np.complex128]:
    """Pad N with zero columns to a square matrix for ``RP_BLOCKS``.

    Parameters
    ----------
    N : ndarray of complex, shape (nw, 1 + k, 2)
        From :func:`rp_matrix`.

    Returns
    -------
    ndarray of complex, shape (nw, 1 + k, 1 + k)
        N with zero columns appended.
    """
    nw, p, m = N.shape
    out = np.zeros((nw, p, p), complex)
    out[:, :, :m] = N
    return out


@dataclass(frozen=True)
class AxisRobustness:
    """mu results of one axis loop at one design point.

    Properties ``mu_rs``/``mu_rp`` give the sweeps' peak upper bounds (the certified
    values), ``gap_rs``/``gap_rp`` the largest absolute upper - lower gap over the grid.

    Parameters
    ----------
    omegas : ndarray of float, shape (nw,)
        Frequencies (rad/s).
    rs, rp : MuSweep
        Robust-stability and robust-performance sweeps (lower/upper bounds per frequency).
    rs_closed_form : ndarray of float, shape (nw,)
        |W_t T_u|, the closed form of the 1 x 1 robust-stability case.
    rs_check : float
        Max over the grid of |mu_upper - |W_t T_u||.
    """

    omegas: NDArray[np.float64]
    rs: MuSweep
    rp: MuSweep
    rs_closed_form: NDArray[np.float64]
    rs_check: float

    @property
    def mu_rs(self) -> float:
        """Certified robust-stability mu: peak of the upper bound over the grid."""
        return self.rs.peak_upper

    @property
    def mu_rp(self) -> float:
        """Certified robust-performance mu: peak of the upper bound over the grid."""
        return self.rp.peak_upper

    @property
    def gap_rs(self) -> float:
        """Largest upper - lower bound gap of the robust-stability sweep."""
        return float(np.max(self.rs.gap))

    @property
    def gap_rp(self) -> float:
        """Largest upper - lower bound gap of the robust-performance sweep."""
        return float(np.max(self.rp.gap))

    def summary(self) -> dict[str, float]:
        """Peaks, lower bounds, peak frequencies (rad/s), gaps and the closed-form check.

        Returns
        -------
        dict of str to float
            The numbers, by name.
        """
        return {
            "mu_rs": self.mu_rs, "mu_rs_lower": self.rs.peak_lower,
            "mu_rs_peak_frequency_rad_s": self.rs.peak_upper_frequency_rad_s,
            "mu_rs_gap": self.gap_rs, "mu_rs_closed_form_check": self.rs_check,
            "mu_rp": self.mu_rp, "mu_rp_lower": self.rp.peak_lower,
            "mu_rp_peak_frequency_rad_s": self.rp.peak_upper_frequency_rad_s,
            "mu_rp_gap": self.gap_rp,
        }


def default_grid() -> NDArray[np.float64]:
    """Frequency grid of the sweeps: 1e-3 .. 1e3 rad/s, 121 points (log).

    Returns
    -------
    ndarray of float, shape (121,)
        Frequencies (rad/s).
    """
    return np.logspace(-3, 3, 121)


def analyse(G: Any, theta: Any, Ws: Any, Wt: Any, Wr: Any | None,
            omegas: NDArray[np.float64] | None = None, *, seed: int = 0) -> AxisRobustness:
    """Robust stability (eq. 13) and robust performance (eq. 14) sweeps of one axis loop.

    Parameters
    ----------
    G : control.StateSpace or tuple
        Plant moment (N m) -> [rate (rad/s); angle (rad)].
    theta : sequence of float or mapping
        The P-PID gains.
    Ws, Wt, Wr : weight or None
        As in :func:`rp_matrix`.
    omegas : ndarray of float, optional
        Frequencies (rad/s); default :func:`default_grid`.
    seed : int
        Seed of the random lower-bound starts.

    Returns
    -------
    AxisRobustness
        The sweeps.
    """
    w = default_grid() if omegas is None else np.asarray(omegas, float)
    if not closed_loop(G, theta).stable():
        raise ValueError("the nominal closed loop is unstable: mu analysis of robust "
                         "stability/performance presupposes nominal stability")
    N = rp_matrix(G, theta, Ws, Wt, Wr, w)
    M = N[:, :1, :1]
    rs = mu_sweep(M, RS_BLOCKS, w, n_starts=0, seed=seed)
    closed = np.abs(M[:, 0, 0])
    blocks = RP_BLOCKS if N.shape[1] == 3 else (Block.full(1, 1), Block.full(1, 1))
    rp = mu_sweep(square_rp(N), blocks, w, n_starts=1, seed=seed)
    return AxisRobustness(w, rs, rp, closed, float(np.max(np.abs(rs.upper - closed))))

"""Predicted yaw RMSE after a fault with the roll-sideslip-yaw coupling, on the linear models.

The single-axis fault predictor (:mod:`vtolftc.synthesis.fault_objective`) sees only the
yaw moment the fault leaves (0.12-0.16 N m on DS-1). In flight the larger yaw disturbance
is often the roll loop's: the fault's roll moment banks the vehicle, gravity accelerates it
sideways, the sideslip meets the fin's weathercock stiffness (C_nbeta) and turns the nose.
Measured (``benchmarks/yaw_ranking.py``, case 1): the paper SHIF's roll and pitch gains with
surface2's GS-SHIF yaw gains bank 6.1 deg, drift 1.0 m/s sideways (sideslip -11.7 deg at
4.4 m/s), the yaw controller commands +0.85 N m against the fin, and the yaw RMSE is 1.15 deg
against 0.25 deg with surface2's own roll and pitch.

The linear chain, at each airspeed V of the case (states: roll loop, lateral velocity, yaw
loop; one step input at t = 0):

    roll loop  (:func:`~vtolftc.synthesis.fault_objective.disturbance_loop`):  d_L -> phi
    lateral    v' = g phi + Y_v v,   Y_v = rho V S CY_beta / (2 m)           [1/s]
    fin        N_beta = N_v v,       N_v = rho V S b C_nbeta / 2             [N m s/m]
    yaw loop   d_N + N_beta -> psi

(beta ~ v / V, so N_beta = qbar S b C_nbeta beta; the yaw plant's own stiffness,
beta = -psi, stays in the yaw design plant.) The predicted RMSE combines the exact ISE of
psi (:func:`~vtolftc.synthesis.fault_objective.step_ise`) over the airspeeds as the fault
predictor does:

    RMSE_pred = sqrt( sum_k w_k ISE_psi(V_k) / T_window )   [rad]

Left out: the pitch loop, the lateral position/velocity of the guidance (none in the
transition), roll-yaw inertia and aerodynamic cross terms (C_lr, C_np), saturation.
"""

from __future__ import annotations

import math
from collections.abc import Callable

import numpy as np

from vtolftc.airframe.loader import Airframe
from vtolftc.synthesis.fault_objective import (
    FaultCase,
    disturbance_loop,
    fault_gamma,
    fault_moment,
    step_ise,
)
from vtolftc.synthesis.hinfnorm import StateSpaceData, as_state_space

__all__ = ["lateral_coefficients", "lateral_fault_loop", "lateral_yaw_rmse"]


def lateral_coefficients(af: Airframe, airspeed_m_s: float) -> tuple[float, float]:
    """Side-force damping and fin yaw moment of a lateral velocity.

    Parameters
    ----------
    af : Airframe
        The airframe.
    airspeed_m_s : float
        Airspeed V [m/s].

    Returns
    -------
    Y_v : float
        rho V S CY_beta / (2 m) [1/s] (<= 0: the side force opposes the drift).
    N_v : float
        rho V S b C_nbeta / 2 [N m s/m] (yaw moment per m/s of lateral body velocity).

    Examples
    --------
    >>> from vtolftc.airframe.loader import load_airframe
    >>> y_v, n_v = lateral_coefficients(load_airframe(), 8.0)
    >>> bool(y_v < 0.0 < n_v)
    True
    """
    V = float(airspeed_m_s)
    w = af.wing
    rho = af.air_density_kg_m3
    c_nbeta = float(af.derivatives.at(V)["C_nbeta"])
    return (rho * V * w.area_m2 * w.CY_beta / (2.0 * af.mass_kg),
            0.5 * rho * V * w.area_m2 * w.span_m * c_nbeta)


def lateral_fault_loop(af: Airframe, airspeed_m_s: float, G_roll: object, K_roll: StateSpaceData,
                       G_yaw: object, K_yaw: StateSpaceData, d_roll: float, d_yaw: float,
                       ) -> StateSpaceData:
    """The coupled loop of the module docstring, unit step input -> yaw angle psi [rad].

    Parameters
    ----------
    af : Airframe
        The airframe (g, mass, wing, C_nbeta).
    airspeed_m_s : float
        Airspeed [m/s].
    G_roll, G_yaw : state-space system
        Roll and yaw plants, moment [N m] -> [rate rad/s; angle rad], strictly proper.
    K_roll, K_yaw : tuple of ndarray
        Their feedbacks [rate; angle] -> moment
        (:func:`~vtolftc.synthesis.fault_objective.ppid_controller`, ``lqr_controller``).
    d_roll, d_yaw : float
        The fault's moment steps [N m] about x and z (body FRD).

    Returns
    -------
    A, B, C, D : ndarray
        States [roll loop; v; yaw loop], one input (the step), output psi [rad].
    """
    A1, B1, C1, _ = disturbance_loop(G_roll, K_roll)
    A3, B3, C3, _ = disturbance_loop(G_yaw, K_yaw)
    y_v, n_v = lateral_coefficients(af, airspeed_m_s)
    n1, n3 = A1.shape[0], A3.shape[0]
    n = n1 + 1 + n3
    A = np.zeros((n, n))
    A[:n1, :n1] = A1
    A[n1, :n1] = af.gravity_m_s2 * C1[0]
    A[n1, n1] = y_v
    A[n1 + 1:, n1] = B3[:, 0] * n_v
    A[n1 + 1:, n1 + 1:] = A3
    B = np.zeros((n, 1))
    B[:n1, 0] = B1[:, 0] * d_roll
    B[n1 + 1:, 0] = B3[:, 0] * d_yaw
    C = np.zeros((1, n))
    C[0, n1 + 1:] = C3[0]
    return A, B, C, np.zeros((1, 1))


def lateral_yaw_rmse(af: Airframe, roll_at: Callable[[float], StateSpaceData],
                     yaw_at: Callable[[float], StateSpaceData], case: FaultCase,
                     plant_at: Callable[[str, float, float], object] | None = None) -> float:
    """Predicted yaw RMSE [rad] of ``case`` with the roll-sideslip-yaw coupling.

    Parameters
    ----------
    af : Airframe
        The airframe.
    roll_at, yaw_at : callable
        Airspeed [m/s] -> the roll / yaw feedback flown there
        (:func:`~vtolftc.synthesis.fault_objective.controller_from_document`).
    case : FaultCase
        The case (losses, airspeeds and time shares, horizon, window).
    plant_at : callable, optional
        (axis, airspeed [m/s], gamma) -> plant; default the robust design plant.

    Returns
    -------
    float
        RMSE_pred [rad] (inf when a loop on the way is unstable).
    """
    from vtolftc.synthesis.robust import design_plant

    plant = plant_at or (lambda ax, v, g: design_plant(af, ax, v, g))
    total = 0.0
    for v, w in zip(case.airspeeds_m_s, case.weights, strict=True):
        G = {ax: as_state_space(plant(ax, v, fault_gamma(af, ax, v, case.losses)))
             for ax in ("roll", "yaw")}
        sys = lateral_fault_loop(af, v, G["roll"], roll_at(v), G["yaw"], yaw_at(v),
                                 fault_moment(af, "roll", v, case.losses),
                                 fault_moment(af, "yaw", v, case.losses))
        total += w * step_ise(sys, 1.0, case.horizon_s)
    return math.sqrt(total / case.window_s)

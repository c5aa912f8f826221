"""Predicted attitude error of the nominal rest of the transition, on the linear models.

Table 4 takes the RMSE over t >= 20 s. The fault predictor
(:mod:`vtolftc.synthesis.fault_objective`) sees only the fault transient (22-26 s); the rest
of the window is the nominal end of the transition and cruise. For DS-1 the nominal flight
(case 0, no fault) has no roll or yaw error at all (1e-8 deg RMSE: no roll or yaw command
or moment change in a straight transition), and a pitch error of 0.205-0.211 deg RMSE whose
largest part is the cruise hand-over at t ~ 30 s: the lift rotors drop to idle, the
altitude dips and the altitude loop steps the pitch reference by about +1.2 deg at 18 m/s
(``docs/ds1-claims/README.md``, table of the case-1 windows, 30-34 s). ~72 % of the case-1
pitch squared error of the first surface design lay after t = 24 s, and a design that
ignored it lowered kp_angle toward cruise (``docs/ds1-surfaces/README.md``).

This module predicts that part as the tracking error of reference steps:

    RMSE_nom = sqrt( sum_k ISE_k / T_window ),   ISE_k = int_0^H e_k(t)^2 dt   [rad]

with e_k = r - angle the error of the closed loop of the design plant at airspeed V_k with
the controller flown there, after a step r_k of the attitude reference
(:func:`reference_loop`, the exact ISE of :func:`~vtolftc.synthesis.fault_objective.step_ise`).
The steps of DS-1 (:data:`NOMINAL_STEPS`): pitch, one step of 1.2 deg at 18 m/s; roll and
yaw none (their nominal error is nil). Squared errors of disjoint time windows add, so the
fault and nominal predictions combine as sqrt(RMSE_fault^2 + RMSE_nom^2) over the same
window (weight 1: both are shares of the same table-4 metric).
"""

from __future__ import annotations

import math
from collections.abc import Callable, Sequence
from dataclasses import dataclass

import numpy as np

from vtolftc.airframe.loader import Airframe
from vtolftc.synthesis.fault_objective import feedback_state_matrix, step_ise
from vtolftc.synthesis.hinfnorm import StateSpaceData, as_state_space
from vtolftc.synthesis.models import Axis

__all__ = ["NOMINAL_STEPS", "NominalStep", "nominal_inputs", "nominal_rmse",
           "nominal_rmse_from_inputs", "reference_loop"]


@dataclass(frozen=True)
class NominalStep:
    """A step of the attitude reference in the nominal flight.

    Parameters
    ----------
    airspeed_m_s : float
        Airspeed where it happens [m/s].
    step_rad : float
        Step height [rad].
    horizon_s : float, optional
        Horizon of its response [s].
    """

    airspeed_m_s: float
    step_rad: float
    horizon_s: float = 6.0


#: DS-1's nominal reference steps after the fault transient, per axis (module docstring).
NOMINAL_STEPS: dict[str, tuple[NominalStep, ...]] = {
    "roll": (), "pitch": (NominalStep(18.0, math.radians(1.2)),), "yaw": (),
}
#: The table-4 metrics window [s] (t >= 20 s of 40 s).
WINDOW_S = 20.0


def reference_loop(G: object, K: StateSpaceData) -> StateSpaceData:
    """Closed loop from the attitude reference r to the error e = r - angle.

    The feedback ``K`` ([rate; angle] -> moment, sign included: :func:`~vtolftc.synthesis.
    fault_objective.ppid_controller`, :func:`~vtolftc.synthesis.fault_objective.
    lqr_controller`) sees the angle error: its inputs are [rate; angle - r] (the cascaded
    P-PID's u = K_rate (kp_angle (r - angle) - rate)).

    Parameters
    ----------
    G : state-space system
        The plant, moment [N m] -> [rate rad/s; angle rad], strictly proper.
    K : tuple of ndarray
        The feedback.

    Returns
    -------
    A, B, C, D : ndarray
        r [rad] -> e [rad], states [plant; controller].
    """
    A, (_, Bg, Cg), (Ak, Bk, _, Dk) = feedback_state_matrix(G, K)
    nk = Ak.shape[0]
    e2 = np.array([[0.0], [1.0]])                    # r enters the angle input with a minus
    B = np.vstack([-Bg @ Dk @ e2, -Bk @ e2])
    C = np.hstack([-Cg[[1], :], np.zeros((1, nk))])
    return A, B, C, np.ones((1, 1))


def nominal_inputs(af: Airframe, axis: Axis, steps: Sequence[NominalStep] | None = None,
                   plant_at: Callable[[float], object] | None = None,
                   ) -> list[tuple[NominalStep, StateSpaceData]]:
    """The plants of the steps (independent of the controller: compute once per design).

    Parameters
    ----------
    af : Airframe
        The airframe.
    axis : {"roll", "pitch", "yaw"}
        The axis.
    steps : sequence of NominalStep, optional
        Default :data:`NOMINAL_STEPS` of the axis.
    plant_at : callable, optional
        Airspeed [m/s] -> plant; default the robust design plant, nominal effectiveness.

    Returns
    -------
    list of (NominalStep, tuple of ndarray)
        Each step with its plant (A, B, C, D).
    """
    from vtolftc.synthesis.robust import design_plant

    st = NOMINAL_STEPS[axis] if steps is None else tuple(steps)
    plant = plant_at or (lambda v: design_plant(af, axis, v))
    return [(s, as_state_space(plant(s.airspeed_m_s))) for s in st]


def nominal_rmse_from_inputs(inputs: Sequence[tuple[NominalStep, StateSpaceData]],
                             controller_at: Callable[[float], StateSpaceData],
                             window_s: float = WINDOW_S) -> float:
    """RMSE_nom [rad] of the module docstring from :func:`nominal_inputs`.

    Parameters
    ----------
    inputs : sequence
        :func:`nominal_inputs`.
    controller_at : callable
        Airspeed [m/s] -> feedback.
    window_s : float
        The metrics window [s].

    Returns
    -------
    float
        [rad] (0 with no step; inf when a loop is unstable).
    """
    total = 0.0
    for s, G in inputs:
        total += step_ise(reference_loop(G, controller_at(s.airspeed_m_s)), s.step_rad,
                          s.horizon_s)
    return math.sqrt(total / window_s)


def nominal_rmse(af: Airframe, axis: Axis, controller_at: Callable[[float], StateSpaceData],
                 steps: Sequence[NominalStep] | None = None,
                 window_s: float = WINDOW_S) -> float:
    """Predicted nominal-transition RMSE [rad] of ``axis`` (module docstring).

    Parameters
    ----------
    af : Airframe
        The airframe.
    axis : {"roll", "pitch", "yaw"}
        The axis.
    controller_at : callable
        Airspeed [m/s] -> the feedback flown there.
    steps : sequence of NominalStep, optional
        Default :data:`NOMINAL_STEPS` of the axis.
    window_s : float
        The metrics window [s].

    Returns
    -------
    float
        RMSE_nom [rad].
    """
    return nominal_rmse_from_inputs(nominal_inputs(af, axis, steps), controller_at, window_s)

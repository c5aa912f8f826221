"""Baseline attitude controllers of the paper's comparison: LQR (this module) and SHIF (the
constant multi-model structured H-infinity design, :func:`vtolftc.synthesis.design.design_shif`).

LQR, per axis, on the hover model (V = 0: the wing terms vanish, the axis is a near-pure
inertia, quadrotor-like; the model keeps whatever V = 0 damping and stiffness
:func:`vtolftc.synthesis.models.axis_coefficients` gives, zero for DS-1), augmented with the
integral of the angle error:

    x = [xi, angle, rate],  xi' = angle_ref - angle,  angle' = rate,
    J rate' = D rate + K angle + tau          (D, K: damping and stiffness at V = 0)

Cost J = int x' Q x + R tau^2 dt with R = 0.5 (the paper) and

    Q = diag(100, 100, 1)  (integral [1/(rad s)^2], angle [1/rad^2], rate [s^2/rad^2])

chosen by Bryson's rule as is usual in quadrotor LQR attitude / fault-tolerant-control
studies (weights = 1 / (acceptable excursion)^2): about 0.1 rad of attitude error, 0.1 rad s
of integrated error and 1 rad/s of body rate are equally costly. With DS-1's inertias this
puts the closed-loop poles near 1-2.4 rad/s (roll/pitch/yaw alike), a conservative attitude
bandwidth below the 250 Hz autopilot and the 20 rad/s actuators. The same Q is used for the
three axes (as in the paper, which gives one R).

Law (u = -K x with K = [k1, k2, k3]; at angle_ref != 0 the angle state is the tracking
error's complement):

    tau = k_int xi + k_angle (angle_ref - angle) - k_rate rate,
    k_int = -k1 [N m/(rad s)], k_angle = k2 [N m/rad], k_rate = k3 [N m s/rad]
"""

from __future__ import annotations

from dataclasses import dataclass

import control as ct
import numpy as np
from numpy.typing import NDArray

from vtolftc.airframe.loader import Airframe
from vtolftc.synthesis.models import AXES, Axis, axis_coefficients

__all__ = ["LQR_Q", "LQR_R", "LqrAxis", "lqr_axis", "lqr_design"]

LQR_Q: tuple[float, float, float] = (100.0, 100.0, 1.0)
LQR_R = 0.5


@dataclass(frozen=True)
class LqrAxis:
    """LQR gains of one axis and the closed-loop poles of the design model.

    Parameters
    ----------
    axis : {"roll", "pitch", "yaw"}
        The axis.
    k_int : float
        Gain on the integral of the angle error (N m / (rad s)).
    k_angle : float
        Gain on the angle error (N m / rad).
    k_rate : float
        Gain on the body rate (N m s / rad).
    poles : tuple of complex
        Closed-loop poles of the design model (1/s).
    A : ndarray of float, shape (3, 3)
        State matrix of the design model (states [xi, angle, rate]).
    B : ndarray of float, shape (3, 1)
        Its input matrix (moment, N m).
    """

    axis: Axis
    k_int: float
    k_angle: float
    k_rate: float
    poles: tuple[complex, ...]
    A: NDArray[np.float64]
    B: NDArray[np.float64]

    def gains(self) -> dict[str, float]:
        """``k_int``, ``k_angle``, ``k_rate`` of this axis as a dict.

        Returns
        -------
        dict of str to float
            N m / (rad s), N m / rad, N m s / rad.
        """
        return {"k_int": self.k_int, "k_angle": self.k_angle, "k_rate": self.k_rate}


def design_model(af: Airframe, axis: Axis, airspeed_m_s: float = 0.0,
                 ) -> tuple[NDArray[np.float64], NDArray[np.float64]]:
    """(A, B) of the integral-augmented axis model, states [xi, angle, rate].

    Parameters
    ----------
    af : Airframe
        The airframe.
    axis : {"roll", "pitch", "yaw"}
        The axis.
    airspeed_m_s : float
        Airspeed (m/s) of the model; 0 is hover.

    Returns
    -------
    A : ndarray of float, shape (3, 3)
        State matrix.
    B : ndarray of float, shape (3, 1)
        Input matrix of the moment (N m).
    """
    c = axis_coefficients(af, axis, airspeed_m_s)
    A = np.array([[0.0, -1.0, 0.0],
                  [0.0, 0.0, 1.0],
                  [0.0, c.stiffness / c.inertia, c.damping / c.inertia]])
    B = np.array([[0.0], [0.0], [1.0 / c.inertia]])
    return A, B


def lqr_axis(af: Airframe, axis: Axis, Q: tuple[float, float, float] = LQR_Q,
             R: float = LQR_R) -> LqrAxis:
    """LQR of one axis on the hover model (module docstring).

    Parameters
    ----------
    af : Airframe
        The airframe.
    axis : {"roll", "pitch", "yaw"}
        The axis.
    Q : (float, float, float)
        State weights on [xi, angle, rate] (1/(rad s)^2, 1/rad^2, s^2/rad^2).
    R : float
        Weight on the moment (1/(N m)^2).

    Returns
    -------
    LqrAxis
        Gains and closed-loop poles.

    Examples
    --------
    >>> from vtolftc.airframe.loader import load_airframe
    >>> k = lqr_axis(load_airframe(), "roll")
    >>> all(p.real < 0 for p in k.poles), k.k_angle > 0
    (True, True)
    """
    A, B = design_model(af, axis, 0.0)
    K, _, E = ct.lqr(A, B, np.diag(Q), np.array([[R]]))
    k1, k2, k3 = (float(x) for x in np.asarray(K).ravel())
    return LqrAxis(axis, -k1, k2, k3, tuple(complex(e) for e in E), A, B)


def lqr_design(af: Airframe, Q: tuple[float, float, float] = LQR_Q, R: float = LQR_R,
               ) -> dict[Axis, LqrAxis]:
    """LQR gains of the three axes.

    Parameters
    ----------
    af : Airframe
        The airframe.
    Q : (float, float, float)
        State weights on [xi, angle, rate], as in :func:`lqr_axis`.
    R : float
        Weight on the moment.

    Returns
    -------
    dict of str to LqrAxis
        Keyed by "roll", "pitch", "yaw".
    """
    return {ax: lqr_axis(af, ax, Q, R) for ax in AXES}
